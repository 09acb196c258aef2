"""The command line: happy paths, metadata pass-through, and one-line errors with exit 2."""

import json

import numpy as np
import pytest
from PIL import Image, ImageCms

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
    assert "mode variant 3x4" in out and "PSF extent" in out
    src, res = read_photo(d / "sharp.jpg"), read_photo(d / "out.jpg")
    assert res.icc_profile == src.icc_profile and res.exif is not None
    assert Image.open(d / "out.jpg").getexif()[0x010F] == "TestCam"
    assert res.pixels.shape == src.pixels.shape
    assert (d / "field.png").exists()


def test_psf_commands(capture_dir):
    d = capture_dir
    assert main(["psf", "--capture", str(d / "cap.json"), "--at", "10,20", "-o", str(d / "p.npy")]) == 0
    p = np.load(d / "p.npy")
    assert p.shape[0] % 2 == 1 and abs(p.sum() - 1) < 1e-5
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "-o", str(d / "f.png")]) == 0
    assert main(["psf", "--capture", str(d / "cap.json"), "--grid", "3x4", "-o", str(d / "f.npy")]) == 0
    assert np.load(d / "f.npy").shape[0] == 12


def _run_error(argv, capsys):
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("gyrodeblur: error: ")
    return err[0]


def test_bad_inputs_exit_2_and_write_nothing(capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    (d / "notimage.jpg").write_text("hello")
    write_photo(d / "square.png", np.zeros((100, 100, 3), np.float32))
    before = sorted(p.name for p in d.iterdir())
    assert "notimage.jpg" in _run_error(["deblur", str(d / "notimage.jpg"), "--capture", cap,
                                         "-o", str(d / "o.png")], capsys)
    assert "aspect ratio" in _run_error(["deblur", str(d / "square.png"), "--capture", cap,
                                         "-o", str(d / "o.png")], capsys)
    assert "does not exist" in _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                                           "-o", str(d / "missing" / "o.png")], capsys)
    msg = _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap, "--exposure-start", "70",
                      "-o", str(d / "o.png")], capsys)
    assert "gyro.gcsv" in msg and "covers" in msg
    assert "exists" in _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                                   "-o", str(d / "square.png")], capsys)
    assert "input photo" in _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap,
                                        "-o", str(d / "sharp.jpg"), "--overwrite"], capsys)
    assert "--grid" in _run_error(["deblur", str(d / "sharp.jpg"), "--capture", cap, "--grid", "0x3",
                                   "-o", str(d / "o.png")], capsys)
    assert sorted(p.name for p in d.iterdir()) == before


@pytest.mark.parametrize("content,match", [
    ("t_s,x,y,z\n50,0,0,0\n50.01,0,0,0\n50.005,0,0,0\n", "not increasing"),
    ("t_s,x,y,z\n50,0,0,0\n50.5,nan,0,0\n51,0,0,0\n", "NaN"),
    ("t_s,x,y,z\n50,0,0,0\n50.1,0,0,0\n50.6,0,0,0\n51,0,0,0\n", "gap"),
    ("t_s,x,y,z\n50.31,0,0,0\n50.32,0,0,0\n", "covers"),
    ("t_s,x,y,z\n50,90,90,90\n50.5,90,90,90\n51,90,90,90\n", "deg/s"),
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
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["format"] = "bag"
    (d / "cap.json").write_text(json.dumps(doc))
    assert "unknown gyro log format" in _run_error(["psf", "--capture", str(d / "cap.json"),
                                                    "--at", "5,5", "-o", str(d / "p.npy")], capsys)


def test_blind_deblur_needs_no_gyro(capture_dir, capsys):
    d = capture_dir
    assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9",
                 "-o", str(d / "blind.png"), "--quiet"]) == 0
    assert "mode blind" in capsys.readouterr().out
    assert read_photo(d / "blind.png").pixels.shape == (192, 256, 3)
    assert "--kernel-size" in _run_error(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size",
                                          "8", "-o", str(d / "b2.png")], capsys)
    assert main(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size", "9", "--grid",
                 "1x2", "-o", str(d / "blind2.png"), "--quiet"]) == 0
    assert "mode blind 1x2" in capsys.readouterr().out
    for grid, problem in (("auto", "with --blind give RxC"), ("6x6", "too small for a 21 px")):
        assert problem in _run_error(["deblur", str(d / "sharp.jpg"), "--blind", "--kernel-size",
                                      "21", "--grid", grid, "-o", str(d / "b3.png")], capsys)


def test_sparse_options_change_the_result_and_are_checked(capture_dir, capsys):
    d = capture_dir
    cap = str(d / "cap.json")
    assert main(["simulate", str(d / "sharp.jpg"), "--capture", cap, "-o", str(d / "b.png"),
                 "--snr-db", "40", "--seed", "1"]) == 0
    for name, extra in (("i2.png", ["--iterations", "2"]), ("i6.png", ["--iterations", "6"]),
                        ("n.png", ["--noise-sigma", "0.05"]), ("default.png", [])):
        assert main(["deblur", str(d / "b.png"), "--capture", cap, "-o", str(d / name), "--quiet",
                     *extra]) == 0
    px = {n: read_photo(d / n).pixels for n in ("i2.png", "i6.png", "n.png", "default.png")}
    np.testing.assert_array_equal(px["i6.png"], px["default.png"])  # 6 is the default
    assert np.abs(px["i2.png"] - px["i6.png"]).mean() > 1e-3
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
    assert sorted(p.name for p in d.iterdir()) == before
