"""Deblurring a photo with the PSFs its gyro log implies (chapter sec. 6.5, and beyond).

Data flow: capture -> PSF field at patch centres -> (where the PSFs' mean displacement
varies fast enough, the alignment warp, :mod:`gyrodeblur.warp`, and centred PSFs) ->
per-patch non-blind deconvolution -> Hamming blending -> (the sparse method, up to 4 MP by
default: refinement under one interpolated-PSF model of the whole photo,
:mod:`gyrodeblur.spacevariant`). Methods plug in by name through :data:`METHODS`; each
turns the whole photo (to estimate e.g. its noise level once) and its options into a
``deconvolve(sub_image, psf)`` callable that the tiler applies patch by patch.
"""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import threading
import time
import warnings
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np
from scipy import ndimage as ndi

from .arguments import check_callback, check_flag, is_count
from .capture import Capture, check_capture
from .errors import GyrodeblurWarning, InputError
from .gyrolog import warn_of_saturation, warn_of_steps
from .images import PHOTO_MAX, PHOTO_MIN, check_image, check_psf, join_alpha, split_alpha
from .psf import (LANCZOS_A, PSFField, displacement_field, psf_extent, psf_variation,
                  render_psf)
from .tiling import (DEFAULT_GRID, DEFAULT_OVERLAP, MIN_WINDOW, check_grid, check_overlap,
                     check_patches, deconvolve_patchwise, patch_grid)
from .tonecurve import TransferCurve, get_transfer_curve
from .warp import CLIPPED, LIGHT_AREA, checked_displacement, warp_checked
from .wiener import check_phi, photo_phi, wiener_deconvolve

__all__ = ["deblur", "deblur_with_psfs", "deblur_blind", "DeblurReport", "METHODS",
           "DEFAULT_METHOD", "register_method", "plan_psf_field", "MODELS",
           "GLOBAL_DEFAULT_MAX_PIXELS", "check_blind_sizes"]

Deconvolver = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _wiener_factory(image: np.ndarray, *, encoded: np.ndarray | None = None,
                    **options) -> Deconvolver:
    """The chapter's Wiener filter (eq. 6.18); its one option is ``phi``, by default
    :func:`gyrodeblur.wiener.photo_phi` of the photo as encoded."""
    unknown = sorted(set(options) - {"phi"})
    if unknown:                      # e.g. the sparse method's noise_sigma
        raise TypeError(f"unknown option(s) {', '.join(unknown)} for method 'wiener' "
                        "(known: phi)")
    phi = options.get("phi")
    phi = photo_phi(image if encoded is None else encoded) if phi is None else check_phi(phi)
    return partial(wiener_deconvolve, phi=phi)


def _sparse_factory(image: np.ndarray, *, encoded: np.ndarray | None = None,
                    noise_sigma: float | None = None, clip: bool = True,
                    **options) -> Deconvolver:
    """Sparse-prior (TV) ADMM deconvolution; the noise level is measured once on the
    photo as encoded (where sensor noise is roughly uniform), not in linear light.
    Options are checked here, before any work (not from inside a worker thread).
    Returns a :class:`gyrodeblur.sparse.SparseSettings` (the resolved settings)."""
    from .noise import estimate_noise_sigma
    from .sparse import SparseSettings, check_sparse_options
    known = {f.name for f in dataclasses.fields(SparseSettings)} | {"noise_sigma", "workers"}
    unknown = sorted(set(options) - known)
    if unknown:
        raise TypeError(f"unknown option(s) {', '.join(unknown)} for method 'sparse' "
                        f"(known: {', '.join(sorted(known - {'clip'}))})")
    if options.pop("workers", None) is not None:
        warnings.warn("the sparse method's workers option is ignored: its FFTs are "
                      "OpenCV's, which threads them itself (cv2.setNumThreads)",
                      DeprecationWarning, stacklevel=3)
    try:
        check_sparse_options(noise_sigma=noise_sigma, **options)
        if noise_sigma is None and options.get("weight") is None:
            noise_sigma = estimate_noise_sigma(image if encoded is None else encoded)
        return SparseSettings.resolve(noise_sigma=noise_sigma, clip=clip, **options)
    except ValueError as exc:
        raise InputError(None, f"method 'sparse': {exc}") from None


#: name -> factory(image, **options) -> deconvolve(sub_image, psf). ``image`` is the
#: photo in linear light; ``encoded`` (keyword) the same photo as given.
METHODS: dict[str, Callable[..., Deconvolver]] = {"sparse": _sparse_factory,
                                                  "wiener": _wiener_factory}
#: The best method measured by benchmarks/compare_methods.py (see BENCHMARKS.md).
DEFAULT_METHOD = "sparse"


#: Methods registered with ``thread_safe=False``, and the lock that lets one call of each
#: run at a time (its factory and its ``deconvolve``), whichever thread or :func:`deblur`
#: call it comes from: their patches run one at a time.
_SERIAL_METHODS: dict[str, threading.RLock] = {}


