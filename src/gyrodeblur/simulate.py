"""Physically exact blur synthesis, independent of the PSF renderer.

For many instants of the exposure the sharp image (seen at the reference orientation)
is warped by the homography ``K R(t) K^-1`` that the camera's rotation implies, each row
at its own rolling-shutter time, and the warps are averaged: a blurred pixel ``x`` on
row ``y`` is ``mean_t u(K R(t) K^-1 x)`` over ``t`` in row ``y``'s exposure. Nothing here
uses a PSF, so comparing it with PSF convolution checks both.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .bands import for_row_bands
from .capture import Capture, check_capture
from .gyrolog import warn_of_steps
from .arguments import check_flag, check_real, check_seed, is_count, is_whole
from .images import PHOTO_MAX, PHOTO_MIN, check_image, check_values, join_alpha, split_alpha
from .psf import check_blur_span
from .tonecurve import LINEAR, TransferCurve, get_transfer_curve

__all__ = ["simulate_blur", "add_noise", "quantize_8bit", "warp_samples"]

#: Largest motion (px) of any pixel between two consecutive time samples.
MAX_STEP_PX = 0.5


#: Mirrored pixels around the spline coefficients: enough for every tap of a coordinate
#: folded into the frame (cubic: ``floor(x) - 1 .. floor(x) + 2`` for ``-0.5 <= x <= n - 0.5``).
_PAD = 2

#: Pixels warped per chunk of rows (keeps the sampler's temporaries in cache).
_CHUNK_PX = 65536

#: The speed probe of :func:`warp_samples`: at least this many time steps per exposure,
#: and two per gyro sample interval where the log is denser, up to the most.
_PROBE_STEPS, _MAX_PROBE_STEPS = 64, 1024
#: Its rows: at least 5, and enough that their exposures tile the readout, up to the most.
_PROBE_ROWS, _MAX_PROBE_ROWS = 5, 33


def _spline_coefficients(planes: np.ndarray, order: int) -> np.ndarray:
    """``(C, H + 2 _PAD, W + 2 _PAD)`` float32: the spline coefficients of the channels of
    ``planes`` (``(H, W, C)``; for order 1 the pixels themselves), with :data:`_PAD`
    mirrored pixels around them (half-sample symmetric, as ``mode="reflect"``)."""
    H, W, C = planes.shape
    padded = np.empty((C, H + 2 * _PAD, W + 2 * _PAD), np.float32)
    for c in range(C):
        p = planes[..., c]
        if order > 1:
            p = ndimage.spline_filter(p, order, output=np.float32, mode="reflect")
        padded[c] = np.pad(p, _PAD, mode="symmetric")
    return padded


def _spline_taps(x: np.ndarray, n: int, order: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Taps of spline ``order`` (1 or 3) at positions ``x`` on an axis of ``n`` pixels.

    ``x`` (float64) is first folded into ``[-0.5, n - 0.5]`` by the half-sample symmetric
    mirror (``map_coordinates``' ``mode="reflect"``; positions already inside are left as
    they are, to the bit). Returns the index, in an array padded by :data:`_PAD` mirrored
    pixels, of the first of the ``order + 1`` taps (intp), and their float32 weights.
    """
    lo, hi = x.min(), x.max()
    if not np.isfinite(lo + hi):              # map_coordinates gave 0 there, silently
        raise ValueError("the rotation carries pixels to infinity (a view turned by 90 "
                         "degrees or more from the reference orientation)")
    if lo < -0.5 or hi > n - 0.5:
        if lo < -n - 0.5 or hi > 2 * n - 0.5:          # more than a frame outside
            far = (x < -n - 0.5) | (x > 2 * n - 0.5)
            x = np.where(far, np.mod(x + 0.5, 2 * n) - 0.5, x)
        x = np.where(x < -0.5, -1 - x, x)
        x = np.where(x > n - 0.5, 2 * n - 1 - x, x)
    i = np.floor(x)
    f = (x - i).astype(np.float32)            # fraction in float64 first: exact at any x
    first = i.astype(np.intp) + (_PAD - order // 2)
    if order == 1:
        return first, [1 - f, f]
    f2 = f * f
    f3 = f2 * f
    g = 1 - f
    w0 = g * g * g * np.float32(1 / 6)       # cubic B-spline: (1-f)^3/6, (3f^3-6f^2+4)/6,
    w1 = f3 * np.float32(0.5) - f2 + np.float32(2 / 3)      # (-3f^3+3f^2+3f+1)/6, f^3/6
    w3 = f3 * np.float32(1 / 6)
    return first, [w0, w1, 1 - w0 - w1 - w3, w3]


def _add_spline_samples(padded: np.ndarray, x: np.ndarray, y: np.ndarray, order: int,
                        out: np.ndarray) -> None:
    """``out[c] += s_c(x, y)``: the spline of ``order`` with coefficients ``padded[c]``
    (from :func:`_spline_coefficients`) at positions ``x``, ``y`` (float64, any shape;
    ``out`` is ``(C,) + x.shape``), mirrored outside the frame: what
    ``scipy.ndimage.map_coordinates(..., mode="reflect", prefilter=False)`` gives, to
    float32 rounding, but with the taps and weights computed once for all channels."""
    C, Hp, Wp = padded.shape
    bx, wx = _spline_taps(x, Wp - 2 * _PAD, order)
    by, wy = _spline_taps(y, Hp - 2 * _PAD, order)
    first = by * Wp + bx                      # flat index of the first tap
    k = order + 1
    row = np.empty(x.shape, np.float32)
    tmp = np.empty(x.shape, np.float32)
    for c in range(C):
        flat = padded[c].ravel()
        for dy in range(k):
            for dx in range(k):
                g = np.take(flat[dy * Wp + dx:], first)    # tap (dy, dx)
                if dx == 0:
                    np.multiply(g, wx[0], out=row)
                else:
                    row += np.multiply(g, wx[dx], out=tmp)
            row *= wy[dy]
            out[c] += row


def _row_homographies(capture: Capture, s: float, r0: int = 0,
                      r1: int | None = None) -> np.ndarray:
    """``(r1 - r0, 3, 3)``: ``K R(t_y) K^-1`` for rows ``y`` in ``r0:r1`` (default all),
    with ``t_y = row_start(y) + s * exposure_time``."""
    cam = capture.camera
    rows = np.arange(r0, cam.height if r1 is None else r1)
    R = capture.orientation.matrices(capture.row_start(rows) + s * capture.exposure_time)
    return cam.K @ R @ cam.K_inv


def warp_samples(capture: Capture, max_step: float = MAX_STEP_PX) -> int:
    """Number of time samples so that the fastest of a grid of probe pixels moves
    less than ``max_step`` pixels between consecutive samples.

    The probe's 5 columns and its rows span the frame. Its rows are at least 5, and
    enough that their exposures tile the readout: under a short exposure and a long
    readout each row sees its own stretch of the motion, and a turn that falls between
    the probe rows' exposures would go unseen. Its time steps are at least 64 per
    exposure and two per gyro sample interval of a denser log (a jolt shorter than a
    64th of the exposure)."""
    cam = capture.camera
    T = capture.exposure_time
    n0 = int(np.clip(np.ceil(2 * T / capture.log.sample_interval), _PROBE_STEPS,
                     _MAX_PROBE_STEPS))
    n_rows = int(np.clip(np.ceil(capture.readout_time / T) + 1, _PROBE_ROWS, _MAX_PROBE_ROWS))
    xs = np.linspace(0, cam.width - 1, 5)
    ys = np.linspace(0, cam.height - 1, n_rows)
    X, Y = np.meshgrid(xs, ys)
    pts = np.stack([X.ravel(), Y.ravel(), np.ones(X.size)])
    s = (np.arange(n0 + 1)) / n0
    times = capture.row_start(Y.ravel())[None, :] + s[:, None] * T
    R = capture.orientation.matrices(times)                          # (n0+1, P, 3, 3)
    H = cam.K @ R @ cam.K_inv
    p = np.einsum("spij,jp->spi", H, pts)
    xy = p[..., :2] / p[..., 2:3]
    check_blur_span(capture, float(np.ptp(xy, axis=0).max()), "across the frame")
    step = np.abs(np.diff(xy, axis=0)).max()
    return max(8, int(np.ceil(n0 * step / (0.8 * max_step))))


def simulate_blur(sharp: np.ndarray, capture: Capture, *, snr_db: float | None = None,
                  seed: int | None = None, quantize: bool = False,
                  n_samples: int | None = None, order: int = 3,
                  transfer: str | TransferCurve = "srgb",
                  full_well: float | None = None) -> np.ndarray:
    """Blur ``sharp`` by the camera rotation recorded in ``capture``.

    Parameters
    ----------
    sharp : ndarray (H, W) or (H, W, C)
        The scene as seen at the reference orientation, float in [0, 1], an **sRGB**
        photo by default (see ``transfer``; in linear light, values above 1 are allowed,
        e.g. for light sources that saturate only after blurring). Its size may differ
        from ``capture.camera``'s by a common scale (the intrinsics are rescaled, as
        :func:`gyrodeblur.deblur.deblur` does). A last channel of 2 or 4 is alpha,
        a mask: returned untouched (not blurred, noised or quantised).
    capture : Capture
    transfer : {"linear", "srgb"} or TransferCurve
        How ``sharp``'s values encode light. Light blurs linearly, so an encoded photo is
        decoded, blurred, noised and encoded again. ``"srgb"`` (default, as
        :func:`gyrodeblur.deblur.deblur`'s, so that the default deblur undoes the default
        blur): ``sharp`` is an sRGB photo. ``"linear"``: ``sharp`` is light itself (a
        render, a raw image, a test pattern). Blurring encoded values as if they were
        light models a camera that does not exist: an sRGB photo so blurred and then
        deblurred as sRGB came out 9-13 dB below the matched pair (session 49, 384 px,
        30 ms). With a curve other than linear, light below
        black (the cubic spline's undershoot beside a hard edge, noise near black) is
        clipped to 0 before it is encoded, as in a camera's output: the curves' steep
        foot (sRGB's 12.92) would turn a little negative light into values far below
        black, which ``deblur`` refuses. Linear results are left unclipped (a linear
        operator).
    snr_db : float, optional
        Signal-to-noise ratio of the result (dB): white Gaussian noise is added to the
        blurred light (as a sensor's read noise; there is no shot noise, which grows with
        the light), before the curve, with the one standard deviation
        that makes its rms after the curve ``std(result) / 10**(snr_db / 20)`` (to first
        order: dark pixels, where sRGB is steep, get more of it, and what falls below
        black is clipped). With ``transfer="linear"`` that is ``std(blurred) /
        10**(snr_db / 20)`` in the image's own values. (The benchmark datasets instead add
        noise of that std to the encoded photo, :func:`gyrodeblur.dataset.render_case`.)
    full_well : float, optional
        Photon shot noise as well: the electrons a pixel collects at white (light 1),
        e.g. several thousand for a phone's sensor at its base ISO, a few hundred at a
        high one. Each pixel's blurred light ``L`` (each channel on its own) becomes
        ``Poisson(L * full_well) / full_well``, its variance ``L / full_well``: bright
        pixels get more noise than dark ones, in light. Added to ``snr_db``'s read noise
        (which it does not change); ``None`` (default): none.
    seed : int, sequence of int, numpy Generator or SeedSequence, optional
        Seed of the noise generator (the read noise is drawn first, as without
        ``full_well``, so that a seed gives the same read noise either way).
    quantize : bool
        Clip to [0, 1] and round to 8-bit levels (k / 255).
    n_samples : int, optional
        Time samples; default: enough that every pixel moves < 0.5 px between samples.
    order : {3, 1}
        Spline order of the sampling between pixels. 3 (default): cubic B-spline, close
        to the band-limited interpolation that a scene low-passed by the lens and the
        pixels' area calls for. 1: bilinear, which low-passes each warp by an amount that
        depends on its sub-pixel position (fully at the Nyquist frequency half-way
        between pixels), as a bilinear PSF splat does: the benchmarks' synthesis before
        session 17. Use 1 for scenes with hard-edged lights far above 1 (a cubic spline
        rings around them, below zero: negative light).

    Returns
    -------
    ndarray, float32, same shape as ``sharp``, encoded as ``sharp`` was.

    Raises
    ------
    InputError
        ``sharp`` is not a float image, or, encoded by a curve other than linear, holds
        values far below black (under :data:`~gyrodeblur.images.PHOTO_MIN`: offset or
        negated) or far above white (over :data:`~gyrodeblur.images.PHOTO_MAX`: 0-255).
    TypeError
        ``capture``, ``snr_db``, ``seed`` or ``quantize`` of the wrong kind.
    ValueError
        A bad ``order``, ``n_samples``, ``snr_db`` or ``full_well``, an image whose aspect
        ratio is not
        the camera's (an :class:`InputError`), or a rotation that carries pixels to
        infinity (by 90 degrees or more).

    Warns
    -----
    GyrodeblurWarning
        Where the gyro log steps more than 15 ms between two samples inside the exposure
        (:func:`gyrodeblur.gyrolog.step_warning`): the blur is made from the motion
        interpolated across it.

    Notes
    -----
    Sampling: the spline of ``order`` (the cubic spline's coefficients computed once per
    channel by ``scipy.ndimage.spline_filter``), evaluated as
    ``scipy.ndimage.map_coordinates(..., mode="reflect", prefilter=False)`` does, to
    float32 rounding: outside the frame the image is mirrored (half-sample symmetric).
    The taps and weights of each warped pixel are computed once for all channels, in
    chunks of rows, and the taps gathered with ``numpy.take``.
    """
    if not (is_whole(order) and order in (1, 3)):
        raise ValueError(f"order must be 1 (bilinear) or 3 (cubic spline), got {order!r}")
    if n_samples is not None and not is_count(n_samples):
        raise ValueError(f"n_samples must be a positive whole number or None, got {n_samples!r}")
    if snr_db is not None:                    # checked before the work, not after it
        snr_db = _checked_snr(snr_db)
    if full_well is not None:
        full_well = check_real(full_well, "full_well")
        if not 1.0 <= full_well <= 1e9:       # a count of electrons
            raise ValueError(f"full_well must be 1 to 1e9 electrons at white, got {full_well!r}")
    check_seed(seed)
    quantize = check_flag(quantize, "quantize")
    check_capture(capture)
    warn_of_steps(capture.log, *capture.log_window, cost="the blur is made from that "
                  "interpolation, not from motion the log recorded")
    curve = get_transfer_curve(transfer)
    # an encoded photo (sRGB) holds neither values far below black (offset or negated) nor
    # far above 1 (0-255, not scaled); linear values are blurred as they are (a linear
    # operator: lights far above 1, or a zero-mean test texture)
    linear = curve.name == LINEAR.name
    img, alpha = split_alpha(check_image(
        sharp, "sharp image", min_value=-np.inf if linear else PHOTO_MIN,
        max_value=np.inf if linear else PHOTO_MAX))                   # alpha: a mask, kept
    img = curve.decode(img)
    H, W = img.shape[:2]
    capture = capture.scaled_to(W, H, source="sharp image")     # as deblur does
    n = int(n_samples) if n_samples is not None else warp_samples(capture)
    planes = img.reshape(H, W, -1)
    padded = _spline_coefficients(planes, order)     # once, sampled unfiltered below
    acc = np.zeros((planes.shape[2], H, W), np.float32)
    xs = np.arange(W, dtype=np.float64)[None, :]
    step = max(1, _CHUNK_PX // W)

    def band(r0, r1):                # rows r0:r1 of every sample, in the samples' order
        for a in range(r0, r1, step):
            b = min(r1, a + step)
            ys = np.arange(a, b, dtype=np.float64)[:, None]
            for j in range(n):
                h = _row_homographies(capture, (j + 0.5) / n, a, b)[:, None]  # (rows, 1, 3, 3)
                den = h[..., 2, 0] * xs + h[..., 2, 1] * ys + h[..., 2, 2]
                sx = (h[..., 0, 0] * xs + h[..., 0, 1] * ys + h[..., 0, 2]) / den
                sy = (h[..., 1, 0] * xs + h[..., 1, 1] * ys + h[..., 1, 2]) / den
                _add_spline_samples(padded, sx, sy, order, acc[:, a:b])

    capture.orientation              # integrated once, before the bands share it
    for_row_bands(band, H)           # np.take and ufuncs release the GIL: one band per core
    out = np.ascontiguousarray(np.moveaxis(acc, 0, -1) / n).reshape(img.shape)
    rng = np.random.default_rng(seed)          # (a Generator given is used as it is)
    clean = out
    if snr_db is not None:
        out = (_with_noise(out, snr_db, rng) if linear
               else _add_light_noise(out, curve, snr_db, rng))
    if full_well is not None:
        out = out + _shot_noise(clean, full_well, rng)
    if not linear:          # an encoded photo holds no light below black, as a camera's
        np.maximum(out, 0.0, out=out)
    out = curve.encode(out)
    if quantize:
        out = _to_8bit_levels(out)
    return join_alpha(out.astype(np.float32, copy=False), alpha)


#: Step (linear light) of the finite difference that gives a curve's slope.
_SLOPE_STEP = 1e-3
#: Most rescalings of the noise drawn for ``snr_db`` (:func:`_add_light_noise`).
_NOISE_STEPS = 8


def _add_light_noise(light: np.ndarray, curve: TransferCurve, snr_db: float,
                     seed=None) -> np.ndarray:
    """White Gaussian noise added to ``light`` (linear, as a sensor's read noise), its one
    standard deviation chosen so that the photo ``curve`` encodes from it (light below
    black clipped) has ``snr_db``: the std of the noise after the curve is ``std(encoded) /
    10**(snr_db / 20)``. Dark pixels, where sRGB is steep, get more of it, as in a
    camera's photo. The first guess scales by the curve's rms slope; then the noise drawn
    is rescaled until its std after the curve is within 0.5 % of that (up to
    :data:`_NOISE_STEPS` times: near 0 dB the clipping at black can keep it short)."""
    base = np.maximum(light, 0.0)
    enc = curve.encode(base)
    target = float(np.std(enc)) / 10 ** (snr_db / 20)
    slope = (curve.encode(base + _SLOPE_STEP) - enc) / _SLOPE_STEP
    sigma = target / max(float(np.sqrt(np.mean(np.square(slope, dtype=np.float64)))), 1e-12)
    z = np.random.default_rng(seed).standard_normal(light.shape)
    for _ in range(_NOISE_STEPS):
        got = float(np.std(curve.encode(np.maximum(light + sigma * z, 0.0)) - enc))
        if not got > 0 or abs(got / target - 1) < 0.005:
            break
        sigma *= target / got
    return (light + sigma * z).astype(np.float32)


def _shot_noise(light: np.ndarray, full_well: float, rng) -> np.ndarray:
    """Photon shot noise of ``light`` (linear; 1 = white): ``Poisson(L * full_well) /
    full_well - L`` per sample, float32 (light below black collects no photons)."""
    lit = np.maximum(light, 0.0).astype(np.float64)
    return (rng.poisson(lit * full_well) / full_well - lit).astype(np.float32)


def _checked_snr(snr_db) -> float:
    """``snr_db`` as a float in -100 to 300 dB, else ``TypeError``/``ValueError``."""
    snr_db = check_real(snr_db, "snr_db")
    if not -100.0 <= snr_db <= 300.0:
        raise ValueError(f"snr_db must be -100 to 300 dB, got {snr_db!r}")
    return snr_db


def add_noise(image: np.ndarray, snr_db: float, seed=None) -> np.ndarray:
    """Add white Gaussian noise of std ``std(image) / 10**(snr_db / 20)``.

    Parameters
    ----------
    image : ndarray, float
        Values as they are, of any shape (no range is assumed).
    snr_db : float
        Signal-to-noise ratio, dB (-100 to 300).
    seed : int, numpy Generator or SeedSequence, optional
        The noise's random state.

    Returns
    -------
    ndarray, float32, the shape of ``image``.
    """
    img = check_values(image)
    return _with_noise(img, _checked_snr(snr_db), np.random.default_rng(check_seed(seed)))


def _with_noise(img: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """:func:`add_noise` of checked values and ``snr_db``, drawn from ``rng``."""
    sigma = float(np.std(img)) / 10 ** (snr_db / 20)
    return (img + rng.normal(0.0, sigma, img.shape)).astype(np.float32)


def quantize_8bit(image: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] and round to the nearest of the 256 8-bit levels (float32; a float
    image is required: 8-bit integers are already quantised)."""
    return _to_8bit_levels(check_values(image))


def _to_8bit_levels(img: np.ndarray) -> np.ndarray:
    """:func:`quantize_8bit` of checked values."""
    return (np.round(np.clip(img, 0, 1) * 255) / 255).astype(np.float32)
