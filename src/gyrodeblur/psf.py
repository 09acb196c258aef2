"""Point-spread functions from camera rotation (chapter eqs. 6.15-6.16, rotation only).

A scene point seen at pixel ``x0`` at the reference time (the first row's exposure
start) is seen at ``x(t) = K R(t)^T K^-1 x0`` at time ``t``, ``R(t)`` being the camera's
orientation relative to the reference (:class:`gyrodeblur.orientation.Orientation`).
With a rolling shutter, what a pixel records depends on *its* row: pixel ``p`` on row
``y_p`` averages, over ``[row_start(y_p), row_start(y_p) + exposure_time]``, the light of
the scene points ``x0(t) = K R(t) K^-1 p`` that the motion brings to it. The PSF at
``x0`` is therefore rendered from the pixel ``p`` its light lands on (on average:
``p = x0 + mean_t (p - x0_p(t))``, found by a few fixed-point steps) as the offsets
``p - x0_p(t)`` over ``p``'s exposure, rendered with equal energy per unit time: the
trace is sampled at the midpoints of ``n`` equal time steps, ``n`` chosen so consecutive
positions are under ``max_step`` pixels apart, and the samples are rendered as a
band-limited image sees them (:func:`lanczos_splat`: each one a windowed sinc at its
sub-pixel position). Timing the trace by ``x0``'s own row instead (where the point was
at the reference time, not where its light is recorded) is wrong by the vertical
displacement times the readout rate: 2-3 px of misplaced PSF for a 40 px shake at the
benchmark's 30 ms readout. For a global shutter both agree to second order in the
rotation.

This is the *gather* kernel, the mix of scene points a pixel near ``x0`` records, which is
what a convolution by the PSF models; it is not ``x0``'s own forward trace ``x(t)`` moved
to start at ``x0``. The two differ where the blur is not a translation: by 1-2 px at 5
degrees of roll during the exposure, 10-16 px at 15 degrees (the arc's curvature), 3-6 px
at the frame's edge for a 0.1 rad yaw. Deconvolving with the forward trace instead lost
2.7 dB on a 10-degree roll (scratch, session 24).

The returned array is odd-sized with ``x0`` at its centre sample, sums to 1, and is
indexed ``psf[dy + r, dx + r]`` for offsets ``(dx, dy)`` in pixels (x right, y down). With
a rolling shutter the trace of a lower row starts away from ``x0`` (the camera moved
before that row began), so the PSF is not centred on its mass: deconvolving with it
brings the photo back to the reference orientation, free of rolling-shutter skew.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .arguments import check_flag, is_count, is_whole
from .capture import Capture, check_capture
from .errors import GyrodeblurWarning, InputError

__all__ = ["trace", "landing_pixel", "render_psf", "splat", "lanczos_splat", "PSFField",
           "psf_field", "psf_extent", "psf_variation", "displacement_field", "check_blur_span",
           "centred_psf"]

#: Largest allowed distance (px) between consecutive trace samples when rendering.
MAX_STEP_PX = 0.25
_MAX_SAMPLES = 1 << 20


def trace(capture: Capture, x0: float, y0: float, n: int, row: float | None = None) -> np.ndarray:
    """Positions ``(n, 2)`` (x, y in pixels) of the PSF at ``(x0, y0)``: ``(x0, y0)`` plus
    the offsets ``p - x0_p(t)`` of the pixel ``p`` its light lands on
    (:func:`landing_pixel`), at the midpoints of ``n`` equal steps of ``p``'s row's
    exposure (``row``: that row's timing instead, e.g. the middle row's for one PSF of the
    whole photo). To first order these are where the point's light goes."""
    check_capture(capture)
    n = _sample_count(n)
    x0, y0 = _pixel_position(x0, y0)
    row = _timing_row(capture, row)
    return _trace_from(capture, x0, y0, landing_pixel(capture, x0, y0, row=row), n, row)


def _timing_row(capture: Capture, row) -> float | None:
    """``row`` (a rolling-shutter timing row) as a float, ``None`` unchanged; InputError
    for one that is not a finite number or lies outside the frame's rows (a row's timing
    off the sensor would extrapolate the gyro past the exposure)."""
    if row is None:
        return None
    try:
        if isinstance(row, (str, bytes, bool, np.bool_)):
            raise TypeError
        r = float(row)
    except (TypeError, ValueError):
        raise InputError(None, f"row must be a number (a row of the frame), got {row!r}") from None
    H = capture.camera.height
    if not (np.isfinite(r) and -0.5 <= r <= H - 0.5):
        raise InputError(None, f"row must be a row of the {H}-row frame (-0.5 to {H - 0.5:g}), "
                               f"got {row!r}")
    return r


