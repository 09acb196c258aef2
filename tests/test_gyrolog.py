import warnings

import numpy as np
import pytest

from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import (GyroLog, check_coverage, read_android_events, read_csv_log,
                                read_gcsv, read_gyro_log, write_gcsv)
from gyrodeblur.log_columns import looks_like_time, rate_axis, time_unit_from_interval


@pytest.fixture
def trace():
    t = 1000.0 + np.arange(50) / 200.0
    w = np.stack([np.sin(t * 7), 0.3 * np.cos(t * 5), -0.2 + 0.01 * np.arange(50)], axis=1)
    return GyroLog(t, w)


def test_gcsv_round_trip(tmp_path, trace):
    p = tmp_path / "g.gcsv"
    write_gcsv(p, trace, tscale=1e-6, gscale=1e-6)
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-6)
    assert np.allclose(log.omega, trace.omega, atol=1e-6)


def test_gcsv_header_scales_and_orientation(tmp_path):
    p = tmp_path / "g.gcsv"
    p.write_text("GYROFLOW IMU LOG\nversion,1.3\nid,test\norientation,YxZ\nframe_readout_time,15.2\n"
                 "tscale,0.001\ngscale,0.01\nt,gx,gy,gz,ax,ay,az\n0,10,20,30,1,2,3\n5,11,21,31,1,2,3\n")
    log = read_gcsv(p)
    assert np.allclose(log.t, [0.0, 0.005])
    # camera x = log Y, camera y = -log X, camera z = log Z
    assert np.allclose(log.omega[0], [0.2, -0.1, 0.3])
    assert log.meta["frame_readout_time"] == "15.2"


def test_csv_units_and_columns(tmp_path, trace):
    p = tmp_path / "g.csv"
    rows = "\n".join(f"{int(round(a * 1e3))},{b},{c},{d}" for a, (b, c, d) in
                     zip(trace.t, np.degrees(trace.omega)))
    p.write_text("time,gx,gy,gz\n" + rows + "\n")
    log = read_csv_log(p, time_unit="ms", rate_unit="deg/s")
    assert np.allclose(log.t, trace.t, atol=1e-9)
    assert np.allclose(log.omega, trace.omega, atol=1e-9)
    assert "time_unit_from" not in log.meta
    # no unit in the name: a 5 ms interval at 200 Hz can only be ms
    guessed = read_csv_log(p, rate_unit="deg/s")
    assert guessed.meta["time_unit"] == "ms" and "interval, 5 ms" in guessed.meta["time_unit_from"]
    assert np.allclose(guessed.t, trace.t, atol=1e-9)
    for scale, unit in ((1.0, "s"), (1e6, "us"), (1e9, "ns")):
        rows = "\n".join(f"{float(a * scale)!r},0,0,0" for a in trace.t)
        p.write_text("time,gx,gy,gz\n" + rows + "\n")
        assert read_csv_log(p).meta["time_unit"] == unit
    # an interval of 150 fits no gyro in any unit (6.7 Hz in us, 6.7 kHz in ms)
    p.write_text("time,gx,gy,gz\n" + "\n".join(f"{150 * k},0,0,0" for k in range(10)) + "\n")
    with pytest.raises(InputError, match="time unit of column 'time' unknown"):
        read_csv_log(p)


def test_csv_units_from_suffix(tmp_path, trace):
    p = tmp_path / "g.csv"
    rows = "\n".join(f"{int(round(a * 1e9))},{b},{c},{d}" for a, (b, c, d) in zip(trace.t, trace.omega))
    p.write_text("t_ns,wx_rad_s,wy_rad_s,wz_rad_s\n" + rows + "\n")
    log = read_gyro_log(p, "csv")
    assert np.allclose(log.t, trace.t, atol=1e-8)


def _csv_text(header, t, columns):
    rows = "\n".join(",".join(repr(float(v)) if not isinstance(v, int) else str(v) for v in vals)
                     for vals in zip(t, *columns))
    return header + "\n" + rows + "\n"


def test_csv_rate_columns_found_by_name_in_any_order(tmp_path, trace):
    """Sensor Logger writes ``time,seconds_elapsed,z,y,x``: read by position, the x rate
    would be the elapsed seconds. The names say which column is which axis."""
    t_ns = [int(round(a * 1e9)) for a in trace.t]
    wx, wy, wz = trace.omega.T
    p = tmp_path / "Gyroscope.csv"
    p.write_text(_csv_text("time,seconds_elapsed,z,y,x", t_ns,
                           [trace.t - trace.t[0], wz, wy, wx]))
    log = read_csv_log(p, time_unit="ns")
    assert np.allclose(log.t, trace.t, atol=1e-8)
    assert np.allclose(log.omega, trace.omega, atol=1e-12)

    # an IMU log with the accelerometer first: the gyro's columns, by name
    p2 = tmp_path / "imu.csv"
    p2.write_text(_csv_text("t_s,acc_x,acc_y,acc_z,gyroX,gyroY,gyroZ", trace.t,
                            [wx + 9, wy + 9, wz + 9, wx, wy, wz]))
    assert np.allclose(read_gyro_log(p2).omega, trace.omega, atol=1e-12)


def test_csv_axis_first_names_and_unnamed_extra_columns(tmp_path, trace):
    wx, wy, wz = trace.omega.T
    p = tmp_path / "imu.csv"
    p.write_text(_csv_text("t_s,x_acc,y_acc,z_acc,x_gyro,y_gyro,z_gyro", trace.t,
                           [wx + 9, wy + 9, wz + 9, wx, wy, wz]))
    assert np.allclose(read_gyro_log(p).omega, trace.omega, atol=1e-12)
    # six unnamed columns: which three are the gyro's would be a guess
    p.write_text(_csv_text("t_s,c1,c2,c3,c4,c5,c6", trace.t, [wx, wy, wz, wx, wy, wz]))
    with pytest.raises(InputError, match="do not say which three hold"):
        read_gyro_log(p)


def test_csv_semicolons_comments_quotes_and_byte_order_mark(tmp_path, trace):
    rows = "\n".join(f'"{a!r}";"{b!r}";"{c!r}";"{d!r}"' for a, (b, c, d) in
                     zip(trace.t.tolist(), trace.omega.tolist()))
    p = tmp_path / "g.csv"
    p.write_text("\ufeff# exported by some app\n\n\"t_s\";\"wx\";\"wy\";\"wz\"\n" + rows + "\n",
                 encoding="utf-8")
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t) and np.allclose(log.omega, trace.omega)
    # semicolons, as spreadsheets write them where the comma is the decimal mark
    p.write_text("t_s;wx;wy;wz\n" + rows.replace('"', "").replace(".", ",") + "\n")
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t) and np.allclose(log.omega, trace.omega)
    # line numbers in messages count the comment lines
    p.write_text("# comment\nt_s;wx;wy;wz\n0;0;0;0\n0.01;0;x;0\n0.02;0;0;0\n")
    with pytest.raises(InputError, match="line 4: column .wy. is not a number"):
        read_gyro_log(p)
    # a gcsv with a byte-order mark
    g = tmp_path / "g.gcsv"
    write_gcsv(g, trace, tscale=1e-6, gscale=1e-6)
    g.write_text("\ufeff" + g.read_text(), encoding="utf-8")
    assert np.allclose(read_gyro_log(g).omega, trace.omega, atol=1e-6)


def test_repeated_lines_and_a_cut_last_line_are_dropped(tmp_path, trace):
    """A sample written twice, or a last line cut short when the logger stopped, is not
    data; a repeated timestamp with other rates, or a bad line before the last, is refused."""
    lines = [f"{a!r},{b!r},{c!r},{d!r}" for a, (b, c, d) in
             zip(trace.t.tolist(), trace.omega.tolist())]
    p = tmp_path / "g.csv"
    p.write_text("t_s,wx,wy,wz\n" + "\n".join(lines[:10] + lines[9:] + ["1010.5,0.1"]) + "\n")
    log = read_gyro_log(p)
    assert np.array_equal(log.t, trace.t) and np.allclose(log.omega, trace.omega)
    p.write_text("t_s,wx,wy,wz\n" + "\n".join(lines[:10] + [lines[9].rsplit(",", 1)[0] + ",0.5"] + lines[10:]) + "\n")
    with pytest.raises(InputError, match="not increasing"):
        read_gyro_log(p)
    p.write_text("t_s,wx,wy,wz\n" + "\n".join(lines[:10] + ["1010.5,0.1"] + lines[10:]) + "\n")
    with pytest.raises(InputError, match="line 12: expected 4 values"):
        read_gyro_log(p)


