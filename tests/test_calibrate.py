"""Self-calibration: recovery of injected errors on a synthetic photo, fixed parameters,
several photos of one session, calibrate's decisions on a scripted search (keep rules,
margins, warnings), the command line.

The blurred photos are made by :func:`gyrodeblur.simulate.simulate_blur` (warping the
sharp image by the recorded rotation), never by convolving the PSFs the calibration fits.
"""

from __future__ import annotations

import json
import os
import re
from types import SimpleNamespace

import numpy as np
import pytest

from gyrodeblur.axes import axes_to_letters, parse_axes
from gyrodeblur.bias_prior import BiasPrior
from gyrodeblur.calibrate import PARAMETERS, calibrate
from gyrodeblur.calibration_fit import TWIN, CalibrationFit, _twin_parameters
from gyrodeblur.calibration_patches import CalibrationPhoto
from gyrodeblur.calibration_search import SearchSpace
from gyrodeblur.calibration_workers import StepRunner
from gyrodeblur.calibrate_cli import format_estimates
from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture, load_capture
from gyrodeblur.cli import main
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog, write_gcsv
from gyrodeblur.imageio import read_photo
from gyrodeblur.simulate import add_noise, quantize_8bit, simulate_blur
from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

W, H = 384, 256
TRUE_AXES = "Xyz"


def _log(seconds: float = 1.2, pan=(0.0, 0.0, 0.0)) -> GyroLog:
    """A 200 Hz log of a hand-shake-like motion (device axes), ``seconds`` long, plus a
    steady ``pan`` (rad/s, camera frame)."""
    t = np.arange(0.0, seconds, 1 / 200)
    wc = np.stack([0.55 * np.sin(2 * np.pi * 3.1 * t + 0.4) + 0.25 * np.sin(2 * np.pi * 7.7 * t),
                   0.75 * np.cos(2 * np.pi * 2.3 * t + 1.0) + 0.3 * np.sin(2 * np.pi * 8.9 * t + 2.0),
                   0.25 * np.sin(2 * np.pi * 4.3 * t + 0.7)], 1) + np.asarray(pan, float)
    return GyroLog(t, wc @ parse_axes(TRUE_AXES))          # camera -> device: M^T w (M^-1 = M^T)


def _long_log(seconds: float, bias, axes: str, turn=(0.0, 0.0, 0.0)) -> GyroLog:
    """``seconds`` of a 200 Hz log (device axes ``axes``) whose hand shake averages out
    within each second (whole cycles), but for a slow random wander of the rate
    (correlated over 0.5 s) and a steady ``turn``, plus the gyro's ``bias`` (rad/s,
    camera frame)."""
    t = np.arange(0.0, seconds, 1 / 200)
    rng = np.random.default_rng(5)
    wander = np.stack([np.convolve(rng.normal(0, 0.05, t.size), np.ones(100) / 100, "same")
                       for _ in range(3)], 1)
    wc = np.stack([0.55 * np.sin(2 * np.pi * 3 * t + 0.4) + 0.25 * np.sin(2 * np.pi * 8 * t),
                   0.75 * np.cos(2 * np.pi * 2 * t + 1.0) + 0.3 * np.sin(2 * np.pi * 9 * t + 2.0),
                   0.25 * np.sin(2 * np.pi * 4 * t + 0.7)], 1) + wander
    wc = wc + np.asarray(turn, float) + np.asarray(bias, float)
    return GyroLog(t, wc @ parse_axes(axes))


def _sharp() -> np.ndarray:
    from skimage import data, transform
    img = transform.resize(data.astronaut(), (H, W), anti_aliasing=True)
    return img.astype(np.float32)


def _true_capture(start: float, log: GyroLog | None = None) -> Capture:
    return Capture(start, 0.04, 0.03, Camera.centred(W, H, 1.3 * W), log or _log(),
                   axes=TRUE_AXES)


def _blur(sharp, cap, seed=0) -> np.ndarray:
    out = linear_to_srgb(simulate_blur(srgb_to_linear(sharp), cap, transfer="linear"))
    return quantize_8bit(add_noise(out, 40.0, seed))


def _corrupt(cap: Capture, *, offset=0.014, readout=1.2, focal=1.06, bias=(0.02, -0.02, 0.0),
             axes="YXz") -> Capture:
    return cap.replace(time_offset=cap.time_offset + offset,
                       readout_time=cap.readout_time * readout,
                       camera=cap.camera.with_focal_scale(focal),
                       bias=np.asarray(bias, float), axes=parse_axes(axes))


@pytest.fixture(scope="module")
def case():
    sharp = _sharp()
    true = _true_capture(0.5)
    return sharp, true, _blur(sharp, true)


@pytest.fixture(scope="module")
def recovered(case):
    _, true, blurred = case
    bad = _corrupt(true)
    lines = []
    res = calibrate([blurred], bad, say=lines.append)
    return res, bad, lines


def test_recovers_injected_offset_axes_focal(case, recovered):
    _, true, _ = case
    res, bad, lines = recovered
    got = res.capture
    assert axes_to_letters(got.axes) == TRUE_AXES
    assert abs(got.time_offset - true.time_offset) < 0.003
    assert abs(got.camera.fx / true.camera.fx - 1) < 0.06
    assert abs(got.readout_time - true.readout_time) < 0.008
    # better than what it was given, on every estimated parameter that matters for PSFs
    assert abs(got.camera.fx - true.camera.fx) < abs(bad.camera.fx - true.camera.fx)
    assert abs(got.readout_time - true.readout_time) < abs(bad.readout_time - true.readout_time)
    # before/after with an uncertainty for each parameter
    est = res.estimates
    assert set(est) == set(PARAMETERS)
    assert est["offset"][0] == pytest.approx(bad.time_offset)
    assert est["offset"][2] is not None and est["offset"][2] > 0
    assert est["focal"][2] is not None and np.all(np.asarray(est["bias"][2]) > 0)
    text = "\n".join(format_estimates(est))
    for word in ("time offset", "readout", "focal scale", "gyro bias", "axes", "->", "+-"):
        assert word in text
    assert any("coarse ranking" in line for line in lines)
    assert res.ranking and res.ranking[0][1] == 0.0
    assert not any("uncertain" in note for note in res.notes)
    assert res.offset_rivals == [] and not any("ambiguous" in note for note in res.notes)
    assert res.blur_gain > 10 and not any("little of the blur" in n for n in res.notes)


def test_the_estimates_report_the_corrected_capture(recovered):
    """Each estimate's "before" is the given capture's value and its "after" the
    corrected capture's (what ``calibrate`` prints and what it writes must agree)."""
    res, bad, _ = recovered
    got, est = res.capture, res.estimates
    assert est["offset"][:2] == (bad.time_offset, got.time_offset)
    assert est["readout"][:2] == (bad.readout_time, got.readout_time)
    assert est["readout"][1] != est["readout"][0]           # it was corrected here
    assert est["focal"][0] == 1.0
    assert est["focal"][1] == pytest.approx(got.camera.fx / bad.camera.fx, rel=1e-12)
    np.testing.assert_array_equal(est["bias"][0], bad.bias)
    np.testing.assert_array_equal(est["bias"][1], got.bias)
    assert est["axes"][:2] == (axes_to_letters(bad.axes), axes_to_letters(got.axes))


def test_the_blur_gain_is_the_blur_evidence_of_the_capture_kept(case):
    """With every parameter fixed, the calibrated capture is the given one, and the gain
    that calibrate checks (tempered nats per 9 patches) is the one
    :func:`gyrodeblur.blur_evidence.capture_gain_over_no_blur` measures for it: the same
    windows, the same units."""
    from gyrodeblur.blur_evidence import capture_gain_over_no_blur
    _, true, blurred = case
    res = calibrate([blurred], true, fix=set(PARAMETERS))
    alone = capture_gain_over_no_blur(blurred, true)
    assert alone > 10
    assert res.blur_gain == pytest.approx(alone, rel=1e-3), (res.blur_gain, alone)


def test_a_sharp_photo_given_a_shaken_log_is_said_to_show_no_blur(case):
    """The sharp original with the capture that blurred it: whatever the search finds,
    no blur at all explains the patches better, and the user is told."""
    sharp, true, _ = case
    res = calibrate([quantize_8bit(sharp)], _corrupt(true))
    assert res.blur_gain < 1.0
    assert any("the photo shows little of the blur the gyro log implies" in n
               for n in res.notes)
    # in a session, the sharp one among blurred photos is named (not outweighed by them;
    # the mapping given and fixed: the search over all 24 took twice the time, same notes)
    later = _true_capture(0.8)
    res = calibrate([_blur(sharp, true), quantize_8bit(sharp)], [true, later], fix={"axes"})
    assert any("photo 2 shows little of the blur" in n for n in res.notes)
    assert not any("photo 1" in n and "little of the blur" in n for n in res.notes)


def test_cli_calibrate_turns_each_photo_back(cli_dir, capsys):
    """--photo-rotation per photo: a session with a portrait export of its second frame
    calibrates exactly as the two frames in the sensor's layout."""
    from gyrodeblur.imageio import read_photo, write_photo

    d = cli_dir
    first = read_photo(d / "blurred.png").pixels
    noise = np.random.default_rng(7).normal(0, 2 / 255, first.shape).astype(np.float32)
    second = np.clip(first + noise, 0, 1)                    # another exposure of the scene
    write_photo(d / "second.png", second, bit_depth=8)
    write_photo(d / "turned.png", np.rot90(read_photo(d / "second.png").pixels, -1), bit_depth=8)
    doc = json.loads((d / "cap.json").read_text())
    doc["exposure_start"] += 2e-4                            # exposed a little later
    (d / "second.json").write_text(json.dumps(doc))
    common = ["--capture", f"{d / 'cap.json'},{d / 'second.json'}",
              "--fix", "bias,readout,focal,axes"]
    assert main(["calibrate", str(d / "blurred.png"), str(d / "second.png"), *common,
                 "-o", str(d / "out" / "same.json")]) == 0
    assert main(["calibrate", str(d / "blurred.png"), str(d / "turned.png"), *common,
                 "--photo-rotation", "0,90", "-o", str(d / "out" / "turned.json")]) == 0
    assert (json.loads((d / "out" / "same.json").read_text())
            == json.loads((d / "out" / "turned.json").read_text()))
    capsys.readouterr()
    assert main(["calibrate", str(d / "blurred.png"), str(d / "turned.png"), *common,
                 "--photo-rotation", "0,90,90", "-o", str(d / "out" / "x.json")]) == 2
    assert "3 rotations for 2 photos" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:        # argparse: not a quarter turn
        main(["calibrate", str(d / "blurred.png"), *common, "--photo-rotation", "45",
              "-o", str(d / "out" / "x.json")])
    assert stop.value.code == 2
    assert "--photo-rotation" in capsys.readouterr().err


def test_estimates_on_an_epoch_clock_print_the_change():
    """A time offset between epoch clocks (seconds of them) hides a few ms of correction in
    its digits: the line says the change too."""
    est = {"offset": (250295.23, 250295.2347, 0.0006), "readout": (0.03, 0.031, 0.001),
           "focal": (1.0, 1.01, 0.02), "bias": (np.zeros(3), np.zeros(3), None),
           "axes": ("XYZ", "XYZ", None)}
    line = format_estimates(est)[0]
    assert "a change of +4.70 ms" in line
    est["offset"] = (0.01, 0.0147, 0.0006)
    assert "change" not in format_estimates(est)[0]


def test_a_compressed_jpeg_is_calibrated_on_the_band_it_kept(case):
    """JPEG quantisation empties the top of the spectrum; calibrate notices the 8 px blocks,
    says so, leaves those frequencies out, and still recovers the injected errors."""
    import io

    from PIL import Image
    _, true, blurred = case
    buf = io.BytesIO()
    Image.fromarray((blurred * 255).round().astype(np.uint8)).save(buf, "JPEG", quality=75)
    jpeg = np.asarray(Image.open(io.BytesIO(buf.getvalue()))).astype(np.float32) / 255
    res = calibrate([jpeg], _corrupt(true))
    assert any("JPEG's 8 px blocks" in note for note in res.notes)
    assert axes_to_letters(res.capture.axes) == TRUE_AXES
    assert abs(res.capture.time_offset - true.time_offset) < 0.003
    # the PNG photo has no blocks, and no such note
    assert not any("JPEG" in note for note in calibrate([blurred], true, fix=["axes"]).notes)


def test_an_uncertain_axis_mapping_is_reported(case):
    """A 6 ms exposure blurs by a few pixels: too little to tell the mapping (and its
    mirror twin) apart. Whatever is chosen, the user is told it is uncertain."""
    sharp, _, _ = case
    true = Capture(0.5, 0.006, 0.03, Camera.centred(W, H, 1.3 * W), _log(), axes=TRUE_AXES)
    res = calibrate([_blur(sharp, true)], _corrupt(true))
    assert any("axis mapping is uncertain" in note and "--orientation" in note
               for note in res.notes)
    assert format_estimates(res.estimates)[-1].endswith("uncertain)")


def test_a_right_mapping_is_not_given_up_for_a_coin_toss(case):
    """The right capture of a photo blurred by a few pixels: another mapping scores about
    as well (the photo cannot tell), and the given one stays. (Before session 8 any gain
    took the other: yXZ, by 0.0 nats.)"""
    sharp, _, _ = case
    true = Capture(0.5, 0.006, 0.03, Camera.centred(W, H, 1.3 * W), _log(), axes=TRUE_AXES)
    res = calibrate([_blur(sharp, true)], true)
    assert axes_to_letters(res.capture.axes) == TRUE_AXES
    assert any("kept the given parameters" in note and "time offset" in note
               for note in res.notes)


