"""The command line: happy paths, metadata pass-through, and one-line errors with exit 2."""

import json

import numpy as np
import pytest
from PIL import Image, ImageCms
from PIL.TiffImagePlugin import IFDRational

from gyrodeblur.cli import main
from gyrodeblur.gyrolog import GyroLog, write_gcsv
from gyrodeblur.imageio import read_photo, write_photo


@pytest.fixture
def capture_dir(tmp_path):
    t = 50.0 + np.arange(200) / 200.0
    rng = np.random.default_rng(0)
    w = np.stack([0.2 * np.sin(9 * t), 0.4 * np.cos(7 * t), 0.5 * np.sin(5 * t)], 1)
    write_gcsv(tmp_path / "gyro.gcsv", GyroLog(t, w + rng.normal(0, 0.005, w.shape)))
    doc = {"exposure_start": 50.3, "exposure_time": 0.03, "readout_time": 0.02,
           "camera": {"fx": 200.0, "fy": 200.0, "cx": 127.5, "cy": 95.5, "width": 256, "height": 192},
           "gyro": {"path": "gyro.gcsv", "format": "gcsv", "orientation": "XYZ", "time_offset": 0.0}}
    (tmp_path / "cap.json").write_text(json.dumps(doc))
    from skimage import data, transform
    img = transform.resize(data.astronaut(), (192, 256), anti_aliasing=True).astype(np.float32)
    exif = Image.Exif()
    exif[0x010F] = "TestCam"
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    im = Image.fromarray((img * 255).round().astype(np.uint8))
    im.save(tmp_path / "sharp.jpg", exif=exif.tobytes(), icc_profile=icc, quality=95)
    return tmp_path


def test_simulate_then_deblur_keeps_metadata(capture_dir, capsys):
    d = capture_dir
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "blurred.jpg"), "--snr-db", "40", "--seed", "1"]) == 0
    assert main(["deblur", str(d / "blurred.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "out.jpg"), "--save-psf", str(d / "field.png"), "--grid", "3x4"]) == 0
    out = capsys.readouterr().out
    assert "mode variant 3x4 (global model)" in out and "PSF extent" in out
    src, res = read_photo(d / "sharp.jpg"), read_photo(d / "out.jpg")
    assert res.icc_profile == src.icc_profile and res.exif is not None
    assert Image.open(d / "out.jpg").getexif()[0x010F] == "TestCam"
    assert res.pixels.shape == src.pixels.shape
    # the photo is deblurred (the 8-bit sRGB PSNR of the chapter, 10 px border)
    from gyrodeblur.metrics import psnr

    sharp, blurred = src.pixels, read_photo(d / "blurred.jpg").pixels
    gain = psnr(sharp, res.pixels, 10) - psnr(sharp, blurred, 10)
    assert gain > 8.0, gain                                  # 13.8 dB at session 38's code
    # the field's picture: one PSF per patch of the 3 x 4 grid, drawn
    field = np.asarray(Image.open(d / "field.png").convert("L"), np.float32)
    assert field.std() > 5 and field.max() > 100
    # --method and --mode reach the deblur: each its own result, each sharper than the input
    outputs = {}
    for opts, name in (([], "default.png"), (["--method", "wiener"], "wiener.png"),
                       (["--mode", "invariant"], "invariant.png")):
        assert main(["deblur", str(d / "blurred.jpg"), "--capture", str(d / "cap.json"),
                     "-o", str(d / name), *opts]) == 0
        other = outputs[name] = read_photo(d / name).pixels
        if not opts:
            continue
        assert np.abs(other - outputs["default.png"]).max() > 4 / 255, opts
        if opts[0] == "--method":        # the library's Wiener result, to the 8-bit level
            from gyrodeblur.capture import load_capture
            from gyrodeblur.deblur import deblur

            lib = deblur(blurred, load_capture(d / "cap.json"), method="wiener")
            assert np.abs(other - lib).max() <= 1 / 255 + 1e-6
        assert psnr(sharp, other, 10) > psnr(sharp, blurred, 10) + 5.0, opts   # 9.9, 13.1
    assert "method wiener" in capsys.readouterr().out


def test_simulate_samples_by_cubic_spline_unless_told_bilinear(capture_dir, capsys):
    """``--sampling bilinear`` reproduces ``simulate_blur(order=1)`` (the synthesis before
    session 17); the default is the cubic spline, which keeps more of the photo's fine
    detail (a bilinear tap pair removes the Nyquist frequency half-way between pixels)."""
    from gyrodeblur.capture import load_capture
    from gyrodeblur.simulate import simulate_blur
    from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

    d = capture_dir
    for sampling in ("cubic", "bilinear"):
        assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                     "-o", str(d / f"{sampling}.png"), "--sampling", sampling,
                     "--bit-depth", "16"]) == 0
    cubic, bilinear = (read_photo(d / f"{s}.png").pixels for s in ("cubic", "bilinear"))
    sharp = srgb_to_linear(read_photo(d / "sharp.jpg").pixels)
    expected = linear_to_srgb(simulate_blur(sharp, load_capture(d / "cap.json"), order=1,
                                            transfer="linear"))
    assert np.abs(bilinear - expected).max() < 1e-4
    detail = [np.abs(np.diff(b, axis=1)).mean() for b in (cubic, bilinear)]
    assert detail[0] > detail[1], detail
    with pytest.raises(SystemExit) as exit_:
        main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
              "-o", str(d / "x.png"), "--sampling", "nearest"])
    assert exit_.value.code == 2 and "--sampling" in capsys.readouterr().err


def test_psf_commands(capture_dir):
    from gyrodeblur.capture import load_capture
    from gyrodeblur.psf import render_psf

    d = capture_dir
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(d / "p.npy")]) == 0
    p = np.load(d / "p.npy")
    assert p.shape[0] % 2 == 1 and abs(p.sum() - 1) < 1e-5
    cap = load_capture(d / "cap.json")          # the PSF at (10, 20), not at the centre
    np.testing.assert_allclose(p, render_psf(cap, 10, 20), atol=1e-7)
    centre = render_psf(cap, cap.camera.cx, cap.camera.cy)
    assert p.shape != centre.shape or np.abs(p - centre).max() > 0.01
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(d / "p.png")]) == 0
    drawn = np.asarray(Image.open(d / "p.png").convert("L"), np.float32)
    assert drawn.std() > 5 and drawn.max() > 100          # a picture of the PSF, not blank
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "-o", str(d / "f.png")]) == 0
    drawn = np.asarray(Image.open(d / "f.png").convert("L"), np.float32)
    assert drawn.std() > 5 and drawn.max() > 100
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "-o", str(d / "f.npy")]) == 0
    assert np.load(d / "f.npy").shape[0] == 12


def test_alpha_is_passed_through_and_leaves_the_colours_alone(capture_dir, capsys):
    """An RGBA photo: the colour channels come out as without an alpha channel, and the
    alpha channel exactly as it went in (it is a mask, not light)."""
    d = capture_dir
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "blurred.png"), "--snr-db", "40", "--seed", "1"]) == 0
    rgb = read_photo(d / "blurred.png").pixels
    alpha = np.ones(rgb.shape[:2], np.float32)
    alpha[40:120, 60:200] = 0.5
    alpha[:, :20] = 0.0
    write_photo(d / "rgba.png", np.dstack([rgb, alpha]), bit_depth=8)
    for src, out in (("blurred.png", "out_rgb.png"), ("rgba.png", "out_rgba.png")):
        assert main(["deblur", str(d / src), "--capture", str(d / "cap.json"),
                     "-o", str(d / out), "--grid", "2x2"]) == 0
    plain, with_alpha = read_photo(d / "out_rgb.png").pixels, read_photo(d / "out_rgba.png").pixels
    assert with_alpha.shape[2] == 4
    np.testing.assert_array_equal(with_alpha[..., :3], plain)
    np.testing.assert_array_equal(with_alpha[..., 3], read_photo(d / "rgba.png").pixels[..., 3])
    # a JPEG cannot hold it: refused before any work, as is a folder given as the output
    import gyrodeblur.deblur as deblur_mod

    def no_work(*args, **kwargs):
        raise AssertionError("deblurred before the output was checked")

    capsys.readouterr()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(deblur_mod, "deblur", no_work)
        assert main(["deblur", str(d / "rgba.png"), "--capture", str(d / "cap.json"),
                     "-o", str(d / "out.jpg")]) == 2
    assert "alpha channel" in capsys.readouterr().err
    # the PSF drawing has no alpha: a JPEG is fine for it
    assert main(["deblur", str(d / "rgba.png"), "--capture", str(d / "cap.json"), "--grid",
                 "2x2", "-o", str(d / "out2.png"), "--save-psf", str(d / "field.jpg")]) == 0
    assert main(["deblur", str(d / "rgba.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d)]) == 2
    assert "is a folder" in capsys.readouterr().err
    # grey + alpha comes out as grey + alpha, the alpha exactly as it went in
    grey = rgb.mean(axis=2)
    Image.fromarray(np.dstack([np.round(grey * 255), np.round(alpha * 255)]).astype(np.uint8),
                    "LA").save(d / "la.png")
    assert main(["deblur", str(d / "la.png"), "--capture", str(d / "cap.json"), "--grid",
                 "2x2", "-o", str(d / "out_la.png")]) == 0
    with Image.open(d / "out_la.png") as im:
        assert im.mode == "LA"
        out = np.asarray(im)
    np.testing.assert_array_equal(out[..., 1], np.round(alpha * 255).astype(np.uint8))
    assert 0.0 < out[..., 0].std() / 255.0 < 0.5


def test_a_photo_turned_from_the_sensor_layout_is_deblurred_as_the_sensor_read_it(capture_dir,
                                                                                    capsys):
    """A portrait export (pixels turned 90 degrees clockwise): with --photo-rotation 90 the
    result is the sensor-layout photo's result, turned the same way."""
    d = capture_dir
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "blurred.png")]) == 0
    landscape = read_photo(d / "blurred.png").pixels
    write_photo(d / "portrait.png", np.rot90(landscape, -1), bit_depth=8)
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "out_l.png"), "--grid", "2x2"]) == 0
    capsys.readouterr()
    assert main(["deblur", str(d / "portrait.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "out_p.png"), "--grid", "2x2"]) == 2      # rows are not rows
    assert "--photo-rotation" in capsys.readouterr().err
    assert main(["deblur", str(d / "portrait.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "out_p.png"), "--grid", "2x2", "--photo-rotation", "90"]) == 0
    out = read_photo(d / "out_p.png").pixels
    np.testing.assert_array_equal(out, np.rot90(read_photo(d / "out_l.png").pixels, -1))
    # the option on a photo that was not turned: said so
    capsys.readouterr()
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "out_x.png"), "--photo-rotation", "270"]) == 2
    assert "were not turned: leave the option out" in capsys.readouterr().err
    # simulate turns the same way: the portrait sharp photo blurs as the landscape one
    write_photo(d / "sharp_p.png", np.rot90(read_photo(d / "sharp.jpg").pixels, -1), bit_depth=8)
    write_photo(d / "sharp_l.png", read_photo(d / "sharp.jpg").pixels, bit_depth=8)
    for src, out_name, rot in (("sharp_l.png", "bl_l.png", "0"), ("sharp_p.png", "bl_p.png", "90")):
        assert main(["simulate", str(d / src), "--capture", str(d / "cap.json"),
                     "-o", str(d / out_name), "--photo-rotation", rot]) == 0
    np.testing.assert_array_equal(read_photo(d / "bl_p.png").pixels,
                                  np.rot90(read_photo(d / "bl_l.png").pixels, -1))


def test_a_gyro_deblur_warns_when_the_logs_blur_does_not_fit_the_photo(capture_dir, capsys):
    """An exposure start 0.3 s off (another stretch of the log) gives PSFs the photo does
    not show: the deblur says so and points to calibrate (it said nothing, and the result
    was worse than the input); with the right start, or --no-blur-check, nothing is said.
    A focal length five times too long (a phone's full-resolution fx given for a photo
    shrunk to a fifth, without camera.width and height) is warned of too, and the likely
    causes named include the focal length."""
    d = capture_dir
    doc = json.loads((d / "cap.json").read_text())
    doc["camera"]["fx"] = doc["camera"]["fy"] = 450.0          # about 10 px of blur
    doc["exposure_time"] = 0.05
    (d / "long.json").write_text(json.dumps(doc))
    cap = str(d / "long.json")
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o",
                 str(d / "b.png"), "--snr-db", "40", "--seed", "2"]) == 0
    capsys.readouterr()
    runs = {"right": [], "late": ["--exposure-start", "50.6"],
            "late, unchecked": ["--exposure-start", "50.6", "--no-blur-check"],
            "fx 5x": ["--fx", "2250", "--fy", "2250"],
            "exposure 13x": ["--exposure-time", "0.65", "--fx", "900", "--fy", "900"]}
    for name, extra in runs.items():
        assert main(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                     str(d / f"{name}.png"), "--model", "patches", *extra]) == 0
        err = capsys.readouterr().err
        warned = "the blur the gyro log implies does not fit the photo" in err
        assert warned == (name in ("late", "fx 5x")), (name, err)
        # a blur over half the photo's side, which the check reads in too few windows
        # (a 40 ms exposure given as 40 had passed it): warned of as such
        long = "spans over half the photo's 192 px shorter side" in err
        assert long == (name == "exposure 13x"), (name, err)
        if long:
            assert "Check exposure_time and readout_time (seconds, not ms)" in err
        if warned:
            assert "run calibrate (or deblur --refine) first" in err
            assert "the focal length (one in the pixels of another resolution)" in err
            assert "digital zoom" not in err
    # the same photo, its EXIF saying digital zoom x2: the warning names the factor
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA404] = IFDRational(2, 1)
    Image.fromarray((read_photo(d / "b.png").pixels * 255).round().astype(np.uint8)).save(
        d / "b_zoom.jpg", exif=exif.tobytes(), quality=95)
    assert main(["deblur", str(d / "b_zoom.jpg"), "--capture", cap, "-o", str(d / "z.png"),
                 "--model", "patches", "--exposure-start", "50.6"]) == 0
    assert ("EXIF says digital zoom x2: where the focal length leaves the zoom out, it "
            "needs multiplying by 2 (--fx, --fy)") in capsys.readouterr().err


def test_a_blur_check_that_fails_does_not_cost_the_deblur(capture_dir, capsys, monkeypatch):
    """The check runs after the deblur: an error inside it is said, and the photo is still
    written (exit 0)."""
    import gyrodeblur.blur_evidence as evidence

    def broken(*args, **kwargs):
        raise ValueError("no textured window")

    monkeypatch.setattr(evidence, "capture_gain_over_no_blur", broken)
    d = capture_dir
    assert main(["deblur", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "--model", "patches", "-o", str(d / "o.png")]) == 0
    assert "the check that the photo shows the gyro log's blur could not run (no textured " \
           "window); the deblurred photo is written" in capsys.readouterr().err
    assert (d / "o.png").exists()


