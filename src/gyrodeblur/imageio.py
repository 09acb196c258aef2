"""Reading and writing photos: JPEG, PNG and TIFF, 8 or 16 bits, with EXIF and ICC.

Inside the library an image is a float32 array in ``[0, 1]`` of shape ``(H, W)`` (grey)
or ``(H, W, C)`` with ``C`` = 3 (RGB) or 4 (RGBA); 8- and 16-bit integers exist only at
the file boundary. :func:`read_photo` returns a :class:`Photo` that also remembers the
stored bit depth, the format and the metadata, so that :func:`write_photo` can give the
result the input's bit depth, EXIF block and ICC profile (``like=photo``).

Conventions
-----------
* Pixels are kept **as stored**: the EXIF Orientation tag is *not* applied (the camera's
  sensor axes, which the gyro log refers to, are the stored axes). The EXIF block, and
  with it the Orientation tag, is carried to the output, so viewers still rotate it.
* Grey+alpha is returned as RGBA (grey copied to R, G, B); alpha is passed through as a
  4th channel, untouched (not premultiplied, not used). Palette images become RGB, or RGBA
  when the palette has transparency; 1-bit images become 8-bit grey. PNG colour-key
  transparency (``tRNS`` on grey/RGB images) is ignored.
* Floating-point TIFFs are accepted: samples are clipped to ``[0, 1]`` (NaN -> 0, with a
  warning when any is outside) and ``bit_depth`` is reported as 16, so a ``like=`` output
  keeps the most precision. Samples far outside, which ``deblur()`` would refuse in an
  array, are refused where they are no photo's light: most of them above 1 and some above 2
  (0-255 values), or more than 1 % below -0.25 (an offset or negated image).
  CMYK, Lab, signed and 32-bit integer images are refused.
* Only the first frame of a multi-page TIFF or animated PNG is read (with a warning; the
  preview frames of an MPO JPEG are skipped silently).
* ``Photo.exif`` is the EXIF block as a JPEG APP1 segment holds it: ``b"Exif\\0\\0"``
  followed by a TIFF-structured directory. From JPEG and PNG it is the file's own block,
  byte for byte. TIFF files keep EXIF in their own tags, so for TIFF the block is
  rebuilt from the descriptive IFD0 tags (Make, Model, Orientation, ...) and the Exif and
  GPS sub-directories (:mod:`gyrodeblur.exif`).
* The print resolution (``Photo.dpi``: a JPEG's JFIF density, a PNG's ``pHYs``, a TIFF's
  X/YResolution, where given in inches or centimetres), XMP (``Photo.xmp``: a JPEG's APP1
  XMP packet, a TIFF's tag 700) and a PNG's text chunks (``Photo.png_text``: title,
  author, copyright, a PNG's XMP ...) are carried too. IPTC is not.
* A PNG's ``gAMA`` chunk (the file gamma, how the values were encoded) is kept in
  ``Photo.png_gamma`` unless an ``sRGB`` chunk says the file is sRGB; the transfer curve
  is read from it where no ICC profile says otherwise (:mod:`gyrodeblur.icc`).

Writing: JPEG stores EXIF (APP1), XMP (APP1) and ICC (APP2); PNG stores ``eXIf``,
``iCCP``, the input's ``gAMA`` and text chunks (XMP as ``XML:com.adobe.xmp``); TIFF
stores the ICC profile (tag 34675), XMP (tag 700) and EXIF as IFD0 tags plus Exif/GPS
sub-IFDs; each stores the print resolution. PNG and TIFF are compressed at zlib level
:data:`~gyrodeblur.pngwrite.DEFLATE_LEVEL` (3: a third of level 6's time, a little larger).
Values are clipped to ``[0, 1]`` and rounded to the nearest integer. Files are written to a
temporary file in the destination folder and moved into place
(:mod:`gyrodeblur.atomicfile`).

Decoders: JPEG and PNG are read with Pillow. Pillow cannot hold 16-bit colour, so
16-bit RGB(A) PNGs are read by letting Pillow's decoder run twice, once keeping the high
and once the low byte of each sample (exact; interlaced files included), and written by
a small numpy + zlib encoder (all 16-bit PNGs; 8-bit PNGs go through Pillow; both in
:mod:`gyrodeblur.pngwrite`). TIFFs are written with :mod:`tifffile` (Deflate, horizontal
predictor) and read with it; what it cannot decode (LZW or JPEG compression without
``imagecodecs``, palette images...) falls back to Pillow/libtiff, with the same two-pass
trick for 16-bit colour and with the rotation Pillow applies to TIFFs undone.
"""

from __future__ import annotations

import logging
import math
import os
import re
import struct
import sys
import warnings
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import tifffile
from PIL import Image, TiffImagePlugin, UnidentifiedImageError

from gyrodeblur.arguments import is_whole
from gyrodeblur.atomicfile import atomic_write, check_folder_of, check_writable
from gyrodeblur.errors import GyrodeblurWarning, InputError
from gyrodeblur.exif import (_EXIF_ERRORS, _EXIF_IFD, _GPS_IFD, _IFD0_ASCII, _JPEG_MAX_EXIF,
                             _ORIENTATION, _exif_for_jpeg, _load_exif, _normalise_exif,
                             _pillow_exif, _sub_ifds, _tiff_exif, _without_thumbnail,
                             exif_capture_hints)
from gyrodeblur.icc import profile_damage
from gyrodeblur.images import PHOTO_MAX, PHOTO_MIN
from gyrodeblur.pngwrite import _PNG_XMP_KEY, DEFLATE_LEVEL, _write_png

__all__ = ["Photo", "read_photo", "write_photo", "check_destination", "exif_capture_hints",
           "EXTENSIONS"]

#: File extensions :func:`write_photo` understands, and the format each one selects.
EXTENSIONS: dict[str, str] = {
    ".jpg": "JPEG",
    ".jpeg": "JPEG",
    ".png": "PNG",
    ".tif": "TIFF",
    ".tiff": "TIFF",
}

# Exceptions that Pillow, tifffile and zlib raise for damaged or odd files.
_DECODE_ERRORS = _EXIF_ERRORS + (tifffile.TiffFileError,)


