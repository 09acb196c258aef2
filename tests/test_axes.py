import numpy as np
import pytest

from gyrodeblur.axes import PROPER_AXIS_LETTERS, axes_to_letters, parse_axes
from gyrodeblur.errors import InputError


def test_letters():
    assert np.array_equal(parse_axes("XYZ"), np.eye(3))
    m = parse_axes("Xyz")
    assert np.array_equal(m @ [1, 2, 3], [1, -2, -3])
    assert np.array_equal(parse_axes("YXz") @ [1, 2, 3], [2, 1, -3])


def test_24_proper_permutations():
    assert len(PROPER_AXIS_LETTERS) == 24
    for s in PROPER_AXIS_LETTERS:
        m = parse_axes(s)
        assert np.isclose(np.linalg.det(m), 1)
        assert axes_to_letters(m) == s


@pytest.mark.parametrize("spec,why", [
    ("YXZ", "reflection"), ("XXZ", "exactly once"), ("XY", "three letters"),
    ([[0, 1, 0], [1, 0, 0], [0, 0, 1]], "determinant"),
    ([[1, 0, 0], [0, 2, 0], [0, 0, 1]], "orthonormal"),
    ([[1, 0, 0], [0, 0.87, -0.5], [0, 0.5, 0.87]], "orthonormal"),   # 30 degrees, rounded
    ([[float("nan"), 0, 0], [0, 1, 0], [0, 0, 1]], "finite"),
])
def test_refuses_non_rotations(spec, why):
    with pytest.raises(InputError, match=why) as e:
        parse_axes(spec, source="cap.json")
    assert "cap.json" in str(e.value)


def test_matrix_accepted():
    m = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
    assert np.array_equal(parse_axes(m), np.asarray(m, float))


@pytest.mark.parametrize("degrees", [0, 90, 180, 270])
def test_named_android_mappings_follow_the_sensor_orientation(degrees):
    """``android-back-camera-<θ>``: Android device axes (x right, y up, z out of the screen,
    natural orientation) to a back camera's sensor-layout frame (x right, y down, z
    forward), for a sensor whose image is shown upright after a clockwise turn of θ. Device
    right, device up and the direction out of the screen, each in the raw sensor image:
    upright, right is (1, 0) and up (0, -1) (image y down); the raw image is the upright
    one turned back (anticlockwise on screen) by θ, which sends image (x, y) to
    (x cos θ + y sin θ, -x sin θ + y cos θ); out of the screen is behind a back camera."""
    m = parse_axes(f"android-back-camera-{degrees}")
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))

    def in_raw(x, y):
        return [x * c + y * s, -x * s + y * c]

    np.testing.assert_allclose(m @ [1.0, 0.0, 0.0], in_raw(1.0, 0.0) + [0.0], atol=1e-12)
    np.testing.assert_allclose(m @ [0.0, 1.0, 0.0], in_raw(0.0, -1.0) + [0.0], atol=1e-12)
    np.testing.assert_allclose(m @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], atol=1e-12)


def test_named_mappings_are_the_rotations_their_names_say():
    """``android-back-camera`` is most phones' sensor orientation, 90 degrees: camera x =
    -device y (the raw image's left is the device's top), camera y = -device x."""
    np.testing.assert_array_equal(parse_axes("android-back-camera") @ [1.0, 2.0, 3.0],
                                  [-2.0, -1.0, -3.0])
    np.testing.assert_array_equal(parse_axes("android-back-camera"),
                                  parse_axes("android-back-camera-90"))
    np.testing.assert_array_equal(parse_axes("android-back-camera-0"), parse_axes("Xyz"))
    np.testing.assert_array_equal(parse_axes("identity"), np.eye(3))


def test_an_iphones_back_camera_from_its_geometry():
    """Core Motion's device axes are Android's (x right, y up, z out of the screen, in
    portrait). An iPhone's sensor image is upright with the phone turned a quarter anticlockwise,
    its bottom on the right (EXIF orientation 1; a portrait photo is tagged 6). Turned so,
    the device's top points to the image's left and its right side up: camera x = -device
    y, camera y (down) = -device x; the back camera looks away from the screen."""
    m = parse_axes("ios-back-camera")
    np.testing.assert_array_equal(m @ [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0])
    np.testing.assert_array_equal(m @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    np.testing.assert_array_equal(m @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0])


def test_a_misspelt_name_is_told_the_names():
    """A spec that is not three letters lists the names accepted as well (a misspelt
    'android_back_camera' was told only of letters); three wrong letters are told of
    letters."""
    with pytest.raises(InputError, match="or a name: identity, android-back-camera-0, "
                                         ".*android-back-camera-270, android-back-camera, "
                                         "ios-back-camera$"):
        parse_axes("android_back_camera")
    with pytest.raises(InputError) as exc:
        parse_axes("XQZ")
    assert exc.value.problem.endswith("must be three letters from X, Y, Z (lowercase = negated)")
