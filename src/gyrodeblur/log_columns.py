"""What the columns of a text gyro log hold: which is the time and which the x, y and z
rates, in which units, split by which delimiter.

Used by :func:`gyrodeblur.gyrolog.read_csv_log` when the caller does not say. Names are
read as loggers write them (``t_ns``, ``wx_rad_s``, ``gx [deg/s]``, ``rotationRateX``,
EuRoC's ``w_RS_S_x``, Sensor Logger's ``time,seconds_elapsed,z,y,x``); a time column without
a unit is read in the unit that gives a gyro's sample interval; where the names leave the
answer open, the caller gets an :class:`~gyrodeblur.errors.InputError` naming the file, not
a guess.
"""

from __future__ import annotations

import csv
import re

import numpy as np

from .errors import InputError

__all__ = ["TIME_UNITS", "RATE_UNITS", "RATE_UNIT_ENDINGS", "RATE_ALIASES",
           "GUESSED_RATE_RANGE", "PLAUSIBLE_RATE_RANGE", "parse_number", "is_number",
           "unit_from_name", "bracketed_unit", "sniff_delimiter", "time_unit_from_interval",
           "implausible_time_unit", "rate_axis",
           "looks_like_time", "default_time_column", "sensor_time_column",
           "default_rate_columns",
           "phone_app", "refuse_signed_names"]

#: Seconds per unit of time.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: rad/s per unit of angular rate.
RATE_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}


def parse_number(text: str, decimal_comma: bool = False) -> float:
    """A value of a log's line, quotes stripped; with ``decimal_comma`` (semicolon- or
    tab-separated files, as spreadsheets and phyphox write them where the comma is the
    decimal mark) ``-0,82`` is -0.82."""
    text = text.strip().strip('"')
    if decimal_comma and "," in text and "." not in text:
        text = text.replace(",", ".")
    return float(text)


#: Endings of a column name that state its rate unit (``wx_rad_s``, ``gx_deg_s``, ``gx_dps``).
RATE_UNIT_ENDINGS = {"_rad_s": "rad/s", "_deg_s": "deg/s", "_dps": "deg/s"}
#: Other spellings of the rate units, as column names state them (spaces removed).
RATE_ALIASES = {"dps": "deg/s", "°/s": "deg/s", "deg/sec": "deg/s", "degrees/s": "deg/s",
                "rad/sec": "rad/s", "rads^-1": "rad/s", "radians/s": "rad/s"}


def unit_from_name(name: str, units: dict) -> str | None:
    """The unit of ``units`` a column's name ends with (``t_ns``, ``wx_deg_s``, ``gx_dps``)
    or states in brackets (``t (ns)``, ``gx [deg/s]``, ``w_x [rad s^-1]``), or ``None``."""
    stated = bracketed_unit(name)
    if stated is not None:
        stated = RATE_ALIASES.get(stated, stated) if units is RATE_UNITS else stated
        return stated if stated in units else None
    low = name.lower().replace("/", "_")
    if units is RATE_UNITS:
        return next((u for end, u in RATE_UNIT_ENDINGS.items() if low.endswith(end)), None)
    for unit in sorted(units, key=len, reverse=True):
        if low.endswith("_" + unit.replace("/", "_")):
            return unit
    return None


def bracketed_unit(name: str) -> str | None:
    """What a column's name states in brackets at its end (lower case, spaces removed):
    ``"gx [deg/s]"`` -> ``"deg/s"``; ``None`` without brackets."""
    m = re.search(r"[(\[]([^()\[\]]*)[)\]]\s*$", name)
    return None if m is None else re.sub(r"\s+", "", m.group(1).lower())


#: Gyro sample rates (Hz, lowest and highest) a time column without a unit is read for: a factor of
#: two inside the rates whose intervals no two units share (10 Hz to 5 kHz), so a log a
#: little outside them is refused rather than read in the wrong unit.
GUESSED_RATE_RANGE = (20.0, 2500.0)


