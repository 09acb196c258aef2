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

    from gyrodeblur.fftutils import FFT_WORKERS

    info = {
        "cpu_count": os.cpu_count(),
        "fft_workers": FFT_WORKERS,
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


def get_cases(*, dataset: str | None = None, **build_options):
    """Benchmark cases: loaded from ``dataset`` when that folder holds a built dataset,
    else built in memory (and written to ``dataset`` when one is named)."""
    from gyrodeblur.dataset import build_dataset, build_cases, load_dataset

    if dataset:
        folder = Path(dataset)
        index = folder / "dataset.json"
        if index.exists():
            stored = json.loads(index.read_text(encoding="utf-8")).get("options", {})
            wanted = {k: (os.fspath(v) if isinstance(v, os.PathLike)
                          else list(v) if isinstance(v, tuple) else v)
                      for k, v in build_options.items() if k != "progress"}
            differ = {k: (stored.get(k), v) for k, v in wanted.items()
                      if k in stored and stored.get(k) != v}
            if differ:
                warnings.warn(f"{folder} was built with other options "
                              f"(stored, asked): {differ}; using it as it is", stacklevel=2)
            return load_dataset(folder)
        build_dataset(folder, **build_options)
        return load_dataset(folder)
    return build_cases(**build_options)


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
    deblurring is judged on."""
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
