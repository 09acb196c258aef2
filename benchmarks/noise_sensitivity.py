"""How gyro errors degrade deblurring: the chapter's Fig. 6.11, and calibration errors.

Protocol (chapter sec. 6.6): one sharp photo is blurred with real gyro samples (a window
of the shared hand-held phone log, blur synthesised by warping in linear light, rolling
shutter included) and 40 dB image noise, then 8-bit quantised. It is then deblurred with
PSFs computed from the *same* gyro samples corrupted by

* **gyro noise** (Fig. 6.11): white Gaussian noise of std 0 .. 0.1 rad/s added to every
  sample and axis, ``N`` realisations per level (default 50); 0.007 rad/s, the chapter's
  typical phone gyro noise, is one of the levels;
* **gyro bias**: a constant rate error of norm 0 .. 0.05 rad/s in a random direction
  (camera frame), ``--bias-realisations`` directions per level;
* **time offset** between the gyro and camera clocks, 0 .. 30 ms, both signs;
* **readout-time error**, 0 .. 20 ms, both signs (true readout 30 ms);
* **focal-length error**, 0 .. 10 %, both signs.

Each corruption is applied to the Capture (``capture.replace(log=..., bias=...,
time_offset=..., readout_time=..., camera=...)``) and the photo is deblurred with
:func:`gyrodeblur.deblur.deblur` (``--method``, ``--mode``). PSNR is the chapter's,
on 8-bit sRGB values, on the central region without a border of 5 % of the smaller side.
The JSON also holds, per run, the PSNR after the best global sub-pixel shift (phase
correlation): calibration errors also move the whole result (it is no longer referenced
to the true exposure-start orientation), which PSNR punishes but a viewer does not see.

Usage::

    python benchmarks/noise_sensitivity.py              # full: ~15-25 min on 2 cores
    python benchmarks/noise_sensitivity.py --quick      # 256 px photo, 2 levels x 2

Writes ``benchmarks/results/noise_sensitivity.{json,png}`` (and, for a full run,
``benchmarks/figures/noise_sensitivity.png``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur import deblur as deblur_mod  # noqa: E402
from gyrodeblur.dataset import (default_gyro, find_gaps, plan_window,  # noqa: E402
                                read_sharp, render_case)
from gyrodeblur.gyrolog import GyroLog, read_gyro_log  # noqa: E402
from gyrodeblur.metrics import default_border, psnr, ssim  # noqa: E402

TYPICAL_NOISE = 0.007  # rad/s, the chapter's Samsung Galaxy S II
GYRO_LEVELS = [0.0, 0.0025, 0.005, 0.007, 0.01, 0.015, 0.02, 0.03, 0.05, 0.07, 0.1]
BIAS_LEVELS = [0.0, 0.005, 0.01, 0.02, 0.03, 0.05]               # rad/s (norm)
OFFSET_LEVELS_MS = [0.0, 2.0, 5.0, 10.0, 20.0, 30.0]
READOUT_LEVELS_MS = [0.0, 2.0, 5.0, 10.0, 15.0, 20.0]
FOCAL_LEVELS_PCT = [0.0, 1.0, 2.0, 5.0, 10.0]
QUICK = {"gyro": [0.0, TYPICAL_NOISE], "bias": [0.0, 0.05], "offset": [0.0, 30.0],
         "readout": [0.0, 10.0], "focal": [0.0, 10.0]}
DEFAULT_PHOTO = "lai_manmade_01.png"


def _summary(values: list[float]) -> dict:
    a = np.asarray(values, float)
    return {"mean": float(a.mean()), "std": float(a.std()), "min": float(a.min()),
            "max": float(a.max()), "n": int(a.size), "values": a.tolist()}


def pick_case(args):
    """Photo x the window (of the first ``--windows-considered``) whose centre blur is the
    median one, so the experiment sees typical shake rather than a still moment."""
    path = _common.pick_photo(args.photo, args.photos, DEFAULT_PHOTO)
    log = read_gyro_log(args.gyro or default_gyro())
    sharp = read_sharp(path, args.max_size)
    h, w = sharp.shape[:2]
    gaps = find_gaps(log)
    plans = [plan_window(log, path.stem, k, w, h, seed=args.seed, exposure=args.exposure,
                         readout=args.readout, focal=args.focal, gaps=gaps)
             for k in range(args.windows_considered)]
    blur = np.array([m["blur_px"] for _, m in plans])
    k = int(np.argsort(blur)[len(blur) // 2])
    cap, meta = plans[k]
    meta["photo"] = path.name
    meta["windows_considered_blur_px"] = blur.tolist()
    return render_case(f"{path.stem}_w{k}", sharp, cap, meta, snr_db=args.snr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="256 px photo, 2 levels x 2 realisations per panel")
    ap.add_argument("--realisations", type=_common.positive_int, default=None,
                    help="gyro-noise realisations per level (default 50; quick 2)")
    ap.add_argument("--bias-realisations", type=_common.positive_int, default=None,
                    help="random bias directions per level (default 10; quick 1)")
    ap.add_argument("--method", default=None,
                    help=f"deconvolution method (default: the project's, now "
                         f"{deblur_mod.DEFAULT_METHOD!r})")
    ap.add_argument("--mode", default="variant", choices=("variant", "invariant"))
    ap.add_argument("--photo", default=None,
                    help=f"photo file, or name (or name stem) in --photos (default "
                         f"{DEFAULT_PHOTO} when the folder has it, else its first photo)")
    _common.add_source_options(ap)
    ap.add_argument("--exposure", type=float, default=0.03, help="exposure time, s")
    ap.add_argument("--readout", type=float, default=0.03, help="readout time, s")
    ap.add_argument("--focal", type=float, default=0.8, help="fx as a fraction of the width")
    ap.add_argument("--snr", type=float, default=40.0, help="image SNR, dB")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--windows-considered", type=_common.positive_int, default=None,
                    help="windows whose median blur is taken (default 7; quick 3)")
    ap.add_argument("--max-size", type=_common.positive_int, default=None,
                    help="downscale the photo (longer side, px); quick: 256")
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "noise_sensitivity.json")
    ap.add_argument("--figure", type=Path, default=None,
                    help="also save the plot here (full run default: "
                         "benchmarks/figures/noise_sensitivity.png)")
    args = ap.parse_args(argv)
    if args.quick and args.max_size is None:        # --quick changes only the defaults
        args.max_size = 256
    if args.windows_considered is None:
        args.windows_considered = 3 if args.quick else 7
    n_noise = args.realisations or (2 if args.quick else 50)
    n_bias = args.bias_realisations or (1 if args.quick else 10)
    levels = QUICK if args.quick else {"gyro": GYRO_LEVELS, "bias": BIAS_LEVELS,
                                       "offset": OFFSET_LEVELS_MS, "readout": READOUT_LEVELS_MS,
                                       "focal": FOCAL_LEVELS_PCT}
    method = args.method or deblur_mod.DEFAULT_METHOD
    t_start = time.perf_counter()
    machine = _common.machine_info()

    case = pick_case(args)
    cap, sharp, blurred = case.capture, case.sharp, case.blurred
    border = default_border(sharp.shape)
    _common.say(f"case {case.name}: {sharp.shape[1]}x{sharp.shape[0]}, exposure "
                f"{cap.exposure_time * 1e3:.1f} ms, readout {cap.readout_time * 1e3:.0f} ms, "
                f"blur {case.meta['blur_px']} px, roll {case.meta['roll_deg']:.2f} deg; "
                f"method {method}, mode {args.mode}; border {border} px")
    timings = []

    registered: dict[int, float] = {}
    last: list[np.ndarray] = []

    def score(capture) -> float:
        """PSNR as the chapter defines it; the PSNR after the best global (sub-pixel)
        shift is kept aside in ``registered`` under the same run index."""
        t0 = time.perf_counter()
        with _common.quiet():
            out = deblur_mod.deblur(blurred, capture, mode=args.mode, method=method)
        timings.append(time.perf_counter() - t0)
        registered[len(timings)] = _common.registered_psnr(sharp, out, border)
        last[:] = [out]
        return psnr(sharp, out, border)

    exact_psnr = score(cap)
    exact_reg = registered[1]
    exact = last[0]
    blurred_psnr = psnr(sharp, blurred, border)
    panels: dict[str, dict] = {}

    # Fig. 6.11: white gyro noise.
    log = cap.log
    rows = []
    for li, level in enumerate(levels["gyro"]):
        vals, regs = [], []
        for r in range(n_noise if level > 0 else 1):
            rng = np.random.default_rng([args.seed, 611, li, r])
            noisy = GyroLog(log.t, log.omega + rng.normal(0.0, level, log.omega.shape),
                            log.source)
            vals.append(exact_psnr if level == 0 else score(cap.replace(log=noisy)))
            regs.append(exact_reg if level == 0 else registered[len(timings)])
        rows.append({**_summary(vals), "registered": _summary(regs)})
        _common.say(f"  gyro noise {level:.4f} rad/s: PSNR {rows[-1]['mean']:.2f} "
                    f"+- {rows[-1]['std']:.2f} dB (n={rows[-1]['n']})")
    panels["gyro_noise"] = {"unit": "rad/s", "levels": levels["gyro"], "psnr": rows,
                            "what": "std of white Gaussian noise added to every gyro sample "
                                    "and axis", "realisations": n_noise}

    # Gyro bias: constant error of a given norm in random directions (camera frame).
    rows = []
    for li, level in enumerate(levels["bias"]):
        vals, regs = [], []
        for r in range(n_bias if level > 0 else 1):
            d = np.random.default_rng([args.seed, 612, li, r]).normal(size=3)
            d /= np.linalg.norm(d)
            vals.append(exact_psnr if level == 0 else score(cap.replace(bias=level * d)))
            regs.append(exact_reg if level == 0 else registered[len(timings)])
        rows.append({**_summary(vals), "registered": _summary(regs)})
        _common.say(f"  bias {level:.3f} rad/s: PSNR {rows[-1]['mean']:.2f} dB")
    panels["bias"] = {"unit": "rad/s", "levels": levels["bias"], "psnr": rows,
                      "what": "norm of a constant gyro bias, random direction",
                      "realisations": n_bias}

    # Deterministic calibration errors, both signs.
    def signed(name, unit, lvls, make, what):
        out = {"+": [], "-": [], "+reg": [], "-reg": []}
        for level in lvls:
            for sign in ("+", "-"):
                if level == 0:
                    v, vr = exact_psnr, exact_reg
                else:
                    v = score(make(level if sign == "+" else -level))
                    vr = registered[len(timings)]
                out[sign].append(v)
                out[sign + "reg"].append(vr)
            _common.say(f"  {name} +-{level:g} {unit}: PSNR {out['+'][-1]:.2f} / "
                        f"{out['-'][-1]:.2f} dB")
        panels[name] = {"unit": unit, "levels": lvls, "psnr_plus": out["+"],
                        "psnr_minus": out["-"], "registered_psnr_plus": out["+reg"],
                        "registered_psnr_minus": out["-reg"], "what": what}

    signed("time_offset", "ms", levels["offset"],
           lambda e: cap.replace(time_offset=cap.time_offset + e * 1e-3),
           "error in the gyro-to-camera clock offset")
    signed("readout", "ms", levels["readout"],
           lambda e: cap.replace(readout_time=max(0.0, cap.readout_time + e * 1e-3)),
           f"error in the readout time (true {cap.readout_time * 1e3:.0f} ms)")
    signed("focal", "%", levels["focal"],
           lambda e: cap.replace(camera=cap.camera.with_focal_scale(1 + e / 100)),
           f"relative error in the focal length (true {cap.camera.fx:.1f} px)")

    g = panels["gyro_noise"]
    i_typ = g["levels"].index(TYPICAL_NOISE)
    drop = exact_psnr - g["psnr"][i_typ]["mean"]
    result = {
        "benchmark": "noise_sensitivity",
        "quick": args.quick,
        "case": {"name": case.name, **case.meta},
        "method": method,
        "mode": args.mode,
        "border_px": border,
        "border_rule": "5% of the smaller image side (metrics.default_border)",
        "psnr_blurred": blurred_psnr,
        "ssim_blurred": ssim(sharp, blurred, border),
        "psnr_exact_gyro": exact_psnr,
        "registered_psnr_exact_gyro": exact_reg,
        "registered_psnr_note": "PSNR after the best global sub-pixel shift "
                                "(phase correlation): what is left when a misalignment of "
                                "the result, harmless to a viewer, is forgiven",
        "ssim_exact_gyro": ssim(sharp, exact, border),
        "typical_gyro_noise": TYPICAL_NOISE,
        "psnr_drop_at_typical_noise_db": drop,
        "panels": panels,
        "deblur_seconds_mean": float(np.mean(timings)) if timings else None,
        "runs": len(timings),
        "total_seconds": time.perf_counter() - t_start,
        "machine": machine,
    }
    _common.write_json(args.out, result)
    png = args.out.with_suffix(".png")
    plot(result, png)
    figure = args.figure or (None if args.quick else _common.FIGURES / "noise_sensitivity.png")
    if figure is not None and Path(figure).resolve() == png.resolve():
        figure = None                    # the report's own figure, asked for by name
    if figure is not None:
        plot(result, Path(figure), dpi=80)
    _common.say(f"blurred {blurred_psnr:.2f} dB, exact gyro {exact_psnr:.2f} dB; "
                f"PSNR drop at {TYPICAL_NOISE} rad/s gyro noise: {drop:.2f} dB "
                f"(mean of {g['psnr'][i_typ]['n']})")
    _common.say(f"wrote {args.out} and {png}" + (f" and {figure}" if figure else ""))
    return 0


def plot(result: dict, path: Path, dpi: int = 110) -> None:
    plt = _common.matplotlib_pyplot()
    p = result["panels"]
    c = result["case"]
    fig = plt.figure(figsize=(13, 8.2), constrained_layout=True)
    gs = fig.add_gridspec(2, 3)
    exact = result["psnr_exact_gyro"]

    def ref_lines(ax):
        ax.axhline(exact, color="0.5", lw=0.8, ls=":", label=f"exact gyro ({exact:.2f} dB)")
        ax.set_ylabel("PSNR (dB)")
        ax.grid(alpha=0.3)

    ax = fig.add_subplot(gs[0, 0:2])
    g = p["gyro_noise"]
    x = np.asarray(g["levels"])
    m = np.array([r["mean"] for r in g["psnr"]])
    s = np.array([r["std"] for r in g["psnr"]])
    lo = np.array([r["min"] for r in g["psnr"]])
    hi = np.array([r["max"] for r in g["psnr"]])
    ax.fill_between(x, lo, hi, color="C0", alpha=0.12, label="min - max")
    ax.fill_between(x, m - s, m + s, color="C0", alpha=0.3, label="mean +- 1 std")
    ax.plot(x, m, "o-", color="C0", label=f"mean of {g['realisations']} realisations")
    ax.plot(x, [r["registered"]["mean"] for r in g["psnr"]], "o:", color="C0", alpha=0.6,
            mfc="none", label="mean after global alignment")
    ax.axvline(result["typical_gyro_noise"], color="C3", ls="--",
               label=f"typical phone gyro noise {result['typical_gyro_noise']} rad/s "
                     f"(drop {result['psnr_drop_at_typical_noise_db']:.2f} dB)")
    ref_lines(ax)
    ax.set_xlabel("gyro noise std (rad/s)")
    ax.set_title("(a) white gyro noise (chapter Fig. 6.11)")
    ax.legend(fontsize=8, loc="upper right")

    ax = fig.add_subplot(gs[0, 2])
    b = p["bias"]
    x = np.asarray(b["levels"])
    m = np.array([r["mean"] for r in b["psnr"]])
    lo = np.array([r["min"] for r in b["psnr"]])
    hi = np.array([r["max"] for r in b["psnr"]])
    ax.fill_between(x, lo, hi, color="C1", alpha=0.25, label="min - max over directions")
    ax.plot(x, m, "o-", color="C1", label=f"mean of {b['realisations']} directions")
    ax.plot(x, [r["registered"]["mean"] for r in b["psnr"]], "o:", color="C1", alpha=0.6,
            mfc="none", label="mean after global alignment")
    ref_lines(ax)
    ax.set_xlabel("gyro bias norm (rad/s)")
    ax.set_title("(b) gyro bias")
    ax.legend(fontsize=8)

    for k, (name, label, title) in enumerate([
            ("time_offset", "gyro-camera time offset error (ms)", "(c) time offset"),
            ("readout", "readout-time error (ms)", "(d) readout time"),
            ("focal", "focal-length error (%)", "(e) focal length")]):
        ax = fig.add_subplot(gs[1, k])
        d = p[name]
        ax.plot(d["levels"], d["psnr_plus"], "o-", color="C2", label="error > 0")
        ax.plot(d["levels"], d["psnr_minus"], "s-", color="C4", label="error < 0")
        ax.plot(d["levels"], d["registered_psnr_plus"], "o:", color="C2", alpha=0.6,
                mfc="none", label="error > 0, after global alignment")
        ax.plot(d["levels"], d["registered_psnr_minus"], "s:", color="C4", alpha=0.6,
                mfc="none", label="error < 0, after global alignment")
        ref_lines(ax)
        ax.set_xlabel(label)
        ax.set_title(title)
        ax.legend(fontsize=8)

    fig.suptitle(
        f"Deblurring PSNR vs gyro and calibration errors\n{c['photo']} "
        f"{c['width']}x{c['height']}, exposure {c['exposure_time'] * 1e3:.0f} ms, readout "
        f"{c['readout_time'] * 1e3:.0f} ms, blur {c['blur_px']} px, {c['snr_db']:g} dB noise; "
        f"{result['method']} {result['mode']}; blurred input {result['psnr_blurred']:.2f} dB",
        fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
