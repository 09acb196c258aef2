import json
import os
import re
import warnings

import numpy as np
import pytest

from gyrodeblur.camera import Camera
from gyrodeblur.capture import load_capture
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog, write_gcsv


@pytest.fixture
def capture_files(tmp_path):
    t = 1000.0 + np.arange(400) / 200.0
    w = np.tile([0.01, 0.3, -0.02], (t.size, 1))
    write_gcsv(tmp_path / "gyro.gcsv", GyroLog(t, w))
    doc = {
        "exposure_start": 1001.0, "exposure_time": 0.03, "readout_time": 0.02,
        "camera": {"fx": 819.2, "fy": 819.2, "cx": 511.5, "cy": 381.5, "width": 1024, "height": 764},
        "gyro": {"path": "gyro.gcsv", "format": "gcsv", "orientation": "XYZ", "time_offset": 0.0},
    }
    (tmp_path / "cap.json").write_text(json.dumps(doc))
    return tmp_path, doc


def test_load_and_round_trip(capture_files):
    d, doc = capture_files
    cap = load_capture(d / "cap.json")
    assert cap.camera == Camera(819.2, 819.2, 511.5, 381.5, 1024, 764)
    assert cap.row_start(764) == pytest.approx(1001.02)
    cap.save(d / "again.json")
    again = load_capture(d / "again.json")
    assert again.to_dict() == cap.to_dict()
    assert json.loads((d / "again.json").read_text())["gyro"]["path"] == "gyro.gcsv"
    # and what the defaults would hide: a mapping, a time offset and a bias of its own
    from gyrodeblur.axes import axes_to_letters, parse_axes

    varied = cap.replace(axes=parse_axes("YxZ"), time_offset=0.0123,
                         bias=np.array([0.01, -0.02, 0.005]))
    varied.save(d / "varied.json")
    back = load_capture(d / "varied.json")
    assert axes_to_letters(back.axes) == "YxZ" and back.time_offset == 0.0123
    np.testing.assert_array_equal(back.bias, [0.01, -0.02, 0.005])
    assert back.to_dict() == varied.to_dict()


def test_captures_naming_one_log_share_it_when_given_a_cache(capture_files):
    """With ``logs``, captures that name the same file (by another relative path too)
    share one log, read once; without it each capture reads its own."""
    d, doc = capture_files
    (d / "sub").mkdir()
    (d / "sub" / "cap2.json").write_text(json.dumps(dict(doc, exposure_start=1001.5, gyro=dict(
        doc["gyro"], path="../gyro.gcsv"))))
    logs = {}
    a = load_capture(d / "cap.json", logs=logs)
    b = load_capture(d / "sub" / "cap2.json", logs=logs)
    assert a.log is b.log and len(logs) == 1 and b.exposure_start == 1001.5
    assert load_capture(d / "cap.json").log is not a.log


def test_overrides_and_offset(capture_files):
    d, _ = capture_files
    cap = load_capture(d / "cap.json", overrides={"time_offset": 0.5, "readout_time": 0.0,
                                                  "orientation": "Xyz", "fx": 500.0})
    t, w = cap.camera_rates()
    assert t[0] == pytest.approx(1000.5)
    assert np.allclose(w[0], [0.01, -0.3, 0.02])
    assert cap.camera.fx == 500 and cap.camera.fy == 819.2 and cap.readout_time == 0


def test_scaled_to_photo(capture_files):
    d, _ = capture_files
    cap = load_capture(d / "cap.json", image_size=(512, 382))
    assert cap.camera.width == 1024        # the JSON's size wins; scaling is explicit
    half = cap.scaled_to(512, 382)
    assert half.camera.fx == pytest.approx(409.6)
    assert half.camera.cx == pytest.approx(255.5)
    with pytest.raises(InputError, match="aspect ratio differs$"):
        cap.scaled_to(512, 512, source="photo.jpg")
    with pytest.raises(InputError, match="turned by 90 degrees"):     # a portrait export
        cap.scaled_to(382, 512, source="photo.jpg")


def test_exif_hints_fill_gaps(capture_files):
    d, doc = capture_files
    del doc["exposure_time"]
    del doc["camera"]
    (d / "cap.json").write_text(json.dumps(doc))
    said = []
    cap = load_capture(d / "cap.json", image_size=(800, 600),
                       exif_hints={"exposure_time": 0.02, "fx": 640.0}, report=said.append)
    assert cap.exposure_time == 0.02 and cap.camera.fx == 640 and cap.camera.cx == 399.5
    assert len(said) == 2 and all("EXIF" in s for s in said)
    # a FocalLength in mm with nothing that gives its pixels' size: said what was found
    with pytest.raises(InputError, match=r"cap.json: no focal length in pixels: the photo's "
                                         r"EXIF gives FocalLength 4.25 mm but no .*"
                                         r"4.25 mm x its longer side in pixels"):
        load_capture(d / "cap.json", image_size=(800, 600),
                     exif_hints={"exposure_time": 0.02, "focal_length_mm": 4.25})
    with pytest.raises(InputError, match=r"cap.json: no focal length: give camera.fx "
                                         r"\(pixels\) or --fx$"):
        load_capture(d / "cap.json",        # the hint in pixels, but no photo size to fit it
                     exif_hints={"exposure_time": 0.02, "focal_length_mm": 4.25, "fx": 9.0})
    # with a photo, one whose EXIF would give it is named; without (the psf command's
    # capture, no photo to read), it is not
    with pytest.raises(InputError, match=r"give camera.fx \(pixels\) or --fx, or a photo "
                                         r"whose EXIF has FocalLengthIn35mmFilm"):
        load_capture(d / "cap.json", image_size=(800, 600), exif_hints={})