def test_the_given_mapping_stands_against_another_within_the_margin():
    """The odds for the given mapping are odds against another mapping at its best: its
    candidate goes on unless the winner's is better by the margin."""
    from gyrodeblur.calibrate import standing_candidate
    given, twin, other = parse_axes("Xyz"), parse_axes("xYz"), parse_axes("zyx")
    rows = [(-3665.9, "x_twin", twin, []), (-3663.4, "x_given", given, []),
            (-3582.5, "x_other", other, [])]
    assert standing_candidate(rows, given, 14.0)[1] == "x_given"      # 2.5 < 14
    assert standing_candidate(rows, given, 2.0)[1] == "x_twin"        # 2.5 >= 2
    assert standing_candidate(rows, other, 14.0)[1] == "x_twin"       # 83 nats behind
    assert standing_candidate(rows, parse_axes("YXz"), 14.0)[1] == "x_twin"   # not a candidate
    assert standing_candidate(rows[1:], given, 14.0)[1] == "x_given"  # the best already
    # at exactly the margin the other goes on: the odds ask for "at least" the margin
    assert standing_candidate([(-100.0, "x_twin", twin, []), (-98.0, "x_given", given, [])],
                              given, 2.0)[1] == "x_twin"


def test_a_wrong_mirror_twin_gives_way_to_the_right_mapping(case):
    """The twin step on the 13 px shake (rolling shutter): the right mapping, refined, keeps
    its place against its twin; its mirror twin, refined to its own optimum, gives way to
    it. Scored unrefined at the twin's optimum, the right mapping's spectra are 200 nats per
    patch worse there (roll and the rolling shutter do not mirror), which kept the wrong
    twin before session 19."""
    _, true, blurred = case
    photos = [CalibrationPhoto(blurred, true, "srgb", 0)]
    fit = CalibrationFit(photos, SearchSpace(photos, set(), 0.04), set(),
                         BiasPrior(np.zeros(3)), 9, 2, lambda msg: None)
    M = true.axes
    x, f = fit.refine(M, np.zeros(6), 10)[:2]
    kept, twin, note, tie = fit.mirror_twin(M, x, f, [true.bias])
    assert twin is None and np.array_equal(kept, M), note
    assert tie is None, note                        # a clear decision: no warning
    Mt = TWIN @ M
    xt, ft = fit.refine(Mt, np.clip(_twin_parameters(x, [true.bias]), fit.lo, fit.hi), 10)[:2]
    taken, refined, note, tie = fit.mirror_twin(Mt, xt, ft, [true.bias])
    assert axes_to_letters(taken) == axes_to_letters(M), note
    assert refined is not None and refined[1] < ft, note
    # the phase was measured on more patches than the fit's (the next most textured)
    phase = fit.phase_patches()
    assert phase is fit.phase_patches()
    assert len(phase.points) > len(fit.fine.points)
    assert f"/{len(phase.points)} patches prefer" in note, note


def test_a_shake_that_repeats_within_the_exposure_makes_the_offset_ambiguous(case):
    """A yaw oscillating at 100 Hz, four whole periods per row's 40 ms exposure: every row's
    PSF is the same segment whatever the time offset, so the photo cannot tell offsets
    apart (it does tell the focal length, by the segment's length). The estimate comes with
    a warning naming other offsets that score as well."""
    sharp, _, _ = case
    t = np.arange(0.0, 1.2, 1 / 1000)
    wc = np.zeros((t.size, 3))
    wc[:, 1] = 6.0 * np.sin(2 * np.pi * 100.0 * t)
    true = Capture(0.5, 0.04, 0.03, Camera.centred(W, H, 1.3 * W),
                   GyroLog(t, wc @ parse_axes(TRUE_AXES)), axes=TRUE_AXES, time_offset=0.2)
    bad = _corrupt(true, offset=0.01, readout=1.0, focal=1.1, bias=(0, 0, 0), axes=TRUE_AXES)
    res = calibrate([_blur(sharp, true)], bad, fix={"axes", "readout", "bias"})
    assert abs(res.capture.camera.fx / true.camera.fx - 1) < 0.03     # the blur's length
    assert res.offset_rivals
    for offset, readout, _ in res.offset_rivals:     # absolute values, near the given ones
        assert abs(offset - bad.time_offset) < 0.05 and readout == pytest.approx(0.03)
    assert any("time offset is ambiguous" in note and "--time-offset" in note
               and "or calibrate on several photos of the session" in note
               for note in res.notes)
    # two photos of the session, as ambiguous: the advice asks for more than these two
    # (a five-frame session had been told to calibrate on several photos)
    later = true.replace(exposure_start=0.62)
    res = calibrate([_blur(sharp, true), _blur(sharp, later, seed=1)],
                    [bad, bad.replace(exposure_start=0.62)], fix={"axes", "readout", "bias"})
    said = [n for n in res.notes if "time offset is ambiguous" in n]
    assert said and "or calibrate on more photos of the session than these 2" in said[0]


def test_deblurring_with_the_calibrated_capture_is_close_to_the_true_one(case, recovered):
    """The calibrated capture deblurs the photo nearly as well as the true one once the
    result is shifted onto the sharp photo: the blur shows the PSFs' shapes, while
    where the output sits (the exposure-start orientation) follows the time offset and
    bias, which one photo pins down to about a millisecond (here -2.3 ms: -2.8 dB
    unregistered, -0.3 dB registered)."""
    from scipy import ndimage
    from skimage.registration import phase_cross_correlation

    from gyrodeblur.deblur import deblur
    from gyrodeblur.metrics import crop_border, psnr
    sharp, true, blurred = case
    res, bad, _ = recovered
    b = 16

    def registered(out):
        shift = phase_cross_correlation(crop_border(sharp.mean(-1), b), crop_border(out.mean(-1), b),
                                        upsample_factor=10, normalization=None)[0]
        return psnr(sharp, ndimage.shift(out, (*shift, 0), order=1, mode="nearest"), b)

    out_true, out_cal, out_bad = (deblur(blurred, c, grid=(2, 3)) for c in (true, res.capture, bad))
    assert psnr(sharp, out_cal, b) > psnr(sharp, out_bad, b) + 3.0
    assert psnr(sharp, out_cal, b) > psnr(sharp, out_true, b) - 4.0
    assert registered(out_cal) > registered(out_true) - 1.0
    assert registered(out_cal) > registered(out_bad) + 6.0


def test_fixed_parameters_are_not_estimated(case):
    _, true, blurred = case
    bad = _corrupt(true, offset=0.01, axes=TRUE_AXES)
    res = calibrate([blurred], bad, fix={"axes", "focal", "readout", "bias"})
    got = res.capture
    np.testing.assert_array_equal(got.axes, bad.axes)
    assert got.camera == bad.camera
    assert got.readout_time == bad.readout_time
    np.testing.assert_array_equal(got.bias, bad.bias)
    # the free one moved towards the truth (it cannot reach it: the fixed ones are wrong)
    assert abs(got.time_offset - true.time_offset) < 0.7 * abs(bad.time_offset - true.time_offset)
    for name in ("focal", "readout", "bias", "axes"):
        assert res.estimates[name][2] is None                     # "fixed"
    assert res.fixed == {"axes", "focal", "readout", "bias"}
    assert "fixed" in "\n".join(format_estimates(res.estimates))


def test_fixed_offset_and_axes(case):
    _, true, blurred = case
    bad = _corrupt(true, offset=0.0, readout=1.35, focal=1.08, bias=(0, 0, 0), axes=TRUE_AXES)
    res = calibrate([blurred], bad, fix={"offset", "axes"})
    got = res.capture
    assert got.time_offset == bad.time_offset
    np.testing.assert_array_equal(got.axes, bad.axes)
    assert abs(got.readout_time - true.readout_time) < abs(bad.readout_time - true.readout_time)
    assert res.estimates["offset"][2] is None and res.estimates["readout"][2] is not None


def test_a_correct_capture_is_left_alone(case):
    _, true, blurred = case
    res = calibrate([blurred], true)
    assert any("kept the given parameters" in n for n in res.notes)
    got = res.capture
    assert got.time_offset == true.time_offset and got.camera == true.camera
    assert got.readout_time == true.readout_time
    np.testing.assert_array_equal(got.axes, true.axes)


def test_everything_fixed_returns_the_given_capture(case):
    _, true, blurred = case
    res = calibrate([blurred], true, fix=set(PARAMETERS))
    got = res.capture
    assert got.time_offset == true.time_offset and got.camera == true.camera
    np.testing.assert_array_equal(got.axes, true.axes)


def test_a_wide_offset_range_finds_clocks_a_quarter_second_apart(case):
    """Clocks known only roughly: a 250 ms offset lies far outside the default search
    (+-40 ms); with ``offset_range=0.3`` it is found, and where the log does not cover
    the asked range (it starts 0.25 s before the exposure as given) a note says where the
    search stopped. (The mapping is given and fixed: with all 24 the test took twice the
    time; test_calibration_with_clocks_known_only_roughly_quick searches them too.)"""
    _, true, blurred = case
    bad = _corrupt(true, offset=0.25, axes=TRUE_AXES)
    lines = []
    res = calibrate([blurred], bad, offset_range=0.3, say=lines.append, fix={"axes"})
    got = res.capture
    assert abs(got.time_offset - true.time_offset) < 0.003
    cut = [n for n in res.notes if "covers the exposure only for time offsets" in n]
    assert len(cut) == 1 and "asked: +-300 ms" in cut[0]


def test_a_wide_search_starts_each_mapping_from_its_distinct_coarse_minima(case):
    """Over a wide range each mapping's coarse row carries its further distinct minima
    (the candidates are started from them too: a far basin can lead the coarse grid and
    lose once refined); over the default range it carries none."""
    from gyrodeblur.calibration_fit import WIDE_APART
    _, true, blurred = case
    photos = [CalibrationPhoto(blurred, true, "srgb", 0)]
    rows = {}
    for reach in (0.04, 0.3):
        fit = CalibrationFit(photos, SearchSpace(photos, set(), reach), set(),
                             BiasPrior(np.zeros(3)), 9, 1, lambda msg: None)
        rows[reach] = fit.coarse_row(True, true.axes)
    assert rows[0.04][5] == ()
    score, tau0, _, _, M, others, bias_step = rows[0.3]
    assert len(others) == 2 and np.array_equal(M, true.axes) and bias_step is None
    assert abs(tau0) < 0.003                      # the truth leads here
    assert all(abs(t - tau0) > WIDE_APART for t, _ in others)
    assert abs(others[0][0] - others[1][0]) > WIDE_APART
    starts = fit.candidates([rows[0.3]], StepRunner(fit, 1))[0]
    assert abs(starts[1][0]) < 0.003                   # the best start is the truth's...
    assert any(abs(xa[0] - others[0][0]) < 0.02 for xa in starts[3])   # ...and the far ones stay


def test_a_long_time_shift_grid_is_costed_in_chunks_each_shift_as_alone(case, monkeypatch):
    """The coarse costs over more time shifts than one chunk holds (a wide search) are
    those of each shift costed on its own: chunks bound the memory, not the result."""
    import gyrodeblur.spectral_criterion as sc
    _, true, blurred = case
    photos = [CalibrationPhoto(blurred, true, "srgb", 0)]
    fit = CalibrationFit(photos, SearchSpace(photos, set(), 0.04), set(),
                         BiasPrior(np.zeros(3)), 9, 1, lambda msg: None)
    theta = fit.theta0.copy(axes=true.axes)
    taus = np.arange(-0.02, 0.0201, 0.002)                   # 21 shifts
    monkeypatch.setattr(sc, "_TAU_CHUNK", 8)                 # 3 chunks
    before = fit.coarse.evaluations
    made, spectra = [], fit.coarse.spectra
    monkeypatch.setattr(fit.coarse, "spectra",
                        lambda th, tl=None, **kw: made.append(len(tl)) or spectra(th, tl, **kw))
    chunked = fit.coarse.costs(theta, taus)
    assert made == [8, 8, 5]                                 # never more than a chunk
    assert fit.coarse.evaluations == before + 1 and chunked.shape == (21, len(fit.coarse.points))
    alone = np.concatenate([fit.coarse.costs(theta, taus[k:k + 1]) for k in range(21)])
    # the same to float32's precision (the batched spectra round a little differently)
    np.testing.assert_allclose(chunked, alone, rtol=1e-6)


def test_both_coarse_envelopes_are_costed_from_one_set_of_spectra(case, monkeypatch):
    """The coarse ranking's flat and fitted-envelope rows of a mapping come from one
    computation of its spectra (per chunk of time shifts), each row as that envelope's
    own would be: the same costs, the same warm starts."""
    import gyrodeblur.spectral_criterion as sc
    _, true, blurred = case
    photos = [CalibrationPhoto(blurred, true, "srgb", 0)]
    fit = CalibrationFit(photos, SearchSpace(photos, set(), 0.04), set(),
                         BiasPrior(np.zeros(3)), 9, 1, lambda msg: None)
    monkeypatch.setattr(sc, "_TAU_CHUNK", 16)                # 41 shifts: 3 chunks
    alone = []
    for envelope in (False, True):
        fit.coarse.start_afresh()
        alone.append(fit.coarse_row(envelope, true.axes))
    made, spectra = [], fit.coarse.spectra
    monkeypatch.setattr(fit.coarse, "spectra",
                        lambda th, tl=None, **kw: made.append(len(tl)) or spectra(th, tl, **kw))
    fit.coarse.start_afresh()
    before = fit.coarse.evaluations
    both = fit.coarse_rows((False, True), true.axes)
    assert made == [16, 16, 9]
    assert fit.coarse.evaluations == before + 2
    for got, want in zip(both, alone):
        assert got[0] == want[0] and got[1:4] == want[1:4]
    assert alone[0][0] != alone[1][0]                   # the envelopes do differ