def _run_error(argv, capsys):
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("gyrodeblur: error: ")
    return err[0]


def test_the_library_names_its_arguments_and_the_command_line_its_options(capsys):
    """A bad keyword argument is named as the library's caller spelled it (``grid:``),
    and on the command line as the option that set it (``--grid:``). Every argument the
    library names that way (``InputError.of_argument`` in the source) is an option of
    one of the commands, so no message names an option that does not exist."""
    import re
    from pathlib import Path

    import gyrodeblur
    from gyrodeblur.cli import as_option
    from gyrodeblur.errors import InputError
    from gyrodeblur.tiling import patch_grid

    with pytest.raises(InputError, match="^grid: expected RxC") as err:
        patch_grid((480, 640), grid="6 by 8")
    assert err.value.argument and as_option(err.value).args == (
        "--grid: expected RxC with two positive integers (e.g. 6x8), got '6 by 8'",)
    assert not as_option(err.value).argument
    assert as_option(InputError.of_argument("captures", "2 photos but 1 captures")).source \
        == "--capture"
    for plain in (InputError("grid.png", "not found"), InputError(None, "no photo")):
        assert as_option(plain) is plain                   # a file's name is left alone
    assert InputError.of_argument("phi", "x").reworded("y").argument
    src = Path(gyrodeblur.__file__).parent
    names = {m for f in src.glob("*.py")
             for m in re.findall(r'of_argument\(\s*"(\w+)"', f.read_text(encoding="utf-8"))}
    assert {"grid", "overlap", "kernel_size", "captures", "phi", "transfer"} <= names, names
    helps = ""
    for command in ("psf", "simulate", "deblur", "calibrate", "demo"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        helps += capsys.readouterr().out
    options = set(re.findall(r"--[a-z][a-z-]*", helps))
    for name in names:
        assert as_option(InputError.of_argument(name, "")).source in options, name


def test_bad_inputs_exit_2_and_write_nothing(capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    (d / "notimage.jpg").write_text("hello")
    write_photo(d / "square.png", np.zeros((100, 100, 3), np.float32))
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    assert "notimage.jpg" in _run_error(["deblur", str(d / "notimage.jpg"), "--capture", cap,
                                         "-o", str(d / "o.png")], capsys)
    msg = _run_error(["deblur", str(d / "square.png"), "--capture", cap, "-o", str(d / "o.png")],
                     capsys)
    assert "square.png" in msg and "aspect ratio" in msg
    msg = _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                      "-o", str(d / "missing" / "o.png")], capsys)
    assert "missing" in msg and "does not exist" in msg
    msg = _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap, "--exposure-start", "70",
                      "-o", str(d / "o.png")], capsys)
    assert "gyro.gcsv" in msg and "covers" in msg
    msg = _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                      "-o", str(d / "square.png")], capsys)
    assert "square.png" in msg and "exists" in msg
    msg = _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                      "-o", str(d / "sharp.jpg"), "--overwrite"], capsys)
    assert "sharp.jpg" in msg and "input photo" in msg
    assert "--grid" in _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap, "--grid", "0x3",
                                   "-o", str(d / "o.png")], capsys)
    assert "an output file's name is empty ('')" in _run_error(
        ["deblur", str(d / "sharp.jpg"), "--capture", cap, "-o", ""], capsys)
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before    # nothing written or changed


@pytest.mark.parametrize("content,match", [
    ("t_s,x,y,z\n50,0,0,0\n50.01,0,0,0\n50.005,0,0,0\n", "not increasing"),
    ("t_s,x,y,z\n50,0,0,0\n50.5,inf,0,0\n51,0,0,0\n", "infinite"),
    ("t_s,x,y,z\n50,0,0,0\n50.1,0,0,0\n50.6,0,0,0\n51,0,0,0\n", "gap"),
    ("t_s,x,y,z\n50.31,0,0,0\n50.32,0,0,0\n", "covers"),
    ("t_s,x,y,z\n50,90,90,90\n50.5,90,90,90\n51,90,90,90\n", "deg/s"),
    ("t_s,x,y,z\n50,0,0,0\n50.3,1e30,0,0\n50.6,0,0,0\n51,0,0,0\n",
     "sample 2 (t = 50.300000 s) has a rate of 1e+30 rad/s, beyond any gyro's range"),
])
def test_bad_gyro_logs_via_cli(capture_dir, capsys, content, match):
    d = capture_dir
    (d / "bad.csv").write_text(content)
    msg = _run_error(["psf", "--capture", str(d / "cap.json"), "--gyro", str(d / "bad.csv"),
                      "--gyro-format", "csv", "--at", "5,5", "-o", str(d / "p.npy")], capsys)
    assert "bad.csv" in msg and match in msg
    assert not (d / "p.npy").exists()


def test_missing_log_and_unknown_format(capture_dir, capsys):
    d = capture_dir
    assert "not found" in _run_error(["psf", "--capture", str(d / "cap.json"), "--gyro",
                                      str(d / "nope.csv"), "--at", "5,5", "-o", str(d / "p.npy")], capsys)
    npy = ["-o", str(d / "p.npy")]
    for bad, flag in ((["--at", "five,5", *npy], "--at"), (["--grid", "3xq", *npy], "--grid"),
                      (["--at", "5,5", "-o", str(d / "p.txt")], "p.txt")):
        msg = _run_error(["psf", "--capture", str(d / "cap.json"), "--gyro", str(d / "nope.csv"),
                          *bad], capsys)                           # the options are checked
        assert flag in msg and "nope.csv" not in msg, msg          # before the log is read
    assert "/dev/null: not a regular file" in _run_error(
        ["psf", "--capture", str(d / "cap.json"), "--gyro", "/dev/null", "--at", "5,5", "-o",
         str(d / "p.npy")], capsys)
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["format"] = "bag"
    (d / "cap.json").write_text(json.dumps(doc))
    assert "unknown gyro log format" in _run_error(["psf", "--capture", str(d / "cap.json"),
                                                    "--at", "5,5", "-o", str(d / "p.npy")], capsys)


def test_blind_deblur_needs_no_gyro(capture_dir, capsys):
    d = capture_dir
    assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9",
                 "-o", str(d / "blind.png"), "--quiet"]) == 0
    got = capsys.readouterr()
    # a sharp photo shows none of the kernel found: it is left as it is, and said so (not
    # "deblurred ... PSF extent 1-1 px")
    assert "warning: the blind kernel explains the photo no better than no blur" in got.err
    assert "as it is (no blind kernel that fits it)" in got.out, got.out
    assert "deblurred" not in got.out and "PSF extent" not in got.out, got.out
    assert "deconvolved for noise" not in got.out, got.out   # a JPEG, but not deconvolved
    kept = read_photo(d / "blind.png").pixels
    assert kept.shape == (192, 256, 3)
    assert np.abs(kept - read_photo(d / "sharp.jpg").pixels).max() <= 1.5 / 255
    assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9",
                 "--no-blur-check", "-o", str(d / "forced.png"), "--quiet"]) == 0
    got = capsys.readouterr()
    assert "no better than no blur" not in got.err and "does not sharpen" not in got.err
    assert "deblurred" in got.out and "as it is" not in got.out, got.out
    assert "JPEG: deconvolved for noise of" in got.out, got.out
    # told not to check, it deconvolves with the kernel it found
    forced = read_photo(d / "forced.png").pixels
    assert np.abs(forced - read_photo(d / "sharp.jpg").pixels).max() > 4 / 255
    assert "--kernel-size" in _run_error(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size",
                                          "8", "-o", str(d / "b2.png")], capsys)
    assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9", "--grid",
                 "1x2", "-o", str(d / "blind2.png"), "--quiet"]) == 0
    got = capsys.readouterr()
    assert "as it is" in got.out and "no better than no blur" in got.err
    assert np.abs(read_photo(d / "blind2.png").pixels - kept).max() <= 1 / 255
    for grid, problem in (("auto", "with --blind give RxC"), ("6x6", "too small for a 21 px")):
        assert problem in _run_error(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size",
                                      "21", "--grid", grid, "-o", str(d / "b3.png")], capsys)


def test_sparse_options_change_the_result_and_are_checked(capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "b.png"),
                 "--snr-db", "40", "--seed", "1"]) == 0
    for name, extra in (("i2.png", ["--iterations", "2"]), ("i6.png", ["--iterations", "6"]),
                        ("n.png", ["--noise-sigma", "0.05"]), ("default.png", []),
                        ("p.png", ["--model", "patches"])):
        assert main(["deblur", str(d / "b.png"), "--capture", cap, "-o", str(d / name), "--quiet",
                     *extra]) == 0
    px = {n: read_photo(d / n).pixels for n in ("i2.png", "i6.png", "n.png", "default.png",
                                                 "p.png")}
    np.testing.assert_array_equal(px["i6.png"], px["default.png"])  # 6 is the default
    # The patches' iterations: the global model's refinement after them undoes much of
    # what fewer leave (0.0089 -> 0.0009 mean difference), but not all.
    assert np.abs(px["i2.png"] - px["i6.png"]).mean() > 3e-4
    assert np.abs(px["p.png"] - px["default.png"]).mean() > 1e-3
    # A 10x larger noise level means a much stronger prior: a smoother result.
    assert np.abs(np.diff(px["n.png"], axis=1)).mean() < np.abs(np.diff(px["i6.png"], axis=1)).mean()
    before = sorted(p.name for p in d.iterdir())
    assert "--iterations" in _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                                         str(d / "x.png"), "--iterations", "0"], capsys)
    assert "--noise-sigma" in _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                                          str(d / "x.png"), "--noise-sigma", "-1"], capsys)
    assert "sparse only" in _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                                        str(d / "x.png"), "--method", "wiener", "--iterations",
                                        "3"], capsys)
    assert "sparse only" in _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                                        str(d / "x.png"), "--method", "wiener", "--model",
                                        "global"], capsys)
    assert "variant only" in _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                                         str(d / "x.png"), "--mode", "invariant", "--model",
                                         "patches"], capsys)
    assert sorted(p.name for p in d.iterdir()) == before


def _edited_capture(d, name, edit):
    """``cap.json`` with ``edit(doc)`` applied, written as ``name``."""
    doc = json.loads((d / "cap.json").read_text())
    edit(doc)
    (d / name).write_text(json.dumps(doc))
    return str(d / name)


@pytest.mark.parametrize("edit,match", [
    (lambda doc: doc.update(camera=[1, 2]), "'camera' must be a JSON object"),
    (lambda doc: doc.update(gyro="gyro.gcsv"), "'gyro' must be a JSON object"),
    (lambda doc: doc["gyro"].update(path=None), "missing gyro.path"),
    (lambda doc: doc["gyro"].update(path=5), "gyro.path must be a file path"),
    (lambda doc: doc["gyro"].update(max_gap="abc"), "'max_gap' must be a number"),
    (lambda doc: doc["gyro"].update(max_gap=-1), "max_gap must be a positive number"),
    (lambda doc: doc["gyro"].update(rate_columns=5), "rate_columns must list three"),
    (lambda doc: doc["gyro"].update(bias={"x": 1}), "bias must be three finite numbers"),
    (lambda doc: doc["gyro"].update(bias=["a", "b", "c"]), "bias must be three finite numbers"),
    (lambda doc: doc.update(exposure_time=True), "'exposure_time' must be a number"),
    (lambda doc: doc["camera"].update(fx=True), "'fx' must be a number"),
    (lambda doc: doc["camera"].update(width=256.5), "camera.width must be a whole number"),
    (lambda doc: doc["camera"].update(height="abc"), "camera.height must be a whole number"),
    (lambda doc: doc["camera"].update(fx=-5.0), "focal lengths must be positive"),
    (lambda doc: doc["camera"].pop("width"), "camera.width missing"),
])
def test_bad_capture_fields_are_named_not_tracebacks(capture_dir, capsys, edit, match):
    """Every field of the wrong type or value is one error line naming the JSON file."""
    d = capture_dir
    cap = _edited_capture(d, "edited.json", edit)
    for argv in (["psf", "--capture", cap, "--at", "5,5", "-o", str(d / "p.npy")],
                 ["deblur", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "o.png")]):
        msg = _run_error(argv, capsys)
        assert "edited.json" in msg and match in msg
    assert not (d / "p.npy").exists() and not (d / "o.png").exists()


def test_a_blur_longer_than_the_frame_is_refused_before_any_work(capture_dir, capsys):
    """A focal length 100x too long (for another resolution) makes the fixture's 0.015 rad
    of shake a blur of about 300 px, longer than its 256 px frame. Every command refuses it
    (instead of exhausting memory, or time in simulate) and names what to check."""
    d = capture_dir
    cap = str(d / "cap.json")
    for argv in (["psf", "--capture", cap, "--fx", "2e4", "--at", "0,0", "-o", str(d / "p.npy")],
                 ["deblur", str(d / "sharp.jpg"), "--capture", cap, "--fx", "2e4", "-o", str(d / "o.png")],
                 ["simulate", str(d / "sharp.jpg"), "--capture", cap, "--fx", "2e4", "-o", str(d / "s.png")]):
        msg = _run_error(argv, capsys)
        assert "cap.json" in msg and "more than the" in msg and "focal length" in msg
    assert not any((d / n).exists() for n in ("p.npy", "o.png", "s.png"))


