"""Tests for gyrodeblur.imageio: round trips, metadata, hints, safe writing, bad files."""

from __future__ import annotations

import dataclasses
import errno
import math
import os
import re
import struct
import warnings
import zlib

import numpy as np
import pytest
import tifffile
from PIL import Image, ImageCms, PngImagePlugin, TiffImagePlugin

from gyrodeblur import imageio
from gyrodeblur.errors import InputError
from gyrodeblur.imageio import Photo, exif_capture_hints, read_photo, write_photo

R = TiffImagePlugin.IFDRational
SRGB = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()


# --------------------------------------------------------------------------- helpers


def levels(shape, bits, seed=0):
    """Random integer levels and the floats k / (2**bits - 1) that encode them."""
    top = 2**bits - 1
    k = np.random.default_rng(seed).integers(0, top + 1, size=shape)
    k.flat[:2] = (0, top)
    return k, (k / top).astype(np.float32)


def smooth(shape):
    """A smooth float image (JPEG-friendly)."""
    h, w = shape[:2]
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w]).reshape(2, 1, 1)
    base = 0.5 + 0.4 * np.sin(2 * x + 3 * y)
    if len(shape) == 2:
        return base.astype(np.float32)
    planes = [base, 1 - base, 0.5 * base + 0.25, np.full_like(base, 0.8)]
    return np.stack(planes[: shape[2]], axis=-1).astype(np.float32)


def exif_block(**extra):
    """EXIF block with Make/Model/Orientation, ExposureTime, FocalLength and GPS."""
    exif = Image.Exif()
    exif[271], exif[272], exif[274] = "Canon", "EOS R5", 6
    sub = exif.get_ifd(0x8769)
    sub[0x829A] = R(1, 60)  # ExposureTime
    sub[0x920A] = R(50, 1)  # FocalLength
    for tag, value in extra.items():
        sub[int(tag.removeprefix("x_"), 16)] = value  # x_A405=... -> tag 0xA405
    exif.get_ifd(0x8825)[1] = "N"
    return exif.tobytes()


def exif_values(block):
    exif = Image.Exif()
    exif.load(block)
    return dict(exif), dict(exif.get_ifd(0x8769)), dict(exif.get_ifd(0x8825))


def like(pixels=None, *, exif=None, icc=None, bit_depth=8, fmt="PNG", path=None):
    pixels = np.zeros((4, 4, 3), np.float32) if pixels is None else pixels
    return Photo(pixels, bit_depth, fmt, path, exif, icc)


def png_chunk(tag, data):
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))


def reference_png16(path, k, interlace=False, exif=None):
    """Independent minimal 16-bit PNG encoder (filter 0; optional Adam7; eXIf last)."""
    h, w, c = k.shape
    passes = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4),
              (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)] if interlace else [(0, 0, 1, 1)]
    data = b""
    for x0, y0, dx, dy in passes:
        sub = k[y0::dy, x0::dx]
        for row in sub:
            if row.size:
                data += b"\x00" + row.astype(">u2").tobytes()
    ihdr = struct.pack(">IIBBBBB", w, h, 16, {3: 2, 4: 6}[c], 0, 0, int(interlace))
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr)
                + png_chunk(b"IDAT", zlib.compress(data))
                + (png_chunk(b"eXIf", exif[6:]) if exif else b"") + png_chunk(b"IEND", b""))


def reference_png16_decode(path):
    """Independent slow PNG decoder for small non-interlaced 16-bit files."""
    blob = open(path, "rb").read()
    pos, idat, ihdr = 8, b"", None
    while pos < len(blob):
        (n,) = struct.unpack(">I", blob[pos:pos + 4])
        tag, body = blob[pos + 4:pos + 8], blob[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, bits, ctype = ihdr[:4]
    c = {0: 1, 2: 3, 6: 4}[ctype]
    bpp, stride = 2 * c, 2 * c * w
    raw, out, prev, filters = zlib.decompress(idat), [], [0] * stride, set()
    for r in range(h):
        ftype, line = raw[r * (stride + 1)], list(raw[r * (stride + 1) + 1:(r + 1) * (stride + 1)])
        filters.add(ftype)
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, cc = prev[i], prev[i - bpp] if i >= bpp else 0
            if ftype == 1:
                line[i] = (line[i] + a) & 255
            elif ftype == 2:
                line[i] = (line[i] + b) & 255
            elif ftype == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ftype == 4:
                p = a + b - cc
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - cc)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else cc)) & 255
        out.append(line)
        prev = line
    arr = np.array(out, np.uint8).reshape(h, w * c, 2)
    return (arr[..., 0].astype(np.uint16) << 8 | arr[..., 1]).reshape(h, w, c), filters


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("ext", [".png", ".tif"])
@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("shape", [(13, 17), (13, 17, 3), (13, 17, 4)])
def test_lossless_round_trip_is_exact(tmp_path, ext, bits, shape):
    k, pixels = levels(shape, bits)
    out = write_photo(tmp_path / f"out{ext}", pixels, bit_depth=bits)
    photo = read_photo(out)
    assert photo.format == {".png": "PNG", ".tif": "TIFF"}[ext]
    assert photo.bit_depth == bits and photo.path == out
    assert photo.pixels.dtype == np.float32 and photo.pixels.shape == shape
    assert np.array_equal(np.rint(photo.pixels * (2**bits - 1)), k)


@pytest.mark.parametrize("shape", [(24, 32), (24, 32, 3)])
def test_jpeg_round_trip_is_close(tmp_path, shape):
    pixels = smooth(shape)
    photo = read_photo(write_photo(tmp_path / "out.jpg", pixels, quality=95))
    assert photo.format == "JPEG" and photo.bit_depth == 8 and photo.pixels.shape == shape
    assert np.abs(photo.pixels - pixels).mean() < 0.01
    # all 8 bits reach the encoder: what Pillow makes of the rounded levels at the same
    # quality, to the decoder's last bit (a write that dropped a bit is 1-2 levels off)
    levels = np.rint(np.clip(pixels, 0, 1) * 255).astype(np.uint8)
    Image.fromarray(levels).save(tmp_path / "ref.jpg", quality=95, subsampling=0)
    ref = np.asarray(Image.open(tmp_path / "ref.jpg"), np.float32) / 255
    np.testing.assert_allclose(photo.pixels, ref, atol=1e-6)


@pytest.mark.parametrize("quality", ["hi", None, 95.7, True, 0, 101])
def test_a_jpeg_quality_that_is_not_a_whole_number_in_range_is_refused(tmp_path, quality):
    """A raw int() error for "hi" and None, and 95.7 cut to 95 without a word."""
    with pytest.raises(ValueError, match="quality must be a whole number within 1-100"):
        write_photo(tmp_path / "out.jpg", smooth((24, 32)), quality=quality)
    assert not (tmp_path / "out.jpg").exists()


def test_values_are_clipped_and_rounded_not_truncated(tmp_path):
    pixels = np.array([[-0.3, 1.7, 10.4 / 255, 10.6 / 255, 0.5]], np.float32)
    write_photo(tmp_path / "a.png", pixels)
    assert np.asarray(Image.open(tmp_path / "a.png")).tolist() == [[0, 255, 10, 11, 128]]


def test_16bit_png_is_readable_by_independent_decoders(tmp_path):
    k, pixels = levels((9, 11, 3), 16, seed=3)
    k[:, :6] = np.cumsum(np.full((9, 6, 3), 700), axis=1)  # smooth part: non-None filters
    pixels = (k / 65535).astype(np.float32)
    write_photo(tmp_path / "a.png", pixels, bit_depth=16)
    decoded, filters = reference_png16_decode(tmp_path / "a.png")
    assert np.array_equal(decoded, k) and len(filters) > 1
    with Image.open(tmp_path / "a.png") as im:  # Pillow keeps the high byte
        assert np.array_equal(np.asarray(im), k >> 8)


