"""Command-line interface: thin wrappers that parse, call the library and print.

Exit status: 0 on success, 2 for bad input (a one-line message naming the file and the
problem; nothing written, but for the photos that ``deblur`` of several photos finished
before, which it names), 1 for anything unexpected.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import time
import warnings
from dataclasses import replace

import numpy as np

from .errors import GyrodeblurWarning, InputError
from .gyrolog import FORMATS
from .images import PHOTO_MAX, join_alpha, split_alpha, to_photo_layout, to_sensor_layout
from .tiling import DEFAULT_OVERLAP

#: Kernel size (px) of ``deblur --blind`` when ``--kernel-size`` is not given.
BLIND_KERNEL_SIZE = 31

FRAMES_HELP = ("Frames: image x right, y down, pixel centres at integer coordinates; camera "
               "x right, y down, z forward; angular rates in rad/s; times in seconds.")


# ----------------------------------------------------------------------------- helpers

def _pair(text: str, what: str, kind=int, sep="x") -> tuple:
    parts = text.lower().replace(",", sep).split(sep)
    try:
        vals = tuple(kind(p) for p in parts)
    except ValueError:
        raise InputError(what, f"expected two numbers like 6{sep}8, got {text!r}") from None
    if len(vals) != 2:
        raise InputError(what, f"expected two numbers like 6{sep}8, got {text!r}")
    return vals


def _one_patch(grid: str) -> bool:
    """Whether the ``--grid`` text asks for one patch (``1x1``, ``1X1``, ``1,1``); "auto"
    and bad text are not (the latter is refused where the grid is read)."""
    try:
        return grid != "auto" and _pair(grid, "--grid") == (1, 1)
    except InputError:
        return False


def _bias(text: str | None):
    if text is None or text == "auto":
        return text
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 3:
        raise InputError("--bias", f"expected 'auto' or three rates bx,by,bz in rad/s, got {text!r}")
    return vals


def _add_capture_options(p: argparse.ArgumentParser, required: bool = False,
                         per_photo: bool = False) -> None:
    g = p.add_argument_group("capture", "The capture description (JSON) and options that "
                             "override its fields. " + FRAMES_HELP)
    if per_photo:
        g.add_argument("--capture", required=required, metavar="C.json", action="append",
                       help="capture description (schema: see README); one for all photos, "
                            "or one per photo, in their order: comma-separated or the option "
                            "repeated")
    else:
        g.add_argument("--capture", required=required, metavar="C.json",
                       help="capture description (schema: see README)")
    g.add_argument("--exposure-start", type=float, metavar="S",
                   help="camera-clock seconds when row 0 starts exposing")
    g.add_argument("--exposure-time", type=float, metavar="S", help="seconds each row integrates")
    g.add_argument("--readout-time", type=float, metavar="S",
                   help="seconds to read all rows out: row y starts y/height of it after "
                        "row 0 (0 = global shutter)")
    for k in ("fx", "fy", "cx", "cy"):
        g.add_argument(f"--{k}", type=float, metavar="PX",
                       help=f"intrinsic {k} in pixels of the capture's camera.width x height "
                            "(the photo's when the capture gives no size)")
    g.add_argument("--gyro", metavar="PATH", help="gyro log (gcsv, csv, android events or json)")
    g.add_argument("--gyro-format", choices=FORMATS)
    g.add_argument("--orientation", metavar="AXES",
                   help="log axes -> camera axes: three letters, e.g. XYZ or yxz (lowercase "
                        "= negated), or a name: identity, android-back-camera (a phone's "
                        "back camera, sensor orientation 90), android-back-camera-0/-90/"
                        "-180/-270, ios-back-camera (an iPhone's or iPad's back camera)")
    g.add_argument("--time-offset", type=float, metavar="S",
                   help="seconds: camera_time = gyro_time + offset")
    g.add_argument("--bias", metavar="auto|bx,by,bz",
                   help="gyro bias to subtract, rad/s in the camera frame, or 'auto'")
    g.add_argument("--time-unit", choices=("s", "ms", "us", "ns"),
                   help="time unit of a csv or json log")
    g.add_argument("--rate-unit", choices=("rad/s", "deg/s"),
                   help="rate unit of a csv or json log")
    g.add_argument("--max-gap", type=float, metavar="S",
                   help="largest gap between gyro samples allowed inside the exposure (default 0.05)")


#: The capture options' destinations (``--capture`` and those that override its fields).
_CAPTURE_OPTIONS = ("capture", "exposure_start", "exposure_time", "readout_time", "fx", "fy",
                    "cx", "cy", "gyro", "gyro_format", "orientation", "time_offset", "bias",
                    "time_unit", "rate_unit", "max_gap")


def _ignored_options(args) -> None:
    """Refuse deblur options that the chosen mode would ignore (naming the first)."""
    def given(name):                 # 0 is a value given; False/None/"" are defaults
        v = getattr(args, name, None)
        return v is not None and v is not False and not (isinstance(v, str) and v == "")

    if args.blind:
        for name in ("refine", "fix", "save_capture") + _CAPTURE_OPTIONS:
            if given(name):
                raise InputError("--" + name.replace("_", "-"),
                                 "does not apply with --blind, which uses no gyro log")
        if args.mode != "variant":
            raise InputError("--mode", "does not apply with --blind (--grid sets its patches)")
        for name in ("overlap", "model"):
            if given(name) and (args.grid is None or _one_patch(args.grid)):
                raise InputError("--" + name, "applies with --blind --grid RxC only (one "
                                              "kernel for the whole photo has no patches)")
    else:
        if args.fix and not args.refine:
            raise InputError("--fix", "applies with --refine only")
        if given("kernel_size"):
            raise InputError("--kernel-size", "applies with --blind only")
        if args.no_blur_check and args.refine:
            raise InputError("--no-blur-check", "does not apply with --refine (the "
                                                "calibration checks the blur itself)")
        if args.mode == "invariant":
            for name in ("grid", "overlap", "model"):
                if given(name):
                    raise InputError("--" + name, "applies to --mode variant only (invariant "
                                                  "deblurs the whole photo with one PSF)")
        elif args.grid is not None and _one_patch(args.grid):
            for name, why in (("overlap", "has no neighbours to overlap"),
                              ("model", "has no neighbours for the global model to "
                                        "refine it with")):
                if given(name):
                    raise InputError("--" + name, f"does not apply with --grid {args.grid} "
                                                  f"(one patch {why})")
    if args.downscale is not None and not args.refine:   # (with --blind, --refine is refused)
        raise InputError("--downscale", "applies with --refine only")
    if args.workers is not None and not args.refine:
        raise InputError("--workers", "applies with --refine only")
    if args.offset_range is not None and not args.refine:
        raise InputError("--offset-range", "applies with --refine only")
    if args.mappings is not None and not args.refine:
        raise InputError("--mappings", "applies with --refine only")


def _load_capture(args, photo=None, say=None, exif_start: bool = True):
    """The capture the options and ``--capture`` describe, fitted to ``photo``; its EXIF
    fills what they leave out (the capture time as the exposure start only where
    ``exif_start``: a sharp scene's time says nothing of a blurred exposure)."""
    from .capture import load_capture

    overrides = {
        "exposure_start": args.exposure_start, "exposure_time": args.exposure_time,
        "readout_time": args.readout_time, "fx": args.fx, "fy": args.fy, "cx": args.cx,
        "cy": args.cy, "gyro_path": args.gyro, "gyro_format": args.gyro_format,
        "orientation": args.orientation, "time_offset": args.time_offset,
        "bias": _bias(args.bias), "time_unit": args.time_unit, "rate_unit": args.rate_unit,
        "max_gap": args.max_gap,
    }
    if args.max_gap is not None and not (np.isfinite(args.max_gap) and args.max_gap > 0):
        raise InputError("--max-gap", f"must be a positive number of seconds, got {args.max_gap!r}")
    if args.capture is None and args.gyro is None:
        raise InputError("--capture", "give a capture description (--capture C.json) or --gyro "
                                      "with the exposure options")
    size = hints = None
    if photo is not None:
        from .imageio import exif_capture_hints
        size = (photo.pixels.shape[1], photo.pixels.shape[0])
        hints = exif_capture_hints(photo)
    turned = getattr(args, "photo_rotation", 0)    # this photo's (psf: none)
    with warnings.catch_warnings():
        if turned:       # turned so that the rows a gcsv header says are read run down
            read = "1" if turned == 180 else "[23]"
            warnings.filterwarnings("ignore", f".*: the gcsv header's frame_readout_direction "
                                              f"is {read} ")
        cap = load_capture(args.capture, overrides=overrides, image_size=size,
                           exif_hints=hints, report=say, logs=getattr(args, "logs", None),
                           exif_start=exif_start)
    if photo is not None:
        # psf has no --photo-rotation: it takes the photo's pixels as stored
        turn = ("give --photo-rotation (90 on most phones)" if hasattr(args, "photo_rotation")
                else "give the photo as the camera stored it")
        if size[1] > size[0] and not turned and cap.log.in_device_axes:
            say(f"note: {photo.path}: taller than wide, while a phone's sensor is wider than "
                f"tall: if an app or an export turned the photo upright, {turn}, or the "
                "rows are not the sensor's readout rows")
        from .exif import orientation_tag
        tag = orientation_tag(photo) if turned else 1
        if tag != 1:
            warnings.warn(f"{photo.path}: its EXIF orientation tag ({tag}) says a viewer turns "
                          f"it for display, its pixels as the camera read them, yet "
                          f"--photo-rotation {turned} says they were turned: a phone's photo "
                          f"with that tag needs no --photo-rotation (with it, the rolling "
                          f"shutter's rows are taken the wrong way)", GyrodeblurWarning,
                          stacklevel=2)
        given_cam = cap.camera
        try:
            cap = cap.scaled_to(size[0], size[1], source=photo.path)
        except InputError as exc:
            if not hasattr(args, "photo_rotation") and "turned by 90 degrees" in exc.problem:
                raise exc.reworded(exc.problem.split(" (turned")[0] + " (turned by 90 "
                                   "degrees? the rows must be the sensor's readout rows: "
                                   "give the photo as the camera stored it)") from None
            if turned and "turned by 90 degrees" in exc.problem:     # by the option itself
                raise exc.reworded(exc.problem.split(" (turned")[0] + f", after "
                                   f"--photo-rotation {turned}; as stored the photo fits, so "
                                   f"its pixels were not turned: leave the option out") from None
            raise
        if cap.camera is not given_cam:
            sx, sy = size[0] / given_cam.width, size[1] / given_cam.height  # more than rounding:
            crop = (f"; the aspect ratios differ by {abs(sx / sy - 1):.2%}: a cropped photo "
                    "needs the crop's own intrinsics" if abs(sx / sy - 1) > 1 / min(size) else "")
            say(f"note: {photo.path}: the capture's camera is {given_cam.width}x"
                f"{given_cam.height}: its intrinsics are scaled to the photo's "
                f"{size[0]}x{size[1]}{crop}")
    return cap


class _Progress:
    """A progress bar on stderr, shown only once a run has taken more than a second, and
    only on a terminal (a log file gets no carriage-return lines)."""

    #: The bar on the terminal now, if any: :func:`main` ends its line when the work
    #: stops early (an error, Ctrl-C), so the message starts a line of its own.
    drawn: "_Progress | None" = None

    def __init__(self, label: str, quiet: bool):
        self.label, self.t0, self.shown = label, time.perf_counter(), False
        self.quiet = quiet or not _is_terminal(sys.stderr)

    def __call__(self, done: int, total: int) -> None:
        if self.quiet or (not self.shown and time.perf_counter() - self.t0 < 1.0):
            return
        self.shown = True
        _Progress.drawn = self
        n = 30 * done // max(total, 1)
        _write(sys.stderr, f"\r{self.label} [{'#' * n}{'.' * (30 - n)}] {done}/{total}")

    def close(self) -> None:
        if self.shown:
            _write(sys.stderr, "\n")
            self.shown = False
        if _Progress.drawn is self:
            _Progress.drawn = None

    @classmethod
    def end_drawn(cls) -> None:
        if cls.drawn is not None:
            cls.drawn.close()


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _write_picture(path: str, rgb_uint8: np.ndarray, overwrite: bool) -> None:
    from .imageio import write_photo
    write_photo(path, rgb_uint8.astype(np.float32) / 255.0, overwrite=overwrite)


def _check_output(path: str, like, overwrite: bool, image: bool = True, inputs=(),
                  bit_depth: int | None = None) -> None:
    from .imageio import check_destination
    check_destination(path, like, overwrite, image=image, inputs=inputs, bit_depth=bit_depth)


def _check_saved_capture(args) -> None:
    """``--save-capture``: with ``--refine`` only, a ``.json`` file, neither another
    output nor an input named on the command line (the log a capture description names
    is checked once it is loaded)."""
    path = args.save_capture
    if not args.refine:
        raise InputError("--save-capture", "applies with --refine only (without it the "
                                           "capture is used as given)")
    for other, option in ((args.output, "-o"), (args.save_psf, "--save-psf")):
        if other and os.path.realpath(path) == os.path.realpath(other):
            raise InputError(path, f"is also the {option} output; choose another file")
    _check_output(path, None, args.overwrite, image=False, inputs=args.inputs)
    from .calibrate_cli import refuse_non_json
    refuse_non_json(path)


def _check_not_over_capture(cap, overwrite: bool, *outputs) -> None:
    """Refuse outputs that are the capture description or its gyro log (known only once
    the capture is loaded), ``--overwrite`` or not."""
    inputs = [p for p in (cap.source, cap.log.source) if p]
    for out in outputs:
        if out:
            _check_output(out, None, overwrite, image=False, inputs=inputs)


def _add_transfer_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--transfer", default="auto",
                   help="transfer curve of the pixel values, undone for the work and reapplied: "
                        "auto (default: the curve the photo's ICC profile declares, e.g. "
                        "linear or gamma 2.2; sRGB without a profile), srgb or linear")


