"""Pictures of PSFs: one PSF enlarged, or a PSF field drawn over the frame.

The field picture is the chapter's Fig. 6.9 / 6.12c: the frame is drawn as a dark
canvas, and at every patch centre its PSF is pasted enlarged (nearest neighbour, one
common zoom so sizes compare) and contrast-stretched (each PSF to its own maximum, with a
square-root curve so faint tails show), so a person sees at a glance how the blur varies
over the photo. Pure numpy; the caller writes the array (uint8 RGB) to a file.
"""

from __future__ import annotations

import numpy as np

from .psf import PSFField

__all__ = ["psf_image", "field_image"]


def _stretch(psf: np.ndarray) -> np.ndarray:
    """``sqrt(psf / max)`` in [0, 1]; the lobes of a windowed sinc below zero draw black."""
    p = np.clip(np.asarray(psf, dtype=np.float64), 0.0, None)
    m = p.max()
    return np.sqrt(p / m) if m > 0 else p


def psf_image(psf: np.ndarray, zoom: int | None = None) -> np.ndarray:
    """One PSF as a grey uint8 picture, enlarged ``zoom`` times (default: to ~256 px),
    contrast-stretched, with the reference (centre) pixel marked by a red dot."""
    k = psf.shape[0]
    zoom = zoom or max(1, 256 // k)
    g = (255 * _stretch(psf)).astype(np.uint8)
    big = np.kron(g, np.ones((zoom, zoom), dtype=np.uint8))
    rgb = np.repeat(big[..., None], 3, axis=2)
    c = (k // 2) * zoom + zoom // 2
    rgb[c, c] = (255, 0, 0)
    return rgb


def field_image(field: PSFField, width: int, height: int, *, canvas_width: int = 1024) -> np.ndarray:
    """The PSF field drawn over a ``width`` x ``height`` frame, as uint8 RGB.

    Parameters
    ----------
    field : PSFField
        PSFs and their (x, y) positions in pixels of the frame.
    width, height : int
        The photo's size in pixels.
    canvas_width : int
        Width of the picture; the height follows the aspect ratio.
    """
    s = canvas_width / width
    ch = max(1, int(round(height * s)))
    canvas = np.full((ch, canvas_width, 3), 24, dtype=np.uint8)
    pts = field.points
    # cell size: the smallest distance between distinct neighbouring centres
    xs, ys = np.unique(np.round(pts[:, 0], 3)), np.unique(np.round(pts[:, 1], 3))
    cell_x = np.diff(xs).min() * s if xs.size > 1 else canvas_width
    cell_y = np.diff(ys).min() * s if ys.size > 1 else ch
    cell = 0.9 * min(cell_x, cell_y)
    kmax = max(p.shape[0] for p in field.psfs)
    zoom = max(1, int(cell // kmax))
    for (x, y), p in zip(pts, field.psfs):
        g = (255 * _stretch(p)).astype(np.uint8)
        big = np.kron(g, np.ones((zoom, zoom), dtype=np.uint8))
        h = big.shape[0]
        cx, cy = int(round(x * s)), int(round(y * s))
        y0, x0 = cy - h // 2, cx - h // 2
        ya, xa = max(y0, 0), max(x0, 0)
        yb, xb = min(y0 + h, ch), min(x0 + h, canvas_width)
        if ya >= yb or xa >= xb:
            continue
        sub = big[ya - y0:yb - y0, xa - x0:xb - x0]
        region = canvas[ya:yb, xa:xb]
        np.maximum(region, sub[..., None], out=region)
        # frame of the PSF box and the reference point, in colour
        region[[0, -1], :] = (70, 110, 160)
        region[:, [0, -1]] = (70, 110, 160)
        if 0 <= cy < ch and 0 <= cx < canvas_width:
            canvas[cy, cx] = (255, 60, 60)
    return canvas