@dataclass(frozen=True, eq=False)
class Photo:
    """A photo as read from a file: float pixels plus what is needed to write it back.

    Parameters
    ----------
    pixels : ndarray of float32, shape (H, W) or (H, W, C)
        Values in ``[0, 1]``; ``C`` is 3 (RGB) or 4 (RGBA, alpha untouched).
    bit_depth : int
        8 or 16, the bits per sample stored in the file (16 for float TIFFs).
    format : str
        ``"JPEG"``, ``"PNG"`` or ``"TIFF"``.
    path : str or None
        The file it was read from.
    exif : bytes or None
        EXIF block, ``b"Exif\\0\\0"`` + TIFF-structured data (see the module notes).
    icc_profile : bytes or None
        Embedded ICC colour profile, unchanged.
    quantization : dict or None
        A JPEG's quantisation tables as stored (table id -> 64 steps in 8-bit levels,
        zigzag order; 0 is the luma table), else ``None``. The compression's error and
        the noise it removed depend on them (:func:`gyrodeblur.noise.photo_noise_sigma`).
    png_gamma : float or None
        A PNG's file gamma (its ``gAMA`` chunk: encoded = linear ** ``png_gamma``, e.g.
        1.0 for linear data, 0.45455 as written beside sRGB), where it has no ``sRGB``
        chunk; else ``None``.
    grey_alpha : bool
        The file holds grey and alpha: ``pixels`` are RGBA with R = G = B, and
        :func:`write_photo` with ``like`` this photo writes grey and alpha again.
    dpi : (float, float) or None
        Print resolution, pixels per inch (x, y), where the file states one in inches or
        centimetres; else ``None``.
    xmp : bytes or None
        A JPEG's or TIFF's XMP packet, unchanged (a PNG's is one of ``png_text``).
    png_text : dict or None
        A PNG's text chunks (``tEXt``, ``zTXt``, ``iTXt``), keyword -> text.

    Notes
    -----
    Equality is identity (``eq=False``): comparing pixel arrays element-wise is rarely
    what ``==`` on photos should mean, and it keeps the instances hashable.
    """

    pixels: np.ndarray
    bit_depth: int
    format: str
    path: str | None = None
    exif: bytes | None = None
    icc_profile: bytes | None = None
    quantization: dict | None = None
    png_gamma: float | None = None
    grey_alpha: bool = False
    dpi: tuple[float, float] | None = None
    xmp: bytes | None = None
    png_text: dict | None = None

    @property
    def stored_channels(self) -> np.ndarray:
        """``pixels`` with the channels the file stores: grey + alpha as ``(H, W, 2)``
        (the work of one channel, not three equal ones), else ``pixels`` itself.
        :func:`write_photo` with ``like`` this photo takes either."""
        if self.grey_alpha and self.pixels.ndim == 3 and self.pixels.shape[2] == 4:
            return self.pixels[..., [0, 3]]
        return self.pixels

    def __post_init__(self):
        if self.bit_depth not in (8, 16):
            raise ValueError(f"bit_depth must be 8 or 16, not {self.bit_depth!r}")
        if self.format not in ("JPEG", "PNG", "TIFF"):
            raise ValueError(f"format must be JPEG, PNG or TIFF, not {self.format!r}")


# --------------------------------------------------------------------------- reading


def read_photo(path: str | os.PathLike, *, scene: bool = False) -> Photo:
    """Read a JPEG, PNG or TIFF photo (8 or 16 bits) into float32 pixels in ``[0, 1]``.

    Parameters
    ----------
    path : str or os.PathLike
        The file. The format is found from the content, not the extension.
    scene : bool
        Read a scene to blur (:func:`gyrodeblur.simulate.simulate_blur`) rather than a
        photo: a float TIFF's samples above 1 are kept, as light brighter than the clip
        level (white = 1), rather than clipped with a warning.

    Returns
    -------
    Photo
        Pixels as stored (EXIF orientation not applied), the stored bit depth, the
        format, and the EXIF block and ICC profile for :func:`write_photo`.

    Raises
    ------
    InputError
        The file is missing, is not a JPEG/PNG/TIFF image, is damaged or truncated, or
        holds a colour mode this library does not handle (CMYK, Lab, 32-bit integer), or
        float samples far outside ``[0, 1]`` (module notes).
    """
    p = os.fspath(path)
    if not os.path.exists(p):
        raise InputError(p, "file not found")
    if os.path.isdir(p):
        raise InputError(p, "is a folder, not an image file")
    _refuse_other_kinds(p)
    try:
        fmt, ints, exif, icc, tables, gamma, carried = _decode(p)
    except InputError:
        raise
    except PermissionError:
        raise InputError(p, "cannot read the file: permission denied") from None
    except UnidentifiedImageError:
        if os.path.getsize(p) == 0:
            raise InputError(p, "the file is empty (0 bytes)") from None
        raise InputError(p, "not a JPEG, PNG or TIFF image (or the file is damaged)") from None
    except Image.DecompressionBombError as exc:
        raise InputError(p, f"image too large to read safely ({exc})") from None
    except _DECODE_ERRORS as exc:
        raise InputError(p, f"cannot decode the image ({_reason(exc)})") from None
    grey_alpha = ints.ndim == 3 and ints.shape[2] == 2
    if grey_alpha:                  # the grey copied to R, G and B: one layout for colour
        ints = _grey_alpha_to_rgba(ints)
    pixels, bit_depth = _to_float(p, ints, keep_bright=scene)
    return Photo(pixels=pixels, bit_depth=bit_depth, format=fmt, path=p,
                 exif=_normalise_exif(exif), icc_profile=icc or None, quantization=tables,
                 png_gamma=gamma, grey_alpha=grey_alpha, **carried)


#: Most pixels a photo may have (Pillow's own guard, 89 MP with a warning and 179 MP
#: refused as a "decompression bomb", is below the 108 and 200 MP of phone sensors).
MAX_PHOTO_PIXELS = 400_000_000


def _open_within_size_limit(p: str) -> Image.Image:
    """``Image.open(p)`` with :data:`MAX_PHOTO_PIXELS` as the size limit (checked on the
    header, before any pixel is decoded) instead of Pillow's."""
    limit = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None          # for this open only (it checks the header)
    try:
        im = Image.open(p)
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    try:
        _refuse_too_many_pixels(p, *im.size)
    except InputError:
        im.close()
        raise
    return im


def _refuse_too_many_pixels(p: str, width: int, height: int) -> None:
    """:class:`InputError` for a header that declares more than :data:`MAX_PHOTO_PIXELS`."""
    if width * height > MAX_PHOTO_PIXELS:
        raise InputError(p, f"{width}x{height} pixels ({width * height / 1e6:.0f} MP) is more "
                            f"than the {MAX_PHOTO_PIXELS / 1e6:.0f} MP this tool reads (a damaged "
                            "file, or one made to exhaust memory?)")


def _decode(p: str) -> tuple[str, np.ndarray, bytes | None, bytes | None, dict | None,
                             float | None, dict]:
    """(format, samples, EXIF block, ICC profile, JPEG quantisation tables, PNG file
    gamma, the other metadata carried: :class:`Photo`'s ``dpi``, ``xmp`` and
    ``png_text``) of a file; decoder errors propagate."""
    tiff = _is_tiff(p)
    if tiff:
        _refuse_truncated_tiff(p)            # before Pillow reads tags past the end
    try:
        im = _open_within_size_limit(p)
    except UnidentifiedImageError:
        if not tiff:
            raise
        try:                                 # e.g. float RGB, which Pillow cannot open
            ints, icc, carried = _read_tiff_tifffile(p)
        except Exception as exc:
            raise _codec_missing(p, exc) or exc
        return "TIFF", ints, None, icc, None, None, carried
    with im:
        fmt = {"MPO": "JPEG"}.get(im.format, im.format)
        if fmt not in ("JPEG", "PNG", "TIFF"):
            raise InputError(p, f"{im.format} images are not supported; use JPEG, PNG or TIFF")
        if fmt == "TIFF":
            _refuse_raw_or_preview(p, dict(im.tag_v2))
            exif, icc = _tiff_exif(im), im.info.get("icc_profile")
            ints = _read_tiff_pixels(p, im)
        else:
            frames = int(getattr(im, "n_frames", 1))
            if fmt == "PNG" and frames > 1:
                warnings.warn(f"{p}: an animated PNG; only the first of its {frames} frames "
                              "is read", GyrodeblurWarning, stacklevel=2)
            ints = _read_pillow_pixels(p, im)
            exif, icc = _pillow_exif(im), im.info.get("icc_profile")
        try:
            carried = _carried_metadata(im, fmt)
        except _DECODE_ERRORS:          # e.g. a damaged text chunk: the photo without it
            carried = {}
    tables = None
    if fmt == "JPEG" and getattr(im, "quantization", None):
        tables = {int(k): [int(q) for q in v] for k, v in im.quantization.items()}
    gamma = None
    if fmt == "PNG" and "srgb" not in im.info:
        g = im.info.get("gamma")
        gamma = float(g) if isinstance(g, (int, float)) and 0 < g < 10 else None
    return fmt, ints, exif, icc, tables, gamma, carried


