"""Metrics: PSNR as the chapter defines it, SSIM, the border, and alignment of results."""

import math

import numpy as np
import pytest
from skimage import data, transform
from skimage.registration import phase_cross_correlation

from conftest import SHARED_DATA
from gyrodeblur.metrics import crop_border, default_border, psnr, ssim


def test_psnr_by_hand():
    ref = np.zeros((2, 2))
    est = np.array([[0.1, 0.0], [0.0, 0.0]])
    # ||u - u_hat||^2 = (0.1 * 255)^2 = 650.25 over |Omega| = 4 pixels
    expected = 10 * math.log10(4 * 255 ** 2 / 650.25)           # = 10 log10(400)
    assert psnr(ref, est) == pytest.approx(expected, abs=1e-9)
    assert psnr(ref, est) == pytest.approx(26.0206, abs=1e-4)


def test_psnr_colour_is_the_channel_averaged_mse():
    rng = np.random.default_rng(0)
    ref = rng.random((8, 9, 3))
    est = ref + rng.normal(0, 0.02, ref.shape)
    mse = np.mean([np.mean(((ref[..., c] - est[..., c]) * 255) ** 2) for c in range(3)])
    assert psnr(ref, est) == pytest.approx(10 * math.log10(255 ** 2 / mse), abs=1e-9)


def test_psnr_identical_is_infinite_and_symmetric():
    a = np.random.default_rng(1).random((5, 5))
    assert psnr(a, a) == float("inf")
    b = a + 0.01
    assert psnr(a, b) == pytest.approx(psnr(b, a))
    assert psnr(a, b) == pytest.approx(10 * math.log10(1 / 0.01 ** 2))     # 40 dB


def test_ssim_identical_is_one_and_drops_with_noise():
    img = transform.resize(data.camera(), (64, 64), anti_aliasing=True)
    assert ssim(img, img) == pytest.approx(1.0)
    rgb = transform.resize(data.astronaut(), (64, 64), anti_aliasing=True)
    assert ssim(rgb, rgb) == pytest.approx(1.0)
    noisy = rgb + np.random.default_rng(0).normal(0, 0.05, rgb.shape)
    s = ssim(rgb, noisy)
    assert 0 < s < 0.95
    per_channel = np.mean([ssim(rgb[..., c], noisy[..., c]) for c in range(3)])
    assert s == pytest.approx(per_channel)
    # scikit-image's, Gaussian-weighted as Wang et al. (sigma 1.5, population covariance)
    from skimage.metrics import structural_similarity

    grey_noisy = np.clip(img + np.random.default_rng(1).normal(0, 0.05, img.shape), 0, 1)
    assert ssim(img, grey_noisy) == pytest.approx(structural_similarity(
        img, grey_noisy, data_range=1.0, gaussian_weights=True, sigma=1.5,
        use_sample_covariance=False), abs=1e-12)


def test_border_is_left_out():
    rng = np.random.default_rng(2)
    ref = rng.random((40, 50, 3))
    est = ref.copy()
    est[:4] = 0.0                 # damage only a 4-px band along the top
    est[:, -3:] = 1.0             # and a 3-px band on the right
    assert psnr(ref, est) < 30
    assert psnr(ref, est, border=4) == float("inf")
    assert ssim(ref, est, border=4) == pytest.approx(1.0)
    assert psnr(ref, est, border=3) < 30                # the top band is 4 px deep
    assert crop_border(ref, 4).shape == (32, 42, 3)
    assert crop_border(ref, 0) is ref
    with pytest.raises(ValueError):
        crop_border(ref, 20)
    with pytest.raises(ValueError, match="border must be a whole number of pixels >= 0"):
        crop_border(ref, -2)


def test_default_border():
    assert default_border((680, 1024, 3)) == 34             # 5 % of the smaller side
    assert default_border((100, 100)) == 5
    assert default_border((680, 1024), psf_radius=17) == 17


def _shift(ref, img, border):
    def luma(a):
        return crop_border(a.mean(axis=2) if a.ndim == 3 else a, border)
    return np.asarray(phase_cross_correlation(luma(ref), luma(img), upsample_factor=20)[0])


def _assert_aligned(sharp, blurred, capture):
    from gyrodeblur.deblur import deblur

    border = default_border(sharp.shape)
    restored = deblur(blurred, capture)
    s_blur = _shift(sharp, blurred, border)
    s_rest = _shift(sharp, restored, border)
    assert np.hypot(*s_rest) < 0.5, f"deblurred result is offset by {s_rest} px"
    return s_blur, s_rest


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_deblurred_dataset_case_aligns_with_the_sharp_photo():
    """Results are referenced to the orientation at exposure start, so they align with
    the sharp photo without registration, while the blurred photo is offset."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")
    from gyrodeblur.dataset import build_cases

    cases = build_cases(max_photos=1, windows_per_photo=2, max_size=320, seed=0)
    offsets = []
    for c in cases:
        s_blur, _ = _assert_aligned(c.sharp, c.blurred, c.capture)
        offsets.append(np.hypot(*s_blur))
    assert max(offsets) > 2.0, f"blurred offsets {offsets}: the test needs real motion"


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_deblurred_demo_aligns_with_the_sharp_photo():
    """The same property without shared data: the bundled demo capture."""
    from gyrodeblur.demo import demo_capture
    from gyrodeblur.simulate import quantize_8bit, simulate_blur
    from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

    sharp = transform.resize(data.astronaut(), (256, 256), anti_aliasing=True).astype(np.float32)
    sharp = quantize_8bit(sharp)
    cap = demo_capture().scaled_to(256, 256)
    blurred = quantize_8bit(linear_to_srgb(simulate_blur(srgb_to_linear(sharp), cap,
                                                         snr_db=40, seed=0, transfer="linear")))
    s_blur, _ = _assert_aligned(sharp, blurred, cap)
    assert np.hypot(*s_blur) > 1.0
