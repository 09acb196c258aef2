"""Packed real FFTs agree with scipy's rfft2 definitions: spectra, products, round trips."""

import numpy as np
import pytest
import scipy.fft as sfft

from gyrodeblur.packedfft import pack_spectrum, packed_irfft2, packed_multiply, packed_rfft2

SHAPES = [(6, 8), (7, 8), (6, 9), (7, 9), (1, 8), (2, 3), (5, 1), (6, 1), (48, 50)]


@pytest.mark.parametrize("shape", SHAPES)
def test_packed_spectrum_is_the_packing_of_rfft2(shape):
    a = np.random.default_rng(0).random(shape).astype(np.float32)
    got = packed_rfft2(a)
    ref = pack_spectrum(sfft.rfft2(a.astype(np.float64)), shape[1])
    assert got.shape == shape and got.dtype == np.float32
    np.testing.assert_allclose(got, ref, atol=1e-5 * np.abs(ref).max())
    np.testing.assert_allclose(packed_irfft2(got), a, atol=1e-5)


@pytest.mark.parametrize("shape", SHAPES)
def test_products_are_circular_convolutions(shape):
    rng = np.random.default_rng(1)
    a, b = rng.random((2,) + shape)
    ref = sfft.irfft2(sfft.rfft2(a) * sfft.rfft2(b), s=shape)
    stack = np.stack([a, 2 * a]).astype(np.float32)       # a factor applies to every plane
    spec = packed_rfft2(stack)
    packed_multiply(spec, pack_spectrum(sfft.rfft2(b), shape[1]), out=spec)
    got = packed_irfft2(spec)
    np.testing.assert_allclose(got[0], ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())
    np.testing.assert_allclose(got[1], 2 * ref, rtol=1e-4, atol=2e-4 * np.abs(ref).max())
    # a real, Hermitian-symmetric factor (|B|) multiplies element-wise once spread
    w = np.abs(sfft.rfft2(b))
    ref_w = sfft.irfft2(sfft.rfft2(a) * w, s=shape)
    got_w = packed_irfft2(packed_rfft2(a.astype(np.float32)) * pack_spectrum(w, shape[1], real=True))
    np.testing.assert_allclose(got_w, ref_w, atol=1e-4 * np.abs(ref_w).max())


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="rfft2 half"):
        pack_spectrum(np.zeros((4, 4), complex), 8)
    with pytest.raises(ValueError, match="real-valued"):
        pack_spectrum(np.zeros((4, 5), complex), 8, real=True)
    with pytest.raises(ValueError, match="C-contiguous float32"):
        packed_rfft2(np.zeros((4, 8), np.float32), out=np.zeros((8, 8), np.float32)[::2])
    a = np.ones((2, 8, 8), np.float32)
    for wrong in (np.zeros((4, 16), np.float32), np.zeros((3, 8, 8), np.float32)):
        with pytest.raises(ValueError, match="out has shape"):   # OpenCV would write elsewhere
            packed_rfft2(a, out=wrong)
        with pytest.raises(ValueError, match="out has shape"):
            packed_irfft2(a, out=wrong)
    with pytest.raises(ValueError, match="factor of shape"):
        packed_multiply(a, np.ones((8, 6), np.float32))
    np.testing.assert_array_equal(packed_multiply(a, np.ones((8, 8))).shape, a.shape)
