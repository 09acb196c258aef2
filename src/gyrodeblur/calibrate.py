"""Self-calibration: fit the few parameters that turn a gyro log into a photo's PSFs.

What a gyro log gets wrong is low-dimensional: the clock offset between gyro and camera,
a constant gyro bias (3 components), the rolling-shutter readout time, the focal length
(a scale), and the axis mapping (one of the 24 proper signed axis permutations). We keep
the physics and fit only these, from the blurred photo(s) themselves.

Criterion
---------
For a few textured patches of each photo (linear-light luminance, downscaled so the
largest PSF spans ~40 px), the blurred patch is modelled as ``g = h * u + n`` with a
Gaussian gradient prior on ``u`` (power spectrum ``a / |D(w)|^2``, ``D`` the discrete
gradient) and white noise of power ``s``. Then the patch's spectrum is Gaussian with
``E|G(w)|^2 = a |H(w)|^2 / |D(w)|^2 + s`` and ``-log p(g | h)`` is, up to constants,
the Whittle likelihood ``sum_w |G(w)|^2 / M(w) + log M(w)`` (periodogram of the
Hann-windowed patch; the model is smoothed by the window's spectral kernel). This is
the chapter's marginal ``p(h | g)`` of eq. 6.7, exact for a Gaussian prior: its log-det
term penalises "no blur" and too much blur alike. ``a`` and ``s`` are fitted per patch
in closed form (iteratively re-weighted least squares). The cost of a parameter set is
the sum over patches and photos.

Search
------
1. Coarse: every allowed axis mapping x a grid of time offsets, other parameters as
   given, on a subset of patches.
2. Refine: Nelder-Mead over the continuous parameters (offset, readout, focal scale,
   bias) for the best few mappings, on all patches.
3. Tie-break: ``|H|`` cannot tell a PSF from its point reflection (negating the x and
   y rates, a proper rotation too). Among mappings whose costs are within a margin,
   the one whose Wiener-deconvolved patches are sparsest (normalised gradient sparsity
   ``||grad u||_1 / ||grad u||_2``, lower = sharper; ghosts from a wrong-phase PSF raise
   it) wins.

Uncertainties are Laplace estimates: ``1 / sqrt(d^2 cost / d theta^2)`` from finite
differences at the optimum (the Whittle cost is a negative log-likelihood). They ignore
model error and are lower bounds. The axis mapping's confidence is the cost gap to the
runner-up (in nats).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from scipy.optimize import minimize

from .axes import PROPER_AXIS_LETTERS, axes_to_letters, parse_axes
from .capture import Capture
from .errors import InputError
from .psf import psf_extent, render_psf
from .tonecurve import get_transfer_curve

__all__ = ["calibrate", "CalibrationResult", "PARAMETERS", "calibrate_command"]

#: Parameters that can be estimated (and fixed with ``fix=``).
PARAMETERS = ("offset", "bias", "readout", "focal", "axes")
_TARGET_EXTENT = 40.0     # px: working scale makes the largest PSF about this long
_PATCH = 160              # px: patch side at working scale
_INVALID = 1e30


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    captures : list of Capture
        The corrected captures, one per photo (``capture`` is the first).
    estimates : dict
        ``name -> (before, after, uncertainty)`` for ``offset`` (s), ``readout`` (s),
        ``focal`` (scale), ``bias`` (rad/s, 3-vector), ``axes`` (letters; uncertainty = cost
        gap to the runner-up mapping, nats).
    ranking : list of (letters, cost)
        Axis mappings by cost after the coarse search.
    scale : float
        Working scale used.
    """

    captures: list
    estimates: dict
    ranking: list = field(default_factory=list)
    scale: float = 1.0

    @property
    def capture(self) -> Capture:
        return self.captures[0]


# ----------------------------------------------------------------------------- patches

@dataclass
class _Patch:
    photo: int
    x: float            # centre, working-scale pixels
    y: float
    gray: np.ndarray    # working-scale patch (linear luminance)
    power: np.ndarray   # periodogram, full fft2 grid


def _window(n: int) -> np.ndarray:
    w = np.hanning(n + 2)[1:-1]
    return np.outer(w, w)


def _freq_terms(n: int):
    u = sfft.fftfreq(n)[:, None]
    v = sfft.fftfreq(n)[None, :]
    d2 = 4 * np.sin(np.pi * u) ** 2 + 4 * np.sin(np.pi * v) ** 2
    r = np.sqrt(u ** 2 + v ** 2)
    mask = r >= 2.5 / n                   # drop DC and the window's leakage around it
    return d2, mask


