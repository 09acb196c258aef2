"""Writing PNG files: 8 bits through Pillow, 16 bits with numpy + zlib (Pillow cannot
write 16-bit colour), and the chunks both carry: ``eXIf``, ``iCCP``, ``gAMA``, ``pHYs``
and text (``tEXt``, or ``iTXt`` for XMP and text that is not Latin-1).

Used by :func:`gyrodeblur.imageio.write_photo`, which decides what the file carries.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
from PIL import Image, PngImagePlugin

from gyrodeblur.exif import _EXIF_HEADER

#: The keyword of the text chunk that holds a PNG's XMP packet.
_PNG_XMP_KEY = "XML:com.adobe.xmp"
#: zlib level of the PNG (and Deflate TIFF) files written: on a 12 MP deblurred photo,
#: 8-bit PNG, 1.2 s and 11.7 MB at 3 against 3.8 s and 10.3 MB at zlib's usual 6 (0.8 s,
#: 12.6 MB at 1); TIFF 0.8 s, 13.0 MB against 3.0 s, 11.8 MB (session 44).
DEFLATE_LEVEL = 3


def _write_png(f, ints, *, exif, icc, gamma=None, dpi=None, text=None) -> None:
    if ints.dtype == np.uint16:
        _write_png16(f, ints, exif=exif, icc=icc, gamma=gamma, dpi=dpi, text=text)
        return
    options = {"compress_level": DEFLATE_LEVEL}
    if exif:
        options["exif"] = exif
    if icc:
        options["icc_profile"] = icc
    if dpi:
        options["dpi"] = dpi
    info = PngImagePlugin.PngInfo()
    if gamma:
        info.add(b"gAMA", _png_gamma_bytes(gamma))
    for key, value in _png_text_items(text):
        if _png_itxt(key, value):
            info.add_itxt(key, value, getattr(value, "lang", None) or "",
                          getattr(value, "tkey", None) or "")
        else:
            info.add_text(key, value)
    options["pnginfo"] = info
    Image.fromarray(ints).save(f, format="PNG", **options)


def _png_text_items(text):
    """``text``'s (keyword, text) pairs that a PNG can hold: a keyword of 1-79 Latin-1
    characters (others are left out)."""
    for key, value in (text or {}).items():
        try:
            ok = 1 <= len(str(key).encode("latin-1")) <= 79
        except UnicodeEncodeError:
            ok = False
        if ok and isinstance(value, str):
            yield str(key), value


def _png_itxt(key: str, value: str) -> bool:
    """Whether a text chunk is written as ``iTXt``: XMP (which the XMP standard puts
    there), an ``iTXt`` read as such (its language tag kept), text that is not Latin-1."""
    if key == _PNG_XMP_KEY or isinstance(value, PngImagePlugin.iTXt):
        return True
    try:
        value.encode("latin-1")
    except UnicodeEncodeError:
        return True
    return False


def _png_text_chunk(key: str, value: str) -> bytes:
    """A ``tEXt`` chunk, or an uncompressed ``iTXt`` as :func:`_png_itxt` decides (the
    keyword Latin-1, as the PNG standard has it; the text UTF-8)."""
    keyword = key.encode("latin-1")
    if not _png_itxt(key, value):
        return _png_chunk(b"tEXt", keyword + b"\0" + value.encode("latin-1"))
    lang = str(getattr(value, "lang", None) or "").encode("latin-1", "replace")
    tkey = str(getattr(value, "tkey", None) or "").encode("utf-8")
    return _png_chunk(b"iTXt", keyword + b"\0\0\0" + lang + b"\0" + tkey + b"\0"
                      + str(value).encode("utf-8"))


def _png_gamma_bytes(gamma: float) -> bytes:
    """A ``gAMA`` chunk's data: the file gamma times 100000, unsigned 32-bit."""
    return struct.pack(">I", int(round(gamma * 100000)))


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))


def _png_filter(rows: np.ndarray, prior: np.ndarray, bpp: int) -> np.ndarray:
    """PNG-filter scanlines, picking per row the filter of least sum of |signed bytes|.

    Parameters
    ----------
    rows : ndarray of uint8, shape (n, N)
        Raw scanlines (without filter bytes).
    prior : ndarray of uint8, shape (N,)
        The scanline above ``rows[0]`` (zeros for the first one).
    bpp : int
        Bytes per complete pixel.

    Returns
    -------
    ndarray of uint8, shape (n, N + 1)
        Filter-type byte followed by the filtered scanline, for each row.
    """
    x = rows.astype(np.int16)
    b = np.concatenate([prior[None].astype(np.int16), x[:-1]])
    a = np.zeros_like(x)
    a[:, bpp:] = x[:, :-bpp]
    c = np.zeros_like(x)
    c[:, bpp:] = b[:, :-bpp]
    p = a + b - c
    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
    paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
    candidates = np.stack([x, x - a, x - b, x - ((a + b) >> 1), x - paeth]).astype(np.uint8)
    cost = np.abs(candidates.view(np.int8).astype(np.int32)).sum(axis=2)
    best = cost.argmin(axis=0)
    chosen = candidates[best, np.arange(len(rows))]
    return np.concatenate([best.astype(np.uint8)[:, None], chosen], axis=1)


def _write_png16(f, ints: np.ndarray, *, exif, icc, gamma=None, dpi=None, text=None) -> None:
    """16-bit grey, grey + alpha, RGB or RGBA PNG with numpy + zlib (Pillow cannot write
    16-bit colour)."""
    height, width = ints.shape[:2]
    channels = 1 if ints.ndim == 2 else ints.shape[2]
    colour_type = {1: 0, 2: 4, 3: 2, 4: 6}[channels]
    raw = np.ascontiguousarray(ints, dtype=">u2").view(np.uint8).reshape(height, -1)
    f.write(b"\x89PNG\r\n\x1a\n")
    f.write(_png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 16, colour_type, 0, 0, 0)))
    if gamma:                                        # before PLTE/IDAT, as the spec wants
        f.write(_png_chunk(b"gAMA", _png_gamma_bytes(gamma)))
    if icc:
        f.write(_png_chunk(b"iCCP", b"ICC Profile\x00\x00" + zlib.compress(icc)))
    if exif:
        f.write(_png_chunk(b"eXIf", exif[len(_EXIF_HEADER):]))
    if dpi:                                          # pixels per metre
        f.write(_png_chunk(b"pHYs", struct.pack(">IIB", *(int(v / 0.0254 + 0.5) for v in dpi),
                                                1)))
    for key, value in _png_text_items(text):
        f.write(_png_text_chunk(key, value))
    compressor = zlib.compressobj(DEFLATE_LEVEL)
    block = max(1, (1 << 20) // raw.shape[1])  # about 1 MiB of scanlines at a time
    pending = []
    prior = np.zeros(raw.shape[1], np.uint8)
    for start in range(0, height, block):
        rows = raw[start:start + block]
        pending.append(compressor.compress(_png_filter(rows, prior, 2 * channels).tobytes()))
        prior = rows[-1]
        if sum(map(len, pending)) >= 1 << 20:
            f.write(_png_chunk(b"IDAT", b"".join(pending)))
            pending = []
    pending.append(compressor.flush())
    f.write(_png_chunk(b"IDAT", b"".join(pending)))
    f.write(_png_chunk(b"IEND", b""))
