"""Command-line glue of calibration: which parameters the options fix, the printed
report, and ``gyrodeblur calibrate``."""

from __future__ import annotations

import argparse
import os
import stat
import warnings
from dataclasses import replace

import numpy as np

from .calibrate import AXES_CONFIDENT_NATS, calibrate, checked_fix, repeated_photo
from .errors import GyrodeblurWarning, InputError
from .images import split_alpha, to_sensor_layout

__all__ = ["format_estimates", "fixed_parameters", "calibrate_command", "save_captures",
           "refuse_non_json", "refuse_repeated_photos", "refuse_one_start_for_several",
           "refuse_repeated_outputs", "photo_rotations", "per_photo_values",
           "note_one_start_for_all", "calibration_downscale", "calibration_options"]

#: Photos are not shrunk by their digital zoom below this many pixels on their shorter
#: side (:func:`calibration_downscale`; ``calibrate`` refuses fewer than 64).
_ZOOM_MIN_SIDE = 96


def warning_notes(say):
    """The ``say`` to give :func:`~gyrodeblur.calibrate.calibrate` on the command line.

    Parameters
    ----------
    say : callable
        Prints one message (the command's own output).

    Returns
    -------
    callable
        Says calibration's messages with ``say``, except its notes that are warnings
        (``"warning: ..."``, indented or not: an uncertain mapping, an ambiguous offset, a
        clipped log), which it issues as a :class:`~gyrodeblur.errors.GyrodeblurWarning`:
        printed as the command's other warnings are, and made errors by the same filter.
    """
    def said(msg: str) -> None:
        text = msg.lstrip()
        if text.startswith("warning: "):
            warnings.warn(text[len("warning: "):], GyrodeblurWarning, stacklevel=2)
        else:
            say(msg)
    return said


def format_estimates(est: dict, kept_given: bool = False,
                     readout_given: bool = True) -> list[str]:
    """Human-readable lines: each parameter before -> after (+- uncertainty, or fixed);
    with ``kept_given`` (:attr:`~gyrodeblur.calibrate.CalibrationResult.kept_given`), a
    last line saying that the "after" values are the given ones, kept (and the readout,
    where none was given, ``readout_given`` false, the one that suits them)."""
    lines = []
    b, a, u = est["offset"]
    change = f", a change of {(a - b) * 1e3:+.2f} ms" if abs(b) >= 1.0 else ""   # clock epochs
    lines.append(f"  time offset  {b * 1e3:+8.2f} ms -> {a * 1e3:+8.2f} ms  "
                 f"({_pm(u, 1e3, 'ms')}{change})")
    b, a, u = est["readout"]
    lines.append(f"  readout      {b * 1e3:8.2f} ms -> {a * 1e3:8.2f} ms  ({_pm(u, 1e3, 'ms')})")
    b, a, u = est["focal"]
    lines.append(f"  focal scale  {b:8.4f}    -> {a:8.4f}     ({_pm(u, 1, '')})")
    b, a, u = est["bias"]
    vec = lambda v: "[" + ", ".join(f"{x:+.4f}" for x in v) + "]"
    unc = "fixed" if u is None else "+- [" + ", ".join(_fmt(v, 1) for v in u) + "]"
    lines.append(f"  gyro bias    {vec(b)} -> {vec(a)} rad/s  ({unc})")
    b, a, gap = est["axes"]
    if gap is None:
        conf = "fixed"
    elif not np.isfinite(gap):
        conf = "only candidate"
    else:
        conf = (f"next best mapping: objective {gap:+.1f} higher" if gap >= 0 else
                f"another mapping: objective {-gap:.1f} lower, within the given one's margin")
        if gap < AXES_CONFIDENT_NATS:
            conf += ": uncertain"
    lines.append(f"  axes         {b} -> {a}  ({conf})")
    if kept_given:
        lines.append("  (the given values kept" + ("" if readout_given else
                                                   ", with the readout that suits them (none "
                                                   "was given)")
                     + ": the photo preferred no others by the keep margin; the "
                     "uncertainties say how loosely it pins them)")
    return lines


