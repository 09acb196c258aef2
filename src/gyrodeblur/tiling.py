"""Patch tiling and Hamming blending for space-variant deconvolution (sec. 6.5.2).

The chapter splits the photo into 6 x 8 overlapping patches (25 % overlap), renders one
PSF at each patch centre, deconvolves every patch with its own PSF and blends the
results with Hamming windows. Here:

* :func:`patch_grid` lays out equal-sized windows that tile the image exactly, with the
  same overlap (in pixels) between every pair of neighbours;
* :func:`blend_weights` gives each window a separable Hamming weight, normalised so the
  weights of all windows sum to one at every pixel (no seams, no brightness steps, no
  dark border; Hamming rather than Hann because it stays positive at the window edge,
  where a border pixel has only one window);
* :func:`deconvolve_patchwise` deconvolves each window with a margin of real
  neighbouring pixels, crops it back, weights it and accumulates it in place into one
  output image, so memory stays at about two images whatever the number of patches.
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .arguments import is_whole
from .errors import GyrodeblurWarning, InputError
from .fftutils import usable_cpus

__all__ = [
    "Patch",
    "check_grid",
    "check_overlap",
    "patch_grid",
    "blend_weights",
    "check_patches",
    "deconvolve_patchwise",
    "psf_radius",
    "patch_margin",
    "DEFAULT_GRID",
    "DEFAULT_OVERLAP",
    "MAX_OVERLAP",
    "MIN_WINDOW",
    "MARGIN_EXTRA",
    "MAX_AUTO_WORKERS",
]

#: The chapter's grid: 6 rows by 8 columns of patches.
DEFAULT_GRID: tuple[int, int] = (6, 8)
#: The chapter's overlap between neighbouring patches, as a fraction of the window size.
DEFAULT_OVERLAP: float = 0.25
#: Largest accepted overlap; beyond one half a pixel lies in three windows along an axis,
#: which costs time and buys nothing.
MAX_OVERLAP: float = 0.5
#: Smallest window side (pixels) that :func:`patch_grid` accepts.
MIN_WINDOW: int = 16
#: A grid whose windows, at their smallest, still overlap by more than this is refused (the
#: asked overlap is met only approximately on small images; 99 % was possible).
CROWDED_OVERLAP: float = 0.75
#: Most threads :func:`deconvolve_patchwise` uses when not told (memory: one extended
#: patch and its FFT buffers each, about 30 MB for a 720 x 720 RGB FFT).
MAX_AUTO_WORKERS: int = 4
#: Pixels added to the PSF radius for the margin of real neighbours around each patch.
MARGIN_EXTRA: int = 8


@dataclass(frozen=True)
class Patch:
    """One patch window in image pixels, half-open: rows ``y0:y1``, columns ``x0:x1``."""

    y0: int
    y1: int
    x0: int
    x1: int

    @property
    def centre(self) -> tuple[float, float]:
        """``(y, x)`` of the window centre in pixel coordinates (pixel centres are integers).

        The window holds pixels ``y0 .. y1 - 1``, so its centre is their mean
        ``(y0 + y1 - 1) / 2``; this is where the patch's PSF should be rendered.
        """
        return (self.y0 + self.y1 - 1) / 2.0, (self.x0 + self.x1 - 1) / 2.0

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)`` of the window."""
        return self.y1 - self.y0, self.x1 - self.x0