@pytest.mark.parametrize("header", [
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]",       # EuRoC / TUM-VI
    "# t_ns,wx,wy,wz",                                            # numpy.savetxt(header=...)
    "t_ns\troll_rad_s\tpitch_rad_s\tyaw_rad_s",                  # tabs; a rate's _s suffix
    ",t_ns,wx,wy,wz",                                             # pandas' index first
    '"time, ns";"gx (dps)";"gy (dps)";"gz (dps)"',               # a quoted comma
])
def test_csv_layouts_found_in_the_wild(tmp_path, trace, header):
    t_ns = [int(round(a * 1e9)) for a in trace.t]
    w = trace.omega.T
    sep = ";" if ";" in header else "\t" if "\t" in header else ","
    deg = "dps" in header
    cols = [np.degrees(c) if deg else c for c in w]
    extra = [np.arange(len(t_ns))] if header.startswith(",") else []
    rows = []
    for k, t in enumerate(t_ns):
        vals = [str(extra[0][k])] if extra else []
        vals += [str(t)] + [repr(float(c[k])) for c in cols]
        if "a_RS_S_x" in header:
            vals += ["9.8", "0.1", "0.2"]
        rows.append(sep.join(vals))
    p = tmp_path / "log.csv"
    p.write_text(header + "\n" + "\n".join(rows) + "\n")
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-8)
    assert np.allclose(log.omega, trace.omega, atol=1e-9)


def test_csv_units_that_cannot_be_told_are_refused(tmp_path, trace):
    p = tmp_path / "g.csv"
    p.write_text(_csv_text("t_s,gx (mrad/s),gy (mrad/s),gz (mrad/s)", trace.t, trace.omega.T))
    with pytest.raises(InputError, match="neither rad/s nor deg/s"):
        read_gyro_log(p)
    # 10 kHz in ns fits no unit (rather than 10 Hz in us)
    t = (np.arange(50) * 1e5).astype(np.int64)
    p.write_text(_csv_text("time,gx,gy,gz", t.tolist(), [np.zeros(50)] * 3))
    with pytest.raises(InputError, match="fits no gyro rate"):
        read_gyro_log(p)
    # a first column that is no time is not guessed at
    p.write_text(_csv_text("idx,gx,gy,gz", list(range(50)), [np.zeros(50)] * 3))
    with pytest.raises(InputError, match="does not say it holds times"):
        read_gyro_log(p)


def test_csv_units_in_brackets(tmp_path, trace):
    p = tmp_path / "g.csv"
    deg = np.degrees(trace.omega).T
    p.write_text(_csv_text("t (ms),gx [deg/s],gy [deg/s],gz [deg/s]", trace.t * 1e3, deg))
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-9)
    assert np.allclose(log.omega, trace.omega, atol=1e-9)


@pytest.mark.parametrize("header,match", [
    ("t_s,x,y,z,wx,wy,wz", "columns x, wx could each be the x rate"),
    # an orientation beside the rates: no preference for a "rotation" (only SensorLog's
    # gyroscope is preferred to its Core Motion rates)
    ("t_s,rotation_x,rotation_y,rotation_z,angular_velocity_x,angular_velocity_y,"
     "angular_velocity_z", "columns rotation_x, angular_velocity_x could each be the x rate"),
    ("t_s,seconds_elapsed,c1,c2", "'seconds_elapsed' would be read as the x rate"),
    ("t_s,y,x,q", "'y' would be read as the x rate"),
])
def test_csv_rate_columns_the_names_contradict_are_refused(tmp_path, trace, header, match):
    p = tmp_path / "odd.csv"
    n = len(header.split(",")) - 1
    # the last three columns hold the x, y and z rates, the others something else
    p.write_text(_csv_text(header, trace.t, [trace.omega[:, 0] + 7.0] * (n - 3)
                           + list(trace.omega.T)))
    with pytest.raises(InputError, match=match) as e:
        read_gyro_log(p, "csv")
    assert "odd.csv" in str(e.value) and "gyro.rate_columns" in str(e.value)
    # naming the columns settles it, each as the axis it is named for
    names = header.split(",")
    log = read_csv_log(p, rate_columns=names[-3:])
    np.testing.assert_allclose(log.omega, trace.omega, atol=1e-9)
    # named in another order, the columns are read in that order
    log = read_csv_log(p, rate_columns=names[-3:][::-1])
    np.testing.assert_allclose(log.omega, trace.omega[:, ::-1], atol=1e-9)


def test_shared_handheld_log_loads(shared_data):
    log = read_gyro_log(shared_data / "gyro" / "handheld_phone_210hz.csv", "csv", time_unit="ns")
    assert len(log) > 30000
    assert 0.2 < np.median(np.linalg.norm(log.omega, axis=1)) < 2.0


def test_android_round_trip(tmp_path, trace):
    p = tmp_path / "events.txt"
    lines = []
    for a, (b, c, d) in zip(trace.t, trace.omega):
        lines.append(f"1 {int(round(a * 1e9))} 9.8 0.1 0.2")
        lines.append(f"4 {int(round(a * 1e9))} {float(b)!r} {float(c)!r} {float(d)!r}")
    p.write_text("\n".join(lines) + "\n")
    log = read_android_events(p)
    assert np.allclose(log.t, trace.t, atol=1e-9)
    assert np.allclose(log.omega, trace.omega)
    assert read_gyro_log(p).t.size == trace.t.size          # format guessed
    # a dump cut short in its last line (the logger stopped) keeps what came before it; a
    # short gyro line before the last is refused
    p.write_text("\n".join(lines + ["4 503001"]) + "\n")
    assert np.allclose(read_android_events(p).omega, trace.omega)
    p.write_text("\n".join(lines[:5] + ["4 503001"] + lines[5:]) + "\n")
    with pytest.raises(InputError, match="line 6: a gyroscope event"):
        read_android_events(p)


def test_shared_android_log(shared_data):
    log = read_gyro_log(shared_data / "real" / "shield-tablet" / "sensor_events.txt", "android")
    assert len(log) == 23


@pytest.mark.parametrize("content,match", [
    ("t_s,x,y,z\n0,0,0,0\n0.01,0,0,0\n0.005,0,0,0\n",
     r"not increasing: sample 3 \(0.005000 s\) is earlier than sample 2 \(0.010000 s\) "
     r"\(sort the log by time\)"),
    # without a unit, said before one is guessed (not as an interval that fits no rate)
    ("timestamp,x,y,z\n2.996237,0,0,0\n2.992646,0,0,0\n2.987381,0,0,0\n",
     r"not increasing: sample 2 \(2.992646\) is earlier than sample 1 \(2.996237\)"),
    ("time,x,y,z\n1.0,0,0,0\n1.0,0,0,1\n1.0,0,0,2\n",
     r"not increasing: sample 2 has the time of sample 1 \(1\) with other rates \(two "
     r"samples at one time: remove one\)"),
    # nanoseconds since 1970 said with every digit (1e-10 apart, they read alike to 10)
    ("time,x,y,z\n1733380020406623488,0,0,0\n1733380020401865728,0,0,0\n",
     r"sample 2 \(1733380020401865728\) is earlier than sample 1 \(1733380020406623488\)"),
    ("time,x,y,z\n1.0,0,0,0\n1.0,0,0,0\n1.0,0,0,0\n", r"only 1 gyro sample\(s\)"),
    ("t_s,x,y,z\n0,50,50,50\n0.01,50,50,50\n0.02,50,50,50\n",
     r"are the rates in deg/s\? \(a CSV or JSON log's unit: --rate-unit deg/s, or "
     r"gyro.rate_unit; a CSV's column names can state it: gx_deg_s, gx \[deg/s\]\)"),
    # epoch microseconds said to be seconds: rounding would eat the exposure
    ("t_s,x,y,z\n1700000000000000,0,0,0\n1700000000005000,0,0,0\n",
     r"time column 't_s' read in s, as its name states: .* 5000 s, .* in us it is a 200 Hz"),
    ("t_s,x,y,z\n100000000000000,0,0,0\n100000000000000.03125,0,0,0\n",
     r"gyro sample 1's time 1e\+14 s is beyond 4.29e\+09 s .* microseconds or "
     r"nanoseconds read as seconds"),
    ("t_s,x,y,z\n0,0,0\n", "expected 4 values"),
    ("t_s,x,y,z\n0,0,0,abc\n", "not a number"),
    ("", "empty"),
])
def test_bad_logs(tmp_path, content, match):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(InputError, match=match) as e:
        read_gyro_log(p, "csv")
    assert "bad.csv" in str(e.value)