def register_method(name: str, factory: Callable[..., Deconvolver], *, default: bool = False,
                    thread_safe: bool = True):
    """Add a deconvolution method to :data:`METHODS`, for ``deblur(..., method=name)``.

    Parameters
    ----------
    name : str
        A name already in :data:`METHODS` is registered anew, its factory replaced for
        the whole process (the built-in ``"sparse"`` and ``"wiener"`` too, and so for the
        command line run in it): give a new name to keep both.
    factory : callable
        ``factory(image, **options) -> deconvolve``, called once per photo. ``image`` is
        the whole photo in linear light, float32 ``(H, W)`` or ``(H, W, C)`` (alpha left
        out); ``options`` are :func:`deblur`'s method options. A factory that takes an
        ``encoded`` keyword also gets the photo as given (before its transfer curve is
        undone), and one that takes ``clip`` gets :func:`deblur`'s.
        ``deconvolve(sub_image, psf) -> array`` of the sub-image's shape: one patch
        (float32, linear light, with a margin of neighbouring pixels) and its PSF (odd
        sides, centred; normalise it if your method needs a sum of exactly 1). If it takes
        an ``unknown`` keyword it is given, where needed, a boolean mask of the pixels that
        are not data.
    default : bool
        Make it the method :func:`deblur` uses when none is named.
    thread_safe : bool
        Whether ``deconvolve`` may run on several patches at once, in threads (the
        default: patches run concurrently, one thread per core). Give False for one that
        keeps state between calls (a shared buffer, a GPU context): its patches then run
        one after the other, and so do its factory and ``deconvolve`` calls from
        :func:`deblur` calls in other threads.

    Notes
    -----
    The arrays the method is given must not be written to: ``image`` and the sub-images
    are the deblur's own (never the caller's photo), but ``encoded``, the photo as given,
    may be the caller's array itself, and is passed read-only.
    """
    global DEFAULT_METHOD
    if not isinstance(name, str) or not name:
        raise TypeError(f"a method's name must be a non-empty string, got {name!r}")
    if not callable(factory):
        raise TypeError(f"the factory of method {name!r} must be callable "
                        f"(factory(image, **options) -> deconvolve), got {factory!r}")
    default, thread_safe = check_flag(default, "default"), check_flag(thread_safe,
                                                                       "thread_safe")
    METHODS[name] = factory
    if thread_safe:
        _SERIAL_METHODS.pop(name, None)
    else:
        _SERIAL_METHODS.setdefault(name, threading.RLock())
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
    #: Forward model used (:data:`MODELS`): ``"global"`` or ``"patches"``.
    model: str = "patches"

    @property
    def extent_range(self) -> tuple[int, int]:
        e = self.field.extents
        return int(e.min()), int(e.max())


#: Largest change (px) of the PSF across one patch that :func:`auto_grid` aims for. Half a
#: pixel: since the PSFs model a band-limited photo (session 17) the deconvolution is sharp
#: enough for sub-pixel PSF errors to cost (gyro noise moving traces by 0.2-0.4 px costs
#: 1 dB). Session 18, on the 36-case benchmark, one run alternating the two: 2 px with one
#: window size for both axes 27.05 dB mean, 79.5 s; half a pixel with the rows and the
#: columns sized apart 27.33 dB, 87.7 s (half a pixel alone, in another run: 27.24 dB, +11 %
#: time; 12 long exposures +0.12 dB). From 3 MP up :data:`AUTO_GRID_MAX_PATCHES` rules.
AUTO_GRID_TOLERANCE = 0.5
#: The alignment warp resamples the photo, a slight low-pass that costs up to ~2 dB on
#: sharp, nearly uniform blurs (measured on the shared benchmark at 34 dB); it is used
#: only where the mean displacement changes faster than this (px per px), where it gained
#: 1-5 dB on the same photos.
ALIGN_MIN_SLOPE = 0.015
#: Most patches :func:`auto_grid` chooses.
AUTO_GRID_MAX_PATCHES = 96