def patch_grid(shape: Sequence[int], grid: Sequence[int] = DEFAULT_GRID,
               overlap: float = DEFAULT_OVERLAP) -> list[Patch]:
    """Equal-sized overlapping windows that tile an image, listed row-major.

    Along each axis of length ``L`` with ``n`` windows of size ``w`` and a constant overlap
    of ``v`` pixels between neighbours, the windows start at ``i * (w - v)`` and the last
    one ends exactly at ``L`` (``n w - (n - 1) v = L``). Among the integer pairs
    ``(w, v)`` that satisfy this, the one whose ``v / w`` is closest to ``overlap`` is
    chosen (ties: the smaller window), so the overlap is exact in pixels and within about
    ``n / w`` of the requested fraction.

    Parameters
    ----------
    shape : (int, int, ...)
        Image shape; only the first two entries (rows, columns) are used.
    grid : (int, int)
        Number of patch rows and columns (the chapter's 6 x 8 by default).
    overlap : float
        Overlap of neighbouring windows as a fraction of the window size, in [0, 0.5].

    Returns
    -------
    list of Patch
        ``grid[0] * grid[1]`` windows, row-major, all of the same size.

    Raises
    ------
    InputError
        Bad ``grid`` (source ``"grid"``): not two positive integers, or so fine that a
        window would be under ``MIN_WINDOW`` pixels. Bad ``overlap`` (source
        ``"overlap"``): not a number in [0, 0.5].

    Examples
    --------
    >>> patches = patch_grid((3000, 4000))
    >>> len(patches), patches[0].shape, patches[1].x0
    (48, (630, 640), 480)
    """
    rows, cols = check_grid(grid)
    overlap = check_overlap(overlap)
    height, width = int(shape[0]), int(shape[1])
    ys = _axis_windows(height, rows, overlap, "rows")
    xs = _axis_windows(width, cols, overlap, "columns")
    return [Patch(y0, y1, x0, x1) for (y0, y1) in ys for (x0, x1) in xs]


