"""The prior on the gyro bias from a long gyro log (:mod:`gyrodeblur.bias_prior`)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodeblur.axes import parse_axes
from gyrodeblur.bias_prior import PRIOR_BIAS, BiasPrior, bias_from_log, log_typical_rate
from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.gyrolog import GyroLog


def _capture(seconds: float, bias, axes: str, pan=(0.0, 0.0, 0.0), start=None) -> Capture:
    """A capture at the middle of a 200 Hz log (device axes ``axes``) of ``seconds``: a
    hand shake in whole cycles per second, a steady ``pan`` and the gyro's ``bias``
    (rad/s, camera frame)."""
    t = np.arange(0.0, seconds, 1 / 200)
    wc = np.stack([0.5 * np.sin(2 * np.pi * 3 * t + 0.4), 0.7 * np.cos(2 * np.pi * 2 * t + 1.0),
                   0.2 * np.sin(2 * np.pi * 4 * t + 0.7)], 1)
    wc = wc + np.asarray(pan, float) + np.asarray(bias, float)
    log = GyroLog(t, wc @ parse_axes(axes))
    start = seconds / 2 if start is None else start
    return Capture(start, 0.03, 0.03, Camera.centred(640, 480, 600.0), log, axes=axes)


def test_a_long_log_centres_the_prior_on_its_rate_in_each_mappings_frame():
    """20 s of log whose shake averages out: with a zero bias given, the prior's mean is
    the gyro's bias (camera frame) under the log's own mapping, and that rate turned by
    another mapping under that one; its sd is the log's error, far below PRIOR_BIAS."""
    b = np.array([0.03, -0.02, 0.01])
    cap = _capture(20.0, b, "yZx")
    M = parse_axes("yZx")
    prior, note = BiasPrior.from_logs([cap], M, np.zeros(3))
    assert "a prior on the bias" in note and "off with probability 1.00" in note
    mu, sd = prior.for_mapping(M)
    assert np.allclose(mu, b, atol=0.002) and np.all(sd < 0.01)
    other = parse_axes("Xyz")
    mu_other = prior.for_mapping(other)[0]
    assert np.allclose(mu_other, other @ M.T @ b, atol=0.002)
    assert not np.allclose(mu_other, mu, atol=0.01)


def test_a_short_log_gives_no_prior():
    cap = _capture(3.0, (0.03, 0.0, 0.0), "Xyz")
    prior, note = BiasPrior.from_logs([cap], parse_axes("Xyz"), np.zeros(3))
    assert note is None
    mu, sd = prior.for_mapping(parse_axes("Xyz"))
    assert np.all(mu == 0.0) and np.all(sd == PRIOR_BIAS)


def test_a_log_that_pans_is_motion_not_a_bias():
    cap = _capture(20.0, (0.0, 0.0, 0.0), "Xyz", pan=(0.0, 0.3, 0.0))
    prior, note = BiasPrior.from_logs([cap], parse_axes("Xyz"), np.zeros(3))
    assert "is motion, not a bias" in note
    assert np.all(prior.for_mapping(parse_axes("Xyz"))[1] == PRIOR_BIAS)


def test_a_given_bias_the_log_bears_out_stays():
    """The right bias given (large, and in a mapping that is not its own transpose): the
    log's rate, turned into the camera frame the right way, agrees with it, so it is
    neither a pan nor off (probability 0.00), and the prior asks for no correction."""
    b = np.array([0.12, -0.09, 0.0])
    cap = _capture(20.0, b, "yZx")
    M = parse_axes("yZx")
    prior, note = BiasPrior.from_logs([cap], M, b)
    assert "off with probability 0.00" in note, note
    mu, sd = prior.for_mapping(M)
    assert np.all(np.abs(mu) < 1e-3) and np.all(sd < 0.01)


def test_the_log_error_has_a_floor():
    """A log with no hand motion at all has a tiny statistical error; what a hand-held
    camera's own turning may leave (at least 0.005 rad/s) is still added."""
    t = np.arange(0.0, 20.0, 1 / 200)
    log = GyroLog(t, np.tile([0.01, 0.0, -0.01], (t.size, 1)))
    cap = Capture(10.0, 0.03, 0.03, Camera.centred(640, 480, 600.0), log)
    assert np.all(log_typical_rate([cap])[1] < 1e-6)
    prior, _ = BiasPrior.from_logs([cap], np.eye(3), np.zeros(3))
    assert np.all(prior.log_rate[1] >= 0.005)


def test_a_log_given_twice_is_pooled_once():
    """Two photos on one log, or on two equal copies of it: the samples are pooled once,
    so the rate, its error and its span are one photo's (not a doubled span, which would
    shrink the stated error)."""
    cap = _capture(20.0, (0.02, 0.0, 0.0), "Xyz")
    copy = GyroLog(cap.log.t.copy(), cap.log.omega.copy())
    one = log_typical_rate([cap])
    for other in (cap.replace(exposure_start=cap.exposure_start + 1.0),
                  cap.replace(log=copy, exposure_start=cap.exposure_start + 1.0)):
        two = log_typical_rate([cap, other])
        assert two[2] == pytest.approx(one[2]) and one[2] == pytest.approx(20.0, abs=1.0)
        assert np.allclose(one[0], two[0]) and np.allclose(one[1], two[1])


