"""Blind deconvolution on the textbook protocol: Levin et al.'s eight real shake kernels.

The calibration and comparison benchmarks judge the blind baseline on space-variant gyro
blur, where one kernel cannot fit a whole photo. This one asks how good the kernel
estimator itself is, on the problem it models: a space-invariant blur (Levin, Weiss,
Durand & Freeman, CVPR 2009, "Understanding and evaluating blind deconvolution
algorithms").

Protocol: sharp photos from the shared data (grey, Rec. 709 luma of the sRGB values,
shrunk so the longer side is ``--max-size``, central ``--crop`` px square or the shorter
side's) x the eight
kernels of ``kernels/levin2009.npz`` (each re-centred on its centre of mass). Each photo is
blurred by convolution over its ``valid`` region (no artificial border: the scene goes on
beyond the frame), Gaussian noise of ``--noise`` (std, on [0, 1]) added and rounded to 8-bit
levels. Pixel values are treated as linear, as in Levin's data. Then

* ``blind``: :func:`gyrodeblur.blind.estimate_kernel` with a support of the kernel's side
  plus ``--margin`` (the protocol's known size bound), then the project's default non-blind
  method (:func:`gyrodeblur.deblur.deblur_with_psfs`, one patch) with that kernel;
* ``oracle``: the same non-blind method with the true kernel.

Each estimate is also put to ``deblur_blind``'s check against no blur
(:func:`gyrodeblur.blur_evidence.kernel_gain_over_no_blur`, then
:func:`~gyrodeblur.blur_evidence.kernel_sparsity_ratio`), and so is the true kernel: the
report counts the kernels kept and how the blind result fared in each group (a dropped
estimate leaves the photo as it is).

Scores, on the central region (a border of the largest kernel's radius + 4 px): PSNR of
the blurred input, of ``blind`` and of ``oracle``, each after the global sub-pixel shift that
best aligns it (a blind kernel is known only up to a shift); Levin's error ratio
``SSD(blind) / SSD(oracle)`` (from the registered PSNRs; Levin et al. count a ratio up to 2-3 as
visually good); the kernel's similarity to the truth (the largest normalised
cross-correlation over shifts); and the time of the kernel estimate.

Usage::

    python benchmarks/blind_levin.py              # 4 photos x 8 kernels
    python benchmarks/blind_levin.py --quick      # 1 photo x 8 kernels, smaller crop

Writes ``benchmarks/results/blind_levin.json`` (or ``--out``), ``.md`` and ``.png`` beside
it (the cumulative distribution of error ratios, Levin et al.'s figure).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur.blind import estimate_kernel  # noqa: E402
from gyrodeblur.blur_evidence import (NO_BLUR_MARGIN, SPARSER_MAX,  # noqa: E402
                                      kernel_gain_over_no_blur, kernel_sparsity_ratio)
from gyrodeblur.dataset import default_shared_data, list_photos, read_sharp  # noqa: E402
from gyrodeblur.deblur import deblur_with_psfs  # noqa: E402
from gyrodeblur.errors import InputError  # noqa: E402
from gyrodeblur.metrics import psnr  # noqa: E402
from gyrodeblur.simulate import quantize_8bit  # noqa: E402
from gyrodeblur.tiling import patch_grid  # noqa: E402

_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
#: Error ratios up to this count as a success in the summary (Levin et al.'s figures mark 2
#: and 3; the lower of the two).
SUCCESS_RATIO = 2.0


def levin_kernels(path: Path) -> dict[str, np.ndarray]:
    """The kernels of ``levin2009.npz``, each shifted by whole pixels so its centre of mass
    is (to half a pixel) its centre sample; float32, summing to 1, odd-sized."""
    with np.load(path) as npz:
        return {name: centred(npz[name]) for name in sorted(npz.files)}


def centred(k: np.ndarray) -> np.ndarray:
    """``k`` in the smallest odd square whose centre sample is its rounded centre of mass."""
    k = np.asarray(k, np.float64)
    k = k / k.sum()
    yy, xx = np.indices(k.shape)
    cy, cx = float((yy * k).sum()), float((xx * k).sum())
    ny, nx = np.nonzero(k > 0)
    r = int(np.ceil(max(np.abs(ny - round(cy)).max(), np.abs(nx - round(cx)).max())))
    out = np.zeros((2 * r + 1, 2 * r + 1))
    out[ny - round(cy) + r, nx - round(cx) + r] = k[ny, nx]
    return out.astype(np.float32)


def grey_crop(path: Path, crop: int, pad: int, max_size: int) -> np.ndarray:
    """The photo's luma (float32, [0, 1]), central ``crop + 2 pad`` px square (less where
    the photo's shorter side is shorter)."""
    img = read_sharp(path, max_size=max_size)
    g = img @ _LUMA if img.ndim == 3 else img
    h, w = g.shape
    side = min(crop + 2 * pad, h, w)
    if side < 64 + 2 * pad:
        raise InputError(str(path), f"{w}x{h} px is too small for a 64 px crop")
    y0, x0 = (h - side) // 2, (w - side) // 2
    return np.ascontiguousarray(g[y0:y0 + side, x0:x0 + side], np.float32)