def test_options_out_of_range_or_ignored_are_refused(capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    photo = str(d / "sharp.jpg")
    cases = [
        (["psf", "--capture", cap, "--at", "nan,3", "-o", str(d / "p.npy")], "--at"),
        (["psf", "--capture", cap, "--at", "5000,5", "-o", str(d / "p.npy")], "--at"),
        (["simulate", photo, "--capture", cap, "--snr-db", "nan", "-o", str(d / "s.png")], "--snr-db"),
        (["simulate", photo, "--capture", cap, "--snr-db", "30", "--seed", "-1", "-o",
          str(d / "s.png")], "--seed"),
        (["deblur", photo, "--capture", cap, "--overlap", "1", "-o", str(d / "o.png")], "--overlap"),
        (["deblur", photo, "--capture", cap, "--overlap", "nan", "-o", str(d / "o.png")], "--overlap"),
        (["deblur", photo, "--capture", cap, "--max-gap", "nan", "-o", str(d / "o.png")], "--max-gap"),
        (["deblur", photo, "--capture", cap, "-o", str(d / "o.png"), "--save-psf", str(d / "o.png")],
         "is also the output photo"),
        (["deblur", photo, "--capture", cap, "--kernel-size", "9", "-o", str(d / "o.png")],
         "--kernel-size: applies with --blind only"),
        (["deblur", photo, "--capture", cap, "--refine", "--no-blur-check", "-o",
          str(d / "o.png")], "--no-blur-check: does not apply with --refine"),
        (["deblur", photo, "--blind", "--refine", "-o", str(d / "o.png")], "--refine: does not apply"),
        (["deblur", photo, "--blind", "--fix", "bias", "-o", str(d / "o.png")], "--fix: does not apply"),
        (["deblur", photo, "--blind", "--time-offset", "0", "-o", str(d / "o.png")],
         "--time-offset: does not apply"),                       # a zero is a value given
        (["deblur", photo, "--blind", "--downscale", "0.5", "-o", str(d / "o.png")],
         "--downscale: applies with --refine only"),
        (["deblur", photo, "--blind", "--capture", cap, "-o", str(d / "o.png")], "--capture: does not apply"),
        (["deblur", photo, "--capture", cap, "--mappings", "all", "-o", str(d / "o.png")],
         "--mappings: applies with --refine only"),
        (["deblur", photo, "--capture", cap, "--mode", "invariant", "--grid", "2x2", "-o",
          str(d / "o.png")], "--grid: applies to --mode variant only"),
    ]
    for argv, match in cases:
        assert match in _run_error(argv, capsys), argv
    assert not any((d / n).exists() for n in ("p.npy", "s.png", "o.png"))


def test_the_mappings_searched_reach_the_calibration(capture_dir, capsys, monkeypatch):
    """``--mappings`` of ``calibrate`` and of ``deblur --refine`` (alone and as a
    session) is what the search gets; left out, the search chooses (``None``)."""
    import gyrodeblur.calibrate
    import gyrodeblur.calibrate_cli
    from gyrodeblur.errors import InputError

    d, asked = capture_dir, []

    def stub(*args, mappings=None, **kwargs):
        asked.append(mappings)
        raise InputError(None, "stopped here")

    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", stub)
    monkeypatch.setattr(gyrodeblur.calibrate_cli, "calibrate", stub)
    main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o",
          str(d / "m.png"), "--overwrite"])
    other = read_photo(d / "m.png").pixels.copy()
    other[0, 0] = 1 - other[0, 0]                   # another photo of the session
    write_photo(d / "m2.png", other, bit_depth=8, overwrite=True)
    photo, cap = str(d / "m.png"), str(d / "cap.json")
    for argv in (["calibrate", photo, "--capture", cap, "-o", str(d / "m.json"), "--mappings",
                  "all"],
                 ["calibrate", photo, "--capture", cap, "-o", str(d / "m.json")],
                 ["deblur", photo, "--capture", cap, "--refine", "--mappings", "phone", "-o",
                  str(d / "mo.png")],
                 ["deblur", photo, str(d / "m2.png"), "--capture", cap, "--refine",
                  "--mappings", "all", "-o", str(d / "mo.png"), "-o", str(d / "mo2.png")]):
        assert "stopped here" in _run_error(argv, capsys), argv
    assert asked == ["all", None, "phone", "all"]
    with pytest.raises(SystemExit):                      # argparse's own refusal
        main(["calibrate", photo, "--capture", cap, "-o", str(d / "m.json"), "--mappings",
              "phones"])
    assert "--mappings: invalid choice: 'phones'" in capsys.readouterr().err


def test_calibrate_never_overwrites_its_inputs(capture_dir, capsys):
    """Not the photo, the capture description or the gyro log, --overwrite or not."""
    d = capture_dir
    main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o", str(d / "b.png")])
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}
    for target in ("b.png", "cap.json", "gyro.gcsv"):
        msg = _run_error(["calibrate", str(d / "b.png"), "--capture", str(d / "cap.json"),
                          "-o", str(d / target), "--overwrite"], capsys)
        assert target in msg and "inputs" in msg
    assert {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()} == before


def test_a_too_small_photo_is_named(capture_dir, capsys):
    d = capture_dir
    write_photo(d / "tiny.png", np.full((8, 8, 3), 0.5, np.float32))
    msg = _run_error(["deblur", str(d / "tiny.png"), "--blind", "-o", str(d / "o.png")], capsys)
    assert "tiny.png: the image has only 8 rows" in msg


def test_a_scaled_camera_is_said_and_a_crop_is_flagged(capture_dir, capsys):
    """The capture's camera is 256x192. A half-size photo is a resize (128x96); a photo
    two columns short is more likely a crop, whose intrinsics scaling would get wrong."""
    d = capture_dir
    full = read_photo(d / "sharp.jpg").pixels
    write_photo(d / "half.png", full[::2, ::2])
    write_photo(d / "crop.png", full[:, 1:-1])
    said = {}
    for name in ("half.png", "crop.png", "sharp.jpg"):
        assert main(["simulate", str(d / name), "--capture", str(d / "cap.json"),
                     "-o", str(d / ("s_" + name.replace(".jpg", ".png")))]) == 0
        said[name] = capsys.readouterr().out
    assert "scaled to the photo's 128x96" in said["half.png"] and "crop" not in said["half.png"]
    assert "scaled to the photo's 254x192; the aspect ratios differ by 0.78%: a cropped" \
        in said["crop.png"]
    assert "intrinsics are scaled" not in said["sharp.jpg"]


def test_a_camera_error_from_an_option_names_the_option(capture_dir, capsys):
    msg = _run_error(["psf", "--capture", str(capture_dir / "cap.json"), "--fx", "3.9",
                      "--at", "0,0", "-o", str(capture_dir / "p.npy")], capsys)
    assert "cap.json with --fx: camera: focal length fx=3.9" in msg and "in mm or 35 mm" in msg


@pytest.mark.parametrize("command", [
    ["deblur", "b.png", "-o", "cap.png"],
    ["deblur", "b.png", "-o", "out.png", "--save-psf", "cap.png"],
    ["deblur", "b.png", "-o", "log.tif", "--mode", "invariant"],
    ["simulate", "sharp.jpg", "-o", "cap.png"],
    ["psf", "--at", "10,20", "-o", "cap.png"],
])
def test_no_command_writes_over_its_capture_or_gyro_log(capture_dir, capsys, command):
    """The capture description and its log are inputs as much as the photo, even with
    ``--overwrite`` and names that look like outputs."""
    d = capture_dir
    main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o", str(d / "b.png")])
    (d / "log.tif").write_bytes((d / "gyro.gcsv").read_bytes())
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["path"] = "log.tif"
    (d / "cap.png").write_text(json.dumps(doc))
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}
    args = [str(d / a) if a.endswith((".png", ".jpg", ".tif")) else a for a in command]
    msg = _run_error(args + ["--capture", str(d / "cap.png"), "--overwrite"], capsys)
    assert "is one of the command's inputs" in msg
    assert {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()} == before


def test_a_photo_too_small_for_the_invariant_mode_is_named(capture_dir, capsys):
    d = capture_dir
    write_photo(d / "strip.png", np.full((7, 100, 3), 0.5, np.float32))
    doc = json.loads((d / "cap.json").read_text())
    doc["camera"] = {"fx": 20.0}                    # the photo's size and centre
    (d / "strip.json").write_text(json.dumps(doc))
    msg = _run_error(["deblur", str(d / "strip.png"), "--capture", str(d / "strip.json"),
                      "--mode", "invariant", "-o", str(d / "o.png")], capsys)
    assert "strip.png: the image has only 7 rows; need at least 16" in msg


def test_simulate_blurs_light_brighter_than_white_and_refuses_16_bit_jpeg_first(capture_dir,
                                                                                capsys):
    import tifffile
    d = capture_dir
    scene = read_photo(d / "sharp.jpg").pixels
    for level in (1.0, 8.0):
        lit = scene.copy()
        lit[90:94, 120:124] = level                  # a lamp
        tifffile.imwrite(d / f"lamp{level:g}.tif", lit, photometric="rgb", metadata=None)
        assert main(["simulate", str(d / f"lamp{level:g}.tif"), "--capture", str(d / "cap.json"),
                     "-o", str(d / f"b{level:g}.tif"), "--transfer", "linear"]) == 0
    assert "samples up to 8 (white = 1)" in capsys.readouterr().out
    dim, bright = (read_photo(d / f"b{v}.tif").pixels for v in ("1", "8"))
    assert bright.max() <= 1.0
    # 8x the light spreads a blurred streak that clips where 1x stays below white
    assert (bright[80:105, 105:140] >= 0.999).sum() > 2 * (dim[80:105, 105:140] >= 0.999).sum()
    # a scene mostly above white (an over-exposure in linear light): clipped, then written
    tifffile.imwrite(d / "over.tif", 3 * scene + 0.5, photometric="rgb", metadata=None)
    assert main(["simulate", str(d / "over.tif"), "--capture", str(d / "cap.json"), "-o",
                 str(d / "b_over.tif"), "--transfer", "linear"]) == 0
    over = read_photo(d / "b_over.tif").pixels
    assert over.max() <= 1.0 and np.median(over) == 1.0
    msg = _run_error(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                      "-o", str(d / "x.jpg"), "--bit-depth", "16"], capsys)
    assert "x.jpg: JPEG stores 8 bits per sample" in msg
    assert not (d / "x.jpg").exists()
    # a float TIFF without a profile is taken as sRGB: 8x white is not an encoded value
    msg = _run_error(["simulate", str(d / "lamp8.tif"), "--capture", str(d / "cap.json"),
                      "-o", str(d / "c8.tif")], capsys)
    assert "lamp8.tif: samples up to 8" in msg and "give --transfer linear" in msg
    assert not (d / "c8.tif").exists()


