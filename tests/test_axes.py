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
])
def test_refuses_non_rotations(spec, why):
    with pytest.raises(InputError, match=why) as e:
        parse_axes(spec, source="cap.json")
    assert "cap.json" in str(e.value)


def test_matrix_accepted():
    m = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
    assert np.array_equal(parse_axes(m), np.asarray(m, float))


def test_named_mappings_are_the_rotations_their_names_say():
    """``android-back-camera``: Android device axes (x right, y up, z out of the screen) to
    the back camera's (x right, y down, z forward): x kept, y and z negated."""
    np.testing.assert_array_equal(parse_axes("android-back-camera") @ [1.0, 2.0, 3.0],
                                  [1.0, -2.0, -3.0])
    np.testing.assert_array_equal(parse_axes("android-back-camera"), parse_axes("Xyz"))
    np.testing.assert_array_equal(parse_axes("identity"), np.eye(3))
