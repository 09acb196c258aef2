"""Non-blind deconvolution with a sparse (TV or hyper-Laplacian) gradient prior.

The chapter's Wiener filter (eq. 6.18) is fast but rings: around borders, around edges, and
worst of all around clipped highlights, where the observed data no longer follow the blur
model at all. :func:`sparse_deconvolve` solves the MAP problem instead,

.. math::
    \\hat u = \\arg\\min_u \\tfrac12 \\lVert M \\odot (h * u - g) \\rVert^2
              + \\lambda \\sum_x |\\partial_x u|^p + |\\partial_y u|^p ,

where ``M`` is 0 outside the photo and around over-exposed lights (clipped pixels that
are merely at the clip level keep a one-sided term), by ADMM with FFT sub-problems.
It has the same call shape as the Wiener filter, ``deconvolve(image, psf) -> image``, so the
patch tiler can use ``functools.partial(sparse_deconvolve, noise_sigma=s)``.
"""

from __future__ import annotations

import functools
import numbers
import threading
import warnings
from dataclasses import dataclass, replace

import cv2
import numpy as np
import scipy.ndimage as ndi

from .arguments import check_flag, is_whole
from .fftutils import fast_shape, psf_to_otf, smooth_periodic_pad
from .images import check_image, check_psf
from .noise import estimate_noise_sigma
from .packedfft import pack_spectrum, packed_irfft2, packed_multiply, packed_rfft2
from .psf import psf_extent

__all__ = ["sparse_deconvolve", "SparseSettings", "regularization_weight",
           "check_sparse_options", "default_iterations", "default_data_penalty"]

#: Regularisation weight per unit noise, ``weight = C * sigma**(2 - p)`` (see
#: :func:`regularization_weight`). Tuned on 8-bit sRGB photos (scikit-image/Lai sets, camera
#: shake kernels of 13-31 px, sigma 0.0025-0.02, deblurred in linear light, 8 iterations):
#: for p = 1 the best values lay in 0.05-0.1 for every noise level.
_WEIGHT_PER_SIGMA = {1.0: 0.07}
#: For other exponents, a rougher calibration (p = 2/3 was worse than TV at 8 iterations).
_WEIGHT_PER_SIGMA_DEFAULT = 0.3

#: ADMM iterations by default (:func:`default_iterations`): ``_ITERATIONS`` for PSFs up to
#: ``_LONG_PSF_PX`` long, more in proportion to a longer PSF's extent, at most
#: ``_MAX_ITERATIONS``. A long blur converges slowly (its spectrum is small over much of the
#: band): on 12 blurs of 51-99 px (150-350 ms windows of the hand-held log, 640 px photos)
#: 6 iterations gave 19.67 dB, this rule 19.94 (every photo better, +0.12 to +0.69), for
#: 1.28x the time; short blurs are unchanged.
_ITERATIONS = 6
_LONG_PSF_PX = 32
_MAX_ITERATIONS = 12

#: Noise floor used for the weight: 8-bit quantisation alone is 1 / (255 sqrt 12) = 0.0011.
_SIGMA_FLOOR = 1e-3

# ADMM constants (penalties relative to a data-term weight of 1); see Notes of
# sparse_deconvolve. Chosen for the fastest PSNR rise in the first ~6 iterations (on the
# 36-case benchmark: beta up to 32 rather than 64 gained 0.07 dB at 8 iterations and lets
# 6 iterations come within 0.11 dB of 8, for 23 % fewer FFTs).
_RHO_DATA = 0.15
#: For PSFs longer than ``_LONG_PSF_PX`` the data penalty falls with the square of the
#: extent, to ``_RHO_DATA_MIN`` (:func:`default_data_penalty`). At the same iterations, on
#: 12 blurs of 51-99 px (150-350 ms, 640 px photos) 19.94 -> 20.36 dB, and on 12 others of
#: 34-112 px (80-250 ms, 800 px, another seed) 21.03 -> 21.60 dB; the worst case -0.06 dB.
#: The cube of the extent gained 0.06-0.12 dB more but lost 0.25 dB on a smooth portrait;
#: a penalty that low throughout (0.05) lost 1.3-2.5 dB on 9-15 px PSFs.
_RHO_DATA_LONG_EXPONENT = 2.0
_RHO_DATA_MIN = 0.03
_BETA0 = 8.0
_BETA_MAX = 32.0
#: Gradient weight of the Tikhonov start, per unit prior weight, by exponent: a smooth start
#: (25) gained 0.06 dB over 3 for TV at 6 iterations; other exponents keep 3 (their weight
#: has other units, and 25 lost 1 dB for p = 2/3).
_INIT_TIKHONOV = {1.0: 25.0}
_INIT_TIKHONOV_DEFAULT = 3.0
#: ADMM over-relaxation factor (Eckstein & Bertsekas); 1.5 gained 0.2-0.4 dB at 8 iterations.
_RELAX = 1.5
_PAD_EXTRA = 8
#: Mean overshoot above 1 of the Wiener estimate inside a clipped blob that marks it as
#: over-exposed (see _clipping).
_OVEREXPOSED = 0.15
#: Mean excess of the least blurred brightness a clipped blob implies over the data around
#: it that marks the blob as over-exposed (see _inconsistency): point lights whose whole
#: streak is clipped 0.34-0.57 (parts of one in a patch included); of the 21 000 clipped
#: blobs that the 36-case benchmark's patches see (none over-exposed), 6 score above 0.3:
#: five of 1-3 px and a 2500 px white area, with no measurable effect on those photos.
_INCONSISTENT = 0.3
#: Fraction of the PSF's mass in the footprint that :func:`_inconsistency` uses.
_FOOTPRINT_MASS = 0.9
#: Around lights no bigger than this many PSF boxes, ADMM starts from the blurred data.
_ZONE_AREA = 2.0
#: Values at or above this are taken as truly clipped (8-bit 255 is 1.0) and get the
#: one-sided data term; clipped-looking values below it keep the plain one.
_CLIP_VALUE = 0.999
#: Colour images larger than this (pixels) are solved one channel at a time. The joint
#: solve holds ~20 float32 arrays per channel (about 240 bytes per pixel for RGB, 2 GB at
#: 8 MP; a whole 48 MP photo took 15 GB); one channel at a time holds a third of that
#: for some repeated set-up (12 MP, one PSF: peak 3.7 -> 2.1 GB, 15.1 -> 17.3 s). Patches
#: stay far below and keep the joint solve.
_CHANNELWISE_PIXELS = 8_000_000
#: Largest work array (bytes) that the solver keeps per thread for its next call (see
#: _Workspace): a 3 x 600 x 600 float32 patch array is 4.3 MB.
_WORKSPACE_MAX_BYTES = 8 << 20


