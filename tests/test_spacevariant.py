"""Tests for gyrodeblur.spacevariant: one interpolated-PSF model for the whole photo.

The physics test blurs a photo by warping (``simulate_blur``: the homographies of a
constant turn with strong roll, row by row under a rolling shutter), not by any PSF, and
deblurs it with the patch centres' PSFs, once patch by patch and once under the global
model.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.signal import fftconvolve
from skimage import data
from skimage.transform import resize

from conftest import constant_rate_capture
from gyrodeblur.deblur import deblur, deblur_with_psfs
from gyrodeblur.errors import InputError
from gyrodeblur.metrics import psnr
from gyrodeblur.simulate import add_noise, quantize_8bit, simulate_blur
from gyrodeblur.spacevariant import InterpolatedBlur, refine_globally
from gyrodeblur.tiling import Patch, patch_grid


def _random_model(rng, shape=(120, 170), grid=(3, 4)):
    patches = patch_grid(shape, grid, 0.25)
    psfs = [rng.random((2 * rng.integers(1, 8) + 1, 2 * rng.integers(1, 8) + 1))
            for _ in patches]
    return InterpolatedBlur(patches, psfs, shape)


def test_the_adjoint_is_the_transpose_of_the_forward_model():
    rng = np.random.default_rng(0)
    blur = _random_model(rng)
    u = rng.standard_normal(blur.padded_shape).astype(np.float32)
    g = rng.standard_normal(blur.shape).astype(np.float32)
    lhs = float(np.vdot(blur.forward(u), g))
    rhs = float(np.vdot(u, blur.adjoint(g)))
    assert abs(lhs - rhs) < 1e-4 * (abs(lhs) + 1.0), (lhs, rhs)


def test_a_closed_model_gives_the_same_answer_on_one_thread():
    rng = np.random.default_rng(4)
    with _random_model(rng) as blur:
        u, v = rng.standard_normal((2,) + blur.padded_shape).astype(np.float32)
        threaded = blur.forward(u).copy()
        blur.forward(v)                         # the work buffer now holds v's planes
    blur.close()                                # closing twice is harmless
    assert blur._pool is None
    np.testing.assert_array_equal(blur.forward(u), threaded)   # every plane filtered anew


def test_one_psf_everywhere_is_a_plain_convolution():
    rng = np.random.default_rng(1)
    k = rng.random((9, 13))
    shape = (120, 170)
    patches = patch_grid(shape, (3, 4), 0.25)
    blur = InterpolatedBlur(patches, [k] * len(patches), shape)
    u = rng.random(blur.padded_shape).astype(np.float32)
    p = blur.pad
    ref = fftconvolve(u, k / k.sum(), mode="same")[p:-p, p:-p]
    assert np.abs(blur.forward(u) - ref).max() < 1e-5


def test_the_psfs_are_interpolated_between_patch_centres():
    """A point source between two patch centres is blurred by the blend of their PSFs,
    in the proportion of the blending weights there."""
    shape = (40, 200)
    patches = patch_grid(shape, (1, 2), 0.5)
    left, right = np.zeros((5, 5)), np.zeros((5, 5))
    left[2, 0] = 1.0                                     # moves light 2 px left
    right[2, 4] = 1.0                                    # ... 2 px right
    blur = InterpolatedBlur(patches, [left, right], shape)
    u = np.zeros(blur.padded_shape, np.float32)
    y, x = 20, 100
    u[y + blur.pad, x + blur.pad] = 1.0
    out = blur.forward(u)
    from gyrodeblur.tiling import blend_weights
    (wy0, wx0), (wy1, wx1) = blend_weights(patches, shape)
    w_left = wx0[x - 2 - patches[0].x0]
    w_right = wx1[x + 2 - patches[1].x0]
    assert out[y, x - 2] == pytest.approx(w_left, abs=1e-6)
    assert out[y, x + 2] == pytest.approx(w_right, abs=1e-6)
    assert 0.2 < w_left < 0.8 and 0.2 < w_right < 0.8


def test_pixels_without_data_do_not_matter():
    rng = np.random.default_rng(2)
    blur = _random_model(rng)
    g = rng.random(blur.shape).astype(np.float32)
    ignore = np.zeros(blur.shape, bool)
    ignore[30:60, 40:90] = True
    spoiled = g.copy()
    spoiled[ignore] = 1.0
    a = refine_globally(g, g, blur, weight=1e-3, ignore=ignore)
    b = refine_globally(spoiled, g, blur, weight=1e-3, ignore=ignore)
    assert np.array_equal(a, b)
    c = refine_globally(spoiled, g, blur, weight=1e-3)
    assert not np.allclose(a, c, atol=1e-3)


def test_strong_roll_deblurs_better_under_the_global_model():
    """A turn with strong roll (blur from ~5 px at the centre to ~20 px at the corners)
    and a 20 ms readout, synthesised by warping: the global model beats patch-wise
    deconvolution with the same PSFs (measured: 23.83 -> 25.32 dB; blurred 14.25)."""
    sharp = resize(data.astronaut(), (240, 320), anti_aliasing=True).astype(np.float32)
    cap = constant_rate_capture((0.3, 0.5, 1.5), exposure=0.05, readout=0.02)
    blurred = quantize_8bit(add_noise(simulate_blur(sharp, cap, transfer="srgb"), 40.0, seed=1))
    b = 16
    before = psnr(sharp, blurred, b)
    patches = psnr(sharp, deblur(blurred, cap, model="patches"), b)
    whole = psnr(sharp, deblur(blurred, cap), b)                 # the default
    assert patches > before + 6.0, (before, patches)
    assert whole > patches + 0.75, (patches, whole)


def test_the_model_is_checked_and_one_patch_needs_no_global_model(make_capture):
    cap = make_capture((0.0, 0.2, 0.0))
    img = np.full((240, 320), 0.5, np.float32)
    with pytest.raises(InputError, match="sparse method"):
        deblur(img, cap, method="wiener", model="global")
    with pytest.raises(InputError, match="unknown model"):
        deblur(img, cap, model="eff")
    k = np.ones((3, 3))
    uneven = [Patch(0, 240, 0, 200), Patch(0, 240, 150, 320)]
    with pytest.raises(InputError, match="equal windows"):
        deblur_with_psfs(img, uneven, [k, k], model="global")
    _, report = deblur(img, cap, grid=(2, 2), return_report=True, iterations=1)
    assert report.model == "global"
    _, report = deblur(img, cap, grid=(2, 2), model="patches", return_report=True,
                       iterations=1)
    assert report.model == "patches"
    whole = [Patch(0, 240, 0, 320)]                  # one patch: already one model
    a = deblur_with_psfs(img, whole, [k], model="global")
    assert np.array_equal(a, deblur_with_psfs(img, whole, [k], model="patches"))


def test_the_default_model_depends_on_the_photo_size(monkeypatch):
    """Global up to GLOBAL_DEFAULT_MAX_PIXELS, patch-wise above (the 12 MP time budget);
    asked for, global at any size."""
    import gyrodeblur.deblur as deblur_mod
    rng = np.random.default_rng(5)
    shape = (96, 128)
    img = np.clip(0.5 + 0.2 * rng.standard_normal(shape), 0, 1).astype(np.float32)
    patches = patch_grid(shape, (2, 2), 0.25)
    psfs = [np.ones((1, 2 * i + 3)) for i in range(len(patches))]
    run = {m: deblur_with_psfs(img, patches, psfs, model=m, iterations=2)
           for m in ("global", "patches")}
    assert not np.array_equal(run["global"], run["patches"])
    np.testing.assert_array_equal(deblur_with_psfs(img, patches, psfs, iterations=2),
                                  run["global"])
    monkeypatch.setattr(deblur_mod, "GLOBAL_DEFAULT_MAX_PIXELS", shape[0] * shape[1] - 1)
    np.testing.assert_array_equal(deblur_with_psfs(img, patches, psfs, iterations=2),
                                  run["patches"])
    np.testing.assert_array_equal(
        deblur_with_psfs(img, patches, psfs, model="global", iterations=2), run["global"])


def test_refine_globally_refuses_bad_settings():
    rng = np.random.default_rng(3)
    blur = _random_model(rng)
    g = rng.random(blur.shape).astype(np.float32)
    with pytest.raises(ValueError, match="outer"):
        refine_globally(g, g, blur, weight=1e-3, outer=0)
    with pytest.raises(ValueError, match="weight"):
        refine_globally(g, g, blur, weight=0.0)
    with pytest.raises(ValueError, match="differ"):
        refine_globally(g[:-1], g[:-1], blur, weight=1e-3)


def test_patches_and_psfs_may_be_given_as_iterators():
    """The model is chosen from the patches without using up an iterator of them."""
    img = np.full((96, 128), 0.5, np.float32)
    patches = patch_grid(img.shape, (2, 2), 0.25)
    psfs = [np.ones((1, 3))] * len(patches)
    np.testing.assert_array_equal(
        deblur_with_psfs(img, iter(patches), iter(psfs), iterations=1),
        deblur_with_psfs(img, patches, psfs, iterations=1))


# ------------------------------------------------ from a mutation audit (session 43)

def _delta_model(shape=(40, 56)):
    from gyrodeblur.spacevariant import InterpolatedBlur
    from gyrodeblur.tiling import patch_grid

    patches = patch_grid(shape, (2, 2), 0.25)
    return InterpolatedBlur(patches, [np.ones((1, 1))] * len(patches), shape)


def test_the_u_step_solves_the_normal_equations():
    """Kills V4 (CG degraded to steepest descent: ``d = r``) and V1 (the periodic wrap
    of ``_add_grad_t_grad`` dropped). From a flat start the first w-step gives w = 0, so
    one outer iteration's u-step solves ``(P^T P + rho grad^T grad) u = P^T g`` (delta
    PSFs: ``A`` is the crop ``P`` of the padded unknown to the photo; periodic
    differences; ``rho = beta0 weight``, the first penalty). Against a sparse direct solve: CG reaches it to
    3e-7 in 40 steps (steepest descent 5e-4; without the wrap 0.13)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from gyrodeblur.spacevariant import _BETA0, refine_globally

    rng = np.random.default_rng(0)
    blur = _delta_model()
    shape, (Hp, Wp), p = blur.shape, blur.padded_shape, blur.pad
    g = rng.random(shape).astype(np.float32)
    weight = 0.1

    def periodic_laplacian_1d(n):
        m = (2 * sp.eye(n) - sp.eye(n, k=1) - sp.eye(n, k=-1)).tolil()
        m[0, n - 1] = m[n - 1, 0] = -1
        return m.tocsr()

    lap = (sp.kron(periodic_laplacian_1d(Hp), sp.eye(Wp))
           + sp.kron(sp.eye(Hp), periodic_laplacian_1d(Wp)))
    inside = np.zeros((Hp, Wp))
    inside[p:p + shape[0], p:p + shape[1]] = 1.0
    gp = inside.copy()
    gp[p:p + shape[0], p:p + shape[1]] = g
    ref = spsolve((sp.diags(inside.ravel()) + _BETA0 * weight * lap).tocsc(), gp.ravel())
    ref = ref.reshape(Hp, Wp)[p:p + shape[0], p:p + shape[1]]
    out = refine_globally(g, np.full(shape, 0.5, np.float32), blur, weight=weight,
                          outer=1, cg_steps=40)
    assert np.abs(out - ref).max() < 2e-5