def blend_weights(patches: Sequence[Patch],
                  shape: Sequence[int]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Separable Hamming blending weights, one ``(wy, wx)`` pair per patch.

    Each window gets the Hamming window of its height (rows) and width (columns). When
    the patches form a row/column grid (every patch row interval paired with every
    column interval exactly once, as :func:`patch_grid` makes), the 1-D windows are
    divided by their per-axis sums, so that
    ``sum_p outer(wy_p, wx_p)`` (each placed at its patch) equals 1 at every pixel.

    Parameters
    ----------
    patches : sequence of Patch
        Windows forming a grid that covers the image.
    shape : (int, int, ...)
        Image shape; only rows and columns are used.

    Returns
    -------
    list of (ndarray, ndarray)
        float32 ``wy`` of length ``y1 - y0`` and ``wx`` of length ``x1 - x0`` per patch;
        the patch's 2-D weight is ``wy[:, None] * wx[None, :]``.

    Raises
    ------
    ValueError
        The patches do not form a row/column grid, leave pixels uncovered or leave the
        image. (:func:`deconvolve_patchwise` still blends such layouts, with a 2-D weight
        map.)
    """
    height, width = int(shape[0]), int(shape[1])
    check_patches(patches, height, width)
    row_ivs = sorted({(p.y0, p.y1) for p in patches})
    col_ivs = sorted({(p.x0, p.x1) for p in patches})
    cells = {(p.y0, p.y1, p.x0, p.x1) for p in patches}
    if len(cells) != len(patches) or len(patches) != len(row_ivs) * len(col_ivs):
        raise ValueError("patches do not form a row/column grid; separable weights that "
                         "sum to one do not exist for this layout")
    wy_of = _normalised_axis_weights(row_ivs, height, "rows")
    wx_of = _normalised_axis_weights(col_ivs, width, "columns")
    return [(wy_of[(p.y0, p.y1)], wx_of[(p.x0, p.x1)]) for p in patches]


def _support(psf: np.ndarray):
    """Indices of the rows and of the columns of ``psf`` holding a non-zero sample."""
    psf = np.asarray(psf)
    nonzero = psf != 0
    return np.flatnonzero(np.any(nonzero, axis=1)), np.flatnonzero(np.any(nonzero, axis=0))


def _radius(psf: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> int:
    if rows.size == 0:
        return 0
    cy, cx = psf.shape[0] // 2, psf.shape[1] // 2
    return int(max(cy - rows[0], rows[-1] - cy, cx - cols[0], cols[-1] - cx))


def psf_radius(psf: np.ndarray) -> int:
    """Largest row or column distance from the centre sample to a non-zero PSF sample."""
    return _radius(np.asarray(psf), *_support(psf))


def patch_margin(psf: np.ndarray) -> int:
    """Pixels of real neighbours :func:`deconvolve_patchwise` keeps around a window by
    default: the larger of the PSF's radius (how far from its centre it reaches, which a
    rolling shutter's offset makes long) and its non-zero extent (one blur length), plus
    :data:`MARGIN_EXTRA`. A camera's blur changes smoothly across the photo, so more real
    context helps; where a blur changes abruptly within a margin (a synthetic test
    pattern), the margin holds the wrong blur, and a smaller ``margin`` is better."""
    psf = np.asarray(psf)
    rows, cols = _support(psf)
    extent = 0 if rows.size == 0 else int(max(rows[-1] - rows[0], cols[-1] - cols[0]) + 1)
    return max(_radius(psf, rows, cols), extent) + MARGIN_EXTRA


def deconvolve_patchwise(image: np.ndarray, patches: Sequence[Patch],
                         psfs: Sequence[np.ndarray],
                         deconvolve: Callable[[np.ndarray, np.ndarray], np.ndarray], *,
                         margin: int | None = None, workers: int | None = None,
                         progress: Callable[[int, int], object] | None = None,
                         unknown: np.ndarray | None = None) -> np.ndarray:
    """Deconvolve every patch with its own PSF and blend the results (sec. 6.5.2).

    For each patch the window is extended by a margin of real neighbouring pixels
    (default :func:`patch_margin`: the larger of the PSF's reach and its length, plus
    ``MARGIN_EXTRA`` = 8 px), clamped at the image border,
    where the deconvolver's own border padding takes over. The extended sub-image goes
    to ``deconvolve(sub_image, psf)``; the result is cropped back to the window,
    multiplied by the window's Hamming weight (:func:`blend_weights`) and added into the
    output in place. Weights sum to one at every pixel, so a flat image stays flat.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Blurred image; computed in float32.
    patches : sequence of Patch
        Windows covering the image, e.g. from :func:`patch_grid`. Layouts that are not a
        row/column grid are blended with an accumulated 2-D weight map instead.
    psfs : sequence of ndarray
        One 2-D odd-sized PSF per patch, in the same order (rendered at
        ``patch.centre``).
    deconvolve : callable
        ``deconvolve(sub_image, psf) -> array`` of the sub-image's shape, e.g.
        ``functools.partial(wiener_deconvolve, phi=0.01)``. Do not let it normalise each
        patch on its own (brightness steps); normalise the blended result instead.
    margin : int, optional
        Margin in pixels around every window, overriding the per-PSF default.
    workers : int, optional
        Patches deconvolved concurrently in threads; default one per core, at most
        ``MAX_AUTO_WORKERS`` = 4; 1 runs them one after the other. FFTs and large NumPy
        operations release the GIL, so the element-wise work of one patch (padding,
        filtering, blending) overlaps another's; this was about 1.6x faster than 1 on
        2 cores. ``deconvolve`` must be thread-safe when ``workers > 1``
        (:func:`~gyrodeblur.wiener.wiener_deconvolve` is). Results are accumulated in
        patch order, so the output is identical for any value.
    progress : callable, optional
        Called as ``progress(done, total)`` after each patch, from the calling thread.
    unknown : ndarray of bool, shape (H, W), optional
        Pixels that are not data (e.g. an alignment warp's samples outside the photo).
        Where an extended window holds some, they are passed on as
        ``deconvolve(sub_image, psf, unknown=sub_mask)``, so ``deconvolve`` must take that
        keyword (:func:`~gyrodeblur.sparse.sparse_deconvolve` does).

    Returns
    -------
    ndarray, float32, same shape as ``image``.

    Warns
    -----
    GyrodeblurWarning
        When a PSF's blur extent (:func:`gyrodeblur.psf.psf_extent`, its offset from the
        centre left out) exceeds the smaller side of its window. The patch is still
        processed: the margin of real neighbours (:func:`patch_margin` on every side) gives
        the deconvolution the context it needs, so windows down to the blur's own size
        work (measured on shared photos); beyond that a patch holds less than one blur
        length of its own content, and a coarser grid is better. We warn rather than
        silently enlarge the patches because the PSFs were rendered for these windows'
        centres.

    Notes
    -----
    Memory: the output image plus at most ``workers + 1`` extended patches and their FFT
    buffers at a time (plus an (H, W) float32 weight map for non-grid layouts); the
    patches are never all held at once.

    Margin: a window needs about one blur length of real neighbours on each side, not
    just the PSF's radius. With the photo aligned first (centred PSFs, the sparse
    method's default) the radius is only half the blur, and windows of about the blur's
    length then lost up to 2 dB (a 60 px shake, 7 x 11 patches). Measured with the
    landing-row PSFs (one run each, this machine): radius + 8 against this default,
    26.39 -> 26.49 dB mean PSNR on the 36-case benchmark (6 % more time), 28.71 -> 28.95
    dB on 24 cases of other photos and shakes (synthetic 400 Hz shake, 100 Hz log, a
    global shutter, 50-100 ms exposures; up to +1.9 dB on 60 px blurs, -0.6 dB the worst
    loss).
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3):
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {image.shape}")
    image = image.astype(np.float32, copy=False)
    height, width = image.shape[:2]
    patches = list(patches)
    psfs = list(psfs)
    if len(psfs) != len(patches):
        raise ValueError(f"got {len(psfs)} PSFs for {len(patches)} patches")
    if not patches:
        raise ValueError("no patches given")
    for psf in psfs:
        if np.ndim(psf) != 2:
            raise ValueError(f"every PSF must be 2-D, got shape {np.shape(psf)}")
    if margin is not None and not (is_whole(margin) and margin >= 0):
        raise ValueError(f"margin must be a non-negative integer, got {margin!r}")
    if workers is None:
        workers = min(usable_cpus(), MAX_AUTO_WORKERS)
    if not (is_whole(workers) and workers >= 1):
        raise ValueError(f"workers must be a positive integer, got {workers!r}")

    margins = [patch_margin(psf) for psf in psfs]
    if unknown is not None:
        unknown = np.asarray(unknown, bool)
        if unknown.shape != (height, width):
            raise ValueError(f"unknown must be a boolean mask of shape {(height, width)}, "
                             f"got {unknown.shape}")
    check_patches(patches, height, width)
    _warn_large_psfs(patches, psfs)

    try:
        weights = blend_weights(patches, (height, width))
        weight_map = None
    except ValueError:
        weights = [(_hamming(p.y1 - p.y0), _hamming(p.x1 - p.x0)) for p in patches]
        weight_map = np.zeros((height, width), np.float32)

    out = np.zeros(image.shape, np.float32)
    channels = 1 if image.ndim == 2 else image.shape[2]
    total = len(patches)

    def extract(k: int) -> tuple[np.ndarray, tuple[int, int]]:
        patch = patches[k]
        m = margins[k] if margin is None else int(margin)
        ey0, ex0 = max(0, patch.y0 - m), max(0, patch.x0 - m)
        sub = image[ey0:min(height, patch.y1 + m), ex0:min(width, patch.x1 + m)]
        return sub, (ey0, ex0)

    def run(k: int) -> tuple[np.ndarray, tuple[int, int]]:
        sub, origin = extract(k)
        mask = None if unknown is None else unknown[origin[0]:origin[0] + sub.shape[0],
                                                    origin[1]:origin[1] + sub.shape[1]]
        if mask is not None and mask.any():
            res = np.asarray(deconvolve(sub, psfs[k], unknown=mask))
        else:
            res = np.asarray(deconvolve(sub, psfs[k]))
        if res.shape != sub.shape:
            raise ValueError(f"deconvolve returned shape {res.shape} for a sub-image of "
                             f"shape {sub.shape}")
        return res, origin

    def accumulate(k: int, res: np.ndarray, origin: tuple[int, int]) -> None:
        patch = patches[k]
        wy, wx = weights[k]
        h, w = patch.shape
        crop = res[patch.y0 - origin[0]:patch.y1 - origin[0],
                   patch.x0 - origin[1]:patch.x1 - origin[1]].reshape(h, w * channels)
        # `out` is C-contiguous, so this reshape is a view into it, never a copy.
        target = out[patch.y0:patch.y1, patch.x0:patch.x1].reshape(h, w * channels)
        # target += crop * wy * wx, rows of w*C contiguous values at a time.
        tmp = np.multiply(crop, np.repeat(wx, channels)[None, :], dtype=np.float32)
        tmp *= wy[:, None]
        target += tmp
        if weight_map is not None:
            weight_map[patch.y0:patch.y1, patch.x0:patch.x1] += np.multiply.outer(wy, wx)
        if progress is not None:
            progress(k + 1, total)

    if workers == 1:
        for k in range(total):
            accumulate(k, *run(k))
    else:
        # `workers` patches in flight while this thread adds the oldest finished one;
        # results are added in patch order, so the output does not depend on timing.
        with ThreadPoolExecutor(max_workers=workers) as pool:
            pending: deque = deque()
            for k in range(total):
                pending.append(pool.submit(run, k))
                if len(pending) > workers:
                    accumulate(k - len(pending) + 1, *pending.popleft().result())
            first = total - len(pending)
            for i, fut in enumerate(pending):
                accumulate(first + i, *fut.result())

    if weight_map is not None:
        if not np.all(weight_map > 0):
            raise ValueError("the patches leave some pixels uncovered")
        np.divide(out, weight_map if image.ndim == 2 else weight_map[..., None], out=out)
    return out