def test_a_description_far_from_the_photos_exif_is_warned_of(capture_files):
    """A focal length or exposure time the user gives more than 1.5x off the photo's
    EXIF values (intrinsics for another resolution, milliseconds for seconds) is warned
    of, naming where it came from; a mild difference and a photo without EXIF pass
    silently, and the given values are used either way."""
    import warnings
    d, doc = capture_files                  # fx 819.2 px at 1024 x 764, 30 ms
    close = {"exposure_time": 0.025, "fx": 0.5 * 819.2 * 1.2}     # a photo at half size
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_capture(d / "cap.json", image_size=(512, 382), exif_hints=close)
        load_capture(d / "cap.json", image_size=(512, 382))
    full_size = {"exposure_time": 0.03, "fx": 5 * 0.5 * 819.2}    # 5x: another resolution
    with pytest.warns(UserWarning, match=r"cap.json: camera.fx is 819 px, but the photo's "
                                         r"EXIF focal length gives 4096 px at 1024 px wide "
                                         r"\(5 times off\): intrinsics for another resolution"):
        cap = load_capture(d / "cap.json", image_size=(512, 382), exif_hints=full_size)
    assert cap.camera.fx == 819.2
    with pytest.warns(UserWarning, match=r"cap.json with --exposure-time: exposure_time is 0.3 "
                                         r"s, but the photo's EXIF ExposureTime is 0.03 s"):
        cap = load_capture(d / "cap.json", overrides={"exposure_time": 0.3},
                           image_size=(512, 382), exif_hints={"exposure_time": 0.03})
    assert cap.exposure_time == 0.3


def test_readout_time_from_the_gcsv_header(capture_files):
    """Gyroflow's gcsv header states the frame readout time (ms): without one in the
    capture, it is used (and said), rather than a global shutter."""
    d, doc = capture_files
    g = d / "gyro.gcsv"
    g.write_text(g.read_text().replace("tscale,", "frame_readout_time,15.2\ntscale,", 1))
    said = []
    assert load_capture(d / "cap.json").readout_time == 0.02           # the capture's wins
    del doc["readout_time"]
    (d / "cap.json").write_text(json.dumps(doc))
    cap = load_capture(d / "cap.json", report=said.append)
    assert cap.readout_time == pytest.approx(0.0152) and not cap.readout_time_unknown
    assert any("frame_readout_time" in s for s in said)
    assert load_capture(d / "cap.json", overrides={"readout_time": 0.0}).readout_time == 0
    # read bottom to top (or along the rows): not this model's rows; said, not used
    g.write_text(g.read_text().replace("tscale,", "frame_readout_direction,1\ntscale,", 1))
    said.clear()
    assert load_capture(d / "cap.json", report=said.append).readout_time == 0
    assert any("frame_readout_direction 1" in s for s in said)
    # a readout given with that header: used, and warned of (the rows run the other way)
    with pytest.warns(UserWarning, match=r"gyro.gcsv: the gcsv header's frame_readout_"
                                         r"direction is 1 \(bottom to top\).*turned by 180 "
                                         r"degrees .*\(--photo-rotation of deblur, calibrate and "
                                         r"simulate\), its rolling shutter is modelled the "
                                         r"wrong way"):
        assert load_capture(d / "cap.json", overrides={"readout_time": 0.02}).readout_time == 0.02
    import warnings
    with warnings.catch_warnings():              # a global shutter has no direction
        warnings.simplefilter("error")
        load_capture(d / "cap.json", overrides={"readout_time": 0.0})
        g.write_text(g.read_text().replace("frame_readout_direction,1", "frame_readout_direction,0"))
        load_capture(d / "cap.json", overrides={"readout_time": 0.02})


def test_bias_auto(tmp_path):
    t = np.arange(0, 2, 0.005)
    w = np.tile([0.02, -0.01, 0.005], (t.size, 1))
    w[(t > 0.9) & (t < 1.1)] += [0.5, 0.3, 0.0]           # shake during the exposure only
    write_gcsv(tmp_path / "g.gcsv", GyroLog(t, w))
    doc = {"exposure_start": 0.95, "exposure_time": 0.05, "readout_time": 0.0,
           "camera": {"fx": 500, "width": 640, "height": 480},
           "gyro": {"path": "g.gcsv", "bias": "auto"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path / "c.json")
    assert np.allclose(cap.bias, [0.02, -0.01, 0.005], atol=2e-6)


@pytest.mark.parametrize("change,match", [
    ({"exposure_start": 2000.0}, "covers"),
    ({"exposure_time": -1}, "positive"),
    ({"exposure_time": 0}, "exposure_time must be positive"),    # no light at all
    ({"gyro": {"path": "missing.gcsv"}}, "not found"),
    ({"gyro": {"path": "gyro.gcsv", "orientation": "YXZ"}}, "reflection"),
    ({"gyro": {"path": "gyro.gcsv", "format": "mp4"}}, "unknown gyro log format"),
])
def test_bad_captures(capture_files, change, match):
    d, doc = capture_files
    doc.update(change)
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match) as e:
        load_capture(d / "cap.json")
    assert any(name in str(e.value) for name in ("cap.json", "gyro.gcsv", "missing.gcsv"))


def test_not_json(tmp_path):
    (tmp_path / "c.json").write_text("{nope")
    with pytest.raises(InputError, match="c.json: not valid JSON"):
        load_capture(tmp_path / "c.json")
    (tmp_path / "c.json").write_text('{"exposure_start": "unterminated}')
    with pytest.raises(InputError, match=r"not valid JSON \(Unterminated string starting at: "
                                         r"line 1, column 20\)"):
        load_capture(tmp_path / "c.json")
    (tmp_path / "d.json").mkdir()            # a folder is named as one, not by its errno
    with pytest.raises(InputError, match=r"d.json: is a folder, not a capture description$"):
        load_capture(tmp_path / "d.json")


