"""EXIF blocks: read from a photo file, rebuilt for a TIFF, fitted into a JPEG, and what
they say about the capture (exposure time, focal length in pixels, capture time).

A block is held as a JPEG's APP1 segment holds it: ``b"Exif\\0\\0"`` followed by a
TIFF-structured directory (:func:`_normalise_exif`). :mod:`gyrodeblur.imageio` carries it
from the photo read to the photo written; :func:`exif_capture_hints` reads the values a
capture description can start from.
"""

from __future__ import annotations

import datetime
import math
import re
import struct
import warnings
import zlib
from typing import TYPE_CHECKING

from PIL import Image

from gyrodeblur.errors import GyrodeblurWarning

if TYPE_CHECKING:
    from gyrodeblur.imageio import Photo

__all__ = ["exif_capture_hints", "orientation_tag"]

_EXIF_HEADER = b"Exif\x00\x00"
_EXIF_IFD, _GPS_IFD, _INTEROP_IFD = 0x8769, 0x8825, 0xA005
# IFD0 tags that describe the capture rather than the pixel layout; carried into TIFFs.
_IFD0_ASCII = (270, 271, 272, 305, 306, 315, 33432)  # Description, Make, Model, Software,
_ORIENTATION = 274  #                                  DateTime, Artist, Copyright
# Exif sub-IFD tags used by exif_capture_hints.
_EXPOSURE_TIME, _FOCAL_LENGTH, _FOCAL_35MM = 0x829A, 0x920A, 0xA405
_DIGITAL_ZOOM = 0xA404
_FP_XRES, _FP_UNIT = 0xA20E, 0xA210
_PIXEL_X_DIM, _PIXEL_Y_DIM = 0xA002, 0xA003
_DATETIME_ORIGINAL, _SUBSEC_ORIGINAL = 0x9003, 0x9291
_OFFSET_TIME, _OFFSET_TIME_ORIGINAL = 0x9010, 0x9011      # the zones of DateTime, and of it
_MM_PER_UNIT = {2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}  # inch, cm, and the mm/um extension
_FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)  # 43.27 mm

# Exceptions that Pillow raises for damaged or odd EXIF blocks.
_EXIF_ERRORS = (OSError, SyntaxError, ValueError, EOFError, struct.error, zlib.error,
                IndexError, KeyError, TypeError, MemoryError, RuntimeError)


def _normalise_exif(block: bytes | None) -> bytes | None:
    """EXIF block with the ``Exif\\0\\0`` header, or None when empty."""
    if not block:
        return None
    block = bytes(block)
    return block if block.startswith(_EXIF_HEADER) else _EXIF_HEADER + block


def _without_thumbnail(block: bytes | None) -> bytes | None:
    """``block`` with its second directory (IFD1: the thumbnail, a small JPEG of the photo
    as it was read, blurred) unlinked from the first, so that no viewer shows the blurred
    preview of a deblurred photo; every other byte as it was (a maker's notes keep their
    offsets). As it is where it has no thumbnail or its directory cannot be read."""
    if not block or not block.startswith(_EXIF_HEADER):
        return block
    tiff = block[len(_EXIF_HEADER):]
    fmt = {b"II": "<", b"MM": ">"}.get(tiff[:2])
    if fmt is None:
        return block
    try:
        (ifd0,) = struct.unpack_from(fmt + "I", tiff, 4)
        (entries,) = struct.unpack_from(fmt + "H", tiff, ifd0)
        link = ifd0 + 2 + 12 * entries
        (ifd1,) = struct.unpack_from(fmt + "I", tiff, link)
    except struct.error:                # a truncated directory: carried as it is
        return block
    if ifd1 == 0:
        return block
    at = len(_EXIF_HEADER) + link
    return block[:at] + b"\0\0\0\0" + block[at + 4:]


#: The largest EXIF block (``Exif\0\0`` header included) a JPEG's APP1 segment holds.
_JPEG_MAX_EXIF = 65533
#: Exif tags a JPEG's EXIF may lose when the block is too long: MakerNote, UserComment.
_BULKY_EXIF_TAGS = (0x927C, 0x9286)