@pytest.mark.parametrize("header,row,match", [
    ("tscale,0.001\ngscale,0\n", "5,1,2,3", "tscale and gscale must be positive"),
    ("tscale,-1\ngscale,0.01\n", "5,1,2,3", "tscale and gscale must be positive"),
    ("tscale,0.001\ngscale,0.01\n", "5,inf,2,3", "NaN or infinite value in gyro sample 2"),
])
def test_bad_gcsv_scales_and_values(tmp_path, header, row, match):
    """A zero scale would silently give a still camera; an infinite rate must be refused
    before the header's axis rotation meets it (no floating-point warning on the way)."""
    p = tmp_path / "g.gcsv"
    p.write_text(f"GYROFLOW IMU LOG\norientation,YxZ\n{header}t,gx,gy,gz\n0,1,2,3\n{row}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=match) as e:
            read_gcsv(p)
    assert "g.gcsv" in str(e.value)


def test_missing_file_and_unknown_format(tmp_path):
    with pytest.raises(InputError, match="nope.csv.*not found"):
        read_gyro_log(tmp_path / "nope.csv")
    p = tmp_path / "x.csv"
    p.write_text("t_s,x,y,z\n0,0,0,0\n1,0,0,0\n")
    with pytest.raises(InputError, match="unknown gyro log format"):
        read_gyro_log(p, "bag")


def _sensor_logger_json(trace, others=True) -> str:
    """Sensor Logger's JSON export of ``trace``: one object per sample, values as text,
    keys ``sensor, time, seconds_elapsed, z, y, x``; with ``others``, an accelerometer's
    samples between them."""
    import json

    out = []
    for a, (wx, wy, wz) in zip(trace.t, trace.omega):
        t = str(int(round(a * 1e9)))
        if others:
            out.append({"sensor": "Accelerometer", "time": t, "seconds_elapsed": "0",
                        "z": "9.8", "y": "0.1", "x": "-0.2"})
        out.append({"sensor": "Gyroscope", "time": t,
                    "seconds_elapsed": repr(float(a - trace.t[0])),
                    "z": repr(float(wz)), "y": repr(float(wy)), "x": repr(float(wx))})
    return json.dumps(out)             # one line, as long as the log


def test_sensor_logger_json_export_reads_as_its_csv(tmp_path):
    """Sensor Logger's JSON export (one long line: over the CSV reader's 128 KB field
    limit here) reads as its CSV export does: the gyroscope's samples, by its keys, the
    time in ns and the phone's device axes; its format is found from its first character."""
    t = 1000.0 + np.arange(600) / 200.0
    trace = GyroLog(t, np.stack([np.sin(t * 7), 0.3 * np.cos(t * 5), 0.1 * t - 100], axis=1))
    p = tmp_path / "Gyroscope.json"
    p.write_text(_sensor_logger_json(trace))
    assert p.stat().st_size > 131072 and "\n" not in p.read_text()
    log = read_gyro_log(p)
    t_ns = [int(round(a * 1e9)) for a in trace.t]
    wx, wy, wz = trace.omega.T
    (tmp_path / "Gyroscope.csv").write_text(_csv_text("time,seconds_elapsed,z,y,x", t_ns,
                                                      [trace.t - trace.t[0], wz, wy, wx]))
    csv_log = read_gyro_log(tmp_path / "Gyroscope.csv")
    assert np.array_equal(log.t, csv_log.t) and np.array_equal(log.omega, csv_log.omega)
    assert np.allclose(log.t, trace.t, atol=1e-8)
    assert log.meta["time_unit"] == "ns" and log.in_device_axes
    assert log.meta["format"] == "json"
    # numbers as numbers, and a sample cut short (no x) skipped with a warning
    import json
    samples = json.loads(_sensor_logger_json(trace, others=False))
    for r in samples:
        r.update(time=int(r["time"]), x=float(r["x"]), y=float(r["y"]), z=float(r["z"]))
    del samples[-1]["x"]
    p.write_text(json.dumps(samples, indent=1))
    with pytest.warns(UserWarning, match="1 sample.* with a missing or NaN value skipped"):
        log = read_gyro_log(p, "json")
    assert np.allclose(log.omega, trace.omega[:-1], atol=1e-12)
    # the CSV options apply: the elapsed seconds as the time
    with pytest.warns(UserWarning, match="1 sample.* skipped"):
        log = read_gyro_log(p, "json", time_column="seconds_elapsed")
    assert np.allclose(log.t, trace.t[:-1] - trace.t[0], atol=1e-12)


@pytest.mark.parametrize("content,match", [
    ('{"Gyroscope": []}', r"must be a list of samples, one object each .*this file holds "
                          r"one object \(keys: Gyroscope\)"),
    ("[1, 2, 3]", "this file holds a list of int"),
    ('[{"sensor": "Gyroscope", "time": 1, "x": 0,', r"not a JSON log: .*\(line 1, column"),
    ("[]", "no samples"),
    ('[{"sensor": "Accelerometer", "time": 1, "x": 0, "y": 0, "z": 0}]',
     r"no gyroscope samples \(the samples' sensors: Accelerometer\)"),
    ('[{"sensor": "Accelerometer", "time": 1},' * 1 + '{"sensor": "Gyroscope", "time": 5000000, '
     '"x": 0, "y": 0, "z": 0}, {"sensor": "Gyroscope", "time": 10000000, "x": 0, "y": 0, '
     '"z": [1]}]', r"Gyroscope.json: sample 3: 'z' is not a number \('\[1\]'\)"),
    ('{"t_s": 0, "wx": 0}\n{"t_s": [0.1', r"not a JSON log: .*\(line 2, column 13\)"),
    ('{"t_s": 0, "wx": 0}\n' + "[" * 100_000, "not a JSON log: line 2 nested too deeply"),
])
def test_json_logs_that_are_not_a_list_of_gyro_samples_are_refused(tmp_path, content, match):
    p = tmp_path / "Gyroscope.json"
    p.write_text(content)
    with pytest.raises(InputError, match=match):
        read_gyro_log(p, "json")


def test_a_csv_line_the_reader_cannot_split_is_refused_by_line(tmp_path, trace):
    """A value over the CSV reader's 128 KB limit (a quoted field) is an error naming the
    file and the line, not the reader's traceback; so is a header line that long."""
    p = tmp_path / "g.csv"
    rows = _csv_text("t_s,wx,wy,wz", trace.t, trace.omega.T).splitlines()
    rows.insert(3, f'1000.011,"{"9" * 200_000}",0,0')
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match=r"g.csv: line 4 cannot be read as CSV \(field larger "):
        read_gyro_log(p)
    p.write_text(f't_s,"{"w" * 200_000}",wy,wz\n0,0,0,0\n')
    with pytest.raises(InputError, match=r"g.csv: line 1 cannot be read as CSV"):
        read_gyro_log(p)


def test_a_log_split_by_spaces_with_a_header(tmp_path, trace):
    """``timestamp x y z`` and rows split by runs of spaces read as the comma-separated
    log does; a row missing a value is refused (the values after it would move into its
    column), as many values as the first row has being the rule (a header may end in a
    unit word: ``t x y z (rad/s)``)."""
    t_ns = [int(round(a * 1e9)) for a in trace.t]
    text = _csv_text("timestamp,x,y,z,temp", t_ns, [*trace.omega.T, 0 * trace.t + 31.5])
    (tmp_path / "c.csv").write_text(text)
    (tmp_path / "s.txt").write_text(text.replace(",", "  "))
    spaced, commas = read_gyro_log(tmp_path / "s.txt"), read_gyro_log(tmp_path / "c.csv")
    assert np.array_equal(spaced.t, commas.t) and np.array_equal(spaced.omega, commas.omega)
    assert np.allclose(spaced.omega, trace.omega, atol=1e-12)
    rows = text.replace(",", " ").splitlines()
    short = rows[5].split()
    rows[5] = " ".join(short[:2] + short[3:])                      # y left out
    (tmp_path / "s.txt").write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match="s.txt: line 6: 4 values where line 2 has 5: split "
                                         "by spaces"):
        read_gyro_log(tmp_path / "s.txt")
    t_s = text.replace(",", " ").splitlines()[1:]
    (tmp_path / "u.txt").write_text("t_ns x y z temp (degC)\n" + "\n".join(t_s) + "\n")
    assert np.array_equal(read_gyro_log(tmp_path / "u.txt", time_unit="ns").omega, commas.omega)


