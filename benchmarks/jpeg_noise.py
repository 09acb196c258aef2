"""JPEG photos: the noise level the deconvolution is regularised for.

JPEG's quantisation removes most of the fine noise that
:func:`gyrodeblur.noise.estimate_noise_sigma` measures, while the error it leaves is
amplified by the deconvolution like noise. So a JPEG is deconvolved for the measured level
raised for its quantisation error (:func:`gyrodeblur.noise.jpeg_noise_sigma`, scale
:data:`gyrodeblur.noise.JPEG_NOISE_SCALE`). This benchmark compares that with the measured
level alone.

Protocol: each sharp photo (longer side ``--max-size``) blurred by the project's forward
model (a window of the shared hand-held gyro log, 15-35 ms exposure, rolling shutter,
warping; 40 dB noise, 8-bit), saved as PNG and as Pillow JPEGs of quality 95, 90 and 80
(4:2:0 chroma), and deblurred with the default method and the true capture, with

* ``measured``: the noise level its pixels show (the default before session 23), and
* ``raised``: :func:`gyrodeblur.noise.photo_noise_sigma` (the default now; a PNG's is
  the measured level).

PSNR is the chapter's (8-bit sRGB, 5 % border). The scale was fitted (session 23) on six of
the shared photos (:data:`FITTED_ON`); the others are reported apart, as held out.

Usage::

    python benchmarks/jpeg_noise.py               # the 12 shared photos, 640 px
    python benchmarks/jpeg_noise.py --quick       # 2 photos, 400 px, quality 90 only

Writes ``benchmarks/results/jpeg_noise.json``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur.dataset import (default_gyro, default_shared_data, find_gaps,  # noqa: E402
                                list_photos, plan_window, read_sharp, render_case)
from gyrodeblur.deblur import deblur  # noqa: E402
from gyrodeblur.gyrolog import read_gyro_log  # noqa: E402
from gyrodeblur.imageio import read_photo  # noqa: E402
from gyrodeblur.metrics import default_border, psnr  # noqa: E402
from gyrodeblur.noise import estimate_noise_sigma, photo_noise_sigma  # noqa: E402

#: The photos the scale was fitted on (session 23's scratch measurement).
FITTED_ON = ("lai_manmade_01", "lai_natural_02", "lai_natural_03", "lai_people_01",
             "lai_saturated_01", "lai_text_01")
QUALITIES = (95, 90, 80)
#: --quick's photos when the folder holds them: one fitted on, one held out.
QUICK_PHOTOS = ("lai_people_01", "lai_saturated_02")


def quick_photos(paths: list[Path]) -> list[Path]:
    """--quick's two photos: :data:`QUICK_PHOTOS` where the folder has them, the first
    others (in name order) for any it lacks; in the folder's order."""
    named = [p for p in paths if p.stem in QUICK_PHOTOS]
    keep = set((named + [p for p in paths if p not in named])[:2])
    return [p for p in paths if p in keep]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="2 photos (two of the shared ones, else the folder's first two), "
                         "400 px, quality 90")
    _common.add_source_options(ap)
    ap.add_argument("--max-size", type=_common.positive_int, default=None,
                    help="longer side, px (default 640; quick 400)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "jpeg_noise.json")
    args = ap.parse_args(argv)
    folder = Path(args.photos) if args.photos else default_shared_data() / "photos"
    paths = list_photos(folder)          # png, jpg, tif; InputError when there are none
    if args.quick:                       # one photo fitted on, one held out
        paths = quick_photos(paths)
    qualities = (90,) if args.quick else QUALITIES
    max_size = args.max_size if args.max_size is not None else (400 if args.quick else 640)
    say = _common.say
    t_start = time.perf_counter()
    log = read_gyro_log(args.gyro or default_gyro())
    gaps = find_gaps(log)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            sharp = read_sharp(path, max_size)
            h, w = sharp.shape[:2]
            cap, meta = plan_window(log, path.stem, 0, w, h, seed=args.seed,
                                    exposure=(0.015, 0.035), gaps=gaps)
            case = render_case(path.stem, sharp, cap, meta, snr_db=40.0)
            border = default_border(sharp.shape)
            ints = np.round(case.blurred * 255).astype(np.uint8)
            files = {"png": Path(tmp, f"{path.stem}.png")}
            Image.fromarray(ints).save(files["png"])
            for q in qualities:
                files[f"q{q}"] = Path(tmp, f"{path.stem}_q{q}.jpg")
                Image.fromarray(ints).save(files[f"q{q}"], quality=q, subsampling=2)
            row = {"photo": path.stem, "fitted_on": path.stem in FITTED_ON,
                   "blur_px": meta["blur_px"], "variants": {}}
            for name, file in files.items():
                photo = read_photo(file)
                measured = estimate_noise_sigma(photo.pixels)
                raised = photo_noise_sigma(photo, measured=measured)
                with _common.quiet():
                    p_meas = psnr(sharp, deblur(photo.pixels, case.capture,
                                                noise_sigma=measured), border)
                    p_rais = p_meas if raised == measured else psnr(
                        sharp, deblur(photo.pixels, case.capture, noise_sigma=raised), border)
                row["variants"][name] = {"sigma_measured": measured, "sigma_raised": raised,
                                         "psnr_measured": p_meas, "psnr_raised": p_rais}
            rows.append(row)
            say(f"{path.stem:18s} " + "  ".join(
                f"{n} {v['psnr_measured']:.2f}->{v['psnr_raised']:.2f}"
                for n, v in row["variants"].items()))
    summary = {}
    for name in ["png"] + [f"q{q}" for q in qualities]:
        for group, keep in (("fitted_on", True), ("held_out", False)):
            gains = [r["variants"][name]["psnr_raised"] - r["variants"][name]["psnr_measured"]
                     for r in rows if r["fitted_on"] == keep]
            if gains:
                summary[f"{name}_{group}"] = {"n": len(gains), "mean_gain_db": float(np.mean(gains)),
                                              "min_gain_db": float(np.min(gains))}
                say(f"{name:4s} {group:9s}: raised - measured {np.mean(gains):+.2f} dB mean "
                    f"(worst {np.min(gains):+.2f}, n={len(gains)})")
    result = {"benchmark": "jpeg_noise", "quick": args.quick, "max_size": max_size,
              "qualities": list(qualities), "rows": rows, "summary": summary,
              "total_seconds": time.perf_counter() - t_start, "machine": _common.machine_info()}
    _common.write_json(args.out, result)
    say(f"wrote {args.out} ({result['total_seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