#: ImageMagick's PNG text chunks for what :func:`write_photo` writes in their own chunks
#: (``eXIf``, ``iCCP``): not carried as text, where they could contradict them.
_RAW_PROFILES_WRITTEN = ("raw profile type exif", "raw profile type app1",
                         "raw profile type icc", "raw profile type icm")


def _carried_metadata(im: Image.Image, fmt: str) -> dict:
    """The metadata :func:`write_photo` carries beside EXIF and ICC, as :class:`Photo`'s
    ``dpi``, ``xmp`` and ``png_text`` (after the pixels are read: a PNG's text chunks
    may follow them). Only what the file states: not Pillow's fallbacks (1 dpi for a
    TIFF without resolution tags, 72 for a JPEG whose JFIF density is an aspect ratio);
    what is malformed is left out."""
    if fmt == "PNG":
        dpi = im.info.get("dpi")                 # from pHYs only where given per metre
    elif fmt == "TIFF":
        dpi = _dpi_of_tags(dict(im.tag_v2))
    elif im.info.get("jfif_unit") in (1, 2):     # JFIF's density per inch or per cm
        dpi = [float(v) * (2.54 if im.info["jfif_unit"] == 2 else 1.0)
               for v in im.info.get("jfif_density", ())]
    else:                                        # an aspect ratio: the EXIF's, if any
        dpi = _dpi_of_tags(dict(im.getexif()))
    if fmt != "PNG":                             # a PNG's XMP is one of its text chunks
        return _checked_dpi_and_xmp(dpi, im.tag_v2.get(700) if fmt == "TIFF"
                                    else im.info.get("xmp"))
    carried = _checked_dpi_and_xmp(dpi)
    text = {str(k): v for k, v in dict(getattr(im, "text", None) or {}).items()
            if isinstance(v, str) and str(k).lower() not in _RAW_PROFILES_WRITTEN}
    if text:
        carried["png_text"] = text
    return carried


def _checked_dpi_and_xmp(dpi=None, xmp=None) -> dict:
    """``{"dpi": ..., "xmp": ...}`` as :class:`Photo` carries them, each checked
    (:func:`_checked_dpi`, :func:`_xmp_bytes`) and left out where nothing usable is left."""
    checked = {"dpi": _checked_dpi(dpi), "xmp": _xmp_bytes(xmp)}
    return {k: v for k, v in checked.items() if v}


def _dpi_of_tags(tags: dict):
    """(x, y) pixels per inch from TIFF or EXIF IFD0 tags (X/YResolution, 282/283, as
    numbers or (numerator, denominator); ResolutionUnit 296: 2 inch, the default, or 3
    cm), or ``None`` where either is missing or the unit is none."""
    def number(v):
        if isinstance(v, (tuple, list)) and len(v) == 2:
            return float(v[0]) / float(v[1]) if float(v[1]) else float("nan")
        return float(v)

    unit = tags.get(296, 2)
    if 282 not in tags or 283 not in tags or unit not in (2, 3):
        return None
    try:
        return [number(tags[k]) * (2.54 if unit == 3 else 1.0) for k in (282, 283)]
    except (TypeError, ValueError, ZeroDivisionError):
        return None


def _checked_dpi(dpi) -> tuple[float, float] | None:
    """``dpi`` as two floats, a value within 0.02 of a whole number of at least 1 made
    whole (a PNG stores whole pixels per metre: 300 dpi reads back as 299.9994), or
    ``None`` where it is not two numbers from 1 pixel per metre to a million per inch."""
    try:
        x, y = (float(v) for v in dpi)
    except (TypeError, ValueError):
        return None
    out = tuple(float(round(v)) if math.isfinite(v) and round(v) >= 1
                and abs(v - round(v)) < 0.02 else v for v in (x, y))
    return out if all(math.isfinite(v) and 0.0254 <= v <= 1e6 for v in out) else None


def _xmp_bytes(value) -> bytes | None:
    """An XMP packet as bytes (Pillow gives a TIFF's tag 700 as bytes, a tuple of
    integers or text), or ``None``."""
    if isinstance(value, str):
        value = value.encode("utf-8")
    elif isinstance(value, (tuple, list, np.ndarray)):
        try:
            value = bytes(bytearray(int(b) for b in value))
        except (TypeError, ValueError):
            return None
    return bytes(value) if isinstance(value, (bytes, bytearray)) and value else None


#: ISO base media file brands (bytes 8-12 after ``ftyp``) of formats read elsewhere, and
#: what to call them: an iPhone saves HEIC by default, a Canon camera its raw as CR3.
_MEDIA_BRANDS = {**dict.fromkeys((b"heic", b"heix", b"hevc", b"hevx", b"heim", b"heis",
                                  b"mif1", b"msf1"), "a HEIF/HEIC image"),
                 b"avif": "an AVIF image", b"avis": "an AVIF image",
                 b"crx ": "a Canon CR3 raw file"}
#: First bytes of camera raw formats (a CR2 is a little-endian TIFF marked ``CR`` 2 at
#: byte 8).
_RAW_MAGIC = ((b"IIRO", "an Olympus ORF raw file"), (b"IIRS", "an Olympus ORF raw file"),
              (b"MMOR", "an Olympus ORF raw file"), (b"IIU\x00", "a Panasonic RW2 raw file"),
              (b"FUJIFILMCCD-RAW", "a Fujifilm RAF raw file"),
              (b"II*\x00\x10\x00\x00\x00CR\x02", "a Canon CR2 raw file"))
_DEVELOP = ("develop it to a JPEG, PNG or 16-bit TIFF at full size (demosaiced, not resized "
            "or cropped), keeping its EXIF")


def _refuse_other_kinds(p: str) -> None:
    """Refuse, by its first bytes, a photo of a kind this tool does not read but can name
    (HEIC, AVIF, camera raw), with what to do; others go on to the decoders."""
    try:
        with open(p, "rb") as f:
            head = f.read(16)
    except OSError:
        return                                 # the decoder says what is wrong
    kind = _MEDIA_BRANDS.get(head[8:12]) if head[4:8] == b"ftyp" else None
    kind = kind or next((k for magic, k in _RAW_MAGIC if head.startswith(magic)), None)
    if kind is None:
        return
    what = (_DEVELOP if "raw" in kind else
            "convert it (on an iPhone: Settings > Camera > Formats > Most Compatible takes "
            "JPEGs) to a JPEG, PNG or 16-bit TIFF at full size, keeping its EXIF")
    raise InputError(p, f"{kind}, which this tool does not read: {what}")