def blur_valid(big: np.ndarray, k: np.ndarray, pad: int, noise: float,
               seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(sharp, blurred): the central part of ``big`` (``pad`` px in from each side) and its
    blur by ``k`` computed from the pixels around it, with noise, on 8-bit levels."""
    r = k.shape[0] // 2
    blurred = signal.fftconvolve(big, k, mode="valid")          # shrinks by 2 r
    cut = pad - r
    blurred = blurred[cut:blurred.shape[0] - cut, cut:blurred.shape[1] - cut]
    sharp = big[pad:big.shape[0] - pad, pad:big.shape[1] - pad]
    rng = np.random.default_rng(seed)
    blurred = blurred + noise * rng.standard_normal(blurred.shape)
    return sharp, quantize_8bit(np.clip(blurred, 0, 1))


def kernel_similarity(a: np.ndarray, b: np.ndarray) -> float:
    """Largest normalised cross-correlation of two kernels over all relative shifts."""
    a = np.asarray(a, np.float64) - np.mean(a)
    b = np.asarray(b, np.float64) - np.mean(b)
    return float(signal.correlate(a, b).max() / (np.linalg.norm(a) * np.linalg.norm(b)))


def deconvolve(blurred: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """The project's default non-blind method with one PSF for the whole (linear) image."""
    return deblur_with_psfs(blurred, patch_grid(blurred.shape, (1, 1)), [psf],
                            transfer="linear")


def run_case(sharp, blurred, k, margin: int, border: int) -> dict:
    size = k.shape[0] + margin
    size += 1 - size % 2
    t0 = time.perf_counter()
    est = estimate_kernel(blurred, size)
    t_kernel = time.perf_counter() - t0
    blind = deconvolve(blurred, est)
    oracle = deconvolve(blurred, k)
    p = {name: _common.registered_psnr(sharp, img, border)
         for name, img in (("blurred", blurred), ("blind", blind), ("oracle", oracle))}
    gain, ratio = _check(blurred, est)
    true_gain, true_ratio = _check(blurred, k)
    kept = not gain < NO_BLUR_MARGIN and not ratio > SPARSER_MAX
    return {"kernel_size": int(k.shape[0]), "support": int(size),
            "psnr_blurred": p["blurred"], "psnr_blind": p["blind"], "psnr_oracle": p["oracle"],
            "no_blur_gain": gain, "sparsity_ratio": ratio, "kept": kept,
            "true_no_blur_gain": true_gain, "true_sparsity_ratio": true_ratio,
            "true_kept": not true_gain < NO_BLUR_MARGIN and not true_ratio > SPARSER_MAX,
            "psnr_checked": p["blind"] if kept else p["blurred"],
            "psnr_blind_unregistered": psnr(sharp, blind, border),
            "error_ratio": float(10 ** ((p["oracle"] - p["blind"]) / 10)),
            "kernel_similarity": kernel_similarity(est, k), "kernel_seconds": t_kernel}


def _check(blurred: np.ndarray, psf: np.ndarray) -> tuple[float, float]:
    """``deblur_blind``'s two tests of a kernel: its spectral gain over no blur, and how
    much sparser it makes the photo's gradients (both computed, for the report)."""
    return (kernel_gain_over_no_blur(blurred, psf, transfer="linear"),
            kernel_sparsity_ratio(blurred, psf, transfer="linear"))


def summarise(rows: list[dict]) -> dict:
    r = np.array([row["error_ratio"] for row in rows])
    mean = {k: float(np.mean([row[k] for row in rows]))
            for k in ("psnr_blurred", "psnr_blind", "psnr_oracle", "kernel_similarity",
                      "kernel_seconds")}
    return {"cases": len(rows), "mean": mean,
            "error_ratio": {"median": float(np.median(r)), "max": float(r.max()),
                            f"within_{SUCCESS_RATIO:g}": int((r <= SUCCESS_RATIO).sum()),
                            "within_3": int((r <= 3).sum())},
            "blind_beats_blurred": int(sum(row["psnr_blind"] > row["psnr_blurred"]
                                           for row in rows)),
            "check": _check_summary(rows),
            "per_kernel_median_ratio": {
                k: float(np.median([row["error_ratio"] for row in rows if row["kernel"] == k]))
                for k in sorted({row["kernel"] for row in rows})}}


def _check_summary(rows: list[dict]) -> dict:
    """How the check against no blur (``deblur_blind``'s default) sorts the estimates:
    kept or not, and where the blind result beat the blurred input in each group."""
    def beats(group) -> int:
        return int(sum(r["psnr_blind"] > r["psnr_blurred"] for r in group))

    kept = [r for r in rows if r["kept"]]
    dropped = [r for r in rows if not r["kept"]]
    return {"kept": len(kept), "true_kernels_kept": int(sum(r["true_kept"] for r in rows)),
            "dropped_by_sparsity": int(sum(not r["no_blur_gain"] < NO_BLUR_MARGIN
                                           and not r["kept"] for r in rows)),
            "kept_beating_blurred": beats(kept), "dropped_beating_blurred": beats(dropped),
            "mean_psnr_checked": float(np.mean([r["psnr_checked"] for r in rows]))}


def markdown(result: dict) -> str:
    s = result["summary"]
    m, ch = s["mean"], s["check"]
    lines = [f"{s['cases']} cases ({result['photos']} photos x 8 Levin kernels, "
             f"grey crops of up to {result['crop']} px, noise {result['noise']:g}, 8-bit); "
             f"PSNR after the best global shift, border {result['border']} px.", "",
             "| | PSNR (dB) |", "|---|---:|",
             f"| blurred | {m['psnr_blurred']:.2f} |",
             f"| blind (estimated kernel) | {m['psnr_blind']:.2f} |",
             f"| oracle (true kernel) | {m['psnr_oracle']:.2f} |", "",
             f"Error ratio SSD(blind)/SSD(oracle): median {s['error_ratio']['median']:.2f}, "
             f"<= {SUCCESS_RATIO:g} in {s['error_ratio'][f'within_{SUCCESS_RATIO:g}']}/"
             f"{s['cases']}, <= 3 in {s['error_ratio']['within_3']}/{s['cases']}; "
             f"kernel similarity (NCC) mean {m['kernel_similarity']:.3f}; "
             f"kernel estimate {m['kernel_seconds']:.2f} s mean.", "",
             f"The checks against no blur (`deblur_blind`'s default: the spectral gain, "
             f"then the sparsity) keep {ch['kept']}/{s['cases']} estimates "
             f"({ch['dropped_by_sparsity']} dropped by the sparsity alone; the true "
             f"kernels: {ch['true_kernels_kept']}/{s['cases']} kept); the blind result "
             f"beats the blurred input in "
             f"{ch['kept_beating_blurred']} of those kept and {ch['dropped_beating_blurred']} "
             f"of those dropped; mean PSNR with the checks {ch['mean_psnr_checked']:.2f} dB.", "",
             "| kernel | median error ratio |", "|---|---:|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in s["per_kernel_median_ratio"].items()]
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    plt = _common.matplotlib_pyplot()
    r = np.sort([row["error_ratio"] for row in rows])
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.step(r, np.arange(1, r.size + 1) / r.size, where="post")
    ax.axvline(SUCCESS_RATIO, color="grey", lw=0.8, ls="--")
    ax.set_xlim(min(1.0, float(r.min()) * 0.95), max(5.0, float(r.max()) * 1.05))
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("error ratio SSD(blind) / SSD(true kernel)")
    ax.set_ylabel("fraction of cases")
    ax.set_title("Blind kernel estimate, Levin et al. kernels")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=4,
                    help="how many of the shared photos (evenly spaced in name order)")
    ap.add_argument("--crop", type=int, default=384, help="side of the square crops, px")
    ap.add_argument("--max-size", type=int, default=768,
                    help="the photos are first shrunk to this longer side, px")
    ap.add_argument("--noise", type=float, default=0.01, help="noise std on [0, 1]")
    ap.add_argument("--margin", type=int, default=6,
                    help="kernel support = the true kernel's side + this, px")
    ap.add_argument("--data", type=Path, default=None,
                    help="the shared data folder (default: ../shared/data)")
    ap.add_argument("--quick", action="store_true", help="1 photo, 256 px crops")
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "blind_levin.json",
                    help="JSON report (the .md and .png are written beside it)")
    args = ap.parse_args(argv)
    if args.quick:
        args.photos, args.crop = 1, 256
    data = args.data or default_shared_data()
    kpath = data / "kernels" / "levin2009.npz"
    if not kpath.is_file():
        where = "" if args.data else " (give the shared data folder: --data)"
        raise InputError(str(kpath), f"the Levin kernels are not there{where}")
    kernels = levin_kernels(kpath)
    photos = list_photos(data / "photos")
    pick = np.unique(np.linspace(0, len(photos) - 1, min(args.photos, len(photos))).round())
    photos = [photos[int(i)] for i in pick]
    pad = max(k.shape[0] for k in kernels.values()) // 2 + 2
    border = pad + 2
    rows = []
    t_start = time.perf_counter()
    for i, path in enumerate(photos):
        big = grey_crop(path, args.crop, pad, args.max_size)
        for j, (name, k) in enumerate(kernels.items()):
            sharp, blurred = blur_valid(big, k, pad, args.noise, seed=100 * i + j)
            row = {"photo": path.stem, "kernel": name, "crop": int(sharp.shape[0]),
                   **run_case(sharp, blurred, k, args.margin, border)}
            rows.append(row)
            _common.say(f"{path.stem:18s} {name}: blurred {row['psnr_blurred']:.2f}, blind "
                        f"{row['psnr_blind']:.2f}, oracle {row['psnr_oracle']:.2f} dB, ratio "
                        f"{row['error_ratio']:.2f}, NCC {row['kernel_similarity']:.3f}, "
                        f"gain over no blur {row['no_blur_gain']:+.1f} "
                        f"({row['kernel_seconds']:.1f} s)")
    result = {"benchmark": "blind_levin", "quick": args.quick, "photos": len(photos),
              "crop": args.crop, "max_size": args.max_size, "noise": args.noise,
              "margin": args.margin, "border": border, "summary": summarise(rows),
              "per_case": rows, "total_seconds": time.perf_counter() - t_start,
              "machine": _common.machine_info()}
    out = args.out
    _common.write_json(out, result)
    md = markdown(result)
    out.with_suffix(".md").write_text(md, encoding="utf-8")
    plot(rows, out.with_suffix(".png"))
    print("\n" + md)
    _common.say(f"wrote {out} (.md, .png) in {result['total_seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
