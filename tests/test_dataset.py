"""Benchmark dataset builder: determinism, layout on disk, CLI-compatible captures, gaps."""

import json

import numpy as np
import pytest

from conftest import SHARED_DATA
from gyrodeblur.capture import load_capture
from gyrodeblur.dataset import (Case, build_cases, build_dataset, draw_window, find_gaps,
                                load_case, load_dataset, write_case)
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog, check_coverage, read_gyro_log

SMALL = dict(max_photos=2, windows_per_photo=2, max_size=128, seed=3)
GYRO = SHARED_DATA / "gyro" / "handheld_phone_210hz.csv"
FILES = {"blurred.png", "sharp.png", "gyro.gcsv", "capture.json", "case.json"}


def _need_shared():
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")


@pytest.fixture(scope="module")
def cases():
    _need_shared()
    return build_cases(**SMALL)


@pytest.fixture(scope="module")
def on_disk(tmp_path_factory):
    _need_shared()
    out = tmp_path_factory.mktemp("dataset")
    build_dataset(out, **SMALL)
    return out


def test_deterministic_for_a_seed(cases):
    again = build_cases(**SMALL)
    assert [c.name for c in again] == [c.name for c in cases]
    for a, b in zip(cases, again):
        assert np.array_equal(a.blurred, b.blurred)
        assert np.array_equal(a.sharp, b.sharp)
        assert a.meta == b.meta
    other = build_cases(**{**SMALL, "seed": 4, "max_photos": 1})
    assert other[0].meta["window_start"] != cases[0].meta["window_start"]
    assert not np.array_equal(other[0].blurred, cases[0].blurred)


def test_case_does_not_depend_on_the_other_photos(cases):
    """Each case draws from its own generator: fewer photos, same first cases."""
    first = build_cases(**{**SMALL, "max_photos": 1})
    assert [c.name for c in first] == [c.name for c in cases[:2]]
    assert np.array_equal(first[1].blurred, cases[1].blurred)


def test_cases_are_sane(cases):
    assert len(cases) == 4
    assert len({c.name for c in cases}) == 4
    assert len({c.meta["window_start"] for c in cases}) == 4       # each its own shake
    for c in cases:
        assert isinstance(c, Case)
        h, w = c.sharp.shape[:2]
        assert max(h, w) == 128 and c.sharp.shape == c.blurred.shape
        assert c.blurred.dtype == np.float32
        assert np.array_equal(np.round(c.blurred * 255) / 255, c.blurred)   # 8-bit levels
        assert 0.010 <= c.capture.exposure_time <= 0.040
        assert c.capture.readout_time == 0.03
        assert c.capture.camera.fx == pytest.approx(0.8 * w)
        assert c.meta["roll_deg"] >= 0 and c.meta["rotation_deg"] >= c.meta["roll_deg"] - 1e-9
        assert c.meta["blur_px"] >= 1
        # the blur actually changes the photo
        assert np.abs(c.blurred - c.sharp).mean() > 0.005


def test_fixed_exposure_and_options():
    _need_shared()
    (c,) = build_cases(max_photos=1, windows_per_photo=1, max_size=64, exposure=0.02,
                       readout=0.0, focal=1.2, snr_db=None, seed=0)
    assert c.capture.exposure_time == 0.02 and c.capture.readout_time == 0.0
    assert c.capture.camera.fx == pytest.approx(1.2 * 64)
    assert c.meta["snr_db"] is None


def test_layout_on_disk(on_disk, cases):
    index = json.loads((on_disk / "dataset.json").read_text())
    assert index["cases"] == [c.name for c in cases]
    assert index["made_with"]["gyrodeblur"]             # the defaults' paths, resolved:
    assert None not in index["made_with"].values()      # the record of what was used
    for c in cases:
        folder = on_disk / c.name
        assert {p.name for p in folder.iterdir()} == FILES
        spec = json.loads((folder / "capture.json").read_text())
        assert spec["gyro"]["path"] == "gyro.gcsv"          # relative, travels with the folder
        assert spec["gyro"]["format"] == "gcsv"


def test_load_case_equals_the_in_memory_case(on_disk, cases):
    loaded = load_dataset(on_disk)
    for a, b in zip(cases, loaded):
        assert a.name == b.name
        assert np.array_equal(a.sharp, b.sharp) and np.array_equal(a.blurred, b.blurred)
        assert np.array_equal(a.capture.log.t, b.capture.log.t)
        assert np.array_equal(a.capture.log.omega, b.capture.log.omega)
        assert np.array_equal(a.capture.axes, b.capture.axes)
        assert a.capture.camera == b.capture.camera
        for k in ("exposure_start", "exposure_time", "readout_time", "time_offset"):
            assert getattr(a.capture, k) == getattr(b.capture, k)
        assert b.meta["photo"] == a.meta["photo"]


