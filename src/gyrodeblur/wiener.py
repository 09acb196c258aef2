"""Wiener deconvolution with a known PSF (chapter sec. 6.5.1, eq. 6.18).

The filter is the chapter's

.. math:: \\hat U = G \\, \\frac{H^*}{|H|^2 + \\Phi},

applied to every colour channel in one real FFT, in float32/complex64. Two departures
from the raw formula, both deliberate:

* **DC gain is exactly 1.** At zero frequency the raw filter gives
  ``H(0) / (H(0)^2 + phi) = 1 / (1 + phi)`` (the PSF sums to 1), i.e. it darkens the
  whole photo by about 1 % at ``phi = 0.01``. We set the filter's DC bin to
  ``1 / H(0) = 1`` so that a flat image stays flat and the mean brightness is kept;
  every other frequency follows eq. 6.18 unchanged.
* **Border blending without touching pixels.** The chapter blends opposite image
  borders over the PSF's width before filtering. We instead pad the image (never resize
  it) by at least the PSF's size, up to fast FFT lengths, with
  :func:`~gyrodeblur.fftutils.smooth_periodic_pad`, whose added band cross-fades from
  the bottom/right border into the top/left one; the result is cropped back.

Public names: :func:`wiener_deconvolve` (the entry point), and its building blocks
:func:`wiener_fft_shape`, :func:`wiener_filter`, :func:`apply_spectral_filter` and
:func:`normalize_range` for callers that want to reuse an OTF or normalise once after
blending patches.
"""

from __future__ import annotations

import numbers

import numpy as np
import scipy.fft as sfft

from .arguments import check_flag
from .errors import InputError
from .fftutils import fast_shape, psf_to_otf, smooth_periodic_pad, usable_cpus
from .images import check_image, check_psf

__all__ = [
    "wiener_deconvolve",
    "wiener_fft_shape",
    "wiener_filter",
    "apply_spectral_filter",
    "normalize_range",
    "check_phi",
    "photo_phi",
    "DEFAULT_PHI",
    "NORMALIZE_PERCENTILES",
]

#: The chapter's inverse-SNR value, "determined experimentally to provide the best
#: looking results" (sec. 6.5.1).
DEFAULT_PHI: float = 0.01

#: :func:`photo_phi`'s factor on the photo's noise-to-signal ratio. Measured (session 49,
#: one run): scikit-image's astronaut, chelsea and camera at a quarter of their brightness
#: with shot noise (variance 0.01 x + 1e-4 in linear light), 8-bit, a 15 ms hand shake:
#: ratios 0.11-0.34, and of phi 0.01 / 0.03 / 0.1 / 0.3 the last was best on all three
#: (22.4, 26.6, 24.4 dB, blurred 20.6-21.2; 0.01 gave 15.4-16.3).
PHOTO_PHI_FACTOR = 3.0

#: Lower and upper percentiles (in %) that :func:`normalize_range` clips to.
NORMALIZE_PERCENTILES: tuple[float, float] = (0.1, 99.9)


