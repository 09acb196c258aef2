"""A prior on the gyro bias from a long gyro log, for calibration.

A bias barely shows in one exposure (0.03 rad/s over 20 ms lengthens a PSF by half a
pixel at f = 1000 px), yet it moves the deblurred image, which is referenced to the first
row's start: by f b t at a row exposed t later. A long log says more: over seconds, the
rate of a hand-held camera averages out, and a gyro's bias does not. So when the logs hold
:data:`_LOG_MIN_SECONDS` s or more within :data:`_LOG_SPAN` s of the photos, their typical
rate (:func:`gyrodeblur.gyrolog.median_rate`: the median of 1 s block means, which a few
seconds of deliberate motion barely move, with an error bar from their spread; to that, in
quadrature, what the camera's own turning may leave: 0.05 rad over the log's length, at
least :data:`_LOG_FLOOR`) becomes a second Gaussian on the bias, combined with the given
bias's. Each candidate mapping turns it into its own camera frame
(:meth:`BiasPrior.for_mapping`); :mod:`gyrodeblur.calibrate` starts its searches from the
prior's centre, and its "given parameters" carry it. But a given bias is either right (a
calibrated gyro, ``"auto"`` from the same log) or off, and moving a right one by the log's
own error (the hand's mean rate) would only add that error: so the log's rate first
decides, by its likelihood ratio, how likely the given bias is to be off (even odds
before), and the prior is the mixture of "right" and "off" (:func:`bias_from_log`). (On
the benchmark's correct captures with 10 s of the shaken trace either side, centring on
the log always cost 0.6-4 dB on five of the photos that calibration otherwise leaves
alone.) A typical rate more than :data:`_LOG_MAX_RATE` from the given bias on an axis is
a pan, not a bias, and is not used (said in the notes); a slower steady pan is
indistinguishable from a bias and is taken for one. Figures with 10 s of the
(deliberately shaken) source trace on each side of each photo (``--log-seconds 10``, with
and without ``--no-errors``): BENCHMARKS.md section 4.
"""

from __future__ import annotations

import numpy as np

from .gyrolog import GyroLog, median_rate

__all__ = ["BiasPrior", "bias_from_log", "log_typical_rate", "logs_with_captures",
           "PRIOR_BIAS"]

#: sd (rad/s per axis) of the prior on the bias correction when nothing else is known, and
#: of how far a given bias that is off may be off.
PRIOR_BIAS = 0.05
#: The bias from the log's typical rate (see :func:`log_typical_rate`): seconds of log used
#: on each side of the photos' exposures; the shortest log that counts (s); what a
#: hand-held camera's own rate may leave in it, added to the statistical error in
#: quadrature: a net turn of _LOG_TURN rad over the log's seconds, at least _LOG_FLOOR
#: rad/s; and the largest difference from the given bias taken for a bias (rad/s; more is
#: motion).
_LOG_SPAN = 30.0
_LOG_MIN_SECONDS = 8.0
_LOG_TURN = 0.05
_LOG_FLOOR = 0.005
_LOG_MAX_RATE = 0.1