#: TIFF tags of camera raw files and previews: DNGVersion, NewSubfileType and
#: PhotometricInterpretation (its CFA and LinearRaw values).
_DNG_VERSION, _NEW_SUBFILE_TYPE, _PHOTOMETRIC = 50706, 254, 262
_RAW_PHOTOMETRIC = {32803: "colour-filter-array", 34892: "linear raw"}


def _refuse_raw_or_preview(p: str, tags: dict) -> None:
    """Refuse a TIFF-structured file whose first image is not the photo: a DNG or another
    TIFF-based camera raw (NEF, CR2, ARW...), whose first image is a small preview or the
    sensor's undemosaiced data. ``tags`` maps the first image's tag codes to values."""
    def first(v):
        return v[0] if isinstance(v, (tuple, list)) and v else v

    if _DNG_VERSION in tags:
        raise InputError(p, f"a DNG (camera raw) file, which this tool does not read: {_DEVELOP}")
    raw = _RAW_PHOTOMETRIC.get(int(first(tags.get(_PHOTOMETRIC, 0)) or 0))
    if raw is not None:
        raise InputError(p, f"camera raw data ({raw}), which this tool does not read: {_DEVELOP}")
    if int(first(tags.get(_NEW_SUBFILE_TYPE, 0)) or 0) & 1:
        raise InputError(p, "its first image is a reduced-resolution preview, not the photo "
                            f"(a camera raw file?): {_DEVELOP}")


