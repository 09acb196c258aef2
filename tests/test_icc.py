"""Tests for gyrodeblur.icc: the transfer curve an embedded ICC profile declares."""

import io
import struct

import numpy as np
import pytest
from iccprofiles import curv_gamma, curv_identity, curv_table, make_icc, para
from PIL import Image, ImageCms

from gyrodeblur.errors import InputError
from gyrodeblur.icc import (parametric_curve, photo_transfer_curve, profile_description,
                            profile_transfer_curve)
from gyrodeblur.imageio import Photo
from gyrodeblur.tonecurve import LINEAR, SRGB, linear_to_srgb, srgb_to_linear

SRGB_PARAMS = (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)

CURVES = {
    "gamma 2.2 (Adobe RGB)": curv_gamma(563 / 256),
    "gamma 1.8 (ProPhoto)": curv_gamma(1.8),
    "table, square law": curv_table(np.linspace(0, 1, 256) ** 2.0),
    "para 0, gamma 2.6 (DCI)": para(0, [2.6]),
    "para 1": para(1, [2.2, 1.1, -0.1]),
    "para 2": para(2, [2.0, 0.9, 0.1, 0.002]),
    "para 4, Rec. 709-like": para(4, [1 / 0.45, 1 / 1.099, 0.099 / 1.099, 1 / 4.5, 0.081,
                                      0.0, 0.0]),
}


@pytest.mark.parametrize("label", sorted(CURVES))
def test_curves_decode_as_littlecms_reads_the_profile(label):
    """Each curve form, against LittleCMS's own conversion of the same profile to its
    built-in sRGB: a grey ramp decoded by our curve and encoded as sRGB lands on LittleCMS's
    8-bit result to its rounding (half a level)."""
    icc = make_icc(CURVES[label])
    ramp = Image.fromarray(np.tile(np.arange(256, dtype=np.uint8)[:, None], (1, 3))[None], "RGB")
    srgb = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))
    theirs = np.asarray(ImageCms.profileToProfile(
        ramp, ImageCms.ImageCmsProfile(io.BytesIO(icc)), srgb, renderingIntent=1,
        outputMode="RGB"))[0, :, 1].astype(float)
    curve = profile_transfer_curve(icc)
    assert curve is not SRGB and curve is not LINEAR
    ours = 255 * linear_to_srgb(np.clip(curve.decode(np.arange(256, dtype=np.float32) / 255),
                                        0, 1))
    assert np.abs(ours - theirs).max() < 0.6, label
    # and it is a transfer curve: encode undoes decode where the curve rises (not on the
    # flat foot of functions 1 and 2; 5e-4 at the joint of function 4, whose two segments
    # the profile's 16-bit fractions leave apart by as much)
    v = np.linspace(0, 1, 4097, dtype=np.float32)
    rising = curve.decode(v) > curve.decode(np.zeros(1, np.float32))[0]
    assert np.abs(curve.encode(curve.decode(v)) - v)[rising].max() < 5e-4, label


def test_srgb_and_linear_profiles_give_the_exact_curves():
    """The profiles phones and editors embed for sRGB (LittleCMS's parametric one, a
    1024-entry table like the classic HP profile, ICC function 3 with sRGB's constants) and
    an identity curve map to the exact built-in curves: a photo with such a profile is
    deblurred exactly as one without."""
    lcms = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    table = make_icc(curv_table(srgb_to_linear(np.linspace(0, 1, 1024))))
    assert profile_transfer_curve(lcms) is SRGB
    assert profile_transfer_curve(table) is SRGB
    assert profile_transfer_curve(make_icc(para(3, SRGB_PARAMS))) is SRGB
    assert profile_transfer_curve(make_icc(curv_identity())) is LINEAR
    assert profile_transfer_curve(make_icc(curv_gamma(1.0))) is LINEAR
    assert profile_transfer_curve(make_icc(curv_identity(), space=b"GRAY")) is LINEAR
    # close to sRGB is not sRGB: a pure gamma 2.2 differs by a level and more in the shadows
    assert profile_transfer_curve(make_icc(curv_gamma(2.2))).name.startswith("gamma 2.2")


def test_channels_with_their_own_curves_are_decoded_each_by_its_own():
    icc = make_icc((curv_gamma(1.8), curv_gamma(2.2), curv_identity()))
    curve = profile_transfer_curve(icc)
    v = np.full((2, 3, 3), 0.5, np.float32)
    lin = curve.decode(v)
    np.testing.assert_allclose(lin[0, 0], [0.5 ** 1.8, 0.5 ** 2.2, 0.5], rtol=2e-3)
    np.testing.assert_allclose(curve.encode(lin), v, atol=1e-5)


def test_profiles_that_declare_no_curve_say_why():
    with pytest.raises(ValueError, match="lookup tables"):
        profile_transfer_curve(make_icc(None))
    with pytest.raises(ValueError, match="not an ICC profile"):
        profile_transfer_curve(b"\0" * 200)
    good = make_icc(curv_gamma(2.2))
    with pytest.raises(ValueError, match="truncated|outside"):
        profile_transfer_curve(good[:150])
    cmyk = bytearray(good)
    cmyk[16:20] = b"CMYK"
    with pytest.raises(ValueError, match="CMYK"):
        profile_transfer_curve(bytes(cmyk))
    with pytest.raises(ValueError, match="function 7"):
        profile_transfer_curve(make_icc(para(7, [2.2])))