def _add_rotation_option(p: argparse.ArgumentParser, per_photo: bool = False,
                         writes_photos: bool = True) -> None:
    what = ("degrees clockwise the photos' pixels were turned from the sensor's layout, one "
            "for all or one per photo, comma-separated or the option repeated" if per_photo else
            "degrees clockwise the photo's pixels were turned from the sensor's layout")
    p.add_argument("--photo-rotation", type=_rotations if per_photo else _rotation,
                   default=None if per_photo else 0, metavar="DEG",
                   action="append" if per_photo else "store",
                   help=what + " (an export that applied a portrait orientation; 0, 90, 180 "
                        "or 270): the photo is turned back for the work, so that its rows are "
                        "the sensor's readout rows and the capture's camera fits"
                        + (", and the result is turned like the input" if writes_photos
                           else ""))


def _rotation(text: str) -> int:
    """One ``--photo-rotation`` value: 0, 90, 180 or 270 (degrees)."""
    try:
        deg = int(text)
    except ValueError:
        deg = None
    if deg not in (0, 90, 180, 270):
        raise argparse.ArgumentTypeError(f"must be 0, 90, 180 or 270, got {text!r}")
    return deg


def _rotations(text: str) -> list[int]:
    """``--photo-rotation`` of several photos: one value, or one per photo."""
    return [_rotation(t.strip()) for t in str(text).split(",")]


# ----------------------------------------------------------------------------- commands

#: Of the photo's shorter side: a blur longer than this is warned of as such (a duration
#: in ms read as seconds, a focal length of another resolution). The blur check reads it
#: in a few windows of 48 px at most (none from about 2/3: it returns NaN), where a 162 px
#: blur on a 320 x 240 photo scored +1.1, passing.
_LONG_BLUR = 0.5