def test_a_16bit_png_of_several_blocks_of_scanlines_round_trips(tmp_path):
    """The 16-bit encoder filters about 1 MiB of scanlines at a time and splits IDAT at
    1 MiB: a photo larger than that (every real one) is exact across the joins. Half of
    each row is noise (so the file passes 1 MiB), half smooth (so the rows at the joins
    are filtered against the row above)."""
    rng = np.random.default_rng(11)
    h, w = 150, 2048                                 # 12 KiB rows: 85 rows a block
    k = rng.integers(0, 65536, (h, w, 3))
    y, x = np.mgrid[0:h, 0:w // 2]
    k[:, w // 2:] = (20000 + 90 * y + 13 * x + 5000 * np.sin(x / 40) * np.cos(y / 30))[..., None] \
        + rng.integers(0, 4, (h, w // 2, 3))
    out = write_photo(tmp_path / "big.png", (k / 65535).astype(np.float32), bit_depth=16)
    assert sum(t == b"IDAT" for t, _ in png_chunks(out)) > 1
    assert np.array_equal(np.rint(read_photo(out).pixels * 65535), k)


@pytest.mark.parametrize("interlace", [False, True])
@pytest.mark.parametrize("channels", [3, 4])
def test_reads_16bit_colour_png_from_another_encoder(tmp_path, interlace, channels):
    k, _ = levels((21, 19, channels), 16, seed=4)
    reference_png16(tmp_path / "ref.png", k, interlace)
    photo = read_photo(tmp_path / "ref.png")
    assert photo.bit_depth == 16
    assert np.array_equal(np.rint(photo.pixels * 65535), k)


def test_reads_exif_placed_after_the_image_data(tmp_path):
    k, _ = levels((4, 5, 3), 16)
    reference_png16(tmp_path / "late.png", k, exif=exif_block())
    assert exif_values(read_photo(tmp_path / "late.png").exif) == exif_values(exif_block())


def test_reads_16bit_grey_alpha_png_as_rgba(tmp_path):
    k, _ = levels((5, 6, 2), 16, seed=5)
    raw = b"".join(b"\x00" + row.astype(">u2").tobytes() for row in k)
    ihdr = struct.pack(">IIBBBBB", 6, 5, 16, 4, 0, 0, 0)
    (tmp_path / "ga.png").write_bytes(b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr)
                                      + png_chunk(b"IDAT", zlib.compress(raw))
                                      + png_chunk(b"IEND", b""))
    photo = read_photo(tmp_path / "ga.png")
    assert photo.bit_depth == 16 and photo.pixels.shape == (5, 6, 4)
    assert np.array_equal(np.rint(photo.pixels * 65535), k[..., [0, 0, 0, 1]])


def test_16bit_tiff_is_readable_by_tifffile(tmp_path):
    k, pixels = levels((7, 9, 3), 16)
    write_photo(tmp_path / "a.tif", pixels, bit_depth=16)
    assert np.array_equal(tifffile.imread(tmp_path / "a.tif"), k)


@pytest.mark.parametrize("byteorder", ["<", ">"])
def test_16bit_colour_tiff_pillow_fallback_is_exact(tmp_path, byteorder):
    # the path used when tifffile lacks a codec (LZW without imagecodecs)
    k, _ = levels((10, 12, 3), 16, seed=6)
    for compression in (None, "zlib"):
        tifffile.imwrite(tmp_path / "a.tif", k.astype(np.uint16), photometric="rgb",
                         byteorder=byteorder, compression=compression, metadata=None)
        with Image.open(tmp_path / "a.tif") as im:
            assert np.array_equal(imageio._pillow_16bit_colour(str(tmp_path / "a.tif"), im), k)


def test_reads_planar_16bit_tiff(tmp_path):
    k, _ = levels((3, 8, 10), 16, seed=7)
    tifffile.imwrite(tmp_path / "p.tif", k.astype(np.uint16), photometric="rgb",
                     planarconfig="separate", metadata=None)
    photo = read_photo(tmp_path / "p.tif")
    assert np.array_equal(np.rint(photo.pixels * 65535), np.moveaxis(k, 0, -1))


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("shape", [(6, 10), (6, 10, 3)])
def test_tiff_orientation_is_not_applied(tmp_path, bits, shape):
    k, _ = levels(shape, bits, seed=8)
    dtype = np.uint8 if bits == 8 else np.uint16
    tifffile.imwrite(tmp_path / "o.tif", k.astype(dtype), metadata=None,
                     photometric="rgb" if len(shape) == 3 else "minisblack",
                     extratags=[(274, 3, 1, 6, True)])
    photo = read_photo(tmp_path / "o.tif")
    assert np.array_equal(np.rint(photo.pixels * (2**bits - 1)), k)
    assert exif_values(photo.exif)[0][274] == 6
    if bits == 16 and len(shape) == 3:  # the Pillow fallback undoes Pillow's rotation too
        with Image.open(tmp_path / "o.tif") as im:
            assert np.array_equal(imageio._pillow_16bit_colour(str(tmp_path / "o.tif"), im), k)


@pytest.mark.parametrize("dtype,text", [(np.uint32, "32-bit unsigned"),
                                        (np.int16, "16-bit signed")])
def test_unsupported_integer_tiffs_are_refused(tmp_path, dtype, text):
    tifffile.imwrite(tmp_path / "i.tif", np.zeros((4, 4), dtype), metadata=None)
    with pytest.raises(InputError, match=f"i.tif.*{text}"):
        read_photo(tmp_path / "i.tif")


def test_camera_raw_files_and_previews_are_refused_not_read_as_the_photo(tmp_path):
    """A DNG's (or a NEF's, an ARW's) first image is a small RGB preview that any TIFF
    reader opens: reading it would deblur a thumbnail without a word. Refused, with what
    to do, whichever decoder reads the file (Pillow; tifffile for float samples); so is
    undemosaiced sensor data. A TIFF of the same pixels without those tags is read."""
    preview = np.full((12, 16, 3), 128, np.uint8)
    dng = [(50706, "B", 4, (1, 4, 0, 0), True)]                     # DNGVersion
    cases = {"dng.dng": dict(data=preview, photometric="rgb", extratags=dng),
             "dngf.dng": dict(data=preview.astype(np.float32) / 255, photometric="rgb",
                              extratags=dng),
             "nef.tif": dict(data=preview, photometric="rgb", subfiletype=1),
             "cfa.tif": dict(data=np.zeros((12, 16), np.uint16), photometric=32803)}
    said = {"dng.dng": "a DNG (camera raw) file", "dngf.dng": "a DNG (camera raw) file",
            "nef.tif": "its first image is a reduced-resolution preview",
            "cfa.tif": "camera raw data (colour-filter-array)"}
    for name, kw in cases.items():
        tifffile.imwrite(tmp_path / name, metadata=None, **kw)
        with pytest.raises(InputError, match=re.escape(f"{name}: {said[name]}") + ".*develop it"):
            read_photo(tmp_path / name)
    tifffile.imwrite(tmp_path / "plain.tif", preview, photometric="rgb", metadata=None)
    assert read_photo(tmp_path / "plain.tif").pixels.shape == (12, 16, 3)


def test_a_heic_photo_or_a_raw_file_is_named_with_what_to_do(tmp_path):
    """An iPhone's default HEIC (an ISO media file, brand ``heic``) gets a message saying
    what it is and how to get a JPEG, and so do camera raw files known by their first
    bytes; bytes of no known kind get the general one."""
    head = b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic"
    (tmp_path / "IMG_0001.HEIC").write_bytes(head + bytes(200))
    with pytest.raises(InputError, match="IMG_0001.HEIC: a HEIF/HEIC image, which this tool "
                                         "does not read: convert it .*Most Compatible"):
        read_photo(tmp_path / "IMG_0001.HEIC")
    (tmp_path / "x.cr3").write_bytes(b"\x00\x00\x00\x18ftypcrx " + bytes(200))
    with pytest.raises(InputError, match="a Canon CR3 raw file.*develop it"):
        read_photo(tmp_path / "x.cr3")
    for name, head, kind in (("a.orf", b"IIRO\x08\x00\x00\x00", "an Olympus ORF raw file"),
                             ("a.rw2", b"IIU\x00\x18\x00\x00\x00", "a Panasonic RW2 raw file"),
                             ("a.raf", b"FUJIFILMCCD-RAW 0201", "a Fujifilm RAF raw file"),
                             ("a.cr2", b"II*\x00\x10\x00\x00\x00CR\x02\x00",
                              "a Canon CR2 raw file")):
        (tmp_path / name).write_bytes(head + bytes(200))
        with pytest.raises(InputError, match=f"{name}: {kind}, which this tool does not read: "
                                             "develop it"):
            read_photo(tmp_path / name)
    (tmp_path / "junk.jpg").write_bytes(bytes(range(256)))
    with pytest.raises(InputError, match="junk.jpg: not a JPEG, PNG or TIFF image"):
        read_photo(tmp_path / "junk.jpg")


@pytest.mark.parametrize("shape,bits", [((6, 10), 8), ((6, 10, 3), 8), ((6, 10), 16)])
def test_lzw_tiffs_with_orientation(tmp_path, shape, bits):
    # without imagecodecs tifffile cannot decode LZW, and Pillow (libtiff) takes over
    k, _ = levels(shape, bits, seed=10)
    im = Image.fromarray(k.astype(np.uint8 if bits == 8 else np.uint16))
    exif = Image.Exif()
    exif[274] = 8
    im.save(tmp_path / "lzw.tif", compression="tiff_lzw", exif=exif)
    photo = read_photo(tmp_path / "lzw.tif")
    assert photo.bit_depth == bits
    assert np.array_equal(np.rint(photo.pixels * (2**bits - 1)), k)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_the_pillow_fallback_undoes_each_orientation(tmp_path, monkeypatch, orientation):
    """Where Pillow decodes a TIFF (LZW without imagecodecs) it applies the Orientation tag
    while loading; each of the eight is undone, 8 and 16 bits: the pixels as stored."""
    k8, _ = levels((6, 10, 3), 8, seed=12)
    exif = Image.Exif()
    exif[274] = orientation
    Image.fromarray(k8.astype(np.uint8)).save(tmp_path / "o8.tif", compression="tiff_lzw",
                                              exif=exif)
    k16, _ = levels((6, 10, 3), 16, seed=13)
    tifffile.imwrite(tmp_path / "o16.tif", k16.astype(np.uint16), photometric="rgb",
                     compression="zlib", extratags=[(274, 3, 1, orientation, True)])
    for name, k, bits in (("o8.tif", k8, 8), ("o16.tif", k16, 16)):
        photo = _read_without_tifffile(tmp_path / name, monkeypatch)
        assert np.array_equal(np.rint(photo.pixels * (2**bits - 1)), k), name
        assert exif_values(photo.exif)[0][274] == orientation


def test_each_orientation_is_written_into_a_tiff(tmp_path):
    """The Orientation tag of the EXIF is an IFD0 tag of a TIFF written: all eight values
    (8, a phone held the other way up in portrait, among them)."""
    for orientation in range(1, 9):
        exif = Image.Exif()
        exif[271], exif[274] = "Canon", orientation
        src = like(smooth((6, 8, 3)), exif=exif.tobytes())
        out = write_photo(tmp_path / f"o{orientation}.tif", src.pixels, like=src)
        with tifffile.TiffFile(out) as tif:
            assert tif.pages.first.tags["Orientation"].value == orientation
        assert exif_values(read_photo(out).exif)[0][274] == orientation


def test_float_tiffs_are_clipped_and_reported_as_16bit(tmp_path):
    grey = np.array([[-0.2, 0.25, 1.9]], np.float32)
    tifffile.imwrite(tmp_path / "g.tif", grey, metadata=None)
    rgb = np.stack([grey, grey, grey], axis=-1)
    tifffile.imwrite(tmp_path / "c.tif", rgb, photometric="rgb", metadata=None)
    for name in ("g.tif", "c.tif"):
        with pytest.warns(UserWarning, match=f"{name}: .* outside \\[0, 1\\] are clipped"):
            photo = read_photo(tmp_path / name)
        assert photo.bit_depth == 16 and photo.pixels.dtype == np.float32
        assert np.allclose(photo.pixels.reshape(-1, 3 if name == "c.tif" else 1)[:, 0],
                           [0.0, 0.25, 1.0])
    tifffile.imwrite(tmp_path / "n.tif", np.array([[0.5, np.nan]], np.float32), metadata=None)
    with pytest.warns(UserWarning, match="1 NaN or infinite samples are read as 0"):
        assert np.array_equal(read_photo(tmp_path / "n.tif").pixels, [[0.5, 0.0]])


@pytest.mark.parametrize("values,scene,match", [
    ([0.0, 128.0, 255.0], False, "float samples up to 255, most of them above 1; .* by 255"),
    ([0.0, 3e4, 65535.0], False, "float samples up to 6.554e\\+04, most .* by 65535"),
    ([-0.5, 0.0, 0.5], False, "float samples down to -0.5; .* offset or negated"),
    ([-0.5, 0.0, 40.0], True, "float samples down to -0.5"),
])
def test_float_tiffs_far_outside_0_1_are_refused_not_clipped(tmp_path, values, scene, match):
    """Clipped, a 0-255 float photo would be white and an offset one half black: such a file
    is refused, naming it, where deblur() would refuse the array (a scene's lights above 1
    are kept for simulate; nothing far below black is light)."""
    tifffile.imwrite(tmp_path / "f.tif", np.array([values], np.float32), metadata=None)
    with pytest.raises(InputError, match=match) as e:
        read_photo(tmp_path / "f.tif", scene=scene)
    assert "f.tif" in str(e.value)
    # a photo mostly in [0, 1], its lights far above (clipped: the photo's clipped
    # highlights), and a stray cold pixel, are read
    ok = np.full(200, 0.5, np.float32)
    ok[:3], ok[3] = 40.0, -0.5
    tifffile.imwrite(tmp_path / "ok.tif", ok[None], metadata=None)
    with pytest.warns(UserWarning, match="4 float samples outside .* clipped"):
        assert read_photo(tmp_path / "ok.tif").pixels.max() == 1.0
    with pytest.warns(UserWarning, match="1 float samples below 0 are clipped"):
        assert read_photo(tmp_path / "ok.tif", scene=True).pixels.max() == 40.0


def test_only_the_first_page_of_a_stack_is_read_with_a_warning(tmp_path):
    stack = np.stack([np.full((4, 5), 10, np.uint8), np.full((4, 5), 200, np.uint8)])
    tifffile.imwrite(tmp_path / "s.tif", stack)
    with pytest.warns(UserWarning, match="only the first of its 2 pages"):
        photo = read_photo(tmp_path / "s.tif")
    assert photo.pixels.shape == (4, 5) and np.allclose(photo.pixels, 10 / 255)
    import warnings

    from gyrodeblur.errors import GyrodeblurWarning
    with warnings.catch_warnings():       # made an error: raised, not taken for a failed
        warnings.simplefilter("error", GyrodeblurWarning)  # decode that Pillow then reads
        with pytest.raises(GyrodeblurWarning, match="only the first of its 2 pages"):
            read_photo(tmp_path / "s.tif")
    # the stack's layout note ({"shape": [2, 4, 5]}) is not carried to a one-page output
    write_photo(tmp_path / "o.tif", photo.pixels, like=photo)
    with tifffile.TiffFile(tmp_path / "o.tif") as tif:
        assert "shape" not in tif.pages.first.description
        assert tif.series[0].shape == (4, 5)


def test_palette_grey_alpha_and_bilevel_are_normalised(tmp_path):
    Image.new("P", (4, 3), 1).save(tmp_path / "p.png")
    p = read_photo(tmp_path / "p.png")
    assert p.pixels.shape == (3, 4, 3) and p.bit_depth == 8
    pt = Image.new("P", (4, 3), 1)
    pt.info["transparency"] = 1
    pt.save(tmp_path / "pt.png", transparency=1)
    assert read_photo(tmp_path / "pt.png").pixels.shape == (3, 4, 4)
    Image.new("LA", (4, 3), (200, 50)).save(tmp_path / "la.png")
    la = read_photo(tmp_path / "la.png")
    assert la.pixels.shape == (3, 4, 4)
    assert np.allclose(la.pixels[0, 0] * 255, [200, 200, 200, 50])
    Image.new("1", (4, 3), 1).save(tmp_path / "b.png")
    b = read_photo(tmp_path / "b.png")
    assert b.pixels.shape == (3, 4) and b.bit_depth == 8 and b.pixels.min() == 1.0


# --------------------------------------------------------------------------- metadata


@pytest.mark.parametrize("src_ext", [".jpg", ".png", ".tif"])
@pytest.mark.parametrize("out_ext,bits", [(".jpg", 8), (".png", 8), (".png", 16),
                                          (".tif", 8), (".tif", 16)])
def test_exif_and_icc_survive_read_write_read(tmp_path, src_ext, out_ext, bits):
    block = exif_block()
    Image.fromarray(np.full((8, 12, 3), 90, np.uint8)).save(
        tmp_path / f"in{src_ext}", exif=block, icc_profile=SRGB)
    src = read_photo(tmp_path / f"in{src_ext}")
    assert src.icc_profile == SRGB
    assert exif_values(src.exif) == exif_values(block)
    out = read_photo(write_photo(tmp_path / f"out{out_ext}", src.pixels, like=src,
                                 bit_depth=None if out_ext == ".jpg" else bits))
    assert out.icc_profile == SRGB
    ifd0, sub, gps = exif_values(out.exif)
    assert (ifd0[271], ifd0[272], ifd0[274]) == ("Canon", "EOS R5", 6)   # make, model, turn
    assert sub[0x829A] == R(1, 60) and sub[0x920A] == 50 and gps[1] == "N"


XMP = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF>rated 4</rdf:RDF></x:xmpmeta>'


@pytest.mark.parametrize("src_ext", [".jpg", ".png", ".tif"])
@pytest.mark.parametrize("out_ext,bits", [(".jpg", 8), (".png", 8), (".png", 16),
                                          (".tif", 8), (".tif", 16)])
def test_print_resolution_and_xmp_survive_read_write_read(tmp_path, src_ext, out_ext, bits):
    """dpi and the XMP packet are carried as EXIF is (a PNG's XMP is its iTXt chunk), beside
    an EXIF block (a TIFF's sub-IFDs are appended after the resolution tags)."""
    im = Image.fromarray(np.full((8, 12, 3), 90, np.uint8))
    if src_ext == ".png":
        info = PngImagePlugin.PngInfo()
        info.add_itxt("XML:com.adobe.xmp", XMP.decode())
        im.save(tmp_path / "in.png", exif=exif_block(), dpi=(300, 150), pnginfo=info)
    elif src_ext == ".tif":                          # XMP is tag 700 of IFD0
        exif = Image.Exif()
        exif.load(exif_block())
        exif[700] = XMP
        im.save(tmp_path / "in.tif", exif=exif, dpi=(300, 150))
    else:
        im.save(tmp_path / "in.jpg", exif=exif_block(), dpi=(300, 150), xmp=XMP)
    src = read_photo(tmp_path / f"in{src_ext}")
    assert src.dpi == pytest.approx((300, 150), abs=0.01)
    out = read_photo(write_photo(tmp_path / f"out{out_ext}", src.pixels, like=src,
                                 bit_depth=None if out_ext == ".jpg" else bits))
    assert out.dpi == pytest.approx((300, 150), abs=0.01)
    got = out.png_text["XML:com.adobe.xmp"].encode() if out_ext == ".png" else out.xmp
    assert got == XMP
    assert exif_values(out.exif)[0][271] == "Canon"


@pytest.mark.parametrize("bits", [8, 16])
def test_png_text_chunks_are_carried_but_not_a_second_exif(tmp_path, bits):
    """A PNG's text (Latin-1 and not) survives; ImageMagick's raw EXIF profile, read as the
    EXIF block and written as eXIf, is not also written as text."""
    info = PngImagePlugin.PngInfo()
    info.add_text("Copyright", "Ann Onym\u00e9")
    info.add_itxt("Title", "\u65e5\u306e\u51fa")
    info.add_text("Raw profile type exif", "stale")
    Image.fromarray(np.full((4, 5, 3), 90, np.uint8)).save(tmp_path / "in.png", pnginfo=info)
    src = read_photo(tmp_path / "in.png")
    assert src.png_text == {"Copyright": "Ann Onym\u00e9", "Title": "\u65e5\u306e\u51fa"}
    out = write_photo(tmp_path / "out.png", src.pixels, like=src, bit_depth=bits)
    with Image.open(out) as im:
        im.load()
        assert im.text == src.png_text
    assert read_photo(write_photo(tmp_path / "no.png", src.pixels)).png_text is None


def png_chunks(path):
    """(type, data) of every chunk of a PNG file."""
    data, pos, out = open(path, "rb").read(), 8, []
    while pos < len(data):
        n = struct.unpack(">I", data[pos:pos + 4])[0]
        out.append((data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]))
        pos += 12 + n
    return out


def test_only_a_resolution_the_file_states_is_carried(tmp_path):
    """No print resolution is made up: a TIFF without resolution tags (Pillow's and
    OpenCV's) and a JPEG whose JFIF density is an aspect ratio, with no EXIF resolution,
    have none, and their outputs state none (Pillow reads them as 1 and 72 dpi); such a
    JPEG's EXIF resolution counts, per cm too; a float TIFF (read by tifffile) keeps its
    dpi and XMP; a resolution under 1 pixel per metre is dropped."""
    rgb = np.full((8, 12, 3), 90, np.uint8)
    Image.fromarray(rgb).save(tmp_path / "plain.tif")
    exif = Image.Exif()
    exif[271] = "Canon"
    Image.fromarray(rgb).save(tmp_path / "aspect.jpg", exif=exif.tobytes())
    for name in ("plain.tif", "aspect.jpg"):
        src = read_photo(tmp_path / name)
        assert src.dpi is None, name
        out = write_photo(tmp_path / f"{name}.out.tif", src.pixels, like=src)
        with tifffile.TiffFile(out) as tif:
            assert int(tif.pages.first.tags["ResolutionUnit"].value) == 1, name    # none
    exif[0x011A], exif[0x011B], exif[0x0128] = 118.11, 118.11, 3                # per cm
    Image.fromarray(rgb).save(tmp_path / "exif_dpi.jpg", exif=exif.tobytes())
    assert read_photo(tmp_path / "exif_dpi.jpg").dpi == (300.0, 300.0)
    tifffile.imwrite(tmp_path / "f.tif", np.full((8, 12, 3), 0.5, np.float32),
                     photometric="rgb", resolution=(240, 240), resolutionunit="INCH",
                     extratags=[(700, 1, len(XMP), XMP, True)])
    flt = read_photo(tmp_path / "f.tif")
    assert flt.dpi == (240.0, 240.0) and flt.xmp == XMP
    tiny = dataclasses.replace(flt, dpi=(0.01, 0.01))
    out = read_photo(write_photo(tmp_path / "tiny.png", tiny.pixels, like=tiny))
    assert out.dpi is None


def test_print_resolution_units_jfif_per_cm_and_none(tmp_path):
    """A JPEG's JFIF density per cm is read in pixels per inch; X/YResolution without a
    unit (ResolutionUnit 1, as tifffile writes by default) states no print resolution."""
    Image.new("RGB", (8, 6)).save(tmp_path / "cm.jpg", dpi=(300, 150))
    data = bytearray((tmp_path / "cm.jpg").read_bytes())
    assert data[6:11] == b"JFIF\0"
    data[13:18] = struct.pack(">BHH", 2, 118, 59)             # per cm
    (tmp_path / "cm.jpg").write_bytes(bytes(data))
    assert read_photo(tmp_path / "cm.jpg").dpi == pytest.approx((118 * 2.54, 59 * 2.54))
    tifffile.imwrite(tmp_path / "none.tif", np.zeros((6, 8, 3), np.uint8), photometric="rgb",
                     resolution=(72, 72), resolutionunit="NONE")
    assert read_photo(tmp_path / "none.tif").dpi is None
    exif = Image.Exif()
    exif[0x011A], exif[0x011B], exif[0x0128] = 72.0, 72.0, 1                  # no unit
    Image.new("RGB", (8, 6)).save(tmp_path / "none.jpg", exif=exif.tobytes())
    assert read_photo(tmp_path / "none.jpg").dpi is None


def test_a_utf16_xmp_packet_goes_into_a_png_as_text(tmp_path):
    """XMP may be UTF-16 (with a byte-order mark): a PNG's XMP chunk gets its text."""
    for codec in ("utf-16", "utf-16-be", "utf-32"):
        packet = XMP.decode().encode(codec)
        if codec == "utf-16-be":
            packet = b"\xfe\xff" + packet
        src = Photo(np.full((4, 5, 3), 0.4, np.float32), 8, "JPEG", xmp=packet)
        out = read_photo(write_photo(tmp_path / f"{codec}.png", src.pixels, like=src))
        assert out.png_text == {"XML:com.adobe.xmp": XMP.decode()}, codec


def test_an_xmp_packet_at_the_jpeg_limit(tmp_path):
    """65504 bytes of XMP fit one JPEG segment and are kept; one more is left out with a
    warning (Pillow refuses to write it)."""
    for size, kept in ((65504, True), (65505, False)):
        src = Photo(np.full((4, 5, 3), 0.4, np.float32), 8, "TIFF", xmp=b"x" * size)
        if kept:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                out = write_photo(tmp_path / f"{size}.jpg", src.pixels, like=src)
        else:
            with pytest.warns(UserWarning, match="XMP .65505 bytes. is longer than one JPEG"):
                out = write_photo(tmp_path / f"{size}.jpg", src.pixels, like=src)
        assert read_photo(out).xmp == (src.xmp if kept else None)


@pytest.mark.parametrize("bits", [8, 16])
def test_png_xmp_and_international_text_are_itxt_chunks(tmp_path, bits):
    """XMP goes into a PNG as an iTXt chunk, where the XMP standard (and Pillow's
    ``getxmp``) look for it, even when it is plain ASCII; an iTXt keeps its language tag
    and translated keyword; a keyword is Latin-1; XMP that is not Unicode text is left out
    of a PNG with a warning."""
    src = Photo(np.full((4, 5, 3), 0.4, np.float32), 8, "JPEG", xmp=XMP,
                png_text={"Gr\u00f6\u00dfe": "\u65e5", "Title": PngImagePlugin.iTXt("Hi", "en", "Titel")})
    out = write_photo(tmp_path / "x.png", src.pixels, like=src, bit_depth=bits)
    chunks = dict((k.decode("latin-1").split("\0")[0], t) for t, k in png_chunks(out)
                  if t in (b"tEXt", b"iTXt"))
    assert chunks == {"XML:com.adobe.xmp": b"iTXt", "Gr\u00f6\u00dfe": b"iTXt",
                      "Title": b"iTXt"}
    with Image.open(out) as im:
        im.load()
        assert im.info["xmp"] == XMP
        assert (im.text["Title"].lang, im.text["Title"].tkey) == ("en", "Titel")
        assert im.text["Gr\u00f6\u00dfe"] == "\u65e5"
    bad = dataclasses.replace(src, xmp=b"<x>\xff</x>", png_text=None)
    with pytest.warns(UserWarning, match="XMP is not UTF-8"):
        out = write_photo(tmp_path / "bad.png", bad.pixels, like=bad, bit_depth=bits)
    assert read_photo(out).png_text is None


@pytest.mark.parametrize("bits", [8, 16])
def test_a_png_text_keyword_longer_than_79_characters_is_left_out(tmp_path, bits):
    """The PNG standard allows keywords of 1 to 79 Latin-1 characters; text under any
    other keyword is not written (libpng drops such a chunk as damaged)."""
    src = Photo(np.full((4, 5, 3), 0.4, np.float32), 8, "PNG",
                png_text={"K" * 79: "kept", "L" * 80: "left out", "": "left out"})
    out = write_photo(tmp_path / "t.png", src.pixels, like=src, bit_depth=bits)
    assert read_photo(out).png_text == {"K" * 79: "kept"}


def test_an_imagemagick_png_s_exif_text_chunk_is_read_as_its_exif(tmp_path):
    """ImageMagick stores a PNG's EXIF as hex in a "Raw profile type exif" text chunk: it
    is the photo's EXIF block (written back as eXIf), not text."""
    block = exif_block()
    info = PngImagePlugin.PngInfo()
    info.add_text("Raw profile type exif", f"\nexif\n{len(block):8d}\n{block.hex()}\n")
    Image.fromarray(np.full((4, 5, 3), 90, np.uint8)).save(tmp_path / "im.png", pnginfo=info)
    src = read_photo(tmp_path / "im.png")
    assert src.png_text is None
    assert exif_values(src.exif) == exif_values(block)
    out = read_photo(write_photo(tmp_path / "out.png", src.pixels, like=src))
    assert exif_values(out.exif)[0][271] == "Canon"


def test_an_xmp_packet_too_long_for_a_jpeg_is_left_out_with_a_warning(tmp_path):
    src = like()
    src = Photo(pixels=src.pixels, bit_depth=8, format="TIFF", xmp=b"x" * 70_000)
    with pytest.warns(UserWarning, match="XMP .70000 bytes. is longer than one JPEG"):
        out = write_photo(tmp_path / "a.jpg", src.pixels, like=src)
    assert read_photo(out).xmp is None
    assert read_photo(write_photo(tmp_path / "a.tif", src.pixels, like=src)).xmp == src.xmp


def test_jpeg_and_png_exif_blocks_pass_through_byte_for_byte(tmp_path):
    block = exif_block()
    Image.new("RGB", (8, 8)).save(tmp_path / "in.jpg", exif=block)
    src = read_photo(tmp_path / "in.jpg")
    assert src.exif == block
    for name in ("a.jpg", "b.png"):
        assert read_photo(write_photo(tmp_path / name, src.pixels, like=src)).exif == block
    assert read_photo(write_photo(tmp_path / "c.png", src.pixels, like=src,
                                  bit_depth=16)).exif == block


def _exif_with_thumbnail(order: str) -> bytes:
    """An EXIF block written by hand: IFD0 with the Orientation (6), then IFD1 holding a
    small JPEG thumbnail, byte order ``"<"`` (II) or ``">"`` (MM)."""
    import io

    buf = io.BytesIO()
    Image.new("RGB", (16, 12), (200, 30, 30)).save(buf, "JPEG")
    thumb = buf.getvalue()
    head = (b"II" if order == "<" else b"MM") + struct.pack(order + "HI", 42, 8)
    ifd0 = struct.pack(order + "H", 1) + struct.pack(order + "HHIHH", 0x0112, 3, 1, 6, 0) \
        + struct.pack(order + "I", 26)
    ifd1 = struct.pack(order + "H", 2) + struct.pack(order + "HHII", 0x0201, 4, 1, 56) \
        + struct.pack(order + "HHII", 0x0202, 4, 1, len(thumb)) + struct.pack(order + "I", 0)
    return b"Exif\0\0" + head + ifd0 + ifd1 + thumb


@pytest.mark.parametrize("order", ["<", ">"])
def test_the_blurred_photo_s_exif_thumbnail_is_not_carried(tmp_path, order):
    """Session 59's audit: the EXIF block was carried byte for byte, its thumbnail with it:
    a file browser showed the deblurred photo's preview blurred. IFD1 is now unlinked
    from IFD0 (every other byte kept, so a maker's notes keep their offsets); the
    Orientation stays."""
    from PIL import ExifTags

    block = _exif_with_thumbnail(order)
    Image.new("RGB", (32, 24)).save(tmp_path / "in.jpg", exif=block)
    src = read_photo(tmp_path / "in.jpg")
    assert src.exif == block
    with Image.open(tmp_path / "in.jpg") as im:                   # the thumbnail is there
        assert 0x0201 in im.getexif().get_ifd(ExifTags.IFD.IFD1)
    for name in ("a.jpg", "b.png"):
        out = write_photo(tmp_path / name, src.pixels, like=src)
        got = read_photo(out).exif
        assert len(got) == len(block) and got != block
        with Image.open(out) as im:
            exif = im.getexif()
            assert exif[0x0112] == 6 and not exif.get_ifd(ExifTags.IFD.IFD1)


def test_icc_profile_of_the_wrong_colour_space_is_left_out(tmp_path):
    src = like(icc=SRGB)
    out = read_photo(write_photo(tmp_path / "grey.png", np.zeros((4, 4), np.float32), like=src))
    assert out.icc_profile is None


@pytest.mark.parametrize("cut", [0, 200, len(SRGB) - 1])
def test_a_damaged_icc_profile_is_left_out_with_a_warning(tmp_path, cut):
    damaged = SRGB[:cut] if cut else SRGB[:36] + b"xxxx" + SRGB[40:]   # no 'acsp'
    with pytest.warns(UserWarning, match=r"out.png: the photo's ICC profile is damaged "
                                         r"\((cut short|not an ICC profile)"):
        out = write_photo(tmp_path / "out.png", smooth((4, 5, 3)), like=like(icc=damaged))
    assert read_photo(out).icc_profile is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")           # a whole one is carried without a word
        out = write_photo(tmp_path / "whole.png", smooth((4, 5, 3)), like=like(icc=SRGB))
    assert read_photo(out).icc_profile == SRGB


def test_no_metadata_gives_none(tmp_path):
    photo = read_photo(write_photo(tmp_path / "a.png", smooth((4, 5, 3))))
    assert photo.exif is None and photo.icc_profile is None


# --------------------------------------------------------------------------- hints


def hints_for(shape, **tags):
    return exif_capture_hints(like(np.zeros(shape, np.float32), exif=exif_block(**tags)))


def test_hints_exposure_focal_length_and_35mm_fx():
    hints = hints_for((40, 60, 3), x_A405=50)  # 3:2 landscape
    assert hints["exposure_time"] == pytest.approx(1 / 60)
    assert hints["focal_length_mm"] == pytest.approx(50.0)
    assert hints["fx"] == pytest.approx(50 / 36 * 60)  # the width rule, for 3:2


def test_hints_35mm_uses_the_diagonal_for_other_aspects_and_portrait():
    hints = hints_for((40, 30), x_A405=26)  # 4:3 portrait
    assert hints["fx"] == pytest.approx(26 * 50 / math.hypot(36, 24))


@pytest.mark.parametrize("unit,mm", [(2, 25.4), (3, 10.0)])
def test_hints_focal_plane_resolution(unit, mm):
    hints = hints_for((40, 60), x_A20E=R(4000, 1), x_A210=unit)
    assert hints["fx"] == pytest.approx(50 * 4000 / mm)
    scaled = hints_for((40, 60), x_A20E=R(4000, 1), x_A210=unit, x_A002=6000, x_A003=4000)
    assert scaled["fx"] == pytest.approx(50 * 4000 / mm * 60 / 6000)
    # an unknown 35mm equivalent (0) does not hide the focal-plane route
    assert hints_for((40, 60), x_A20E=R(4000, 1), x_A210=unit, x_A405=0)["fx"] == \
        pytest.approx(hints["fx"])


def test_hints_capture_time_in_unix_time_from_its_zone_and_fraction():
    """DateTimeOriginal is the local time; OffsetTimeOriginal its zone (without it there
    is no Unix time, only the text); SubSecTimeOriginal the digits after the second."""
    hints = hints_for((4, 4), x_9003="2024:12:05 07:27:10", x_9011="+01:00", x_9291="512")
    assert hints["capture_time_unix"] == pytest.approx(1733380030.512, abs=1e-6)
    assert hints["capture_time_text"] == "2024:12:05 07:27:10.512 +01:00"
    west = hints_for((4, 4), x_9003="2024:12:05 00:57:10", x_9011="-05:30", x_9291="05")
    assert west["capture_time_unix"] == pytest.approx(1733380030.05, abs=1e-6)
    short = hints_for((4, 4), x_9003="2024:12:05 07:27:10", x_9010="+01", x_9291="5\xb2")
    # OffsetTime's zone; a damaged fraction is none: the time is the second's middle
    assert short["capture_time_unix"] == pytest.approx(1733380030.5, abs=1e-6)
    assert short["capture_time_text"] == "2024:12:05 07:27:10 +01"
    assert short["capture_time_whole_second"] and "capture_time_whole_second" not in west
    whole = hints_for((4, 4), x_9003="2024:12:05 07:27:10", x_9011="+01:00")  # no SubSec
    assert whole["capture_time_unix"] == pytest.approx(1733380030.5, abs=1e-6)
    assert whole["capture_time_whole_second"]
    local = hints_for((4, 4), x_9003="2024:12:05 07:27:10")
    assert "capture_time_unix" not in local
    assert local["capture_time_text"] == "2024:12:05 07:27:10"
    assert "capture_time_text" not in hints_for((4, 4), x_9003="0000:00:00 00:00:00")


def test_hints_say_which_values_are_present_but_unreadable():
    """A negative ExposureTime or a DateTimeOriginal that is no date is said to be there
    and unreadable (for a message better than "missing"); the EXIF "unknown" (0, all
    zeros) and a readable value are not."""
    bad = hints_for((4, 4), x_829A=R(-3, 100), x_9003="2024:13:45 99:99:99")
    assert "exposure_time" not in bad and "capture_time_text" not in bad
    assert bad["unreadable"] == {"exposure_time": "ExposureTime -0.03",
                                 "capture_time": "DateTimeOriginal '2024:13:45 99:99:99'"}
    for ok in (hints_for((4, 4), x_829A=R(0, 1), x_9003="0000:00:00 00:00:00"),
               hints_for((4, 4), x_9003="2024:12:05 07:27:10")):
        assert "unreadable" not in ok


def test_hints_focal_plane_resolution_in_mm_and_the_inch_default():
    """FocalPlaneResolutionUnit 4 is pixels per mm (as some cameras write); without the
    unit tag the EXIF default, inches, applies."""
    assert hints_for((40, 60), x_A20E=R(250, 1), x_A210=4)["fx"] == pytest.approx(50 * 250)
    assert hints_for((40, 60), x_A20E=R(4000, 1))["fx"] == pytest.approx(50 * 4000 / 25.4)


def test_hints_the_35mm_equivalent_comes_first_and_a_resize_scales_by_the_long_side():
    """With both a 35 mm equivalent and a focal-plane resolution, fx is the 35 mm one; a
    resized photo's focal-plane fx scales by its long side over the recorded long side,
    whichever way the photo stands."""
    both = hints_for((40, 60), x_A405=50, x_A20E=R(4000, 1), x_A210=2)
    assert both["fx"] == pytest.approx(50 / 36 * 60)
    portrait = hints_for((60, 40), x_A20E=R(4000, 1), x_A210=2, x_A002=6000, x_A003=4000)
    assert portrait["fx"] == pytest.approx(50 * 4000 / 25.4 * 60 / 6000)


def test_hints_offset_time_original_is_the_zone_before_offset_time():
    """OffsetTimeOriginal is DateTimeOriginal's own zone; OffsetTime (the file's) is only
    the fallback: a photo edited abroad must not move its capture time by hours."""
    hints = hints_for((4, 4), x_9003="2024:12:05 07:27:10", x_9291="512",
                      x_9011="+01:00", x_9010="-08:00")
    assert hints["capture_time_unix"] == pytest.approx(1733380030.512, abs=1e-6)
    assert hints["capture_time_text"] == "2024:12:05 07:27:10.512 +01:00"
    # an OffsetTimeOriginal written blank (EXIF's "unknown") leaves OffsetTime to say it
    for blank in ("   :  ", "", "\x00"):
        hints = hints_for((4, 4), x_9003="2024:12:05 07:27:10", x_9291="512",
                          x_9011=blank, x_9010="+01:00")
        assert hints["capture_time_unix"] == pytest.approx(1733380030.512, abs=1e-6)
        assert hints["capture_time_text"] == "2024:12:05 07:27:10.512 +01:00"


def test_hints_digital_zoom_only_where_the_camera_zoomed():
    """DigitalZoomRatio above 1 is reported; 1, and the standard's 0/0 or 0/1 for "not
    used", are not; fx is left as the focal-length tags give it."""
    zoomed = hints_for((40, 60), x_A405=50, x_A404=R(2, 1))
    assert zoomed["digital_zoom"] == pytest.approx(2.0)
    assert zoomed["fx"] == pytest.approx(hints_for((40, 60), x_A405=50)["fx"])
    assert hints_for((40, 60), x_A404=R(13, 10))["digital_zoom"] == pytest.approx(1.3)
    for none in (R(1, 1), R(0, 1), R(0, 0)):
        assert "digital_zoom" not in hints_for((40, 60), x_A404=none)


def test_hints_missing_or_damaged_exif():
    assert "fx" not in hints_for((40, 60))
    assert exif_capture_hints(like()) == {}
    assert exif_capture_hints(like(exif=b"Exif\x00\x00garbage")) == {}


# --------------------------------------------------------------------------- writing


def test_bit_depth_choice(tmp_path):
    px = smooth((4, 5, 3))
    src = like(bit_depth=16)
    assert read_photo(write_photo(tmp_path / "a.png", px, like=src)).bit_depth == 16
    assert read_photo(write_photo(tmp_path / "b.tif", px, like=src, bit_depth=8)).bit_depth == 8
    assert read_photo(write_photo(tmp_path / "c.png", px)).bit_depth == 8
    with pytest.warns(UserWarning, match="written at 8"):
        assert read_photo(write_photo(tmp_path / "d.jpg", px, like=src)).bit_depth == 8
    with pytest.raises(InputError, match="e.jpg"):
        write_photo(tmp_path / "e.jpg", px, bit_depth=16)
    with pytest.raises(InputError, match="alpha"):
        write_photo(tmp_path / "f.jpg", smooth((4, 5, 4)))


def test_bad_pixels_are_refused(tmp_path):
    with pytest.raises(ValueError, match="float"):
        write_photo(tmp_path / "a.png", np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="shape"):
        write_photo(tmp_path / "a.png", np.zeros((4, 4, 5), np.float32))
    with pytest.raises(ValueError, match="NaN"):
        write_photo(tmp_path / "a.png", np.full((4, 4), np.nan, np.float32))
    # infinite values and 0-255 values: no clipping makes them a photo
    px = smooth((8, 8, 3))
    ramp = px + np.linspace(-0.1, 0.1, 8, dtype=np.float32)[:, None, None]  # an overshoot:
    write_photo(tmp_path / "ok.png", ramp)                                # written, clipped
    os.remove(tmp_path / "ok.png")
    inf = px.copy()
    inf[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="pixels contain infinite values"):
        write_photo(tmp_path / "a.png", inf)
    with pytest.raises(InputError, match=r"a.png: float samples up to .*most of them above 1; "
                                         r"expected light in \[0, 1\] \(divide 0-255"):
        write_photo(tmp_path / "a.png", px * 255)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name,depth", [("la.png", 8), ("la16.png", 16), ("la.tif", 8),
                                        ("la16.tif", 16)])
