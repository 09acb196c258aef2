"""Every benchmark runs in its --quick mode and writes sane JSON, so the code cannot rot.

The full runs are not part of the test suite (see BENCHMARKS.md). The calibration runs
that ask only about the calibration deblur their photos with the Wiener filter
(``--method wiener``): the default method's three deblurs per photo cost 11 s at 512 px,
a third of such a test's time, and test_compare_methods_quick runs every method.
"""

import importlib.util
import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_DATA

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _need_shared():
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_noise_sensitivity_quick(tmp_path):
    _need_shared()
    out = tmp_path / "noise.json"
    assert _load("noise_sensitivity").main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert r["psnr_exact_gyro"] > r["psnr_blurred"] + 3
    assert math.isfinite(r["psnr_drop_at_typical_noise_db"])
    assert 0 < r["psnr_drop_at_typical_noise_db"] < 0.5        # session 38: 0.07 dB
    b = r["panels"]["bias"]                                  # 0.05 rad/s: 29.37 -> 24.27 dB
    assert b["levels"] == [0.0, 0.05]
    assert b["psnr"][1]["mean"] < b["psnr"][0]["mean"] - 2
    g = r["panels"]["gyro_noise"]
    assert g["levels"] == [0.0, 0.007] and g["psnr"][1]["n"] == 2
    assert set(r["panels"]) == {"gyro_noise", "bias", "time_offset", "readout", "focal"}
    for name in ("time_offset", "readout", "focal"):
        p = r["panels"][name]
        assert len(p["psnr_plus"]) == len(p["psnr_minus"]) == len(p["levels"])
        assert p["psnr_plus"][0] == pytest.approx(r["psnr_exact_gyro"])
        # a large calibration error hurts
        assert min(p["psnr_plus"][-1], p["psnr_minus"][-1]) < r["psnr_exact_gyro"]
    assert r["border_px"] > 0 and r["method"]