def _exif_for_jpeg(block: bytes, path: str) -> bytes | None:
    """An EXIF ``block`` too long for a JPEG, without its bulky tags (a maker's notes), or
    ``None`` when that is not enough; either is warned of."""
    try:
        exif = _load_exif(block[len(_EXIF_HEADER):])
        ifd = exif.get_ifd(_EXIF_IFD)
        dropped = [t for t in _BULKY_EXIF_TAGS if t in ifd]
        for t in dropped:
            del ifd[t]
        smaller = _normalise_exif(exif.tobytes())
    except Exception:                  # a block Pillow cannot rewrite
        smaller, dropped = None, []
    if smaller is not None and dropped and len(smaller) <= _JPEG_MAX_EXIF:
        names = {0x927C: "MakerNote", 0x9286: "UserComment"}
        warnings.warn(f"{path}: the EXIF block ({len(block)} bytes) is more than a JPEG "
                      f"holds ({_JPEG_MAX_EXIF}); written without its "
                      f"{' and '.join(names[t] for t in dropped)}",
                      GyrodeblurWarning, stacklevel=3)
        return smaller
    warnings.warn(f"{path}: the EXIF block ({len(block)} bytes) is more than a JPEG holds "
                  f"({_JPEG_MAX_EXIF}); written without EXIF (a PNG or TIFF keeps it)",
                  GyrodeblurWarning, stacklevel=3)
    return None


def _pillow_exif(im: Image.Image) -> bytes | None:
    """The EXIF block of a loaded JPEG/PNG, as stored."""
    block = im.info.get("exif")
    if block:
        return block
    exif = im.getexif()  # e.g. ImageMagick's "Raw profile type exif" PNG text
    return exif.tobytes() if len(exif) else None


def _tiff_exif(im: Image.Image) -> bytes | None:
    """EXIF block rebuilt from a TIFF's descriptive tags and Exif/GPS sub-IFDs."""
    try:
        src = im.getexif()
        out = Image.Exif()
        for tag in (*_IFD0_ASCII, _ORIENTATION):
            if tag in src and not (tag == 270 and _is_layout_note(src[tag])):
                out[tag] = src[tag]
        sub = _sub_ifds(src)
        for tag, values in sub.items():
            out[tag] = values
        return out.tobytes() if len(out) else None
    except _EXIF_ERRORS:
        return None  # damaged metadata is not worth refusing the photo for


def _is_layout_note(description) -> bool:
    """Whether a TIFF ImageDescription is tifffile's note of the file's array layout
    (``{"shape": [...]}``): it describes that file, not the photo, and would misdescribe
    the output."""
    return str(description).lstrip().startswith('{"shape"')


def _sub_ifds(exif: Image.Exif) -> dict[int, dict]:
    """Exif and GPS sub-directories of ``exif`` as dicts (Interop nested in Exif)."""
    out = {}
    for tag in (_EXIF_IFD, _GPS_IFD):
        if tag not in exif:
            continue
        values = dict(exif.get_ifd(tag))
        if tag == _EXIF_IFD and _INTEROP_IFD in values:
            interop = exif.get_ifd(_INTEROP_IFD)
            if interop:
                values[_INTEROP_IFD] = dict(interop)
            else:
                del values[_INTEROP_IFD]
        if values:
            out[tag] = values
    return out


def _load_exif(block: bytes) -> Image.Exif:
    exif = Image.Exif()
    exif.load(block)
    return exif


def orientation_tag(photo: Photo) -> int:
    """The photo's EXIF orientation tag, 1-8 (1, the pixels shown as stored, where it has
    none or its EXIF cannot be read). Any other value says the pixels are stored as the
    sensor read them, and a viewer turns them for display."""
    if not photo.exif:
        return 1
    try:
        tag = _load_exif(photo.exif).get(_ORIENTATION, 1)
    except _EXIF_ERRORS:
        return 1
    return tag if isinstance(tag, int) and 1 <= tag <= 8 else 1


