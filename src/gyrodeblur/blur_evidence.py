"""Whether a photo shows a given blur: a kernel's spectral evidence against no blur at all.

The same test guards a gyro deblur (:func:`capture_gain_over_no_blur`): PSFs from a log
whose clock, exposure start or axes are far off, or from another shot's log, explain the
photo worse than no blur, and deblurring with them makes it worse without a word.

A blind kernel estimate can be wrong in a way its own cost does not see: on a photo with
little blur (a page of text, a near-sharp shot) the alternating MAP estimate can settle on
a streak several pixels long, and deconvolving with it rings. The photo's spectrum tells:
under the calibration's criterion (:mod:`gyrodeblur.spectral_criterion`, a Whittle
likelihood with an envelope fitted to each patch), a kernel the photo really shows explains
its most textured patches better than no blur, and a wrong one explains them worse, because
its ``|H|^2`` puts dips where the photo has none. The criterion sees only ``|H|``, so a kernel
and its reflection score alike; it is a check, not an estimator.

Seeing only ``|H|`` it can also be fooled: on a repeating pattern or a page of text a
kernel shaped like the pattern fits the spectrum's lines. A blind kernel is therefore also
asked to sharpen the photo (:func:`kernel_sparsity_ratio`): deconvolved with it, the
textured windows' gradients must come out sparser than deconvolved with no blur, as they
do where the kernel gathers blurred edges and do not where it adds ghost ones.
"""

from __future__ import annotations

import numpy as np

from .calibration_fit import (_TEMPERATURE, FINE_ROWS, SMALLEST_PATCH, fine_samples,
                              spectral_band, working_patch)
from .calibration_patches import CalibrationPhoto, patch_centres
from .calibration_search import psf_extent_and_path
from .spectral_criterion import Corrections, PatchSpectra

__all__ = ["NO_BLUR_MARGIN", "WRONG_BLUR_MARGIN", "SPARSER_MAX", "kernel_gain_over_no_blur",
           "kernel_sparsity_ratio", "blind_kernel_evidence", "capture_gain_over_no_blur"]

#: A kernel (or a calibration's PSFs) must explain a photo's patches better than no blur at
#: all by this much (tempered nats per 9 patches); below it, the photo shows little of that
#: blur. On the calibration benchmark's 24 cases the true PSFs' gains were 3.4 (7 px of blur)
#: to 140; the sharp originals given the same captures (six cases) and a sharp photo given a
#: capture of 27 px blur scored 4.5, 0.7, 0.2, -3.7, -26, -43 and -46. Blind kernels
#: (session 37, BENCHMARKS.md section 2): on Levin et al.'s protocol (12 photos x 8 kernels,
#: one true kernel each) every true kernel passed (gains 5.5 and up) and 93 of 96 estimates,
#: the 3 dropped each deblurring worse than the input; on the 36 gyro-blur cases, where one
#: kernel cannot fit a rolling shutter's blur, 16 of 36.
NO_BLUR_MARGIN = 1.0
#: A capture whose PSFs explain a photo worse than no blur at all by more than this
#: (tempered nats per 9 patches) is not the photo's, or the photo is sharp: a deblur with
#: it makes the photo worse. On the 36 cases of the benchmark dataset (session 39) the true
#: captures scored +0.3 (the fence, lai_manmade_03_w0) to +136; the same blurred photos
#: given an exposure 0.3 s late -148 to +0.0 (35 of 36 below this), their sharp originals
#: -96 to -0.3 (33 of 36 below: the three above have 7-9 px of blur); the real Shield
#: frames with their hand-worked captures +45 to +83. A photo softer than its pixels scores
#: low with its true capture too: three of those photos upscaled 4.15x (12 MP) scored +3,
#: -27 and -59, and one upscaled 2x -41.
WRONG_BLUR_MARGIN = -5.0

#: A blind kernel must also make the photo sharper than no blur does: deconvolved with
#: it (the sparse method), the most textured windows' gradients must be sparser than
#: deconvolved with no blur, their L1/L2 (:func:`kernel_sparsity_ratio`) under this
#: fraction of the latter's. The spectral gain above sees only ``|H|``, so a repeating
#: pattern or a page of text can pass it with a kernel shaped like the pattern (session
#: 59's audit: +21 nats for a crisp synthetic text page, which came out at 8 dB against
#: itself); its phase does not fit, and deconvolving with it adds ghost edges rather than
#: gathering blurred ones. On that audit's cases (scratch ``/tmp/w/s59/nsm``: 39 photos
#: blurred by lines, arcs, random walks, a disc and a Levin kernel at 0-2 % noise, and 21
#: with no blur) the 29 estimates that deblurred 0.3 dB or more better than their input
#: measured 0.61-0.82, the no-blur photos' false kernels 0.94-1.30 but one (a brick wall,
#: 0.86, which passes). On Levin et al.'s protocol (96 cases) the true kernels measured
#: 0.55-0.80 and the estimates 0.56-0.94 (BENCHMARKS.md section 2). A blind estimate is
#: the sparsest explanation the estimator found, and measures lower than the true kernel
#: (0.78 against 0.88 on ``test_blur_evidence``'s soft scene); the true kernels of blurs
#: of about 5 px measured 0.82-0.91 in a review, so a short blur's estimate has the
#: smallest margin.
SPARSER_MAX = 0.9

