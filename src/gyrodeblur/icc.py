"""ICC colour profiles: the transfer curve a photo's embedded profile declares.

Deconvolution runs in linear light (:mod:`gyrodeblur.tonecurve`), so it must undo the curve
the photo's values were encoded with. A JPEG or PNG from a phone is sRGB-encoded (Display
P3 uses the same curve); a TIFF from a raw converter may be linear, or Adobe RGB (gamma
2.2), or ProPhoto (gamma 1.8), and says so in its ICC profile. This module reads that
curve: the ``rTRC``/``gTRC``/``bTRC`` tags of an RGB profile, ``kTRC`` of a grey one
(ICC.1:2010, sections 9.2 and 10.5-10.18: ``curv`` tables and gammas, ``para``
parametric functions 0-4). A curve that decodes like sRGB (or like no curve) to a quarter
of an 8-bit level is replaced by the exact :data:`~gyrodeblur.tonecurve.SRGB`
(:data:`~gyrodeblur.tonecurve.LINEAR`): the common profiles give exactly what
``transfer="srgb"`` gives.

Profiles built on lookup tables only (``A2B0``, no TRC tags) declare no curve this module
reads; :func:`photo_transfer_curve` then assumes sRGB and says so. A PNG without a profile
may state its file gamma instead (``gAMA``; :attr:`gyrodeblur.imageio.Photo.png_gamma`):
1.0 is linear, and 1/2.2 (what libpng writes beside an ``sRGB`` chunk, and what viewers
show as sRGB) is taken as sRGB; any other is a pure gamma. Colour (the primaries)
is not converted: blur mixes light of each channel with itself, so only the curve matters.
"""

from __future__ import annotations

import struct

from .errors import InputError
from .tonecurve import (LINEAR, SRGB, ParametricCurve, PerChannelCurve, TableCurve,
                        TransferCurve, get_transfer_curve, matches_curve)

__all__ = ["profile_transfer_curve", "profile_description", "profile_damage",
           "parametric_curve", "photo_transfer_curve", "said_transfer_curve", "AUTO"]

#: The ``transfer`` name that means "the photo's ICC profile's curve, sRGB without one".
AUTO = "auto"
#: A PNG file gamma within this relative distance of 1/2.2 is sRGB's (0.45455 is written
#: for sRGB; a pure 2.2 gamma differs from sRGB's curve by about a level in the shadows)
_SRGB_FILE_GAMMA_TOLERANCE = 0.01

_HEADER = 128
# parameters of ICC's parametric functions 0-4 (ICC.1:2010, table 65)
_PARA_COUNTS = {0: 1, 1: 3, 2: 4, 3: 5, 4: 7}


def parametric_curve(function: int, params) -> ParametricCurve:
    """ICC parametric function ``function`` (0-4) with its parameters, in the general form.

    Parameters
    ----------
    function : int
        0: ``L = V^g``; 1: ``(aV + b)^g`` above ``V = -b/a``, else 0; 2: the same plus
        ``c``; 3: ``(aV + b)^g`` above ``V = d``, else ``cV``; 4: function 3 plus ``e``
        above ``d`` and ``f`` below.
    params : sequence of float
        ``g``, then ``a, b, c, d, e, f`` as far as the function has them.

    Examples
    --------
    >>> c = parametric_curve(3, (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045))
    >>> round(float(c.decode(0.5)), 4)        # sRGB's curve, as ICC function 3 writes it
    0.214
    """
    p = [float(v) for v in params]
    if function not in _PARA_COUNTS or len(p) != _PARA_COUNTS[function]:
        raise ValueError(f"parametric function {function} with {len(p)} parameters")
    if function == 0:
        return ParametricCurve(p[0])
    if function in (1, 2):
        g, a, b = p[:3]
        if a <= 0:
            raise ValueError(f"parametric function {function}: a = {a:g} is not positive")
        off = p[3] if function == 2 else 0.0
        return ParametricCurve(g, a, b, 0.0, -b / a, off, off)
    return ParametricCurve(*p)