def _sample_count(n) -> int:
    """``n`` as a whole number of samples >= 1, or ValueError."""
    if not is_count(n):
        raise ValueError(f"n must be a whole number of samples >= 1, got {n!r}")
    return int(n)


def _pixel_position(x, y) -> tuple[float, float]:
    """``(x, y)`` as floats, or InputError naming what is not a pixel position."""
    try:
        if isinstance(x, (str, bytes)) or isinstance(y, (str, bytes)):
            raise TypeError
        fx, fy = float(x), float(y)
    except (TypeError, ValueError):
        raise InputError(None, f"a pixel position must be two numbers (x, y), got "
                               f"({x!r}, {y!r})") from None
    if not (np.isfinite(fx) and np.isfinite(fy)):
        raise InputError(None, f"a pixel position must be finite, got ({x!r}, {y!r})")
    return fx, fy


def _trace_from(capture: Capture, x0: float, y0: float, p: np.ndarray, n: int,
                row: float | None) -> np.ndarray:
    """:func:`trace` with the landing pixel ``p`` already found."""
    return np.array([x0, y0], np.float64) + _gather_offsets(capture, p[0], p[1], n, row)


def _gather_offsets(capture: Capture, px, py, n: int, row=None) -> np.ndarray:
    """``(..., n, 2)``: ``p - x0_p(t)`` for pixels ``p = (px, py)`` (arrays of one shape),
    ``x0_p(t) = K R(t) K^-1 p`` the reference-time position of the scene point that ``p``
    records at ``t``, over ``n`` equal steps of ``p``'s row's exposure (or ``row``'s)."""
    cam = capture.camera
    px = np.asarray(px, np.float64)
    py = np.asarray(py, np.float64)
    timing = py if row is None else np.full(py.shape, float(row))
    times = (capture.row_start(timing)[..., None]
             + capture.exposure_time * (np.arange(n) + 0.5) / n)            # (..., n)
    return offsets_under_rotation(cam, capture.orientation.matrices(times), px, py)


def offsets_under_rotation(camera, R: np.ndarray, px, py) -> np.ndarray:
    """``(..., n, 2)``: ``p - K R K^-1 p`` (pixels) for pixels ``p = (px, py)`` (arrays of
    one shape ``(...)``) and camera-frame rotations ``R`` ``(..., n, 3, 3)``: with ``R`` the
    orientation at ``n`` times relative to the reference, how far the scene point each
    pixel records then lay from it at the reference time (the gather form)."""
    px = np.asarray(px, np.float64)
    py = np.asarray(py, np.float64)
    src = camera.project(np.einsum("...nij,...j->...ni", R, camera.rays(px, py)))  # R ray
    return np.stack([px, py], axis=-1)[..., None, :] - src


#: Fixed-point steps :func:`landing_pixel` takes at most, and the change (px) at which it
#: stops. Each step shrinks the error by the rolling shutter's skew, the change of the
#: mean displacement per pixel (about rate x fx x readout / height: 0.06 px per px at
#: 1.7 rad/s, fx 1000 px, a 25 ms readout and 680 rows), so for hand shake two or three
#: steps reach the tolerance; a fast tilt (skew 0.5 and more) needs many more, or diverges
#: (content moving against the sweep faster than it), and the points still moving after
#: these steps are solved by Newton's method (:func:`_landing_by_newton`).
_LANDING_STEPS = 8
_LANDING_TOL = 1e-3
#: Newton steps at most, and the finite-difference step (px) of their Jacobian.
_NEWTON_STEPS = 8
_NEWTON_DELTA = 1e-2


