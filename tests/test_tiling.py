"""Properties of patch tiling and blending (gyrodeblur.tiling)."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
from scipy import ndimage

from gyrodeblur.errors import InputError
from gyrodeblur.tiling import (
    MIN_WINDOW,
    Patch,
    blend_weights,
    deconvolve_patchwise,
    patch_margin,
    patch_grid,
    psf_radius,
)
from gyrodeblur.wiener import wiener_deconvolve


def _line_psf(length, angle, size=None):
    """Line PSF of ``length`` px at ``angle`` (radians), bilinear splat, centred, odd size."""
    size = size or (2 * int(np.ceil(length / 2)) + 3)
    psf = np.zeros((size, size))
    c = size // 2
    for t in np.linspace(-length / 2, length / 2, 4 * int(np.ceil(length)) + 1):
        y, x = c + t * np.sin(angle), c + t * np.cos(angle)
        y0, x0 = int(np.floor(y)), int(np.floor(x))
        fy, fx = y - y0, x - x0
        psf[y0, x0] += (1 - fy) * (1 - fx)
        psf[y0 + 1, x0] += fy * (1 - fx)
        psf[y0, x0 + 1] += (1 - fy) * fx
        psf[y0 + 1, x0 + 1] += fy * fx
    return psf / psf.sum()


def _scene(shape, seed=0, sigma=2.0):
    rng = np.random.default_rng(seed)
    sig = (sigma, sigma) + (0,) * (len(shape) - 2)
    img = ndimage.gaussian_filter(rng.random(shape), sig)
    img = (img - img.min()) / (img.max() - img.min())
    yy = np.linspace(0, 1, shape[0])[:, None]
    if len(shape) == 3:
        yy = yy[..., None]
    return (0.1 + 0.5 * img + 0.3 * yy).astype(np.float32)


# ---------------------------------------------------------------- patch_grid

@pytest.mark.parametrize("shape, grid, overlap", [
    ((3000, 4000), (6, 8), 0.25),
    ((480, 640, 3), (6, 8), 0.25),
    ((201, 333), (3, 5), 0.25),
    ((201, 333), (4, 2), 0.5),
    ((100, 157), (2, 3), 0.0),
    ((97, 101), (1, 1), 0.25),
])
def test_patch_grid_tiles_with_equal_windows_and_exact_overlap(shape, grid, overlap):
    patches = patch_grid(shape, grid, overlap)
    rows, cols = grid
    assert len(patches) == rows * cols
    sizes = {p.shape for p in patches}
    assert len(sizes) == 1, sizes
    h, w = sizes.pop()
    cover = np.zeros(shape[:2], int)
    for p in patches:
        assert 0 <= p.y0 < p.y1 <= shape[0] and 0 <= p.x0 < p.x1 <= shape[1]
        cover[p.y0:p.y1, p.x0:p.x1] += 1
    assert cover.min() >= 1
    # Row-major, first window at the origin, last one flush with the far corner.
    assert (patches[0].y0, patches[0].x0) == (0, 0)
    assert (patches[-1].y1, patches[-1].x1) == shape[:2]
    assert [p.x0 for p in patches[:cols]] == sorted(p.x0 for p in patches[:cols])
    # Every pair of neighbours overlaps by the same number of pixels, close to `overlap`.
    for n, size, starts in ((rows, h, [patches[i * cols].y0 for i in range(rows)]),
                            (cols, w, [patches[j].x0 for j in range(cols)])):
        if n == 1:
            continue
        overlaps = {size - (b - a) for a, b in zip(starts, starts[1:])}
        assert len(overlaps) == 1, overlaps
        v = overlaps.pop()
        assert v >= 0
        assert abs(v / size - overlap) <= n / size + 1e-9, (v, size)


def test_patch_grid_chapter_layout():
    patches = patch_grid((3000, 4000))
    assert len(patches) == 48
    assert patches[0].shape == (630, 640)
    assert patches[1].x0 == 480  # 160 px = 25 % of 640 overlap
    assert patches[8].y0 == 630 - 156


def test_patch_centre():
    p = Patch(10, 20, 0, 5)
    assert p.centre == (14.5, 2.0)
    assert p.shape == (10, 5)
    with pytest.raises(AttributeError):
        p.y0 = 3  # frozen


@pytest.mark.parametrize("grid", [(0, 8), (6,), (6, 8, 1), "6x", "0x8", "6x8x1", "6 by 8",
                                  (6.0, 8), (True, 8), (-1, 2), None])
def test_bad_grid_raises_input_error(grid):
    with pytest.raises(InputError, match="^grid: "):
        patch_grid((480, 640), grid=grid)


def test_a_grid_may_be_given_as_text():
    assert patch_grid((480, 640), grid="3x4") == patch_grid((480, 640), grid=(3, 4))
    assert patch_grid((480, 640), grid=" 3X4 ") == patch_grid((480, 640), grid=(3, 4))


@pytest.mark.parametrize("overlap", [-0.1, 0.6, 1.0, float("nan"), "0.25", None])
def test_bad_overlap_raises_input_error(overlap):
    with pytest.raises(InputError, match="^overlap: "):
        patch_grid((480, 640), overlap=overlap)


def test_grid_too_fine_raises_input_error():
    with pytest.raises(InputError, match="^grid: "):
        patch_grid((60, 640), grid=(6, 8))
    # one window along an axis: the image itself is too small, whatever the grid
    with pytest.raises(InputError, match="image has only") as err:
        patch_grid((MIN_WINDOW - 1, 640), grid=(1, 8))
    assert err.value.source is None


# ---------------------------------------------------------------- blend_weights

@pytest.mark.parametrize("shape, grid, overlap", [
    ((240, 320), (6, 8), 0.25), ((101, 77), (3, 2), 0.5), ((64, 64), (1, 1), 0.25),
    ((90, 120), (2, 3), 0.0),
])
def test_blend_weights_sum_to_one(shape, grid, overlap):
    patches = patch_grid(shape, grid, overlap)
    total = np.zeros(shape)
    for p, (wy, wx) in zip(patches, blend_weights(patches, shape)):
        assert wy.dtype == np.float32 and wx.shape == (p.x1 - p.x0,)
        assert np.all(wy > 0) and np.all(wx > 0)
        total[p.y0:p.y1, p.x0:p.x1] += np.outer(wy, wx)
    np.testing.assert_allclose(total, 1.0, atol=1e-6)


def test_blend_weights_are_normalised_hamming_windows():
    shape = (300, 400)
    patches = patch_grid(shape, (3, 4), 0.25)
    weights = blend_weights(patches, shape)
    cols = [(p.x0, p.x1) for p in patches[:4]]
    total = np.zeros(shape[1])
    for a, b in cols:
        total[a:b] += np.hamming(b - a)
    for j, (a, b) in enumerate(cols):
        np.testing.assert_allclose(weights[4 + j][1], np.hamming(b - a) / total[a:b], rtol=1e-5)
    # Across an overlap the weight of the left patch falls smoothly from near 1 to near 0.
    a1 = cols[1][0]
    left = weights[4][1][a1 - cols[0][0]:]
    assert left[0] > 0.8 and left[-1] < 0.2
    assert np.all(np.diff(left) < 0)


def test_blend_weights_reject_non_grid_layout():
    patches = [Patch(0, 40, 0, 40), Patch(20, 64, 20, 64)]
    with pytest.raises(ValueError):
        blend_weights(patches, (64, 64))


# ---------------------------------------------------------------- deconvolve_patchwise

def _psf_field(n, seed=0):
    rng = np.random.default_rng(seed)
    return [_line_psf(rng.uniform(1, 9), rng.uniform(0, np.pi)) for _ in range(n)]


@pytest.mark.parametrize("shape", [(150, 200), (150, 200, 3)])
def test_flat_image_stays_flat_with_varied_psfs(shape):
    img = np.full(shape, 0.42, np.float32)
    patches = patch_grid(shape, (3, 4), 0.25)
    out = deconvolve_patchwise(img, patches, _psf_field(len(patches)),
                               functools.partial(wiener_deconvolve, phi=0.01))
    assert out.shape == shape and out.dtype == np.float32
    assert np.max(np.abs(out - 0.42)) < 1e-3


def test_identity_deconvolver_returns_input_exactly():
    # Blending alone must not change anything: no seams, steps or dark border.
    img = _scene((120, 170, 3))
    patches = patch_grid(img.shape, (3, 4), 0.25)
    out = deconvolve_patchwise(img, patches, _psf_field(len(patches)), lambda s, p: s)
    np.testing.assert_allclose(out, img, atol=2e-6)


def test_same_psf_everywhere_matches_whole_image_wiener():
    # No seams: with one PSF in every patch the result should match one global filter,
    # except for the small effect of the finite patch margins.
    img = _scene((180, 240, 3), seed=4)
    psf = _line_psf(7, 0.4)
    patches = patch_grid(img.shape, (3, 4), 0.25)
    out = deconvolve_patchwise(img, patches, [psf] * len(patches), wiener_deconvolve)
    whole = wiener_deconvolve(img, psf)
    # The Wiener filter's tails are long, so a 12 px margin leaves a small difference
    # (about 2e-3 on average here, a few 1e-2 at most); a seam would be far larger.
    err = np.abs(out - whole)[16:-16, 16:-16]
    assert err.mean() < 4e-3 and err.max() < 4e-2, (err.mean(), err.max())


def test_patchwise_restores_space_variant_blur():
    # Left half blurred horizontally, right half vertically (independent shift model).
    sharp = _scene((120, 240), seed=5, sigma=0.8)
    shifts_h = [(0, t) for t in range(-3, 4)]
    shifts_v = [(t, 0) for t in range(-3, 4)]

    def blur(shifts):
        return np.mean([ndimage.shift(sharp, s, order=0, mode="nearest") for s in shifts], axis=0)

    blurred = np.concatenate([blur(shifts_h)[:, :120], blur(shifts_v)[:, 120:]], axis=1)
    blurred = blurred.astype(np.float32)
    patches = patch_grid(blurred.shape, (1, 2), 0.0)
    psf_h = np.zeros((7, 7))
    psf_h[3, :] = 1 / 7
    # The blur changes abruptly at the seam (camera shake never does): a window's margin
    # holds the other half's blur, so the margin here is the PSF's radius + 8, not the
    # default blur length + 8 (with which the error ratio is 0.72 instead of 0.58).
    out = deconvolve_patchwise(blurred, patches, [psf_h, psf_h.T],
                               functools.partial(wiener_deconvolve, phi=0.002),
                               margin=psf_radius(psf_h) + 8)
    inner = (slice(8, -8), np.r_[8:110, 130:232])
    err_out = np.sqrt(np.mean((out[inner] - sharp[inner]) ** 2))
    err_in = np.sqrt(np.mean((blurred[inner] - sharp[inner]) ** 2))
    assert err_out < 0.6 * err_in, (err_out, err_in)


def test_threads_give_identical_result_and_progress_is_reported():
    img = _scene((100, 130, 3), seed=6)
    patches = patch_grid(img.shape, (2, 3), 0.25)
    psfs = _psf_field(len(patches), seed=1)
    calls = []
    serial = deconvolve_patchwise(img, patches, psfs, wiener_deconvolve, workers=1,
                                  progress=lambda d, t: calls.append((d, t)))
    assert calls == [(k, 6) for k in range(1, 7)]
    for workers in (2, 3, None):
        calls.clear()
        threaded = deconvolve_patchwise(img, patches, psfs, wiener_deconvolve,
                                        workers=workers,
                                        progress=lambda d, t: calls.append((d, t)))
        np.testing.assert_array_equal(threaded, serial)
        assert calls == [(k, 6) for k in range(1, 7)]


def test_margin_uses_real_neighbours_clamped_at_border():
    img = _scene((90, 120))
    patches = patch_grid(img.shape, (2, 2), 0.25)
    psf = _line_psf(6, 0.0)
    seen = []

    def record(sub, p):
        seen.append(sub.shape)
        return sub

    deconvolve_patchwise(img, patches, [psf] * 4, record)
    r = patch_margin(psf)
    h, w = patches[0].shape
    # Every window touches two image borders here, so one side of each axis is clamped.
    assert seen == [(h + r, w + r)] * 4
    assert deconvolve_patchwise(img, patches, [psf] * 4, record, margin=0).shape == img.shape
    assert seen[-1] == (h, w)


def test_margin_is_a_blur_length_beyond_the_psfs_reach():
    centred = np.zeros((21, 21), np.float32)
    centred[10, :] = 1 / 21                    # a 21 px streak: radius 10, extent 21
    assert psf_radius(centred) == 10 and patch_margin(centred) == 21 + 8
    offset = np.zeros((61, 61), np.float32)
    offset[30, 50:] = 1 / 11                   # 11 px, 20-30 px from the centre
    assert patch_margin(offset) == 30 + 8


def test_non_grid_layout_blends_with_weight_map():
    img = np.full((64, 80), 0.3, np.float32)
    patches = [Patch(0, 40, 0, 50), Patch(30, 64, 0, 80), Patch(0, 40, 40, 80)]
    out = deconvolve_patchwise(img, patches, _psf_field(3), wiener_deconvolve)
    assert np.max(np.abs(out - 0.3)) < 1e-3
    with pytest.raises(ValueError, match="uncovered"):
        deconvolve_patchwise(img, patches[:2], _psf_field(2), wiener_deconvolve)


def test_large_psf_warns():
    img = _scene((120, 160))
    patches = patch_grid(img.shape, (2, 2), 0.25)  # windows 68x91 (about)
    psfs = [_line_psf(3, 0.0)] * 3 + [_line_psf(85, 0.3)]
    with pytest.warns(UserWarning, match="coarser grid"):
        deconvolve_patchwise(img, patches, psfs, lambda s, p: s)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        deconvolve_patchwise(img, patches, [_line_psf(3, 0.0)] * 4, lambda s, p: s)
    # a PSF longer than the photo's shorter side: no grid can help, and the warning says
    # so rather than asking for a coarser one
    strip = _scene((40, 400))
    patches = patch_grid(strip.shape, (1, 4), 0.25)
    with pytest.warns(UserWarning, match="shorter side is only 40 px, so no grid helps"):
        deconvolve_patchwise(strip, patches, [_line_psf(61, 0.0)] * 4, lambda s, p: s)


def test_psf_radius():
    psf = np.zeros((11, 11))
    psf[5, 5] = 1
    assert psf_radius(psf) == 0
    psf[5, 8] = 1
    assert psf_radius(psf) == 3
    psf[0, 5] = 1
    assert psf_radius(psf) == 5


def test_argument_checks():
    img = np.zeros((64, 64), np.float32)
    patches = patch_grid(img.shape, (2, 2), 0.25)
    psf = np.ones((3, 3)) / 9
    with pytest.raises(ValueError, match="PSFs"):
        deconvolve_patchwise(img, patches, [psf] * 3, wiener_deconvolve)
    with pytest.raises(ValueError, match="shape"):
        deconvolve_patchwise(img, patches, [psf] * 4, lambda s, p: s[1:])
    with pytest.raises(ValueError, match="leaves"):
        deconvolve_patchwise(img, [Patch(0, 65, 0, 64)], [psf], wiener_deconvolve)
    with pytest.raises(ValueError, match="workers"):
        deconvolve_patchwise(img, patches, [psf] * 4, wiener_deconvolve, workers=0)


# ------------------------------------------------ from a mutation audit (session 43)

def test_psf_radius_of_a_non_square_psf():
    """Kills T8 (``_radius`` taking the centre row from the column count and vice versa).
    ``check_psf`` accepts any odd sizes (a 1 x 9 streak), and the radius is measured from
    the centre sample (kh // 2, kw // 2)."""
    from gyrodeblur.tiling import patch_margin, psf_radius

    assert psf_radius(np.ones((1, 9)) / 9) == 4
    offset = np.zeros((3, 61), np.float32)
    offset[1, 50:] = 1 / 11                     # 11 px, 20-30 px right of the centre
    assert psf_radius(offset) == 30
    assert patch_margin(offset) == 30 + 8


def test_patch_grid_ties_go_to_the_smaller_window():
    """Kills T4 (``err <= best[0]``: ties to the larger window). 63 rows in 4 windows at
    25 %: 18 px windows overlapping by 3 (1/6) and 21 px ones overlapping by 7 (1/3) are
    equally far from 1/4; the docstring picks the smaller window."""
    from gyrodeblur.tiling import patch_grid

    patches = patch_grid((63, 64), (4, 1), 0.25)
    assert patches[0].shape[0] == 18
    assert [p.y0 for p in patches] == [0, 15, 30, 45]


# ------------------------------------------------ from a mutation audit (session 47)

def test_a_window_of_exactly_min_window_pixels_is_accepted_along_either_kind_of_axis():
    """Kills T6 and T9 (``< MIN_WINDOW`` made ``<=``, for several windows along an axis and
    for one). ``MIN_WINDOW`` is the smallest side accepted, not the first one refused: 32
    rows in two windows without overlap are two 16 px windows, and 16 columns are one."""
    patches = patch_grid((2 * MIN_WINDOW, MIN_WINDOW), (2, 1), 0.0)
    assert [(p.y0, p.y1, p.x0, p.x1) for p in patches] == [
        (0, MIN_WINDOW, 0, MIN_WINDOW), (MIN_WINDOW, 2 * MIN_WINDOW, 0, MIN_WINDOW)]


def test_a_grid_crowded_past_three_quarters_is_refused_and_three_quarters_is_not():
    """Kills T7 (the crowding limit made exclusive), T8 (no crowding check) and T10 (the
    limit raised to 90 %). 20 windows across 92 rows can be no smaller than 16 px, which
    overlap by 12 px: exactly 75 %, accepted. Across 95 rows the smallest are 19 px
    overlapping by 15 (79 %), where each row lies in five windows: refused as too many,
    rather than met with windows far more overlapped than asked."""
    patches = patch_grid((92, 64), (20, 1), 0.25)
    assert patches[0].shape == (16, 64) and patches[1].y0 == 4 and patches[-1].y1 == 92
    with pytest.raises(InputError, match=r"^grid: 20 patches across 95 rows are too many: "
                                         r"they would overlap by 79 %"):
        patch_grid((95, 64), (20, 1), 0.25)


def test_a_row_grid_with_a_gap_is_refused_rather_than_left_black():
    """Kills T12 (``_normalised_axis_weights`` without its coverage check). Two full-width
    windows with rows 10-19 between them form a row/column grid, so the separable weights
    would be used, and they leave the gap at zero: a black band in the output. The gap is
    refused instead, named by its first row."""
    patches = [Patch(0, 10, 0, 64), Patch(20, 64, 0, 64)]
    with pytest.raises(ValueError, match=r"leave image rows uncovered \(first: 10\)"):
        blend_weights(patches, (64, 64))
    with pytest.raises(ValueError, match="uncovered"):
        deconvolve_patchwise(np.full((64, 64), 0.5, np.float32), patches,
                             [np.ones((1, 1))] * 2, lambda s, p: s)


def test_a_window_listed_twice_does_not_make_a_grid():
    """Kills T13 (the grid test counting windows, not distinct windows). Four windows over
    two row and two column intervals, one of them twice and the cell (rows 30-64, columns
    0-50) missing: no separable weights sum to one there, so ``blend_weights`` refuses it,
    and blending it with the weight map finds the missing cell uncovered (rather than the
    doubled window shining twice as bright and the missing one black)."""
    a, b = (0, 40), (30, 64)
    c, d = (0, 50), (40, 80)
    patches = [Patch(*a, *c), Patch(*a, *c), Patch(*b, *d), Patch(*a, *d)]
    with pytest.raises(ValueError, match="do not form a row/column grid"):
        blend_weights(patches, (64, 80))
    with pytest.raises(ValueError, match="uncovered"):
        deconvolve_patchwise(np.full((64, 80), 0.5, np.float32), patches,
                             [np.ones((1, 1))] * 4, lambda s, p: s)


def test_a_deconvolver_returning_a_larger_array_is_refused():
    """Kills T19 (no check of the deconvolver's result shape). A result padded by a row and
    a column can still be cropped to the window, one pixel off, without any error from
    NumPy; the contract is a result of the sub-image's shape, and anything else is named."""
    img = _scene((64, 64))
    patches = patch_grid(img.shape, (2, 2), 0.25)
    with pytest.raises(ValueError, match=r"deconvolve returned shape \(\d+, \d+\) for a "
                                         r"sub-image of shape"):
        deconvolve_patchwise(img, patches, [np.ones((1, 1))] * 4,
                             lambda s, p: np.pad(s, ((1, 0), (1, 0))))


def test_the_large_psf_warning_names_the_longest_blur_and_spares_one_as_long_as_the_window():
    """Kills T22 (a blur as long as the window's smaller side warned about) and T23 (the
    warning naming the shortest of the blurs that are too long). The docstring warns when
    the extent *exceeds* the smaller side; the message gives the worst extent, which is
    what decides how much coarser the grid should be."""
    img = _scene((120, 160))
    patches = patch_grid(img.shape, (2, 2), 0.25)
    side = min(patches[0].shape)

    def streak(n):                      # a horizontal streak of n samples: extent n
        psf = np.zeros((3, 2 * n + 1))
        psf[1, n:2 * n] = 1.0 / n
        return psf

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        deconvolve_patchwise(img, patches, [streak(side)] * 4, lambda s, p: s, margin=0)
    psfs = [streak(3), streak(side + 2), streak(side + 9), streak(side + 5)]
    with pytest.warns(UserWarning, match=rf"PSF extent up to {side + 9} px exceeds the patch "
                                         rf"window .* in 3 of 4 patches"):
        deconvolve_patchwise(img, patches, psfs, lambda s, p: s, margin=0)


@pytest.mark.parametrize("flag", [False, True, np.bool_(False)])
def test_a_flag_is_not_an_overlap(flag):
    """Kills T29 (``check_overlap`` without its ``bool`` test). ``False`` is the number 0
    to Python, but an overlap given as a flag is a mistake, refused like the other
    arguments the library checks (:mod:`gyrodeblur.arguments`)."""
    with pytest.raises(InputError, match="^overlap: "):
        patch_grid((480, 640), overlap=flag)


@pytest.mark.parametrize("patch", [Patch(10, 10, 0, 64), Patch(0, 64, 30, 30),
                                   Patch(0, 64, 0, 65)])
def test_an_empty_window_or_one_past_the_right_edge_is_refused(patch):
    """Kills T30 (empty windows accepted) and T31 (a window one column past the right
    edge accepted). ``check_patches`` refuses a window that is empty or leaves the image,
    along the columns as along the rows."""
    img = np.zeros((64, 64), np.float32)
    with pytest.raises(ValueError, match="is empty or leaves the 64x64 image"):
        deconvolve_patchwise(img, [Patch(0, 64, 0, 64), patch], [np.ones((1, 1))] * 2,
                             lambda s, p: s)


def test_a_non_grid_layout_is_blended_with_hamming_windows():
    """Kills T34 (the weight-map path blending with other windows). Two windows that do not
    form a grid, each "deconvolved" to a constant: where both cover a pixel the output is
    the mean of the two constants weighted by each window's separable Hamming weight at
    that pixel, as for a grid (sec. 6.5.2), and 1 and 2 where only one window covers it."""
    patches = [Patch(0, 40, 0, 48), Patch(24, 64, 16, 64)]    # not a grid; plus the rest:
    patches += [Patch(0, 24, 48, 64), Patch(40, 64, 0, 16)]
    consts = [1.0, 2.0, 3.0, 4.0]
    psfs = [np.full((1, 1), c) for c in consts]
    out = deconvolve_patchwise(np.zeros((64, 64), np.float32), patches, psfs,
                               lambda s, p: np.full(s.shape, p[0, 0], np.float32))
    num = np.zeros((64, 64))
    den = np.zeros((64, 64))
    for p, c in zip(patches, consts):
        w = np.outer(np.hamming(p.y1 - p.y0), np.hamming(p.x1 - p.x0))
        num[p.y0:p.y1, p.x0:p.x1] += c * w
        den[p.y0:p.y1, p.x0:p.x1] += w
    np.testing.assert_allclose(out, num / den, rtol=1e-5)
    assert out[5, 5] == pytest.approx(1.0) and out[60, 60] == pytest.approx(2.0)
    assert 1.0 < out[30, 30] < 2.0


def test_patchwise_arguments_are_checked_by_name():
    """Kills T35 (a negative margin accepted), T36 (an empty patch list refused only by
    accident, as "rows uncovered"), T38 (a 3-D PSF accepted) and T39 (a 4-D image accepted
    until a reshape fails). Each is refused before any work with a message that says
    what is wrong."""
    img = np.zeros((64, 64), np.float32)
    patches = patch_grid(img.shape, (2, 2), 0.25)
    psfs = [np.ones((3, 3)) / 9] * 4
    work = []

    def deconvolve(s, p):
        work.append(1)
        return s

    for margin in (-1, 2.0, True):
        with pytest.raises(ValueError, match="margin must be a non-negative integer"):
            deconvolve_patchwise(img, patches, psfs, deconvolve, margin=margin)
    with pytest.raises(ValueError, match="no patches given"):
        deconvolve_patchwise(img, [], [], deconvolve)
    with pytest.raises(ValueError, match="every PSF must be 2-D"):
        deconvolve_patchwise(img, patches, psfs[:3] + [np.ones((3, 3, 1)) / 9], deconvolve)
    with pytest.raises(ValueError, match=r"image must have shape \(H, W\) or \(H, W, C\)"):
        deconvolve_patchwise(img[..., None, None], patches, psfs, deconvolve)
    assert work == []
