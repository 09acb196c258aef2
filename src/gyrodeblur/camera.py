"""Pinhole camera intrinsics (pixels, OpenCV convention)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import InputError

__all__ = ["Camera", "MAX_SIDE"]

#: Longest image side (px) a camera description may give: far beyond any sensor (the
#: largest have about 20 000 px), short of sizes that only overflow later.
MAX_SIDE = 1 << 20


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics in pixels for an image of ``width`` x ``height``.

    Pixel centres are at integer coordinates (OpenCV): the top-left pixel's centre is
    ``(0, 0)`` and the exact image centre is ``((width - 1) / 2, (height - 1) / 2)``.
    The camera frame is x right, y down, z forward; no lens distortion is modelled.

    Attributes
    ----------
    fx, fy : float
        Focal lengths in pixels (from millimetres: ``f_mm * width_px / sensor_width_mm``).
        Only their sign is checked here; a capture description
        (:func:`gyrodeblur.capture.load_capture`) also refuses one under 0.15 x the longer
        side, a value in mm.
    cx, cy : float
        Principal point in pixels. Any finite value: a crop's own intrinsics may put it
        outside the image, even far outside. A capture description
        (:func:`gyrodeblur.capture.load_capture`) also refuses one more than a frame from
        the image's centre, and warns of one more than a quarter of it off centre.
    width, height : int
        Image size the intrinsics are valid for.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self):
        def finite(v) -> bool:
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                return False
            try:
                return math.isfinite(float(v))
            except OverflowError:           # an int beyond any float
                return False

        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if not finite(v):
                raise InputError(f"camera.{name}", f"must be a finite number, got {v!r}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if not finite(v) or v != int(v):
                raise InputError(f"camera.{name}", f"must be a whole number of pixels, got {v!r}")
        if self.fx <= 0 or self.fy <= 0:
            raise InputError("camera", f"focal lengths must be positive (fx={self.fx}, fy={self.fy})")
        if int(self.width) < 2 or int(self.height) < 2:
            raise InputError("camera", f"image size {self.width}x{self.height} is too small")
        if max(int(self.width), int(self.height)) > MAX_SIDE:
            raise InputError("camera", f"image size {self.width}x{self.height} is not a "
                                       f"sensor's (sides up to {MAX_SIDE} px)")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix (3x3, float64)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def K_inv(self) -> np.ndarray:
        """Inverse intrinsic matrix (3x3, float64)."""
        return np.array([[1.0 / self.fx, 0.0, -self.cx / self.fx],
                         [0.0, 1.0 / self.fy, -self.cy / self.fy],
                         [0.0, 0.0, 1.0]])

    @classmethod
    def centred(cls, width: int, height: int, fx: float, fy: float | None = None) -> "Camera":
        """Intrinsics with the principal point at the exact image centre."""
        return cls(fx, fx if fy is None else fy, (width - 1) / 2, (height - 1) / 2, width, height)

    def scaled_to(self, width: int, height: int, *, source: str | None = None,
                  tolerance: float = 0.01) -> "Camera":
        """The same camera for an image resized to ``width`` x ``height``.

        Pixel edges scale, centres follow: ``c' = s (c + 0.5) - 0.5``, ``f' = s f``.

        Raises
        ------
        InputError
            If the aspect ratio differs by more than ``tolerance`` (relative), naming
            ``source`` (the photo).
        """
        if (width, height) == (self.width, self.height):
            return self
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 2
                   for v in (width, height)):
            raise InputError(source, f"photo size {width!r}x{height!r} is not two whole "
                                     "numbers of pixels, each at least 2")
        sx, sy = width / self.width, height / self.height
        if abs(sx / sy - 1) > tolerance:
            turned = abs((width / self.height) / (height / self.width) - 1) <= tolerance
            hint = (" (turned by 90 degrees? the rows must be the sensor's readout rows: "
                    "give --photo-rotation 90 or 270, the degrees clockwise it was turned)"
                    if turned else "")
            raise InputError(source, f"photo is {width}x{height} but the capture's camera is "
                                     f"{self.width}x{self.height}: the aspect ratio differs"
                                     + hint)
        return Camera(self.fx * sx, self.fy * sy, sx * (self.cx + 0.5) - 0.5,
                      sy * (self.cy + 0.5) - 0.5, width, height)

    def with_focal_scale(self, scale: float) -> "Camera":
        """Focal lengths multiplied by ``scale`` (principal point unchanged)."""
        return replace(self, fx=self.fx * scale, fy=self.fy * scale)

    def rays(self, x, y) -> np.ndarray:
        """Viewing rays ``(..., 3)`` (camera frame, z = 1) of the pixels at ``x``, ``y``
        (pixels; arrays of one shape, or scalars): ``K^-1 (x, y, 1)``."""
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        return np.stack([(x - self.cx) / self.fx, (y - self.cy) / self.fy, np.ones_like(x)], -1)

    def project(self, rays: np.ndarray) -> np.ndarray:
        """Pixel positions ``(..., 2)`` (x, y) of camera-frame directions ``rays``
        ``(..., 3)`` in front of the camera (z > 0): ``K d``, divided by its z."""
        d = np.asarray(rays, np.float64)
        return np.stack([self.fx * d[..., 0] / d[..., 2] + self.cx,
                         self.fy * d[..., 1] / d[..., 2] + self.cy], -1)