def test_a_jpeg_is_deconvolved_for_its_compression_error_as_well(capture_dir, capsys):
    """JPEG's quantisation hides the noise the estimator measures but leaves an error
    that the deconvolution amplifies: the level it is deconvolved for is raised, and the
    result is sharper than with the level its pixels show (synthesised by warping)."""
    from gyrodeblur.metrics import psnr
    from gyrodeblur.noise import estimate_noise_sigma
    d = capture_dir
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "b.png"), "--snr-db", "40", "--seed", "3"]) == 0
    Image.open(d / "b.png").save(d / "b.jpg", quality=90)
    shown = estimate_noise_sigma(read_photo(d / "b.jpg").pixels)
    assert main(["deblur", str(d / "b.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "raised.png")]) == 0
    assert "JPEG: deconvolved for noise of" in capsys.readouterr().out
    assert main(["deblur", str(d / "b.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "shown.png"), "--noise-sigma", f"{shown:.6f}"]) == 0
    sharp = read_photo(d / "sharp.jpg").pixels
    gain = (psnr(read_photo(d / "raised.png").pixels, sharp, border=16)
            - psnr(read_photo(d / "shown.png").pixels, sharp, border=16))
    assert gain > 0.3, gain


def test_a_photo_given_twice_and_a_bad_grid_are_refused_before_any_calibration(capture_dir,
                                                                               capsys,
                                                                               monkeypatch):
    import shutil

    import gyrodeblur.calibrate
    import gyrodeblur.calibrate_cli

    def no_calibration(*args, **kwargs):
        raise AssertionError("calibrated before the inputs were checked")

    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", no_calibration)
    monkeypatch.setattr(gyrodeblur.calibrate_cli, "calibrate", no_calibration)
    d = capture_dir
    main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o", str(d / "b.png")])
    shutil.copy(d / "b.png", d / "copy.png")
    capsys.readouterr()
    cap = str(d / "cap.json")
    msg = _run_error(["calibrate", str(d / "b.png"), str(d / "b.png"), "--capture", cap,
                      "-o", str(d / "o.json")], capsys)
    assert "b.png: is " in msg and "given already" in msg
    msg = _run_error(["calibrate", str(d / "b.png"), str(d / "copy.png"), "--capture", cap,
                      "-o", str(d / "o.json")], capsys)
    assert "copy.png: holds the same pixels as" in msg
    msg = _run_error(["deblur", str(d / "b.png"), "--capture", cap, "--refine", "--grid",
                      "100x100", "-o", str(d / "o.png")], capsys)
    assert "--grid" in msg
    assert not (d / "o.json").exists() and not (d / "o.png").exists()


def test_a_linear_photo_is_deblurred_through_the_curve_its_icc_profile_declares(capture_dir,
                                                                                capsys):
    """A 16-bit PNG of linear light with a linear ICC profile (a raw converter's export),
    blurred by warping the linear scene: by default it is deconvolved as linear (the profile
    says so, and the tool says it read that), which restores it better than taking it as
    sRGB-encoded; the output keeps the profile. ``simulate`` reads the profile alike."""
    from iccprofiles import curv_gamma, curv_identity, make_icc

    from gyrodeblur.capture import load_capture
    from gyrodeblur.imageio import Photo
    from gyrodeblur.metrics import psnr
    from gyrodeblur.simulate import simulate_blur
    from gyrodeblur.tonecurve import srgb_to_linear
    d = capture_dir
    scene = srgb_to_linear(read_photo(d / "sharp.jpg").pixels)
    linear_icc = make_icc(curv_identity(), name="Linear Rec709")
    blurred = simulate_blur(scene, load_capture(d / "cap.json"), snr_db=45, seed=2, transfer="linear")
    write_photo(d / "lin.png", blurred, bit_depth=16,
                like=Photo(blurred, 16, "PNG", icc_profile=linear_icc))
    assert main(["deblur", str(d / "lin.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "auto.png")]) == 0
    assert "'Linear Rec709') declares a linear transfer curve" in capsys.readouterr().out
    assert main(["deblur", str(d / "lin.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "as_srgb.png"), "--transfer", "srgb"]) == 0
    out = read_photo(d / "auto.png")
    assert out.icc_profile == linear_icc and out.bit_depth == 16
    gain = (psnr(out.pixels, scene, border=16)
            - psnr(read_photo(d / "as_srgb.png").pixels, scene, border=16))
    assert gain > 3.0, gain                         # 9.2 dB when written
    # simulate: a gamma-1.8 photo is blurred in the light its profile decodes it to
    g18 = make_icc(curv_gamma(1.8), name="ProPhoto-like")
    gamma = np.float32(461 / 256)                   # 1.8 as the profile's 8.8 bits hold it
    sharp18 = scene ** (1 / gamma)
    write_photo(d / "g18.png", sharp18, bit_depth=16, like=Photo(sharp18, 16, "PNG",
                                                                 icc_profile=g18))
    assert main(["simulate", str(d / "g18.png"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "g18_blurred.png")]) == 0
    expected = np.clip(simulate_blur(read_photo(d / "g18.png").pixels ** gamma,
                                     load_capture(d / "cap.json"), transfer="linear"),
                       0, 1) ** (1 / gamma)
    got = read_photo(d / "g18_blurred.png").pixels
    assert np.abs(got - expected).max() < 2e-5      # 16-bit rounding


class _StopCalibration(Exception):
    """Raised by :func:`_spy_on_calibrate`'s stand-in: the command stops there."""


def _spy_on_calibrate(monkeypatch, key: str | None, record=None) -> list:
    """Put a stand-in for ``calibrate`` where the commands find it: it records the value of
    its keyword argument ``key`` (or ``record(images, captures, kwargs)``) in the list
    returned, then raises :class:`_StopCalibration`."""
    import gyrodeblur.calibrate
    import gyrodeblur.calibrate_cli

    seen = []

    def spy(images, captures, **kwargs):
        seen.append(kwargs[key] if record is None else record(images, captures, kwargs))
        raise _StopCalibration

    monkeypatch.setattr(gyrodeblur.calibrate_cli, "calibrate", spy)
    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", spy)
    return seen


def _blurred_a_png(d, cap: str) -> np.ndarray:
    """``d/sharp.jpg`` blurred by the capture ``cap`` into ``d/a.png`` (40 dB, seed 1);
    its pixels."""
    main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "a.png"),
          "--seed", "1", "--snr-db", "40"])
    return read_photo(d / "a.png").pixels


def test_calibrations_warnings_are_the_commands_warnings(capture_dir, capsys, monkeypatch):
    """On the command line, calibration's notes that are warnings ("warning: ...": an
    uncertain mapping, a clipped log) are printed as every other warning, on the error
    stream, and a filter that makes warnings errors stops ``calibrate`` and ``deblur
    --refine`` there (exit status 3); its other notes stay on the output."""
    import warnings

    from gyrodeblur.errors import GyrodeblurWarning

    def doubtful(images, captures, say=None, **kwargs):
        say("searched 24 mappings")
        say("  warning: the axis mapping is uncertain: a test's")   # as calibrate indents it
        raise _StopCalibration

    import gyrodeblur.calibrate
    import gyrodeblur.calibrate_cli
    monkeypatch.setattr(gyrodeblur.calibrate_cli, "calibrate", doubtful)
    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", doubtful)
    d = capture_dir
    runs = (["calibrate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o",
             str(d / "c.json")],
            ["deblur", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "--refine",
             "-o", str(d / "o.png")])
    for argv in runs:
        with pytest.raises(_StopCalibration):
            main(argv)
        got = capsys.readouterr()
        assert "searched 24 mappings" in got.out and "uncertain" not in got.out
        assert "gyrodeblur: warning: the axis mapping is uncertain: a test's" in got.err
        with warnings.catch_warnings():
            warnings.simplefilter("error", GyrodeblurWarning)
            assert main(argv) == 3
        assert "error: the axis mapping is uncertain" in capsys.readouterr().err
    assert not (d / "c.json").exists() and not (d / "o.png").exists()


def test_a_warning_said_twice_is_shown_once_and_one_made_an_error_names_its_photo(
        capture_dir, capsys, monkeypatch):
    """The same words warned from two places in one command (deblur --refine: a gap in
    the log, from its calibration and from its deblur) are shown once; among several
    photos, a warning made an error by the filter names the photo it came from."""
    import warnings

    import gyrodeblur.cli as cli
    from gyrodeblur.errors import GyrodeblurWarning

    def twice(args, say):
        warnings.warn("gap of 30.0 ms in the gyro log", GyrodeblurWarning)
        warnings.warn("gap of 30.0 ms in the gyro log", GyrodeblurWarning)
        warnings.warn("another", GyrodeblurWarning)

    monkeypatch.setattr(cli, "cmd_psf", twice)
    d = capture_dir
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "-o",
                 str(d / "p.npy")]) == 0
    assert capsys.readouterr().err.count("gap of 30.0 ms") == 1
    monkeypatch.undo()
    # two photos: a blurred one, then the sharp one, whose blur check warns
    _blurred_a_png(d, str(d / "cap.json"))
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error", GyrodeblurWarning)
        assert main(["deblur", str(d / "a.png"), str(d / "sharp.jpg"), "--capture",
                     str(d / "cap.json"), "-o", f"{d / 'oa.png'},{d / 'os.png'}"]) == 3
    err = capsys.readouterr().err
    assert f"error: {d / 'sharp.jpg'}: the blur the gyro log implies" in err, err
    assert (d / "oa.png").exists() and not (d / "os.png").exists()


def test_calibrate_and_refine_read_each_photo_through_its_own_curve(capture_dir, capsys,
                                                                    monkeypatch):
    """``calibrate`` takes each photo's curve from its profile (or ``--transfer``), and
    ``deblur --refine`` calibrates through the curve it deblurs with (it used sRGB's)."""
    from iccprofiles import curv_identity, make_icc

    from gyrodeblur.imageio import Photo
    from gyrodeblur.tonecurve import LINEAR, SRGB

    seen = _spy_on_calibrate(monkeypatch, "transfer")
    d = capture_dir
    cap = str(d / "cap.json")
    a = _blurred_a_png(d, cap)
    b = np.clip(a + 0.01, 0, 1)
    write_photo(d / "b.png", b, bit_depth=16, like=Photo(b, 16, "PNG",
                                                         icc_profile=make_icc(curv_identity())))
    with pytest.raises(_StopCalibration):
        main(["calibrate", str(d / "a.png"), str(d / "b.png"), "--capture", cap,
              "-o", str(d / "o.json")])
    assert seen[-1] == [SRGB, LINEAR]
    with pytest.raises(_StopCalibration):
        main(["calibrate", str(d / "a.png"), str(d / "b.png"), "--capture", cap,
              "-o", str(d / "o.json"), "--transfer", "srgb"])
    assert seen[-1] == [SRGB, SRGB]
    with pytest.raises(_StopCalibration):
        main(["deblur", str(d / "a.png"), "--capture", cap, "--refine", "--transfer",
              "linear", "-o", str(d / "o.png")])
    assert seen[-1] is LINEAR
    msg = _run_error(["calibrate", str(d / "a.png"), "--capture", cap, "-o", str(d / "o.json"),
                      "--transfer", "gamma"], capsys)
    assert "--transfer: unknown transfer curve 'gamma' (known: auto, linear" in msg


def test_a_digitally_zoomed_photo_is_calibrated_shrunk_by_its_zoom(capture_dir, capsys,
                                                                  monkeypatch):
    """A photo whose EXIF records a digital zoom Z is calibrated shrunk by 1/Z unless
    ``--downscale`` is given (``calibrate``, ``deblur --refine`` alone and as a session),
    and the tool says so; the factor leaves at least 96 px on the shorter side; photos
    without a zoom keep the default of 1."""
    seen = _spy_on_calibrate(monkeypatch, "downscale")
    d = capture_dir
    cap = str(d / "cap.json")
    pixels = _blurred_a_png(d, cap)
    for name, ratio in (("x2.jpg", IFDRational(2, 1)), ("x4.jpg", IFDRational(4, 1)),
                        ("x1.jpg", IFDRational(0, 1))):
        exif = Image.Exif()
        exif.get_ifd(0x8769)[0xA404] = ratio
        Image.fromarray((pixels * 255).round().astype(np.uint8)).save(
            d / name, exif=exif.tobytes(), quality=95)
    capsys.readouterr()

    def calibrated(*argv):
        with pytest.raises(_StopCalibration):
            main(list(argv))
        return seen[-1], capsys.readouterr().out

    factor, out = calibrated("calibrate", str(d / "x2.jpg"), "--capture", cap,
                             "-o", str(d / "o.json"))
    assert factor == 0.5
    assert "digitally zoomed x2 (EXIF DigitalZoomRatio)" in out and "shrunk by 0.5" in out
    assert calibrated("calibrate", str(d / "x2.jpg"), "--capture", cap, "-o",
                      str(d / "o.json"), "--downscale", "1")[0] == 1.0
    assert calibrated("calibrate", str(d / "x1.jpg"), "--capture", cap,
                      "-o", str(d / "o.json")) == (1.0, "")
    # 192 rows: shrunk by 1/4 they would be 48, under calibrate's 64; 96 are kept
    assert calibrated("calibrate", str(d / "x4.jpg"), "--capture", cap,
                      "-o", str(d / "o.json"))[0] == 0.5
    factor, out = calibrated("deblur", str(d / "x2.jpg"), "--capture", cap, "--refine",
                             "-o", str(d / "o.png"))
    assert factor == 0.5 and "shrunk by 0.5" in out
    factor, out = calibrated("deblur", str(d / "a.png"), str(d / "x2.jpg"), "--capture",
                             f"{cap},{cap}", "--refine", "-o",
                             f"{d / 'o1.png'},{d / 'o2.png'}")
    assert factor == 0.5 and "shrunk by 0.5 with the others" in out


def test_sigterm_while_writing_leaves_no_file_and_exits_143(capture_dir):
    """SIGTERM (a batch system's stop) is handled like Ctrl-C: the temporary file being
    written is removed, no output appears, one line is said, exit status 143."""
    import signal
    import subprocess
    import sys
    import time
    d = capture_dir
    script = (
        "import sys, time\n"
        "import gyrodeblur.imageio as io\n"
        "def slow(f, ints, **kw):\n"
        "    f.write(b'partial'); f.flush(); time.sleep(60)\n"
        "io._write_png = slow\n"
        "from gyrodeblur.cli import main\n"
        f"sys.exit(main(['simulate', {str(d / 'sharp.jpg')!r}, '--capture', "
        f"{str(d / 'cap.json')!r}, '-o', {str(d / 'out.png')!r}]))\n")
    before = set(d.iterdir())
    child = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.endswith(".tmp") for p in d.iterdir()):
            assert time.monotonic() < deadline and child.poll() is None, "never wrote"
            time.sleep(0.05)
        child.send_signal(signal.SIGTERM)
        _, err = child.communicate(timeout=20)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == 143
    assert err.strip().splitlines()[-1] == "gyrodeblur: terminated; nothing written"
    assert set(d.iterdir()) == before


def test_a_reader_that_closes_the_pipe_does_not_stop_the_work(capture_dir):
    """``gyrodeblur ... | head -0`` and ``... 2>&1 | true``: the reader closes the pipe
    before the command says anything. The work is still done and written, nothing else
    is said, and the exit status is 0 (it was a BrokenPipeError traceback and 1, and the
    outputs after the first line said were lost)."""
    import subprocess
    import sys
    d = capture_dir
    doc = json.loads((d / "cap.json").read_text())
    doc["readout"] = 0.02                                # a misspelt key: a warning
    (d / "warned.json").write_text(json.dumps(doc))
    runs = {"psf": (["psf", "--capture", str(d / "cap.json"), "--at", "60,40", "-o",
                     str(d / "p.npy")], False),
            "deblur": (["deblur", str(d / "sharp.jpg"), "--capture", str(d / "warned.json"),
                        "--model", "patches", "-o", str(d / "o.png")], True)}
    for name, (argv, both) in runs.items():
        script = ("import sys, time\n"
                  "from gyrodeblur.cli import main\n"
                  "time.sleep(1.0)\n"      # the reader closes the pipe before the command speaks
                  f"sys.exit(main({argv!r}))\n")
        child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT if both else subprocess.PIPE,
                                 text=True)
        child.stdout.close()
        try:
            err = "" if both else child.stderr.read()
            child.wait(timeout=120)
        finally:
            if child.poll() is None:
                child.kill()
        assert err == "" and child.returncode == 0, (name, child.returncode, err)
    psf = np.load(d / "p.npy")
    assert psf.shape[0] % 2 == 1 and abs(float(psf.sum()) - 1) < 1e-5
    assert read_photo(d / "o.png").pixels.shape == read_photo(d / "sharp.jpg").pixels.shape


def test_outputs_are_all_written_or_none(capture_dir, capsys, monkeypatch):
    """A PSF drawing that cannot be written takes the new photo with it (exit 2, nothing
    written); a folder that refuses files is said before the work; the .npy of ``psf``
    is written through a temporary file of its own, leaving others' files alone."""
    import gyrodeblur.cli as cli
    from gyrodeblur.errors import InputError
    d = capture_dir
    cap = str(d / "cap.json")
    main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "b.png")])

    def refuse(path, *args):
        raise InputError(path, "cannot write the file: No space left on device")

    monkeypatch.setattr(cli, "_write_picture", refuse)
    capsys.readouterr()
    msg = _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o", str(d / "o.png"),
                      "--grid", "2x2", "--save-psf", str(d / "field.png")], capsys)
    assert "field.png: cannot write" in msg
    assert not (d / "o.png").exists() and not (d / "field.png").exists()
    monkeypatch.undo()
    # a folder that refuses new files (sysfs does, even for root): said before the work
    from gyrodeblur.atomicfile import check_writable
    try:
        check_writable("/sys/out.png")
    except InputError:
        import gyrodeblur.deblur as deblur_mod

        def no_work(*args, **kwargs):
            raise AssertionError("deblurred before the output folder was checked")

        monkeypatch.setattr(deblur_mod, "deblur", no_work)
        msg = _run_error(["deblur", str(d / "b.png"), "--capture", cap, "-o",
                          "/sys/out.png"], capsys)
        assert "/sys/out.png: cannot write in folder /sys" in msg
        monkeypatch.undo()
    (d / "p.npy.part.npy").write_bytes(b"someone else's")
    assert main(["psf", "--capture", cap, "--at", "10,20", "-o", str(d / "p.npy")]) == 0
    assert (d / "p.npy.part.npy").read_bytes() == b"someone else's"
    assert np.load(d / "p.npy").ndim == 2
    assert not [p for p in d.iterdir() if p.name.endswith((".tmp", ".probe"))]


def test_the_demo_writes_over_its_own_folder_but_not_over_a_user_s_files(tmp_path, capsys,
                                                                           monkeypatch):
    import gyrodeblur.demo as demo

    ran = []
    monkeypatch.setattr(demo, "simulate_blur", lambda *a, **k: ran.append(1) or (
        _ for _ in ()).throw(KeyboardInterrupt))    # stop at the work: the folder matters
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "capture.json").write_text("my notes")
    err = _run_error(["demo", "--out", str(mine)], capsys)
    assert "capture.json, not written by the demo" in err and "--overwrite" in err
    assert (mine / "capture.json").read_text() == "my notes" and ran == []
    with pytest.raises(KeyboardInterrupt):
        demo.run_demo(str(mine), overwrite=True, say=lambda s: None)
    assert ran == [1]
    own = tmp_path / "own"                   # a folder the demo wrote before
    own.mkdir()
    (own / demo.MARKER).write_text("")
    (own / "capture.json").write_text("{}")
    with pytest.raises(KeyboardInterrupt):
        demo.run_demo(str(own), say=lambda s: None)
    assert ran == [1, 1]


def test_a_phone_photo_of_more_megapixels_than_pillow_allows_is_read(tmp_path, monkeypatch):
    """Pillow calls anything over 89 MP a possible decompression bomb (and refuses 179 MP);
    phones take 108 and 200 MP photos. Shown at a small scale: Pillow's limit lowered
    under the photo's size reads it anyway, the tool's own limit refuses it clearly."""
    import warnings

    import gyrodeblur.imageio as imageio
    from gyrodeblur.errors import InputError

    p = write_photo(tmp_path / "big.png", np.full((60, 80, 3), 0.5, np.float32))
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)      # 4800 px: over twice that
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_photo(p).pixels.shape == (60, 80, 3)
    assert Image.MAX_IMAGE_PIXELS == 1000                     # left as it was
    monkeypatch.setattr(imageio, "MAX_PHOTO_PIXELS", 4000)
    with pytest.raises(InputError, match=r"80x60 pixels \(0 MP\) is more than"):
        read_photo(p)