def test_at_least_pixels_far_below_the_estimate_have_no_data_term():
    """Kills V5 (the one-sided active set inverted: ``<= g``). A pixel at the clip value
    asks only ``A u >= g``: where ``g`` lies far below anything ``A u`` reaches (-1 here,
    the photo and PSFs being non-negative) it constrains nothing, exactly as an ignored
    pixel."""
    from gyrodeblur.spacevariant import InterpolatedBlur, refine_globally
    from gyrodeblur.tiling import patch_grid

    rng = np.random.default_rng(3)
    shape = (64, 80)
    patches = patch_grid(shape, (2, 2), 0.25)
    blur = InterpolatedBlur(patches, [rng.random((5, 7)) for _ in patches], shape)
    g = rng.random(shape).astype(np.float32)
    mask = np.zeros(shape, bool)
    mask[20:40, 30:50] = True
    low = g.copy()
    low[mask] = -1.0
    a = refine_globally(low, g, blur, weight=1e-3, outer=3, at_least=mask)
    b = refine_globally(g, g, blur, weight=1e-3, outer=3, ignore=mask)
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_fixed_pixels_keep_their_start_values():
    """Kills V7 (the first CG residual not zeroed on the held pixels, so the first step
    moves them). ``fixed`` pixels are held at ``start``'s values, exactly."""
    from gyrodeblur.spacevariant import InterpolatedBlur, refine_globally
    from gyrodeblur.tiling import patch_grid

    rng = np.random.default_rng(4)
    shape = (64, 80)
    patches = patch_grid(shape, (2, 2), 0.25)
    blur = InterpolatedBlur(patches, [rng.random((5, 7)) for _ in patches], shape)
    g = rng.random(shape).astype(np.float32)
    start = ndimage.uniform_filter(g, 5)
    fixed = np.zeros(shape, bool)
    fixed[25:35, 30:42] = True
    out = refine_globally(g, start, blur, weight=1e-3, outer=2, fixed=fixed)
    np.testing.assert_array_equal(out[fixed], start[fixed])
    assert np.abs(out - start)[~fixed].max() > 1e-2          # the rest did move


