"""Point-spread functions from camera rotation (chapter eqs. 6.15-6.16, rotation only).

A scene point seen at pixel ``x0`` at the reference time (the first row's exposure
start) is seen at ``x(t) = K R(t)^T K^-1 x0`` at time ``t``, ``R(t)`` being the camera's
orientation relative to the reference (:class:`gyrodeblur.orientation.Orientation`). The
PSF at ``x0`` is that trace over the exposure window of ``x0``'s row
(``[row_start(y0), row_start(y0) + exposure_time]``), rendered with equal energy per unit
time: the trace is sampled at the midpoints of ``n`` equal time steps, ``n`` chosen so
consecutive positions are under ``max_step`` pixels apart, and each sample is splatted
bilinearly onto the pixel grid.

The returned array is odd-sized with ``x0`` at its centre sample, sums to 1, and is
indexed ``psf[dy + r, dx + r]`` for offsets ``(dx, dy)`` in pixels (x right, y down). With
a rolling shutter the trace of a lower row starts away from ``x0`` (the camera moved
before that row began), so the PSF is not centred on its mass: deconvolving with it
brings the photo back to the reference orientation, free of rolling-shutter skew.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .capture import Capture

__all__ = ["trace", "render_psf", "splat", "PSFField", "psf_field", "psf_extent"]

#: Largest allowed distance (px) between consecutive trace samples when rendering.
MAX_STEP_PX = 0.25
_MAX_SAMPLES = 1 << 20


def trace(capture: Capture, x0: float, y0: float, n: int, row: float | None = None) -> np.ndarray:
    """Positions ``(n, 2)`` (x, y in pixels) of the point seen at ``(x0, y0)`` at the
    reference time, at the midpoints of ``n`` equal steps of the exposure of row ``row``
    (default ``y0``, the point's own row)."""
    t_row = float(capture.row_start(y0 if row is None else row))
    times = t_row + capture.exposure_time * (np.arange(n) + 0.5) / n
    return _project(capture, np.asarray([x0, y0], dtype=np.float64), times)


def _project(capture: Capture, xy: np.ndarray, times: np.ndarray) -> np.ndarray:
    cam = capture.camera
    R = capture.orientation.matrices(times)                     # (n, 3, 3)
    ray = cam.K_inv @ np.array([xy[0], xy[1], 1.0])
    d = np.einsum("nji,j->ni", R, ray)                           # R^T ray
    p = d @ cam.K.T
    return p[:, :2] / p[:, 2:3]


def _adaptive_trace(capture: Capture, x0: float, y0: float, max_step: float,
                    row: float | None = None) -> np.ndarray:
    n = 64
    while True:
        pts = trace(capture, x0, y0, n, row)
        step = np.abs(np.diff(pts, axis=0)).max() if n > 1 else 0.0
        if step < max_step or n >= _MAX_SAMPLES:
            return pts
        n = min(_MAX_SAMPLES, int(np.ceil(n * step / (0.8 * max_step))))


def splat(offsets: np.ndarray, weights: np.ndarray | None = None,
          radius: int | None = None) -> np.ndarray:
    """Bilinearly splat points at pixel ``offsets`` (``(n, 2)``, x, y) into a centred array.

    Returns a ``(2r+1, 2r+1)`` float32 array normalised to sum 1, where ``r`` is
    ``radius`` or just enough to hold every point.
    """
    offsets = np.asarray(offsets, dtype=np.float64)
    w = np.full(len(offsets), 1.0) if weights is None else np.asarray(weights, np.float64)
    if radius is None:
        radius = int(np.ceil(np.abs(offsets).max())) + 1 if len(offsets) else 1
    size = 2 * radius + 1
    fx = np.floor(offsets[:, 0])
    fy = np.floor(offsets[:, 1])
    ax = offsets[:, 0] - fx
    ay = offsets[:, 1] - fy
    ix = fx.astype(np.int64) + radius
    iy = fy.astype(np.int64) + radius
    acc = np.zeros(size * size)
    for dy, wy in ((0, 1 - ay), (1, ay)):
        for dx, wx in ((0, 1 - ax), (1, ax)):
            jx, jy = ix + dx, iy + dy
            ok = (jx >= 0) & (jx < size) & (jy >= 0) & (jy < size)
            acc += np.bincount((jy * size + jx)[ok], weights=(w * wx * wy)[ok],
                               minlength=size * size)
    acc = acc.reshape(size, size)
    total = acc.sum()
    if total > 0:
        acc /= total
    return acc.astype(np.float32)


def render_psf(capture: Capture, x: float, y: float, *, max_step: float = MAX_STEP_PX,
               radius: int | None = None, row: float | None = None) -> np.ndarray:
    """The PSF at pixel ``(x, y)`` (pixels, reference-image coordinates).

    Parameters
    ----------
    capture : Capture
    x, y : float
        Pixel position; the PSF's centre sample is this point.
    max_step : float
        Largest distance (px) between consecutive trace samples (default 0.25).
    radius : int, optional
        Force the half-size; default: the smallest holding the whole trace (+1 px).
    row : float, optional
        Row whose rolling-shutter timing to use (default ``y``).

    Returns
    -------
    ndarray, float32, shape (2r+1, 2r+1), sums to 1.
    """
    pts = _adaptive_trace(capture, float(x), float(y), max_step, row)
    return splat(pts - np.array([x, y]), radius=radius)


@dataclass(frozen=True)
class PSFField:
    """PSFs at a set of points of one photo.

    Attributes
    ----------
    points : ndarray (N, 2)
        (x, y) pixel positions, row-major over the grid when made from one.
    psfs : list of ndarray
        One odd-sized PSF per point.
    grid : (rows, cols) or None
    """

    points: np.ndarray
    psfs: list
    grid: tuple | None = None

    @property
    def extents(self) -> np.ndarray:
        """Per PSF, :func:`psf_extent` (px)."""
        return np.asarray([psf_extent(p) for p in self.psfs])


def psf_extent(psf: np.ndarray, rel_threshold: float = 1e-3) -> int:
    """The larger side (px) of the bounding box of a PSF's mass (samples above
    ``rel_threshold`` times its maximum): the blur's size, whatever its offset."""
    ys, xs = np.nonzero(psf > psf.max() * rel_threshold)
    return int(max(np.ptp(xs), np.ptp(ys)) + 1)


def psf_field(capture: Capture, points, *, grid: tuple | None = None,
              max_step: float = MAX_STEP_PX) -> PSFField:
    """PSFs at ``points`` (``(N, 2)`` x, y pixels). See :func:`render_psf`."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return PSFField(pts, [render_psf(capture, x, y, max_step=max_step) for x, y in pts], grid)