def landing_pixel(capture: Capture, x0, y0, *, row=None, n: int = 32) -> np.ndarray:
    """Where, on average, the light of the point seen at ``(x0, y0)`` at the reference
    time is recorded: the pixel ``p`` with ``p - mean_t (p - x0_p(t)) = (x0, y0)``.

    ``x0``, ``y0`` are pixel positions (scalars or arrays of one shape); ``n`` time steps
    of ``p``'s row's exposure (or ``row``'s) form the mean. Returns ``(..., 2)`` (x, y).

    A fixed-point iteration solves this in two or three steps for hand shake; where it is
    slow or does not settle (a fast tilt: content crossing rows at half the shutter's
    sweep or more), Newton's method finishes it. The solution is unique while the map
    ``p -> p - mean_t (p - x0_p(t))`` does not fold (content moving along the sweep more
    slowly than the shutter, or against it at any speed). Where it folds (a telephoto lens
    tilting fast with a short exposure), the point falls back to its own position: its PSF
    is then timed by its own row, as a global shutter would have it. So does a point whose
    Newton root lies outside the frame (such a root is not trusted). A landing pixel the
    fixed-point iteration settles on is kept even a little past the frame's edge (its
    row's time extrapolated beyond the readout), so that the PSFs stay continuous up to
    the border: that light is not recorded, but the pixels beside it are.
    """
    check_capture(capture)
    x0 = np.asarray(x0, np.float64)
    y0 = np.asarray(y0, np.float64)
    start = np.stack([x0, y0], axis=-1)
    p = start.copy()
    for _ in range(_LANDING_STEPS):
        new = start + _gather_offsets(capture, p[..., 0], p[..., 1], n, row).mean(axis=-2)
        step = np.abs(new - p)
        p = new
        if not np.nanmax(step, initial=0.0) >= _LANDING_TOL:     # all converged, or all NaN
            break
    slow = ~(step.max(axis=-1) < _LANDING_TOL)                    # NaN too
    if np.any(slow):
        p[slow] = _landing_by_newton(capture, start[slow], n, row)
    return p


def _landing_by_newton(capture: Capture, start: np.ndarray, n: int, row) -> np.ndarray:
    """Finish :func:`landing_pixel` for the points ``start`` ``(m, 2)``: Newton steps from
    them on ``F(p) = start + g(p) - p`` (``g`` the mean gather offset), the 2 x 2 Jacobian
    by finite differences. A root is kept where it converges to :data:`_LANDING_TOL`
    inside the frame and the map does not fold there (every eigenvalue of ``dg/dp`` of
    real part under 1, i.e. ``p - g(p)`` keeps its orientation); else ``start``."""
    def residual(q):
        return start + _gather_offsets(capture, q[:, 0], q[:, 1], n, row).mean(axis=-2) - q

    eye = np.eye(2)
    p = start.copy()
    f = residual(p)
    for _ in range(_NEWTON_STEPS):
        jac = np.stack([(residual(p + _NEWTON_DELTA * e) - f) / _NEWTON_DELTA for e in eye],
                       axis=-1)                                   # dF/dp, (m, 2, 2)
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        ok = np.abs(det) > 1e-9
        inv = np.stack([np.stack([jac[:, 1, 1], -jac[:, 0, 1]], -1),
                        np.stack([-jac[:, 1, 0], jac[:, 0, 0]], -1)], -2)
        step = np.einsum("mij,mj->mi", inv, f) / np.where(ok, det, 1.0)[:, None]
        p = np.where(ok[:, None], p - step, p)
        f = residual(p)
        if not np.nanmax(np.abs(f), initial=0.0) >= _LANDING_TOL:
            break
    finite = np.isfinite(jac).all(axis=(1, 2))
    fold = np.full(len(p), np.inf)                                # dg/dp = dF/dp + I
    fold[finite] = np.linalg.eigvals(jac[finite] + eye).real.max(axis=-1)
    cam = capture.camera
    inside = ((p[:, 0] >= -0.5) & (p[:, 0] <= cam.width - 0.5)
              & (p[:, 1] >= -0.5) & (p[:, 1] <= cam.height - 0.5))
    kept = (np.abs(f).max(axis=-1) < _LANDING_TOL) & (fold < 1.0) & inside  # NaN: not kept
    return np.where(kept[:, None], p, start)


def check_blur_span(capture: Capture, span: float, where: str, *, what: str = "blur") -> None:
    """Refuse a blur longer than the frame: ``span`` (px) is how far a point moves during
    its exposure (at ``where``, for the message), or, ``what`` saying so, the side of a
    PSF centred on its point. Such a blur comes from wrong capture values (a focal length
    in mm rather than pixels, deg/s read as rad/s, an exposure in ms read as s), and
    rendering or simulating it would exhaust memory or time."""
    cam = capture.camera
    limit = max(cam.width, cam.height)
    if not span <= limit:                     # NaN too
        raise InputError(capture.source,
                         f"the {what} {where} would span {span:.0f} px, more than the "
                         f"{cam.width}x{cam.height} frame: check the focal length (fx, fy, "
                         "pixels), the gyro's rate unit and the exposure and readout times")


