"""Compare deblurring methods on the benchmark dataset: PSNR, SSIM and time per megapixel.

Cases: the shared sharp photos x real shake windows of the shared hand-held gyro log
(:mod:`gyrodeblur.dataset`: exposure 10-40 ms, readout 30 ms, fx = 0.8 width, 40 dB
noise, 8-bit sRGB). Default: the 12 photos x 3 windows at full size (~1024 x 680);
``--quick``: 2 photos x 1 window at 256 px.

Methods (the registry :func:`registry`, ``name -> (callable(case) -> image, note)``):

* ``blurred``: the input as is;
* ``wiener-invariant``, ``wiener-variant``: :func:`gyrodeblur.deblur.deblur` with the Wiener
  method, one PSF for the photo (the principal point's, middle row's timing) or the
  chapter's 6 x 8 patches; ``wiener-aligned``: the same filter in the pipeline the other
  methods use (warp by the PSFs' mean-displacement field, centred PSFs, automatic grid),
  which separates what the pipeline gains from what the method gains;
* ``skimage-wiener``: ``skimage.restoration.wiener`` (balance 0.01, its default Laplacian
  regulariser; the best of 0.005-0.1 on 4 cases at 512 px, by < 0.2 dB)
  and ``skimage-rl``: ``skimage.restoration.richardson_lucy`` (30 iterations),
  both given the true PSF at the image centre (the one ``wiener-invariant`` uses; for
  Richardson-Lucy, which needs a kernel without negative values, its windowed-sinc
  lobes clipped at 0 and the rest normalised: with them it diverged, session 60), per
  channel, in linear light like ours; no padding (scikit-image's wiener wraps around
  periodically, richardson_lucy's convolutions assume zeros outside), as a user would
  call them;
* every further method registered in :data:`gyrodeblur.deblur.METHODS` (``sparse``, ...),
  through ``deblur(..., method=name)`` in the default (variant) mode with the method's
  default grid and alignment; ``NAME@MODE`` picks
  the mode (e.g. ``sparse@invariant``);
* ``blind``: :func:`gyrodeblur.deblur.deblur_blind` (one kernel estimated from the photo
  alone, then the default method), when the library has it; kernel support
  ``max(15, 1.2 x`` the centre PSF's extent) px (its only hint); ``blind-patches``: the
  same with one kernel per patch of a 2 x 3 grid (``deblur_blind(..., grid=)``).

Scores: PSNR as the chapter defines it and SSIM (scikit-image's), on 8-bit sRGB values,
on the central region without a border of 5 % of the smaller side; and the PSNR after
the best global sub-pixel shift (``psnr_reg``), which forgives a method that does not
reference its result to the exposure start (blind ones cannot know it) and shows how far
the blurred input is from the sharp photo apart from its displacement; and the PSNR after
the best smooth displacement field (``psnr_field``, :func:`_common.field_registered_psnr`),
which also forgives the rolling shutter's skew, so that a method that cannot know the
geometry (one kernel for the photo, blind or not) is judged on its deblurring. Time: wall-clock
seconds of the call, per megapixel (total time / total megapixels).

Usage::

    python benchmarks/compare_methods.py                    # 36 cases, ~20-30 min on 2 cores
    python benchmarks/compare_methods.py --quick            # seconds
    python benchmarks/compare_methods.py --methods wiener-variant,skimage-rl
    python benchmarks/compare_methods.py --dataset benchmarks/results/dataset   # cache cases

Writes ``benchmarks/results/compare_methods.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

from gyrodeblur import deblur as deblur_mod  # noqa: E402
from gyrodeblur.metrics import default_border, psnr, ssim  # noqa: E402
from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear  # noqa: E402

SKIMAGE_WIENER_BALANCE = 0.01  # best of 0.005..0.1 on 4 cases at 512 px, by < 0.2 dB
SKIMAGE_RL_ITERATIONS = 30
#: Patch grid of ``blind-patches`` (landscape: rows x columns): 389 x 410 px patches
#: (25 % overlap) on the dataset's 1024 x 680 photos, each over twice the largest kernel.
BLIND_GRID = (2, 3)
BASE = ["blurred", "wiener-invariant", "wiener-variant", "skimage-wiener", "skimage-rl"]


def centre_psf(case) -> np.ndarray:
    """The true PSF at the principal point, with the middle row's timing."""
    _, field, _ = deblur_mod.plan_psf_field(case.capture, case.blurred.shape[:2],
                                            mode="invariant")
    return field.psfs[0]


