"""Gyroscope logs: parsing, validation and coverage checks.

Every supported format is converted here, once, to one representation: a
:class:`GyroLog` of timestamps in seconds (float64, on the gyro's own clock) and angular
velocity in rad/s along the log's own three axes. Mapping those axes to the camera frame
(x right, y down, z forward) is the job of :mod:`gyrodeblur.axes`; aligning the clocks is
the capture description's ``time_offset``. What a CSV log's columns hold, when the caller
does not say, is worked out by :mod:`gyrodeblur.log_columns`.

Formats
-------
``gcsv``
    Gyroflow's text log (``GYROFLOW IMU LOG`` or ``CAMERA IMU LOG`` first line,
    ``key,value`` header lines, then a ``t,gx,gy,gz[,...]`` column line and integer or
    decimal rows). ``t * tscale`` is seconds and ``g * gscale`` is rad/s. The header's
    ``orientation`` (default ``XYZ``) uses the same letters as the capture's
    ``gyro.orientation``: the i-th letter names the log column (X=gx, Y=gy, Z=gz;
    lowercase = negated) that becomes the i-th axis. It is applied while reading, so a
    ``GyroLog`` from a gcsv file is already in the frame the file's header declares; the
    capture's own ``orientation`` is applied after it. ``frame_readout_time``
    (milliseconds) is kept in :attr:`GyroLog.meta`.
``csv``
    A CSV file with a header: a time column and three rate columns. Column names and
    units are options (:func:`read_csv_log`). Without them the rate columns are those
    whose names say their axis (``x``, ``gx``, ``gyro_x``, ``rotationRateX``, in any
    order: Sensor Logger's ``time,seconds_elapsed,z,y,x``), and units are read from
    suffixes such as ``t_ns`` or ``wx_rad_s`` / ``gx_deg_s``, or brackets (``t (ms)``).
``android``
    Android sensor-event dumps, one event per line, ``type timestamp_ns x y z``; only
    type 4 (``TYPE_GYROSCOPE``, rad/s, device axes) is kept.
``json``
    A JSON list of samples, one object each, as Sensor Logger's JSON export writes them
    (``{"sensor": "Gyroscope", "time": "1733380020401865728", "seconds_elapsed": "0.0",
    "z": ..., "y": ..., "x": ...}``, values as numbers or as text), or one object per line
    (JSON Lines): where the objects name their ``sensor``, only the gyroscope's are kept.
    Their keys are read as a CSV log's column names, by the same rules and options
    (:func:`read_json_log`).
"""

from __future__ import annotations

import csv
import inspect
import json
import os
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from .errors import GyrodeblurWarning, InputError
from .log_columns import (GUESSED_RATE_RANGE, RATE_UNITS, TIME_UNITS, bracketed_unit,
                          default_rate_columns, default_time_column, implausible_time_unit,
                          is_number, looks_like_time, parse_number, phone_app,
                          refuse_signed_names, sensor_time_column, sniff_delimiter,
                          time_unit_from_interval, unit_from_name)

__all__ = [
    "GyroLog",
    "read_gyro_log",
    "read_gcsv",
    "read_csv_log",
    "read_android_events",
    "read_json_log",
    "check_format",
    "write_gcsv",
    "check_coverage",
    "largest_step",
    "step_warning",
    "warn_of_steps",
    "saturation_warning",
    "warn_of_saturation",
    "naming_log",
    "INTERPOLATED_STEP",
    "rate_noise",
    "median_rate",
    "FORMATS",
    "TIME_UNITS",
    "RATE_UNITS",
]

FORMATS = ("gcsv", "csv", "android", "json")
#: How a log's units are given, for the errors that suspect them: the options and capture
#: fields, and column names, which also serve where no option reaches (a benchmark's --gyro)
_SAY_RATE_UNIT = ("(a CSV or JSON log's unit: --rate-unit deg/s, or gyro.rate_unit; a CSV's "
                  "column names can state it: gx_deg_s, gx [deg/s])")
_SAY_TIME_UNIT = ("(a CSV or JSON log's unit: --time-unit, or gyro.time_unit; a CSV's time "
                  "column name can state it: t_us, t [ns])")
#: A median rate above this (rad/s) almost surely means deg/s read as rad/s.
IMPLAUSIBLE_MEDIAN_RATE = 35.0
#: No gyro measures a rate above this (rad/s, about 11500 deg/s, well over the widest
#: ranges of MEMS gyros, +-4000 deg/s): a sample beyond it is corrupt (or in another unit).
MAX_GYRO_RATE = 200.0
#: Latest sample time a log may hold (s, about 136 years): beyond it float64 seconds are
#: coarser than a microsecond, and a photo's exposure is lost to rounding. Unix seconds
#: (1.7e9 now) are below it; microseconds or nanoseconds read as seconds are not.
MAX_TIME = 2.0 ** 32
#: A log's median rate above this (rad/s, 115 deg/s) is a fast pan from start to end: where
#: no unit was stated, deg/s read as rad/s is likelier (a hand-held phone's median is
#: 0.05-0.7 rad/s; the same in deg/s reads as 3-40).
FAST_MEDIAN_RATE = 2.0


@dataclass(frozen=True, eq=False)
class GyroLog:
    """Angular-velocity samples.

    Attributes
    ----------
    t : ndarray, shape (N,), float64
        Sample times in seconds on the gyro clock, strictly increasing.
    omega : ndarray, shape (N, 3), float64
        Angular velocity in rad/s along the log's axes (right-hand rule).
    source : str or None
        The file it came from, for error messages.
    meta : dict
        Extra header values (e.g. gcsv ``frame_readout_time``).

    Notes
    -----
    Equality is identity (its arrays have no single truth value); the instance is
    hashable, so it can key a cache.
    """

    t: np.ndarray
    omega: np.ndarray
    source: str | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if isinstance(self.source, os.PathLike):
            object.__setattr__(self, "source", os.fspath(self.source))
        if self.source is not None and not isinstance(self.source, str):
            raise TypeError(f"GyroLog source must be a file name (str) or None, got "
                            f"{type(self.source).__name__}")
        if not isinstance(self.meta, Mapping):
            raise TypeError(f"GyroLog meta must be a mapping of header values, got "
                            f"{type(self.meta).__name__}")
        object.__setattr__(self, "meta", dict(self.meta))    # the caller's may change
        for name in ("t", "omega"):
            kind = np.asarray(getattr(self, name)).dtype.kind
            if kind not in "iuf":
                raise InputError(self.source, f"gyro {name} must be real numbers, got "
                                              f"dtype {np.asarray(getattr(self, name)).dtype}")
        _refuse_coarse_times(np.asarray(self.t), self.source)
        t = np.array(self.t, dtype=np.float64)         # copies: the caller's arrays may
        w = np.array(self.omega, dtype=np.float64)     # change after validation
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "omega", w)
        _validate(t, w, self.source)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def sample_interval(self) -> float:
        """The median time between samples (s): one over the log's rate, its gaps left
        out (a log has at least two samples)."""
        return float(np.median(np.diff(self.t)))

    @property
    def in_device_axes(self) -> bool:
        """Whether the rates are in a phone's device axes (x right, y up, z out of the
        screen) by the log's own format: an Android sensor dump, or a phone app's CSV
        (``meta["axes"]``, set by the readers)."""
        return self.meta.get("axes") in ("android device", "phone device")

    def rotated(self, matrix: np.ndarray) -> "GyroLog":
        """The same log expressed in another frame: ``omega_new = matrix @ omega``."""
        m = np.asarray(matrix, dtype=np.float64)
        return GyroLog(self.t, self.omega @ m.T, self.source, dict(self.meta))

    def window(self, t0: float, t1: float) -> "GyroLog":
        """Samples with ``t0 <= t <= t1`` (seconds, this log's clock)."""
        keep = (self.t >= t0) & (self.t <= t1)
        return GyroLog(self.t[keep], self.omega[keep], self.source, dict(self.meta))