def centred_psf(reach: float, on: str = "its point") -> str:
    """:func:`check_blur_span`'s ``what`` for a PSF centred ``on`` its point (or another
    centre), whose side is twice the ``reach`` (px) of its blur from that centre."""
    return f"PSF centred on {on} (its blur reaching {reach:.0f} px from it)"


def _adaptive_trace(capture: Capture, x0: float, y0: float, max_step: float,
                    row: float | None = None) -> np.ndarray:
    if not (np.isfinite(x0) and np.isfinite(y0)):
        raise InputError(None, f"pixel position ({x0}, {y0}) is not finite")
    n = 64
    p = landing_pixel(capture, x0, y0, row=row)       # once: it does not depend on n
    pts = _trace_from(capture, x0, y0, p, n, row)
    check_blur_span(capture, float(np.ptp(pts, axis=0).max()), f"at ({x0:.0f}, {y0:.0f})")
    while True:
        step = np.abs(np.diff(pts, axis=0)).max() if n > 1 else 0.0
        if step < max_step or n >= _MAX_SAMPLES:
            return pts
        n = min(_MAX_SAMPLES, int(np.ceil(n * step / (0.8 * max_step))))
        pts = _trace_from(capture, x0, y0, p, n, row)


def splat(offsets: np.ndarray, weights: np.ndarray | None = None,
          radius: int | None = None) -> np.ndarray:
    """Bilinearly splat points at pixel ``offsets`` (``(n, 2)``, x, y) into a centred array.

    Returns a ``(2r+1, 2r+1)`` float32 array normalised to sum 1, where ``r`` is
    ``radius`` or just enough to hold every point.
    """
    return _separable_splat(offsets, weights, radius, np.arange(0, 2), _triangle)


#: Lobes of the windowed sinc :func:`lanczos_splat` renders each point with (Lanczos-a):
#: 2a taps per axis, reaching a px beyond the point.
LANCZOS_A = 3
#: Points per block of :func:`_separable_splat` (bounds its memory: up to 36 taps each).
_SPLAT_BLOCK = 1 << 16


def lanczos_splat(offsets: np.ndarray, weights: np.ndarray | None = None,
                  radius: int | None = None) -> np.ndarray:
    """Points at pixel ``offsets`` (``(n, 2)``, x, y) as a band-limited image sees them.

    A photo's pixels sample a scene that the lens and the pixels' area have low-passed,
    so a shift by a fraction of a pixel moves every frequency's phase and damps almost
    none: the discrete PSF of a point off the grid is a sinc centred on it, not the
    bilinear splat's two taps per axis (:func:`splat`), which low-passes by an amount
    that changes with the sub-pixel position (fully at the Nyquist frequency half-way
    between pixels). Each point here is a Lanczos-3 windowed sinc
    (``sinc(d) sinc(d / 3)`` for ``|d| < 3``, separable, its taps normalised to sum 1),
    which keeps the sinc's passband and first side lobes and stays compact. A point on the
    grid gives a single sample, as with :func:`splat`; one off it rings a little below
    zero beside it.

    Measured with the default deblur (BENCHMARKS.md, section 2): on blur synthesised at
    twice the resolution and area-averaged (a camera integrating over its pixels; 12
    photos, scratch), 27.08 dB against 26.14 with bilinear PSFs, 12 of 12 photos better;
    on the benchmark's 36 cases synthesised by cubic spline, 27.05 against 26.09 dB; on
    the same cases synthesised bilinearly (which shares the bilinear splat's low-pass),
    26.26 against 26.61 dB. A full sinc did as well on the first and worse on the last;
    Lanczos-2 and cubic convolution kept less of the gain.

    Returns a ``(2r+1, 2r+1)`` float32 array normalised to sum 1, where ``r`` is
    ``radius`` or the points' reach plus :data:`LANCZOS_A` px. Taps outside it are
    dropped.
    """
    a = LANCZOS_A
    return _separable_splat(offsets, weights, radius, np.arange(1 - a, a + 1),
                            lambda d: _lanczos(d, a))