def test_json_lines_a_bracketed_csv_header_and_samples_that_name_no_sensor(tmp_path, trace):
    """One JSON object per line reads as a list of them; a CSV whose header starts with
    a bracket is not taken for JSON; samples without a ``sensor`` among named ones are
    left out with a warning; text in a key not read (newlines, commas) is no matter."""
    import json

    samples = json.loads(_sensor_logger_json(trace, others=False))
    for r in samples:
        r["note"] = "a, b\nc\u2028d"
    (tmp_path / "g.jsonl").write_text("\n".join(json.dumps(r) for r in samples) + "\n")
    log = read_gyro_log(tmp_path / "g.jsonl")
    assert log.meta["format"] == "json" and np.allclose(log.omega, trace.omega, atol=1e-12)
    for r in samples[::2]:
        r["sensor"] = "GYROSCOPE"                    # its name in any case
    (tmp_path / "g.json").write_text(json.dumps(samples + [{"time": "1", "x": "9"},
                                                           {"sensor": None, "time": "2"}]))
    with pytest.warns(UserWarning, match="g.json: 2 sample.* name no sensor, where the others "
                                         "do: left out \\(only the GYROSCOPE samples"):
        log = read_gyro_log(tmp_path / "g.json")
    assert np.allclose(log.omega, trace.omega, atol=1e-12)
    p = tmp_path / "b.csv"
    p.write_text(_csv_text("[time] [ms],x,y,z", [float(a * 1e3) for a in trace.t],
                           trace.omega.T))
    assert np.allclose(read_gyro_log(p).t, trace.t, atol=1e-9)


def test_coverage_and_gaps():
    t = np.concatenate([np.arange(0, 0.1, 0.005), np.arange(0.2, 0.3, 0.005)])
    log = GyroLog(t, np.zeros((t.size, 3)), "g.csv")
    check_coverage(log, 0.01, 0.05)
    with pytest.raises(InputError, match="g.csv.*gap of"):
        check_coverage(log, 0.05, 0.25)
    with pytest.raises(InputError, match="g.csv.*covers"):
        check_coverage(log, 0.25, 0.4)
    with pytest.raises(InputError, match="g.csv.*covers"):     # starts before the log
        check_coverage(log, -0.05, 0.02)
    # a start given in ms (or us, ns) where the log's seconds are: said so
    with pytest.raises(InputError, match=r"covers 0.000000..0.295000 s but the exposure needs "
                                         r"200.000000..200.030000 s .*; if exposure_start is "
                                         r"in ms, give it in seconds: read as ms it falls in "
                                         r"the log\)"):
        check_coverage(log, 200.0, 200.03)
    for t0 in (1e12, 2.0):       # neither in the log read as ms, nor far beyond the log
        with pytest.raises(InputError, match="covers") as e:
            check_coverage(log, t0, t0 + 0.03)
        assert "read as" not in str(e.value)


def test_a_window_ending_on_the_last_sample_is_covered_despite_rounding():
    """A window computed as start + readout + exposure can end one rounding step past a
    log's last sample (0.5 + 0.03 + 0.04 = 0.5700000000000001), or start one before its
    first on a Unix clock: still covered. A millisecond beyond is not."""
    t = np.linspace(0.0, 0.57, 115)
    log = GyroLog(t, np.zeros((t.size, 3)), "g.csv")
    check_coverage(log, 0.5, 0.5 + 0.03 + 0.04)
    with pytest.raises(InputError, match="g.csv.*covers"):
        check_coverage(log, 0.5, 0.571)
    unix = 1.7e9 + np.arange(0.0, 1.0, 0.005)
    log = GyroLog(unix, np.zeros((unix.size, 3)), "u.csv")
    start = (unix[0] + 0.4) - 0.4            # the first sample, give or take a rounding step
    check_coverage(log, np.nextafter(start, 0.0), start + 0.05)
    with pytest.raises(InputError, match="u.csv.*covers"):
        check_coverage(log, unix[0] - 1e-3, unix[0] + 0.05)


def test_a_coarse_log_is_told_its_rate_and_the_limit_is_inclusive():
    """A 20 Hz log (steps of 50 ms, as read from text: not exactly 0.05) meets a 50 ms
    limit; under a 40 ms limit it is refused for its rate, not for a gap it does not
    have. A real gap in a 200 Hz log is still a gap."""
    t = np.arange(40) * 0.05
    log = GyroLog(t, np.zeros((t.size, 3)), "slow.csv")
    assert np.diff(t).max() > 0.05                          # the float steps
    check_coverage(log, 0.5, 0.6, max_gap=0.05)
    with pytest.raises(InputError, match=r"slow.csv.*only every 50.0 ms \(20 Hz\)") as e:
        check_coverage(log, 0.5, 0.6, max_gap=0.04)
    assert "gap of" not in str(e.value)
    t = np.concatenate([np.arange(0, 0.5, 0.005), np.arange(0.56, 1.0, 0.005)])
    with pytest.raises(InputError, match="g.csv.*gap of 65.0 ms"):
        check_coverage(GyroLog(t, np.zeros((t.size, 3)), "g.csv"), 0.45, 0.6)


def test_rate_noise_measures_white_noise_not_hand_motion():
    from gyrodeblur.gyrolog import rate_noise

    t = np.arange(0.0, 3.0, 1 / 200)
    shake = np.stack([0.6 * np.sin(2 * np.pi * 3.1 * t), 0.8 * np.cos(2 * np.pi * 8.9 * t),
                      0.3 * np.sin(2 * np.pi * 4.3 * t + 0.7)], 1)
    assert rate_noise(GyroLog(t, shake)) < 0.002          # smooth motion: almost nothing
    rng = np.random.default_rng(0)
    for sigma in (0.007, 0.02, 0.05):
        noisy = GyroLog(t, shake + rng.normal(0, sigma, shake.shape))
        assert rate_noise(noisy) == pytest.approx(sigma, rel=0.15)
    assert np.isnan(rate_noise(GyroLog(t[:8], shake[:8])))
    # at 50 Hz a shake of 2-9 Hz on every axis nearly fills the band; still the noise,
    # not the motion, is read (a fourth difference read 0.035 here for 0.005, and made
    # calibration keep wrong parameters under a margin seven times too wide)
    t = np.arange(0.0, 3.0, 1 / 50)
    shake = np.stack([0.5 * np.sin(2 * np.pi * 3.1 * t) + 0.3 * np.sin(2 * np.pi * 8.3 * t),
                      0.4 * np.cos(2 * np.pi * 9.1 * t) + 0.4 * np.sin(2 * np.pi * 2.2 * t),
                      0.2 * np.sin(2 * np.pi * 4.3 * t + 0.7)
                      + 0.3 * np.sin(2 * np.pi * 7.7 * t + 2)], 1)
    for sigma in (0.005, 0.02):
        noisy = GyroLog(t, shake + rng.normal(0, sigma, shake.shape))
        assert rate_noise(noisy) == pytest.approx(sigma, rel=0.5)


def test_median_rate_finds_a_bias_under_hand_motion_with_an_honest_error():
    from gyrodeblur.gyrolog import median_rate

    t = np.arange(0.0, 20.0, 1 / 200)
    bias = np.array([0.03, -0.02, 0.01])
    errors, ses, naive = [], [], []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        # hand motion: oscillations plus a slow random wander of the rate, correlated
        # over ~0.5 s (its mean over the log is what the error bar must cover)
        wander = np.stack([np.convolve(rng.normal(0, 0.3, t.size), np.ones(100) / 100,
                                       "same") for _ in range(3)], 1)
        shake = np.stack([0.15 * np.sin(2 * np.pi * 3.1 * t + seed),
                          0.2 * np.cos(2 * np.pi * 8.9 * t), 0.12 * np.sin(2 * np.pi * 4.3 * t)],
                         1) + wander
        m, se, secs = median_rate(GyroLog(t, shake + bias))
        assert secs == pytest.approx(20.0)
        errors.append(m - bias)
        ses.append(se)
        naive.append(shake.std(axis=0) / np.sqrt(t.size))
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    typical = np.sqrt(np.mean(np.square(ses), axis=0))
    assert np.all(rms < 0.01)
    assert np.all((typical > 0.6 * rms) & (typical < 1.7 * rms))   # the error bar is honest
    assert np.all(np.mean(naive, axis=0) < 0.6 * rms)   # which per-sample statistics are not
    # a few seconds of deliberate motion (a 3 s pan at 0.5 rad/s) move it little
    pan = shake + bias
    pan[(t > 8) & (t < 11), 1] += 0.5
    m_pan = median_rate(GyroLog(t, pan))[0]
    assert abs(m_pan[1] - m[1]) < 0.02 < 0.5 * 3 / 20
    # two stretches of log a minute apart (one session's photos): the time between them
    # and the half-filled blocks at their ends are not counted
    apart = np.r_[t[:1100], t[:1100] + 60.0] + 0.3
    m, se, secs = median_rate(GyroLog(apart, np.r_[shake[:1100], shake[:1100]]))
    assert secs == pytest.approx(10.0)
    # under two whole blocks: nothing
    m, se, secs = median_rate(GyroLog(t[:300], shake[:300]))
    assert secs == 0.0 and np.all(np.isnan(m)) and np.all(np.isnan(se))