def _tags(profile: bytes) -> dict[bytes, bytes]:
    """Tag signature -> tag data of an ICC profile (ValueError if it is not one)."""
    if len(profile) < _HEADER + 4 or profile[36:40] != b"acsp":
        raise ValueError("not an ICC profile (no 'acsp' signature)")
    (count,) = struct.unpack_from(">I", profile, _HEADER)
    if _HEADER + 4 + 12 * count > len(profile):
        raise ValueError(f"truncated: {count} tags do not fit in {len(profile)} bytes")
    tags = {}
    for i in range(count):
        sig, off, size = struct.unpack_from(">4sII", profile, _HEADER + 4 + 12 * i)
        if off + size > len(profile) or size < 8:
            raise ValueError(f"tag {sig.decode('latin-1')!r} lies outside the profile")
        tags[sig] = profile[off:off + size]
    return tags


def profile_damage(profile: bytes) -> str | None:
    """What is wrong with an ICC profile's structure, or ``None`` where it is whole.

    A profile is damaged when it is shorter than the size its header declares (a file cut
    short), has no ``acsp`` signature, or its tag table or a tag lies past its end. Such a
    profile is not carried into a written photo: viewers would refuse it or misread it.
    """
    if len(profile) >= 4:
        (declared,) = struct.unpack_from(">I", profile, 0)
        if declared > len(profile):
            return f"cut short: its header declares {declared} bytes, it holds {len(profile)}"
    try:
        _tags(profile)
    except ValueError as exc:
        return str(exc)
    return None


def _curve(data: bytes, sig: str) -> TransferCurve:
    """One TRC tag (``curv`` or ``para``) as a transfer curve."""
    kind = data[:4]
    if kind == b"curv":
        (n,) = struct.unpack_from(">I", data, 8)
        if 12 + 2 * n > len(data):
            raise ValueError(f"{sig}: {n} curve entries do not fit in the tag")
        if n == 0:
            return LINEAR
        if n == 1:
            (gamma,) = struct.unpack_from(">H", data, 12)
            if gamma == 0:
                raise ValueError(f"{sig}: gamma 0")
            return ParametricCurve(gamma / 256.0).transfer_curve()
        samples = [v / 65535.0 for v in struct.unpack_from(f">{n}H", data, 12)]
        return TableCurve(samples).transfer_curve()
    if kind == b"para":
        (function,) = struct.unpack_from(">H", data, 8)
        if function not in _PARA_COUNTS:
            raise ValueError(f"{sig}: unknown parametric function {function}")
        k = _PARA_COUNTS[function]
        if 12 + 4 * k > len(data):
            raise ValueError(f"{sig}: parametric function {function} is truncated")
        params = [v / 65536.0 for v in struct.unpack_from(f">{k}i", data, 12)]
        return parametric_curve(function, params).transfer_curve()
    raise ValueError(f"{sig}: a {kind.decode('latin-1')!r} tag, not a curve")


def _known(curve: TransferCurve) -> TransferCurve:
    """The exact sRGB or linear curve where ``curve`` decodes like it, else ``curve``."""
    for ref in (SRGB, LINEAR):
        if curve is ref or matches_curve(curve, ref):
            return ref
    return curve


def profile_transfer_curve(profile: bytes) -> TransferCurve:
    """The transfer curve an ICC profile declares (its TRC tags).

    Parameters
    ----------
    profile : bytes
        The profile, as embedded in the photo.

    Returns
    -------
    TransferCurve
        :data:`~gyrodeblur.tonecurve.SRGB` or :data:`~gyrodeblur.tonecurve.LINEAR` where
        the profile's curve decodes like them (to a quarter of an 8-bit level), else the
        profile's own curve (one per channel where an RGB profile's channels differ).

    Raises
    ------
    ValueError
        Not an ICC profile, damaged, of another colour space than RGB or grey, or without
        TRC tags (a profile of lookup tables); the message says which.
    """
    tags = _tags(profile)
    space = bytes(profile[16:20])
    if space == b"GRAY":
        names = ("kTRC",)
    elif space == b"RGB ":
        names = ("rTRC", "gTRC", "bTRC")
    else:
        raise ValueError(f"a {space.decode('latin-1').strip()!r} profile, not RGB or grey")
    missing = [n for n in names if n.encode() not in tags]
    if missing:
        raise ValueError(f"no {'/'.join(missing)} tag (a profile of lookup tables)")
    curves = [_known(_curve(tags[n.encode()], n)) for n in names]
    if len(curves) == 1:
        return curves[0]
    r, g, b = curves
    same = (len({tags[n.encode()] for n in names}) == 1
            or all(c is g for c in curves))               # all sRGB, or all linear
    return g if same else PerChannelCurve(r, g, b).transfer_curve()