def test_argument_errors_are_one_line_and_options_that_would_be_ignored_are_refused(
        capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    with pytest.raises(SystemExit) as exit_:
        main(["deblur", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "o.png"),
              "--photo-rotation", "45"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2 and len(err) == 1
    assert err[0].startswith("gyrodeblur: error: deblur: argument --photo-rotation")
    assert err[0].endswith("(see gyrodeblur deblur --help)")
    for argv, flag in (
            (["deblur", str(d / "sharp.jpg"), "--blind", "--overlap", "0.3"], "--overlap"),
            (["psf", "--capture", cap, "--at", "5,5", "--overlap", "0.4"], "--overlap"),
            (["simulate", str(d / "sharp.jpg"), "--capture", cap, "--seed", "7"], "--seed")):
        assert flag in _run_error(argv + ["-o", str(d / "o.png")], capsys)
    assert not (d / "o.png").exists()


def test_negative_lists_need_no_equals_sign_and_calibrate_writes_json_only(capture_dir, capsys):
    d = capture_dir
    out = d / "p.npy"
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "100,80", "-o", str(out),
                 "--bias", "-0.01,0.02,0"]) == 0
    with_bias = np.load(out)
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "100,80", "-o", str(out),
                 "--overwrite"]) == 0
    assert not np.allclose(with_bias, np.load(out))       # the bias was read, and applied
    no_bias = np.load(out)
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "100,80", "-o", str(out),
                 "--overwrite", "--time-offset", "-4e-3"]) == 0   # an exponent, negative
    from gyrodeblur.capture import load_capture
    from gyrodeblur.psf import render_psf

    cap = load_capture(d / "cap.json")
    np.testing.assert_allclose(np.load(out), render_psf(cap.replace(time_offset=-4e-3), 100, 80),
                               atol=1e-7)                 # read as -4 ms, and applied
    assert no_bias.shape != np.load(out).shape or not np.allclose(no_bias, np.load(out))
    msg = _run_error(["psf", "--capture", str(d / "cap.json"), "--at", "-1,-1", "-o",
                      str(d / "q.npy")], capsys)
    assert "--at: (-1, -1) is not a pixel" in msg
    msg = _run_error(["calibrate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                      "-o", str(d / "x.png")], capsys)
    assert "x.png: the corrected capture description is JSON" in msg
    assert not (d / "x.png").exists()


def test_each_command_shows_its_own_warnings_and_leaves_the_hook(capture_dir, capsys):
    """Two runs in one process (a batch script calling main) each show their warning,
    even when it is word for word the same, and main leaves warnings.showwarning as it
    found it."""
    import warnings

    hook = warnings.showwarning
    d = capture_dir
    for k in range(2):
        assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9",
                     "-o", str(d / f"same{k}.png"), "--quiet"]) == 0
        assert "gyrodeblur: warning: the blind kernel explains" in capsys.readouterr().err
    assert warnings.showwarning is hook


def test_the_demo_runs_to_the_end(tmp_path, capsys):
    """The README's first command: every file written, the deblurred photo sharper."""
    import json as _json

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for name in ("blurred.png", "deblurred.png", "psf_field.png", "comparison.png",
                 "capture.json"):
        assert (out / name).stat().st_size > 0, name
    blurred, deblurred = (float(line.split("PSNR")[1].split("dB")[0])
                          for line in text.splitlines()
                          if line.strip().startswith(("blurred ", "deblurred ")))
    assert deblurred > blurred + 8, text                  # 14.9 -> 28.7 dB at session 38
    # (mutation audit, session 47: D8, D10, D20) the folder holds what the demo says it
    # writes and its marker, nothing else; the comparison is blurred | deblurred | sharp
    import gyrodeblur.demo as demo

    assert sorted(p.name for p in out.iterdir()) == sorted(demo.OUTPUTS + (demo.MARKER,))
    side = read_photo(out / "comparison.png").pixels
    parts = [read_photo(out / name).pixels for name in ("blurred.png", "deblurred.png",
                                                         "sharp.png")]
    w = parts[0].shape[1]
    for k, part in enumerate(parts):
        np.testing.assert_array_equal(side[:, k * (w + 8):k * (w + 8) + w], part)


def test_overlap_with_one_patch_is_refused_however_the_grid_is_spelt(capture_dir, capsys):
    """One patch has nothing to overlap: --overlap is refused rather than ignored, with or
    without --blind, for 1x1, 1X1 and 1,1 alike."""
    d = capture_dir
    base = ["deblur", str(d / "sharp.jpg"), "-o", str(d / "o.png")]
    for grid in ("1x1", "1X1", "1,1"):
        msg = _run_error(base + ["--capture", str(d / "cap.json"), "--grid", grid,
                                 "--overlap", "0.4"], capsys)
        assert "--overlap" in msg and "one patch" in msg, (grid, msg)
        msg = _run_error(base + ["--blind", "--kernel-size", "9", "--grid", grid,
                                 "--overlap", "0.3"], capsys)
        assert "--overlap" in msg and "--grid RxC only" in msg, (grid, msg)
    assert not (d / "o.png").exists()


def test_model_with_one_patch_is_refused(capture_dir, capsys):
    """One patch (``--grid 1x1``, or ``--blind``'s one kernel) has no neighbours for the
    global model to refine it with, so ``--model`` is refused rather than ignored (it
    changed nothing: session 59's audit found the outputs bit-identical)."""
    d = capture_dir
    base = ["deblur", str(d / "sharp.jpg"), "-o", str(d / "o.png")]
    for model in ("global", "patches"):
        msg = _run_error(base + ["--capture", str(d / "cap.json"), "--grid", "1x1",
                                 "--model", model], capsys)
        assert "--model" in msg and "one patch" in msg, msg
        for grid in ([], ["--grid", "1,1"]):
            msg = _run_error(base + ["--blind", "--kernel-size", "9", "--model", model] + grid,
                             capsys)
            assert "--model" in msg and "--grid RxC only" in msg, msg
    assert not (d / "o.png").exists()


def test_writing_over_a_file_keeps_its_permissions(capture_dir):
    """--overwrite replaces the file's content, not who may read it."""
    import os
    import stat

    d = capture_dir
    out = d / "private.npy"
    np.save(out, np.zeros(3))
    os.chmod(out, 0o600)
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(out),
                 "--overwrite"]) == 0
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o600 and np.load(out).ndim == 2
    fresh = d / "fresh.npy"                         # a new file takes the usual mode
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(fresh)]) == 0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(fresh).st_mode) == 0o666 & ~umask


def test_the_demo_refuses_a_folder_it_cannot_make_and_leaves_none_when_stopped(
        tmp_path, capsys, monkeypatch):
    import gyrodeblur.demo as demo

    (tmp_path / "afile").write_text("x")
    for out, problem in (("", "--out: give a folder"), (str(tmp_path / "afile" / "x"),
                                                        "is a file, not a folder")):
        assert problem in _run_error(["demo", "--out", out], capsys), out
    # folders to be made on the way are made
    assert main(["demo", "--out", str(tmp_path / "a" / "b")]) == 0
    assert (tmp_path / "a" / "b" / "deblurred.png").is_file()
    # stopped before it writes, it leaves no folder (which it would later take for its own)
    monkeypatch.setattr(demo, "simulate_blur", lambda *a, **k: (_ for _ in ()).throw(
        KeyboardInterrupt))
    assert main(["demo", "--out", str(tmp_path / "new")]) == 130
    assert not (tmp_path / "new").exists()


def test_the_demo_writes_through_no_link(tmp_path, capsys):
    """A link of a demo output's name in the demo's folder is replaced, not written
    through: the file it pointed at, outside the folder, is left alone."""
    import gyrodeblur.demo as demo

    out = tmp_path / "dm"
    out.mkdir()
    (out / demo.MARKER).write_text("")
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    for name in ("metrics.json", "deblurred.png", demo.MARKER):
        if (out / name).exists():
            (out / name).unlink()
        (out / name).symlink_to(victim)
    assert main(["demo", "--out", str(out)]) == 0
    assert victim.read_text() == "mine"
    assert not (out / "metrics.json").is_symlink() and "psnr" in (out / "metrics.json").read_text()
    assert not (out / "deblurred.png").is_symlink()     # (audit, session 47: D14)


def test_an_empty_capture_name_is_named_as_such(capture_dir, capsys):
    msg = _run_error(["psf", "--capture", "", "--at", "1,1", "-o",
                      str(capture_dir / "p.npy")], capsys)
    assert "--capture: an empty file name" in msg


def test_an_interrupted_run_ends_its_progress_bar_before_saying_so(capture_dir, capsys,
                                                                  monkeypatch):
    """On a terminal, Ctrl-C during the deblur: the bar's line is ended, so "interrupted"
    starts a line of its own."""
    import gyrodeblur.cli as cli
    import gyrodeblur.deblur as deblur_module

    monkeypatch.setattr(cli, "_is_terminal", lambda stream: True)

    def stopped(*args, progress=None, **kwargs):
        progress.t0 -= 5.0                           # past the bar's one-second wait
        progress(3, 10)
        raise KeyboardInterrupt

    monkeypatch.setattr(deblur_module, "deblur", stopped)
    d = capture_dir
    assert main(["deblur", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "o.png")]) == 130
    err = capsys.readouterr().err
    assert "3/10\ngyrodeblur: interrupted; nothing written" in err
    assert cli._Progress.drawn is None