#: Coarsest rounding of float times of fewer bits than float64, as a fraction of the
#: log's median sample interval.
_COARSEST_TIME_STEP = 0.1


def _refuse_coarse_times(t: np.ndarray, source: str | None) -> None:
    """Refuse float32 (or float16) times rounded to more than a tenth of the log's sample
    interval: Unix times in float32 are kept to 128 s, and samples collapse onto one time
    (times since boot, to 0.12 ms after 20 minutes, are kept)."""
    if t.dtype.kind != "f" or t.dtype.itemsize >= 8 or t.size < 2 or not np.isfinite(t).all():
        return                    # NaN and too few samples are told by _validate
    top = float(np.abs(t).max())
    step = float(np.spacing(t.dtype.type(top)))
    interval = float(np.median(np.diff(t.astype(np.float64))))
    if step > _COARSEST_TIME_STEP * interval or interval <= 0:
        raise InputError(source, f"gyro times are {t.dtype}: at {top:.6g} s they are kept "
                                 f"only to {step:.3g} s; give them as float64")


def _check_increasing(t: np.ndarray, source: str | None, unit: str | None = "s",
                      w: np.ndarray | None = None) -> None:
    """Refuse timestamps ``t`` that do not increase, naming the first sample that does not
    (in ``unit``; ``None``: as the file writes them, its unit still unknown; ``w``: the
    rates, to say whether two samples at one time differ)."""
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        a, b = float(t[i + 1]), float(t[i])

        def said(v: float) -> str:     # all its digits (ns times differ in the last ones,
            if unit == "s":           # as float64 holds them: to 256 ns since 1970)
                return f"{v:.6f} s"
            return f"{int(v)}" if v.is_integer() and abs(v) < 1e19 else repr(v)

        if a == b:
            rates = ("" if w is None else " with the same rates"
                     if np.array_equal(w[i], w[i + 1]) else " with other rates")
            raise InputError(source, f"timestamps are not increasing: sample {i + 2} has the "
                                     f"time of sample {i + 1} ({said(a)}){rates} "
                                     "(two samples at one time: remove one)")
        raise InputError(source, f"timestamps are not increasing: sample {i + 2} "
                                 f"({said(a)}) is earlier than sample {i + 1} ({said(b)}) "
                                 "(sort the log by time)")


def _validate(t: np.ndarray, w: np.ndarray, source: str | None) -> None:
    if t.ndim != 1 or w.shape != (t.size, 3):
        raise InputError(source, f"expected N times and N x 3 rates, got {t.shape} and {w.shape}")
    if t.size < 2:
        raise InputError(source, f"only {t.size} gyro sample(s); at least 2 are needed")
    bad = ~np.isfinite(t) | ~np.all(np.isfinite(w), axis=1)
    if bad.any():
        raise InputError(source, f"NaN or infinite value in gyro sample {int(np.argmax(bad)) + 1}")
    if np.abs(t).max() > MAX_TIME:
        i = int(np.argmax(np.abs(t) > MAX_TIME))
        raise InputError(source, f"gyro sample {i + 1}'s time {float(t[i]):.6g} s is beyond "
                                 f"{MAX_TIME:.3g} s (136 years), where seconds are too coarse "
                                 "for an exposure: microseconds or nanoseconds read as "
                                 f"seconds? {_SAY_TIME_UNIT}")
    _check_increasing(t, source, w=w)
    med = float(np.median(np.linalg.norm(w, axis=1)))
    peak = np.max(np.abs(w), axis=1)
    if med <= IMPLAUSIBLE_MEDIAN_RATE and np.any(peak > MAX_GYRO_RATE):
        i = int(np.argmax(peak > MAX_GYRO_RATE))
        raise InputError(source, f"gyro sample {i + 1} (t = {float(t[i]):.6f} s) has a rate of "
                                 f"{float(peak[i]):.4g} rad/s, beyond any gyro's range "
                                 f"({MAX_GYRO_RATE:g} rad/s): a corrupt sample, or rates in "
                                 f"deg/s read as rad/s? {_SAY_RATE_UNIT}")
    if med > IMPLAUSIBLE_MEDIAN_RATE:
        raise InputError(source, f"median angular rate {med:.1f} rad/s is implausible for a "
                                 "hand-held camera; are the rates in deg/s? "
                                 f"{_SAY_RATE_UNIT}")


#: s: times that differ by less are equal (a 20 Hz log's 0.05 s steps read from text)
_TIME_TOLERANCE = 1e-9

#: s: how far beyond its first or last sample a log still covers a window, for
#: :func:`check_coverage`: a few rounding steps of a Unix time (2.4e-7 s near 1.7e9 s), so
#: that a window computed as ``start + readout + exposure`` ending on the last sample is
#: covered (beyond the log, its last rate is held).
_EDGE_TOLERANCE = 1e-6


def check_coverage(log: GyroLog, t0: float, t1: float, *, max_gap: float = 0.05,
                   what: str = "exposure") -> None:
    """Check that ``log`` covers ``[t0, t1]`` (seconds, the log's clock) without big gaps.

    Raises
    ------
    InputError
        If the first sample is after ``t0``, the last before ``t1``, or two consecutive
        samples that bracket part of the window are more than ``max_gap`` seconds apart
        (a log sampled that coarsely throughout is told so, not said to have a gap).
    """
    src = log.source
    if log.t[0] > t0 + _EDGE_TOLERANCE or log.t[-1] < t1 - _EDGE_TOLERANCE:
        span, clocks = t1 - t0, "time_offset and exposure_start"
        units = (f"the {what} lasts {span:.6g} s: exposure_time and readout_time are seconds, "
                 "not ms")
        if span <= 1.0:                            # a photo's exposure: the clocks
            check = clocks
        elif span <= log.t[-1] - log.t[0]:         # a night exposure, or ms read as s
            check = f"{units}; else {clocks}"
        else:                                      # longer than the whole log
            check = f"the durations: {units}"
        scaled = next((unit for unit, f in (("ms", 1e3), ("us", 1e6), ("ns", 1e9))
                       if log.t[0] <= t0 / f <= log.t[-1]), None)
        far = abs(t0) > 10 * max(abs(log.t[0]), abs(log.t[-1]), 1.0)
        if scaled is not None and far and span <= 1.0:    # a start in ms where s belong?
            check += (f"; if exposure_start is in {scaled}, give it in seconds: read as "
                      f"{scaled} it falls in the log")
        raise InputError(src, f"gyro log covers {_secs(log.t[0])}..{_secs(log.t[-1])} s but the "
                              f"{what} needs {_secs(t0)}..{_secs(t1)} s (check {check})")
    gap, at = largest_step(log, t0, t1)
    if gap > max_gap + _TIME_TOLERANCE:
        limit = (f"(limit {max_gap * 1e3:.0f} ms; gyro.max_gap or --max-gap raises it, at "
                 f"the cost of interpolating across the gap)")
        coarse, said = _long_step(log, gap, at, what)
        if coarse:
            raise InputError(src, f"{said}, too few for the motion within the {what}: log "
                                  f"the gyro at 100 Hz or more {limit}")
        raise InputError(src, f"{said} {limit}")