def _warn_if_the_blur_does_not_fit(cap, image, curve, zoom: float | None = None, *,
                                   extent: float = 0.0) -> None:
    """Warn where no blur at all explains the photo better than the capture's PSFs do, by
    :data:`~gyrodeblur.blur_evidence.WRONG_BLUR_MARGIN`
    (:func:`~gyrodeblur.blur_evidence.capture_gain_over_no_blur`): a time offset, exposure
    start, axis mapping, focal length or log that are not the photo's (or a sharp photo),
    which the deblur cannot see and which make the photo worse. ``zoom``: the photo's
    digital zoom (EXIF), named with the focal length it may have left out. ``extent``
    (px): the PSFs' largest; a blur over :data:`_LONG_BLUR` of the photo's shorter side
    is warned of in place of the check, which reads it in too few windows, or none (a
    40 ms exposure given as 40 had passed it, the photo ruined)."""
    from .blur_evidence import WRONG_BLUR_MARGIN, capture_gain_over_no_blur
    side = min(image.shape[:2])
    if extent > _LONG_BLUR * side:
        warnings.warn(f"the blur the gyro log implies, up to {extent:.0f} px, spans over "
                      f"half the photo's {side} px shorter side: longer than a hand-held "
                      f"photo's blur usually is, and too long to check against the photo. "
                      f"Check exposure_time and readout_time (seconds, not ms), the focal "
                      f"length (in this photo's pixels) and the log's rate unit",
                      GyrodeblurWarning, stacklevel=2)
        return
    try:                              # a check only: it must not cost the finished deblur
        gain = capture_gain_over_no_blur(image, cap, transfer=curve)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        warnings.warn(f"the check that the photo shows the gyro log's blur could not run "
                      f"({exc}); the deblurred photo is written",
                      GyrodeblurWarning, stacklevel=2)
        return
    if gain < WRONG_BLUR_MARGIN:
        warnings.warn(f"the blur the gyro log implies does not fit the photo: no blur at all "
                      f"explains its most textured windows better ({gain:+.1f} nats per 9 "
                      f"windows). The time offset, the exposure start, the axis mapping, the "
                      f"focal length (one in the pixels of another resolution) or the log is "
                      f"likely not the photo's, and the result is then likely worse than "
                      f"the input: run calibrate (or deblur --refine) first. A sharp photo, or one "
                      f"softer than its pixels (upscaled, digitally zoomed, heavily denoised), "
                      f"also gives this (--no-blur-check skips the check)"
                      + ("" if not zoom else
                         f". This photo's EXIF says digital zoom x{zoom:g}: where the focal "
                         f"length leaves the zoom out, it needs multiplying by {zoom:g} "
                         f"(--fx, --fy)"), GyrodeblurWarning, stacklevel=2)


def cmd_psf(args, say) -> None:
    from .deblur import plan_psf_field
    from .psf import render_psf
    from .psfplot import field_image, psf_image

    if (args.at is None) == (args.grid is None):
        raise InputError("--at/--grid", "give exactly one of --at X,Y or --grid RxC")
    if args.at is not None and args.overlap is not None:
        raise InputError("--overlap", "applies with --grid only (one PSF at --at has no patches)")
    out = args.output
    if not out.lower().endswith((".npy", ".npz", ".png")):
        raise InputError(out, "output must end in .npy, .npz or .png")
    _check_output(out, None, args.overwrite, image=out.lower().endswith(".png"),
                  inputs=[args.photo] if args.photo else ())
    at = None if args.at is None else _pair(args.at, "--at", float, sep=",")
    grid = None if args.grid is None else _pair(args.grid, "--grid")
    photo = None
    if args.photo is not None:                  # its size and EXIF, as deblur takes them
        from .imageio import read_photo
        photo = read_photo(args.photo)
    # reads the log: after the cheap checks; the photo's EXIF time is no exposure start
    # here (known to tens of ms, where deblur searches it with --refine)
    try:
        cap = _load_capture(args, photo, say=say, exif_start=False)
    except InputError as exc:
        if photo is None or exc.problem != "missing 'exposure_start'":
            raise
        raise exc.reworded(exc.problem + " (give --exposure-start: psf does not take the "
                           "photo's EXIF time, known to tens of ms at best)") from None
    _check_not_over_capture(cap, args.overwrite, args.output)
    if at is not None:
        x, y = at
        cam = cap.camera
        if not (0 <= x <= cam.width - 1 and 0 <= y <= cam.height - 1):
            raise InputError("--at", f"({x:g}, {y:g}) is not a pixel of the {cam.width}x"
                                     f"{cam.height} frame (x 0-{cam.width - 1}, y 0-{cam.height - 1})")
        psf = render_psf(cap, x, y)
        if out.lower().endswith(".npy"):
            _atomic_npy(out, psf)
        elif out.lower().endswith(".npz"):
            _atomic_npz(out, psfs=psf[None], centres_xy=np.array([[x, y]]),
                        grid=np.array([1, 1]))
        else:
            _write_picture(out, psf_image(psf), args.overwrite)
        say(f"PSF at ({x:g}, {y:g}): {psf.shape[0]}x{psf.shape[1]} px -> {out}")
        return
    cam = cap.camera
    _, field, notes = plan_psf_field(cap, (cam.height, cam.width), grid=grid,
                                     overlap=DEFAULT_OVERLAP if args.overlap is None
                                     else args.overlap, max_fraction=np.inf)
    if out.lower().endswith((".npy", ".npz")):
        k = max(p.shape[0] for p in field.psfs)
        stack = np.zeros((len(field.psfs), k, k), np.float32)
        for i, p in enumerate(field.psfs):
            o = (k - p.shape[0]) // 2
            stack[i, o:o + p.shape[0], o:o + p.shape[1]] = p
        if out.lower().endswith(".npy"):
            _atomic_npy(out, stack)
        else:
            _atomic_npz(out, psfs=stack, centres_xy=np.asarray(field.points, np.float64),
                        grid=np.array(field.grid))
    else:
        _write_picture(out, field_image(field, cam.width, cam.height), args.overwrite)
    e = field.extents
    say(f"PSF field {grid[0]}x{grid[1]} over {cam.width}x{cam.height}: extent {e.min()}-{e.max()} px -> {out}")


def _atomic_npz(path: str, **arrays) -> None:
    """``arrays`` in one ``.npz`` file at ``path``, atomically."""
    from .atomicfile import atomic_write
    atomic_write(path, lambda f: np.savez(f, **arrays))


def _atomic_npy(path: str, array: np.ndarray) -> None:
    from .atomicfile import atomic_write
    atomic_write(path, lambda f: np.save(f, array))


def cmd_simulate(args, say) -> None:
    from .imageio import read_photo, write_photo
    from .icc import said_transfer_curve
    from .simulate import quantize_8bit, simulate_blur

    given = read_photo(args.sharp, scene=True)
    _check_output(args.output, given, args.overwrite, bit_depth=args.bit_depth)
    photo = replace(given, pixels=to_sensor_layout(given.stored_channels,
                                                     args.photo_rotation))
    if args.snr_db is not None and not np.isfinite(args.snr_db):
        raise InputError("--snr-db", f"must be a finite number of dB, got {args.snr_db!r}")
    if args.seed is not None and args.seed < 0:
        raise InputError("--seed", f"must be a non-negative integer, got {args.seed}")
    if args.full_well is not None and not (np.isfinite(args.full_well)
                                           and 1 <= args.full_well <= 1e9):
        raise InputError("--full-well", f"must be 1 to 1e9 electrons at white, got "
                                        f"{args.full_well!r}")
    if args.seed is not None and args.snr_db is None and args.full_well is None:
        raise InputError("--seed", "seeds the noise: it applies with --snr-db or --full-well "
                                   "only")
    cap = _load_capture(args, photo, say, exif_start=False)
    _check_not_over_capture(cap, args.overwrite, args.output)
    curve = said_transfer_curve(given, args.transfer, say)
    brightest = float(split_alpha(given.pixels)[0].max())
    if brightest > PHOTO_MAX and curve.name != "linear":
        raise InputError(args.sharp, f"samples up to {brightest:.3g} (white = 1) are light far "
                                     f"brighter than white, which an encoded ({curve.name}) "
                                     "photo cannot hold: for a scene in linear light give "
                                     "--transfer linear")
    if brightest > 1:
        say(f"{args.sharp}: samples up to {brightest:.3g} (white = 1) are light brighter than "
            "the clip level: blurred as they are, clipped after the blur")
    t0 = time.perf_counter()
    colour, alpha = split_alpha(photo.pixels)
    blurred = simulate_blur(colour, cap, snr_db=args.snr_db, seed=args.seed,
                            order={"cubic": 3, "bilinear": 1}[args.sampling], transfer=curve,
                            full_well=args.full_well)
    blurred = np.clip(blurred, 0.0, 1.0)         # lights above white: clipped after the blur
    if args.bit_depth == 8 or (args.bit_depth is None and photo.bit_depth == 8):
        blurred = quantize_8bit(blurred)
    blurred = to_photo_layout(join_alpha(blurred, alpha), args.photo_rotation)
    write_photo(args.output, blurred, like=given, bit_depth=args.bit_depth,
                overwrite=args.overwrite)
    noise = ([] if args.snr_db is None else [f"SNR {args.snr_db:g} dB"]) + (
        [] if args.full_well is None else [f"shot noise of {args.full_well:g} e- at white"])
    snr = ", ".join(noise) or "no noise"
    gh, gw = given.pixels.shape[:2]
    say(f"simulated {args.sharp} -> {args.output}: {gw}x{gh}, {snr}, {time.perf_counter() - t0:.2f} s")


