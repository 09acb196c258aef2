"""A kernel's spectral evidence against no blur (:mod:`gyrodeblur.blur_evidence`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from skimage import data
from skimage.transform import resize

from gyrodeblur.blur_evidence import (NO_BLUR_MARGIN, SPARSER_MAX, WRONG_BLUR_MARGIN,
                                     capture_gain_over_no_blur, kernel_gain_over_no_blur,
                                     kernel_sparsity_ratio)


def _scene() -> np.ndarray:
    """A textured grey photo, 384 x 512, linear values in [0.05, 0.95]."""
    img = data.astronaut().mean(axis=2) / 255
    return (0.05 + 0.9 * resize(img, (384, 512), anti_aliasing=True)).astype(np.float32)


def _streak(length: int, vertical: bool = False) -> np.ndarray:
    k = np.zeros((length, length), np.float32)
    k[length // 2, :] = 1 / length
    return k.T.copy() if vertical else k


def _moved_along_x(img: np.ndarray, length: int) -> np.ndarray:
    """The forward model kept apart from the kernels judged: the scene shifted by cubic
    interpolation to 4 positions per pixel along ``length`` px of x, and averaged."""
    shifts = np.linspace(-(length - 1) / 2, (length - 1) / 2, 4 * (length - 1) + 1)
    out = np.mean([ndimage.shift(img, (0, s), order=3, mode="mirror") for s in shifts], axis=0)
    rng = np.random.default_rng(0)
    return np.clip(out + 0.003 * rng.normal(size=out.shape), 0, 1).astype(np.float32)


def test_the_blur_a_photo_shows_is_told_from_a_wrong_one_and_from_none():
    sharp = _scene()
    blurred = _moved_along_x(sharp, 9)
    gain = {name: kernel_gain_over_no_blur(blurred, k, transfer="linear")
            for name, k in (("true", _streak(9)), ("turned", _streak(9, vertical=True)),
                            ("short", _streak(5)), ("long", _streak(13)))}
    delta = np.zeros((9, 9), np.float32)
    delta[4, 4] = 1
    assert gain["true"] > 20 * NO_BLUR_MARGIN, gain
    assert gain["turned"] < 0, gain
    assert max(gain["short"], gain["long"]) < gain["true"] - 10, gain
    assert abs(kernel_gain_over_no_blur(blurred, delta, transfer="linear")) < 0.05 * NO_BLUR_MARGIN
    # the sharp scene shows none of the streak; the same kernel scored on it loses
    assert kernel_gain_over_no_blur(sharp, _streak(9), transfer="linear") < 0


def test_a_photo_too_small_for_the_kernel_is_not_judged():
    small = _scene()[:40, :60]
    assert np.isnan(kernel_gain_over_no_blur(small, _streak(9), transfer="linear"))


def test_a_captures_blur_is_told_from_another_stretch_of_its_log(make_capture):
    """The capture's own PSFs (a yaw and pitch with a rolling shutter, blurred by the
    warping forward model) explain the photo far better than no blur; the same capture
    with its clock 0.12 s off (a turn the other way), and the sharp scene, far worse."""
    from gyrodeblur.capture import Capture
    from gyrodeblur.camera import Camera
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.simulate import simulate_blur
    t = np.arange(0.0, 0.6, 0.005)
    w = np.stack([0.6 * np.sin(2 * np.pi * 2 * t), 0.8 * np.cos(2 * np.pi * 2 * t),
                  0.1 * np.ones_like(t)], axis=1)
    cap = Capture(0.25, 0.04, 0.02, Camera.centred(512, 384, 420.0), GyroLog(t, w))
    sharp = _scene()
    blurred = simulate_blur(sharp, cap, snr_db=45, seed=1, transfer="linear")
    right = capture_gain_over_no_blur(blurred, cap, transfer="linear")
    wrong = capture_gain_over_no_blur(blurred, cap.replace(time_offset=0.12),
                                      transfer="linear")
    assert right > 10 * NO_BLUR_MARGIN, right
    assert wrong < WRONG_BLUR_MARGIN, wrong
    assert capture_gain_over_no_blur(sharp, cap, transfer="linear") < WRONG_BLUR_MARGIN
    small = cap.replace(camera=Camera.centred(60, 40, 420.0 * 60 / 512))
    assert np.isnan(capture_gain_over_no_blur(sharp[:40, :60], small, transfer="linear"))


def test_deblur_blind_leaves_a_sharp_photo_as_it_is_and_says_why():
    from gyrodeblur.deblur import deblur_blind

    sharp = _scene()
    with pytest.warns(UserWarning, match="no better than no blur at all.*returned as it is"):
        out, field = deblur_blind(sharp, 15, transfer="linear")
    assert np.array_equal(out, sharp)
    assert field.psfs[0][7, 7] == 1 and field.psfs[0].sum() == 1
    # asked not to check, it deconvolves with whatever it estimated
    from gyrodeblur.deblur import deblur_with_psfs
    from gyrodeblur.tiling import patch_grid

    forced, kept = deblur_blind(sharp, 15, transfer="linear", check_blur=False)
    assert kept.psfs[0][7, 7] < 1
    np.testing.assert_array_equal(
        forced, deblur_with_psfs(sharp, patch_grid(sharp.shape[:2], (1, 1)), kept.psfs,
                                 transfer="linear"))
    assert not np.array_equal(forced, sharp)
    with pytest.raises(TypeError, match="check_blur must be True or False"):
        deblur_blind(sharp, 15, check_blur="no")


def test_deblur_blind_keeps_a_kernel_the_photo_shows():
    """The streak photo's estimate passes the check (no warning) and is deconvolved; with a
    grid, a sharp photo's patches all get delta kernels."""
    import warnings

    from gyrodeblur.deblur import deblur_blind
    from gyrodeblur.metrics import psnr

    sharp = _scene()
    blurred = _moved_along_x(sharp, 9)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, field = deblur_blind(blurred, 15, transfer="linear")
    assert field.psfs[0].max() < 0.5                     # a streak, not a delta
    assert psnr(sharp, out, 16) > psnr(sharp, blurred, 16) + 2
    with pytest.warns(UserWarning, match="returned as it is"):
        kept, field2 = deblur_blind(sharp, 15, grid=(1, 2), transfer="linear")
    assert np.array_equal(kept, sharp) and len(field2.psfs) == 2
    assert all(k[7, 7] == 1 for k in field2.psfs)