class BiasPrior:
    """Prior mean and sd of the bias correction (rad/s, camera frame) for any candidate
    axis mapping: the given bias, either right or off by up to ~:data:`PRIOR_BIAS` (even
    odds), weighed against the log's typical rate when the log is long enough.

    Parameters
    ----------
    given_bias : array_like, shape (3,)
        The given bias (rad/s, camera frame; the mean over the photos).
    log_rate : tuple of ndarray, optional
        The log's typical rate and its sd (rad/s, log axes); ``None``: no log prior.
    """

    def __init__(self, given_bias, log_rate=None):
        self.given = np.asarray(given_bias, float)
        self.log_rate = log_rate

    @classmethod
    def from_logs(cls, captures, axes: np.ndarray, given_bias) -> tuple["BiasPrior", str | None]:
        """The prior the captures' logs imply (given mapping ``axes``), and a note on it
        (``None`` when the logs are too short to say anything)."""
        given_bias = np.asarray(given_bias, float)
        m_log, se_log, secs_log = log_typical_rate(captures)
        if not secs_log >= _LOG_MIN_SECONDS:
            return cls(given_bias), None
        if np.max(np.abs(m_log - axes.T @ given_bias)) > _LOG_MAX_RATE:
            return cls(given_bias), (
                f"the gyro log's typical rate over {secs_log:.0f} s, {_vec(m_log)} rad/s (log "
                f"axes), is motion, not a bias: the bias is not taken from it")
        floor = max(_LOG_FLOOR, _LOG_TURN / secs_log)
        log_rate = (m_log, np.hypot(se_log, floor))
        off = bias_from_log(axes @ m_log - given_bias, (axes ** 2) @ log_rate[1] ** 2)[2]
        return cls(given_bias, log_rate), (
            f"the gyro log's typical rate over {secs_log:.0f} s: {_vec(m_log)} +- "
            f"{_vec(log_rate[1])} rad/s (log axes), a prior on the bias (the given bias, "
            f"{_vec(given_bias)} rad/s, is off with probability {off:.2f})")

    def for_mapping(self, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and sd (rad/s, camera frame) of the bias correction under mapping ``M``."""
        if self.log_rate is None:
            return np.zeros(3), np.full(3, PRIOR_BIAS)
        return bias_from_log(M @ self.log_rate[0] - self.given,
                             (M ** 2) @ self.log_rate[1] ** 2)[:2]


def bias_from_log(d: np.ndarray, var_log: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The prior on the bias correction from the log: mean, sd (rad/s, camera frame) and
    the probability that the given bias is off.

    ``d``: the log's typical rate minus the given bias, ``var_log`` its variance, per
    axis. A given bias is taken to be either right or off by a Gaussian amount of sd
    :data:`PRIOR_BIAS`, at even odds; ``d`` decides between the two (its likelihood
    ratio, all axes together), and the prior is the moment-matched mixture of "right" (no
    correction) and "off" (the given bias's Gaussian combined with the log's). A log that
    bears the given bias out leaves it where it is, with the log's precision: moving a
    right bias by the log's own error (the hand's mean rate) would only add that error.
    """
    var_off = var_log + PRIOR_BIAS ** 2
    llr = 0.5 * float(np.sum(np.log(var_log / var_off) + d ** 2 / var_log - d ** 2 / var_off))
    p_off = float(1.0 / (1.0 + np.exp(-np.clip(llr, -50.0, 50.0))))
    p_log, p_given = 1.0 / var_log, 1.0 / PRIOR_BIAS ** 2
    mu_off = p_log * d / (p_given + p_log)
    var = 1.0 / (p_given + p_log) + p_off * (1.0 - p_off) * mu_off ** 2
    return p_off * mu_off, np.sqrt(var), p_off


def log_typical_rate(captures) -> tuple[np.ndarray, np.ndarray, float]:
    """Typical rate of the captures' gyro logs (rad/s, log axes), its standard error and
    the seconds it spans (:func:`gyrodeblur.gyrolog.median_rate`): the samples within
    :data:`_LOG_SPAN` s of any photo's exposure, pooled over the photos (one session
    shares one gyro clock; a sample logged twice counts once)."""
    ts, ws = [], []
    for log, caps in logs_with_captures(captures):
        near = np.zeros(len(log.t), bool)
        for c in caps:
            t0, t1 = c.log_window
            near |= (log.t >= t0 - _LOG_SPAN) & (log.t <= t1 + _LOG_SPAN)
        ts.append(log.t[near])
        ws.append(log.omega[near])
    t, first = np.unique(np.concatenate(ts), return_index=True)
    if t.size < 2:
        nan = np.full(3, np.nan)
        return nan, nan.copy(), 0.0
    return median_rate(GyroLog(t, np.concatenate(ws)[first]))


def logs_with_captures(captures):
    """``(log, [captures using it])`` for each distinct gyro log."""
    groups: dict[int, tuple] = {}
    for c in captures:
        groups.setdefault(id(c.log), (c.log, []))[1].append(c)
    return list(groups.values())


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:+.4f}" for x in np.asarray(v, float)) + ")"