def _per_channel_linear(image: np.ndarray, fn) -> np.ndarray:
    """sRGB -> linear, ``fn`` on each channel, clip >= 0, -> sRGB, clip to [0, 1]."""
    lin = srgb_to_linear(image).astype(np.float64)
    chans = [lin] if lin.ndim == 2 else [lin[..., c] for c in range(lin.shape[2])]
    out = np.stack([fn(ch) for ch in chans], axis=-1)
    if lin.ndim == 2:
        out = out[..., 0]
    return np.clip(linear_to_srgb(np.clip(out, 0, None)), 0, 1)


def _skimage_wiener(case):
    from skimage.restoration import wiener

    psf = centre_psf(case).astype(np.float64)
    return _per_channel_linear(case.blurred, lambda ch: wiener(
        ch, psf, balance=SKIMAGE_WIENER_BALANCE, clip=False))


def _skimage_rl(case):
    from skimage.restoration import richardson_lucy

    psf = np.clip(centre_psf(case).astype(np.float64), 0.0, None)   # RL's kernel is >= 0
    psf /= psf.sum()
    return _per_channel_linear(case.blurred, lambda ch: richardson_lucy(
        ch, psf, num_iter=SKIMAGE_RL_ITERATIONS, clip=False))


def _deblur(method: str, mode: str, **kw):
    def run(case):
        return deblur_mod.deblur(case.blurred, case.capture, mode=mode, method=method, **kw)
    return run


def _supports(option: str, fn=None) -> bool:
    import inspect

    return option in inspect.signature(fn or deblur_mod.deblur).parameters