def exif_capture_hints(photo: Photo) -> dict:
    """Exposure time and focal length in pixels from a photo's EXIF block.

    Parameters
    ----------
    photo : Photo
        A photo from :func:`read_photo` (or any with ``exif`` set).

    Returns
    -------
    dict
        Keys present only when found:

        ``"exposure_time"`` : float
            Seconds, from ExposureTime.
        ``"focal_length_mm"`` : float
            The lens's real focal length, from FocalLength.
        ``"fx"`` : float
            Focal length in pixels at this photo's stored width and height.
        ``"digital_zoom"`` : float
            DigitalZoomRatio, where above 1: the camera enlarged a central part of its
            sensor's image to the stored size, so the photo holds detail only up to
            ``1 / digital_zoom`` of its pixel grid's band (or, where the sensor has more
            pixels than the photo, somewhat more).
        ``"capture_time_unix"`` : float
            When the photo was taken, Unix time (s), from DateTimeOriginal,
            OffsetTimeOriginal or else OffsetTime (the time zone: without one there is
            no Unix time) and SubSecTimeOriginal (fractions of a second; without it, the
            middle of the second). A phone writes it to the
            millisecond but it marks the exposure only to tens or hundreds of them.
        ``"capture_time_whole_second"`` : bool
            Present (True) where there was no SubSecTimeOriginal.
        ``"capture_time_text"`` : str
            DateTimeOriginal as written, with its zone and fraction where present
            (``"2024:12:05 07:27:10.512 +01:00"``).
        ``"unreadable"`` : dict
            ``"exposure_time"`` and ``"capture_time"`` where the photo has the tag but its
            value cannot be read as one (a negative ExposureTime, a DateTimeOriginal not
            in EXIF's ``YYYY:MM:DD HH:MM:SS`` form): the tag and the value as written,
            for a message.

    Notes
    -----
    ``fx`` comes from the first source that is present and valid:

    1. FocalLengthIn35mmFilm :math:`f_{35}` with the **diagonal** convention (the usual
       crop-factor definition): the photo's diagonal corresponds to the 43.27 mm
       diagonal of 36 x 24 mm film, so

       .. math:: f_x = f_{35} \\, \\sqrt{W^2 + H^2} \\, / \\, 43.27\\,\\mathrm{mm}.

       For a 3:2 landscape photo this equals :math:`f_{35} W / 36\\,\\mathrm{mm}`; unlike
       that width rule it also holds for 4:3 sensors and for portrait photos.
    2. FocalLength :math:`f` (mm) and FocalPlaneXResolution :math:`r` (pixels per
       FocalPlaneResolutionUnit: 2 = inch, 3 = cm, and 4 = mm, 5 = um as some cameras
       write): :math:`f_x = f \\, r / \\mathrm{mm\\_per\\_unit}`, scaled by
       :math:`\\max(W, H) / \\max(X, Y)` when PixelXDimension/PixelYDimension
       (:math:`X, Y`) record a different size (a resized photo).

    Square pixels are assumed (``fy == fx``). A damaged EXIF block gives ``{}``.
    """
    if not photo.exif:
        return {}
    try:
        exif = _load_exif(photo.exif)
        ifd0 = dict(exif)
        sub = dict(exif.get_ifd(_EXIF_IFD))
    except _EXIF_ERRORS:
        return {}

    def number(tag):
        value = sub.get(tag, ifd0.get(tag))
        if isinstance(value, tuple):
            value = value[0] if value else None
        try:
            value = float(value)
        except (TypeError, ValueError, ZeroDivisionError):
            return None
        return value if math.isfinite(value) and value > 0 else None

    hints: dict = {}
    exposure, focal = number(_EXPOSURE_TIME), number(_FOCAL_LENGTH)
    unreadable = {}                  # present, and neither a value nor "unknown" (0)
    written = _as_written(sub.get(_EXPOSURE_TIME, ifd0.get(_EXPOSURE_TIME)))
    if exposure is None and written not in ("", "0", "nan"):
        unreadable["exposure_time"] = f"ExposureTime {written}"
    zoom = number(_DIGITAL_ZOOM)        # 0/0 or 0/1: no digital zoom
    if zoom is not None and zoom > 1:
        hints["digital_zoom"] = zoom
    if exposure is not None:
        hints["exposure_time"] = exposure
    if focal is not None:
        hints["focal_length_mm"] = focal
    height, width = photo.pixels.shape[:2]
    f35 = number(_FOCAL_35MM)
    xres, unit = number(_FP_XRES), number(_FP_UNIT)
    if f35 is not None:
        hints["fx"] = f35 * math.hypot(width, height) / _FULL_FRAME_DIAGONAL_MM
    elif focal is not None and xres is not None and int(unit or 2) in _MM_PER_UNIT:
        fx = focal * xres / _MM_PER_UNIT[int(unit or 2)]
        px, py = number(_PIXEL_X_DIM), number(_PIXEL_Y_DIM)
        if px is not None and py is not None:
            fx *= max(width, height) / max(px, py)
        hints["fx"] = fx
    hints.update(_capture_time(sub, ifd0))
    written = _as_written(sub.get(_DATETIME_ORIGINAL, ifd0.get(_DATETIME_ORIGINAL)))
    if "capture_time_text" not in hints and re.search("[1-9]", written):  # not "0000:00:00"
        unreadable["capture_time"] = f"DateTimeOriginal {written}"
    if unreadable:
        hints["unreadable"] = unreadable
    return hints