def test_capture_json_works_like_a_users_capture(on_disk, tmp_path):
    from gyrodeblur.cli import main
    from gyrodeblur.imageio import read_photo
    from gyrodeblur.metrics import psnr

    folder = on_disk / sorted(p.name for p in on_disk.iterdir() if p.is_dir())[0]
    cap = load_capture(folder / "capture.json")
    t0, t1 = cap.window
    check_coverage(cap.log, t0 - cap.time_offset, t1 - cap.time_offset)
    assert cap.log.t[0] <= t0 - 0.29 and cap.log.t[-1] >= t1 + 0.29   # +-0.3 s excerpt
    out = tmp_path / "out.png"
    rc = main(["deblur", str(folder / "blurred.png"), "--capture", str(folder / "capture.json"),
               "-o", str(out), "--quiet"])
    assert rc == 0 and out.exists()
    sharp = read_photo(folder / "sharp.png").pixels
    blurred = read_photo(folder / "blurred.png").pixels
    restored = read_photo(out).pixels
    assert psnr(sharp, restored, 6) > psnr(sharp, blurred, 6) + 3


def test_write_case_roundtrip_single(cases, tmp_path):
    write_case(cases[0], tmp_path / "one")
    back = load_case(tmp_path / "one")
    assert back.name == cases[0].name and np.array_equal(back.blurred, cases[0].blurred)


def test_a_case_without_its_sharp_photo_is_written_and_read_back_without_one(cases, tmp_path):
    """A case read from a folder without ``sharp.png`` writes without one; a ``sharp.png``
    left from another case is removed with ``overwrite`` (else the folder would read back
    with that case's ground truth) and refused without it."""
    write_case(cases[0], tmp_path / "a")
    (tmp_path / "a" / "sharp.png").unlink()
    bare = load_case(tmp_path / "a")
    assert bare.sharp is None
    write_case(cases[1], tmp_path / "b")
    with pytest.raises(InputError, match="sharp.png"):
        write_case(bare, tmp_path / "b", overwrite=False)
    assert (tmp_path / "b" / "sharp.png").exists()
    write_case(bare, tmp_path / "b")
    back = load_case(tmp_path / "b")
    assert back.sharp is None and back.name == cases[0].name
    assert np.array_equal(back.blurred, cases[0].blurred)


def test_shared_log_gap_is_found_and_avoided(cases):
    log = read_gyro_log(GYRO)
    gaps = find_gaps(log)
    assert len(gaps) == 1
    gap_t0, gap_t1 = log.t[gaps[0]], log.t[gaps[0] + 1]
    assert 0.02 < gap_t1 - gap_t0 < 0.03
    for c in cases:
        exc = c.capture.log
        assert len(find_gaps(exc)) == 0
        assert exc.t[-1] < gap_t0 or exc.t[0] > gap_t1
    # many draws: none touches the gap
    rng = np.random.default_rng(0)
    for _ in range(300):
        s = draw_window(log, 0.07, rng, margin=0.3, gaps=gaps)
        assert s + 0.07 + 0.3 <= gap_t0 or s - 0.3 >= gap_t1


def test_draw_window_avoids_gaps_in_a_small_log():
    """A synthetic log that is mostly gap: every draw lands in the one clean stretch."""
    t = np.concatenate([np.arange(0, 1.0, 0.005), [1.2], np.arange(1.3, 2.0, 0.005)])
    t = np.unique(t)
    log = GyroLog(t, np.full((t.size, 3), 0.1))
    gaps = find_gaps(log)
    assert len(gaps) == 2
    rng = np.random.default_rng(1)
    for _ in range(200):
        s = draw_window(log, 0.05, rng, margin=0.1)
        assert (s - 0.1 >= 0 and s + 0.15 <= log.t[gaps[0]]) or s - 0.1 >= 1.3
    with pytest.raises(InputError, match="gap-free"):
        draw_window(log, 0.5, np.random.default_rng(0), margin=0.4, tries=50)
    with pytest.raises(InputError, match="too short"):
        draw_window(log, 5.0, np.random.default_rng(0))


def test_missing_photo_folder_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="photo folder not found"):
        build_cases(photos=tmp_path / "nope", gyro=GyroLog([0, 1], np.zeros((2, 3))))
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no photos"):
        build_cases(photos=tmp_path / "empty", gyro=GyroLog([0, 1], np.zeros((2, 3))))


