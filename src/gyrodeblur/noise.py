"""Estimate the standard deviation of additive white noise in a photo.

The regularisation weight of the sparse deconvolution (:mod:`gyrodeblur.sparse`) is set
from the noise level, so the level must be measured from the blurred photo itself when the
caller does not know it.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from .images import split_alpha

__all__ = ["estimate_noise_sigma", "coarse_noise_sigma", "coarse_noise_reading",
           "jpeg_noise_sigma", "photo_noise_sigma", "JPEG_NOISE_SCALE", "COARSE_MIN_SIDE"]

#: Scale (``[0, 1]`` units: 1.7 8-bit levels) of the level a JPEG is deconvolved for:
#: ``sigma^2 = estimate^2 + JPEG_NOISE_SCALE * q``, ``q = sqrt(mean(Q^2) / 12) / 255`` the
#: rms error of the luma steps ``Q``. Measured (session 23, scratch; see BENCHMARKS section
#: 2): six Lai photos blurred by warping at 40 and 30 dB, saved at quality 80-95 (4:2:0 and
#: 4:4:4), deblurred with the sparse method over a grid of levels. The best level grew
#: about 1.4x per doubling of the table, as ``sqrt(q)``, not as ``q``: a coarser table
#: zeroes more coefficients, whose error is less than a step's. The scale fitted on the
#: six was 0.0065 (0.0043-0.0093 leaving one photo out); ``benchmarks/jpeg_noise.py``
#: checks it on the six other shared photos.
JPEG_NOISE_SCALE = 0.0065

#: Shortest side (px) :func:`coarse_noise_sigma` reads: 8 x 8 at half resolution in each
#: phase.
COARSE_MIN_SIDE = 17

#: Median of |N(0, 1)| is 0.6745; 1 / 0.6745 turns a median absolute value into a sigma.
_MAD_TO_SIGMA = 1.482602218505602
#: Truncation point (in sigmas) of the refining step and the variance of N(0, 1) truncated
#: to +-3: 1 - 2 * 3 * phi(3) / (2 * Phi(3) - 1).
_TRUNC = 3.0
_TRUNC_VAR = 0.9733369246625415
#: The responses left after clipped highlights are taken out, below which those areas
#: are measured too (a page of text clipped nearly everywhere): this many, or half
#: the channel's in a small image.
_MIN_MEASURED = 400


def estimate_noise_sigma(image: np.ndarray, *, edge_quantile: float = 0.15,
                         max_pixels: int = 1_000_000) -> float:
    r"""Standard deviation of additive white Gaussian noise, in the image's own units.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The (blurred, noisy) image; for float32 photos in ``[0, 1]`` the answer is on the
        same ``[0, 1]`` scale (multiply by 255 for 8-bit levels). At least 8x8 pixels, of
        real values (integers in their own units; not booleans), finite where measured
        (``ValueError`` otherwise).
    edge_quantile : float, optional
        Fraction of pixels, those with the weakest smoothed gradient, that the estimate
        uses; edges and texture in the rest are ignored. 0.15 kept the bias on strongly
        textured test images within +5 % (0.5: +20 % at sigma 0.005).
    max_pixels : int, optional
        Larger images are measured on a regular subsample of rows and columns blocks
        (whole 3x3 neighbourhoods are kept), which bounds the time on 12 MP photos.

    Returns
    -------
    float
        The noise sigma, averaged over the channels.

    Notes
    -----
    Each channel is filtered with Immerkaer's noise-estimation mask, normalised to unit
    noise gain,

    .. math::
        r = \frac{1}{6}\begin{pmatrix}1&-2&1\\-2&4&-2\\1&-2&1\end{pmatrix} \star g ,

    the product of second differences along x and along y. Its response is zero along both
    frequency axes and rises as :math:`\omega_x^2 \omega_y^2` near the origin, so smooth
    shading, straight horizontal or vertical edges and anything a camera-shake blur has
    already smoothed barely reach it, while white noise passes with gain 1. Pixels whose
    Gaussian-smoothed gradient magnitude (sigma 1 px) lies above the ``edge_quantile``
    quantile are dropped: that removes oblique edges, corners and texture. The gradient
    filters are odd and the mask even, so for Gaussian noise the selection is independent of
    the response and does not bias the result. Before that, responses that touch a plateau
    at the channel's highest value (a pixel there with most of its 3 x 3 there too) are
    left out: clipped highlights are flat and carry no noise, and taken as the least
    textured pixels they had read a low-light photo 12.6 % clipped at a quarter of its
    noise (1.6 levels for 6.0); unless fewer than 400 responses (or half the channel's,
    in a small image) are left, as on a page clipped nearly everywhere. Crushed blacks
    stay: a photo whose noise was added in light and then encoded has its largest noise
    beside them, and leaving them out too read the demo's photo 20 % low and the
    benchmark's dark saturated photos 1.5-2x high. A first
    estimate is the median absolute deviation,
    :math:`\sigma_0 = 1.4826\,\mathrm{median}|r|`; the answer is the RMS of the responses
    within :math:`\pm 3\sigma_0`, divided by the RMS of a unit Gaussian truncated there
    (0.9866). The median alone moves in steps on 8-bit data (the
    responses of integer levels lie on a grid of 1/1530), up to 25 % apart at 40 dB
    noise; the truncated RMS does not. On photos it overestimates
    slightly where fine texture survives (1 % on average, at most 7 %, on the 12 blurred
    benchmark photos at sigma 0.0025-0.02); 8-bit
    quantisation adds its own :math:`1/\sqrt{12}` levels, which is noise the deconvolution
    sees too.

    References
    ----------
    J. Immerkaer, "Fast noise variance estimation", CVIU 64(2), 1996.
    D. L. Donoho, I. M. Johnstone, "Ideal spatial adaptation by wavelet shrinkage",
    Biometrika 81(3), 1994 (the MAD estimator).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> flat = np.full((128, 128), 0.5, np.float32)
    >>> noisy = flat + rng.normal(0, 0.02, flat.shape).astype(np.float32)
    >>> round(estimate_noise_sigma(noisy), 2)
    0.02
    """
    if np.asarray(image).dtype.kind not in "uif":
        raise ValueError(f"expected real pixel values, got dtype {np.asarray(image).dtype}")
    img = np.asarray(image, dtype=np.float32)
    if img.ndim not in (2, 3) or min(img.shape[:2]) < 8:
        raise ValueError(f"expected an (H, W) or (H, W, C) image of at least 8x8, got {img.shape}")
    if not 0 < edge_quantile <= 1:
        raise ValueError(f"edge_quantile must be in (0, 1], got {edge_quantile}")
    img = _subsample(img, max_pixels)
    if not np.isfinite(img).all():           # (of the pixels measured)
        raise ValueError("the image has NaN or infinite values: its noise cannot be measured")
    chans = [img] if img.ndim == 2 else [img[..., c] for c in range(img.shape[2])]
    sigmas = [_channel_sigma(np.ascontiguousarray(ch), edge_quantile) for ch in chans]
    return float(np.mean(sigmas))


def _channel_sigma(ch: np.ndarray, edge_quantile: float) -> float:
    d2 = np.array([1.0, -2.0, 1.0], dtype=np.float32)
    r = ndi.correlate1d(ndi.correlate1d(ch, d2, axis=0), d2, axis=1)[1:-1, 1:-1]
    r = np.abs(r.ravel()) / 6.0
    grad = ndi.gaussian_gradient_magnitude(ch, 1.0)[1:-1, 1:-1].ravel()
    # Clipped highlights (the channel's highest value) are flat and noise-free: their
    # responses would be the least textured and read no noise. Left out, unless they are
    # nearly the whole channel. (Crushed blacks are kept: beside them, noise added in
    # light and encoded is at its largest, and leaving them out read the demo 20 % low.)
    top = ch >= ch.max()            # a plateau there: most of a pixel's 3 x 3 at the top
    plateau = top & (ndi.uniform_filter(top.astype(np.float32), 3) > 0.5)
    clipped = ndi.maximum_filter(plateau, size=3)[1:-1, 1:-1]
    measured = ~clipped.ravel()
    if measured.sum() >= min(_MIN_MEASURED, measured.size // 2):
        r, grad = r[measured], grad[measured]
    if edge_quantile < 1:
        k = max(int(edge_quantile * grad.size) - 1, 0)
        thresh = np.partition(grad, k)[k]
        r = r[grad <= thresh]
    s0 = _MAD_TO_SIGMA * float(np.median(r))
    if s0 == 0.0:  # e.g. a flat or barely noisy 8-bit image: most responses are exactly 0
        return float(np.sqrt(np.pi / 2) * r.mean())
    # Refine with the variance of the responses within +-3 s0, corrected for the
    # truncation: continuous in the data, where the median of 8-bit data jumps in steps.
    kept = r[r <= _TRUNC * s0]
    return float(np.sqrt(np.mean(kept.astype(np.float64) ** 2) / _TRUNC_VAR))


def _subsample(img: np.ndarray, max_pixels: int) -> np.ndarray:
    """Keep a regular grid of 64-row and 64-column bands so that about max_pixels remain."""
    h, w = img.shape[:2]
    if h * w <= max_pixels:
        return img
    keep = np.sqrt(max_pixels / (h * w))  # fraction of rows (and of columns) to keep
    band = 64
    step = max(int(band / keep), band)
    rows = np.concatenate([np.arange(s, min(s + band, h)) for s in range(0, h, step)])
    cols = np.concatenate([np.arange(s, min(s + band, w)) for s in range(0, w, step)])
    # Bands are glued together; the few 3x3 neighbourhoods that straddle a seam are
    # outliers that the median ignores.
    return img[np.ix_(rows, cols)]


def jpeg_noise_sigma(estimate: float, luma_table) -> float:
    """The noise level to deconvolve a JPEG with: the measured ``estimate`` raised for the
    compression's own error.

    JPEG quantises each 8x8 block's DCT coefficients (an orthonormal transform) with the
    steps of ``luma_table``; a coefficient kept has an error up to uniform over its step,
    ``Q^2 / 12`` (8-bit levels), one zeroed has its own, smaller value. The quantisation
    removes the fine noise that :func:`estimate_noise_sigma` measures (on a quality-95
    photo it reads about half the noise, on a page of text next to none), while the error
    it leaves is amplified by the deconvolution like noise. So
    ``sigma = sqrt(estimate^2 + JPEG_NOISE_SCALE * q)``, ``q = sqrt(mean(Q^2) / 12) / 255``
    (:data:`JPEG_NOISE_SCALE`, measured), in the photo's ``[0, 1]`` units.

    Parameters
    ----------
    estimate : float
        The measured noise sigma, ``[0, 1]`` units.
    luma_table : sequence of 64 numbers
        The luma quantisation steps, 8-bit levels (``Photo.quantization[0]``).
    """
    steps = np.asarray(luma_table, np.float64)
    if steps.size != 64 or not np.all(np.isfinite(steps)) or np.any(steps <= 0):
        raise ValueError(f"luma_table must be 64 positive quantisation steps, got "
                         f"{steps.size} values")
    q = float(np.sqrt(np.mean(steps ** 2) / 12.0)) / 255.0
    return float(np.sqrt(float(estimate) ** 2 + JPEG_NOISE_SCALE * q))


def coarse_noise_sigma(image: np.ndarray, *, max_pixels: int = 2_000_000) -> float:
    """The white-noise level that :func:`estimate_noise_sigma` reads at half resolution:
    twice its estimate on the image averaged over 2 x 2 blocks (which halves white
    noise), in the image's own units; the largest over the four phases of the blocks.

    JPEG zeroes the fine frequencies' noise, which the full-resolution estimate reads (at
    quality 80, a quarter of it or less), and keeps the noise below about 0.25 cycles/px,
    whose quantisation steps are small: the noise the deconvolution amplifies. Blocks in
    phase with 4:2:0 chroma keep its noise, others average it with a neighbour's (on a
    test photo 20 % less); the largest of the four phases is read in any layout of the
    photo (rotated, cropped by a pixel). Texture leaks into it more than into the
    full-resolution estimate (a close-up of grass reads four times what that reads), so
    it is a bound beside the other, not the level itself.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        At least :data:`COARSE_MIN_SIDE` pixels a side (each phase's half-resolution
        image 8 x 8).
    max_pixels : int, optional
        Larger images are measured on bands of rows and columns, as
        :func:`estimate_noise_sigma` measures them (12 MP: 0.6 s, the full-resolution
        estimate 0.3 s, on a loaded 2-core VM).
    """
    img = _subsample(np.asarray(image, dtype=np.float32), max_pixels)
    if min(img.shape[:2]) < COARSE_MIN_SIDE:
        raise ValueError(f"expected an (H, W) or (H, W, C) image of at least "
                         f"{COARSE_MIN_SIDE}x{COARSE_MIN_SIDE}, got {img.shape}")
    readings = []
    for dy in (0, 1):
        for dx in (0, 1):
            x = img[dy:, dx:]
            x = x[:x.shape[0] // 2 * 2, :x.shape[1] // 2 * 2]
            half = 0.25 * (x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2])
            readings.append(2.0 * estimate_noise_sigma(half, max_pixels=half.shape[0]
                                                       * half.shape[1]))
    return max(readings)


def coarse_noise_reading(image: np.ndarray) -> float | None:
    """:func:`coarse_noise_sigma` where the image is large enough for it
    (:data:`COARSE_MIN_SIDE`), else ``None``."""
    if min(np.shape(image)[:2]) < COARSE_MIN_SIDE:
        return None
    return coarse_noise_sigma(image)


def photo_noise_sigma(photo, measured: float | None = None,
                      coarse: float | None = None) -> float:
    """The noise level to deconvolve a photo from :func:`gyrodeblur.imageio.read_photo`
    with: :func:`estimate_noise_sigma` of its colour channels (alpha left out); for a JPEG
    with quantisation tables, the larger of that and :func:`coarse_noise_sigma` (the
    noise the compression kept; a photo under :data:`COARSE_MIN_SIDE` px a side has only
    the first), raised
    by :func:`jpeg_noise_sigma`.

    ``measured``, ``coarse`` (optional): those readings, when the caller has them
    already. Pass the result as the sparse method's ``noise_sigma``
    (``deblur(..., noise_sigma=...)``).

    The coarse bound (session 62): a helper's held-out low-light JPEGs brought up by gain
    (quality 75-85, 4:2:0) read 1.0-7.2 levels at full resolution and had been
    deconvolved for 3.4-7.9, two of them into results below the blurred photo; with the
    bound they are deconvolved for 6.0-12.2 and gain 0.35-2.4 dB. A close-up of grass
    lost 0.9 dB (its texture read as noise). BENCHMARKS.md section 2 has the figures and
    ``benchmarks/jpeg_noise.py``'s (photos with little noise: about nothing).
    """
    colour = split_alpha(photo.pixels)[0]
    sigma = estimate_noise_sigma(colour) if measured is None else measured
    tables = getattr(photo, "quantization", None)
    if photo.format == "JPEG" and tables and 0 in tables:
        if coarse is None:
            coarse = coarse_noise_reading(colour)
        sigma = jpeg_noise_sigma(max(sigma, coarse or 0.0), tables[0])
    return sigma