def _blind_kernel_size(case) -> int:
    k = int(max(15, 1.2 * case.meta.get("blur_px", 12))) | 1
    return min(k, (min(case.blurred.shape[:2]) // 2 - 1) | 1)


def _blind(case):
    """The pipeline's blind entry (``deblur.deblur_blind``) when it exists, else
    ``blind.blind_deconvolve`` in linear light."""
    k = _blind_kernel_size(case)
    if hasattr(deblur_mod, "deblur_blind"):
        out, _ = deblur_mod.deblur_blind(case.blurred, k)
        return out
    from gyrodeblur.blind import blind_deconvolve

    out, _ = blind_deconvolve(srgb_to_linear(case.blurred), k)
    return np.clip(linear_to_srgb(np.clip(out, 0, None)), 0, 1)


def _blind_patches(case):
    """``deblur_blind`` with a kernel per patch of :data:`BLIND_GRID` (rows and columns
    swapped for a portrait photo)."""
    h, w = case.blurred.shape[:2]
    grid = BLIND_GRID if w >= h else BLIND_GRID[::-1]
    out, _ = deblur_mod.deblur_blind(case.blurred, _blind_kernel_size(case), grid=grid)
    return out


def registry() -> dict[str, tuple[Callable, str]]:
    """Every method this script knows now: ``name -> (callable(case) -> image, note)``."""
    reg: dict[str, tuple[Callable, str]] = {
        "blurred": (lambda case: case.blurred, "the blurred input"),
        "wiener-invariant": (_deblur("wiener", "invariant"),
                             "ours: Wiener (phi 0.01), one PSF for the whole photo"),
        "wiener-variant": (_deblur("wiener", "variant"),
                           "ours: Wiener (phi 0.01), 6x8 patches, one PSF each"),
        "skimage-wiener": (_skimage_wiener,
                           f"skimage.restoration.wiener, balance {SKIMAGE_WIENER_BALANCE}, "
                           "true centre PSF, per channel, linear light, no padding"),
        "skimage-rl": (_skimage_rl,
                       f"skimage.restoration.richardson_lucy, {SKIMAGE_RL_ITERATIONS} "
                       "iterations, true centre PSF clipped at 0, per channel, linear light, "
                       "no padding"),
    }
    if _supports("align"):
        reg["wiener-aligned"] = (_deblur("wiener", "variant", grid="auto", align=True),
                                 "ours: Wiener (phi 0.01) after the displacement-field warp, "
                                 "auto grid (the other methods' pipeline)")
    for name in deblur_mod.METHODS:
        if name != "wiener":
            default = " [the project's default]" if name == deblur_mod.DEFAULT_METHOD else ""
            reg[name] = (_deblur(name, "variant"),
                         f"ours: deblur(method={name!r}) with its default grid and "
                         f"alignment{default}")
    if _supports("model", deblur_mod.deblur_with_psfs):
        reg["sparse-patches"] = (_deblur("sparse", "variant", model="patches"),
                                 "ours: the sparse method patch by patch, blended, without "
                                 "the global model's refinement (the default before "
                                 "session 28)")
    has_blind = hasattr(deblur_mod, "deblur_blind")
    if not has_blind:
        try:
            from gyrodeblur import blind
            has_blind = hasattr(blind, "blind_deconvolve")
        except ImportError:
            pass
    if has_blind and "blind" not in reg:
        reg["blind"] = (_blind, "ours: one kernel estimated from the photo alone (no gyro), "
                                "then the default method")
    if has_blind and _supports("grid", deblur_mod.deblur_blind):
        reg["blind-patches"] = (_blind_patches,
                                f"ours: blind, one kernel per patch of a {BLIND_GRID[0]}x"
                                f"{BLIND_GRID[1]} grid (landscape; transposed for portrait), "
                                "then the default method")
    return reg


def resolve(names: list[str]) -> dict[str, tuple[Callable, str]]:
    """The registry entries for ``names``; ``METHOD@MODE`` builds a deblur call."""
    reg = registry()
    out = {}
    for name in names:
        if name in reg:
            out[name] = reg[name]
        elif "@" in name and name.split("@")[0] in deblur_mod.METHODS:
            method, mode = name.split("@", 1)
            out[name] = (_deblur(method, mode), f"ours: deblur(method={method!r}, mode={mode!r})")
        else:
            raise SystemExit(f"unknown method {name!r}; known: {', '.join(reg)} "
                             f"(or METHOD@MODE with METHOD in {', '.join(deblur_mod.METHODS)})")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 photos x 1 window at 256 px")
    ap.add_argument("--methods", help="comma-separated registry names (default: all); "
                                      "--list shows them")
    ap.add_argument("--list", action="store_true", help="list the methods and exit")
    _common.add_source_options(ap)
    ap.add_argument("--max-photos", type=_common.positive_int, default=None,
                    help="use only the first N photos (default all; quick 2)")
    ap.add_argument("--windows", type=_common.positive_int, default=None,
                    help="shake windows per photo (default 3; quick 1)")
    ap.add_argument("--max-size", type=_common.positive_int, default=None,
                    help="downscale photos (px; quick 256)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dataset", help="load the cases from this folder, or build and "
                                      "write them there first")
    ap.add_argument("--out", type=Path, default=_common.RESULTS / "compare_methods.json")
    args = ap.parse_args(argv)
    if args.list:
        for name, (_, note) in registry().items():
            print(f"{name:<18} {note}")
        return 0
    names = args.methods.split(",") if args.methods else list(registry())
    methods = resolve([n.strip() for n in names if n.strip()])
    build = build_options(args)
    t_start = time.perf_counter()
    machine = _common.machine_info()
    _common.say(f"building cases ({build})")
    cases, used = _common.get_cases_and_options(
        dataset=args.dataset, progress=_common.progress_printer("case"), **build)
    t_cases = time.perf_counter() - t_start

    per_case = []
    totals = {m: {"seconds": 0.0, "mp": 0.0, "errors": 0} for m in methods}
    for i, case in enumerate(cases):
        border = default_border(case.sharp.shape)
        row = {"case": case.name, "border_px": border,
               "shape": list(case.sharp.shape), "blur_px": case.meta.get("blur_px"),
               "roll_deg": case.meta.get("roll_deg"),
               "exposure_time": case.meta.get("exposure_time"), "methods": {}}
        for name, (fn, _) in methods.items():
            t0 = time.perf_counter()
            try:
                with _common.quiet():
                    out = fn(case)
            except Exception as exc:  # a broken plug-in must not stop the table
                row["methods"][name] = {"error": f"{type(exc).__name__}: {exc}"}
                totals[name]["errors"] += 1
                continue
            dt = time.perf_counter() - t0
            out = np.clip(np.asarray(out, np.float32), 0, 1)
            row["methods"][name] = {
                "psnr": psnr(case.sharp, out, border),
                "ssim": ssim(case.sharp, out, border),
                "psnr_reg": _common.registered_psnr(case.sharp, out, border),
                "psnr_field": _common.field_registered_psnr(case.sharp, out, border),
                "seconds": dt,
            }
            if name != "blurred":
                totals[name]["seconds"] += dt
                totals[name]["mp"] += case.megapixels
        per_case.append(row)
        summary = "  ".join(f"{n} {m['psnr']:.2f}" for n, m in row["methods"].items()
                            if "psnr" in m)
        _common.say(f"[{i + 1}/{len(cases)}] {case.name} (blur {row['blur_px']} px, roll "
                    f"{row['roll_deg']:.2f} deg): PSNR {summary}")

    table = {}
    for name, (_, note) in methods.items():
        ok = [r["methods"][name] for r in per_case if "psnr" in r["methods"].get(name, {})]
        t = totals[name]
        table[name] = {
            "note": note,
            "psnr_mean": float(np.mean([m["psnr"] for m in ok])) if ok else None,
            "ssim_mean": float(np.mean([m["ssim"] for m in ok])) if ok else None,
            "psnr_reg_mean": float(np.mean([m["psnr_reg"] for m in ok])) if ok else None,
            "psnr_field_mean": float(np.mean([m["psnr_field"] for m in ok])) if ok else None,
            "seconds_per_mp": (t["seconds"] / t["mp"]) if t["mp"] > 0 else None,
            "cases": len(ok),
            "errors": t["errors"],
        }
    result = {
        "benchmark": "compare_methods",
        "quick": args.quick,
        # the options the cases were built with (a dataset folder's own, stored ones)
        "dataset": {**{k: (str(v) if isinstance(v, Path) else v) for k, v in used.items()},
                    "from_folder": args.dataset, "cases": len(cases),
                    "snr_db": (cases[0].meta.get("snr_db", used.get("snr_db"))
                               if cases else used.get("snr_db")),
                    "readout_time": cases[0].meta.get("readout_time") if cases else None,
                    "focal_fraction": cases[0].meta.get("focal_fraction") if cases else None,
                    "build_seconds": t_cases},
        "border_rule": "5% of the smaller image side (metrics.default_border)",
        "psnr_reg_note": "PSNR after the best global sub-pixel shift (phase correlation)",
        "psnr_field_note": "PSNR after the best smooth displacement field (phase correlation "
                           "of 128 px blocks every 64 px, median-filtered, interpolated)",
        "time_note": "wall-clock seconds of the method call / megapixels, all cases",
        "skimage": {"wiener_balance": SKIMAGE_WIENER_BALANCE,
                    "rl_iterations": SKIMAGE_RL_ITERATIONS, "padding": "none"},
        "table": table,
        "per_case": per_case,
        "total_seconds": time.perf_counter() - t_start,
        "machine": machine,
    }
    _common.write_json(args.out, result)
    md = markdown_table(result)
    args.out.with_suffix(".md").write_text(md, encoding="utf-8")
    print(md)
    _common.say(f"wrote {args.out} and {args.out.with_suffix('.md')}")
    return 0


def build_options(args) -> dict:
    """The dataset options asked for: explicit values as given, ``--quick`` changing only
    the defaults (2 photos, 1 window, 256 px)."""
    def pick(value, quick, full):
        return value if value is not None else quick if args.quick else full

    return dict(photos=args.photos, gyro=args.gyro,
                max_photos=pick(args.max_photos, 2, None),
                windows_per_photo=pick(args.windows, 1, 3),
                max_size=pick(args.max_size, 256, None), seed=args.seed)


def _noise_words(snr_db) -> str:
    if snr_db is None:
        return "no added noise"
    return f"{snr_db:g} dB noise"


def markdown_table(result: dict) -> str:
    d = result["dataset"]
    lines = [
        f"{d['cases']} cases (photos x shake windows, {_noise_words(d.get('snr_db'))}, "
        f"8-bit); PSNR/SSIM on the "
        f"central region (border 5 % of the smaller side); PSNR reg. = after the best "
        f"global shift; PSNR field = after the best smooth displacement field (forgives "
        f"any smooth geometric difference, e.g. a rolling shutter's skew); time = wall "
        f"clock per megapixel.",
        "",
        "| method | PSNR (dB) | SSIM | PSNR reg. (dB) | PSNR field (dB) | s / MP | what |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]

    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    for name, r in result["table"].items():
        err = f" ({r['errors']} failed)" if r["errors"] else ""
        lines.append(f"| {name} | {f(r['psnr_mean'], '.2f')} | {f(r['ssim_mean'], '.3f')} | "
                     f"{f(r['psnr_reg_mean'], '.2f')} | {f(r['psnr_field_mean'], '.2f')} | "
                     f"{f(r['seconds_per_mp'], '.2f')} | "
                     f"{r['note']}{err} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(_common.run_main(main))