def test_any_folder_and_log(tmp_path):
    """A user's own folder of photos and their own gcsv log work too (no shared data)."""
    from skimage import data

    from gyrodeblur.gyrolog import write_gcsv
    from gyrodeblur.imageio import write_photo
    from gyrodeblur.shake import synthetic_hand_shake

    (tmp_path / "photos").mkdir()
    write_photo(tmp_path / "photos" / "astro.png", data.astronaut()[::8, ::8] / 255.0)
    write_gcsv(tmp_path / "shake.gcsv", synthetic_hand_shake(2.0, seed=1))
    cs = build_cases(photos=tmp_path / "photos", gyro=tmp_path / "shake.gcsv",
                     windows_per_photo=2, orientation="XYZ", seed=0)
    assert [c.name for c in cs] == ["astro_w0", "astro_w1"]
    assert cs[0].sharp.shape == (64, 64, 3)
    build_dataset(tmp_path / "ds", photos=tmp_path / "photos", gyro=tmp_path / "shake.gcsv",
                  windows_per_photo=1, orientation="XYZ")
    assert load_capture(tmp_path / "ds" / "astro_w0" / "capture.json").camera.width == 64


def test_command_line(tmp_path, capsys):
    _need_shared()
    from gyrodeblur.dataset import main

    assert main([str(tmp_path / "ds"), "--max-size", "48", "--max-photos", "1",
                 "--windows", "1", "--exposure", "0.02", "--seed", "5"]) == 0
    assert "wrote 1 cases" in capsys.readouterr().out
    (case,) = load_dataset(tmp_path / "ds")
    assert case.capture.exposure_time == 0.02 and case.meta["seed"] == 5
    assert main([str(tmp_path / "ds2"), "--photos", str(tmp_path / "nowhere")]) == 2


def test_a_jittery_log_with_single_dropped_samples_has_no_gap():
    """Phones' logs jitter (here steps of 0.65-1.35 median, some 1.75) and drop single
    samples (2 steps): no gap, so their windows can be drawn; a run of missing samples is
    still one."""
    rng = np.random.default_rng(4)
    dt = 0.005 * (1 + rng.uniform(-0.35, 0.35, 4000))
    dt[100::50] = 0.00875                        # steps of 1.75
    t = np.cumsum(dt)
    keep = np.ones(t.size, bool)
    keep[300::97] = False                        # single samples dropped: steps of 2
    t = t[keep]
    log = GyroLog(t, np.zeros((t.size, 3)))
    assert len(find_gaps(log)) == 0
    draw_window(log, 0.04, np.random.default_rng(0))
    holed = GyroLog(np.delete(t, np.arange(2000, 2004)), np.zeros((t.size - 4, 3)))
    assert len(find_gaps(holed)) == 1


def test_photos_of_one_name_stem_are_refused_and_hidden_files_skipped(tmp_path):
    from skimage import data

    from gyrodeblur.dataset import list_photos
    from gyrodeblur.imageio import write_photo
    (tmp_path / "p").mkdir()
    small = data.astronaut()[::8, ::8] / 255.0
    write_photo(tmp_path / "p" / "x.png", small)
    (tmp_path / "p" / "._x.png").write_bytes(b"\0\5\26\7 AppleDouble")
    assert [p.name for p in list_photos(tmp_path / "p")] == ["x.png"]
    write_photo(tmp_path / "p" / "x.jpg", small)
    with pytest.raises(InputError, match="x.png: has the name stem of x.jpg"):
        list_photos(tmp_path / "p")
    with pytest.raises(InputError, match="name stem"):
        build_cases(photos=[tmp_path / "p" / "x.jpg", tmp_path / "p" / "x.png"],
                    gyro=GyroLog([0, 1], np.zeros((2, 3))))


