"""FFT helpers shared by every deconvolution method.

Conventions: images are float32 arrays of shape ``(H, W)`` or ``(H, W, C)``; a PSF is a
2-D odd-sized float array that sums to 1, whose centre sample is the PSF's reference
point (pixel offset 0). Convolution means ``g(x) = sum_s h(s) u(x - s)``, so a PSF whose
mass sits at offset ``+d`` moves content by ``+d``.
"""

from __future__ import annotations

import functools
import os

import numpy as np
import scipy.fft as sfft

__all__ = [
    "FFT_WORKERS",
    "fast_shape",
    "psf_to_otf",
    "smooth_periodic_pad",
    "convolve_fft",
]

#: Threads given to ``scipy.fft`` (all cores of this machine).
FFT_WORKERS: int = os.cpu_count() or 1


def fast_shape(shape: tuple[int, int]) -> tuple[int, int]:
    """Smallest shape ``>= shape`` whose sides are fast real-FFT lengths (5-smooth)."""
    return tuple(sfft.next_fast_len(int(n), real=True) for n in shape)  # type: ignore[return-value]


def psf_to_otf(psf: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Optical transfer function of a centred PSF for real FFTs of ``shape``.

    The result is ``rfft2`` of the PSF zero-padded to ``shape`` and circularly shifted so
    that its centre sample lands on index ``(0, 0)``: complex64 of shape
    ``(shape[0], shape[1] // 2 + 1)``.

    Parameters
    ----------
    psf : ndarray, shape (kh, kw)
        Odd-sized PSF, centre at ``(kh // 2, kw // 2)``. Must fit inside ``shape``.
    shape : (int, int)
        FFT shape (rows, columns).

    Notes
    -----
    For a ``kh x kw`` PSF the OTF is a separable DFT, ``H = E_y @ h @ E_x`` with
    ``E_y[k, j] = exp(-2 pi i k (j - kh//2) / M)`` (``M x kh``) and ``E_x`` its
    ``kw x (N//2 + 1)`` half-spectrum counterpart: two small matrix products, about 10x
    faster than padding and an ``rfft2`` for a 31 px PSF in a 720 x 720 FFT (the patch-wise
    case); the DFT matrices are cached per size. PSFs over ``_DIRECT_OTF_MAX`` px take the
    padded FFT. The two agree to float32 round-off (~1e-7).
    """
    psf = np.asarray(psf, dtype=np.float32)
    kh, kw = psf.shape
    if kh > shape[0] or kw > shape[1]:
        raise ValueError(f"PSF of shape {psf.shape} does not fit an FFT of shape {shape}")
    if max(kh, kw) <= _DIRECT_OTF_MAX:
        ey = _dft_matrix(int(shape[0]), kh, False)
        ex = _dft_matrix(int(shape[1]), kw, True)
        return ey @ (psf.astype(np.complex64) @ ex)
    padded = np.zeros(shape, dtype=np.float32)
    padded[:kh, :kw] = psf
    padded = np.roll(padded, (-(kh // 2), -(kw // 2)), axis=(0, 1))
    return sfft.rfft2(padded, workers=1).astype(np.complex64, copy=False)


#: Largest PSF side for which :func:`psf_to_otf` uses the direct separable DFT.
_DIRECT_OTF_MAX = 128


@functools.lru_cache(maxsize=64)
def _dft_matrix(n: int, k: int, half: bool) -> np.ndarray:
    """``exp(-2 pi i f (j - k//2) / n)``: (n, k) for all f, or (k, n//2 + 1) for the half."""
    freqs = np.arange(n // 2 + 1 if half else n, dtype=np.int64)
    offsets = np.arange(k, dtype=np.int64) - k // 2
    phase = np.outer(offsets, freqs) if half else np.outer(freqs, offsets)
    mat = np.exp((-2j * np.pi / n) * (phase % n)).astype(np.complex64)
    mat.flags.writeable = False
    return mat


def smooth_periodic_pad(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Extend ``image`` to ``shape`` so that its periodic extension has no jump.

    The chapter (sec. 6.5.1) blends opposite image borders over the PSF's width so that
    FFT-based deconvolution sees a smooth periodic signal. We do the same without
    touching a single image pixel: the image keeps its place at the top-left, and the
    added rows/columns cross-fade (raised cosine) from a mirror of the bottom/right
    border into a mirror of the top/left border. The wrap-around is then continuous in
    value and nearly in slope, which removes border ringing; crop ``[:H, :W]`` after
    deconvolution.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    shape : (int, int)
        Target rows and columns, each ``>= `` the image's and at least 2 more than it
        when padding is needed at all.

    Returns
    -------
    ndarray, shape ``shape + image.shape[2:]``, dtype of ``image``.
    """
    out = image
    for axis in (0, 1):
        out = _pad_axis(out, int(shape[axis]), axis)
    return out


def _pad_axis(image: np.ndarray, target: int, axis: int) -> np.ndarray:
    n = image.shape[axis]
    p = target - n
    if p < 0:
        raise ValueError(f"target length {target} is shorter than the image ({n})")
    if p == 0:
        return image
    idx = np.arange(p)
    # Mirror of the far border, continuing past the end: n-1, n-2, ...
    tail = np.take(image, np.clip(n - 1 - idx, 0, n - 1), axis=axis)
    # Mirror of the near border, arriving at index 0 from the left: ..., 1, 0
    head = np.take(image, np.clip(p - 1 - idx, 0, n - 1), axis=axis)
    w = 0.5 - 0.5 * np.cos(np.pi * (idx + 0.5) / p)
    wshape = [1] * image.ndim
    wshape[axis] = p
    w = w.reshape(wshape).astype(image.dtype, copy=False)
    fill = (1 - w) * tail + w * head
    return np.concatenate([image, fill.astype(image.dtype, copy=False)], axis=axis)


def convolve_fft(image: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """Convolve ``image`` with a centred PSF using circular FFT convolution.

    Boundary is periodic; callers pad first where that matters. Works on ``(H, W)`` and
    ``(H, W, C)`` (the PSF is applied to each channel). Returns float32.
    """
    image = np.asarray(image, dtype=np.float32)
    shape = image.shape[:2]
    otf = psf_to_otf(psf, shape)
    if image.ndim == 2:
        return sfft.irfft2(sfft.rfft2(image, workers=FFT_WORKERS) * otf, s=shape,
                           workers=FFT_WORKERS).astype(np.float32, copy=False)
    spec = sfft.rfft2(image, axes=(0, 1), workers=FFT_WORKERS) * otf[..., None]
    return sfft.irfft2(spec, s=shape, axes=(0, 1), workers=FFT_WORKERS).astype(np.float32,
                                                                               copy=False)