def wiener_deconvolve(image: np.ndarray, psf: np.ndarray, phi: float = DEFAULT_PHI, *,
                      taper: bool = True, normalize: bool = False) -> np.ndarray:
    """Deconvolve ``image`` by ``psf`` with the Wiener filter of eq. 6.18.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Blurred image, linear values nominally in [0, 1]. Computed in float32.
    psf : ndarray, shape (kh, kw)
        Odd-sized PSF whose centre sample is offset 0 (``g(x) = sum_s h(s) u(x - s)``).
        It is divided by its sum, so it need not be normalised exactly.
    phi : float, optional
        Inverse signal-to-noise ratio :math:`\\Phi` (> 0). Larger is smoother and rings
        less; the chapter uses 0.01 for phone photos.
    taper : bool, optional
        ``True`` (default): pad by at least the PSF's size to fast FFT lengths with a
        smooth periodic extension, so the borders do not ring. ``False``: filter the image
        at its own size with the FFT's periodic boundary (the raw formula; it rings at
        non-periodic borders and can be slow for sizes with large prime factors).
    normalize : bool, optional
        Apply the chapter's optional "normalization with clipping of outliers"
        (:func:`normalize_range`): clip the result to its 0.1st/99.9th percentiles and map
        that range linearly onto the input's ``[min, max]``. Off by default because it is
        not photometrically neutral: it rescales contrast by a data-dependent factor, so
        the output is no longer linear in the input, and when each patch of a
        space-variant deconvolution normalises itself, neighbouring patches get different
        gains and the blend shows brightness steps. Normalise once, after blending, if at
        all.

    Returns
    -------
    ndarray, float32, same shape as ``image``
        Values may leave [0, 1] (overshoot at edges) unless ``normalize`` is set; clip or
        normalise when writing the file.

    Raises
    ------
    InputError
        ``phi`` is not a positive finite number (source ``"phi"``); ``image`` fails
        :func:`~gyrodeblur.images.check_image`, or ``psf``
        :func:`~gyrodeblur.images.check_psf` (2-D, odd sides, finite, positive sum).

    Notes
    -----
    With :math:`G`, :math:`H` the DFTs of the (padded) image and the PSF,

    .. math::

        W(\\omega) = \\frac{H^*(\\omega)}{|H(\\omega)|^2 + \\Phi} \\quad (\\omega \\neq 0),
        \\qquad W(0) = 1 / H(0) = 1, \\qquad \\hat U = W G.

    The raw eq. 6.18 has DC gain :math:`1/(1+\\Phi)` and would darken the photo by about
    1 %; setting :math:`W(0) = 1/H(0)` keeps the mean, so a flat image stays flat.
    All channels share one OTF (:func:`~gyrodeblur.fftutils.psf_to_otf`) and go through
    one ``rfft2``/``irfft2`` pair over axes (0, 1), in complex64, with
    as many threads as :func:`~gyrodeblur.fftutils.usable_cpus`.

    References
    ----------
    F. Sroubek, J. Flusser, "Removing camera shake in smartphones without hardware
    stabilization", sec. 6.5.1, eq. (6.18).

    Examples
    --------
    >>> import numpy as np
    >>> img = np.full((32, 48), 0.5, np.float32)
    >>> psf = np.full((1, 5), 0.2)
    >>> out = wiener_deconvolve(img, psf)
    >>> out.dtype, out.shape, bool(np.allclose(out, 0.5, atol=1e-6))
    (dtype('float32'), (32, 48), True)
    """
    check_flag(taper, "taper")
    check_flag(normalize, "normalize")
    image = _as_image(image)
    psf = check_psf(psf)
    phi = check_phi(phi)
    height, width = image.shape[:2]
    shape = wiener_fft_shape(image.shape, psf.shape, taper=taper)
    padded = smooth_periodic_pad(image, shape) if shape != (height, width) else image
    filt = wiener_filter(psf_to_otf(psf, shape), phi)
    out = apply_spectral_filter(padded, filt, crop=(height, width))
    if normalize:
        out = normalize_range(out, image)
    return out


def wiener_fft_shape(image_shape: tuple[int, ...], psf_shape: tuple[int, int], *,
                     taper: bool = True) -> tuple[int, int]:
    """FFT shape that :func:`wiener_deconvolve` uses for an image and PSF of these shapes.

    With ``taper`` it is the smallest fast real-FFT shape at least
    ``(H + kh, W + kw)``, so the smooth border band is at least as wide as the PSF;
    without it, the image's own ``(H, W)``.
    """
    height, width = int(image_shape[0]), int(image_shape[1])
    if not taper:
        return height, width
    return fast_shape((height + int(psf_shape[0]), width + int(psf_shape[1])))


def wiener_filter(otf: np.ndarray, phi: float = DEFAULT_PHI) -> np.ndarray:
    """Wiener filter ``conj(H) / (|H|^2 + phi)`` with its DC bin set to ``1 / H(0)``.

    Parameters
    ----------
    otf : ndarray, complex, shape (M, N // 2 + 1)
        Half-spectrum OTF as returned by :func:`~gyrodeblur.fftutils.psf_to_otf`.
    phi : float
        Inverse SNR, > 0.

    Returns
    -------
    ndarray, complex64, same shape as ``otf``.
    """
    phi = check_phi(phi)
    otf = np.asarray(otf).astype(np.complex64, copy=False)
    dc = otf[0, 0]
    if dc == 0:
        raise ValueError("the PSF sums to zero: its DC gain cannot be inverted")
    re, im = otf.real, otf.imag
    scale = re * re
    scale += im * im
    scale += np.float32(phi)
    np.reciprocal(scale, out=scale)
    # conj(H) / (|H|^2 + phi), written part by part (a complex division costs far more).
    filt = np.empty_like(otf)
    np.multiply(re, scale, out=filt.real)
    np.multiply(im, scale, out=filt.imag)
    np.negative(filt.imag, out=filt.imag)
    filt[0, 0] = 1.0 / dc
    return filt