def test_grey_and_alpha_are_written_as_they_are_read(tmp_path, name, depth):
    """An (H, W, 2) array is grey + alpha, and is stored as grey + alpha. Such a file reads
    as RGBA with equal colours (``grey_alpha``; ``stored_channels`` gives the two), and
    written ``like`` it, RGBA goes back to grey + alpha, with a grey ICC profile kept."""
    import tifffile
    from PIL import ImageCms
    la = np.dstack([np.linspace(0, 1, 20).reshape(4, 5), np.full((4, 5), 0.6)]).astype(np.float32)
    path = write_photo(tmp_path / name, la, bit_depth=depth)
    if name.endswith(".tif"):
        assert tifffile.imread(path).shape == (4, 5, 2)
    else:                         # IHDR: bit depth, colour type 4 (grey + alpha)
        assert open(path, "rb").read()[24:26] == bytes([depth, 4])
    photo = read_photo(path)
    assert photo.grey_alpha and photo.bit_depth == depth and photo.pixels.shape == (4, 5, 4)
    step = 0.5 / (2 ** depth - 1)
    assert np.allclose(photo.pixels[..., :3], la[..., :1], atol=step)
    assert np.allclose(photo.stored_channels, la, atol=step)
    grey_icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("LAB")).tobytes()
    grey_icc = grey_icc[:16] + b"GRAY" + grey_icc[20:]       # a grey data colour space
    photo = dataclasses.replace(photo, icc_profile=grey_icc)
    out = write_photo(tmp_path / ("b_" + name), photo.pixels, like=photo)
    again = read_photo(out)
    assert again.grey_alpha and again.icc_profile == grey_icc
    assert np.array_equal(again.pixels, photo.pixels)