@pytest.mark.parametrize("name, axis", [
    ("x", "x"), ("gyro_y", "y"), ("rotationRateZ", "z"), ("w_RS_S_x", "x"), ("x_gyro", "x"),
    ("gx [deg/s]", "x"), ("wz_rad_s", "z"), ("ax", None), ("acc_x", None), ("time", None)])
def test_rate_axis_reads_the_axis_from_loggers_column_names(name, axis):
    assert rate_axis(name) == axis


@pytest.mark.parametrize("name, is_time", [
    ("t", True), ("timestamp", True), ("seconds_elapsed", True), ("t_ns", True),
    ("roll_rad_s", False), ("x", False), ("sample", False)])
def test_looks_like_time_tells_times_from_rates(name, is_time):
    assert looks_like_time(name) is is_time


def test_time_unit_from_interval_refuses_rates_outside_a_gyros():
    t = np.arange(100) * 5e6                       # 200 Hz in ns
    assert time_unit_from_interval(t)[0] == "ns"
    assert time_unit_from_interval(np.arange(100) * 0.1)[0] is None   # 10 Hz in s: refused


def test_read_gyro_log_checks_its_format_and_options(tmp_path, trace):
    write_gcsv(tmp_path / "g.gcsv", trace)
    with pytest.raises(InputError, match="unknown gyro log format 'tsv'"):
        read_gyro_log(tmp_path / "g.gcsv", "tsv", time_unit="ms")
    with pytest.raises(TypeError, match="unknown option.*time_units"):
        read_gyro_log(tmp_path / "g.gcsv", time_units="ms")
    with pytest.warns(UserWarning, match="time_unit applies to CSV and JSON logs only; this "
                                         "log is gcsv"):
        read_gyro_log(tmp_path / "g.gcsv", time_unit="ms")


def _rows(trace, rate_scale=1.0, prefix=""):
    return "\n".join(f"{prefix}{int(round(a * 1e9))}," + ",".join(repr(float(v) * rate_scale)
                                                               for v in w)
                     for a, w in zip(trace.t, trace.omega))


def test_text_columns_the_log_does_not_use_are_not_read(tmp_path, trace):
    # the iOS SensorLog app writes a date first, then times and the gyro's columns by name
    p = tmp_path / "sensorlog.csv"
    p.write_text("loggingTime(txt),gyroTimestamp_sinceReboot(ns),gyroRotationX(rad/s),"
                 "gyroRotationY(rad/s),gyroRotationZ(rad/s)\n"
                 + _rows(trace, prefix="2024-01-01 10:00:00.000 +0100,") + "\n")
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-9) and np.allclose(log.omega, trace.omega)
    # a text value in a column that is used is named by its column
    p.write_text("t_ns,gx,gy,gz\n0,0,0,0\n5000000,0,abc,0\n10000000,0,0,0\n")
    with pytest.raises(InputError, match=r"line 3: column 'gy' is not a number \('abc'\)"):
        read_gyro_log(p, time_unit="ns", rate_unit="rad/s")


@pytest.mark.parametrize("location", [True, False])
def test_a_log_of_several_sensors_takes_the_gyros_own_timestamps(tmp_path, trace, location):
    """iOS SensorLog's full export: the location's and the accelerometer's timestamps come
    before the gyro's own, and the rates are paired with the time column of their own
    sensor (the first time column would be the location's, repeated between fixes, or the
    accelerometer's, 6 ms off)."""
    names = (["loggingTime(txt)", "loggingSample(N)"]
             + ["locationTimestamp_since1970(s)"] * location
             + ["accelerometerTimestamp_sinceReboot(s)", "accelerometerAccelerationX(G)",
                "accelerometerAccelerationY(G)", "accelerometerAccelerationZ(G)",
                "gyroTimestamp_sinceReboot(s)", "gyroRotationX(rad/s)", "gyroRotationY(rad/s)",
                "gyroRotationZ(rad/s)", "motionTimestamp_sinceReboot(s)", "motionYaw(rad)",
                "motionRotationRateX(rad/s)", "motionRotationRateY(rad/s)",
                "motionRotationRateZ(rad/s)"])
    rows = []
    for k, (a, w) in enumerate(zip(trace.t, trace.omega)):
        rows.append(",".join(["2024-12-05 07:27:10.512 +0100", str(k)]
                             + ["1733380030.5"] * location
                             + [repr(float(a) + 0.006), "0.01", "-0.99", "0.02"]
                             + [repr(float(a))] + [repr(float(v)) for v in w]
                             + [repr(float(a) + 0.001), "0.1"] + [repr(0.9 * float(v)) for v in w]))
    p = tmp_path / "sensorlog.csv"
    p.write_text(",".join(names) + "\n" + "\n".join(rows) + "\n")
    log = read_gyro_log(p)
    np.testing.assert_allclose(log.t, trace.t, atol=1e-9)
    np.testing.assert_allclose(log.omega, trace.omega)
    assert log.meta.get("axes") == "phone device"        # Core Motion's device axes
    # a column named by the caller is taken as it is
    log = read_gyro_log(p, time_column="accelerometerTimestamp_sinceReboot(s)")
    np.testing.assert_allclose(log.t, trace.t + 0.006, atol=1e-9)
    # an export of Core Motion's rates alone: theirs, with their own time
    keep = [0] + [i for i, n in enumerate(names) if n.startswith("motion")]
    p.write_text(",".join(names[i] for i in keep) + "\n" + "\n".join(
        ",".join(r.split(",")[i] for i in keep) for r in rows) + "\n")
    log = read_gyro_log(p)
    np.testing.assert_allclose(log.t, trace.t + 0.001, atol=1e-9)
    np.testing.assert_allclose(log.omega, 0.9 * trace.omega)
    assert log.meta.get("axes") == "phone device"


@pytest.mark.parametrize("names", [
    ("time_acc", "ax", "ay", "az", "time_gyro", "gx", "gy", "gz"),
    ("acc_timestamp", "acc_x", "acc_y", "acc_z", "timestamp_gyro", "gyro_x", "gyro_y", "gyro_z"),
    ("accTimestamp", "accX", "accY", "accZ", "gyrTimestamp", "wx", "wy", "wz"),
])
def test_an_imu_log_pairs_the_gyros_rates_with_the_gyros_own_time(tmp_path, trace, names):
    """An IMU log with the accelerometer's time column first: the rates named as the gyro's
    take the time column that names the gyro, in whichever word of its name."""
    rows = [f"{float(a) + 0.004!r},0.0,0.0,9.8,{float(a)!r}," + ",".join(map(repr, map(float, w)))
            for a, w in zip(trace.t, trace.omega)]
    p = tmp_path / "imu.csv"
    p.write_text(",".join(names) + "\n" + "\n".join(rows) + "\n")
    log = read_gyro_log(p, time_unit="s")
    np.testing.assert_allclose(log.t, trace.t, atol=1e-12)
    np.testing.assert_allclose(log.omega, trace.omega)


@pytest.mark.parametrize("options,match", [
    ({"rate_columns": (1, 1, 1)}, "three different columns"),
    ({"rate_columns": ("gx", "gy", "gy")}, "three different columns"),
    ({"rate_columns": (0, 1, 2)}, "other than the time column"),
    ({"rate_columns": (True, 2, 3)}, "must name a column .* got True"),
    ({"rate_columns": (-1, -2, -3)}, "column -1 does not exist"),
    ({"time_column": -4}, "column -4 does not exist"),
    ({"time_unit": ["ns"]}, r"time_unit must be one of s, ms, us, ns, got \['ns'\]"),
    ({"rate_unit": {"u": "rad/s"}}, "rate_unit must be one of rad/s, deg/s"),
])
def test_csv_options_of_the_wrong_kind_are_refused(tmp_path, trace, options, match):
    p = tmp_path / "g.csv"
    p.write_text("t_ns,gx,gy,gz\n" + _rows(trace) + "\n")
    with pytest.raises(InputError, match=match) as e:
        read_csv_log(p, **options)
    assert "g.csv" in str(e.value)


