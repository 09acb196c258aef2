"""The alignment warp: a photo sampled where each pixel's light landed on average.

With a rolling shutter, or a blur that turns, the PSFs of a photo are not centred on
their pixels: each is displaced by the mean of its trace
(:func:`gyrodeblur.psf.displacement_field`). :func:`warp_by_displacement` moves every
pixel by that displacement, so that the PSFs are centred and the deconvolution that
follows restores the photo in the geometry of the first row's exposure start
(:mod:`gyrodeblur.deblur` decides where it is worth its resampling).
Clipped point lights are kept clipped and free of the interpolation's undershoot.
"""

from __future__ import annotations

import cv2
import numpy as np

from .images import check_image
from .sparse import _CLIP_VALUE, _ZONE_AREA

__all__ = ["warp_by_displacement", "warp_checked", "checked_displacement", "CLIPPED",
           "LIGHT_AREA", "WARP_INTERPOLATION"]

#: Interpolation of the alignment warp: Lanczos (8 x 8 taps). Against a quintic-spline
#: reference on a smoothly warped photo it is 58 dB accurate; OpenCV's bicubic 47 dB and
#: the quadratic B-spline used before 49 dB (0.5-1 s at 12 MP against 2 s for that spline).
#: On the 36-case benchmark all three lie within 0.01 dB of each other (saturated photos:
#: bicubic +0.05, Lanczos -0.08 dB against the spline).
WARP_INTERPOLATION = cv2.INTER_LANCZOS4
#: Samples of the alignment warp this close (px, Chebyshev) to a small clipped blob are
#: clamped to their neighbours' range: Lanczos4 reads the 8 x 8 pixels around a sample,
#: up to 4 px away (see :func:`warp_by_displacement`).
_CLIPPED_REACH = 4
#: Blocks (rows, columns) of the warp's output in which that clamp is worked out, only
#: where a block holds such samples.
_CLAMP_BLOCK = (64, 256)
#: Output tile (rows, columns) of the alignment warp.
_WARP_TILE = (1024, 8192)

#: Linear values at or above this are clipped (8-bit 255 decodes to 1.0): the sparse
#: solver's own clip value, so that what the warp keeps clipped is what the solver treats
#: as clipped.
CLIPPED = _CLIP_VALUE
#: Clipped blobs no bigger than this many boxes of the largest PSF are point lights'
#: streaks to the alignment warp (the sparse solver's bound for the over-exposed blobs it
#: starts from the data around, ``_ZONE_AREA``, per patch PSF).
LIGHT_AREA = _ZONE_AREA


def warp_by_displacement(image: np.ndarray, displacement, *, clipped: float | None = None,
                         light_area: int | None = None, return_outside: bool = False):
    """``g(x + c(x))``: sample ``image`` where each pixel's light landed on average.

    ``displacement`` is ``(ys, xs, d)`` from :func:`gyrodeblur.psf.displacement_field`
    (a regular grid), interpolated bilinearly to every pixel; the image is sampled with
    OpenCV's ``remap`` and :data:`WARP_INTERPOLATION` (mirrored outside the frame, sample
    positions rounded to 1/32 px). After this warp every pixel's PSF is centred on it.
    The output is made in tiles of :data:`_WARP_TILE` (OpenCV spreads each over its
    threads), each from the part of the photo its samples need, so photos of any size
    work (``remap`` itself takes images under 32767 px a side); memory: the output, the
    sample positions of one band of rows (2 x 1024 x width float32: 31 MiB at 4000 px) and
    a float32 copy of the input if it is not one already.

    ``clipped``: values at or above it are clipped data, and stay so: where a channel's
    clipped pixels cover at least half of a sample position (their indicator warped
    bilinearly), the warped channel is set to the photo's clip value (its maximum).
    Interpolating across a clipped plateau otherwise leaves it ragged (Lanczos lobes dip
    below the clip value), and the deconvolution then cannot tell an over-exposed light's
    streak from ordinary data
    (:func:`gyrodeblur.sparse.sparse_deconvolve`).

    ``light_area`` (pixels, needs ``clipped``): beside clipped blobs no bigger than this
    (8-connected, any channel: point lights' streaks), samples whose Lanczos taps reach
    the blob (within :data:`_CLIPPED_REACH` px) are clamped to the range of their four
    nearest pixels. A clipped streak is a step far steeper than the blurred scene around it
    (in the photo, a light far over the clip level drops from the clip value to the
    background within a pixel), and Lanczos lobes would leave a dark halo of undershoot
    beside it that the deconvolution reads as scene: ripples around street lights. Bigger
    clipped areas (white paper, sky) keep plain Lanczos at their edges: those are ordinary
    edges, and clamping there cost up to 0.3 dB on the benchmark's text photos. ``None``
    (default): no clamping.

    A clipped line exactly half a pixel off the grid comes out two pixels wide (both
    neighbours are half covered). Photos with values above 1 (linear data with no clip
    ceiling) are warped as they are. Memory, when the photo has clipped pixels: one uint8
    indicator per channel and pixel; with ``light_area``, two more uint8 and, for a moment,
    one int32 per pixel (blob labels).

    ``return_outside``: also return a boolean ``(H, W)`` mask of the pixels whose sample
    position lies outside the photo (more than half a pixel beyond its edge pixels): their
    values are mirrored, not data (the light they need was recorded outside the frame).
    """
    img = check_image(image, "image", min_size=1, max_channels=np.iinfo(np.int32).max)
    return warp_checked(img, checked_displacement(displacement, img.shape[:2]),
                        clipped=clipped, light_area=light_area, return_outside=return_outside)