@pytest.mark.parametrize("name", ["out.bmp", "out"])
def test_unknown_extension(tmp_path, name):
    with pytest.raises(InputError, match=name):
        write_photo(tmp_path / name, smooth((4, 4)))


def test_returns_path_and_leaves_no_temporary_file(tmp_path):
    assert write_photo(str(tmp_path / "a.png"), smooth((4, 4))) == str(tmp_path / "a.png")
    assert os.listdir(tmp_path) == ["a.png"]


def test_refuses_existing_output_unless_overwrite(tmp_path):
    out = tmp_path / "a.png"
    write_photo(out, np.zeros((4, 4), np.float32))
    with pytest.raises(InputError, match=r"exists; --overwrite \(overwrite=True\) replaces it") as info:
        write_photo(out, np.ones((4, 4), np.float32))
    assert "a.png" in str(info.value)
    assert read_photo(out).pixels.max() == 0
    for empty in ("", "  "):                  # not ": unknown image type"
        with pytest.raises(InputError, match="^an output file's name is empty"):
            write_photo(empty, np.ones((4, 4), np.float32))
    write_photo(out, np.ones((4, 4), np.float32), overwrite=True)
    assert read_photo(out).pixels.min() == 1


def test_never_overwrites_the_input(tmp_path):
    (tmp_path / "sub").mkdir()
    write_photo(tmp_path / "in.png", np.zeros((4, 4), np.float32))
    src = read_photo(tmp_path / "in.png")
    os.symlink(tmp_path / "in.png", tmp_path / "link.png")
    for target in (tmp_path / "in.png", tmp_path / "sub" / ".." / "in.png", tmp_path / "link.png"):
        with pytest.raises(InputError, match="input"):
            write_photo(target, np.ones((4, 4), np.float32), like=src, overwrite=True)
    assert read_photo(tmp_path / "in.png").pixels.max() == 0


