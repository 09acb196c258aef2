"""Synthetic hand-shake gyro traces, for demos and for blur synthesis without a real log.

Hand shake seen by a gyroscope is dominated by two bands (e.g. Gavant et al., "Physiologic
camera shake", and the shared hand-held phone log): a slow sway of the arm below ~3 Hz and
physiological tremor around 8-12 Hz, with roll (about the optical axis) weaker than
pitch and yaw. We draw each axis as the sum of two band-limited Gaussian processes (white
noise filtered in the Fourier domain to those bands), scaled to given RMS rates, plus
white sensor noise. Deterministic for a seed.
"""

from __future__ import annotations

import numpy as np

from .arguments import check_real, check_seed
from .gyrolog import GyroLog

__all__ = ["synthetic_hand_shake"]

#: Shortest stretch (s) the bands are drawn over; a shorter log is its start.
_MIN_DRAWN = 1.0
#: Highest sampling rate (Hz; gyros log at up to a few kHz) and most samples (two
#: hours at 2 kHz; 1.4 GB of rates) a synthetic log may have.
_MAX_RATE_HZ = 100_000.0
_MAX_SAMPLES = 15_000_000


def _band_noise(rng, n: int, dt: float, lo: float, hi: float) -> np.ndarray:
    spec = rng.normal(size=n // 2 + 1) + 1j * rng.normal(size=n // 2 + 1)
    f = np.fft.rfftfreq(n, dt)
    spec *= np.exp(-0.5 * ((f - 0.5 * (lo + hi)) / (0.5 * (hi - lo))) ** 4)
    x = np.fft.irfft(spec, n)
    return x / (x.std() + 1e-12)


def synthetic_hand_shake(duration: float = 2.0, rate_hz: float = 200.0, *, seed: int = 0,
                         sway_rms=(0.10, 0.12, 0.05), tremor_rms=(0.08, 0.08, 0.04),
                         sensor_noise: float = 0.005, t0: float = 0.0) -> GyroLog:
    """A gyro log of hand shake, camera frame (x right, y down, z forward), rad/s.

    Parameters
    ----------
    duration : float
        Seconds, > 0; at least two samples' worth.
    rate_hz : float
        Sampling rate, > 0.
    seed : int, sequence of int, numpy Generator or SeedSequence
    sway_rms, tremor_rms : 3 floats
        RMS angular rate (rad/s, >= 0) of the slow sway (0.3-3 Hz) and the tremor
        (7-12 Hz) about x, y, z.
    sensor_noise : float
        Std of white measurement noise, rad/s, >= 0 (0.007 is typical of phone gyros).
    t0 : float
        Time of the first sample, seconds.

    Returns
    -------
    GyroLog
        ``round(duration * rate_hz)`` samples from ``t0``, every ``1 / rate_hz`` s.

    Raises
    ------
    TypeError, ValueError
        An argument of the wrong kind or out of its range, named.

    Notes
    -----
    The bands are drawn over at least :data:`_MIN_DRAWN` seconds and a shorter log is
    their start: a band of 0.3-3 Hz has no frequency to draw from in a fraction of a
    second (a 0.2 s draw had been scaled up from nearly nothing to absurd rates). Logs
    of :data:`_MIN_DRAWN` s or more are drawn over their own length.
    """
    duration = check_real(duration, "duration")
    rate_hz = check_real(rate_hz, "rate_hz")
    if not 0 < rate_hz <= _MAX_RATE_HZ:
        raise ValueError(f"rate_hz must be > 0 and at most {_MAX_RATE_HZ:g} (samples per "
                         f"second), got {rate_hz!r}")
    if not duration * rate_hz <= _MAX_SAMPLES:
        raise ValueError(f"duration x rate_hz must be at most {_MAX_SAMPLES:g} samples, got "
                         f"{duration!r} s x {rate_hz!r} Hz")
    n = int(round(duration * rate_hz))
    if n < 2:
        raise ValueError(f"duration must hold at least two samples at {rate_hz:g} Hz "
                         f"(>= {1.5 / rate_hz:.3g} s), got {duration!r}")
    check_seed(seed)
    sway, tremor = (_three_rates(v, name) for v, name in ((sway_rms, "sway_rms"),
                                                           (tremor_rms, "tremor_rms")))
    sensor_noise = check_real(sensor_noise, "sensor_noise")
    if sensor_noise < 0:
        raise ValueError(f"sensor_noise must be >= 0 (rad/s), got {sensor_noise!r}")
    t0 = check_real(t0, "t0")
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    drawn = max(n, int(round(_MIN_DRAWN * rate_hz)))   # a longer log: its own length
    w = np.zeros((drawn, 3))
    for k in range(3):
        w[:, k] = (sway[k] * _band_noise(rng, drawn, dt, 0.3, 3.0)
                   + tremor[k] * _band_noise(rng, drawn, dt, 7.0, 12.0))
    w += rng.normal(0.0, sensor_noise, w.shape)
    return GyroLog(t0 + np.arange(n) * dt, w[:n], "synthetic hand shake", {"seed": seed})


def _three_rates(value, name: str) -> np.ndarray:
    """``value`` as three RMS rates (rad/s, finite, >= 0), or an error naming ``name``."""
    not_numbers = (f"{name} must be three numbers (RMS rates, rad/s, about x, y, z), "
                   f"got {value!r}")
    items = list(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    if items is None or any(isinstance(v, (bool, np.bool_, str, bytes)) for v in items):
        raise TypeError(not_numbers)
    try:
        rates = np.asarray(items, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(not_numbers) from None
    if rates.shape != (3,) or not np.all(np.isfinite(rates)):
        raise ValueError(f"{name} must be three finite RMS rates (rad/s, about x, y, z), "
                         f"got {value!r}")
    if np.any(rates < 0):
        raise ValueError(f"{name} must be >= 0 (RMS rates, rad/s), got {value!r}")
    return rates
