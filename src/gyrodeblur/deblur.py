"""Deblurring a photo with the PSFs its gyro log implies (chapter sec. 6.5, and beyond).

Data flow: capture -> PSF field at patch centres -> per-patch non-blind deconvolution
-> Hamming blending. Methods plug in by name through :data:`METHODS`; each turns the
whole photo (to estimate e.g. its noise level once) and its options into a
``deconvolve(sub_image, psf)`` callable that the tiler applies patch by patch.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

from .capture import Capture
from .errors import InputError
from .psf import PSFField, psf_extent, render_psf
from .tiling import DEFAULT_GRID, DEFAULT_OVERLAP, deconvolve_patchwise, patch_grid
from .tonecurve import get_transfer_curve
from .wiener import DEFAULT_PHI, wiener_deconvolve

__all__ = ["deblur", "deblur_with_psfs", "deblur_blind", "DeblurReport", "METHODS",
           "DEFAULT_METHOD", "register_method", "plan_psf_field"]

Deconvolver = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _wiener_factory(image: np.ndarray, *, phi: float = DEFAULT_PHI, **_) -> Deconvolver:
    return partial(wiener_deconvolve, phi=phi)


#: name -> factory(image, **options) -> deconvolve(sub_image, psf)
METHODS: dict[str, Callable[..., Deconvolver]] = {"wiener": _wiener_factory}
DEFAULT_METHOD = "wiener"


def register_method(name: str, factory: Callable[..., Deconvolver], *, default: bool = False):
    """Add a deconvolution method: ``factory(image, **options) -> deconvolve(sub, psf)``."""
    global DEFAULT_METHOD
    METHODS[name] = factory
    if default:
        DEFAULT_METHOD = name


@dataclass
class DeblurReport:
    """What a :func:`deblur` run did (for the CLI's summary line and for benchmarks)."""

    mode: str
    method: str
    grid: tuple[int, int]
    field: PSFField
    seconds: float = 0.0
    notes: list = field(default_factory=list)

    @property
    def extent_range(self) -> tuple[int, int]:
        e = self.field.extents
        return int(e.min()), int(e.max())


def plan_psf_field(capture: Capture, shape: tuple[int, int], *, mode: str = "variant",
                   grid=DEFAULT_GRID, overlap: float = DEFAULT_OVERLAP,
                   max_fraction: float = 0.5):
    """Patches and their PSFs for a photo of ``shape`` (rows, cols).

    ``mode="invariant"``: one patch (the whole photo) and the PSF at the principal point
    with the middle row's rolling-shutter timing. ``mode="variant"``: ``grid`` patches
    with ``overlap``, each with the PSF of its centre (and its row's timing). If a PSF's
    extent exceeds ``max_fraction`` of its window's smaller side, the grid is made
    coarser (one row and column fewer at a time) and a warning says so.

    Returns
    -------
    patches : list of Patch
    field : PSFField
    notes : list of str
    """
    from .tiling import Patch
    H, W = shape[:2]
    cap = capture.scaled_to(W, H)
    notes: list[str] = []
    if mode == "invariant":
        cam = cap.camera
        psf = render_psf(cap, cam.cx, cam.cy, row=(H - 1) / 2)
        return [Patch(0, H, 0, W)], PSFField(np.array([[cam.cx, cam.cy]]), [psf], (1, 1)), notes
    if mode != "variant":
        raise InputError("--mode", f"unknown mode {mode!r} (variant or invariant)")
    rows, cols = int(grid[0]), int(grid[1])
    first = (rows, cols)
    while True:
        patches = patch_grid((H, W), (rows, cols), overlap)
        pts = np.array([[p.centre[1], p.centre[0]] for p in patches])
        psfs = [render_psf(cap, x, y) for x, y in pts]
        side = min(patches[0].shape)
        worst = max(psf_extent(p) for p in psfs)
        if worst <= max_fraction * side or (rows, cols) == (1, 1):
            break
        rows, cols = max(1, rows - 1), max(1, cols - 1)
    if (rows, cols) != first:
        msg = (f"grid coarsened from {first[0]}x{first[1]} to {rows}x{cols}: PSFs up to "
               f"{worst} px do not fit patches of the finer grid")
        warnings.warn(msg, stacklevel=3)
        notes.append(msg)
    return patches, PSFField(pts, psfs, (rows, cols)), notes


def deblur_with_psfs(image: np.ndarray, patches, psfs, *, method: str | None = None,
                     transfer: str = "srgb", clip: bool = True, progress=None,
                     **options) -> np.ndarray:
    """Deconvolve ``image`` patch by patch with given PSFs (no gyro needed).

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C), float in [0, 1]
    patches : list of Patch
    psfs : list of ndarray
        One PSF per patch.
    method : str
        A key of :data:`METHODS` (default :data:`DEFAULT_METHOD`).
    transfer : {"srgb", "linear"}
        The photo's transfer curve: undone before deconvolution, reapplied after.
    clip : bool
        Clip the result to [0, 1] (default; values outside are ringing or overshoot).
    **options
        Passed to the method's factory (e.g. ``phi`` for Wiener).
    """
    method = method or DEFAULT_METHOD
    if method not in METHODS:
        raise InputError("--method", f"unknown method {method!r} (known: {', '.join(METHODS)})")
    curve = get_transfer_curve(transfer)
    img = curve.decode(np.asarray(image, dtype=np.float32))
    deconvolve = METHODS[method](img, **options)
    if len(patches) == 1 and patches[0].shape == img.shape[:2]:
        out = deconvolve(img, psfs[0])
        if progress:
            progress(1, 1)
    else:
        out = deconvolve_patchwise(img, patches, psfs, deconvolve, progress=progress)
    out = curve.encode(np.clip(out, 0, None) if clip else out)
    return np.clip(out, 0, 1).astype(np.float32) if clip else out.astype(np.float32)


def deblur(image: np.ndarray, capture: Capture, *, mode: str = "variant",
           grid=DEFAULT_GRID, overlap: float = DEFAULT_OVERLAP, method: str | None = None,
           transfer: str = "srgb", clip: bool = True, progress=None,
           return_report: bool = False, **options):
    """Remove camera-shake blur from ``image`` using the motion in ``capture``.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo, float32 in [0, 1]. Its size may differ from the capture's
        camera by a common scale (the intrinsics are rescaled).
    capture : Capture
        Exposure timing, intrinsics and gyro log.
    mode : {"variant", "invariant"}
        Space-variant patch-wise deconvolution (default) or one PSF for the whole photo
        (the principal point's, with the middle row's rolling-shutter timing).
    grid : (rows, cols)
        Patch grid for ``mode="variant"`` (default 6 x 8, the chapter's).
    overlap : float
        Overlap between neighbouring patches, fraction of the patch size (default 0.25).
    method : str
        Deconvolution method, a key of :data:`METHODS`.
    transfer : {"srgb", "linear"}
        Transfer curve of the photo's values; deconvolution runs in linear light.
    clip : bool
        Clip the output to [0, 1].
    progress : callable(done, total), optional
    return_report : bool
        Also return a :class:`DeblurReport`.
    **options
        Method options (``phi`` for Wiener, ...).

    Returns
    -------
    ndarray float32 like ``image`` (and a DeblurReport if asked). The result is
    referenced to the camera's orientation at ``capture.exposure_start``: it aligns
    with the scene as the first row saw it, free of rolling-shutter skew.
    """
    t0 = time.perf_counter()
    method = method or DEFAULT_METHOD
    patches, field_, notes = plan_psf_field(capture, image.shape[:2], mode=mode, grid=grid,
                                            overlap=overlap)
    out = deblur_with_psfs(image, patches, field_.psfs, method=method, transfer=transfer,
                           clip=clip, progress=progress, **options)
    if not return_report:
        return out
    return out, DeblurReport(mode, method, field_.grid, field_, time.perf_counter() - t0, notes)


def deblur_blind(image: np.ndarray, kernel_size: int, *, method: str | None = None,
                 transfer: str = "srgb", max_pixels: int = 1_000_000, clip: bool = True,
                 progress=None, **options):
    """Deblur without a gyro log: estimate one PSF from the photo, then deconvolve.

    The kernel is estimated by :func:`gyrodeblur.blind.estimate_kernel` (sec. 6.3.1:
    gradients, coarse-to-fine, L0 prior with a decreasing weight, positivity and support
    constraints) on the linear-light luminance of the central ``max_pixels`` of the photo
    (the blur is assumed space-invariant; a crop keeps the time bounded on big photos),
    then the whole photo is deconvolved with it by ``method``.

    Returns
    -------
    restored : ndarray float32
    field : PSFField
        The estimated PSF, at the image centre.
    """
    from .blind import estimate_kernel
    from .tiling import Patch

    H, W = image.shape[:2]
    lin = get_transfer_curve(transfer).decode(np.asarray(image, np.float32))
    lum = lin.mean(axis=2) if lin.ndim == 3 else lin
    if H * W > max_pixels:
        s = np.sqrt(max_pixels / (H * W))
        h, w = int(H * s), int(W * s)
        y0, x0 = (H - h) // 2, (W - w) // 2
        lum = lum[y0:y0 + h, x0:x0 + w]
    psf = estimate_kernel(lum, kernel_size)
    out = deblur_with_psfs(image, [Patch(0, H, 0, W)], [psf], method=method, transfer=transfer,
                           clip=clip, progress=progress, **options)
    return out, PSFField(np.array([[(W - 1) / 2, (H - 1) / 2]]), [psf], (1, 1))
