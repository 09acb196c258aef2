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

from .gyrolog import GyroLog

__all__ = ["synthetic_hand_shake"]


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
        Seconds.
    rate_hz : float
        Sampling rate.
    seed : int
    sway_rms, tremor_rms : 3 floats
        RMS angular rate (rad/s) of the slow sway (0.3-3 Hz) and the tremor (7-12 Hz)
        about x, y, z.
    sensor_noise : float
        Std of white measurement noise, rad/s (0.007 is typical of phone gyros).
    t0 : float
        Time of the first sample, seconds.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate_hz))
    dt = 1.0 / rate_hz
    w = np.zeros((n, 3))
    for k in range(3):
        w[:, k] = (sway_rms[k] * _band_noise(rng, n, dt, 0.3, 3.0)
                   + tremor_rms[k] * _band_noise(rng, n, dt, 7.0, 12.0))
    w += rng.normal(0.0, sensor_noise, w.shape)
    return GyroLog(t0 + np.arange(n) * dt, w, "synthetic hand shake", {"seed": seed})