def test_never_overwrites_the_input_through_a_hard_link(tmp_path):
    """A hard link is the input photo under another name (realpath cannot tell)."""
    write_photo(tmp_path / "in.png", np.zeros((4, 4), np.float32))
    src = read_photo(tmp_path / "in.png")
    os.link(tmp_path / "in.png", tmp_path / "hard.png")
    with pytest.raises(InputError, match="hard.png: is the input photo"):
        write_photo(tmp_path / "hard.png", np.ones((4, 4), np.float32), like=src,
                    overwrite=True)
    assert read_photo(tmp_path / "in.png").pixels.max() == 0


def test_a_dangling_link_at_the_output_is_an_existing_file(tmp_path):
    """A symbolic link whose target is gone is still a name in the folder: not replaced
    without ``overwrite``."""
    os.symlink(tmp_path / "gone.png", tmp_path / "out.png")
    with pytest.raises(InputError, match="out.png: exists"):
        write_photo(tmp_path / "out.png", np.zeros((4, 4), np.float32))
    assert os.path.islink(tmp_path / "out.png")


def test_check_destination_is_the_same_check_without_writing(tmp_path):
    imageio.check_destination(tmp_path / "new.png")
    with pytest.raises(InputError, match="unknown image type"):
        imageio.check_destination(tmp_path / "new.gif")
    (tmp_path / "old.png").write_bytes(b"x")
    with pytest.raises(InputError, match="exists"):
        imageio.check_destination(tmp_path / "old.png")
    imageio.check_destination(tmp_path / "old.png", overwrite=True)
    with pytest.raises(InputError, match="input"):
        imageio.check_destination(tmp_path / "old.png", like(path=str(tmp_path / "old.png")),
                                  overwrite=True)
    assert sorted(os.listdir(tmp_path)) == ["old.png"]