def _smooth_window(m: np.ndarray) -> np.ndarray:
    """Convolve a spectrum with the Hann window's power kernel [1/6, 2/3, 1/6] (2-D, circular)."""
    out = (2 / 3) * m + (np.roll(m, 1, 0) + np.roll(m, -1, 0)) / 6
    return (2 / 3) * out + (np.roll(out, 1, 1) + np.roll(out, -1, 1)) / 6


def _luminance(image: np.ndarray, transfer: str) -> np.ndarray:
    img = get_transfer_curve(transfer).decode(np.asarray(image, np.float32))
    return img.mean(axis=2) if img.ndim == 3 else img


def _select_patches(gray: np.ndarray, photo: int, n: int, size: int,
                    saturated: np.ndarray) -> list[_Patch]:
    H, W = gray.shape
    if H < size or W < size:
        raise InputError(None, f"photo {photo + 1} is too small ({W}x{H} at working scale) "
                               f"for calibration patches of {size} px")
    gy, gx = np.gradient(gray)
    energy = gy ** 2 + gx ** 2
    energy[saturated] = 0
    rows = cols = int(np.ceil(np.sqrt(n)))
    ys = np.linspace(0, H - size, rows + 2)[1:-1] if H - size > 0 else [0]
    xs = np.linspace(0, W - size, cols + 2)[1:-1] if W - size > 0 else [0]
    win = _window(size)
    step = max(8, size // 4)
    out = []
    for cy in ys:
        for cx in xs:
            best, pos = -1.0, None
            for y0 in range(int(max(0, cy - size / 2)), int(min(H - size, cy + size / 2)) + 1, step):
                for x0 in range(int(max(0, cx - size / 2)), int(min(W - size, cx + size / 2)) + 1, step):
                    if saturated[y0:y0 + size, x0:x0 + size].mean() > 0.01:
                        continue
                    e = energy[y0:y0 + size, x0:x0 + size].mean()
                    if e > best:
                        best, pos = e, (y0, x0)
            if pos is None:
                continue
            y0, x0 = pos
            g = gray[y0:y0 + size, x0:x0 + size].astype(np.float64)
            gw = (g - g.mean()) * win
            power = np.abs(sfft.fft2(gw)) ** 2 / (win ** 2).sum()
            out.append(_Patch(photo, x0 + (size - 1) / 2, y0 + (size - 1) / 2, g, power))
    out.sort(key=lambda p: -p.power.sum())
    return out[:n]


# ----------------------------------------------------------------------------- the model

class _Problem:
    """The calibration cost over a set of photos sharing the unknown parameters."""

    def __init__(self, images, captures, *, transfer="srgb", n_patches=9,
                 target_extent=_TARGET_EXTENT, patch=_PATCH):
        self.base = captures
        ext = []
        for img, cap in zip(images, captures):
            H, W = img.shape[:2]
            c = cap.scaled_to(W, H)
            for fx, fy in ((0.5, 0.5), (0.1, 0.1), (0.9, 0.9), (0.1, 0.9), (0.9, 0.1)):
                ext.append(psf_extent(render_psf(c, fx * (W - 1), fy * (H - 1), max_step=0.5)))
        self.scale = float(np.clip(target_extent / max(max(ext), 1), 0.1, 1.0))
        self.size = patch
        self.d2, self.mask = _freq_terms(patch)
        self.win = _window(patch)
        self.patches: list[_Patch] = []
        self.work_caps = []
        per = max(3, int(np.ceil(n_patches / len(images))))
        from skimage.transform import rescale
        for i, (img, cap) in enumerate(zip(images, captures)):
            lum = _luminance(img, transfer)
            sat = (np.asarray(img).max(axis=2) if np.ndim(img) == 3 else np.asarray(img)) > 0.98
            if self.scale < 1:
                lum = rescale(lum, self.scale, anti_aliasing=True).astype(np.float32)
                sat = rescale(sat.astype(np.float32), self.scale) > 0.01
            h, w = lum.shape
            self.work_caps.append(cap.scaled_to(img.shape[1], img.shape[0]).scaled_to(w, h))
            self.patches += _select_patches(lum, i, per, patch, sat)
        if not self.patches:
            raise InputError(None, "no textured, unsaturated patch found for calibration")

    # theta: dict(offset=ds, readout=s, focal=scale, bias=(3,), axes=3x3)
    def captures_for(self, theta, caps=None) -> list[Capture] | None:
        caps = caps or self.work_caps
        out = []
        for c in caps:
            try:
                out.append(c.replace(time_offset=c.time_offset + theta["offset"],
                                     readout_time=max(0.0, theta["readout"]),
                                     camera=c.camera.with_focal_scale(theta["focal"]),
                                     bias=np.asarray(theta["bias"], float), axes=theta["axes"]))
            except InputError:
                return None
        return out

    def _psf(self, cap, p: _Patch, fast: bool) -> np.ndarray | None:
        psf = render_psf(cap, p.x, p.y, max_step=0.5 if fast else 0.25)
        if psf.shape[0] > self.size:
            return None
        return psf

    def patch_cost(self, psf: np.ndarray, p: _Patch) -> float:
        k = np.zeros((self.size, self.size))
        r = psf.shape[0]
        k[:r, :r] = psf
        h2 = np.abs(sfft.fft2(k)) ** 2
        S = _smooth_window(h2 / np.maximum(self.d2, 1e-6))[self.mask]
        P = p.power[self.mask]
        a, s = _fit_spectrum(S, P)
        M = a * S + s
        return float(np.sum(P / M + np.log(M)))

    def cost(self, theta, patches=None, fast=False) -> float:
        caps = self.captures_for(theta)
        if caps is None:
            return _INVALID
        total = 0.0
        for p in (patches or self.patches):
            psf = self._psf(caps[p.photo], p, fast)
            if psf is None:
                return _INVALID
            total += self.patch_cost(psf, p)
        return total

    def sparsity(self, theta) -> float:
        """Mean normalised gradient sparsity of the Wiener-deconvolved patches."""
        from .wiener import wiener_deconvolve
        caps = self.captures_for(theta)
        vals = []
        for p in self.patches:
            psf = self._psf(caps[p.photo], p, False)
            u = wiener_deconvolve(p.gray.astype(np.float32), psf, 0.005)
            m = psf.shape[0]
            u = u[m:-m, m:-m] if u.shape[0] > 2 * m + 8 else u
            gy, gx = np.gradient(u.astype(np.float64))
            g = np.hypot(gx, gy)
            vals.append(g.sum() / np.sqrt((g ** 2).sum() * g.size + 1e-20))
        return float(np.mean(vals))


def _fit_spectrum(S: np.ndarray, P: np.ndarray, iters: int = 6) -> tuple[float, float]:
    """ML fit of ``P ~ a S + s`` (Whittle) by iteratively re-weighted least squares."""
    a = max(np.median(P / np.maximum(S, 1e-12)) * 0.5, 1e-12)
    s = max(np.percentile(P, 5), 1e-12)
    for _ in range(iters):
        w = 1.0 / (a * S + s) ** 2
        A = np.array([[np.sum(w * S * S), np.sum(w * S)], [np.sum(w * S), np.sum(w)]])
        b = np.array([np.sum(w * S * P), np.sum(w * P)])
        try:
            a_new, s_new = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            break
        a, s = max(a_new, 1e-12), max(s_new, 1e-12)
    return a, s


# ----------------------------------------------------------------------------- search

_STEPS = {"offset": 0.003, "readout": 0.003, "focal": 0.02, "bias": 0.01}


def _vector_names(fix) -> list[tuple[str, int | None]]:
    names = []
    for k in ("offset", "readout", "focal"):
        if k not in fix:
            names.append((k, None))
    if "bias" not in fix:
        names += [("bias", 0), ("bias", 1), ("bias", 2)]
    return names


def _theta_from(vec, names, base):
    th = {k: (np.array(v, float) if k == "bias" else v) for k, v in base.items()}
    th["bias"] = np.array(base["bias"], float)
    for v, (k, i) in zip(vec, names):
        scaled = v * _STEPS[k]
        if i is None:
            th[k] = base[k] + scaled
        else:
            th["bias"][i] = base["bias"][i] + scaled
    return th


def calibrate(images, captures, *, fix=(), offset_range: float = 0.04,
              offset_step: float = 0.005, transfer: str = "srgb", n_patches: int = 9,
              say=None) -> CalibrationResult:
    """Estimate time offset, gyro bias, readout time, focal scale and axis mapping.

    Parameters
    ----------
    images : list of ndarray
        Blurred photos (float in [0, 1]), one per capture.
    captures : Capture or list of Capture
        Their capture descriptions (one shared, or one per photo); they share the
        unknown parameters (one camera, one gyro, one session).
    fix : iterable of str
        Parameters not to estimate, from :data:`PARAMETERS`.
    offset_range, offset_step : float
        Seconds searched on each side of the given offset in the coarse stage, and the
        step.
    transfer : str
        Transfer curve of the photos' values (``"srgb"`` or ``"linear"``).
    n_patches : int
        Patches in all (spread over the photos and over each frame).
    say : callable(str), optional
        Progress messages.

    Returns
    -------
    CalibrationResult
    """
    if isinstance(captures, Capture):
        captures = [captures] * len(images)
    if len(captures) != len(images):
        raise InputError("--capture", f"{len(images)} photos but {len(captures)} captures")
    fix = set(fix)
    unknown = fix - set(PARAMETERS)
    if unknown:
        raise InputError("--fix", f"unknown parameter(s) {sorted(unknown)}; known: {', '.join(PARAMETERS)}")
    prob = _Problem(images, captures, transfer=transfer, n_patches=n_patches)
    c0 = captures[0]
    base = {"offset": 0.0, "readout": c0.readout_time, "focal": 1.0,
            "bias": np.array(c0.bias, float), "axes": c0.axes}
    letters0 = axes_to_letters(c0.axes)
    axes_list = [c0.axes] if "axes" in fix else [parse_axes(s) for s in PROPER_AXIS_LETTERS]
    if letters0 is None and "axes" not in fix:
        axes_list.append(c0.axes)
    offsets = [0.0] if "offset" in fix else \
        list(np.arange(-offset_range, offset_range + 1e-9, offset_step))
    coarse_patches = prob.patches[:max(4, len(prob.patches) // 2)]
    if say:
        say(f"calibrating on {len(prob.patches)} patches of {prob.size} px at scale "
            f"{prob.scale:.2f}: {len(axes_list)} axis mappings x {len(offsets)} offsets")
    scored = []
    for M in axes_list:
        best = (_INVALID, 0.0)
        for off in offsets:
            th = dict(base, axes=M, offset=off)
            best = min(best, (prob.cost(th, coarse_patches, fast=True), off))
        scored.append((best[0], best[1], M))
    scored.sort(key=lambda r: r[0])
    if scored[0][0] >= _INVALID:
        raise InputError(c0.source, "no axis mapping and time offset in the searched range "
                                    "gives PSFs covered by the gyro log")
    names = _vector_names(fix)
    refined = []
    for cost0, off, M in scored[:3]:
        start = dict(base, axes=M, offset=off)
        if names:
            f = lambda v: prob.cost(_theta_from(v, names, start))
            res = minimize(f, np.zeros(len(names)), method="Nelder-Mead",
                           options={"xatol": 0.05, "fatol": 0.05, "maxfev": 60 * len(names),
                                    "initial_simplex": _simplex(len(names))})
            th, cost = _theta_from(res.x, names, start), float(res.fun)
        else:
            th, cost = start, prob.cost(start)
        refined.append((cost, th))
    refined.sort(key=lambda r: r[0])
    best_cost, best = refined[0]
    # tie-break reflections (and near-ties) by sparsity of the deconvolved patches
    close = [r for r in refined if r[0] - best_cost < max(5.0, 1e-3 * abs(best_cost))]
    if len(close) > 1:
        sp = [(prob.sparsity(th), c, th) for c, th in close]
        sp.sort(key=lambda r: r[0])
        best_cost, best = sp[0][1], sp[0][2]
        if say:
            say("  near-tie between axis mappings " + ", ".join(
                f"{axes_to_letters(th['axes'])} (sparsity {s:.4f})" for s, _, th in sp))
    runner = [c for c, th in refined if axes_to_letters(th["axes"]) != axes_to_letters(best["axes"])]
    gap = (runner[0] - best_cost) if runner else float("nan")
    unc = _uncertainties(prob, best, names)
    caps = []
    for c in captures:
        caps.append(c.replace(time_offset=c.time_offset + best["offset"],
                              readout_time=max(0.0, best["readout"]),
                              camera=c.camera.with_focal_scale(best["focal"]),
                              bias=best["bias"], axes=best["axes"]))
    est = {
        "offset": (c0.time_offset, c0.time_offset + best["offset"], unc.get("offset")),
        "readout": (c0.readout_time, max(0.0, best["readout"]), unc.get("readout")),
        "focal": (1.0, best["focal"], unc.get("focal")),
        "bias": (np.array(c0.bias), np.array(best["bias"]),
                 np.array([unc.get(f"bias{i}", np.nan) for i in range(3)])),
        "axes": (letters0 or np.round(c0.axes, 6).tolist(),
                 axes_to_letters(best["axes"]) or np.round(best["axes"], 6).tolist(), gap),
    }
    ranking = [(axes_to_letters(M) or "given", float(c)) for c, _, M in scored]
    return CalibrationResult(caps, est, ranking, prob.scale)


def _simplex(n: int) -> np.ndarray:
    return np.vstack([np.zeros(n), np.eye(n)])


def _uncertainties(prob: _Problem, theta, names) -> dict:
    out = {}
    c0 = prob.cost(theta)
    for k, i in names:
        h = _STEPS[k]
        vals = []
        for sgn in (-1, 1):
            th = {kk: (np.array(v, float) if kk == "bias" else v) for kk, v in theta.items()}
            if i is None:
                th[k] = theta[k] + sgn * h
            else:
                th["bias"][i] += sgn * h
            vals.append(prob.cost(th))
        curv = (vals[0] + vals[1] - 2 * c0) / h ** 2
        key = k if i is None else f"bias{i}"
        out[key] = float(1 / np.sqrt(curv)) if curv > 0 and max(vals) < _INVALID else float("inf")
    return out


# ----------------------------------------------------------------------------- CLI glue

def format_estimates(est: dict) -> list[str]:
    """Human-readable lines: each parameter before -> after (+- uncertainty)."""
    lines = []
    b, a, u = est["offset"]
    lines.append(f"  time offset  {b * 1e3:+8.2f} ms -> {a * 1e3:+8.2f} ms  (+- {_fmt(u, 1e3)} ms)")
    b, a, u = est["readout"]
    lines.append(f"  readout      {b * 1e3:8.2f} ms -> {a * 1e3:8.2f} ms  (+- {_fmt(u, 1e3)} ms)")
    b, a, u = est["focal"]
    lines.append(f"  focal scale  {b:8.4f}    -> {a:8.4f}     (+- {_fmt(u, 1)})")
    b, a, u = est["bias"]
    lines.append("  gyro bias    [" + ", ".join(f"{v:+.4f}" for v in b) + "] -> ["
                 + ", ".join(f"{v:+.4f}" for v in a) + "] rad/s  (+- ["
                 + ", ".join(_fmt(v, 1) for v in u) + "])")
    b, a, gap = est["axes"]
    conf = "n/a" if not np.isfinite(gap) else f"cost gap to runner-up {gap:.1f}"
    lines.append(f"  axes         {b} -> {a}  ({conf})")
    return lines


def _fmt(u, mult) -> str:
    if u is None or not np.isfinite(u):
        return "?"
    return f"{u * mult:.3g}"


def calibrate_command(args, say, load_capture) -> None:
    """`gyrodeblur calibrate PHOTO... --capture C.json -o OUT.json`."""
    from .imageio import check_destination, read_photo

    photos = [read_photo(p) for p in args.photos]
    check_destination(args.output, None, args.overwrite, image=False)
    fix = {f.strip() for f in args.fix.split(",") if f.strip()}
    caps = []
    for ph in photos:
        caps.append(load_capture(args, ph, say))
    res = calibrate([p.pixels for p in photos], caps, fix=fix, say=say)
    say(f"calibration of {len(photos)} photo(s) (before -> after):")
    for line in format_estimates(res.estimates):
        say(line)
    src = caps[0].source
    gyro_rel = caps[0].gyro_spec.get("path")
    if src and src != "capture" and gyro_rel is not None:
        gyro_abs = os.path.join(os.path.dirname(os.path.abspath(src)), gyro_rel)
        gyro_rel = os.path.relpath(gyro_abs, os.path.dirname(os.path.abspath(args.output)))
    tmp = args.output + ".part"
    try:
        res.capture.save(tmp, gyro_path=gyro_rel)
        os.replace(tmp, args.output)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    say(f"wrote {args.output}")
