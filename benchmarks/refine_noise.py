"""Gyro noise with and without self-calibration (``deblur --refine``): a small version of
the chapter's Fig. 6.11.

Protocol: one sharp photo blurred by a real hand-shake gyro window (the shared hand-held
phone log, rolling shutter, 40 dB noise, 8-bit; the window with the median blur of the
first ``--windows-considered``), as in ``benchmarks/noise_sensitivity.py``. The capture's
gyro samples are then corrupted by white Gaussian noise (std per sample and axis, rad/s)
and the photo deblurred (the project's default method, space-variant)

* with the noisy capture as it is, and
* after ``calibrate([photo], noisy capture)`` (what ``gyrodeblur deblur --refine`` does:
  time offset, bias, readout, focal scale and axis mapping all free).

PSNR is the chapter's (8-bit sRGB, 5 % border). The target of issue 6: with refinement,
the PSNR at 0.02 rad/s within 1 dB of the noiseless result (exact capture, no refinement).

Usage::

    python benchmarks/refine_noise.py            # 4 levels x 3 realisations, 640 px
    python benchmarks/refine_noise.py --quick    # levels 0 and 0.02, 1 realisation, 400 px

Writes ``benchmarks/results/refine_noise.json`` (and ``.png``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur.calibrate import calibrate  # noqa: E402
from gyrodeblur.dataset import (default_gyro, find_gaps, plan_window,  # noqa: E402
                                read_sharp, render_case)
from gyrodeblur.deblur import deblur  # noqa: E402
from gyrodeblur.gyrolog import GyroLog, read_gyro_log  # noqa: E402
from gyrodeblur.metrics import default_border, psnr  # noqa: E402

LEVELS = [0.0, 0.007, 0.02, 0.05]
TARGET_LEVEL = 0.02
TARGET_DB = 1.0
DEFAULT_PHOTO = "lai_manmade_01.png"


def pick_case(photo: str | None, max_size: int, windows: int, seed: int, *, photos=None,
              gyro=None):
    path = _common.pick_photo(photo, photos, DEFAULT_PHOTO)
    log = read_gyro_log(gyro or default_gyro())
    sharp = read_sharp(path, max_size)
    h, w = sharp.shape[:2]
    gaps = find_gaps(log)
    plans = [plan_window(log, path.stem, k, w, h, seed=seed, exposure=0.03, readout=0.03,
                         focal=0.8, gaps=gaps) for k in range(windows)]
    blur = np.array([m["blur_px"] for _, m in plans])
    k = int(np.argsort(blur)[len(blur) // 2])
    cap, meta = plans[k]
    meta["photo"] = path.name
    return render_case(f"{path.stem}_w{k}", sharp, cap, meta, snr_db=40.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="levels 0 and 0.02, 1 realisation, 400 px")
    ap.add_argument("--photo", default=None,
                    help=f"photo file, or name (or name stem) in --photos (default "
                         f"{DEFAULT_PHOTO} when the folder has it, else its first photo)")
    _common.add_source_options(ap)
    ap.add_argument("--max-size", type=_common.positive_int, default=None,
                    help="longer side, px (default 640; quick 400)")
    ap.add_argument("--realisations", type=_common.positive_int, default=None,
                    help="per level (default 3; quick 1)")
    ap.add_argument("--windows-considered", type=_common.positive_int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "refine_noise.json")
    args = ap.parse_args(argv)
    levels = [0.0, TARGET_LEVEL] if args.quick else LEVELS
    n_real = args.realisations or (1 if args.quick else 3)
    max_size = args.max_size if args.max_size is not None else (400 if args.quick else 640)
    say = _common.say
    t_start = time.perf_counter()
    case = pick_case(args.photo, max_size, args.windows_considered, args.seed,
                     photos=args.photos, gyro=args.gyro)
    cap, sharp, blurred = case.capture, case.sharp, case.blurred
    border = default_border(sharp.shape)
    with _common.quiet():
        exact = psnr(sharp, deblur(blurred, cap), border)
    say(f"case {case.name}: {sharp.shape[1]}x{sharp.shape[0]}, blur {case.meta['blur_px']} px; "
        f"exact gyro {exact:.2f} dB, blurred {psnr(sharp, blurred, border):.2f} dB")
    rows = []
    for li, level in enumerate(levels):
        plain, refined, secs = [], [], []
        for r in range(n_real):
            rng = np.random.default_rng([args.seed, 6110, li, r])
            noisy = cap if level == 0 else cap.replace(log=GyroLog(
                cap.log.t, cap.log.omega + rng.normal(0.0, level, cap.log.omega.shape),
                cap.log.source))
            t0 = time.perf_counter()
            cal = calibrate([blurred], noisy).capture
            secs.append(time.perf_counter() - t0)
            with _common.quiet():
                plain.append(psnr(sharp, deblur(blurred, noisy), border))
                refined.append(psnr(sharp, deblur(blurred, cal), border))
        row = {"level": level, "psnr_plain": plain, "psnr_refined": refined,
               "plain_mean": float(np.mean(plain)), "refined_mean": float(np.mean(refined)),
               "calibrate_seconds": secs}
        rows.append(row)
        say(f"  gyro noise {level:.3f} rad/s: PSNR {row['plain_mean']:.2f} dB without, "
            f"{row['refined_mean']:.2f} dB with refinement (worst {min(refined):.2f}; "
            f"n={n_real}, calibrate {np.mean(secs):.1f} s)")
    at = next(r for r in rows if r["level"] == TARGET_LEVEL)
    gap = at["refined_mean"] - exact
    ok = gap >= -TARGET_DB
    say(f"with refinement at {TARGET_LEVEL} rad/s: {at['refined_mean']:.2f} dB vs noiseless "
        f"{exact:.2f} dB ({gap:+.2f} dB; target within {TARGET_DB} dB: "
        f"{'met' if ok else 'NOT met'})")
    result = {"benchmark": "refine_noise", "quick": args.quick, "case": {"name": case.name,
              **case.meta}, "psnr_exact": exact, "levels": rows, "target_level": TARGET_LEVEL,
              "gap_at_target_db": gap, "target_met": bool(ok),
              "total_seconds": time.perf_counter() - t_start, "machine": _common.machine_info()}
    _common.write_json(args.out, result)
    try:
        plot(result, args.out.with_suffix(".png"))
    except Exception as exc:                       # a plot is a convenience
        say(f"(no plot: {exc})")
    say(f"wrote {args.out}")
    return 0


def plot(result: dict, path: Path) -> None:
    plt = _common.matplotlib_pyplot()
    x = [r["level"] for r in result["levels"]]
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ax.plot(x, [r["plain_mean"] for r in result["levels"]], "o-", label="noisy gyro")
    ax.plot(x, [r["refined_mean"] for r in result["levels"]], "s-", label="noisy gyro + refine")
    ax.axhline(result["psnr_exact"], color="0.5", ls=":", label="exact gyro")
    ax.axhline(result["psnr_exact"] - TARGET_DB, color="C3", ls="--", lw=0.8,
               label=f"target (-{TARGET_DB} dB)")
    ax.set_xlabel("gyro noise std (rad/s)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"{result['case']['name']}: gyro noise with and without --refine")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