def test_missing_folder_is_an_input_error_and_writes_nothing(tmp_path):
    out = tmp_path / "nope" / "a.png"
    with pytest.raises(InputError, match="does not exist") as info:
        write_photo(out, smooth((4, 4)))
    assert str(out) in str(info.value)
    assert os.listdir(tmp_path) == []


def test_failed_write_removes_temporary_and_keeps_old_file(tmp_path, monkeypatch):
    out = tmp_path / "a.png"
    write_photo(out, np.zeros((4, 4), np.float32))
    before = out.read_bytes()

    def broken(f, ints, **kwargs):
        f.write(b"partial")
        raise RuntimeError("encoder crashed")

    monkeypatch.setattr(imageio, "_write_png", broken)
    with pytest.raises(RuntimeError):
        write_photo(out, np.ones((4, 4), np.float32), overwrite=True)
    assert os.listdir(tmp_path) == ["a.png"] and out.read_bytes() == before

    def full(f, ints, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(imageio, "_write_png", full)
    with pytest.raises(InputError, match="No space left"):
        write_photo(tmp_path / "b.png", np.ones((4, 4), np.float32))
    assert os.listdir(tmp_path) == ["a.png"]


def test_the_temporary_file_is_hidden_beside_the_destination(tmp_path, monkeypatch):
    """The file is written under a new hidden, random name in the destination's folder
    (so that the move into place is one rename on one file system), never under a name
    a user's file may have; a folder refusing new files is said, naming the output."""
    from gyrodeblur.atomicfile import atomic_write, atomic_write_text, check_writable

    (tmp_path / "a.png.tmp").write_bytes(b"mine")
    seen = []
    for _ in range(2):
        atomic_write(tmp_path / "a.png", lambda f: seen.append(f.name))
    assert [os.path.dirname(n) for n in seen] == [str(tmp_path)] * 2
    assert all(os.path.basename(n).startswith(".a.png.") for n in seen) and seen[0] != seen[1]
    assert (tmp_path / "a.png.tmp").read_bytes() == b"mine"
    atomic_write_text(tmp_path / "t.json", '{"lens": "\u00e9 \u2713"}')
    assert (tmp_path / "t.json").read_bytes().decode("utf-8") == '{"lens": "\u00e9 \u2713"}'

    def refuse(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    with monkeypatch.context() as m:
        m.setattr(os, "open", refuse)
        with pytest.raises(InputError, match=re.escape(f"o.png: cannot write in folder "
                                                       f"{tmp_path}: Permission denied")):
            check_writable(tmp_path / "o.png")


# --------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="missing.png.*not found"):
        read_photo(tmp_path / "missing.png")


def test_text_file_named_png(tmp_path):
    (tmp_path / "notes.png").write_text("not an image\n")
    with pytest.raises(InputError, match="notes.png"):
        read_photo(tmp_path / "notes.png")


@pytest.mark.parametrize("name,bits", [("cut.jpg", 8), ("cut.png", 8), ("cut16.png", 16),
                                       ("cut16.tif", 16)])
def test_truncated_files(tmp_path, name, bits):
    full = tmp_path / f"full{os.path.splitext(name)[1]}"
    _, pixels = levels((64, 64, 3), bits, seed=9)
    write_photo(full, pixels, bit_depth=bits)
    data = full.read_bytes()
    (tmp_path / name).write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=name):
        read_photo(tmp_path / name)


@pytest.mark.parametrize("layout", ["pixels first", "directory first", "float RGB"])
def test_a_tiff_cut_short_is_refused_as_truncated(tmp_path, recwarn, layout):
    """A TIFF cut short (an interrupted copy) is told as such, whether the cut loses its
    directory (Pillow writes it after the pixels) or its pixels (tifffile writes the
    directory first), and whichever decoder would read it, with no other warning; an
    empty file is told as empty."""
    rng = np.random.default_rng(3)
    full = tmp_path / "full.tif"
    if layout == "pixels first":
        Image.fromarray(rng.integers(0, 255, (96, 96, 3), np.uint8)).save(
            full, compression="tiff_lzw")
    else:
        pixels = rng.random((96, 96, 3)).astype(np.float32 if layout == "float RGB"
                                                 else np.float64)
        tifffile.imwrite(full, pixels if layout == "float RGB" else
                         (pixels * 65535).astype(np.uint16), photometric="rgb",
                         metadata=None)
    data = full.read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) * 6 // 10])
    where = "first directory is at byte" if layout == "pixels first" else "image data runs to"
    with pytest.raises(InputError, match=rf"cut.tif: truncated: the file has "
                                         rf"{len(data) * 6 // 10} bytes, but its {where}"):
        read_photo(tmp_path / "cut.tif")
    if layout == "pixels first":      # the directory last: a cut inside it, of any length
        for lost in (1, 7, 30, 60, 120):
            (tmp_path / "cut.tif").write_bytes(data[:-lost])
            with pytest.raises(InputError, match=r"cut.tif: truncated: the file has \d+ "
                                                 r"bytes, but its (first directory|tag \d+)"):
                read_photo(tmp_path / "cut.tif")
    assert not recwarn.list
    (tmp_path / "empty.jpg").write_bytes(b"")
    with pytest.raises(InputError, match=r"empty.jpg: the file is empty \(0 bytes\)"):
        read_photo(tmp_path / "empty.jpg")