_PATCHES = 9


def kernel_gain_over_no_blur(image: np.ndarray, psf: np.ndarray, *, transfer="srgb",
                             n_patches: int = _PATCHES) -> float:
    """How much better one kernel explains a photo than no blur at all.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo, float in [0, 1] (a last channel of 2 or 4 is alpha, ignored).
    psf : ndarray (k, k)
        The kernel, odd square, centred, at the photo's resolution (pixels).
    transfer : str or TransferCurve
        Transfer curve of the photo's values (the patches are read in linear light).
    n_patches : int
        Most textured, unclipped windows spread over the photo that are scored
        (:func:`gyrodeblur.calibration_patches.select_patch_centres`).

    Returns
    -------
    float
        The gain in tempered nats per 9 patches (the calibration's units): compare with
        :data:`NO_BLUR_MARGIN`. ``nan`` when the photo is too small for the kernel (a
        working-scale patch under 48 px) or has no textured window.

    Notes
    -----
    Each window is taken at a working scale where the kernel spans at most 32 px, as
    calibration does, in patches of up to 128 px; the kernel's transfer function is
    evaluated exactly at that scale's frequencies
    (:meth:`gyrodeblur.spectral_criterion.PatchSpectra.psf_gain_over_no_blur`).
    """
    return _kernel_gain(CalibrationPhoto(image, None, transfer, 0), psf, n_patches)


def _kernel_gain(photo: CalibrationPhoto, psf: np.ndarray, n_patches: int) -> float:
    """:func:`kernel_gain_over_no_blur` on a photo already read."""
    k = np.asarray(psf, np.float64)
    rows, cols = np.nonzero(k > 0)
    extent = float(max(np.ptp(rows), np.ptp(cols)) + 1) if rows.size else 1.0
    windows = _windows(photo, extent, n_patches)
    if windows is None:
        return float("nan")
    spectra = PatchSpectra([photo], *windows)
    return _per_9_patches(spectra.psf_gain_over_no_blur(k))


def kernel_sparsity_ratio(image: np.ndarray, psf: np.ndarray, *, transfer="srgb",
                          n_patches: int = _PATCHES) -> float:
    """How much sparser a photo's gradients are deconvolved with a kernel than with none.

    Parameters
    ----------
    image, psf, transfer, n_patches
        As for :func:`kernel_gain_over_no_blur` (the windows here are deconvolved).

    Returns
    -------
    float
        Mean over the windows of the gradients' normalised sparsity (``|grad u|_1 /
        |grad u|_2``, :func:`_sparsity`) of each window's linear-light luminance
        deconvolved with ``psf``, over the same deconvolved with a one-pixel kernel; both
        by the sparse method, so that both are denoised alike. Under 1 the kernel sharpens
        the photo: compare with :data:`SPARSER_MAX`. ``nan`` when no window is textured,
        or the photo leaves a window under 32 px inside its kernel-wide margin.

    Notes
    -----
    A blur spreads each edge over the kernel's length, and the right kernel gathers it
    again, while a wrong one adds ghost edges. Windows are ``6 k`` px (96-256) plus a
    ``k`` px margin each side, deconvolved at full resolution; the measure leaves the
    margin out.
    """
    return _sparsity_ratio(CalibrationPhoto(image, None, transfer, 0), psf, n_patches)


def blind_kernel_evidence(image: np.ndarray, psf: np.ndarray, *,
                          transfer="srgb") -> tuple[float, float]:
    """Both tests of a blind kernel, on one reading of the photo (its windows chosen once):
    ``(gain, ratio)`` of :func:`kernel_gain_over_no_blur` and
    :func:`kernel_sparsity_ratio`; ``ratio`` is ``nan`` where the gain is already under
    :data:`NO_BLUR_MARGIN` (not computed)."""
    photo = CalibrationPhoto(image, None, transfer, 0)
    gain = _kernel_gain(photo, psf, _PATCHES)
    if gain < NO_BLUR_MARGIN:
        return gain, float("nan")
    return gain, _sparsity_ratio(photo, psf, _PATCHES)


#: Smallest side (px) of a window's part inside its kernel-wide margin that
#: :func:`kernel_sparsity_ratio` measures: a photo smaller than that is not judged.
_SPARSITY_MIN_SIDE = 32


