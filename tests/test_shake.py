"""Synthetic hand shake (:mod:`gyrodeblur.shake`): its rates and bands, its seed, short
logs, and its arguments checked."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodeblur.shake import synthetic_hand_shake


def test_rates_are_the_given_rms_in_their_bands():
    sway, tremor, noise = (0.10, 0.12, 0.05), (0.08, 0.06, 0.04), 0.005
    log = synthetic_hand_shake(60.0, 200.0, seed=5, sway_rms=sway, tremor_rms=tremor,
                               sensor_noise=noise)
    assert len(log.t) == 12000 and np.allclose(np.diff(log.t), 1 / 200.0)
    rms = np.sqrt((log.omega ** 2).mean(axis=0))
    expected = np.sqrt(np.square(sway) + np.square(tremor) + noise ** 2)
    np.testing.assert_allclose(rms, expected, rtol=0.03)
    power = np.abs(np.fft.rfft(log.omega, axis=0)) ** 2
    f = np.fft.rfftfreq(len(log.t), 1 / 200.0)
    slow, fast = (f > 0.1) & (f < 4.0), (f > 6.0) & (f < 13.5)
    share_slow = power[slow].sum(axis=0) / power.sum(axis=0)
    share_fast = power[fast].sum(axis=0) / power.sum(axis=0)
    np.testing.assert_allclose(share_slow, np.square(sway) / expected ** 2, atol=0.03)
    np.testing.assert_allclose(share_fast, np.square(tremor) / expected ** 2, atol=0.03)


def test_a_seed_gives_the_same_log_and_another_seed_another():
    a, b = synthetic_hand_shake(1.5, seed=7), synthetic_hand_shake(1.5, seed=7)
    np.testing.assert_array_equal(a.omega, b.omega)
    assert not np.allclose(a.omega, synthetic_hand_shake(1.5, seed=8).omega)
    later = synthetic_hand_shake(1.5, seed=7, t0=12.25)
    np.testing.assert_allclose(later.t, a.t + 12.25)


def test_a_log_of_a_second_or_more_is_its_own_draw_at_any_rate():
    """A log of 1 s or more is drawn over its own length, a rate that is not a whole
    number of Hz included (200.5 Hz, 1 s: 200 samples, drawn as 200, not 201)."""
    from gyrodeblur import shake

    log = shake.synthetic_hand_shake(1.0, 200.5, seed=4, sensor_noise=0.0)
    rng = np.random.default_rng(4)
    n, dt = len(log.t), 1 / 200.5
    assert n == 200
    x = (0.10 * shake._band_noise(rng, n, dt, 0.3, 3.0)
         + 0.08 * shake._band_noise(rng, n, dt, 7.0, 12.0))
    np.testing.assert_allclose(log.omega[:, 0], x, atol=1e-12)


@pytest.mark.parametrize("duration", [0.05, 0.2, 0.5])
def test_a_short_log_is_the_start_of_a_one_second_one_at_hand_rates(duration):
    """The bands are drawn over a second at least: a 0.2 s draw had been scaled up from
    almost nothing to millions of rad/s."""
    short = synthetic_hand_shake(duration, 200.0, seed=3)
    assert len(short.t) == round(duration * 200)
    np.testing.assert_array_equal(short.omega,
                                  synthetic_hand_shake(1.0, 200.0, seed=3).omega[:len(short.t)])
    assert np.abs(short.omega).max() < 1.0


@pytest.mark.parametrize("kwargs,error,words", [
    (dict(duration=-1.0), ValueError, "duration"),
    (dict(duration=0.004), ValueError, "two samples"),
    (dict(rate_hz=0), ValueError, "rate_hz"),
    (dict(rate_hz="200"), TypeError, "rate_hz"),
    (dict(sway_rms=(0.1, 0.1)), ValueError, "sway_rms"),
    (dict(sway_rms=(0.1, True, 0.1)), TypeError, "sway_rms"),
    (dict(sway_rms="abc"), TypeError, "sway_rms"),
    (dict(rate_hz=1e9, duration=2e-9), ValueError, "rate_hz"),
    (dict(rate_hz=1e5, duration=1e300), ValueError, "at most"),
    (dict(tremor_rms=(0.1, -0.1, 0.1)), ValueError, "tremor_rms"),
    (dict(sway_rms=(0.1, float("nan"), 0.1)), ValueError, "sway_rms must be three finite"),
    (dict(seed="a"), TypeError, "seed"),
    (dict(seed=True), TypeError, "seed"),
    (dict(sensor_noise=-0.01), ValueError, "sensor_noise"),
    (dict(t0=float("nan")), ValueError, "t0"),
])
def test_bad_arguments_are_named(kwargs, error, words):
    with pytest.raises(error, match=words):
        synthetic_hand_shake(**kwargs)


def test_the_sample_count_is_rounded_not_truncated():
    """``round(duration * rate_hz)`` samples: 0.29 s at 100 Hz is 28.999999999999996 in
    floating point, and 29 samples, not 28 (nor 1.15 s at 100 Hz 114)."""
    assert len(synthetic_hand_shake(0.29, 100.0, seed=1).t) == 29
    assert len(synthetic_hand_shake(1.15, 100.0, seed=1).t) == 115


def test_the_default_log_has_weak_roll_and_the_stated_sensor_noise():
    """The defaults as the module describes hand shake: roll (about z) weaker than pitch
    and yaw, and white sensor noise of 0.005 rad/s (all that is above the tremor band)."""
    log = synthetic_hand_shake(20.0, 200.0, seed=11)
    rms = np.sqrt((log.omega ** 2).mean(axis=0))
    assert rms[2] < 0.6 * min(rms[0], rms[1]), rms
    spec = np.fft.rfft(log.omega, axis=0)
    f = np.fft.rfftfreq(len(log.t), 1 / 200.0)
    high = np.fft.irfft(np.where((f > 25.0)[:, None], spec, 0), len(log.t), axis=0)
    noise = high.std(axis=0) / np.sqrt(75.0 / 100.0)    # the share of white noise above 25 Hz
    np.testing.assert_allclose(noise, 0.005, rtol=0.1)