def _separable_splat(offsets, weights, radius: int | None, taps: np.ndarray,
                     kernel) -> np.ndarray:
    """Spread each point over the pixels ``floor(o) + taps`` along each axis with weights
    ``kernel(o - pixel)`` (normalised to sum 1 per point and axis), into a centred
    ``(2r+1, 2r+1)`` float32 array normalised to sum 1; ``r`` is ``radius`` or the
    points' reach plus the last tap. Taps outside the array are dropped."""
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.ndim == 0 or offsets.shape[-1] != 2 or offsets.size == 0:
        raise ValueError(f"offsets must be (n, 2) pixel offsets (x, y), n >= 1, got shape "
                         f"{offsets.shape}")
    offsets = offsets.reshape(-1, 2)
    w = (np.full(len(offsets), 1.0) if weights is None
         else np.asarray(weights, np.float64).reshape(-1))
    if w.shape != (len(offsets),):
        raise ValueError(f"weights must be one per point, shape ({len(offsets)},), got "
                         f"{w.shape}")
    if not (np.all(np.isfinite(offsets)) and np.all(np.isfinite(w)) and w.sum() > 0):
        raise ValueError("offsets and weights must be finite, the weights' sum positive")
    reach = int(taps[-1])
    if radius is None:
        radius = int(np.ceil(np.abs(offsets).max())) + reach if len(offsets) else reach
    size = 2 * radius + 1
    taps = taps[:, None]                                                # (t, 1)
    acc = np.zeros(size * size)
    for k in range(0, len(offsets), _SPLAT_BLOCK):
        o, wk = offsets[k:k + _SPLAT_BLOCK], w[k:k + _SPLAT_BLOCK]
        base = np.floor(o)
        ix = base[:, 0].astype(np.int64) + taps + radius                 # (t, m)
        iy = base[:, 1].astype(np.int64) + taps + radius
        kx = kernel(o[:, 0] - (base[:, 0] + taps))
        ky = kernel(o[:, 1] - (base[:, 1] + taps))
        kx /= kx.sum(axis=0)
        ky /= ky.sum(axis=0)
        ok = ((ix >= 0) & (ix < size))[None, :, :] & ((iy >= 0) & (iy < size))[:, None, :]
        index = iy[:, None, :] * size + ix[None, :, :]                  # (t, t, m)
        value = ky[:, None, :] * kx[None, :, :] * wk
        acc += np.bincount(index[ok], weights=value[ok], minlength=size * size)
    psf = acc.reshape(size, size)
    total = psf.sum()
    if total > 0:
        psf /= total
    return psf.astype(np.float32)


def _triangle(d: np.ndarray) -> np.ndarray:
    """The bilinear (tent) kernel ``max(0, 1 - |d|)``."""
    return np.maximum(0.0, 1.0 - np.abs(d))


def _lanczos(d: np.ndarray, a: int) -> np.ndarray:
    """The Lanczos-``a`` kernel ``sinc(d) sinc(d / a)`` (0 for ``|d| >= a``, and exactly 0
    at whole pixels, where ``np.sinc`` leaves ~1e-17)."""
    k = np.where(np.abs(d) < a, np.sinc(d) * np.sinc(d / a), 0.0)
    k[np.abs(k) < 1e-12] = 0.0
    return k


