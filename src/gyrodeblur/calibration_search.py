"""The machinery of the calibration search: parameter vectors, bounds, line fits over
time shifts, and Levenberg-Marquardt on the tempered criterion with Gaussian priors.

The parameter vector ``x`` is ``(tmid, readout, log focal, bias x, y, z)``: the time
shift at the pivot row ``ubar`` (s), the readout-time correction (s), the log of the focal
scale, and the bias correction (rad/s, camera frame). See :mod:`gyrodeblur.calibrate`.
"""

from __future__ import annotations

import numpy as np

from .calibration_patches import CalibrationPhoto
from .capture import UNKNOWN_READOUT_MAX
from .errors import InputError
from .spectral_criterion import Corrections, PatchSpectra

__all__ = ["SearchSpace", "psf_extent_and_path", "line_fit", "line_fit_minima", "objective",
           "lm_refine", "X_NAMES"]

#: Names of the parameter vector's coordinates.
X_NAMES = ("tmid", "readout", "focal", "bias0", "bias1", "bias2")


class SearchSpace:
    """The parameter space of a calibration: the time shifts the log allows, the free
    coordinates (those not in ``fix``), their bounds, and vector -> :class:`Corrections`.

    Parameters
    ----------
    photos : list of CalibrationPhoto
        The photos (their captures set the log's coverage and the given readout time).
    fix : set of str
        Parameters not estimated (see :data:`gyrodeblur.calibrate.PARAMETERS`).
    offset_range : float
        Seconds searched on each side of the given time offset.
    """

    def __init__(self, photos: list[CalibrationPhoto], fix: set, offset_range: float):
        self.photos = photos
        self.fix = fix
        self.offset_range = float(offset_range)
        c0 = photos[0].cap
        self.r0 = c0.readout_time
        #: the given readout is a stand-in (0): searched over 0-UNKNOWN_READOUT_MAX
        self.readout_unknown = bool(c0.readout_time_unknown) and "readout" not in fix
        self.tau_lo, self.tau_hi = self._coverage()

    # -- admissible time shifts -------------------------------------------------------
    def _coverage(self) -> tuple[float, float]:
        """Time shifts (added to every capture's offset) for which the log covers every
        photo's exposure with a 30 % longer readout (a bit of slack for the search)."""
        lo, hi = -np.inf, np.inf
        for ph in self.photos:
            c = ph.cap
            span = self.longest_window(c) + 0.005
            t0 = c.log.t[0] + c.time_offset
            t1 = c.log.t[-1] + c.time_offset
            hi = min(hi, c.exposure_start - t0)               # window start after log start
            lo = max(lo, c.exposure_start + span - t1)        # window end before log end
        lo = max(lo, -self.offset_range)
        hi = min(hi, self.offset_range)
        if "offset" in self.fix:
            lo, hi = 0.0, 0.0
        if lo > hi:
            raise InputError(self.photos[0].cap.source,
                             "the gyro log does not cover the exposure window at any time "
                             "offset in the search range")
        return lo, hi

    def longest_window(self, c) -> float:
        """s: the longest a capture ``c``'s exposure window (first row's start to last
        row's end) may be in the search: its readout 60 % longer, or the longest of an
        unknown readout's range, plus the exposure time."""
        longest = UNKNOWN_READOUT_MAX if self.readout_unknown else c.readout_time * 1.6
        return longest + c.exposure_time

    def log_span(self, c) -> tuple[float, float]:
        """Where on its log's clock (s) the search may place capture ``c``'s exposure
        window: every admitted time shift, the longest window (:meth:`longest_window`)."""
        start = c.exposure_start - c.time_offset
        return start - self.tau_hi, start + self.longest_window(c) - self.tau_lo

    # -- vector <-> theta -------------------------------------------------------------
    def free(self) -> list[str]:
        out = []
        if "offset" not in self.fix:
            out.append("tmid")
        if "readout" not in self.fix:
            out.append("readout")
        if "focal" not in self.fix:
            out.append("focal")
        if "bias" not in self.fix:
            out += ["bias0", "bias1", "bias2"]
        return out

    def theta_of(self, x: np.ndarray, axes: np.ndarray, ubar: float) -> Corrections:
        return Corrections(axes=axes, offset=float(x[0] + ubar * x[1]), readout=float(x[1]),
                           focal=float(np.exp(x[2])), bias=np.array(x[3:6], float))

    def bounds(self, ubar: float):
        r0 = self.r0
        rlo, rhi = ((-r0, 0.6 * r0 + 0.003) if r0 > 0 and not self.readout_unknown
                    else (-r0, UNKNOWN_READOUT_MAX - r0))
        lo = np.array([self.tau_lo - 0.01, max(rlo, -0.6 * r0), np.log(0.7), -0.2, -0.2, -0.2])
        hi = np.array([self.tau_hi + 0.01, rhi, np.log(1.4), 0.2, 0.2, 0.2])
        return lo, hi