def apply_spectral_filter(padded: np.ndarray, filt: np.ndarray,
                          crop: tuple[int, int] | None = None) -> np.ndarray:
    """Multiply every channel's spectrum by ``filt`` and return the cropped result.

    This is the FFT core of :func:`wiener_deconvolve`, for callers that keep a filter
    (or OTF-derived filter) for several images of the same padded shape.

    Parameters
    ----------
    padded : ndarray, float32, shape (M, N) or (M, N, C)
        Image already padded to the FFT shape.
    filt : ndarray, complex64, shape (M, N // 2 + 1)
        Spectral filter (e.g. from :func:`wiener_filter`), shared by all channels.
    crop : (int, int), optional
        Rows and columns to keep from the top-left corner; default all.

    Returns
    -------
    ndarray, float32, C-contiguous, shape ``crop + padded.shape[2:]``.
    """
    shape = padded.shape[:2]
    if filt.shape != (shape[0], shape[1] // 2 + 1):
        raise ValueError(f"filter of shape {filt.shape} does not match an FFT of shape {shape}")
    workers = usable_cpus()
    spec = sfft.rfft2(padded, axes=(0, 1), workers=workers)
    if spec.dtype != np.complex64:
        spec = spec.astype(np.complex64)
    spec *= filt if padded.ndim == 2 else filt[..., None]
    out = sfft.irfft2(spec, s=shape, axes=(0, 1), workers=workers, overwrite_x=True)
    if crop is not None:
        out = out[:crop[0], :crop[1]]
    return np.ascontiguousarray(out, dtype=np.float32)


def normalize_range(result: np.ndarray, reference: np.ndarray,
                    percentiles: tuple[float, float] = NORMALIZE_PERCENTILES) -> np.ndarray:
    """The chapter's "normalization with clipping of outliers", defined precisely.

    Let ``lo, hi`` be the ``percentiles`` (default 0.1 % and 99.9 %) of ``result`` over
    all pixels and channels together (one gain for all channels keeps the colour
    balance), and ``rmin, rmax`` the minimum and maximum of ``reference`` (the blurred
    input). Then

    ``out = rmin + (clip(result, lo, hi) - lo) * (rmax - rmin) / (hi - lo)``,

    so the outliers (ringing overshoot, the darkest and brightest 0.1 %) are clipped and
    the rest is mapped linearly onto the input's range. If ``hi == lo`` (a flat result)
    the result is only clipped to ``[rmin, rmax]``.

    Parameters
    ----------
    result : ndarray
        Deconvolved image.
    reference : ndarray
        The image whose value range to map onto, normally the blurred input.
    percentiles : (float, float)
        Lower and upper clipping percentiles, ``0 <= lower < upper <= 100``.

    Returns
    -------
    ndarray, float32, same shape as ``result``.
    """
    p_lo, p_hi = (float(p) for p in percentiles)
    if not 0.0 <= p_lo < p_hi <= 100.0:
        raise ValueError(f"percentiles must satisfy 0 <= lower < upper <= 100, got {percentiles}")
    result = np.asarray(result, dtype=np.float32)
    reference = np.asarray(reference)
    rmin, rmax = np.float32(reference.min()), np.float32(reference.max())
    lo, hi = (np.float32(v) for v in np.percentile(result, (p_lo, p_hi)))
    if not hi > lo:
        return np.clip(result, rmin, rmax)
    out = np.clip(result, lo, hi)
    out -= lo
    out *= np.float32((rmax - rmin) / (hi - lo))
    out += rmin
    return out


def _as_image(image: np.ndarray) -> np.ndarray:
    return check_image(image)


def photo_phi(encoded: np.ndarray) -> float:
    """The Wiener method's default ``phi`` for a photo (its values as encoded): the
    chapter's :data:`DEFAULT_PHI`, or the photo's own noise-to-signal ratio where that is
    larger, :data:`PHOTO_PHI_FACTOR` x ``sigma^2 / var`` (``sigma`` the photo's noise,
    :func:`gyrodeblur.noise.estimate_noise_sigma`, and ``var`` its variance, both on the
    values as encoded, where a sensor's noise is roughly uniform).

    On a photo in good light the ratio is 1e-4 to 0.02, and this is the chapter's filter.
    On a dark, noisy one the chapter's 0.01 amplifies the noise past the blurred photo's
    PSNR. Session 49, one run: five scikit-image photos, a 15 ms hand shake, 384 px,
    8-bit, shot noise at four levels and none (25 cases). With no noise this gave 0.01;
    in the 20 noisy cases it beat 0.01 in all (by up to 10.7 dB; 0.01 gave 15.4-24.9 dB,
    16 of them below the blurred photo), came within 0.5 dB of the best of 0.01 / 0.1 /
    0.3 in 18 (1.0 and 1.6 dB in the other two), and beat the blurred photo in all 25.
    """
    from .noise import estimate_noise_sigma
    g = np.asarray(encoded, np.float32)
    var = float(np.var(g))
    if not var > 0:
        return DEFAULT_PHI
    return max(DEFAULT_PHI, PHOTO_PHI_FACTOR * estimate_noise_sigma(g) ** 2 / var)


def check_phi(phi: float) -> float:
    """``phi`` as a float, or :class:`InputError` unless it is a positive finite number."""
    if isinstance(phi, bool) or not isinstance(phi, numbers.Real) or not np.isfinite(phi) \
            or phi <= 0:
        raise InputError.of_argument("phi", f"must be a positive number (inverse SNR), got {phi!r}")
    return float(phi)