def _as_written(value) -> str:
    """An EXIF value for a message: text quoted, a number (or a rational) as a float;
    ``""`` for none."""
    if isinstance(value, tuple):
        value = value[0] if value else None
    if value is None:
        return ""
    if isinstance(value, bytes):
        value = value.decode("ascii", "replace")
    if isinstance(value, str):
        return repr(value.strip().strip("\x00"))
    try:
        return f"{float(value):g}"
    except (TypeError, ValueError, ZeroDivisionError):
        return repr(value)[:40]


#: A time zone as EXIF's OffsetTime tags write it (``+01:00``; ``+0100``, ``+01`` and ``Z``
#: read too).
_ZONE = r"Z|[+-][0-9]{2}(:?[0-9]{2})?"


def _capture_time(sub: dict, ifd0: dict) -> dict:
    """``capture_time_unix`` and ``capture_time_text`` of :func:`exif_capture_hints` from
    the Exif sub-IFD (or IFD0) tags; ``{}`` without a readable DateTimeOriginal. The zone
    is OffsetTimeOriginal's, else (where that is missing or blank) OffsetTime's (the
    file's, which phones write alike)."""
    def text(tag):
        v = sub.get(tag, ifd0.get(tag))
        if isinstance(v, bytes):
            v = v.decode("ascii", "replace")
        return v.strip().strip("\x00").strip() if isinstance(v, str) else None

    stamp, frac = text(_DATETIME_ORIGINAL), text(_SUBSEC_ORIGINAL)
    zone = next((z for z in (text(_OFFSET_TIME_ORIGINAL), text(_OFFSET_TIME))
                 if z and re.fullmatch(_ZONE, z)), None)    # not "   :  " (unknown)
    try:
        local = datetime.datetime.strptime(stamp or "", "%Y:%m:%d %H:%M:%S")
    except ValueError:
        return {}
    frac = frac if frac and re.fullmatch("[0-9]+", frac) else None
    out = {"capture_time_text": stamp + (f".{frac}" if frac else "") + (f" {zone}" if zone else "")}
    if zone and re.fullmatch(r"[+-][0-9]{2}", zone):
        zone += ":00"                          # whole hours written short
    try:
        tz = datetime.datetime.strptime(zone or "", "%z").tzinfo
    except ValueError:
        return out                             # a local time of no known zone
    # without SubSecTimeOriginal the time is the whole second it fell in: its middle
    out["capture_time_unix"] = (local.replace(tzinfo=tz).timestamp()
                                + (float("0." + frac) if frac else 0.5))
    if not frac:
        out["capture_time_whole_second"] = True
    return out