def test_unknown_keys_are_warned_of_and_notes_are_not(capture_files):
    """A misspelt key would silently fall back to a default (here: a global shutter)."""
    d, doc = capture_files
    doc["readout_tme"] = doc.pop("readout_time")
    doc["camera"]["focal"] = 5.0
    doc["comment"] = "taken at dusk"
    doc["gyro"]["_note"] = "phone B"
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning) as rec:
        cap = load_capture(d / "cap.json")
    text = " | ".join(str(r.message) for r in rec)
    assert "cap.json: unknown key(s) readout_tme ignored" in text
    assert "camera.focal" in text
    assert "comment" not in text.replace("known:", "") and "_note" not in text
    assert cap.readout_time == 0.0
    doc.pop("readout_tme"), doc["camera"].pop("focal")
    (d / "cap.json").write_text(json.dumps(doc))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_capture(d / "cap.json")                   # a clean file: no warning


@pytest.mark.parametrize("fx", [4.2, 26.0])     # a phone's focal length in mm, its 35 mm equiv.
def test_a_focal_length_not_in_pixels_is_refused(capture_files, fx):
    """Either would make a wide-angle blur at the corners, not one longer than the frame,
    so only this check catches it."""
    d, doc = capture_files
    doc["camera"].update(fx=fx, fy=fx)
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"cap.json: camera: focal length .* is it in mm or 35 "
                                         r"mm-equivalent\? In pixels it is"):
        load_capture(d / "cap.json")


def test_focal_length_checks_name_where_the_value_came_from(capture_files):
    d, doc = capture_files
    doc["camera"].update(fx=0.16 * 1024, fy=0.16 * 1024)   # a 145-degree view: fine
    (d / "cap.json").write_text(json.dumps(doc))
    load_capture(d / "cap.json")
    with pytest.raises(InputError, match=r"cap.json with --fx: camera: focal length fx=3"):
        load_capture(d / "cap.json", overrides={"fx": 3.0})
    del doc["camera"]
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="the focal length from the photo's EXIF"):
        load_capture(d / "cap.json", image_size=(1024, 764), exif_hints={"fx": 40.0})


def test_a_principal_point_a_frame_off_is_refused_and_off_centre_warned(capture_files):
    d, doc = capture_files
    doc["camera"].update(cx=5000.0, cy=-3000.0)
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"principal point \(5000, -3000\) px is more than a "
                                         "frame from the centre"):
        load_capture(d / "cap.json")
    # a crop's own intrinsics (the top-left quarter of a 2048x1528 frame): outside, accepted
    doc["camera"].update(cx=1023.5, cy=763.5)
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="far from the centre.*right for a crop's own"):
        assert load_capture(d / "cap.json").camera.cx == 1023.5
    # intrinsics of the full frame without its size, for a half-size photo: the principal
    # point lands at the photo's corner; said, since nothing else would
    del doc["camera"]["width"], doc["camera"]["height"]
    doc["camera"].update(cx=511.5, cy=381.5)
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="far from the centre.*give camera.width"):
        load_capture(d / "cap.json", image_size=(512, 382))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_capture(d / "cap.json", image_size=(1024, 764))         # the right size: quiet


def test_a_key_given_twice_is_refused(capture_files):
    d, _ = capture_files
    text = (d / "cap.json").read_text().replace('"readout_time": 0.02',
                                                '"readout_time": 0.02, "readout_time": 0')
    (d / "cap.json").write_text(text)
    with pytest.raises(InputError, match="cap.json: key 'readout_time' appears twice"):
        load_capture(d / "cap.json")


def test_json_true_is_not_a_bias(capture_files):
    d, doc = capture_files
    doc["gyro"]["bias"] = [True, False, False]
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="bias must be three finite numbers"):
        load_capture(d / "cap.json")


def test_csv_options_on_another_format_are_warned_of(capture_files):
    d, doc = capture_files
    doc["gyro"].update(time_unit="ms", rate_unit="deg/s")
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="gyro.gcsv: rate_unit, time_unit apply to CSV and JSON "
                                         "logs only; this log is gcsv: ignored"):
        cap = load_capture(d / "cap.json")
    assert np.allclose(cap.log.omega[0], [0.01, 0.3, -0.02])


def test_null_means_not_given(capture_files):
    d, doc = capture_files
    doc["exposure_time"] = None
    doc["camera"].update(cy=None, fy=None)
    doc["gyro"]["orientation"] = None
    (d / "cap.json").write_text(json.dumps(doc))
    cap = load_capture(d / "cap.json", exif_hints={"exposure_time": 0.02})
    assert cap.exposure_time == 0.02 and cap.camera.cy == 381.5 and cap.camera.fy == 819.2
    assert np.array_equal(cap.axes, np.eye(3))


def test_gyro_paths_home_folders_and_deep_nesting(capture_files, monkeypatch):
    d, doc = capture_files
    monkeypatch.setenv("HOME", str(d))
    doc["gyro"]["path"] = "~/gyro.gcsv"
    (d / "cap.json").write_text(json.dumps(doc))
    assert load_capture(d / "cap.json").log.source == str(d / "gyro.gcsv")
    (d / "logs").mkdir()
    doc["gyro"]["path"] = "logs"
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="logs: is a folder, not a gyro log"):
        load_capture(d / "cap.json")
    (d / "deep.json").write_text("[" * 100000 + "]" * 100000)
    with pytest.raises(InputError, match="deep.json: not valid JSON"):
        load_capture(d / "deep.json")


def test_a_duration_in_ms_is_named_when_the_log_does_not_cover_it(capture_files):
    d, doc = capture_files
    doc["exposure_time"] = 30.0                  # ms written as seconds
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="durations: the exposure lasts 30.02 s: exposure_time "
                                         "and "
                                         "readout_time are seconds, not ms"):
        load_capture(d / "cap.json")
    doc["exposure_time"], doc["exposure_start"] = 0.03, 2000.0     # a clock mismatch
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"\(check time_offset and exposure_start\)"):
        load_capture(d / "cap.json")
    doc["exposure_time"] = 1.5                   # a night exposure, or ms: both named
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="not ms; else time_offset and exposure_start"):
        load_capture(d / "cap.json")


def test_a_key_in_the_wrong_section_is_explained(capture_files):
    d, doc = capture_files
    doc["bias"] = [0.0, 0.0, 0.0]                  # belongs in "gyro"
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="unknown key.*bias belongs in gyro"):
        load_capture(d / "cap.json")