def test_the_offset_range_is_checked(case):
    _, true, blurred = case
    for bad in (0, -0.01, float("nan"), True, 6.0, "0.1"):
        with pytest.raises(InputError, match="must be seconds in"):
            calibrate([blurred], true, offset_range=bad)
    with pytest.raises(InputError, match="time offset is fixed"):
        calibrate([blurred], true, offset_range=0.5, fix="offset")


def test_bad_fix_name_is_an_input_error(case):
    _, true, blurred = case
    with pytest.raises(InputError, match="unknown parameter"):
        calibrate([blurred], true, fix={"offset", "focus"})
    with pytest.raises(InputError, match="^fix: must name parameters .* got 5; known: offset"):
        calibrate([blurred], true, fix=5)


def test_several_photos_share_the_corrections(case):
    sharp, _, _ = case
    log = _log()
    t1, t2 = _true_capture(0.45, log), _true_capture(0.53, log)
    # the second photo sees the scene a little to the side: roll the sharp image
    b1 = _blur(sharp, t1, seed=1)
    b2 = _blur(np.roll(sharp, 6, axis=1), t2, seed=2)
    kw = dict(offset=-0.012, readout=0.85, focal=0.95, bias=(0.0, 0.02, -0.01), axes="xYz")
    res = calibrate([b1, b2], [_corrupt(t1, **kw), _corrupt(t2, **kw)])
    c1, c2 = res.captures
    assert c1.exposure_start == t1.exposure_start and c2.exposure_start == t2.exposure_start
    assert c1.time_offset == c2.time_offset                        # one correction for both
    assert c1.camera.fx == c2.camera.fx and c1.readout_time == c2.readout_time
    np.testing.assert_array_equal(c1.bias, c2.bias)
    assert axes_to_letters(c1.axes) == TRUE_AXES
    # The issue's 3 ms is what the benchmark counts; on these two photos the estimate sits
    # 2.9 ms off with bilinear blur synthesis and 3.4 ms off with the cubic-spline one
    # (session 17), a focal-bias trade-off (fx 8 % short) the calibration did not change;
    # 4.0 ms off (fx 5.6 % short) since the kernels are seen through the rolling shutter's
    # local warp (session 32), which brought the benchmark's offsets 20 -> 21 of 24; 4.8 ms
    # off since each patch's blur is read at 2 x 2 points across it (session 51), which
    # brought them 22 -> 24 of 24 and the benchmark's two-photo sessions' median
    # error 0.61 -> 0.29 ms
    assert abs(c1.time_offset - t1.time_offset) < 0.005


def test_mismatched_inputs(case):
    _, true, blurred = case
    with pytest.raises(InputError, match="2 photos but 3 captures"):
        calibrate([blurred, blurred], [true, true, true])
    with pytest.raises(InputError, match="no photo"):
        calibrate([], true)
    # the same photo twice, as one array or as a copy, would count its evidence twice
    for second in (blurred, blurred.copy()):
        with pytest.raises(InputError, match="photos 1 and 2 hold the same pixels"):
            calibrate([blurred, second], [true, true])
    # two photos given one start on one log (one description for both): refused, unless
    # the start is each photo's EXIF time, or the time offsets put them apart
    other = np.clip(blurred[::-1] * 0.9 + 0.05, 0, 1)
    with pytest.raises(InputError, match="^captures: photos 1 and 2 start exposing at the "
                                         "same time .* on the same gyro log"):
        calibrate([blurred, other], [true, true])
    from gyrodeblur.calibrate import _refuse_one_start
    _refuse_one_start([true, true.replace(exposure_start=true.exposure_start + 2e-4)])
    _refuse_one_start([true, true.replace(time_offset=true.time_offset + 0.1)])
    _refuse_one_start([true.replace(exposure_start_from_exif=True)] * 2)


# ------------------------------------------------ decisions on a scripted search

class _ScriptedFit:
    """A stand-in for :class:`CalibrationFit` (``calibrate`` makes it in its place) whose
    steps come out as ``script`` says, in tempered nats: ``"candidates"`` the first
    candidate mappings' objectives (letters -> objective; their coarse scores as well),
    ``"wide"`` the coarse scores with the bias moved, ``"objectives"`` the objectives of
    mappings first refined from there, ``"winner"`` the winner's refined objective (at
    ``"x"``, default a 5 ms time shift), ``"given"`` the given parameters', ``"tie"`` the
    twin step's unsettled tie ``(objective gap, z)``, ``"gains"`` each photo's blur gain
    and ``"owners"`` each patch's photo. What calibrate decides from them is then exact."""

    def __init__(self, script, search, fix):
        from gyrodeblur.calibration_search import X_NAMES
        self.script, self.search = script, search
        self.idx = [X_NAMES.index(k) for k in search.free()]
        self.ubar, self.basins, self.blockiness, self.band = 0.5, [], 1.0, np.inf
        self.refined, self.twin_steps = [], 0          # the mappings of each candidates step
        owners = script.get("owners", [0] * 9)
        per_patch = [100.0 * script.get("gains", [30.0])[k] / 9 for k in owners]
        self.fine = SimpleNamespace(band_cuts=False, scale=1.0, evaluations=0,
                                    points=[(k, 0.0, 0.0) for k in owners],
                                    gain_over_no_blur=lambda theta: np.array(per_patch))
        self.coarse = SimpleNamespace(evaluations=0)

    def coarse_rankings(self, cand, steps, bias_steps=(None,), envelopes=(False, True), stride=1):
        widened = len(bias_steps) > 1
        scores = self.script.get("wide", {}) if widened else self.script["candidates"]
        rows = sorted(((f, 0.0, 0.0, 1.0, parse_axes(a), (), None) for a, f in scores.items()),
                      key=lambda r: r[0])
        return [rows] * len(envelopes)

    def candidates(self, rows, steps):
        objectives = {**self.script["candidates"], **self.script.get("objectives", {})}
        self.refined.append([axes_to_letters(r[4]) for r in rows])
        return [(objectives[axes_to_letters(r[4])], np.r_[0.005, np.zeros(5)], r[4], [])
                for r in rows]

    def refine_winner(self, M, x, alts, steps):
        return (np.asarray(self.script.get("x", x), float), self.script["winner"],
                1e6 * np.eye(len(self.idx)), None)

    def given_objective(self, M):
        return self.script["given"], np.zeros(6)

    def refine(self, M, x, iters, which=None):        # only ever at the given parameters
        return x, self.script["given"], 1e4 * np.eye(len(self.idx)), None

    def offset_rivals(self, M, x, f):
        return [(0.01, 0.0, 0.5)]                       # a rival whenever asked

    def prior_for(self, M):
        return (np.r_[0.0, 0.0, 0.0, 0.02, 0.0, 0.0], np.r_[np.inf, 0.009, 0.1, 0.05, 0.05, 0.05],
                100.0)

    def mirror_twin(self, M, x, f, given_biases):
        self.twin_steps += 1
        tie = self.script.get("tie")
        note = f"mirror twin {axes_to_letters(TWIN @ M)}: {axes_to_letters(M)} kept"
        return M, None, note, None if tie is None else (TWIN @ M,) + tuple(tie)


def _scripted(monkeypatch, script, captures=None, **kwargs):
    """:func:`calibrate` on flat photos (one per capture; default one of
    :func:`_true_capture`'s) with a :class:`_ScriptedFit` run by ``script``: the result
    and the fit."""
    import gyrodeblur.calibrate as cal
    made = []
    monkeypatch.setattr(cal, "CalibrationFit", lambda photos, search, fix, *args:
                        made.append(_ScriptedFit(script, search, fix)) or made[-1])
    captures = [_true_capture(0.5)] if captures is None else captures
    photos = [np.full((H, W), 0.3 + 0.1 * k, np.float32) for k in range(len(captures))]
    return calibrate(photos, captures, workers=1, **kwargs), made[-1]


def _said(res, words: str) -> bool:
    return any(words in n for n in res.notes)


def test_the_given_parameters_stay_unless_the_found_ones_gain_the_margin(monkeypatch):
    """All six coordinates free, the given mapping the best: the found parameters must
    lower the objective by 10 (9.9 keeps the given ones, 10.1 does not). Kept, the capture
    is the given one, with no offset rivals, no prior distance, no twin step, the
    uncertainties at the given parameters, and the mapping's gap measured from the given
    objective (3.1 to the next best mapping: uncertain)."""
    true = _true_capture(0.5)
    script = {"candidates": {"Xyz": -100.0, "xYz": -92.0, "YXz": -90.0}, "winner": -105.0}
    res, fit = _scripted(monkeypatch, dict(script, given=-95.1))
    assert _said(res, "kept the given parameters") and _said(res, "(< 10)"), res.notes
    got = res.capture
    assert (got.time_offset, got.readout_time, got.camera) == (true.time_offset,
                                                               true.readout_time, true.camera)
    assert res.offset_rivals == [] and not _said(res, "ambiguous")
    assert res.prior_distance == 0.0 and fit.twin_steps == 0
    assert res.estimates["axes"][2] == pytest.approx(3.1)
    assert _said(res, "the next best (xYz) scores only 3.1 worse")
    assert res.estimates["readout"][2] == pytest.approx(0.01)      # the given's Hessian
    assert not _said(res, "covers the exposure only")              # the log covers +-40 ms
    assert res.kept_given
    # a mapping that scores better than the kept given parameters is not "the next best"
    better = {"candidates": {"Xyz": -100.0, "xYz": -96.0, "YXz": -90.0}, "winner": -105.0}
    res, _ = _scripted(monkeypatch, dict(better, given=-95.1))
    assert res.kept_given and res.estimates["axes"][2] == pytest.approx(-0.9)
    assert _said(res, "another mapping (xYz) scores 0.9 better"), res.notes
    assert not _said(res, "next best"), res.notes
    res, fit = _scripted(monkeypatch, dict(script, given=-94.9))
    assert not _said(res, "kept the given parameters"), res.notes
    assert not res.kept_given
    assert res.capture.time_offset == pytest.approx(true.time_offset + 0.005)
    assert res.offset_rivals == [(true.time_offset + 0.01, true.readout_time, 0.5)]
    assert fit.twin_steps == 1 and res.prior_distance > 0
    assert res.estimates["axes"][2] == pytest.approx(13.0) and not _said(res, "uncertain")
    assert res.estimates["readout"][2] == pytest.approx(0.001)     # the winner's


def test_another_mapping_must_gain_the_mapping_margin(monkeypatch):
    """Another mapping replaces the given one when it lowers the given objective by 2
    (three times as much under three times the typical gyro noise, and as much with the
    mapping the only free parameter); its candidate goes on only when it beats the given
    mapping's own by 2 as well (within that, the given mapping stands)."""
    true = _true_capture(0.5)
    other = {"candidates": {"YXz": -106.0, "Xyz": -103.0, "ZXY": -80.0}, "winner": -106.0}
    res, _ = _scripted(monkeypatch, dict(other, given=-103.9))              # 2.1
    assert axes_to_letters(res.capture.axes) == "YXz", res.notes
    res, _ = _scripted(monkeypatch, dict(other, given=-104.1))              # 1.9
    assert axes_to_letters(res.capture.axes) == TRUE_AXES and _said(res, "(< 2)"), res.notes
    res, _ = _scripted(monkeypatch, dict(other, given=-104.1),
                       fix=("offset", "readout", "focal", "bias"))
    assert axes_to_letters(res.capture.axes) == TRUE_AXES, res.notes
    res, _ = _scripted(monkeypatch, dict(other, given=-103.9), captures=[_noisy(true, 0.021)])
    assert _said(res, "gyro noise ") and axes_to_letters(res.capture.axes) == TRUE_AXES
    # the given mapping's candidate 1.5 behind: it stands, and is refined as the winner
    res, _ = _scripted(monkeypatch, {"candidates": {"YXz": -103.0, "Xyz": -101.5},
                                     "winner": -106.0, "given": -90.0})
    assert axes_to_letters(res.capture.axes) == TRUE_AXES and _said(res, ": it stands")


def test_the_mapping_is_uncertain_under_8_nats_or_a_twin_tie(monkeypatch):
    """The gap to the next best mapping: 8.0 is confident, 7.5 is not; a runner-up whose
    candidate beat the winner's refinement (the given mapping stood) makes it 0, not
    negative; a twin tie that the phase could not settle makes it the tie's objective gap
    (0 when the other scored better), unless a candidate of the mapping's own pair is
    closer, and the note names the mapping the phase preferred."""
    def run(**script):
        return _scripted(monkeypatch, dict({"given": -80.0}, **script))[0]

    for gap, uncertain in ((8.0, False), (7.5, True)):
        res = run(candidates={"Xyz": -110.0, "YXz": -110.0 + gap}, winner=-110.0)
        assert res.estimates["axes"][2] == gap and _said(res, "uncertain") == uncertain
    res = run(candidates={"YXz": -101.0, "Xyz": -100.0}, winner=-100.5)
    assert res.estimates["axes"][2] == 0.0 and _said(res, "(YXz) scores only 0.0 worse")
    three = {"Xyz": -120.0, "xYz": -119.5, "YXz": -110.0}
    res = run(candidates=three, winner=-120.0, tie=(1.0, 1.5))
    assert res.estimates["axes"][2] == 0.5, res.notes           # the twin's own candidate
    assert _said(res, "its mirror twin xYz explains the blur about as well (objective +1.0), "
                      "and the phase of the deconvolved patches prefers Xyz by only 1.5")
    res = run(candidates=dict(three, xYz=-110.0), winner=-120.0, tie=(1.0, 1.5))
    assert res.estimates["axes"][2] == 1.0, res.notes
    res = run(candidates=dict(three, xYz=-110.0), winner=-120.0, tie=(-0.5, -1.0))
    assert res.estimates["axes"][2] == 0.0 and _said(res, "prefers xYz by only 1.0")


