"""Transfer curves: between encoded pixel values and linear scene radiance.

Camera shake blurs light, not pixel codes: a blurred photo is the average of sharp
*radiance* images, so deconvolution is only exact on linear data. The pipeline therefore
decodes a photo with :func:`srgb_to_linear` (or whichever curve the capture names), deblurs,
and re-encodes with :func:`linear_to_srgb`.

Both functions implement the exact piecewise sRGB curve of IEC 61966-2-1:1999, on values in
``[0, 1]``; float32 in, float32 out (the maths runs in float64 internally so that a round
trip is exact to ~1e-7). Values outside ``[0, 1]`` are accepted: the linear segment is
extended below 0 (odd symmetry) and the power segment above 1, so an overshoot survives a
round trip instead of being silently clipped.

Other curves, as colour profiles declare them (:mod:`gyrodeblur.icc` reads them from a
photo's ICC profile): :class:`ParametricCurve` (a pure gamma, or ICC's parametric
functions, Adobe RGB's gamma 2.2 and ProPhoto's 1.8 among them), :class:`TableCurve` (a
sampled curve) and :class:`PerChannelCurve` (one curve per colour channel), each turned
into a :class:`TransferCurve` by its ``transfer_curve`` method.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .bands import for_row_bands
from .errors import InputError

__all__ = [
    "srgb_to_linear",
    "linear_to_srgb",
    "TransferCurve",
    "SRGB",
    "LINEAR",
    "get_transfer_curve",
    "ParametricCurve",
    "TableCurve",
    "PerChannelCurve",
    "matches_curve",
]

# IEC 61966-2-1 constants. The encoding threshold 0.0031308 and the decoding threshold
# 0.04045 are the standard's own (they agree to ~1e-7, 12.92 * 0.0031308 = 0.040450).
_A = 0.055
_GAMMA = 2.4
_SLOPE = 12.92
_LIN_THRESHOLD = 0.0031308
_ENC_THRESHOLD = 0.04045


def srgb_to_linear(image: np.ndarray) -> np.ndarray:
    r"""Decode sRGB-encoded values to linear light (IEC 61966-2-1).

    Parameters
    ----------
    image : array_like
        Encoded values, nominally in ``[0, 1]``; any shape.

    Returns
    -------
    ndarray, float32, same shape.

    Notes
    -----
    .. math::
        L = \begin{cases} V / 12.92 & |V| \le 0.04045 \\
        \left(\frac{V + 0.055}{1.055}\right)^{2.4} & V > 0.04045 \end{cases}

    extended with odd symmetry for ``V < -0.04045``.

    Examples
    --------
    >>> float(srgb_to_linear(np.float32(0.5)))  # doctest: +ELLIPSIS
    0.2140...
    """
    return _piecewise(image, _ENC_THRESHOLD, 1 / _SLOPE,
                      lambda a: np.power(np.multiply(np.add(a, _A, out=a), 1 / (1 + _A), out=a),
                                         _GAMMA, out=a))


def linear_to_srgb(image: np.ndarray) -> np.ndarray:
    r"""Encode linear light as sRGB values (IEC 61966-2-1); inverse of :func:`srgb_to_linear`.

    Parameters
    ----------
    image : array_like
        Linear values, nominally in ``[0, 1]``; any shape.

    Returns
    -------
    ndarray, float32, same shape.

    Notes
    -----
    .. math::
        V = \begin{cases} 12.92\,L & |L| \le 0.0031308 \\
        1.055\,L^{1/2.4} - 0.055 & L > 0.0031308 \end{cases}

    extended with odd symmetry for ``L < -0.0031308``.

    Examples
    --------
    >>> round(float(linear_to_srgb(np.float32(0.18))), 4)
    0.4614
    """
    return _piecewise(image, _LIN_THRESHOLD, _SLOPE,
                      lambda a: np.subtract(np.multiply(np.power(a, 1 / _GAMMA, out=a), 1 + _A,
                                                        out=a), _A, out=a))


def _piecewise(image, threshold: float, slope: float, power_segment) -> np.ndarray:
    """Odd-symmetric curve: ``slope * |x|`` up to ``threshold``, ``power_segment`` above.

    float32 throughout, with in-place operations: a 12 MP RGB photo costs about one extra
    image-sized buffer rather than a dozen float64 ones. Large images are processed in row
    bands on all cores (:func:`gyrodeblur.bands.for_row_bands`)."""
    def band(xs, o) -> None:
        np.abs(xs, out=o)
        small = o <= threshold
        power_segment(o)
        np.copysign(o, xs, out=o)
        # the linear segment is odd by itself; masked writes, not fancy indexing (3x faster)
        np.multiply(xs, np.float32(slope), out=o, where=small)

    return _elementwise(image, band)


def _identity(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, dtype=np.float32)


def _elementwise(image, fill) -> np.ndarray:
    """A float32 image of the same shape, ``fill(rows, out_rows)`` writing each band of
    rows of the output from the same rows of ``image`` (row bands on all cores)."""
    x = np.asarray(image, dtype=np.float32)
    if not x.flags.c_contiguous:
        x = np.ascontiguousarray(x)
    out = np.empty_like(x)
    if x.size == 0:
        return out
    rows_x = x.reshape(1, -1) if x.ndim == 0 else x.reshape(x.shape[0], -1)
    rows_out = out.reshape(rows_x.shape)
    for_row_bands(lambda r0, r1: fill(rows_x[r0:r1], rows_out[r0:r1]), rows_x.shape[0])
    return out


@dataclass(frozen=True)
class TransferCurve:
    """A named pair of functions: ``decode`` (encoded -> linear) and ``encode`` (inverse).

    Attributes
    ----------
    name : str
        Canonical name, e.g. ``"srgb"``.
    decode : callable
        ``decode(image) -> float32 ndarray`` of linear values.
    encode : callable
        ``encode(image) -> float32 ndarray`` of encoded values.
    """

    name: str
    decode: Callable[[np.ndarray], np.ndarray]
    encode: Callable[[np.ndarray], np.ndarray]


#: The sRGB curve of IEC 61966-2-1 (what 8-bit JPEG/PNG photos carry).
SRGB = TransferCurve("srgb", srgb_to_linear, linear_to_srgb)
#: No curve: the data are already linear (e.g. raw-derived TIFFs).
LINEAR = TransferCurve("linear", _identity, _identity)

_CURVES = {"srgb": SRGB, "linear": LINEAR, "none": LINEAR}


@dataclass(frozen=True)
class ParametricCurve:
    r"""A decoding curve of ICC's parametric form (ICC.1:2010, section 10.18, function 4).

    .. math::
        L = \begin{cases} (aV + b)^g + e & V \ge d \\ cV + f & V < d \end{cases}

    ``ParametricCurve(g)`` is a pure gamma (``L = V^g``); ICC's functions 0-3 are this
    form with some parameters zero (:func:`gyrodeblur.icc.parametric_curve`). ``V`` and
    ``L`` in ``[0, 1]``, the encoded value and linear light. The power's base is taken as
    0 where ``aV + b`` is negative.

    Outside ``[0, 1]`` (an overshoot of the deconvolution): a curve through the origin is
    extended with odd symmetry, as :func:`srgb_to_linear` is; one with an offset (``e``
    or ``f`` shifting black), or flat at black (``b < 0`` with no linear segment: light
    at or below 0 encodes as the flat foot's end), keeps its own segments.
    """

    g: float
    a: float = 1.0
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0
    e: float = 0.0
    f: float = 0.0

    def __post_init__(self):
        if not all(np.isfinite(v) for v in (self.g, self.a, self.b, self.c, self.d, self.e,
                                             self.f)):
            raise ValueError(f"curve parameters must be finite: {self}")
        if not (self.g > 0 and self.a > 0 and self.c >= 0):
            raise ValueError(f"not an increasing curve (needs g > 0, a > 0, c >= 0): {self}")

    @property
    def _odd(self) -> bool:
        # through the origin and rising from it within a quarter of an 8-bit level: a
        # curve flat at black (ICC function 1 with b < 0) would jump from its foot's end to
        # minus it at 0 under the mirror; a b of a fixed-point step or so (-1/65536) is 0
        at_0, above = self._decode64(np.array([0.0, 0.25 / 255]))
        return abs(float(at_0)) < 1e-7 and above > at_0

    def _decode64(self, v: np.ndarray) -> np.ndarray:
        base = np.maximum(self.a * v + self.b, 0.0)
        return np.where(v >= self.d, base ** self.g + self.e, self.c * v + self.f)

    def decode(self, image) -> np.ndarray:
        """Encoded values -> linear light (float32, any shape)."""
        g, a, b, c, d, e, f = (np.float32(v) for v in (self.g, self.a, self.b, self.c,
                                                        self.d, self.e, self.f))
        odd = self._odd

        def rows(v, o):
            x = np.abs(v) if odd else v
            with np.errstate(invalid="ignore"):
                y = np.power(np.maximum(a * x + b, np.float32(0)), g) + e
            y = np.where(x >= d, y, c * x + f)
            o[...] = np.copysign(y, v) if odd else y

        return _elementwise(image, rows)

    def encode(self, image) -> np.ndarray:
        """Linear light -> encoded values (float32, any shape); inverse of :meth:`decode`."""
        a, b, c, d, e, f = (np.float32(v) for v in (self.a, self.b, self.c, self.d, self.e,
                                                     self.f))
        odd = self._odd
        y_d = np.float32(self._decode64(np.array([self.d]))[0])   # where the segments meet

        def rows(v, o):
            y = np.abs(v) if odd else v
            x = (np.power(np.maximum(y - e, np.float32(0)), np.float32(1 / self.g)) - b) / a
            if c > 0:
                x = np.where(y >= y_d, x, (y - f) / c)
            else:                    # a flat foot: every value below it encodes as d
                x = np.where(y >= y_d, x, d)
            o[...] = np.copysign(x, v) if odd else x

        return _elementwise(image, rows)

    def transfer_curve(self, name: str | None = None) -> TransferCurve:
        """This curve as a :class:`TransferCurve` (named ``gamma G`` for a pure gamma)."""
        pure = (self.a, self.b, self.c, self.d, self.e, self.f) == (1, 0, 0, 0, 0, 0)
        label = name or (f"gamma {self.g:.3g}" if pure else f"parametric (gamma {self.g:.3g})")
        return TransferCurve(label, self.decode, self.encode)


@dataclass(frozen=True, eq=False)
class TableCurve:
    """A decoding curve sampled at evenly spaced encoded values (an ICC ``curv`` table).

    Parameters
    ----------
    samples : array_like, shape (N,), N >= 2
        Linear light at encoded values ``0, 1/(N-1), ..., 1``, non-decreasing (a table
        that dips is made non-decreasing). Between samples the curve is linear, and so is
        its extension outside ``[0, 1]`` (the end segments continued).
    """

    samples: np.ndarray

    def __post_init__(self):
        s = np.asarray(self.samples, dtype=np.float64).ravel()
        if s.size < 2 or not np.all(np.isfinite(s)):
            raise ValueError("a table curve needs at least 2 finite samples")
        object.__setattr__(self, "samples", np.maximum.accumulate(s))

    def decode(self, image) -> np.ndarray:
        """Encoded values -> linear light (float32, any shape)."""
        s = self.samples.astype(np.float32)
        n = s.size

        def rows(v, o):
            t = v * np.float32(n - 1)
            i = np.clip(np.floor(t), 0, n - 2).astype(np.intp)
            o[...] = s[i] + (t - i) * (s[i + 1] - s[i])

        return _elementwise(image, rows)

    def encode(self, image) -> np.ndarray:
        """Linear light -> encoded values (float32, any shape); inverse of :meth:`decode`
        (the value of a flat stretch of the table encodes as the stretch's end)."""
        s = self.samples
        xs = np.linspace(0.0, 1.0, s.size)
        rise = np.flatnonzero(np.diff(s) > 0)
        step = 1.0 / (s.size - 1)
        # beyond the table: its first and last rising segments continued
        lo = step / (s[rise[0] + 1] - s[rise[0]]) if rise.size else 0.0
        hi = step / (s[rise[-1] + 1] - s[rise[-1]]) if rise.size else 0.0

        def rows(v, o):
            y = v.astype(np.float64)
            # np.interp takes the last of equal samples: a flat stretch maps to its end
            x = np.interp(y, s, xs)
            x = np.where(y < s[0], (y - s[0]) * lo, x)
            o[...] = np.where(y > s[-1], 1.0 + (y - s[-1]) * hi, x)

        return _elementwise(image, rows)

    def transfer_curve(self, name: str | None = None) -> TransferCurve:
        """This curve as a :class:`TransferCurve`."""
        return TransferCurve(name or f"{self.samples.size}-point tabulated", self.decode,
                             self.encode)


@dataclass(frozen=True)
class PerChannelCurve:
    """One curve per colour channel (red, green, blue), for profiles whose channels differ.

    On an image without three channels the green curve is used for every value.
    """

    red: TransferCurve
    green: TransferCurve
    blue: TransferCurve

    def _apply(self, image, which: str) -> np.ndarray:
        x = np.asarray(image, dtype=np.float32)
        curves = (self.red, self.green, self.blue)
        if x.ndim != 3 or x.shape[2] != 3:
            return getattr(self.green, which)(x)
        out = np.empty(x.shape, np.float32)
        for ch, curve in enumerate(curves):
            out[..., ch] = getattr(curve, which)(np.ascontiguousarray(x[..., ch]))
        return out

    def decode(self, image) -> np.ndarray:
        """Encoded RGB -> linear light, each channel by its own curve (float32)."""
        return self._apply(image, "decode")

    def encode(self, image) -> np.ndarray:
        """Linear RGB -> encoded values; inverse of :meth:`decode` (float32)."""
        return self._apply(image, "encode")

    def transfer_curve(self, name: str | None = None) -> TransferCurve:
        """This curve as a :class:`TransferCurve`."""
        label = name or f"per channel ({self.red.name}, {self.green.name}, {self.blue.name})"
        return TransferCurve(label, self.decode, self.encode)


def matches_curve(curve: TransferCurve, reference: TransferCurve, *,
                  tolerance: float = 0.25 / 255) -> bool:
    """Whether ``curve`` decodes like ``reference`` to within ``tolerance`` of an encoded
    value (default: a quarter of an 8-bit level) over ``[0, 1]``: the reference, exact and
    faster, can stand in for it.

    Examples
    --------
    >>> matches_curve(ParametricCurve(2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)
    ...               .transfer_curve(), SRGB)
    True
    >>> matches_curve(ParametricCurve(2.2).transfer_curve(), SRGB)
    False
    """
    v = np.linspace(0.0, 1.0, 1025, dtype=np.float32)
    back = reference.encode(np.clip(curve.decode(v), 0.0, None))
    return bool(np.max(np.abs(back - v)) <= tolerance)


def get_transfer_curve(name: str | TransferCurve, source: str | None = None) -> TransferCurve:
    """Look up a transfer curve by name (case-insensitive): ``"srgb"``, ``"linear"``/``"none"``.

    A :class:`TransferCurve` passes through unchanged.

    Parameters
    ----------
    name : str or TransferCurve
    source : str or None
        What to name in the error message: the file the name came from; by default the
        keyword argument ``transfer`` (on the command line, ``--transfer``).

    Raises
    ------
    InputError
        For an unknown name; the message lists the known ones.

    Examples
    --------
    >>> get_transfer_curve("sRGB").name
    'srgb'
    """
    if isinstance(name, TransferCurve):
        return name

    def refused(problem: str) -> InputError:
        return (InputError.of_argument("transfer", problem) if source is None
                else InputError(source, problem))

    if not isinstance(name, str):        # None would read as "none", i.e. linear
        raise refused(f"a transfer curve is a name ({', '.join(sorted(_CURVES))}) or a "
                      f"TransferCurve, got {name!r}")
    key = name.strip().lower()
    try:
        return _CURVES[key]
    except KeyError:
        known = ", ".join(sorted(_CURVES))
        raise refused(f"unknown transfer curve {name!r} (known: {known})") from None
