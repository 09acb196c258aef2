"""Benchmark dataset: sharp photos blurred by real hand shake recorded by a gyroscope.

Every case is one sharp photo and one window of a real gyro log. The blur is synthesised
the way light blurs, independently of the PSF renderer that deblurring uses:

    sharp sRGB photo -> linear light -> :func:`~gyrodeblur.simulate.simulate_blur`
    (warping by the rotation the log records, rolling shutter included) -> sRGB
    -> :func:`~gyrodeblur.simulate.add_noise` (``snr_db``) -> :func:`~gyrodeblur.simulate.quantize_8bit`

A case on disk is exactly what a user's own capture looks like, so the command-line tool
runs on it unchanged::

    <case>/blurred.png    the photo to deblur (8-bit sRGB)
    <case>/gyro.gcsv      the log around the exposure (window +- ``margin`` s), Gyroflow gcsv
    <case>/capture.json   the capture description (gyro path relative to it)
    <case>/sharp.png      the ground truth (8-bit sRGB)
    <case>/case.json      how the case was made (source photo, window, seed, roll, ...)

    gyrodeblur deblur <case>/blurred.png --capture <case>/capture.json -o out.png

The in-memory API (:func:`build_cases`) gives the same cases as :class:`Case` objects, so
benchmarks need not touch the disk; :func:`write_case` / :func:`load_case` go to and from
the folder layout, and :func:`build_dataset` does both. Everything is deterministic for a
seed: each case draws its window, exposure and image noise from its own generator, seeded
by ``(seed, crc32(photo name), window index)``, so a case does not change when other
photos are added or left out.

Command line::

    python -m gyrodeblur.dataset OUT_DIR [--max-size 512] [--windows 3] [--seed 0] ...
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .arguments import is_count
from .atomicfile import atomic_write_text
from .camera import Camera
from .capture import Capture, load_capture
from .errors import InputError
from .gyrolog import FORMATS, GyroLog, read_gyro_log, write_gcsv
from .psf import psf_extent, render_psf
from .simulate import add_noise, quantize_8bit, simulate_blur, warp_samples
from .tonecurve import linear_to_srgb, srgb_to_linear

__all__ = [
    "Case",
    "build_cases",
    "build_dataset",
    "write_case",
    "load_case",
    "load_dataset",
    "default_gyro",
    "list_photos",
    "find_gaps",
    "draw_window",
    "plan_window",
    "render_case",
    "read_sharp",
    "shake_stats",
    "default_shared_data",
    "DEFAULTS",
]

#: Defaults of :func:`build_cases` (units: seconds, fraction of the width, dB, px).
DEFAULTS = {
    "exposure": (0.010, 0.040),   # s; a range is sampled uniformly per case
    "readout": 0.030,             # s, readout of all rows (row y starts y/H of it later)
    "focal": 0.8,                 # fx = focal * width (px); 0.8 ~ a 28 mm-equivalent lens
    "snr_db": 40.0,               # image noise, dB (std(blurred) / std(noise))
    "windows_per_photo": 3,
    "seed": 0,
    "margin": 0.3,                # s of log kept on each side of the exposure window
    "orientation": "Xyz",         # log axes -> camera axes (android-back-camera-0)
    "sim_step_px": 1.0,           # px between blur-synthesis time samples (see notes)
}
#: A step between two log samples longer than this many median steps is a gap (two
#: samples or more missing in a row). Phones' logs jitter, and drop single samples: a
#: step of 1.5-2 median steps is common and harmless to the integration (the shared log's
#: one gap is 5.4 steps, its other steps at most 1.02).
GAP_FACTOR = 3.0
#: gcsv resolution: 1 us and 1e-6 rad/s (the defaults of :func:`write_gcsv`).
_TSCALE = 1e-6
_GSCALE = 1e-6
_PHOTO_EXT = (".png", ".jpg", ".jpeg", ".tif", ".tiff")


def default_shared_data() -> Path:
    """``$GYRODEBLUR_SHARED_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get("GYRODEBLUR_SHARED_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2].parent / "shared" / "data"


def _default_photos() -> Path:
    return default_shared_data() / "photos"


def default_gyro() -> Path:
    """The hand-held gyro trace the benchmark cases are blurred with (shared data)."""
    return default_shared_data() / "gyro" / "handheld_phone_210hz.csv"


@dataclass(frozen=True, eq=False)
class Case:
    """One benchmark case.

    Attributes
    ----------
    name : str
        ``<photo stem>_w<k>``.
    sharp : ndarray (H, W, 3) or (H, W), float32, or None
        Ground truth, sRGB-encoded, on 8-bit levels (what ``sharp.png`` holds); None for a
        case read from a folder without one.
    blurred : ndarray, like ``sharp``
        The synthetic photo, sRGB, 8-bit levels (what ``blurred.png`` holds).
    capture : Capture
        Its capture description; ``capture.log`` is the excerpt written as ``gyro.gcsv``.
    meta : dict
        ``photo`` (source file name), ``window_start`` (s, gyro clock), ``exposure_time``,
        ``readout_time`` (s), ``fx`` (px), ``snr_db``, ``noise_seed``, ``roll_deg`` (largest
        roll, rotation about the optical axis, during the window, degrees),
        ``rotation_deg`` (largest total rotation), ``blur_px`` (extent of the PSF at the
        image centre), ``mean_rate`` (rad/s), ``sim_samples``, ``sim_sampling``
        (:func:`simulate_blur`'s sampling between pixels: "cubic spline" since session 17;
        absent: bilinear).
    """

    name: str
    sharp: np.ndarray
    blurred: np.ndarray
    capture: Capture
    meta: dict = field(default_factory=dict)

    @property
    def roll_deg(self) -> float:
        return float(self.meta["roll_deg"])

    @property
    def megapixels(self) -> float:
        return self.sharp.shape[0] * self.sharp.shape[1] / 1e6


# ----------------------------------------------------------------------------- inputs

def list_photos(folder: str | os.PathLike) -> list[Path]:
    """Image files (png, jpg, tif) in ``folder``, sorted by name; hidden files (a name
    starting with ``.``, e.g. macOS's ``._photo.png``) are not photos.

    Raises
    ------
    InputError
        No such folder, no photo in it, or two photos of one name stem (``x.jpg`` and
        ``x.png``): cases are named, and seeded, by the stem.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(str(folder), "photo folder not found")
    photos = sorted(p for p in folder.iterdir()
                    if p.suffix.lower() in _PHOTO_EXT and not p.name.startswith(".")
                    and p.is_file())
    if not photos:
        raise InputError(str(folder), "no photos (png, jpg, tif) in the folder")
    _refuse_shared_stems(photos)
    return photos


def _refuse_shared_stems(paths) -> None:
    seen: dict[str, Path] = {}
    for p in paths:
        if p.stem in seen:
            raise InputError(str(p), f"has the name stem of {seen[p.stem].name}: cases are "
                                     "named and seeded by it (one would replace the other); "
                                     "rename one of them")
        seen[p.stem] = p


def read_sharp(path: str | os.PathLike, max_size: int | None = None) -> np.ndarray:
    """A sharp photo as float32 sRGB on 8-bit levels, RGB (alpha dropped), optionally
    downscaled (in linear light, anti-aliased) so its longer side is ``max_size``."""
    from .imageio import read_photo

    if max_size is not None and (isinstance(max_size, bool) or not isinstance(
            max_size, (int, np.integer)) or max_size < 2):
        raise InputError(None, f"max_size must be a whole number of pixels >= 2, got {max_size!r}")
    img = read_photo(path).pixels
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    h, w = img.shape[:2]
    if max_size is not None and max(h, w) > max_size:
        from skimage.transform import resize

        s = max_size / max(h, w)
        shape = (max(2, round(h * s)), max(2, round(w * s))) + img.shape[2:]
        lin = resize(srgb_to_linear(img), shape, order=1, anti_aliasing=True,
                     preserve_range=True)
        img = linear_to_srgb(lin)
    return quantize_8bit(img)


def find_gaps(log: GyroLog, factor: float = GAP_FACTOR) -> np.ndarray:
    """Indices ``i`` where ``t[i+1] - t[i]`` exceeds ``factor`` times the median step
    (:attr:`GyroLog.sample_interval`)."""
    return np.nonzero(np.diff(log.t) > factor * log.sample_interval)[0]


def draw_window(log: GyroLog, duration: float, rng: np.random.Generator, *,
                margin: float = DEFAULTS["margin"], gaps: np.ndarray | None = None,
                tries: int = 10000) -> float:
    """A start time ``s`` (gyro clock) such that ``[s - margin, s + duration + margin]``
    lies inside the log and contains no gap (uniform over such starts)."""
    gaps = find_gaps(log) if gaps is None else gaps
    lo, hi = log.t[0] + margin, log.t[-1] - margin - duration
    if hi <= lo:
        raise InputError(log.source, f"the gyro log ({log.t[-1] - log.t[0]:.2f} s) is too "
                                     f"short for a {duration * 1e3:.0f} ms window with "
                                     f"{margin:g} s margins")
    g0, g1 = log.t[gaps], log.t[gaps + 1]
    for _ in range(tries):
        s = float(rng.uniform(lo, hi))
        a, b = s - margin, s + duration + margin
        if not np.any((g1 > a) & (g0 < b)):
            return s
    raise InputError(log.source, "found no gap-free window in the gyro log")


def _quantized_excerpt(log: GyroLog, t0: float, t1: float) -> GyroLog:
    """Samples covering ``[t0, t1]`` (one beyond each end), at gcsv resolution, so the
    in-memory log equals the one read back from ``gyro.gcsv`` bit for bit."""
    i0 = max(int(np.searchsorted(log.t, t0, side="right")) - 2, 0)
    i1 = min(int(np.searchsorted(log.t, t1, side="left")) + 2, len(log.t))
    t = np.round(log.t[i0:i1] / _TSCALE).astype(np.int64) * _TSCALE
    w = np.round(log.omega[i0:i1] / _GSCALE).astype(np.int64) * _GSCALE
    return GyroLog(t, w, log.source, {})


def shake_stats(capture: Capture, n: int = 257) -> dict:
    """Roll and total rotation (degrees, largest during the window, relative to the
    exposure start), mean angular rate (rad/s) and the centre PSF's extent (px)."""
    t0, t1 = capture.window
    q = capture.orientation.quaternions(np.linspace(t0, t1, n))
    q = q * np.sign(q[:, :1] + (q[:, :1] == 0))                  # w >= 0
    vn = np.linalg.norm(q[:, 1:], axis=1)
    ang = 2 * np.arctan2(vn, q[:, 0])
    rotvec = q[:, 1:] * np.where(vn > 0, ang / np.where(vn > 0, vn, 1), 2.0)[:, None]
    _, w = capture.camera_rates()
    keep = (capture.log.t + capture.time_offset >= t0) & (capture.log.t + capture.time_offset <= t1)
    cam = capture.camera
    psf = render_psf(capture, cam.cx, cam.cy, row=(cam.height - 1) / 2)
    return {
        "roll_deg": float(np.degrees(np.abs(rotvec[:, 2]).max())),
        "rotation_deg": float(np.degrees(np.linalg.norm(rotvec, axis=1).max())),
        "mean_rate": float(np.linalg.norm(w[keep], axis=1).mean()) if keep.any() else 0.0,
        "blur_px": psf_extent(psf),
    }


# ----------------------------------------------------------------------------- building

def _exposure_range(exposure) -> tuple[float, float]:
    if np.ndim(exposure) == 0:
        e = float(exposure)
        return e, e
    lo, hi = (float(v) for v in exposure)
    if not 0 < lo <= hi:
        raise InputError("exposure", f"need 0 < min <= max, got {exposure!r}")
    return lo, hi


def plan_window(log: GyroLog, stem: str, k: int, width: int, height: int, *,
                seed: int = DEFAULTS["seed"], exposure=DEFAULTS["exposure"],
                readout: float = DEFAULTS["readout"], focal: float = DEFAULTS["focal"],
                margin: float = DEFAULTS["margin"], orientation=DEFAULTS["orientation"],
                gaps: np.ndarray | None = None) -> tuple[Capture, dict]:
    """The capture of window ``k`` for photo ``stem`` (no image work: cheap).

    Draws, from the generator seeded by ``(seed, crc32(stem), k)``: the exposure time
    (uniform in ``exposure`` when it is a range; rounded to 1 us), a gap-free window start
    (:func:`draw_window`), and the image-noise seed. The capture's log is the excerpt
    ``[start - margin, end + margin]`` at gcsv resolution; the camera is centred with
    ``fx = fy = focal * width``.

    Returns
    -------
    capture : Capture
    meta : dict
        Window, timing, seeds and :func:`shake_stats`.
    """
    e_lo, e_hi = _exposure_range(exposure)
    for name, value in (("readout", readout), ("margin", margin)):
        if not (isinstance(value, (int, float, np.integer, np.floating))
                and not isinstance(value, bool) and 0 <= value < np.inf):
            raise InputError(None, f"{name} must be a number of seconds >= 0, got {value!r}")
    if not (isinstance(focal, (int, float, np.integer, np.floating))
            and not isinstance(focal, bool) and 0 < focal < np.inf):
        raise InputError(None, f"focal must be a positive multiple of the width, got {focal!r}")
    rng = np.random.default_rng([int(seed), zlib.crc32(stem.encode()), int(k)])
    e = round(float(rng.uniform(e_lo, e_hi)) if e_hi > e_lo else e_lo, 6)
    dur = readout + e
    start = round(draw_window(log, dur, rng, margin=margin, gaps=gaps), 6)
    noise_seed = int(rng.integers(2 ** 31))
    excerpt = _quantized_excerpt(log, start - margin, start + dur + margin)
    cam = Camera.centred(width, height, focal * width)
    cap = Capture(start, e, readout, cam, excerpt, axes=orientation,
                  gyro_spec={"path": "gyro.gcsv", "format": "gcsv"})
    meta = {"window_start": start, "exposure_time": e, "readout_time": readout,
            "fx": cam.fx, "focal_fraction": focal, "seed": int(seed), "window": int(k),
            "noise_seed": noise_seed, "width": width, "height": height, **shake_stats(cap)}
    return cap, meta


def render_case(name: str, sharp: np.ndarray, capture: Capture, meta: dict, *,
                snr_db: float | None = DEFAULTS["snr_db"],
                sim_step_px: float = DEFAULTS["sim_step_px"],
                linear: np.ndarray | None = None) -> Case:
    """Blur ``sharp`` (sRGB) by ``capture``: linear light, :func:`simulate_blur`, sRGB,
    noise at ``snr_db`` (seed ``meta["noise_seed"]``), 8-bit levels."""
    lin = srgb_to_linear(sharp) if linear is None else linear
    n = warp_samples(capture, max_step=sim_step_px)
    blurred = linear_to_srgb(simulate_blur(lin, capture, n_samples=n, order=3, transfer="linear"))
    if snr_db is not None:
        blurred = add_noise(blurred, snr_db, meta.get("noise_seed"))
    meta = {**meta, "snr_db": snr_db, "sim_samples": n, "sim_step_px": sim_step_px,
            "sim_sampling": "cubic spline"}                  # order=3 above
    return Case(name, sharp, quantize_8bit(blurred), capture, meta)


def build_cases(photos=None, gyro=None, *, exposure=DEFAULTS["exposure"],
                readout: float = DEFAULTS["readout"], focal: float = DEFAULTS["focal"],
                snr_db: float | None = DEFAULTS["snr_db"],
                windows_per_photo: int = DEFAULTS["windows_per_photo"],
                seed: int = DEFAULTS["seed"], max_size: int | None = None,
                max_photos: int | None = None, margin: float = DEFAULTS["margin"],
                orientation=DEFAULTS["orientation"], gyro_format: str | None = None,
                sim_step_px: float = DEFAULTS["sim_step_px"], progress=None) -> list[Case]:
    """Blur every photo with ``windows_per_photo`` real shake windows, in memory.

    Parameters
    ----------
    photos : folder, or list of image files, optional
        Default: ``../shared/data/photos`` beside the repository.
    gyro : path or GyroLog, optional
        The log to draw shake from; default the shared hand-held phone log (csv, t in ns,
        rad/s, 210 Hz).
    exposure : float or (min, max)
        Exposure time in seconds, or a range sampled uniformly per case (default 10-40 ms).
    readout : float
        Rolling-shutter readout time, s (default 0.03).
    focal : float
        Focal length as a fraction of the image width: ``fx = fy = focal * width`` px,
        principal point at the centre (default 0.8). Scales with ``max_size``.
    snr_db : float or None
        Image noise after blurring, dB (default 40; None: none).
    windows_per_photo : int
    seed : int
    max_size : int, optional
        Downscale photos (in linear light) so their longer side is at most this.
    max_photos : int, optional
        Use only the first photos (sorted by name).
    margin : float
        Seconds of log kept each side of the exposure window (the case's gyro file), and
        kept gap-free.
    orientation : str or 3x3
        Log axes -> camera axes (default ``"Xyz"``, ``android-back-camera-0``: Android
        device axes -> a back camera whose sensor rows run along the device's x axis).
    gyro_format : str, optional
        Format of ``gyro`` (default: guessed).
    sim_step_px : float
        Largest motion (px) between the time samples of the blur synthesis. 1 px agrees
        with 0.5 px (simulate's default) to 63-79 dB PSNR (session 60's audit) at half the
        cost.
    progress : callable(done, total, name), optional

    Returns
    -------
    list of Case, photo by photo, window by window.
    """
    _check_build_numbers(snr_db, windows_per_photo, max_photos)
    if isinstance(photos, (list, tuple)):
        paths = [Path(p) for p in photos]
        if not paths:
            raise InputError("photos", "an empty list: name at least one photo")
        _refuse_shared_stems(paths)
    else:
        paths = list_photos(photos or _default_photos())
    if max_photos is not None:
        paths = paths[:max_photos]
    if isinstance(gyro, GyroLog):
        log = gyro
    else:
        log = read_gyro_log(gyro or default_gyro(), gyro_format)
    gaps = find_gaps(log)
    e_lo, e_hi = _exposure_range(exposure)
    if readout < 0:
        raise InputError("readout", f"must be >= 0, got {readout}")
    if focal <= 0:
        raise InputError("focal", f"must be > 0, got {focal}")
    cases: list[Case] = []
    total = len(paths) * windows_per_photo
    for path in paths:
        sharp = read_sharp(path, max_size)
        lin = srgb_to_linear(sharp)
        h, w = sharp.shape[:2]
        for k in range(windows_per_photo):
            cap, meta = plan_window(log, path.stem, k, w, h, seed=seed, exposure=(e_lo, e_hi),
                                    readout=readout, focal=focal, margin=margin,
                                    orientation=orientation, gaps=gaps)
            meta["photo"] = path.name
            cases.append(render_case(f"{path.stem}_w{k}", sharp, cap, meta, snr_db=snr_db,
                                     sim_step_px=sim_step_px, linear=lin))
            if progress:
                progress(len(cases), total, cases[-1].name)
    return cases


def _check_build_numbers(snr_db, windows_per_photo, max_photos) -> None:
    """Refuse :func:`build_cases`' counts and SNR that no case could be built with (a NaN
    or infinite SNR, no windows), before any work, naming the argument."""
    if snr_db is not None and not (isinstance(snr_db, (int, float, np.integer, np.floating))
                                   and not isinstance(snr_db, bool)
                                   and -1e6 < float(snr_db) < 1e6):      # (not NaN)
        raise InputError("snr_db", f"must be a finite number of dB, or None for no noise, "
                                   f"got {snr_db!r}")
    for name, v in (("windows_per_photo", windows_per_photo), ("max_photos", max_photos)):
        if (v is not None or name == "windows_per_photo") and not is_count(v):
            raise InputError(name, f"must be a whole number >= 1, got {v!r}")


# ----------------------------------------------------------------------------- disk

def write_case(case: Case, folder: str | os.PathLike, *, overwrite: bool = True) -> Path:
    """Write ``case`` as ``blurred.png``, ``gyro.gcsv``, ``capture.json``, ``sharp.png``
    and ``case.json`` into ``folder`` (created).

    A case without a ground truth (``sharp`` None, as :func:`load_case` reads a folder
    without ``sharp.png``) is written without ``sharp.png``; one left in ``folder`` from
    another case is removed (with ``overwrite``; without it, refused), so that the folder
    reads back as this case."""
    from .imageio import write_photo

    folder = Path(folder)
    sharp_path = folder / "sharp.png"
    if case.sharp is None and sharp_path.exists() and not overwrite:
        raise InputError(str(sharp_path), "exists, and this case has no sharp photo to write in "
                         "its place: give overwrite=True to remove it")
    folder.mkdir(parents=True, exist_ok=True)
    write_photo(folder / "blurred.png", case.blurred, bit_depth=8, overwrite=overwrite)
    if case.sharp is not None:
        write_photo(sharp_path, case.sharp, bit_depth=8, overwrite=overwrite)
    elif sharp_path.exists():
        sharp_path.unlink()
    write_gcsv(folder / "gyro.gcsv", case.capture.log, tscale=_TSCALE, gscale=_GSCALE)
    case.capture.save(folder / "capture.json", gyro_path="gyro.gcsv")
    with open(folder / "case.json", "w", encoding="utf-8") as fh:
        json.dump({"name": case.name, **case.meta}, fh, indent=2)
        fh.write("\n")
    return folder


def load_case(folder: str | os.PathLike) -> Case:
    """Read a case folder written by :func:`write_case` (or laid out the same way;
    ``sharp.png`` and ``case.json`` are optional: ``sharp`` is then None)."""
    from .imageio import read_photo

    folder = Path(folder)
    blurred = read_photo(folder / "blurred.png").pixels
    sharp_path = folder / "sharp.png"
    sharp = read_photo(sharp_path).pixels if sharp_path.exists() else None
    cap = load_capture(folder / "capture.json")
    meta_path = folder / "case.json"
    meta = json.loads(meta_path.read_text(encoding="utf-8")) if meta_path.exists() else {}
    name = meta.pop("name", folder.name)
    return Case(name, sharp, blurred, cap, meta)


def build_dataset(out_dir: str | os.PathLike, **options) -> list[Path]:
    """:func:`build_cases` with ``options`` and write each case to ``out_dir/<name>/``,
    plus ``out_dir/dataset.json`` (the options, with the photo and gyro paths absolute;
    under ``made_with`` the package's version, its git commit where it has one, and the
    photos and log used, defaults resolved; and the case list).

    Built again into the same folder, the cases of the former index that the new one
    lacks are removed (their folders only), so that the folder holds one dataset."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(str(out), "is a file, not a folder for the dataset")
    cases = build_cases(**options)
    out.mkdir(parents=True, exist_ok=True)
    former = _indexed_cases(out)
    folders = [write_case(c, out / c.name) for c in cases]
    for name in sorted(set(former) - {c.name for c in cases}):
        stale = out / name
        if (stale / "case.json").is_file() and stale.parent == out and stale.name == name:
            shutil.rmtree(stale)

    def plain(k, v):
        if isinstance(v, GyroLog):
            return v.source or "GyroLog (in memory)"
        if k in ("photos", "gyro") and isinstance(v, (str, os.PathLike)):
            return os.path.abspath(os.fspath(v))      # found from anywhere later
        if isinstance(v, os.PathLike):
            return os.fspath(v)
        if isinstance(v, (list, tuple)):
            return [plain(k, x) for x in v]
        if isinstance(v, np.ndarray):
            return v.tolist()
        return v

    opts = {k: plain(k, v) for k, v in options.items() if k != "progress"}
    from . import __version__
    gyro = options.get("gyro") or default_gyro()
    used = {"gyrodeblur": __version__,        # what the defaults (None) were, for the record
            "photos": plain("photos", options.get("photos") or _default_photos()),
            "gyro": plain("gyro", gyro.source if isinstance(gyro, GyroLog) and gyro.source
                          else gyro)}
    commit = _source_commit()
    if commit:
        used["commit"] = commit
    index = {"options": opts, "made_with": used, "cases": [c.name for c in cases]}
    atomic_write_text(out / "dataset.json", json.dumps(index, indent=2) + "\n")
    return folders


def _source_commit() -> str | None:
    """The git commit of the package's own source, where it is a git checkout (an
    installed copy has none), else ``None``."""
    import subprocess
    try:
        done = subprocess.run(["git", "-C", str(Path(__file__).resolve().parent), "rev-parse",
                               "HEAD"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    head = done.stdout.strip()
    return head if done.returncode == 0 and len(head) == 40 else None


def _indexed_cases(folder: Path) -> list[str]:
    """The case names a folder's ``dataset.json`` lists (none if it has no readable one)."""
    try:
        names = json.loads((folder / "dataset.json").read_text(encoding="utf-8"))["cases"]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    # one plain folder name each: never "..", ".", a path, or (on Windows) "a/b"
    return [n for n in names if isinstance(n, str) and n not in ("", ".", "..")
            and os.path.basename(n) == n and (os.altsep is None or os.altsep not in n)]


