"""Benchmark: the default method against Wiener at phi = 0.01 and at its best phi per case.

The best phi per case (from 0.001, 0.003, 0.01, 0.03, chosen by PSNR against the sharp
photo) is an oracle no user has; beating it shows the default's gain is not just tuning.
Runs on a dataset folder written by ``python -m gyrodeblur.dataset DIR`` (the one
``compare_methods.py --dataset DIR`` builds). Prints a per-case table and the means,
writes ``benchmarks/results/wiener_oracle.json``.

    python benchmarks/wiener_oracle.py --dataset benchmarks/results/dataset
    python benchmarks/wiener_oracle.py --quick          # builds 2 small cases
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur.deblur import DEFAULT_METHOD, deblur  # noqa: E402
from gyrodeblur.metrics import default_border, psnr, ssim  # noqa: E402

PHIS = (0.001, 0.003, 0.01, 0.03)


def _cases(args):
    """The cases its ``dataset.json`` lists (:func:`gyrodeblur.dataset.load_dataset`: not
    every sub-folder), or 2 small built ones."""
    from gyrodeblur import dataset
    if args.dataset:
        return _common.load_cases(args.dataset)     # InputError: missing or empty
    return dataset.build_cases(max_photos=2, windows_per_photo=1, max_size=320, seed=0)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", help="folder of cases (python -m gyrodeblur.dataset DIR)")
    ap.add_argument("--quick", action="store_true", help="2 small built cases")
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "wiener_oracle.json")
    args = ap.parse_args(argv)
    machine = _common.machine_info()     # at the start: the load before this run
    if not args.dataset and not args.quick:
        ap.error("give --dataset DIR or --quick")
    rows = []
    for case in _cases(args):
        b = default_border(case.sharp.shape)
        default = deblur(case.blurred, case.capture)
        wiener = {phi: deblur(case.blurred, case.capture, method="wiener", phi=phi) for phi in PHIS}
        p_w = {phi: psnr(case.sharp, out, b) for phi, out in wiener.items()}
        best = max(p_w, key=p_w.get)
        row = {"case": case.name, "default_psnr": psnr(case.sharp, default, b),
               "default_ssim": ssim(case.sharp, default, b), "wiener_psnr": p_w[0.01],
               "wiener_ssim": ssim(case.sharp, wiener[0.01], b),
               "oracle_psnr": p_w[best], "oracle_phi": best}
        rows.append(row)
        print(f"{case.name:24s} default {row['default_psnr']:6.2f}  wiener {row['wiener_psnr']:6.2f}"
              f"  oracle {row['oracle_psnr']:6.2f} (phi {best:g})", flush=True)
    g = np.array([r["default_psnr"] - r["wiener_psnr"] for r in rows])
    summary = {
        "method": DEFAULT_METHOD, "cases": len(rows),
        "mean_psnr": {k: float(np.mean([r[k] for r in rows]))
                      for k in ("default_psnr", "wiener_psnr", "oracle_psnr")},
        "mean_ssim": {k: float(np.mean([r[k] for r in rows])) for k in ("default_ssim", "wiener_ssim")},
        "gain_over_wiener_db": {"mean": float(g.mean()), "min": float(g.min())},
        "gain_over_oracle_db": float(np.mean([r["default_psnr"] - r["oracle_psnr"] for r in rows])),
        "saturated_gain_db": [float(r["default_psnr"] - r["wiener_psnr"]) for r in rows
                              if "saturated" in r["case"]],
    }
    print(f"mean PSNR: {DEFAULT_METHOD} {summary['mean_psnr']['default_psnr']:.2f}, wiener(0.01) "
          f"{summary['mean_psnr']['wiener_psnr']:.2f}, wiener(best phi) "
          f"{summary['mean_psnr']['oracle_psnr']:.2f} dB; gain {g.mean():+.2f} dB (min {g.min():+.2f}); "
          f"SSIM {summary['mean_ssim']['default_ssim']:.3f} vs {summary['mean_ssim']['wiener_ssim']:.3f}")
    _common.write_json(args.out, {"summary": summary, "per_case": rows, "machine": machine})
    return summary


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