@pytest.mark.parametrize("encoding", ["utf-16", "utf-8-sig", "utf-16-le"])
def test_a_description_in_utf16_or_with_a_byte_order_mark_is_read(capture_files, encoding):
    d, doc = capture_files                     # as Windows editors save "Unicode" text
    doc["gyro"]["path"] = "gyro ü.gcsv"
    os.replace(d / "gyro.gcsv", d / "gyro ü.gcsv")
    (d / "cap.json").write_text(json.dumps(doc, ensure_ascii=False), encoding=encoding)
    assert load_capture(d / "cap.json").log.source == str(d / "gyro ü.gcsv")


def test_a_description_in_another_encoding_is_refused(capture_files):
    d, doc = capture_files
    doc["gyro"]["path"] = "gyro é.gcsv"
    (d / "cap.json").write_text(json.dumps(doc, ensure_ascii=False), encoding="cp1252")
    with pytest.raises(InputError, match="cap.json: cannot read: not UTF-8 or UTF-16 text"):
        load_capture(d / "cap.json")


def test_an_empty_gyro_path_is_named_as_empty(capture_files):
    d, doc = capture_files
    doc["gyro"]["path"] = " "
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"cap.json: gyro.path: an empty file name"):
        load_capture(d / "cap.json")
    with pytest.raises(InputError, match=r"^--gyro: an empty file name"):
        load_capture(d / "cap.json", overrides={"gyro_path": ""})


@pytest.mark.skipif(not hasattr(os, "symlink") or os.name == "nt", reason="symbolic links")
def test_a_linked_description_finds_its_log_beside_the_link_or_its_target(capture_files):
    d, doc = capture_files
    (d / "elsewhere").mkdir()
    os.symlink(d / "cap.json", d / "elsewhere" / "cap.json")
    assert load_capture(d / "elsewhere" / "cap.json").log.source == str(d / "gyro.gcsv")
    beside_link = d / "elsewhere" / "gyro.gcsv"     # a log beside the link comes first
    beside_link.write_bytes((d / "gyro.gcsv").read_bytes())
    assert load_capture(d / "elsewhere" / "cap.json").log.source == str(beside_link)
    os.remove(d / "gyro.gcsv")
    os.remove(beside_link)
    with pytest.raises(InputError, match=re.escape(str(beside_link))):
        load_capture(d / "elsewhere" / "cap.json")    # named where the link reads it


@pytest.mark.parametrize("override, named", [
    ({"readout_time": -1.0}, "with --readout-time: readout_time must be >= 0"),
    ({"bias": [float("nan"), 0, 0]}, "with --bias: gyro bias must be three finite numbers"),
    ({"max_gap": -1.0}, "with --max-gap: max_gap must be a positive number"),
])
def test_a_bad_value_from_an_option_names_the_option(capture_files, override, named):
    d, _ = capture_files
    with pytest.raises(InputError, match="cap.json " + named):
        load_capture(d / "cap.json", overrides=override)


def test_a_readout_in_ms_is_refused_even_where_the_log_covers_it(capture_files):
    d, doc = capture_files
    doc["readout_time"] = 0.5                    # the log (2 s) covers a 0.5 s readout
    (d / "cap.json").write_text(json.dumps(doc))
    assert load_capture(d / "cap.json").readout_time == 0.5
    with pytest.raises(InputError, match="cap.json with --readout-time: readout_time 1.5 s is "
                                         "longer than any sensor's readout .*not ms"):
        load_capture(d / "cap.json", overrides={"readout_time": 1.5})
    g = d / "gyro.gcsv"                          # a header's own value is blamed on the log
    g.write_text(g.read_text().replace("tscale,", "frame_readout_time,-20\ntscale,", 1))
    del doc["readout_time"]
    (d / "cap.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"gyro.gcsv: the gcsv header's frame_readout_time "
                                         r"\(ms\) must be 0 to 1000, got -20"):
        load_capture(d / "cap.json")