def _deblur_jobs(args) -> list[argparse.Namespace]:
    """One namespace per photo of ``deblur``, with that photo's ``photo``, ``output``,
    ``capture``, ``save_psf``, ``save_capture`` and ``photo_rotation``, ``inputs`` (every
    file the command names to read), ``several`` (whether there are other photos, which
    its messages then name it apart from) and ``written`` (the outputs of the photos
    finished, one list shared with ``args``). The outputs are checked not to repeat."""
    from .calibrate_cli import (per_photo_values, photo_rotations,
                                refuse_one_start_for_several, refuse_repeated_outputs)
    photos = list(args.photos)
    n = len(photos)
    outputs = per_photo_values(args.output, n, "-o", (n,), "output")
    captures = per_photo_values(args.capture, n, "--capture", (0, 1, n),
                                "capture description", read=True)
    psfs = per_photo_values(args.save_psf, n, "--save-psf", (0, n), "PSF drawing")
    saved = per_photo_values(args.save_capture, n, "--save-capture", (0, 1, n),
                             "corrected capture description")
    turns = photo_rotations(args.photo_rotation, n)
    refuse_one_start_for_several(args, n)
    if n > 1:                              # one photo's: said as each is checked
        refuse_repeated_outputs(outputs + psfs + saved)
    inputs = photos + captures + ([args.gyro] if args.gyro else [])
    args.written, args.logs = [], {}
    jobs = []
    for k, photo in enumerate(photos):
        a = argparse.Namespace(**vars(args))
        a.photo, a.output = photo, outputs[k]
        a.capture = captures[k] if len(captures) > 1 else (captures or [None])[0]
        a.save_psf = psfs[k] if psfs else None
        a.save_capture = saved[k] if k < len(saved) else None
        a.photo_rotation = turns[k]
        a.inputs, a.several, a.written, a.logs = inputs, n > 1, args.written, args.logs
        a.save_capture_once = n > 1 and len(saved) == 1
        jobs.append(a)
    return jobs


def cmd_deblur(args, say) -> None:
    """``gyrodeblur deblur PHOTO... -o OUT...``: each photo deblurred with its own capture
    (one for all, or one per photo), its outputs all written or none.

    Several photos are all read and checked first (their pixels then let go until their
    turn), so that a bad input stops the command before any work. With ``--refine`` they
    are calibrated together, as one session sharing one correction (``calibrate``'s
    rule), and each is deblurred with its own corrected capture; where any photo's
    exposure start is its EXIF time (each off by its own amount) every photo is
    calibrated alone instead. Without it they are deblurred one after another."""
    jobs = _deblur_jobs(args)
    if len(jobs) == 1:
        run = _PhotoDeblur(jobs[0], say)
        if args.refine:
            run.calibrate_alone()
        run.finish()
        return
    runs, digests = [], []
    for a in jobs:
        with _this_photo(a):
            runs.append(_PhotoDeblur(a, _naming(a.photo, say)))
        if args.refine:                  # a photo calibrated twice: refused, as calibrate does
            digests.append(_pixel_digest(runs[-1].photo.pixels))
        runs[-1].release()
    if args.refine:
        from .calibrate_cli import refuse_repeated_photos
        refuse_repeated_photos(args.photos, digests)
    if all(r.cap is not None for r in runs):
        outputs = [o for r in runs for o in (r.args.output, r.args.save_psf,
                                             r.args.save_capture)]
        for r in runs:         # no output is another photo's capture or log either
            _check_not_over_capture(r.cap, args.overwrite, *outputs)
        if len({a.capture for a in jobs}) == 1 and not args.refine:   # refine: refused
            from .calibrate_cli import note_one_start_for_all
            note_one_start_for_all(jobs[0].capture, [r.cap for r in runs], say)
    from_exif = [r.args.photo for r in runs if r.cap is not None
                 and r.cap.exposure_start_from_exif]
    if args.refine and not from_exif:
        _deblur_session(runs, say)
        return
    if args.refine:
        if runs[0].args.save_capture_once:
            raise InputError("--save-capture", "one file for several photos calibrated "
                                               "each alone would hold only the first's "
                                               "calibration: give one per photo")
        which = (f"the exposure starts of {', '.join(from_exif)} are their EXIF times"
                 if len(from_exif) > 1 else
                 f"the exposure start of {from_exif[0]} is its EXIF time")
        say(f"{which}, each off by an amount of its own, which no other photo shares: "
            "each photo is calibrated alone")
    for run in runs:
        run.t0 = time.perf_counter()           # its own time, not the others' before it
        run.load()
        if args.refine:
            run.calibrate_alone()
        run.finish()
        run.release()


def _pixel_digest(pixels: np.ndarray) -> np.ndarray:
    """A photo's pixels, shape and type as a 20-byte array: equal only where they are."""
    import hashlib
    a = np.ascontiguousarray(pixels)
    h = hashlib.sha1(f"{a.shape}{a.dtype.str}".encode())
    h.update(a.tobytes())
    return np.frombuffer(h.digest(), np.uint8)


@contextlib.contextmanager
def _this_photo(args):
    """Among several photos, what goes wrong with one (``args.photo``) names it: its
    warnings, as they come, and its errors (one of no file of its own, which :func:`main`
    would say of every photo, is the photo's)."""
    if not args.several:
        yield
        return
    try:
        with warnings.catch_warnings():
            # a filter added makes Python forget the warnings shown for the photos before
            warnings.simplefilter("default", append=True)
            shown = warnings.showwarning

            def named(message, category, filename, lineno, file=None, line=None):
                shown(f"{args.photo}: {message}", category, filename, lineno, file, line)

            warnings.showwarning = named
            yield
    except InputError as exc:
        if exc.source is None:
            raise InputError(args.photo, exc.problem) from None
        if exc.source != args.photo and args.photo not in exc.problem:
            raise exc.reworded(f"{exc.problem} (for {args.photo})") from None
        raise
    except GyrodeblurWarning as exc:          # a warning made an error: named as shown
        raise GyrodeblurWarning(f"{args.photo}: {exc}") from None


def _naming(photo: str, say):
    """``say`` for one photo among several: a message that does not name it is prefixed
    with its name."""
    return lambda msg: say(msg if photo in msg else f"{photo}: {msg}")


def _deblur_session(runs, say) -> None:
    """``deblur --refine`` of several photos: one calibration of them all, as one session
    (:func:`gyrodeblur.calibrate.calibrate`), then each photo deblurred with its own
    corrected capture."""
    from .calibrate import calibrate
    from .calibrate_cli import calibration_options, format_estimates, warning_notes
    args = runs[0].args
    for run in runs:
        run.load()
    res = calibrate([r.colour for r in runs], [r.cap for r in runs], fix=runs[0].fix,
                    say=warning_notes(say), transfer=[r.curve for r in runs],
                    **calibration_options(args, [r.photo for r in runs], say))
    say(f"calibration of {len(runs)} photos in {res.seconds:.1f} s (before -> after, "
        f"one-sigma uncertainty):")
    for line in format_estimates(res.estimates, res.kept_given,
                                 not runs[0].cap.readout_time_unknown):
        say(line)
    for run, cap in zip(runs, res.captures):
        run.cap, run.t0 = cap, time.perf_counter()
        run.finish()
        run.release()