def test_a_rate_unit_against_the_names_warns_and_an_unstated_one_is_said(tmp_path, trace):
    p = tmp_path / "g.csv"
    p.write_text("t_ns,wx_rad_s,wy_rad_s,wz_rad_s\n" + _rows(trace) + "\n")
    with pytest.warns(UserWarning, match="deg/s, overrides the rad/s that column 'wx_rad_s'"):
        log = read_csv_log(p, rate_unit="deg/s")
    assert np.allclose(log.omega, np.radians(trace.omega))
    assert "rate_unit_from" not in log.meta
    p.write_text("t_ns,gx,gy,gz\n" + _rows(trace) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # a hand-held log in rad/s: no warning
        assert read_csv_log(p).meta["rate_unit_from"].startswith("assumed")
    # a calm hand (about 0.05 rad/s) logged in deg/s, unlabelled: read as a pan of 2.6 rad/s
    p.write_text("t_ns,gx,gy,gz\n" + _rows(trace, 0.05 * 180 / np.pi) + "\n")
    with pytest.warns(UserWarning, match="fast pan throughout; if they are deg/s"):
        read_csv_log(p)


def test_an_android_dump_of_many_sensors_keeps_the_gyro(tmp_path, trace):
    p = tmp_path / "events.txt"
    lines = ["# type timestamp_ns values"]
    for a, (b, c, d) in zip(trace.t, trace.omega):
        ns = int(round(a * 1e9))
        lines += [f"16 {ns} 0.1 0.2 0.3 0.001 0.002 0.003", f"5 {ns} 120.0",
                  f"4 {ns} {float(b)!r} {float(c)!r} {float(d)!r}",
                  f"11 {ns} 0.1 0.2 0.3 0.9 0.01"]
    p.write_text("\n".join(lines) + "\n")
    log = read_gyro_log(p)                       # format guessed from a type-16 line
    assert np.allclose(log.t, trace.t, atol=1e-9) and np.allclose(log.omega, trace.omega)
    p.write_text("4 1000000000 0.1 0.2\n4 1005000000 0.1 0.2 0.3\n")
    with pytest.raises(InputError, match="line 1: a gyroscope event .* got 4 values"):
        read_android_events(p)


@pytest.mark.parametrize("encoding", ["cp1252", "utf-16"])
def test_logs_saved_by_windows_tools_are_read(tmp_path, trace, encoding):
    p = tmp_path / "g.csv"
    rows = _rows(trace, 180 / np.pi).replace(",", ";").replace(".", ",")
    p.write_bytes(("t (ns);gx (°/s);gy (°/s);gz (°/s)\r\n" + rows + "\r\n").encode(encoding))
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-9) and np.allclose(log.omega, trace.omega)
    p.write_bytes(b"t_ns,gx,gy,gz\n\x00\x01\x02")
    with pytest.raises(InputError, match="not a text file"):
        read_gyro_log(p)


def _formatted_rows(trace, fmt, sep=","):
    return "".join(sep.join(fmt(v) for v in (t, *w)) + "\n" for t, w in zip(trace.t, trace.omega))


def test_quoted_values_holding_the_delimiter_keep_the_columns_apart(tmp_path, trace):
    """A spreadsheet quotes a text value holding a comma; an unquoted one shifts the
    columns, which is refused rather than read as other rates."""
    p = tmp_path / "q.csv"
    p.write_text("t_s,place,gx,gy,gz\n" + "".join(
        f'{t:.6f},"48.1,11.5",{w[0]:.9f},{w[1]:.9f},{w[2]:.9f}\n'
        for t, w in zip(trace.t, trace.omega)))
    log = read_gyro_log(p)
    assert np.allclose(log.omega, trace.omega, atol=1e-8)
    p.write_text(p.read_text().replace('"48.1,11.5"', "48.1,11.5"))
    with pytest.raises(InputError, match="6 values where the header names 5 columns"):
        read_gyro_log(p)


def test_a_tab_separated_log_may_use_the_decimal_comma(tmp_path, trace):
    """phyphox's "CSV (Tabulator, decimal comma)" export."""
    p = tmp_path / "phyphox.csv"
    p.write_text('"Time (s)"\t"Gyroscope x (rad/s)"\t"Gyroscope y (rad/s)"\t'
                 '"Gyroscope z (rad/s)"\n'
                 + _formatted_rows(trace, lambda v: f"{v:.9E}".replace(".", ","), "\t"))
    log = read_gyro_log(p)
    assert np.allclose(log.t, trace.t, atol=1e-6) and np.allclose(log.omega, trace.omega)
    assert log.in_device_axes and log.meta["app"] == "phyphox"     # a phone's own axes


def test_samples_with_a_missing_value_are_skipped_with_a_warning(tmp_path, trace):
    p = tmp_path / "gaps.csv"
    lines = ["t_s,wx,wy,wz"] + _formatted_rows(trace, lambda v: f"{v:.9f}").splitlines()
    lines[5] = lines[5].split(",")[0] + ",NaN,NaN,NaN"          # phyphox
    lines[9] = ",".join(lines[9].split(",")[:2]) + ",,0.1"      # an empty cell
    p.write_text("\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match="2 sample"):
        log = read_gyro_log(p)
    assert len(log) == len(trace) - 2
    assert np.allclose(log.omega, np.delete(trace.omega, [4, 8], axis=0))


def test_format_names_and_column_names_are_matched_as_a_person_types_them(tmp_path, trace):
    p = tmp_path / "log.csv"
    p.write_text("Time since start in ms ,wx,wy,wz\n"
                 + _formatted_rows(trace, lambda v: f"{v:.9f}"))
    log = read_gyro_log(p, "CSV", time_column="Time since start in ms ", time_unit="s")
    assert np.allclose(log.omega, trace.omega)
    with pytest.raises(InputError, match="unknown gyro log format 'tsv'"):
        read_gyro_log(p, "tsv")


def test_rate_columns_of_different_stated_units_are_refused(tmp_path, trace):
    p = tmp_path / "mixed.csv"
    p.write_text(_csv_text("t_s,gx (rad/s),gy (deg/s),gz (deg/s)", trace.t, list(trace.omega.T)))
    with pytest.raises(InputError, match="mixed.csv: the rate columns .* state different units"):
        read_gyro_log(p, "csv")
    p.write_text(_csv_text("t_s,gx (deg/s),gy (deg/s),gz (deg/s)", trace.t,
                           list(np.degrees(trace.omega).T)))
    np.testing.assert_allclose(read_gyro_log(p, "csv").omega, trace.omega, atol=1e-9)


def test_a_trailing_delimiter_names_no_column(tmp_path, trace):
    """``time,a,b,c,`` with rows ending in a comma is the four-column log it looks like."""
    p = tmp_path / "trail.csv"
    text = _csv_text("t_s,wx,wy,wz", trace.t, list(trace.omega.T))
    p.write_text("\n".join(line + "," for line in text.splitlines()) + "\n")
    log = read_gyro_log(p, "csv")
    np.testing.assert_allclose(log.omega, trace.omega, atol=1e-9)


def test_a_gcsv_header_key_given_twice_is_refused(tmp_path, trace):
    p = tmp_path / "dup.gcsv"
    write_gcsv(p, trace, tscale=1e-3)
    lines = p.read_text().splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("tscale"))
    p.write_text("\n".join(lines[:at + 1] + ["tscale,1"] + lines[at + 1:]) + "\n")
    with pytest.raises(InputError, match="dup.gcsv: the gcsv header gives tscale twice"):
        read_gyro_log(p)


def test_a_unit_stated_on_one_rate_column_holds_for_all(tmp_path, trace):
    p = tmp_path / "one.csv"
    p.write_text(_csv_text("t_s,gx (deg/s),gy,gz", trace.t, list(np.degrees(trace.omega).T)))
    np.testing.assert_allclose(read_gyro_log(p, "csv").omega, trace.omega, atol=1e-9)


@pytest.mark.parametrize("header, options", [
    ("t_s,gx,-gy,gz", {}),                             # found by name
    ("t_s,wx,wy,+wz", {}),
    ("t_s,gx,-gy,gz", {"rate_columns": ["gx", "-gy", "gz"]}),
    ("t_s,a,-b,c,temp", {"rate_columns": [1, 2, 3]}),  # given by index
])
def test_a_rate_column_whose_name_carries_a_sign_is_refused(tmp_path, trace, header, options):
    """A sign in a column's name is not read: taking ``-gy`` as +y turned the camera the
    wrong way without a word."""
    p = tmp_path / "signed.csv"
    cols = list(trace.omega.T) + ([np.zeros(len(trace))] if header.endswith("temp") else [])
    p.write_text(_csv_text(header, trace.t, cols))
    signed = next(h for h in header.split(",") if h[0] in "+-")
    with pytest.raises(InputError, match=f"signed.csv: rate column '\\{signed}' carries a "
                                         f"sign, which is not read"):
        read_gyro_log(p, "csv", **options)
    p.write_text(_csv_text(header.replace(signed, signed[1:]), trace.t, cols))
    unsigned = {k: [signed[1:] if c == signed else c for c in v] for k, v in options.items()}
    np.testing.assert_allclose(read_gyro_log(p, "csv", **unsigned).omega, trace.omega,
                               atol=1e-9)


def test_a_log_needs_two_samples_of_three_rates(trace):
    with pytest.raises(InputError, match="g.csv: only 1 gyro sample"):
        GyroLog(trace.t[:1], trace.omega[:1], "g.csv")
    with pytest.raises(InputError, match=r"g.csv: expected N times and N x 3 rates, got "
                                         r"\(50,\) and \(50, 2\)"):
        GyroLog(trace.t, trace.omega[:, :2], "g.csv")