def _reason(exc: BaseException) -> str:
    """One-line description of a decoder exception."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


def _is_tiff(path: str) -> bool:
    with open(path, "rb") as f:
        return f.read(4) in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


def _rawmode(im: Image.Image) -> str:
    """The rawmode of the first decoder tile (before ``load``), or ``""``."""
    if not im.tile:
        return ""
    args = im.tile[0][3]
    return args if isinstance(args, str) else str(args[0])


def _read_pillow_pixels(path: str, im: Image.Image) -> np.ndarray:
    """Integer (or float) array of a JPEG/PNG opened by Pillow, colour normalised."""
    raw = _rawmode(im)
    if im.format == "PNG" and raw in ("RGB;16B", "RGBA;16B"):
        return _pillow_16bit_colour(path, im)
    if im.format == "PNG" and raw == "LA;16B":
        return _pillow_png16_grey_alpha(im)
    im.load()
    return _pillow_to_array(path, im)


def _pillow_to_array(path: str, im: Image.Image) -> np.ndarray:
    """Array of a loaded Pillow image of an 8-bit, 16-bit grey or float mode."""
    mode = im.mode
    if mode == "1":
        im = im.convert("L")
    elif mode in ("P", "PA"):
        keep_alpha = mode == "PA" or "transparency" in im.info
        im = im.convert("RGBA" if keep_alpha else "RGB")
    elif mode in ("RGBX", "YCbCr"):
        im = im.convert("RGB")
    elif mode == "RGBa":
        im = im.convert("RGBA")
    elif mode == "La":
        im = im.convert("LA")
    elif mode == "I" and im.format == "PNG":  # 16-bit grey in older Pillow
        return np.asarray(im).astype(np.uint16)
    elif mode not in ("L", "LA", "RGB", "RGBA", "I;16", "I;16L", "I;16B", "I;16N", "F"):
        raise InputError(path, f"unsupported colour mode {mode}; convert to RGB or grey first")
    arr = np.asarray(im)
    if arr.dtype.kind == "u" and arr.dtype.itemsize == 2:
        arr = arr.astype(np.uint16)  # native byte order
    return arr


def _load_as_stored(im: Image.Image) -> int:
    """Load a Pillow image; return the EXIF orientation Pillow applied while loading.

    Pillow rotates/flips TIFFs by their Orientation tag on load (and then drops the
    tag); JPEG and PNG are loaded as stored. The returned value (1: nothing applied) is
    for :func:`_unorient`.
    """
    before = im.tag_v2.get(_ORIENTATION, 1) if im.format == "TIFF" else 1
    im.load()
    if im.format == "TIFF" and before in range(2, 9) and _ORIENTATION not in im.tag_v2:
        return int(before)
    return 1


def _unorient(arr: np.ndarray, orientation: int) -> np.ndarray:
    """Undo the transpose that EXIF ``orientation`` (1-8) asks a viewer to apply."""
    undo = {
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1],
        5: lambda a: a.swapaxes(0, 1),
        6: lambda a: np.rot90(a, 1),
        7: lambda a: a[::-1, ::-1].swapaxes(0, 1),
        8: lambda a: np.rot90(a, -1),
    }.get(orientation)
    return arr if undo is None else np.ascontiguousarray(undo(arr))


def _grey_alpha_to_rgba(arr: np.ndarray) -> np.ndarray:
    return arr[..., [0, 0, 0, 1]]


def _tile_with_rawmode(tile, rawmode: str):
    """Copy of a Pillow decoder tile with another rawmode."""
    args = tile[3]
    args = rawmode if isinstance(args, str) else (rawmode, *tuple(args)[1:])
    if hasattr(tile, "_replace"):
        return tile._replace(args=args)
    return (tile[0], tile[1], tile[2], args)


def _other_byte(rawmode: str) -> str:
    """Rawmode that picks the other byte of each 16-bit sample (``X;16B`` <-> ``X;16L``)."""
    if rawmode.endswith(";16N"):
        rawmode = rawmode[:-1] + ("L" if sys.byteorder == "little" else "B")
    swap = {";16B": ";16L", ";16L": ";16B"}
    if rawmode[-4:] not in swap:
        raise ValueError(f"no 16-bit rawmode: {rawmode}")
    return rawmode[:-4] + swap[rawmode[-4:]]


def _pillow_16bit_colour(path: str, im: Image.Image) -> np.ndarray:
    """Exact 16-bit RGB(A) samples from Pillow, which itself keeps only the high byte.

    Pillow unpacks a 16-bit colour sample with a rawmode such as ``RGB;16B`` that keeps
    one byte of it. Decoding a second time with the mirror rawmode (``RGB;16L``) keeps
    the other byte; the decompression, PNG unfiltering and TIFF predictor run before
    unpacking, so the two passes see the same bytes. Works for PNG (interlaced too) and
    for chunky (planar configuration 1) TIFF, raw or through libtiff.

    ``im`` is ``path`` opened and not yet loaded; it is loaded here (the first pass), so
    its ``info`` is complete afterwards.
    """
    def rawmode(t) -> str:
        return t[3] if isinstance(t[3], str) else t[3][0]

    # premultiplied colours (``RGBa``) are read as they are stored: Pillow would divide
    # each byte by its alpha on its own, which scrambles the two halves; the whole
    # 16-bit samples are divided below
    premultiplied = any(rawmode(t).startswith("RGBa") for t in im.tile)
    if premultiplied:
        im.tile = [_tile_with_rawmode(t, rawmode(t).replace("RGBa", "RGBA", 1))
                   for t in im.tile]
    other = [_tile_with_rawmode(t, _other_byte(rawmode(t))) for t in im.tile]
    orientation = _load_as_stored(im)
    high = np.asarray(im).astype(np.uint16)
    with Image.open(path) as second:
        second.tile = other
        second.load()
        low = np.asarray(second).astype(np.uint16)
    arr = _unorient((high << 8) | low, orientation)
    return _with_plain_alpha(arr, [1]) if premultiplied else arr


def _pillow_png16_grey_alpha(im: Image.Image) -> np.ndarray:
    """16-bit grey+alpha PNG as (H, W, 2) uint16 (Pillow would keep 8 bits).

    The 4 bytes of a pixel (grey and alpha, big-endian) are decoded unchanged with the
    identity rawmode ``RGBA``, which has the same 4-byte pixel stride as ``LA;16B``.
    ``im`` is the opened PNG, not yet loaded.
    """
    im.tile = [_tile_with_rawmode(t, "RGBA") for t in im.tile]
    im.load()
    b = np.asarray(im).astype(np.uint16)
    return np.stack([(b[..., 0] << 8) | b[..., 1], (b[..., 2] << 8) | b[..., 3]], axis=-1)


def _read_tiff_pixels(path: str, im: Image.Image) -> np.ndarray:
    """Pixels of a TIFF that Pillow opened (for its tags), as stored.

    tifffile decodes first: it never applies the Orientation tag, and Pillow's own
    handling of that tag is unreliable (uncompressed grey TIFFs with orientation 5-8
    come out scrambled in Pillow 13). Pillow decodes what tifffile cannot (LZW or JPEG
    compression without ``imagecodecs``, palette, min-is-white...), and its rotation is
    undone.
    """
    try:
        return _read_tiff_tifffile(path)[0]
    except GyrodeblurWarning:            # a warning made an error: not a decoder's failure
        raise
    except Exception as exc:
        tifffile_error = exc
    try:
        return _read_tiff_by_pillow(path, im, tifffile_error)
    except InputError:                   # what Pillow's path refuses, imagecodecs or not
        raise
    except Exception as exc:
        refusal = _codec_missing(path, tifffile_error)
        if refusal is None:
            raise
        raise refusal from exc


#: Bytes per value of each TIFF field type (TIFF 6.0 and BigTIFF).
_TIFF_TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8,
                    13: 4, 16: 8, 17: 8, 18: 8}


def _refuse_truncated_tiff(path: str) -> None:
    """Refuse a TIFF cut short (a copy or download interrupted), saying so: one whose
    header, first directory (its tags, which a writer may put after the pixels), a value one of
    its tags points to (an ICC profile, an Exif directory) or its first image's strips or
    tiles lie past the end of the file. The decoders would say only "(0)", "decoder error
    -2" or "corrupted IFD structure", Pillow would warn of corrupt EXIF or a truncated
    read, libtiff would print its own line, and a cut LZW file would be taken for one that
    needs imagecodecs."""
    size = os.path.getsize(path)

    def cut(what: str, end: int) -> InputError:
        return InputError(path, f"truncated: the file has {size} bytes, but {what} "
                                f"{end} (an incomplete copy or download?)")

    with open(path, "rb") as f:
        head = f.read(16)
        order = "<" if head[:2] == b"II" else ">"
        big = head[2:4] in (b"+\x00", b"\x00+")
        offset, entry, count_size = ("Q", 20, 8) if big else ("I", 12, 2)
        if len(head) < (16 if big else 8):
            raise cut("its header runs to byte", 16 if big else 8)
        first = struct.unpack(order + offset, head[8:16] if big else head[4:8])[0]
        if first >= size:
            raise cut("its first directory is at byte", first)
        f.seek(first)
        raw = f.read(count_size)
        count = struct.unpack(order + ("Q" if big else "H"), raw)[0] \
            if len(raw) == count_size else None
        end = first + count_size + entry * (count or 0) + (8 if big else 4)
        if count is None or end > size:
            raise cut("its first directory runs to byte", end)
        entries = f.read(entry * count)
    inline = 8 if big else 4
    for k in range(count):
        e = entries[k * entry:(k + 1) * entry]
        tag, kind = struct.unpack(order + "HH", e[:4])
        n = struct.unpack(order + offset, e[4:12] if big else e[4:8])[0]
        at = struct.unpack(order + offset, e[12:20] if big else e[8:12])[0]
        nbytes = n * _TIFF_TYPE_BYTES.get(kind, 1)
        if nbytes > inline and at + nbytes > size:
            raise cut(f"its tag {tag}'s value runs to byte", at + nbytes)
        if tag in (_EXIF_IFD, _GPS_IFD) and nbytes <= inline and at >= size:   # sub-IFD
            raise cut(f"its tag {tag}'s directory is at byte", at)
    try:
        with _tifffile_quiet(), tifffile.TiffFile(path) as tif:
            page = tif.pages.first
            end = max((int(o) + int(n) for o, n in zip(page.dataoffsets, page.databytecounts)
                       if n), default=0)
    except Exception:
        return
    if end > size:
        raise cut("its image data runs to byte", end)


def _codec_missing(path: str, exc: BaseException) -> InputError | None:
    """The error to raise where tifffile could not decode the TIFF ``path`` for want of
    ``imagecodecs`` (``exc`` reads ``"<COMPRESSION.LZW: 5> requires the 'imagecodecs'
    package"``), naming what needs it and what to do; ``None`` for any other failure."""
    text = str(exc)
    if "imagecodecs" not in text:
        return None
    found = re.search(r"<(COMPRESSION|PREDICTOR)\.(\w+)", text)
    what = f"{found[2]} {found[1].lower()}" if found else "encoding"
    return InputError(path, f"its {what} needs the package imagecodecs (not installed, or "
                            "without that codec): `pip install imagecodecs` (or "
                            "gyrodeblur's `tiff` extra), or save the TIFF uncompressed")


def _read_tiff_by_pillow(path: str, im: Image.Image, tifffile_error: Exception) -> np.ndarray:
    """:func:`_read_tiff_pixels`' fallback: the pixels as Pillow (libtiff) decodes them, its
    rotation undone; ``tifffile_error`` re-raised where Pillow cannot hold the samples."""
    tags = im.tag_v2
    bits = tags.get(258, (1,))
    bits = bits if isinstance(bits, tuple) else (bits,)
    if int(tags.get(277, 1)) > 1 and max(bits) > 8:
        if int(tags.get(284, 1)) != 1 or max(bits) != 16:
            raise tifffile_error
        arr = _pillow_16bit_colour(path, im)
    elif im.mode == "I":  # 32-bit or signed integers; unsigned 16-bit is fine
        signed = tags.get(339, (1,)) in (2, (2,))
        if max(bits) != 16 or signed:
            kind = "signed" if signed else "unsigned"
            raise InputError(path, f"unsupported samples ({max(bits)}-bit {kind} integers); "
                             "use 8 or 16 bits")
        orientation = _load_as_stored(im)
        arr = _unorient(np.asarray(im).astype(np.uint16), orientation)
    else:
        orientation = _load_as_stored(im)
        arr = _unorient(_pillow_to_array(path, im), orientation)
    stored = (tags.get(257), tags.get(256))
    if arr.shape[:2] != stored:
        raise InputError(path, f"decoded {arr.shape[:2]} pixels, but the file says {stored}")
    if tags.get(262) in (0, (0,)) and arr.dtype == np.uint16:
        arr = np.uint16(65535) - arr        # min-is-white: Pillow inverts 8-bit ink, not 16
    return arr


@contextmanager
def _tifffile_quiet():
    """tifffile logs what it cannot parse of a broken file on its own logger (several
    lines of its internals); the failure reaches the user as one :class:`InputError`."""
    logger = logging.getLogger("tifffile")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _read_tiff_tifffile(path: str) -> tuple[np.ndarray, bytes | None, dict]:
    """First page of a TIFF with tifffile: (samples as (H, W) or (H, W, C), ICC, the
    metadata carried as :func:`_carried_metadata` reads it)."""
    with _tifffile_quiet(), tifffile.TiffFile(path) as tif:
        if len(tif.pages) > 1:
            warnings.warn(f"{path}: only the first of its {len(tif.pages)} pages is read",
                          GyrodeblurWarning, stacklevel=2)
        page = tif.pages.first
        _refuse_raw_or_preview(path, {t.code: t.value for t in page.tags.values()})
        _refuse_too_many_pixels(path, int(page.imagewidth), int(page.imagelength))
        photometric = int(page.photometric)
        if photometric not in (0, 1, 2):  # MINISWHITE, MINISBLACK, RGB
            name = getattr(page.photometric, "name", str(photometric))
            raise InputError(path, f"unsupported TIFF colour model {name}")
        arr = page.asarray()
        if photometric == 0:              # grey stored as ink: 0 is white
            if arr.dtype.kind == "f":
                raise InputError(path, "unsupported TIFF colour model MINISWHITE with float "
                                       "samples")
            top = True if arr.dtype == np.bool_ else np.iinfo(arr.dtype).max
            grey = arr if arr.ndim == 2 else arr[..., 0] if not page.axes.startswith("S") \
                else arr[0]
            grey[...] = ~grey if arr.dtype == np.bool_ else top - grey
        axes = page.axes
        extra = [int(e) for e in (page.extrasamples or ())]
        icc_tag = page.tags.get(34675)
        icc = bytes(icc_tag.value) if icc_tag is not None else None
        values = {t.code: t.value for t in page.tags.values() if t.code in (282, 283, 296,
                                                                             700)}
    carried = _checked_dpi_and_xmp(
        _dpi_of_tags({k: int(v) if k == 296 else v for k, v in values.items()}),
        values.get(700))
    if arr.ndim == 3 and axes.startswith("S"):
        arr = np.moveaxis(arr, 0, -1)
    arr = _with_plain_alpha(arr, extra)
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[-1] not in (2, 3, 4)):
        raise InputError(path, f"unsupported TIFF layout (samples of shape {arr.shape})")
    return arr, icc, carried