def _pm(u, mult, unit) -> str:
    if u is None:
        return "fixed"
    return f"+- {_fmt(u, mult)}{(' ' + unit) if unit else ''}"


def _fmt(u, mult) -> str:
    if u is None or not np.isfinite(u):
        return "?"
    return f"{u * mult:.2g}"


#: Capture options whose value, given on the command line, fixes a parameter.
_FIXING_OPTIONS = (("time_offset", "offset"), ("bias", "bias"), ("readout_time", "readout"),
                   ("fx", "focal"), ("fy", "focal"), ("orientation", "axes"))


def fixed_parameters(args) -> set[str]:
    """Parameters the user fixes on the command line: those named by ``--fix``, and those
    whose value is given explicitly (``--time-offset``, ``--bias``, ``--readout-time``,
    ``--fx``/``--fy``, ``--orientation``): a value stated on the command line is taken as
    known, not as a starting guess."""
    fix = checked_fix(f.strip() for f in (getattr(args, "fix", None) or "").split(","))
    for option, name in _FIXING_OPTIONS:
        if getattr(args, option, None) is not None:
            fix.add(name)
    return fix


def calibration_downscale(given, photos, say) -> float:
    """The factor the photos are calibrated shrunk by: ``given`` (``--downscale``) where
    the user gave one, else ``1 / z`` for the largest digital zoom ``z`` the photos' EXIF
    records (DigitalZoomRatio), said in a note, else 1.

    A digitally zoomed photo is a central part of the sensor's image enlarged to the
    stored size: above ``1 / z`` of its band it holds the enlargement's smooth fill, not
    the scene, and the calibration's spectral criterion reads that empty band as blur (on
    the calibration benchmark, five photos enlarged 2x, one run: 2 of 5 wrong mappings, one
    with its offset 53 ms off, at full size; every mapping right at half size, offsets
    within 1.8 ms). Shrunk by ``1 / z`` the photo is about at its sensor's sampling
    again. The factor keeps at least :data:`_ZOOM_MIN_SIDE` px on the smallest photo's
    shorter side.

    Parameters
    ----------
    given : float or None
        ``--downscale`` as given (``None``: not given).
    photos : list of Photo
        The photos as read (:func:`gyrodeblur.imageio.read_photo`), for their EXIF.
    say : callable(str)
        Where the note goes.
    """
    if given is not None:
        return given
    from .imageio import exif_capture_hints

    zooms = [exif_capture_hints(ph).get("digital_zoom", 1.0) for ph in photos]
    z = max(zooms)
    if not z > 1.0:
        return 1.0
    side = min(min(ph.pixels.shape[:2]) for ph in photos)
    factor = min(1.0, max(1.0 / z, _ZOOM_MIN_SIDE / side))
    if factor >= 1.0:
        return 1.0
    which = photos[zooms.index(z)].path
    say(f"note: {which}: digitally zoomed x{z:g} (EXIF DigitalZoomRatio), so its detail "
        f"ends below its pixel grid's: calibrated shrunk by {factor:.3g}"
        + ("" if len(photos) == 1 else " with the others")
        + " (--downscale sets the factor, 1 for none); the corrected capture keeps the "
          "full resolution")
    return factor


def calibration_options(args, photos, say) -> dict:
    """The keyword arguments of :func:`gyrodeblur.calibrate.calibrate` that the options of
    ``calibrate`` and ``deblur --refine`` set alike: ``downscale``
    (:func:`calibration_downscale`), ``workers``, ``offset_range`` and ``mappings``."""
    return {"downscale": calibration_downscale(args.downscale, photos, say),
            "workers": args.workers, "offset_range": args.offset_range,
            "mappings": args.mappings}


def refuse_repeated_photos(paths, images) -> None:
    """One photo given twice would count its evidence twice (:func:`calibrate.calibrate`
    refuses it too); said here with the files' names, whether the same file or a copy.
    ``images``: the photos' pixels (or any arrays equal where the pixels are, e.g. their
    digests)."""
    pair = repeated_photo(images)
    if pair is not None:
        first, path = paths[pair[0]], paths[pair[1]]
        same = os.path.exists(path) and os.path.samefile(path, first)
        raise InputError(path, f"{'is' if same else 'holds the same pixels as'} "
                               f"{first}, given already: one photo counted twice "
                               "would seem twice as sure")


