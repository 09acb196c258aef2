"""gyrodeblur: remove camera-shake blur from photos using the camera's gyroscope log.

The API lives in the submodules, one concept each; the entry points:

* :func:`gyrodeblur.capture.load_capture` - a photo's capture description (camera
  intrinsics in pixels, exposure and readout in seconds, the gyro log and its axis
  mapping) as a :class:`~gyrodeblur.capture.Capture`;
* :func:`gyrodeblur.deblur.deblur` - deblur a photo (float in [0, 1]) with the PSFs its
  capture implies; :func:`gyrodeblur.deblur.deblur_blind` without a gyro log;
* :func:`gyrodeblur.calibrate.calibrate` - estimate the time offset, gyro bias, readout
  time, focal-length scale and axis mapping from the blurred photo(s) themselves;
* :func:`gyrodeblur.psf.render_psf`, :func:`gyrodeblur.psf.psf_field` - the PSF at a
  pixel, or on a grid;
* :func:`gyrodeblur.simulate.simulate_blur` - blur a sharp photo by a capture's rotation
  (an independent forward model: warping, not convolution);
  :func:`gyrodeblur.shake.synthetic_hand_shake` - a synthetic gyro log;
* :func:`gyrodeblur.imageio.read_photo`, :func:`gyrodeblur.imageio.write_photo` - JPEG,
  PNG and TIFF files, 8 or 16 bits, their metadata carried;
* :func:`gyrodeblur.gyrolog.read_gyro_log` - gyro logs (gcsv, CSV, Android events);
* :mod:`gyrodeblur.metrics` - PSNR and SSIM as the benchmarks measure them.

Conventions: camera frame x right, y down, z forward (OpenCV); angular velocity of the
camera body in rad/s in that frame; time in seconds; pixel centres at integer
coordinates; PSFs odd-sized and summing to 1, their centre sample the pixel they belong
to. The command line (``gyrodeblur --help``) does the same from files.
"""

__version__ = "0.1.0"