def test_a_mapping_only_the_widened_ranking_found_is_as_uncertain_as_the_first_were_close(
        monkeypatch):
    """The first candidates within 3 of each other: the widened ranking's best (ZXY) joins
    them with its mirror twin, and winning, is reported with the first candidates' gap
    (unless its own is smaller). The first candidates' best winning after all is not; a
    given mapping that stood against a better first candidate is not either (nothing was
    added); and when the first candidates are not close, a widened ranking that only
    rescored mappings refined already adds nothing."""
    first = {"Xyz": -100.0, "YXz": -97.0}
    res, fit = _scripted(monkeypatch, {"candidates": first, "wide": {"ZXY": -140.0},
                                       "objectives": {"ZXY": -130.0, "zxY": -125.0},
                                       "winner": -131.0, "given": -100.0})
    assert axes_to_letters(res.capture.axes) == "ZXY" and fit.refined[1] == ["ZXY", "zxY"]
    assert res.estimates["axes"][2] == 3.0 and _said(res, "won only once the search moved "
                                                          "the bias"), res.notes
    res, _ = _scripted(monkeypatch, {"candidates": first, "wide": {"ZXY": -140.0},
                                     "objectives": {"ZXY": -130.5, "zxY": -130.0},
                                     "winner": -131.0, "given": -100.0})
    assert res.estimates["axes"][2] == 1.0, res.notes
    res, _ = _scripted(monkeypatch, {"candidates": first, "wide": {"ZXY": -140.0},
                                     "objectives": {"ZXY": -90.0, "zxY": -90.0},
                                     "winner": -108.0, "given": -90.0})
    assert axes_to_letters(res.capture.axes) == TRUE_AXES
    assert res.estimates["axes"][2] == 11.0 and not _said(res, "uncertain"), res.notes
    res, fit = _scripted(monkeypatch, {"candidates": {"YXz": -101.0, "Xyz": -100.0},
                                       "winner": -103.0, "given": -80.0})
    assert axes_to_letters(res.capture.axes) == TRUE_AXES and len(fit.refined) == 1
    assert res.estimates["axes"][2] == 2.0 and _said(res, "(YXz) scores only 2.0 worse")
    lines = []
    _, fit = _scripted(monkeypatch, {"candidates": {"Xyz": -100.0, "YXz": -90.0},
                                     "wide": {"Xyz": -200.0, "YXz": -95.0},
                                     "winner": -100.0, "given": -100.0}, say=lines.append)
    assert len(fit.refined) == 1 and not any("bias moved" in line for line in lines), lines


def test_the_five_best_of_the_shortlist_and_the_best_ones_twin_are_refined(monkeypatch):
    scores = {a: -100.0 + k for k, a in enumerate(("Xyz", "YXz", "ZXY", "XZy", "yXZ", "zYX",
                                                   "xYz"))}
    _, fit = _scripted(monkeypatch, {"candidates": scores, "winner": -100.0, "given": -100.0},
                       fix=("bias",))
    assert fit.refined == [["Xyz", "YXz", "ZXY", "XZy", "yXZ", "xYz"]]


def test_the_blur_gain_is_that_of_the_photo_that_shows_least(monkeypatch):
    """Two photos, the second with little blur (a gain of 0.5 per 9 patches, on 2 patches
    against the first's 4): the reported gain is the second's, and the warning names it
    alone."""
    caps = [_true_capture(0.45), _true_capture(0.53)]
    res, _ = _scripted(monkeypatch, {"candidates": {"Xyz": -100.0}, "winner": -100.0,
                                     "given": -100.0, "gains": [30.0, 0.5],
                                     "owners": [0, 0, 0, 0, 1, 1]},
                       captures=caps, fix=set(PARAMETERS))
    assert res.blur_gain == pytest.approx(0.5)
    assert _said(res, "photo 2 shows little of the blur") and not _said(res, "photo 1")


def test_estimates_far_from_the_priors_are_weighed_against_the_free_coordinates(monkeypatch):
    """Bias corrections of 2.45 prior sds on x and y (from the prior's centre, 0.02 rad/s
    on x) sum to squared z-scores of 12: beyond chi-square's 95 % quantile for the five
    free coordinates a prior holds (11.07; not six, 12.59: the time offset has none)."""
    z = np.sqrt(6.0)
    res, _ = _scripted(monkeypatch, {"candidates": {"Xyz": -130.0, "YXz": -100.0},
                                     "winner": -130.0, "given": -100.0,
                                     "x": [0.005, 0.0, 0.0, 0.02 + 0.05 * z, 0.05 * z, 0.0]})
    assert res.prior_distance == pytest.approx(12.0)
    assert _said(res, "lie far from the given values for errors of the priors' size (moved by "
                      "bias x +0.122 rad/s (+2.4 sd), y +0.122 rad/s (+2.4 sd) (camera frame);")


def test_the_arguments_reach_the_search_at_their_limits(monkeypatch):
    """The widest offset range is allowed; a fixed readout lets photos whose descriptions
    give it and do not share a session."""
    script = {"candidates": {"Xyz": -100.0}, "winner": -100.0, "given": -100.0}
    from gyrodeblur.calibrate import MAX_OFFSET_RANGE
    res, _ = _scripted(monkeypatch, script, offset_range=MAX_OFFSET_RANGE, fix="axes")
    assert _said(res, "asked: +-5000 ms")
    caps = [_true_capture(0.45), _true_capture(0.53).replace(readout_time_unknown=True)]
    _scripted(monkeypatch, script, captures=caps, fix=("readout", "axes"))


def test_a_downscale_that_leaves_under_64_px_is_refused(case):
    _, true, blurred = case
    with pytest.raises(InputError, match="shrinks a 384x256 photo to 77x51"):
        calibrate([blurred], true, downscale=0.2)


def test_a_fixed_bias_takes_nothing_from_a_long_log(case):
    """A 20 s log whose typical rate says the given bias is 0.04 rad/s off: with the bias
    fixed it stays as given, and the log lends no prior."""
    b = np.array([0.04, -0.04, 0.0])
    log = _long_log(20.0, b, TRUE_AXES)
    given = Capture(10.0, 0.04, 0.03, Camera.centred(W, H, 1.3 * W), log, axes=TRUE_AXES)
    res = calibrate([case[2]], given, fix=set(PARAMETERS))
    np.testing.assert_array_equal(res.capture.bias, given.bias)
    assert not _said(res, "prior on the bias")


def test_the_gyro_noise_is_the_noisiest_logs():
    from gyrodeblur.calibrate import _gyro_noise_level
    quiet, noisy = _true_capture(0.45), _noisy(_true_capture(0.53), 0.02)
    assert _gyro_noise_level([quiet, noisy]) == pytest.approx(0.02, rel=0.1)
    assert _gyro_noise_level([noisy, quiet]) == _gyro_noise_level([quiet, noisy])


def test_the_candidate_mappings():
    """All 24 proper signed permutations (or those asked), plus a measured mapping that is
    none of them; the given one alone when fixed."""
    from gyrodeblur.axes import PROPER_AXIS_LETTERS
    from gyrodeblur.calibrate import _candidate_mappings
    given = parse_axes("Xyz")
    assert [axes_to_letters(M) for M in _candidate_mappings(given, set(), None)] == \
        list(PROPER_AXIS_LETTERS)
    assert [axes_to_letters(M) for M in _candidate_mappings(given, set(), ["YXz"])] == ["YXz"]
    c, s = np.cos(0.05), np.sin(0.05)
    measured = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ given
    cand = _candidate_mappings(measured, set(), ["YXz", "Xyz"])
    assert len(cand) == 3 and cand[-1] is measured
    (only,) = _candidate_mappings(measured, {"axes"}, None)
    assert only is measured


def test_a_phone_log_is_searched_over_the_mappings_a_phone_s_camera_can_have(monkeypatch):
    """A phone's own camera looks along the device's z axis, so from a phone app's log (in
    the device's axes) only the 8 mappings that keep camera z on log z are searched, and a
    given mapping outside them is not kept however close it scores; a plain log (or a
    session with one) gets all 24, and ``mappings`` chooses either."""
    from gyrodeblur.axes import PHONE_AXIS_LETTERS, PROPER_AXIS_LETTERS
    from gyrodeblur.calibrate import searched_mappings

    assert len(PHONE_AXIS_LETTERS) == 8 and all(a[2] in "Zz" for a in PHONE_AXIS_LETTERS)
    true = _true_capture(0.5)
    phone = true.replace(log=GyroLog(true.log.t, true.log.omega, None, {"axes": "phone device"}))
    assert phone.log.in_device_axes and not true.log.in_device_axes
    letters, why = searched_mappings(None, [phone])
    assert letters == list(PHONE_AXIS_LETTERS) and "searching the 8 axis mappings" in why
    assert "not among" not in why
    assert searched_mappings(None, [true]) == (list(PROPER_AXIS_LETTERS), None)
    assert searched_mappings(None, [phone, true])[0] == list(PROPER_AXIS_LETTERS)
    assert searched_mappings("all", [phone]) == (list(PROPER_AXIS_LETTERS), None)
    assert searched_mappings(" Phone ", [true]) == (list(PHONE_AXIS_LETTERS), None)
    assert searched_mappings(None, [phone], {"axes"})[1] is None
    sideways = parse_axes("Yzx")                      # the camera looking out of a side
    _, why = searched_mappings(None, [phone.replace(axes=sideways)])
    assert "is not among those searched: a phone's camera does not look" in why, why
    for bad in ("phones", ["QQQ"], ["XYz", "XXY"]):
        with pytest.raises(InputError, match="^mappings: ") as err:
            searched_mappings(bad, [phone])
        assert err.value.argument
    script = {"candidates": {"Xyz": -100.0, "xYz": -92.0}, "winner": -105.0, "given": -104.9}
    res, _ = _scripted(monkeypatch, script, captures=[phone.replace(axes=sideways)])
    assert axes_to_letters(res.capture.axes) == "Xyz" and not _said(res, "kept the given")
    assert _said(res, "searching the 8 axis mappings"), res.notes
    res, _ = _scripted(monkeypatch, script, captures=[true.replace(axes=sideways)])
    assert axes_to_letters(res.capture.axes) == "Yzx" and _said(res, "kept the given")


def test_the_widened_ranking_steps_each_axis_by_its_own_prior_sd():
    """A long log's prior on the bias is tighter on some axes than on others: each bias step
    is one sd of its own axis."""
    from gyrodeblur.calibrate import _bias_steps
    prior = BiasPrior(np.zeros(3), (np.zeros(3), np.array([0.004, 0.02, 0.01])))
    M = parse_axes("Xyz")
    sd = prior.for_mapping(M)[1]
    assert sd[0] != sd[1]
    got = {tuple(np.round(s, 12)) for s in _bias_steps(prior, M)}
    assert got == {(round(i * sd[0], 12), round(j * sd[1], 12), 0.0)
                   for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j}


def test_the_widened_ranking_runs_one_mapping_of_each_twin_pair():
    from gyrodeblur.calibrate import _one_of_each_twin_pair
    cand = [parse_axes(a) for a in ("Xyz", "YXz", "xYz", "ZXY", "yxz")]
    assert [axes_to_letters(M) for M in _one_of_each_twin_pair(cand)] == ["Xyz", "YXz", "ZXY"]


def test_fix_names_may_come_with_empty_ones():
    from gyrodeblur.calibrate import checked_fix
    assert checked_fix("offset,,bias,") == {"offset", "bias"}
    assert checked_fix(["axes", "", None]) == {"axes"} and checked_fix(None) == set()


# ----------------------------------------------------------------------------- CLI

@pytest.fixture(scope="module")
def cli_dir(tmp_path_factory, case):
    from gyrodeblur.imageio import write_photo
    _, true, blurred = case
    d = tmp_path_factory.mktemp("cal")
    write_gcsv(d / "gyro.gcsv", true.log)
    write_photo(d / "blurred.png", blurred, bit_depth=8)
    bad = _corrupt(true)
    doc = {"exposure_start": true.exposure_start, "exposure_time": true.exposure_time,
           "readout_time": bad.readout_time,
           "camera": {"fx": bad.camera.fx, "fy": bad.camera.fy, "cx": bad.camera.cx,
                      "cy": bad.camera.cy, "width": W, "height": H},
           "gyro": {"path": "gyro.gcsv", "format": "gcsv", "orientation": "YXz",
                    "time_offset": bad.time_offset, "bias": list(bad.bias)}}
    (d / "cap.json").write_text(json.dumps(doc))
    (d / "out").mkdir()
    return d


