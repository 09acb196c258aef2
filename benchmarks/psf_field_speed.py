"""Benchmark: time to render a 6 x 8 PSF field for a 12 MP capture (issue target < 0.5 s).

Prints the figures and writes ``benchmarks/results/psf_field_speed.json``. Not a test:
run ``python benchmarks/psf_field_speed.py`` (``--quick`` for a 1 MP capture).

The capture: 4000 x 3000 px, f = 0.8 x width, 30 ms exposure, 30 ms readout, a generated
hand-shake trace (gyrodeblur.shake, seed 1) at 200 Hz. The field is rendered at the patch
centres of the 6 x 8 grid with 25 % overlap, as `gyrodeblur deblur --method wiener` does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.deblur import plan_psf_field
from gyrodeblur.shake import synthetic_hand_shake


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 MP capture, 2 repeats")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results",
                                                  "psf_field_speed.json"))
    args = ap.parse_args(argv)
    W, H = (1152, 864) if args.quick else (4000, 3000)
    repeats = 2 if args.quick else args.repeats
    base = synthetic_hand_shake(1.0, 200.0, seed=1)
    res = {"size": [W, H], "grid": [6, 8], "target_seconds": 0.5, "repeats": repeats,
           "machine": f"{platform.machine()}, {os.cpu_count()} cores",
           "load_average": os.getloadavg()[0], "cases": {}}
    for label, gain in (("typical shake", 1.0), ("strong shake (rates x5)", 5.0)):
        log = base.rotated(gain * np.eye(3))
        cap = Capture(0.4, 0.03, 0.03, Camera.centred(W, H, 0.8 * W), log)
        times = []
        for _ in range(repeats):
            fresh = cap.replace()             # a new capture: orientation integrated again
            t0 = time.perf_counter()
            _, field, _ = plan_psf_field(fresh, (H, W), grid=(6, 8), max_fraction=np.inf)
            times.append(time.perf_counter() - t0)
        case = {"seconds_best": min(times), "seconds_median": float(np.median(times)),
                "psf_extent_px": [int(field.extents.min()), int(field.extents.max())]}
        res["cases"][label] = case
        print(f"6x8 PSF field, {W}x{H}, {label}: best {case['seconds_best']:.3f} s, median "
              f"{case['seconds_median']:.3f} s over {repeats} (target 0.5 s); PSF extent "
              f"{case['psf_extent_px'][0]}-{case['psf_extent_px'][1]} px")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w", encoding="utf-8") as fh:
        json.dump(res, fh, indent=2)
    print(f"(load average {res['load_average']:.1f} on {res['machine']}); wrote {args.out}")
    return res


if __name__ == "__main__":
    import _common                      # the script's folder is on sys.path

    raise SystemExit(_common.run_main(main))
