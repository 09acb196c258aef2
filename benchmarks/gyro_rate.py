"""How the gyro log's sample rate changes the deblurred result.

Many logging apps record the gyro at 50-100 Hz, where a phone's own log may run at 200 Hz
or more, and a hand's shake has power up to 20-30 Hz: what the PSFs make of the motion
between samples then matters. Protocol: the benchmark cases (each sharp photo blurred by a
window of the shared 210 Hz hand-held phone log, rolling shutter, 40 dB noise, 8-bit; the
motion between samples as :class:`gyrodeblur.orientation.Orientation` interpolates it) are
deblurred (the project's default method, space-variant) with the case's log

* as it is (210 Hz),
* with every 2nd / 4th sample (105 / 52.5 Hz: a sensor read at a lower rate), and
* with the mean of every 2 / 4 samples, time-stamped at their centre (a sensor that
  averages over its sample period).

Reported per rate: mean PSNR and its loss against the full log (chapter's PSNR, 8-bit
sRGB, 5 % border). Decimation aliases what the shake holds above the new Nyquist rate
(26 Hz at 52.5 Hz): part of the loss belongs to the data, not to the interpolation.

Usage::

    python benchmarks/gyro_rate.py            # 12 cases, 640 px, factors 2 and 4 (2 min)
    python benchmarks/gyro_rate.py --quick    # 3 cases, 320 px

Writes ``benchmarks/results/gyro_rate.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur.deblur import deblur  # noqa: E402
from gyrodeblur.gyrolog import GyroLog  # noqa: E402
from gyrodeblur.metrics import default_border, psnr  # noqa: E402

FACTORS = (2, 4)


def decimated(log: GyroLog, factor: int, how: str) -> GyroLog:
    """``log`` at ``1 / factor`` of its rate: every ``factor``-th sample (``"pick"``), or
    the mean of each run of ``factor`` samples at their mean time (``"mean"``)."""
    if how == "pick":
        return GyroLog(log.t[::factor], log.omega[::factor], log.source)
    n = (log.t.size // factor) * factor
    t = log.t[:n].reshape(-1, factor).mean(axis=1)
    w = log.omega[:n].reshape(-1, factor, 3).mean(axis=1)
    return GyroLog(t, w, log.source)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 cases, 320 px")
    _common.add_source_options(ap)
    ap.add_argument("--max-size", type=_common.positive_int, default=None,
                    help="longer side, px (default 640; quick 320)")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "gyro_rate.json")
    args = ap.parse_args(argv)
    max_size = args.max_size or (320 if args.quick else 640)
    say = _common.say
    t_start = time.perf_counter()
    cases = _common.get_cases(photos=args.photos, gyro=args.gyro, windows_per_photo=1,
                              max_size=max_size, seed=args.seed,
                              max_photos=3 if args.quick else None)
    variants = [("full", 1, "pick")] + [(f"{how} {f}", f, how) for how in ("pick", "mean")
                                        for f in FACTORS]
    rows = []
    for case in cases:
        cap = case.capture
        border = default_border(case.sharp.shape)
        row = {"case": case.name, "blur_px": case.meta.get("blur_px"),
               "rate_hz": (cap.log.t.size - 1) / (cap.log.t[-1] - cap.log.t[0]), "psnr": {}}
        for name, factor, how in variants:
            c = cap if factor == 1 else cap.replace(log=decimated(cap.log, factor, how))
            with _common.quiet():
                row["psnr"][name] = psnr(case.sharp, deblur(case.blurred, c), border)
        rows.append(row)
        say(f"  {case.name:22s} {row['blur_px']:>4} px  " + "  ".join(
            f"{n} {v:5.2f}" for n, v in row["psnr"].items()))
    rate = float(np.median([r["rate_hz"] for r in rows]))       # Hz, the full logs'
    summary = {}
    for name, factor, how in variants:
        vals = np.array([r["psnr"][name] for r in rows])
        loss = vals - np.array([r["psnr"]["full"] for r in rows])
        summary[name] = {"rate_hz": rate / factor, "mean_psnr": float(vals.mean()),
                         "mean_loss_db": float(loss.mean()), "worst_loss_db": float(loss.min())}
        say(f"{name:8s} ({rate / factor:5.1f} Hz): {vals.mean():.2f} dB, "
            f"{loss.mean():+.2f} dB against the full log (worst {loss.min():+.2f})")
    result = {"benchmark": "gyro_rate", "quick": args.quick, "max_size": max_size,
              "seed": args.seed, "cases": rows, "summary": summary,
              "total_seconds": time.perf_counter() - t_start,
              "machine": _common.machine_info()}
    _common.write_json(args.out, result)
    say(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
