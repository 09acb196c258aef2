"""Wall time and peak memory of deblurring against image size, with the FFT floor.

For every size (1, 3, 12, 24, 48 MP, RGB, 4:3), every method (default: all of
:data:`gyrodeblur.deblur.METHODS`) and both modes (``variant``: the automatic grid of
patches, with the method's default model; ``invariant``: one whole-image PSF; and, when
asked for with ``--modes``, ``patches``: ``variant`` with ``model="patches"``, the sparse
method without its global refinement), a fresh Python process

1. builds a photo-like float32 sRGB image (scikit-image's astronaut mirror-tiled, as
   ``benchmarks/deconv_speed.py`` does) and a capture from a real shake window of the
   shared hand-held gyro log (the bundled demo log when the shared data are absent):
   exposure 20 ms, readout 30 ms, fx = 0.8 x width, so blur in pixels grows with the
   width as it does on a real sensor;
2. times ``deblur(image, capture, mode=..., method=...)`` end to end (sRGB decode, PSF
   rendering, deconvolution, blending, encode): best of ``--repeat`` runs (default 3 up
   to 3 MP, 2 above, 1 with --quick);
3. measures, in the same process right after, the FFT floor: one forward and one inverse
   real FFT of the 3-channel float32 image, zero-padded to the next fast FFT shape, the
   faster of ``scipy.fft`` (axes (0, 1), all FFT workers) and OpenCV's packed transforms
   (:mod:`gyrodeblur.packedfft`, which the sparse solver uses); the least any whole-image
   FFT deconvolution can cost.

Memory: the child's ``ru_maxrss`` (peak resident set, the whole process: interpreter,
libraries, input image and the call, scipy.fft's buffers included) read after the first
timed call, and its growth over the call (peak after minus peak before). Each child runs
under an address-space limit of 90 % of the memory available at its start, so a size that
would not fit fails cleanly (recorded) instead of taking the machine down.

Usage::

    python benchmarks/speed.py                # 1-48 MP, a few minutes on 2 cores
    python benchmarks/speed.py --quick        # 0.25 and 1 MP, the default method, 1 run

Writes ``benchmarks/results/speed.{json,md,png}`` (and, for a full run,
``benchmarks/figures/speed.png``).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

SIZES_MP = [1, 3, 12, 24, 48]
QUICK_SIZES_MP = [0.25, 1]
MODES = ["variant", "invariant"]
#: Modes ``--modes`` may name: deblur()'s mode and model for each.
MODE_CALLS = {"variant": {"mode": "variant"}, "invariant": {"mode": "invariant"},
              "patches": {"mode": "variant", "model": "patches"}}
EXPOSURE = 0.02
READOUT = 0.03
FOCAL = 0.8


def dims(megapixels: float) -> tuple[int, int]:
    """``(height, width)``, 4:3, width a multiple of 16 (48 MP -> 6000 x 8000)."""
    w = 16 * round(math.sqrt(megapixels * 1e6 * 4 / 3) / 16)
    return round(w * 3 / 4), w


def _maxrss_mib() -> float:
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 1024 ** 2
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def _capture(height: int, width: int):
    """A capture with real shake: of the first 7 windows of the log (seed 0), the one
    whose centre blur is the median."""
    from gyrodeblur.dataset import default_gyro, find_gaps, plan_window
    from gyrodeblur.gyrolog import read_gyro_log

    path = default_gyro()
    if path.exists():
        log, source, axes = read_gyro_log(path), "shared handheld_phone_210hz.csv", "Xyz"
    else:
        from importlib import resources
        p = resources.files("gyrodeblur") / "data" / "demo_gyro.gcsv"
        log, source, axes = read_gyro_log(str(p), "gcsv"), "bundled demo_gyro.gcsv", "XYZ"
    gaps = find_gaps(log)
    plans = [plan_window(log, "speed", k, width, height, exposure=EXPOSURE, readout=READOUT,
                         focal=FOCAL, orientation=axes, gaps=gaps) for k in range(7)]
    blur = [m["blur_px"] for _, m in plans]
    cap, meta = plans[int(np.argsort(blur)[len(blur) // 2])]
    return cap, {"gyro": source, "window_start": meta["window_start"],
                 "blur_px_centre": meta["blur_px"], "roll_deg": meta["roll_deg"]}


def worker(mp: float, method: str, mode: str, repeat: int) -> dict:
    """One measurement, in this (fresh) process."""
    import scipy.fft as sfft

    from deconv_speed import make_photo
    from gyrodeblur.deblur import deblur
    from gyrodeblur.fftutils import fast_shape, usable_cpus
    from gyrodeblur.packedfft import packed_irfft2, packed_rfft2
    from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

    height, width = dims(mp)
    image = make_photo(height, width)
    cap, info = _capture(height, width)
    rss_before = _maxrss_mib()
    runs, report, rss_after = [], None, None
    with _common.quiet():
        for _ in range(repeat):
            t0 = time.perf_counter()
            out, report = deblur(image, cap, method=method, return_report=True,
                                 **MODE_CALLS[mode])
            runs.append(time.perf_counter() - t0)
            del out
            if rss_after is None:
                rss_after = _maxrss_mib()
    curve = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        linear_to_srgb(srgb_to_linear(image))
        curve.append(time.perf_counter() - t0)
    shape = fast_shape((height, width))
    padded = np.zeros(shape + (3,), np.float32)
    padded[:height, :width] = image
    del image
    floor_scipy, floor_cv = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        spec = sfft.rfft2(padded, axes=(0, 1), workers=usable_cpus())
        sfft.irfft2(spec, s=shape, axes=(0, 1), workers=usable_cpus(), overwrite_x=True)
        floor_scipy.append(time.perf_counter() - t0)
        del spec
    planes = np.ascontiguousarray(np.moveaxis(padded, 2, 0))
    del padded
    for _ in range(repeat):
        t0 = time.perf_counter()
        packed_irfft2(packed_rfft2(planes))
        floor_cv.append(time.perf_counter() - t0)
    floor = [min(a, b) for a, b in zip(floor_scipy, floor_cv)]
    lo, hi = report.extent_range
    return {"mp": mp, "width": width, "height": height, "megapixels": width * height / 1e6,
            "method": method, "mode": mode, "status": "ok", "seconds": min(runs),
            "runs_s": runs, "floor_s": min(floor), "floor_runs_s": floor,
            "floor_scipy_s": min(floor_scipy), "floor_opencv_s": min(floor_cv),
            "floor_shape": list(shape), "ratio_to_floor": min(runs) / min(floor),
            "transfer_curve_s": min(curve),
            "peak_rss_mib": rss_after, "rss_before_call_mib": rss_before,
            "call_growth_mib": rss_after - rss_before,
            "image_mib": width * height * 3 * 4 / 2 ** 20,
            "grid": list(report.grid), "psf_extent_px": [lo, hi], **info}


def _limit_memory(limit: int | None):
    def apply():
        if limit:
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return apply


def run_child(mp: float, method: str, mode: str, repeat: int, timeout: float) -> dict:
    avail = _common.mem_available_bytes()
    limit = int(0.9 * avail) if avail else None
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(mp), method, mode,
           str(repeat)]
    base = {"mp": mp, "method": method, "mode": mode,
            "memory_limit_gib": None if limit is None else round(limit / 2 ** 30, 1)}
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              preexec_fn=_limit_memory(limit))
    except subprocess.TimeoutExpired:
        return {**base, "status": f"timeout after {timeout:.0f} s"}
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        oom = "MemoryError" in proc.stderr or proc.returncode in (-9, 137)
        return {**base, "status": ("out of memory: " if oom else "failed: ") + tail[0],
                "wall_s": time.perf_counter() - t0}
    return {**base, **json.loads(lines[-1]), "child_wall_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == "--worker":
        mp, method, mode, repeat = float(argv[1]), argv[2], argv[3], int(argv[4])
        print(json.dumps(worker(mp, method, mode, repeat)), flush=True)
        return 0
    from gyrodeblur.deblur import DEFAULT_METHOD, METHODS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="0.25 and 1 MP, the default method only")
    ap.add_argument("--sizes", help="comma-separated megapixels (default 1,3,12,24,48)")
    ap.add_argument("--methods", help=f"comma-separated (default all: {', '.join(METHODS)})")
    ap.add_argument("--modes", default=",".join(MODES),
                    help=f"comma-separated, of {', '.join(MODE_CALLS)} (default "
                         f"{','.join(MODES)})")
    ap.add_argument("--repeat", type=int, default=None,
                    help="timed runs per measurement (default 3 up to 3 MP, 2 above; quick 1)")
    ap.add_argument("--timeout", type=float, default=900.0,
                    help="seconds per measurement; a method that times out is not tried "
                         "at larger sizes")
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "speed.json")
    ap.add_argument("--figure", type=Path, default=None,
                    help="also save the plot here (full run default: benchmarks/figures/speed.png)")
    args = ap.parse_args(argv)
    sizes = ([float(s) for s in args.sizes.split(",")] if args.sizes
             else (QUICK_SIZES_MP if args.quick else SIZES_MP))
    methods = (args.methods.split(",") if args.methods
               else ([DEFAULT_METHOD] if args.quick else list(METHODS)))
    modes = args.modes.split(",")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise SystemExit(f"unknown method(s) {unknown}; known: {', '.join(METHODS)}")
    unknown = [m for m in modes if m not in MODE_CALLS]
    if unknown:
        raise SystemExit(f"unknown mode(s) {unknown}; known: {', '.join(MODE_CALLS)}")
    t_start = time.perf_counter()
    machine = _common.machine_info()
    runs, given_up = [], set()
    for mp in sorted(sizes):
        for method in methods:
            for mode in modes:
                if (method, mode) in given_up:
                    runs.append({"mp": mp, "method": method, "mode": mode,
                                 "status": "skipped (failed or timed out at a smaller size)"})
                    continue
                repeat = args.repeat or (1 if args.quick else 3 if mp <= 3 else 2)
                r = run_child(mp, method, mode, repeat, args.timeout)
                runs.append(r)
                if r["status"] != "ok":
                    given_up.add((method, mode))
                    _common.say(f"{mp:>6g} MP {method:>10} {mode:>9}: {r['status']}")
                    continue
                _common.say(f"{mp:>6g} MP {method:>10} {mode:>9}: {r['seconds']:8.2f} s  "
                            f"floor {r['floor_s']:6.2f} s  x{r['ratio_to_floor']:5.1f}  "
                            f"peak RSS {r['peak_rss_mib']:7.0f} MiB (call +"
                            f"{r['call_growth_mib']:.0f})  PSF {r['psf_extent_px'][0]}-"
                            f"{r['psf_extent_px'][1]} px")
    result = {
        "benchmark": "speed",
        "quick": args.quick,
        "sizes_mp": sizes,
        "methods": methods,
        "modes": modes,
        "capture": {"exposure_time": EXPOSURE, "readout_time": READOUT,
                    "focal_fraction": FOCAL},
        "time_note": "best of the timed runs of deblur() end to end (sRGB decode, PSFs, "
                     "deconvolution, blending, encode), float32 RGB input",
        "floor_note": "forward + inverse real FFT of the 3-channel float32 image zero-padded "
                      "to the next fast shape, the faster of scipy.fft (axes (0, 1), all "
                      "workers) and OpenCV's packed cv2.dft/idft (per channel, its own "
                      "threads), same process, right after",
        "transfer_note": "srgb_to_linear + linear_to_srgb of the image alone (part of the time)",
        "memory_note": "ru_maxrss of the measuring child process (whole process), read after "
                       "the first timed call; call_growth = its increase over the call",
        "runs": runs,
        "total_seconds": time.perf_counter() - t_start,
        "machine": machine,
    }
    _common.write_json(args.out, result)
    md = markdown_table(result)
    args.out.with_suffix(".md").write_text(md, encoding="utf-8")
    png = args.out.with_suffix(".png")
    plot(result, png)
    full = not args.quick and not args.sizes and not args.methods and args.modes == ",".join(MODES)
    figure = args.figure or (_common.FIGURES / "speed.png" if full else None)
    if figure is not None:
        plot(result, Path(figure), dpi=80)
    print(md)
    _common.say(f"wrote {args.out}, {args.out.with_suffix('.md')} and {png}"
                + (f" and {figure}" if figure else ""))
    return 0


def markdown_table(result: dict) -> str:
    lines = ["| MP | size | method | mode | time (s) | all runs (s) | FFT floor (s) | x floor "
             "| sRGB curves (s) | peak RSS (MiB) | call + (MiB) | PSF extent (px) |",
             "|---:|---|---|---|---:|---|---:|---:|---:|---:|---:|---|"]
    for r in result["runs"]:
        if r.get("status") != "ok":
            lines.append(f"| {r['mp']:g} | | {r['method']} | {r['mode']} | {r['status']} "
                         f"| | | | | | | |")
            continue
        lines.append(f"| {r['mp']:g} | {r['width']}x{r['height']} | {r['method']} | "
                     f"{r['mode']} | {r['seconds']:.2f} | "
                     f"{', '.join(format(v, '.1f') for v in r['runs_s'])} | {r['floor_s']:.2f} | "
                     f"{r['ratio_to_floor']:.1f} | {r['transfer_curve_s']:.2f} | "
                     f"{r['peak_rss_mib']:.0f} | "
                     f"{r['call_growth_mib']:.0f} | {r['psf_extent_px'][0]}-"
                     f"{r['psf_extent_px'][1]} |")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: Path, dpi: int = 110) -> None:
    plt = _common.matplotlib_pyplot()
    ok = [r for r in result["runs"] if r.get("status") == "ok"]
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    keys = sorted({(r["method"], r["mode"]) for r in ok})
    for i, (method, mode) in enumerate(keys):
        rs = sorted((r for r in ok if (r["method"], r["mode"]) == (method, mode)),
                    key=lambda r: r["megapixels"])
        x = [r["megapixels"] for r in rs]
        ls = "-" if mode == "variant" else "--"
        best = np.array([r["seconds"] for r in rs])
        worst = np.array([max(r["runs_s"]) for r in rs])
        ax_t.errorbar(x, best, yerr=[np.zeros_like(best), worst - best], fmt="o" + ls,
                      color=f"C{i}", capsize=3,
                      label=f"{method}, {mode} (best; bar: slowest run)")
        ax_m.plot(x, [r["peak_rss_mib"] / 1024 for r in rs], "o" + ls, color=f"C{i}",
                  label=f"{method}, {mode}: peak RSS")
    sizes = sorted({r["megapixels"] for r in ok})
    floor = [min(r["floor_s"] for r in ok if r["megapixels"] == s) for s in sizes]
    ax_t.plot(sizes, floor, "k^:", label="FFT floor (forward + inverse, 3 ch)")
    ax_m.plot(sizes, [s * 1e6 * 12 / 2 ** 30 for s in sizes], "k:",
              label="one float32 RGB image")
    for ax in (ax_t, ax_m):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("image size (megapixels, RGB)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        ax.set_xticks(sizes)
        ax.set_xticklabels([f"{s:.3g}" for s in sizes])
    ax_t.set_ylabel("wall time (s)")
    ax_t.set_title("deblur time vs image size")
    ax_m.set_ylabel("peak memory (GiB)")
    ax_m.set_title("peak resident memory of the process")
    m = result["machine"]
    fig.suptitle(f"gyrodeblur speed on {m['cpu_count']} cores ({m['processor']}), "
                 f"exposure {result['capture']['exposure_time'] * 1e3:.0f} ms, readout "
                 f"{result['capture']['readout_time'] * 1e3:.0f} ms, fx = "
                 f"{result['capture']['focal_fraction']} x width", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