def test_window_keeps_both_ends_and_median_rate_counts_seconds(trace):
    assert len(trace.window(trace.t[0], trace.t[4])) == 5             # t0 <= t <= t1
    from gyrodeblur.gyrolog import median_rate

    t = np.arange(0.0, 20.0, 1 / 200)
    assert median_rate(GyroLog(t, np.zeros((t.size, 3))), block=2.0)[2] == pytest.approx(20.0)


def test_csv_units_and_time_names_loggers_use(tmp_path, trace):
    """``gx_dps`` states deg/s; ``ts`` names a time column whose unit (here ms) the sample
    interval tells, not one that ends in the letter s."""
    p = tmp_path / "g.csv"
    p.write_text(_csv_text("ts,gx_dps,gy_dps,gz_dps", [int(round(a * 1e3)) for a in trace.t],
                           np.degrees(trace.omega).T))
    log = read_csv_log(p)
    assert log.meta["time_unit"] == "ms" and log.meta["rate_unit"] == "deg/s"
    assert np.allclose(log.t, trace.t, atol=1e-9)
    assert np.allclose(log.omega, trace.omega, atol=1e-9)


def test_five_unnamed_columns_are_not_guessed(tmp_path, trace):
    """A time and four unnamed columns (a gyro and a temperature?): which three are the
    rates would be a guess."""
    wx, wy, wz = trace.omega.T
    p = tmp_path / "imu.csv"
    p.write_text(_csv_text("t_s,c1,c2,c3,c4", trace.t, [wx, wy, wz, wx]))
    with pytest.raises(InputError, match="imu.csv: the column names .* do not say which three"):
        read_gyro_log(p)


def test_the_sample_interval_is_the_median_step_a_gap_left_out():
    """200 Hz with one 25 ms gap: 5 ms, as if the gap were not there."""
    t = np.r_[np.arange(0.0, 0.5, 0.005), 0.525 + np.arange(0.0, 0.5, 0.005)]
    assert GyroLog(t, np.zeros((t.size, 3))).sample_interval == pytest.approx(0.005)


def test_a_plain_numeric_log_is_read_at_once_to_the_same_bits_as_line_by_line(tmp_path,
                                                                             monkeypatch):
    """A log of numbers only (a gcsv, a CSV) is parsed by NumPy in one call, not line by
    line in Python (a 10-minute 4 kHz log: 9 s -> 3 s): every value is the one the
    line-by-line reader gives, bit for bit. A log it cannot take whole (an empty cell)
    goes line by line, as before."""
    import gyrodeblur.gyrolog as gl

    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.004, 0.006, 500))
    w = rng.normal(0, 0.3, (500, 3)) * 10.0 ** rng.integers(-6, 2, (500, 3))
    write_gcsv(tmp_path / "a.gcsv", GyroLog(t, w))
    rows = [",".join(repr(float(v)) for v in (ti, *wi)) for ti, wi in zip(t, w)]
    head = "t_s,wx_rad_s,wy_rad_s,wz_rad_s"
    (tmp_path / "b.csv").write_text("\n".join([head] + rows) + "\n")
    used = []
    plain = gl._plain_numeric_rows
    monkeypatch.setattr(gl, "_plain_numeric_rows",
                        lambda *a: used.append(plain(*a)) or used[-1])
    fast = [read_gyro_log(tmp_path / n) for n in ("a.gcsv", "b.csv")]
    assert len(used) == 2 and all(r is not None for r in used)
    monkeypatch.setattr(gl, "_plain_numeric_rows", lambda *a: None)
    for log, name in zip(fast, ("a.gcsv", "b.csv")):
        slow = read_gyro_log(tmp_path / name)
        assert np.array_equal(log.t, slow.t) and np.array_equal(log.omega, slow.omega)
    np.testing.assert_array_equal(fast[1].t, t)
    np.testing.assert_array_equal(fast[1].omega, w)
    monkeypatch.setattr(gl, "_plain_numeric_rows", plain)
    (tmp_path / "c.csv").write_text("\n".join([head] + rows[:250] + [f"{float(t[250]) - 1e-4!r},,0,0"]
                                               + rows[250:]) + "\n")
    assert plain(rows[:250] + ["1.0,,0,0"], [0, 1, 2, 3], ",", head.split(",")) is None
    with pytest.warns(UserWarning, match="1 sample"):
        assert len(read_gyro_log(tmp_path / "c.csv")) == 500


def test_a_gyro_clipped_at_its_range_is_told_and_peaks_constants_and_steps_are_not():
    """``saturation_warning``: a shake clipped at 1 rad/s (the rate run flat at the log's
    largest value, entered at a slope that would have gone beyond it) is told with its
    axis, level and run, inside the window only; the same shake unclipped, a constant
    rate, a step up to one and a coarsely quantised slow peak (several equal samples at
    the top, reached gently) are not."""
    from gyrodeblur.gyrolog import saturation_warning

    t = np.arange(0.0, 2.0, 0.005)
    shake = 2.0 * np.sin(2 * np.pi * 3.0 * t) * np.exp(-((t - 1.0) / 0.3) ** 2)

    def log(x):
        return GyroLog(t, np.stack([np.zeros_like(x), x, np.zeros_like(x)], axis=1))

    said = saturation_warning(log(np.clip(shake, -1.0, 1.0)), 0.9, 1.1)
    assert said is not None
    assert said.startswith("the rates look clipped within the exposure (axis y at +1 rad/s "
                           "for ")
    assert "axis y at -1 rad/s for " in said                      # both sides clipped
    glitch = np.clip(shake, -1.0, 1.0)
    glitch[20] = 1.3                                              # one sample above the clip
    assert "axis y at +1 rad/s for " in saturation_warning(log(glitch), 0.9, 1.1)
    lopsided = np.clip(shake, -1.1, 0.9)           # a bias subtracted: +0.9 and -1.1 (-1.1
    assert "at -1.1 rad/s" in saturation_warning(log(lopsided), 0.9, 1.1)   # found alone)
    assert "the PSFs come out too short" in said
    assert saturation_warning(log(np.clip(shake, -1.0, 1.0)), 0.0, 0.3) is None  # not there
    assert saturation_warning(log(shake), 0.0, 2.0) is None
    assert saturation_warning(log(np.full_like(t, 0.7)), 0.0, 2.0) is None
    assert saturation_warning(log(np.where(t > 1.0, 0.7, 0.0)), 0.0, 2.0) is None
    slow = np.round(np.sin(2 * np.pi * 0.2 * t) / 0.01) * 0.01      # 5 s period, 0.01 steps
    assert np.sum(slow == slow.max()) >= 3
    assert saturation_warning(log(slow), 0.0, 2.0) is None
    # a 500 Hz log of a smooth sway rounded to a +-2000 deg/s 16-bit gyro's step: its
    # peak repeats its top value, entered two steps below it, which extrapolates a step
    # beyond (a rule without a margin took 42 of 240 such logs for clipped)
    t5 = np.arange(0.0, 1.0, 1 / 500)
    quantum = np.radians(2000) / 32768
    sway = np.round(1.2 * np.sin(2 * np.pi * 2.0 * t5 + 1.0) / quantum) * quantum
    assert np.sum(np.abs(sway) == np.abs(sway).max()) >= 3
    rounded = GyroLog(t5, np.stack([sway, 0 * sway, 0 * sway], axis=1))
    assert saturation_warning(rounded, 0.0, 1.0) is None


def test_a_step_between_samples_inside_the_exposure_is_told_as_a_gap_or_a_rate():
    """``step_warning``: silent for a 200 Hz log and for a dropout outside the window; a
    dropout inside it is named with its length and time; a 40 Hz log by its rate."""
    from gyrodeblur.gyrolog import INTERPOLATED_STEP, largest_step, step_warning

    t = np.arange(0.0, 1.0, 0.005)
    full = GyroLog(t, np.zeros((t.size, 3)))
    assert step_warning(full, 0.4, 0.46) is None
    keep = np.ones(t.size, bool)
    keep[83:88] = False                                   # 0.410 -> 0.440: a 30 ms step
    holed = GyroLog(t[keep], np.zeros((keep.sum(), 3)))
    gap, at = largest_step(holed, 0.4, 0.46)
    assert gap == pytest.approx(0.03) and at == pytest.approx(0.41)
    said = step_warning(holed, 0.4, 0.46)
    assert said.startswith("gap of 30.0 ms in the gyro log at 0.410000 s, inside the exposure")
    assert step_warning(holed, 0.5, 0.56) is None         # the hole lies before the window
    assert step_warning(holed, 0.3, 0.4101) is not None   # a window that enters the hole
    edge = np.ones(t.size, bool)
    edge[83:85] = False                                   # 0.410 -> 0.425: the limit, passes
    assert INTERPOLATED_STEP == pytest.approx(0.015)
    assert step_warning(GyroLog(t[edge], np.zeros((edge.sum(), 3))), 0.4, 0.46) is None
    t40 = np.arange(0.0, 1.0, 0.025)
    coarse = step_warning(GyroLog(t40, np.zeros((t40.size, 3))), 0.4, 0.46)
    assert coarse.startswith("the gyro log has a sample only every 25.0 ms (40 Hz)")
    assert largest_step(full, 2.0, 3.0) == (0.0, 2.0)     # no two samples around it


