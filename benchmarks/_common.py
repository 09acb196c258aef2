"""Helpers shared by the benchmark scripts (not part of the library).

Paths: results (JSON, markdown, full-size plots) go to ``benchmarks/results/`` (git-ignored);
small plots meant for BENCHMARKS.md are copied to ``benchmarks/figures/`` (tracked) by the
full runs only.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
FIGURES = HERE / "figures"


def machine_info() -> dict:
    """Where and with what the numbers were measured."""
    import scipy
    import skimage

    from gyrodeblur.fftutils import usable_cpus

    info = {
        "cpu_count": os.cpu_count(),
        "fft_workers": usable_cpus(),
        "loadavg_1min_at_start": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-image": skimage.__version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "git_head": _git_head(),
    }
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemTotal:"):
                    info["mem_total_gib"] = round(int(line.split()[1]) / 2 ** 20, 1)
    except OSError:
        pass
    return info


def _git_head() -> str | None:
    import subprocess

    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE,
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def mem_available_bytes() -> int | None:
    """``MemAvailable`` from /proc/meminfo (Linux), else None."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def write_json(path: Path, obj) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=2, default=_jsonable) + "\n", encoding="utf-8")
    return path


def _jsonable(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


@contextmanager
def quiet():
    """Silence the library's UserWarnings (e.g. large-PSF notes) during a benchmark."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        yield


def run_main(main, argv: list[str] | None = None) -> int:
    """Run a benchmark's ``main(argv)`` as a command: an :class:`~gyrodeblur.errors.InputError`
    (bad photo folder, gyro log, dataset, option...) is printed as one line,
    ``error: <message>`` on stderr, with exit status 2 instead of a traceback. A ``main``
    that returns something other than an int (a summary) counts as success."""
    from gyrodeblur.errors import InputError

    try:
        rc = main(argv)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr, flush=True)
        return 2
    return rc if isinstance(rc, int) else 0


def add_source_options(parser) -> None:
    """Add ``--photos`` and ``--gyro`` to an argparse ``parser``: the folder of sharp photos
    and the gyro log a benchmark draws its cases from (``None``: the shared data's)."""
    parser.add_argument("--photos", help="photo folder (default ../shared/data/photos)")
    parser.add_argument("--gyro", help="gyro log (default the shared hand-held phone log)")


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (a count of 0 would silently mean nothing)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def pick_photo(photo: str | None, photos: str | os.PathLike | None,
               default_name: str | None = None) -> Path:
    """The one photo a single-photo benchmark uses: ``photo`` as a file, or as a name or
    name stem (``lai_text_01`` for ``lai_text_01.png``) in the folder ``photos`` (default
    ``../shared/data/photos``); without ``photo``, ``default_name`` when the folder holds it,
    else the folder's first photo (:func:`gyrodeblur.dataset.list_photos`' order).

    Raises
    ------
    InputError
        No such photo, or a folder without photos."""
    from gyrodeblur.dataset import default_shared_data, list_photos
    from gyrodeblur.errors import InputError

    folder = Path(photos) if photos else default_shared_data() / "photos"
    if photo:
        if Path(photo).is_file():
            return Path(photo)
        if (folder / photo).is_file():
            return folder / photo
        if not folder.is_dir():
            raise InputError(photo, f"photo not found (nor a photo folder {folder})")
        found = [p for p in list_photos(folder) if p.stem == photo or p.name == photo]
        if not found:
            raise InputError(photo, f"photo not found, as a file or a name in {folder}")
        return found[0]
    if default_name and (folder / default_name).is_file():
        return folder / default_name
    return list_photos(folder)[0]


def resolve_stored_path(value: str, folder: str | os.PathLike, what: str = "path") -> Path:
    """A path a dataset's ``dataset.json`` stores: as it is when absolute; a relative one
    (datasets built before the paths were stored absolute) relative to the dataset folder
    first, then to the current folder."""
    from gyrodeblur.errors import InputError

    p = Path(value)
    if p.is_absolute():
        if not p.exists():
            raise InputError(str(p), f"{what} stored in {Path(folder) / 'dataset.json'} "
                                     "not found")
        return p
    for candidate in (Path(folder) / p, p):
        if candidate.exists():
            return candidate
    raise InputError(value, f"{what} stored in {Path(folder) / 'dataset.json'} not found "
                            f"(relative to {folder} or to the current folder)")


def _same_option(key: str, stored, wanted, folder: Path) -> bool:
    """Whether a stored dataset option is the one asked for; photo and gyro paths are
    compared by their real absolute form (None: the shared default)."""
    if key not in ("photos", "gyro"):
        return stored == wanted
    from gyrodeblur.dataset import default_gyro, default_shared_data

    default = default_shared_data() / "photos" if key == "photos" else default_gyro()

    def real(v, base):
        if v is None:
            return os.path.realpath(default)
        if not isinstance(v, (str, os.PathLike)):
            return v
        p = Path(v)
        if not p.is_absolute() and base is not None and (base / p).exists():
            p = base / p
        return os.path.realpath(p)

    return real(stored, folder) == real(wanted, None)


def stored_options(folder: str | os.PathLike) -> dict:
    """The build options a dataset folder's ``dataset.json`` records ({} without one)."""
    index = Path(folder) / "dataset.json"
    if not index.is_file():
        return {}
    try:
        return dict(json.loads(index.read_text(encoding="utf-8")).get("options", {}))
    except (OSError, ValueError, TypeError, AttributeError):
        return {}


def load_cases(folder: str | os.PathLike) -> list:
    """The cases of a built dataset folder (:func:`gyrodeblur.dataset.load_dataset`: the
    ones its ``dataset.json`` lists).

    Raises
    ------
    InputError
        No such folder, or no case in it."""
    from gyrodeblur.dataset import load_dataset
    from gyrodeblur.errors import InputError

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(str(folder), "dataset folder not found")
    try:
        cases = load_dataset(folder)
    except (ValueError, KeyError, TypeError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(str(folder / "dataset.json"), f"unreadable dataset index "
                                                        f"({type(exc).__name__}: {exc})") from None
    if not cases:
        raise InputError(str(folder), "no cases in the dataset folder (build one with "
                                      "python -m gyrodeblur.dataset DIR)")
    for case in cases:
        if case.sharp is None:
            raise InputError(str(folder / case.name), "no sharp.png: a benchmark case needs "
                                                      "its ground truth")
    return cases


def get_cases(*, dataset: str | None = None, **build_options):
    """Benchmark cases: loaded from ``dataset`` when that folder holds a built dataset,
    else built in memory (and written to ``dataset`` when one is named)."""
    return get_cases_and_options(dataset=dataset, **build_options)[0]


def get_cases_and_options(*, dataset: str | None = None, **build_options):
    """:func:`get_cases`, and the build options of the cases returned: those of the
    folder's ``dataset.json`` when ``dataset`` is given (what the cases were built with,
    not what was asked, when the two differ; a warning says so; an option it does not
    record is :func:`gyrodeblur.dataset.build_cases`' default), else ``build_options``."""
    import inspect

    from gyrodeblur.dataset import build_cases, build_dataset

    asked = {k: v for k, v in build_options.items() if k != "progress"}
    if not dataset:
        return build_cases(**build_options), asked
    folder = Path(dataset)
    index = folder / "dataset.json"
    if index.exists():
        stored = stored_options(folder)
        wanted = {k: (os.fspath(v) if isinstance(v, os.PathLike)
                      else list(v) if isinstance(v, tuple) else v)
                  for k, v in asked.items()}
        differ = {k: (stored.get(k), v) for k, v in wanted.items()
                  if k in stored and not _same_option(k, stored.get(k), v, folder)}
        if differ:
            warnings.warn(f"{folder} was built with other options "
                          f"(stored, asked): {differ}; using it as it is", stacklevel=3)
    else:
        build_dataset(folder, **build_options)
        stored = stored_options(folder)
    cases = load_cases(folder)
    params = inspect.signature(build_cases).parameters
    used = {k: stored.get(k, params[k].default if k in params else None) for k in asked}
    used.update({k: v for k, v in stored.items() if k not in used})
    return cases, used


def progress_printer(label: str):
    def show(i, n, name=""):
        print(f"  {label} [{i}/{n}] {name}", flush=True)
    return show


def matplotlib_pyplot():
    """pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def say(msg: str) -> None:
    print(msg, flush=True)
    sys.stdout.flush()


def registered_psnr(reference: np.ndarray, estimate: np.ndarray, border: int,
                    upsample: int = 10) -> float:
    """PSNR (the chapter's) after shifting ``estimate`` by the global sub-pixel shift that
    best aligns it with ``reference`` (phase correlation on luma, inside the border)."""
    from scipy import ndimage
    from skimage.registration import phase_cross_correlation

    from gyrodeblur.metrics import crop_border, psnr

    shift = phase_cross_correlation(crop_border(_luma(reference), border),
                                    crop_border(_luma(estimate), border),
                                    upsample_factor=upsample, normalization=None)[0]
    if np.allclose(shift, 0):
        return psnr(reference, estimate, border)
    full = tuple(shift) + (0,) * (np.ndim(estimate) - 2)
    moved = ndimage.shift(np.asarray(estimate, np.float32), full, order=1, mode="nearest")
    return psnr(reference, moved, border)


def field_registered_psnr(reference: np.ndarray, estimate: np.ndarray, border: int,
                          block: int = 128, step: int = 64, upsample: int = 10) -> float:
    """PSNR (the chapter's) after warping ``estimate`` by the smooth displacement field that
    best aligns it with ``reference``: the shift of each ``block`` px square every ``step``
    px (phase correlation on luma), median-filtered over 3 x 3 neighbours (a flat block's
    shift is noise), interpolated bilinearly between the blocks' centres, applied with
    bicubic interpolation. It forgives any smooth geometric difference (a global shift, a
    rolling shutter's skew and wobble, a small rotation), which a method that does not
    know the exposure-start orientation (a blind one) cannot avoid, and keeps what
    deblurring is judged on. It is no upper bound of the global shift's PSNR: each
    block's shift is measured on its own, so on a small photo (few blocks) or a blurred
    one (flat correlation peaks) the field can be noisier than one shift, and score below
    it (a held-out audit: a 320 px blurred input, 28.62 dB against 28.76)."""
    import cv2
    from scipy import ndimage
    from skimage.registration import phase_cross_correlation

    from gyrodeblur.metrics import psnr

    ref, est = _luma(reference), _luma(estimate)
    h, w = ref.shape
    block = min(block, h, w)
    ys = np.arange(0, h - block + 1, step)
    xs = np.arange(0, w - block + 1, step)
    shifts = np.zeros((ys.size, xs.size, 2))
    with warnings.catch_warnings():     # a flat block (clipped, black) has no error
        warnings.simplefilter("ignore", UserWarning)   # figure; the median filter copes
        for i, y in enumerate(ys):
            for j, x in enumerate(xs):
                shifts[i, j] = phase_cross_correlation(
                    ref[y:y + block, x:x + block], est[y:y + block, x:x + block],
                    upsample_factor=upsample, normalization=None)[0]
    shifts = np.stack([ndimage.median_filter(shifts[..., k], 3, mode="nearest")
                       for k in range(2)], -1)
    # field at every pixel: bilinear between block centres, constant beyond the outer ones
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    gy = np.clip((yy - (ys[0] + block / 2 - 0.5)) / step, 0, ys.size - 1)
    gx = np.clip((xx - (xs[0] + block / 2 - 0.5)) / step, 0, xs.size - 1)
    d = [ndimage.map_coordinates(shifts[..., k], [gy, gx], order=1) for k in range(2)]
    img = np.ascontiguousarray(estimate, np.float32)
    moved = cv2.remap(img, (xx - d[1]).astype(np.float32), (yy - d[0]).astype(np.float32),
                      cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    return psnr(reference, np.clip(moved, 0, 1), border)     # no bicubic overshoot


def _luma(a) -> np.ndarray:
    """Mean of the channels (float32): what the registrations align."""
    a = np.asarray(a, np.float32)
    return a.mean(axis=2) if a.ndim == 3 else a