def calibrate_command(args, say, load_capture) -> None:
    """`gyrodeblur calibrate PHOTO... --capture C.json[,C2.json...] -o OUT.json[,OUT2.json...]`.

    Several photos of one session are calibrated together; each needs its own exposure
    start, so ``--capture`` may list one description per photo (comma-separated, or the
    option repeated). ``-o`` likewise: one output is the first photo's corrected
    description (the corrections are shared), one per photo gives each its own. All of
    them are written, or none."""
    from .imageio import check_destination, read_photo

    fix = fixed_parameters(args)
    outputs = _outputs(args.output, len(args.photos))

    refuse_one_start_for_several(args, len(args.photos))
    turns = photo_rotations(args.photo_rotation, len(args.photos))
    # before reading anything; the inputs are checked once the captures name their logs
    for out in outputs:
        check_destination(out, None, args.overwrite, image=False, inputs=args.photos)
    photos = [read_photo(p) for p in args.photos]
    photos = [replace(ph, pixels=to_sensor_layout(ph.stored_channels, deg))
              for ph, deg in zip(photos, turns)]
    paths = per_photo_values(args.capture, len(photos), "--capture", (1, len(photos)),
                             "capture description", read=True)
    refuse_repeated_photos(args.photos, [p.pixels for p in photos])
    caps, args.logs = [], {}            # one long log named by every capture: read once
    for k, ph in enumerate(photos):
        a = argparse.Namespace(**vars(args))
        a.capture = paths[k] if len(paths) > 1 else paths[0]
        a.photo_rotation = turns[k]                  # this photo's, as its messages say
        caps.append(load_capture(a, ph, say))
    inputs = list(args.photos) + [c.source for c in caps] + [c.log.source for c in caps]
    for out in outputs:
        check_destination(out, None, args.overwrite, image=False, inputs=inputs)
    for out in outputs:     # after the inputs' check: "it is an input" says more than "not .json"
        refuse_non_json(out)
    from .icc import said_transfer_curve
    curves = [said_transfer_curve(ph, args.transfer, say) for ph in photos]
    res = calibrate([split_alpha(p.pixels)[0] for p in photos], caps, fix=fix,
                    say=warning_notes(say),
                    transfer=curves, **calibration_options(args, photos, say))
    say(f"calibration of {len(photos)} photo(s) in {res.seconds:.1f} s (before -> after, "
        f"one-sigma uncertainty):")
    for line in format_estimates(res.estimates, res.kept_given,
                                 not caps[0].readout_time_unknown):
        say(line)
    save_captures(res.captures[:len(outputs)], outputs)
    say(f"wrote {', '.join(outputs)}")
    if len(outputs) < len(photos):
        say("(the first photo's description: the others keep their own exposure start, "
            "exposure time and log; give one -o per photo to write each)")


def note_one_start_for_all(path, caps, say) -> None:
    """Say that several photos given one capture description (``path``; ``None``: the
    options alone) all start exposing at its one start, unless that is their EXIF times
    (each photo's own)."""
    if len(caps) > 1 and not any(c.exposure_start_from_exif for c in caps):
        say(f"note: all {len(caps)} photos take their exposure start from "
            f"{path or 'the options'}; give one capture per photo (--capture "
            "a.json,b.json,... or --capture repeated) if they were taken at different times")


def refuse_one_start_for_several(args, n_photos: int) -> None:
    """``--exposure-start`` with several photos would start them all at once: each
    photo's start belongs in its own capture description."""
    if n_photos > 1 and args.exposure_start is not None:
        raise InputError("--exposure-start", "would give every photo the same start: give "
                                             "each its own in its capture description "
                                             "(--capture a.json,b.json)")


def _outputs(given, n_photos: int) -> list[str]:
    """The output paths of ``-o`` (as :func:`per_photo_values` reads them): one, or one per
    photo, no two the same file."""
    outs = per_photo_values(given, n_photos, "-o", (1, n_photos), "output",
                            hint="one is the first photo's corrected description")
    refuse_repeated_outputs(outs)
    return outs