# ------------------------------------------------ from a mutation audit (session 44)

def test_the_model_default_and_report_follow_the_documented_rules(monkeypatch):
    """Kills three mutants of ``_check_model``: a photo of exactly
    GLOBAL_DEFAULT_MAX_PIXELS is still "at most" it (global); patches of unequal windows
    default to patch-wise (the global model needs patch_grid's equal windows); and one
    patch covering the photo reports "patches" even when "global" was asked for."""
    import gyrodeblur.deblur as deblur_mod
    from gyrodeblur.deblur import _check_model

    shape = (96, 128)
    grid = patch_grid(shape, (2, 2), 0.25)
    monkeypatch.setattr(deblur_mod, "GLOBAL_DEFAULT_MAX_PIXELS", shape[0] * shape[1])
    assert _check_model(None, "sparse", grid, shape) == "global"
    uneven = [Patch(0, 96, 0, 80), Patch(0, 96, 60, 128)]
    assert _check_model(None, "sparse", uneven, shape) == "patches"
    img = np.clip(0.5 + 0.2 * np.random.default_rng(1).standard_normal(shape), 0, 1)
    img = img.astype(np.float32)
    psfs = [np.ones((1, 3)), np.ones((3, 1))]
    np.testing.assert_array_equal(deblur_with_psfs(img, uneven, psfs, iterations=2),
                                  deblur_with_psfs(img, uneven, psfs, model="patches",
                                                   iterations=2))
    cap = constant_rate_capture((0.0, 0.2, 0.0), width=128, height=96, f=120.0)
    _, report = deblur(img, cap, grid=(1, 1), model="global", iterations=1,
                       return_report=True)
    assert report.model == "patches"