def psf_extent_and_path(photos, theta: Corrections, taus) -> tuple[float, float]:
    """Typical largest PSF extent and path length (full-res px) over a 3x3 grid of
    points of each photo, the median over ``taus``."""
    geo = PatchSpectra(photos, [], 1.0, 16, n_samples=96)
    ext, path = [], []
    for tau in taus:
        items = [(i, fx * (ph.W - 1), fy * (ph.H - 1), fy * (ph.H - 1), tau)
                 for i, ph in enumerate(photos) for fx in (0.1, 0.5, 0.9) for fy in (0.1, 0.5, 0.9)]
        d = geo.displacements(theta, items)
        ext.append(float(np.max(np.ptp(d, axis=1))))
        path.append(float(np.max(np.sum(np.hypot(*np.diff(d, axis=1).transpose(2, 0, 1)), 1))))
    return float(np.median(ext)), float(np.median(path))


def line_fit(C: np.ndarray, taus: np.ndarray, u: np.ndarray, kappas) -> tuple[float, float, float]:
    """Best ``sum_i C_i(tau0 - kappa u_i)`` over ``tau0`` in ``taus`` and ``kappa`` in
    ``kappas`` (each patch's cost curve ``C[:, i]`` interpolated linearly, held constant
    beyond the grid)."""
    if len(taus) == 1:
        return float(C.sum()), float(taus[0]), 0.0
    best = (np.inf, float(taus[0]), 0.0)
    for kap, tot in zip(kappas, _line_totals(C, taus, u, kappas)):
        i = int(np.argmin(tot))
        if tot[i] < best[0]:
            best = (float(tot[i]), float(taus[i]), float(kap))
    return best


def line_fit_minima(C: np.ndarray, taus: np.ndarray, u: np.ndarray, kappas, n: int,
                    apart: float) -> list[tuple[float, float, float]]:
    """Up to ``n`` distinct minima of :func:`line_fit`'s total over ``tau0`` (the best
    ``kappa`` at each), best first: each the lowest within ``apart`` / 2 (s) either side
    of it, lower than some point there (not flat ground), and more than ``apart`` from
    every better one. ``taus`` is a regular grid (its first step sets the window). For a
    search over a long stretch of log, where a far basin can lead the coarse grid yet
    lose once refined."""
    if len(taus) == 1:
        return [line_fit(C, taus, u, kappas)]
    totals = _line_totals(C, taus, u, kappas)
    k_best = np.argmin(totals, axis=0)              # the first of equal kappas
    tot = totals[k_best, np.arange(len(taus))]
    half = max(1, int(round(0.5 * apart / abs(taus[1] - taus[0]))))
    padded = np.pad(tot, half, constant_values=np.inf)
    window = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    around = np.where(np.isfinite(window), window, -np.inf).max(axis=1)
    local = (tot <= window.min(axis=1)) & (tot < around)
    out: list[tuple[float, float, float]] = []
    for i in np.argsort(tot, kind="stable"):
        if len(out) >= n:
            break
        if local[i] and all(abs(taus[i] - t) > apart for _, t, _ in out):
            out.append((float(tot[i]), float(taus[i]), float(kappas[k_best[i]])))
    return out