def load_dataset(folder: str | os.PathLike) -> list[Case]:
    """All cases of a folder written by :func:`build_dataset` (order of its index, else
    every sub-folder holding a ``capture.json``, sorted)."""
    folder = Path(folder)
    index = folder / "dataset.json"
    if index.exists():
        names = json.loads(index.read_text(encoding="utf-8"))["cases"]
    else:
        names = sorted(p.name for p in folder.iterdir() if (p / "capture.json").exists())
    return [load_case(folder / n) for n in names]


# ----------------------------------------------------------------------------- CLI

def _range(text: str):
    parts = [float(p) for p in text.replace(":", ",").split(",")]
    if len(parts) == 1:
        return parts[0]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected S or MIN,MAX seconds, got {text!r}")
    return tuple(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyrodeblur.dataset",
                                 description="Build a benchmark dataset: sharp photos x real "
                                             "gyro shake windows, one folder per case.")
    ap.add_argument("out", help="output folder")
    ap.add_argument("--photos", help="folder of sharp photos (default ../shared/data/photos)")
    ap.add_argument("--gyro", help="gyro log (default ../shared/data/gyro/handheld_phone_210hz.csv)")
    ap.add_argument("--gyro-format", choices=FORMATS)
    ap.add_argument("--exposure", type=_range, default=DEFAULTS["exposure"],
                    help="exposure time, s, or MIN,MAX sampled per case (default 0.01,0.04)")
    ap.add_argument("--readout", type=float, default=DEFAULTS["readout"], help="readout time, s")
    ap.add_argument("--focal", type=float, default=DEFAULTS["focal"],
                    help="focal length as a fraction of the width (default 0.8)")
    ap.add_argument("--snr", type=float, default=DEFAULTS["snr_db"], help="image SNR, dB")
    ap.add_argument("--windows", type=int, default=DEFAULTS["windows_per_photo"],
                    help="shake windows per photo")
    ap.add_argument("--seed", type=int, default=DEFAULTS["seed"])
    ap.add_argument("--max-size", type=int, help="downscale photos to this longer side (px)")
    ap.add_argument("--max-photos", type=int, help="use only the first N photos")
    ap.add_argument("--orientation", default=DEFAULTS["orientation"], metavar="AXES",
                    help="the log's axes -> camera axes, as gyro.orientation (default Xyz, "
                         "android-back-camera-0: an Android phone's device axes -> a back "
                         "camera whose sensor rows run along the device's x axis; XYZ for a "
                         "log already in camera axes)")
    args = ap.parse_args(argv)
    try:
        folders = build_dataset(
            args.out, photos=args.photos, gyro=args.gyro, gyro_format=args.gyro_format,
            orientation=args.orientation,
            exposure=args.exposure, readout=args.readout, focal=args.focal,
            snr_db=args.snr, windows_per_photo=args.windows, seed=args.seed,
            max_size=args.max_size, max_photos=args.max_photos,
            progress=lambda i, n, name: print(f"[{i}/{n}] {name}", flush=True))
    except InputError as exc:
        option = _OPTIONS.get(exc.source)        # named as the command line spells it
        print(f"error: {exc if option is None else f'{option}: {exc.problem}'}",
              file=sys.stderr)
        return 2
    print(f"wrote {len(folders)} cases to {args.out}")
    return 0


#: :func:`build_cases`' arguments, by the options of :func:`main` that set them.
_OPTIONS = {"snr_db": "--snr", "windows_per_photo": "--windows", "max_photos": "--max-photos",
            "max_size": "--max-size", "readout": "--readout", "focal": "--focal",
            "exposure": "--exposure", "orientation": "--orientation"}


if __name__ == "__main__":
    raise SystemExit(main())