def test_deblur_with_psfs_never_clips_the_caller_s_photo():
    """Kills dropping the copy in ``deblur_with_psfs``: a method that hands its input back
    (one patch, linear light) must not let the clip to [0, 1] reach the caller's array."""
    from gyrodeblur.deblur import METHODS, register_method

    register_method("as-is", lambda image: (lambda sub, psf: sub))
    try:
        photo = np.full((40, 50), 0.5, np.float32)
        photo[5, 5], photo[20, 30] = -0.1, 1.4
        before = photo.copy()
        out = deblur_with_psfs(photo, [Patch(0, 40, 0, 50)], [np.ones((1, 1))],
                               method="as-is", transfer="linear")
        assert out.min() == 0.0 and out.max() == 1.0
        np.testing.assert_array_equal(photo, before)
    finally:
        METHODS.pop("as-is")


# ------------------------------------------------ from a mutation audit (session 46)

def _transposable_case(rng):
    """A 2 x 3 grid of random 5 x 7 PSFs on a 48 x 64 photo, and the same model transposed
    (a 3 x 2 grid on 64 x 48, each PSF transposed, in its row-major place)."""
    shape = (48, 64)
    patches = patch_grid(shape, (2, 3), 0.25)
    psfs = [rng.random((5, 7)) for _ in patches]
    flipped = [psfs[i * 3 + j].T for j in range(3) for i in range(2)]
    return (InterpolatedBlur(patches, psfs, shape),
            InterpolatedBlur(patch_grid(shape[::-1], (3, 2), 0.25), flipped, shape[::-1]))