def test_blind_levin_without_its_kernels_is_a_clear_error(tmp_path, capsys):
    """A --data folder without kernels/levin2009.npz: one line naming the file, exit 2 as
    for the other benchmarks' bad inputs (not "give --data" when it was given)."""
    mod = _load("blind_levin")
    (tmp_path / "photos").mkdir()
    assert _load("_common").run_main(mod.main, ["--data", str(tmp_path), "--out",
                                                str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err
    assert "levin2009.npz: the Levin kernels are not there" in err and "--data" not in err
    assert not (tmp_path / "b.json").exists()


def test_blind_levin_quick(tmp_path):
    """The Levin-protocol benchmark: the true kernel through the default method restores
    far better than the blurred input, a blind estimate lands in between on average, and
    the report's pieces are written."""
    _need_shared()
    mod = _load("blind_levin")
    k = mod.levin_kernels(SHARED_DATA / "kernels" / "levin2009.npz")["levin_4"]
    yy, xx = np.indices(k.shape)
    c = k.shape[0] // 2
    assert k.shape[0] % 2 == 1 and abs(k.sum() - 1) < 1e-5
    assert abs((yy * k).sum() - c) <= 0.5 and abs((xx * k).sum() - c) <= 0.5
    out = tmp_path / "levin.json"
    assert mod.main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    m = r["summary"]["mean"]
    assert len(r["per_case"]) == 8 and out.with_suffix(".png").stat().st_size > 5_000
    assert m["psnr_oracle"] > m["psnr_blurred"] + 5
    # (20.66 dB against the input's 17.75, kernel similarity 0.71, at session 38's code; a
    # delta scores 0.48 against these kernels, a photo-blind round Gaussian passed the
    # looser bounds these replace)
    assert m["psnr_blurred"] + 1.5 < m["psnr_blind"] < m["psnr_oracle"]
    assert m["kernel_similarity"] > 0.62           # the estimates resemble the kernels
    # the blind checks against no blur pass every true kernel (the photo shows its blur,
    # and it sharpens the photo) and most estimates
    assert r["summary"]["check"]["true_kernels_kept"] == 8
    assert r["summary"]["check"]["kept"] >= 6
    assert all(c["true_sparsity_ratio"] < 0.9 for c in r["per_case"])
    assert "The checks against no blur" in out.with_suffix(".md").read_text()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_compare_methods_quick(tmp_path):
    _need_shared()
    out = tmp_path / "compare.json"
    mod = _load("compare_methods")
    assert mod.main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    table = r["table"]
    for name in mod.BASE:
        assert name in table
    from gyrodeblur.deblur import METHODS
    # every registered method takes part ("wiener" as wiener-variant/-invariant)
    assert {"wiener-variant" if n == "wiener" else n for n in METHODS} <= set(table)
    assert r["dataset"]["cases"] == 2 and len(r["per_case"]) == 2
    for name, row in table.items():
        assert row["errors"] == 0, (name, r["per_case"])
        assert 5 < row["psnr_mean"] < 60 and 0 < row["ssim_mean"] <= 1
        assert 5 < row["psnr_field_mean"] < 60
        if name != "blurred":
            assert row["seconds_per_mp"] > 0
    assert table["wiener-variant"]["psnr_mean"] > table["blurred"]["psnr_mean"] + 3
    # the gyro methods deblur (session 38: blurred 19.30, wiener-variant 33.92, wiener-aligned
    # 34.38, sparse 36.80, sparse-patches 36.33 dB), the default best of all by a margin
    for name in ("wiener-variant", "wiener-aligned", "sparse", "sparse-patches"):
        assert table[name]["psnr_mean"] > table["blurred"]["psnr_mean"] + 5, name
    assert table["sparse"]["psnr_mean"] > table["wiener-variant"]["psnr_mean"] + 1
    md = out.with_suffix(".md").read_text()
    assert "| wiener-variant |" in md and "| skimage-rl |" in md


def test_compare_methods_registry_plugs_in_new_methods(monkeypatch):
    from gyrodeblur import deblur as deblur_mod

    mod = _load("compare_methods")
    monkeypatch.setitem(deblur_mod.METHODS, "dummy", deblur_mod.METHODS["wiener"])
    reg = mod.registry()
    assert "dummy" in reg
    assert "dummy@invariant" in mod.resolve(["dummy@invariant"])
    with pytest.raises(SystemExit):
        mod.resolve(["no-such-method"])


def test_speed_quick(tmp_path):
    out = tmp_path / "speed.json"
    assert _load("speed").main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["sizes_mp"] == [0.25, 1]
    assert len(r["runs"]) == 4            # 2 sizes x 2 modes, the default method
    for run in r["runs"]:
        assert run["status"] == "ok", run
        assert run["seconds"] > 0 and run["floor_s"] > 0
        assert run["ratio_to_floor"] == pytest.approx(run["seconds"] / run["floor_s"])
        assert run["peak_rss_mib"] > run["image_mib"]
        assert run["width"] * 3 == run["height"] * 4
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert "| 1 | 1152x864 |" in out.with_suffix(".md").read_text()


def test_calibration_coverage_counts_errors_within_the_stated_sigmas():
    """Errors of 0.5, 1.5 and 3 sigmas: one within 1 sd, two within 2; a fixed parameter
    (no stated figure) is skipped, and the bias counts per axis."""
    cal = _load("calibration")
    rows = [{"offset_error_ms": e, "readout_error_ms": 0.0, "focal_error_pct": 0.0,
             "bias_error": [e * 0.01, 0.0, -0.03],
             "stated_sd": {"offset_ms": 1.0, "readout_ms": None, "focal_pct": 2.0,
                           "bias": [0.01, 0.01, 0.01]}} for e in (0.5, -1.5, 3.0)]
    cov = cal.coverage(rows)
    assert cov["offset_ms"] == {"n": 3, "within_1sd": 1, "within_2sd": 2, "median_z": 1.5}
    assert cov["readout_ms"] == {"n": 0}
    assert cov["focal_pct"]["within_1sd"] == 3
    assert cov["bias"]["n"] == 9 and cov["bias"]["within_1sd"] == 4 and cov["bias"]["within_2sd"] == 5
    est = {"offset": (0.0, 0.001, 0.0005), "readout": (0.03, 0.03, None),
           "focal": (1.0, 1.02, 0.01), "bias": (np.zeros(3), np.zeros(3), np.array([0.01, np.nan, 0.01]))}
    sd = cal.stated_sd(est)
    assert sd["offset_ms"] == pytest.approx(0.5) and sd["readout_ms"] is None
    assert sd["focal_pct"] == pytest.approx(1.0) and sd["bias"] is None


def test_calibration_readout_unknown_leaves_the_readout_out(capsys):
    """--readout-unknown: the corrupted capture has readout 0 marked unknown (the other
    errors as drawn), its results file its own name; with --no-errors it is refused."""
    from conftest import constant_rate_capture
    cal = _load("calibration")
    cap = constant_rate_capture((0.0, 0.6, 0.0), width=160, height=120, f=300.0,
                                readout=0.02)
    errors = cal.draw_errors(cap, np.random.default_rng(0))
    bad = cal.corrupt(cap, dict(errors, readout_factor=0.0, readout_unknown=True))
    assert bad.readout_time == 0.0 and bad.readout_time_unknown
    assert bad.time_offset == pytest.approx(errors["offset_ms"] * 1e-3)
    assert not cal.corrupt(cap, errors).readout_time_unknown
    assert cal.parse_args(["--readout-unknown"]).out.name == "calibration_readout_unknown.json"
    with pytest.raises(SystemExit):
        cal.parse_args(["--readout-unknown", "--no-errors"])
    assert "--readout-unknown leaves out the readout" in capsys.readouterr().err


def test_an_injected_offset_that_leaves_the_log_is_moved_back_inside():
    """--offset-range with a short log: an offset that would carry an exposure out of its
    log (no capture could be made, and the run stopped after its first case) is moved
    towards 0 until every session photo's exposure, its readout as corrupted, is 1 ms
    inside; one that fits is left as drawn."""
    from types import SimpleNamespace

    from conftest import constant_rate_capture
    cal = _load("calibration")
    cap = constant_rate_capture((0.0, 0.6, 0.0), width=160, height=120, f=300.0,
                                readout=0.02)
    t, (w0, w1) = cap.log.t, cap.log_window
    case = SimpleNamespace(capture=cap)
    errors = {"offset_ms": 0.0, "readout_factor": 1.3}
    assert cal.offset_inside_logs([case], errors) == 0.0
    late = (w0 - t[0]) * 1e3                       # the exposure would start before the log
    got = cal.offset_inside_logs([case], dict(errors, offset_ms=late + 500.0))
    assert got == pytest.approx(late - 1.0)
    early = (w1 + 0.3 * 0.02 - t[-1]) * 1e3        # ... or end after it (readout x 1.3)
    got = cal.offset_inside_logs([case], dict(errors, offset_ms=early - 500.0))
    assert got == pytest.approx(early + 1.0)
    bad = cal.corrupt(cap, dict(cal.draw_errors(cap, np.random.default_rng(0)),
                                offset_ms=got, readout_factor=1.3))
    assert bad.log_window[1] <= t[-1] - 0.999e-3


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_calibration_sessions_quick(tmp_path):
    """Two photos of one session share the injected errors and are calibrated together."""
    _need_shared()
    out = tmp_path / "cal.json"
    assert _load("calibration").main(["--quick", "--sessions", "--method", "wiener",
                                      "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    rows = r["cases"]
    assert r["mode"] == "sessions" and r["summary"]["sessions"] == 1 and len(rows) == 2
    assert rows[0]["injected"] == rows[1]["injected"]
    assert rows[0]["seconds"] == rows[1]["seconds"]          # one calibration for both
    for row in rows:
        assert row["axes_correct"], row["estimates"]
        assert abs(row["offset_error_ms"]) < 3, row["estimates"]
        assert row["psnr_calibrated"] > row["psnr_corrupted"] + 5


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_calibration_of_true_captures_with_long_logs_quick(tmp_path):
    """--no-errors calibrates a true capture; --log-seconds 10 gives it 10 s of the
    source trace either side, which calibrate reads (the typical-rate note) and which
    bears its bias out: the capture stays (nearly) where it was."""
    _need_shared()
    out = tmp_path / "cal.json"
    assert _load("calibration").main(["--quick", "--cases", "1", "--no-errors",
                                      "--log-seconds", "10", "--method", "wiener",
                                      "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["no_errors"] and r["log_seconds"] == 10 and len(r["cases"]) == 1
    for row in r["cases"]:
        assert row["injected"]["offset_ms"] == 0 and row["injected"]["bias"] == [0, 0, 0]
        assert any("typical rate over" in note for note in row["notes"]), row["notes"]
        assert row["axes_correct"] and abs(row["offset_error_ms"]) < 1, row["estimates"]
        assert np.max(np.abs(row["bias_error"])) < 0.01, row["bias_error"]


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_calibration_burst_quick(tmp_path):
    """--burst calibrates a photo with its next frame: one session, the photo's own
    injected errors for both, and the two frames registered to each other."""
    _need_shared()
    out = tmp_path / "cal.json"
    assert _load("calibration").main(["--quick", "--burst", "--cases", "1",
                                      "--method", "wiener", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    first, nxt = r["cases"]
    assert r["mode"] == "bursts" and r["summary"]["sessions"] == 1
    assert nxt["case"] == first["case"] + "_next"
    # the errors injected are the single-photo run's for this case (a paired comparison)
    import _common
    case = _common.get_cases(windows_per_photo=1, max_size=512, max_photos=1)[0]
    single = _load("calibration").draw_errors(case.capture, np.random.default_rng([0, 6, 0]))
    assert first["injected"]["axes"] == single["axes"]
    assert first["injected"]["offset_ms"] == pytest.approx(single["offset_ms"])
    assert first["injected"]["bias"] == pytest.approx(single["bias"])
    assert any("registration chi2" in note for note in first["notes"]), first["notes"]
    assert first["axes_correct"] and abs(first["offset_error_ms"]) < 3, first["estimates"]
    # the next frame's own blur is reported, not the first frame's
    from gyrodeblur.dataset import shake_stats
    assert nxt["blur_px"] == shake_stats(case.capture.replace(
        exposure_start=case.capture.exposure_start + max(1 / 30, case.capture.exposure_time
                                                          + 0.001)))["blur_px"]


def _texture_8bit(seed: int, shape=(120, 160)) -> np.ndarray:
    """A smooth random texture in [0.1, 0.9] on 8-bit levels (float32): a sharp photo."""
    from scipy import ndimage

    t = ndimage.gaussian_filter(np.random.default_rng(seed).random(shape), 2.0)
    return (np.round(255 * (0.1 + 0.8 * (t - t.min()) / np.ptp(t))) / 255).astype(np.float32)


def test_burst_partner_is_the_scene_seen_one_frame_later():
    """A camera yawing right at 0.6 rad/s turns 0.02 rad in 1/30 s: the next frame's sharp
    image is the scene moved by -f tan(0.02) = -6.0 px in x (f = 300 px), and it is blurred
    from a capture that starts 1/30 s later."""
    from conftest import constant_rate_capture
    from gyrodeblur.dataset import render_case
    from gyrodeblur.frame_registration import phase_shift

    cal = _load("calibration")
    sharp = _texture_8bit(seed=3)
    cap = constant_rate_capture((0.0, 0.6, 0.0), width=160, height=120, f=300.0,
                                exposure=0.01)
    case = render_case("toy_w0", sharp, cap, {"noise_seed": 1},
                       snr_db=None)
    nxt = cal.burst_partner(case)
    assert nxt.name == "toy_w0_next" and nxt.meta["burst_of"] == "toy_w0"
    assert nxt.capture.exposure_start == pytest.approx(cap.exposure_start + 1 / 30)
    d, _ = phase_shift(case.sharp, nxt.sharp)
    assert d == pytest.approx([-300 * np.tan(0.02), 0.0], abs=0.15)
    # the next frame's blur is its own capture's: a 0.006 rad streak, 1.8 px, along x
    d_blur, _ = phase_shift(nxt.sharp, nxt.blurred)
    assert d_blur[0] == pytest.approx(-0.9, abs=0.3) and abs(d_blur[1]) < 0.2


def test_burst_partner_is_referenced_to_the_next_frames_first_row():
    """With a rolling shutter and a yaw rate ramping up (0.3 rad/s + 30 rad/s^2 t), the
    next frame's reference is its first row's start, 1/30 s after this frame's: the camera
    turned 0.3/30 + 30/(2 * 30^2) = 0.0267 rad in between (a reference at the middle row,
    10 ms of readout later, would add 0.01 rad: 3 px more)."""
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.dataset import render_case
    from gyrodeblur.frame_registration import phase_shift
    from gyrodeblur.gyrolog import GyroLog

    cal = _load("calibration")
    sharp = _texture_8bit(seed=5)
    t = np.arange(0.0, 0.2, 1 / 400)
    start = 0.05
    w = np.zeros((t.size, 3))
    w[:, 1] = 0.3 + 30.0 * (t - start)
    cap = Capture(start, 0.01, 0.02, Camera.centred(160, 120, 300.0), GyroLog(t, w))
    case = render_case("ramp_w0", sharp, cap, {"noise_seed": 1},
                       snr_db=None)
    d, _ = phase_shift(case.sharp, cal.burst_partner(case).sharp)
    turn = 0.3 / 30 + 30.0 / (2 * 30 ** 2)
    assert d == pytest.approx([-300 * np.tan(turn), 0.0], abs=0.3)


def test_field_registered_psnr_forgives_a_smooth_warp_but_not_blur():
    """A sharp texture sheared like a rolling shutter (each row moved by up to 3 px, a
    bent line) scores low as it is, high after the field registration; a blurred copy,
    warped the same, stays low: the registration undoes geometry, not blur."""
    from scipy import ndimage

    from gyrodeblur.metrics import psnr

    common = _load("_common")
    rng = np.random.default_rng(3)
    tex = ndimage.gaussian_filter(rng.normal(size=(384, 512)), 1.2)
    sharp = np.clip(0.5 + 0.15 * tex / tex.std(), 0, 1).astype(np.float32)
    rows = np.arange(384, dtype=float)[:, None]
    shear = 3.0 * (rows / 383) ** 2 + np.zeros((1, 512))           # px along x, per row
    yy, xx = np.mgrid[0:384, 0:512].astype(float)

    def warp(img):
        return ndimage.map_coordinates(img, [yy, xx - shear], order=3, mode="reflect")

    warped = warp(sharp)
    blurred = warp(ndimage.uniform_filter1d(sharp, 5, axis=1))
    b = 16
    box = ndimage.uniform_filter1d(sharp, 5, axis=1)
    assert psnr(sharp, warped, b) < 22
    assert common.field_registered_psnr(sharp, warped, b) > 35
    assert common.field_registered_psnr(sharp, blurred, b) < psnr(sharp, box, b) + 0.5


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_calibration_runs_on_other_photos_and_another_gyro_log(tmp_path):
    """--photos and --gyro build the cases from the user's folder and shake log (here a
    bundled photo and a synthetic 20 s hand shake written as gcsv): the report names the
    folder's photo, and a log that does not exist is an error, not the shared log."""
    from PIL import Image
    from skimage import data

    from gyrodeblur.gyrolog import GyroLog, write_gcsv

    photos = tmp_path / "photos"
    photos.mkdir()
    Image.fromarray(data.astronaut()).save(photos / "astro.png")
    t = np.arange(0.0, 20.0, 1 / 200)
    rng = np.random.default_rng(2)
    freqs = rng.uniform(2.0, 9.0, (3, 4))
    phases = rng.uniform(0, 2 * np.pi, (3, 4))
    w = np.stack([0.25 * np.sin(2 * np.pi * freqs[a][:, None] * t + phases[a][:, None]).sum(0)
                  for a in range(3)], axis=1)
    write_gcsv(tmp_path / "shake.gcsv", GyroLog(t, w))
    out = tmp_path / "cal.json"
    args = ["--photos", str(photos), "--cases", "1", "--windows", "1", "--max-size", "320",
            "--out", str(out)]
    cal = _load("calibration")
    from gyrodeblur.errors import InputError

    with pytest.raises(InputError, match="missing.gcsv"):
        cal.main(args[:-2] + ["--gyro", str(tmp_path / "missing.gcsv"), "--out", str(out)])
    assert cal.main(args + ["--gyro", str(tmp_path / "shake.gcsv")]) == 0
    row, = json.loads(out.read_text())["cases"]
    assert row["case"] == "astro_w0" and row["blur_px"] > 2
    assert row["axes_correct"] and abs(row["offset_error_ms"]) < 3, row["estimates"]


def test_attribute_gap_calibrates_with_one_parameter_known_and_with_one_unknown(monkeypatch):
    """--attribute's wiring, with calibrate and the deblurring stubbed: for each parameter,
    one calibration from the corrupted captures with that parameter set right and fixed,
    and one with all the others set right and fixed; the gaps are the stub PSNRs minus the
    true capture's, per photo of the session."""
    from types import SimpleNamespace

    from conftest import constant_rate_capture
    from gyrodeblur.axes import parse_axes

    cal = _load("calibration")
    true = [constant_rate_capture((0.1, 0.2, 0.0)), constant_rate_capture((0.0, 0.3, 0.1))]
    bad = [c.replace(time_offset=0.01, bias=np.array([0.02, 0.0, 0.0]), readout_time=0.02,
                     camera=c.camera.with_focal_scale(1.1), axes=parse_axes("YXz"))
           for c in true]
    seen = []

    def fake_calibrate(images, caps, *, fix, n_patches=None):
        seen.append((set(fix), caps))
        return SimpleNamespace(captures=caps)

    monkeypatch.setattr(cal, "calibrate", fake_calibrate)
    monkeypatch.setattr(cal, "deblur", lambda img, cap, method=None: cap)
    monkeypatch.setattr(cal, "psnr", lambda sharp, cap, border: 30.0 + 100 * cap.time_offset)
    cases = [SimpleNamespace(blurred=np.zeros((8, 8)), sharp=np.zeros((240, 320)), capture=c)
             for c in true]
    rows = [{"psnr_true": 30.0}, {"psnr_true": 30.0}]
    cal.attribute_gap(cases, bad, rows)
    assert len(seen) == 10
    for fix, caps in seen:
        for cap, t, b in zip(caps, true, bad):
            for name, field in cal.PARAMETER_FIELDS.items():
                want = t if name in fix else b
                assert np.all(np.asarray(getattr(cap, field) == getattr(want, field))), (fix, name)
    assert {frozenset(f) for f, _ in seen[:5]} == {frozenset([n]) for n in cal.PARAMETER_FIELDS}
    for row in rows:        # the offset is wrong (+10 ms: +1 dB here) unless known
        assert row["gap_if_known_db"] == pytest.approx(
            {"offset": 0.0, "bias": 1.0, "readout": 1.0, "focal": 1.0, "axes": 1.0})
        assert row["gap_if_only_db"] == pytest.approx(
            {"offset": 1.0, "bias": 0.0, "readout": 0.0, "focal": 0.0, "axes": 0.0})
        assert row["errors_if_only"]["offset"] == {"offset_error_ms": pytest.approx(10.0)}


def test_jpeg_noise_quick(tmp_path):
    """A JPEG deconvolved for its compression error as well as the noise its pixels show
    beats the measured level alone; a PNG is left as it was."""
    _need_shared()
    out = tmp_path / "jpeg.json"
    assert _load("jpeg_noise").main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [row["fitted_on"] for row in r["rows"]] == [True, False]
    for row in r["rows"]:
        png, jpg = row["variants"]["png"], row["variants"]["q90"]
        assert png["sigma_raised"] == png["sigma_measured"]
        assert jpg["sigma_raised"] > jpg["sigma_measured"]
        assert jpg["psnr_raised"] > jpg["psnr_measured"] + 0.2
    assert set(r["summary"]) == {"png_fitted_on", "png_held_out", "q90_fitted_on", "q90_held_out"}


# ----------------------------------------------------------------------------- on tiny inputs
# (no shared data: a few small photos and a synthetic hand-shake log, seconds in all)

def _run(mod_name: str, argv: list[str]) -> int:
    """A benchmark's main as its command line runs it (_common.run_main: an InputError is
    one line on stderr, exit status 2)."""
    common = _load("_common")
    return common.run_main(_load(mod_name).main, argv)


def _one_line_error(capsys, *needles) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """``photos/`` (two PNGs and a JPEG of 160 x 120 px, and a text file), ``jpegs/`` (two
    JPEGs), ``empty/``, and ``shake.gcsv``: 12 s of synthetic hand shake at 200 Hz."""
    from PIL import Image

    from gyrodeblur.gyrolog import GyroLog, write_gcsv

    root = tmp_path_factory.mktemp("tiny")
    for sub in ("photos", "jpegs", "empty"):
        (root / sub).mkdir()
    for i, (sub, name) in enumerate([("photos", "a.png"), ("photos", "b.png"),
                                     ("photos", "c.jpg"), ("jpegs", "p.jpg"),
                                     ("jpegs", "q.jpeg")]):
        pix = np.round(255 * _texture_8bit(10 + i, (120, 160))).astype(np.uint8)
        Image.fromarray(np.stack([pix, pix[::-1], pix[:, ::-1]], -1)).save(
            root / sub / name, **({"quality": 95} if name.endswith(("jpg", "jpeg")) else {}))
    (root / "photos" / "notes.txt").write_text("not a photo")
    t = np.arange(0.0, 12.0, 1 / 200)
    rng = np.random.default_rng(4)
    freqs, phases = rng.uniform(2.0, 9.0, (3, 4)), rng.uniform(0, 2 * np.pi, (3, 4))
    w = np.stack([0.25 * np.sin(2 * np.pi * freqs[a][:, None] * t + phases[a][:, None]).sum(0)
                  for a in range(3)], axis=1)
    write_gcsv(root / "shake.gcsv", GyroLog(t, w))
    return root


def _tiny_dataset(tiny, folder, **options):
    from gyrodeblur.dataset import build_dataset

    opts = dict(photos=tiny / "photos", gyro=tiny / "shake.gcsv", max_size=64,
                windows_per_photo=1)
    build_dataset(folder, **{**opts, **options})
    return folder


def test_run_main_turns_an_input_error_into_one_line_and_status_2(capsys):
    from gyrodeblur.errors import InputError

    common = _load("_common")

    def bad(argv):
        raise InputError("x.csv", "no samples")

    assert common.run_main(bad, []) == 2
    assert _one_line_error(capsys) == "error: x.csv: no samples"
    assert common.run_main(lambda argv: {"summary": 1}, []) == 0    # a main returning a dict
    assert common.run_main(lambda argv: 3, []) == 3


def test_scripts_run_as_commands_print_input_errors_as_one_line(tiny):
    """The scripts' __main__ goes through run_main: no traceback, exit status 2."""
    import subprocess

    for script, args in (("wiener_oracle", ["--dataset", str(tiny / "empty")]),
                         ("compare_methods", ["--photos", str(tiny / "empty"), "--methods",
                                              "blurred"])):
        out = subprocess.run([sys.executable, str(BENCH / f"{script}.py"), *args,
                              "--out", str(tiny / "never.json")],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 2, (script, out.stderr)
        err = out.stderr.strip()
        assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
        assert not (tiny / "never.json").exists()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_jpeg_noise_reads_any_photo_folder_and_refuses_an_empty_one(tiny, tmp_path, capsys):
    """--quick on a folder without the shared photos takes its first two (JPEGs too: the
    dataset builder's list_photos); a folder without photos is a one-line error."""
    mod = _load("jpeg_noise")
    assert [p.name for p in mod.quick_photos([Path(f"{n}.png") for n in
                                              ("a", "lai_people_01", "lai_saturated_02", "z")])
            ] == ["lai_people_01.png", "lai_saturated_02.png"]
    assert [p.name for p in mod.quick_photos([Path(n) for n in ("a.jpg", "b.png", "c.tif")])
            ] == ["a.jpg", "b.png"]
    out = tmp_path / "jpeg.json"
    assert _run("jpeg_noise", ["--quick", "--photos", str(tiny / "jpegs"), "--gyro",
                               str(tiny / "shake.gcsv"), "--max-size", "64",
                               "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [row["photo"] for row in r["rows"]] == ["p", "q"] and r["max_size"] == 64
    assert _run("jpeg_noise", ["--photos", str(tiny / "empty"), "--out", str(out)]) == 2
    _one_line_error(capsys, "no photos")


def test_single_photo_benchmarks_pick_the_default_a_stem_or_the_first_photo(tiny, tmp_path,
                                                                            capsys):
    common = _load("_common")
    photos = tiny / "photos"
    assert common.pick_photo(None, photos, "lai_manmade_01.png") == photos / "a.png"
    assert common.pick_photo(None, photos, "b.png") == photos / "b.png"
    assert common.pick_photo("c", photos) == photos / "c.jpg"            # a stem
    assert common.pick_photo("b.png", photos) == photos / "b.png"
    assert common.pick_photo(str(tiny / "jpegs" / "p.jpg"), photos) == tiny / "jpegs" / "p.jpg"
    from gyrodeblur.errors import InputError

    with pytest.raises(InputError, match="nosuch"):
        common.pick_photo("nosuch", photos)
    with pytest.raises(InputError, match="no photos"):
        common.pick_photo(None, tiny / "empty")
    # the scripts: a case from the folder's first photo; bad names are one-line errors
    ns = _load("noise_sensitivity")
    args = ns.argparse.Namespace(photo=None, photos=str(photos), gyro=str(tiny / "shake.gcsv"),
                                 max_size=64, seed=0, exposure=0.03, readout=0.03, focal=0.8,
                                 windows_considered=1, snr=40.0)
    assert ns.pick_case(args).meta["photo"] == "a.png"
    case = _load("refine_noise").pick_case("c", 64, 1, 0, photos=str(photos),
                                           gyro=str(tiny / "shake.gcsv"))
    assert case.meta["photo"] == "c.jpg"
    for script in ("noise_sensitivity", "refine_noise"):
        assert _run(script, ["--quick", "--photos", str(photos), "--photo", "nosuch",
                             "--out", str(tmp_path / "x.json")]) == 2
        _one_line_error(capsys, "nosuch")
        assert _run(script, ["--quick", "--photos", str(tiny / "empty"),
                             "--out", str(tmp_path / "x.json")]) == 2
        _one_line_error(capsys, "no photos")


def test_compare_methods_records_the_options_the_stored_cases_were_built_with(
        tiny, tmp_path, monkeypatch, capsys):
    """--dataset on a folder built with other options: a warning, the stored cases, and
    the JSON and markdown say how those were built (here 20 dB noise, 64 px, 1 window);
    the same folder asked for by a relative path is no difference."""
    ds = _tiny_dataset(tiny, tmp_path / "ds", snr_db=20.0, max_photos=1)
    out = tmp_path / "compare.json"
    with pytest.warns(UserWarning, match="other options"):
        assert _run("compare_methods", [
            "--dataset", str(ds), "--photos", str(tiny / "jpegs"), "--windows", "2",
            "--max-size", "48", "--methods", "blurred", "--out", str(out)]) == 0
    d = json.loads(out.read_text())["dataset"]
    assert d["photos"] == os.path.abspath(tiny / "photos")
    assert d["windows_per_photo"] == 1 and d["max_size"] == 64 and d["max_photos"] == 1
    assert d["snr_db"] == 20.0 and d["cases"] == 1 and d["from_folder"] == str(ds)
    assert out.with_suffix(".md").read_text().startswith(
        "1 cases (photos x shake windows, 20 dB noise, 8-bit)")
    monkeypatch.chdir(tiny)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        cases, used = _load("_common").get_cases_and_options(
            dataset=str(ds), photos="photos", gyro="shake.gcsv", max_size=64,
            windows_per_photo=1, max_photos=1)
    assert len(cases) == 1 and used["snr_db"] == 20.0
    # the markdown of a dataset without noise does not claim 40 dB
    assert "no added noise" in _load("compare_methods").markdown_table(
        {"dataset": {"cases": 1, "snr_db": None}, "table": {}})


def test_count_options_are_honoured_and_zero_is_refused(tiny, tmp_path, capsys):
    """--quick changes the defaults only: explicit --windows / --max-photos are kept
    (compare_methods and calibration), and a count of 0 is an argparse error."""
    out = tmp_path / "compare.json"
    assert _run("compare_methods", [
        "--quick", "--photos", str(tiny / "photos"), "--gyro", str(tiny / "shake.gcsv"),
        "--windows", "2", "--max-photos", "1", "--max-size", "48", "--methods", "blurred",
        "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [c["case"] for c in r["per_case"]] == ["a_w0", "a_w1"]
    assert r["dataset"]["windows_per_photo"] == 2 and r["dataset"]["max_size"] == 48
    cm = _load("compare_methods")
    for option in ("--windows", "--max-photos", "--max-size"):
        with pytest.raises(SystemExit) as exc:
            cm.main(["--quick", option, "0", "--methods", "blurred", "--out", str(out)])
        assert exc.value.code == 2
        assert "must be at least 1" in capsys.readouterr().err
    cal = _load("calibration")
    assert cal.parse_args(["--quick", "--windows", "3"]).windows == 3
    assert cal.parse_args(["--quick", "--sessions", "--windows", "1"]).windows == 1
    a = cal.parse_args(["--quick"])
    assert (a.windows, a.cases, a.max_size) == (1, 2, 512)
    assert cal.parse_args(["--quick", "--sessions"]).windows == 2
    assert cal.parse_args([]).windows == 2
    with pytest.raises(SystemExit):
        cal.parse_args(["--quick", "--windows", "0"])
    ns = _load("noise_sensitivity")
    with pytest.raises(SystemExit):
        ns.main(["--quick", "--realisations", "0"])


def test_wiener_oracle_scores_the_indexed_cases_only(tiny, tmp_path, capsys):
    """A folder rebuilt with fewer photos, a stale case folder left in it and a folder of
    other things: only the cases dataset.json lists are scored; an empty or missing
    folder is a one-line error."""
    import shutil

    ds = _tiny_dataset(tiny, tmp_path / "ds", max_size=None, max_photos=1)   # 6 x 8 patches
    shutil.copytree(ds / "a_w0", ds / "old_w0")            # stale: not in the index
    (ds / "results").mkdir()                               # not a case at all
    out = tmp_path / "oracle.json"
    assert _run("wiener_oracle", ["--dataset", str(ds), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [row["case"] for row in r["per_case"]] == ["a_w0"] and r["summary"]["cases"] == 1
    (tmp_path / "empty").mkdir()
    for folder in (tmp_path / "empty", tmp_path / "missing"):
        assert _run("wiener_oracle", ["--dataset", str(folder), "--out", str(out)]) == 2
        _one_line_error(capsys, str(folder))


def test_calibration_long_logs_find_the_stored_log_and_refuse_one_that_does_not_cover(
        tiny, tmp_path, monkeypatch):
    """--log-seconds' source trace: a relative path stored in dataset.json (a dataset
    built before paths were stored absolute) is found beside the dataset first, then in
    the current folder; a log that does not cover the exposures is an error, not nothing
    added."""
    import shutil

    from gyrodeblur.errors import InputError
    from gyrodeblur.gyrolog import GyroLog, write_gcsv

    cal = _load("calibration")
    ds = _tiny_dataset(tiny, tmp_path / "ds", max_size=48, max_photos=1)
    index = json.loads((ds / "dataset.json").read_text())
    assert cal.dataset_gyro(ds) == tiny / "shake.gcsv"                   # stored absolute
    index["options"]["gyro"] = "shake.gcsv"
    (ds / "dataset.json").write_text(json.dumps(index))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    with pytest.raises(InputError, match="shake.gcsv"):
        cal.dataset_gyro(ds)                                              # nowhere
    t = np.arange(100.0, 102.0, 1 / 200)          # another log, of 2 s, under that name
    write_gcsv(elsewhere / "shake.gcsv", GyroLog(t, np.zeros((t.size, 3))))
    assert cal.dataset_gyro(ds) == Path("shake.gcsv")                     # the current folder
    cases = _load("_common").load_cases(ds)
    with pytest.raises(InputError, match="does not cover"):
        cal.with_long_logs(cases, 5.0, cal.dataset_gyro(ds))
    shutil.copy(tiny / "shake.gcsv", ds / "shake.gcsv")
    assert cal.dataset_gyro(ds) == ds / "shake.gcsv"                      # beside it first
    long, = cal.with_long_logs(cases, 5.0, cal.dataset_gyro(ds))
    t0, t1 = cases[0].capture.window
    assert long.capture.log.t[0] == 0.0 and long.capture.log.t[-1] > t1 + 4.9   # 5 s more
    assert set(cases[0].capture.log.t) <= set(long.capture.log.t)          # the excerpt kept


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_calibration_with_clocks_known_only_roughly_quick(tmp_path):
    """--offset-range 0.25: the usual injected offset scaled from +-30 ms to +-0.25 s (the
    other errors as drawn; here -44 ms, beyond the default +-40 ms search), searched over
    +-0.26 s with 0.85 s of log on each side, and found again; the option's bad values and
    conflicts are argparse errors. (0.25 s rather than 0.3: a shorter test, still beyond.)"""
    _need_shared()
    cal = _load("calibration")
    out = tmp_path / "cal.json"
    assert cal.main(["--quick", "--cases", "1", "--offset-range", "0.25", "--method", "wiener",
                     "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["offset_range"] == 0.25 and r["log_seconds"] == pytest.approx(0.85)
    import _common
    case = _common.get_cases(windows_per_photo=1, max_size=512, max_photos=1)[0]
    usual = cal.draw_errors(case.capture, np.random.default_rng([0, 6, 0]))
    row = r["cases"][0]
    assert row["injected"]["offset_ms"] == pytest.approx(usual["offset_ms"] * 0.25 / 0.03)
    assert row["injected"]["bias"] == usual["bias"] and row["injected"]["axes"] == usual["axes"]
    assert abs(row["injected"]["offset_ms"]) > 40            # beyond the default search
    assert abs(row["offset_error_ms"]) < 3, row["estimates"]
    for bad in (["--offset-range", "0"], ["--offset-range", "3"],
                ["--offset-range", "0.1", "--no-errors"], ["--offset-range", "0.1", "--attribute"]):
        with pytest.raises(SystemExit):
            cal.parse_args(["--quick"] + bad)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_gyro_rate_quick(tmp_path):
    """A log at half its rate (105 Hz) deblurs nearly as well as the full one: the motion
    between samples is interpolated, not held (held, the same cases lost 1.1 dB); a
    quarter of the rate (52 Hz, below the shake's bandwidth) loses more."""
    _need_shared()
    out = tmp_path / "rate.json"
    assert _load("gyro_rate").main(["--quick", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    s = r["summary"]
    assert len(r["cases"]) == 3 and set(s) == {"full", "pick 2", "pick 4", "mean 2", "mean 4"}
    assert s["full"]["mean_loss_db"] == 0.0
    assert s["pick 2"]["rate_hz"] == pytest.approx(s["full"]["rate_hz"] / 2)
    assert -0.5 < s["pick 2"]["mean_loss_db"] < 0.1
    assert s["pick 4"]["mean_loss_db"] < s["pick 2"]["mean_loss_db"]
