"""Tests for single-image blind deconvolution (gyrodeblur.blind)."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from scipy import ndimage, signal

from gyrodeblur import blind
from gyrodeblur.blind import _wiener, blind_deconvolve, estimate_kernel
from gyrodeblur.errors import InputError

NOISE = 0.005


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sharp() -> np.ndarray:
    """A 256x256 grey natural image in [0, 1] (scikit-image's camera, downsized)."""
    from skimage import data
    from skimage.transform import resize

    img = data.camera().astype(np.float32) / 255.0
    return resize(img, (256, 256), anti_aliasing=True).astype(np.float32)


@pytest.fixture
def levin(shared_data) -> dict[str, np.ndarray]:
    """Levin et al. 2009 camera-shake kernels, each re-centred on its centre of mass."""
    path = shared_data / "kernels" / "levin2009.npz"
    if not path.is_file():
        pytest.skip(f"Levin 2009 kernels not found at {path}")
    with np.load(path) as npz:
        return {name: _centred(npz[name]) for name in npz.files}


def _centred(k: np.ndarray) -> np.ndarray:
    """Shift a kernel by whole pixels so that its centroid is the centre sample."""
    k = np.asarray(k, dtype=np.float64)
    k = k / k.sum()
    yy, xx = np.indices(k.shape)
    cy, cx = (yy * k).sum(), (xx * k).sum()
    ny, nx = np.nonzero(k > 0)
    half = int(np.ceil(max(np.abs(ny - cy).max(), np.abs(nx - cx).max()))) + 1
    out = np.zeros((2 * half + 1, 2 * half + 1))
    oy, ox = half - int(round(cy)), half - int(round(cx))
    out[ny + oy, nx + ox] = k[ny, nx]
    return out.astype(np.float32)


def _blur(img: np.ndarray, k: np.ndarray, sigma: float = NOISE, seed: int = 0) -> np.ndarray:
    blurred = ndimage.convolve(img, k, mode="reflect")
    noise = sigma * np.random.default_rng(seed).standard_normal(img.shape)
    return np.clip(blurred + noise, 0, 1).astype(np.float32)


def _support(k: np.ndarray, margin: int = 4) -> int:
    return k.shape[0] + margin + 1 - (k.shape[0] + margin) % 2


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Largest normalised cross-correlation over all relative shifts (kernels are only
    defined up to a shift)."""
    a = np.asarray(a, np.float64) - np.mean(a)
    b = np.asarray(b, np.float64) - np.mean(b)
    n = max(a.shape[0], b.shape[0])
    a = np.pad(a, (n - a.shape[0]) // 2)
    b = np.pad(b, (n - b.shape[0]) // 2)
    return float(signal.correlate(a, b).max() / (np.linalg.norm(a) * np.linalg.norm(b)))


def _psnr(x: np.ndarray, ref: np.ndarray, max_shift: int = 2) -> float:
    """PSNR of ``x`` against ``ref`` at the best whole-pixel shift up to ``max_shift``
    (the estimated kernel's registration is arbitrary up to rounding of its centroid);
    8-pixel borders excluded."""
    m = 8
    h, w = ref.shape
    core = ref[m:h - m, m:w - m]
    x = np.clip(x, 0, 1)
    best = -np.inf
    for dy in range(-max_shift, max_shift + 1):
        for dx in range(-max_shift, max_shift + 1):
            mse = np.mean((x[m + dy:h - m + dy, m + dx:w - m + dx] - core) ** 2)
            best = max(best, 10 * np.log10(1.0 / mse))
    return float(best)


def _assert_valid_psf(psf: np.ndarray, size: int) -> None:
    assert psf.shape == (size, size)
    assert psf.dtype == np.float32
    assert psf.min() >= 0
    assert psf.sum() == pytest.approx(1.0, abs=1e-5)


# --------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [4, 1, -3, 2, 129, 301, 9.0, True, "15"])
def test_bad_kernel_size_raises_input_error_naming_the_argument(size):
    img = np.zeros((256, 258), np.float32)
    with pytest.raises(InputError, match="^kernel_size: ") as err:
        estimate_kernel(img, size)
    assert err.value.source == "kernel_size" and err.value.argument


def test_kernel_size_just_under_half_the_image_is_accepted():
    img = np.random.default_rng(1).random((40, 60), dtype=np.float32)
    _assert_valid_psf(estimate_kernel(img, 19, iterations=1), 19)


def test_bad_init_psf_and_image_shape_raise_value_error():
    img = np.zeros((64, 64), np.float32)
    with pytest.raises(ValueError, match="init_psf"):
        estimate_kernel(img, 9, init_psf=np.ones((4, 4)))
    with pytest.raises(ValueError, match="init_psf"):
        estimate_kernel(img, 9, init_psf=-np.ones((3, 3)))
    with pytest.raises(ValueError, match="image"):
        estimate_kernel(np.zeros((4, 64, 64, 3), np.float32), 9)


# --------------------------------------------------------------------------------------
# properties
# --------------------------------------------------------------------------------------
def test_sharp_image_gives_kernel_concentrated_at_centre(sharp):
    g = np.clip(sharp + NOISE * np.random.default_rng(2).standard_normal(sharp.shape), 0, 1)
    psf = estimate_kernel(g.astype(np.float32), 21)
    _assert_valid_psf(psf, 21)
    r = np.hypot(*(np.indices(psf.shape) - 10))
    assert psf[r <= 2].sum() > 0.9
    assert np.unravel_index(psf.argmax(), psf.shape) in {(y, x) for y in (9, 10, 11)
                                                          for x in (9, 10, 11)}


def test_colour_input_is_estimated_on_luminance(sharp, levin):
    k = levin["levin_5"]
    g = _blur(sharp, k)
    # a colour photo whose Rec. 709 luma is exactly g, while its green channel and its
    # channel mean carry the strong edges of another scene (a texture in the luma's null
    # space): an estimate from either would differ
    other = np.ascontiguousarray(np.rot90(sharp), np.float32)
    rgb = np.stack([g, g, g], axis=2)
    rgb[..., 0] += 0.5 * other
    rgb[..., 1] -= 0.5 * other * 0.2126 / 0.7152
    luma = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    np.testing.assert_allclose(luma, g, atol=1e-5)
    assert np.abs(rgb[..., 1] - g).max() > 0.1 and np.abs(rgb.mean(axis=2) - g).max() > 0.1
    a = estimate_kernel(rgb, 17, levels=2, iterations=2)
    b = estimate_kernel(g, 17, levels=2, iterations=2)
    # the luma is g only to a unit in the last place (numpy 2.4's float32 matmul rounds
    # some pixels the other way), and the estimator's discrete steps can turn such a
    # difference into up to 6e-4 (seen: 1-ulp changes of 30 % of g's pixels moved one of
    # four trials that far, the others 2e-6); an estimate from the green channel or the
    # channel mean is 0.06-0.07 away
    np.testing.assert_allclose(a, b, atol=2e-3)
    for wrong in (rgb[..., 1], rgb.mean(axis=2)):
        other_estimate = estimate_kernel(np.clip(wrong, 0, 1), 17, levels=2, iterations=2)
        assert np.abs(other_estimate - b).max() > 10 * 2e-3


def test_estimated_kernel_is_recentred(sharp, levin):
    k = levin["levin_6"]
    # an off-centre blur: the same kernel shifted by (+3, -2) pixels inside its support
    shifted = np.zeros((k.shape[0] + 8,) * 2, np.float32)
    shifted[7:7 + k.shape[0], 2:2 + k.shape[1]] = k
    psf = estimate_kernel(_blur(sharp, shifted), _support(shifted, 0))
    yy, xx = np.indices(psf.shape)
    c = psf.shape[0] // 2
    assert abs((yy * psf).sum() - c) <= 0.5 + 1e-4
    assert abs((xx * psf).sum() - c) <= 0.5 + 1e-4


# --------------------------------------------------------------------------------------
# recovering real camera-shake kernels
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["levin_3", "levin_8"])
def test_levin_kernel_is_recovered_and_deblurring_helps(sharp, levin, name):
    k = levin[name]
    g = _blur(sharp, k)
    size = _support(k)
    restored, psf = blind_deconvolve(g, size, deconvolve=_wiener)
    _assert_valid_psf(psf, size)
    assert restored.shape == g.shape and restored.dtype == np.float32
    assert _ncc(psf, k) > 0.75
    assert _psnr(restored, sharp) > _psnr(g, sharp) + 1.0


def _drawn_shake_kernel(size: int = 15, seed: int = 11) -> np.ndarray:
    """A camera-shake-like kernel that needs no shared data: a smooth random trajectory
    (integrated random acceleration) splatted bilinearly onto a ``size`` grid, centred on
    its centre of mass."""
    rng = np.random.default_rng(seed)
    vel = np.cumsum(rng.normal(0, 1, (400, 2)), axis=0)
    path = np.cumsum(vel, axis=0)
    path -= path.mean(axis=0)
    path *= (size // 2 - 2) / np.abs(path).max()
    k = np.zeros((size, size))
    for x, y in path + size // 2:
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    return _centred(k)


def test_a_drawn_shake_kernel_is_recovered_without_shared_data(sharp):
    k = _drawn_shake_kernel()
    assert k.shape[0] >= 9 and (k > 0.01 * k.max()).sum() > 12       # a streak, not a dot
    g = _blur(sharp, k)
    size = _support(k)
    restored, psf = blind_deconvolve(g, size, deconvolve=_wiener)
    _assert_valid_psf(psf, size)
    assert _ncc(psf, k) > 0.75
    assert _psnr(restored, sharp) > _psnr(g, sharp) + 1.0


def test_init_with_true_kernel_stays_close(sharp, levin):
    k = levin["levin_2"]
    g = _blur(sharp, k)
    size = _support(k)
    psf = estimate_kernel(g, size, init_psf=k)
    _assert_valid_psf(psf, size)
    assert _ncc(psf, k) > 0.85
    # registration is kept: centroid where the initial kernel's is (to a pixel)
    yy, xx = np.indices(psf.shape)
    assert abs((yy * psf).sum() - size // 2) <= 1.0
    assert abs((xx * psf).sum() - size // 2) <= 1.0


def test_init_psf_larger_than_support_is_cropped_about_its_centre(sharp, levin):
    k = levin["levin_5"]
    size = _support(k)
    big = np.pad(k, 10)
    # the kernel padded by 10 on every side comes back as itself in the support
    np.testing.assert_allclose(blind._fit_support(big, size),
                               np.pad(k, (size - k.shape[0]) // 2), atol=1e-6)
    # a larger kernel cropped keeps its centre 7 x 7 samples, renormalised
    wide = np.random.default_rng(5).random((31, 31)).astype(np.float32)
    np.testing.assert_allclose(blind._fit_support(wide, 7),
                               wide[12:19, 12:19] / wide[12:19, 12:19].sum(), rtol=1e-5)
    g = _blur(sharp, k)
    psf = estimate_kernel(g, size, init_psf=big, iterations=2)
    _assert_valid_psf(psf, size)
    assert _ncc(psf, k) > 0.8


# --------------------------------------------------------------------------------------
# final non-blind step
# --------------------------------------------------------------------------------------
def _tiny_photo(colour: bool = False) -> np.ndarray:
    rng = np.random.default_rng(3)
    img = ndimage.gaussian_filter(rng.random((64, 64)), 1.5).astype(np.float32)
    return np.repeat(img[..., None], 3, axis=2) if colour else img


def test_custom_deconvolve_is_called_with_image_and_psf():
    seen = {}

    def fake(image, psf):
        seen["args"] = (image.shape, psf.shape)
        return image * 0 + 0.5

    img = _tiny_photo(colour=True)
    restored, psf = blind_deconvolve(img, 7, deconvolve=fake, levels=1, iterations=1)
    assert seen["args"] == ((64, 64, 3), (7, 7))
    assert np.all(restored == 0.5)


def test_default_deconvolve_prefers_sparse_module(monkeypatch):
    fake = types.ModuleType("gyrodeblur.sparse")
    fake.sparse_deconvolve = lambda image, psf: np.full_like(image, 0.25)
    monkeypatch.setitem(sys.modules, "gyrodeblur.sparse", fake)
    restored, _ = blind_deconvolve(_tiny_photo(), 7, levels=1, iterations=1)
    assert np.all(restored == 0.25)


def test_default_deconvolve_falls_back_to_wiener_then_builtin(monkeypatch):
    monkeypatch.setitem(sys.modules, "gyrodeblur.sparse", None)  # import fails
    fake = types.ModuleType("gyrodeblur.wiener")
    fake.wiener_deconvolve = lambda image, psf: np.full_like(image, 0.75)
    monkeypatch.setitem(sys.modules, "gyrodeblur.wiener", fake)
    assert blind._default_deconvolve()(np.zeros((8, 8), np.float32), np.ones((1, 1)))[0, 0] == 0.75
    monkeypatch.setitem(sys.modules, "gyrodeblur.wiener", None)
    assert blind._default_deconvolve() is _wiener


def test_builtin_wiener_properties():
    img = _tiny_photo(colour=True)
    delta = np.zeros((5, 5), np.float32)
    delta[2, 2] = 1
    out = _wiener(img, delta)
    assert out.shape == img.shape and out.dtype == np.float32
    np.testing.assert_allclose(out, img, atol=2e-3)
    flat = np.full((40, 50), 0.3, np.float32)
    box = np.full((5, 5), 1 / 25, np.float32)
    np.testing.assert_allclose(_wiener(flat, box), flat, atol=1e-5)


def test_builtin_wiener_undoes_an_asymmetric_blur(sharp):
    """A one-sided streak (an L: 6 px right, then 4 px down) is undone, and the same
    filter with the kernel turned 180 degrees (the conjugate dropped) does far worse."""
    k = np.zeros((11, 11), np.float32)
    k[5, 5:11] = 1.0
    k[6:10, 10] = 1.0
    k /= k.sum()
    g = _blur(sharp, k, sigma=0.002)
    restored = _wiener(g, k)
    turned = _wiener(g, k[::-1, ::-1].copy())
    assert _psnr(restored, sharp, 0) > _psnr(g, sharp, 0) + 3.0
    assert _psnr(restored, sharp, 0) > _psnr(turned, sharp, 3) + 3.0


# --------------------------------------------------------------------------------------
# operators the solvers rely on (dot tests)
# --------------------------------------------------------------------------------------
def test_gradient_matches_its_otf_and_adjoint():
    from gyrodeblur.fftutils import psf_to_otf

    rng = np.random.default_rng(4)
    u = rng.standard_normal((20, 26)).astype(np.float32)
    ux, uy = blind._grad(u)
    dx = psf_to_otf(np.array([[1.0, -1.0, 0.0]]), u.shape)
    dy = psf_to_otf(np.array([[1.0], [-1.0], [0.0]]), u.shape)
    np.testing.assert_allclose(np.fft.rfft2(ux), dx * np.fft.rfft2(u), atol=1e-4)
    np.testing.assert_allclose(np.fft.rfft2(uy), dy * np.fft.rfft2(u), atol=1e-4)
    px, py = rng.standard_normal((2, 20, 26)).astype(np.float32)
    lhs = np.vdot(ux, px) + np.vdot(uy, py)
    rhs = np.vdot(u, blind._grad_adjoint(px, py))
    assert lhs == pytest.approx(rhs, rel=1e-5)


def test_kernel_normal_equations_dot_test():
    from gyrodeblur.fftutils import convolve_fft

    rng = np.random.default_rng(5)
    ux, uy, yx, yy = rng.standard_normal((4, 24, 28)).astype(np.float32)
    h = rng.standard_normal((5, 5)).astype(np.float32)
    auto, b = blind._kernel_normal_equations(ux, uy, np.fft.rfft2(yx), np.fft.rfft2(yy), 2)
    # <A h, y> == <h, A^T y>
    lhs = np.vdot(convolve_fft(ux, h), yx) + np.vdot(convolve_fft(uy, h), yy)
    assert lhs == pytest.approx(np.vdot(h, b), rel=1e-4)
    # A^T A h through the autocorrelation == A^T applied to A h
    _, atah = blind._kernel_normal_equations(ux, uy, np.fft.rfft2(convolve_fft(ux, h)),
                                             np.fft.rfft2(convolve_fft(uy, h)), 2)
    np.testing.assert_allclose(blind._normal_apply(auto, h), atah, rtol=1e-4, atol=1e-3)


def test_flat_image_gives_a_delta():
    psf = estimate_kernel(np.full((64, 64), 0.4, np.float32), 9)
    _assert_valid_psf(psf, 9)
    assert psf[4, 4] == pytest.approx(1.0)


@pytest.mark.parametrize("bad, problem", [
    (lambda g: (g * 255).astype(np.uint8), "floating-point values in \\[0, 1\\]"),
    (lambda g: g * 255, "image"),
    (lambda g: g > 0.5, "floating-point"),
    (lambda g: np.where(g > 0.5, np.nan, g), "NaN"),
])
def test_a_photo_that_is_not_one_in_0_1_is_refused(sharp, bad, problem):
    """Integers, 255-scaled floats, booleans and NaN gave a kernel, wrong, without a word."""
    with pytest.raises(InputError, match=problem):
        estimate_kernel(bad(sharp), 9)


def test_grey_and_alpha_is_estimated_on_the_grey(sharp, levin):
    g = _blur(sharp, levin["levin_3"])
    alpha = np.random.default_rng(7).random(g.shape).astype(np.float32)
    np.testing.assert_array_equal(estimate_kernel(np.dstack([g, alpha]), 17, levels=2,
                                                  iterations=2),
                                  estimate_kernel(g, 17, levels=2, iterations=2))


@pytest.mark.parametrize("option, value", [
    ("cleanup", 2.0), ("cleanup", 1.0), ("edge_decay", 0.0), ("kernel_reg", float("nan")),
    ("iterations", 2.7), ("iterations", "x"), ("levels", 0), ("lambda_decay", 1.5),
    ("lambda_grad", -1.0), ("edge_pixels", True),
])
def test_options_out_of_range_are_refused_by_name(option, value):
    img = np.random.default_rng(8).random((64, 64)).astype(np.float32)
    with pytest.raises((ValueError, TypeError), match=option):
        estimate_kernel(img, 9, **{option: value})


# ------------------------------------------------ from a mutation audit (session 44)

def test_a_refined_kernel_keeps_the_initial_kernel_s_registration(sharp):
    """Kills re-centring a refinement on the centre sample: with ``init_psf`` the result's
    centre of mass falls on ``init_psf``'s (to whole pixels), so a refined gyro PSF keeps
    the gyro's registration, even where that is off the centre sample."""
    k = _drawn_shake_kernel(9)
    off = np.zeros((21, 21), np.float32)
    off[4:4 + k.shape[0], 9:9 + k.shape[1]] = k        # centroid 3 px up, 2 px right of centre
    psf = estimate_kernel(_blur(sharp, off), 21, init_psf=off, iterations=2)
    _assert_valid_psf(psf, 21)
    yy, xx = np.indices(psf.shape)
    target = ((yy * off).sum(), (xx * off).sum())
    assert abs(target[0] - 10) > 1.5 and abs(target[1] - 10) > 1.5
    assert abs((yy * psf).sum() - target[0]) <= 0.5 + 1e-4
    assert abs((xx * psf).sum() - target[1]) <= 0.5 + 1e-4
