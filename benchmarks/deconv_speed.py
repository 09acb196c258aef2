"""Speed and memory of the patchwise Wiener deconvolution (chapter sec. 6.5.2 setup).

Times ``deconvolve_patchwise`` + ``wiener_deconvolve`` (6 x 8 patches, 25 % overlap, one
~30 px PSF per patch) on a 4000 x 3000 RGB float32 photo, against:

* the FFT floor measured in the same run: one ``rfft2`` + ``irfft2`` of all 3 channels
  of the whole image (float32, axes (0, 1), same ``workers``), i.e. the least work any
  FFT-based deconvolution of this photo needs;
* ``skimage.restoration.wiener`` on the same photo with one PSF, per channel.

Memory is reported two ways, both for one patchwise call: the tracemalloc peak (every
NumPy/Python allocation made during the call, not scipy.fft's internal C++ buffers) and
the growth of the process's peak RSS (``resource.getrusage(...).ru_maxrss``) over the
call, which counts everything but is only a high-water mark.

Usage::

    python benchmarks/deconv_speed.py            # full size, 4000 x 3000
    python benchmarks/deconv_speed.py --quick    # 1000 x 750, seconds

Writes ``benchmarks/results/deconv_speed.json``.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import scipy
import scipy.fft as sfft

from gyrodeblur.fftutils import usable_cpus
from gyrodeblur.tiling import MAX_AUTO_WORKERS, deconvolve_patchwise, patch_grid
from gyrodeblur.wiener import DEFAULT_PHI, wiener_deconvolve

RESULTS = Path(__file__).resolve().parent / "results" / "deconv_speed.json"
TARGETS = {"seconds": 1.5, "x_fft_floor": 4.0, "peak_mib": 1.5 * 1024}


def make_photo(height: int, width: int) -> np.ndarray:
    """A photo-like float32 RGB image: scikit-image's astronaut, mirror-tiled to size.

    Filled tile by tile into one preallocated array, so building it does not raise the
    process's peak RSS above the image itself.
    """
    from skimage import data

    tile = data.astronaut().astype(np.float32) / 255.0
    tile = np.concatenate([tile, tile[::-1]], axis=0)
    tile = np.concatenate([tile, tile[:, ::-1]], axis=1)  # seamless 1024 x 1024
    th, tw = tile.shape[:2]
    photo = np.empty((height, width, 3), np.float32)
    for y in range(0, height, th):
        for x in range(0, width, tw):
            h, w = min(th, height - y), min(tw, width - x)
            photo[y:y + h, x:x + w] = tile[:h, :w]
    return photo


def make_psfs(n: int, extent: int, seed: int = 0) -> list[np.ndarray]:
    """``n`` curved-motion PSFs of about ``extent`` px, odd-sized, unit sum."""
    rng = np.random.default_rng(seed)
    size = extent + 2 + (extent + 1) % 2
    c = size // 2
    psfs = []
    for _ in range(n):
        angle = rng.uniform(0, np.pi)
        bend = rng.uniform(-0.5, 0.5)
        t = np.linspace(-0.5, 0.5, 8 * extent)
        x = t * (extent - 2)
        y = bend * (extent - 2) * (t ** 2 - 1 / 12)
        yy = c + y * np.cos(angle) + x * np.sin(angle)
        xx = c + x * np.cos(angle) - y * np.sin(angle)
        psf = np.zeros((size, size))
        np.add.at(psf, (np.rint(yy).astype(int), np.rint(xx).astype(int)), 1.0)
        psfs.append((psf / psf.sum()).astype(np.float32))
    return psfs


def timed(fn, repeat: int) -> dict:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"best_s": min(times), "median_s": statistics.median(times), "runs_s": times}


def maxrss_mib() -> float:
    # Linux reports KiB, macOS bytes.
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 1024 ** 2
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1000 x 750 image, 15 px PSFs")
    ap.add_argument("--repeat", type=int, default=None,
                    help="timed runs per measurement (default 5, quick 3)")
    ap.add_argument("--no-skimage", action="store_true", help="skip the scikit-image run")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)

    height, width, extent = (750, 1000, 15) if args.quick else (3000, 4000, 30)
    repeat = args.repeat or (3 if args.quick else 5)
    image = make_photo(height, width)
    patches = patch_grid(image.shape, (6, 8), 0.25)
    psfs = make_psfs(len(patches), extent)
    deconv = functools.partial(wiener_deconvolve, phi=DEFAULT_PHI)

    # Memory first (before anything else has raised the RSS high-water mark).
    rss_before = maxrss_mib()
    t0 = time.perf_counter()
    out = deconvolve_patchwise(image, patches, psfs, deconv)
    cold_s = time.perf_counter() - t0
    rss_growth = maxrss_mib() - rss_before
    del out
    tracemalloc.start()
    out = deconvolve_patchwise(image, patches, psfs, deconv)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    auto_workers = min(usable_cpus(), MAX_AUTO_WORKERS)
    serial = deconvolve_patchwise(image, patches, psfs, deconv, workers=1)
    # what was timed is a deconvolution: the same with one worker or several, the mean
    # level kept (the PSFs sum to 1), and the photo changed
    check = {"workers_max_abs_diff": float(np.abs(out - serial).max()),
             "mean_in": float(image.mean()), "mean_out": float(out.mean()),
             "rms_change": float(np.sqrt(np.mean((out - image) ** 2)))}
    del out, serial

    def fft_floor():
        spec = sfft.rfft2(image, axes=(0, 1), workers=usable_cpus())
        sfft.irfft2(spec, s=image.shape[:2], axes=(0, 1), workers=usable_cpus(),
                    overwrite_x=True)

    # Interleave the measurements so that load from other processes hits them alike.
    runs: dict[str, list[float]] = {"fft_floor": [], "patchwise_auto": [], "patchwise_w1": []}
    for _ in range(repeat):
        for name, fn in (
                ("fft_floor", fft_floor),
                ("patchwise_auto", lambda: deconvolve_patchwise(image, patches, psfs, deconv)),
                ("patchwise_w1", lambda: deconvolve_patchwise(image, patches, psfs, deconv,
                                                              workers=1))):
            runs[name].append(timed(fn, 1)["best_s"])
    res = {k: {"best_s": min(v), "median_s": statistics.median(v), "runs_s": v}
           for k, v in runs.items()}
    floor = res["fft_floor"]["best_s"]

    sk = None
    if not args.no_skimage:
        from skimage.restoration import wiener as sk_wiener

        psf = psfs[len(psfs) // 2]

        def skimage_run():
            for c in range(image.shape[2]):
                sk_wiener(image[..., c], psf, balance=DEFAULT_PHI, clip=False)

        sk = timed(skimage_run, 1 if not args.quick else 2)

    peak_traced_mib = traced_peak / 2 ** 20
    image_mib = image.nbytes / 2 ** 20
    report = {
        "image": [height, width, 3],
        "dtype": "float32",
        "grid": [6, 8],
        "overlap": 0.25,
        "psf_extent_px": extent,
        "n_psfs": len(psfs),
        "phi": DEFAULT_PHI,
        "fft_workers": usable_cpus(),
        "patch_workers_auto": auto_workers,
        "cpu_count": os.cpu_count(),
        "loadavg_1min": os.getloadavg()[0],
        "repeat": repeat,
        "timings": res,
        "check": check,
        "patchwise_cold_s": cold_s,
        "skimage_wiener_per_channel": sk,
        "memory": {
            "image_mib": image_mib,
            "tracemalloc_peak_mib": peak_traced_mib,
            "tracemalloc_note": "NumPy/Python allocations during one deconvolve_patchwise "
                                "call (default workers), excluding the input image; "
                                "scipy.fft's internal buffers are not traced",
            "maxrss_growth_mib": rss_growth,
            "maxrss_mib": maxrss_mib(),
            "maxrss_before_mib": rss_before,
            "maxrss_note": "ru_maxrss high-water mark of the whole process (Linux, KiB->MiB); "
                           "growth is over the first patchwise call",
        },
        "versions": {"python": platform.python_version(), "numpy": np.__version__,
                     "scipy": scipy.__version__},
    }
    best = res["patchwise_auto"]["best_s"]
    report["targets"] = {
        **TARGETS,
        "met_seconds": best < TARGETS["seconds"],
        "met_x_fft_floor": best / floor <= TARGETS["x_fft_floor"],
        "met_peak_mib": (image_mib + peak_traced_mib) < TARGETS["peak_mib"],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))

    print(f"image {width}x{height} RGB float32, 6x8 patches, 25% overlap, "
          f"{len(psfs)} PSFs of ~{extent} px, FFT workers {usable_cpus()}, "
          f"load {report['loadavg_1min']:.2f} on {os.cpu_count()} cores")
    print(f"{'measurement':<40}{'best s':>9}{'median s':>10}{'x floor':>9}")
    rows = [("FFT floor (rfft2+irfft2, 3 ch)", res["fft_floor"]),
            (f"patchwise Wiener, workers={auto_workers} (default)", res["patchwise_auto"]),
            ("patchwise Wiener, workers=1", res["patchwise_w1"])]
    if sk is not None:
        rows.append(("skimage wiener, 1 PSF, per channel", sk))
    for name, r in rows:
        print(f"{name:<40}{r['best_s']:>9.3f}{r['median_s']:>10.3f}{r['best_s'] / floor:>9.2f}")
    print(f"patchwise first (cold) call: {cold_s:.3f} s")
    print(f"memory: image {image_mib:.0f} MiB; tracemalloc peak during call "
          f"{peak_traced_mib:.0f} MiB (+ image = {image_mib + peak_traced_mib:.0f} MiB); "
          f"ru_maxrss {report['memory']['maxrss_mib']:.0f} MiB "
          f"(growth over first call {rss_growth:.0f} MiB)")
    t = report["targets"]
    print(f"targets: < {TARGETS['seconds']} s: {'yes' if t['met_seconds'] else 'NO'}; "
          f"<= {TARGETS['x_fft_floor']}x floor: {'yes' if t['met_x_fft_floor'] else 'NO'}; "
          f"< {TARGETS['peak_mib']:.0f} MiB: {'yes' if t['met_peak_mib'] else 'NO'}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    import _common                      # the script's folder is on sys.path

    raise SystemExit(_common.run_main(main))