def regularization_weight(noise_sigma: float, exponent: float = 1.0) -> float:
    r"""Default prior weight :math:`\lambda` for a given noise level.

    .. math:: \lambda = C_p\,\max(\sigma, 10^{-3})^{2 - p}

    The power ``2 - p`` balances the quadratic data term against the ``p``-th power prior at
    the noise scale (both then grow alike when ``sigma`` changes); ``C_1 = 0.07`` was tuned
    empirically (see ``_WEIGHT_PER_SIGMA``), other exponents use a rougher ``C_p = 0.3``.

    Parameters
    ----------
    noise_sigma : float
        Noise standard deviation, in image units (``[0, 1]`` scale).
    exponent : float
        The prior exponent ``p`` in ``(0, 1]``.
    """
    c = _WEIGHT_PER_SIGMA.get(float(exponent), _WEIGHT_PER_SIGMA_DEFAULT)
    return float(c * max(float(noise_sigma), _SIGMA_FLOOR) ** (2.0 - exponent))


def default_iterations(psf: np.ndarray) -> int:
    """The ADMM iterations :func:`sparse_deconvolve` runs for ``psf`` when not told: 6 for
    a PSF whose extent (:func:`gyrodeblur.psf.psf_extent`) is at most 32 px, then in
    proportion to it (9 at 48 px), at most 12 (from 64 px)."""
    extent = psf_extent(psf)
    return int(min(_MAX_ITERATIONS, max(_ITERATIONS, round(_ITERATIONS * extent / _LONG_PSF_PX))))


def default_data_penalty(psf: np.ndarray) -> float:
    r"""ADMM's data penalty :math:`\rho_v` for ``psf`` (relative to a data weight of 1):
    0.15 for a PSF whose extent (:func:`gyrodeblur.psf.psf_extent`) is at most 32 px, then
    ``0.15 (32 / extent)^2`` (0.0375 at 64 px), at least 0.03 (from 72 px).

    A long PSF's spectrum is small over much of the band, and with the short-blur penalty
    its solve gains little per iteration; a lower penalty ties the split ``v = h*u`` to the
    photo sooner (measured: see the comment on ``_RHO_DATA_LONG_EXPONENT``).
    """
    extent = psf_extent(psf)
    if extent <= _LONG_PSF_PX:
        return _RHO_DATA
    scaled = _RHO_DATA * (_LONG_PSF_PX / extent) ** _RHO_DATA_LONG_EXPONENT
    return float(max(_RHO_DATA_MIN, scaled))