def sniff_delimiter(line: str) -> str:
    """Of comma, semicolon and tab, the one that splits the header ``line`` into the most
    fields (quotes respected; on a tie semicolon, then tab: a sample written with decimal
    commas, ``0,1;0,2;0,3``, holds as many commas as semicolons); ``" "`` (runs of
    whitespace) for a line that holds none of them but does hold spaces (``timestamp x y
    z``)."""
    if not any(d in line for d in ",;\t") and len(line.split()) > 1:
        return " "

    def count(d: str) -> int:
        try:
            return len(next(csv.reader([line], delimiter=d)))
        except csv.Error:              # a field the reader will not take: counted plainly
            return len(line.split(d))

    return max((count(d), -k, d) for k, d in enumerate((";", "\t", ",")))[2]


def time_unit_from_interval(t: np.ndarray) -> tuple[str | None, float]:
    """The time unit in which the median interval between increasing timestamps ``t`` is
    that of a gyro sampled at 20 Hz to 2.5 kHz, and that interval. The units' ranges are
    125 wide and 1000 apart, so no interval fits two units, and a log sampled up to twice
    as fast or as slow as these rates fits none (rather than the wrong one); one yet
    further outside could fit the wrong unit (a 25 kHz log in ns reads as 25 Hz in us)."""
    d = np.diff(np.asarray(t, np.float64))
    d = d[d > 0]
    if d.size == 0:
        return None, float("nan")
    m = float(np.median(d))
    for unit, per_second in (("s", 1.0), ("ms", 1e3), ("us", 1e6), ("ns", 1e9)):
        if per_second / GUESSED_RATE_RANGE[1] <= m <= per_second / GUESSED_RATE_RANGE[0]:
            return unit, m
    return None, m


#: Sample rates (Hz) beyond which a stated time unit is taken for a wrong one: a log of
#: 50 Hz to 1.5 kHz (a phone's game rate to a fast IMU's) read in a unit 1000 off lands
#: outside, a drone's 32 kHz gyro inside, and so does a log as slow as 2 Hz, which is of
#: no use for an exposure but not a wrong unit.
PLAUSIBLE_RATE_RANGE = (2.0, 40_000.0)


def implausible_time_unit(t: np.ndarray, unit: str) -> str | None:
    """What is wrong with reading the increasing times ``t`` in ``unit``, when their
    median sample interval then makes a gyro faster or slower than
    :data:`PLAUSIBLE_RATE_RANGE` (a column named ``t_ns`` that holds milliseconds), with
    the unit that would fit; ``None`` when it does not (or under two distinct times)."""
    fits, interval = time_unit_from_interval(t)
    if not np.isfinite(interval):
        return None
    rate = 1.0 / (interval * TIME_UNITS[unit])
    if PLAUSIBLE_RATE_RANGE[0] <= rate <= PLAUSIBLE_RATE_RANGE[1]:
        return None
    then = (f"; in {fits} it is a {1.0 / (interval * TIME_UNITS[fits]):.4g} Hz gyro's"
            if fits is not None else "")
    return (f"its median sample interval, {interval:.6g} {unit}, is that of a {rate:.4g} Hz "
            f"gyro, which no gyro is{then}")


#: What may come before a rate column's axis letter (lower case, letters only): ``x``,
#: ``wx``, ``gx``, ``gyro_x``, ``gyroX``, ``omega_x``, ``rotationRateX``, ``gyroRotationX``
#: and ``motionRotationRateX`` (the iOS SensorLog app's gyroscope and Core Motion's
#: bias-corrected rate of it),
#: ``angular_velocity_x`` (an accelerometer's ``ax`` or ``acc_x`` is none of them).
_RATE_PREFIXES = frozenset({"", "w", "g", "gyr", "gyro", "gyroscope", "omega", "rot",
                            "rotation", "rotationrate", "rate", "angularvelocity", "angvel",
                            "gyrorotation", "gyrorotationrate", "motionrotationrate"})
#: What may follow the axis letter instead: ``x_gyro``, ``xGyro``, ``x_rate``.
_RATE_SUFFIXES = frozenset({"gyr", "gyro", "gyroscope", "omega", "rate", "rot"})