def test_cli_calibrate_writes_a_loadable_capture(cli_dir, case, capsys):
    _, true, _ = case
    d = cli_dir
    out = d / "out" / "corrected.json"
    assert main(["calibrate", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
                 "--fix", "bias", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "time offset" in text and "->" in text and "+-" in text and "wrote" in text
    assert "gyro bias" in text and "fixed" in text
    cap = load_capture(out)                      # the gyro path was made relative to out/
    assert axes_to_letters(cap.axes) == TRUE_AXES
    # The bias is fixed at a wrong value, which the other parameters absorb: 3.9 ms off with
    # cubic-spline blur synthesis (session 17), under 3 ms with bilinear.
    assert abs(cap.time_offset - true.time_offset) < 0.0045
    np.testing.assert_allclose(cap.bias, [0.02, -0.02, 0.0])   # fixed: as given
    doc = json.loads(out.read_text())
    assert doc["gyro"]["orientation"] == TRUE_AXES


def test_cli_calibrate_with_gyro_from_the_working_directory(cli_dir, monkeypatch):
    """``--gyro`` is read relative to the working directory, not to the capture's folder:
    the corrected capture must point at the log that was read."""
    d = cli_dir
    (d / "sub").mkdir(exist_ok=True)
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["path"] = "not-here.gcsv"
    (d / "sub" / "cap.json").write_text(json.dumps(doc))
    monkeypatch.chdir(d)
    out = d / "out" / "from_cwd.json"
    assert main(["calibrate", "blurred.png", "--capture", "sub/cap.json", "--gyro", "gyro.gcsv",
                 "--fix", "bias,readout,focal,axes", "-o", str(out)]) == 0
    written = json.loads(out.read_text())["gyro"]["path"]
    assert os.path.normpath(os.path.join(d / "out", written)) == str(d / "gyro.gcsv")
    load_capture(out)                            # loads from anywhere


def test_cli_bad_fix_name_exits_2(cli_dir, capsys):
    d = cli_dir
    rc = main(["calibrate", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
               "--fix", "offset,zoom", "-o", str(d / "out" / "x.json")])
    assert rc == 2
    err = capsys.readouterr()
    assert "--fix" in (err.out + err.err) and "zoom" in (err.out + err.err)
    assert not (d / "out" / "x.json").exists()


def test_cli_capture_per_photo_count_must_match(cli_dir, capsys):
    d = cli_dir
    rc = main(["calibrate", str(d / "blurred.png"), str(d / "blurred.png"), "--capture",
               f"{d / 'cap.json'},{d / 'cap.json'},{d / 'cap.json'}", "-o",
               str(d / "out" / "y.json")])
    assert rc == 2
    assert "3 capture descriptions for 2 photos: give 1 or 2" in capsys.readouterr().err


def test_cli_calibrate_reads_per_photo_options_as_deblur_does(cli_dir, capsys, monkeypatch):
    """calibrate reads --capture and -o as deblur does (one reading,
    calibrate_cli.per_photo_values): one photo's value as written, commas and all; a file
    given once for several photos that exists is that file, not a list; an option repeated
    for one photo is refused before any calibration."""
    import shutil
    import gyrodeblur.calibrate_cli as cc

    class Stop(Exception):
        pass

    seen = []

    def stand_in(images, caps, **kwargs):
        seen.append([c.source for c in caps])
        raise Stop

    monkeypatch.setattr(cc, "calibrate", stand_in)
    d = cli_dir
    comma = d / "cap,1.json"
    shutil.copy(d / "cap.json", comma)
    photo = str(d / "blurred.png")
    for photos in ([photo], [photo, str(d / "again_for_commas.png")]):
        if len(photos) == 2:
            from gyrodeblur.imageio import read_photo, write_photo
            px = read_photo(photo).pixels
            write_photo(photos[1], np.clip(px[::-1] * 0.9 + 0.05, 0, 1), bit_depth=8)
        out = d / "out" / ("c,1.json" if len(photos) == 1 else "c1.json")  # outputs: split
        with pytest.raises(Stop):
            main(["calibrate", *photos, "--capture", str(comma), "-o", str(out)])
        assert [os.path.basename(s) for s in seen.pop()] == ["cap,1.json"] * len(photos)
    capsys.readouterr()
    assert main(["calibrate", photo, "--capture", str(d / "cap.json"), "-o",
                 str(d / "out" / "a.json"), "-o", str(d / "out" / "b.json")]) == 2
    assert "-o: given 2 times for one photo" in capsys.readouterr().err
    for empty in ("", ","):                        # no description at all, for two photos
        assert main(["calibrate", photo, str(d / "again_for_commas.png"), "--capture", empty,
                     "-o", str(d / "out" / "a.json")]) == 2
        assert "--capture: 0 capture descriptions for 2 photos" in capsys.readouterr().err
    assert not seen and not (d / "out" / "a.json").exists()


def test_a_comma_separated_list_of_files_drops_the_spaces_after_its_commas():
    """``-o "a.jpg, b.jpg"`` (as a list is usually typed) names b.jpg: the second photo's
    result was written to " b.jpg", a file whose name starts with a space; a value
    repeated, or one photo's, stays as written."""
    from gyrodeblur.calibrate_cli import per_photo_values
    assert per_photo_values("a.jpg, b.jpg", 2, "-o", (2,), "output") == ["a.jpg", "b.jpg"]
    assert per_photo_values(" a.json ,\tb.json ", 2, "--capture", (1, 2),
                            "capture description") == ["a.json", "b.json"]
    assert per_photo_values(["a.jpg", " b.jpg"], 2, "-o", (2,), "output") == ["a.jpg", " b.jpg"]
    assert per_photo_values([" a, b.jpg"], 1, "-o", (1,), "output") == [" a, b.jpg"]
    with pytest.raises(InputError, match="1 output for 2 photos"):
        per_photo_values("a.jpg, ", 2, "-o", (2,), "output")


def test_cli_a_photo_without_texture_is_named_in_the_error(cli_dir, capsys):
    """A problem with the photo itself (nothing textured to calibrate on) names the photo,
    in calibrate and in deblur --refine, and writes nothing."""
    from gyrodeblur.imageio import write_photo
    d = cli_dir
    flat = d / "flat.png"
    write_photo(flat, np.full((H, W), 0.5, np.float32), bit_depth=8)
    for cmd, out in (("calibrate", d / "out" / "flat.json"), ("deblur", d / "out" / "flat_out.png")):
        argv = [cmd, str(flat), "--capture", str(d / "cap.json"), "-o", str(out)]
        rc = main(argv + (["--refine", "--quiet"] if cmd == "deblur" else []))
        assert rc == 2
        err = capsys.readouterr().err
        assert f"{flat}: no textured" in err
        assert not out.exists()


def test_cli_deblur_refine_runs_the_calibration(cli_dir, capsys):
    """``deblur --refine`` calibrates, then deblurs; ``--save-capture`` writes the capture
    it refined, which deblurs the photo again to the same pixels with no calibration."""
    d = cli_dir
    out = d / "out" / "refined.png"
    saved = d / "out" / "refined.json"
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
                 "--refine", "--grid", "2x3", "--quiet", "-o", str(out),
                 "--save-capture", str(saved)]) == 0
    text = capsys.readouterr().out
    assert "coarse ranking" in text and "deblurred" in text
    assert re.search(r"deblurred .* [0-9.]+ s \(the calibration's [0-9.]+ s included\)", text)
    assert f"wrote the corrected capture description {saved}" in text
    given, refined = load_capture(d / "cap.json"), load_capture(saved)
    assert axes_to_letters(refined.axes) == TRUE_AXES != axes_to_letters(given.axes)
    again = d / "out" / "again.png"
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(saved), "--grid", "2x3",
                 "--quiet", "-o", str(again)]) == 0
    assert "coarse ranking" not in capsys.readouterr().out
    assert np.array_equal(read_photo(again).pixels, read_photo(out).pixels)


def _session_of_two(d, photo: str, capture: str) -> list[str]:
    """A second photo of ``d/blurred.png``'s session (the same scene, new noise, exposed
    0.2 ms later) written to ``d/photo``, its description to ``d/capture``: the command
    line's photos and ``--capture`` for both."""
    from gyrodeblur.imageio import write_photo

    first = read_photo(d / "blurred.png").pixels
    noise = np.random.default_rng(9).normal(0, 2 / 255, first.shape).astype(np.float32)
    write_photo(d / photo, np.clip(first + noise, 0, 1), bit_depth=8)
    doc = json.loads((d / "cap.json").read_text())
    doc["exposure_start"] += 2e-4
    (d / capture).write_text(json.dumps(doc))
    return [str(d / "blurred.png"), str(d / photo), "--capture",
            f"{d / 'cap.json'},{d / capture}"]


def test_cli_deblur_refine_of_several_photos_calibrates_them_as_one_session(cli_dir, capsys):
    """``deblur a b --refine`` calibrates the photos together, as ``calibrate a b`` does
    (the same corrected descriptions, each with its own exposure start), then deblurs each
    with its own: the same pixels as a deblur with the description calibrate wrote."""
    d = cli_dir
    common = _session_of_two(d, "next.png", "next.json") + ["--fix", "bias,readout,focal,axes"]
    photos = common[:2]
    o = d / "out"
    assert main(["calibrate", *common, "-o", str(o / "sa.json"), "-o", str(o / "sb.json")]) == 0
    capsys.readouterr()
    assert main(["deblur", *common, "--refine", "--grid", "2x3", "--quiet",
                 "-o", f"{o / 'sa.png'},{o / 'sb.png'}",
                 "--save-capture", f"{o / 'da.json'},{o / 'db.json'}"]) == 0
    said = capsys.readouterr().out
    assert "calibration of 2 photos" in said and said.count("deblurred ") == 2
    for name in "ab":
        assert json.loads((o / f"d{name}.json").read_text()) == \
            json.loads((o / f"s{name}.json").read_text()), name
    assert main(["deblur", photos[1], "--capture", str(o / "sb.json"), "--grid", "2x3",
                 "--quiet", "-o", str(o / "sb_again.png")]) == 0
    assert np.array_equal(read_photo(o / "sb_again.png").pixels, read_photo(o / "sb.png").pixels)


def test_cli_save_capture_needs_refine_and_a_json_file_apart(cli_dir, capsys):
    """``--save-capture`` is refused before any work: without --refine, with --blind, not
    .json, the -o file (also through a link), an input, or a file that exists."""
    d = cli_dir
    out = d / "out" / "o.png"
    link = d / "out" / "link.json"
    link.symlink_to(out)
    (d / "old.json").write_text("{}")
    base = ["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"), "-o", str(out)]
    for extra, says in (
            (["--save-capture", str(d / "c.json")], "--save-capture: applies with --refine only"),
            (["--blind", "--save-capture", str(d / "c.json")],
             "--save-capture: does not apply with --blind"),
            (["--refine", "--save-capture", str(d / "c.txt")], "c.txt: the corrected capture "
                                                               "description is JSON"),
            (["--refine", "--save-capture", str(link)], "link.json: is also the -o output"),
            (["--refine", "--save-capture", str(d / "cap.json"), "--overwrite"],
             "cap.json: is one of the command's inputs"),
            (["--refine", "--save-capture", str(d / "cap.json")],
             "cap.json: is one of the command's inputs"),
            (["--refine", "--save-capture", str(d / "old.json")],
             "old.json: exists; --overwrite (overwrite=True) replaces it")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert says in err, err
    assert not out.exists() and not (d / "c.json").exists()
    assert (d / "old.json").read_text() == "{}"
    link.unlink()


def test_cli_save_capture_failing_leaves_the_other_outputs_as_they_were(cli_dir, capsys,
                                                                       monkeypatch):
    """The corrected capture is written before the photo and moved into place last: where
    it cannot be written, the error names it (not its hidden part file), no output is
    left, and files --overwrite allowed stay as they were."""
    import types

    import gyrodeblur.calibrate
    import gyrodeblur.calibrate_cli

    d = cli_dir
    given = load_capture(d / "cap.json")
    fake = types.SimpleNamespace(capture=given, estimates=None, seconds=0.0, kept_given=False)
    monkeypatch.setattr(gyrodeblur.calibrate, "calibrate", lambda *a, **k: fake)
    monkeypatch.setattr(gyrodeblur.calibrate_cli, "format_estimates", lambda est, *kept: [])

    def refused(self, path, gyro_path=None):     # the disk fills as it is written
        def write(f):
            raise OSError(28, "No space left on device")
        atomic_write(path, write)

    from gyrodeblur.atomicfile import atomic_write
    monkeypatch.setattr(Capture, "save", refused)
    out, psf, saved = d / "out" / "kept.png", d / "out" / "kept_psf.png", d / "out" / "c.json"
    argv = ["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"), "--refine",
            "--grid", "2x3", "--quiet", "-o", str(out), "--save-psf", str(psf),
            "--save-capture", str(saved)]
    assert main(argv) == 2
    err = capsys.readouterr().err        # the output named, not the hidden part file
    assert "c.json: cannot write the file: No space left on device" in err
    assert ".part" not in err
    assert not out.exists() and not psf.exists() and not saved.exists()
    out.write_bytes(b"old photo")
    psf.write_bytes(b"old drawing")
    assert main(argv + ["--overwrite"]) == 2
    assert out.read_bytes() == b"old photo" and psf.read_bytes() == b"old drawing"
    assert sorted(p.name for p in (d / "out").iterdir() if "kept" in p.name or
                  p.name.startswith(".")) == ["kept.png", "kept_psf.png"]
    out.unlink()
    psf.unlink()


def test_cli_values_given_on_the_command_line_are_kept(cli_dir, case, capsys):
    """A value stated with an option is known, not a starting guess: --time-offset fixes the
    offset, --orientation the mapping (the JSON's wrong YXz is overridden), in calibrate and
    in deblur --refine alike."""
    _, true, _ = case
    d = cli_dir
    out = d / "out" / "given.json"
    assert main(["calibrate", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
                 "--time-offset", "0.004", "--orientation", TRUE_AXES, "--fix", "bias",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    cap = load_capture(out)
    assert cap.time_offset == pytest.approx(0.004)
    assert axes_to_letters(cap.axes) == TRUE_AXES
    assert " 1 axis mapping" in text             # one mapping given: no search over 24
    refined = d / "out" / "refined_given.png"
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"), "--refine",
                 "--time-offset", "0.004", "--fix", "axes,bias", "--grid", "2x3", "--quiet",
                 "-o", str(refined)]) == 0
    text = capsys.readouterr().out
    assert "time offset" in text and "(fixed)" in text and refined.exists()


