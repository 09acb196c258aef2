"""Tests for gyrodeblur.tonecurve: the IEC 61966-2-1 sRGB curve, the curve lookup, and the
parametric, sampled and per-channel curves colour profiles declare."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import gyrodeblur.tonecurve as tc
from gyrodeblur.errors import InputError
from gyrodeblur.tonecurve import (LINEAR, SRGB, ParametricCurve, PerChannelCurve,
                                  TableCurve, TransferCurve, get_transfer_curve,
                                  linear_to_srgb, matches_curve, srgb_to_linear)


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
    with pytest.raises(InputError, match=r"^transfer: unknown transfer curve 'rec709'.*srgb"):
        get_transfer_curve("rec709")
    with pytest.raises(InputError, match=r"^photo.tif: unknown"):
        get_transfer_curve("gamma", source="photo.tif")
    with pytest.raises(ValueError):     # InputError is a ValueError
        get_transfer_curve("")


def test_a_parametric_curve_with_srgb_s_constants_is_srgb():
    curve = ParametricCurve(2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)
    v = np.linspace(-0.3, 1.4, 20001, dtype=np.float32)      # overshoots included
    assert np.abs(curve.decode(v) - srgb_to_linear(v)).max() < 2e-6
    assert np.abs(curve.encode(srgb_to_linear(v)) - v).max() < 2e-6


def test_a_gamma_keeps_overshoots_with_odd_symmetry():
    curve = ParametricCurve(2.2)
    v = np.float32([-0.5, -0.1, 0.0, 0.3, 1.0, 1.2])
    lin = curve.decode(v)
    np.testing.assert_allclose(lin, np.sign(v) * np.abs(v) ** 2.2, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(curve.encode(lin), v, atol=1e-6)
    assert lin.dtype == np.float32 and curve.decode(np.ones((3, 2, 3))).shape == (3, 2, 3)


def test_a_curve_with_a_black_offset_keeps_its_own_segments():
    """ICC function 4 with f > 0 (black lifted): below 0 the linear segment continues
    rather than mirroring (a mirror would jump at 0)."""
    curve = ParametricCurve(2.0, 1.0, 0.0, 0.05, 0.1, 0.0, 0.005)   # continuous at 0.1
    v = np.float32([-0.1, 0.0, 0.05, 0.5])
    np.testing.assert_allclose(curve.decode(v), [0.0, 0.005, 0.0075, 0.25], atol=1e-6)
    np.testing.assert_allclose(curve.encode(curve.decode(v)), v, atol=1e-6)


def test_invalid_parametric_curves_are_refused():
    for bad in (dict(g=0.0), dict(g=2.2, a=-1.0), dict(g=np.nan), dict(g=2.2, c=-0.1)):
        with pytest.raises(ValueError):
            ParametricCurve(**bad)


def test_a_table_curve_interpolates_and_inverts():
    samples = np.linspace(0, 1, 33) ** 2
    samples[10] = samples[9] - 0.01                      # a dip: made non-decreasing
    curve = TableCurve(samples)
    assert np.all(np.diff(curve.samples) >= 0)
    v = np.linspace(-0.1, 1.1, 1201, dtype=np.float32)
    lin = curve.decode(v)
    assert np.all(np.diff(lin) >= -1e-7)
    np.testing.assert_allclose(curve.decode(np.float32([0.5, 1.0])), [0.25, 1.0], atol=1e-6)
    up = np.diff(lin) > 1e-7
    rises = np.concatenate([[True], up]) & np.concatenate([up, [True]])  # not in the flat
    np.testing.assert_allclose(curve.encode(lin)[rises], v[rises], atol=1e-5)
    flat = (v > 9 / 32 + 1e-3) & (v < 10 / 32 - 1e-3)
    np.testing.assert_allclose(curve.encode(lin[flat]), 10 / 32, atol=1e-6)  # its end
    with pytest.raises(ValueError):
        TableCurve([0.5])


def test_per_channel_curves_and_pickling():
    """Each channel through its own curve; a grey image through the green one. Curves
    pickle (worker processes may receive them)."""
    import pickle
    curve = PerChannelCurve(LINEAR, SRGB, ParametricCurve(2.0).transfer_curve()).transfer_curve()
    v = np.full((1, 1, 3), 0.5, np.float32)
    np.testing.assert_allclose(curve.decode(v)[0, 0], [0.5, srgb_to_linear(np.float32(0.5)), 0.25],
                               rtol=1e-5)
    np.testing.assert_allclose(curve.decode(np.float32([[0.5]])), srgb_to_linear(np.float32([[0.5]])))
    again = pickle.loads(pickle.dumps(curve))
    np.testing.assert_array_equal(again.encode(again.decode(v)), curve.encode(curve.decode(v)))


def test_matching_a_reference_curve():
    table = TableCurve(srgb_to_linear(np.linspace(0, 1, 1024))).transfer_curve()
    assert matches_curve(table, SRGB) and not matches_curve(table, LINEAR)
    assert not matches_curve(ParametricCurve(2.2).transfer_curve(), SRGB)


def test_matching_is_to_a_quarter_level_over_the_whole_range():
    """matches_curve's default tolerance is a quarter of an 8-bit level, shadows included:
    half a level off is another curve, a tenth of one is the same; so is sRGB's power
    segment without its linear toe (it differs below 0.04, by up to 3 levels)."""
    def shifted(levels):
        return TransferCurve("shifted", lambda v: srgb_to_linear(np.asarray(v) + levels / 255),
                             linear_to_srgb)

    assert not matches_curve(shifted(0.5), SRGB)
    assert matches_curve(shifted(0.1), SRGB)
    no_toe = ParametricCurve(2.4, 1 / 1.055, 0.055 / 1.055).transfer_curve()
    assert not matches_curve(no_toe, SRGB)


def test_a_flat_foot_encodes_as_its_end():
    """ICC function 2 (b < 0, black lifted to c) is flat below V = -b/a: linear light at
    or below that black (an undershoot of the deconvolution) encodes as the foot's end, as
    a table curve's flat stretch does, not as 0."""
    from gyrodeblur.icc import parametric_curve
    curve = parametric_curve(2, (2.0, 2.0, -0.5, 0.01))            # flat below V = 0.25
    np.testing.assert_allclose(curve.encode(np.float32([0.0, 0.005, 0.01, 0.26])),
                               [0.25, 0.25, 0.25, 0.5], atol=1e-6)


