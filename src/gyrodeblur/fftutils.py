"""FFT helpers shared by every deconvolution method.

Conventions: images are float32 arrays of shape ``(H, W)`` or ``(H, W, C)``; a PSF is a
2-D odd-sized float array that sums to 1, whose centre sample is the PSF's reference
point (pixel offset 0). Convolution means ``g(x) = sum_s h(s) u(x - s)``, so a PSF whose
mass sits at offset ``+d`` moves content by ``+d``.
"""

from __future__ import annotations

import os
import warnings

import numpy as np
import scipy.fft as sfft

from .errors import GyrodeblurWarning

__all__ = [
    "THREADS_ENV",
    "usable_cpus",
    "fast_shape",
    "psf_to_otf",
    "smooth_periodic_pad",
    "convolve_fft",
]

#: Environment variable that caps the CPUs one gyrodeblur process uses (its FFT threads,
#: row bands and calibration workers): e.g. ``1`` where several processes run at once.
THREADS_ENV = "GYRODEBLUR_THREADS"


#: The ``GYRODEBLUR_THREADS`` values that were not whole numbers >= 1, warned of once each.
_SAID_BAD_CAPS: set = set()


def usable_cpus() -> int:
    """The CPUs this process may run on: its affinity mask where the system has one
    (``taskset``, a container's cpuset), else every core of the machine, and at most
    ``$GYRODEBLUR_THREADS`` where that is set (a whole number >= 1; anything else is
    ignored, with a warning). ``os.cpu_count`` counts the machine's cores, so a process
    held to 2 of 64 cores would start 64 threads.

    Read at each call (the FFTs' threads, the row bands, the calibration's workers), so a
    cap or an affinity set after ``import gyrodeblur`` (a process pool's initializer)
    counts."""
    try:
        n = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):       # not on Linux
        n = os.cpu_count() or 1
    cap = os.environ.get(THREADS_ENV, "").strip()
    if cap:
        if cap.isdecimal() and int(cap) >= 1:
            n = min(n, int(cap))
        elif cap not in _SAID_BAD_CAPS:        # read at every call: said once
            _SAID_BAD_CAPS.add(cap)
            warnings.warn(f"{THREADS_ENV}={cap!r} is not a whole number >= 1: ignored",
                          GyrodeblurWarning, stacklevel=2)
    return n


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
    One single-threaded ``scipy.fft.rfft2`` of the padded PSF (0.9 ms for a 540 x 576 FFT).
    Not the separable DFT as two small matrix products (``E_y @ h @ E_x``), although that
    is twice as fast on its own: matrix products go to the BLAS, and OpenBLAS's threads
    busy-wait for a while after every call. Called once per patch inside the patch-wise
    thread pool, that spinning took as much CPU as the deconvolution itself and a 12 MP
    space-variant deblur on 2 cores took 10.1 s instead of 7.9 s.
    """
    psf = np.asarray(psf, dtype=np.float32)
    kh, kw = psf.shape
    if kh > shape[0] or kw > shape[1]:
        raise ValueError(f"PSF of shape {psf.shape} does not fit an FFT of shape {shape}")
    padded = np.zeros(shape, dtype=np.float32)
    padded[:kh, :kw] = psf
    padded = np.roll(padded, (-(kh // 2), -(kw // 2)), axis=(0, 1))
    return sfft.rfft2(padded, workers=1).astype(np.complex64, copy=False)


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
    workers = usable_cpus()                 # now: a cap or an affinity set after import
    if image.ndim == 2:
        return sfft.irfft2(sfft.rfft2(image, workers=workers) * otf, s=shape,
                           workers=workers).astype(np.float32, copy=False)
    spec = sfft.rfft2(image, axes=(0, 1), workers=workers) * otf[..., None]
    return sfft.irfft2(spec, s=shape, axes=(0, 1), workers=workers).astype(np.float32,
                                                                         copy=False)