def test_a_rebuild_replaces_the_dataset_and_records_absolute_paths(tmp_path, monkeypatch):
    """Built again into its folder with fewer cases, the former cases are removed (not
    other files); dataset.json's photo and gyro paths are absolute, so a benchmark run
    from another folder finds them."""
    from skimage import data

    from gyrodeblur.gyrolog import write_gcsv
    from gyrodeblur.imageio import write_photo
    from gyrodeblur.shake import synthetic_hand_shake
    (tmp_path / "photos").mkdir()
    for name in ("a", "b"):
        write_photo(tmp_path / "photos" / f"{name}.png", data.astronaut()[::8, ::8] / 255.0)
    write_gcsv(tmp_path / "shake.gcsv", synthetic_hand_shake(2.0, seed=1))
    monkeypatch.chdir(tmp_path)
    opts = dict(photos="photos", gyro="shake.gcsv", orientation="XYZ")
    build_dataset("ds", windows_per_photo=2, **opts)
    (tmp_path / "ds" / "notes.txt").write_text("mine")
    build_dataset("ds", windows_per_photo=1, max_photos=1, **opts)
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == [
        "a_w0", "dataset.json", "notes.txt"]
    index = json.loads((tmp_path / "ds" / "dataset.json").read_text())
    assert index["options"]["gyro"] == str(tmp_path / "shake.gcsv")
    assert index["options"]["photos"] == str(tmp_path / "photos")
    from gyrodeblur import __version__
    made_with = index["made_with"]
    commit = made_with.pop("commit", "0" * 40)        # where the source is a git checkout
    assert len(commit) == 40 and int(commit, 16) >= 0
    assert made_with == {"gyrodeblur": __version__, "gyro": str(tmp_path / "shake.gcsv"),
                         "photos": str(tmp_path / "photos")}
    assert [c.name for c in load_dataset(tmp_path / "ds")] == ["a_w0"]


def test_command_line_takes_the_log_s_axes(tmp_path, capsys):
    from skimage import data

    from gyrodeblur.dataset import main
    from gyrodeblur.gyrolog import write_gcsv
    from gyrodeblur.imageio import write_photo
    from gyrodeblur.shake import synthetic_hand_shake
    (tmp_path / "photos").mkdir()
    write_photo(tmp_path / "photos" / "a.png", data.astronaut()[::8, ::8] / 255.0)
    write_gcsv(tmp_path / "shake.gcsv", synthetic_hand_shake(2.0, seed=1))
    base = [str(tmp_path / "ds"), "--photos", str(tmp_path / "photos"), "--gyro",
            str(tmp_path / "shake.gcsv"), "--windows", "1"]
    assert main(base + ["--orientation", "XYZ"]) == 0
    same = load_dataset(tmp_path / "ds")[0].capture.axes
    assert main(base + ["--orientation", "YxZ"]) == 0
    turned = load_dataset(tmp_path / "ds")[0].capture.axes
    np.testing.assert_array_equal(same, np.eye(3))
    assert not np.array_equal(turned, same)
    assert main(base + ["--orientation", "XXZ"]) == 2
    assert "error:" in capsys.readouterr().err


def test_planning_options_that_are_not_times_or_sizes_are_named(tmp_path):
    from gyrodeblur.dataset import plan_window, read_sharp
    from gyrodeblur.imageio import write_photo
    t = np.arange(0.0, 3.0, 0.005)
    log = GyroLog(t, np.tile([0.1, 0.3, 0.05], (t.size, 1)))
    for kw, what in (({"readout": -1.0}, "readout must be"), ({"margin": np.nan}, "margin must be"),
                     ({"focal": 0.0}, "focal must be")):
        with pytest.raises(InputError, match=what):
            plan_window(log, "x", 0, 200, 150, **kw)
    cap, meta = plan_window(log, "x", 0, 200, 150)
    assert meta["readout_time"] == pytest.approx(cap.readout_time)
    path = tmp_path / "sharp.png"
    write_photo(path, np.full((20, 30, 3), 0.5, np.float32))
    for bad in (0, -5, 1, 2.5):
        with pytest.raises(InputError, match="max_size must be"):
            read_sharp(path, bad)
    assert read_sharp(path, 10).shape == (7, 10, 3)


def test_shake_stats_measure_roll_about_the_optical_axis_and_the_windows_rate():
    """Physics: a camera turning at a constant rate about its optical axis (z) rolls by
    ``rate x window`` (all of its rotation is roll); turning about x it does not roll. The
    mean rate is taken over the exposure window only (here a rate growing with time)."""
    from conftest import constant_rate_capture
    from gyrodeblur.dataset import shake_stats

    for axis, roll in ((2, True), (0, False)):
        rate = np.zeros(3)
        rate[axis] = 1.5
        cap = constant_rate_capture(rate, exposure=0.03, readout=0.02)
        t0, t1 = cap.window
        st = shake_stats(cap)
        want = np.degrees(1.5 * (t1 - t0))
        assert st["rotation_deg"] == pytest.approx(want, rel=1e-3)
        assert st["roll_deg"] == pytest.approx(want if roll else 0.0, rel=1e-3, abs=1e-6)
        assert st["mean_rate"] == pytest.approx(1.5)
    cap = constant_rate_capture([0.0, 0.0, 1.0], exposure=0.03, readout=0.0, start=0.05)
    t = cap.log.t
    cap = cap.replace(log=GyroLog(t, np.stack([np.zeros_like(t), np.zeros_like(t), t], 1)))
    assert shake_stats(cap)["mean_rate"] == pytest.approx(0.065, abs=0.003)