def test_a_curve_flat_at_black_does_not_mirror_through_zero():
    """ICC function 1 with b < 0 is 0 below V = -b/a: it passes through the origin, but
    flat. Mirrored, light just below 0 encoded as minus the foot's end (-0.25 beside
    +0.25 at 0: speckle in deblurred blacks); it is the foot's end on both sides."""
    from gyrodeblur.icc import parametric_curve
    curve = parametric_curve(1, (2.0, 2.0, -0.5))                   # flat below V = 0.25
    np.testing.assert_allclose(curve.encode(np.float32([-1e-3, -1e-6, 0.0, 1e-6])),
                               [0.25, 0.25, 0.25, 0.2505], atol=1e-4)
    np.testing.assert_allclose(curve.decode(np.float32([-0.1, 0.1, 0.25, 0.75])),
                               [0.0, 0.0, 0.0, 1.0], atol=1e-6)
    # a b of one 16-bit fixed-point step below 0 is a gamma through the origin: mirrored
    near = parametric_curve(1, (2.2, 1.0, -1 / 65536))
    assert near.encode(np.float32([-0.01]))[0] == pytest.approx(-(0.01 ** (1 / 2.2)), abs=1e-3)


def test_a_curve_that_is_not_named_is_an_input_error():
    """None (a capture description's "transfer": null) is not read as "none" (linear)."""
    with pytest.raises(InputError, match=r"^cap.json: a transfer curve is a name .*got None"):
        get_transfer_curve(None, source="cap.json")


def test_doctests():
    assert doctest.testmod(tc).failed == 0