def _check_blur_fits_the_frame(cap) -> None:
    """Refuse a blur longer than the frame at the frame's corners or centre
    (:func:`gyrodeblur.psf.check_blur_span`, which the deblur applies to every PSF): wrong
    units in one photo's capture, said before another photo is deblurred."""
    from .psf import centred_psf, check_blur_span, trace
    cam = cap.camera
    for x, y in ((0, 0), (cam.width - 1, 0), (cam.cx, cam.cy), (0, cam.height - 1),
                 (cam.width - 1, cam.height - 1)):
        reach = float(np.abs(trace(cap, x, y, 64) - [x, y]).max())   # as render_psf's
        check_blur_span(cap, 2 * reach, f"at ({x:.0f}, {y:.0f})", what=centred_psf(reach))


class _PhotoDeblur:
    """One photo of ``deblur``: read and checked, with its capture loaded
    (``__init__``), calibrated alone (:meth:`calibrate_alone`) or given its capture from a
    session's calibration, then deblurred and written (:meth:`finish`)."""

    def __init__(self, args, say) -> None:
        from .deblur import DEFAULT_METHOD
        from .icc import said_transfer_curve

        self.args, self.say = args, say
        inputs = args.inputs
        self.given = self.photo = None
        self.load()
        given, photo = self.given, self.photo
        _check_output(args.output, given, args.overwrite, inputs=inputs)
        if args.save_psf:
            _check_output(args.save_psf, None, args.overwrite,      # a drawing: no alpha
                          inputs=inputs)
            if os.path.realpath(args.save_psf) == os.path.realpath(args.output):
                raise InputError(args.save_psf, "is also the output photo (-o); choose another "
                                                "file")
        _ignored_options(args)
        if args.save_capture:
            _check_saved_capture(args)
        self.overlap = DEFAULT_OVERLAP if args.overlap is None else args.overlap
        self.method = method = args.method or DEFAULT_METHOD
        self.options = options = {}
        if args.phi is not None:
            if method != "wiener":
                raise InputError("--phi", "applies to --method wiener only")
            options["phi"] = args.phi
        for name, value in (("iterations", args.iterations), ("noise_sigma", args.noise_sigma)):
            if value is None:
                continue
            flag = "--" + name.replace("_", "-")
            if method != "sparse":
                raise InputError(flag, "applies to --method sparse only")
            if name == "iterations" and not 1 <= value <= 100:
                raise InputError(flag, f"must be 1-100, got {value!r}")
            if name == "noise_sigma" and not 0 <= value < 1:
                raise InputError(flag, f"must be in [0, 1) (pixel-value units), got {value!r}")
            options[name] = value
        if args.model is not None:
            if method != "sparse":
                raise InputError("--model", "applies to --method sparse only")
            options["model"] = args.model
        self.grid = grid = (None if args.grid is None else args.grid if args.grid == "auto"
                            else _pair(args.grid, "--grid"))
        self.progress = _Progress("deblurring", args.quiet)
        h, w = photo.pixels.shape[:2]
        from .tiling import patch_grid     # refused now, not after a calibration (--refine)
        if isinstance(grid, tuple):        # or another photo's deblur
            patch_grid((h, w), grid, self.overlap)
        else:                              # smaller than one window in any mode
            patch_grid((h, w), (1, 1), 0.0)
        self.curve = said_transfer_curve(given, args.transfer, say)
        self.t0 = time.perf_counter()
        self.cap = self.fix = None
        self.calibrated_here = ""          # said after the time: what it includes
        if args.blind:
            if grid == "auto":
                raise InputError("--grid", "'auto' sizes patches by the gyro's PSFs: with "
                                           "--blind give RxC (default 1x1, one kernel)")
            self.blind_grid = (1, 1) if grid is None else grid
            self.kernel_size = (BLIND_KERNEL_SIZE if args.kernel_size is None
                                else args.kernel_size)
            from .deblur import check_blind_sizes     # now, not at the photo's turn
            check_blind_sizes((h, w), self.kernel_size, self.blind_grid, self.overlap)
            self._jpeg_noise()
            return
        if args.refine:
            from .calibrate_cli import fixed_parameters
            self.fix = fixed_parameters(args)
        self.cap = cap = _load_capture(args, photo, say)
        _check_not_over_capture(cap, args.overwrite, args.output, args.save_psf,
                                args.save_capture)
        if args.several:        # one photo alone: the deblur's own check, before any output
            _check_blur_fits_the_frame(cap)
        if cap.exposure_start_from_exif and not args.refine:
            from .calibrate import exif_offset_range
            raise InputError(args.capture or args.photo,  # the file without exposure_start
                             "the exposure start is the photo's EXIF time, known only to "
                             "tens of milliseconds or worse, and the PSFs need it to well "
                             "under one: add --refine (it searches "
                             f"{exif_offset_range([cap]):g} s either way), calibrate first, "
                             "or give exposure_start")
        self._jpeg_noise()

    def load(self) -> None:
        """Read the photo (again, after :meth:`release`): ``given`` as stored, ``photo``
        turned to the sensor's layout, and its ``colour`` and ``alpha``."""
        if self.given is not None:
            return
        from .imageio import read_photo
        args = self.args
        given = read_photo(args.photo)
        self.given, self.photo = given, replace(
            given, pixels=to_sensor_layout(given.stored_channels, args.photo_rotation))
        self.colour, self.alpha = split_alpha(self.photo.pixels)

    def release(self) -> None:
        """Let the photo's pixels go until :meth:`load` (one photo of many, between its
        checks and its turn)."""
        self.given = self.photo = self.colour = self.alpha = None

    def _jpeg_noise(self) -> None:
        """For a JPEG, the sparse method's noise level raised for its compression error;
        for the Wiener method, its phi raised for a noisy photo
        (:func:`gyrodeblur.wiener.photo_phi`). Said at the photo's turn, once every
        photo's inputs are known to be good."""
        photo, options = self.photo, self.options
        self.noise_note = ""
        if self.method == "sparse" and "noise_sigma" not in options and photo.quantization:
            from .noise import coarse_noise_reading, estimate_noise_sigma, photo_noise_sigma
            shown = estimate_noise_sigma(self.colour)
            coarse = coarse_noise_reading(self.colour)
            options["noise_sigma"] = photo_noise_sigma(photo, measured=shown, coarse=coarse)
            half = "" if coarse is None else f", {255 * coarse:.2f} at half resolution"
            self.noise_note = (f"JPEG: deconvolved for noise of "
                               f"{255 * options['noise_sigma']:.2f} levels (its pixels show "
                               f"{255 * shown:.2f}{half}; the compression's error counts as "
                               "noise too; --noise-sigma sets it)")
        if self.method == "wiener" and "phi" not in options:
            from .wiener import DEFAULT_PHI, photo_phi
            phi = photo_phi(self.colour)
            if phi > DEFAULT_PHI:
                options["phi"] = phi
                self.noise_note = (f"Wiener filter: phi {phi:.3g}, this photo's own "
                                   f"noise-to-signal ratio, as the chapter's {DEFAULT_PHI:g} "
                                   "would amplify its noise (--phi sets it)")

    def calibrate_alone(self) -> None:
        """``--refine`` for this photo alone: its capture replaced by the calibrated one."""
        from .calibrate import calibrate
        from .calibrate_cli import calibration_options, format_estimates, warning_notes
        options = calibration_options(self.args, [self.photo], self.say)
        with _this_photo(self.args):
            res = calibrate([self.colour], self.cap, fix=self.fix, say=warning_notes(self.say),
                            transfer=self.curve, **options)
        for line in format_estimates(res.estimates, res.kept_given,
                                     not self.cap.readout_time_unknown):
            self.say(line)
        self.cap = res.capture
        self.calibrated_here = f" (the calibration's {res.seconds:.1f} s included)"

    def finish(self) -> None:
        """Deblur the photo and write its outputs: all of them or none."""
        with _this_photo(self.args):
            self._finish()
        args = self.args
        args.written.extend(o for o in (args.output, args.save_psf, args.save_capture) if o)

    def _finish(self) -> None:
        from .deblur import deblur
        from .imageio import write_photo
        from .psfplot import field_image

        args, say, options = self.args, self.say, self.options
        grid, overlap, curve, progress = self.grid, self.overlap, self.curve, self.progress
        colour, given = self.colour, self.given
        as_it_is = False
        if self.noise_note and not args.blind:
            say(self.noise_note)
        if args.blind:
            from .deblur import deblur_blind
            blind_grid = self.blind_grid
            restored, field = deblur_blind(colour, self.kernel_size, grid=blind_grid,
                                           overlap=overlap, method=args.method,
                                           transfer=curve, check_blur=not args.no_blur_check,
                                           progress=progress, **options)
            as_it_is = (not args.no_blur_check and field.extents.max() == 1  # the checks'
                        and np.array_equal(restored, np.clip(colour, 0.0, 1.0)))  # deltas
            mode_txt = "blind"
            grid_txt = f" {blind_grid[0]}x{blind_grid[1]}" if blind_grid != (1, 1) else ""
        else:
            cap = self.cap
            restored, report = deblur(colour, cap, mode=args.mode, grid=grid,
                                      overlap=args.overlap, method=args.method,
                                      transfer=curve, progress=progress,
                                      return_report=True, **options)
            if not (args.refine or args.no_blur_check):  # options are all checked by now
                from .imageio import exif_capture_hints
                _warn_if_the_blur_does_not_fit(cap, colour, curve,
                                               exif_capture_hints(self.photo).get("digital_zoom"),
                                               extent=float(report.field.extents.max()))
            field = report.field
            mode_txt = args.mode
            grid_txt = f" {report.grid[0]}x{report.grid[1]}" if args.mode == "variant" else ""
            if report.model == "global":
                grid_txt += " (global model)"
        progress.close()
        if args.blind and self.noise_note and not as_it_is:   # of a photo deconvolved only
            say(self.noise_note)
        h, w = self.photo.pixels.shape[:2]
        drawing = (to_photo_layout(field_image(field, w, h), args.photo_rotation)
                   if args.save_psf else None)
        new_output = not os.path.lexists(args.output)
        new_drawing = bool(args.save_psf) and not os.path.lexists(args.save_psf)

        def write_pictures() -> None:
            write_photo(args.output, to_photo_layout(join_alpha(restored, self.alpha),
                                                     args.photo_rotation),
                        like=given, overwrite=args.overwrite)
            if args.save_psf:
                _write_picture(args.save_psf, drawing, args.overwrite)

        try:                         # all outputs or none (a photo it replaced is gone)
            if args.save_capture:    # its file written first, moved into place last
                from .calibrate_cli import save_captures
                save_captures([self.cap], [args.save_capture], before_moving=write_pictures)
            else:
                write_pictures()
        except BaseException:
            for path, new in ((args.output, new_output), (args.save_psf, new_drawing)):
                if new and os.path.lexists(path):
                    os.remove(path)
            raise
        e = field.extents
        gh, gw = given.pixels.shape[:2]
        if as_it_is:
            say(f"wrote {args.photo} as it is (no blind kernel that fits it) -> "
                f"{args.output}: {gw}x{gh}, {time.perf_counter() - self.t0:.2f} s")
        else:
            say(f"deblurred {args.photo} -> {args.output}: {gw}x{gh}, mode {mode_txt}"
                f"{grid_txt}, method {self.method}, PSF extent {e.min()}-{e.max()} px, "
                f"{time.perf_counter() - self.t0:.2f} s{self.calibrated_here}")
        if args.save_capture:
            first = (" (the first photo's: the others keep their own exposure start; give "
                     "one --save-capture per photo to write each)"
                     if args.save_capture_once else "")
            say(f"wrote the corrected capture description {args.save_capture}{first}")