def _text_page() -> np.ndarray:
    """A crisp page of text, 300 x 400, sRGB values: words drawn 4x larger by Pillow and
    area-averaged, 0.5 % noise, 8-bit levels. Its repeated glyphs lead the blind estimate
    to a kernel shaped like a letter."""
    from PIL import Image, ImageDraw, ImageFont

    page = Image.new("L", (1600, 1200), 235)
    draw = ImageDraw.Draw(page)
    try:
        font = ImageFont.load_default(size=56)
    except TypeError:                                   # Pillow < 10.1: a bitmap font
        font = ImageFont.load_default()
    rng = np.random.default_rng(0)
    words = "the quick brown fox jumps over lazy dog camera shake blur kernel".split()
    for y in range(20, 1140, 72):
        draw.text((20, y), " ".join(rng.choice(words, 8)), fill=20, font=font)
    img = np.asarray(page, np.float64).reshape(300, 4, 400, 4).mean(axis=(1, 3)) / 255
    img += np.random.default_rng(1).normal(0, 0.005, img.shape)
    return (np.round(np.clip(img, 0, 1) * 255) / 255).astype(np.float32)


def test_the_right_kernel_sparsens_the_photo_and_a_wrong_one_does_not():
    """Deconvolved with the kernel the blind estimator finds for a streaked photo, its
    gradients are far sparser than with no blur; with the streak itself too, less so (the
    estimate is the sparsest explanation: 0.78 against 0.88 on this soft scene); with no
    blur's kernel the ratio is 1; a streak across the blur, or the streak on the sharp
    scene, sharpens less or nothing."""
    from gyrodeblur.blind import estimate_kernel

    sharp = _scene()
    blurred = _moved_along_x(sharp, 9)
    one = np.ones((1, 1), np.float32)
    estimate = kernel_sparsity_ratio(blurred, estimate_kernel(blurred, 15), transfer="linear")
    assert estimate < SPARSER_MAX - 0.1, estimate
    true = kernel_sparsity_ratio(blurred, _streak(9), transfer="linear")
    assert estimate < true < SPARSER_MAX, (estimate, true)
    assert kernel_sparsity_ratio(blurred, one, transfer="linear") == pytest.approx(1.0)
    turned = kernel_sparsity_ratio(blurred, _streak(9, vertical=True), transfer="linear")
    assert turned > true + 0.03, (turned, true)
    assert kernel_sparsity_ratio(sharp, _streak(9), transfer="linear") > SPARSER_MAX + 0.2
    assert np.isnan(kernel_sparsity_ratio(np.full((200, 200), 0.5, np.float32), _streak(9),
                                          transfer="linear"))


def test_the_sparsity_is_read_in_linear_light_of_the_colours_not_the_alpha():
    """An sRGB colour photo streaked in linear light: its streak sharpens it, and not the
    sharp photo; an alpha channel changes nothing; a photo too small to leave 32 px inside
    a window's kernel-wide margins is not judged."""
    from gyrodeblur.tonecurve import get_transfer_curve

    srgb = get_transfer_curve("srgb")
    sharp = data.coffee()[:300, :400].astype(np.float32) / 255
    light = srgb.decode(sharp)
    moved = np.mean([ndimage.shift(light, (0, s, 0), order=3, mode="mirror")
                     for s in np.linspace(-4, 4, 33)], axis=0)
    noise = 0.003 * np.random.default_rng(0).normal(size=moved.shape)
    blurred = (np.round(np.clip(srgb.encode(np.clip(moved, 0, 1)) + noise, 0, 1) * 255)
               / 255).astype(np.float32)
    streak = _streak(9)
    ratio = kernel_sparsity_ratio(blurred, streak)
    assert ratio < SPARSER_MAX, ratio                                   # 0.87
    assert kernel_sparsity_ratio(sharp, streak) > SPARSER_MAX + 0.2     # 1.25
    alpha = np.random.default_rng(1).uniform(size=blurred.shape[:2] + (1,)).astype(np.float32)
    assert kernel_sparsity_ratio(np.concatenate([blurred, alpha], 2), streak) == ratio
    assert np.isnan(kernel_sparsity_ratio(blurred[:49, :49], streak))  # 49 - 18 < 32
    assert np.isfinite(kernel_sparsity_ratio(blurred[:60, :60], streak))