def per_photo_values(values, n: int, option: str, allowed: tuple[int, ...], what: str,
                     read: bool = False, hint: str = "") -> list:
    """The values of a repeatable option for ``n`` photos, as ``calibrate`` and ``deblur``
    read them. One photo's are taken as given (a file name may hold a comma); for
    several, an option given once is a list split at its commas, each item without the
    spaces around it (``a.jpg, b.jpg`` names ``b.jpg``, not `` b.jpg``), unless ``read``,
    files the command reads, and it names an existing file; one repeated gives a value
    each time. The count must be one of ``allowed``; ``hint`` ends the message when not."""
    given = values if isinstance(values, list) else ([] if values is None else [values])
    if n == 1:
        if len(given) > 1:
            raise InputError(option, f"given {len(given)} times for one photo")
        return given
    vals = given
    if len(given) == 1 and not (read and os.path.isfile(os.fspath(given[0]))):
        vals = [v.strip() for v in os.fspath(given[0]).split(",") if v.strip()]
    if len(vals) not in allowed:
        spelt = " or ".join(str(k) for k in allowed if k)
        raise InputError(option, f"{len(vals)} {what}{'s' * (len(vals) != 1)} for {n} photos: "
                                 f"give {spelt} (comma-separated, or the option repeated)"
                                 + (f"; {hint}" if hint else ""))
    return vals


def refuse_repeated_outputs(paths) -> None:
    """No file may be named twice among a command's outputs (also through a link)."""
    for k, out in enumerate(paths):
        for other in paths[:k]:
            if os.path.realpath(out) == os.path.realpath(other):
                raise InputError(out, "is named twice as an output; give each its own file")


def photo_rotations(given, n_photos: int) -> list[int]:
    """``--photo-rotation`` for ``n_photos`` photos: its values (the option appended, each
    time a list) as one per photo, one given serving all."""
    turns = [t for entry in given or [[0]] for t in entry]
    if len(turns) not in (1, n_photos):
        raise InputError("--photo-rotation", f"{len(turns)} rotation{'s' * (len(turns) != 1)} "
                                             f"for {n_photos} photo{'s' * (n_photos != 1)}: "
                                             f"give one{', or one per photo' * (n_photos > 1)}")
    return turns * n_photos if len(turns) == 1 else turns


def refuse_non_json(path) -> None:
    """A corrected capture description's output must be named ``*.json``."""
    if not os.fspath(path).lower().endswith(".json"):
        raise InputError(path, "the corrected capture description is JSON: give an output "
                               "ending in .json")


def save_captures(captures, outputs, before_moving=None) -> None:
    """Write each capture to its output: all of them or none. Each is written whole beside
    its output first (the gyro path made relative to that folder), then
    ``before_moving()`` is called (the command's other outputs), and only once all that
    is done are they moved into place, over files ``--overwrite`` allows (a failure or
    Ctrl-C between two of these renames, microseconds apart, would leave the first
    moved)."""
    import secrets

    parts = []
    try:
        for cap, out in zip(captures, outputs):
            folder, name = os.path.split(os.path.abspath(out))
            part = os.path.join(folder, f".{name}.{secrets.token_hex(4)}.part")
            parts.append(part)
            try:
                cap.save(part)
            except OSError as exc:
                raise InputError(out, f"cannot write the file: {exc.strerror}") from None
            except InputError as exc:    # the atomic write's, naming the hidden part file
                if exc.source != part:
                    raise
                raise InputError(out, exc.problem) from None
        if before_moving is not None:
            before_moving()
        for part, out in zip(parts, outputs):
            try:
                if os.path.exists(out):      # a file written over keeps its permission bits
                    os.chmod(part, stat.S_IMODE(os.stat(out).st_mode))
                os.replace(part, out)
            except OSError as exc:
                raise InputError(out, f"cannot write the file: {exc.strerror}") from None
    finally:
        for part in parts:
            if os.path.lexists(part):
                os.remove(part)