def _long_step(log: GyroLog, gap: float, at: float, what: str) -> tuple[bool, str]:
    """Whether a long step ``gap`` (s) between samples, the first at ``at`` (s), is the
    log's own rate (no step of it is much shorter) rather than a gap in it, and how to say
    which, for :func:`check_coverage` and :func:`step_warning`."""
    step = log.sample_interval
    if gap <= 1.5 * step:
        return True, (f"the gyro log has a sample only every {step * 1e3:.1f} ms "
                      f"({1 / step:.3g} Hz)")
    return False, f"gap of {gap * 1e3:.1f} ms in the gyro log at {at:.6f} s, inside the {what}"


def largest_step(log: GyroLog, t0: float, t1: float) -> tuple[float, float]:
    """The longest time (s) between two consecutive samples of ``log`` that bracket part
    of ``[t0, t1]`` (the log's clock, s), and the time of the first of them; ``(0.0, t0)``
    where no two samples do."""
    i0 = max(int(np.searchsorted(log.t, t0, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(log.t, t1, side="left")), len(log.t) - 1)
    steps = np.diff(log.t[i0:i1 + 1])
    if not steps.size:
        return 0.0, float(t0)
    j = int(np.argmax(steps))
    return float(steps[j]), float(log.t[i0 + j])


#: s: the longest step between gyro samples inside an exposure that :func:`step_warning`
#: lets pass. Across a longer one the motion is interpolated, and hand shake changes
#: within it: a step of 20-25 ms in the middle of 12 long exposures of the benchmark's
#: real hand-held log (640 px, 21-52 px) cost 2.3 dB on average (worst 5.4), 30-35 ms
#: 5.2 dB; 20 ms 0-0.7 dB on a strong synthetic shake (session 48); the log decimated to
#: 52 Hz (19 ms steps) lost 2.1 dB (BENCHMARKS section 1).
INTERPOLATED_STEP = 0.015


#: What a long step costs a deblurred photo, as :func:`step_warning` says it.
LESS_SHARP = "the result will be less sharp than the log could make it"


def step_warning(log: GyroLog, t0: float, t1: float, *, what: str = "exposure",
                 cost: str = LESS_SHARP) -> str | None:
    """A sentence for the user where the longest step between ``log``'s samples inside
    ``[t0, t1]`` (the log's clock, s) exceeds :data:`INTERPOLATED_STEP`: a dropout, or a
    log sampled that coarsely throughout; ``None`` otherwise. ``cost`` says what the
    interpolation across it costs (default: a deblurred photo's sharpness)."""
    gap, at = largest_step(log, t0, t1)
    if gap <= INTERPOLATED_STEP + _TIME_TOLERANCE:
        return None
    cost = f"the motion between samples is interpolated, and {cost}"
    coarse, said = _long_step(log, gap, at, what)
    return f"{said}: {cost}; log the gyro at 100 Hz or more" if coarse else f"{said}: {cost}"


def warn_of_steps(log: GyroLog, t0: float, t1: float, *, cost: str = LESS_SHARP,
                  stacklevel: int = 2) -> None:
    """A :class:`~gyrodeblur.errors.GyrodeblurWarning`, naming the log, with
    :func:`step_warning`'s sentence where it has one (``stacklevel`` as
    :func:`warnings.warn`'s, counted from the caller)."""
    said = step_warning(log, t0, t1, cost=cost)
    if said is not None:
        warnings.warn(naming_log(log, said), GyrodeblurWarning, stacklevel=stacklevel + 1)


def naming_log(log: GyroLog, sentence: str) -> str:
    """``sentence`` (:func:`step_warning`'s, :func:`saturation_warning`'s) after the
    log's file name, as a warning or a note says it."""
    return f"{log.source or 'gyro log'}: {sentence}"


#: Samples in a row at one rate, the highest the log holds that long on an axis and side,
#: entered or left at a slope that would have carried the rate beyond it, that
#: :func:`saturation_warning` reads as the gyro's range exceeded (a clipped sensor), rather
#: than a peak that happens to repeat a value.
SATURATED_RUN = 3

#: rad/s: a level under this is not read as a clip. No gyro's range is under 125 deg/s
#: (2.2 rad/s, less a bias subtracted by the phone), while a small motion logged in a
#: sensor's rounding steps repeats its top value by chance (a review's steady-hand logs
#: rounded to a 16-bit +-2000 deg/s gyro's steps: 21-43 % of them).
CLIP_MIN_RATE = 1.0


def saturation_warning(log: GyroLog, t0: float, t1: float, *,
                       what: str = "within the exposure") -> str | None:
    """A sentence for the user where ``log``'s rates look clipped in ``[t0, t1]`` (the
    log's clock, s; ``what`` says where that is); ``None`` otherwise.

    A gyro driven past its range reports its largest value, sample after sample, while
    the motion goes on: the PSFs then come out too short, and calibration fits the
    offset and bias to the loss (an audit's log clipped at 0.5 rad/s, a range no gyro has:
    the offset 34 ms off, stated +-2 ms). Read as clipped, per log axis and sign (a gyro
    whose bias is subtracted clips at two levels, ``+R - b`` and ``-R - b``):
    :data:`SATURATED_RUN` samples or more in a row at one rate, the highest that the rate
    holds that long on that side and exceeded by two samples at most (a glitch), where the
    two samples before the run (or after it) extrapolate beyond it by more than 1 % of it
    and 3 of the log's smallest steps between values (up to 5 % of it): a smooth peak of a
    log rounded to a 16-bit sensor's steps, sampled at a kHz, can repeat its top value a
    few times. A level under :data:`CLIP_MIN_RATE` is not a clip (small motion in rounding
    steps); nor is a constant rate, or a step up to one.
    """
    i0 = max(int(np.searchsorted(log.t, t0, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(log.t, t1, side="left")) + 1, len(log.t))
    found = []
    for axis in range(log.omega.shape[1]):
        w = log.omega[:, axis]
        values = np.unique(w)
        quantum = float(np.min(np.diff(values))) if values.size > 1 else 0.0
        for sign in (1.0, -1.0):
            level, longest = _clipped_run(sign * w, i0, i1, quantum)
            if longest:
                found.append(f"axis {'xyz'[axis]} at {sign * level:+.4g} rad/s for {longest} "
                             "samples in a row")
    if not found:
        return None
    return (f"the rates look clipped {what} ({'; '.join(found)}: the highest rate held "
            "that long, entered or left at a slope that would have gone beyond it): the "
            "gyro's range was exceeded, the motion beyond it is lost, and the PSFs come out "
            "too short there (log with a wider gyro range)")


def _clipped_run(v: np.ndarray, i0: int, i1: int, quantum: float) -> tuple[float, int]:
    """:func:`saturation_warning` on one side of one axis (``v``: the rates, signed so
    that the side is positive; ``[i0, i1)`` the samples of the window; ``quantum`` the
    log's smallest step between values): ``(level, the longest clipped run there in
    samples)``, the run 0 where none is."""
    change = np.flatnonzero(np.diff(v) != 0)
    starts = np.concatenate([[0], change + 1])
    ends = np.concatenate([change, [len(v) - 1]])
    held = (ends - starts + 1 >= SATURATED_RUN) & (v[starts] > 0)
    if not held.any():
        return 0.0, 0
    level = float(v[starts[held]].max())
    # the top of that side but for two samples at most (a glitch above a clip), and no less
    # than a gyro's range could be
    if level < CLIP_MIN_RATE or level < np.partition(v, -SATURATED_RUN)[-SATURATED_RUN]:
        return level, 0
    beyond = level + max(min(3 * quantum, 0.05 * level), 0.01 * level)
    longest = 0
    for first, last in zip(starts[held], ends[held]):
        if v[first] != level or last < i0 or first >= i1:
            continue
        entered = first >= 2 and 2 * v[first - 1] - v[first - 2] > beyond
        left = last + 2 < len(v) and 2 * v[last + 1] - v[last + 2] > beyond
        if entered or left:
            longest = max(longest, int(last - first + 1))
    return level, longest


def warn_of_saturation(log: GyroLog, t0: float, t1: float, *, stacklevel: int = 2) -> None:
    """A :class:`~gyrodeblur.errors.GyrodeblurWarning`, naming the log, with
    :func:`saturation_warning`'s sentence where it has one (``stacklevel`` as
    :func:`warnings.warn`'s, counted from the caller)."""
    said = saturation_warning(log, t0, t1)
    if said is not None:
        warnings.warn(naming_log(log, said), GyrodeblurWarning, stacklevel=stacklevel + 1)


def _secs(t: float) -> str:
    """A time for a message: microseconds, or 7 digits for an absurd one (a 1e300 offset)."""
    return f"{t:.6f}" if abs(t) < 1e19 else f"{t:.6g}"


def rate_noise(log: GyroLog) -> float:
    """White-noise level of a log's rates, rad/s per sample (``nan`` under 9 samples).

    The median absolute eighth difference of each axis, scaled to the standard deviation
    of white noise (its eighth difference has variance ``C(16, 8) sigma^2 = 12870
    sigma^2``; median absolute value ``0.6745`` sigma for a Gaussian), then the median over
    the three axes. A difference of order ``k`` passes a rate of frequency ``f`` sampled
    at ``fs`` by ``(2 sin(pi f / fs))^k``, white noise by ``sqrt(C(2k, k))``: hand motion,
    smooth at a gyro's rates, barely enters it. A 10 Hz, 0.5 rad/s shake adds about 4e-7
    rad/s at 200 Hz, and at 50 Hz 0.016 (a fourth difference, as before session 65: 6e-4
    and 0.11, which made a 50 Hz log with 0.003 rad/s of noise read 0.11 and calibration
    keep wrong parameters). A phone gyro logged at 210 Hz measures 0.001 rad/s here, the
    chapter's typical figure is 0.007.
    """
    if len(log.t) < 9:
        return float("nan")
    d8 = np.diff(np.asarray(log.omega, np.float64), n=8, axis=0)
    return float(np.median(np.median(np.abs(d8), axis=0)) / (0.6745 * np.sqrt(12870.0)))


def median_rate(log: GyroLog, *, block: float = 1.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Typical measured rate of a log (rad/s, the log's axes) and its standard error.

    The log is cut into blocks of ``block`` seconds from its first sample; blocks less
    than 80 % as full as the median block (the end of the log, the edges of a gap) are
    dropped. The result is the median of the block means, per axis, and its standard
    error from their spread (median absolute deviation; ``1.2533 * 1.4826 * MAD /
    sqrt(n)``, the Gaussian values). Blocks, not samples: hand motion is correlated over a
    fraction of a second, so the samples themselves would understate the error. The
    median, not the mean: a few seconds of deliberate motion (raising the camera, a short
    pan) move it little. Over a long log of a hand-held camera the true rate averages out
    and what is left is the gyro's bias (see :mod:`gyrodeblur.bias_prior`).

    Returns
    -------
    rate : ndarray (3,)
        rad/s (``nan`` when fewer than two blocks are kept).
    standard_error : ndarray (3,)
        rad/s, likewise.
    seconds : float
        Seconds of log in the blocks kept (``0.0`` when fewer than two).
    """
    t = np.asarray(log.t, np.float64)
    nan = np.full(3, np.nan)
    if t.size < 2:
        return nan, nan.copy(), 0.0
    k = ((t - t[0]) // block).astype(np.int64)
    counts = np.bincount(k)
    full = counts >= 0.8 * np.median(counts[counts > 0])
    if full.sum() < 2:
        return nan, nan.copy(), 0.0
    w = np.asarray(log.omega, np.float64)
    means = np.stack([np.bincount(k, weights=w[:, a], minlength=counts.size)
                      for a in range(3)], axis=1)[full] / counts[full, None]
    med = np.median(means, axis=0)
    mad = np.median(np.abs(means - med), axis=0)
    se = 1.2533 * 1.4826 * mad / np.sqrt(len(means))
    return med, se, float(full.sum() * block)


# ----------------------------------------------------------------------------- readers

def read_gyro_log(path: str | os.PathLike, format: str | None = None, **options) -> GyroLog:
    """Read a gyro log in any supported format.

    Parameters
    ----------
    path : path-like
    format : {"gcsv", "csv", "android", "json"} or None
        ``None`` guesses from the extension (``.gcsv``) or the first line (a list of
        objects, or an object, opens a JSON log).
    **options
        Passed to :func:`read_csv_log` for ``csv`` and to :func:`read_json_log` for
        ``json``.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(path, "is a folder, not a gyro log")
    if not os.path.isfile(path):
        raise InputError(path, "not a regular file (a device or a pipe), not a gyro log"
                         if os.path.exists(path) else "gyro log not found")
    if format is None:
        format = _guess_format(path)
        if format == "android" and (options.get("time_column") is not None
                                    or options.get("rate_columns") is not None):
            format = "csv"      # columns given by number: a table without names, not a dump
    else:
        format = check_format(format)
    unknown = sorted(set(options) - set(_CSV_OPTIONS))
    if unknown:
        raise TypeError(f"unknown option(s) {', '.join(unknown)} "
                        f"(known: {', '.join(_CSV_OPTIONS)})")
    if options and format not in _TABLE_FORMATS:
        verb = "applies" if len(options) == 1 else "apply"
        warnings.warn(f"{path}: {', '.join(sorted(options))} {verb} to CSV and JSON logs "
                      f"only; this log is {format}: ignored", GyrodeblurWarning, stacklevel=2)
    if format == "gcsv":
        return read_gcsv(path)
    if format == "csv":
        return read_csv_log(path, **options)
    if format == "json":
        if options.pop("delimiter", None) is not None:
            warnings.warn(f"{path}: delimiter applies to CSV logs only; this log is json: "
                          "ignored", GyrodeblurWarning, stacklevel=2)
        return read_json_log(path, **options)
    return read_android_events(path)


#: Formats whose columns are found by name (:mod:`gyrodeblur.log_columns`), and which take
#: :func:`read_csv_log`'s options.
_TABLE_FORMATS = ("csv", "json")


def check_format(format, source: str | None = None) -> str:
    """A log format's name (any case) as a key of :data:`FORMATS`, or :class:`InputError`
    naming ``source`` (where the name was given)."""
    key = format.strip().lower() if isinstance(format, str) else None
    if key not in FORMATS:
        raise InputError(source, f"unknown gyro log format {format!r} (known: "
                                 f"{', '.join(FORMATS)})")
    return key


def _guess_format(path: str) -> str:
    if path.lower().endswith(".gcsv"):
        return "gcsv"
    first = [ln for ln in _read_lines(path) if ln.strip() and not ln.lstrip().startswith("#")][:1]
    if first and first[0].strip().upper() in ("GYROFLOW IMU LOG", "CAMERA IMU LOG"):
        return "gcsv"
    if first and re.match(r'\s*(\{\s*("|$)|\[\s*(\{|\]|$))', first[0]):  # not "[t] [ms],x"
        return "json"
    values = first[0].split() if first else []
    if len(values) >= 2 and values[0].isdigit() and all(is_number(v) for v in values):
        return "android"        # "type timestamp_ns values...", whichever sensor comes first
    return "csv"


def _read_lines(path: str) -> list[str]:
    """The lines of a text log (:func:`_read_text`)."""
    return _read_text(path).splitlines()


def _read_text(path: str) -> str:
    """The text of a log: UTF-8 (a byte-order mark dropped), UTF-16 with its byte-order
    mark (as Windows tools save "Unicode text"), else Windows-1252 (a European
    spreadsheet's export, whose ``°/s`` is one byte). Numbers and the names that matter are
    ASCII in all three; a file with NUL bytes and no UTF-16 mark is not text."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            raise InputError(path, "not a text file (a UTF-16 mark, then bytes that are "
                                   "not UTF-16)") from None
    if b"\x00" in raw:
        raise InputError(path, "not a text file (it holds NUL bytes)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


def read_gcsv(path: str | os.PathLike) -> GyroLog:
    """Read a Gyroflow ``.gcsv`` log (see the module docstring for the header)."""
    from .axes import parse_axes

    path = os.fspath(path)
    lines = _read_lines(path)
    if not lines or lines[0].strip().upper() not in ("GYROFLOW IMU LOG", "CAMERA IMU LOG"):
        raise InputError(path, "not a gcsv log (first line must be 'GYROFLOW IMU LOG' or "
                               "'CAMERA IMU LOG')")
    header: dict[str, str] = {}
    start = None
    for i, line in enumerate(lines[1:], start=1):
        parts = [p.strip() for p in line.split(",")]
        if parts[0] == "t":
            start = i
            break
        if len(parts) >= 2:
            if parts[0] in header:         # which one was meant? (as a JSON key given twice)
                raise InputError(path, f"the gcsv header gives {parts[0]} twice (again on "
                                       f"line {i + 1})")
            header[parts[0]] = ",".join(parts[1:])
    if start is None:
        raise InputError(path, "no 't,gx,gy,gz' column line in the gcsv header")
    columns = [c.strip() for c in lines[start].split(",")]
    try:
        gi = [columns.index(c) for c in ("gx", "gy", "gz")]
    except ValueError:
        raise InputError(path, f"gcsv columns {columns} lack gx, gy, gz") from None
    try:
        tscale = float(header.get("tscale", "1"))
        gscale = float(header.get("gscale", "1"))
    except ValueError:
        raise InputError(path, "tscale/gscale are not numbers") from None
    if not (np.isfinite(tscale) and tscale > 0 and np.isfinite(gscale) and gscale > 0):
        raise InputError(path, f"tscale and gscale must be positive numbers, got {tscale!r} "
                               f"and {gscale!r}")
    rows = _parse_numeric_rows(path, lines[start + 1:], [0] + gi, first_line=start + 2,
                               sep=",", names=columns)
    t = rows[:, 0] * tscale
    w = rows[:, 1:] * gscale
    meta = {k: v for k, v in header.items() if k not in ("tscale", "gscale")}
    axes = parse_axes(header.get("orientation", "XYZ"), source=f"{path} (orientation header)")
    _validate(t, w, path)                 # before the rotation: a NaN must not reach it
    return GyroLog(t, w @ axes.T, path, meta)


def _parse_numeric_rows(path: str, lines: list[str], columns: list[int], *, first_line: int,
                        sep: str | None, names: list[str] | None = None) -> np.ndarray:
    """The values of ``columns`` (indices) on each non-blank line, as float64 rows; other
    columns are not read (a logger's date or label column may hold text). ``names`` (the
    header) name a column whose value is not a number."""
    rows = _plain_numeric_rows(lines, columns, sep, names)
    if rows is None:
        rows = _numeric_rows_one_by_one(path, lines, columns, first_line, sep, names)
    return _complete_rows(path, rows)


def _complete_rows(path: str, rows: np.ndarray) -> np.ndarray:
    """``rows`` without those with a missing (NaN) value, which a warning counts, and
    without repeated ones (:func:`_without_repeats`)."""
    missing = np.isnan(rows).any(axis=1)      # (an infinite value is refused, not missing)
    if missing.any():          # phyphox writes NaN, a spreadsheet an empty cell
        rows = rows[~missing]
        if len(rows) == 0:
            raise InputError(path, "no data row holds a time and three rates")
        warnings.warn(f"{path}: {int(missing.sum())} sample(s) with a missing or NaN value "
                      "skipped; an exposure they fall in sees a gap in the log",
                      GyrodeblurWarning, stacklevel=5)
    return _without_repeats(rows)


def _plain_numeric_rows(lines: list[str], columns: list[int], sep: str | None,
                        names: list[str] | None) -> np.ndarray | None:
    """The rows of a log that is numbers only, every line with the header's number of
    values (or at least the columns read, without a header), read by NumPy's parser at
    once (a 10-minute 4 kHz log: 2.4 M lines); ``None`` for anything else (text, empty
    cells, quotes, a decimal comma, a ragged or cut line), which
    :func:`_numeric_rows_one_by_one` reads and, where it must, refuses by line."""
    if sep not in (",", " ", None):     # (a quote, never part of a number, fails the parse)
        return None
    data = [line for line in lines if line.strip()]
    if not data:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")           # NumPy's own warnings: read by line
            table = np.loadtxt(data, dtype=np.float64, delimiter=None if sep == " " else sep,
                               comments=None, ndmin=2)
    except (ValueError, Warning):
        return None
    if table.shape[1] < max(columns) + 1 or (names and table.shape[1] != len(names)):
        return None
    return table[:, columns]


def _numeric_rows_one_by_one(path: str, lines: list[str], columns: list[int],
                             first_line: int, sep: str | None,
                             names: list[str] | None) -> np.ndarray:
    """:func:`_parse_numeric_rows`' rows, line by line (missing values as NaN)."""
    out = []
    need = max(columns) + 1
    last = max((k for k, line in enumerate(lines) if line.strip()), default=-1)
    first = next((k for k, line in enumerate(lines) if line.strip()), -1)
    width = len(lines[first].split()) if sep in (None, " ") and first >= 0 else None
    decimal_comma = sep in (";", "\t", " ")  # a comma that cannot split is a decimal mark
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        parts = _fields(line, sep, path, f"line {first_line + k}")
        try:
            if len(parts) < need:
                raise InputError(path, f"line {first_line + k}: expected {need} values, "
                                       f"got {len(parts)}")
            if width is not None and len(parts) != width:
                raise InputError(path, f"line {first_line + k}: {len(parts)} values where line "
                                       f"{first_line + first} has {width}: split by spaces, a "
                                       "missing value would move the others into its column")
            if names and len(parts) > len(names) and any(v.strip() for v in parts[len(names):]):
                raise InputError(path, f"line {first_line + k}: {len(parts)} values where the "
                                       f"header names {len(names)} columns, so the columns "
                                       f"cannot be told apart (a value holding the delimiter "
                                       f"{sep!r} without quotes?)")
            row = []
            for c in columns:
                if not parts[c].strip().strip('"'):      # an empty cell: a missing value
                    row.append(np.nan)
                    continue
                try:
                    row.append(parse_number(parts[c], decimal_comma=decimal_comma))
                except ValueError:
                    what = f"column {names[c]!r}" if names else f"value {c + 1}"
                    raise InputError(path, f"line {first_line + k}: {what} is not a number "
                                           f"({parts[c].strip()!r})") from None
            out.append(row)
        except InputError:
            if k == last and out:      # a logger stopped in the middle of its last line
                break
            raise
    if not out:
        raise InputError(path, "no data rows")
    return np.asarray(out, dtype=np.float64)


def _fields(line: str, sep: str | None, path: str | None = None,
            where: str = "a line") -> list[str]:
    """The values of one line: split by ``sep`` (runs of whitespace for ``None`` or
    ``" "``), quotes respected (a spreadsheet quotes a text value holding the delimiter);
    a line the CSV reader cannot split (a value over 128 KB) is refused naming ``path``
    and ``where`` it is."""
    if sep is None or sep == " ":
        return line.split()
    if '"' not in line:
        return line.split(sep)
    try:
        return next(csv.reader([line], delimiter=sep))
    except csv.Error as exc:
        raise InputError(path, f"{where} cannot be read as CSV ({exc}): not a CSV gyro "
                               "log?") from None


def _without_repeats(rows: np.ndarray) -> np.ndarray:
    """``rows`` without lines that repeat the line before exactly (some loggers write a
    sample twice; a repeat says nothing new, and its equal timestamp would be refused)."""
    if len(rows) < 2:
        return rows
    keep = np.r_[True, np.any(rows[1:] != rows[:-1], axis=1)]
    return rows if keep.all() else rows[keep]


def read_csv_log(path: str | os.PathLike, *, time_column: str | int | None = None,
                 rate_columns: tuple | None = None, time_unit: str | None = None,
                 rate_unit: str | None = None, delimiter: str | None = None) -> GyroLog:
    """Read a plain CSV gyro log with a header line.

    Parameters
    ----------
    path : path-like
    time_column : str or int, optional
        Name or index of the time column. Default: the first column, unless its name is not
        a time's and a later one's is (an index column first); in a log of several sensors,
        the time column named for the rate columns' sensor
        (:func:`~gyrodeblur.log_columns.sensor_time_column`).
    rate_columns : three names or indices, optional
        Default: the columns whose names say which rate they hold (``x``, ``wx``,
        ``gyro_x``, ``rotationRateX``, ... with or without a unit suffix), in x, y, z order
        whatever their order in the file; else the three columns after the time column,
        taken as x, y, z (refused when a name there says otherwise).
    time_unit : {"s", "ms", "us", "ns"}, optional
        Default: from the column name's suffix (``t_ns`` -> ns) or brackets, else, for a
        column named as times (``time``, ``t``, ``timestamp``), the unit in which the median
        sample interval is that of a 20 Hz to 2.5 kHz gyro (Sensor Logger's ``time`` in ns:
        5e6 at 200 Hz; recorded in ``meta["time_unit_from"]``), else an error.
    rate_unit : {"rad/s", "deg/s"}, optional
        Default: from the rate columns' suffix (``wx_deg_s``, ``gx_dps`` -> deg/s) or
        brackets (``gx [deg/s]``, refused when they state another unit), else rad/s.
    delimiter : str, optional
        Default: of comma, semicolon and tab, the one that splits the header line into the
        most fields; runs of spaces where the header holds none of them (``" "`` says
        so). Leading lines that start with ``#`` are comments, the last of them the
        column names when the first other line holds only numbers (EuRoC's
        ``#timestamp [ns],w_RS_S_x [rad s^-1],...``, ``numpy.savetxt``'s ``# t,wx,wy,wz``);
        numbers may be quoted.

    Examples
    --------
    The shared hand-held log (``t_ns,wx_rad_s,wy_rad_s,wz_rad_s``) needs no option at all;
    explicitly it is ``read_csv_log(p, time_unit="ns", rate_unit="rad/s")``.
    """
    path = os.fspath(path)
    lines = _read_lines(path)
    skip, comment = 0, None       # leading comment lines ("# recorded by ...") and blanks
    while skip < len(lines) and (not lines[skip].strip() or lines[skip].lstrip().startswith("#")):
        if lines[skip].strip():
            comment = lines[skip].lstrip()[1:]
        skip += 1
    lines = lines[skip:]
    if not lines:
        raise InputError(path, "empty file")
    if delimiter is None:
        delimiter = sniff_delimiter(lines[0])
    header = [h.strip() for h in _fields(lines[0], delimiter, path, f"line {skip + 1}")]
    while len(header) > 1 and not header[-1]:     # a trailing delimiter names no column
        header.pop()
    if all(is_number(h) for h in header) and comment is not None:
        # the names on the last comment line ("#timestamp [ns],w_RS_S_x ..." as EuRoC
        # writes, "# t_s,wx,wy,wz" as numpy.savetxt does)
        named = [h.strip() for h in _fields(comment, delimiter, path, "the column names")]
        if len(named) >= len(header) and not any(is_number(h) for h in named):
            header, lines, skip = named, [comment] + lines, skip - 1
    numbered = _numbers_only(header, delimiter)
    if numbered:                       # no column names: the data from this line on
        if time_column is None or rate_columns is None:
            raise InputError(path, "no header line (expected column names such as "
                                   "t_ns,wx,wy,wz; for a log without one, give its time and "
                                   "rate columns by number, from 0: the capture's "
                                   "gyro.time_column and gyro.rate_columns)")
        if header != [str(k) for k in range(len(header))]:   # pandas' names 0, 1, 2, ...
            lines, skip = [""] + lines, skip - 1
        header = [f"column {k}" for k in range(len(header))]
    first_row = _fields(next((ln for ln in lines[1:] if ln.strip()), ""), delimiter, path,
                        f"line {skip + 2}")
    return _log_from_table(path, header, first_row, partial(
        _parse_numeric_rows, path, lines[1:], first_line=skip + 2, sep=delimiter,
        names=header), time_column, rate_columns, time_unit, rate_unit, numbered=numbered)


def _numbers_only(fields: list[str], delimiter: str | None) -> bool:
    """Whether a CSV line's ``fields`` are all numbers (a sample, not column names), with a
    decimal comma where the delimiter allows one (semicolon, tab)."""
    comma = delimiter in (";", "\t")
    try:
        for f in fields:
            parse_number(f, decimal_comma=comma)
    except ValueError:
        return False
    return True


def _log_from_table(path: str, header: list[str], first_row: list[str], read_rows,
                    time_column, rate_columns, time_unit, rate_unit, *,
                    numbered: bool = False) -> GyroLog:
    """A CSV or JSON log's samples, from its column names ``header``, the text of its
    first sample's values ``first_row``, and ``read_rows(columns)``, the float64 values of
    those columns (indices) in every complete sample (:func:`_complete_rows`); the other
    arguments are :func:`read_csv_log`'s. ``numbered``: the file names no columns (its
    ``header`` is ``column 0``, ``column 1``, ...; the caller gave the columns by number)."""
    def col(c, what: str) -> int:
        if isinstance(c, (int, np.integer)) and not isinstance(c, (bool, np.bool_)):
            i = int(c)
        elif isinstance(c, str) and c.isascii() and c.isdigit():
            i = int(c)
        elif isinstance(c, str):
            if c.strip() not in header:   # names are compared as the header's, stripped
                raise InputError(path, f"no column named {c!r} (columns: {', '.join(header)})")
            return header.index(c.strip())
        else:
            raise InputError(path, f"{what} must name a column (its name, or its index from "
                                   f"0), got {c!r}")
        if not 0 <= i < len(header):
            raise InputError(path, f"column {i} does not exist (the log has {len(header)}, "
                                   "counted from 0)")
        return i

    ti = (default_time_column(header, first_row) if time_column is None
          else col(time_column, "time_column"))
    if rate_columns is None:
        ri = default_rate_columns(path, header, ti)
    else:
        if isinstance(rate_columns, str) or len(rate_columns) != 3:
            raise InputError(path, "rate_columns must name exactly three columns")
        ri = [col(c, "rate_columns") for c in rate_columns]
        if len(set(ri)) < 3 or ti in ri:
            raise InputError(path, "rate_columns must be three different columns, other than "
                                   f"the time column; got {', '.join(header[i] for i in ri)} "
                                   f"(time: {header[ti]})")
    if time_column is None:
        ti = sensor_time_column(header, first_row, ri, ti)
    refuse_signed_names(path, header, ri)
    for name, given, known in (("time_unit", time_unit, TIME_UNITS),
                               ("rate_unit", rate_unit, RATE_UNITS)):
        if given is not None and not isinstance(given, str):
            raise InputError(path, f"{name} must be one of {', '.join(known)}, got {given!r}")
    named_tu = unit_from_name(header[ti], TIME_UNITS)
    tu = time_unit or named_tu
    if tu is not None and tu not in TIME_UNITS:
        raise InputError(path, f"unknown time unit {tu!r} (known: s, ms, us, ns)")
    stated_ru = [unit_from_name(header[i], RATE_UNITS) for i in ri]
    if rate_unit is None and len({u for u in stated_ru if u is not None}) > 1:
        raise InputError(path, f"the rate columns {', '.join(header[i] for i in ri)} state "
                               f"different units ({', '.join(str(u) for u in stated_ru)}): "
                               "write them in one unit")
    named_ru = next((u for u in stated_ru if u is not None), None)
    ru = rate_unit or named_ru
    if ru is None and bracketed_unit(header[ri[0]]) is not None:
        raise InputError(path, f"column {header[ri[0]]!r} states a unit that is neither "
                               "rad/s nor deg/s; give it (--rate-unit rad/s|deg/s)")
    if ru is not None and ru not in RATE_UNITS:
        raise InputError(path, f"unknown rate unit {ru!r} (known: rad/s, deg/s)")
    for name, given, stated, column in (("time unit", time_unit, named_tu, header[ti]),
                                        ("rate unit", rate_unit, named_ru, header[ri[0]])):
        if given is not None and stated is not None and given != stated:
            warnings.warn(f"{path}: the {name} given, {given}, overrides the {stated} that "
                          f"column {column!r} states", GyrodeblurWarning, stacklevel=4)
    rows = read_rows([ti] + ri)                                          # time, x, y, z
    meta = {}
    app = phone_app(header, ri)
    if app is not None:
        meta["axes"] = "phone device"
        meta["app"] = app
    if tu is None and not numbered and not looks_like_time(header[ti]):
        raise InputError(path, f"time unit of column {header[ti]!r} unknown, and its name "
                               "does not say it holds times; give the unit (--time-unit "
                               "s|ms|us|ns) or name the column (gyro.time_column)")
    if tu is None:
        if len(rows) < 2:                             # (repeated rows are one sample)
            raise InputError(path, f"only {len(rows)} gyro sample(s); at least 2 are needed")
        _check_increasing(rows[:, 0], path, None, rows[:, 1:])  # before a unit is guessed
        tu, interval = time_unit_from_interval(rows[:, 0])
        if tu is None:
            raise InputError(path, f"time unit of column {header[ti]!r} unknown (its median "
                                   f"sample interval, {interval:.6g}, fits no gyro rate from "
                                   f"{GUESSED_RATE_RANGE[0]:g} Hz to "
                                   f"{GUESSED_RATE_RANGE[1] / 1e3:g} kHz in any unit); "
                                   "give it (--time-unit s|ms|us|ns)")
        meta["time_unit_from"] = f"the median sample interval, {interval:.6g} {tu}"
    else:
        wrong = implausible_time_unit(rows[:, 0], tu)
        if wrong is not None:
            told = "given" if time_unit is not None else "its name states"
            raise InputError(path, f"time column {header[ti]!r} read in {tu}, as {told}: "
                                   f"{wrong}; give the right unit (--time-unit s|ms|us|ns, "
                                   "or gyro.time_unit)")
    if ru is None:
        ru = "rad/s"
        meta["rate_unit_from"] = "assumed: the column names state no unit"
    log = GyroLog(rows[:, 0] * TIME_UNITS[tu], rows[:, 1:] * RATE_UNITS[ru], path,
                  {"time_unit": tu, "rate_unit": ru, **meta})
    if "rate_unit_from" in meta:
        med = float(np.median(np.linalg.norm(log.omega, axis=1)))
        if med > FAST_MEDIAN_RATE:
            warnings.warn(f"{path}: rates read as rad/s (the column names state no unit), "
                          f"and their median over the whole log, {med:.2f} rad/s, is a fast "
                          "pan throughout; if they are deg/s, give --rate-unit deg/s "
                          "(gyro.rate_unit)", GyrodeblurWarning, stacklevel=4)
    return log


#: The options of :func:`read_csv_log`, which :func:`read_gyro_log` passes on.
_CSV_OPTIONS = tuple(inspect.signature(read_csv_log).parameters)[1:]


def read_json_log(path: str | os.PathLike, *, time_column: str | int | None = None,
                  rate_columns: tuple | None = None, time_unit: str | None = None,
                  rate_unit: str | None = None) -> GyroLog:
    """Read a JSON gyro log: a list of samples, one object each, as Sensor Logger's JSON
    export writes them (``[{"sensor": "Gyroscope", "time": "1733380020401865728",
    "seconds_elapsed": "0.0", "z": "0.44", "y": "-0.32", "x": "0.34"}, ...]``), or one
    object per line (JSON Lines).

    Where the samples name their ``sensor``, only the gyroscope's are kept (``Gyroscope``,
    or else the one sensor whose name starts with ``gyro``, such as an uncalibrated
    gyroscope's; samples that name none are left out, with a warning). The keys are the
    columns, in the order they first appear; values may be numbers or numbers written as
    text, and a sample without a value the log is read from is skipped, with a warning.
    Which key holds the time and which the rates, and their units, are worked out from
    the keys as for a CSV log's column names, with the same options
    (:func:`read_csv_log`). Sensor Logger's keys (``time`` in ns since 1970, ``x``, ``y``,
    ``z`` in rad/s, device axes) need none. Messages count the file's objects from 1.
    """
    path = os.fspath(path)
    numbered = list(enumerate(_json_samples(path, _read_text(path)), start=1))
    numbered = _gyroscope_samples(path, numbered)
    header: dict = {}
    for _, r in numbered:
        header.update(dict.fromkeys(r))
    keys = list(header)
    first = numbered[0][1]
    first_row = [_json_text(first.get(k)) for k in keys]

    def read_rows(columns: list[int]) -> np.ndarray:
        return _complete_rows(path, _json_values(path, numbered, [keys[c] for c in columns]))

    log = _log_from_table(path, [str(k).strip() for k in keys], first_row, read_rows,
                          time_column, rate_columns, time_unit, rate_unit)
    log.meta["format"] = "json"
    return log


def _json_samples(path: str, text: str) -> list:
    """The samples of a JSON log's ``text``: its list of objects, or its lines' objects
    (JSON Lines); refused naming ``path`` where it is neither."""
    lines = None
    try:
        samples = json.loads(text)
    except json.JSONDecodeError as exc:
        if not (exc.msg == "Extra data" and text.lstrip().startswith("{")):
            raise InputError(path, f"not a JSON log: {exc.msg} (line {exc.lineno}, column "
                                   f"{exc.colno})") from None
        lines = text.splitlines()                                      # JSON Lines
    except RecursionError:
        raise InputError(path, "not a JSON log: nested too deeply") from None
    if lines is not None:
        samples = []
        for k, line in enumerate(lines, start=1):
            if not line.strip():
                continue
            try:
                samples.append(json.loads(line))
            except json.JSONDecodeError as exc:
                raise InputError(path, f"not a JSON log: {exc.msg} (line {k}, column "
                                       f"{exc.colno})") from None
            except RecursionError:
                raise InputError(path, f"not a JSON log: line {k} nested too deeply") from None
    if isinstance(samples, dict):
        keys = ", ".join(map(str, list(samples)[:6])) + (", ..." if len(samples) > 6 else "")
        raise InputError(path, f"a JSON log must be a list of samples, one object each (as "
                               f"Sensor Logger's JSON export); this file holds one object "
                               f"(keys: {keys or 'none'})")
    if not isinstance(samples, list) or not all(isinstance(r, dict) for r in samples):
        kind = (type(samples).__name__ if not isinstance(samples, list) else "a list of "
                + next(type(r).__name__ for r in samples if not isinstance(r, dict)))
        raise InputError(path, f"a JSON log must be a list of samples, one object each (as "
                               f"Sensor Logger's JSON export); this file holds {kind}")
    if not samples:
        raise InputError(path, "no samples (an empty list)")
    return samples


def _gyroscope_samples(path: str, numbered: list) -> list:
    """The ``(number, sample)`` pairs of a JSON log that are the gyroscope's, where the
    samples name a ``sensor`` (:func:`read_json_log`); all of them where none does."""
    def sensor(r) -> str:                     # "" where the sample names none
        v = r.get("sensor")
        return "" if v is None else str(v).strip()

    as_written = {sensor(r) for _, r in numbered} - {""}
    if not as_written:
        return numbered
    named = {n.lower() for n in as_written}            # "Gyroscope" and "gyroscope" alike
    gyro = [n for n in named if n in ("gyroscope", "gyro")]
    if not gyro:
        gyro = [n for n in named if n.startswith("gyro")]
    if len(gyro) != 1:
        said = ", ".join(sorted(as_written)[:8]) + (", ..." if len(as_written) > 8 else "")
        problem = ("no gyroscope samples" if not gyro
                   else "samples of several gyroscopes, and which to read is not clear")
        raise InputError(path, f"{problem} (the samples' sensors: {said}); export the "
                               "gyroscope's alone")
    unnamed = sum(not sensor(r) for _, r in numbered)
    if unnamed:
        name = min(n for n in as_written if n.lower() == gyro[0])
        warnings.warn(f"{path}: {unnamed} sample(s) name no sensor, where the others do: "
                      f"left out (only the {name} samples are read)",
                      GyrodeblurWarning, stacklevel=4)
    return [(n, r) for n, r in numbered if sensor(r).lower() == gyro[0]]


def _json_values(path: str, numbered: list, keys: list) -> np.ndarray:
    """The values of ``keys`` in each ``(number, sample)`` pair, as float64 rows (NaN where
    missing, null or empty); one that is not a number is refused by its sample's number."""
    out = np.empty((len(numbered), len(keys)))
    for j, k in enumerate(keys):
        values = [r.get(k) for _, r in numbered]
        if not any(isinstance(v, bool) for v in values):
            try:                                  # numbers, or numbers as text: at once
                out[:, j] = np.asarray(values, dtype=np.float64)
                continue
            except (TypeError, ValueError, OverflowError):
                pass                              # (None, "", "0,5", text): one by one
        _json_column_one_by_one(path, numbered, k, out[:, j])
    return out


def _json_column_one_by_one(path: str, numbered: list, k, out: np.ndarray) -> None:
    """:func:`_json_values`' column of key ``k`` into ``out``, sample by sample."""
    for i, (n, r) in enumerate(numbered):
        v = r.get(k)
        if v is None or (isinstance(v, str) and not v.strip()):
            out[i] = np.nan
            continue
        try:
            if isinstance(v, bool) or not isinstance(v, (int, float, str)):
                raise ValueError
            out[i] = parse_number(v) if isinstance(v, str) else float(v)
        except (ValueError, OverflowError):
            raise InputError(path, f"sample {n}: {k!r} is not a number "
                                   f"({_json_text(v)[:40]!r})") from None


def _json_text(value) -> str:
    """A JSON value as its text (a number or a string as written; none empty)."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    return json.dumps(value)


def read_android_events(path: str | os.PathLike) -> GyroLog:
    """Read an Android sensor-event dump (``type timestamp_ns x y z``; gyro = type 4).

    Rates are rad/s in Android device axes (x right, y up, z out of the screen in the
    device's natural orientation); map them with an explicit axis mapping. Lines of other
    sensors (any number of values) and ``#`` comments are skipped.
    """
    path = os.fspath(path)
    lines = _read_lines(path)
    last = max((k for k, line in enumerate(lines, start=1) if line.strip()), default=0)
    rows = []
    for k, line in enumerate(lines, start=1):
        parts = line.split()
        if not parts or parts[0] != "4":      # comments, other sensors (of any length)
            continue
        problem = None
        if len(parts) != 5:
            problem = (f"line {k}: a gyroscope event (type 4) must read "
                       f"'4 timestamp_ns x y z', got {len(parts)} values")
        else:
            try:
                rows.append([float(p) for p in parts[1:]])
            except ValueError:
                problem = f"line {k}: not a number in {line!r}"
        if problem:
            if k == last and rows:     # a logger stopped in the middle of its last line
                break
            raise InputError(path, problem)
    if not rows:
        raise InputError(path, "no gyroscope events (type 4) in the file")
    a = _without_repeats(np.asarray(rows, dtype=np.float64))
    return GyroLog(a[:, 0] * 1e-9, a[:, 1:], path, {"axes": "android device"})


def write_gcsv(path: str | os.PathLike, log: GyroLog, *, tscale: float = 1e-6,
               gscale: float = 1e-6, extra_header: dict | None = None) -> None:
    """Write ``log`` as a Gyroflow gcsv file (integers times ``tscale`` / ``gscale``).

    Time is written relative to nothing (absolute, in ``tscale`` units); the default
    scales give 1 us and 1e-6 rad/s resolution.
    """
    lines = ["GYROFLOW IMU LOG", "version,1.3", "id,gyrodeblur", "orientation,XYZ"]
    for k, v in (extra_header or {}).items():
        lines.append(f"{k},{v}")
    lines += [f"tscale,{tscale!r}", f"gscale,{gscale!r}", "t,gx,gy,gz"]
    ti = np.round(log.t / tscale).astype(np.int64)
    gi = np.round(log.omega / gscale).astype(np.int64)
    lines += [f"{a},{b},{c},{d}" for a, (b, c, d) in zip(ti, gi)]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