def _line_totals(C: np.ndarray, taus: np.ndarray, u: np.ndarray, kappas) -> np.ndarray:
    """``sum_i C_i(tau0 - kappa u_i)`` for every ``kappa`` (rows) and ``tau0`` in ``taus``."""
    out = np.zeros((len(kappas), len(taus)))
    for row, kap in zip(out, kappas):
        for j in range(C.shape[1]):
            row += np.interp(taus - kap * u[j], taus, C[:, j])
    return out


def _penalty(prior, idx, extra):
    """The objective's part beside the tempered cost, as a function of ``x``: the Gaussian
    priors on the coordinates ``idx`` and the ``extra`` residuals; and the priors'
    precisions (0 where flat)."""
    mu, sig, _ = prior
    prec = np.where(np.isfinite(sig), 1.0 / np.where(np.isfinite(sig), sig, 1.0) ** 2, 0.0)

    def pen(v):
        p = 0.5 * float(np.sum(prec[idx] * (v[idx] - mu[idx]) ** 2))
        if extra is not None:
            p += 0.5 * float(np.sum(extra(v) ** 2))
        return p

    return pen, prec


def objective(spectra: PatchSpectra, theta_of, x, idx, prior, extra=None) -> float:
    """The objective of :func:`lm_refine` at ``x`` (envelopes fitted there)."""
    pen, _ = _penalty(prior, list(idx), extra)
    spectra.set_envelope(theta_of(x))
    return spectra.cost(theta_of(x)) / prior[2] + pen(x)


def lm_refine(spectra: PatchSpectra, theta_of, x, idx, lo, hi, hs, caps, prior, *,
              iters: int = 8, refit_every: int = 2, tol: float = 0.01, extra=None):
    """Levenberg-Marquardt on ``cost / T + prior`` with the patch envelopes held (refitted
    every ``refit_every`` iterations); steps capped per coordinate (``caps``).

    ``prior = (mu, sigma, T)``: independent Gaussian priors on the coordinates (``sigma``
    inf = flat) and the temperature ``T`` dividing the Whittle cost.

    Returns ``x``, the objective, its Gauss-Newton Hessian and the per-patch scores (both
    for the free coordinates ``idx``, tempered)."""
    mu, _, T = prior
    idx = list(idx)
    x = np.array(x, float)
    pen, prec = _penalty(prior, idx, extra)

    def terms(v):
        c, g, F, sc = spectra.gauss_newton(theta_of, v, idx, hs)
        g = g / T + prec[idx] * (v[idx] - mu[idx])
        F = F / T + np.diag(prec[idx])
        if extra is not None:
            r0 = extra(v)
            if r0.size:
                J = np.empty((r0.size, len(idx)))
                for k, j in enumerate(idx):
                    y = v.copy()
                    y[j] += hs[j]
                    J[:, k] = (extra(y) - r0) / hs[j]
                g = g + J.T @ r0
                F = F + J.T @ J
        return c / T + pen(v), g, F, sc / T

    spectra.set_envelope(theta_of(x))
    lam = 1e-3
    for it in range(iters):
        if it and it % refit_every == 0:
            spectra.set_envelope(theta_of(x))
        if not idx:
            break
        c, g, F, _ = terms(x)
        moved = False
        for _ in range(5):
            A = F + lam * np.diag(np.diag(F)) + 1e-12 * np.eye(len(idx))
            try:
                d = -np.linalg.solve(A, g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            shrink = min(1.0, float(np.min(caps[idx] / np.maximum(np.abs(d), 1e-300))))
            y = x.copy()
            y[idx] = np.clip(x[idx] + shrink * d, lo[idx], hi[idx])
            fy = spectra.cost(theta_of(y)) / T + pen(y)
            if fy < c:
                moved = True
                break
            lam *= 10
        if not moved:
            break
        x = y
        lam = max(lam / 10, 1e-6)
        if c - fy < tol:
            break
    spectra.set_envelope(theta_of(x))
    c, g, F, sc = terms(x)
    return x, c, F, sc