def check_grid(grid: Sequence[int] | str) -> tuple[int, int]:
    """``grid`` as ``(rows, cols)``, or :class:`InputError` (``--grid``) unless it is two
    positive integers, as a pair or as the text ``"RxC"`` (e.g. ``"6x8"``)."""
    if isinstance(grid, str):
        parts = grid.strip().lower().split("x")
        items = ([int(v) for v in parts]
                 if len(parts) == 2 and all(v.strip().isdigit() for v in parts) else None)
        if items is None or min(items) < 1:
            raise InputError.of_argument(
                "grid", f"expected RxC with two positive integers (e.g. 6x8), "
                        f"got {grid!r}")
        return items[0], items[1]
    try:
        items = list(grid)
    except TypeError:
        items = None
    if (items is None or len(items) != 2
            or not all(is_whole(v) for v in items)
            or not all(v >= 1 for v in items)):
        raise InputError.of_argument(
            "grid", f"must be two positive integers (rows, columns), got {grid!r}")
    return int(items[0]), int(items[1])


def check_overlap(overlap: float) -> float:
    """``overlap`` as a float, or :class:`InputError` (``--overlap``) unless it is a finite
    fraction of the patch size in [0, :data:`MAX_OVERLAP`]."""
    if (isinstance(overlap, bool) or not isinstance(overlap, numbers.Real)
            or not math.isfinite(overlap) or not 0.0 <= overlap <= MAX_OVERLAP):
        raise InputError.of_argument("overlap", "must be a fraction of the patch size in "
                                                f"[0, {MAX_OVERLAP}], got {overlap!r}")
    return float(overlap)