def render_psf(capture: Capture, x: float, y: float, *, max_step: float = MAX_STEP_PX,
               radius: int | None = None, row: float | None = None,
               centred: bool = False) -> np.ndarray:
    """The PSF at pixel ``(x, y)`` (pixels, reference-image coordinates).

    Parameters
    ----------
    capture : Capture
    x, y : float
        Pixel position; the PSF's centre sample is this point.
    max_step : float
        Largest distance (px) between consecutive trace samples (default 0.25).
    radius : int, optional
        Force the half-size; default: the smallest holding the whole trace and its
        samples' sinc lobes (+ :data:`LANCZOS_A` px). A trace that reaches beyond it is
        cut there and what is left renormalised, with a warning: that PSF is no longer
        the blur; one of which it holds less than half is refused.
    row : float, optional
        Row whose rolling-shutter timing to use (default: the row the light lands on,
        :func:`landing_pixel`).
    centred : bool
        Subtract the trace's mean displacement, so the PSF's centre of mass is its centre
        sample (its shape only; see :func:`displacement_field`).

    Returns
    -------
    ndarray, float32, shape (2r+1, 2r+1), sums to 1.
        Each trace sample is spread by a windowed sinc (Lanczos), the band-limited blur a
        pixel grid holds, so the PSF rings below zero beside a thin trace (its negative
        samples summed to -0.15 to -0.41 on the benchmark's 36 centre PSFs). A
        method that needs a kernel without negative values (Richardson-Lucy) wants it
        clipped at 0 and normalised again: ``k = np.clip(psf, 0, None); k /= k.sum()``.

    Raises
    ------
    InputError
        A PSF (trace, or its distance from ``(x, y)``) larger than the frame, a point more
        than a frame outside it, a ``max_step`` that is not a positive number, a
        ``radius`` that is not a whole number from 0 to the frame's size, or one that
        holds less than half the trace.
    """
    if not (isinstance(max_step, (int, float, np.floating, np.integer)) and max_step > 0
            and np.isfinite(max_step)):
        raise InputError(None, f"max_step must be a positive number of pixels, got {max_step!r}")
    check_flag(centred, "centred")
    cam = check_capture(capture).camera
    if radius is not None and not (is_whole(radius)
                                   and 0 <= radius <= max(cam.width, cam.height)):
        raise InputError(None, f"radius must be a whole number of pixels from 0 to "
                               f"{max(cam.width, cam.height)}, got {radius!r}")
    x, y = _pixel_position(x, y)
    if not (-cam.width <= x <= 2 * cam.width and -cam.height <= y <= 2 * cam.height):
        raise InputError(None, f"pixel position ({x:g}, {y:g}) lies more than a frame outside "
                               f"the {cam.width}x{cam.height} frame")
    row = _timing_row(capture, row)
    pts = _adaptive_trace(capture, x, y, max_step, row)
    offsets = pts - np.array([x, y])
    if centred:
        offsets -= offsets.mean(axis=0)
    reach = float(np.abs(offsets).max())
    if radius is None:     # a point far off the frame sees its trace far from itself
        check_blur_span(capture, 2 * reach, f"at ({x:.0f}, {y:.0f})",
                        what=centred_psf(reach, "its trace's mean" if centred else "its point"))
    elif reach > radius + 0.5:
        kept = float(np.mean(np.abs(offsets).max(axis=1) <= radius + 0.5))
        where = (f"the blur at ({x:.0f}, {y:.0f}) reaches {reach:.1f} px from it, beyond "
                 f"radius={radius}, which holds {100 * kept:.0f} % of its trace")
        if kept < 0.5:     # what is left is not the blur, and may not even sum to 1
            raise InputError(None, f"{where}: leave radius out for the whole trace")
        warnings.warn(f"{where}: the PSF is cut there and renormalised, and is no longer the "
                      "blur (leave radius out for the whole trace)",
                      GyrodeblurWarning, stacklevel=2)
    return lanczos_splat(offsets, radius=radius)


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
    displacement : (ys, xs, d) or None
        When the PSFs are centred (shape only), the mean-displacement field they were
        centred by (:func:`displacement_field`).
    """

    points: np.ndarray
    psfs: list
    grid: tuple | None = None
    displacement: tuple | None = None

    @property
    def extents(self) -> np.ndarray:
        """Per PSF, :func:`psf_extent` (px)."""
        return np.asarray([psf_extent(p) for p in self.psfs])


def psf_extent(psf: np.ndarray, rel_threshold: float = 1e-3) -> int:
    """The larger side (px) of the bounding box of a PSF's mass (samples above
    ``rel_threshold`` times its maximum): the blur's size, whatever its offset."""
    psf = np.asarray(psf)
    if psf.ndim != 2 or psf.size == 0 or not np.isfinite(psf).all() or psf.max() <= 0:
        raise ValueError(f"a PSF must be a finite 2-D array with a positive sample, got "
                         f"shape {psf.shape}")
    ys, xs = np.nonzero(psf > psf.max() * rel_threshold)
    return int(max(np.ptp(xs), np.ptp(ys)) + 1)