def test_descriptions_in_both_versions():
    assert profile_description(make_icc(curv_gamma(2.2), name="Adobe RGB (1998)")) \
        == "Adobe RGB (1998)"
    assert profile_description(make_icc(curv_gamma(2.2), name="Linear Rec2020",
                                        v4_name=True)) == "Linear Rec2020"
    assert profile_description(b"junk") is None


def test_parametric_functions_in_the_general_form():
    """ICC's functions 1 and 2 switch at V = -b/a, with 0 (or c) below."""
    c1 = parametric_curve(1, (2.0, 2.0, -0.5))
    np.testing.assert_allclose(c1.decode(np.float32([0.1, 0.25, 0.75])), [0, 0, 1.0], atol=1e-6)
    c2 = parametric_curve(2, (1.0, 1.0, -0.5, 0.1))
    np.testing.assert_allclose(c2.decode(np.float32([0.2, 0.8])), [0.1, 0.4], atol=1e-6)
    with pytest.raises(ValueError):
        parametric_curve(3, (2.2,))


def _photo(icc, fmt="PNG", bit_depth=8):
    return Photo(np.zeros((4, 4, 3), np.float32), bit_depth, fmt, path="p.tif", icc_profile=icc)


def test_the_photo_s_curve_and_what_is_said_of_it():
    lin = make_icc(curv_identity(), name="Linear Rec2020")
    curve, note = photo_transfer_curve(_photo(lin, "TIFF", 16))
    assert curve is LINEAR and "'Linear Rec2020'" in note and "linear transfer" in note
    curve, note = photo_transfer_curve(_photo(make_icc(curv_gamma(1.8))))
    assert curve.name.startswith("gamma 1.8") and "gamma 1.8" in note
    # a table's note reads as English (it was "declares a table of 300 transfer curve")
    curve, note = photo_transfer_curve(_photo(make_icc(curv_table(
        np.linspace(0, 1, 300) ** 2.0))))
    assert "declares a 300-point tabulated transfer curve" in note, note
    lcms = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    assert photo_transfer_curve(_photo(lcms)) == (SRGB, None)
    assert photo_transfer_curve(_photo(None)) == (SRGB, None)
    curve, note = photo_transfer_curve(_photo(None, "TIFF", 16))
    assert curve is SRGB and "no ICC profile" in note and "--transfer linear" in note
    curve, note = photo_transfer_curve(_photo(make_icc(None)))
    assert curve is SRGB and "lookup tables" in note and "sRGB assumed" in note
    # a name given is taken as given, whatever the profile says
    assert photo_transfer_curve(_photo(lin), "srgb") == (SRGB, None)
    assert photo_transfer_curve(_photo(lcms), "linear") == (LINEAR, None)


def test_a_png_s_file_gamma_stands_in_for_a_profile():
    def png(gamma, icc=None):
        photo = _photo(icc)
        return Photo(photo.pixels, 16, "PNG", path="p.png", icc_profile=icc, png_gamma=gamma)

    curve, note = photo_transfer_curve(png(1.0))
    assert curve is LINEAR and "file gamma 1" in note
    assert photo_transfer_curve(png(0.45455)) == (SRGB, None)      # libpng's sRGB gamma
    curve, note = photo_transfer_curve(png(1 / 1.8))
    assert curve.name == "gamma 1.8" and "gAMA" in note
    # a profile, where there is one, says more than the gAMA chunk
    lcms = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    assert photo_transfer_curve(png(1.0, lcms)) == (SRGB, None)


def test_a_damaged_profile_is_said_and_srgb_assumed():
    """A curve tag whose entries or parameters do not fit it, or a tag that lies past the
    profile's end (a file cut short), is a ValueError naming it: the photo's curve is then
    sRGB, with a note, rather than a crash."""
    short_table = b"curv" + b"\0" * 4 + struct.pack(">I4H", 1000, 0, 100, 200, 300)
    damaged = {"1000 curve entries": make_icc(short_table),
               "function 3 is truncated": make_icc(para(3, [2.4, 1.0])),
               "outside the profile": make_icc(curv_gamma(2.2))[:-8]}
    for said, icc in damaged.items():
        with pytest.raises(ValueError, match=said):
            profile_transfer_curve(icc)
        curve, note = photo_transfer_curve(_photo(icc))
        assert curve is SRGB and said in note and "sRGB assumed" in note


def test_a_v4_description_of_any_length():
    assert profile_description(make_icc(curv_gamma(2.2), name="Display P3",
                                        v4_name=True)) == "Display P3"


def test_an_unknown_curve_name_lists_auto_too():
    with pytest.raises(InputError, match=r"unknown transfer curve 'rec709' \(known: auto, "
                                         r"linear, none, srgb\)"):
        photo_transfer_curve(_photo(None), "rec709")