def test_a_log_built_in_code_is_refused_as_it_is_wrong():
    """Boolean rates had been read as 0 and 1 rad/s; two samples at one time were said to
    have "other rates" when theirs were equal; float32 Unix times, which collapse onto one
    another, were told only as repeated times."""
    t = 100.0 + np.arange(400) * 0.005
    with pytest.raises(InputError, match="gyro omega must be real numbers, got dtype bool"):
        GyroLog(t, np.zeros((400, 3), bool))
    twice = t.copy()
    twice[10] = twice[9]
    with pytest.raises(InputError, match=r"sample 11 has the time of sample 10 \(100.045000 s\) "
                                         r"with the same rates"):
        GyroLog(twice, np.zeros((400, 3)))
    w = np.zeros((400, 3))
    w[10] = 0.1
    with pytest.raises(InputError, match="with other rates"):
        GyroLog(twice, w)
    with pytest.raises(InputError, match=r"gyro times are float32: at 1.7e\+09 s they are kept "
                                         r"only to 128 s; give them as float64"):
        GyroLog((1.7e9 + np.arange(400) * 0.005).astype(np.float32), np.zeros((400, 3)))
    since_boot = (1200.0 + np.arange(400) * 0.005).astype(np.float32)   # to 0.12 ms
    assert GyroLog(since_boot, np.zeros((400, 3))).t.dtype == np.float64


def test_a_time_unit_that_makes_no_gyros_rate_is_refused_naming_the_one_that_fits(
        tmp_path, trace):
    """A column named ``t_ns`` that holds milliseconds read as nanoseconds is a 200 MHz
    gyro: refused, with the unit that makes the log a 200 Hz one (it had been read, and
    then said not to cover the exposure, blaming the capture's start). A unit given that
    way is refused the same; a drone's 8 kHz log in ns and a 2 Hz one in s are read."""
    p = tmp_path / "ms.csv"
    p.write_text("t_ns,wx,wy,wz\n" + "".join(
        f"{t * 1e3:.4f},{w[0]:.6f},{w[1]:.6f},{w[2]:.6f}\n" for t, w in zip(trace.t, trace.omega)))
    with pytest.raises(InputError, match=r"time column 't_ns' read in ns, as its name states: "
                                         r"its median sample interval, 5 ns, is that of a "
                                         r"2e\+08 Hz gyro, which no gyro is; in ms it is a "
                                         r"200 Hz gyro's; give the right unit \(--time-unit "
                                         r"s\|ms\|us\|ns, or gyro.time_unit\)"):
        read_gyro_log(p)
    with pytest.warns(UserWarning, match="the time unit given, ms, overrides the ns"):
        assert np.allclose(read_gyro_log(p, time_unit="ms").t, trace.t, atol=1e-6)
    s = tmp_path / "s.csv"
    s.write_text("t,wx,wy,wz\n" + _formatted_rows(trace, lambda v: f"{v:.6f}"))
    with pytest.raises(InputError, match=r"read in ms, as given: .* 2e\+05 Hz gyro.* in s "
                                         r"it is a 200 Hz"):
        read_gyro_log(s, time_unit="ms")
    fast = tmp_path / "fast.csv"
    fast.write_text("t_ns,wx,wy,wz\n" + "".join(f"{k * 125_000},0.1,0.2,0.3\n"
                                                 for k in range(50)))
    assert read_gyro_log(fast).sample_interval == pytest.approx(1.25e-4)
    slow = tmp_path / "slow.csv"
    slow.write_text("t_s,wx,wy,wz\n" + "".join(f"{k * 0.5},0.1,0.2,0.3\n" for k in range(9)))
    assert read_gyro_log(slow).sample_interval == pytest.approx(0.5)


def test_a_log_without_a_header_line_is_read_from_the_column_numbers_given(tmp_path, trace):
    """A logger that writes no header (``x,y,z,timestamp_ns``, as OpenCamera Sensors is
    said to): with the time and rate columns given by number (from 0) it is read, the
    unit of the times given or found from their intervals, the first line a sample, its
    line numbers the file's; without them it is refused with the options named (they had
    not helped: the header was required all the same)."""
    p = tmp_path / "noheader.csv"
    p.write_text("".join(f"{w[0]:.9f},{w[1]:.9f},{w[2]:.9f},{int(round(t * 1e9))}\n"
                         for t, w in zip(trace.t, trace.omega)))
    log = read_gyro_log(p, time_column=3, rate_columns=(0, 1, 2), time_unit="ns")
    assert np.allclose(log.t, trace.t, atol=1e-9) and np.allclose(log.omega, trace.omega)
    log = read_gyro_log(p, time_column="3", rate_columns=["0", "1", "2"])    # as JSON may
    assert np.allclose(log.t, trace.t, atol=1e-9) and log.meta["time_unit"] == "ns"
    log = read_gyro_log(p, time_column=3, rate_columns=(2, 1, 0), time_unit="ns")
    assert np.allclose(log.omega, trace.omega[:, ::-1])
    with pytest.raises(InputError, match=r"no header line .* give its time and rate columns "
                                         r"by number, from 0: the capture's gyro.time_column"):
        read_gyro_log(p)
    with pytest.raises(InputError, match="no header line"):
        read_gyro_log(p, time_column=3)
    with pytest.raises(InputError, match=r"column 4 does not exist \(the log has 4, counted "
                                         r"from 0\)"):
        read_gyro_log(p, time_column=3, rate_columns=(0, 1, 4))
    with pytest.raises(InputError, match="rate_columns must be three different columns"):
        read_gyro_log(p, time_column=3, rate_columns=(0, 1, 1))
    lines = p.read_text().splitlines()
    lines[2] = lines[2].replace(",", ";", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 3"):
        read_gyro_log(p, time_column=3, rate_columns=(0, 1, 2))


@pytest.mark.parametrize("layout", ["spaces", "pandas", "decimal comma"])
def test_headerless_logs_in_other_layouts_are_read_from_the_column_numbers(tmp_path, trace,
                                                                           layout):
    """Without column names: space-separated with an integer time first (it had been
    taken for an Android dump, the column numbers ignored), pandas' ``0,1,2,3`` names
    (not a sample at t = 0), and semicolons with decimal commas (as many commas as
    semicolons in a sample: the semicolon is the delimiter)."""
    ns = [int(round(t * 1e9)) for t in trace.t]
    if layout == "spaces":
        text = "".join(f"{n} {w[0]:.9f} {w[1]:.9f} {w[2]:.9f}\n" for n, w in zip(ns, trace.omega))
    elif layout == "pandas":
        text = "0,1,2,3\n" + "".join(f"{n},{w[0]:.9f},{w[1]:.9f},{w[2]:.9f}\n"
                                     for n, w in zip(ns, trace.omega))
    else:
        text = "".join(";".join([str(n)] + [f"{v:.9f}".replace(".", ",") for v in w]) + "\n"
                       for n, w in zip(ns, trace.omega))
    p = tmp_path / "log.txt"
    p.write_text(text)
    log = read_gyro_log(p, time_column=0, rate_columns=(1, 2, 3))
    assert len(log) == len(trace) and log.meta["time_unit"] == "ns"
    assert np.allclose(log.t, trace.t, atol=1e-9) and np.allclose(log.omega, trace.omega)


@pytest.mark.parametrize("name, scale, rate, fits", [
    ("t_ms", 1.0, 50, "in s it is a 50 Hz"),          # Android's slowest game rate, in s
    ("t_s", 1e3, 1000, "in ms it is a 1000 Hz"),      # a fast IMU's, in ms
    ("t_ms", 1e6, 1500, "in us it is a 1500 Hz"),
])
def test_phone_and_imu_rates_a_unit_off_are_refused(tmp_path, name, scale, rate, fits):
    t = 100.0 + np.arange(40) / rate
    p = tmp_path / "log.csv"
    p.write_text(f"{name},wx,wy,wz\n" + "".join(f"{v * scale:.6f},0.1,0.2,0.3\n" for v in t))
    with pytest.raises(InputError, match=fits):
        read_gyro_log(p)