def test_an_exif_exposure_start_reaches_calibration_marked_as_such(tmp_path, monkeypatch,
                                                                   capsys):
    """With the exposure start taken from the photo's EXIF time (a phone app's log on Unix
    time), calibrate and deblur --refine hand calibration a capture marked as such (it
    then searches a second either way); a description or an option that gives the start
    is not marked, whether it is the EXIF time itself (as in calibrate's own corrected
    description) or another."""
    from gyrodeblur.imageio import Photo

    def flags(captures):
        return [c.exposure_start_from_exif for c in
                (captures if isinstance(captures, list) else [captures])]

    seen = _spy_on_calibrate(monkeypatch, None, lambda images, captures, kw: flags(captures))
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    sub[0x9003], sub[0x9011], sub[0x9291] = "2024:12:05 07:27:10", "+01:00", "512"
    pixels = np.full((48, 64, 3), 0.5, np.float32)
    write_photo(tmp_path / "p.png", pixels, like=Photo(pixels, 8, "PNG", None, exif.tobytes()))
    t = 1733380029.0 + np.arange(0, 3, 0.005)
    (tmp_path / "g.csv").write_text("t_s,wx,wy,wz\n" + "\n".join(
        f"{a:.4f},0.1,0.2,0.3" for a in t) + "\n")
    doc = {"exposure_time": 0.03, "readout_time": 0.02, "camera": {"fx": 60},
           "gyro": {"path": "g.csv"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    for name, start in (("s.json", 1733380030.4), ("same.json", 1733380030.512)):
        (tmp_path / name).write_text(json.dumps(dict(doc, exposure_start=start)))
    photo, out = str(tmp_path / "p.png"), str(tmp_path / "o.json")
    runs = [(["calibrate", photo, "--capture", str(tmp_path / "c.json"), "-o", out], [True]),
            (["deblur", photo, "--capture", str(tmp_path / "c.json"), "--refine", "-o",
              str(tmp_path / "o.png")], [True]),
            (["calibrate", photo, "--capture", str(tmp_path / "s.json"), "-o", out], [False]),
            (["calibrate", photo, "--capture", str(tmp_path / "same.json"), "-o", out],
             [False]),
            (["calibrate", photo, "--capture", str(tmp_path / "c.json"), "-o", out,
              "--exposure-start", "1733380030.512"], [False])]
    for argv, marked in runs:
        with pytest.raises(_StopCalibration):
            main(argv)
        assert seen[-1] == marked, argv
        assert "from the photo's EXIF time" in capsys.readouterr().out or not marked[0]
    # two photos of one description: each takes its own EXIF time, not the description's
    write_photo(tmp_path / "q.png", pixels * 0.9, like=Photo(pixels, 8, "PNG", None,
                                                             exif.tobytes()))
    with pytest.raises(_StopCalibration):
        main(["calibrate", photo, str(tmp_path / "q.png"), "--capture",
              str(tmp_path / "c.json"), "-o", out])
    assert seen[-1] == [True, True]
    assert "take their exposure start from" not in capsys.readouterr().out
    # deblur --refine of both: each EXIF time is off by its own amount, so one at a time
    with pytest.raises(_StopCalibration):
        main(["deblur", photo, str(tmp_path / "q.png"), "--capture", str(tmp_path / "c.json"),
              "--refine", "-o", str(tmp_path / "d1.png"), "-o", str(tmp_path / "d2.png")])
    assert seen[-1] == [True]
    said = capsys.readouterr().out
    assert "each photo is calibrated alone" in said and "take their exposure start" not in said
    # refused before any calibration: the same photo twice, and one --save-capture for
    # photos calibrated each alone (it would hold the first's calibration only)
    calls = len(seen)
    for extra, what in (([photo], f"{photo}: is {photo}, given already"),
                        ([str(tmp_path / "q.png"), "--save-capture", str(tmp_path / "s1.json")],
                         "--save-capture: one file for several photos calibrated each alone")):
        msg = _run_error(["deblur", photo, *extra, "--capture", str(tmp_path / "c.json"),
                          "--refine", "-o", str(tmp_path / "d1.png"), "-o",
                          str(tmp_path / "d2.png")], capsys)
        assert what in msg, msg
    assert len(seen) == calls
    # deblur without --refine would deblur with a start tens of milliseconds off
    msg = _run_error(["deblur", photo, "--capture", str(tmp_path / "c.json"), "-o",
                      str(tmp_path / "plain.png")], capsys)
    assert "c.json: the exposure start is the photo's EXIF time" in msg   # no --refine given
    assert "add --refine (it searches 1 s either way)" in msg
    assert not (tmp_path / "plain.png").exists()
    # a sharp scene's EXIF time says nothing of the exposure simulate makes
    msg = _run_error(["simulate", photo, "--capture", str(tmp_path / "c.json"), "-o",
                      str(tmp_path / "b.png")], capsys)
    assert msg.endswith("c.json: missing 'exposure_start'")


def test_a_phone_photo_taller_than_wide_is_said_to_need_its_rotation(tmp_path, monkeypatch,
                                                                     capsys):
    """A phone's sensor is wider than tall, so a photo from a phone app's log that is
    taller than wide was most likely turned upright by an app or an export: the rows are
    then not the readout's, and the tool says to give --photo-rotation. Given, or a photo
    as the sensor stored it: nothing said."""
    seen = _spy_on_calibrate(monkeypatch, "fix")
    t = 1733380029.0 + np.arange(0, 3, 0.005)
    (tmp_path / "Gyroscope.csv").write_text("time,seconds_elapsed,z,y,x\n" + "\n".join(
        f"{int(round(a * 1e9))},{a - t[0]:.3f},0.3,0.2,0.1" for a in t) + "\n")
    doc = {"exposure_start": 1733380030.0, "exposure_time": 0.03, "readout_time": 0.02,
           "camera": {"fx": 60}, "gyro": {"path": "Gyroscope.csv",
                                          "orientation": "android-back-camera"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    write_photo(tmp_path / "upright.png", np.full((64, 48, 3), 0.5, np.float32))
    write_photo(tmp_path / "stored.png", np.full((48, 64, 3), 0.5, np.float32))
    said = "taller than wide, while a phone's sensor is wider than tall"
    for name, extra, told in (("upright.png", [], True), ("upright.png", ["--photo-rotation",
                              "90"], False), ("stored.png", [], False)):
        with pytest.raises(_StopCalibration):
            main(["calibrate", str(tmp_path / name), "--capture", str(tmp_path / "c.json"),
                  "-o", str(tmp_path / "o.json"), *extra])
        assert (said in capsys.readouterr().out) == told, (name, extra)
    assert len(seen) == 3
    # stored as the sensor read it, with an EXIF orientation tag for display (as phones
    # save them): --photo-rotation contradicts the tag, and is warned of
    from PIL import Image
    tag = Image.Exif()
    tag[274] = 6
    Image.fromarray(np.full((48, 64, 3), 128, np.uint8)).save(tmp_path / "tagged.jpg", exif=tag)
    for extra, told in (([], False), (["--photo-rotation", "90"], True)):
        with pytest.raises(_StopCalibration):
            main(["calibrate", str(tmp_path / "tagged.jpg"), "--capture",
                  str(tmp_path / "c.json"), "-o", str(tmp_path / "o.json"), *extra])
        err = capsys.readouterr().err
        assert ("tagged.jpg: its EXIF orientation tag (6) says" in err) == told, (extra, err)


def test_a_sensor_logger_json_export_serves_as_its_csv(tmp_path, capsys):
    """``--gyro Gyroscope.json`` (Sensor Logger's JSON export, found by its first
    character) gives the PSF its CSV export gives; a JSON file that is not a list of
    samples is one line naming it, exit status 2."""
    t = 1733380029.0 + np.arange(0, 3, 0.005)
    w = np.stack([0.1 + 0.3 * np.sin(5 * t), 0.2 * np.cos(3 * t), 0.05 + 0 * t], axis=1)
    (tmp_path / "Gyroscope.csv").write_text("time,seconds_elapsed,z,y,x\n" + "\n".join(
        f"{int(round(a * 1e9))},{a - t[0]:.3f},{z:.9f},{y:.9f},{x:.9f}"
        for a, (x, y, z) in zip(t, w)) + "\n")
    (tmp_path / "Gyroscope.json").write_text(json.dumps([
        {"sensor": "Gyroscope", "time": str(int(round(a * 1e9))), "seconds_elapsed":
         f"{a - t[0]:.3f}", "z": f"{z:.9f}", "y": f"{y:.9f}", "x": f"{x:.9f}"}
        for a, (x, y, z) in zip(t, w)]))
    doc = {"exposure_start": 1733380030.0, "exposure_time": 0.03, "readout_time": 0.02,
           "camera": {"fx": 300, "width": 320, "height": 240},
           "gyro": {"path": "Gyroscope.csv", "orientation": "android-back-camera"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    for log in ("Gyroscope.csv", "Gyroscope.json"):
        assert main(["psf", "--capture", str(tmp_path / "c.json"), "--gyro",
                     str(tmp_path / log), "--at", "40,200", "-o",
                     str(tmp_path / f"{log}.npy")]) == 0
    csv_psf, json_psf = (np.load(tmp_path / f"Gyroscope.{e}.npy") for e in ("csv", "json"))
    assert csv_psf.shape[0] > 5 and np.array_equal(csv_psf, json_psf)
    (tmp_path / "bad.json").write_text('{"Gyroscope": [{"time": 1}]}')
    msg = _run_error(["psf", "--capture", str(tmp_path / "c.json"), "--gyro",
                      str(tmp_path / "bad.json"), "--at", "40,200", "-o",
                      str(tmp_path / "bad.npy")], capsys)
    assert "bad.json: a JSON log must be a list of samples" in msg and "\n" not in msg


def test_several_photos_are_deblurred_one_after_another_each_as_alone(capture_dir, capsys):
    """``deblur a b -o A -o B`` (or ``-o A,B``) gives each photo what deblurring it alone
    gives, with its own capture (one for all, or one per photo) and its own PSF drawing.
    Counts that do not pair, a file named twice, and an output that exists are refused
    before any photo is written."""
    d = capture_dir
    cap, cap2 = str(d / "cap.json"), str(d / "cap2.json")
    doc = json.loads((d / "cap.json").read_text())
    (d / "cap2.json").write_text(json.dumps(dict(doc, exposure_start=50.5)))
    for capture, name in ((cap, "b1.png"), (cap2, "b2.jpg")):
        assert main(["simulate", str(d / "sharp.jpg"), "--capture", capture,
                     "-o", str(d / name), "--snr-db", "40", "--seed", "1"]) == 0
    photos = [str(d / "b1.png"), str(d / "b2.jpg")]
    for k, capture in enumerate((cap, cap2)):
        assert main(["deblur", photos[k], "--capture", capture, "--grid", "2x2",
                     "-o", str(d / f"alone{k}.png")]) == 0
    capsys.readouterr()
    assert main(["deblur", *photos, "--capture", f"{cap},{cap2}", "--grid", "2x2",
                 "-o", str(d / "both0.png"), "-o", str(d / "both1.png"),
                 "--save-psf", f"{d / 'f0.png'},{d / 'f1.png'}"]) == 0
    out = capsys.readouterr().out
    assert f"{photos[0]} -> {d / 'both0.png'}" in out and f"{photos[1]} -> " in out
    assert "take their exposure start from" not in out
    assert f"{photos[1]}: JPEG: deconvolved for noise" in out       # named among several,
    assert out.index(f"{photos[0]} -> ") < out.index(f"{photos[1]}: JPEG")     # at its turn
    for k in range(2):
        assert np.array_equal(read_photo(d / f"both{k}.png").pixels,
                              read_photo(d / f"alone{k}.png").pixels), k
        assert (d / f"f{k}.png").exists()
    # the two photos differ, so each was deblurred with its own capture
    assert not np.array_equal(read_photo(d / "both0.png").pixels,
                              read_photo(d / "both1.png").pixels)
    # one description for both: the same start, said
    assert main(["deblur", *photos, "--capture", cap, "--grid", "2x2",
                 "-o", f"{d / 'same0.png'},{d / 'same1.png'}"]) == 0
    assert "all 2 photos take their exposure start from" in capsys.readouterr().out
    assert np.array_equal(read_photo(d / "same0.png").pixels,
                          read_photo(d / "alone0.png").pixels)
    (d / "taken.png").write_bytes(b"someone's")
    for outs, said in (([d / "n0.png"], "-o: 1 output for 2 photos: give 2"),
                       ([d / "n0.png", d / "n0.png"], "n0.png: is named twice as an output"),
                       ([d / "n0.png", d / "taken.png"], "taken.png: exists"),
                       ([d / "n0.png", d / "b1.png"], "b1.png: is one of the command's inputs")):
        msg = _run_error(["deblur", *photos, "--capture", cap, "--overwrite" if "inputs" in said
                          else "--quiet", *[v for o in outs for v in ("-o", str(o))]], capsys)
        assert said in msg, msg
    msg = _run_error(["deblur", *photos, "--capture", cap, "-o", str(d / "n0.png"), "-o",
                      str(d / "n1.png"), "--save-psf", str(d / "f.png")], capsys)
    assert "--save-psf: 1 PSF drawing for 2 photos: give 2" in msg
    assert not (d / "n0.png").exists() and (d / "taken.png").read_bytes() == b"someone's"
    # a JPEG's noise level is said at its turn: not for a command a later photo stops
    write_photo(d / "tiny.png", np.full((6, 8, 3), 0.5, np.float32), bit_depth=8)
    assert main(["deblur", photos[1], str(d / "tiny.png"), "--capture", cap, "-o",
                 f"{d / 'n0.png'},{d / 'n1.png'}"]) == 2
    said = capsys.readouterr()
    assert "the image has only 6 rows" in said.err and "JPEG" not in said.out


def test_several_photos_are_all_checked_before_any_work_and_each_named(capture_dir, capsys,
                                                                        monkeypatch):
    """Every photo of ``deblur a b`` is read and checked before the first is deblurred: a
    bad second photo or capture leaves nothing written, an error of the photo itself names
    that photo alone, and an output may be no photo's capture or log. A repeated
    --photo-rotation gives each photo its own; --exposure-start, one start for all, is
    refused. A stop after the first photo says what it wrote."""
    import gyrodeblur.deblur as deblur_mod
    from PIL import Image as PILImage

    d = capture_dir
    cap = str(d / "cap.json")
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "b1.png"),
                 "--seed", "1", "--snr-db", "40"]) == 0
    PILImage.open(d / "b1.png").rotate(180).save(d / "b1_turned.png")
    assert main(["deblur", str(d / "b1_turned.png"), "--capture", cap, "--grid", "2x2",
                 "--photo-rotation", "180", "-o", str(d / "turned_alone.png")]) == 0
    assert main(["deblur", str(d / "b1.png"), str(d / "b1_turned.png"), "--capture", cap,
                 "--grid", "2x2", "--photo-rotation", "0", "--photo-rotation", "180",
                 "-o", str(d / "r0.png"), "-o", str(d / "r1.png")]) == 0
    assert np.array_equal(read_photo(d / "r1.png").pixels,
                          read_photo(d / "turned_alone.png").pixels)
    capsys.readouterr()
    # a tiny second photo, a missing second capture, a second photo's log as an output
    write_photo(d / "tiny.png", np.full((6, 8, 3), 0.5, np.float32), bit_depth=8)
    (d / "glog.json").write_bytes((d / "gyro.gcsv").read_bytes())
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["path"] = "glog.json"
    (d / "cap_glog.json").write_text(json.dumps(doc))
    doc = json.loads((d / "cap.json").read_text())          # a focal length 100x too long
    doc["camera"].update(fx=2e4, fy=2e4)
    (d / "cap_mm.json").write_text(json.dumps(doc))

    def no_work(*args, **kwargs):
        raise AssertionError("deblurred or calibrated before every photo was checked")

    monkeypatch.setattr(deblur_mod, "deblur", no_work)
    monkeypatch.setattr(deblur_mod, "deblur_blind", no_work)
    import gyrodeblur.calibrate
    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", no_work)
    outs = ["-o", str(d / "n0.png"), "-o", str(d / "n1.png")]
    write_photo(d / "small.png", read_photo(d / "b1.png").pixels[:60, :80], bit_depth=8)
    for argv, said in (
            ([str(d / "b1.png"), str(d / "tiny.png"), "--capture", cap],
             f"error: {d / 'tiny.png'}: the image has only 6 rows"),
            ([str(d / "b1.png"), str(d / "b1_turned.png"), "--capture",
              f"{cap},{d / 'missing.json'}"], "missing.json"),
            ([str(d / "b1.png"), str(d / "b1_turned.png"), "--capture",
              f"{cap},{d / 'cap_glog.json'}", "--refine", "--save-capture",
              str(d / "glog.json"), "--overwrite"], "glog.json: is one of the command's inputs"),
            ([str(d / "b1.png"), str(d / "b1_turned.png"), "--capture", cap,
              "--exposure-start", "50.3"], "--exposure-start: would give every photo"),
            ([str(d / "b1.png"), str(d / "b1_turned.png"), "--capture",
              f"{cap},{d / 'cap_mm.json'}"],
             f"cap_mm.json: the PSF centred on its point (its blur reaching"),
            ([str(d / "b1.png"), str(d / "small.png"), "--blind", "--kernel-size", "31"],
             f"--kernel-size: 31 px is too large for a 80x60 image"),
            ([str(d / "b1.png"), str(d / "small.png"), "--blind", "--kernel-size", "19",
              "--grid", "2x2"], "--grid: 4 patches of")):
        msg = _run_error(["deblur", *argv, *outs], capsys)
        assert said in msg and "written before" not in msg, msg
        if "cap_mm" in said:                         # the photo it concerns is named
            assert msg.endswith(f"(for {d / 'b1_turned.png'})"), msg
        if "--blind" in argv:
            assert msg.endswith(f"(for {d / 'small.png'})"), msg
        assert not (d / "n0.png").exists()
    assert (d / "glog.json").read_bytes() == (d / "gyro.gcsv").read_bytes()
    # stopped while deblurring the second: what the first wrote is said
    monkeypatch.undo()
    real, calls = deblur_mod.deblur, []

    def stop_at_the_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(deblur_mod, "deblur", stop_at_the_second)
    assert main(["deblur", str(d / "b1.png"), str(d / "b1_turned.png"), "--capture", cap,
                 "--grid", "2x2", *outs]) == 130
    err = capsys.readouterr().err
    assert f"interrupted; written before it stopped: {d / 'n0.png'}; nothing else" in err
    assert (d / "n0.png").exists() and not (d / "n1.png").exists()


def test_each_capture_value_given_on_the_command_line_fixes_its_parameter():
    """``calibrate`` (and ``deblur --refine``) take a value stated with an option as
    known: ``--time-offset`` fixes the offset, ``--bias`` the bias, ``--readout-time`` the
    readout, ``--fx`` or ``--fy`` the focal length, ``--orientation`` the mapping, on top
    of ``--fix``; parsed by the real parser, so an option whose value went unseen (a
    renamed destination) fails here too."""
    from gyrodeblur.calibrate_cli import fixed_parameters
    from gyrodeblur.cli import build_parser

    base = ["calibrate", "p.png", "--capture", "c.json", "-o", "o.json"]
    parse = build_parser().parse_args
    assert fixed_parameters(parse(base)) == set()
    for option, value, name in (("--time-offset", "0.01", "offset"),
                                ("--bias", "0.01,0,0", "bias"),
                                ("--readout-time", "0.02", "readout"),
                                ("--fx", "1000", "focal"), ("--fy", "1000", "focal"),
                                ("--orientation", "Xyz", "axes")):
        assert fixed_parameters(parse(base + [option, value])) == {name}, option
    both = parse(base + ["--fix", "bias,focal", "--readout-time", "0.02"])
    assert fixed_parameters(both) == {"bias", "focal", "readout"}


def test_a_psf_field_npy_is_the_field_for_the_overlap_given_each_psf_centred(capture_dir):
    """``psf --grid RxC -o F.npy``: the stack holds the PSFs of the field planned with
    the ``--overlap`` given (not the default's), each centred in its K x K slice (a
    smaller PSF padded equally on every side)."""
    from gyrodeblur.capture import load_capture
    from gyrodeblur.deblur import plan_psf_field
    from gyrodeblur.tiling import DEFAULT_OVERLAP

    d = capture_dir
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "--overlap", "0",
                 "-o", str(d / "f.npy")]) == 0
    stack = np.load(d / "f.npy")
    cap = load_capture(d / "cap.json")
    fields = {ov: plan_psf_field(cap, (192, 256), grid=(3, 4), overlap=ov,
                                 max_fraction=np.inf)[1] for ov in (0.0, DEFAULT_OVERLAP)}
    psfs = fields[0.0].psfs
    assert [p.shape for p in psfs] != [p.shape for p in fields[DEFAULT_OVERLAP].psfs]
    assert len({p.shape for p in psfs}) > 1                  # some are padded
    k = stack.shape[1]
    assert stack.shape == (12, k, k) and k == max(p.shape[0] for p in psfs)
    for i, p in enumerate(psfs):
        o = (k - p.shape[0]) // 2
        np.testing.assert_array_equal(stack[i, o:o + p.shape[0], o:o + p.shape[1]], p)
        assert stack[i].sum() == pytest.approx(1.0, abs=1e-5)
    # a .npz keeps each PSF's pixel and the grid beside the same stack
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "--overlap", "0",
                 "-o", str(d / "f.npz")]) == 0
    with np.load(d / "f.npz") as saved:
        np.testing.assert_array_equal(saved["psfs"], stack)
        np.testing.assert_array_equal(saved["centres_xy"], fields[0.0].points)
        assert saved["grid"].tolist() == [3, 4]
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "30,40", "-o",
                 str(d / "p.npz")]) == 0
    with np.load(d / "p.npz") as saved:
        assert saved["psfs"].shape[0] == 1 and saved["centres_xy"].tolist() == [[30, 40]]