def _with_plain_alpha(arr: np.ndarray, extra: list[int]) -> np.ndarray:
    """A TIFF's samples with its extra samples (TIFF tag 338: 0 unspecified, 1
    associated alpha, 2 unassociated alpha) made what the rest of the module expects:
    colours, then at most one straight (unassociated) alpha. An unspecified sample is
    no alpha and is dropped, as are any after the first extra one; premultiplied colours
    are divided by their alpha (the file is written back with unassociated alpha)."""
    if arr.ndim != 3 or not extra or len(extra) >= arr.shape[-1]:
        return arr
    colours = arr.shape[-1] - len(extra)
    if extra[0] not in (1, 2):
        return arr[..., :colours]
    arr = arr[..., :colours + 1]
    if extra[0] == 1:
        c = arr[..., :colours].astype(np.float64)
        a = arr[..., colours:].astype(np.float64)
        top = 1.0 if arr.dtype.kind == "f" else float(np.iinfo(arr.dtype).max)
        straight = np.divide(c * top, a, out=np.zeros_like(c), where=a > 0)
        straight = np.minimum(straight, top)
        if arr.dtype.kind != "f":
            straight = np.rint(straight)
        arr = np.concatenate([straight.astype(arr.dtype), arr[..., colours:]], axis=-1)
    return arr


def _to_float(path: str, arr: np.ndarray, keep_bright: bool = False) -> tuple[np.ndarray, int]:
    """Integer samples -> float32 in [0, 1] and the bit depth they had (float samples
    above 1 kept with ``keep_bright``)."""
    if arr.dtype == np.uint8:
        return arr.astype(np.float32) / np.float32(255), 8
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) / np.float32(65535), 16
    if arr.dtype == np.bool_:
        return arr.astype(np.float32), 8
    if arr.dtype.kind == "f":
        a = arr.astype(np.float32)
        finite = np.isfinite(a)
        bad = int(a.size - np.count_nonzero(finite))
        _refuse_far_outside(path, a[finite], keep_bright)
        top = np.inf if keep_bright else 1.0
        over = int(np.count_nonzero(finite & ((a > top) | (a < 0))))
        if bad or over:
            what = []
            if over:
                where = "below 0" if keep_bright else "outside [0, 1]"
                what.append(f"{over} float samples {where} are clipped (range "
                            f"{a[finite].min():.3g} to {a[finite].max():.3g})")
            if bad:
                what.append(f"{bad} NaN or infinite samples are read as 0 (+inf as 1)")
            advice = "" if keep_bright else ": scale a scene-linear or HDR image to [0, 1] first"
            warnings.warn(f"{path}: " + "; ".join(what) + advice,
                          GyrodeblurWarning, stacklevel=2)
        out = np.nan_to_num(a, nan=0.0, posinf=1.0, neginf=0.0)
        return np.clip(out, 0.0, top), 16
    kind = {"i": "signed integers", "u": "unsigned integers"}.get(arr.dtype.kind, str(arr.dtype))
    raise InputError(path, f"unsupported samples ({8 * arr.dtype.itemsize}-bit {kind}); "
                     "use 8 or 16 bits")


