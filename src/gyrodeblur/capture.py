"""The capture description: when the photo was exposed, by which camera, with which gyro log.

JSON schema (stable; other tools write it)::

    {
      "exposure_start": 1012.345678,   # s, camera clock: the first row starts exposing
      "exposure_time": 0.030,          # s each row integrates light
      "readout_time": 0.030,           # s to read all rows out: row y starts y/height
                                       # of it later (rolling shutter; 0 = global)
      "camera": {"fx": 819.2, "fy": 819.2, "cx": 511.5, "cy": 381.5,
                 "width": 1024, "height": 764},          # pixels, OpenCV convention
      "gyro": {"path": "gyro.gcsv",    # relative to the JSON file
               "format": "gcsv",       # gcsv | csv | android | json
               "orientation": "XYZ",   # log axes -> camera axes (letters or 3x3 matrix)
               "time_offset": 0.0}     # s: camera_time = gyro_time + time_offset
    }

Optional keys in ``gyro``: ``bias`` (``[bx, by, bz]`` rad/s in the camera frame, or
``"auto"``), ``max_gap`` (s, default 0.05) and, for ``csv`` and ``json``, ``time_unit``,
``rate_unit``, ``time_column``, ``rate_columns``. Row ``y`` starts exposing at
``exposure_start + readout_time * y / height``; without a ``readout_time``, a gcsv log's
``frame_readout_time`` header (ms) gives it, else it is 0 (a global shutter). Without an
``exposure_start``, a photo's EXIF capture time serves where the log runs on Unix time (a
phone app's), to be refined by calibration (see :func:`load_capture`).
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from .axes import axes_to_letters, parse_axes
from .camera import Camera
from .errors import GyrodeblurWarning, InputError
from .gyrolog import RATE_UNITS, TIME_UNITS, GyroLog, check_coverage, check_format, read_gyro_log
from .orientation import Orientation

__all__ = ["Capture", "check_capture", "load_capture", "estimate_bias_outside", "CSV_OPTION_KEYS",
           "EXIF_START_TOLERANCE", "EXIF_WHOLE_SECOND_TOLERANCE", "UNKNOWN_READOUT_MAX",
           "UNKNOWN_READOUT_PRIOR"]

CSV_OPTION_KEYS = ("time_unit", "rate_unit", "time_column", "rate_columns")
#: Seconds kept clear of the exposure window when estimating bias from the samples outside it.
BIAS_GUARD = 0.05
#: Longest rolling-shutter readout accepted (s): sensors read a frame out in 5-100 ms, the
#: slowest electronic shutters in about 0.3 s; a larger value is milliseconds given as seconds.
MAX_READOUT_TIME = 1.0
#: Longest readout time (s) that calibration searches where none was given
#: (:attr:`Capture.readout_time_unknown`): phones' and most cameras' electronic shutters
#: read a frame out in 5-40 ms.
UNKNOWN_READOUT_MAX = 0.05
#: Mean and standard deviation (s) of the weak Gaussian prior that calibration puts on a
#: readout time not given: those of readouts spread evenly over 0-40 ms. Where the photo
#: cannot tell (a blur of a few pixels), it keeps the estimate among likely values rather
#: than at a bound of the search; on the 24-case benchmark with no readout given (true
#: 30 ms) it gained 0.8 dB on average over no prior and lost one small blur's mapping
#: (BENCHMARKS section 4, session 41).
UNKNOWN_READOUT_PRIOR = (0.020, 0.012)
#: An automatic bias (rad/s, any axis) above this, or a spread of the samples it comes
#: from above it, says they were not still: a phone's gyro bias is typically under 0.02.
_AUTO_BIAS_SUSPECT = 0.05
#: A principal point further than this fraction of the size from the image centre gets a
#: warning (intrinsics for another resolution, or a crop).
_FAR_PRINCIPAL_POINT = 0.25
#: Smallest focal length a capture may give, as a fraction of the image's longer side: a
#: pinhole view of about 147 degrees across that side. A focal length in mm or 35
#: mm-equivalent given as pixels is far below it.
MIN_FOCAL_PER_SIDE = 0.15
_WIDEST_VIEW_DEG = float(np.degrees(2 * np.arctan(0.5 / MIN_FOCAL_PER_SIDE)))
#: Seconds of gyro log integrated on each side of the exposure window.
ORIENTATION_MARGIN = 0.25


@dataclass(frozen=True, eq=False)
class Capture:
    """Everything needed to turn a gyro log into the PSFs of one photo.

    Attributes
    ----------
    exposure_start : float
        Camera-clock seconds at which row 0 starts exposing; the reference time of the
        orientation (restored photos are referenced to it).
    exposure_time : float
        Seconds each row integrates light (> 0).
    readout_time : float
        Seconds the sensor takes to read all rows out: row ``y`` starts
        ``readout_time * y / height`` after the first (the last one row's time before
        ``readout_time``; >= 0; 0 = global shutter).
    camera : Camera
        Intrinsics in pixels.
    log : GyroLog
        The gyro samples on the gyro clock, in the log's axes.
    axes : ndarray (3, 3)
        Proper rotation with ``w_camera = axes @ w_log``.
    time_offset : float
        Seconds: ``camera_time = gyro_time + time_offset``.
    bias : ndarray (3,)
        Gyro bias in rad/s, camera frame, subtracted from every sample.
    gyro_spec : dict
        The JSON ``gyro`` block as given (path, format, csv options), for saving.
    source : str or None
        The JSON file, for messages.
    max_gap : float
        Largest allowed gap between gyro samples inside the exposure (s).
    exposure_start_from_exif : bool
        Whether ``exposure_start`` is the photo's EXIF capture time (:func:`load_capture`),
        which marks the exposure only to tens or hundreds of milliseconds:
        :func:`gyrodeblur.calibrate.calibrate` then searches a second either way (1.5 s
        for a time to the whole second), and its corrected capture is no longer so.
    readout_time_unknown : bool
        Whether ``readout_time`` was not given (:func:`load_capture`: no
        ``readout_time`` and no gcsv header stating it), so that its 0 is a stand-in, not
        a global shutter: :func:`gyrodeblur.calibrate.calibrate` then searches readouts
        of 0 to :data:`UNKNOWN_READOUT_MAX` under the weak prior
        :data:`UNKNOWN_READOUT_PRIOR`, and its corrected capture is no longer so.
    exif_time_to_the_second : bool
        Whether that EXIF time had no SubSecTimeOriginal (``exposure_start`` is then the
        middle of its second): calibrate searches :data:`EXIF_WHOLE_SECOND_TOLERANCE`
        either way.

    Notes
    -----
    Equality is identity (its arrays have no single truth value); the instance is
    hashable, so it can key a cache.
    """

    exposure_start: float
    exposure_time: float
    readout_time: float
    camera: Camera
    log: GyroLog
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))
    time_offset: float = 0.0
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_spec: dict = field(default_factory=dict)
    source: str | None = None
    max_gap: float = 0.05
    exposure_start_from_exif: bool = False
    readout_time_unknown: bool = False
    exif_time_to_the_second: bool = False

    def __post_init__(self):
        src = self.source
        if not isinstance(self.camera, Camera):
            raise TypeError(f"camera must be a Camera, got {type(self.camera).__name__}")
        if not isinstance(self.log, GyroLog):
            raise TypeError(f"log must be a GyroLog, got {type(self.log).__name__}")
        for name in ("exposure_start", "exposure_time", "readout_time", "time_offset"):
            try:
                if isinstance(getattr(self, name), (bool, np.bool_)):
                    raise TypeError             # True is not one second
                v = float(getattr(self, name))
            except (TypeError, ValueError):
                raise InputError(src, f"{name} must be a number, got {getattr(self, name)!r}") from None
            if not np.isfinite(v):
                raise InputError(src, f"{name} must be a finite number")
            object.__setattr__(self, name, v)
        if self.exposure_time <= 0:
            raise InputError(src, f"exposure_time must be positive, got {self.exposure_time}")
        if self.readout_time < 0:
            raise InputError(src, f"readout_time must be >= 0, got {self.readout_time}")
        if self.readout_time > MAX_READOUT_TIME:
            raise InputError(src, f"readout_time {self.readout_time:g} s is longer than any "
                                  f"sensor's readout (at most {MAX_READOUT_TIME:g} s; it is "
                                  "seconds, not ms)")
        object.__setattr__(self, "axes", parse_axes(self.axes, source=src))
        try:
            if any(isinstance(b, (bool, np.bool_)) for b in np.ravel(np.asarray(self.bias, object))):
                raise TypeError             # JSON true/false is not a rate
            bias = np.array(self.bias, dtype=np.float64).reshape(-1)     # a copy
        except (TypeError, ValueError):
            bias = np.full(1, np.nan)
        if bias.shape != (3,) or not np.all(np.isfinite(bias)):
            raise InputError(src, f"gyro bias must be three finite numbers (rad/s), got {self.bias!r}")
        object.__setattr__(self, "bias", bias)
        try:
            gap = float(self.max_gap)
        except (TypeError, ValueError):
            gap = np.nan
        if not (np.isfinite(gap) and gap > 0):
            raise InputError(src, f"max_gap must be a positive number of seconds, got {self.max_gap!r}")
        object.__setattr__(self, "max_gap", gap)
        check_coverage(self.log, *self.log_window, max_gap=self.max_gap)

    # -- timing -------------------------------------------------------------------------
    @property
    def window(self) -> tuple[float, float]:
        """Camera-clock seconds from the first row's start to the last row's end."""
        return (self.exposure_start,
                self.exposure_start + self.readout_time + self.exposure_time)

    @property
    def log_window(self) -> tuple[float, float]:
        """:attr:`window` on the gyro log's clock (s; camera time = gyro time +
        ``time_offset``)."""
        t0, t1 = self.window
        return t0 - self.time_offset, t1 - self.time_offset

    def row_start(self, y) -> np.ndarray:
        """Camera-clock start time (s) of row ``y`` (float rows allowed)."""
        return self.exposure_start + self.readout_time * np.asarray(y, np.float64) / self.camera.height

    # -- motion -------------------------------------------------------------------------
    def camera_rates(self) -> tuple[np.ndarray, np.ndarray]:
        """``(t, w)``: camera-clock seconds and bias-free rad/s in the camera frame."""
        return self.log.t + self.time_offset, self.log.omega @ self.axes.T - self.bias

    @cached_property
    def orientation(self) -> Orientation:
        """Camera orientation relative to ``exposure_start``.

        Only the samples within :data:`ORIENTATION_MARGIN` seconds of the exposure window
        are integrated (a long log would otherwise cost time on every capture).
        """
        t, w = self.camera_rates()
        t0, t1 = self.window
        i0 = max(int(np.searchsorted(t, t0 - ORIENTATION_MARGIN)) - 1, 0)
        i1 = min(int(np.searchsorted(t, t1 + ORIENTATION_MARGIN)) + 1, t.size)
        if i1 - i0 < 2:
            i0, i1 = max(0, i1 - 2), max(i1, 2)
        return Orientation(t[i0:i1], w[i0:i1], self.exposure_start)

    # -- variants -----------------------------------------------------------------------
    def replace(self, **changes) -> "Capture":
        """A copy with fields changed (validated again)."""
        return replace(self, **changes)

    def scaled_to(self, width: int, height: int, *, source: str | None = None) -> "Capture":
        """The capture for a photo of ``width`` x ``height`` (same aspect ratio)."""
        cam = self.camera.scaled_to(width, height, source=source)
        return self if cam is self.camera else replace(self, camera=cam)

    # -- files --------------------------------------------------------------------------
    def to_dict(self, gyro_path: str | None = None) -> dict:
        """The JSON description (``gyro_path`` overrides the stored relative path; a
        readout time not known is left out, as it was given)."""
        c = self.camera
        gyro = dict(self.gyro_spec)
        if not gyro and "time_unit" in self.log.meta:     # a capture made in code, of a CSV
            gyro = {"format": self.log.meta.get("format", "csv"),
                    "time_unit": self.log.meta["time_unit"],
                    "rate_unit": self.log.meta["rate_unit"]}
        if gyro_path is not None:
            gyro["path"] = gyro_path
        letters = axes_to_letters(self.axes)
        gyro["orientation"] = letters if letters else np.round(self.axes, 12).tolist()
        gyro["time_offset"] = self.time_offset
        if np.any(self.bias != 0):
            gyro["bias"] = self.bias.tolist()
        else:
            gyro.pop("bias", None)
        out = {
            "exposure_start": self.exposure_start,
            "exposure_time": self.exposure_time,
            "readout_time": self.readout_time,
            "camera": {"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
                       "width": c.width, "height": c.height},
            "gyro": gyro,
        }
        if self.readout_time_unknown:      # its 0 is a placeholder, not a global shutter
            del out["readout_time"]
        return out

    def save(self, path: str | os.PathLike, gyro_path: str | None = None) -> None:
        """Write the JSON description to ``path`` (whole or not at all).

        ``gyro.path`` is ``gyro_path`` if given, else the log the capture was read from
        (:attr:`GyroLog.source`), relative to ``path``'s folder (absolute if it was given
        so), so that :func:`load_capture` of the file finds it wherever it is written.

        Raises
        ------
        InputError
            The log was made in memory (no file) and ``gyro_path`` is not given.
        """
        from .atomicfile import atomic_write_text
        path = os.fspath(path)
        if gyro_path is None:
            gyro_path = self._gyro_path_from(os.path.dirname(os.path.abspath(path)))
        atomic_write_text(path, json.dumps(self.to_dict(gyro_path), indent=2) + "\n")

    def _gyro_path_from(self, folder: str) -> str:
        stored, opened = self.gyro_spec.get("path"), self.log.source
        if stored is not None and os.path.isabs(os.path.expanduser(os.fspath(stored))):
            return os.fspath(stored)
        if opened and os.path.isfile(opened):
            where = os.path.abspath(opened)
            try:                                 # relative unless only the root is shared
                shared = os.path.commonpath([where, folder])
            except ValueError:                   # another drive (Windows)
                return where
            if shared == os.path.dirname(shared):
                return where
            return os.path.relpath(where, folder)
        if stored is not None:
            return os.fspath(stored)
        raise InputError(self.source, "the capture's gyro log has no file to refer to (it was "
                                      "made in memory): write it (gyrodeblur.gyrolog."
                                      "write_gcsv) and give gyro_path")


def estimate_bias_outside(log: GyroLog, axes: np.ndarray, t0: float, t1: float,
                          *, min_samples: int = 20, source: str | None = None) -> np.ndarray:
    """Gyro bias (rad/s, camera frame) from the samples outside ``[t0, t1]`` (gyro clock).

    Method: the per-axis median of the rates measured more than :data:`BIAS_GUARD`
    seconds before the exposure starts or after it ends. This is the bias only where
    the camera was (on average) still outside the exposure, e.g. a log that starts on a
    table or a tripod; the median resists short movements.

    Raises
    ------
    InputError
        If fewer than ``min_samples`` samples lie outside the window.
    """
    out = (log.t < t0 - BIAS_GUARD) | (log.t > t1 + BIAS_GUARD)
    n = int(out.sum())
    if n < min_samples:
        raise InputError(source, f"bias 'auto' needs at least {min_samples} gyro samples "
                                 f"outside the exposure window, the log has {n}")
    rates = log.omega[out] @ np.asarray(axes).T
    bias = np.median(rates, axis=0)
    spread = 1.4826 * np.median(np.abs(rates - bias), axis=0)     # robust sigma
    if np.max(np.abs(bias)) > _AUTO_BIAS_SUSPECT or np.max(spread) > _AUTO_BIAS_SUSPECT:
        why = (f"comes from samples that vary by {np.max(spread):.3f} rad/s: the camera "
               "was not still outside the exposure" if np.max(spread) > _AUTO_BIAS_SUSPECT
               else f"comes from samples that agree to {np.max(spread):.3f} rad/s: the "
                    "camera was turning steadily outside the exposure (a pan, a tripod "
                    "head), if not a gyro that drifts that much")
        warnings.warn(f"{source}: the automatic bias, "
                      f"{', '.join(f'{b:+.3f}' for b in bias)} rad/s, {why}; a phone's bias "
                      f"is rarely above {_AUTO_BIAS_SUSPECT:g} rad/s: give gyro.bias, or "
                      "leave it to calibrate", GyrodeblurWarning, stacklevel=3)
    return bias


def _get(d: dict, key: str, source: str, kind=float, required=True):
    if key not in d or d[key] is None:
        if required:
            raise InputError(source, f"missing {key!r}")
        return None
    v = d[key]
    try:
        if isinstance(v, bool):           # JSON true/false is not a number here
            raise TypeError
        return kind(v)
    except (TypeError, ValueError, OverflowError):
        raise InputError(source, f"{key!r} must be a number, got {v!r}") from None


#: Unix times (s) a log's clock is taken to be Unix time within: 2000 to 2100.
_UNIX_CLOCK = (946_684_800.0, 4_102_444_800.0)
#: Seconds a photo's EXIF capture time may be off its exposure start: calibration searches
#: this far either way (:data:`gyrodeblur.calibrate.EXIF_START_OFFSET_RANGE`), and a time
#: this close to the log is moved to the log's nearest covered start.
EXIF_START_TOLERANCE = 1.0
#: The same for an EXIF time to the second (no SubSecTimeOriginal), taken at the middle of
#: its second: half a second more, so that it covers the same lags of the time behind the
#: exposure (or ahead of it) as a time with its fraction.
EXIF_WHOLE_SECOND_TOLERANCE = EXIF_START_TOLERANCE + 0.5


def _exposure_start_from_exif(hints: dict, log, offset: float, duration: float, src: str,
                              report) -> float:
    """The photo's EXIF capture time as ``exposure_start`` (Unix seconds), where the
    capture description gives none and the gyro log runs on Unix time (a phone app's,
    e.g. Sensor Logger's ``time``) and covers it and the ``duration`` (s: readout and
    exposure) after it; an :class:`InputError` saying why not where it cannot serve."""
    text, unix = hints["capture_time_text"], hints.get("capture_time_unix")
    lo, hi = float(log.t[0]) + offset, float(log.t[-1]) + offset      # camera clock
    if unix is None:
        raise InputError(src, f"missing 'exposure_start': the photo's EXIF time ({text}) "
                              "has no readable time zone (OffsetTimeOriginal or OffsetTime), "
                              "so it is no Unix time; give exposure_start on the gyro log's "
                              "clock")
    if not (_UNIX_CLOCK[0] <= lo and hi <= _UNIX_CLOCK[1]):
        raise InputError(src, f"missing 'exposure_start': the photo's EXIF time ({text}) is "
                              f"Unix time, but the gyro log's clock is not (its times run "
                              f"{lo:.3f} to {hi:.3f} s); give exposure_start on the log's "
                              "clock")
    whole = bool(hints.get("capture_time_whole_second"))
    tolerance = EXIF_WHOLE_SECOND_TOLERANCE if whole else EXIF_START_TOLERANCE
    first, last = lo, hi - duration           # the starts whose exposure the log covers
    start = min(max(unix, first), last)
    if last < first or abs(start - unix) > tolerance:
        raise InputError(src, f"missing 'exposure_start', and the gyro log (Unix {lo:.3f} to "
                              f"{hi:.3f} s, {hi - lo:.1f} s) does not cover an exposure within "
                              f"{tolerance:g} s of the photo's EXIF time ({text}, "
                              f"Unix {unix:.3f} s): is it the log of this photo's session, "
                              "and the phone's clock and time zone right?")
    if report:
        moved = (f"; {abs(start - unix) * 1e3:.0f} ms {'before' if unix < start else 'after'} "
                 f"the exposures the log covers, so the search starts from the nearest one"
                 if start != unix else "")
        if whole:
            which, how_well = (", the middle of its second",
                               "half a second either way (no SubSecTimeOriginal)")
        else:
            which, how_well = "", "tens or hundreds of milliseconds"
        report(f"exposure_start = {start:.3f} s (Unix time, from the photo's EXIF time {text}"
               f"{which}{moved}): that marks the exposure only to {how_well}, and "
               f"calibration searches {tolerance:g} s either way")
    return start


def _readout_direction(value, source: str) -> int:
    """A gcsv header's ``frame_readout_direction`` (0 top to bottom, 1 bottom to top, 2 and
    3 along the rows), written ``0`` or ``0.0``; anything else is an InputError."""
    try:
        d = float(str(value).strip())
    except ValueError:
        d = float("nan")
    if d not in (0, 1, 2, 3):
        raise InputError(source, f"the gcsv header's frame_readout_direction must be 0 (top "
                                 f"to bottom), 1, 2 or 3, got {value!r}")
    return int(d)


def _whole(v) -> int:
    """A pixel count: a finite whole number (``1024`` or ``1024.0``, not ``1024.5``)."""
    if isinstance(v, bool):
        raise TypeError(v)
    f = float(v)
    if not np.isfinite(f) or f != int(f):
        raise ValueError(v)
    return int(f)


#: The keys :func:`load_capture` takes in ``overrides``.
OVERRIDE_KEYS = ("exposure_start", "exposure_time", "readout_time", "fx", "fy", "cx", "cy",
                 "width", "height", "gyro_path", "gyro_format", "orientation", "time_offset",
                 "bias", "max_gap") + CSV_OPTION_KEYS
#: The keys of a capture description, per section ("" = top level).
KNOWN_KEYS = {
    "": ("exposure_start", "exposure_time", "readout_time", "camera", "gyro"),
    "camera": ("fx", "fy", "cx", "cy", "width", "height"),
    "gyro": ("path", "format", "orientation", "time_offset", "bias", "max_gap") + CSV_OPTION_KEYS,
}


def _warn_unknown_keys(data: dict, source: str) -> None:
    """Warn of keys no reader uses (a misspelt ``readout_time`` would silently mean a global
    shutter). Keys that start with ``_`` or are ``comment`` are notes, and stay quiet."""
    sections = [("", data)] + [(k, data[k]) for k in ("camera", "gyro")
                               if isinstance(data.get(k), dict)]
    for name, d in sections:
        unknown = [k for k in d if k not in KNOWN_KEYS[name] and not str(k).startswith("_")
                   and k != "comment"]
        if unknown:
            where = f"{name}." if name else ""
            moved = [f"{k} belongs in {sec}" for k in unknown for sec in ("camera", "gyro")
                     if not name and k in KNOWN_KEYS[sec]]
            warnings.warn(f"{source}: unknown key(s) {', '.join(where + str(k) for k in unknown)} "
                          f"ignored (known: {', '.join(where + k for k in KNOWN_KEYS[name])}"
                          + (f"; {', '.join(moved)}" if moved else "") + ")",
                          GyrodeblurWarning, stacklevel=3)


#: A description's ``fx`` or ``exposure_time`` this many times the photo's EXIF value, or
#: less than its inverse, is warned of (:func:`load_capture`).
EXIF_DISAGREEMENT = 1.5


def _warn_where_exif_disagrees(camera: Camera, exposure_time: float, hints: dict,
                               image_size, origin, *, fx_given: bool,
                               exposure_given: bool) -> None:
    """Warn where the description's focal length or exposure time, given by the user,
    differs from the photo's EXIF value by more than :data:`EXIF_DISAGREEMENT` times:
    intrinsics for another resolution (the blur's length follows ``fx``, and calibrate
    searches it only within about 10 %), a time in milliseconds, another photo's
    description. A mild difference (a crop, a rounded value) passes silently."""
    def ratio(a, b):
        return max(a / b, b / a) if a > 0 and b > 0 else 1.0

    if fx_given and "fx" in hints and image_size is not None:
        exif_fx = hints["fx"] * camera.width / image_size[0]
        r = ratio(camera.fx, exif_fx)
        if r > EXIF_DISAGREEMENT:
            warnings.warn(f"{origin(('fx',))}: camera.fx is {camera.fx:.0f} px, but the "
                          f"photo's EXIF focal length gives {exif_fx:.0f} px at "
                          f"{camera.width} px wide ({r:.2g} times off): intrinsics for "
                          f"another resolution (give camera.width and height with them), "
                          f"or a digitally zoomed or cropped photo? The blur's length "
                          f"follows fx", GyrodeblurWarning, stacklevel=3)
    if exposure_given and "exposure_time" in hints:
        r = ratio(exposure_time, hints["exposure_time"])
        if r > EXIF_DISAGREEMENT:
            warnings.warn(f"{origin(('exposure_time',))}: exposure_time is "
                          f"{exposure_time:.4g} s, but the photo's EXIF ExposureTime is "
                          f"{hints['exposure_time']:.4g} s ({r:.2g} times off): milliseconds "
                          f"for seconds, or another photo's description?",
                          GyrodeblurWarning, stacklevel=3)


def _check_intrinsics(camera: Camera, origin, *, from_exif: bool, size_given: bool) -> None:
    """Refuse intrinsics no pinhole photo has, and warn of unlikely ones: the values enter
    here, as typed by a person or written by another tool (a focal length in mm, a principal
    point as a fraction). ``origin(keys)`` names where the keys came from."""
    w, h = camera.width, camera.height
    side = max(w, h)
    if min(camera.fx, camera.fy) < MIN_FOCAL_PER_SIDE * side:
        what = ("the focal length from the photo's EXIF" if from_exif else
                "is it in mm or 35 mm-equivalent? In pixels it is f_mm x width_px / "
                "sensor_width_mm, or f_35mm x diagonal_px / 43.27")
        raise InputError(origin(("fx", "fy")),
                         f"camera: focal length fx={camera.fx:g}, fy={camera.fy:g} px is under "
                         f"{MIN_FOCAL_PER_SIDE:g} x the image's {side} px side (a view wider "
                         f"than {_WIDEST_VIEW_DEG:.0f} degrees): {what}")
    # a crop's own intrinsics may put the principal point outside it, but not a frame away
    off = max(abs(camera.cx - (w - 1) / 2) / w, abs(camera.cy - (h - 1) / 2) / h)
    if off > 1.0:
        raise InputError(origin(("cx", "cy")),
                         f"camera: principal point ({camera.cx:g}, {camera.cy:g}) px is more "
                         f"than a frame from the centre of the {w}x{h} image: it is in pixels of "
                         "that size, not a fraction of it")
    if off > _FAR_PRINCIPAL_POINT:
        hint = ("; if camera.fx, cx and cy are for another resolution, give camera.width and "
                "camera.height too (they are then scaled to the photo)" if not size_given
                else " (right for a crop's own intrinsics, not for a scaled photo)")
        warnings.warn(f"{origin(('cx', 'cy'))}: the principal point ({camera.cx:g}, "
                      f"{camera.cy:g}) px is far from the centre of the {w}x{h} image{hint}",
                      GyrodeblurWarning, stacklevel=3)


def _log_path(given, base: str, capture_path) -> str:
    """The gyro log named ``given``: a relative path is read from ``base`` (the capture's
    folder, or the working folder for an option); where the log is not found there and the
    capture description's path passes through symbolic links, beside the file it resolves
    to."""
    given = os.path.expanduser(os.fspath(given))
    gpath = os.path.normpath(os.path.join(base, given))
    if capture_path is not None and not os.path.isabs(given) and not os.path.exists(gpath):
        linked = os.path.dirname(os.path.realpath(capture_path))
        beside_target = os.path.normpath(os.path.join(linked, given))
        if os.path.exists(beside_target):
            return beside_target
    return gpath


def _no_repeated_keys(source: str):
    """A ``json.load`` hook refusing a key given twice in one object (the last would win
    silently: ``"readout_time": 0.03, ..., "readout_time": 0`` a global shutter)."""
    def hook(pairs):
        seen = set()
        for k, _ in pairs:
            if k in seen:
                raise InputError(source, f"key {k!r} appears twice in one object")
            seen.add(k)
        return dict(pairs)
    return hook


def _given(d: dict) -> dict:
    """``d`` without the keys whose value is ``null``: null means "not given" everywhere."""
    return {k: v for k, v in d.items() if v is not None}


def _section(data: dict, key: str, source: str) -> dict:
    """``data[key]`` (a JSON object, or absent/null: empty) as a new dict."""
    v = data.get(key)
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise InputError(source, f"{key!r} must be a JSON object, got {v!r}")
    return _given(v)


def check_capture(capture, what: str = "capture") -> "Capture":
    """``capture`` unchanged when it is a :class:`Capture`, else a ``TypeError`` that says
    where one comes from (a capture left out or given as a dict or a path)."""
    if not isinstance(capture, Capture):
        raise TypeError(f"{what} must be a Capture (see gyrodeblur.capture.load_capture), "
                        f"got {type(capture).__name__}")
    return capture


def load_capture(path: str | os.PathLike | None = None, *, overrides: dict | None = None,
                 image_size: tuple[int, int] | None = None,
                 exif_hints: dict | None = None, report=None,
                 logs: dict | None = None, exif_start: bool = True) -> Capture:
    """Build a :class:`Capture` from a JSON file, options and EXIF hints.

    Parameters
    ----------
    path : path-like or None
        The capture JSON (schema in the module docstring). ``None``: everything comes
        from ``overrides``.
    overrides : dict, optional
        Values that replace the JSON's: ``exposure_start``, ``exposure_time``,
        ``readout_time``, ``fx``, ``fy``, ``cx``, ``cy``, ``width``, ``height``,
        ``gyro_path``, ``gyro_format``, ``orientation``, ``time_offset``, ``bias``
        (3 numbers or ``"auto"``), ``max_gap`` and the csv options. ``None`` values are
        ignored.
    image_size : (width, height), optional
        The photo's size; gives the camera size when the JSON gives neither width nor
        height (and with it the principal point, the image centre, when that is missing),
        and the size at which EXIF's ``fx`` is. The capture keeps the JSON's camera size:
        :meth:`Capture.scaled_to` rescales it to the photo (as :func:`deblur` does by
        itself).
    exif_hints : dict, optional
        ``exposure_time`` (s), ``fx`` (pixels at ``image_size``) and the capture time
        (``capture_time_unix``, ``capture_time_text``) read from the photo
        (:func:`gyrodeblur.imageio.exif_capture_hints`), used only where the JSON and the
        options leave the value out: the capture time as ``exposure_start`` only when
        the gyro log runs on Unix time and covers the exposure from it (the capture's
        ``exposure_start_from_exif`` then says so).
    report : callable(str), optional
        Told which values came from EXIF, and the units a log was read in where its
        column names do not say them.
    logs : dict, optional
        Gyro logs already read, by file and reading options: a log found there is shared,
        not read again nor its units told again, and one read is added (several photos'
        captures naming one long log then hold one copy).
    exif_start : bool
        Whether a missing ``exposure_start`` may be the EXIF capture time (``False`` for
        a sharp scene to be blurred: its time says nothing of an exposure).
    """
    data: dict = {}
    base = "."
    src = "capture"
    if path is not None:
        src = os.fspath(path)
        if not src:
            raise InputError("--capture", "an empty file name: give the capture description")
        try:
            with open(src, "rb") as fh:       # bytes: json tells UTF-8, -16 and -32
                data = json.loads(fh.read(), object_pairs_hook=_no_repeated_keys(src))
        except FileNotFoundError:
            raise InputError(src, "capture description not found") from None
        except IsADirectoryError:
            raise InputError(src, "is a folder, not a capture description") from None
        except RecursionError:
            raise InputError(src, "not valid JSON (nested too deeply)") from None
        except json.JSONDecodeError as exc:
            raise InputError(src, f"not valid JSON ({exc.msg}: line {exc.lineno}, column "
                                  f"{exc.colno})") from None
        except UnicodeDecodeError:
            raise InputError(src, "cannot read: not UTF-8 or UTF-16 text (save it as "
                                  "UTF-8)") from None
        except ValueError as exc:           # e.g. an integer of more digits than Python reads
            raise InputError(src, f"not valid JSON ({str(exc).split(';')[0]})") from None
        except OSError as exc:
            raise InputError(src, f"cannot read ({exc})") from None
        if not isinstance(data, dict):
            raise InputError(src, "the capture description must be a JSON object")
        _warn_unknown_keys(data, src)
        data = _given(data)
        base = os.path.dirname(os.path.abspath(src))
    if overrides is not None and not isinstance(overrides, dict):
        raise TypeError(f"overrides must be a dict, got {type(overrides).__name__}")
    ov = {k: v for k, v in (overrides or {}).items() if v is not None}
    unknown = sorted(set(ov) - set(OVERRIDE_KEYS))
    if unknown:
        raise ValueError(f"unknown override(s) {', '.join(unknown)} (known: "
                         f"{', '.join(OVERRIDE_KEYS)})")
    cam_d = _section(data, "camera", src)
    json_cam = set(cam_d)                 # the camera keys the file gives
    gyro_d = _section(data, "gyro", src)
    for k in ("fx", "fy", "cx", "cy", "width", "height"):
        if k in ov:
            cam_d[k] = ov[k]
    for k in ("exposure_start", "exposure_time", "readout_time"):
        if k in ov:
            data[k] = ov[k]
    for k_ov, k in (("gyro_path", "path"), ("gyro_format", "format"),
                    ("orientation", "orientation"), ("time_offset", "time_offset"),
                    ("bias", "bias"), ("max_gap", "max_gap")) + tuple((k, k) for k in CSV_OPTION_KEYS):
        if k_ov in ov:
            gyro_d[k] = ov[k_ov]
            if k_ov == "gyro_path":
                base = os.getcwd()
                if "gyro_format" not in ov:   # the file's format said nothing of another
                    gyro_d.pop("format", None)
    hints = exif_hints or {}
    exposure_given = "exposure_time" in data
    if "exposure_time" not in data and "exposure_time" in hints:
        data["exposure_time"] = hints["exposure_time"]
        if report:
            report(f"exposure_time = {hints['exposure_time']:.6g} s (from EXIF)")
    if image_size is not None and "width" not in cam_d and "height" not in cam_d:
        cam_d["width"], cam_d["height"] = image_size      # one alone would not match
    if "fx" not in cam_d and "fx" in hints and image_size is not None:
        s = _get(cam_d, "width", src) / image_size[0]
        cam_d["fx"] = hints["fx"] * s
        if report:
            report(f"fx = {cam_d['fx']:.1f} px (from EXIF focal length)")
    if "fx" not in cam_d and "fx" not in hints and "focal_length_mm" in hints:
        mm = hints["focal_length_mm"]
        raise InputError(src, f"no focal length in pixels: the photo's EXIF gives FocalLength "
                              f"{mm:g} mm but no FocalLengthIn35mmFilm, nor a "
                              f"FocalPlaneXResolution in a known unit, so the size of its "
                              f"pixels is unknown: give camera.fx or --fx, in pixels: for an "
                              f"uncropped photo {mm:g} mm x its longer side in pixels / the "
                              f"sensor's longer side in mm")
    if "fx" not in cam_d:
        raise InputError(src, "no focal length: give camera.fx (pixels) or --fx" + (
            "" if image_size is None else  # no photo to read (the psf command's capture)
            ", or a photo whose EXIF has FocalLengthIn35mmFilm, or FocalLength with "
            "FocalPlaneXResolution"))
    cam_d.setdefault("fy", cam_d["fx"])
    missing = [k for k in ("width", "height") if k not in cam_d]
    if missing:
        raise InputError(src, f"camera.{' and camera.'.join(missing)} missing")
    size = []
    for k in ("width", "height"):
        try:
            size.append(_whole(cam_d[k]))
        except (TypeError, ValueError, OverflowError):
            raise InputError(src, f"camera.{k} must be a whole number of pixels, got "
                                  f"{cam_d[k]!r}") from None
    width, height = size
    cam_d.setdefault("cx", (width - 1) / 2)
    cam_d.setdefault("cy", (height - 1) / 2)
    intrinsics = [_get(cam_d, k, src) for k in ("fx", "fy", "cx", "cy")]

    def origin(keys) -> str:          # the file, and the options among ``keys`` that set them
        named = ["--" + k.replace("_", "-") for k in keys if k in ov]
        if not named:
            return src
        return f"{src} with {', '.join(named)}" if path is not None else ", ".join(named)

    try:
        camera = Camera(*intrinsics, width, height)
    except InputError as exc:         # source "camera.fx" (one value) or "camera" (fx, fy)
        keys = ("fx", "fy") if exc.source == "camera" else (exc.source.removeprefix("camera."),)
        raise InputError(origin(keys), f"{exc.source}: {exc.problem}") from None
    _check_intrinsics(camera, origin, from_exif=not ({"fx", "fy"} & (json_cam | set(ov))),
                      size_given=bool({"width", "height"} & (json_cam | set(ov))))

    if "path" not in gyro_d:
        raise InputError(src, "missing gyro.path (or --gyro)")
    if not isinstance(gyro_d["path"], (str, os.PathLike)):
        raise InputError(src, f"gyro.path must be a file path (a string), got {gyro_d['path']!r}")
    if not os.fspath(gyro_d["path"]).strip():
        where = "--gyro" if "gyro_path" in ov else f"{src}: gyro.path"
        raise InputError(where, "an empty file name: give the gyro log")
    gpath = _log_path(gyro_d["path"], base, None if "gyro_path" in ov else path)
    fmt = gyro_d.get("format")
    if fmt is not None:                   # named where it was given, not at the log
        fmt = check_format(fmt, origin(("gyro_format",)) if "gyro_format" in ov
                           else f"{src}: gyro.format")
    for key, known in (("time_unit", TIME_UNITS), ("rate_unit", RATE_UNITS)):
        if key in gyro_d and (not isinstance(gyro_d[key], str) or gyro_d[key] not in known):
            where = origin((key,)) if key in ov else f"{src}: gyro.{key}"
            raise InputError(where, f"unknown unit {gyro_d[key]!r} (known: {', '.join(known)})")
    csv_opts = {k: gyro_d[k] for k in CSV_OPTION_KEYS if k in gyro_d}
    rc = csv_opts.get("rate_columns")
    if rc is not None:
        if isinstance(rc, str) or not isinstance(rc, (list, tuple)) or len(rc) != 3:
            raise InputError(src, f"gyro.rate_columns must list three columns, got {rc!r}")
        csv_opts["rate_columns"] = tuple(rc)
    key = (os.path.realpath(gpath), fmt, repr(sorted(csv_opts.items())))
    log = None if logs is None else logs.get(key)
    read_here = log is None     # a log shared by several captures is read, and told of, once
    if read_here:
        log = read_gyro_log(gpath, fmt, **csv_opts)
        if logs is not None:
            logs[key] = log
    if "time_unit_from" in log.meta and report and read_here:
        report(f"gyro log times read in {log.meta['time_unit']} (from "
               f"{log.meta['time_unit_from']}; give --time-unit if that is wrong)")
    if "rate_unit_from" in log.meta and report and read_here:
        report("gyro rates read in rad/s (the column names state no unit; give --rate-unit "
               "deg/s if they are degrees)")
    orientation = gyro_d.get("orientation", "XYZ")
    device = log.meta.get("axes")
    if "orientation" not in gyro_d and log.in_device_axes:
        orientation = "android-back-camera"      # not the camera's axes, as XYZ would say
        app = log.meta.get("app")
        what = ("an Android sensor log" if device == "android device" else
                "a phone app's log" + (f" (its column names are {app}'s)" if app else ""))
        warnings.warn(f"{src}: {what} is in the device's axes (x right, y "
                      f"up, z out of the screen); with no gyro.orientation (--orientation) "
                      f"given, it is read as android-back-camera (yxz: a back camera of "
                      f"SENSOR_ORIENTATION 90, as most phones' and iPhones' "
                      f"(ios-back-camera), its photo in the sensor's layout; "
                      f"android-back-camera-0, -180 or -270 for others; calibrate "
                      f"and deblur --refine try the 8 mappings a phone's own camera can "
                      f"have)", GyrodeblurWarning, stacklevel=2)
    axes = parse_axes(orientation, source=("--orientation" if "orientation" in ov
                                           else f"{src} (gyro.orientation)"))
    offset = _get(gyro_d, "time_offset", src, required=False) or 0.0
    no_start = data.get("exposure_start") is None
    from_exif = exif_start and no_start and "capture_time_text" in hints
    unreadable = dict(hints.get("unreadable", {}))  # (a capture time there is none in hints)
    if not exif_start:
        unreadable.pop("capture_time", None)
    for key, hint, what, give in (
            ("exposure_time", "exposure_time", "a positive number of seconds",
             "exposure_time (s)"),
            ("exposure_start", "capture_time", "a date and time in EXIF's form, YYYY:MM:DD "
             "HH:MM:SS", "exposure_start on the gyro log's clock")):
        said = unreadable.get(hint)
        if data.get(key) is None and said:
            raise InputError(src, f"missing {key!r}: the photo's EXIF {said} is not {what}; "
                                  f"give {give}")
    if no_start and exif_start and exif_hints is not None and not from_exif:
        raise InputError(src, "missing 'exposure_start' (s on the gyro log's clock: when the "
                              "photo's first row started exposing), and the photo has no EXIF "
                              "capture time (DateTimeOriginal) to take it from: give it")
    exposure_time = _get(data, "exposure_time", src)
    _warn_where_exif_disagrees(camera, exposure_time, hints, image_size, origin,
                               fx_given="fx" in (json_cam | set(ov)),
                               exposure_given=exposure_given)
    readout = _get(data, "readout_time", src, required=False)
    direction = _readout_direction(log.meta.get("frame_readout_direction", "0"), gpath)
    if readout is None and "frame_readout_time" in log.meta and direction != 0:
        if report:             # 1: bottom to top, 2 and 3: along the rows
            report(f"the gcsv header's frame_readout_time is not used: its "
                   f"frame_readout_direction {direction} is not top to bottom (turn the photo "
                   f"so that it is, --photo-rotation, and give readout_time)")
    elif readout is None and "frame_readout_time" in log.meta:
        # Gyroflow's gcsv header states it (milliseconds) for the camera that wrote the log
        readout = _get(log.meta, "frame_readout_time", gpath) * 1e-3
        if not 0 <= readout <= MAX_READOUT_TIME:
            raise InputError(gpath, f"the gcsv header's frame_readout_time (ms) must be 0 to "
                                    f"{MAX_READOUT_TIME * 1e3:g}, got "
                                    f"{log.meta['frame_readout_time']}; or give readout_time")
        if report:
            report(f"readout_time = {readout:.6g} s (from the gcsv header's frame_readout_time)")
    if readout and direction != 0:     # given: this model reads rows top to bottom
        warnings.warn(f"{gpath}: the gcsv header's frame_readout_direction is {direction} ("
                      f"{'bottom to top' if direction == 1 else 'along the rows'}), while "
                      "readout_time is applied from the photo's first row down: unless the "
                      f"photo was turned by {'180' if direction == 1 else '90 or 270'} "
                      "degrees so that its rows are read top to bottom (--photo-rotation "
                      "of deblur, calibrate and simulate), its rolling shutter is modelled "
                      "the wrong way",
                      GyrodeblurWarning, stacklevel=2)
    unknown = readout is None
    if unknown and report:
        report("readout_time not given: 0 (a global shutter) unless calibrated (a phone's "
               "rolling shutter reads out in about 10-30 ms: give a guess, or let calibrate or "
               "deblur --refine search for it)")
    readout = 0.0 if readout is None else readout
    to_the_second = from_exif and bool(hints.get("capture_time_whole_second"))
    if from_exif:                # the durations' own checks come later, in Capture
        sane = 0 <= readout <= MAX_READOUT_TIME and exposure_time > 0
        longest = UNKNOWN_READOUT_MAX if unknown else readout     # as calibration searches
        data["exposure_start"] = _exposure_start_from_exif(
            hints, log, offset, longest + exposure_time if sane else 0.0, src, report)
    exposure_start = _get(data, "exposure_start", src)
    bias_spec = gyro_d.get("bias")
    if isinstance(bias_spec, str):
        if bias_spec != "auto":
            raise InputError(src, f"gyro.bias must be 3 numbers or 'auto', got {bias_spec!r}")
        t0 = exposure_start - offset
        bias = estimate_bias_outside(log, axes, t0, t0 + readout + exposure_time, source=gpath)
        if report:
            report("gyro bias (auto, median outside the exposure) = "
                   + ", ".join(f"{b:+.4f}" for b in bias) + " rad/s")
    elif bias_spec is None:
        bias = np.zeros(3)
    else:
        bias = bias_spec
    spec = {k: v for k, v in gyro_d.items() if k not in ("bias",)}
    spec["path"] = os.fspath(gyro_d["path"])
    max_gap = _get(gyro_d, "max_gap", src, required=False)
    try:
        return Capture(exposure_start, exposure_time, readout, camera, log, axes, offset, bias,
                       spec, src, 0.05 if max_gap is None else max_gap, from_exif, unknown,
                       to_the_second)
    except InputError as exc:       # a field an option set: name the option too
        if exc.source != src:
            raise                   # the log's own errors (coverage) name the log
        field = exc.problem.split()[0]          # "readout_time must be ...", "gyro bias ..."
        where = origin(({"gyro": "bias"}.get(field, field),))
        if where == src:
            raise
        raise InputError(where, exc.problem) from None
