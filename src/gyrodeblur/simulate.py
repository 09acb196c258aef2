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
from .arguments import check_flag, check_real
from .images import PHOTO_MAX, PHOTO_MIN, check_image, join_alpha, split_alpha
from .psf import check_blur_span
from .tonecurve import LINEAR, TransferCurve, get_transfer_curve

__all__ = ["simulate_blur", "add_noise", "quantize_8bit", "warp_samples"]

#: Largest motion (px) of any pixel between two consecutive time samples.
MAX_STEP_PX = 0.5


def _row_homographies(capture: Capture, s: float, r0: int = 0,
                      r1: int | None = None) -> np.ndarray:
    """``(r1 - r0, 3, 3)``: ``K R(t_y) K^-1`` for rows ``y`` in ``r0:r1`` (default all),
    with ``t_y = row_start(y) + s * exposure_time``."""
    cam = capture.camera
    rows = np.arange(r0, cam.height if r1 is None else r1)
    R = capture.orientation.matrices(capture.row_start(rows) + s * capture.exposure_time)
    return cam.K @ R @ cam.K_inv


def warp_samples(capture: Capture, max_step: float = MAX_STEP_PX) -> int:
    """Number of time samples so that the fastest of a 5x5 set of probe pixels moves
    less than ``max_step`` pixels between consecutive samples."""
    cam = capture.camera
    n0 = 64
    xs = np.linspace(0, cam.width - 1, 5)
    ys = np.linspace(0, cam.height - 1, 5)
    X, Y = np.meshgrid(xs, ys)
    pts = np.stack([X.ravel(), Y.ravel(), np.ones(X.size)])
    s = (np.arange(n0 + 1)) / n0
    times = capture.row_start(Y.ravel())[None, :] + s[:, None] * capture.exposure_time
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
                  transfer: str | TransferCurve = "linear") -> np.ndarray:
    """Blur ``sharp`` by the camera rotation recorded in ``capture``.

    Parameters
    ----------
    sharp : ndarray (H, W) or (H, W, C)
        The scene as seen at the reference orientation, float in [0, 1] (values above 1
        are allowed, e.g. for light sources that saturate only after blurring), in
        **linear light** by default (see ``transfer``). Its size must match
        ``capture.camera`` (use ``capture.scaled_to``). A last channel of 2 or 4 is alpha,
        a mask: returned untouched (not blurred, noised or quantised).
    capture : Capture
    transfer : {"linear", "srgb"} or TransferCurve
        How ``sharp``'s values encode light. Light blurs linearly, so an encoded photo is
        decoded, blurred, noised and encoded again. ``"linear"`` (default): ``sharp`` is
        light itself. For an sRGB photo pass ``"srgb"``: the result is then what
        :func:`gyrodeblur.deblur.deblur` expects by default (its ``transfer="srgb"``);
        blurring encoded values directly would model a camera that does not exist and
        cost a deblur of them several dB.
    snr_db : float, optional
        Add Gaussian noise with standard deviation ``std(blurred) / 10**(snr_db / 20)``.
    seed : int, sequence of int, numpy Generator or SeedSequence, optional
        Seed of the noise generator.
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

    Notes
    -----
    Sampling: ``scipy.ndimage.map_coordinates`` of ``order`` (the cubic spline's
    coefficients computed once per channel); outside the frame the image is mirrored
    (half-sample symmetric).
    """
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, (int, np.integer)) \
            or order not in (1, 3):
        raise ValueError(f"order must be 1 (bilinear) or 3 (cubic spline), got {order!r}")
    if n_samples is not None and (isinstance(n_samples, bool) or not isinstance(
            n_samples, (int, np.integer)) or n_samples < 1):
        raise ValueError(f"n_samples must be a positive whole number or None, got {n_samples!r}")
    if snr_db is not None:
        snr_db = check_real(snr_db, "snr_db")
        if not -100.0 <= snr_db <= 300.0:     # checked before the work, not after it
            raise ValueError(f"snr_db must be -100 to 300 dB, got {snr_db!r}")
    try:
        if isinstance(seed, (bool, np.bool_)):
            raise TypeError
        np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise TypeError(f"seed must be a whole number >= 0 (or a sequence of them), a numpy "
                        f"Generator or SeedSequence, or None, got {seed!r}") from None
    quantize = check_flag(quantize, "quantize")
    check_capture(capture)
    curve = get_transfer_curve(transfer, "transfer")
    # an encoded photo (sRGB) holds neither values far below black (offset or negated) nor
    # far above 1 (0-255, not scaled); linear values are blurred as they are (a linear
    # operator: lights far above 1, or a zero-mean test texture)
    linear = curve.name == LINEAR.name
    img, alpha = split_alpha(check_image(
        sharp, "sharp image", min_value=-np.inf if linear else PHOTO_MIN,
        max_value=np.inf if linear else PHOTO_MAX))                   # alpha: a mask, kept
    img = curve.decode(img)
    H, W = img.shape[:2]
    cam = capture.camera
    if (W, H) != (cam.width, cam.height):
        raise ValueError(f"image is {W}x{H} but the capture's camera is {cam.width}x{cam.height}")
    n = int(n_samples) if n_samples is not None else warp_samples(capture)
    planes = img.reshape(H, W, -1)
    acc = np.zeros_like(planes)
    if order > 1:                    # spline coefficients, once (sampled unfiltered below)
        planes = np.stack([ndimage.spline_filter(planes[..., c], order, output=np.float32,
                                                 mode="reflect")
                           for c in range(planes.shape[2])], axis=-1)
    xs = np.arange(W, dtype=np.float64)[None, :]

    def band(r0, r1):                # rows r0:r1 of every sample, in the samples' order
        ys = np.arange(r0, r1, dtype=np.float64)[:, None]
        for j in range(n):
            h = _row_homographies(capture, (j + 0.5) / n, r0, r1)[:, None]  # (rows, 1, 3, 3)
            den = h[..., 2, 0] * xs + h[..., 2, 1] * ys + h[..., 2, 2]
            sx = (h[..., 0, 0] * xs + h[..., 0, 1] * ys + h[..., 0, 2]) / den
            sy = (h[..., 1, 0] * xs + h[..., 1, 1] * ys + h[..., 1, 2]) / den
            coords = np.stack([sy, sx])
            for c in range(planes.shape[2]):
                acc[r0:r1, :, c] += ndimage.map_coordinates(
                    planes[..., c], coords, order=order, mode="reflect", prefilter=False)

    capture.orientation              # integrated once, before the bands share it
    for_row_bands(band, H)           # map_coordinates releases the GIL: one band per core
    out = (acc / n).reshape(img.shape)
    if snr_db is not None:
        out = add_noise(out, snr_db, seed)
    out = curve.encode(out)
    if quantize:
        out = quantize_8bit(out)
    return join_alpha(out.astype(np.float32, copy=False), alpha)


def add_noise(image: np.ndarray, snr_db: float, seed: int | None = None) -> np.ndarray:
    """Add white Gaussian noise of std ``std(image) / 10**(snr_db / 20)`` (float32)."""
    rng = np.random.default_rng(seed)
    sigma = float(np.std(image)) / 10 ** (snr_db / 20)
    return (image + rng.normal(0.0, sigma, image.shape)).astype(np.float32)


def quantize_8bit(image: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] and round to the nearest of the 256 8-bit levels (float32)."""
    return (np.round(np.clip(image, 0, 1) * 255) / 255).astype(np.float32)