def psf_field(capture: Capture, points, *, grid: tuple | None = None,
              max_step: float = MAX_STEP_PX) -> PSFField:
    """PSFs at ``points`` (``(N, 2)`` x, y pixels). See :func:`render_psf`. ``grid``,
    when the points are a grid's in row-major order, is its ``(rows, columns)``: their
    product must be ``N``."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(None, f"points must be (N, 2) pixel positions (x, y), got "
                               f"{points!r}") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(None, f"points must be (N, 2) pixel positions (x, y), got shape "
                               f"{pts.shape}")
    if grid is not None:
        try:
            rows, cols = grid
        except (TypeError, ValueError):
            rows = cols = None
        if not (is_whole(rows) and is_whole(cols) and rows >= 1 and cols >= 1
                and rows * cols == len(pts)):
            raise InputError(None, f"grid must be (rows, columns) of the {len(pts)} points, "
                                   f"got {grid!r}")
        grid = (int(rows), int(cols))
    return PSFField(pts, [render_psf(capture, x, y, max_step=max_step) for x, y in pts], grid)


def psf_variation(capture: Capture, *, probes: tuple[int, int] = (7, 9), n: int = 32,
                  centred: bool = False, per_axis: bool = False):
    """How fast the PSF changes across the frame: pixels of trace difference per pixel.

    The traces (:func:`trace`) of a ``probes`` grid of points are sampled at ``n`` equal
    steps of the exposures of the rows their light lands on; for every pair of
    neighbouring probes, the largest difference of their offsets from the probe at equal
    steps, divided by their distance, is a
    finite-difference estimate of the displacement field's spatial derivative (roll,
    perspective and the rolling shutter's row timing all contribute). The maximum over
    pairs is returned: a patch of ``w`` pixels sees its PSF change by about
    ``w * psf_variation`` pixels from one side to the other. ``centred=True`` measures
    the change of the PSFs' shape only (each trace minus its mean displacement), what is
    left once the photo is warped by :func:`displacement_field`. ``per_axis=True`` returns
    the maxima over vertical and over horizontal pairs apart, ``(down, across)``: a rolling
    shutter changes the PSF from row to row faster than from column to column.
    """
    if (len(probes) != 2 or not all(isinstance(p, (int, np.integer)) and not isinstance(p, bool)
                                    and p >= 2 for p in probes)):
        raise ValueError(f"probes must be two whole numbers >= 2 (rows, columns), got {probes!r}")
    n = _sample_count(n)
    cam = check_capture(capture).camera
    ys = np.linspace(0, cam.height - 1, probes[0])
    xs = np.linspace(0, cam.width - 1, probes[1])
    d = np.empty((probes[0], probes[1], n, 2))
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            d[i, j] = trace(capture, x, y, n) - (x, y)
            if centred:
                d[i, j] -= d[i, j].mean(axis=0)
    dx = np.abs(np.diff(d, axis=1)).max(axis=(2, 3)) / (xs[1] - xs[0])
    dy = np.abs(np.diff(d, axis=0)).max(axis=(2, 3)) / (ys[1] - ys[0])
    if per_axis:
        return float(dy.max()), float(dx.max())
    return float(max(dx.max(), dy.max()))


def displacement_field(capture: Capture, *, step: float = 48.0, n: int = 32):
    """Mean displacement (px) of each pixel's PSF: where, on average over the exposure,
    the light of the reference-time pixel is recorded, relative to that pixel
    (:func:`landing_pixel`; warping the photo by it,
    :func:`gyrodeblur.warp.warp_by_displacement`, leaves each pixel's PSF centred on it).

    Evaluated on a regular grid (about ``step`` px apart, corners included) with ``n``
    time steps per row's exposure, vectorised; the field is smooth, so bilinear
    interpolation between grid points is accurate.

    Returns
    -------
    ys, xs : ndarray
        Grid row and column coordinates (pixels).
    d : ndarray, shape (len(ys), len(xs), 2)
        Mean displacement (dx, dy) in pixels at each grid point.
    """
    cam = check_capture(capture).camera
    if isinstance(step, bool) or not isinstance(step, (int, float, np.number)) \
            or not (np.isfinite(step) and step >= 1) or isinstance(n, bool) or not (
            isinstance(n, (int, np.integer)) and n >= 1):
        raise InputError(None, f"displacement_field needs step >= 1 px and n >= 1 time steps, "
                               f"got step={step!r}, n={n!r}")
    ny = max(2, int(np.ceil((cam.height - 1) / step)) + 1)
    nx = max(2, int(np.ceil((cam.width - 1) / step)) + 1)
    ys = np.linspace(0, cam.height - 1, ny)
    xs = np.linspace(0, cam.width - 1, nx)
    X, Y = np.meshgrid(xs, ys)                                                # (ny, nx)
    return ys, xs, landing_pixel(capture, X, Y, n=n) - np.stack([X, Y], axis=-1)