def test_the_log_decides_how_likely_the_given_bias_is_off():
    """A log whose typical rate matches the given bias leaves it (probability off near 0,
    no correction); one 0.04 rad/s away on an axis, 8 of its standard errors, moves it
    nearly all the way (the given bias's +-0.05 combined with the log's +-0.005); in
    between, the correction grows with the distance."""
    var = np.full(3, 0.005 ** 2)
    mu, sd, p_off = bias_from_log(np.zeros(3), var)
    assert p_off < 0.01 and np.all(mu == 0.0) and np.all(sd < 0.006)
    mu, sd, p_off = bias_from_log(np.array([0.04, 0.0, 0.0]), var)
    assert p_off > 0.999
    assert mu[0] == pytest.approx(0.04 * 0.05 ** 2 / (0.05 ** 2 + 0.005 ** 2), rel=1e-3)
    assert mu[1] == mu[2] == 0.0
    steps = [bias_from_log(np.array([x, 0.0, 0.0]), var) for x in (0.005, 0.01, 0.015, 0.02)]
    assert all(a[2] < b[2] and a[0][0] < b[0][0] for a, b in zip(steps, steps[1:]))
    assert np.all(steps[1][1] >= sd)          # the sd covers the doubt between the two


def test_a_given_bias_in_doubt_widens_the_prior_to_cover_both_cases():
    """Where the log leaves the given bias's fate in doubt (probability off near one
    half), the prior is the mixture of "right" (no correction) and "off" (nearly the
    log's rate), moment-matched: its sd must span the distance between the two, far wider
    than either case's own sd (the log's error combined with the given bias's)."""
    var = np.full(3, 0.005 ** 2)
    either = bias_from_log(np.zeros(3), var)[1][0]          # one case's own sd
    mu, sd, p_off = bias_from_log(np.array([0.0185, 0.0, 0.0]), var)
    assert 0.3 < p_off < 0.7, p_off
    mu_off = mu[0] / p_off                                  # the "off" case's centre
    assert sd[0] > 1.5 * either, (sd, either)
    assert sd[0] >= 0.45 * mu_off, (sd, mu_off)             # half the distance at even odds
    assert sd[1] == pytest.approx(either) and sd[2] == pytest.approx(either)


def test_the_log_near_the_photos_is_found_on_the_logs_own_clock():
    """The log's clock is the camera's minus the capture's time offset. A 100 s log whose
    typical rate changes at 45 s, a photo at 20 s of it (camera clock 60 s, offset 40 s):
    the samples within 30 s of the exposure are the log's first 50 s, whose typical rate
    is the first one's. (Read on the camera's clock, the window would hold mostly the
    second rate; with the offset's sign turned, no sample at all.)"""
    t = np.arange(0.0, 100.0, 1 / 200)
    first, second = np.array([0.02, -0.01, 0.0]), np.array([-0.03, 0.04, 0.01])
    w = np.where((t < 45.0)[:, None], first, second)
    w = w + 0.2 * np.sin(2 * np.pi * 3 * t)[:, None]          # a shake in whole cycles
    cap = Capture(60.0, 0.03, 0.03, Camera.centred(640, 480, 600.0), GyroLog(t, w),
                  time_offset=40.0)
    rate, se, secs = log_typical_rate([cap])
    np.testing.assert_allclose(rate, first, atol=1e-3)
    assert secs == pytest.approx(50.0, abs=1.5), secs


def test_photos_far_apart_on_one_log_pool_their_neighbourhoods():
    """The samples within 30 s of either photo count: photos 80 s apart on a 100 s log
    give 80 s of log, not one photo's 40."""
    cap = _capture(100.0, (0.02, 0.0, 0.0), "Xyz", start=10.0)
    assert log_typical_rate([cap])[2] == pytest.approx(40.0, abs=1.0)
    both = log_typical_rate([cap, cap.replace(exposure_start=90.0)])
    assert both[2] == pytest.approx(80.0, abs=1.0)


def test_a_short_log_leaves_its_turn_over_its_length():
    """Over 9 s, a net turn of 0.05 rad is 0.0056 rad/s: more than the 0.005 floor."""
    t = np.arange(0.0, 9.0, 1 / 200)
    log = GyroLog(t, np.tile([0.01, 0.0, -0.01], (t.size, 1)))
    cap = Capture(4.5, 0.03, 0.03, Camera.centred(640, 480, 600.0), log)
    prior, _ = BiasPrior.from_logs([cap], np.eye(3), np.zeros(3))
    np.testing.assert_allclose(prior.log_rate[1], 0.05 / 9, rtol=1e-6)