def _axis_windows(length: int, n: int, overlap: float, axis_name: str) -> list[tuple[int, int]]:
    if n == 1:
        if length < MIN_WINDOW:
            raise InputError(None, f"the image has only {length} {axis_name}; need at "
                                   f"least {MIN_WINDOW}")
        return [(0, length)]
    best = None
    # n w - (n - 1) v = L  =>  w = L (mod n - 1); stride w - v >= 1 and v >= 0.
    first = -(-length // n)
    first += (length - first) % (n - 1)
    for w in range(first, length + 1, n - 1):
        v = (n * w - length) // (n - 1)
        if v < 0 or v >= w:
            continue
        err = abs(v / w - overlap)
        if best is None or err < best[0] - 1e-12:
            best = (err, w, v)
    if best is None or best[1] < MIN_WINDOW:
        raise InputError.of_argument(
            "grid", f"{n} patches across {length} {axis_name} are too many: "
                    f"windows would be under {MIN_WINDOW} px")
    _, w, v = best
    if v / w > CROWDED_OVERLAP:       # the windows are as small as allowed and still crowd
        raise InputError.of_argument(
            "grid", f"{n} patches across {length} {axis_name} are too many: "
                    f"they would overlap by {100 * v / w:.0f} % (more than "
                    f"{100 * CROWDED_OVERLAP:.0f} %)")
    return [(i * (w - v), i * (w - v) + w) for i in range(n)]


def _hamming(n: int) -> np.ndarray:
    return np.hamming(n).astype(np.float32) if n > 1 else np.ones(n, np.float32)


def _normalised_axis_weights(intervals: list[tuple[int, int]], length: int,
                             axis_name: str) -> dict[tuple[int, int], np.ndarray]:
    total = np.zeros(length, np.float64)
    raw = {}
    for a, b in intervals:
        raw[(a, b)] = np.hamming(b - a) if b - a > 1 else np.ones(b - a)
        total[a:b] += raw[(a, b)]
    if not np.all(total > 0):
        first = int(np.flatnonzero(total <= 0)[0])
        raise ValueError(f"the patches leave image {axis_name} uncovered (first: {first})")
    return {iv: (w / total[iv[0]:iv[1]]).astype(np.float32) for iv, w in raw.items()}


def check_patches(patches: Sequence[Patch], height: int, width: int) -> None:
    """Refuse a window that is not a :class:`Patch` of whole-number bounds (TypeError),
    or that is empty or leaves the ``height`` x ``width`` image (ValueError)."""
    for p in patches:
        if not isinstance(p, Patch):
            raise TypeError(f"patches must be gyrodeblur.tiling.Patch windows (y0, y1, x0, "
                            f"x1), got {type(p).__name__} {p!r}")
        if not all(is_whole(v) for v in (p.y0, p.y1, p.x0, p.x1)):
            raise TypeError(f"{p}: a window's bounds must be whole numbers of pixels")
        if not (0 <= p.y0 < p.y1 <= height and 0 <= p.x0 < p.x1 <= width):
            raise ValueError(f"{p} is empty or leaves the {height}x{width} image")


def _warn_large_psfs(patches: Sequence[Patch], psfs: Sequence[np.ndarray]) -> None:
    # The blur's own size counts here, not its offset from the centre sample (a rolling
    # shutter displaces lower rows' PSFs; the margin takes care of the displacement).
    from .psf import psf_extent
    extents = [psf_extent(np.asarray(p)) for p in psfs]
    bad = [(e, p) for p, e in zip(patches, extents) if e > min(p.shape)]
    if bad:
        extent, patch = max(bad, key=lambda t: t[0])
        side = min(max(p.y1 for p in patches), max(p.x1 for p in patches))
        advice = ("use a coarser grid" if extent <= side else
                  f"the photo's shorter side is only {side} px, so no grid helps")
        warnings.warn(
            f"PSF extent up to {extent} px exceeds the patch window "
            f"({patch.shape[0]}x{patch.shape[1]} px) in {len(bad)} of {len(patches)} patches: "
            f"deblurring will be poor there; {advice}",
            GyrodeblurWarning, stacklevel=3)