def test_unsupported_formats_and_modes(tmp_path):
    Image.new("RGB", (4, 4)).save(tmp_path / "a.gif")
    with pytest.raises(InputError, match="a.gif.*GIF"):
        read_photo(tmp_path / "a.gif")
    Image.new("CMYK", (4, 4)).save(tmp_path / "c.jpg")
    with pytest.raises(InputError, match="c.jpg.*CMYK"):
        read_photo(tmp_path / "c.jpg")
    with pytest.raises(InputError, match="folder"):
        read_photo(tmp_path)


def test_photo_is_frozen_with_identity_equality():
    photo = like()
    with pytest.raises(AttributeError):
        photo.bit_depth = 16
    assert photo == photo and photo != like() and hash(photo) == hash(photo)
    with pytest.raises(ValueError):
        like(bit_depth=12)


def test_a_scene_keeps_light_above_white(tmp_path):
    rgb = np.stack([np.array([[-0.2, 0.25, 8.0]], np.float32)] * 3, axis=-1)
    tifffile.imwrite(tmp_path / "hdr.tif", rgb, photometric="rgb", metadata=None)
    with pytest.warns(UserWarning, match="3 float samples below 0 are clipped \\(range -0.2 to 8\\)$"):
        scene = read_photo(tmp_path / "hdr.tif", scene=True)
    assert np.allclose(scene.pixels[0, :, 0], [0.0, 0.25, 8.0])
    with pytest.warns(UserWarning, match=r"6 float samples outside \[0, 1\]"):
        assert read_photo(tmp_path / "hdr.tif").pixels.max() == 1.0


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_tiff_extra_samples_become_straight_alpha_or_are_dropped(tmp_path, dtype):
    top = 1.0 if dtype == np.float32 else np.iinfo(dtype).max
    colour = np.random.default_rng(1).uniform(0.1, 1.0, (6, 8, 3))
    alpha = np.tile(np.linspace(0.25, 1.0, 8), (6, 1))[..., None]
    enc = (lambda a: a.astype(dtype)) if dtype == np.float32 else \
        (lambda a: np.rint(a * top).astype(dtype))
    # an unspecified extra sample is no alpha: the photo is RGB
    tifffile.imwrite(tmp_path / "x.tif", enc(np.concatenate([colour, alpha], -1)),
                     photometric="rgb", extrasamples=["unspecified"], metadata=None)
    assert read_photo(tmp_path / "x.tif").pixels.shape == (6, 8, 3)
    # premultiplied (associated) alpha: the colours come back straight
    tifffile.imwrite(tmp_path / "a.tif", enc(np.concatenate([colour * alpha, alpha], -1)),
                     photometric="rgb", extrasamples=["assocalpha"], metadata=None)
    px = read_photo(tmp_path / "a.tif").pixels
    assert px.shape == (6, 8, 4)
    assert np.allclose(px[..., :3], colour, atol=6 / 255 if dtype == np.uint8 else 1e-3)
    assert np.allclose(px[..., 3:], alpha, atol=1 / 255)
    # two extra samples, alpha first: RGBA; the second is dropped
    tifffile.imwrite(tmp_path / "b.tif", enc(np.concatenate([colour, alpha, alpha], -1)),
                     photometric="rgb", extrasamples=["unassalpha", "unspecified"],
                     metadata=None)
    assert np.allclose(read_photo(tmp_path / "b.tif").pixels[..., 3:], alpha, atol=1 / 255)


def test_an_exif_block_too_long_for_a_jpeg_loses_its_maker_notes(tmp_path):
    exif = Image.Exif()
    exif[0x010F] = "Maker"
    exif[0x0112] = 6                                   # orientation: kept
    exif.get_ifd(0x8769)[0x927C] = b"M" * 70000        # a maker's notes: 70 KB
    Image.fromarray(np.full((8, 8, 3), 100, np.uint8)).save(tmp_path / "in.png",
                                                             exif=exif.tobytes())
    photo = read_photo(tmp_path / "in.png")
    assert len(photo.exif) > 65533
    with pytest.warns(UserWarning, match="more than a JPEG holds .* without its MakerNote"):
        write_photo(tmp_path / "out.jpg", photo.pixels, like=photo)
    with Image.open(tmp_path / "out.jpg") as im:
        kept = im.getexif()
        assert kept[0x010F] == "Maker" and kept[0x0112] == 6
        assert 0x927C not in kept.get_ifd(0x8769)
    write_photo(tmp_path / "out.png", photo.pixels, like=photo)    # a PNG keeps it all
    assert read_photo(tmp_path / "out.png").exif == photo.exif


def test_a_bare_exif_block_is_written_with_its_header(tmp_path):
    """A Photo's EXIF given without the ``Exif\\0\\0`` header (a bare TIFF-structured
    block, as some libraries hand it) is stored whole, with the header, in each format."""
    block = exif_block()
    src = like(smooth((6, 8, 3)), exif=block[6:])
    for name, bits in (("a.jpg", 8), ("b.png", 8), ("c.png", 16), ("d.tif", 8)):
        out = read_photo(write_photo(tmp_path / name, src.pixels, like=src, bit_depth=bits))
        assert exif_values(out.exif) == exif_values(block), name


def test_copyright_artist_and_interoperability_survive_a_tiff(tmp_path):
    """The descriptive IFD0 tags (Artist, Copyright among them) and the Interoperability
    directory inside the Exif one (its index R03 says Adobe RGB to DCF readers) are
    rebuilt from a TIFF's tags and written into a TIFF's."""
    exif = Image.Exif()
    exif[271], exif[315], exif[33432] = "Canon", "Ann Onym", "(c) 2024 Ann Onym"
    exif[0x8769] = {0x829A: R(1, 60), 0xA005: {1: "R03"}}
    Image.new("RGB", (8, 6)).save(tmp_path / "in.jpg", exif=exif.tobytes())
    src = read_photo(tmp_path / "in.jpg")
    for name in ("a.tif", "b.jpg"):                     # JPEG -> TIFF -> TIFF reader -> JPEG
        src = read_photo(write_photo(tmp_path / name, src.pixels, like=src))
        got = Image.Exif()
        got.load(src.exif)
        assert (got[271], got[315], got[33432]) == ("Canon", "Ann Onym", "(c) 2024 Ann Onym")
        assert got.get_ifd(0x8769)[0x829A] == R(1, 60)
        assert dict(got.get_ifd(0xA005)) == {1: "R03"}, name


def test_an_exif_block_at_the_jpeg_limit(tmp_path):
    """Up to 65533 bytes (header included) fit a JPEG's APP1 segment and are written
    whole; more, and the maker's notes go, with a warning (Pillow refuses to write them).
    Pillow pads the block to an even length: 65532 and 65534 bytes either side."""
    def block_of(size):
        exif = Image.Exif()
        exif[271] = "Canon"
        exif.get_ifd(0x8769)[0x927C] = b"M" * 100
        extra = size - len(exif.tobytes())
        exif.get_ifd(0x8769)[0x927C] = b"M" * (100 + extra)
        block = exif.tobytes()
        assert len(block) == size
        return block

    fits = like(smooth((8, 8, 3)), exif=block_of(65532))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = read_photo(write_photo(tmp_path / "fits.jpg", fits.pixels, like=fits))
    assert out.exif == fits.exif
    over = like(smooth((8, 8, 3)), exif=block_of(65534))
    with pytest.warns(UserWarning, match=r"\(65534 bytes\) is more than a JPEG holds "
                                         r"\(65533\); written without its MakerNote"):
        out = read_photo(write_photo(tmp_path / "over.jpg", over.pixels, like=over))
    assert exif_values(out.exif)[0][271] == "Canon"
    assert 0x927C not in exif_values(out.exif)[1]