def rate_axis(name: str) -> str | None:
    """The axis (``"x"``, ``"y"`` or ``"z"``) a column's name says it holds the rate of, or
    ``None``. A rate-unit suffix (``_rad_s``, ``_deg_s``) or a bracketed unit is ignored."""
    low = re.sub(r"[(\[].*?[)\]]", "", name.lower()).strip().replace("/", "_")
    for ending in RATE_UNIT_ENDINGS:
        if low.endswith(ending):
            low = low[:-len(ending)]
    key = re.sub(r"[^a-z]", "", low)
    if key and key[-1] in "xyz" and key[:-1] in _RATE_PREFIXES:
        return key[-1]
    if len(key) > 1 and key[0] in "xyz" and key[1:] in _RATE_SUFFIXES:
        return key[0]
    words = [w for w in re.split(r"[^a-z]+", low) if w]     # EuRoC's w_RS_S_x
    if len(words) > 2 and words[0] in _RATE_PREFIXES and words[-1] in ("x", "y", "z"):
        return words[-1]
    return None


def looks_like_time(name: str) -> bool:
    """Whether a column's name says it holds times (``t``, ``time``, ``timestamp``,
    ``seconds_elapsed``, ``t_ns``; not ``roll_rad_s``, whose ``_s`` is a rate's)."""
    low = name.lower()
    if unit_from_name(low, RATE_UNITS) is not None:
        return False
    return (low in ("t", "ts") or unit_from_name(low, TIME_UNITS) is not None
            or any(w in low for w in ("time", "stamp", "elapsed", "second")))


def default_time_column(header: list[str], first_row: list[str] | None = None) -> int:
    """The first column, unless its name is not a time's and another's is (an index column
    first, as pandas writes: ``,t_s,wx,wy,wz`` or ``sample,time,x,y,z``). With the values
    of the first data row, a column named as a time whose value there is not a number (a
    logger's ``loggingTime(txt)`` date) is passed over for the next one."""
    times = [i for i, h in enumerate(header) if looks_like_time(h)]
    if 0 in times and _is_numeric_field(first_row, 0):
        return 0
    return next((i for i in times if _is_numeric_field(first_row, i)), 0)


#: Words that name the gyroscope in a column's name (``gyroTimestamp``, ``time_gyro``,
#: ``gyrTimestamp``; a rate column ``gx`` or ``wx`` is the gyro's too).
_GYRO_WORDS = frozenset({"g", "w", "gyr", "gyro", "gyroscope", "omega", "rot", "rotation"})


def _name_words(name: str) -> list[str]:
    """A column name's words, lowercased: split at case changes and at anything not a
    letter (``gyroTimestamp_sinceReboot(s)`` -> gyro, timestamp, since, reboot, s)."""
    return [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])", name)]


def _sensor_of(rate_name: str) -> frozenset:
    """The words that name the sensor of a rate column: the gyroscope's
    (:data:`_GYRO_WORDS`) for ``gx``, ``wx_rad_s``, ``gyro_x``, ``gyroRotationX(rad/s)``;
    its own first word for another (``motionRotationRateX``: motion); none for a bare
    ``x``."""
    words = _name_words(rate_name)
    first = words[0] if words else ""
    if len(first) > 1 and first[-1] in "xyz" and rate_axis(rate_name) is not None \
            and first[:-1] in _GYRO_WORDS | {""}:
        first = first[:-1]                      # gx, wx: the axis letter joined on
    if not first or first in "xyz":
        return frozenset()
    return _GYRO_WORDS if first in _GYRO_WORDS else frozenset({first})


def sensor_time_column(header: list[str], first_row: list[str] | None, rate_columns: list[int],
                       ti: int) -> int:
    """The time column that goes with ``rate_columns`` in a log of several sensors: a
    column named as a time (and a number in ``first_row``) one of whose words names the
    rate columns' sensor (iOS SensorLog's ``gyroTimestamp_sinceReboot(s)`` for
    ``gyroRotationX(rad/s)``, ``time_gyro`` for ``gx``; not the accelerometer's or the
    location's before it); ``ti`` (the default time column) when it is one such, or when
    the rate columns share no sensor or no such column exists."""
    sensors = {_sensor_of(header[i]) for i in rate_columns}
    sensor = sensors.pop() if len(sensors) == 1 else frozenset()
    if not sensor:
        return ti

    def its(i: int) -> bool:
        return (i not in rate_columns and looks_like_time(header[i])
                and _is_numeric_field(first_row, i) and bool(sensor & set(_name_words(header[i]))))

    if ti < len(header) and its(ti):
        return ti
    return next((i for i in range(len(header)) if its(i)), ti)


def _is_numeric_field(row: list[str] | None, i: int) -> bool:
    """Whether field ``i`` of ``row`` is a number (``True`` where there is no such field)."""
    if row is None or i >= len(row):
        return True
    try:
        parse_number(row[i], decimal_comma=True)
        return True
    except ValueError:
        return False


