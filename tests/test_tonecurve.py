"""Tests for gyrodeblur.tonecurve: the IEC 61966-2-1 sRGB curve and the curve lookup."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import gyrodeblur.tonecurve as tc
from gyrodeblur.errors import InputError
from gyrodeblur.tonecurve import (LINEAR, SRGB, TransferCurve, get_transfer_curve,
                                  linear_to_srgb, srgb_to_linear)


def test_round_trips():
    v = np.linspace(0, 1, 100001, dtype=np.float32)
    assert np.abs(linear_to_srgb(srgb_to_linear(v)) - v).max() < 1e-6
    assert np.abs(srgb_to_linear(linear_to_srgb(v)) - v).max() < 1e-6


@pytest.mark.parametrize("encoded, linear", [
    (0.0, 0.0),
    (1.0, 1.0),
    (0.04045, 0.04045 / 12.92),          # end of the linear segment
    (0.5, 0.21404114048223255),
    (0.46135612950044164, 0.18),         # 18 % grey
    (0.2, 0.033104766570885055),
    (0.01, 0.01 / 12.92),
])
def test_known_values(encoded, linear):
    assert float(srgb_to_linear(np.float32(encoded))) == pytest.approx(linear, rel=1e-6, abs=1e-9)
    assert float(linear_to_srgb(np.float32(linear))) == pytest.approx(encoded, rel=1e-6, abs=1e-9)


def test_continuous_and_monotonic_at_the_segment_joint():
    v = np.linspace(0.03, 0.05, 20001)
    lin = srgb_to_linear(v).astype(np.float64)
    assert np.all(np.diff(lin) >= 0)
    assert np.abs(np.diff(lin)).max() < 1e-5     # no jump at 0.04045
    x = np.linspace(0.0025, 0.0035, 20001)
    assert np.abs(np.diff(linear_to_srgb(x).astype(np.float64))).max() < 1e-5


def test_dtype_shape_and_out_of_range_values():
    img = np.random.default_rng(0).random((4, 5, 3))
    for f in (srgb_to_linear, linear_to_srgb):
        out = f(img)
        assert out.dtype == np.float32 and out.shape == img.shape
    # Odd extension below 0; overshoots above 1 survive a round trip.
    assert float(srgb_to_linear(np.float32(-0.5))) == pytest.approx(-float(srgb_to_linear(0.5)))
    assert float(linear_to_srgb(srgb_to_linear(np.float32(1.2)))) == pytest.approx(1.2, rel=1e-6)


def test_curve_lookup():
    assert get_transfer_curve("srgb") is SRGB
    assert get_transfer_curve(" sRGB ") is SRGB
    assert get_transfer_curve("linear") is LINEAR
    assert get_transfer_curve("None") is LINEAR
    assert get_transfer_curve(SRGB) is SRGB
    img = np.array([[0.25, 0.5]], np.float64)
    np.testing.assert_array_equal(LINEAR.decode(img), img.astype(np.float32))
    assert LINEAR.encode(img).dtype == np.float32
    np.testing.assert_array_equal(SRGB.decode(img), srgb_to_linear(img))
    custom = TransferCurve("gamma2", lambda x: np.float32(x) ** 2, np.sqrt)
    assert get_transfer_curve(custom) is custom


def test_unknown_curve_is_an_input_error():
    with pytest.raises(InputError, match=r"--transfer: unknown transfer curve 'rec709'.*srgb"):
        get_transfer_curve("rec709")
    with pytest.raises(InputError, match=r"^photo.tif: unknown"):
        get_transfer_curve("gamma", source="photo.tif")
    with pytest.raises(ValueError):     # InputError is a ValueError
        get_transfer_curve("")


def test_doctests():
    assert doctest.testmod(tc).failed == 0