def test_an_automatic_bias_from_a_camera_that_was_not_still_is_warned_of(tmp_path):
    rng = np.random.default_rng(3)
    t = np.arange(0, 2, 0.005)
    w = 0.02 + 0.004 * rng.standard_normal((t.size, 3))             # still, on a table
    doc = {"exposure_start": 0.95, "exposure_time": 0.05, "readout_time": 0.0,
           "camera": {"fx": 500, "width": 640, "height": 480},
           "gyro": {"path": "g.gcsv", "bias": "auto"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    write_gcsv(tmp_path / "g.gcsv", GyroLog(t, w))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.allclose(load_capture(tmp_path / "c.json").bias, 0.02, atol=2e-3)
    w += 0.3 * np.sin(2 * np.pi * 1.5 * t)[:, None]                 # held in a hand
    write_gcsv(tmp_path / "g.gcsv", GyroLog(t, w))
    with pytest.warns(UserWarning, match="g.gcsv: the automatic bias, .* comes from samples "
                                         "that vary by 0.3.. rad/s: the camera was not still"):
        load_capture(tmp_path / "c.json")


def test_rates_read_in_an_assumed_unit_are_said(tmp_path):
    t = 1000.0 + np.arange(400) / 200.0
    rows = "\n".join(f"{v:.3f},0.01,0.3,-0.02" for v in t)
    (tmp_path / "g.csv").write_text("t_s,gx,gy,gz\n" + rows + "\n")
    doc = {"exposure_start": 1001.0, "exposure_time": 0.03, "readout_time": 0.02,
           "camera": {"fx": 500, "width": 640, "height": 480}, "gyro": {"path": "g.csv"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    said = []
    load_capture(tmp_path / "c.json", report=said.append)
    assert said == ["gyro rates read in rad/s (the column names state no unit; give "
                    "--rate-unit deg/s if they are degrees)"]
    said.clear()
    load_capture(tmp_path / "c.json", overrides={"rate_unit": "rad/s"}, report=said.append)
    assert said == []
    # several photos' captures sharing the log: it is read, and its unit told, once
    logs: dict = {}
    for _ in range(3):
        load_capture(tmp_path / "c.json", report=said.append, logs=logs)
    assert len(said) == 1 and len(logs) == 1, said
    said.clear()
    assert not load_capture(tmp_path / "c.json").readout_time_unknown
    # a readout time left out is 0 marked unknown (calibrate searches it), and said
    del doc["readout_time"]
    (tmp_path / "c.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path / "c.json", overrides={"rate_unit": "rad/s"},
                       report=said.append)
    assert cap.readout_time == 0.0 and cap.readout_time_unknown
    assert said == ["readout_time not given: 0 (a global shutter) unless calibrated (a "
                    "phone's rolling shutter reads out in about 10-30 ms: give a guess, or "
                    "let calibrate or deblur --refine search for it)"]
    # saved, it is left out again: its 0 is no global shutter's (which would not be searched)
    assert "readout_time" not in cap.to_dict()
    cap.save(tmp_path / "saved.json")
    again = load_capture(tmp_path / "saved.json", overrides={"rate_unit": "rad/s"})
    assert again.readout_time == 0.0 and again.readout_time_unknown
    # the option gives it
    cap = load_capture(tmp_path / "c.json", overrides={"rate_unit": "rad/s",
                                                       "readout_time": 0.02})
    assert cap.readout_time == 0.02 and not cap.readout_time_unknown


def test_a_capture_saved_anywhere_loads_again(capture_files, tmp_path_factory):
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import read_gyro_log

    d, _ = capture_files
    cap = load_capture(d / "cap.json")
    elsewhere = tmp_path_factory.mktemp("out") / "sub"
    elsewhere.mkdir()
    cap.save(elsewhere / "c.json")                     # the log's path is made relative there
    again = load_capture(elsewhere / "c.json")
    assert os.path.samefile(again.log.source, cap.log.source)
    assert {k: v for k, v in again.to_dict().items() if k != "gyro"} == \
        {k: v for k, v in cap.to_dict().items() if k != "gyro"}
    # made in code from a CSV read with options: format and units are written too
    rows = "\n".join(f"{1000 + k / 200:.3f},0.01,0.3,-0.02" for k in range(400))
    (d / "g.csv").write_text("t,gx,gy,gz\n" + rows + "\n")
    made = Capture(1001.0, 0.03, 0.0, cap.camera, read_gyro_log(d / "g.csv", "csv", time_unit="s"))
    made.save(elsewhere / "made.json")
    assert np.array_equal(load_capture(elsewhere / "made.json").log.t, made.log.t)
    in_memory = Capture(1001.0, 0.03, 0.0, cap.camera, GyroLog(made.log.t, made.log.omega))
    with pytest.raises(InputError, match="no file to refer to"):
        in_memory.save(elsewhere / "x.json")


def test_a_capture_keeps_its_own_copy_of_the_axis_matrix(capture_files):
    from gyrodeblur.capture import Capture
    d, _ = capture_files
    cap = load_capture(d / "cap.json")
    m = np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]])
    made = Capture(cap.exposure_start, cap.exposure_time, 0.0, cap.camera, cap.log, axes=m)
    m[0, 0] = -1.0                                      # now a reflection
    assert np.linalg.det(made.axes) == pytest.approx(1.0)


def test_a_bad_gyro_format_or_unit_is_named_where_it_was_given(capture_files):
    d, doc = capture_files
    for key, value, said in (("format", "CSV-ish", "gyro.format"),
                             ("time_unit", "sec", "gyro.time_unit")):
        (d / "bad.json").write_text(json.dumps({**doc, "gyro": {**doc["gyro"], key: value}}))
        with pytest.raises(InputError, match=f"bad.json: {said}") as exc:
            load_capture(d / "bad.json")
        assert "gyro.gcsv" not in str(exc.value)
    (d / "upper.json").write_text(json.dumps({**doc, "gyro": {**doc["gyro"], "format": "GCSV"}}))
    assert len(load_capture(d / "upper.json").log) == 400


def test_another_log_given_as_an_option_has_its_own_format(capture_files):
    """``--gyro other.csv`` with a capture that says ``"format": "gcsv"``: the JSON's
    format was its own log's; the new one's is worked out from the new file."""
    d, doc = capture_files
    log = load_capture(d / "cap.json").log
    (d / "other.csv").write_text("t_s,wx,wy,wz\n" + "".join(
        f"{t:.6f},{w[0]},{w[1]},{w[2]}\n" for t, w in zip(log.t, log.omega)))
    cap = load_capture(d / "cap.json", overrides={"gyro_path": str(d / "other.csv")})
    assert np.allclose(cap.log.omega, log.omega)
    with pytest.raises(InputError, match="--gyro-format"):
        load_capture(d / "cap.json", overrides={"gyro_path": str(d / "other.csv"),
                                                "gyro_format": "nope"})


def test_parsing_mistakes_are_named_not_tracebacks(capture_files):
    """A unit given as a list, an integer of more digits than Python reads, and a gcsv
    frame_readout_direction that is not 0-3 are each an InputError naming the file."""
    d, doc = capture_files
    (d / "c.json").write_text(json.dumps({**doc, "gyro": {**doc["gyro"], "time_unit": ["s"]}}))
    with pytest.raises(InputError, match="c.json: gyro.time_unit.*unknown unit"):
        load_capture(d / "c.json")
    (d / "c.json").write_text(json.dumps(doc)[:-1] + ', "x": ' + "9" * 5000 + "}")
    with pytest.raises(InputError, match="c.json: not valid JSON"):
        load_capture(d / "c.json")


@pytest.mark.parametrize("direction, readout", [("0", 0.0166), ("0.0", 0.0166), ("1", 0.0),
                                                ("2", 0.0), ("3", 0.0),    # along the rows
                                                ("top", None), ("7", None)])
def test_the_gcsv_readout_direction_is_read_as_a_number(tmp_path, direction, readout):
    from gyrodeblur.gyrolog import GyroLog, write_gcsv

    t = np.arange(0, 1, 0.005)
    write_gcsv(tmp_path / "g.gcsv", GyroLog(t, np.zeros((t.size, 3))))
    lines = (tmp_path / "g.gcsv").read_text().splitlines()
    lines[1:1] = ["frame_readout_time,16.6", f"frame_readout_direction,{direction}"]
    (tmp_path / "g.gcsv").write_text("\n".join(lines) + "\n")
    (tmp_path / "c.json").write_text(json.dumps({
        "exposure_start": 0.5, "exposure_time": 0.03,
        "camera": {"fx": 500, "width": 640, "height": 480}, "gyro": {"path": "g.gcsv"}}))
    if readout is None:
        with pytest.raises(InputError, match="g.gcsv: the gcsv header's frame_readout_direction"):
            load_capture(tmp_path / "c.json")
    else:
        assert load_capture(tmp_path / "c.json").readout_time == pytest.approx(readout)


def test_a_bad_mapping_from_the_option_names_the_option(capture_files):
    """--orientation's bad value is the option's, not the file's: the error named the
    capture's gyro.orientation, which held a good one (as --fx's names --fx)."""
    d, _ = capture_files
    with pytest.raises(InputError) as exc:
        load_capture(d / "cap.json", overrides={"orientation": "android-front-camera"})
    assert exc.value.source == "--orientation"
    doc = json.loads((d / "cap.json").read_text())
    doc["gyro"]["orientation"] = "android_back_camera"
    (d / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError) as exc:                 # the file's own: the file's key
        load_capture(d / "bad.json")
    assert exc.value.source.endswith("bad.json (gyro.orientation)")


def test_an_android_log_given_no_mapping_is_read_as_the_back_camera(tmp_path):
    """Not as camera axes: the named android-back-camera, and a warning that says so."""
    from gyrodeblur.axes import parse_axes

    t = np.arange(0, 1, 0.005)
    lines = [f"4 {int(round(a * 1e9))} 0.1 0.2 0.3" for a in t]
    (tmp_path / "events.txt").write_text("\n".join(lines) + "\n")
    doc = {"exposure_start": 0.5, "exposure_time": 0.03,
           "camera": {"fx": 500, "width": 640, "height": 480},
           "gyro": {"path": "events.txt", "format": "android"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="c.json: an Android sensor log .* android-back-camera"):
        cap = load_capture(tmp_path / "c.json")
    np.testing.assert_array_equal(cap.axes, parse_axes("android-back-camera"))
    doc["gyro"]["orientation"] = "XYZ"                 # given: taken as it is, no warning
    (tmp_path / "c.json").write_text(json.dumps(doc))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(load_capture(tmp_path / "c.json").axes, np.eye(3))


@pytest.mark.parametrize("header, app", [
    ("time,seconds_elapsed,z,y,x", "Sensor Logger"),
    ("timestamp,rotationRateX,rotationRateY,rotationRateZ", "Core Motion"),
    ("gyroTimestamp_sinceReboot(s),gyroRotationX(rad/s),gyroRotationY(rad/s),"
     "gyroRotationZ(rad/s)", "SensorLog"),
    ('"Time (s)","Gyroscope x (rad/s)","Gyroscope y (rad/s)","Gyroscope z (rad/s)",'
     '"Absolute (rad/s)"', "phyphox")])
def test_a_phone_apps_csv_given_no_mapping_is_read_as_the_back_camera(tmp_path, header, app):
    """Sensor Logger's, phyphox's and Core Motion's columns are in the device's axes: read,
    like an Android dump, as android-back-camera (yxz, most phones' sensor orientation)
    with a warning that names the app (a phyphox log had been read in camera axes
    without a word: an audit's photo 13.7 dB against 28.2 with its mapping); a plain CSV
    stays in camera axes, silently."""
    from gyrodeblur.axes import parse_axes

    t = 1.7e9 + np.arange(0, 1, 0.005)
    rows = ([f"{int(round(a * 1e9))},{a - t[0]:.3f},0.3,0.2,0.1" for a in t]
            if "elapsed" in header else [f"{a:.4f},0.1,0.2,0.3,0.37" for a in t]
            if "Absolute" in header else [f"{a:.4f},0.1,0.2,0.3" for a in t])
    (tmp_path / "phone.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    doc = {"exposure_start": t[100], "exposure_time": 0.03,
           "camera": {"fx": 500, "width": 640, "height": 480}, "gyro": {"path": "phone.csv"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match=f"c.json: a phone app's log \\(its column names "
                                         f"are {app}'s\\) .* device's axes .* "
                                         "android-back-camera \\(yxz"):
        cap = load_capture(tmp_path / "c.json")
    np.testing.assert_array_equal(cap.axes, parse_axes("yxz"))
    np.testing.assert_allclose(cap.log.omega[0], [0.1, 0.2, 0.3])      # x, y, z by name
    (tmp_path / "phone.csv").write_text("t_s,wx,wy,wz\n" + "\n".join(
        f"{a:.4f},0.1,0.2,0.3" for a in t) + "\n")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(load_capture(tmp_path / "c.json").axes, np.eye(3))


def test_the_photos_exif_time_starts_the_exposure_on_a_unix_clock_log(tmp_path):
    """A phone app's log on Unix time and a description without exposure_start: the
    photo's EXIF capture time (in Unix time) serves, and the tool says it is only a
    start for calibration. It does not serve where the log runs on another clock, where
    it falls outside the log, or where its time zone is unknown (each said), nor where
    exposure_start is given."""
    t = 1733380029.0 + np.arange(0, 3, 0.005)
    (tmp_path / "unix.csv").write_text("t_s,wx,wy,wz\n" + "\n".join(
        f"{a:.4f},0.1,0.2,0.3" for a in t) + "\n")
    (tmp_path / "boot.csv").write_text("t_s,wx,wy,wz\n" + "\n".join(
        f"{a - 1733379000.0:.4f},0.1,0.2,0.3" for a in t) + "\n")
    doc = {"exposure_time": 0.03, "camera": {"fx": 500, "width": 640, "height": 480},
           "gyro": {"path": "unix.csv"}}
    (tmp_path / "c.json").write_text(json.dumps(doc))
    hints = {"capture_time_unix": 1733380030.512,
             "capture_time_text": "2024:12:05 07:27:10.512 +01:00"}
    said = []
    cap = load_capture(tmp_path / "c.json", exif_hints=hints, report=said.append)
    assert cap.exposure_start == 1733380030.512 and cap.exposure_start_from_exif
    assert any("from the photo's EXIF time 2024:12:05 07:27:10.512 +01:00)" in s
               and "calibration searches 1 s either way" in s for s in said), said
    # a time just outside what the log covers (a log stopped right after the shot): the
    # search starts from the nearest start the log covers (with the longest readout
    # calibration searches where none is given, 50 ms), and says so
    said.clear()
    late = load_capture(tmp_path / "c.json", exif_hints=dict(hints, capture_time_unix=t[-1]),
                        report=said.append)
    assert late.exposure_start == pytest.approx(t[-1] - 0.08) and late.exposure_start_from_exif
    assert any("80 ms after the exposures the log covers" in s for s in said), said
    (tmp_path / "c.json").write_text(json.dumps(dict(doc, readout_time=0.02)))
    late = load_capture(tmp_path / "c.json", exif_hints=dict(hints, capture_time_unix=t[-1]))
    assert late.exposure_start == pytest.approx(t[-1] - 0.05)     # the readout given
    (tmp_path / "c.json").write_text(json.dumps(doc))
    # a time to the whole second (no SubSecTimeOriginal) is its middle, searched 1.5 s
    # either way, and said so; 1.2 s off the log is within that
    said.clear()
    whole_hints = {"capture_time_unix": 1733380030.5, "capture_time_whole_second": True,
                   "capture_time_text": "2024:12:05 07:27:10 +01:00"}
    whole = load_capture(tmp_path / "c.json", report=said.append, exif_hints=whole_hints)
    assert whole.exposure_start == 1733380030.5 and whole.exif_time_to_the_second
    assert not cap.exif_time_to_the_second
    assert any("EXIF time 2024:12:05 07:27:10 +01:00, the middle of its second): that "
               "marks the exposure only to half a second either way (no SubSecTimeOriginal), "
               "and calibration searches 1.5 s either way" in s for s in said), said
    early = load_capture(tmp_path / "c.json", exif_hints=dict(
        whole_hints, capture_time_unix=t[0] - 1.2))
    assert early.exposure_start == pytest.approx(t[0])
    for gyro, h, problem in (
            ("boot.csv", hints, "the gyro log's clock is not (its times run 1029.000"),
            ("unix.csv", dict(hints, capture_time_unix=1733380130.0),
             "does not cover an exposure within 1 s of the photo's EXIF time"),
            ("unix.csv", {"capture_time_text": "2024:12:05 07:27:10"},
             "has no readable time zone"),
            ("unix.csv", {"unreadable": {"capture_time": "DateTimeOriginal '2024:13:45'"}},
             "the photo's EXIF DateTimeOriginal '2024:13:45' is not a date and time in "
             "EXIF's form, YYYY:MM:DD HH:MM:SS; give exposure_start on the gyro log's clock")):
        (tmp_path / "c.json").write_text(json.dumps(dict(doc, gyro={"path": gyro})))
        with pytest.raises(InputError, match="c.json: missing 'exposure_start'.*"
                                             + problem.replace("(", "\\(")):
            load_capture(tmp_path / "c.json", exif_hints=h)
    # an EXIF exposure time that is there but no time is said to be so
    (tmp_path / "c.json").write_text(json.dumps({k: v for k, v in doc.items()
                                                 if k != "exposure_time"}))
    with pytest.raises(InputError, match="c.json: missing 'exposure_time': the photo's EXIF "
                                         "ExposureTime -0.03 is not a positive number of "
                                         "seconds"):
        load_capture(tmp_path / "c.json", exif_hints=dict(
            hints, unreadable={"exposure_time": "ExposureTime -0.03"}))
    (tmp_path / "c.json").write_text(json.dumps(dict(doc, readout_time=20)))   # ms, by mistake
    with pytest.raises(InputError, match="readout_time 20 s is longer than any sensor's"):
        load_capture(tmp_path / "c.json", exif_hints=hints)
    (tmp_path / "c.json").write_text(json.dumps(dict(doc, exposure_start=1733380031.0)))
    given = load_capture(tmp_path / "c.json", exif_hints=hints)
    assert given.exposure_start == 1733380031.0 and not given.exposure_start_from_exif
    (tmp_path / "c.json").write_text(json.dumps(doc))
    # a photo with no capture time (its EXIF has none, or it has no EXIF) is told so
    with pytest.raises(InputError, match="c.json: missing 'exposure_start' .*, and the photo "
                                         "has no EXIF capture time .* to take it from"):
        load_capture(tmp_path / "c.json", exif_hints={})
    for kw in ({}, {"exif_hints": hints, "exif_start": False}):   # no photo; a sharp scene's
        with pytest.raises(InputError, match="c.json: missing 'exposure_start'$"):
            load_capture(tmp_path / "c.json", **kw)


def test_camera_rates_are_the_mapped_log_less_the_bias(capture_files):
    """``w_camera = axes @ w_log - bias``, on ``camera_time = gyro_time + time_offset``:
    with a mapping that is not its own transpose (YxZ), so that M and M^T differ."""
    d, doc = capture_files
    doc["gyro"].update(orientation="YxZ", bias=[0.01, -0.02, 0.005], time_offset=0.25)
    doc["exposure_start"] = 1001.25
    (d / "cap.json").write_text(json.dumps(doc))
    cap = load_capture(d / "cap.json")
    t, w = cap.camera_rates()
    assert t[0] == pytest.approx(1000.25)
    # the log is (0.01, 0.3, -0.02): camera x = log Y, y = -log X, z = log Z
    np.testing.assert_allclose(w[0], [0.3 - 0.01, -0.01 + 0.02, -0.02 - 0.005], atol=1e-9)


def test_the_log_must_cover_the_exposure_on_its_own_clock(capture_files):
    """The log (1000-1002 s, gyro clock) covers a camera-clock exposure at 1002.0 s only
    through a time_offset of 1.5 s; one at 1001.0 s, gyro 999.5 s, it does not cover."""
    d, _ = capture_files
    cap = load_capture(d / "cap.json", overrides={"time_offset": 1.5, "exposure_start": 1002.0})
    assert cap.window[0] - cap.time_offset == pytest.approx(1000.5)
    with pytest.raises(InputError, match=r"gyro.gcsv: gyro log covers .* but the exposure "
                                         r"needs 999.500000"):
        load_capture(d / "cap.json", overrides={"time_offset": 1.5, "exposure_start": 1001.0})


def test_max_gap_sets_the_largest_gap_allowed_inside_the_exposure(capture_files):
    """An 80 ms gap inside the exposure is refused at the default 50 ms and accepted
    with gyro.max_gap (or --max-gap) 0.1 s."""
    d, doc = capture_files
    t = 1000.0 + np.arange(400) / 200.0
    keep = (t < 1000.99) | (t > 1001.06)            # 1000.985 s, then 1001.065 s: 80 ms
    write_gcsv(d / "gyro.gcsv", GyroLog(t[keep], np.tile([0.01, 0.3, -0.02], (keep.sum(), 1))))
    with pytest.raises(InputError, match=r"gyro.gcsv: gap of 80.0 ms .* \(limit 50 ms"):
        load_capture(d / "cap.json")
    assert load_capture(d / "cap.json", overrides={"max_gap": 0.1}).max_gap == 0.1
    doc["gyro"]["max_gap"] = 0.1
    (d / "cap.json").write_text(json.dumps(doc))
    assert load_capture(d / "cap.json").max_gap == 0.1


def test_an_exif_focal_length_is_scaled_to_the_cameras_size(capture_files):
    """The EXIF ``fx`` is in pixels of the photo (``image_size``); a camera size given in
    the JSON (here twice the photo's) gets it scaled to that size."""
    d, doc = capture_files
    doc["camera"] = {"width": 1024, "height": 764}
    (d / "cap.json").write_text(json.dumps(doc))
    cap = load_capture(d / "cap.json", image_size=(512, 382), exif_hints={"fx": 400.0})
    assert cap.camera.fx == pytest.approx(800.0) and cap.camera.fy == pytest.approx(800.0)


def test_a_gyro_log_given_as_an_option_is_relative_to_the_working_folder(
        capture_files, tmp_path_factory, monkeypatch):
    """``--gyro other.gcsv`` names a file where the command runs, not beside the JSON."""
    d, _ = capture_files
    elsewhere = tmp_path_factory.mktemp("cwd")
    (elsewhere / "other.gcsv").write_text((d / "gyro.gcsv").read_text())
    monkeypatch.chdir(elsewhere)
    cap = load_capture(d / "cap.json", overrides={"gyro_path": "other.gcsv"})
    assert os.path.samefile(cap.log.source, elsewhere / "other.gcsv")


def test_an_automatic_bias_is_in_the_camera_frame_and_clear_of_the_exposure(tmp_path):
    """bias "auto": the median of the samples outside the exposure (on the gyro clock:
    gyro time = camera time - time_offset), mapped to the camera frame; refused where
    fewer than 20 samples lie outside it."""
    t = np.arange(0, 1, 0.005)
    still = np.array([0.02, -0.01, 0.005])
    w = np.tile(still, (t.size, 1))
    w[(t >= 0.2) & (t <= 0.8)] += 0.5                     # moving during the exposure only
    write_gcsv(tmp_path / "g.gcsv", GyroLog(t, w))
    doc = {"exposure_start": 0.05, "exposure_time": 0.6, "readout_time": 0.0,
           "camera": {"fx": 500, "width": 640, "height": 480},
           "gyro": {"path": "g.gcsv", "bias": "auto", "orientation": "YxZ",
                    "time_offset": -0.15}}                # the exposure: gyro 0.2-0.8 s
    (tmp_path / "c.json").write_text(json.dumps(doc))
    cap = load_capture(tmp_path / "c.json")
    np.testing.assert_allclose(cap.bias, [-0.01, -0.02, 0.005], atol=2e-6)   # YxZ @ still
    with pytest.raises(InputError, match="g.gcsv: bias 'auto' needs at least 20 gyro "
                                         "samples outside the exposure window, the log has 0"):
        load_capture(tmp_path / "c.json", overrides={"exposure_time": 0.9,
                                                     "exposure_start": -0.1})


def test_a_large_negative_automatic_bias_is_warned_of():
    """A bias of -0.08 rad/s is as suspect as +0.08 (a phone's is under 0.02)."""
    from gyrodeblur.capture import estimate_bias_outside

    t = np.arange(0, 2, 0.005)
    log = GyroLog(t, np.tile([-0.08, 0.0, 0.0], (t.size, 1)), "g.gcsv")
    with pytest.warns(UserWarning, match="g.gcsv: the automatic bias, -0.080.* agree to "
                                         "0.000 rad/s: the camera was turning steadily"):
        estimate_bias_outside(log, np.eye(3), 0.9, 1.0, source="g.gcsv")
    shaky = log.omega + np.random.default_rng(0).normal(0.0, 0.1, log.omega.shape)
    with pytest.warns(UserWarning, match=r"vary by 0.\d+ rad/s: the camera was not still"):
        estimate_bias_outside(GyroLog(t, shaky, "g.gcsv"), np.eye(3), 0.9, 1.0,
                              source="g.gcsv")


def test_a_focal_length_too_short_on_one_axis_is_refused(capture_files):
    d, _ = capture_files
    with pytest.raises(InputError, match=r"cap.json with --fy: camera: focal length "
                                         r"fx=819.2, fy=4.2 px is under"):
        load_capture(d / "cap.json", overrides={"fy": 4.2})
