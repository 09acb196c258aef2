"""Tests for gyrodeblur.noise.estimate_noise_sigma."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import scipy.ndimage as ndi

import gyrodeblur.noise as noise_mod
from gyrodeblur.noise import estimate_noise_sigma


def _textured(rng, shape):
    """Natural-looking texture in [0.1, 0.9]: several scales plus sharp-edged discs."""
    sig = lambda s: (s, s) + (0,) * (len(shape) - 2)  # noqa: E731
    t = sum(ndi.gaussian_filter(rng.standard_normal(shape), sig(s)) * s for s in (1, 2, 4, 8))
    t = (t - t.min()) / (t.max() - t.min())
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    for _ in range(12):
        y, x, r = rng.integers(0, shape[0]), rng.integers(0, shape[1]), rng.integers(4, 30)
        t[(yy - y) ** 2 + (xx - x) ** 2 < r * r] = rng.uniform()
    return (0.1 + 0.8 * t).astype(np.float32)


@pytest.mark.parametrize("sigma", [0.005, 0.01, 0.02, 0.05])
@pytest.mark.parametrize("channels", [0, 3])
def test_within_20_percent_on_a_textured_image(sigma, channels):
    rng = np.random.default_rng(int(sigma * 1000) + channels)
    shape = (256, 256, channels) if channels else (256, 256)
    img = _textured(rng, shape)
    noisy = img + rng.normal(0, sigma, shape).astype(np.float32)
    est = estimate_noise_sigma(noisy)
    # measured at session 38's code: +0.2 to +4.8 %
    assert est == pytest.approx(sigma, rel=0.08)


def test_sees_8bit_noise_smoothly():
    """On 8-bit data the estimate varies continuously with the noise (no median steps)."""
    rng = np.random.default_rng(1)
    img = ndi.gaussian_filter(_textured(rng, (256, 256)), 2.0)
    ests = []
    for sigma in np.linspace(0.002, 0.004, 5):
        q = np.round(np.clip(img + rng.normal(0, sigma, img.shape), 0, 1) * 255) / 255
        ests.append(estimate_noise_sigma(q))
        # quantisation adds its own 1/sqrt(12) levels
        true = np.hypot(sigma, 1 / 255 / np.sqrt(12))
        assert ests[-1] == pytest.approx(true, rel=0.2)
    assert np.all(np.diff(ests) > 0)


def test_units_follow_the_image_and_flat_is_zero():
    rng = np.random.default_rng(2)
    img = _textured(rng, (128, 128)) + rng.normal(0, 0.01, (128, 128)).astype(np.float32)
    assert estimate_noise_sigma(255 * img) == pytest.approx(255 * estimate_noise_sigma(img),
                                                            rel=1e-4)
    assert estimate_noise_sigma(np.full((32, 32), 0.3, np.float32)) == 0.0


def test_channel_average():
    rng = np.random.default_rng(3)
    img = np.stack([_textured(rng, (128, 128))] * 3, axis=2)
    sig = np.array([0.01, 0.01, 0.04], np.float32)     # mean 0.02; median 0.01, rms 0.0245
    noisy = img + rng.normal(0, 1, img.shape).astype(np.float32) * sig
    assert estimate_noise_sigma(noisy) == pytest.approx(sig.mean(), rel=0.05)


def test_large_images_are_subsampled():
    rng = np.random.default_rng(4)
    img = _textured(rng, (600, 700)) + rng.normal(0, 0.02, (600, 700)).astype(np.float32)
    full = estimate_noise_sigma(img, max_pixels=10 ** 7)
    sub = estimate_noise_sigma(img, max_pixels=60_000)
    assert sub == pytest.approx(full, rel=0.1)
    from gyrodeblur.noise import _subsample
    assert _subsample(img, 60_000).size < 0.3 * img.size        # it did measure less


@pytest.mark.parametrize("bad", [np.zeros(10), np.zeros((4, 40)), np.zeros((2, 8, 8, 3))])
def test_bad_input(bad):
    with pytest.raises(ValueError, match="image of at least 8x8"):
        estimate_noise_sigma(bad)


def test_bad_edge_quantile():
    with pytest.raises(ValueError, match="edge_quantile must be in"):
        estimate_noise_sigma(np.zeros((16, 16)), edge_quantile=0)


def test_doctests():
    assert doctest.testmod(noise_mod).failed == 0


def test_a_jpeg_noise_level_grows_with_the_root_of_its_quantisation_error():
    from gyrodeblur.noise import JPEG_NOISE_SCALE, jpeg_noise_sigma
    ones = [1] * 64                                         # quality 100
    added = np.sqrt(JPEG_NOISE_SCALE * np.sqrt(1 / 12) / 255)
    assert jpeg_noise_sigma(0.0, ones) == pytest.approx(added)
    assert jpeg_noise_sigma(0.003, ones) == pytest.approx(np.hypot(0.003, added))
    # steps four times coarser: twice the level, not four times
    assert jpeg_noise_sigma(0.0, [4] * 64) == pytest.approx(2 * added)
    with pytest.raises(ValueError, match="64 positive quantisation steps"):
        jpeg_noise_sigma(0.001, [1] * 63)


def test_a_photos_noise_level_reads_its_jpeg_tables(tmp_path):
    from PIL import Image
    from gyrodeblur.imageio import read_photo
    from gyrodeblur.noise import coarse_noise_sigma, jpeg_noise_sigma, photo_noise_sigma
    rng = np.random.default_rng(0)
    img = np.clip(0.5 + 0.01 * rng.standard_normal((64, 64, 3)), 0, 1)
    ints = (img * 255).round().astype(np.uint8)
    Image.fromarray(ints).save(tmp_path / "a.png")
    Image.fromarray(ints).save(tmp_path / "a.jpg", quality=80)
    png, jpg = read_photo(tmp_path / "a.png"), read_photo(tmp_path / "a.jpg")
    assert png.quantization is None and photo_noise_sigma(png) == estimate_noise_sigma(png.pixels)
    assert sorted(jpg.quantization) == [0, 1] and len(jpg.quantization[0]) == 64
    measured = max(estimate_noise_sigma(jpg.pixels), coarse_noise_sigma(jpg.pixels))
    assert photo_noise_sigma(jpg) == pytest.approx(
        jpeg_noise_sigma(measured, jpg.quantization[0]))
    assert photo_noise_sigma(jpg) > 1.5 * estimate_noise_sigma(jpg.pixels)


@pytest.mark.parametrize("quality", [75, 85])
def test_a_noisy_jpeg_is_deconvolved_for_the_noise_its_compression_kept(tmp_path, quality):
    """A dark photo brought up by gain (white noise of 10 levels), saved as a JPEG (4:2:0):
    the compression zeroes the fine noise, which the pixels show at full resolution (over
    a dozen seeds 1.4-1.6 levels at quality 75, 4.1-4.8 at 85). At half resolution the
    noise survives; the level is read from there too (6.7-8.5; the fine reading raised
    for the tables alone: 4.3 and 5.2-5.7), in any phase of the 2 x 2 blocks (a photo
    cropped by a pixel or turned)."""
    from PIL import Image
    from gyrodeblur.imageio import read_photo
    from gyrodeblur.noise import coarse_noise_sigma, jpeg_noise_sigma, photo_noise_sigma
    rng = np.random.default_rng(4)
    scene = _textured(rng, (192, 256, 3))
    noisy = np.clip(scene + rng.normal(0, 10 / 255, scene.shape), 0, 1)
    Image.fromarray((noisy * 255).round().astype(np.uint8)).save(
        tmp_path / "n.jpg", quality=quality, subsampling=2)
    jpg = read_photo(tmp_path / "n.jpg")
    fine = estimate_noise_sigma(jpg.pixels)
    assert fine < 0.5 * 10 / 255                       # what the fine mask still sees
    assert jpeg_noise_sigma(fine, jpg.quantization[0]) < 0.6 * 10 / 255
    coarse = coarse_noise_sigma(jpg.pixels)
    assert coarse > 0.6 * 10 / 255
    for moved in (jpg.pixels[1:, 1:], jpg.pixels[:, 1:], jpg.pixels[::-1, ::-1]):
        assert coarse_noise_sigma(moved) == pytest.approx(coarse, rel=0.03)
    assert 0.65 * 10 / 255 < photo_noise_sigma(jpg) < 1.4 * 10 / 255


def test_a_tiny_jpeg_s_noise_level_is_read_at_full_resolution_only(tmp_path):
    """Under 17 px a side the half-resolution reading has too few pixels (it raised)."""
    from PIL import Image
    from gyrodeblur.imageio import read_photo
    from gyrodeblur.noise import coarse_noise_sigma, jpeg_noise_sigma, photo_noise_sigma
    rng = np.random.default_rng(5)
    Image.fromarray(rng.integers(60, 200, (12, 12, 3), dtype=np.uint8)).save(tmp_path / "t.jpg")
    jpg = read_photo(tmp_path / "t.jpg")
    assert photo_noise_sigma(jpg) == pytest.approx(
        jpeg_noise_sigma(estimate_noise_sigma(jpg.pixels), jpg.quantization[0]))
    with pytest.raises(ValueError, match="at least 17x17"):
        coarse_noise_sigma(jpg.pixels)


def test_a_non_finite_or_boolean_image_is_refused():
    """A NaN pixel made the estimate NaN, and a boolean mask was read as 0 and 1, without
    a word (integer images stay welcome: the answer is in their own units)."""
    img = np.full((16, 16), 0.5, np.float32)
    img[3, 3] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        estimate_noise_sigma(img)
    with pytest.raises(ValueError, match="real pixel values, got dtype bool"):
        estimate_noise_sigma(np.zeros((16, 16), bool))
    assert estimate_noise_sigma(np.full((16, 16), 128, np.uint8)) == 0.0


def test_a_barely_noisy_8bit_image_is_not_noiseless():
    """Where most filter responses are exactly 0 (an 8-bit image with a few pixels a level
    off) the median is 0, but the noise is not: the estimate comes from the mean."""
    rng = np.random.default_rng(7)
    img = np.full((64, 64), 128, np.float32)
    img[rng.random(img.shape) < 0.05] += 1
    est = estimate_noise_sigma(img / 255)
    assert 0.02 / 255 < est < 1 / 255


def test_a_photos_noise_level_leaves_its_alpha_out():
    """An RGBA photo's level is its colours' (a constant alpha would pull it down by a
    quarter)."""
    from gyrodeblur.imageio import Photo
    from gyrodeblur.noise import photo_noise_sigma
    rng = np.random.default_rng(8)
    rgb = _textured(rng, (96, 96, 3)) + rng.normal(0, 0.01, (96, 96, 3)).astype(np.float32)
    rgba = np.concatenate([rgb, np.ones((96, 96, 1), np.float32)], axis=2)
    photo = Photo(rgba, 16, "PNG")
    assert photo_noise_sigma(photo) == estimate_noise_sigma(rgb)


@pytest.mark.parametrize("bits", [None, 8])
def test_clipped_highlights_do_not_read_as_noiseless(bits):
    """A photo with blown-out lights: the flat clipped areas carry no noise and are left
    out, so the level is the rest's (a held-out night photo, 12.6 % clipped, had read a
    quarter of its noise); on a clipped page a grey band's or a 40 px patch's noise is
    read, and a page with almost nothing unclipped is measured as a whole."""
    rng = np.random.default_rng(7)
    sigma = 0.02
    img = _textured(rng, (256, 256))
    lit = (img + rng.normal(0, sigma, img.shape)).astype(np.float32)
    lit[:100] = lit[:100] * 3.0                  # a floodlit band, two thirds clipped
    lit[200:, :128] += 0.8                       # a lit wall, mostly clipped
    photo = np.clip(lit, 0.0, 1.0)
    if bits:
        photo = np.round(photo * 255) / 255
        sigma = np.hypot(sigma, 1 / 255 / np.sqrt(12))
    assert np.mean(photo >= 1.0) > 0.25
    assert estimate_noise_sigma(photo) == pytest.approx(sigma, rel=0.2)
    page = np.ones((64, 64), np.float32)                 # a grey band on a clipped page
    page[20:32] = 0.5 + rng.normal(0, 0.02, (12, 64))
    assert estimate_noise_sigma(page) == pytest.approx(0.02, rel=0.2)
    big = np.ones((512, 512), np.float32)                # a 40 px patch on a large page:
    big[200:240, 300:340] = 0.5 + rng.normal(0, 0.02, (40, 40))    # 1444 responses
    assert estimate_noise_sigma(big) == pytest.approx(0.02, rel=0.25)
    page[20:32] = 1.0                                    # nothing left but a thin line:
    page[30:32, 10:50] = 0.2 + rng.normal(0, 0.02, (2, 40))   # measured as a whole
    assert np.isfinite(estimate_noise_sigma(page))
