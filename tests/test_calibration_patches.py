"""Where calibration looks (:mod:`gyrodeblur.calibration_patches`)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage
from skimage import data, transform

from gyrodeblur.calibration_fit import BLOCKY
from gyrodeblur.calibration_patches import CalibrationPhoto, patch_centres, select_patch_centres
from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog


def _capture(w=600, h=400) -> Capture:
    t = np.arange(0.0, 1.0, 0.005)
    return Capture(0.5, 0.03, 0.03, Camera.centred(w, h, 500.0), GyroLog(t, np.zeros((t.size, 3))))


def test_patches_are_textured_unclipped_and_apart():
    """Texture on the left half only, with a clipped highlight in its middle. The frame is
    covered by a grid of cells (3 x 2 for six patches), each giving its best window: the
    four cells that hold texture give windows on it, and these come first (best
    texture first); no window is mostly highlight (a page of text on white paper has
    little else, so up to 30 % clipped is allowed); no two overlap much."""
    rng = np.random.default_rng(0)
    img = np.full((400, 600), 0.4, np.float32)
    img[:, :300] += 0.15 * ndimage.gaussian_filter(rng.normal(size=(400, 300)), 1.5)
    img[150:250, 100:200] = 1.0
    photo = CalibrationPhoto(np.clip(img, 0, 1), _capture(), "srgb", 0)
    centres = select_patch_centres(photo, 6, 64)
    assert len(centres) == 6
    for x, y in centres[:4]:
        assert x < 300 - 16, centres
    for x, y in centres:
        win = img[int(y) - 32:int(y) + 32, int(x) - 32:int(x) + 32]
        assert (win >= 1.0).mean() < 0.3, (x, y)
    d = [np.hypot(a[0] - b[0], a[1] - b[1]) for i, a in enumerate(centres) for b in centres[i + 1:]]
    assert min(d) > 0.5 * 64


def test_a_page_of_text_gets_all_its_patches_the_unclipped_ones_first():
    """White paper (clipped) with dark strokes all over, so that nearly every window is
    more than 30 % clipped, and one grey textured corner. The corner's windows come
    first; the strokes' best windows fill the other places rather than leaving them
    empty (a photo with only two unclipped windows must not be calibrated on two patches
    when one with none gets six)."""
    rng = np.random.default_rng(2)
    img = np.ones((400, 600), np.float32)
    strokes = ndimage.gaussian_filter(rng.normal(size=(400, 600)), 2.0)
    img[strokes > 0.08] = 0.1
    img[:110, :110] = 0.4 + 0.15 * ndimage.gaussian_filter(rng.normal(size=(110, 110)), 1.5)
    img = np.clip(img, 0, 1)
    win = 64
    clipped = ndimage.uniform_filter((img >= 1.0).astype(float), win)[32:-32, 32:-32]
    assert (clipped > 0.3).mean() > 0.9           # the page: nearly all windows clipped
    photo = CalibrationPhoto(img, _capture(), "srgb", 0)
    centres = select_patch_centres(photo, 6, win)
    assert len(centres) == 6
    first = [(x, y) for x, y in centres if x < 110 and y < 110]
    assert len(first) >= 1 and centres[:len(first)] == first, centres
    for x, y in centres[len(first):]:
        w = img[int(y) - 32:int(y) + 32, int(x) - 32:int(x) + 32]
        assert w.std() > 0.2, (x, y)              # on the strokes, not on blank paper
    d = [np.hypot(a[0] - b[0], a[1] - b[1]) for i, a in enumerate(centres) for b in centres[i + 1:]]
    assert min(d) > 0.5 * win


def test_a_nearly_flat_cell_gives_its_place_to_texture_elsewhere():
    """The right half is sky: flat but for faint sensor noise. Its grid cells' best windows
    would show noise, not blur, so all six windows lie on the textured left half."""
    rng = np.random.default_rng(1)
    img = np.full((400, 600), 0.4, np.float32) + 0.002 * rng.normal(size=(400, 600))
    img[:, :300] += 0.15 * ndimage.gaussian_filter(rng.normal(size=(400, 300)), 1.5)
    photo = CalibrationPhoto(np.clip(img, 0, 1).astype(np.float32), _capture(), "srgb", 0)
    centres = select_patch_centres(photo, 6, 64)
    assert len(centres) == 6
    assert all(x < 300 for x, _ in centres), centres


def test_texture_in_every_direction_beats_stripes():
    """Stripes say nothing about blur along them: with a square of texture on the left and
    stronger full-height stripes on the right, all nine windows lie on the texture, kept
    apart by 0.7 of their side (packed as close as that allows)."""
    rng = np.random.default_rng(0)
    img = np.full((400, 600), 0.4, np.float32)
    img[100:300, 50:250] += 0.15 * ndimage.gaussian_filter(rng.normal(size=(200, 200)), 1.5)
    img[:, 350:550] += 0.3 * np.sin(2 * np.pi * np.arange(200) / 6)[None, :]
    photo = CalibrationPhoto(np.clip(img, 0, 1), _capture(), "srgb", 0)
    centres = select_patch_centres(photo, 9, 64)
    assert len(centres) == 9
    for x, y in centres:
        assert 50 <= x <= 250 and 100 <= y <= 300, centres
    d = [np.hypot(a[0] - b[0], a[1] - b[1]) for i, a in enumerate(centres) for b in centres[i + 1:]]
    assert 0.7 * 64 - 3 < min(d) < 0.7 * 64 + 8, min(d)


def test_the_thumbnail_is_block_means_made_once_and_read_only():
    """A 1030 x 700 RGB photo at 512 px: blocks of 3 (the remainder cut), the mean of the
    encoded channels and the share of pixels with a channel over 0.98. Asked again (the
    twin's patches, the frame registration) it is the same arrays, which no caller can
    change under another."""
    rng = np.random.default_rng(3)
    img = rng.uniform(0.0, 1.0, (700, 1030, 3)).astype(np.float32)
    photo = CalibrationPhoto(img, _capture(1030, 700), "srgb", 0)
    th, st, k = photo.thumbnail()
    assert k == 3 and th.shape == st.shape == (233, 343)
    np.testing.assert_allclose(th[5, 7], img[15:18, 21:24].mean(), rtol=1e-5)
    assert st[5, 7] == pytest.approx((img[15:18, 21:24].max(axis=2) > 0.98).mean())
    again = photo.thumbnail()
    assert again[0] is th and again[1] is st
    with pytest.raises(ValueError):
        th[0, 0] = 0.0


def test_a_photo_must_be_an_image():
    with pytest.raises(InputError, match="photo 1"):
        CalibrationPhoto(np.zeros(10), _capture(), "srgb", 0)


def _jpeg(u8: np.ndarray, quality: int) -> np.ndarray:
    buf = io.BytesIO()
    Image.fromarray(u8).save(buf, format="JPEG", quality=quality)
    return np.asarray(Image.open(io.BytesIO(buf.getvalue())))


def _blockiness(u8: np.ndarray) -> float:
    return CalibrationPhoto(u8.astype(np.float32) / 255, _capture(u8.shape[1], u8.shape[0]),
                            "srgb", 0).blockiness()


def test_blockiness_tells_a_jpeg_from_the_same_photo_uncompressed():
    """JPEG's 8 px blocks stand out in one phase of the neighbour differences: the phase of
    a grid from the first row and column, or any phase on both axes (a crop); an
    uncompressed photo has no such phase."""
    img = transform.resize(data.astronaut(), (256, 384), anti_aliasing=True).astype(np.float32)
    img = ndimage.gaussian_filter(img, (1.5, 1.5, 0))           # a blurred photo
    u8 = (img * 255).round().astype(np.uint8)
    assert _blockiness(u8) < 1.05
    assert _blockiness(_jpeg(u8, 80)) > BLOCKY
    assert _blockiness(_jpeg(u8, 60)[3:, 5:]) > BLOCKY          # the grid shifted, both axes
    assert _blockiness(_jpeg(u8, 60)[5:, 3:]) > BLOCKY


def test_a_scene_that_was_a_jpeg_is_not_taken_for_a_compressed_photo():
    """A photo of a scene that was itself a JPEG (a synthetic blur of a JPEG, as benchmarks
    make them) holds the scene's block grid, moved by the motion and smeared along it: on
    one axis only, at another phase. Its band is not cut. The same photo compressed after
    the blur is."""
    img = transform.resize(data.astronaut(), (256, 384), anti_aliasing=True).astype(np.float32)
    scene = _jpeg((img * 255).round().astype(np.uint8), 60).astype(np.float32) / 255
    moved = np.roll(scene, (3, 5), axis=(0, 1))
    streak = ndimage.uniform_filter1d(moved, 9, axis=1)          # a 9 px horizontal blur
    photo = (streak * 255).round().astype(np.uint8)
    assert _blockiness(photo) < BLOCKY
    assert _blockiness(_jpeg(photo, 80)) > BLOCKY


def test_the_grid_s_phase_is_counted_from_the_photo_s_own_first_row():
    """On one axis the grid counts at the phase of blocks from the photo's first row, also
    where only the photo's centre is measured (a large photo): a JPEG streaked along x
    after compression keeps its grid in the row differences only. Moved by 3 rows, the
    same grid is at another phase, on one axis: not counted."""
    img = transform.resize(data.astronaut(), (256, 384), anti_aliasing=True).astype(np.float32)
    jpeg = _jpeg((img * 255).round().astype(np.uint8), 20).astype(np.float32) / 255
    streak = ndimage.uniform_filter1d(jpeg, 9, axis=1)

    def centre(a):     # 50 000 px of the photo's centre: rows 37-218, columns 55-327
        return CalibrationPhoto(a, _capture(a.shape[1], a.shape[0]), "srgb",
                                0).blockiness(max_pixels=50_000)

    assert centre(streak) > BLOCKY
    assert centre(np.roll(streak, 3, axis=0)) < BLOCKY


@pytest.mark.parametrize("seed", [1, 3, 5])
def test_a_partly_clipped_window_pays_for_its_clipped_share(seed):
    """Clipped highlights break the linear model, so a window under 30 % clipped is
    penalised for its share. The right half's texture is 1.5 times the left's in
    contrast but about a quarter of its pixels are clipped: the one window asked for lies
    on the unclipped left half (the right's, unpenalised, has more texture and won)."""
    rng = np.random.default_rng(seed)
    tex = ndimage.gaussian_filter(rng.normal(size=(400, 600)), 1.5)
    tex /= tex.std()
    img = 0.5 + 0.1 * tex
    img[:, 300:] = 0.88 + 0.15 * tex[:, 300:]
    img = np.clip(img, 0, 1).astype(np.float32)
    assert 0.2 < (img[:, 300:] >= 0.98).mean() < 0.3
    photo = CalibrationPhoto(img, _capture(), "srgb", 0)
    (x, y), = select_patch_centres(photo, 1, 64)
    assert x < 300 - 16, (x, y)


def test_gray_is_linear_light_luminance_of_the_colour_channels():
    """The criterion models light: a crop's grey is the mean of the decoded (linear) colour
    channels, an sRGB 0.5 being 0.214 in linear light; an alpha channel is a mask, not
    light, and leaves the grey alone."""
    rgb = np.zeros((40, 60, 3), np.float32)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 0.5, 0.5, 1.0
    g = CalibrationPhoto(rgb, _capture(60, 40), "srgb", 0).gray(5, 15, 10, 30)
    assert g.shape == (10, 20) and g.dtype == np.float64
    np.testing.assert_allclose(g, (2 * 0.21404 + 1.0) / 3, rtol=1e-4)
    rgba = np.concatenate([rgb, np.full((40, 60, 1), 0.25, np.float32)], axis=2)
    np.testing.assert_allclose(CalibrationPhoto(rgba, _capture(60, 40), "srgb", 0).gray(5, 15, 10, 30),
                               g, rtol=1e-6)
    lin = CalibrationPhoto(rgb[..., 0], _capture(60, 40), "linear", 0).gray(0, 2, 0, 2)
    np.testing.assert_allclose(lin, 0.5)


def test_each_thumbnail_size_is_made_for_itself():
    """The thumbnails are kept per ``max_side``: one asked for after another of a different
    size has its own block size."""
    img = np.random.default_rng(0).uniform(0, 1, (700, 1030)).astype(np.float32)
    photo = CalibrationPhoto(img, _capture(1030, 700), "srgb", 0)
    assert photo.thumbnail()[2] == 3
    th, _, k = photo.thumbnail(256)
    assert k == 5 and th.shape == (140, 206)
    assert photo.thumbnail()[2] == 3 and photo.thumbnail(256)[0] is th


def test_a_window_centre_is_its_thumbnail_blocks_centre_in_photo_pixels():
    """A single textured blob centred on a thumbnail block (blocks of 3 px: block ``b``
    spans photo pixels ``3b .. 3b + 2``, centre ``3b + 1``): the one window found is
    centred on it to the pixel, in photo coordinates."""
    y, x = np.mgrid[0:700, 0:1030]
    blob = np.exp(-((x - 301.0) ** 2 + (y - 199.0) ** 2) / (2 * 12.0 ** 2))
    img = (0.3 + 0.4 * blob).astype(np.float32)
    photo = CalibrationPhoto(img, _capture(1030, 700), "linear", 0)
    assert photo.thumbnail()[2] == 3
    (cx, cy), = select_patch_centres(photo, 1, 64)
    assert (cx, cy) == (301.0, 199.0)


def test_patch_centres_name_their_photo():
    """Centres of several photos come photo by photo, each tagged with its photo's index
    and placed as that photo alone would place them."""
    rng = np.random.default_rng(4)
    photos = []
    for i, side in enumerate(("left", "right")):
        img = np.full((400, 600), 0.4, np.float32)
        cols = slice(0, 300) if side == "left" else slice(300, 600)
        img[:, cols] += 0.15 * ndimage.gaussian_filter(rng.normal(size=(400, 300)), 1.5)
        photos.append(CalibrationPhoto(np.clip(img, 0, 1), _capture(), "srgb", i))
    got = patch_centres(photos, 3, 64)
    assert [i for i, _, _ in got] == [0, 0, 0, 1, 1, 1]
    for i, ph in enumerate(photos):
        assert [(x, y) for j, x, y in got if j == i] == select_patch_centres(ph, 3, 64)
    assert all(x < 300 + 32 for i, x, _ in got if i == 0)      # on each photo's texture
    assert all(x > 300 - 32 for i, x, _ in got if i == 1)


def test_the_windows_come_best_texture_first():
    """Three cells side by side (a 900 x 300 photo, three windows), texture contrast growing
    from left to right: each cell gives its window, listed best first, so right to left."""
    rng = np.random.default_rng(6)
    tex = ndimage.gaussian_filter(rng.normal(size=(300, 900)), 1.5)
    amp = np.linspace(0.02, 0.3, 900)[None, :]
    img = np.clip(0.4 + amp * tex / tex.std(), 0, 1).astype(np.float32)
    photo = CalibrationPhoto(img, _capture(900, 300), "linear", 0)
    xs = [x for x, _ in select_patch_centres(photo, 3, 64)]
    assert xs == sorted(xs, reverse=True) and xs[0] - xs[-1] > 400, xs