def profile_description(profile: bytes) -> str | None:
    """The profile's own name (its ``desc`` tag, ICC v2 text or v4 ``mluc``), if it has one."""
    try:
        data = _tags(profile).get(b"desc")
    except ValueError:
        return None
    if data is None or len(data) < 12:
        return None
    try:
        if data[:4] == b"desc":
            (n,) = struct.unpack_from(">I", data, 8)
            text = data[12:12 + n].split(b"\0")[0].decode("latin-1")
        elif data[:4] == b"mluc":
            count, _size = struct.unpack_from(">II", data, 8)
            if count < 1:
                return None
            length, off = struct.unpack_from(">II", data, 20)
            text = data[off:off + length].decode("utf-16-be")
        else:
            return None
    except (struct.error, UnicodeDecodeError):
        return None
    text = text.strip().strip("\0")
    return text or None


def photo_transfer_curve(photo, requested: str | TransferCurve = AUTO
                         ) -> tuple[TransferCurve, str | None]:
    """The transfer curve to deblur a photo through, and a note on where it came from.

    Parameters
    ----------
    photo : gyrodeblur.imageio.Photo
        The photo as read (its ICC profile, format and bit depth are looked at).
    requested : str or TransferCurve
        ``"auto"`` (the profile's curve; sRGB without a profile), or a curve name
        (``"srgb"``, ``"linear"``) or :class:`~gyrodeblur.tonecurve.TransferCurve`, taken
        as given.

    Returns
    -------
    curve : TransferCurve
    note : str or None
        For the user, where ``"auto"`` chose something other than sRGB, or assumed sRGB
        where linear data are likely (a 16-bit or float TIFF without a profile) or the
        profile could not say; ``None`` otherwise.
    """
    if isinstance(requested, TransferCurve) or str(requested).strip().lower() != AUTO:
        try:
            return get_transfer_curve(requested), None
        except InputError as exc:
            raise exc.reworded(exc.problem.replace("(known: ", f"(known: {AUTO}, ")) from None

    where = photo.path or "the photo"
    icc = photo.icc_profile
    override = "--transfer srgb or linear sets it"
    gamma = getattr(photo, "png_gamma", None)
    if not icc and gamma:
        if abs(gamma * 2.2 - 1) <= _SRGB_FILE_GAMMA_TOLERANCE:
            return SRGB, None
        curve = _known(ParametricCurve(1 / gamma).transfer_curve())
        return curve, (f"{where}: its gAMA chunk (file gamma {gamma:.5g}) declares a "
                       f"{curve.name} transfer curve, undone for the work in linear light "
                       f"({override})")
    if not icc:
        if photo.format == "TIFF" and photo.bit_depth == 16:
            return SRGB, (f"{where}: no ICC profile: its values are taken as sRGB-encoded "
                          "(--transfer linear for linear data, e.g. from a raw converter)")
        return SRGB, None
    name = profile_description(icc)
    label = f"its ICC profile ({name!r})" if name else "its ICC profile"
    try:
        curve = profile_transfer_curve(icc)
    except ValueError as exc:
        return SRGB, (f"{where}: {label} declares no transfer curve this tool reads ({exc}): "
                      f"sRGB assumed ({override})")
    if curve is SRGB:
        return SRGB, None
    return curve, (f"{where}: {label} declares a {curve.name} transfer curve, undone for "
                   f"the work in linear light ({override})")


def said_transfer_curve(photo, requested: str | TransferCurve, say) -> TransferCurve:
    """:func:`photo_transfer_curve`'s curve, its note (if any) passed to ``say``."""
    curve, note = photo_transfer_curve(photo, requested)
    if note:
        say(note)
    return curve