def cmd_demo(args, say) -> None:
    from .demo import run_demo
    run_demo(args.out, say=say, overwrite=args.overwrite)


def cmd_calibrate(args, say) -> None:
    from .calibrate_cli import calibrate_command
    calibrate_command(args, say, _load_capture)


# ----------------------------------------------------------------------------- parser

DOWNSCALE_HELP = ("calibrate on the photos shrunk by this factor, 0 < F <= 1 (default 1, or "
                  "1/Z for a photo whose EXIF records a digital zoom Z): for photos softer "
                  "than their pixel grid, e.g. upscaled or heavily denoised, try 0.5; the "
                  "corrected capture keeps the given resolution")
OFFSET_RANGE_HELP = ("seconds searched on each side of the given time offset (default "
                     "0.04, or 1 around an exposure start taken from the photo's EXIF "
                     "time, 1.5 if that time is to the second); where the gyro and camera "
                     "clocks are known only roughly, e.g. 1: as far as the log covers it, "
                     "about 30 s more per second on each side on 2 cores")
MAPPINGS_HELP = ("axis mappings searched: phone, the 8 of a phone's own camera (it looks "
                 "along the device's z axis), or all 24; default phone for a phone app's "
                 "log or an Android sensor dump (in the device's axes), else all. Give all "
                 "for a phone's log and a photo from another camera fixed to it")
WORKERS_HELP = ("processes that refine the calibration's independent starts side by side "
                "(Linux; default: the CPUs available, up to 4; 1: none); the result is the "
                "same for any number. The environment variable GYRODEBLUR_THREADS=N caps "
                "the CPUs one process uses, workers and threads alike")


