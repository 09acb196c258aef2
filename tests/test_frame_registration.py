"""Image motion between photos (:mod:`gyrodeblur.frame_registration`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from gyrodeblur.frame_registration import phase_shift


@pytest.mark.parametrize("d", [(3.4, -2.2), (-7.0, 0.6), (0.0, 0.0)])
def test_phase_shift_finds_a_known_translation(d):
    """``b(x) = a(x - d)``: the shift comes back as ``(dx, dy)`` to a fraction of a pixel,
    with a clear peak."""
    rng = np.random.default_rng(1)
    a = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    b = ndimage.shift(a, (d[1], d[0]), order=3, mode="reflect")
    found, prominence = phase_shift(a, b)
    assert np.allclose(found, d, atol=0.3), found
    assert prominence > 3.0


def test_phase_shift_of_unrelated_images_has_no_clear_peak():
    rng = np.random.default_rng(2)
    a = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    b = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    assert phase_shift(a, b)[1] < 3.0