def test_deblur_blind_leaves_a_crisp_page_of_text_as_it_is():
    """Session 59's audit: the glyph-shaped kernel a sharp page of text leads to passed the
    spectral check (+21 nats per 9 windows: ``|H|`` fits the page's repeated strokes) and
    the page came out at 8 dB against itself. Deconvolving with it adds ghost strokes, so
    the sparsity check refuses it and the page is returned as it is."""
    from gyrodeblur.deblur import deblur_blind

    page = _text_page()
    with pytest.warns(UserWarning, match="does not sharpen the photo.*returned as it is"):
        out, field = deblur_blind(page, 15)
    assert np.array_equal(out, page)
    assert field.psfs[0][7, 7] == 1


# ------------------------------------------------ from a mutation audit (session 44)

def test_the_photo_is_judged_in_linear_light_through_its_transfer_curve(make_capture):
    """Kills ``kernel_gain_over_no_blur`` and ``capture_gain_over_no_blur`` reading the
    photo's values as light whatever ``transfer`` says: the sRGB-encoded photo with
    ``transfer="srgb"`` scores as the linear one does; read as linear it scores otherwise."""
    from gyrodeblur.simulate import simulate_blur
    from gyrodeblur.tonecurve import linear_to_srgb

    sharp = _scene()[:192, :256]
    blurred = _moved_along_x(sharp, 9)
    encoded = linear_to_srgb(blurred)
    k = _streak(9)
    linear = kernel_gain_over_no_blur(blurred, k, transfer="linear")
    assert kernel_gain_over_no_blur(encoded, k) == pytest.approx(linear, rel=0.05)
    assert abs(kernel_gain_over_no_blur(encoded, k, transfer="linear") - linear) > 5.0
    cap = make_capture((0.3, 1.5, 0.1), width=256, height=192, f=200.0, readout=0.02)
    blurred = simulate_blur(sharp, cap, snr_db=45, seed=1, transfer="linear")        # a 9 px turn
    encoded = linear_to_srgb(np.clip(blurred, 0, None))
    by_light = capture_gain_over_no_blur(blurred, cap, transfer="linear")
    assert by_light > 10 * NO_BLUR_MARGIN
    assert capture_gain_over_no_blur(encoded, cap) == pytest.approx(by_light, rel=1e-3)
    assert abs(capture_gain_over_no_blur(encoded, cap, transfer="linear") - by_light) > 0.3


def test_a_photo_without_texture_is_not_judged():
    """Kills ``_windows`` scoring an empty set of windows: "``nan`` when the photo ...
    has no textured window"."""
    flat = np.full((200, 260), 0.4, np.float32)
    assert np.isnan(kernel_gain_over_no_blur(flat, _streak(9), transfer="linear"))


def _rolling(roll: float):
    """The astronaut (320 x 480, sRGB) taken while the camera rolls at ``roll`` rad/s
    about its optical axis (a little hand shake besides; f 0.8 x width, 40 ms exposure,
    20 ms readout), blurred by warping the sharp photo; and its capture."""
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.simulate import simulate_blur

    sharp = resize(data.astronaut(), (320, 480), anti_aliasing=True).astype(np.float32)
    t = np.arange(0.0, 1.2, 1 / 200)
    w = np.stack([0.05 * np.sin(2 * np.pi * 3.1 * t), 0.06 * np.cos(2 * np.pi * 2.3 * t),
                  np.full(t.size, roll)], 1)
    cap = Capture(0.5, 0.04, 0.02, Camera.centred(480, 320, 384.0), GyroLog(t, w))
    return simulate_blur(sharp, cap, snr_db=40, seed=1, quantize=True, transfer="srgb"), cap


@pytest.mark.parametrize("roll", [1.5, 3.0])
def test_a_roll_blurs_each_window_unevenly_and_its_capture_still_explains_it(roll,
                                                                             monkeypatch):
    """Under a roll the kernel changes across each window (a point at the centre of the
    roll, arcs around it): the blur test averages the kernel's power over the window, and
    the true capture explains the photo better than no blur. Judged by the window
    centre's kernel alone (every point of the 2 x 2 read at the centre), the same capture
    scored far below the 'wrong blur' margin: the deblur then told the user that the log
    was not the photo's."""
    import gyrodeblur.spectral_criterion as sc
    blurred, cap = _rolling(roll)
    assert capture_gain_over_no_blur(blurred, cap) > NO_BLUR_MARGIN
    monkeypatch.setattr(sc, "_KERNEL_CHANGE", np.inf)
    monkeypatch.setattr(sc, "_ACROSS", 0.0)
    assert capture_gain_over_no_blur(blurred, cap) < WRONG_BLUR_MARGIN