def _sparsity_ratio(photo: CalibrationPhoto, psf: np.ndarray, n_patches: int) -> float:
    """:func:`kernel_sparsity_ratio` on a photo already read."""
    from .deblur import deblur_with_psfs
    from .tiling import patch_grid

    k = np.asarray(psf, np.float32)
    ks = k.shape[0]
    side = int(np.clip(6 * ks, 96, 256))
    full = side + 2 * ks
    if min(photo.H, photo.W, full) - 2 * ks < _SPARSITY_MIN_SIDE:
        return float("nan")
    one = np.ones((1, 1), np.float32)
    measures, seen = [], set()
    for _, x, y in patch_centres([photo], n_patches, side):
        y0 = int(np.clip(round(y) - full // 2, 0, max(photo.H - full, 0)))
        x0 = int(np.clip(round(x) - full // 2, 0, max(photo.W - full, 0)))
        if (y0, x0) in seen:           # a photo smaller than a window has just one
            continue
        seen.add((y0, x0))
        window = photo.gray(y0, y0 + full, x0, x0 + full).astype(np.float32)
        patches = patch_grid(window.shape, (1, 1), 0.0)
        pair = [_sparsity(deblur_with_psfs(window, patches, [kernel], method="sparse",
                                           transfer="linear")[ks:-ks, ks:-ks])
                for kernel in (k, one)]
        if pair[1] > 0:
            measures.append(pair)
    if not measures:
        return float("nan")
    with_kernel, without = np.mean(measures, axis=0)
    return float(with_kernel / without)


def _sparsity(u: np.ndarray) -> float:
    """``|grad u|_1 / |grad u|_2`` over ``sqrt(n)``, each axis's forward differences
    counted on their own: ``sqrt(2)`` where every difference has one size, lower for
    sparser gradients; 0 for a flat ``u``.

    Not :meth:`gyrodeblur.spectral_criterion.PatchSpectra.sparsity`'s measure (central
    differences' magnitudes), which calibration's twin test reads at its working scale:
    central differences do not see the finest detail (their response is 0 at Nyquist),
    which is what a right kernel restores at full resolution, and a streak sharpens one
    axis's differences. On a photo streaked along x on its left half and along y on its
    right, the one-kernel compromise that a 1 x 2 grid then refines measured 0.96 by
    magnitudes and under 0.9 by this (``test_blind_kernels_per_patch_follow_a_blur...``)."""
    gx = np.diff(u, axis=1)[:-1].astype(np.float64)
    gy = np.diff(u, axis=0)[:, :-1].astype(np.float64)
    l2 = np.sqrt((gx ** 2).sum() + (gy ** 2).sum())
    if not l2 > 0:
        return 0.0
    return float((np.abs(gx).sum() + np.abs(gy).sum()) / l2 / np.sqrt(gx.size))


def capture_gain_over_no_blur(image: np.ndarray, capture, *, transfer="srgb",
                              n_patches: int = _PATCHES) -> float:
    """How much better a capture's PSFs explain a photo than no blur at all.

    The calibration's own test of its result (``calibrate`` warns under
    :data:`NO_BLUR_MARGIN`), for a capture taken as it is: each of the photo's most textured
    windows is scored with the PSFs the capture gives there (rolling shutter, roll and lens
    included), at the calibration's working scale.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo, float in [0, 1] (a last channel of 2 or 4 is alpha, ignored).
    capture : Capture
        Its capture (scaled to the photo's size when it is another).
    transfer : str or TransferCurve
        Transfer curve of the photo's values.
    n_patches : int
        Windows scored.

    Returns
    -------
    float
        Tempered nats per 9 windows, as :func:`kernel_gain_over_no_blur`: under
        :data:`NO_BLUR_MARGIN`, the photo shows little of that blur; under
        :data:`WRONG_BLUR_MARGIN`, the capture's timing, axes or log are not the photo's
        (or it is sharp). ``nan`` when the photo is too small for the blur or has no
        textured window.
    """
    photo = CalibrationPhoto(image, capture, transfer, 0)
    theta = Corrections(axes=photo.cap.axes)
    extent, path = psf_extent_and_path([photo], theta, [0.0])
    windows = _windows(photo, max(extent, 2.0), n_patches)
    if windows is None:
        return float("nan")
    centres, scale, size = windows
    spectra = PatchSpectra([photo], centres, scale, size, rows=FINE_ROWS, across=True,
                           n_samples=fine_samples(path, scale),
                           band=spectral_band(photo.blockiness()))
    return _per_9_patches(spectra.gain_over_no_blur(theta))


def _windows(photo: CalibrationPhoto, extent: float, n_patches: int):
    """``(centres, scale, size)`` of the photo's ``n_patches`` most textured windows at the
    working scale where a blur of ``extent`` px spans at most 32 px, as calibration takes
    them; ``None`` when a working patch would be under :data:`SMALLEST_PATCH` px or no
    window is textured."""
    scale, size = working_patch(extent, min(photo.H, photo.W))
    if size < SMALLEST_PATCH:
        return None
    centres = patch_centres([photo], n_patches, int(round(size / scale)))
    return (centres, scale, size) if centres else None


def _per_9_patches(gain: np.ndarray) -> float:
    """Per-patch gains (untempered nats) as tempered nats per :data:`_PATCHES` patches."""
    return float(gain.sum() / _TEMPERATURE * _PATCHES / len(gain))
