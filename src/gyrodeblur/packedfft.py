"""Real 2-D FFTs in OpenCV's packed layout, for solvers that run many transforms per patch.

A real ``(M, N)`` image has a Hermitian spectrum: ``rfft2`` keeps its ``(M, N // 2 + 1)``
complex half. OpenCV's ``cv2.dft`` stores the same information in a real ``(M, N)`` float32
array ("CCS" packing) and computes it faster than ``scipy.fft`` on the patch sizes of
:mod:`gyrodeblur.sparse` (a 625 x 600 plane on one core: 0.75 against 1.05 ms forward,
0.86 against 1.02 ms inverse). A whole ADMM patch gained about 10 % (238 -> 212 ms, one
thread), the threaded 12 MP pipeline 5-10 %: there memory traffic limits both libraries.

Layout, for column frequency ``j`` and row frequency ``k`` of ``Y = rfft2(image)``:

* columns ``2j - 1, 2j`` (``1 <= j < N / 2``) hold ``Re Y[k, j], Im Y[k, j]`` for every row
  ``k = 0 .. M - 1``;
* column 0 (``j = 0``) and, for even ``N``, column ``N - 1`` (``j = N / 2``) hold the
  one-sided spectrum of a real sequence along the rows: ``Re Y[0], Re Y[1], Im Y[1],
  Re Y[2], Im Y[2], ...`` ending in ``Re Y[M / 2]`` for even ``M``.

Products of spectra go through ``cv2.mulSpectrums``, which knows this layout; a real
per-frequency factor (a Hermitian-symmetric one, such as ``|H|^2``) multiplies the packed
array element by element once spread over both slots of each frequency
(:func:`pack_spectrum` with ``real=True``).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["pack_spectrum", "packed_rfft2", "packed_irfft2", "packed_multiply"]

_INVERSE_FLAGS = cv2.DFT_REAL_OUTPUT | cv2.DFT_SCALE


def pack_spectrum(half: np.ndarray, width: int, *, real: bool = False) -> np.ndarray:
    """Pack an ``rfft2``-shaped spectrum ``(M, width // 2 + 1)`` into the ``(M, width)``
    float32 layout of this module.

    Parameters
    ----------
    half : ndarray, complex or real, shape (M, width // 2 + 1)
        The spectrum of a real image (Hermitian: the values that the packing leaves out
        must be the conjugates of those it keeps), e.g. from ``rfft2`` or
        :func:`gyrodeblur.fftutils.psf_to_otf`.
    width : int
        ``N``, the real image's number of columns (``half`` cannot tell odd from even).
    real : bool
        ``half`` is a real-valued factor to multiply spectra with: each value is written
        to both the real and the imaginary slot of its frequency, so that
        ``packed * pack_spectrum(f, N, real=True)`` is the packing of ``Y * f``. The
        factor must be Hermitian-symmetric (``f[k, j] == f[-k, j]`` in the columns ``j = 0``
        and ``N / 2``, as ``|H|^2`` is): only the rows ``k <= M / 2`` of those columns are
        read.

    Returns
    -------
    ndarray, float32, shape (M, width)
    """
    half = np.asarray(half)
    if half.ndim != 2 or half.shape[1] != width // 2 + 1:
        raise ValueError(f"spectrum of shape {half.shape} is not the rfft2 half of an image "
                         f"{width} columns wide")
    if real and np.iscomplexobj(half):
        raise ValueError("a real factor must be real-valued")
    M, N = half.shape[0], int(width)
    re = half.real
    im = re if real else half.imag
    out = np.empty((M, N), np.float32)
    inner = (N - 1) // 2                       # frequencies 1 .. inner fill column pairs
    out[:, 1:2 * inner:2] = re[:, 1:inner + 1]
    out[:, 2:2 * inner + 1:2] = im[:, 1:inner + 1]
    edges = [(0, 0)] + ([(N - 1, N // 2)] if N % 2 == 0 else [])
    rows = (M - 1) // 2                        # row frequencies 1 .. rows as (re, im) pairs
    for col, j in edges:
        out[0, col] = re[0, j]
        out[1:2 * rows:2, col] = re[1:rows + 1, j]
        out[2:2 * rows + 1:2, col] = im[1:rows + 1, j]
        if M % 2 == 0:
            out[M - 1, col] = re[M // 2, j]
    return out


def packed_rfft2(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Packed spectra of float32 images ``(..., M, N)``, one 2-D transform per plane.
    ``out``, if given, is a C-contiguous float32 array of the same shape (may be ``image``)."""
    image = np.ascontiguousarray(image, dtype=np.float32)
    out = _output(out, image)
    for src, dst in zip(_planes(image), _planes(out)):
        cv2.dft(src, dst=dst)
    return out


def packed_irfft2(spectrum: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Real images ``(..., M, N)`` from their packed spectra (the inverse of
    :func:`packed_rfft2`, scaled by ``1 / (M N)``); ``out`` as for :func:`packed_rfft2`."""
    spectrum = np.ascontiguousarray(spectrum, dtype=np.float32)
    out = _output(out, spectrum)
    for src, dst in zip(_planes(spectrum), _planes(out)):
        cv2.idft(src, dst=dst, flags=_INVERSE_FLAGS)
    return out


def packed_multiply(spectra: np.ndarray, factor: np.ndarray,
                    out: np.ndarray | None = None) -> np.ndarray:
    """Products ``spectra * factor`` of packed spectra, ``factor`` (M, N) applied to every
    plane of ``spectra`` (..., M, N); ``out`` may be ``spectra`` itself."""
    spectra = np.ascontiguousarray(spectra, dtype=np.float32)
    factor = np.ascontiguousarray(factor, dtype=np.float32)
    if factor.shape != spectra.shape[-2:]:
        raise ValueError(f"factor of shape {factor.shape} for spectra of shape {spectra.shape}")
    out = _output(out, spectra)
    for src, dst in zip(_planes(spectra), _planes(out)):
        cv2.mulSpectrums(src, factor, 0, c=dst)
    return out


def _output(out: np.ndarray | None, like: np.ndarray) -> np.ndarray:
    """``out``, checked to match ``like`` (OpenCV would silently write elsewhere)."""
    if out is None:
        return np.empty_like(like)
    if out.shape != like.shape:
        raise ValueError(f"out has shape {out.shape}, expected {like.shape}")
    return out


def _planes(a: np.ndarray) -> np.ndarray:
    """``a`` (..., M, N) as a stack of 2-D planes, a view (OpenCV writes into them)."""
    if a.dtype != np.float32 or not a.flags.c_contiguous or a.ndim < 2:
        raise ValueError(f"expected a C-contiguous float32 array of images, got {a.dtype} "
                         f"array of shape {a.shape}")
    return a.reshape((-1,) + a.shape[-2:])