class _OneLineErrors(argparse.ArgumentParser):
    """An argument parser whose errors are one line, like the tool's own (``--help``
    prints the usage)."""

    def error(self, message):
        command = self.prog.partition(" ")[2]          # "deblur" of "gyrodeblur deblur"
        where = f"{command}: " if command else ""
        self.exit(2, f"gyrodeblur: error: {where}{message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .deblur import METHODS

    p = _OneLineErrors(
        prog="gyrodeblur",
        description="Remove camera-shake blur from photos using the camera's gyroscope log.",
        epilog=FRAMES_HELP)
    p.add_argument("--version", action="version",
                   version=f"gyrodeblur {__import__('gyrodeblur').__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("psf", help="render the PSF at a pixel or a PSF field",
                       description="Render the point-spread function the gyro log implies: at one "
                       "pixel (--at X,Y, pixels) or on a patch grid (--grid RxC). Output .npy "
                       "(float32, sums to 1, odd-sized, centred on the pixel; a grid gives an "
                       "N x K x K stack, row-major), .npz (that stack as 'psfs', with "
                       "'centres_xy', each PSF's pixel (x, y), and 'grid', rows and columns) "
                       "or .png (a picture). " + FRAMES_HELP)
    s.add_argument("--at", metavar="X,Y", help="pixel position (x right, y down, pixels)")
    s.add_argument("--grid", metavar="RxC", help="patch grid, e.g. 6x8")
    s.add_argument("--overlap", type=float, default=None,
                   help=f"patch overlap fraction, with --grid (default {DEFAULT_OVERLAP:g})")
    s.add_argument("-o", "--output", required=True, metavar="OUT.npy|OUT.npz|OUT.png")
    s.add_argument("--photo", metavar="PHOTO",
                   help="the blurred photo, as the camera stored it (its rows the sensor's "
                        "readout rows): the capture is fitted to its size, and its EXIF "
                        "fills what the capture leaves out (focal length, exposure time; "
                        "not the exposure start, which must be given)")
    s.add_argument("--overwrite", action="store_true",
                   help="write over an existing output file (never over an input)")
    _add_capture_options(s)
    s.set_defaults(func=cmd_psf)

    s = sub.add_parser("simulate", help="blur a sharp photo with a gyro log",
                       description="Synthesise the blurred photo the capture's camera rotation "
                       "would give, by warping the sharp photo with K R(t) K^-1 row by row "
                       "(rolling shutter) in linear light and averaging. " + FRAMES_HELP)
    s.add_argument("sharp", metavar="SHARP")
    s.add_argument("-o", "--output", required=True, metavar="BLURRED")
    s.add_argument("--snr-db", type=float, default=None,
                   help="add Gaussian noise to the blurred light, so that the photo written "
                        "has this SNR (dB: its std over the noise's)")
    s.add_argument("--full-well", type=float, default=None, metavar="ELECTRONS",
                   help="add photon shot noise too: the electrons a pixel collects at white "
                        "(a phone: several thousand at base ISO, hundreds at a high one); "
                        "bright pixels get more noise than dark ones, in light")
    s.add_argument("--seed", type=int, default=None, help="noise seed")
    s.add_argument("--sampling", choices=("cubic", "bilinear"), default="cubic",
                   help="sampling of the sharp photo between pixels: cubic spline (default; a "
                        "band-limited scene) or bilinear (for hard lights far above the clip "
                        "level, which a spline rings around; the synthesis before session 17)")
    _add_transfer_option(s)
    s.add_argument("--bit-depth", type=int, choices=(8, 16), help="output bit depth (default: the input's)")
    _add_rotation_option(s)
    s.add_argument("--overwrite", action="store_true",
                   help="write over an existing output file (never over an input)")
    _add_capture_options(s)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("deblur", help="deblur a photo",
                       description="Deblur a photo with the PSFs its gyro log implies "
                       "(space-variant patches by default), or blindly (--blind). The result is "
                       "referenced to the camera's orientation at exposure start (a blind one "
                       "keeps the blurred photo's geometry). " + FRAMES_HELP)
    s.add_argument("photos", nargs="+", metavar="PHOTO",
                   help="the photo, or several: with --refine, calibrated together as one "
                        "session (photos started at their EXIF times: one at a time), "
                        "otherwise deblurred one after another")
    s.add_argument("-o", "--output", required=True, metavar="OUT", action="append",
                   help="the deblurred photo; for several photos one per photo, in their "
                        "order: comma-separated or the option repeated")
    s.add_argument("--mode", choices=("variant", "invariant"), default="variant",
                   help="'variant' (default): a PSF per patch, as the blur changes across the "
                        "photo; 'invariant': one PSF, the principal point's, for the whole "
                        "photo")
    s.add_argument("--grid", default=None, metavar="RxC|auto",
                   help="patch grid; default: 6x8 (the chapter's) for --method wiener, 'auto' "
                        "(patches small enough that the PSF changes < 0.5 px across one) otherwise; "
                        "with --blind, 1x1 (one kernel) unless given")
    s.add_argument("--overlap", type=float, default=None, help=f"patch overlap fraction (default {DEFAULT_OVERLAP:g})")
    s.add_argument("--method", choices=sorted(METHODS), default=None,
                   help="deconvolution method (default: the best available)")
    s.add_argument("--model", choices=("global", "patches"), default=None,
                   help="sparse method: 'global' refines the patches' result under one "
                        "blur model for the whole photo, the PSFs interpolated between patch "
                        "centres (default up to 4 MP; about 3x the time); 'patches' "
                        "deconvolves each patch alone and blends them (the chapter's design; "
                        "default above 4 MP; see BENCHMARKS.md)")
    s.add_argument("--phi", type=float, default=None,
                   help="Wiener inverse SNR (default 0.01, the chapter's, or the photo's "
                        "own noise-to-signal ratio where that is larger: a dark, noisy photo)")
    s.add_argument("--iterations", type=int, default=None,
                   help="sparse method: ADMM iterations per patch (default 6, up to 12 for PSFs longer "
                        "than 32 px, which converge slowly; fewer is faster, see BENCHMARKS.md "
                        "for the trade)")
    s.add_argument("--noise-sigma", type=float, default=None,
                   help="sparse method: noise std of the photo in [0, 1] units, which sets the "
                        "prior weight (default: measured on the photo; for a JPEG, raised "
                        "for its quantisation error)")
    _add_transfer_option(s)
    s.add_argument("--blind", action="store_true", help="estimate the blur from the photo alone")
    s.add_argument("--kernel-size", type=int, default=None,
                   help=f"blind kernel size, px (odd; default {BLIND_KERNEL_SIZE})")
    s.add_argument("--no-blur-check", action="store_true",
                   help="blind: deconvolve with the estimated kernel even where the photo's "
                        "spectrum shows none of its blur or it does not sharpen the photo (by "
                        "default such a photo is left as it is, with a warning); with the "
                        "gyro (without --refine): do not check that the photo shows the blur "
                        "its log implies (by default a warning says when it does not: a "
                        "wrong time offset or log)")
    s.add_argument("--refine", action="store_true",
                   help="self-calibrate time offset, bias, readout, focal length and axes first "
                        "(a value given with --time-offset, --bias, --readout-time, --fx/--fy or "
                        "--orientation is kept as given)")
    s.add_argument("--fix", default="", metavar="NAMES",
                   help="with --refine: parameters not to estimate, comma-separated from "
                        "offset,bias,readout,focal,axes")
    s.add_argument("--downscale", type=float, default=None, metavar="F",
                   help="with --refine: " + DOWNSCALE_HELP)
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --refine: " + WORKERS_HELP)
    s.add_argument("--offset-range", type=float, default=None, metavar="S",
                   help="with --refine: " + OFFSET_RANGE_HELP)
    s.add_argument("--mappings", choices=("phone", "all"), default=None,
                   help="with --refine: " + MAPPINGS_HELP)
    s.add_argument("--save-psf", metavar="FIELD.png", action="append",
                   help="also draw the PSF field used (several photos: one per photo)")
    s.add_argument("--save-capture", metavar="CORRECTED.json", action="append",
                   help="with --refine: also write the corrected capture description, as "
                        "calibrate -o does, so that deblurring the photo again needs no "
                        "second calibration (several photos: the first photo's, or one per "
                        "photo)")
    _add_rotation_option(s, per_photo=True)
    s.add_argument("--overwrite", action="store_true",
                   help="write over an existing output file (never over an input)")
    s.add_argument("--quiet", action="store_true", help="no progress bar (none is drawn where stderr is not a terminal)")
    _add_capture_options(s, per_photo=True)
    s.set_defaults(func=cmd_deblur)

    s = sub.add_parser("demo", help="run the bundled demo",
                       description="Blur a bundled public-domain photo with a bundled gyro trace, "
                       "deblur it and write the pictures and PSNR/SSIM into a folder.")
    s.add_argument("--out", default="gyrodeblur-demo", help="output folder (default ./gyrodeblur-demo); "
                   "a folder the demo wrote before is written over, another one's files of the "
                   "demo's names only with --overwrite")
    s.add_argument("--overwrite", action="store_true",
                   help="write over files of the demo's names in a folder the demo did not write")
    s.set_defaults(func=cmd_demo)

    s = sub.add_parser("calibrate", help="estimate time offset, bias, readout, focal scale and axes",
                       description="Self-calibrate the capture from blurred photos: time offset, "
                       "gyro bias, readout time, focal-length scale and the axis mapping. Several "
                       "photos of one session share offset, mapping and bias. " + FRAMES_HELP)
    s.add_argument("photos", nargs="+", metavar="PHOTO")
    s.add_argument("-o", "--output", required=True, metavar="CORRECTED.json", action="append",
                   help="corrected capture description: one (the first photo's; the "
                        "corrections are shared), or one per photo, in their order, each "
                        "with its own exposure start: comma-separated or the option repeated")
    s.add_argument("--fix", default="", metavar="NAMES",
                   help="comma-separated parameters not to estimate: offset,bias,readout,focal,"
                        "axes (a value given with --time-offset, --bias, --readout-time, "
                        "--fx/--fy or --orientation is fixed too)")
    s.add_argument("--downscale", type=float, default=None, metavar="F", help=DOWNSCALE_HELP)
    s.add_argument("--workers", type=int, default=None, metavar="N", help=WORKERS_HELP)
    s.add_argument("--offset-range", type=float, default=None, metavar="S",
                   help=OFFSET_RANGE_HELP)
    s.add_argument("--mappings", choices=("phone", "all"), default=None, help=MAPPINGS_HELP)
    _add_transfer_option(s)
    _add_rotation_option(s, per_photo=True, writes_photos=False)     # calibrate
    s.add_argument("--overwrite", action="store_true",
                   help="write over an existing output file (never over an input)")
    _add_capture_options(s, required=True, per_photo=True)
    s.set_defaults(func=cmd_calibrate)
    return p


def _photos(args) -> str | None:
    """The photo file(s) a command reads, for an error that names no other source."""
    paths = [getattr(args, "photo", None), getattr(args, "sharp", None),
             *(getattr(args, "photos", None) or [])]
    return ", ".join(p for p in paths if p) or None


#: A value that starts with a minus and reads as a number or a list of them (``-1e-3``,
#: ``-0.01,0.02,0``): argparse takes it for an option unless it is a plain decimal.
_NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d)[\d.eE+\-, ]*$")