def auto_grid(capture: Capture, shape: tuple[int, int], overlap: float = DEFAULT_OVERLAP, *,
              tolerance: float = AUTO_GRID_TOLERANCE,
              max_patches: int = AUTO_GRID_MAX_PATCHES, centred: bool = True) -> tuple[int, int]:
    """A patch grid fine enough that each patch's PSF is nearly constant over it.

    One PSF per patch is exact only where the blur does not change; roll, wide lenses
    and the rolling shutter make it change (:func:`gyrodeblur.psf.psf_variation`, px per
    px). Windows are made about ``tolerance / variation`` pixels tall and wide, with the
    variation down the frame and across it apart (a rolling shutter makes the PSF
    change faster from row to row: the rows get more of the patches), but sized for
    windows no narrower than the largest PSF's extent (the margin of real neighbours
    around each window gives the deconvolution its context) nor 32 px (the count is
    rounded up, so a window can come out a little narrower: :func:`plan_psf_field` then
    checks each patch's own PSF against its window, and coarsens with a note), never
    coarser than the chapter's 6 x 8 (unless the photo is too small for it: windows stay
    at least 1.25x :data:`~gyrodeblur.tiling.MIN_WINDOW`), and never more than
    ``max_patches`` in all.
    ``centred``: count only the PSFs' shape, their change and their extent (the photo is
    aligned by the displacement field first, see :func:`plan_psf_field`).

    Returns
    -------
    (rows, cols)
    """
    H, W = shape[:2]
    overlap = check_overlap(overlap)
    cap = capture.scaled_to(W, H)
    # the PSFs' extent as they are deconvolved: their shape alone where the photo is
    # aligned first (a long readout displaces the last rows by hundreds of px, which the
    # warp undoes: counted, it made a 20 px blur "span" the frame and refused the photo)
    extent = max(psf_extent(render_psf(cap, x, y, max_step=0.5, centred=centred))
                 for x in (0, (W - 1) / 2, W - 1) for y in (0, (H - 1) / 2, H - 1))

    def count(length: int, variation: float) -> int:
        window = tolerance / variation if variation > 0 else np.inf
        window = max(window, float(extent), 32.0)
        return max(1, int(np.ceil((length / window - overlap) / (1 - overlap))))

    def fits(length: int) -> int:        # most patches whose windows keep 1.25x the smallest
        return max(1, int((length / (1.25 * MIN_WINDOW) - overlap) / (1 - overlap)))

    down, across = psf_variation(cap, centred=centred, per_axis=True)
    rows = min(max(count(H, down), DEFAULT_GRID[0]), fits(H))
    cols = min(max(count(W, across), DEFAULT_GRID[1]), fits(W))
    if rows * cols > max_patches:       # both axes shrink alike, not under the 6 x 8
        f = np.sqrt(max_patches / (rows * cols))
        fl_r, fl_c = ((min(rows, DEFAULT_GRID[0]), min(cols, DEFAULT_GRID[1]))
                      if np.prod(DEFAULT_GRID) <= max_patches else (1, 1))
        rows, cols = max(fl_r, int(rows * f)), max(fl_c, int(cols * f))
        rows = max(fl_r, min(rows, max_patches // cols))    # a floor's gain is the other's loss
        cols = max(fl_c, min(cols, max_patches // rows))
    return rows, cols


def plan_psf_field(capture: Capture, shape: tuple[int, int], *, mode: str = "variant",
                   grid=DEFAULT_GRID, overlap: float = DEFAULT_OVERLAP,
                   max_fraction: float = 1.0, align: bool = False,
                   warn_coarsened: bool = True):
    """Patches and their PSFs for a photo of ``shape`` (rows, cols).

    ``mode="invariant"``: one patch (the whole photo) and the PSF at the principal point
    with the middle row's rolling-shutter timing. ``mode="variant"``: ``grid`` patches
    (``"auto"``: :func:`auto_grid`) with ``overlap``, each with the PSF of its centre
    (and its row's timing). If a PSF's
    extent exceeds ``max_fraction`` of its window's height (width), the grid gets fewer
    rows (columns), each axis only as far as its windows need, and a warning says so
    (a note only, for ``"auto"`` or where not ``warn_coarsened``: a grid the caller did
    not choose, whose sizing nothing they gave can change).

    ``align=True``: the PSFs are rendered centred (their shape only) and the field keeps
    the mean-displacement field; :func:`deblur_with_psfs` then warps the photo by it
    before deconvolving, so the part of the blur that varies fastest across the frame (a
    displacement that changes from row to row with the rolling shutter, and with roll)
    is undone exactly per pixel rather than per patch.

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
    disp = displacement_field(cap) if align else None
    if mode == "invariant":
        cam = cap.camera
        psf = render_psf(cap, cam.cx, cam.cy, row=(H - 1) / 2, centred=align)
        return ([Patch(0, H, 0, W)], PSFField(np.array([[cam.cx, cam.cy]]), [psf], (1, 1), disp),
                notes)
    if mode != "variant":
        raise InputError.of_argument("mode", f"unknown mode {mode!r} (variant or invariant)")
    automatic = isinstance(grid, str) and grid.strip().lower() == "auto"
    if automatic:
        grid = auto_grid(cap, (H, W), overlap, centred=align)
    rows, cols = check_grid(grid)
    if disp is not None:
        slope = _displacement_slope(disp)
        if slope < ALIGN_MIN_SLOPE:
            notes.append(f"alignment warp skipped: the mean displacement changes by only "
                         f"{slope:.4f} px per px")
            disp = None
            align = False
    first = (rows, cols)
    while True:
        patches = patch_grid((H, W), (rows, cols), overlap)
        pts = _centres_xy(patches)
        psfs = [render_psf(cap, x, y, centred=align) for x, y in pts]
        worst = max(psf_extent(p) for p in psfs)
        need = worst / max_fraction           # px of window, down and across
        # each axis is coarsened only as far as its own windows need: taking a column
        # off with each row (as before) cut a 20 x 8 request down to 11 x 1
        fewer_rows = _most_patches_holding(need, (H, W), (rows, cols), overlap, axis=0)
        fewer_cols = _most_patches_holding(need, (H, W), (fewer_rows, cols), overlap, axis=1)
        if (fewer_rows, fewer_cols) == (rows, cols):
            break
        rows, cols = fewer_rows, fewer_cols
    if (rows, cols) != first:
        msg = (f"grid coarsened from {first[0]}x{first[1]} to {rows}x{cols}: PSFs up to "
               f"{worst} px do not fit patches of the finer grid")
        if warn_coarsened and not automatic:     # the grid asked for is not the one used
            warnings.warn(msg, GyrodeblurWarning, stacklevel=3)
        notes.append(msg)
    return patches, PSFField(pts, psfs, (rows, cols), disp), notes


def _grid_that_fits(shape, grid: tuple[int, int], overlap: float) -> tuple[int, int]:
    """``grid`` with fewer rows (columns) where the photo is too small for them."""
    fitted = list(grid)
    for axis in (0, 1):
        while fitted[axis] > 1:
            try:
                patch_grid(shape, tuple(fitted) if axis == 1 else (fitted[0], 1), overlap)
                break
            except InputError:
                fitted[axis] -= 1
    return fitted[0], fitted[1]


def _most_patches_holding(need: float, shape, grid, overlap: float, axis: int) -> int:
    """The most patches along ``axis``, at most ``grid[axis]``, whose windows are at least
    ``need`` px long on that axis (1 if none are: the whole side is the best there is)."""
    n = grid[axis]
    while n > 1:
        g = (n, grid[1]) if axis == 0 else (grid[0], n)
        if patch_grid(shape, g, overlap)[0].shape[axis] >= need:
            break
        n -= 1
    return n


def _displacement_slope(displacement) -> float:
    """Largest change of the mean displacement per pixel between neighbouring grid points."""
    ys, xs, d = displacement
    sx = np.abs(np.diff(d, axis=1)).max() / (xs[1] - xs[0]) if len(xs) > 1 else 0.0
    sy = np.abs(np.diff(d, axis=0)).max() / (ys[1] - ys[0]) if len(ys) > 1 else 0.0
    return float(max(sx, sy))


def _checked_method(method: str | None) -> str:
    """``method``, or the default for ``None``; an unknown name refused."""
    method = DEFAULT_METHOD if method is None else method
    if method not in METHODS:
        raise InputError.of_argument(
            "method", f"unknown method {method!r} (known: {', '.join(METHODS)})")
    return method


def _deconvolver(method: str, img: np.ndarray, encoded: np.ndarray, clip: bool, options):
    """The method's deconvolver for the photo ``img`` (linear light; ``encoded`` as
    given), its ``options`` checked by its factory."""
    factory = METHODS[method]
    if _takes_keyword(factory, "clip"):               # the method clips (or not) itself
        options = {**options, "clip": clip}
    if _takes_keyword(factory, "encoded"):
        encoded = encoded.view()                      # the caller's photo: not to write to
        encoded.flags.writeable = False
        options = {**options, "encoded": encoded}
    return factory(img, **options)


def _light_of(encoded: np.ndarray, curve: TransferCurve, image: np.ndarray) -> np.ndarray:
    """``encoded`` (the colours of the caller's ``image``) decoded to light by ``curve``,
    in an array of the deblur's own: the linear curve's decoding is ``encoded`` itself,
    copied, so that a method writing to its input cannot change the caller's photo."""
    light = curve.decode(encoded)
    return light.copy() if np.may_share_memory(light, image) else light


def _one_call_at_a_time(method: str):
    """The lock a method registered ``thread_safe=False`` holds while its factory and
    deconvolver run (a context that does nothing for any other)."""
    return _SERIAL_METHODS.get(method, contextlib.nullcontext())


def deblur_with_psfs(image: np.ndarray, patches, psfs, *, method: str | None = None,
                     transfer: str | TransferCurve = "srgb", clip: bool = True, progress=None,
                     displacement=None, model: str | None = None, **options) -> np.ndarray:
    """Deconvolve ``image`` patch by patch with given PSFs (no gyro needed).

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C), float in [0, 1]
        A last channel of 2 or 4 (grey + alpha, RGBA) is alpha, a mask: passed through
        untouched, and the colours are deblurred as without it.
    patches : list of Patch
    psfs : list of ndarray
        One PSF per patch (odd sides, a positive sum; each method normalises it), its
        light spread over no more than the photo's larger side and its sinc lobes (a PSF
        for another size of photo is refused).
    method : str
        A key of :data:`METHODS` (default :data:`DEFAULT_METHOD`).
    transfer : {"srgb", "linear"} or TransferCurve
        The photo's transfer curve: undone before deconvolution, reapplied after
        (:func:`gyrodeblur.icc.photo_transfer_curve` gives the one a photo's ICC profile
        declares).
    clip : bool
        Clip the result to [0, 1] (default; values outside are ringing or overshoot).
    progress : callable(done, total), optional
        Called as the work goes on, as in :func:`deblur`: the patches, then the global
        model's refinement steps.
    displacement : (ys, xs, d), optional
        Mean-displacement field the (centred) PSFs leave out; the photo is warped by it
        first (:func:`gyrodeblur.warp.warp_by_displacement`). Where the warp samples
        outside the photo (a strip as wide as the displacement at an edge) the values are
        mirrored, not data; a method whose deconvolver takes an ``unknown`` mask
        (``"sparse"``) gives them no data term.
    model : {"global", "patches"}, optional
        ``"patches"``: each patch deconvolved with its PSF and the results blended (the
        chapter's design). ``"global"``: that result refined under one forward model for
        the whole photo, the PSFs interpolated between the patch centres by the blending
        weights (:mod:`gyrodeblur.spacevariant`), so no patch's boundary or neighbour's
        blur is mistaken for its own; ``"sparse"`` only. Default: ``"global"`` for
        ``"sparse"`` with a grid of equal windows (:func:`~gyrodeblur.tiling.patch_grid`'s)
        of more than one patch on a photo of at most :data:`GLOBAL_DEFAULT_MAX_PIXELS`
        (4 MP; the refinement costs about twice the patch-wise solve), else
        ``"patches"``.
    **options
        Passed to the method's factory (e.g. ``phi`` for Wiener).
    """
    method = _checked_method(method)
    clip = check_flag(clip, "clip")
    check_callback(progress, "progress")
    curve = get_transfer_curve(transfer)
    checked = check_image(image, "photo", max_value=PHOTO_MAX,
                          min_value=PHOTO_MIN)
    if isinstance(psfs, np.ndarray) and psfs.ndim == 2:     # its rows are not PSFs
        raise TypeError(f"psfs must hold one 2-D PSF per patch (a list, or an N x K x K "
                        f"stack), got one {psfs.shape[0]}x{psfs.shape[1]} array: give [psf]")
    patches, psfs = list(patches), list(psfs)
    check_patches(patches, *checked.shape[:2])
    model = _check_model(model, method, patches, checked.shape[:2])
    encoded, alpha = split_alpha(checked)          # alpha is a mask: passed through
    if len(psfs) != len(patches):
        raise InputError(None, f"{len(psfs)} PSFs for {len(patches)} patches: give one each")
    side = max(checked.shape[:2])
    longest = 0
    for i, k in enumerate(psfs):      # checked here, before any work; used as given
        extent = psf_extent(check_psf(k, f"PSF {i + 1}"))
        longest = max(longest, extent)
        if extent > side + 2 * LANCZOS_A:   # longer than any blur a capture may give
            # (psf.check_blur_span), lobes included: no photo is left to restore from
            raise InputError(None, f"PSF {i + 1} spreads light over {extent} px, more than the "
                                   f"{checked.shape[1]}x{checked.shape[0]} photo (a PSF for "
                                   "another size of photo?)")
    if displacement is not None:
        displacement = checked_displacement(displacement, checked.shape[:2])
    img = _light_of(encoded, curve, image)   # patches are cut from it
    workers = 1 if method in _SERIAL_METHODS else None      # its patches one at a time
    with _one_call_at_a_time(method):       # the method's state: one call at a time
        deconvolve = _deconvolver(method, img, encoded, clip, options)
        unknown = None
        if displacement is not None:
            box = max(p.shape[0] * p.shape[1] for p in psfs)
            warp = partial(warp_checked, img, displacement, clipped=CLIPPED,
                           light_area=int(LIGHT_AREA * box))
            if _takes_unknown(deconvolve):  # mirrored samples are not data: no data term
                img, outside = warp(return_outside=True)
                unknown = outside if outside.any() else None
            else:
                img = warp()
        if len(patches) == 1 and patches[0].shape == img.shape[:2]:
            out = (deconvolve(img, psfs[0]) if unknown is None
                   else deconvolve(img, psfs[0], unknown=unknown))
            if progress:
                progress(1, 1)
        elif model == "global":
            out = _deconvolve_globally(img, patches, psfs, deconvolve, unknown, progress,
                                       longest, workers)
        else:
            out = deconvolve_patchwise(img, patches, psfs, deconvolve, progress=progress,
                                       unknown=unknown, workers=workers)
    out = np.asarray(out, np.float32)
    if out.shape != img.shape:
        raise ValueError(f"method {method!r} returned an image of shape {out.shape} for a "
                         f"photo of shape {img.shape}")
    if not np.isfinite(out).all():
        raise ValueError(f"method {method!r} returned NaN or infinite values")
    if np.may_share_memory(out, image):  # never clip the caller's array in place
        out = out.copy()
    if clip:  # negative light is ringing; clip before the curve (in row bands, in place)
        _clip_rows(out, 0.0, None)
    out = curve.encode(out)
    if clip:
        _clip_rows(out, 0.0, 1.0)
    return out if alpha is None else join_alpha(out, alpha)


#: Forward models of :func:`deblur_with_psfs`.
MODELS = ("global", "patches")
#: Largest photo (pixels) for which ``"global"`` is the default model. The refinement
#: costs about twice the patch-wise solve (speed benchmark, session 29, 4 x 8 steps,
#: 2 cores: 1 MP 1.0 -> 3.0 s, 3 MP 2.3 -> 7.2 s, 12 MP 8.1 -> 31.0 s and 1.0 -> 2.3 GB
#: peak), so larger photos stay patch-wise by default, within issue 5's 12 MP budget
#: (10 s, 2 GB); ``model="global"`` still asks for it at any size.
GLOBAL_DEFAULT_MAX_PIXELS = 4_000_000


def _check_model(model, method: str, patches, shape) -> str:
    """The forward model to use (see :func:`deblur_with_psfs`), checked."""
    one_grid = len(patches) > 1 and len({p.shape for p in patches}) == 1
    if model is None:
        small = shape[0] * shape[1] <= GLOBAL_DEFAULT_MAX_PIXELS
        return "global" if method == "sparse" and one_grid and small else "patches"
    if model not in MODELS:
        raise InputError.of_argument("model", f"unknown model {model!r} (global or patches)")
    if model == "global":
        if method != "sparse":
            raise InputError.of_argument("model", f"'global' is the sparse method's; method "
                                                  f"{method!r} deconvolves patch by patch")
        if len(patches) > 1 and not one_grid:
            raise InputError.of_argument("model", "'global' needs a grid of equal windows "
                                                  "(gyrodeblur.tiling.patch_grid)")
    return model if len(patches) > 1 else "patches"


def _deconvolve_globally(img, patches, psfs, deconvolve, unknown, progress, extent,
                         workers=None):
    """The patch-wise sparse result refined under the interpolated-PSF model of the whole
    photo (:func:`gyrodeblur.spacevariant.refine_globally`), with the patch-wise solver's
    own prior weight and clipped-pixel handling, for the budget of the longest PSF's
    ``extent`` (px; one budget for the run and the progress it announces); the patches
    solved in ``workers`` threads (:func:`deconvolve_patchwise`'s)."""
    from .sparse import SparseSettings, _clipping
    from .spacevariant import InterpolatedBlur, refine_globally, refinement_budget
    if not isinstance(deconvolve, SparseSettings):
        raise TypeError("the global model needs the sparse method's deconvolver "
                        f"(gyrodeblur.sparse.SparseSettings), got {deconvolve!r}")
    settings = deconvolve
    channels = 1 if img.ndim == 2 else img.shape[2]
    outer, cg_steps = refinement_budget(extent)
    total = len(patches) + outer * channels
    report = None if progress is None else (lambda done, _: progress(done, total))
    # the patches' results blended unclipped, then clipped below 0 (negative light is
    # ringing) and above 1 but where a compact blob is clipped (``_clip_start_above_one``);
    # with ``clip=False`` the start is the blend as it is, as before
    start = deconvolve_patchwise(img, patches, psfs, dataclasses.replace(settings, clip=False),
                                 progress=report, unknown=unknown, workers=workers)
    if settings.clip:
        np.maximum(start, 0.0, out=start)
    gc = np.moveaxis(img, 2, 0) if img.ndim == 3 else img[None]
    middle = psfs[len(psfs) // 2]
    sat = _clipping(gc, settings.saturation_level, settings.saturation_dilation,
                    np.asarray(middle, np.float32) / np.float32(np.sum(middle)))
    ignore = None if sat is None else sat.ignore
    with InterpolatedBlur(patches, psfs, img.shape[:2]) as blur:
        lights = None
        if sat is not None and sat.lights is not None:
            # held at the patch-wise result: over-exposed lights and the pixels whose light
            # lands mostly on them (with a rolling shutter a light's core may lie beside its
            # streak): no data says more about them than the patches' start does
            cover = blur.adjoint(sat.ignore.astype(np.float32))
            p = blur.pad
            lights = sat.ignore | (cover[p:p + img.shape[0], p:p + img.shape[1]] > 0.5)
        if settings.clip:
            _clip_start_above_one(start, sat, lights, float(extent) ** 2)
        if unknown is not None:
            ignore = unknown if ignore is None else ignore | unknown
        at_least = None
        if sat is not None and sat.at_least is not None:
            at_least = np.moveaxis(sat.at_least, 0, 2) if img.ndim == 3 else sat.at_least[0]
        step = None if progress is None else (
            lambda done: progress(len(patches) + done, total))
        return refine_globally(img, start, blur, outer=outer, cg_steps=cg_steps,
                               weight=settings.weight, exponent=settings.exponent, ignore=ignore,
                               at_least=at_least, fixed=lights, progress=step)


#: Clipped blobs (any channel, one-sided pixels) up to this many boxes of the longest PSF
#: keep the global model's start above 1 (:func:`_clip_start_above_one`).
_START_FREE_BOXES = 8.0


def _clip_start_above_one(start: np.ndarray, sat, lights: np.ndarray | None,
                          box: float) -> None:
    """Clip the global model's start (the patch-wise result, (H, W) or (H, W, C)) to 1 in
    place, but where a light is held (``lights``, with ``sat.ignore``: the over-exposed
    blobs) or the photo is clipped in a blob of at most :data:`_START_FREE_BOXES` x
    ``box`` pixels (``sat.at_least``, each channel's one-sided pixels; ``box``: the
    longest PSF's extent squared).

    Above 1 elsewhere the start is ringing. Where a compact blob is clipped, the scene
    may be far brighter than the clip value (a lamp's glow, a galaxy, a rocket in the
    sun that the over-exposure tests take for clipped but consistent data), and a held
    light must keep the light its streak shows beyond it: from a start clipped to 1, the
    refinement put that light in rings along the trace around the object (held-out
    scenes of session 62: 0.15-1.4 dB of the whole photo, 3 dB beside a 4x glow). A large
    clipped area (white paper, an over-exposed sky) keeps the start at 1: its interior is
    not blurred, and kept above 1 the start cost its text photos up to 0.08 dB."""
    over = start > 1.0
    if sat is not None:
        free = sat.ignore if lights is None else lights       # lights hold sat.ignore
        one_sided = sat.at_least
        if one_sided is not None:         # only in clipped blobs of a few PSF boxes
            lab, n = ndi.label(one_sided.any(axis=0))
            small = np.bincount(lab.ravel(), minlength=n + 1) <= _START_FREE_BOXES * box
            small[0] = False
            one_sided = one_sided & small[lab][None]
        if start.ndim == 3:
            free = np.broadcast_to(free[..., None], start.shape)
            if one_sided is not None:
                free = free | np.moveaxis(one_sided, 0, 2)
        elif one_sided is not None:
            free = free | one_sided[0]
        over &= ~free
    start[over] = 1.0


def _takes_unknown(deconvolve) -> bool:
    """Whether a method's deconvolver takes an ``unknown`` mask (pixels without data)."""
    return _takes_keyword(deconvolve, "unknown")


def _takes_keyword(function, name: str) -> bool:
    """Whether ``function`` names the parameter ``name`` (a ``**kwargs`` does not count:
    it may pass everything on to something that does not take it)."""
    try:
        return name in inspect.signature(function).parameters
    except (TypeError, ValueError):      # a callable without an inspectable signature
        return False


def _clip_rows(a: np.ndarray, lo, hi) -> None:
    """``np.clip(a, lo, hi, out=a)`` on all cores."""
    from .bands import for_row_bands
    for_row_bands(lambda r0, r1: np.clip(a[r0:r1], lo, hi, out=a[r0:r1]), a.shape[0])


#: Per-method defaults of :func:`deblur`: the chapter's 6 x 8 grid and no alignment warp
#: for its Wiener filter; :func:`auto_grid` and the warp for the others.
METHOD_DEFAULTS = {"wiener": {"grid": DEFAULT_GRID, "align": False}}
_OTHER_DEFAULTS = {"grid": "auto", "align": True}


def deblur(image: np.ndarray, capture: Capture, *, mode: str = "variant",
           grid=None, overlap: float | None = None, method: str | None = None,
           align: bool | None = None,
           transfer: str | TransferCurve = "srgb", clip: bool = True, progress=None,
           return_report: bool = False, **options):
    """Remove camera-shake blur from ``image`` using the motion in ``capture``.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo, float32 in [0, 1]. Its size may differ from the capture's
        camera by a common scale (the intrinsics are rescaled). A last channel of 2 or 4
        is alpha, passed through untouched (as :func:`~gyrodeblur.imageio.read_photo`
        gives a grey + alpha or RGBA file): two channels are never two colours.
    capture : Capture
        Exposure timing, intrinsics and gyro log.
    mode : {"variant", "invariant"}
        Space-variant patch-wise deconvolution (default) or one PSF for the whole photo
        (the principal point's, with the middle row's rolling-shutter timing).
    grid : (rows, cols), "RxC" or "auto"
        Patch grid for ``mode="variant"`` (with ``mode="invariant"`` it is refused, as is
        ``overlap``: one PSF serves the whole photo). Default: the chapter's 6 x 8 for
        ``method="wiener"`` (fewer rows or columns on a photo too small for it),
        ``"auto"`` (:func:`auto_grid`: patches small enough that the PSF changes by at
        most ~half a pixel across one) for the other methods.
    overlap : float
        Overlap between neighbouring patches, fraction of the patch size (default 0.25).
    method : str
        Deconvolution method, a key of :data:`METHODS`.
    align : bool, optional
        Warp the photo by the PSFs' mean-displacement field and deconvolve with centred
        PSFs (see :func:`plan_psf_field`). Default: off for ``"wiener"`` (the chapter's
        design), on for the other methods.
    transfer : {"srgb", "linear"} or TransferCurve
        Transfer curve of the photo's values (default sRGB, as a photo file holds them;
        :func:`gyrodeblur.simulate.simulate_blur` makes such a photo by default);
        deconvolution runs in linear light
        (:func:`gyrodeblur.icc.photo_transfer_curve` gives the one a photo's ICC profile
        declares).
    clip : bool
        Clip the output to [0, 1].
    progress : callable(done, total), optional
        Called as the work goes on: ``done`` of ``total`` steps, the patches and, with
        the global model, its refinement's steps after them.
    return_report : bool
        Also return a :class:`DeblurReport`.
    **options
        Method options: ``phi`` for ``"wiener"`` (default
        :func:`gyrodeblur.wiener.photo_phi`: the chapter's 0.01, raised for a noisy
        photo); ``iterations``, ``noise_sigma``, ``weight``, ``exponent`` for ``"sparse"``
        (see :func:`gyrodeblur.sparse.sparse_deconvolve`);
        ``model`` (``"global"`` or ``"patches"``, see :func:`deblur_with_psfs`: by default
        global for ``"sparse"`` up to :data:`GLOBAL_DEFAULT_MAX_PIXELS`).

    Returns
    -------
    ndarray float32 like ``image`` (and a DeblurReport if asked). The result is
    referenced to the camera's orientation at ``capture.exposure_start``: it aligns
    with the scene as the first row saw it, free of rolling-shutter skew.

    Warns
    -----
    GyrodeblurWarning
        Where the gyro log steps more than 15 ms between two samples inside the exposure
        (:func:`gyrodeblur.gyrolog.step_warning`: a dropout, or a log that coarse): the
        motion across it is interpolated, and the result less sharp.
    """
    t0 = time.perf_counter()
    image = check_image(image, "photo", max_value=PHOTO_MAX,
                        min_value=PHOTO_MIN)
    patch_grid(image.shape[:2], (1, 1), 0.0)        # a photo too small for any mode: said
    check_capture(capture)
    check_flag(clip, "clip")
    return_report = check_flag(return_report, "return_report")
    check_callback(progress, "progress")
    get_transfer_curve(transfer)                   # refused before the PSFs are rendered
    warn_of_steps(capture.log, *capture.log_window)
    warn_of_saturation(capture.log, *capture.log_window)
    if align is not None:
        align = check_flag(align, "align")
    method = _checked_method(method)
    defaults = METHOD_DEFAULTS.get(method, _OTHER_DEFAULTS)
    if mode == "invariant":
        for name, value in (("grid", grid), ("overlap", overlap),
                            ("model", options.get("model"))):
            if value is not None:
                raise InputError.of_argument(name, "does not apply with mode='invariant' "
                                                   "(one PSF for the whole photo, no patches)")
    overlap = DEFAULT_OVERLAP if overlap is None else overlap
    grid_given = grid is not None
    if grid is None:
        grid = defaults["grid"]
        if not isinstance(grid, str):    # the method's fixed default: as much as fits
            grid = _grid_that_fits(image.shape[:2], check_grid(grid), overlap)
    align = defaults["align"] if align is None else align
    patches, field_, notes = plan_psf_field(capture, image.shape[:2], mode=mode, grid=grid,
                                            overlap=overlap, align=align,
                                            warn_coarsened=grid_given)
    out = deblur_with_psfs(image, patches, field_.psfs, method=method, transfer=transfer,
                           clip=clip, progress=progress, displacement=field_.displacement,
                           **options)
    if not return_report:
        return out
    model = _check_model(options.get("model"), method, patches, image.shape[:2])
    return out, DeblurReport(mode, method, field_.grid, field_, time.perf_counter() - t0, notes,
                             model)


def deblur_blind(image: np.ndarray, kernel_size: int, *, grid=(1, 1),
                 overlap: float = DEFAULT_OVERLAP, method: str | None = None,
                 transfer: str | TransferCurve = "srgb", max_pixels: int = 1_000_000, clip: bool = True,
                 check_blur: bool = True, progress=None, **options):
    """Deblur without a gyro log: estimate the blur from the photo, then deconvolve.

    The kernel is estimated by :func:`gyrodeblur.blind.estimate_kernel` (sec. 6.3.1:
    gradients, coarse-to-fine, L0 prior with a decreasing weight, positivity and support
    constraints) on the mean of the linear-light channels over the central ``max_pixels``
    of the photo (a crop keeps the time bounded on big photos), then the photo is
    deconvolved with it by ``method``.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        The blurred photo, float32 in [0, 1] (a last channel of 2 or 4 is alpha, passed
        through).
    kernel_size : int
        Side of the kernel support, px (odd; a little more than the blur's extent).
    grid : (rows, cols) or "RxC"
        ``(1, 1)`` (default): one kernel for the whole photo, the space-invariant
        baseline. A finer grid cuts the photo into overlapping patches
        (:func:`gyrodeblur.tiling.patch_grid`, ``overlap``), refines the photo's kernel
        on each patch's own pixels (the finest two pyramid levels, started from it: a
        patch with little texture strays less than an estimate from scratch), and
        deconvolves and blends the patches as the gyro pipeline does: a rotation about
        the optical axis or a rolling shutter makes the blur vary across the photo. Each
        kernel keeps the photo kernel's centre of mass, so each patch's result keeps the
        blurred photo's geometry, and the patches stay registered to one another.
    overlap : float
        Overlap of neighbouring patches (fraction of the patch size).
    method, transfer, clip, progress, **options
        As for :func:`deblur_with_psfs`.
    max_pixels : int
        Pixels the kernel is estimated on (the central part of the photo, or of each
        patch in proportion).
    check_blur : bool
        Check the photo's kernel against the photo's spectrum
        (:func:`gyrodeblur.blur_evidence.kernel_gain_over_no_blur`): a kernel that
        explains the most textured windows no better than no blur (by
        :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN`) is a false estimate (a
        near-sharp photo, a page of text) or the blur varies too much for one kernel, and
        deconvolving with it rings; so is one that passes but does not sharpen those
        windows (:func:`gyrodeblur.blur_evidence.kernel_sparsity_ratio` over
        :data:`~gyrodeblur.blur_evidence.SPARSER_MAX`: a kernel shaped like a repeated
        pattern or glyph, whose ``|H|`` fits the spectrum). The photo is then returned as
        it is (clipped to [0, 1] with ``clip``), the field holds delta kernels, and a
        warning says so. With a grid, the check is the photo kernel's, before the patches
        refine it (checked patch by patch on the benchmark, the smaller windows' verdicts
        cost more than they saved). ``False``: the kernels are used as estimated.

    Returns
    -------
    restored : ndarray float32
    field : PSFField
        The estimated kernels at the patches' centres. Unlike the gyro pipeline's result,
        the restored photo is not referenced to the exposure start: a blind kernel is
        known only up to a shift, and each is centred on its centre of mass.

    Raises
    ------
    InputError
        A bad ``grid`` or ``overlap`` (sources ``"grid"``, ``"overlap"``), or
        patches too small for the kernel (``"grid"``).
    """
    from .blind import estimate_kernel

    image = check_image(image, "photo", max_value=PHOTO_MAX,
                        min_value=PHOTO_MIN)
    method = _checked_method(method)
    clip = check_flag(clip, "clip")
    check_flag(check_blur, "check_blur")
    check_callback(progress, "progress")
    if not is_count(max_pixels):
        raise InputError(None, f"max_pixels must be a whole number >= 1, got {max_pixels!r}")
    H, W = image.shape[:2]
    if isinstance(grid, str) and grid.strip().lower() == "auto":
        raise InputError.of_argument("grid", "'auto' sizes the patches by how fast the gyro's "
                                             "PSFs change across the photo, which a blind "
                                             "deblur has no gyro for: give RxC (e.g. 2x3)")
    grid = check_grid(grid)
    encoded = split_alpha(image)[0]                  # not the mask
    lin = _light_of(encoded, get_transfer_curve(transfer), image)
    lum = lin.mean(axis=2) if lin.ndim == 3 else lin
    patches = check_blind_sizes((H, W), kernel_size, grid, overlap, max_pixels)
    psfs = [estimate_kernel(_central(lum, max_pixels), kernel_size)]
    if check_blur and _shows_no_blur(image, psfs[0], transfer):
        with _one_call_at_a_time(method):                # its options refused as always
            _deconvolver(method, lin, encoded, clip, options)
        delta = np.zeros_like(psfs[0])
        delta[kernel_size // 2, kernel_size // 2] = 1.0
        out = np.array(image, np.float32)
        if progress is not None:                     # nothing left to do
            progress(1, 1)
        return (np.clip(out, 0.0, 1.0) if clip else out), \
            PSFField(_centres_xy(patches), [delta] * len(patches), grid)
    if len(patches) > 1:       # each patch refines the photo's kernel on its own pixels
        share = max_pixels / len(patches)
        psfs = [estimate_kernel(_central(lum[p.y0:p.y1, p.x0:p.x1], share), kernel_size,
                                init_psf=psfs[0]) for p in patches]
    out = deblur_with_psfs(image, patches, psfs, method=method, transfer=transfer,
                           clip=clip, progress=progress, **options)
    return out, PSFField(_centres_xy(patches), psfs, grid)


def check_blind_sizes(shape: tuple[int, int], kernel_size: int, grid=(1, 1),
                      overlap: float = DEFAULT_OVERLAP, max_pixels: int = 1_000_000) -> list:
    """Refuse a kernel that :func:`deblur_blind` could not estimate on a photo of ``shape``
    (rows, columns): one not under half the shorter side of the part it is estimated on
    (the central ``max_pixels``, and each patch's share of them), or a ``grid`` whose
    patches it does not fit. Cheap (no pixels): for checking every photo of a command
    before any is deblurred. Returns the patches.

    Raises
    ------
    InputError
        Sources ``"kernel_size"`` (a size not odd, or too large for the photo),
        ``"grid"`` (patches too small for the kernel) or ``"overlap"``.
    """
    from .blind import _check_kernel_size
    patches = patch_grid(shape, grid, overlap)
    central = _central_shape(shape, max_pixels)
    _check_kernel_size(kernel_size, central, "image" if central == tuple(shape[:2]) else
                       "px central crop the kernel is estimated on")
    if len(patches) > 1:
        if kernel_size >= min(patches[0].shape) // 2:
            raise InputError.of_argument(
                "grid", f"{len(patches)} patches of {patches[0].shape[1]}x"
                        f"{patches[0].shape[0]} px are too small for a "
                        f"{kernel_size} px kernel (it must be under half a "
                        f"patch's shorter side): use a coarser grid")
        share = max_pixels / len(patches)
        for p in patches:
            _check_kernel_size(kernel_size, _central_shape(p.shape, share),
                               "px central crop of each patch its kernel is estimated on")
    return patches


#: How both of :func:`_shows_no_blur`'s warnings end.
_RETURNED_AS_IT_IS = ("It is returned as it is (--no-blur-check, check_blur=False: deconvolve "
                      "anyway; with the camera's gyro log, --capture gives the blur at every "
                      "pixel)")


def _shows_no_blur(image, psf, transfer) -> bool:
    """Whether ``image`` shows less of the blur ``psf`` than no blur at all would explain
    (:func:`gyrodeblur.blur_evidence.kernel_gain_over_no_blur` under
    :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN`), or is not sharpened by it
    (:func:`~gyrodeblur.blur_evidence.kernel_sparsity_ratio` over
    :data:`~gyrodeblur.blur_evidence.SPARSER_MAX`); a warning says which. ``False`` when
    neither can tell (a photo too small for the first, with no textured window for the
    second)."""
    from .blur_evidence import NO_BLUR_MARGIN, SPARSER_MAX, blind_kernel_evidence
    from .psf import psf_extent

    gain, ratio = blind_kernel_evidence(image, psf, transfer=transfer)
    if not gain < NO_BLUR_MARGIN:
        if not ratio > SPARSER_MAX:
            return False
        warnings.warn(f"the blind kernel does not sharpen the photo: deconvolved with it, "
                      f"the most textured windows' edges are hardly sparser than with no "
                      f"blur (their gradients' L1/L2 x{ratio:.2f} of that, over "
                      f"{SPARSER_MAX:g}), as where a repeating pattern or text is taken for "
                      f"the blur, the photo shows little blur, or the kernel size is far "
                      f"larger than the blur (give one a little over the blur's length). "
                      f"Deconvolving with it would add ghost edges. {_RETURNED_AS_IT_IS}",
                      GyrodeblurWarning, stacklevel=3)
        return True
    side = psf.shape[0]
    why = (f"the photo shows little blur, or its blur is longer than the {side} px kernel "
           f"support" + (", as the estimate filling the whole support suggests"
                         if psf_extent(psf) >= side - 1 else "")
           + " (try a larger kernel size if the photo is visibly blurred: on a sharp photo "
             "a larger support only invites a false kernel)")
    warnings.warn(f"the blind kernel explains the photo no better than no blur at all "
                  f"({gain:+.1f} nats per 9 windows, under {NO_BLUR_MARGIN:g}), so it does not "
                  f"fit the photo: {why}, or its blur is not one "
                  f"kernel's (a rolling shutter, a roll or a wide lens make it vary across "
                  f"the frame), or the scene misled the estimate (text, a few straight "
                  f"edges). Deconvolving with it would add ringing. {_RETURNED_AS_IT_IS}",
                  GyrodeblurWarning, stacklevel=3)
    return True


def _centres_xy(patches) -> np.ndarray:
    """``(N, 2)`` centres (x, y) of ``patches``, pixels: where their PSFs belong."""
    return np.array([[p.centre[1], p.centre[0]] for p in patches])


def _central(a: np.ndarray, max_pixels: float) -> np.ndarray:
    """The central part of ``a`` with at most ``max_pixels`` pixels (same aspect ratio)."""
    h, w = a.shape[:2]
    hh, ww = _central_shape((h, w), max_pixels)
    y0, x0 = (h - hh) // 2, (w - ww) // 2
    return a[y0:y0 + hh, x0:x0 + ww]


def _central_shape(shape: tuple[int, int], max_pixels: float) -> tuple[int, int]:
    """(rows, columns) of :func:`_central`'s part of an array of ``shape``."""
    h, w = shape
    if h * w <= max_pixels:
        return h, w
    s = np.sqrt(max_pixels / (h * w))
    return int(h * s), int(w * s)