def _refuse_far_outside(path: str, values: np.ndarray, keep_bright: bool,
                        keep_dark: bool = False) -> None:
    """Refuse float samples that no clipping makes a photo of: most of them above 1, beyond
    :data:`~gyrodeblur.images.PHOTO_MAX` (0-255 or 0-65535 values; a photo's or a scene's
    lights above white are kept or clipped), or more than 1 % below
    :data:`~gyrodeblur.images.PHOTO_MIN` (an offset or negated image; a stray cold pixel is
    clipped; not with ``keep_dark``), the limits ``deblur()`` holds an array to."""
    if not values.size:
        return
    high = float(values.max())
    some = values[::max(1, values.size // 1_000_000)]      # the median of a sample will do
    if not keep_bright and high > PHOTO_MAX and float(np.median(some)) > 1.0:
        raise InputError(path, f"float samples up to {high:.4g}, most of them above 1; "
                               "expected light in [0, 1] (divide 0-255 values by 255, "
                               "0-65535 ones by 65535; scale or clip an HDR image)")
    if not keep_dark and np.count_nonzero(values < PHOTO_MIN) > 0.01 * values.size:
        raise InputError(path, f"float samples down to {float(values.min()):.4g}; expected "
                               "light in [0, 1] (light is never below black: is it offset "
                               "or negated?)")


#: Longest XMP packet one JPEG APP1 segment holds (after its 29-byte namespace header).
_JPEG_MAX_XMP = 65504


# --------------------------------------------------------------------------- writing


def write_photo(
    path: str | os.PathLike,
    pixels: np.ndarray,
    *,
    like: Photo | None = None,
    bit_depth: int | None = None,
    overwrite: bool = False,
    quality: int = 95,
) -> str:
    """Write float pixels in ``[0, 1]`` to a JPEG, PNG or TIFF file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; ``.jpg``/``.jpeg``, ``.png`` or ``.tif``/``.tiff`` selects the format.
    pixels : ndarray, shape (H, W), (H, W, 1), (H, W, 2), (H, W, 3) or (H, W, 4)
        Floating-point samples; clipped to ``[0, 1]`` and rounded to the nearest integer.
        Samples no clipping makes a photo of are refused, as :func:`read_photo` refuses
        them in a float TIFF: most above 1 and some above 2 (0-255 values).
        ``(H, W, 2)`` is grey + alpha, written as such; so is RGBA when ``like`` was read
        from a grey + alpha file (its colours averaged: they are equal there).
    like : Photo, optional
        The input photo: its EXIF block and ICC profile are written with the pixels
        (where the format allows; an ICC profile whose colour space does not fit the
        channels - e.g. an RGB profile on grey pixels - is left out), its bit depth is
        the default, and its file is never overwritten.
    bit_depth : {8, 16}, optional
        Bits per sample; default ``like.bit_depth``, else 8. JPEG is always 8-bit: an
        inherited 16 is lowered silently, an explicit ``bit_depth=16`` is an error.
    overwrite : bool
        Replace an existing file (never ``like.path``).
    quality : int
        JPEG quality, 1-100 (chroma is not subsampled: 4:4:4).

    Returns
    -------
    str
        ``path``, as written.

    Raises
    ------
    InputError
        Unknown extension, missing folder, existing file without ``overwrite``, output
        is the input photo, alpha channel for JPEG, 16-bit JPEG, or the OS refused the
        write (permissions, disk full). No partial file is left behind.
    ValueError
        ``pixels`` is not a float array of a supported shape, holds NaN or infinite
        values, or values far outside ``[0, 1]`` (an :class:`InputError` naming
        ``path``), or ``bit_depth``/``quality`` is out of range.
    """
    p = os.fspath(path)
    _refuse_empty_name(p)
    fmt = _format_of(p)
    pixels = _check_pixels(pixels)
    # 0-255 values refused; an unclipped deblur's ringing far below black is clipped
    _refuse_far_outside(p, pixels, keep_bright=False, keep_dark=True)
    depth = _choose_bit_depth(p, fmt, bit_depth, like)
    if not (is_whole(quality) and 1 <= quality <= 100):   # not "hi", 95.7 or True
        raise ValueError(f"quality must be a whole number within 1-100, not {quality!r}")
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if fmt == "JPEG" and channels in (2, 4):
        raise InputError(p, "JPEG cannot store an alpha channel; write .png or .tif")
    if fmt == "JPEG":
        _refuse_too_big_for_jpeg(p, pixels)
    check_destination(p, like, overwrite)
    if fmt == "JPEG" and bit_depth is None and like is not None and like.bit_depth == 16:
        warnings.warn(f"{p}: JPEG stores 8 bits per sample: the 16-bit photo is written at 8 "
                      "(.png or .tif keep 16)", GyrodeblurWarning, stacklevel=2)

    if like is not None and like.grey_alpha and channels == 4:   # grey + alpha again
        pixels = np.stack([pixels[..., :3].mean(axis=2), pixels[..., 3]], axis=2)
        channels = 2
    ints = _to_integers(pixels, depth)
    exif = _without_thumbnail(_normalise_exif(like.exif)) if like is not None else None
    icc = like.icc_profile if like is not None else None
    damage = profile_damage(icc) if icc else None
    if damage:
        warnings.warn(f"{p}: the photo's ICC profile is damaged ({damage}): left out",
                      GyrodeblurWarning, stacklevel=2)
        icc = None
    if icc and not _icc_fits(icc, channels):
        icc = None
    if fmt == "JPEG" and exif and len(exif) > _JPEG_MAX_EXIF:
        exif = _exif_for_jpeg(exif, p)
    dpi = like.dpi if like is not None else None
    xmp = like.xmp if like is not None else None
    if fmt == "PNG":
        gamma = like.png_gamma if like is not None else None
        text = dict(like.png_text or {}) if like is not None else {}
        if xmp and _PNG_XMP_KEY not in text:                    # a JPEG's or TIFF's
            packet = _xmp_text(xmp)
            if packet is None:
                warnings.warn(f"{p}: the photo's XMP is not UTF-8 or UTF-16/32 text, as a "
                              "PNG's must be: left out (.jpg or .tif keep it)",
                              GyrodeblurWarning, stacklevel=2)
            else:
                text[_PNG_XMP_KEY] = packet
        atomic_write(p, lambda f: _write_png(f, ints, exif=exif, icc=icc, gamma=gamma,
                                             dpi=dpi, text=text))
        return p
    if xmp is None and like is not None and like.png_text:      # a PNG's, for JPEG / TIFF
        xmp = (like.png_text.get(_PNG_XMP_KEY) or "").encode("utf-8") or None
    if fmt == "JPEG" and xmp and len(xmp) > _JPEG_MAX_XMP:
        warnings.warn(f"{p}: the photo's XMP ({len(xmp)} bytes) is longer than one JPEG "
                      "segment holds: left out (.png or .tif keep it)",
                      GyrodeblurWarning, stacklevel=2)
        xmp = None
    writer = {"JPEG": _write_jpeg, "TIFF": _write_tiff}[fmt]
    atomic_write(p, lambda f: writer(f, ints, exif=exif, icc=icc, quality=int(quality),
                                     dpi=dpi, xmp=xmp))
    return p


def _check_pixels(pixels) -> np.ndarray:
    arr = np.asarray(pixels)
    if arr.dtype.kind != "f":
        raise ValueError(f"pixels must be floats in [0, 1], not {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (2, 3, 4))) or 0 in arr.shape:
        raise ValueError(f"pixels must have shape (H, W) or (H, W, 1 to 4), not {arr.shape}")
    if np.isnan(arr).any():
        raise ValueError("pixels contain NaN")
    if np.isinf(arr).any():
        raise ValueError("pixels contain infinite values")
    return arr


def _choose_bit_depth(path: str, fmt: str, bit_depth: int | None, like: Photo | None) -> int:
    if bit_depth is not None and bit_depth not in (8, 16):
        raise ValueError(f"bit_depth must be 8 or 16, not {bit_depth!r}")
    if fmt == "JPEG":
        if bit_depth == 16:
            raise InputError(path, "JPEG stores 8 bits per sample; write .png or .tif for 16 bits")
        return 8
    if bit_depth is not None:
        return bit_depth
    return like.bit_depth if like is not None else 8


def _refuse_empty_name(path: str) -> None:
    if not path.strip():
        raise InputError(None, f"an output file's name is empty ({path!r}): name a file")


def _format_of(path: str) -> str:
    fmt = EXTENSIONS.get(os.path.splitext(path)[1].lower())
    if fmt is None:
        raise InputError(path, "unknown image type; use .jpg, .jpeg, .png, .tif or .tiff")
    return fmt


def check_destination(path: str | os.PathLike, like: Photo | None = None,
                      overwrite: bool = False, *, image: bool = True, inputs=(),
                      bit_depth: int | None = None) -> None:
    """Check, before any work, that :func:`write_photo` may write ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The intended output file.
    like : Photo, optional
        The input photo, which is never overwritten.
    overwrite : bool
        Whether an existing file may be replaced.
    image : bool
        Whether ``path`` must have an image extension (``False`` for other outputs such
        as ``.npy`` or ``.json``, which get the same folder and overwrite checks).
    inputs : iterable of str or os.PathLike
        Other files the command reads (photos, capture descriptions, gyro logs), which
        are never overwritten either, ``overwrite`` or not.
    bit_depth : {8, 16}, optional
        The bit depth asked for (16 is refused for a JPEG here, before the work).

    Raises
    ------
    InputError
        Unknown extension, missing or unwritable folder, ``path`` is a folder, the input
        photo or another input, it exists and ``overwrite`` is false, or it is a JPEG and
        ``like`` has an alpha channel or ``bit_depth`` is 16.
    """
    path = os.fspath(path)
    _refuse_empty_name(path)
    if os.path.isdir(path):
        raise InputError(path, "is a folder; name the output file")
    if image:
        fmt = _format_of(path)
        _choose_bit_depth(path, fmt, bit_depth, like)
        if fmt == "JPEG" and like is not None:
            _refuse_too_big_for_jpeg(path, like.pixels)
        if fmt == "JPEG" and like is not None and like.pixels.ndim == 3 \
                and like.pixels.shape[2] == 4:
            raise InputError(path, "JPEG cannot store the photo's alpha channel; write .png "
                                   "or .tif")
    check_folder_of(path)
    if like is not None and like.path is not None and _same_file(path, like.path):
        raise InputError(path, "is the input photo; choose another output file")
    for other in inputs:
        if other is not None and _same_file(path, os.fspath(other)):
            raise InputError(path, "is one of the command's inputs; choose another output file")
    if os.path.lexists(path) and not overwrite:
        raise InputError(path, "exists; --overwrite (overwrite=True) replaces it")
    check_writable(path)


def _same_file(a: str, b: str) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links, case-insensitive file systems
    except OSError:
        return False


def _to_integers(pixels: np.ndarray, bit_depth: int) -> np.ndarray:
    """Clip to [0, 1], scale and round half to even: uint8 or uint16."""
    top = 255 if bit_depth == 8 else 65535
    scaled = np.clip(pixels.astype(np.float32, copy=False), 0.0, 1.0) * np.float32(top)
    return np.rint(scaled).astype(np.uint8 if bit_depth == 8 else np.uint16)


def _icc_fits(icc: bytes, channels: int) -> bool:
    """Whether an ICC profile's data colour space suits grey (1, 2 with alpha) or RGB(A)
    pixels."""
    space = bytes(icc[16:20])
    if space == b"GRAY":
        return channels in (1, 2)
    if space == b"RGB ":
        return channels in (3, 4)
    return False


#: The longest side a JPEG file can hold (the format's 16-bit sizes, as libjpeg caps them).
JPEG_MAX_SIDE = 65500


def _refuse_too_big_for_jpeg(path: str, pixels: np.ndarray) -> None:
    if max(pixels.shape[:2]) > JPEG_MAX_SIDE:
        raise InputError(path, f"JPEG holds at most {JPEG_MAX_SIDE} px a side, the photo is "
                               f"{pixels.shape[1]}x{pixels.shape[0]}: write .png or .tif")


def _write_jpeg(f, ints, *, exif, icc, quality, dpi=None, xmp=None) -> None:
    options = {"quality": quality, "subsampling": 0 if ints.ndim == 3 else -1}
    if exif:
        options["exif"] = exif
    if icc:
        options["icc_profile"] = icc
    if dpi:                                # JFIF's density: whole dots per inch
        options["dpi"] = tuple(max(1, min(65535, round(v))) for v in dpi)
    if xmp:
        options["xmp"] = xmp
    Image.fromarray(ints).save(f, format="JPEG", **options)


def _xmp_text(xmp: bytes) -> str | None:
    """An XMP packet's text (UTF-8, or UTF-16/32 with a byte-order mark), else ``None``."""
    import codecs
    for bom, codec in ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"),
                       (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16")):
        if xmp.startswith(bom):
            try:
                return xmp.decode(codec)
            except UnicodeDecodeError:
                return None
    try:
        return xmp.decode("utf-8")
    except UnicodeDecodeError:
        return None


def _write_tiff(f, ints, *, exif, icc, quality, dpi=None, xmp=None) -> None:
    """Deflate-compressed TIFF via tifffile; EXIF added afterwards (tifffile cannot)."""
    channels = 1 if ints.ndim == 2 else ints.shape[2]
    extratags = []
    exif_obj = None
    if exif:
        try:
            exif_obj = _load_exif(exif)
            for tag in _IFD0_ASCII:
                value = exif_obj.get(tag)
                if isinstance(value, str) and value:
                    extratags.append((tag, 2, 0, value.encode("latin-1", "replace"), True))
            orientation = exif_obj.get(_ORIENTATION)
            if isinstance(orientation, int) and 1 <= orientation <= 8:
                extratags.append((_ORIENTATION, 3, 1, orientation, True))
        except _DECODE_ERRORS:
            exif_obj, extratags = None, []  # damaged EXIF: write the pixels without it
    if xmp:
        extratags.append((700, 1, len(xmp), xmp, True))
    tifffile.imwrite(
        f, ints,
        photometric="minisblack" if channels <= 2 else "rgb",
        extrasamples=("unassalpha",) if channels in (2, 4) else None,
        compression="zlib", compressionargs={"level": DEFLATE_LEVEL}, predictor=True,
        iccprofile=icc or None,
        metadata=None, software=False, byteorder="<", bigtiff=False, extratags=extratags,
        resolution=tuple(dpi) if dpi else None, resolutionunit="INCH" if dpi else None,
    )
    if exif_obj is not None:
        try:
            sub = _sub_ifds(exif_obj)
        except _DECODE_ERRORS:
            sub = {}
        if sub:
            _append_tiff_sub_ifds(f, sub)


def _append_tiff_sub_ifds(f, sub_ifds: dict[int, dict]) -> None:
    """Append Exif/GPS sub-IFDs to a classic TIFF and point IFD0 at them.

    tifffile refuses to write the ExifIFD/GPSInfo pointer tags, so the sub-IFDs are
    serialised (by Pillow) at the end of the file, and IFD0 is copied there too with
    the two pointer entries added; the header is then pointed at the new IFD0. Strip
    and tag-data offsets stay valid because nothing already written moves.
    """
    f.seek(0)
    header = f.read(8)
    order = "<" if header[:2] == b"II" else ">"
    (ifd0,) = struct.unpack(order + "I", header[4:8])
    f.seek(ifd0)
    (count,) = struct.unpack(order + "H", f.read(2))
    entries = {struct.unpack(order + "H", e[:2])[0]: e
               for e in (f.read(12) for _ in range(count))}
    next_ifd = f.read(4)
    end = f.seek(0, os.SEEK_END)
    for tag, values in sub_ifds.items():
        end += end % 2
        f.seek(end)
        ifd = TiffImagePlugin.ImageFileDirectory_v2(ifh=header, group=tag)
        for key, value in values.items():
            ifd[key] = value
        f.write(ifd.tobytes(end))
        entries[tag] = struct.pack(order + "HHII", tag, 4, 1, end)  # LONG offset
        end = f.tell()
    end += end % 2
    f.seek(end)
    f.write(struct.pack(order + "H", len(entries)))
    f.write(b"".join(entries[t] for t in sorted(entries)))
    f.write(next_ifd)
    f.seek(4)
    f.write(struct.pack(order + "I", end))