@pytest.mark.parametrize("exponent", [1.0, 2 / 3])
def test_rows_and_columns_are_treated_alike(exponent):
    """The model, the prior and the splitting are symmetric in x and y: the transposed
    problem has the transposed answer, to float32 rounding (mean 5e-7). Kills the x dual
    updated with ``+ w`` (mean 0.006) and the y shrinkage taking p = 1 (0.017 at p = 2/3).
    The mean, not the largest difference: for p < 1 the shrinkage jumps at its threshold,
    where rounding may tip a pixel either way (one such pixel moved by 0.0025 in a trial)."""
    rng = np.random.default_rng(7)
    blur, blur_t = _transposable_case(rng)
    g = rng.random(blur.shape).astype(np.float32)
    start = ndimage.uniform_filter(g, 3)
    kw = dict(weight=3e-3, exponent=exponent, outer=4)
    with blur, blur_t:
        out = refine_globally(g, start, blur, **kw)
        flipped = refine_globally(np.ascontiguousarray(g.T), np.ascontiguousarray(start.T),
                                  blur_t, **kw)
    assert np.abs(flipped.T - out).mean() < 1e-4


def test_psfs_of_different_sizes_are_centred_in_the_common_support():
    """A 1 x 1 delta and a 7 x 7 centred delta are the same PSF: the model is the crop of
    the unknown to the photo wherever the patches' weights put either of them."""
    shape = (48, 64)
    patches = patch_grid(shape, (2, 2), 0.25)
    wide = np.zeros((7, 7))
    wide[3, 3] = 1.0
    psfs = [np.ones((1, 1)), wide, wide, np.ones((1, 1))]
    with InterpolatedBlur(patches, psfs, shape) as blur:
        u = np.random.default_rng(3).random(blur.padded_shape).astype(np.float32)
        p = blur.pad
        np.testing.assert_allclose(blur.forward(u), u[p:-p, p:-p], atol=1e-6)


def test_one_sided_pixels_are_each_channel_s_own():
    """``at_least`` of shape (H, W, C): channel c is solved with its own plane of it, as if
    alone. Kills every channel taking channel 0's one-sided pixels."""
    rng = np.random.default_rng(3)
    shape = (64, 80)
    patches = patch_grid(shape, (2, 2), 0.25)
    g = rng.random(shape + (3,)).astype(np.float32)
    at_least = np.zeros(g.shape, bool)
    at_least[20:40, 30:50, 1] = True
    at_least[5:15, 5:25, 2] = True
    g[at_least] = -1.0                     # below anything A u reaches: no data there
    with InterpolatedBlur(patches, [rng.random((5, 7)) for _ in patches], shape) as blur:
        out = refine_globally(g, g, blur, weight=1e-3, outer=2, at_least=at_least)
        for c in range(3):
            alone = refine_globally(g[..., c], g[..., c], blur, weight=1e-3, outer=2,
                                    at_least=at_least[..., c])
            np.testing.assert_array_equal(out[..., c], alone)


def test_pixels_without_data_do_not_matter_beside_one_sided_ones():
    """``ignore`` still holds when some pixels are one-sided (whose active set is rebuilt
    each iteration): the ignored pixels' values change nothing. Kills the rebuilt mask
    starting from all ones."""
    rng = np.random.default_rng(2)
    blur = _random_model(rng)
    g = rng.random(blur.shape).astype(np.float32)
    ignore = np.zeros(blur.shape, bool)
    ignore[30:60, 40:90] = True
    at_least = np.zeros(blur.shape, bool)
    at_least[80:100, 100:140] = True
    spoiled = g.copy()
    spoiled[ignore] = 1.0
    kw = dict(weight=1e-3, outer=2, ignore=ignore, at_least=at_least)
    with blur:
        np.testing.assert_array_equal(refine_globally(g, g, blur, **kw),
                                      refine_globally(spoiled, g, blur, **kw))


def test_progress_counts_the_iterations_over_the_channels():
    rng = np.random.default_rng(6)
    calls = []
    with _random_model(rng) as blur:
        g = rng.random(blur.shape + (3,)).astype(np.float32)
        refine_globally(g, g, blur, weight=1e-3, outer=2, cg_steps=1, progress=calls.append)
    assert calls == [1, 2, 3, 4, 5, 6]