def test_psf_takes_one_of_at_and_grid_a_pixel_of_the_frame_and_npy_or_png(capture_dir, capsys):
    """``--at`` and ``--grid`` together (or neither) are refused; ``--at`` must be a pixel
    centre of the frame: x up to width - 1 and y up to height - 1, not the width; the
    output is a .npy, a .npz or a .png, nothing else."""
    d = capture_dir
    base = ["psf", "--capture", str(d / "cap.json"), "-o", str(d / "p.npy")]
    for extra in (["--at", "5,5", "--grid", "2x2"], []):
        assert "give exactly one of --at X,Y or --grid RxC" in _run_error(base + extra, capsys)
    for at in ("256,0", "0,192"):
        assert "is not a pixel of the 256x192 frame" in _run_error(base + ["--at", at], capsys)
    for name in ("p.jpg", "p.npx"):                          # the three formats only
        assert f"{name}: output must end in .npy, .npz or .png" in _run_error(
            ["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "-o", str(d / name)],
            capsys)
    assert not [p for p in d.iterdir() if p.name.startswith("p.")]
    assert main(base + ["--at", "255,191"]) == 0


def test_psf_takes_a_photos_size_and_exif_but_not_its_exif_time(capture_dir, capsys):
    """``psf --photo``: a capture without a camera or an exposure time takes them from the
    photo's EXIF (FocalLengthIn35mmFilm, ExposureTime) and its size, as deblur does; the
    PSF is the one the completed capture renders. The photo's EXIF time is not taken for
    the exposure start, an output may not be the photo, and a photo turned upright is
    refused naming what to give (psf has no --photo-rotation)."""
    from gyrodeblur.capture import load_capture
    from gyrodeblur.psf import render_psf

    d = capture_dir
    doc = json.loads((d / "cap.json").read_text())
    del doc["camera"], doc["exposure_time"]
    (d / "bare.json").write_text(json.dumps(doc))
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    sub[0xA405], sub[0x829A], sub[0x9003] = 28, 0.02, "2024:12:05 07:27:10"
    pixels = (np.random.default_rng(1).random((96, 128, 3)) * 255).astype(np.uint8)
    Image.fromarray(pixels).save(d / "p.jpg", exif=exif.tobytes(), quality=90)
    Image.fromarray(pixels.transpose(1, 0, 2)).save(d / "upright.jpg", exif=exif.tobytes())
    base = ["psf", "--capture", str(d / "bare.json"), "--at", "30,40"]
    assert "no focal length" in _run_error(base + ["-o", str(d / "q.npy")], capsys)
    assert main(base + ["--photo", str(d / "p.jpg"), "-o", str(d / "q.npy")]) == 0
    fx = 28 * np.hypot(128, 96) / np.hypot(36, 24)
    cap = load_capture(d / "bare.json", overrides={"fx": fx, "fy": fx, "cx": 63.5, "cy": 47.5,
                                                   "exposure_time": 0.02},
                       image_size=(128, 96))
    np.testing.assert_allclose(np.load(d / "q.npy"), render_psf(cap, 30, 40), atol=1e-6)
    del doc["exposure_start"]
    (d / "nostart.json").write_text(json.dumps(doc))
    err = _run_error(["psf", "--capture", str(d / "nostart.json"), "--at", "30,40", "--photo",
                      str(d / "p.jpg"), "-o", str(d / "r.npy")], capsys)
    assert err.endswith("missing 'exposure_start' (give --exposure-start: psf does not take "
                        "the photo's EXIF time, known to tens of ms at best)")
    assert not (d / "r.npy").exists()
    Image.fromarray(pixels).save(d / "p.png", exif=exif.tobytes())   # an output's suffix
    before = (d / "p.png").read_bytes()
    err = _run_error(base + ["--photo", str(d / "p.png"), "-o", str(d / "p.png"), "--overwrite"],
                     capsys)
    assert "p.png: is one of the command's inputs" in err
    assert (d / "p.png").read_bytes() == before
    err = _run_error(["psf", "--capture", str(d / "cap.json"), "--at", "30,40", "--photo",
                      str(d / "upright.jpg"), "-o", str(d / "u.png")], capsys)  # 256 x 192
    assert "give the photo as the camera stored it" in err and "--photo-rotation" not in err


def test_a_gcsv_read_bottom_to_top_is_warned_of_unless_the_photo_is_turned(capture_dir,
                                                                          capsys):
    """A gcsv header's frame_readout_direction 1 with a readout time given: warned of (the
    model reads rows top to bottom), except where --photo-rotation turns the photo."""
    d = capture_dir
    g = d / "gyro.gcsv"
    g.write_text(g.read_text().replace("tscale,", "frame_readout_direction,1\ntscale,", 1))
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "-o",
                 str(d / "p.npy")]) == 0
    assert "frame_readout_direction is 1 (bottom to top)" in capsys.readouterr().err
    for turn, warned in (("180", False), ("0", True)):
        assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                     "-o", str(d / f"s{turn}.png"), "--photo-rotation", turn]) == 0
        assert ("frame_readout_direction" in capsys.readouterr().err) == warned, turn
    # read along the rows: turning the photo by 180 degrees does not make its rows run down
    g.write_text(g.read_text().replace("frame_readout_direction,1", "frame_readout_direction,2"))
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "s2.png"), "--photo-rotation", "180"]) == 0
    assert "frame_readout_direction is 2 (along the rows)" in capsys.readouterr().err
    # a pipeline that makes the library's warnings errors gets a one-line error, exit
    # status 3 and nothing written, not a traceback
    import warnings

    from gyrodeblur.errors import GyrodeblurWarning
    with warnings.catch_warnings():
        warnings.simplefilter("error", GyrodeblurWarning)
        assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                     "-o", str(d / "strict.png")]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gyrodeblur: error: ") and err[0].endswith(
        "(a warning made an error by the warnings filter)")
    assert not (d / "strict.png").exists()


def test_the_progress_bar_is_drawn_on_a_terminal_only_and_never_with_quiet(monkeypatch,
                                                                          capsys):
    """A log file gets no carriage-return lines, and ``--quiet`` silences the bar on a
    terminal too."""
    import gyrodeblur.cli as cli

    for terminal, quiet, drawn in ((False, False, False), (True, True, False),
                                   (True, False, True)):
        monkeypatch.setattr(cli, "_is_terminal", lambda stream: terminal)
        bar = cli._Progress("deblurring", quiet)
        bar.t0 -= 5.0                                   # past the one-second wait
        bar(3, 10)
        bar.close()
        assert ("3/10" in capsys.readouterr().err) == drawn, (terminal, quiet)


def _spy_on_deblur(monkeypatch) -> list:
    """A stand-in for the library's ``deblur`` that records its keyword arguments and
    stops the command (:class:`_StopCalibration`)."""
    import gyrodeblur.deblur as deblur_mod

    seen = []

    def spy(image, cap, **kwargs):
        seen.append(kwargs)
        raise _StopCalibration

    monkeypatch.setattr(deblur_mod, "deblur", spy)
    return seen


def test_deblur_options_reach_the_library_and_sparse_limits_are_checked(capture_dir, capsys,
                                                                         monkeypatch):
    """``--overlap`` is handed to the deblur, not dropped; ``--phi`` applies to Wiener only,
    ``--iterations`` is 1-100 and ``--noise-sigma`` under 1, refused before any work."""
    seen = _spy_on_deblur(monkeypatch)
    d = capture_dir
    base = ["deblur", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o",
            str(d / "o.png")]
    with pytest.raises(_StopCalibration):
        main(base + ["--grid", "2x2", "--overlap", "0.1"])
    assert seen[-1]["overlap"] == 0.1
    for extra, said in ((["--phi", "0.01"], "--phi: applies to --method wiener only"),
                        (["--iterations", "101"], "--iterations: must be 1-100, got 101"),
                        (["--noise-sigma", "1"], "--noise-sigma: must be in [0, 1)")):
        assert said in _run_error(base + extra, capsys), extra
    assert len(seen) == 1 and not (d / "o.png").exists()


def test_blind_and_invariant_refuse_the_options_they_would_ignore(capture_dir, capsys):
    """``--blind --mode invariant`` (blind has its own patches) and ``--mode invariant
    --overlap`` (one PSF, no patches) are refused, not ignored; and without
    ``--kernel-size`` blind uses 31 px, said too large for a photo of 60 rows."""
    d = capture_dir
    photo, out = str(d / "sharp.jpg"), str(d / "o.png")
    assert "--mode: does not apply with --blind" in _run_error(
        ["deblur", photo, "--blind", "--mode", "invariant", "-o", out], capsys)
    assert "--overlap: applies to --mode variant only" in _run_error(
        ["deblur", photo, "--capture", str(d / "cap.json"), "--mode", "invariant",
         "--overlap", "0.2", "-o", out], capsys)
    write_photo(d / "small.png", read_photo(d / "sharp.jpg").pixels[:60, :80], bit_depth=8)
    assert "--kernel-size: 31 px is too large for a 80x60 image" in _run_error(
        ["deblur", str(d / "small.png"), "--blind", "-o", out], capsys)
    assert not (d / "o.png").exists()


def test_main_leaves_the_sigterm_handler_as_it_found_it(capture_dir, capsys):
    """A batch script that calls ``main`` keeps its own SIGTERM handling afterwards,
    whether the command succeeded or failed."""
    import signal

    def mine(signum, frame):
        pass

    before = signal.signal(signal.SIGTERM, mine)
    try:
        d = capture_dir
        assert main(["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "-o",
                     str(d / "p.npy")]) == 0
        assert main(["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "-o",
                     str(d / "p.npy")]) == 2
        assert signal.getsignal(signal.SIGTERM) is mine
    finally:
        signal.signal(signal.SIGTERM, before)


def test_simulate_takes_seed_0_and_checks_the_output_format_before_the_work(capture_dir, capsys,
                                                                    monkeypatch):
    """0 is a seed like any other; an output that cannot hold the result (16 bits in a
    JPEG) is refused before the blur is synthesised, not after."""
    import gyrodeblur.simulate as simulate_mod

    d = capture_dir
    base = ["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json")]
    assert main(base + ["--snr-db", "30", "--seed", "0", "-o", str(d / "s.png")]) == 0

    def no_work(*args, **kwargs):
        raise AssertionError("blurred before the output was checked")

    monkeypatch.setattr(simulate_mod, "simulate_blur", no_work)
    assert "x.jpg: JPEG stores 8 bits per sample" in _run_error(
        base + ["-o", str(d / "x.jpg"), "--bit-depth", "16"], capsys)


def test_bias_auto_is_read_from_the_command_line(capture_dir, capsys):
    """``--bias auto`` (the help's own value) takes the bias from the log outside the
    exposure, as ``"bias": "auto"`` in a capture description does; not a parse error."""
    d = capture_dir
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "5,5", "--bias", "auto",
                 "-o", str(d / "p.npy")]) == 0
    assert "gyro bias (auto, median outside the exposure)" in capsys.readouterr().out


def test_a_command_without_a_capture_or_log_says_to_give_one(capture_dir, capsys):
    """Neither ``--capture`` nor ``--gyro``: the message says what is missing (not a
    missing focal length, the first field the empty description lacks)."""
    d = capture_dir
    for argv in (["deblur", str(d / "sharp.jpg"), "-o", str(d / "o.png")],
                 ["psf", "--at", "5,5", "-o", str(d / "p.npy")],
                 ["simulate", str(d / "sharp.jpg"), "-o", str(d / "s.png")]):
        assert "--capture: give a capture description (--capture C.json) or --gyro" in \
            _run_error(argv, capsys), argv


def test_one_photos_psf_drawing_may_not_be_another_photos_output(capture_dir, capsys,
                                                                  monkeypatch):
    """``deblur a b -o A,B --save-psf B,F``: photo a's drawing would be written over by
    photo b's result (or stop the command half-way): refused before any work, as any
    file named twice among the outputs is."""
    import gyrodeblur.deblur as deblur_mod

    def no_work(*args, **kwargs):
        raise AssertionError("deblurred before the outputs were checked")

    monkeypatch.setattr(deblur_mod, "deblur", no_work)
    d = capture_dir
    write_photo(d / "other.png", read_photo(d / "sharp.jpg").pixels * 0.9, bit_depth=8)
    msg = _run_error(["deblur", str(d / "sharp.jpg"), str(d / "other.png"), "--capture",
                      str(d / "cap.json"), "-o", f"{d / 'n0.png'},{d / 'n1.png'}",
                      "--save-psf", f"{d / 'n1.png'},{d / 'f1.png'}", "--overwrite"], capsys)
    assert "n1.png: is named twice as an output" in msg
    assert not any((d / n).exists() for n in ("n0.png", "n1.png", "f1.png"))


def _no_calibration(monkeypatch) -> list:
    """``calibrate`` as the command finds it, replaced by one that returns the captures
    as given (a correction of nothing, at once); returns the list of its calls."""
    from types import SimpleNamespace

    import gyrodeblur.calibrate_cli as calibrate_cli

    calls = []

    def as_given(images, captures, **kwargs):
        calls.append(len(images))
        return SimpleNamespace(seconds=0.0, estimates=None, captures=list(captures),
                               kept_given=False)

    monkeypatch.setattr(calibrate_cli, "calibrate", as_given)
    monkeypatch.setattr(calibrate_cli, "format_estimates", lambda est, *kept: [])
    return calls


