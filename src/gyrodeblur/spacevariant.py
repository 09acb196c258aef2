"""Deconvolution under one space-variant blur for the whole photo, not one PSF per patch.

Patch-wise deconvolution (:func:`gyrodeblur.tiling.deconvolve_patchwise`) solves each
window, with its margin, as if one PSF blurred all of it. Where the PSF changes across
that support (roll, a wide lens, the rolling shutter, and above all long exposures, whose
PSFs are as long as the windows) the model is wrong inside every window, and blending the
windows' answers does not make it right. Here the whole photo is solved at once under

.. math:: A u = \\sum_r W_r \\odot (k_r * u),

the PSFs ``k_r`` of the patch centres interpolated across the photo by the patches'
Hamming blending weights ``W_r`` (which sum to one at every pixel): the same PSFs, with
no window boundary anywhere in the model. The solver is sparse-prior (TV) ADMM like
:func:`gyrodeblur.sparse.sparse_deconvolve`, but ``A`` is not a convolution, so its
u-step is a few conjugate-gradient steps instead of a closed-form FFT solve; it starts
from the patch-wise result, which it refines.

Convolution convention as in :mod:`gyrodeblur.fftutils`: ``(k * u)(x) = sum_s k(s) u(x - s)``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Sequence

import cv2
import numpy as np

from .arguments import check_real, is_count
from .fftutils import fast_shape, usable_cpus
from .psf import psf_extent
from .sparse import _BETA_MAX as _SPARSE_BETA_MAX
from .sparse import _dx, _dx_t_set, _dy, _dy_t_add, _shrink_residual
from .tiling import Patch, blend_weights

__all__ = ["InterpolatedBlur", "refine_globally", "refinement_budget", "DEFAULT_OUTER",
           "DEFAULT_CG_STEPS"]

#: ADMM iterations of :func:`refine_globally` (each one shrinkage and one u-step).
#: Outer iterations buy more than CG steps: from the same patch-wise start (session 29,
#: 12 cases of 8-19 px / 12 of 35-67 px, mean PSNR and the refinement's time) 4 x 8 gave
#: 29.02 / 22.44 dB in 0.66 / 1.19 s, 6 x 4 29.03 / 22.52 in 0.58 / 1.04 s, 6 x 5
#: 29.07 / 22.53 in 0.67 / 1.22 s, 8 x 4 29.06 / 22.55 in 0.77 / 1.36 s.
DEFAULT_OUTER = 6
#: Conjugate-gradient steps per u-step (each costs two batched FFT pairs of all patches).
DEFAULT_CG_STEPS = 5
#: Longest PSF extent (px) for which :func:`refinement_budget` gives the base budget
#: above; beyond it both counts grow in proportion to the extent, up to
#: ``_MAX_BUDGET_SCALE`` times from 64 px, as the patch-wise solver's iterations do
#: (:func:`gyrodeblur.sparse.default_iterations`). A long PSF's u-step converges slowly,
#: and the first iterates, started from the patch-wise result with no dual, leave it: on a
#: 0.2 s exposure of a dark scene (95 px) the base budget ended 1.35 dB below its start,
#: twice it 0.07 above, 24 x 15 steps 3.0 above (session 48, BENCHMARKS section 2). On 24
#: long exposures of the benchmark's photos and log (80-200 ms, 640 px, 16-73 px at the
#: centre) this rule gained +0.25 dB on average (20 better, worst -0.03) for 1.8x the
#: time; on the 36 benchmark cases +0.02 (6 better, worst -0.14) for 1.13x. A cap of 3
#: gained more on blurs over 90 px but took 4.5x as long on a Shield frame (131-165 px),
#: against 2.0x.
_BUDGET_FROM_PX = 32
_MAX_BUDGET_SCALE = 2.0
#: Penalty of the gradient split: ``beta * weight``, x1.5 per iteration, at most 64. It
#: starts where the patch-wise solve (:mod:`gyrodeblur.sparse`) ends its continuation at
#: its default iterations (3 or more; 1 or 2 end lower), whose result it refines:
#: starting again from 8 first undid some of that result's detail (session 43, one run
#: each, mean PSNR gain of starting from 32: +0.027 dB on the 36 benchmark cases, 26
#: better, worst -0.13; +0.037 on 12 blurs of 8-19 px, 8 better; +0.054 on 12 of 35-67 px,
#: all 12; on four held-out photos -0.11 to +0.44; the same time).
_BETA0, _BETA_GROWTH, _BETA_MAX = _SPARSE_BETA_MAX, 1.5, 64.0
#: Most threads the windows' transforms are spread over.
_MAX_THREADS = 4


class InterpolatedBlur:
    """The forward model ``A u = sum_r W_r (k_r * u)`` and its adjoint, for a grid of
    equal windows.

    ``u`` lives on the photo extended by ``pad`` pixels on every side (the light a PSF
    brings in from beyond the frame); ``A u`` is photo-sized.

    Parameters
    ----------
    patches : sequence of Patch
        Windows of equal size forming a row/column grid that covers the photo
        (:func:`gyrodeblur.tiling.patch_grid`).
    psfs : sequence of ndarray
        One odd-sized PSF per patch (each normalised to sum 1 here).
    shape : (H, W)
        The photo's rows and columns.

    Attributes
    ----------
    pad : int
        Pixels by which the unknown extends the photo on every side.
    extent : int
        The longest PSF's extent, px (:func:`gyrodeblur.psf.psf_extent`): it sets
        :func:`refine_globally`'s default budget.

    Notes
    -----
    Each window, extended by the largest PSF's size, is convolved by OpenCV's real FFT
    (:mod:`gyrodeblur.packedfft`'s layout), the windows spread over threads (OpenCV
    releases the GIL). Memory: two float32 stacks of all the extended windows (their
    spectra, and the work buffer the transforms run in), about
    ``2 * len(patches) * (h + kh) * (w + kw)`` values. Not thread-safe: one model per
    thread. It holds a pool of threads for the transforms: use it as a context manager,
    or call :meth:`close` when done (an unclosed model's threads end when it is
    garbage-collected).
    """

    def __init__(self, patches: Sequence[Patch], psfs: Sequence[np.ndarray],
                 shape: tuple[int, int]):
        patches, psfs = list(patches), [np.asarray(k, np.float64) for k in psfs]
        if len(patches) != len(psfs) or not patches:
            raise ValueError(f"need one PSF per patch, got {len(psfs)} for {len(patches)}")
        sizes = {p.shape for p in patches}
        if len(sizes) != 1:
            raise ValueError("the global model needs windows of one size (patch_grid's)")
        H, W = int(shape[0]), int(shape[1])
        weights = blend_weights(patches, (H, W))          # refuses a layout that is no grid
        kh = max(k.shape[0] for k in psfs)
        kw = max(k.shape[1] for k in psfs)
        self.h, self.w = sizes.pop()
        self.kh, self.kw = kh, kw
        self.pad = max(kh, kw) // 2 + 1
        self.shape = (H, W)
        self.patches = patches
        self.n = fast_shape((self.h + kh - 1, self.w + kw - 1))
        self.otf = np.zeros((len(psfs),) + self.n, np.float32)
        for i, k in enumerate(psfs):     # top-left, centred in the common kh x kw
            oy, ox = (kh - k.shape[0]) // 2, (kw - k.shape[1]) // 2
            self.otf[i, oy:oy + k.shape[0], ox:ox + k.shape[1]] = k / k.sum()
            cv2.dft(self.otf[i], dst=self.otf[i])
        self.weights = [np.outer(wy, wx).astype(np.float32) for wy, wx in weights]
        self.extent = max(psf_extent(k) for k in psfs)
        self._buf = np.zeros_like(self.otf)
        self._threads = max(1, min(usable_cpus(), _MAX_THREADS, len(patches)))
        self._chunks = [range(t, len(patches), self._threads) for t in range(self._threads)]
        self._pool = ThreadPoolExecutor(self._threads) if self._threads > 1 else None

    def close(self) -> None:
        """End the model's transform threads (it can still be used, on one thread)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
            self._chunks = [range(len(self.patches))]

    def __enter__(self) -> "InterpolatedBlur":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def padded_shape(self) -> tuple[int, int]:
        """Shape of the unknown: the photo with ``pad`` px on every side."""
        return self.shape[0] + 2 * self.pad, self.shape[1] + 2 * self.pad

    def _extended(self, p: Patch) -> tuple[int, int]:
        """Top-left corner, in padded coordinates, of window ``p`` extended by the PSF."""
        return p.y0 + self.pad - self.kh // 2, p.x0 + self.pad - self.kw // 2

    def _filter_planes(self, fill, conjugate: bool) -> None:
        """``fill(i, plane)`` writes plane ``i`` of the work buffer; it is then filtered
        by PSF ``i`` (convolved, or correlated when ``conjugate``), in place, the planes
        spread over threads."""
        def run(indices):
            for i in indices:
                plane = self._buf[i]
                fill(i, plane)
                cv2.dft(plane, dst=plane)
                cv2.mulSpectrums(plane, self.otf[i], 0, c=plane, conjB=conjugate)
                cv2.idft(plane, dst=plane, flags=cv2.DFT_REAL_OUTPUT | cv2.DFT_SCALE)
        if self._pool is None:
            run(self._chunks[0])
            return
        list(self._pool.map(run, self._chunks))

    def forward(self, u: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``A u``: ``u`` of :attr:`padded_shape` -> photo-sized float32 (into ``out``)."""
        eh, ew = self.h + self.kh - 1, self.w + self.kw - 1

        def fill(i, plane):
            y, x = self._extended(self.patches[i])
            plane[:eh, :ew] = u[y:y + eh, x:x + ew]
            plane[eh:] = 0.0
            plane[:eh, ew:] = 0.0

        self._filter_planes(fill, conjugate=False)
        out = np.zeros(self.shape, np.float32) if out is None else out
        out[...] = 0.0
        y0, x0 = self.kh - 1, self.kw - 1
        for i, p in enumerate(self.patches):        # out += W_i * valid part, one pass
            cv2.accumulateProduct(self._buf[i, y0:y0 + self.h, x0:x0 + self.w],
                                  self.weights[i], out[p.y0:p.y1, p.x0:p.x1])
        return out

    def adjoint(self, g: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``A^T g``: photo-sized ``g`` -> float32 of :attr:`padded_shape` (into ``out``)."""
        eh, ew = self.h + self.kh - 1, self.w + self.kw - 1
        y0, x0 = self.kh - 1, self.kw - 1

        def fill(i, plane):                        # W_i g in the window, zero around it
            p = self.patches[i]
            plane[:y0] = 0.0
            plane[y0 + self.h:] = 0.0
            plane[y0:y0 + self.h, :x0] = 0.0
            plane[y0:y0 + self.h, x0 + self.w:] = 0.0
            np.multiply(g[p.y0:p.y1, p.x0:p.x1], self.weights[i],
                        out=plane[y0:y0 + self.h, x0:x0 + self.w])

        self._filter_planes(fill, conjugate=True)
        out = np.zeros(self.padded_shape, np.float32) if out is None else out
        out[...] = 0.0
        for i, p in enumerate(self.patches):
            y, x = self._extended(p)
            view = out[y:y + eh, x:x + ew]
            cv2.add(view, self._buf[i, :eh, :ew], dst=view)
        return out


_LAPLACIAN = np.array([[0, -1, 0], [-1, 4, -1], [0, -1, 0]], np.float32)


def _add_grad_t_grad(v: np.ndarray, rho: float, out: np.ndarray, scratch: np.ndarray) -> None:
    """``out += rho * grad^T grad v``, ``grad`` the periodic forward differences of
    :mod:`gyrodeblur.sparse` (``_dx``, ``_dy``): the 5-point Laplacian
    ``4 v - (the four neighbours)``, in two OpenCV passes."""
    cv2.filter2D(v, -1, _LAPLACIAN, dst=scratch, borderType=cv2.BORDER_CONSTANT)
    scratch[0] -= v[-1]                   # the neighbours across the periodic edges
    scratch[-1] -= v[0]
    scratch[:, 0] -= v[:, -1]
    scratch[:, -1] -= v[:, 0]
    cv2.scaleAdd(scratch, float(rho), out, dst=out)


def refinement_budget(extent: float) -> tuple[int, int]:
    """The ADMM iterations and CG steps per iteration that :func:`refine_globally` runs
    by default for PSFs whose longest extent (:func:`gyrodeblur.psf.psf_extent`) is
    ``extent`` px: :data:`DEFAULT_OUTER` x :data:`DEFAULT_CG_STEPS` up to 32 px, both in
    proportion to the extent beyond, at most twice (12 x 10 from 64 px). A ``TypeError``
    for a non-number (:func:`gyrodeblur.arguments.check_real`), a ``ValueError`` for one
    that is not finite and positive."""
    if check_real(extent, "extent") <= 0:
        raise ValueError(f"extent must be a positive number of pixels, got {extent!r}")
    scale = min(_MAX_BUDGET_SCALE, max(1.0, float(extent) / _BUDGET_FROM_PX))
    return int(round(DEFAULT_OUTER * scale)), int(round(DEFAULT_CG_STEPS * scale))


def refine_globally(image: np.ndarray, start: np.ndarray, blur: InterpolatedBlur, *,
                    weight: float, exponent: float = 1.0, outer: int | None = None,
                    cg_steps: int | None = None, ignore: np.ndarray | None = None,
                    at_least: np.ndarray | None = None, fixed: np.ndarray | None = None,
                    progress=None) -> np.ndarray:
    """Refine ``start`` towards ``argmin_u 1/2 |M (A u - g)|^2 + weight sum |grad u|^p``.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo ``g``, linear light, float32.
    start : ndarray like ``image``
        The first estimate (the patch-wise result); each channel is solved on its own.
    blur : InterpolatedBlur
        The forward model ``A`` for this photo's patches and PSFs.
    weight : float
        Prior weight (:func:`gyrodeblur.sparse.regularization_weight` of the photo's
        noise: the patch-wise solver's own).
    exponent : float
        Prior exponent ``p`` in (0, 1] (1: total variation).
    outer, cg_steps : int, optional
        ADMM iterations, and conjugate-gradient steps in each one's u-step. Default
        :func:`refinement_budget` of the model's longest PSF (``blur.extent``).
    ignore : ndarray of bool (H, W), optional
        Pixels with no data term (over-exposed lights, samples from outside the photo).
    at_least : ndarray of bool (H, W) or (H, W, C), optional
        Pixels at the clip value: they ask only ``A u >= g`` (their data term counts
        where the current estimate falls below the clipped value).
    fixed : ndarray of bool (H, W), optional
        Pixels held at ``start``'s values: where the photo holds no data and the start
        knows more than the prior would (over-exposed lights, which the patch-wise solver
        gathers into their cores; left to the prior, such a light fades).
    progress : callable(done), optional
        Called after each iteration, ``done`` counting over the channels.

    Returns
    -------
    ndarray float32 like ``image`` (not clipped).
    """
    g = np.asarray(image, np.float32)
    u0 = np.asarray(start, np.float32)
    if g.shape != u0.shape or g.shape[:2] != blur.shape:
        raise ValueError(f"image {g.shape}, start {u0.shape} and model {blur.shape} differ")
    default_outer, default_steps = refinement_budget(blur.extent)
    outer = default_outer if outer is None else outer
    cg_steps = default_steps if cg_steps is None else cg_steps
    for name, v in (("outer", outer), ("cg_steps", cg_steps)):
        if not is_count(v):
            raise ValueError(f"{name} must be a positive whole number, got {v!r}")
    if not (np.isfinite(weight) and weight > 0):
        raise ValueError(f"weight must be a positive number, got {weight!r}")
    color = g.ndim == 3
    gc = np.moveaxis(g, 2, 0) if color else g[None]
    uc = np.moveaxis(u0, 2, 0) if color else u0[None]
    out = np.empty(gc.shape, np.float32)
    base = np.ones(blur.shape, np.float32)
    if ignore is not None:
        base[np.asarray(ignore, bool)] = 0.0
    held = None
    if fixed is not None and np.any(fixed):
        held = np.pad(np.asarray(fixed, bool), blur.pad)
    for c in range(gc.shape[0]):
        one_sided = None
        if at_least is not None:
            a = np.asarray(at_least, bool)
            one_sided = a[..., c] if a.ndim == 3 else a
            if not one_sided.any():
                one_sided = None
        step = None if progress is None else (lambda k, c=c: progress(c * outer + k))
        out[c] = _solve_channel(np.ascontiguousarray(gc[c]), uc[c], blur, float(weight),
                                float(exponent), int(outer), int(cg_steps), base, one_sided,
                                held, step)
    return np.moveaxis(out, 0, 2).copy() if color else out[0]


def _solve_channel(g, u0, blur: InterpolatedBlur, weight, p, outer, cg_steps, base,
                   one_sided, held, progress):
    """ADMM on one channel: ``w = grad u`` split off, the u-step by CG, warm-started.
    Work arrays are allocated once (15 of the padded size, one of the photo's)."""
    pad = blur.pad
    u = np.pad(u0, pad, mode="edge").astype(np.float32)
    gx, gy, wx, wy, b, r, d, nd, t1, t2, t3 = (np.empty_like(u) for _ in range(11))
    dx = np.zeros_like(u)                    # scaled duals of the split
    dy = np.zeros_like(u)
    image_sized = np.empty(blur.shape, np.float32)
    masked = None if base.all() else base
    m = masked
    rho = 0.0
    atg = None                               # A^T M g

    def normal(v, out):                      # out = (A^T M A + rho grad^T grad) v
        blur.forward(v, out=image_sized)
        if m is not None:
            np.multiply(image_sized, m, out=image_sized)
        blur.adjoint(image_sized, out=out)
        _add_grad_t_grad(v, rho, out, scratch=t3)

    _dx(u, gx)
    _dy(u, gy)
    beta = _BETA0
    for it in range(outer):
        rho = weight * beta
        # w-step: w = prox(grad u + d); b = A^T M g + rho grad^T (w - d)
        np.add(gx, dx, out=t1)
        _shrink_residual(t1, beta, p, out=wx)
        np.subtract(t1, wx, out=wx)
        np.add(gy, dy, out=t1)
        _shrink_residual(t1, beta, p, out=wy)
        np.subtract(t1, wy, out=wy)
        np.subtract(wx, dx, out=t1)
        np.subtract(wy, dy, out=t2)
        _dx_t_set(t1, b)
        _dy_t_add(t2, b)
        b *= np.float32(rho)
        m = masked
        if one_sided is not None:            # active set of the one-sided pixels
            m = base.copy()
            m[one_sided & (blur.forward(u, out=image_sized) >= g)] = 0.0
        if one_sided is not None or atg is None:   # A^T M g: once, unless M moves
            np.copyto(image_sized, g)
            if m is not None:
                image_sized *= m
            atg = blur.adjoint(image_sized, out=np.empty_like(u) if atg is None else atg)
        b += atg
        # u-step: CG on the normal equations from the current u
        normal(u, nd)
        np.subtract(b, nd, out=r)
        if held is not None:          # CG over the free pixels only: u stays put there
            r[held] = 0.0
        np.copyto(d, r)
        rr = float(np.vdot(r, r))
        for _ in range(cg_steps):
            if rr == 0.0:
                break
            normal(d, nd)
            step = rr / float(np.vdot(d, nd))
            cv2.scaleAdd(d, step, u, dst=u)           # u += step d
            cv2.scaleAdd(nd, -step, r, dst=r)         # r -= step A'A d
            if held is not None:
                r[held] = 0.0
            rr_new = float(np.vdot(r, r))
            cv2.scaleAdd(d, rr_new / rr, r, dst=d)    # d = r + (rr_new / rr) d
            rr = rr_new
        # dual update, then continuation (the scaled dual rescaled: the true one stays)
        _dx(u, gx)
        _dy(u, gy)
        dx += gx
        dx -= wx
        dy += gy
        dy -= wy
        new_beta = min(beta * _BETA_GROWTH, _BETA_MAX)
        dx *= np.float32(beta / new_beta)
        dy *= np.float32(beta / new_beta)
        beta = new_beta
        if progress is not None:
            progress(it + 1)
    return u[pad:pad + blur.shape[0], pad:pad + blur.shape[1]]