def warp_checked(img: np.ndarray, displacement: tuple, *, clipped: float | None = None,
                 light_area: int | None = None, return_outside: bool = False):
    """:func:`warp_by_displacement` of a photo and field already checked (a float32 photo
    of finite values; ``displacement`` as :func:`checked_displacement` returns it for
    this photo's size), for a caller that checked them before its own work."""
    ys, xs, d = displacement
    img = np.asarray(img, np.float32)               # (no copy of a float32 photo)
    planes = img[..., None] if img.ndim == 2 else img
    H, W, C = planes.shape
    # Bilinear interpolation of the grid, rows then columns, as two-tap sums in a fixed
    # order: the same result to the last bit whatever the machine's thread count (a BLAS
    # matrix product here made the output depend on it)
    ax = _linear_taps(np.arange(W) * ((len(xs) - 1) / max(xs[-1], 1)), len(xs))
    fields = [np.ascontiguousarray(d[..., k], dtype=np.float32) for k in (0, 1)]
    out = np.empty((H, W, C), np.float32)
    outside = np.zeros((H, W), bool) if return_outside else None
    # remap takes up to 4 interleaved channels (a copy only for more than 4)
    groups = [np.ascontiguousarray(planes[..., c:c + 4]) for c in range(0, C, 4)]
    masks = nearby = None
    top = max(float(g.max()) for g in groups) if clipped is not None else 0.0
    if clipped is not None and clipped <= top <= 1.0:    # values above 1: no clip ceiling
        masks = [(g >= clipped).view(np.uint8) * np.uint8(255) for g in groups]
        if light_area is not None:
            nearby = _beside_small_blobs(masks, light_area)
    rows, cols = _WARP_TILE
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        ay = _linear_taps(np.arange(r0, r1) * ((len(ys) - 1) / max(ys[-1], 1)), len(ys))
        map_x = _interpolate_grid(fields[0], ay, ax)
        map_x += np.arange(W, dtype=np.float32)[None, :]
        map_y = _interpolate_grid(fields[1], ay, ax)
        map_y += np.arange(r0, r1, dtype=np.float32)[:, None]
        if outside is not None:
            outside[r0:r1] = ((map_x < -0.5) | (map_x > W - 0.5)
                              | (map_y < -0.5) | (map_y > H - 0.5))
        for c0 in range(0, W, cols):
            c1 = min(W, c0 + cols)
            mx, my = map_x[:, c0:c1], map_y[:, c0:c1]
            y0, y1 = _source_window(my, H)
            x0, x1 = _source_window(mx, W)
            sx, sy = mx - np.float32(x0), my - np.float32(y0)
            near = None
            if nearby is not None and nearby[y0:y1, x0:x1].any():
                near = cv2.remap(nearby[y0:y1, x0:x1], sx, sy, cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REFLECT_101) > 0
            for k, src in zip(range(0, C, 4), groups):
                res = cv2.remap(src[y0:y1, x0:x1], sx, sy, WARP_INTERPOLATION,
                                borderMode=cv2.BORDER_REFLECT_101)
                res = res.reshape(r1 - r0, c1 - c0, -1)
                if near is not None:
                    _clamp_beside_lights(res, src, near, mx, my)
                if masks is not None:
                    m = cv2.remap(masks[k // 4][y0:y1, x0:x1], sx, sy, cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REFLECT_101)
                    res[m.reshape(res.shape) >= 128] = top
                out[r0:r1, c0:c1, k:k + src.shape[2]] = res
    out = out[..., 0] if img.ndim == 2 else out
    return (out, outside) if return_outside else out


def checked_displacement(displacement, shape: tuple[int, int]) -> tuple:
    """``displacement`` as ``(ys, xs, d)`` float arrays
    (:func:`gyrodeblur.psf.displacement_field`'s), refused naming the argument where it is
    not such a grid over a photo of ``shape`` (rows, columns): evenly spaced rows and
    columns from 0 to the photo's last (within a pixel), displacements finite."""
    try:
        ys, xs, d = (np.asarray(v, np.float64) for v in displacement)
    except (TypeError, ValueError):
        raise TypeError("displacement must be (ys, xs, d), as "
                        "gyrodeblur.psf.displacement_field returns it") from None
    if (ys.ndim != 1 or xs.ndim != 1 or len(ys) < 2 or len(xs) < 2
            or d.shape != (len(ys), len(xs), 2) or not np.isfinite(d).all()
            or ys[0] != 0 or xs[0] != 0 or not _evenly_rising(ys) or not _evenly_rising(xs)):
        raise ValueError(f"displacement must be a grid from row and column 0, ys and xs "
                         f"evenly spaced and increasing, d finite of shape (len(ys), "
                         f"len(xs), 2), got ys {ys.shape}, xs {xs.shape}, d {d.shape}")
    if abs(ys[-1] - (shape[0] - 1)) > 1 or abs(xs[-1] - (shape[1] - 1)) > 1:
        raise ValueError(f"displacement's grid spans {xs[-1] + 1:g}x{ys[-1] + 1:g} px, the "
                         f"photo {shape[1]}x{shape[0]}: a field for another size of photo?")
    return ys, xs, d


def _evenly_rising(grid: np.ndarray) -> bool:
    """Whether grid points rise by one step (the warp interpolates by index)."""
    step = np.diff(grid)
    return bool(np.isfinite(grid).all() and np.all(step > 0)
                and np.allclose(step, step.mean(), rtol=1e-6, atol=0))


def _beside_small_blobs(masks: list, light_area: int) -> np.ndarray | None:
    """uint8 (H, W): 255 within :data:`_CLIPPED_REACH` px of a clipped blob (any channel,
    8-connected) of at most ``light_area`` pixels; ``None`` when there is no such blob."""
    clipped = masks[0][..., 0].copy()   # element-wise: reductions over the last axis are slow
    for m in masks:
        for c in range(m.shape[2]):
            np.maximum(clipped, m[..., c], out=clipped)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(clipped, connectivity=8)
    small = stats[:, cv2.CC_STAT_AREA] <= light_area
    small[0] = False
    if not small[1:].any():
        return None
    clipped = small[labels].view(np.uint8) * np.uint8(255)
    reach = np.ones((2 * _CLIPPED_REACH + 1,) * 2, np.uint8)
    return cv2.dilate(clipped, reach)


def _clamp_beside_lights(res: np.ndarray, src: np.ndarray, near: np.ndarray,
                         mx: np.ndarray, my: np.ndarray) -> None:
    """Clamp the marked samples of a warped tile to their four nearest pixels' range.

    Parameters
    ----------
    res : ndarray (rows, cols, c) float32
        Warped samples; changed in place where ``near`` is true.
    src : ndarray (H, W, c) float32
        The photo they were sampled from.
    near : ndarray (rows, cols) bool
        Samples to clamp (beside a light's streak).
    mx, my : ndarray (rows, cols) float32
        Sample positions in ``src`` (x, y pixels).

    Only blocks of :data:`_CLAMP_BLOCK` that hold marked samples are worked on.
    """
    bh, bw = _CLAMP_BLOCK
    for r in range(0, near.shape[0], bh):
        band = near[r:r + bh].any(axis=0)
        for c in range(0, near.shape[1], bw):
            if not band[c:c + bw].any():
                continue
            part, mark = res[r:r + bh, c:c + bw], near[r:r + bh, c:c + bw]
            lo, hi = _neighbour_range(src, mx[r:r + bh, c:c + bw], my[r:r + bh, c:c + bw])
            lo, hi = lo.reshape(part.shape), hi.reshape(part.shape)
            np.clip(part, lo, hi, out=lo)
            part[mark] = lo[mark]


def _neighbour_range(src: np.ndarray, mx: np.ndarray, my: np.ndarray):
    """Least and greatest value of the four pixels around each sample position: pixels
    ``floor(s)`` and ``floor(s) + 1`` along each axis, the range bilinear interpolation
    keeps to. Positions outside the photo are first mirrored into it (OpenCV's
    ``BORDER_REFLECT_101``, as the warp samples them: Lanczos weights are symmetric, so a
    mirrored position samples the same value).

    Returns
    -------
    lo, hi : ndarray (rows, cols[, c]) float32
    """
    H, W = src.shape[:2]
    mx, my = _reflect_101(mx, W), _reflect_101(my, H)
    y0, y1 = _source_window(my, H)
    x0, x1 = _source_window(mx, W)
    window = src[y0:y1, x0:x1]
    # Nearest-neighbour sampling of s - 1/2 reads pixel floor(s); at an integer s OpenCV
    # rounds the half to even, so it may read s - 1: harmless, Lanczos returns pixel s
    # there, which both pairs hold.
    sx, sy = mx - np.float32(x0 + 0.5), my - np.float32(y0 + 0.5)
    box = np.ones((2, 2), np.uint8)     # anchor (0, 0): pixel (i, j) and the three after it
    return tuple(cv2.remap(morph(window, box, anchor=(0, 0), borderType=cv2.BORDER_REFLECT_101),
                           sx, sy, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT_101)
                 for morph in (cv2.erode, cv2.dilate))


def _reflect_101(s: np.ndarray, n: int) -> np.ndarray:
    """Positions mirrored into ``[0, n - 1]`` about the end pixels (``-s`` and
    ``2 (n - 1) - s``; one reflection, enough for positions less than ``n - 1`` outside)."""
    last = np.float32(max(n - 1, 0))
    return last - np.abs(last - np.abs(s))


def _source_window(positions: np.ndarray, size: int) -> tuple[int, int]:
    """``[lo, hi)`` along one axis of length ``size`` that holds every sample position, its
    interpolation taps (4 px either side) and, where samples fall outside the photo, the
    pixels they mirror to: cropping the photo to it changes no sampled value."""
    lo = int(np.floor(positions.min())) - 4
    hi = int(np.ceil(positions.max())) + 5
    if lo < 0:               # mirrored about 0: -k reads +k
        hi = max(hi, 1 - lo)
    if hi > size:            # mirrored about size - 1
        lo = min(lo, 2 * size - 1 - hi)
    return max(0, lo), min(size, hi)


def _linear_taps(t: np.ndarray, n: int):
    """Linear interpolation at grid coordinates ``t`` (clamped to ``[0, n - 1]``) of a
    grid of ``n`` values: the two indices and their float32 weights."""
    t = np.clip(np.asarray(t, np.float64), 0, n - 1)
    i0 = np.minimum(np.floor(t).astype(np.intp), max(n - 2, 0))
    f = (t - i0).astype(np.float32)
    return i0, np.minimum(i0 + 1, n - 1), 1 - f, f


def _interpolate_grid(values: np.ndarray, rows, cols) -> np.ndarray:
    """Bilinear interpolation of a (ny, nx) grid at the taps of :func:`_linear_taps`
    (``rows`` down, ``cols`` across): float32, (len rows, len cols)."""
    i0, i1, w0, w1 = rows
    by_row = values[i0] * w0[:, None] + values[i1] * w1[:, None]
    j0, j1, u0, u1 = cols
    return by_row[:, j0] * u0 + by_row[:, j1] * u1