def test_the_penalty_starts_where_the_patch_solver_ends_and_grows_to_64(monkeypatch):
    """The continuation of ``_BETA0``'s comment: beta starts at the patch-wise solver's
    last (32), grows 1.5x per iteration, at most 64 (one shrinkage per direction)."""
    import gyrodeblur.spacevariant as sv

    seen = []
    shrink = sv._shrink_residual
    monkeypatch.setattr(sv, "_shrink_residual",
                        lambda z, beta, p, out: seen.append(beta) or shrink(z, beta, p, out))
    rng = np.random.default_rng(8)
    with _random_model(rng) as blur:
        g = rng.random(blur.shape).astype(np.float32)
        refine_globally(g, g, blur, weight=1e-3, outer=5, cg_steps=1)
    assert seen == [b for b in (32.0, 48.0, 64.0, 64.0, 64.0) for _ in "xy"]


def test_the_refinement_budget_grows_with_the_longest_psf():
    """Base budget up to 32 px, both counts in proportion beyond, twice at most."""
    from gyrodeblur.spacevariant import DEFAULT_CG_STEPS, DEFAULT_OUTER, refinement_budget

    assert refinement_budget(1) == refinement_budget(32) == (DEFAULT_OUTER, DEFAULT_CG_STEPS)
    assert refinement_budget(48) == (9, 8)          # 1.5 x 6, 1.5 x 5 rounded half to even
    assert refinement_budget(64) == refinement_budget(400) == (12, 10)
    for bad in (0, -3, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="extent"):
            refinement_budget(bad)
    for bad in (None, "41", True):                  # not numbers: arguments.check_real's
        with pytest.raises(TypeError, match="extent"):
            refinement_budget(bad)


def test_the_model_knows_its_longest_psf_and_sets_the_default_budget(monkeypatch):
    import gyrodeblur.spacevariant as sv

    shape = (120, 170)
    patches = patch_grid(shape, (2, 2), 0.25)
    psfs = [np.ones((1, 1))] * 3 + [np.pad(np.ones((1, 41)), ((0, 0), (5, 5)))]  # 41 px
    seen = []
    monkeypatch.setattr(sv, "_solve_channel",
                        lambda g, u0, blur, weight, p, outer, steps, *a: seen.append(
                            (outer, steps)) or u0)
    with InterpolatedBlur(patches, psfs, shape) as blur:
        assert blur.extent == 41
        g = np.zeros(shape, np.float32)
        refine_globally(g, g, blur, weight=1e-3)
        refine_globally(g, g, blur, weight=1e-3, outer=2, cg_steps=3)
    assert seen == [sv.refinement_budget(41), (2, 3)] == [(8, 6), (2, 3)]


def test_a_long_blur_gains_from_the_longer_refinement(monkeypatch):
    """A 0.2 s exposure of a steady turn (41 px at the centre, longer towards the
    corners), synthesised by warping: the budget that grows with the PSFs' extent beats
    the short-blur budget (measured: 19.19 -> 19.61 dB; blurred 10.83)."""
    import gyrodeblur.spacevariant as sv

    sharp = resize(data.astronaut(), (240, 320), anti_aliasing=True).astype(np.float32)
    cap = constant_rate_capture((0.6, 0.3, 0.3), exposure=0.2, readout=0.02, duration=0.4)
    blurred = quantize_8bit(add_noise(simulate_blur(sharp, cap, transfer="srgb"), 40.0, seed=1))
    calls = []
    out, report = deblur(blurred, cap, progress=lambda *a: calls.append(a),
                         return_report=True)
    grown = psnr(sharp, out, 16)
    done, total = calls[-1]
    assert done == total and {t for _, t in calls} == {total}  # the count announced, reached
    outer = (total - int(np.prod(report.grid))) / 3            # per channel, after the patches
    assert outer == round(outer) and outer > sv.DEFAULT_OUTER, (total, report.grid)
    monkeypatch.setattr(sv, "refinement_budget", lambda extent: (6, 5))
    short = psnr(sharp, deblur(blurred, cap), 16)
    assert short > psnr(sharp, blurred, 16) + 6.0, short
    assert grown > short + 0.25, (short, grown)