def test_a_long_user_comment_goes_and_an_exif_block_still_too_long_is_left_out(tmp_path):
    """A UserComment too long for a JPEG goes as a maker's notes do; where leaving them out
    is not enough (a long description), the JPEG is written without EXIF, with a warning,
    rather than not at all."""
    exif = Image.Exif()
    exif[271] = "Canon"
    exif.get_ifd(0x8769)[0x9286] = b"ASCII\0\0\0" + b"c" * 70000    # UserComment
    src = like(smooth((8, 8, 3)), exif=exif.tobytes())
    with pytest.warns(UserWarning, match="written without its UserComment"):
        out = read_photo(write_photo(tmp_path / "comment.jpg", src.pixels, like=src))
    assert exif_values(out.exif)[0][271] == "Canon"
    exif[270] = "d" * 70000                                         # ImageDescription
    src = like(smooth((8, 8, 3)), exif=exif.tobytes())
    with pytest.warns(UserWarning, match="written without EXIF"):
        out = read_photo(write_photo(tmp_path / "long.jpg", src.pixels, like=src))
    assert out.exif is None and out.pixels.shape == (8, 8, 3)


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_a_png_file_gamma_is_read_and_written_back(tmp_path, bit_depth):
    """``gAMA`` is kept (a linear PNG must not come out looking like sRGB), unless an
    ``sRGB`` chunk says what the gamma means."""
    from PIL import PngImagePlugin
    info = PngImagePlugin.PngInfo()
    info.add(b"gAMA", (100000).to_bytes(4, "big"))
    Image.fromarray(np.full((4, 5, 3), 100, np.uint8)).save(tmp_path / "lin.png", pnginfo=info)
    photo = read_photo(tmp_path / "lin.png")
    assert photo.png_gamma == 1.0
    write_photo(tmp_path / "out.png", photo.pixels, like=photo, bit_depth=bit_depth)
    with Image.open(tmp_path / "out.png") as im:
        assert im.info.get("gamma") == 1.0
    assert read_photo(tmp_path / "out.png").png_gamma == 1.0
    srgb = PngImagePlugin.PngInfo()
    srgb.add(b"sRGB", b"\0")
    srgb.add(b"gAMA", (45455).to_bytes(4, "big"))
    Image.fromarray(np.full((4, 5, 3), 100, np.uint8)).save(tmp_path / "srgb.png", pnginfo=srgb)
    assert read_photo(tmp_path / "srgb.png").png_gamma is None


def test_a_16_bit_photo_written_as_jpeg_is_said_and_a_file_is_no_folder(tmp_path):
    from gyrodeblur.errors import InputError
    from gyrodeblur.imageio import check_destination

    px = np.linspace(0, 1, 48, dtype=np.float32).reshape(4, 4, 3)
    src = read_photo(write_photo(tmp_path / "s16.png", px, bit_depth=16))
    with pytest.warns(UserWarning, match="JPEG stores 8 bits per sample"):
        write_photo(tmp_path / "s.jpg", px, like=src)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match="afile is a file, not a folder"):
        check_destination(tmp_path / "afile" / "x.png")


def _read_without_tifffile(path, monkeypatch):
    """``read_photo`` as on a machine where tifffile cannot decode the file (LZW or JPEG
    compression without imagecodecs): Pillow decodes it."""
    def cannot(p):
        raise RuntimeError("requires the 'imagecodecs' package")

    with monkeypatch.context() as m:
        m.setattr(imageio, "_read_tiff_tifffile", cannot)
        return read_photo(path)


@pytest.mark.parametrize("kind", ["float RGB", "16-bit planar"])
def test_a_tiff_needing_imagecodecs_is_refused_saying_what_to_do(tmp_path, monkeypatch,
                                                                 kind):
    """Where tifffile cannot decode a TIFF for want of imagecodecs (LZW on float samples,
    the floating-point predictor, LZW on colour planes) and Pillow cannot either, the
    message names what needs it and how to get it, not tifffile's internals."""
    k = np.arange(8 * 8 * 3).reshape(8, 8, 3)
    if kind == "float RGB":               # Pillow cannot open float colour at all
        tifffile.imwrite(tmp_path / "a.tif", (k / k.max()).astype(np.float32),
                         photometric="rgb", metadata=None)
        need = r"FLOATINGPOINT predictor"
        text = "<PREDICTOR.FLOATINGPOINT: 3> requires the 'imagecodecs' package"
    else:                                 # Pillow opens it, but not 16-bit planes
        tifffile.imwrite(tmp_path / "a.tif", np.moveaxis(k.astype(np.uint16), -1, 0),
                         photometric="rgb", planarconfig="separate", metadata=None)
        need = r"LZW compression"
        text = "<COMPRESSION.LZW: 5> requires the 'imagecodecs' package"

    def cannot(p):
        raise ValueError(text)

    monkeypatch.setattr(imageio, "_read_tiff_tifffile", cannot)
    with pytest.raises(InputError, match=rf"a.tif: its {need} needs the package "
                                         r"imagecodecs.*pip install imagecodecs.*or save the "
                                         r"TIFF uncompressed"):
        read_photo(tmp_path / "a.tif")


def test_a_refusal_of_what_a_tiff_holds_is_not_put_down_to_imagecodecs(tmp_path):
    """32-bit integer samples in an LZW TIFF (Pillow's mode I), which tifffile cannot
    decode without imagecodecs: refused for its samples, as uncompressed, not with advice
    to install a package that would not help (a review found the refusal replaced)."""
    ints = np.arange(32 * 32, dtype=np.int32).reshape(32, 32) * 1000
    for name, kw in (("lzw.tif", {"compression": "tiff_lzw"}), ("raw.tif", {})):
        Image.fromarray(ints).save(tmp_path / name, **kw)
        with pytest.raises(InputError, match=rf"{name}: unsupported samples \(32-bit"):
            read_photo(tmp_path / name)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_a_min_is_white_tiff_is_read_as_light_not_ink(tmp_path, monkeypatch, dtype):
    """Grey stored as ink (photometric 0: 0 is white) comes out as light, 8 or 16 bits,
    whichever decoder reads it (16-bit ones read by Pillow came out as a negative)."""
    top = np.iinfo(dtype).max
    ink = np.random.default_rng(5).integers(0, top + 1, (12, 16)).astype(dtype)
    tifffile.imwrite(tmp_path / "mw.tif", ink, photometric="miniswhite")
    for photo in (read_photo(tmp_path / "mw.tif"),
                  _read_without_tifffile(tmp_path / "mw.tif", monkeypatch)):
        assert photo.bit_depth == 8 * ink.itemsize
        np.testing.assert_array_equal(np.rint(photo.pixels * top), top - ink.astype(np.int64))


def test_premultiplied_16bit_colour_is_divided_whole_by_either_decoder(tmp_path, monkeypatch):
    """Associated (premultiplied) alpha at 16 bits: Pillow's decoder divided each byte of a
    sample by the alpha on its own; both decoders now give the same straight colours."""
    rng = np.random.default_rng(6)
    alpha = rng.integers(1, 65536, (12, 16, 1))
    colour = rng.integers(0, 65536, (12, 16, 3)) * alpha // 65535
    stored = np.concatenate([colour, alpha], axis=2).astype(np.uint16)
    tifffile.imwrite(tmp_path / "pm.tif", stored, photometric="rgb", extrasamples=[1])
    by_tifffile = read_photo(tmp_path / "pm.tif")
    by_pillow = _read_without_tifffile(tmp_path / "pm.tif", monkeypatch)
    assert by_tifffile.bit_depth == by_pillow.bit_depth == 16
    np.testing.assert_array_equal(by_pillow.pixels, by_tifffile.pixels)
    straight = np.minimum(np.rint(colour * 65535 / alpha), 65535)
    np.testing.assert_array_equal(np.rint(by_tifffile.pixels[..., :3] * 65535), straight)


def test_a_tiff_only_tifffile_reads_is_held_to_the_size_limit(tmp_path, monkeypatch):
    """Float RGB, which Pillow cannot open, is refused on its declared size like the rest,
    before its pixels are decoded."""
    tifffile.imwrite(tmp_path / "f.tif", np.zeros((40, 30, 3), np.float32), photometric="rgb")
    monkeypatch.setattr(imageio, "MAX_PHOTO_PIXELS", 1000)
    with pytest.raises(InputError, match="f.tif: 30x40 pixels .* more than"):
        read_photo(tmp_path / "f.tif")


def test_a_jpeg_wider_than_the_format_holds_is_refused_before_writing(tmp_path):
    with pytest.raises(InputError, match="long.jpg: JPEG holds at most 65500 px a side"):
        write_photo(tmp_path / "long.jpg", np.zeros((4, 65501), np.float32))
    assert not list(tmp_path.iterdir())
    like = Photo(np.zeros((4, 65501), np.float32), 8, "PNG")
    with pytest.raises(InputError, match="write .png or .tif"):
        imageio.check_destination(tmp_path / "o.jpg", like, False)


@pytest.mark.parametrize("name,bits", [("s.png", 8), ("s.png", 16), ("s.tif", 8), ("s.tif", 16)])
def test_png_and_tiff_are_compressed(tmp_path, name, bits):
    """PNG and TIFF are written Deflate-compressed (at ``pngwrite.DEFLATE_LEVEL``): a
    smooth photo takes a fraction of its raw bytes, and reads back exactly."""
    px = smooth((120, 160, 3))
    out = write_photo(tmp_path / name, px, bit_depth=bits)
    raw = px.size * bits // 8
    assert os.path.getsize(out) < 0.5 * raw
    top = 2 ** bits - 1
    np.testing.assert_array_equal(np.rint(read_photo(out).pixels * top), np.rint(px * top))
