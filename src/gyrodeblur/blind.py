"""Single-image blind deconvolution: estimate the blur from the photo alone.

This is the baseline that gyro-derived PSFs are compared against, and a refiner of gyro
PSFs (start from the gyro kernel instead of a delta). It follows the recipe of the
chapter's section 6.3.1 ("MAP and beyond"): alternating MAP_{u,h} minimisation made to
work by the four "tweaks" the chapter names,

1. the kernel is estimated on image *gradients* (``grad g = h * grad u``);
2. a gradual decrease of the noise-variance/regularisation weight (annealing), so the
   coarse shape of the blur is found before its details;
3. a coarse-to-fine image pyramid;
4. kernel positivity and a support constraint (plus normalisation, removal of small
   disconnected specks and re-centring).

The latent-image prior is the L0 norm of the gradient (Xu, Zheng & Jia 2013; Pan, Hu, Su
& Yang 2014): the intermediate latent image is piecewise constant with sharp steps, which
is what steers the alternation away from the "no-blur" solution the chapter warns about.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import scipy.fft as sfft
from scipy import ndimage, signal

from .arguments import check_real, is_count, is_whole
from .errors import InputError
from .fftutils import fast_shape, psf_to_otf, smooth_periodic_pad, usable_cpus
from .images import PHOTO_MAX, PHOTO_MIN, check_image, check_psf, split_alpha

__all__ = ["estimate_kernel", "blind_deconvolve"]

#: Rec. 709 luma weights used to reduce colour input to one channel.
_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)

#: Pyramid scale step between consecutive levels.
_LEVEL_RATIO = 1.0 / math.sqrt(2.0)

#: Half-quadratic splitting of the L0 latent-image step: beta grows by _KAPPA per step.
_KAPPA = 2.0

#: Kernel step: reweighted least-squares passes approximating an L^_IRLS_P kernel prior;
#: weights are floored at _IRLS_EPS times the kernel's peak.
_IRLS = 3
_IRLS_P = 1.0
_IRLS_EPS = 0.05


# --------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------
def estimate_kernel(
    image: np.ndarray,
    kernel_size: int,
    *,
    init_psf: np.ndarray | None = None,
    levels: int | None = None,
    iterations: int = 5,
    lambda_grad: float = 2e-2,
    lambda_min: float = 1e-4,
    lambda_decay: float = 0.9,
    kernel_reg: float = 0.02,
    edge_pixels: float = 20.0,
    edge_decay: float = 1.1,
    cleanup: float = 0.05,
    recenter: bool = True,
) -> np.ndarray:
    """Estimate a camera-shake blur kernel from one blurred photo.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Blurred photo, float in [0, 1]. Colour input is reduced to Rec. 709 luma.
    kernel_size : int
        Side of the square kernel support in pixels; odd, >= 3 and smaller than half the
        image's shorter side. Choose it a little larger than the expected blur extent.
    init_psf : ndarray, shape (kh, kw), optional
        Starting kernel (e.g. a gyro PSF) for refinement. It is centred into the
        ``kernel_size`` support (cropped or zero-padded about its centre sample) and used
        from the start of the finest pyramid levels instead of a delta.
    levels : int, optional
        Pyramid levels (scale step 1/sqrt(2)). Default: enough levels for the kernel to
        be about 3 pixels wide at the coarsest one; with ``init_psf``, 2.
    iterations : int
        Alternating (latent image, kernel) iterations per level.
    lambda_grad, lambda_min, lambda_decay : float
        Weight of the L0 gradient prior of the latent image. It starts at ``lambda_grad``
        and is multiplied by ``lambda_decay`` after every iteration, down to
        ``lambda_min`` (the chapter's gradual noise-variance decrease).
    kernel_reg : float
        Weight of the kernel prior, relative to the energy of the latent image's
        selected gradients (Tikhonov on the first pass, then reweighted towards a sparse
        L1 prior).
    edge_pixels, edge_decay : float
        Only the strongest latent-image gradients take part in the kernel step: at each
        level the squared-magnitude threshold is set so that ``edge_pixels * ksize``
        pixels survive in each of four orientation bins (``ksize`` the level's kernel
        side), then divided by ``edge_decay`` after every iteration.
    cleanup : float
        Kernel samples below ``cleanup * max`` are zeroed, as are 8-connected
        components holding less than 10 % of the mass.
    recenter : bool
        The kernel is only defined up to a shift (a shifted kernel with a shifted latent
        image explains the photo equally well). When true, the result is shifted by whole
        pixels so that its centre of mass falls on the centre sample or, with
        ``init_psf``, on ``init_psf``'s centre of mass, so that a refined gyro PSF keeps
        the gyro's registration.

    Returns
    -------
    psf : ndarray, shape (kernel_size, kernel_size), float32
        Non-negative kernel summing to 1, reference point at the centre sample.

    Raises
    ------
    InputError
        ``kernel_size`` is not odd, below 3 or not smaller than half the image
        (source ``"kernel_size"``); ``init_psf`` fails
        :func:`~gyrodeblur.images.check_psf`.

    Notes
    -----
    At each pyramid level and iteration the latent image is

    .. math:: \\hat u = \\arg\\min_u \\|h * u - g\\|^2 + \\lambda \\|\\nabla u\\|_0 ,

    solved by half-quadratic splitting (gradient hard-thresholding alternating with a
    Fourier-domain quadratic solve), and the kernel is

    .. math:: \\hat h = \\arg\\min_{h \\in S} \\sum_{d \\in \\{x, y\\}}
              \\|\\partial_d \\hat u_{sel} * h - \\partial_d g\\|^2
              + \\gamma \\sum_i w_i h_i^2

    over the support ``S`` (the level's kernel square), with ``w = 1`` on the first pass
    and ``w_i = max|h| / max(|h_i|, 0.05 max|h|)`` on two reweighted passes (an L1 kernel
    prior by IRLS). Each pass is conjugate gradients on the normal equations, whose
    operator is the autocorrelation of the selected latent gradients (computed once per
    iteration with FFTs, so a CG step costs only a kernel-sized convolution). The
    result is then projected: negatives and values under ``cleanup * max`` zeroed,
    8-connected specks holding under 10 % of the mass removed, sum normalised to 1. The
    photo is extended with :func:`smooth_periodic_pad` so the circular FFT model has no
    border jump; the kernel is re-centred at the end of every level.

    Refinement from ``init_psf`` runs only the finest ``levels`` levels, with the
    annealing schedule (``lambda``) the full pyramid would have there.

    References
    ----------
    F. Sroubek, J. Flusser, "Removing camera shake", sec. 6.3.1.
    S. Cho, S. Lee, "Fast motion deblurring", SIGGRAPH Asia 2009 (edge selection).
    L. Xu, S. Zheng, J. Jia, "Unnatural L0 sparse representation for natural image
    deblurring", CVPR 2013.
    J. Pan, Z. Hu, Z. Su, M.-H. Yang, "Deblurring text images via L0-regularized
    intensity and gradient prior", CVPR 2014.

    Examples
    --------
    >>> import numpy as np
    >>> from gyrodeblur.blind import estimate_kernel
    >>> photo = np.random.default_rng(0).random((96, 96), dtype=np.float32)
    >>> psf = estimate_kernel(photo, 9)
    >>> psf.shape, psf.dtype.name, round(float(psf.sum()), 5), bool(psf.min() >= 0)
    ((9, 9), 'float32', 1.0, True)
    """
    gray = _to_gray(image)
    _check_kernel_size(kernel_size, gray.shape)
    _check_options(iterations, levels, lambda_grad, lambda_min, lambda_decay, kernel_reg,
                   edge_pixels, edge_decay, cleanup)
    iterations = int(iterations)

    init = None if init_psf is None else _fit_support(_check_psf(init_psf), kernel_size)
    if levels is None:
        levels = 2 if init is not None else _auto_levels(kernel_size)
    levels = int(levels)
    if levels < 1:
        raise ValueError(f"levels must be >= 1, got {levels}")
    levels = min(levels, _max_levels(kernel_size, gray.shape))

    # the annealing schedule is that of the full pyramid: a shorter pyramid (refinement
    # from init_psf) starts at the weight the full one would have reached at its level
    skipped = max(0, _auto_levels(kernel_size) - levels)
    lam = max(float(lambda_grad) * float(lambda_decay) ** (skipped * iterations), float(lambda_min))
    psf: np.ndarray | None = None
    for level in range(levels):
        scale = _LEVEL_RATIO ** (levels - 1 - level)
        ksize = _odd_size(kernel_size * scale)
        blurred = _downscale(gray, scale)
        if psf is None:
            if init is not None:
                psf = _resample_kernel(init, scale, ksize)
            else:
                psf = np.zeros((ksize, ksize), np.float32)
                psf[ksize // 2, ksize // 2] = 1.0
        else:
            psf = _resample_kernel(psf, 1.0 / _LEVEL_RATIO, ksize)

        psf, lam = _estimate_level(blurred, psf, iterations, lam, lambda_min, lambda_decay,
                                   kernel_reg, edge_pixels, edge_decay, cleanup)
        if recenter:
            psf = _recenter(psf, None if init is None else _resample_kernel(init, scale, ksize))

    assert psf is not None and psf.shape == (kernel_size, kernel_size)
    return psf.astype(np.float32, copy=False)


def blind_deconvolve(
    image: np.ndarray,
    kernel_size: int,
    *,
    deconvolve: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    **kw,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimate the blur of a photo with :func:`estimate_kernel`, then deblur it.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Blurred photo, float in [0, 1].
    kernel_size : int
        Kernel support side, odd (see :func:`estimate_kernel`).
    deconvolve : callable ``(image, psf) -> restored``, optional
        Non-blind deconvolution for the final image (the pipeline passes its best
        method). Default: ``gyrodeblur.sparse.sparse_deconvolve`` when that module
        exists, else ``gyrodeblur.wiener.wiener_deconvolve``, else a built-in
        gradient-regularised Wiener filter.
    **kw
        Passed to :func:`estimate_kernel`.

    Returns
    -------
    restored : ndarray, shape and channel count of ``image``
        Deblurred photo as returned by ``deconvolve`` (the built-in filter returns
        float32, unclipped).
    psf : ndarray, shape (kernel_size, kernel_size), float32
        The estimated kernel.
    """
    psf = estimate_kernel(image, kernel_size, **kw)
    if deconvolve is None:
        deconvolve = _default_deconvolve()
    restored = deconvolve(np.asarray(image, dtype=np.float32), psf)
    return restored, psf


# --------------------------------------------------------------------------------------
# validation and conversions
# --------------------------------------------------------------------------------------
def _to_gray(image: np.ndarray) -> np.ndarray:
    """The photo's Rec. 709 luma (grey as it is), its alpha channel left out; an
    InputError for what is not a photo in [0, 1] (integers, NaN, 255-scaled values)."""
    img, _ = split_alpha(check_image(image, "image", max_value=PHOTO_MAX, min_value=PHOTO_MIN))
    if img.ndim == 3:
        img = (np.tensordot(img, _LUMA, axes=([2], [0])) if img.shape[2] == 3
               else img[..., 0])
    return np.ascontiguousarray(img, dtype=np.float32)


def _check_options(iterations, levels, lambda_grad, lambda_min, lambda_decay, kernel_reg,
                   edge_pixels, edge_decay, cleanup) -> None:
    """ValueError/TypeError naming the first of :func:`estimate_kernel`'s options that is
    out of its range (a whole count where one is meant, finite weights, a decay in (0, 1],
    a cleanup threshold under 1 that leaves the kernel's peak)."""
    for name, v in (("iterations", iterations), ("levels", levels)):
        if v is not None and not is_count(v):
            raise ValueError(f"{name} must be a whole number >= 1, got {v!r}")
    for name, v, ok, what in (("lambda_grad", lambda_grad, lambda x: x > 0, "> 0"),
                              ("lambda_min", lambda_min, lambda x: x >= 0, ">= 0"),
                              ("lambda_decay", lambda_decay, lambda x: 0 < x <= 1, "in (0, 1]"),
                              ("kernel_reg", kernel_reg, lambda x: x > 0, "> 0"),
                              ("edge_pixels", edge_pixels, lambda x: x > 0, "> 0"),
                              ("edge_decay", edge_decay, lambda x: x > 0, "> 0"),
                              ("cleanup", cleanup, lambda x: 0 <= x < 1, "in [0, 1)")):
        if not ok(check_real(v, name)):
            raise ValueError(f"{name} must be {what}, got {v!r}")


def _check_kernel_size(kernel_size, shape: tuple[int, int], what: str = "image") -> None:
    if not is_whole(kernel_size):
        raise InputError.of_argument("kernel_size", f"must be an odd integer, got {kernel_size!r}")
    k = int(kernel_size)
    if k < 3 or k % 2 == 0:
        raise InputError.of_argument("kernel_size", f"must be odd and >= 3, got {k}")
    limit = min(shape) / 2
    if k >= limit:
        raise InputError.of_argument("kernel_size",
                                     f"{k} px is too large for a {shape[1]}x{shape[0]} {what} "
                                     f"(must be smaller than {limit:g}, half its shorter side)")


def _check_psf(psf: np.ndarray) -> np.ndarray:
    """The initial kernel: a checked PSF (:func:`~gyrodeblur.images.check_psf`: its sum is
    positive) without its negative entries (the kernel estimate is non-negative)."""
    k = np.clip(check_psf(psf, "init_psf"), 0, None)
    return k / k.sum()


def _fit_support(psf: np.ndarray, size: int) -> np.ndarray:
    """Crop or zero-pad ``psf`` about its centre sample to ``size`` x ``size``; renormalise."""
    out = np.zeros((size, size), np.float32)
    c = size // 2
    ch, cw = psf.shape[0] // 2, psf.shape[1] // 2
    r0, r1 = max(-c, -ch), min(c, psf.shape[0] - 1 - ch)
    q0, q1 = max(-c, -cw), min(c, psf.shape[1] - 1 - cw)
    out[c + r0:c + r1 + 1, c + q0:c + q1 + 1] = psf[ch + r0:ch + r1 + 1, cw + q0:cw + q1 + 1]
    s = out.sum()
    if s <= 0:
        out[c, c] = 1.0
        return out
    return out / s


# --------------------------------------------------------------------------------------
# pyramid
# --------------------------------------------------------------------------------------
def _odd_size(x: float) -> int:
    return max(3, 2 * int(round((x - 1) / 2)) + 1)


def _auto_levels(kernel_size: int) -> int:
    n = 1
    k = float(kernel_size)
    while k * _LEVEL_RATIO >= 3.0:
        k *= _LEVEL_RATIO
        n += 1
    return n


def _max_levels(kernel_size: int, shape: tuple[int, int]) -> int:
    """Levels allowed before the coarsest image gets smaller than 32 px or 4 kernels."""
    n = 1
    while True:
        s = _LEVEL_RATIO ** n
        if min(shape) * s < max(32, 4 * _odd_size(kernel_size * s)):
            return n
        n += 1


def _downscale(gray: np.ndarray, scale: float) -> np.ndarray:
    """One pyramid level: ``gray`` resized by ``scale`` (bilinear, with skimage's Gaussian
    anti-aliasing of sigma ``(1 / scale - 1) / 2`` px), float32.

    The kernel goes down the pyramid through the same prefilter (:func:`_resample_kernel`),
    so image and kernel stay consistent at every level. (``calibrate``'s ``downscale`` uses
    area averaging instead: it shrinks a photo softer than its pixel grid once, before
    anything else, and what softening that adds is part of the photo the criterion sees.)"""
    if scale >= 0.999:
        return gray
    from skimage.transform import resize

    shape = (max(1, round(gray.shape[0] * scale)), max(1, round(gray.shape[1] * scale)))
    return resize(gray, shape, order=1, anti_aliasing=True, preserve_range=True).astype(np.float32)


def _resample_kernel(psf: np.ndarray, scale: float, size: int) -> np.ndarray:
    """Scale a centred kernel by ``scale`` about its centre sample into ``size`` x ``size``."""
    k = np.asarray(psf, dtype=np.float64)
    if scale < 1.0:
        k = ndimage.gaussian_filter(k, sigma=max(0.0, (1.0 / scale - 1.0) / 2.0), mode="constant")
    c_in = np.array(k.shape, dtype=np.float64) // 2
    off = (np.arange(size) - size // 2) / scale
    rr, cc = np.meshgrid(c_in[0] + off, c_in[1] + off, indexing="ij")
    out = ndimage.map_coordinates(k, [rr, cc], order=1, mode="constant", cval=0.0)
    out = np.clip(out, 0, None).astype(np.float32)
    s = out.sum()
    if s <= 0:
        out = np.zeros((size, size), np.float32)
        out[size // 2, size // 2] = 1.0
        return out
    return out / s


# --------------------------------------------------------------------------------------
# one pyramid level
# --------------------------------------------------------------------------------------
def _estimate_level(blurred, psf, iterations, lam, lambda_min, lambda_decay, kernel_reg,
                    edge_pixels, edge_decay, cleanup):
    h, w = blurred.shape
    ksize = psf.shape[0]
    shape = fast_shape((h + ksize + 1, w + ksize + 1))
    g = smooth_periodic_pad(blurred, shape)
    g_f = sfft.rfft2(g, workers=usable_cpus())
    dx_otf = psf_to_otf(np.array([[1.0, -1.0, 0.0]], np.float32), shape)
    dy_otf = psf_to_otf(np.array([[1.0], [-1.0], [0.0]], np.float32), shape)
    grad2 = (np.abs(dx_otf) ** 2 + np.abs(dy_otf) ** 2).astype(np.float32)
    gx_f = dx_otf * g_f
    gy_f = dy_otf * g_f
    threshold = None
    for _ in range(iterations):
        latent = _l0_restore(g, g_f, psf_to_otf(psf, shape), grad2, lam)
        if threshold is None:
            threshold = _edge_threshold(latent[:h, :w], ksize, edge_pixels)
        ux, uy = _select_edges(latent, threshold)
        threshold /= edge_decay
        psf = _kernel_step(ux, uy, gx_f, gy_f, psf, kernel_reg)
        psf = _cleanup_kernel(psf, cleanup)
        lam = max(lam * lambda_decay, lambda_min)
    return psf, lam


def _grad(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward differences with periodic wrap: ``u(x+1) - u(x)``."""
    ux = np.empty_like(u)
    ux[:, :-1] = u[:, 1:] - u[:, :-1]
    ux[:, -1] = u[:, 0] - u[:, -1]
    uy = np.empty_like(u)
    uy[:-1] = u[1:] - u[:-1]
    uy[-1] = u[0] - u[-1]
    return ux, uy


def _grad_adjoint(px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Adjoint of :func:`_grad`: ``p(x-1) - p(x)`` summed over both axes."""
    out = np.empty_like(px)
    out[:, 1:] = px[:, :-1] - px[:, 1:]
    out[:, 0] = px[:, -1] - px[:, 0]
    out[1:] += py[:-1] - py[1:]
    out[0] += py[-1] - py[0]
    return out


def _l0_restore(g, g_f, k_otf, grad2, lam, beta_max=1e5, kappa=None):
    """Latent image under an L0 gradient prior, by half-quadratic splitting."""
    kappa = _KAPPA if kappa is None else kappa
    shape = g.shape
    num1 = np.conj(k_otf) * g_f
    den_k = (np.abs(k_otf) ** 2).astype(np.float32)
    u = g
    beta = 2.0 * lam
    workers = usable_cpus()
    while beta < beta_max:
        ux, uy = _grad(u)
        mag = ux * ux
        mag += uy * uy
        small = mag < lam / beta
        ux[small] = 0
        uy[small] = 0
        spec = sfft.rfft2(_grad_adjoint(ux, uy), workers=workers)
        spec *= np.float32(beta)
        spec += num1
        spec /= den_k + np.float32(beta) * grad2
        u = sfft.irfft2(spec, s=shape, workers=workers).astype(np.float32, copy=False)
        beta *= kappa
    return u


def _edge_threshold(latent, ksize, edge_pixels):
    """Squared-gradient threshold keeping ``edge_pixels * ksize`` pixels in each of four
    gradient orientation bins (Cho & Lee 2009): enough strong edges in every direction."""
    ux, uy = _grad(latent)
    mag = (ux * ux + uy * uy).ravel()
    ang = np.mod(np.arctan2(uy, ux).ravel(), np.pi)
    bins = np.minimum((ang / (np.pi / 4)).astype(int), 3)
    need = max(1, int(edge_pixels * ksize))
    t = np.inf
    for b in range(4):
        m = np.sort(mag[bins == b])
        if m.size == 0:
            continue
        t = min(t, m[max(0, m.size - need)])
    return float(t) if np.isfinite(t) else 0.0


def _select_edges(latent, threshold):
    ux, uy = _grad(latent)
    weak = ux * ux + uy * uy < threshold
    if np.all(weak):
        return ux, uy
    ux[weak] = 0
    uy[weak] = 0
    return ux, uy


def _offsets(a: np.ndarray, m: int) -> np.ndarray:
    """Samples of a periodic array at offsets -m..m on both axes (centre at index m)."""
    ri = np.arange(-m, m + 1) % a.shape[0]
    ci = np.arange(-m, m + 1) % a.shape[1]
    return a[np.ix_(ri, ci)]


def _kernel_normal_equations(ux, uy, gx_f, gy_f, r):
    """Normal equations of ``min_h sum_d ||u_d * h - g_d||^2`` over offsets ``-r..r``.

    With ``A`` the operator ``h -> (u_x * h, u_y * h)`` (circular), returns ``auto``, the
    autocorrelation of the latent gradients at offsets ``-2r..2r`` (so that
    ``A^T A h = _normal_apply(auto, h)``), and ``b = A^T (g_x, g_y)`` at offsets
    ``-r..r``; ``gx_f``, ``gy_f`` are the ``rfft2`` of the photo's gradients.
    """
    shape = ux.shape
    workers = usable_cpus()
    ux_f = sfft.rfft2(ux, workers=workers)
    uy_f = sfft.rfft2(uy, workers=workers)
    gram_f = ux_f.real ** 2 + ux_f.imag ** 2 + uy_f.real ** 2 + uy_f.imag ** 2
    rhs_f = np.conj(ux_f) * gx_f + np.conj(uy_f) * gy_f
    auto = _offsets(sfft.irfft2(gram_f, s=shape, workers=workers), 2 * r)
    b = _offsets(sfft.irfft2(rhs_f, s=shape, workers=workers), r)
    return auto.astype(np.float64), b.astype(np.float64)


def _normal_apply(auto, h):
    """``A^T A h``: ``sum_t R(s - t) h(t)`` for ``s`` in ``-r..r``, ``R`` = ``auto``."""
    return signal.fftconvolve(auto, h, mode="valid")


def _kernel_step(ux, uy, gx_f, gy_f, psf, kernel_reg, cg_iter=30, tol=1e-5):
    r = psf.shape[0] // 2
    auto, b = _kernel_normal_equations(ux, uy, gx_f, gy_f, r)
    gamma = kernel_reg * max(auto[2 * r, 2 * r], 1e-12)
    x = psf.astype(np.float64)
    weight = np.ones_like(x)
    for _ in range(_IRLS):
        x = _cg(lambda h: _normal_apply(auto, h) + gamma * weight * h, b, x, cg_iter, tol)
        # reweight towards a sparse (L^p, p < 2) kernel prior: IRLS
        mag = np.abs(x)
        ref = mag.max()
        if not ref > 0:
            break
        weight = (np.maximum(mag, _IRLS_EPS * ref) / ref) ** (_IRLS_P - 2.0)
    return x.astype(np.float32)


def _cg(apply, b, x, n_iter, tol):
    """Conjugate gradients for a symmetric positive-definite ``apply``, warm-started at x."""
    x = x.copy()
    res = b - apply(x)
    p = res.copy()
    rs = float(np.vdot(res, res))
    b_norm = float(np.vdot(b, b))
    for _ in range(n_iter):
        if rs <= tol * tol * b_norm:
            break
        ap = apply(p)
        curv = float(np.vdot(p, ap))
        if not curv > 0:
            break
        alpha = rs / curv
        x += alpha * p
        res -= alpha * ap
        rs_new = float(np.vdot(res, res))
        p = res + (rs_new / rs) * p
        rs = rs_new
    return x


def _cleanup_kernel(psf: np.ndarray, rel: float) -> np.ndarray:
    k = np.clip(psf, 0, None)
    peak = k.max()
    if peak <= 0:
        out = np.zeros_like(k)
        out[k.shape[0] // 2, k.shape[1] // 2] = 1.0
        return out
    k[k < rel * peak] = 0
    labels, n = ndimage.label(k > 0, structure=np.ones((3, 3)))
    if n > 1:
        mass = ndimage.sum(k, labels, index=np.arange(1, n + 1))
        keep = mass >= 0.1 * mass.sum()
        keep[np.argmax(mass)] = True
        k[~np.concatenate([[False], keep])[labels]] = 0
    return (k / k.sum()).astype(np.float32)


def _centroid(k: np.ndarray) -> np.ndarray:
    idx = np.indices(k.shape, dtype=np.float64)
    s = k.sum()
    return np.array([(idx[0] * k).sum() / s, (idx[1] * k).sum() / s])


def _recenter(psf: np.ndarray, ref: np.ndarray | None) -> np.ndarray:
    """Shift by whole pixels so the centroid lands on ``ref``'s (or the centre sample)."""
    target = (np.array(psf.shape) // 2).astype(np.float64) if ref is None else _centroid(ref)
    dy, dx = np.round(target - _centroid(psf)).astype(int)
    if dy == 0 and dx == 0:
        return psf
    out = ndimage.shift(psf, (dy, dx), order=0, mode="constant", cval=0.0)
    s = out.sum()
    return psf if s <= 0 else (out / s).astype(np.float32)


# --------------------------------------------------------------------------------------
# final non-blind step
# --------------------------------------------------------------------------------------
def _default_deconvolve() -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    try:
        from .sparse import sparse_deconvolve
    except ImportError:
        pass
    else:
        return sparse_deconvolve
    try:
        from .wiener import wiener_deconvolve
    except ImportError:
        pass
    else:
        return wiener_deconvolve
    return _wiener


def _wiener(image: np.ndarray, psf: np.ndarray, reg: float = 2e-3) -> np.ndarray:
    """Wiener filter with a gradient (Laplacian) prior; float32, unclipped, same shape."""
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape[:2]
    kh, kw = psf.shape
    shape = fast_shape((h + kh + 1, w + kw + 1))
    padded = smooth_periodic_pad(img, shape)
    k_otf = psf_to_otf(psf, shape)
    dx = psf_to_otf(np.array([[1.0, -1.0, 0.0]], np.float32), shape)
    dy = psf_to_otf(np.array([[1.0], [-1.0], [0.0]], np.float32), shape)
    filt = np.conj(k_otf) / (np.abs(k_otf) ** 2 + reg * (np.abs(dx) ** 2 + np.abs(dy) ** 2))
    if img.ndim == 3:
        filt = filt[..., None]
    workers = usable_cpus()
    spec = sfft.rfft2(padded, axes=(0, 1), workers=workers) * filt
    out = sfft.irfft2(spec, s=shape, axes=(0, 1), workers=workers)
    return np.ascontiguousarray(out[:h, :w], dtype=np.float32)
