"""Image-quality metrics: PSNR as the chapter defines it, and SSIM.

Both compare a restored image with the sharp one on a central region that leaves out a
border (``border`` pixels on every side), where the scene outside the frame leaked into
the blur and no method can be fair; averaged over colour channels (an alpha channel,
the last of 2 or 4, is a mask and is left out). Images are on the [0, 1] scale: values
far outside it (0-255 floats) are refused rather than scored.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity

from .arguments import is_whole
from .images import PHOTO_MAX, PHOTO_MIN, check_image, split_alpha

__all__ = ["psnr", "ssim", "crop_border", "default_border"]


def default_border(shape: tuple[int, ...], psf_radius: int | None = None,
                   fraction: float = 0.05) -> int:
    """The border left out of the metrics: the PSF radius when known, else
    ``fraction`` of the smaller image side (5 %)."""
    if psf_radius is not None:
        return int(psf_radius)
    return int(round(fraction * min(shape[:2])))


def crop_border(image: np.ndarray, border: int) -> np.ndarray:
    """``image`` without ``border`` pixels on each side."""
    if not (is_whole(border) and border >= 0):
        raise ValueError(f"border must be a whole number of pixels >= 0, got {border!r}")
    if border == 0:
        return image
    if 2 * border >= min(image.shape[:2]):
        raise ValueError(f"border {border} leaves nothing of an image of shape {image.shape}")
    return image[border:-border, border:-border]


def psnr(reference: np.ndarray, estimate: np.ndarray, border: int = 0) -> float:
    """PSNR in dB on the 8-bit scale, eq. of sec. 6.6:
    ``10 log10(|Omega| 255^2 / ||u - u_hat||^2)`` with images in [0, 1] scaled by 255,
    over the central region and all channels (i.e. the channel-averaged MSE)."""
    a, b = _pair(reference, estimate, border)
    a, b = a * 255.0, b * 255.0
    mse = np.mean((a - b) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0 ** 2 / mse))


def ssim(reference: np.ndarray, estimate: np.ndarray, border: int = 0) -> float:
    """SSIM (scikit-image's, Gaussian-weighted as Wang et al. 2004, data range 1) over the
    central region, averaged over channels."""
    a, b = _pair(reference, estimate, border, min_size=11)     # the 11x11 Gaussian window
    kw = dict(data_range=1.0, gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
    if a.ndim == 3:
        return float(np.mean([structural_similarity(a[..., c], b[..., c], **kw)
                              for c in range(a.shape[2])]))
    return float(structural_similarity(a, b, **kw))


def _pair(reference, estimate, border: int, min_size: int = 1):
    """Both images checked (float, finite, on the [0, 1] scale, the same shape), their
    colour channels (alpha left out), cropped, as float64."""
    a, b = (check_image(image, what, min_size=1, dtype=np.float64, max_value=PHOTO_MAX,
                        min_value=PHOTO_MIN)
            for image, what in ((reference, "reference"), (estimate, "estimate")))
    if a.shape != b.shape:
        raise ValueError(f"reference and estimate differ in shape: {a.shape} and {b.shape}")
    a, b = split_alpha(a)[0], split_alpha(b)[0]
    a, b = crop_border(a, border), crop_border(b, border)
    if min(a.shape[:2]) < min_size:
        raise ValueError(f"{a.shape[1]}x{a.shape[0]} pixels (after a border of {border}) are "
                         f"too few; need at least {min_size}x{min_size}")
    return a, b