def test_cli_offset_range_reaches_the_search_and_needs_a_free_offset(cli_dir, capsys):
    d = cli_dir
    out = d / "out" / "wide.png"
    assert main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"), "--refine",
                 "--offset-range", "0.1", "--fix", "axes,bias,focal,readout", "--orientation",
                 TRUE_AXES, "--grid", "2x3", "--quiet", "-o", str(out)]) == 0
    assert "searching time offsets within +-100 ms of the given one" in capsys.readouterr().out
    rc = main(["calibrate", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
               "--time-offset", "0.004", "--offset-range", "0.04", "-o", str(d / "out" / "w.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "--offset-range" in err and "time offset is fixed" in err
    assert not (d / "out" / "w.json").exists()


def test_cli_fix_needs_refine(cli_dir, capsys):
    d = cli_dir
    rc = main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"), "--fix",
               "offset", "-o", str(d / "out" / "nofix.png")])
    assert rc == 2 and "--refine" in capsys.readouterr().err


@pytest.mark.parametrize("option, value, bad, says", [("--downscale", "0.5", "2", "(0, 1]"),
                                                     ("--workers", "2", "0", ">= 1"),
                                                     ("--offset-range", "0.1", "-1", "(0, 5]")])
def test_cli_calibration_options_need_refine_and_a_valid_value(cli_dir, capsys, option, value,
                                                               bad, says):
    d = cli_dir
    rc = main(["deblur", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
               option, value, "-o", str(d / "out" / "norefine.png")])
    assert rc == 2 and "--refine" in capsys.readouterr().err
    rc = main(["calibrate", str(d / "blurred.png"), "--capture", str(d / "cap.json"),
               option, bad, "-o", str(d / "out" / "bad.json")])
    err = capsys.readouterr().err
    assert rc == 2 and option in err and says in err
    assert not (d / "out" / "bad.json").exists()


def _noisy(cap: Capture, sigma: float, seed: int = 0) -> Capture:
    rng = np.random.default_rng(seed)
    log = cap.log
    return cap.replace(log=GyroLog(log.t, log.omega + rng.normal(0, sigma, log.omega.shape)))


def test_keep_margin_grows_with_gyro_noise():
    from gyrodeblur.calibrate import _KEEP_MARGIN, _keep_margin
    assert _keep_margin(float("nan")) == _keep_margin(0.002) == _KEEP_MARGIN
    assert _keep_margin(0.021) == pytest.approx(3 * _KEEP_MARGIN)


def test_the_uncertainties_are_the_laplace_posteriors_marginals():
    """One-sigma figures are the marginals of the posterior ``N(x, F^-1)`` (``F`` the
    tempered Hessian, priors included) of the reported quantities: draws of ``x`` mapped
    by the search's own parametrisation (:meth:`SearchSpace.theta_of`) to a time offset
    (the time shift at the pivot row plus ``ubar`` times the readout correction, strongly
    anti-correlated here), a readout, a focal scale and a bias have those sds. Neither
    the Hessian's own diagonal nor the offset's variance without the readout's share
    gives them."""
    from gyrodeblur.calibrate import _uncertainties
    from gyrodeblur.calibration_search import SearchSpace

    sd = np.array([0.001, 0.002, 0.03, 0.01, 0.02, 0.005])
    corr = np.eye(6)
    corr[0, 1] = corr[1, 0] = -0.6              # time shift against readout
    corr[2, 3] = corr[3, 2] = 0.5               # focal length against a bias
    x = np.array([0.002, 0.003, 0.2, 0.01, -0.02, 0.0])      # focal x1.22
    ubar = 0.4
    rng = np.random.default_rng(0)
    for idx in ([0, 1, 2, 3, 4, 5], [0, 2, 3, 4, 5], [1, 2, 3]):
        cov = (corr * np.outer(sd, sd))[np.ix_(idx, idx)]
        unc = _uncertainties(x, idx, np.linalg.inv(cov), None, ubar)
        v = np.tile(x, (40000, 1))
        v[:, idx] = rng.multivariate_normal(x[idx], cov, 40000)
        th = [SearchSpace.theta_of(None, row, np.eye(3), ubar) for row in v]
        want = {"offset": np.std([t.offset for t in th]),
                "readout": np.std([t.readout for t in th]),
                "focal": np.std([t.focal for t in th])}
        want.update({f"bias{k}": np.std([t.bias[k] for t in th]) for k in range(3)})
        names = ("offset", "readout", "focal", "bias0", "bias1", "bias2")
        assert set(unc) == {names[j] for j in idx}
        for name, got in unc.items():
            assert got == pytest.approx(want[name], rel=0.03), (idx, name, got, want[name])


def test_the_prior_distance_is_measured_from_the_priors_centre():
    """How far the estimates lie from the given values is counted in prior sds from the
    priors' centres, which are not always zero corrections (an unknown readout's 20 ms
    under a given 0, a long log's bias): at the centre it is 0, a sd off on each of the
    readout, focal length and one bias axis it is 3 (the time offset has no prior and
    does not count)."""
    from types import SimpleNamespace

    from gyrodeblur.calibrate import _prior_distance
    mu = np.array([0.0, 0.02, 0.0, 0.03, -0.01, 0.0])
    sig = np.array([np.inf, 0.012, 0.1, 0.005, 0.005, 0.05])
    fit = SimpleNamespace(idx=[0, 1, 2, 3, 4, 5], prior_for=lambda M: (mu, sig, 100.0))
    assert _prior_distance(fit, np.eye(3), mu) == pytest.approx(0.0, abs=1e-12)
    off = mu + np.array([0.01, 0.012, -0.1, 0.0, 0.005, 0.0])
    assert _prior_distance(fit, np.eye(3), off) == pytest.approx(3.0)


def test_gyro_noise_is_measured_per_sample_at_200_hz():
    """The angle white rate noise adds over an exposure grows with sigma sqrt(dt): a 1 kHz
    log with sqrt(5) times the per-sample noise of a 200 Hz one blurs PSFs as much, and
    its level (what raises the keep margin) is the same."""
    from gyrodeblur.calibrate import _gyro_noise_level
    rng = np.random.default_rng(3)

    def level(rate, sigma):
        t = np.arange(0.0, 1.2, 1 / rate)
        log = GyroLog(t, 0.2 * np.sin(2 * np.pi * 2 * t)[:, None] + rng.normal(0, sigma, (t.size, 3)))
        return _gyro_noise_level([_true_capture(0.5, log)])

    slow, fast = level(200, 0.02), level(1000, 0.02 * np.sqrt(5))
    assert slow == pytest.approx(0.02, rel=0.1)
    assert fast == pytest.approx(slow, rel=0.1)
    assert level(1000, 0.02) == pytest.approx(0.02 / np.sqrt(5), rel=0.1)


def test_keep_margin_shrinks_with_fewer_free_coordinates(case):
    """With all six continuous coordinates free the margin is 10 nats; with fewer, the
    same odds of moving a right capture by chance (twice the gain ~ chi-square with
    ``n_free`` degrees of freedom): 4.48 for one, 7.05 for three; the noise scaling on
    top. A calibration with only the offset free uses the one-coordinate margin."""
    from scipy.stats import chi2

    from gyrodeblur.calibrate import _KEEP_MARGIN, _keep_margin
    margins = [_keep_margin(float("nan"), k) for k in range(1, 7)]
    assert margins[-1] == _KEEP_MARGIN and np.all(np.diff(margins) > 0)
    assert margins[0] == pytest.approx(4.48, abs=0.01) and margins[2] == pytest.approx(7.05, abs=0.01)
    odds = [chi2.sf(2 * m, k) for k, m in enumerate(margins, 1)]
    assert np.allclose(odds, odds[-1], rtol=1e-6)
    assert _keep_margin(0.021, 1) == pytest.approx(3 * margins[0])
    _, true, blurred = case
    res = calibrate([blurred], true, fix=set(PARAMETERS) - {"offset"})
    assert any("kept the given parameters" in n and "(< 4.48)" in n for n in res.notes), res.notes


def test_noisy_gyro_keeps_a_correct_capture_but_still_fixes_an_offset(case):
    sharp, true, blurred = case
    noisy = _noisy(true, 0.03)
    res = calibrate([blurred], noisy)
    level = [float(n.split()[2]) for n in res.notes if n.startswith("gyro noise")]
    assert level and level[0] == pytest.approx(0.03, rel=0.15)
    assert any("kept the given parameters" in n for n in res.notes)
    assert res.capture.time_offset == noisy.time_offset
    # kept by the raised margin where a quiet gyro's would have moved it: said
    raised = [n for n in res.notes if "kept only because the gyro log reads as noisy" in n]
    gain = float(next(n for n in res.notes if "kept the given" in n).split("by only ")[1].split()[0])
    from gyrodeblur.calibrate import _keep_margin
    assert bool(raised) == (gain >= _keep_margin(float("nan"))), res.notes
    off = calibrate([blurred], noisy.replace(time_offset=noisy.time_offset + 0.012)).capture
    assert abs(off.time_offset - true.time_offset) < 0.003


def test_a_capture_the_photo_rejects_is_not_kept_whatever_the_margin(case, monkeypatch):
    """The keep margin protects a right capture from a fit that follows noise; it must not
    keep one whose PSFs explain the photo worse than no blur at all (a held-out audit: a
    noisy 100 Hz log 12 ms off, kept under a margin of 22 though the best found was 0.6 ms
    off, deblurred below its input). With the margin made endless, a right capture is
    still kept and one 15 ms off is still corrected."""
    import gyrodeblur.calibrate as cal
    _, true, blurred = case
    monkeypatch.setattr(cal, "_keep_margin", lambda noise, n_free=6: 1e9)
    res = calibrate([blurred], true)
    assert any("kept the given parameters" in n for n in res.notes), res.notes
    assert res.capture.time_offset == true.time_offset
    off = true.replace(time_offset=true.time_offset + 0.015)
    res = calibrate([blurred], off)
    said = [n for n in res.notes if "the given parameters are not kept" in n]
    assert said and "no blur at all explains the photo better" in said[0], res.notes
    assert abs(res.capture.time_offset - true.time_offset) < 0.003


def test_the_rejection_needs_a_bad_given_capture_and_a_good_found_one(monkeypatch):
    """The thresholds of the rule, per photo of a session: the given parameters are let go
    only where some photo scores them below WRONG_BLUR_MARGIN against no blur and the
    best found scores at least NO_BLUR_MARGIN on every photo; the note names that photo."""
    from types import SimpleNamespace

    import gyrodeblur.calibrate as cal
    from gyrodeblur.blur_evidence import NO_BLUR_MARGIN, WRONG_BLUR_MARGIN
    monkeypatch.setattr(cal, "_gains_per_photo", lambda spectra, theta, n: np.asarray(theta))
    fit = SimpleNamespace(fine=None, ubar=0.5)
    search = SimpleNamespace(theta_of=lambda x, M, ubar: x)
    bad, good = WRONG_BLUR_MARGIN - 0.1, NO_BLUR_MARGIN + 0.1

    def rule(given, found):
        return cal._rejected_by_photos(fit, search, given, None, found, None, len(given))

    assert "photo 2 better" in rule([3.0, bad], [good, 9.0])
    assert "explains the photo better" in rule([bad], [good])
    assert rule([3.0, WRONG_BLUR_MARGIN + 0.1], [good, 9.0]) == ""    # not bad enough
    assert rule([3.0, bad], [NO_BLUR_MARGIN - 0.1, 9.0]) == ""        # found not good enough
    assert rule([np.nan, bad], [np.nan, good]) != ""                   # a photo without patches
    assert rule([np.nan], [np.nan]) == ""


def test_parameters_kept_only_for_a_noisy_gyro_are_warned_of(case, monkeypatch):
    """Given parameters that a quiet gyro's margin would have moved, kept only because the
    log reads as noisy (a 50-100 Hz log's own motion can read so), get a warning naming
    the offset found; a gain a quiet gyro's margin would not take either gets none."""
    import gyrodeblur.calibrate as cal
    _, true, blurred = case
    monkeypatch.setattr(cal, "_gyro_noise_level", lambda captures: 0.2)
    res = calibrate([blurred], true.replace(time_offset=true.time_offset + 0.006))
    assert res.capture.time_offset == pytest.approx(true.time_offset + 0.006)
    said = [n for n in res.notes if "kept only because the gyro log reads as noisy" in n]
    assert said and said[0].startswith("warning:") and "time offset" in said[0], res.notes
    res = calibrate([blurred], true.replace(time_offset=true.time_offset + 0.003))
    gain = float(next(n for n in res.notes if "kept the given" in n).split("by only ")[1].split()[0])
    assert gain < cal._keep_margin(float("nan"))
    assert not any("reads as noisy" in n for n in res.notes), res.notes


def test_cli_capture_may_be_repeated_per_photo(cli_dir, capsys):
    d = cli_dir
    rc = main(["calibrate", str(d / "blurred.png"), str(d / "blurred.png"),
               "--capture", str(d / "cap.json"), "--capture", str(d / "cap.json"),
               "--capture", str(d / "cap.json"), "-o", str(d / "out" / "r.json")])
    assert rc == 2                                   # three for two photos: counted, refused
    assert "3 capture descriptions for 2 photos" in capsys.readouterr().err
    # one for each photo: read and paired, as the one description given for both
    from gyrodeblur.imageio import read_photo, write_photo

    first = read_photo(d / "blurred.png").pixels
    noise = np.random.default_rng(8).normal(0, 2 / 255, first.shape).astype(np.float32)
    write_photo(d / "again.png", np.clip(first + noise, 0, 1), bit_depth=8)
    photos = [str(d / "blurred.png"), str(d / "again.png")]
    doc = json.loads((d / "cap.json").read_text())
    doc["exposure_start"] += 2e-4                            # exposed a little later
    (d / "again.json").write_text(json.dumps(doc))
    fix = ["--fix", "bias,readout,focal,axes"]
    assert main(["calibrate", *photos, "--capture", str(d / "cap.json"), "--capture",
                 str(d / "again.json"), *fix, "-o", str(d / "out" / "each.json")]) == 0
    assert main(["calibrate", *photos, "--capture", f"{d / 'cap.json'},{d / 'again.json'}",
                 *fix, "-o", str(d / "out" / "listed.json")]) == 0
    assert (json.loads((d / "out" / "each.json").read_text())
            == json.loads((d / "out" / "listed.json").read_text()))
    # one description for both (given once, or twice) starts them at one time: a
    # session's photos are taken at different times, so it is refused before any work
    capsys.readouterr()
    for given in (["--capture", str(d / "cap.json")],
                  ["--capture", str(d / "cap.json"), "--capture", str(d / "cap.json")]):
        assert main(["calibrate", *photos, *given, *fix,
                     "-o", str(d / "out" / "shared.json")]) == 2
        err = capsys.readouterr().err
        assert "--capture: photos 1 and 2 start exposing at the same time" in err, err
        assert "one capture description per photo" in err
    assert not (d / "out" / "shared.json").exists()


def test_an_exif_exposure_start_is_searched_a_second_either_way(case, monkeypatch):
    """A capture whose exposure start is its photo's EXIF time is searched +-1 s (the
    default +-40 ms would miss a phone's EXIF time; +-1.5 s around the middle of a time to
    the second), and says why; a range given, or the
    offset fixed, rule. A session with such a start is refused unless the offset is
    fixed: no one offset fits photos whose EXIF times are each off by their own amount.
    The corrected capture is no longer marked."""
    import gyrodeblur.calibrate as cal

    class Stop(Exception):
        pass

    asked = []
    real_search_space = cal.SearchSpace

    def search_space(photos, fix, offset_range):
        asked.append(offset_range)
        return real_search_space(photos, fix, offset_range)

    def stop(*args, **kwargs):                  # after the range is said, before the work
        raise Stop

    _, true, blurred = case
    exif = true.replace(exposure_start_from_exif=True)
    to_the_second = exif.replace(exif_time_to_the_second=True)
    later = true.replace(exposure_start=true.exposure_start + 0.5)
    monkeypatch.setattr(cal, "SearchSpace", search_space)
    monkeypatch.setattr(cal, "CalibrationFit", stop)
    said = []
    for captures, kwargs, span in (([exif], {}, cal.EXIF_START_OFFSET_RANGE),
                                   ([to_the_second], {}, cal.EXIF_WHOLE_SECOND_OFFSET_RANGE),
                                   ([true], {}, cal.DEFAULT_OFFSET_RANGE),
                                   ([exif], {"offset_range": 0.3}, 0.3),
                                   ([exif], {"fix": "offset"}, cal.DEFAULT_OFFSET_RANGE),
                                   ([later, exif], {"fix": "offset"}, cal.DEFAULT_OFFSET_RANGE)):
        with pytest.raises(Stop):
            calibrate([blurred, blurred[::-1]][:len(captures)], captures, say=said.append,
                      **kwargs)
        assert asked[-1] == span
        why = [m for m in said if "EXIF" in m and "--offset-range sets another range" in m]
        assert bool(why) == (span in (cal.EXIF_START_OFFSET_RANGE,
                                      cal.EXIF_WHOLE_SECOND_OFFSET_RANGE)), said
        # a start the log cuts short may be the log's nearest covered one, not EXIF's own
        assert all("or the nearest one the log covers" in m for m in why
                   if "covers the exposure only" in m), why
        said.clear()
    # a session: each EXIF time is off by its own amount, which no shared offset fits
    with pytest.raises(InputError, match="^captures: photo 2 of this session starts at the "
                                         "EXIF capture time.*one at a time"):
        calibrate([blurred, blurred[::-1]], [later, exif])
    monkeypatch.undo()
    corrected = calibrate([blurred], to_the_second, fix="axes,focal,readout,bias").capture
    assert not (corrected.exposure_start_from_exif or corrected.exif_time_to_the_second)


def test_cli_writes_each_photo_its_corrected_description(cli_dir, capsys, monkeypatch):
    """-o once per photo (like --capture): each output is its own photo's description,
    with its own exposure start, and the shared corrections. Counts that do not pair, and
    one file named twice, are refused before any work; a failed write leaves none."""
    d = cli_dir
    common = _session_of_two(d, "later.png", "cap2.json") + ["--fix", "bias,readout,focal,axes"]
    a, b = d / "out" / "a.json", d / "out" / "b.json"
    assert main(["calibrate", *common, "-o", str(a), "-o", str(b)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {a}, {b}" in out and "give one -o per photo" not in out
    ca, cb = json.loads(a.read_text()), json.loads(b.read_text())
    assert cb["exposure_start"] - ca["exposure_start"] == pytest.approx(2e-4, abs=1e-9)
    given = json.loads((d / "cap.json").read_text())
    assert ca["exposure_start"] == given["exposure_start"]
    assert ca["gyro"]["time_offset"] != given["gyro"]["time_offset"]     # corrected ...
    for key in ("readout_time", "camera", "gyro"):                        # ... alike
        assert ca[key] == cb[key], key
    # one output: the first photo's, and the way to the others said
    assert main(["calibrate", *common, "-o", str(d / "out" / "one.json")]) == 0
    assert "give one -o per photo" in capsys.readouterr().out
    assert json.loads((d / "out" / "one.json").read_text()) == ca
    # refused before the work
    for outs, said in (([str(d / "out" / "x.json")] * 2, "is named twice as an output"),
                       ([",".join(str(d / "out" / f"{k}.json") for k in "xyz")],
                        "3 outputs for 2 photos")):
        assert main(["calibrate", *common, *[v for o in outs for v in ("-o", o)]]) == 2
        assert said in capsys.readouterr().err
    assert not (d / "out" / "x.json").exists()
    # a failure writing the second removes the first
    save = Capture.save

    def full_disk(self, path, *args, **kwargs):
        if "q.json" in str(path):
            raise InputError(path, "cannot write the file: No space left on device")
        return save(self, path, *args, **kwargs)

    monkeypatch.setattr(Capture, "save", full_disk)
    p, q = d / "out" / "first.json", d / "out" / "q.json"
    assert main(["calibrate", *common, "-o", f"{p},{q}"]) == 2
    assert "No space left" in capsys.readouterr().err
    assert not p.exists() and not q.exists()
    p.write_text("OLD")                               # nor over a file --overwrite allows
    assert main(["calibrate", *common, "-o", f"{p},{q}", "--overwrite"]) == 2
    assert p.read_text() == "OLD" and not q.exists()
    monkeypatch.setattr(Capture, "save", save)         # a move refused: said, not a traceback
    real_replace = os.replace

    def refused(src, dst):
        if str(dst).endswith("q.json"):
            raise PermissionError(1, "Operation not permitted")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", refused)
    assert main(["calibrate", *common, "-o", f"{p},{q}", "--overwrite"]) == 2
    assert f"{q}: cannot write the file: Operation not permitted" in capsys.readouterr().err
    monkeypatch.setattr(os, "replace", real_replace)
    assert sorted(f.name for f in (d / "out").iterdir() if f.name.startswith(".")) == []
    for f in (a, b, d / "out" / "one.json", p):      # the folder is shared with other tests
        f.unlink()


def test_the_real_shield_capture_is_calibrated_from_its_frames(shared_data):
    """The real Shield-tablet pan (examples/shield-tablet): from the published focal length,
    no time offset and the wrong one of the two proper mappings next to the published matrix,
    the five frames inside the log calibrated together find what was worked out by hand: the
    mapping ``yxz`` and a time offset near +17.6 ms. (Two frames are not enough for the
    offset: this pan is nearly uniform.) The focal length is known only roughly: the
    capture's authors published 1558.69 px, the frames' registration gives ~2010 px. The
    blur's lies between the two: 1915 px with three rows of each patch's centre, 1862 px
    with 2 x 2 points across each patch (session 51)."""
    from pathlib import Path

    from gyrodeblur.imageio import read_photo

    data = shared_data / "real" / "shield-tablet"
    example = Path(__file__).resolve().parents[1] / "examples" / "shield-tablet"
    base = load_capture(example / "capture_0003.json",
                        overrides={"gyro_path": str(data / "sensor_events.txt")})
    starts = [int(line.split()[0]) * 1e-9
              for line in (data / "frames.txt").read_text().splitlines() if line.strip()]
    frames = (2, 3, 4, 5, 6)
    photos = [read_photo(data / f"{k:04d}.jpg").pixels for k in frames]
    caps = [base.replace(exposure_start=starts[k - 1], axes=parse_axes("YXz"), time_offset=0.0,
                         camera=base.camera.with_focal_scale(1558.69 / base.camera.fx))
            for k in frames]
    res = calibrate(photos, caps)
    got = res.capture
    assert axes_to_letters(got.axes) == "yxz", res.notes
    assert 1558.69 < got.camera.fx < 2010.0 * 1.05, got.camera.fx
    off, sigma = res.estimates["offset"][1:]
    assert sigma < 0.008, sigma                           # pinned, not just allowed
    assert abs(off - 0.0176) < max(3 * sigma, 0.006), (off, sigma)


def test_a_photo_softer_than_its_pixels_is_calibrated_shrunk(case):
    """The test photo upscaled x2 (nothing above a quarter cycle per pixel) with its capture
    scaled alike: ``downscale=0.5`` calibrates it as well as the original, and the corrected
    capture keeps the upscaled photo's resolution. (At full size it takes the mapping YxZ:
    the empty top octave reads as blur.)"""
    import cv2

    _, true, blurred = case
    big = cv2.resize(blurred, (2 * W, 2 * H), interpolation=cv2.INTER_LINEAR)
    true2 = true.scaled_to(2 * W, 2 * H)
    res = calibrate([big], _corrupt(true2), downscale=0.5)
    got = res.capture
    assert (got.camera.width, got.camera.height) == (2 * W, 2 * H)
    assert axes_to_letters(got.axes) == TRUE_AXES
    assert abs(got.time_offset - true.time_offset) < 0.003
    assert abs(got.camera.fx / true2.camera.fx - 1) < 0.06
    with pytest.raises(InputError, match="downscale"):
        calibrate([blurred], true, downscale=1.5)
    with pytest.raises(InputError, match="too small"):
        calibrate([blurred], true, downscale=0.1)


def test_a_long_log_lends_its_typical_rate_as_the_bias(case):
    """Hand motion averages out over seconds of log and a gyro's bias does not: with 20 s
    of log, the bias comes out within 0.01 rad/s per axis (and its stated uncertainty)
    from a capture that gives a wrong one, where 1.2 s of log (no prior from it) leaves it
    several times further off.
    (A mapping that is not its own transpose and a given bias that is not zero: the log's
    rate must be turned into the camera frame the right way round, and the correction
    measured from the given bias.)"""
    sharp = case[0]
    b = np.array([0.045, -0.04, 0.03])
    log = _long_log(20.0, b, "yZx")
    true = Capture(10.0, 0.04, 0.03, Camera.centred(W, H, 1.3 * W), log, axes="yZx", bias=b)
    blurred = _blur(sharp, true)
    bad = _corrupt(true, bias=(-0.04, 0.04, -0.03))
    res = calibrate([blurred], bad)
    assert any("a prior on the bias" in note for note in res.notes), res.notes
    assert axes_to_letters(res.capture.axes) == "yZx"
    err_long = np.abs(res.capture.bias - b)
    assert np.all(err_long < 0.01), err_long
    assert np.all(err_long < 3 * np.asarray(res.estimates["bias"][2])), res.estimates["bias"]
    short = calibrate([blurred], bad.replace(log=log.window(9.4, 10.6), axes=true.axes),
                      fix={"axes"})          # the mapping given: the contrast is the prior's
    assert not any("prior on the bias" in note for note in short.notes)
    assert np.max(np.abs(short.capture.bias - b)) > 2 * np.max(err_long)


def test_a_long_log_that_bears_the_given_bias_out_leaves_it(case):
    """A 20 s log in which the hand also turned steadily by 9 degrees (8 mrad/s): with the
    right bias given, the log's typical rate agrees with it within the log's error, so the
    given bias stays rather than taking up the turn."""
    sharp = case[0]
    b = np.array([0.045, -0.04, 0.03])
    log = _long_log(20.0, b, "yZx", turn=(0.008, 0.0, 0.0))
    true = Capture(10.0, 0.04, 0.03, Camera.centred(W, H, 1.3 * W), log, axes="yZx", bias=b)
    res = calibrate([_blur(sharp, true)], true, fix=("offset", "readout", "focal", "axes"))
    assert any("a prior on the bias" in note for note in res.notes)
    assert np.all(np.abs(res.capture.bias - b) < 0.002), res.capture.bias - b


def test_a_log_that_pans_throughout_is_not_read_as_a_bias(case):
    sharp = case[0]
    log = _log(20.0, pan=(0.0, 0.3, 0.0))
    true = _true_capture(10.0, log)
    res = calibrate([_blur(sharp, true)], true, fix=("offset", "readout", "focal", "axes"))
    assert any("is motion, not a bias" in note for note in res.notes)
    assert not any("prior on the bias" in note for note in res.notes)
    assert np.all(np.abs(res.capture.bias) < 0.03)


def _with_errors(true: Capture, offset: float, readout: float, focal: float, bias,
                 axes: str) -> Capture:
    """``true`` as the calibration benchmark corrupts it: the time offset moved by
    ``offset`` (s), the readout time and focal length scaled by ``readout`` and ``focal``,
    ``bias`` (rad/s, the log's axes) added, the axis mapping replaced by ``axes``."""
    return true.replace(time_offset=true.time_offset + offset,
                        readout_time=true.readout_time * readout,
                        camera=true.camera.with_focal_scale(focal),
                        bias=np.asarray(true.bias) + bias, axes=parse_axes(axes))


def test_a_mapping_that_the_given_bias_hides_is_found_by_a_widened_ranking(shared_data):
    """A benchmark photo (lai_manmade_02, its first shake window: 7 px of blur) given the
    calibration benchmark's errors for it, among them a bias 0.045 rad/s off along y. At
    that bias the right mapping ranks 19th of 24 in the coarse search (fitted envelope) and
    is never refined; the best candidates are within a few nats of each other, so the
    coarse ranking is run again with the bias moved by one prior sd each way, which ranks
    the right mapping first. Before, the calibration ended at a wrong mapping (``XZy``)
    16.5 ms off."""
    from gyrodeblur.dataset import build_cases

    case = build_cases([shared_data / "photos" / "lai_manmade_02.png"],
                       shared_data / "gyro" / "handheld_phone_210hz.csv",
                       windows_per_photo=2)[0]
    true = case.capture
    given = _with_errors(true, -0.0198, 1.169, 0.926, [-0.013, -0.045, 0.044], "YZX")
    lines = []
    res = calibrate([case.blurred], given, say=lines.append)
    assert axes_to_letters(res.capture.axes) == axes_to_letters(true.axes), res.notes
    assert abs(res.capture.time_offset - true.time_offset) < 0.003
    assert any("within" in line and "coarse ranking with the bias moved" in line
               for line in lines), lines
    # found only that way: reported uncertain, as close as the first candidates were
    assert any("won only once the search moved the bias" in n for n in res.notes), res.notes
    assert res.estimates["axes"][2] < 8.0
    assert res.prior_distance < 5 and not any("lie far" in n for n in res.notes)


def test_a_confident_wrong_mapping_gives_way_to_one_the_moved_bias_ranks_first(shared_data):
    """A smoother, gentler hand shake than the shared log's (a synthetic one: sway and
    tremor bands, median rate 0.35 rad/s) on lai_manmade_02 (its second window: 11 px of
    blur), given a bias 0.043 rad/s off along the log's y and the other errors the
    calibration benchmark drew for it. At that bias the right mapping ranks 4th of 24 by
    the fitted envelope and below the 6th by the flat one, so it is never refined, and a
    wrong one (``zYX``) wins by 37 nats over the next: confidently enough that the first
    widening (candidates within 8 nats) never runs. With the bias moved by a prior sd the
    right mapping ranks first, better than any mapping at the given bias, and wins."""
    from gyrodeblur.dataset import build_cases
    from gyrodeblur.shake import synthetic_hand_shake

    log = synthetic_hand_shake(180.0, 200.0, seed=34, sway_rms=(0.2, 0.24, 0.1),
                               tremor_rms=(0.16, 0.16, 0.08), sensor_noise=0.003)
    case = build_cases([shared_data / "photos" / "lai_manmade_02.png"], log,
                       windows_per_photo=2)[1]
    true = case.capture
    given = _with_errors(true, 0.0274, 0.986, 1.043, [0.018, -0.043, 0.009], "ZXY")
    lines = []
    res = calibrate([case.blurred], given, say=lines.append)
    assert axes_to_letters(res.capture.axes) == axes_to_letters(true.axes), res.notes
    assert abs(res.capture.time_offset - true.time_offset) < 0.003
    assert any("better with the bias moved than any mapping at the given one" in line
               for line in lines), lines
    assert res.estimates["axes"][2] >= 8.0          # won by a wide margin: not flagged
    assert res.prior_distance < 5 and not any("lie far" in n for n in res.notes)


def test_the_benchmark_fence_is_flagged_exactly_when_its_estimates_lie_far(shared_data):
    """The calibration benchmark's one wrong mapping: lai_manmade_03 (its first window,
    24 px of blur along a fence of vertical bars) given the benchmark's errors for it. The
    far-estimates warning is given exactly when the squared z-scores pass chi-square's
    95 % quantile. Until session 50 the wrong mapping explained the blur there by moving
    bias, readout and focal length well over a prior sd each (about 12-15.5) and was
    flagged; with the search's 2 x 2 points per patch (session 51) it moves them less
    (about 9) and goes unflagged: a periodic texture fools the search outright.
    (:func:`test_estimates_far_from_the_priors_are_weighed_against_the_free_coordinates`
    tests the warning on a scripted search.)"""
    from scipy.stats import chi2

    from gyrodeblur.dataset import build_cases

    case = build_cases([shared_data / "photos" / "lai_manmade_03.png"],
                       shared_data / "gyro" / "handheld_phone_210hz.csv",
                       windows_per_photo=2)[0]
    true = case.capture
    given = _with_errors(true, -0.0251, 1.133, 0.944, [-0.024, 0.036, 0.009], "xzy")
    res = calibrate([case.blurred], given)
    flagged = any("lie far from the given values" in n for n in res.notes)
    assert flagged == (res.prior_distance > chi2.ppf(0.95, 5))
    # as now: the criterion's failure. A criterion that gets this photo right fails this
    # line (then say so in the docstring and the README, and assert the right mapping)
    assert axes_to_letters(res.capture.axes) != axes_to_letters(true.axes), res.notes


def test_the_widened_ranking_takes_each_mappings_best_bias_step(case):
    """Given a bias 0.05 rad/s off along x, the coarse rows over the eight bias steps of one
    prior sd keep, per mapping, the step that undoes the error (the truth's blur), and score
    it better than the given bias does."""
    from gyrodeblur.calibrate import _bias_steps
    _, true, blurred = case
    given = true.replace(bias=np.asarray(true.bias) + [0.05, 0.0, 0.0])
    photos = [CalibrationPhoto(blurred, given, "srgb", 0)]
    prior = BiasPrior(np.zeros(3))
    fit = CalibrationFit(photos, SearchSpace(photos, set(), 0.04), set(), prior, 9, 1,
                         lambda msg: None)
    steps = _bias_steps(prior, true.axes)
    want = {(0.05 * i, 0.05 * j, 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j}
    assert len(steps) == 8 and {tuple(np.round(s, 12)) for s in steps} == want
    (row,), = fit.coarse_rankings([true.axes], StepRunner(fit, 1), bias_steps=steps,
                                  envelopes=(True,), stride=2)
    np.testing.assert_allclose(row[6], [-0.05, 0.0, 0.0])
    assert row[0] < fit.coarse_row(True, true.axes, None, 2)[0]


def test_a_straight_blur_leaves_the_mirror_twin_uncertain(case):
    """A steady turn about an axis in the x-y plane blurs every pixel along a straight,
    even streak, and a streak is its own reflection: the mirror twin (x and y rates
    negated) explains the photo exactly as well, and nothing in it tells the two apart.
    The other mappings turn or roll the streaks. Calibrate says the mapping is uncertain,
    naming the twin, whichever of the two it took."""
    sharp, _, _ = case
    t = np.arange(0.0, 1.2, 1 / 200)
    wc = np.tile([0.35, -0.5, 0.0], (t.size, 1))
    log = GyroLog(t, wc @ parse_axes(TRUE_AXES))
    true = Capture(0.5, 0.03, 0.0, Camera.centred(W, H, 1.3 * W), log, axes=TRUE_AXES)
    res = calibrate([_blur(sharp, true)], _corrupt(true, offset=0.0, readout=1.0))
    got = axes_to_letters(res.capture.axes)
    assert got in (TRUE_AXES, axes_to_letters(TWIN @ true.axes)), res.notes
    other = axes_to_letters(TWIN @ res.capture.axes)
    assert any("axis mapping is uncertain" in n and f"mirror twin {other}" in n
               for n in res.notes), res.notes
    assert format_estimates(res.estimates)[-1].endswith("uncertain)")


def test_cli_a_photo_that_needs_turning_is_told_so_whatever_the_others_rotation(cli_dir,
                                                                                capsys):
    """Two portrait exports, only the second said to be turned: the first is told it looks
    turned by 90 degrees (its own rotation is 0), not to leave the option out."""
    from gyrodeblur.imageio import read_photo, write_photo

    d = cli_dir
    first = read_photo(d / "blurred.png").pixels
    write_photo(d / "portrait1.png", np.rot90(first, -1), bit_depth=8)
    noise = np.random.default_rng(9).normal(0, 2 / 255, first.shape).astype(np.float32)
    write_photo(d / "portrait2.png", np.rot90(np.clip(first + noise, 0, 1), -1), bit_depth=8)
    rc = main(["calibrate", str(d / "portrait1.png"), str(d / "portrait2.png"), "--capture",
               str(d / "cap.json"), "--photo-rotation", "0,90", "-o", str(d / "out" / "p.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "portrait1.png" in err and "turned by 90 degrees" in err, err
    assert "leave the option out" not in err


def test_a_readout_not_given_is_searched_not_held_at_a_global_shutter(case):
    """A description without ``readout_time`` (a phone user's) loads as 0 marked unknown;
    calibrate then searches readouts of 0-50 ms under a weak prior and finds the true 30 ms,
    with the offset and mapping. The same 0 given as a global shutter is held near 0 by
    its prior, which is what the mark changes."""
    _, true, blurred = case
    bad = _corrupt(true, readout=0.0)
    lines = []
    res = calibrate([blurred], bad.replace(readout_time_unknown=True), say=lines.append)
    got = res.capture
    assert any("readout time not given: searching 0-50 ms" in line for line in lines)
    assert axes_to_letters(got.axes) == TRUE_AXES
    assert abs(got.time_offset - true.time_offset) < 0.003
    assert abs(got.readout_time - true.readout_time) < 0.008
    assert not got.readout_time_unknown
    assert res.estimates["readout"][2] is not None
    held = calibrate([blurred], bad, fix={"axes", "offset"}).capture
    assert held.readout_time < 0.01, held.readout_time
    # a readout not given and fixed (not estimated) is still not known afterwards: saved,
    # it is left out, not written as a global shutter's 0
    kept = calibrate([blurred], bad.replace(readout_time_unknown=True),
                     fix={"axes", "readout", "focal", "bias"}).capture
    assert kept.readout_time == 0.0 and kept.readout_time_unknown
    assert "readout_time" not in kept.to_dict()
    # a session shares one readout correction: one photo's readout given, another's not
    later = _true_capture(0.8)
    with pytest.raises(InputError, match="photo 2's capture gives no readout_time while the other descriptions"):
        calibrate([blurred, _blur(_sharp(), later)],
                  [bad, later.replace(readout_time=0.0, readout_time_unknown=True)])


@pytest.mark.parametrize("offset", [-0.012, 0.0, 0.008])
def test_a_readout_not_given_does_not_hide_an_offset_error(case, offset):
    """With no readout given, the given time offset held with a longer or shorter readout
    keeps the middle rows' times right, and explained the photo nearly as well as the
    true capture (a held-out audit: 12 ms off, kept with a readout of 45 ms for a true 25,
    19.9 dB against 30.1). The given parameters are judged at their best readout within
    6 ms of the best found's: offsets 12 ms early or 8 ms late are found, not kept (they
    were kept with readouts of 12 and 44 ms for the true 30); a right one is kept."""
    _, true, blurred = case
    bad = _corrupt(true, offset=offset, readout=0.0, focal=1.0, bias=(0.0, 0.0, 0.0),
                   axes=TRUE_AXES).replace(readout_time_unknown=True)
    res = calibrate([blurred], bad, fix={"axes"})
    got = res.capture
    assert res.kept_given == (offset == 0.0)
    assert abs(got.time_offset - true.time_offset) < 0.003, got.time_offset - true.time_offset
    assert abs(got.readout_time - true.readout_time) < 0.008, got.readout_time


def test_cli_one_exposure_start_for_several_photos_is_refused(cli_dir, capsys):
    """Each photo's start is its own: ``--exposure-start`` with several photos would give
    them all one, so calibrate refuses it (as deblur does) before any work."""
    d = cli_dir
    out = d / "out" / "one_start.json"
    rc = main(["calibrate", *_session_of_two(d, "start2.png", "start2.json"),
               "--exposure-start", "1.0", "-o", str(out)])
    assert rc == 2 and "--exposure-start: would give every photo the same start" in \
        capsys.readouterr().err
    assert not out.exists()


def test_the_far_estimates_threshold_is_the_chi_square_quantile():
    """The far-estimates warning's threshold is scipy's ``chi2.ppf`` (the 95 % quantile of
    6 degrees of freedom is 12.59), made without importing ``scipy.stats``, which costs
    about a second of every calibrating command's start."""
    import subprocess
    import sys

    from scipy.stats import chi2

    from gyrodeblur.calibrate import _chi2_quantile

    assert _chi2_quantile(0.95, 6) == pytest.approx(12.5916, abs=1e-4)
    for dof in range(1, 9):
        assert _chi2_quantile(0.95, dof) == pytest.approx(chi2.ppf(0.95, dof), rel=1e-12)
    script = ("import sys, gyrodeblur.calibrate, gyrodeblur.cli; "
              "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_a_clipped_log_and_a_gap_in_the_exposure_are_warned_of(case):
    """The log the search reads clipped at its range (the rate flat at its largest value
    on an axis, reached at a slope that would have gone beyond it) and, at the calibrated
    parameters, a 35 ms gap inside the exposure: calibrate notes both, naming the log
    (each had gone unsaid: a held-out log clipped at 0.5 rad/s took an offset 34 ms off,
    stated +-2 ms)."""
    _, true, blurred = case
    log = true.log
    t0, t1 = true.log_window
    omega = np.clip(2.0 * log.omega, -1.0, 1.0)   # a faster shake than the photo's: for the
    #                                                 warning alone
    keep = ~((log.t > t0 + 0.01) & (log.t < t0 + 0.045))       # 35 ms without samples
    holed = GyroLog(log.t[keep], omega[keep], "clipped.csv")
    res = calibrate([blurred], true.replace(log=holed, max_gap=0.1),
                    fix=("axes", "focal", "readout"))
    said = "\n".join(res.notes)
    assert re.search(r"warning: clipped.csv: the rates look clipped where the search may "
                     r"place the exposure \(axis [xyz] at [+-]1 rad/s for \d+ samples in a "
                     r"row", said)
    assert re.search(r"warning: clipped.csv: gap of 3\d\.\d ms in the gyro log at "
                     r"[0-9.]+ s, inside the exposure", said)
    res = calibrate([blurred], true, fix=("axes", "focal", "readout"))
    assert not any("clipped" in n or "gap of" in n for n in res.notes)
