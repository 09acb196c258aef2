"""gyrodeblur: remove camera-shake blur from photos using the camera's gyroscope log."""

__version__ = "0.1.0"
