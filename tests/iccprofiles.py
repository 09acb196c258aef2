"""ICC profiles written byte by byte for the tests (ICC.1:2010 layout, version 2).

Real profiles from raw converters and editors are not redistributable here; these carry
the same tags a display profile does (description, white point, sRGB's D50 primaries and
the transfer-curve tags), so LittleCMS (Pillow's ``ImageCms``) accepts them and can check
the curves independently.
"""

import struct

import numpy as np


def _s15(v: float) -> bytes:
    return struct.pack(">i", int(round(v * 65536)))


def _xyz(x: float, y: float, z: float) -> bytes:
    return b"XYZ " + b"\0" * 4 + _s15(x) + _s15(y) + _s15(z)


def curv_gamma(gamma: float) -> bytes:
    """A ``curv`` tag holding one gamma (u8Fixed8)."""
    return b"curv" + b"\0" * 4 + struct.pack(">IH", 1, int(round(gamma * 256))) + b"\0\0"


def curv_identity() -> bytes:
    """A ``curv`` tag with no entries: the identity (linear data)."""
    return b"curv" + b"\0" * 4 + struct.pack(">I", 0)


def curv_table(values) -> bytes:
    """A ``curv`` tag sampling a curve at evenly spaced inputs (values in [0, 1])."""
    v = np.round(np.asarray(values, float) * 65535).astype(int)
    return b"curv" + b"\0" * 4 + struct.pack(f">I{v.size}H", v.size, *v)


def para(function: int, params) -> bytes:
    """A ``para`` tag: ICC parametric function 0-4 with its parameters."""
    return (b"para" + b"\0" * 4 + struct.pack(">HH", function, 0)
            + b"".join(_s15(p) for p in params))


def _desc(text: str) -> bytes:
    t = text.encode("latin-1") + b"\0"
    return b"desc" + b"\0" * 4 + struct.pack(">I", len(t)) + t + b"\0" * 78


def _mluc(text: str) -> bytes:
    t = text.encode("utf-16-be")
    return (b"mluc" + b"\0" * 4 + struct.pack(">II", 1, 12) + b"enUS"
            + struct.pack(">II", len(t), 28) + t)


def make_icc(trc=None, *, space: bytes = b"RGB ", name: str = "test profile",
             v4_name: bool = False) -> bytes:
    """A display profile with transfer-curve tag data ``trc``: one tag for all channels
    (or the grey one), three for red, green, blue, or ``None`` for no TRC tags at all
    (a profile of lookup tables would have ``A2B0`` instead)."""
    tags = [(b"desc", _mluc(name) if v4_name else _desc(name)),
            (b"wtpt", _xyz(0.9642, 1.0, 0.8249))]
    if space == b"GRAY":
        if trc is not None:
            tags.append((b"kTRC", trc))
    else:
        tags += [(b"rXYZ", _xyz(0.4361, 0.2225, 0.0139)), (b"gXYZ", _xyz(0.3851, 0.7169, 0.0971)),
                 (b"bXYZ", _xyz(0.1431, 0.0606, 0.7141))]
        if trc is not None:
            r, g, b = (trc, trc, trc) if isinstance(trc, bytes) else trc
            tags += [(b"rTRC", r), (b"gTRC", g), (b"bTRC", b)]
    table, data = b"", b""
    start = 128 + 4 + 12 * len(tags)
    for sig, body in tags:
        table += struct.pack(">4sII", sig, start + len(data), len(body))
        data += body + b"\0" * (-len(body) % 4)
    header = struct.pack(">I4sI4s4s4s", start + len(data), b"lcms", 0x02100000, b"mntr",
                         space, b"XYZ ")
    header += b"\0" * 12 + b"acsp" + b"\0" * 24 + _s15(0.9642) + _s15(1.0) + _s15(0.8249)
    header += b"\0" * (128 - len(header))
    return header + struct.pack(">I", len(tags)) + table + data