def test_calibrate_says_whose_description_one_output_holds(capture_dir, capsys, monkeypatch):
    """Two photos, one ``-o``: the description written is the first photo's, and the
    command says so; one photo says nothing of it. (One description for both is refused
    by ``calibrate`` itself: test_calibrate.py.)"""
    calls = _no_calibration(monkeypatch)
    d = capture_dir
    write_photo(d / "other.png", read_photo(d / "sharp.jpg").pixels * 0.9, bit_depth=8)
    later = json.loads((d / "cap.json").read_text())
    later["exposure_start"] = 50.5
    (d / "later.json").write_text(json.dumps(later))
    base = ["calibrate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json")]
    first, start = "(the first photo's description", "take their exposure start from"
    assert main(["calibrate", str(d / "sharp.jpg"), str(d / "other.png"), "--capture",
                 f"{d / 'cap.json'},{d / 'later.json'}", "-o", str(d / "a.json")]) == 0
    out = capsys.readouterr().out
    assert first in out and start not in out
    assert json.loads((d / "a.json").read_text())["exposure_start"] == 50.3
    assert main(base + ["-o", str(d / "b.json")]) == 0
    out = capsys.readouterr().out
    assert first not in out and start not in out and f"wrote {d / 'b.json'}" in out
    assert calls == [2, 1]


def test_an_output_named_twice_through_another_spelling_or_a_link_is_refused(tmp_path):
    """The same file is the same output however it is spelt: ``sub/../o.json`` or a link
    to it."""
    from gyrodeblur.calibrate_cli import refuse_repeated_outputs
    from gyrodeblur.errors import InputError

    (tmp_path / "sub").mkdir()
    (tmp_path / "link.json").symlink_to(tmp_path / "o.json")
    for other in (tmp_path / "sub" / ".." / "o.json", tmp_path / "link.json"):
        with pytest.raises(InputError, match="is named twice as an output"):
            refuse_repeated_outputs([str(tmp_path / "o.json"), str(other)])
    refuse_repeated_outputs([str(tmp_path / "o.json"), str(tmp_path / "p.json")])


def test_a_corrected_description_written_over_keeps_its_permissions(capture_dir):
    """``save_captures`` over an existing file keeps who may read it (as the other
    outputs do), and leaves no temporary file behind."""
    import os
    import stat

    from gyrodeblur.calibrate_cli import save_captures
    from gyrodeblur.capture import load_capture

    d = capture_dir
    out = d / "o.json"
    out.write_text("{}")
    os.chmod(out, 0o600)
    save_captures([load_capture(d / "cap.json")], [str(out)])
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o600
    assert json.loads(out.read_text())["exposure_start"] == 50.3
    assert not [p for p in d.iterdir() if p.name.endswith((".part", ".tmp"))]


def test_the_estimates_report_gives_each_uncertainty_in_its_unit_or_says_fixed():
    """Each line of ``format_estimates``: before -> after, then the one-sigma uncertainty
    in the parameter's unit (ms for times, none for the focal scale), or "fixed"."""
    from gyrodeblur.calibrate_cli import format_estimates

    est = {"offset": (0.0, 0.0021, 0.0003), "readout": (0.02, 0.021, 0.0005),
           "focal": (1.0, 1.01, 0.002), "bias": (np.zeros(3), np.array([1e-3, 0, 0]),
                                                 np.full(3, 1e-4)),
           "axes": ("XYZ", "XYZ", 30.0)}
    lines = format_estimates(est)
    assert lines[0].endswith("+0.00 ms ->    +2.10 ms  (+- 0.3 ms)")
    assert lines[1].endswith("20.00 ms ->    21.00 ms  (+- 0.5 ms)")
    assert lines[2].endswith("1.0000    ->   1.0100     (+- 0.002)")
    assert lines[3].endswith("rad/s  (+- [0.0001, 0.0001, 0.0001])")
    assert lines[4].endswith("XYZ -> XYZ  (next best mapping: objective +30.0 higher)")
    fixed = {k: (b, a, None) for k, (b, a, _) in est.items()}
    assert all(line.endswith("(fixed)") for line in format_estimates(fixed))
    # a mapping scoring better than the given one kept within its margin is not "the next
    # best" (session 59's audit); kept given values are said to be the given ones
    kept = dict(est, axes=("yxz", "yxz", -2.4))
    lines = format_estimates(kept, kept_given=True, readout_given=False)
    assert lines[4].endswith("(another mapping: objective 2.4 lower, within the given one's "
                             "margin: uncertain)"), lines[4]
    assert lines[5].startswith("  (the given values kept, with the readout that suits them "
                               "(none was given): ") and len(lines) == 6, lines[5]
    assert format_estimates(kept, kept_given=True)[5].startswith(  # a readout given
        "  (the given values kept: the photo preferred no others")
    assert len(format_estimates(est)) == 5


def test_calibrate_tells_each_photo_of_its_own_rotation(capture_dir, capsys, monkeypatch):
    """``--photo-rotation 90,0``: the first portrait export is turned back and fits; the
    second, said not to be turned, is told it looks turned by 90 degrees, not to leave
    out a rotation it was not given (the first photo's)."""
    calls = _no_calibration(monkeypatch)
    d = capture_dir
    sharp = read_photo(d / "sharp.jpg").pixels
    write_photo(d / "p1.png", np.rot90(sharp, -1), bit_depth=8)
    write_photo(d / "p2.png", np.rot90(sharp * 0.9, -1), bit_depth=8)
    msg = _run_error(["calibrate", str(d / "p1.png"), str(d / "p2.png"), "--capture",
                      str(d / "cap.json"), "--photo-rotation", "90,0", "-o",
                      str(d / "o.json")], capsys)
    assert "p2.png" in msg and "turned by 90 degrees" in msg, msg
    assert "leave the option out" not in msg and calls == []


# ------------------------------------------------ from a mutation audit (session 47)

def _demo_that_must_not_start(monkeypatch):
    """The demo with its work replaced by a failure: a refusal must come before it."""
    import gyrodeblur.demo as demo

    def no_work(*args, **kwargs):
        raise AssertionError("the demo started its work")

    monkeypatch.setattr(demo, "simulate_blur", no_work)
    return demo


def test_the_demo_refuses_a_file_or_an_unwritable_place_for_its_folder_before_any_work(
        tmp_path, capsys, monkeypatch):
    """Kills D2 (``--out`` naming a file let through, to fail after the work) and D4 (a
    folder that cannot be made where it is asked for, found only after the work: /sys
    takes no new entries, even from root)."""
    _demo_that_must_not_start(monkeypatch)
    (tmp_path / "afile").write_text("x")
    msg = _run_error(["demo", "--out", str(tmp_path / "afile")], capsys)
    assert msg.endswith("afile: exists and is not a folder"), msg
    assert (tmp_path / "afile").read_text() == "x"
    msg = _run_error(["demo", "--out", "/sys/gyrodeblur-demo"], capsys)
    assert "/sys/gyrodeblur-demo: cannot write in folder /sys" in msg, msg


def test_the_demo_takes_a_dangling_link_in_a_user_s_folder_for_the_user_s(tmp_path, capsys,
                                                                           monkeypatch):
    """Kills D7 (the outputs looked for with ``exists``, which a link to nowhere fails).
    A link of an output's name is the user's, wherever it points: refused unless
    ``--overwrite``, like a file."""
    _demo_that_must_not_start(monkeypatch)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "metrics.json").symlink_to(tmp_path / "not-yet-written.json")
    msg = _run_error(["demo", "--out", str(mine)], capsys)
    assert "already holds metrics.json, not written by the demo" in msg, msg
    assert (mine / "metrics.json").is_symlink()


def test_the_demo_capture_is_the_one_its_docstring_describes():
    """Kills D13 (another focal length). ``demo_capture``: 512 x 512, f = 0.8 x width,
    40 ms exposure, 20 ms readout, and the bundled gyro log."""
    from gyrodeblur.demo import demo_capture

    cap = demo_capture()
    cam = cap.camera
    assert (cam.width, cam.height) == (512, 512)
    assert cam.fx == pytest.approx(0.8 * 512) and cam.fy == pytest.approx(0.8 * 512)
    assert (cap.exposure_time, cap.readout_time) == (0.04, 0.02)
    assert cap.gyro_spec["path"].endswith("demo_gyro.gcsv") and cap.gyro_spec["format"] == "gcsv"


def test_the_wiener_method_says_when_it_raises_its_phi(capture_dir, capsys):
    """``--method wiener`` on a noisy photo says the phi it uses (the photo's own
    noise-to-signal ratio) and writes what the library gives with that phi; ``--phi``
    keeps the value given, silently; a clean photo keeps the chapter's 0.01, silently."""
    from gyrodeblur.wiener import photo_phi
    d = capture_dir
    for snr, name in ((6, "noisy.png"), (45, "clean.png")):
        assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                     "-o", str(d / name), "--snr-db", str(snr), "--seed", "2"]) == 0
    capsys.readouterr()
    phi = photo_phi(read_photo(d / "noisy.png").pixels)
    assert phi > 0.03
    assert main(["deblur", str(d / "noisy.png"), "--capture", str(d / "cap.json"),
                 "--method", "wiener", "-o", str(d / "auto.png")]) == 0
    assert f"Wiener filter: phi {phi:.3g}, this photo's own" in capsys.readouterr().out
    assert main(["deblur", str(d / "noisy.png"), "--capture", str(d / "cap.json"),
                 "--method", "wiener", "--phi", f"{phi!r}", "-o", str(d / "given.png")]) == 0
    assert "Wiener filter: phi" not in capsys.readouterr().out
    assert np.array_equal(read_photo(d / "auto.png").pixels, read_photo(d / "given.png").pixels)
    assert main(["deblur", str(d / "clean.png"), "--capture", str(d / "cap.json"),
                 "--method", "wiener", "-o", str(d / "clean_out.png")]) == 0
    assert "Wiener filter: phi" not in capsys.readouterr().out


def test_simulate_adds_shot_noise_given_a_full_well(capture_dir, capsys):
    """``--full-well N`` adds photon shot noise (with or without ``--snr-db``; ``--seed``
    then applies), said in the summary; a count that is no sensor's is refused."""
    d = capture_dir
    base = ["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "--bit-depth",
            "16"]
    assert main(base + ["-o", str(d / "clean.png")]) == 0
    for name in ("a", "b"):
        assert main(base + ["-o", str(d / f"{name}.png"), "--full-well", "300",
                            "--seed", "7"]) == 0
    assert "shot noise of 300 e- at white" in capsys.readouterr().out
    clean, a, b = (read_photo(d / f"{n}.png").pixels for n in ("clean", "a", "b"))
    assert np.array_equal(a, b) and 0.005 < np.std(a - clean) < 0.05
    for bad in ("0", "nan"):
        assert "--full-well: must be 1 to 1e9 electrons" in _run_error(
            base + ["-o", str(d / "x.png"), "--full-well", bad], capsys)


def test_the_readmes_python_api_example_runs_on_a_short_description(capture_dir, capsys):
    """README's "The same as a Python API" block, run as written (file names aside) on a
    JPEG whose EXIF gives the exposure time and the focal length, with a description that
    leaves both out: it reads them from the EXIF, as the command line does, and deblurs."""
    import re
    from pathlib import Path

    from gyrodeblur.metrics import psnr

    d = capture_dir
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"),
                 "-o", str(d / "b.png"), "--snr-db", "40", "--seed", "1"]) == 0
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    sub[0x829A], sub[0xA405] = IFDRational(3, 100), 27      # 30 ms; 27 mm: fx 199.7 px
    Image.open(d / "b.png").save(d / "photo.jpg", exif=exif.tobytes(), quality=95)
    doc = json.loads((d / "cap.json").read_text())
    del doc["exposure_time"], doc["camera"]
    (d / "short.json").write_text(json.dumps(doc))
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    code = re.search(r"The same as a Python API:\n\n```python\n(.*?)```", readme, re.S)[1]
    for name, path in (("photo.jpg", "photo.jpg"), ("capture.json", "short.json"),
                       ("sharp.jpg", "out.jpg")):
        assert f'"{name}"' in code
        code = code.replace(f'"{name}"', repr(str(d / path)))
    capsys.readouterr()
    exec(compile(code, "README.md", "exec"), {})
    said = capsys.readouterr().out
    assert "exposure_time = 0.03 s (from EXIF)" in said and "fx = 199.7 px" in said
    sharp = read_photo(d / "sharp.jpg").pixels
    gain = (psnr(read_photo(d / "out.jpg").pixels, sharp, border=16)
            - psnr(read_photo(d / "photo.jpg").pixels, sharp, border=16))
    assert gain > 3, gain


def test_a_home_folder_is_expanded_in_every_file_option(capture_dir, capsys, monkeypatch):
    """``~`` in ``--capture=~/...`` and ``-o=~/...`` (which the shell leaves alone) is the
    home folder, as in a capture's ``gyro.path`` and ``--gyro``: before, the capture was
    "not found" and the output's folder taken for one named ``~``."""
    d = capture_dir
    monkeypatch.setenv("HOME", str(d))
    monkeypatch.chdir(d / "..")
    assert main(["simulate", "--capture=~/cap.json", "~/sharp.jpg", "--output=~/b.png"]) == 0
    assert main(["deblur", "~/b.png", "--capture=~/cap.json", "--output=~/out.png",
                 "--method", "wiener", "--save-psf=~/psf.png"]) == 0
    assert (d / "out.png").is_file() and (d / "psf.png").is_file()
    assert not (d / ".." / "~").exists()
    assert "deblurred" in capsys.readouterr().out
    # in a list of several photos' files, with spaces after the commas
    assert main(["deblur", "~/b.png", "~/b.png", "--capture=~/cap.json, ~/cap.json",
                 "-o", "~/o1.png, ~/o2.png", "--method", "wiener", "--quiet"]) == 0
    assert (d / "o1.png").is_file() and (d / "o2.png").is_file()


def test_an_option_of_one_value_given_twice_is_refused(capture_dir, capsys):
    """``--fx 300 --fx 3000`` had deblurred with 3000 without a word (argparse keeps the
    last), while ``-o`` given twice for one photo is refused: now each names the option.
    A flag given twice, and a value after ``--``, are left alone."""
    d = capture_dir
    base = ["deblur", str(d / "sharp.jpg"), "--capture", str(d / "cap.json"), "-o",
            str(d / "o.png"), "--method", "wiener"]
    for twice in (["--fx", "300", "--fx", "3000"], ["--orientation", "XYZ", "--orientation=yxz"],
                  ["--time-offset", "-0.001", "--time-offset=0"]):
        assert f"{twice[0]}: given twice: give it once" in _run_error(base + twice, capsys)
    # as argparse also reads them: abbreviated, or short with the value attached
    for twice, named in ((["--exposure-t", "0.01", "--exposure-time", "0.02"], "--exposure-time"),
                         (["--exposure-time", "0.01", "--exposure-t=0.02"], "--exposure-t")):
        assert f"{named}: given twice: give it once" in _run_error(base + twice, capsys)
    psf = ["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(d / "p.npy")]
    assert "-o: given twice: give it once" in _run_error(psf + ["-o" + str(d / "q.npy")], capsys)
    assert not (d / "p.npy").exists() and not (d / "q.npy").exists()
    assert not (d / "o.png").exists()
    assert main(base + ["--overwrite", "--overwrite", "--quiet"]) == 0
