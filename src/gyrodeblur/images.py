"""Image arrays (and PSFs) as the library's functions take them, checked once at the door.

Inside the library an image is a float array of shape ``(H, W)`` or ``(H, W, C)`` (channels
last, ``C`` from 1 to 4), with values in [0, 1] (8- and 16-bit integers live only in files,
see :mod:`gyrodeblur.imageio`). :func:`check_image` refuses anything else with one clear
:class:`~gyrodeblur.errors.InputError`, rather than letting it turn into a silently wrong
result: ``uint8`` values read as 0-255 come out nearly white, and a single NaN pixel
spreads over its whole patch through the FFTs.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError

__all__ = ["check_image", "check_values", "check_psf", "split_alpha", "join_alpha",
           "to_sensor_layout", "to_photo_layout", "MAX_CHANNELS", "PHOTO_MAX", "PHOTO_MIN"]

#: Most channels an image may have (grey, grey + alpha, RGB, RGBA).
MAX_CHANNELS = 4
#: Largest value a photo to deblur or calibrate may hold (a little overshoot from earlier
#: processing passes; 0-255 values do not).
PHOTO_MAX = 2.0
#: Smallest value a photo to deblur or calibrate may hold: a little undershoot from earlier
#: processing (sharpening, a black level subtracted from noisy data) is tolerated, but no
#: light is far below black (an offset photo, ``x - 0.5``, or negated values are refused).
PHOTO_MIN = -0.25


def check_image(image, what: str = "image", *, min_size: int = 2,
                dtype=np.float32, max_value: float = np.inf,
                min_value: float = -np.inf, max_channels: int = MAX_CHANNELS) -> np.ndarray:
    """``image`` as a float32 (or ``dtype``) array, or :class:`InputError` saying what is
    wrong.

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, C)
        Floating-point pixel values (any float dtype; float32 is returned without a copy).
    what : str
        How the messages name the argument (e.g. ``"photo 2"``).
    min_size : int
        Smallest height and width accepted, pixels.
    dtype : numpy dtype
        Floating-point type of the result (float64 for metrics).
    max_value : float
        Largest value accepted: a photo in [0, 1] has none far above 1, and one with values
        up to 255 was not scaled (:data:`PHOTO_MAX` for photos; a scene to blur may hold
        brighter light).
    min_value : float
        Smallest value accepted (:data:`PHOTO_MIN` for photos).
    max_channels : int
        Most channels accepted (a photo's :data:`MAX_CHANNELS`; more for an array of
        planes that are warped alike).

    Returns
    -------
    ndarray of ``dtype``, the same shape.

    Raises
    ------
    InputError
        An integer, boolean or complex dtype (the values would be misread), a shape that is
        not ``(H, W)`` or channels-last ``(H, W, C)`` with ``C <= max_channels``, a side under
        ``min_size``, NaN/infinite values, or values outside ``[min_value, max_value]``.
    """
    arr = _float_array(image, what)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and not 1 <= arr.shape[2] <= max_channels):
        raise InputError(None, f"{what} must have shape (H, W) or (H, W, C) with at most "
                               f"{max_channels} channels last, got {arr.shape}")
    if min(arr.shape[:2]) < min_size:
        raise InputError(None, f"{what} is {arr.shape[1]}x{arr.shape[0]} pixels; need at "
                               f"least {min_size}x{min_size}")
    arr = arr.astype(dtype, copy=False)
    _refuse_non_finite(arr, what)
    if np.isfinite(max_value):
        top = float(arr.max())
        if top > max_value:
            raise InputError(None, f"{what} has values up to {top:.4g}; expected [0, 1] "
                                   "(divide 8-bit values by 255, 16-bit ones by 65535)")
    if np.isfinite(min_value):
        bottom = float(arr.min())
        if bottom < min_value:
            raise InputError(None, f"{what} has values down to {bottom:.4g}; expected [0, 1] "
                                   "(light is never below black: is it offset or negated?)")
    return arr


def check_values(values, what: str = "image") -> np.ndarray:
    """``values`` of any shape as a float array of their own precision (float64 stays
    float64), or :class:`InputError`: integers, booleans or complex numbers (pixel values
    are floats in [0, 1]), or NaN/infinite values."""
    arr = _float_array(values, what)
    _refuse_non_finite(arr, what)
    return arr


def _float_array(image, what: str) -> np.ndarray:
    if isinstance(image, np.ndarray):
        arr = image
    else:
        try:
            arr = np.asarray(image)
        except (TypeError, ValueError) as exc:
            raise InputError(None, f"{what} is not an array of pixel values ({exc})") from None
    if arr.dtype.kind != "f":
        hint = (" (divide 8-bit values by 255, 16-bit ones by 65535)"
                if arr.dtype.kind in "ui" else "")
        raise InputError(None, f"{what} must hold floating-point values in [0, 1], got dtype "
                               f"{arr.dtype}{hint}")
    return arr


def _refuse_non_finite(arr: np.ndarray, what: str) -> None:
    finite = np.isfinite(arr)
    if not finite.all():
        n = int(arr.size - np.count_nonzero(finite))
        raise InputError(None, f"{what} has {n} NaN or infinite value(s)")


def check_psf(psf, what: str = "PSF", *, dtype=np.float32) -> np.ndarray:
    """``psf`` normalised to sum 1, or :class:`InputError` saying what is wrong.

    Parameters
    ----------
    psf : array_like, shape (kh, kw)
        Real weights; both sides odd (the centre sample is the pixel the PSF belongs to).
        Negative entries are kept: a PSF estimated or resampled elsewhere may ring a
        little below zero.
    what : str
        How the messages name the argument (e.g. ``"init_psf"``).
    dtype : numpy dtype
        Floating-point type of the result (normalised in float64 first).

    Returns
    -------
    ndarray of ``dtype``, shape (kh, kw), summing to 1.

    Raises
    ------
    InputError
        Not an array of real numbers, not 2-D with odd sides, NaN or infinite entries, or
        a sum that is not positive and finite.
    """
    try:
        k = np.asarray(psf)
        if k.dtype.kind == "c":
            raise TypeError("complex values")
        k = k.astype(np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(None, f"{what} is not an array of real numbers ({exc})") from None
    if k.ndim != 2 or k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        raise InputError(None, f"{what} must be a 2-D array with odd sides, got shape "
                               f"{k.shape}")
    if not np.all(np.isfinite(k)):
        raise InputError(None, f"{what} has NaN or infinite values")
    with np.errstate(over="ignore"):
        total = float(k.sum())
    if not np.isfinite(total) or total <= 0:
        raise InputError(None, f"{what} must have a positive finite sum, got {total:.4g}")
    return (k / total).astype(dtype)


def split_alpha(pixels: np.ndarray):
    """``(colour, alpha)``: an RGBA (or grey + alpha, ``(H, W, 2)``) photo's colour
    channels and its alpha channel, each ``(H, W, C)``; ``(pixels, None)`` without one.
    Alpha is a mask, not light: it is neither blurred nor deblurred, and must not take
    part in what the colour channels' result depends on."""
    if pixels.ndim == 3 and pixels.shape[2] in (2, 4):
        return pixels[..., :-1], pixels[..., -1:]
    return pixels, None


def join_alpha(colour: np.ndarray, alpha) -> np.ndarray:
    """``colour`` with ``alpha`` (from :func:`split_alpha`) put back, untouched."""
    if alpha is None:
        return colour
    return np.concatenate([colour, alpha.astype(colour.dtype, copy=False)], axis=2)


def to_sensor_layout(pixels: np.ndarray, degrees: int) -> np.ndarray:
    """A photo's pixels turned back ``degrees`` counter-clockwise, to the layout the
    sensor read out (rows = readout rows), for a photo an export turned ``degrees``
    clockwise (0, 90, 180 or 270); ``pixels`` itself for 0."""
    if not degrees:
        return pixels
    return np.ascontiguousarray(np.rot90(pixels, degrees // 90))


def to_photo_layout(pixels: np.ndarray, degrees: int) -> np.ndarray:
    """The inverse of :func:`to_sensor_layout`: a result turned like the input photo."""
    return np.ascontiguousarray(np.rot90(pixels, -(degrees // 90))) if degrees else pixels
