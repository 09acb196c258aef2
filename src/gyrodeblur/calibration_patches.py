"""The photos that calibration works on, and where their textured patches are.

A photo is read through its transfer curve into linear light; patches are chosen where the
texture is rich in every direction (the smaller eigenvalue of the structure tensor) and
highlights are not clipped, spread over the frame so that the rolling shutter's rows and a
roll's field of PSFs are all seen.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .capture import Capture
from .images import PHOTO_MAX, PHOTO_MIN, check_image, split_alpha
from .tonecurve import get_transfer_curve

__all__ = ["CalibrationPhoto", "select_patch_centres", "patch_centres"]

#: a grid cell whose best window has less texture than this fraction of the photo's best
#: (smaller structure-tensor eigenvalue) gives no window: another cell's takes its place
_FLAT_FRACTION = 0.05

#: a window with more of its pixels clipped than this is taken only when the photo has too
#: few others
_SATURATED_MAX = 0.3


class CalibrationPhoto:
    """A blurred photo, its full-resolution capture (``None`` for a photo without a gyro
    log, as the blind kernel check has), and cheap access to its pixels."""

    def __init__(self, image, capture: Capture | None, transfer, index: int):
        img = check_image(image, f"photo {index + 1}", max_value=PHOTO_MAX,
                          min_value=PHOTO_MIN)
        img = split_alpha(img)[0]                       # alpha is a mask, not light
        if img.shape[2:] == (1,):
            img = img[..., 0]
        self.image = img
        self.H, self.W = img.shape[:2]
        self.cap = None if capture is None else capture.scaled_to(self.W, self.H)
        self.curve = get_transfer_curve(transfer)
        self.index = index
        self._thumbnails: dict = {}

    def gray(self, y0, y1, x0, x1) -> np.ndarray:
        """Linear-light luminance of a crop (float64)."""
        c = np.asarray(self.image[y0:y1, x0:x1], np.float32)
        lin = self.curve.decode(c)
        return (lin.mean(axis=2) if lin.ndim == 3 else lin).astype(np.float64)

    def blockiness(self, max_pixels: int = 4_000_000) -> float:
        """How strongly the photo shows the 8 px block grid of a JPEG compressed after the
        blur.

        Per axis (column differences, row differences), the mean absolute difference
        between neighbouring columns (rows) in each of the 8 phases, over their median. A
        camera's or an app's JPEG starts its grid at the photo's first column and row, so
        that phase of either axis counts on its own. Any other phase counts only where the
        grid shows on both axes, as compression leaves it (a JPEG cropped): the smaller of
        the two axes' largest phases. Returned: the larger of the two rules' figures (1.0
        where neither can be read: an axis under 129 px is not read). A grid on one axis at
        another phase is the scene's own, a JPEG's blocks photographed, moved and smeared
        along the motion by the blur (a synthetic blur of a photo that was itself a JPEG:
        1.11-1.17 on three of the gentler shake's text photos by any phase on either axis,
        1.03-1.05 by these rules). Measured on the central ``max_pixels`` of the photo,
        encoded values. On the calibration benchmark's photos (its 24 cases on the shared
        log and on a gentler shake, 48): 1.00-1.08 uncompressed; saved as JPEG, 1.01-1.40
        at quality 95, 1.04-1.62 at 90 and 1.05-1.92 at 80."""
        s = min(1.0, float(np.sqrt(max_pixels / (self.H * self.W))))
        h, w = max(16, int(self.H * s)), max(16, int(self.W * s))
        y0, x0 = (self.H - h) // 2, (self.W - w) // 2
        g = np.asarray(self.image[y0:y0 + h, x0:x0 + w], np.float32)
        g = g.mean(axis=2) if g.ndim == 3 else g
        at_origin, anywhere = [], []
        for a, start in ((g, x0), (g.T, y0)):
            d = np.abs(np.diff(a, axis=1)).mean(axis=0)
            if d.size < 128:           # under 16 samples a phase: one of 8 stands out by chance
                continue
            phases = np.array([d[k::8].mean() for k in range(8)])
            med = float(np.median(phases))
            ratios = phases / med if med > 0 else np.ones(8)
            at_origin.append(float(ratios[(7 - start) % 8]))    # between 8k - 1 and 8k
            anywhere.append(float(ratios.max()))
        both = min(anywhere) if len(anywhere) == 2 else 1.0
        return max(max(at_origin, default=1.0), both)

    def thumbnail(self, max_side: int = 512):
        """Block-averaged encoded luminance and saturated fraction, and the block size
        (made once per ``max_side``: a calibration asks for it again for its twin's
        patches, and at 12 MP each costs 0.7 s)."""
        if max_side not in self._thumbnails:
            self._thumbnails[max_side] = self._make_thumbnail(max_side)
        return self._thumbnails[max_side]

    def _make_thumbnail(self, max_side: int):
        k = max(1, int(np.ceil(max(self.H, self.W) / max_side)))
        h, w = self.H // k, self.W // k
        img = np.asarray(self.image[:h * k, :w * k], np.float32)
        if img.ndim == 3:
            sat = img.max(axis=2) > 0.98
            img = img.mean(axis=2)
        else:
            sat = img > 0.98
        th = img.reshape(h, k, w, k).mean(axis=(1, 3))
        st = sat.reshape(h, k, w, k).mean(axis=(1, 3))
        th.setflags(write=False)                 # shared by every caller
        st.setflags(write=False)
        return th, st, k


def select_patch_centres(photo: CalibrationPhoto, n: int, footprint: int) -> list[tuple[float, float]]:
    """Centres (full-res x, y) of up to ``n`` textured, unsaturated windows of side
    ``footprint`` spread over a grid of cells (best isotropic texture per cell: the
    smaller eigenvalue of the structure tensor; none from a cell whose best is nearly
    flat, under ``_FLAT_FRACTION`` of the photo's best: the next cell, or the best
    remaining anywhere, takes its place), then the best remaining anywhere. Windows more
    than ``_SATURATED_MAX`` clipped are left out while these fill the ``n``; where they
    do not (a page of text on white paper), the same pass is made again with them in,
    penalised for their clipped share, and its windows come after the first pass's."""
    th, sat, k = photo.thumbnail()
    h, w = th.shape
    win = max(3, int(round(footprint / k)))
    win = min(win, h, w)
    gy, gx = np.gradient(th.astype(np.float64))
    jxx = ndimage.uniform_filter(gx * gx, win, mode="nearest")
    jyy = ndimage.uniform_filter(gy * gy, win, mode="nearest")
    jxy = ndimage.uniform_filter(gx * gy, win, mode="nearest")
    lam_min = 0.5 * (jxx + jyy - np.sqrt((jxx - jyy) ** 2 + 4 * jxy ** 2))
    satf = ndimage.uniform_filter(sat, win, mode="nearest")
    # clipped highlights break the linear model: windows over 30 % clipped come only after
    # every other, and the rest are penalised for what they have; but a page of text on
    # white paper has little else, and a cell is better served by its best such window
    # than by none
    tiers = (np.where(satf > _SATURATED_MAX, -1.0, lam_min * (1 - 3 * satf)),
             lam_min * (1 - 0.9 * satf))
    half = win / 2
    ylo, yhi = int(np.ceil(half)) - 1, int(np.floor(h - half))
    xlo, xhi = int(np.ceil(half)) - 1, int(np.floor(w - half))
    if yhi < ylo:
        ylo = yhi = h // 2
    if xhi < xlo:
        xlo = xhi = w // 2
    aspect = photo.W / photo.H
    cols = max(1, int(round(np.sqrt(n * aspect))))
    rows = max(1, int(np.ceil(n / cols)))
    yb = np.linspace(ylo, yhi + 1, rows + 1).astype(int)
    xb = np.linspace(xlo, xhi + 1, cols + 1).astype(int)
    Y, X = np.mgrid[0:h, 0:w]
    taken: list = []
    radius = 0.7 * win
    found = []

    def pick(valid, tier, y0, y1, x0, x1, least=0.0) -> bool:
        sub = valid[y0:y1, x0:x1].copy()
        for (ty, tx) in taken:
            sub[np.hypot(Y[y0:y1, x0:x1] - ty, X[y0:y1, x0:x1] - tx) < radius] = -np.inf
        if not np.isfinite(sub).any():
            return False
        j = int(np.argmax(sub))
        v = float(sub.flat[j])
        if not (v > 0 and v >= least):
            return False
        yy, xx = np.unravel_index(j, sub.shape)
        taken.append((y0 + yy, x0 + xx))
        found.append((tier, -v, (x0 + xx + 0.5) * k - 0.5, (y0 + yy + 0.5) * k - 0.5))
        return True

    for tier, score in enumerate(tiers):
        if len(found) >= n:                      # the unclipped windows filled them all
            break
        valid = np.full(score.shape, -np.inf)
        valid[ylo:yhi + 1, xlo:xhi + 1] = score[ylo:yhi + 1, xlo:xhi + 1]
        # a cell with nothing but a nearly flat window (sky, a wall) gives its place to
        # another cell's window: its spectrum would show noise, not blur
        floor = _FLAT_FRACTION * float(valid.max()) if np.isfinite(valid).any() else 0.0
        for r in range(rows):                    # the best window of each cell ...
            for c in range(cols):
                if len(found) < n:
                    pick(valid, tier, yb[r], max(yb[r + 1], yb[r] + 1),
                         xb[c], max(xb[c + 1], xb[c] + 1), floor)
        while len(found) < n and pick(valid, tier, 0, h, 0, w):   # ... then anywhere else
            pass
    found.sort()
    return [(x, y) for _, _, x, y in found[:n]]


def patch_centres(photos, per_photo: int, footprint: int) -> list[tuple[int, float, float]]:
    """``(photo index, x, y)`` of up to ``per_photo`` windows of each photo
    (:func:`select_patch_centres`), photo by photo."""
    return [(i, x, y) for i, ph in enumerate(photos)
            for x, y in select_patch_centres(ph, per_photo, footprint)]