def check_sparse_options(*, exponent: float | None = None, iterations: int | None = None,
                         noise_sigma: float | None = None,
                         saturation_level: float | None = None,
                         weight: float | None = None,
                         saturation_dilation: int | None = None, **others) -> None:
    """Check :func:`sparse_deconvolve`'s numeric options (ValueError naming the bad one);
    ``None`` is an option not given (or, for ``saturation_level``, turned off).

    The other options (``others``) are not numeric and are not looked at.
    """
    for name, value in (("exponent", exponent), ("iterations", iterations),
                        ("noise_sigma", noise_sigma), ("saturation_level", saturation_level),
                        ("weight", weight)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise ValueError(f"{name} must be a number, got {value!r}")
    if exponent is not None and not 0 < exponent <= 1:
        raise ValueError(f"exponent must be in (0, 1], got {exponent}")
    if iterations is not None and (not isinstance(iterations, numbers.Integral)
                                   or iterations < 0):
        raise ValueError(f"iterations must be a whole number >= 0, got {iterations!r}")
    if noise_sigma is not None and not (np.isfinite(noise_sigma) and 0 <= noise_sigma < 1):
        raise ValueError(f"noise_sigma must be in [0, 1) (pixel-value units), got {noise_sigma!r}")
    if saturation_level is not None and not (np.isfinite(saturation_level)
                                             and 0 < saturation_level <= 1):
        raise ValueError(f"saturation_level must be in (0, 1] or None, got {saturation_level!r}")
    if weight is not None and not (np.isfinite(weight) and _WEIGHT_RANGE[0] <= weight
                                   <= _WEIGHT_RANGE[1]):
        raise ValueError(f"weight must be a positive number in {_WEIGHT_RANGE[0]:g} to "
                         f"{_WEIGHT_RANGE[1]:g} (beyond, float32 overflows), got {weight!r}")
    if saturation_dilation is not None and not (is_whole(saturation_dilation)
                                                and saturation_dilation >= 0):
        raise ValueError(f"saturation_dilation must be a whole number of pixels >= 0, got "
                         f"{saturation_dilation!r}")


#: The prior weights the float32 solver can hold (``weight`` 1e38 or 1e-42 gave NaN).
_WEIGHT_RANGE = (1e-20, 1e20)


def sparse_deconvolve(
    image: np.ndarray,
    psf: np.ndarray,
    *,
    noise_sigma: float | None = None,
    weight: float | None = None,
    exponent: float = 1.0,
    iterations: int | None = None,
    saturation_level: float | None = 0.98,
    saturation_dilation: int = 1,
    clip: bool = True,
    workers: int | None = None,
    unknown: np.ndarray | None = None,
) -> np.ndarray:
    r"""Deconvolve ``image`` by ``psf`` with a sparse gradient prior (TV by default).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Blurred image, float in ``[0, 1]``, ideally linear light (see
        :mod:`gyrodeblur.tonecurve`).
    psf : ndarray, shape (kh, kw)
        Odd-sized, centred PSF (normalised here to sum 1). Convolution convention
        ``g(x) = sum_s h(s) u(x - s)``.
    noise_sigma : float, optional
        Standard deviation of the noise, on the ``[0, 1]`` scale, used to set ``weight``.
        Default: :func:`gyrodeblur.noise.estimate_noise_sigma` of ``image``. When ``image``
        is linearised sRGB, pass the sigma measured on the *encoded* photo: the linear
        noise is signal-dependent and the weight rule was tuned that way.
    weight : float, optional
        Prior weight :math:`\lambda`; overrides ``noise_sigma``. Default
        :func:`regularization_weight` ``(noise_sigma, exponent)``.
    exponent : float, optional
        Prior exponent ``p`` in ``(0, 1]``: 1 is anisotropic total variation (default:
        better than ``p = 2/3`` at this iteration budget, and its shrinkage is cheapest);
        smaller values give the hyper-Laplacian of Krishnan and Fergus.
    iterations : int, optional
        ADMM iterations (each costs four FFTs per channel). Default
        :func:`default_iterations`: 6 (most of the gain: 8 gave +0.1 dB on the benchmark
        for a third more time), more for a PSF longer than 32 px, which converges slowly
        (up to 12).
    saturation_level : float or None, optional
        Pixels at or above this value (image units) in any channel count as clipped.
        Clipped blobs whose surroundings show the scene was far brighter (point lights)
        get no data term; elsewhere, channel values at the clip value only ask
        ``h*u >= g`` (see Notes). ``None`` turns the handling off.
    saturation_dilation : int, optional
        Grow the mask of an over-exposed blob by this many pixels (4-connected): the edge
        of a clipped streak is where a slightly wrong PSF or camera processing errs most.
    clip : bool, optional
        Clip the result to ``[0, 1]``.
    workers : int, optional
        Deprecated and ignored: the FFTs are OpenCV's now (see Notes, *Cost*).
    unknown : ndarray of bool, shape (H, W), optional
        Pixels whose values are not data (e.g. where an alignment warp sampled outside the
        photo): they get no data term, like the border the solver adds, and the prior
        fills them.

    Returns
    -------
    ndarray, float32, same shape as ``image``.

    Notes
    -----
    *Model.* The unknown ``u`` lives on a periodic domain larger than the photo by the PSF
    size (plus a few pixels, rounded to a fast FFT length). Data weight ``M`` is 1 on
    photo pixels and 0 on the added border, which is left to the prior: no wrap-around
    ringing (Almeida & Figueiredo 2013).

    *Clipped pixels.* Each connected blob of clipped pixels is tested with the chapter's
    Wiener filter (luminance, phi 0.01): if the estimate inside the blob overshoots 1 by
    more than 0.15 on average, the data there cannot come from a scene below the clip
    value, i.e. the blob is an over-exposed light. A light whose whole streak is clipped
    deconvolves to a plateau instead; it is caught by the data beside it, darker than a
    scene at most 1 could leave there (:func:`_inconsistency`; one dilation and one
    filter pass over the patch, only when some blob fails the first test). Such blobs
    (dilated) get ``M = 0``, so a street light's clipped streak cannot pull dark ripples
    into its surroundings (Cho et al. 2011; Whyte et al. 2014). Elsewhere, a channel at the
    clip value itself (>= 0.999) gets the exact one-sided term
    :math:`\tfrac12\max(0, g - h*u)^2`, and every other
    pixel keeps its plain data term: blurred photos whose clipped areas were already
    clipped before the blur (white paper, lit windows) are consistent data, and dropping
    them lost 2-5 dB on such photos.

    *Algorithm.* Variable splitting :math:`v = h*u`, :math:`w = \nabla u` with scaled-dual
    ADMM. Per iteration: :math:`w \leftarrow \mathrm{shrink}(\nabla u + y_w)` (soft
    threshold for ``p = 1``, a lookup table of the exact :math:`|w|^p` proximal map
    otherwise), :math:`v \leftarrow (M g + \rho_v z)/(M + \rho_v)` with
    :math:`z = h*u + y_v`, then the closed-form FFT solve

    .. math::
        u = \mathcal F^{-1}\frac{\rho_v \bar H\,\mathcal F(v - y_v)
            + \rho_w \mathcal F(\nabla^T(w - y_w))}{\rho_v |H|^2 + \rho_w |D|^2}.

    :math:`\rho_v = 0.15` for PSFs up to 32 px, less for longer ones
    (:func:`default_data_penalty`); :math:`\rho_w = \beta\lambda` with :math:`\beta`
    doubling from 8 to 32 (continuation, Krishnan & Fergus 2009). ``u`` starts as a
    Tikhonov solution (gradient weight :math:`25\lambda` for TV, :math:`3\lambda`
    otherwise), except around small over-exposed blobs (point lights), where it starts as
    the blurred image with each light's clipped streak gathered into the streak's core,
    where the light must be (:func:`_start_lights_at_their_cores`): the Tikhonov start
    would ring there, and ADMM is slow to undo ringing, or to gather a streak into its
    light, inside data-free areas.
    Over-relaxation 1.5 (Eckstein & Bertsekas) on both splits.

    *Cost.* Four real FFTs per channel and iteration plus about 22 array passes; with
    clipped pixels, one more Wiener solve on the luminance. The FFTs are OpenCV's, in its
    packed layout (:mod:`gyrodeblur.packedfft`); OpenCV may spread a large transform over
    its own threads (``cv2.setNumThreads``). Memory: about 20 float32 arrays of the padded
    size per channel, for one channel at a time above 8 megapixels (the channels do not
    interact; the clipped-pixel classification is made once for all). Thread-safe (no
    shared mutable state).

    References
    ----------
    D. Krishnan, R. Fergus, "Fast image deconvolution using hyper-Laplacian priors",
    NIPS 2009. S. Cho, J. Wang, S. Lee, "Handling outliers in non-blind image
    deconvolution", ICCV 2011. O. Whyte, J. Sivic, A. Zisserman, "Deblurring shaken and
    partially saturated images", IJCV 2014. M. Almeida, M. Figueiredo, "Deconvolving images
    with unknown boundaries using the alternating direction method of multipliers",
    IEEE TIP 2013.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = rng.random((64, 64)).astype(np.float32)
    >>> out = sparse_deconvolve(img, np.ones((1, 1)), noise_sigma=0.0)
    >>> out.shape, out.dtype
    ((64, 64), dtype('float32'))
    """
    g = check_image(image)
    h = check_psf(psf)
    check_sparse_options(exponent=exponent, iterations=iterations, noise_sigma=noise_sigma,
                         saturation_level=saturation_level, weight=weight,
                         saturation_dilation=saturation_dilation)
    check_flag(clip, "clip")
    if workers is not None:
        warnings.warn("sparse_deconvolve(workers=...) is ignored: its FFTs are OpenCV's, "
                      "which threads them itself (cv2.setNumThreads)", DeprecationWarning,
                      stacklevel=2)
    if weight is None:
        if noise_sigma is None:
            noise_sigma = estimate_noise_sigma(g)
        weight = regularization_weight(noise_sigma, exponent)
    if not (np.isfinite(weight) and weight > 0):
        raise ValueError(f"weight must be a positive number, got {weight!r}")

    color = g.ndim == 3
    gc = np.moveaxis(g, 2, 0) if color else g[None]  # (C, H, W) view
    sat = _clipping(gc, saturation_level, saturation_dilation, h)
    if unknown is not None:
        unknown = np.asarray(unknown, bool)
        if unknown.shape != gc.shape[1:]:
            raise ValueError(f"unknown must be a boolean mask of shape {gc.shape[1:]}, "
                             f"got {unknown.shape}")
        if unknown.any():
            sat = _without_data(sat, unknown)
    if iterations is None:
        iterations = default_iterations(h)
    args = (float(weight), float(exponent), int(iterations), default_data_penalty(h))
    if gc.shape[0] > 1 and gc.shape[1] * gc.shape[2] > _CHANNELWISE_PIXELS:
        out = np.empty(gc.shape, np.float32)
        for c in range(gc.shape[0]):
            out[c] = _admm(gc[c:c + 1], h, *args, _one_channel(sat, c))[0]
    else:
        out = _admm(gc, h, *args, sat)
    out = np.moveaxis(out, 0, 2) if color else out[0]
    if clip:
        np.clip(out, 0.0, 1.0, out=out)
    return np.ascontiguousarray(out, dtype=np.float32)


@dataclass(frozen=True)
class SparseSettings:
    r""":func:`sparse_deconvolve`'s settings for one photo, resolved, and a deconvolver
    with them: ``settings(image, psf, unknown=None)`` calls :func:`sparse_deconvolve`.

    What the patches of one photo share (the prior weight is set once, from the whole
    photo's noise), kept readable so that a later stage (the global refinement of
    :mod:`gyrodeblur.spacevariant`) solves with the same prior and the same clipped-pixel
    rules. Make one with :meth:`resolve`.

    Attributes
    ----------
    weight : float
        Prior weight :math:`\lambda` (image units to the power ``2 - exponent``).
    exponent : float
        Prior exponent ``p`` in ``(0, 1]``.
    iterations : int or None
        ADMM iterations per patch (``None``: :func:`default_iterations` of each PSF).
    saturation_level : float or None
        Clip level of the clipped-pixel handling (``None``: off).
    saturation_dilation : int
        Growth, in pixels, of an over-exposed blob's mask.
    clip : bool
        Whether results are clipped to ``[0, 1]``.
    """

    weight: float
    exponent: float = 1.0
    iterations: int | None = None
    saturation_level: float | None = 0.98
    saturation_dilation: int = 1
    clip: bool = True

    @classmethod
    def resolve(cls, *, noise_sigma: float | None = None, weight: float | None = None,
                exponent: float = 1.0, **options) -> "SparseSettings":
        """Settings from :func:`sparse_deconvolve`'s keywords: ``weight`` if given, else
        :func:`regularization_weight` of ``noise_sigma`` (which must then be given).
        The options are checked (:func:`check_sparse_options`: ValueError)."""
        check_sparse_options(noise_sigma=noise_sigma, weight=weight, exponent=exponent,
                             **options)
        if weight is None:
            if noise_sigma is None:
                raise ValueError("give noise_sigma or weight")
            weight = regularization_weight(noise_sigma, exponent)
        return cls(weight=float(weight), exponent=float(exponent), **options)

    def __call__(self, image: np.ndarray, psf: np.ndarray, *,
                 unknown: np.ndarray | None = None) -> np.ndarray:
        return sparse_deconvolve(image, psf, weight=self.weight, exponent=self.exponent,
                                 iterations=self.iterations,
                                 saturation_level=self.saturation_level,
                                 saturation_dilation=self.saturation_dilation,
                                 clip=self.clip, unknown=unknown)


@dataclass
class _Clipping:
    """How clipped pixels enter the data term (all arrays (H, W) or (C, H, W), photo grid)."""

    ignore: np.ndarray           # bool (H, W): no data term (over-exposed blobs, dilated)
    at_least: np.ndarray | None  # bool (C, H, W): one-sided "h*u >= g" (other clipped)
    lights: np.ndarray | None    # bool (H, W): the over-exposed blobs (undilated)


def _clipping(gc: np.ndarray, level: float | None, dilation: int,
              h: np.ndarray) -> _Clipping | None:
    """Classify clipped pixels; ``None`` when there are none.

    A clipped blob is *over-exposed* when the data around it cannot come from a scene
    that stays below the clip value: deconvolved with a plain Wiener filter (phi = 0.01,
    luminance), its pixels then overshoot 1 by more than ``_OVEREXPOSED`` on average
    (point lights: 0.25-0.35; blobs of clipped-but-consistent data, such as sharp white
    areas that were already 255 before the blur: at most 0.08 on the 12-photo benchmark).
    That test misses lights whose whole streak is clipped (the Wiener estimate of a
    uniformly clipped streak is a plateau near 1 with ripples outside it), so a blob is
    also over-exposed when the data around it contradict a scene at most 1
    (:func:`_inconsistency` above ``_INCONSISTENT``).
    Over-exposed blobs lose their data term (mask grown by ``dilation`` px, 4-connected):
    their true brightness is unknown and far above the clip level. Elsewhere, channels at
    the clip value itself (>= ``_CLIP_VALUE``) get the one-sided term ``h*u >= g``, exact
    for clipped data; everything else keeps its plain data term.
    """
    if level is None:
        return None
    # Element-wise passes over the channels: ``gc`` is often a strided view of an
    # (H, W, C) photo, where reductions along its first axis are several times slower.
    top = gc[0].copy()
    for plane in gc[1:]:
        np.maximum(top, plane, out=top)
    sat = top >= level
    if not sat.any():                      # most patches of a daylight photo: done
        return None
    lum = gc[0].astype(np.float32, copy=True)
    for plane in gc[1:]:
        lum += plane
    lum /= np.float32(gc.shape[0])
    lab, n = ndi.label(sat)
    u = _wiener_luminance(lum, h)
    inside = lab[sat]                      # clipped pixels are few: average over them only
    over = (np.bincount(inside, np.maximum(u[sat] - 1.0, 0.0), minlength=n + 1)
            / np.maximum(np.bincount(inside, minlength=n + 1), 1))
    hot = over > _OVEREXPOSED
    if not hot[1:].all():
        hot |= _inconsistency(top, sat, lab, n, h) > _INCONSISTENT
    hot[0] = False
    lights = hot[lab]
    if lights.any() and dilation > 0:      # 4-connected, as ndimage.binary_dilation
        cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        ignore = cv2.dilate(lights.view(np.uint8), cross, iterations=int(dilation)) > 0
    else:
        ignore = lights
    at_least = (gc >= max(level, _CLIP_VALUE)) & ~ignore[None]
    return _Clipping(ignore, at_least if at_least.any() else None,
                     lights if lights.any() else None)


def _inconsistency(top: np.ndarray, sat: np.ndarray, lab: np.ndarray, n: int,
                   h: np.ndarray) -> np.ndarray:
    """How far the data around each clipped blob fall below what a scene <= 1 would give.

    If the scene stays at most 1, a pixel blurred to the clip value needs the scene at
    nearly 1 under most of the PSF: here over ``S``, the blob dilated by the PSF's
    footprint (its brightest samples holding ``_FOOTPRINT_MASS`` of the mass). The blurred
    photo should then be about at least ``L = h * 1_S`` (times 0.975 for the clip level's
    slack): a heuristic bound, not a strict one (the scene may be darker under the
    footprint's faintest samples). A point light's streak clips over the PSF's footprint,
    so ``L`` is 0.5-1 beside the streak where the photo is dark; a white area's blurred
    edges stay above ``L``. Each unclipped pixel with ``L >= 0.5`` counts for its nearest
    blob only, so a light next to a white area is judged on its own surroundings.

    Parameters
    ----------
    top : (H, W) float32
        Largest channel value per pixel (the clipped channel's own bound).
    sat, lab, n
        Clipped pixels, their blob labels 1..n.
    h : (kh, kw) float32
        The PSF (odd-sized, sums to 1).

    Returns
    -------
    (n + 1,) float: per blob label, the mean of ``max(0, 0.975 L - top)`` over the unclipped
    pixels with ``L >= 0.5`` nearest to it (index 0 unused).
    """
    forced = cv2.dilate(sat.view(np.uint8), _footprint(h))       # S: {x - s : x in blob, s in F}
    least = cv2.filter2D(forced.astype(np.float32), -1, np.ascontiguousarray(h[::-1, ::-1]),
                         borderType=cv2.BORDER_REFLECT)      # h * 1_S (correlation flipped)
    beside = (least >= 0.5) & ~sat
    # nearest clipped pixel of every pixel (OpenCV numbers the clipped pixels), its blob
    _, nearest = cv2.distanceTransformWithLabels((~sat).view(np.uint8), cv2.DIST_L2, 3,
                                                 labelType=cv2.DIST_LABEL_PIXEL)
    blob_of = np.zeros(int(nearest.max()) + 1, np.intp)
    blob_of[nearest[sat]] = lab[sat]
    owner = blob_of[nearest[beside]]
    deficit = np.maximum(np.float32(0.975) * least[beside] - top[beside], 0.0)
    return (np.bincount(owner, deficit, minlength=n + 1)
            / np.maximum(np.bincount(owner, minlength=n + 1), 1))


def _without_data(sat: _Clipping | None, unknown: np.ndarray) -> _Clipping:
    """``sat`` with the ``unknown`` pixels added to those without a data term."""
    if sat is None:
        return _Clipping(unknown, None, None)
    at_least = None if sat.at_least is None else sat.at_least & ~unknown[None]
    return _Clipping(sat.ignore | unknown, at_least if at_least is not None and at_least.any()
                     else None, sat.lights)


def _one_channel(sat: _Clipping | None, c: int) -> _Clipping | None:
    """The clipping description of channel ``c`` alone."""
    if sat is None or sat.at_least is None:
        return sat
    at_least = sat.at_least[c:c + 1]
    return replace(sat, at_least=at_least if at_least.any() else None)


def _wiener_luminance(lum: np.ndarray, h: np.ndarray, phi: float = 0.01) -> np.ndarray:
    """The chapter's Wiener filter on one channel (smooth periodic padding)."""
    H, W = lum.shape
    N = fast_shape((H + h.shape[0] - 1 + _PAD_EXTRA, W + h.shape[1] - 1 + _PAD_EXTRA))
    K = psf_to_otf(h, N)
    U = packed_rfft2(smooth_periodic_pad(lum, N))
    packed_multiply(U, pack_spectrum(np.conj(K) / (np.abs(K) ** 2 + phi), N[1]), out=U)
    return packed_irfft2(U)[:H, :W]


class _Workspace(threading.local):
    """Work arrays of :func:`_admm` kept per thread from one call to the next.

    A patch solve uses about 20 arrays of 1-4 MB (23 names in all). Freshly allocated,
    each is mapped anew and every one of its pages faults on first touch (glibc maps blocks
    this large straight from the kernel and unmaps them on free): about 20 000 page faults
    per 3 x 576 x 576 patch, a quarter of its time. Reusing the arrays avoids that. Each name keeps one
    flat buffer, grown when a call needs more; arrays over ``_WORKSPACE_MAX_BYTES`` are
    not kept. A thread's buffers go when the thread ends (the patch tiler's worker threads
    end with each photo); the calling thread keeps at most 23 x 8 MB.
    """

    def __init__(self):
        self.buffers: dict[str, np.ndarray] = {}

    def array(self, name: str, shape: tuple[int, ...], *, zero: bool = False) -> np.ndarray:
        """A float32 array of ``shape`` (contents undefined unless ``zero``)."""
        n = int(np.prod(shape))
        if 4 * n > _WORKSPACE_MAX_BYTES:
            return np.zeros(shape, np.float32) if zero else np.empty(shape, np.float32)
        buf = self.buffers.get(name)
        if buf is None or buf.size < n:
            buf = self.buffers[name] = np.empty(n, np.float32)
        out = buf[:n].reshape(shape)
        if zero:
            out.fill(0.0)
        return out


_WORKSPACE = _Workspace()


def _admm(gc: np.ndarray, h: np.ndarray, weight: float, p: float, iterations: int,
          rho: float, sat: _Clipping | None) -> np.ndarray:
    """The solver on a (C, H, W) stack; returns (C, H, W) float32 (a fresh array). ``rho``
    is the data penalty (:func:`default_data_penalty`).

    Spectra are kept in the packed real layout of :mod:`gyrodeblur.packedfft` (float32,
    the padded shape): products with the PSF's spectrum go through
    :func:`~gyrodeblur.packedfft.packed_multiply`, real factors multiply element-wise.
    Work arrays come from this thread's :class:`_Workspace`; the result is a copy.
    """
    C, H, W = gc.shape
    kh, kw = h.shape
    N = fast_shape((H + kh - 1 + _PAD_EXTRA, W + kw - 1 + _PAD_EXTRA))
    f32 = np.float32
    CN = (C,) + N

    def work(name, shape=CN, zero=False):
        return _WORKSPACE.array(name, shape, zero=zero)

    # Periodic domain: photo at the top-left, smooth fill elsewhere (used only to start).
    gp = work("gp")
    for c in range(C):
        gp[c] = smooth_periodic_pad(gc[c], N)
    K = psf_to_otf(h, N)
    K2 = K.real * K.real + K.imag * K.imag
    D2 = _laplacian_otf(N)
    k_packed = pack_spectrum(K, N[1])

    # Start: Tikhonov solution of the (padded) data.
    init = _INIT_TIKHONOV.get(p, _INIT_TIKHONOV_DEFAULT) * weight
    U = packed_rfft2(gp, out=work("U"))
    packed_multiply(U, pack_spectrum(np.conj(K) / (K2 + init * D2), N[1]), out=U)
    u = packed_irfft2(U, out=work("u"))
    small = None if sat is None or sat.lights is None else _small_lights(sat.lights, kh, kw)
    if small is not None:  # start from the blurred data around point lights...
        u += _light_zone(small > 0, kh, kw, N) * (gp - u)
        _start_lights_at_their_cores(u, gp, small, h)     # ...and the lights at their cores
        packed_rfft2(u, out=U)
    if iterations == 0:
        return u[:, :H, :W].copy()

    # Data weight M / (M + rho) on the photo, 0 on the border and on clipped pixels.
    mw = work("mw", N, zero=True)
    mw[:H, :W] = 1.0 / (1.0 + rho)
    ms = None
    if sat is not None:
        mw[:H, :W][sat.ignore] = 0.0
        if sat.at_least is not None:
            ms = work("ms", zero=True)
            ms[:, :H, :W][sat.at_least] = 1.0 / (1.0 + rho)
            mw = np.where(ms > 0, f32(0), mw)  # per channel from here on: (C, N0, N1)
            t = work("t")
    kc_rho = pack_spectrum(np.conj(K) * rho, N[1])
    k2_rho = pack_spectrum(K2 * rho, N[1], real=True)
    d2 = pack_spectrum(D2, N[1], real=True)

    a = f32(_RELAX)
    a1 = f32(1.0 - _RELAX)
    ku = packed_irfft2(packed_multiply(U, k_packed, out=U), out=work("ku"))
    # Each split enters the next iteration only through m = (1 - a) * (its last value)
    # + (its scaled dual), which is kept instead of both (fewer passes over the arrays).
    mv = np.multiply(ku, a1, out=work("mv"))         # v = h*u, y_v = 0
    mx = _dx(u, out=work("mx"))                      # w = D u, y_w = 0, per direction
    mx *= a1
    my = _dy(u, out=work("my"))
    my *= a1
    yx = work("yx")                                  # scaled duals of w (for continuation)
    yy = work("yy")
    z = work("z")
    e = work("e")
    r = work("r")
    num, R = U, work("R")                # packed spectra
    beta = _BETA0
    factors: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    for it in range(iterations):
        rho_w = weight * beta
        # w-step, per direction: z = a D u + m (the relaxed D u plus the dual); w = prox(z);
        # y <- z - w (= c, what the shrinkage removed); m <- (1 - a) w + y; the u-step needs
        # q = w - y = z - 2c. r = D^T q accumulates over the directions: x writes it, y
        # adds to it.
        for diff, diff_t, y, m in ((_dx, _dx_t_set, yx, mx), (_dy, _dy_t_add, yy, my)):
            diff(u, out=z)
            _scale_add(a, z, m, out=z)
            _shrink_residual(z, beta, p, out=y)
            _weighted_sum(a1, z, a, y, out=m)        # (1 - a)(z - y) + y
            _scale_add(f32(-2.0), y, z, out=z)
            diff_t(z, r)
        # v-step: z = a h*u + m_v; v = z + e, e = mw (g - z); y_v <- -e, so
        # m_v <- (1 - a)(z + e) - e; q = v - y_v = z + 2e.
        _scale_add(a, ku, mv, out=z)
        np.subtract(gp, z, out=e)
        e *= mw
        if ms is not None:  # one-sided: pull z up to the clipped value only when below it
            np.subtract(gp, z, out=t)
            np.maximum(t, 0.0, out=t)
            t *= ms
            e += t
        _weighted_sum(a1, z, -a, e, out=mv)
        _scale_add(f32(2.0), e, z, out=z)
        # u-step (closed form in the Fourier domain): U = A Z + B R with, for this beta,
        # A = rho_v conj(H) / den and B = rho_w / den (real), den = rho_v |H|^2 + rho_w |D|^2.
        if beta not in factors:
            k = len(factors)
            inv = np.multiply(d2, f32(rho_w), out=work("inv", N))
            inv += k2_rho
            np.divide(f32(1.0), inv, out=inv)
            factors[beta] = (np.multiply(kc_rho, inv, out=work(f"A{k}", N)),
                             np.multiply(inv, f32(rho_w), out=work(f"B{k}", N)))
        A, B = factors[beta]
        packed_multiply(packed_rfft2(z, out=num), A, out=num)
        packed_rfft2(r, out=R)
        for c in range(C):               # num += R B, one pass
            cv2.accumulateProduct(R[c], B, num[c])
        u = packed_irfft2(num, out=u)
        if it == iterations - 1:  # h*u is not needed after the last u-step
            break
        packed_irfft2(packed_multiply(num, k_packed, out=num), out=ku)
        # Continuation: raise rho_w, rescale the scaled dual to keep the true dual fixed.
        # (m = (1 - a) w + y becomes (1 - a) w + s y; y itself is overwritten next).
        nbeta = min(2.0 * beta, _BETA_MAX)
        if nbeta != beta:
            s = f32(beta / nbeta)
            _scale_add(s - 1, yx, mx, out=mx)
            _scale_add(s - 1, yy, my, out=my)
            beta = nbeta
    return u[:, :H, :W].copy()


def _scale_add(alpha, x: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """``out = alpha x + y`` in one pass (OpenCV; C-contiguous float32 arrays of one shape,
    ``out`` may be ``x`` or ``y``)."""
    _check_views(x, y, out)
    width = x.shape[-1]
    cv2.scaleAdd(x.reshape(-1, width), float(alpha), y.reshape(-1, width),
                 dst=out.reshape(-1, width))


def _weighted_sum(alpha, x: np.ndarray, beta, y: np.ndarray, out: np.ndarray) -> None:
    """``out = alpha x + beta y`` in one pass (as :func:`_scale_add`)."""
    _check_views(x, y, out)
    width = x.shape[-1]
    cv2.addWeighted(x.reshape(-1, width), float(alpha), y.reshape(-1, width), float(beta),
                    0.0, dst=out.reshape(-1, width))


def _check_views(*arrays: np.ndarray) -> None:
    """OpenCV writes into ``dst`` only through a 2-D view of it, which needs C-contiguous
    float32 arrays; anything else would leave the result in a copy, silently."""
    for a in arrays:
        if a.dtype != np.float32 or not a.flags.c_contiguous:
            raise ValueError("expected C-contiguous float32 work arrays")


def _small_lights(lights: np.ndarray, kh: int, kw: int) -> np.ndarray | None:
    """The over-exposed blobs no bigger than ``_ZONE_AREA`` PSF boxes (point lights), as
    (H, W) blob labels (0 elsewhere; the numbering may skip); ``None`` when there are none."""
    lab, _ = ndi.label(lights)
    small = np.bincount(lab.ravel()) <= _ZONE_AREA * kh * kw
    small[0] = False
    return np.where(small[lab], lab, 0) if small.any() else None


def _light_zone(small: np.ndarray, kh: int, kw: int, shape: tuple[int, int]) -> np.ndarray:
    """Smooth 0..1 weight around the point lights ``small``, on the padded grid ``shape``."""
    # Dilation by a kh x kw box: OpenCV's separable running maximum (a generic 2-D
    # structuring element costs kh * kw operations per pixel; ndimage's maximum_filter
    # is separable too but 6x slower here).
    lights = cv2.dilate(small.view(np.uint8), np.ones((kh, kw), np.uint8)) > 0
    zone = np.zeros(shape, np.float32)
    zone[: lights.shape[0], : lights.shape[1]] = lights
    return ndi.uniform_filter(zone, (kh, kw), mode="wrap")


def _start_lights_at_their_cores(u: np.ndarray, gp: np.ndarray, labels: np.ndarray,
                                 h: np.ndarray) -> None:
    """Put each point light's start where the light must be, in place.

    A light at ``p`` clips the pixels ``p + s`` for ``s`` in the PSF's footprint, so it
    lies in the blob's *core*: the blob eroded by the footprint (:func:`_footprint`). The
    start inside each blob is the mean of ``u`` just around it, plus, spread evenly over
    its core, the light the clipped data hold above that (per channel: the blob's sum of
    data minus its surroundings, a lower bound of the light's energy; a coloured light
    keeps its hue). Starting from the blurred data instead (the streak itself), ADMM gathers the
    streak's energy back into the light slowly: ripples around lights through the whole
    pipeline were 1.9-6.3x Wiener's at 6 iterations, 2.8-8.0x with this start (per light,
    synthetic scenes). Blobs whose footprint does not fit inside them keep the data.

    Parameters
    ----------
    u, gp : ndarray (C, N0, N1) float32
        The start (changed) and the padded data; the photo is their top-left (H, W).
    labels : ndarray (H, W) int
        The point lights' labels (:func:`_small_lights`).
    h : ndarray (kh, kw) float32
        The PSF.
    """
    H, W = labels.shape
    lab, n = labels, int(labels.max())
    small = lab > 0
    core = cv2.erode(small.view(np.uint8), _footprint(h), borderType=cv2.BORDER_CONSTANT,
                     borderValue=0) > 0
    if not core.any():
        return
    cores = np.bincount(lab[core], minlength=n + 1)
    cores[0] = 0
    inside = (cores > 0)[lab]                                   # blobs with a core
    ring = cv2.dilate(inside.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ring &= ~small
    near = ndi.grey_dilation(lab, size=(3, 3))[ring]            # the blob each ring pixel borders
    count = np.maximum(np.bincount(near, minlength=n + 1), 1)
    per_core = 1.0 / np.maximum(cores, 1)
    for c in range(u.shape[0]):
        plane, data = u[c, :H, :W], gp[c, :H, :W]
        around = np.bincount(near, plane[ring], minlength=n + 1) / count
        excess = np.bincount(lab[inside], data[inside] - around[lab[inside]], minlength=n + 1)
        plane[inside] = around[lab[inside]]
        plane[core] += (np.maximum(excess, 0.0) * per_core)[lab[core]]


def _footprint(h: np.ndarray) -> np.ndarray:
    """uint8 mask of the PSF's brightest samples holding ``_FOOTPRINT_MASS`` of its mass."""
    v = np.sort(h.ravel())[::-1]
    cut = v[min(v.size - 1, int(np.searchsorted(np.cumsum(v), _FOOTPRINT_MASS * v.sum())))]
    return (h >= cut).astype(np.uint8)


def _laplacian_otf(shape: tuple[int, int]) -> np.ndarray:
    """|D_x|^2 + |D_y|^2 of periodic forward differences, on the rfft2 grid."""
    ny, nx = shape
    ky = 2.0 - 2.0 * np.cos(2.0 * np.pi * np.arange(ny) / ny)
    kx = 2.0 - 2.0 * np.cos(2.0 * np.pi * np.arange(nx // 2 + 1) / nx)
    return (ky[:, None] + kx[None, :]).astype(np.float32)


# Periodic forward differences on the last two axes and their adjoints (added in place).
def _dx(u, out):
    np.subtract(u[..., 1:], u[..., :-1], out=out[..., :-1])
    np.subtract(u[..., 0], u[..., -1], out=out[..., -1])
    return out


def _dy(u, out):
    np.subtract(u[..., 1:, :], u[..., :-1, :], out=out[..., :-1, :])
    np.subtract(u[..., 0, :], u[..., -1, :], out=out[..., -1, :])
    return out


def _dx_t_set(w, out):
    """``out = D_x^T w`` (one pass, where zero-fill then add takes three)."""
    np.subtract(w[..., :-1], w[..., 1:], out=out[..., 1:])
    np.subtract(w[..., -1], w[..., 0], out=out[..., 0])
    return out


def _dy_t_add(w, out):
    out[..., 1:, :] += w[..., :-1, :]
    out[..., 0, :] += w[..., -1, :]
    out -= w
    return out


def _shrink_residual(z: np.ndarray, beta: float, p: float, out: np.ndarray) -> np.ndarray:
    """``out = z - prox(z)``, prox(z) = argmin_w |w|^p + beta/2 (w - z)^2 (elementwise)."""
    if p == 1.0:
        t = np.float32(1.0 / beta)
        return np.clip(z, -t, t, out=out)
    # Scale invariance: prox_beta(z) = s prox_1(z / s) with s = beta^(-1 / (2 - p)).
    s = beta ** (-1.0 / (2.0 - p))
    table, step, tau = _shrink_table(float(p))
    a = np.abs(z)
    a *= np.float32(1.0 / (s * step))
    np.minimum(a, np.float32(table.size - 1), out=a)
    below = a < np.float32(tau / step)     # prox is exactly 0 there: residual = z
    idx = a.astype(np.int32)
    np.take(table, idx, out=out)
    out *= np.float32(s)
    np.copysign(out, z, out=out)
    np.copyto(out, z, where=below)
    return out


@functools.lru_cache(maxsize=8)
def _shrink_table(p: float, step: float = 1.0 / 256, top: float = 256.0):
    """Table of d(y) = y - t*(y), t* = argmin_t |t|^p + (t - y)^2 / 2, y = 0, step, ..., top,
    its step, and the threshold tau below which t* = 0.

    Beyond ``top`` the shrinkage amount ``p y^(p - 1)`` is below 0.15 and decreasing; the
    last entry is used there.
    """
    y = np.arange(0.0, top + step / 2, step)
    t = y.copy()
    for _ in range(60):  # Newton on t - y + p t^(p-1) = 0, from t = y (the larger root)
        tt = np.maximum(t, 1e-12)
        f1 = tt - y + p * tt ** (p - 1)
        f2 = 1 + p * (p - 1) * tt ** (p - 2)
        t = np.where(f2 > 0, np.maximum(tt - f1 / np.where(f2 > 0, f2, 1), 1e-12), 0.5 * (tt + y))
    t = np.where(t ** p + 0.5 * (t - y) ** 2 < 0.5 * y * y, t, 0.0)
    tau = y[np.argmax(t > 0)]  # the threshold below which the prox is 0
    return (y - t).astype(np.float32), step, float(tau)