def test_photos_are_downscaled_in_linear_light(tmp_path):
    """A fine checker of sRGB 0.2 and 0.8 halved in size averages the light, not the
    encoded values: linear 0.0331 and 0.6038 average to 0.3185, sRGB 0.600 (0.5 if the
    encoded values were averaged)."""
    from gyrodeblur.dataset import read_sharp
    from gyrodeblur.imageio import write_photo

    y, x = np.mgrid[0:64, 0:64]
    img = np.where((x + y) % 2 == 0, 0.2, 0.8).astype(np.float32)
    img = np.repeat(img[..., None], 3, axis=2)
    write_photo(tmp_path / "checker.png", img, bit_depth=16)
    got = read_sharp(tmp_path / "checker.png", 32)
    assert got.shape == (32, 32, 3)
    np.testing.assert_allclose(got[8:-8, 8:-8], 0.600, atol=0.01)


def test_an_exposure_range_must_be_ordered_and_positive():
    from gyrodeblur.dataset import plan_window

    t = np.arange(0.0, 3.0, 0.005)
    log = GyroLog(t, np.tile([0.1, 0.3, 0.05], (t.size, 1)))
    for bad in ((0.04, 0.01), (0.0, 0.02), (-0.01, 0.02)):
        with pytest.raises(InputError, match="min <= max"):
            plan_window(log, "x", 0, 200, 150, exposure=bad)
    cap, _ = plan_window(log, "x", 0, 200, 150, exposure=(0.01, 0.02))
    assert 0.01 <= cap.exposure_time <= 0.02


def test_a_rebuild_removes_only_former_case_folders(tmp_path):
    """The former index names what a rebuild removes, but only case folders inside the
    dataset: a listed name that is not a case (no case.json), ``..`` (the folder above,
    even when it holds a case.json) or ``.`` (the dataset itself) is left alone."""
    from skimage import data

    from gyrodeblur.dataset import build_dataset
    from gyrodeblur.gyrolog import write_gcsv
    from gyrodeblur.imageio import write_photo
    from gyrodeblur.shake import synthetic_hand_shake

    (tmp_path / "photos").mkdir()
    write_photo(tmp_path / "photos" / "a.png", data.astronaut()[::8, ::8] / 255.0)
    write_gcsv(tmp_path / "shake.gcsv", synthetic_hand_shake(2.0, seed=1))
    outer = tmp_path / "outer"
    ds = outer / "ds"
    (ds / "mine").mkdir(parents=True)
    (ds / "mine" / "notes.txt").write_text("keep")
    (outer / "case.json").write_text("{}")
    (ds / "dataset.json").write_text(json.dumps({"cases": ["..", ".", "mine", "old"]}))
    (ds / "case.json").write_text("{}")
    (ds / "old").mkdir()
    (ds / "old" / "case.json").write_text("{}")
    build_dataset(ds, photos=tmp_path / "photos", gyro=tmp_path / "shake.gcsv",
                  windows_per_photo=1, orientation="XYZ")
    assert (outer / "case.json").is_file() and (ds / "mine" / "notes.txt").is_file()
    assert sorted(p.name for p in ds.iterdir()) == ["a_w0", "case.json", "dataset.json",
                                                    "mine"]


@pytest.mark.parametrize("options,what", [
    (["--snr", "nan"], "--snr: must be a finite number of dB"),
    (["--snr", "inf"], "--snr: must be a finite number of dB"),     # "Infinity" in case.json
    (["--windows", "0"], "--windows: must be a whole number >= 1, got 0"),
    (["--max-photos", "-2"], "--max-photos: must be a whole number >= 1, got -2"),
    (["--snr", str(2 ** 64)], "--snr: must be a finite number of dB"),
])
def test_build_numbers_no_case_could_be_built_with_are_refused_first(tmp_path, capsys,
                                                                     options, what):
    """A NaN SNR had failed deep in the first case (a traceback, a half-written folder),
    an infinite one had been written as JSON's invalid ``Infinity``, and no windows had
    written an empty dataset with exit status 0."""
    from gyrodeblur.dataset import main
    assert main([str(tmp_path / "ds"), *options]) == 2
    assert what in capsys.readouterr().err
    assert not (tmp_path / "ds").exists()


def test_an_empty_list_of_photos_is_refused(tmp_path):
    with pytest.raises(InputError, match="photos: an empty list"):
        build_dataset(tmp_path / "ds", photos=[])
    assert not (tmp_path / "ds").exists()