def joined_negative_lists(argv: list[str]) -> list[str]:
    """``argv`` with ``--bias -0.01,0.02,0`` written as ``--bias=-0.01,0.02,0`` (and
    ``--time-offset -1e-3`` as ``--time-offset=-1e-3``): argparse reads a value that
    starts with a minus and is not a plain decimal as an option, and says ``expected one
    argument``; a bias, a position or a time offset is often negative. Only long options
    are joined (no command's flag is followed by a negative number)."""
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if (tok.startswith("--") and "=" not in tok and i + 1 < len(argv)
                and _NEGATIVE_VALUE.match(argv[i + 1])):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


#: The library's keyword arguments that an option of another name sets.
_OPTION_OF_ARGUMENT = {"captures": "--capture"}


def as_option(exc: InputError) -> InputError:
    """``exc`` as the command line says it: a library function's keyword argument named
    as the option that set it (``kernel_size`` -> ``--kernel-size``, ``captures`` ->
    ``--capture``); an error about a file or an option unchanged."""
    if not exc.argument:
        return exc
    return InputError(_OPTION_OF_ARGUMENT.get(exc.source, "--" + exc.source.replace("_", "-")),
                      exc.problem)


#: The arguments that name one file each, and the options that name files (a comma-
#: separated list for several photos), whose ``~`` :func:`_home_expanded` expands.
_FILE_ARGUMENTS = ("photos", "sharp")
_FILE_OPTIONS = ("capture", "gyro", "output", "save_psf", "save_capture", "out")


def _home_expanded(args) -> None:
    """``~`` expanded in every file name ``args`` holds, as in a capture's ``gyro.path``:
    the shell leaves it alone after ``--capture=`` or ``-o=``, where it had been taken for
    a folder named ``~``. An option's value is expanded item by item of its
    comma-separated list (the spaces before an item dropped, as the list reader drops
    them); an argument's, whole."""
    def expand(value, listed: bool):
        if isinstance(value, list):
            return [expand(v, listed) for v in value]
        if not isinstance(value, str) or "~" not in value:
            return value
        if not listed:
            return os.path.expanduser(value)
        return ",".join(os.path.expanduser(v.lstrip()) if v.lstrip().startswith("~") else v
                        for v in value.split(","))

    for names, listed in ((_FILE_ARGUMENTS, False), (_FILE_OPTIONS, True)):
        for name in names:
            if getattr(args, name, None) is not None:
                setattr(args, name, expand(getattr(args, name), listed))


def _option_action(actions: dict, option: str):
    """The action argparse takes ``option`` for: its own, the one long option it abbreviates
    (argparse refuses an ambiguous one), or a short option with its value attached."""
    if option in actions:
        return actions[option]
    if option.startswith("--"):
        matches = {actions[o] for o in actions if o.startswith(option)}
        return matches.pop() if len(matches) == 1 else None
    return actions.get(option[:2])


def _refuse_repeated_options(parser: argparse.ArgumentParser, args, argv: list[str]) -> None:
    """Refuse an option of one value given twice (``--fx 300 --fx 3000``): argparse keeps
    the last without a word, where ``-o`` or ``--capture`` given twice for one photo is
    refused. An option is known however argparse reads it: abbreviated (``--exposure-t``
    for ``--exposure-time``) or a short one with its value attached (``-oout.png``).
    Options that take a value each time (``action="append"``) and flags are left alone;
    so is everything after ``--``."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    actions = sub.choices[args.command]._option_string_actions
    seen: set[str] = set()
    for tok in argv:
        if tok == "--":
            break
        option = tok.split("=", 1)[0]
        action = _option_action(actions, option) if tok.startswith("-") else None
        if not isinstance(action, argparse._StoreAction):
            continue
        if not option.startswith("--"):
            option = option[:2]                 # -oout.png
        if action.dest in seen:
            raise InputError(option, "given twice: give it once (the last would silently "
                                     "replace the first)")
        seen.add(action.dest)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = joined_negative_lists(sys.argv[1:] if argv is None else list(argv))
    args = parser.parse_args(argv)
    _home_expanded(args)

    def say(msg: str) -> None:
        _write(sys.stdout, f"{msg}\n")

    shown = set()

    def warn(message, category, filename, lineno, file=None, line=None):
        if str(message) in shown:    # the same words from two places: deblur --refine's
            return                   # calibration and its deblur (a gap in the log)
        shown.add(str(message))
        _write(sys.stderr, f"gyrodeblur: warning: {message}\n")

    previous = _on_sigterm(_terminate)
    try:
        with warnings.catch_warnings():
            # each command shows its own warnings: a filter added (last, so the user's -W
            # and PYTHONWARNINGS still rule) makes Python forget those shown before
            warnings.simplefilter("default", append=True)
            warnings.showwarning = warn
            try:
                _refuse_repeated_options(parser, args, argv)
                args.func(args, say)
            finally:                        # a message after a bar starts its own line
                _Progress.end_drawn()
    except InputError as exc:
        if exc.source is None and _photos(args):     # a problem of the photo(s) themselves
            exc = InputError(_photos(args), exc.problem)
        exc = as_option(exc)
        _write(sys.stderr, f"gyrodeblur: error: {exc}{_written_before(args)}\n")
        return 2
    except GyrodeblurWarning as exc:   # made an error: -W or PYTHONWARNINGS=error::...
        _write(sys.stderr, f"gyrodeblur: error: {exc} (a warning made an error by the "
                           f"warnings filter){_written_before(args)}\n")
        return 3
    except KeyboardInterrupt:
        _write(sys.stderr, f"gyrodeblur: interrupted; {_written_before(args, 'nothing')}\n")
        return 130
    except _Terminated:
        _write(sys.stderr, f"gyrodeblur: terminated; {_written_before(args, 'nothing')}\n")
        return 143
    except Exception:                   # unexpected (exit 1, a traceback): what is written
        if getattr(args, "written", None):
            _write(sys.stderr, f"gyrodeblur: {_written_before(args, 'nothing')}\n")
        raise
    finally:
        _on_sigterm(previous)
    return 0


def _written_before(args, none: str = "") -> str:
    """What a command of several photos (``deblur``) wrote before it stopped: the files
    of the photos it finished (``args.written``); ``none`` where it wrote nothing."""
    done = getattr(args, "written", None)
    if not done:
        return f"{none} written" if none else ""
    return (f"{'' if none else ' ('}written before it stopped: {', '.join(done)}; nothing "
            f"else{'' if none else ')'}")


def _write(stream, text: str) -> None:
    """Write ``text`` to ``stream`` (standard output or error) now. Where the reader has
    closed the pipe (``| head``, ``2>&1 | true``), what is still to be said goes to the
    null device: the files the command writes matter more than its report, and the work
    goes on (the interpreter's own flush at exit would fail again on the pipe)."""
    try:
        stream.write(text)
        stream.flush()
    except BrokenPipeError:
        _to_devnull(stream)


def _to_devnull(stream) -> None:
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):    # not a file (a test's capture)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


class _Terminated(BaseException):
    """SIGTERM, raised where the program is, so that temporary files are removed and
    worker processes stopped on the way out (as for Ctrl-C)."""


def _terminate(signum, frame):
    raise _Terminated


def _on_sigterm(handler):
    """Install ``handler`` for SIGTERM and return the one before (``None`` where signals
    cannot be set: outside the main thread)."""
    import signal
    if handler is None:
        return None
    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:           # not the main thread of the interpreter
        return None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