def default_rate_columns(path: str, header: list[str], ti: int) -> list[int]:
    """The x, y, z rate columns of a CSV header when none are given: by name when the names
    say which axis each column holds, whatever their order (Sensor Logger writes
    ``time,seconds_elapsed,z,y,x``), the gyroscope's where two sensors' names do (iOS
    SensorLog's ``gyroRotationX``, not Core Motion's ``motionRotationRateX``); else the
    three columns after the time column, unless a name there contradicts that (an axis out
    of place, or a time) or the file has other columns too (which three would be a guess)."""
    named = {a: [i for i, h in enumerate(header) if i != ti and rate_axis(h) == a]
             for a in "xyz"}
    where = "; name them in the capture's gyro.rate_columns"
    if any(len(cols) > 1 for cols in named.values()):   # SensorLog's gyroRotationX beside
        sensors = {i: _sensor_of(header[i]) for cols in named.values() for i in cols}
        gyro = {a: [i for i in cols if sensors[i] == _GYRO_WORDS]     # motionRotationRateX:
                for a, cols in named.items()}                         # the gyroscope's own
        others = {sensors[i] for cols in named.values() for i in cols} - {_GYRO_WORDS}
        if others == {frozenset({"motion"})} and all(len(c) == 1 for c in gyro.values()):
            return [gyro[a][0] for a in "xyz"]
    for a, cols in named.items():
        if len(cols) > 1:
            raise InputError(path, f"columns {', '.join(header[i] for i in cols)} could each "
                                   f"be the {a} rate{where}")
    if all(named.values()):
        return [named[a][0] for a in "xyz"]
    ri = [ti + 1, ti + 2, ti + 3]
    if ri[-1] >= len(header):
        raise InputError(path, f"need a time column and three rate columns, header has "
                               f"{len(header)} columns ({', '.join(header)})")
    if len(header) > 4:        # which three? (an IMU log's accelerometer must not be taken)
        raise InputError(path, f"the column names ({', '.join(header)}) do not say which "
                               f"three hold the gyro's x, y and z rates{where}")
    for a, i in zip("xyz", ri):
        said = rate_axis(header[i])
        if (said is not None and said != a) or (said is None and looks_like_time(header[i])):
            raise InputError(path, f"column {header[i]!r} would be read as the {a} rate, "
                                   f"which its name contradicts{where}")
    return ri


def phone_app(header: list[str], rate_columns: list[int]) -> str | None:
    """The phone app whose CSV columns these are, when they are one's (its rates are then
    in the device's axes), else ``None``: ``"Sensor Logger"`` (its ``seconds_elapsed``
    column), ``"phyphox"`` (``"Time (s)"`` first, the rates ``"Gyroscope x (rad/s)"``),
    ``"SensorLog"`` (iOS; ``gyroRotationX(rad/s)`` or ``motionRotationRateX(rad/s)``) or
    ``"Core Motion"`` (rates named as its ``rotationRateX``, as iOS apps write them)."""
    names = [h.strip().lower() for h in header]
    rates = [names[i] for i in rate_columns]
    if "seconds_elapsed" in names:
        return "Sensor Logger"
    if names[:1] == ["time (s)"] and all(
            re.fullmatch(r"gyroscope [xyz] \(rad/s\)", r) for r in rates):
        return "phyphox"
    if any(r.startswith(("gyrorotation", "motionrotationrate")) for r in rates):
        return "SensorLog"
    if any(r.startswith("rotationrate") for r in rates):
        return "Core Motion"
    return None


def refuse_signed_names(path: str, header: list[str], columns: list[int]) -> None:
    """Refuse rate columns whose names carry a sign (``-gy``). The sign is not read: a
    log's axes become the camera's only through the capture's ``gyro.orientation``, a
    rotation, never by a sign in a name, so reading such a column as it is could turn
    the camera the wrong way without a word."""
    for i in columns:
        if header[i].strip().startswith(("-", "+", "\u2212")):
            raise InputError(path, f"rate column {header[i]!r} carries a sign, which is not "
                                   f"read (the log's axes become the camera's only through "
                                   f"gyro.orientation): rename the column, negating its "
                                   f"values if they are the rate's opposite")


def is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
