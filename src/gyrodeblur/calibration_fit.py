"""The search of a calibration: working scales and patches, the coarse ranking of the axis
mappings, the candidates' starts and refinements, the winner's further refinements, and
the mirror-twin check.

:func:`gyrodeblur.calibrate.calibrate` runs these steps in order and decides what to
report and what to keep; its module docstring (Search) tells why each step is there and
what it bought on the benchmark. The criterion is :mod:`gyrodeblur.spectral_criterion`;
parameter vectors, bounds and Levenberg-Marquardt are :mod:`gyrodeblur.calibration_search`.
"""

from __future__ import annotations

import numpy as np

from .axes import axes_to_letters
from .bias_prior import PRIOR_BIAS, BiasPrior
from .calibration_patches import patch_centres
from .calibration_search import (X_NAMES, SearchSpace, line_fit, line_fit_minima, lm_refine,
                                 objective, psf_extent_and_path)
from .capture import UNKNOWN_READOUT_MAX, UNKNOWN_READOUT_PRIOR
from .errors import InputError
from .frame_registration import FrameRegistration
from .spectral_criterion import Corrections, PatchSpectra

__all__ = ["CalibrationFit", "relative_ranking", "shortlist", "with_twin", "TWIN",
           "OFFSET_APART", "OFFSET_RIVAL_NATS", "BLOCKY", "COMPRESSED_BAND", "FINE_ROWS",
           "fine_samples", "spectral_band"]

#: The mirror twin of a mapping ``M`` is ``TWIN @ M``: the camera's x and y rates negated
#: (a proper rotation), which nearly reflects every PSF (see Search, 3).
TWIN = np.diag([-1.0, -1.0, 1.0])
#: The Whittle cost over-counts (neighbouring frequencies of a Hann-windowed patch are
#: correlated, images are not Gaussian): on the benchmark cases the patch-sandwich
#: variance of the estimates is 15-170x the Fisher variance, median ~100. The cost is
#: divided by this before the priors are added.
_TEMPERATURE = 100.0
#: Prior standard deviations around the given capture: readout (fraction), log focal scale,
#: bias (rad/s per axis). They matter only where the photo cannot tell (e.g. focal length
#: against a bias along a nearly straight, uniform motion).
_PRIOR_READOUT = 0.3
_PRIOR_FOCAL = 0.1
#: Starts refined per candidate mapping (the best line fits over time shift x readout x
#: focal scale that differ by more than these, s): on the 24-case benchmark 3 starts rather
#: than 1 got 22 rather than 21 mappings right and a mean PSNR gap of -3.67 rather than
#: -4.05 dB, for 40 % more time.
_CANDIDATE_STARTS = 3
_DISTINCT_SHIFT = 0.004
_DISTINCT_READOUT = 0.006
#: Time shifts scanned around the winner's (s): step, reach either side, and how many of
#: the best (after four iterations) are refined fully.
_SCAN_STEP = 0.002
_SCAN_REACH = 0.006
_SCAN_REFINED = 2
#: Readout corrections (fractions of the given readout time) scanned at the winner's
#: mid-row time.
_READOUT_SCAN = (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3)
#: Readout times (s) scanned there where none was given (see
#: :data:`~gyrodeblur.capture.UNKNOWN_READOUT_MAX`).
_UNKNOWN_READOUT_SCAN = (0.0, 0.006, 0.012, 0.018, 0.024, 0.03, 0.036, 0.045)
#: s: where no readout was given, the given parameters are judged against the best found
#: (of the given mapping) at their best readout within this of the best found's (the
#: given offset held). At their best readout anywhere, an offset error hid in it: a
#: shorter readout with an earlier offset (or a longer with a later) keeps the middle
#: rows' times, and the photo tells the two apart only weakly (session 66: a held-out audit's 12 ms error kept with 45 ms for a true 25, 19.9
#: dB against 30.1; 3 of 24 benchmark photos given 9-18 ms errors kept). Exactly at the
#: best found's, a right capture was moved where the best found had slid along that
#: ridge (1 of 24: 1.4 ms and 2.1 ms off, -4.7 dB). 6 ms, the scan's step, is about twice
#: the readout's stated uncertainty there, and takes an offset error of about 3 ms.
JUDGED_READOUT_REACH = 0.006
#: Another basin of the chosen mapping whose time offset lies more than ``OFFSET_APART``
#: (s) from the estimate and whose objective is within ``OFFSET_RIVAL_NATS`` of it is
#: reported: the photo cannot tell the two offsets apart.
OFFSET_APART = 0.003
OFFSET_RIVAL_NATS = 2.0
#: Without a frame registration the mirror twin, refined from the winner's parameters, is
#: taken when the spectra cannot tell the two apart (the twin's objective is less than
#: ``_TWIN_TIE_NATS`` worse than the winner's, the threshold under which
#: :data:`OFFSET_RIVAL_NATS` calls two offsets indistinguishable) and the phase prefers it
#: by ``_TWIN_SIGMAS`` standard errors of its mean over the patches (a blur of a few pixels
#: has hardly any phase: a coin toss keeps the winner; with a single patch there is no
#: standard error, and the phase never swaps). Until session 19 the twin was scored at the
#: winner's parameters unrefined, and kept out by a spectral gap of 40 nats per patch there:
#: roll and the rolling shutter do not mirror, so a right twin sits a little away from the
#: wrong winner's optimum (lai_manmade_02_w1, 29 px: +69 nats per patch unrefined, 0.8
#: better refined). Until session 36 the twin had to be no worse at all: the same photo's
#: right twin, refined, scored -0.6 in one run and +0.3 in the next, and was left out.
_TWIN_SIGMAS = 2.0
_TWIN_TIE_NATS = 2.0
#: A tie (objectives within ``_TWIN_TIE_NATS``) that the phase decides by fewer standard
#: errors than this is reported as an uncertain mapping (:meth:`CalibrationFit.mirror_twin`).
_TWIN_CLEAR_SIGMAS = 3.0
#: The phase is measured on up to this many times the fit's patches (the next most
#: textured windows): on the 24 benchmark cases (shared log, session 36) 27 patches rather
#: than 9 made the right winners' phase preference 1.4x as many standard errors (median),
#: and the synthetic log's one right twin's 3.3 -> 4.8.
_TWIN_PATCH_FACTOR = 3
_TARGET_EXTENT = 32.0      # px: working scale makes the largest PSF about this long
_PATCH = 128               # px: patch side at working scale
_COARSE_EXTENT = 16.0      # px: the same for the coarse search
#: px: a working-scale patch side below this says too little (the fit refuses the photos,
#: the blind kernel check gives no verdict)
SMALLEST_PATCH = 48
_COARSE_PATCH = 64
_COARSE_STEP = 0.002       # s: time-shift grid of the coarse search
#: Over a coarse time-shift grid spanning more than ``WIDE_SPAN`` (s; the default offset
#: range spans 0.08 s), each candidate mapping is started from its ``WIDE_MINIMA`` best
#: distinct coarse minima, more than ``WIDE_APART`` (s) apart, not from its best alone: over
#: +-0.5 s of log the coarse grid's best lay in another basin than the truth's in 5 of 24
#: benchmark photos, and in the two checked the truth's basin, refined, scored 13-14 lower.
WIDE_SPAN = 0.1
WIDE_MINIMA = 3
WIDE_APART = 0.02
#: A photo whose 8 px block grid is this strong (:meth:`CalibrationPhoto.blockiness`) is
#: taken for a compressed JPEG, and the criterion keeps frequencies up to
#: ``COMPRESSED_BAND`` cycles per pixel of the photo rather than 0.42: JPEG quantisation
#: empties the top of the spectrum, which reads as blur. The calibration benchmark's 48
#: photos (shared log and gentler shake): 1.00-1.08 uncompressed; saved as JPEG, 1.01-1.40
#: at quality 95, 1.04-1.62 at 90 and 1.05-1.92 at 80. Photos blurred from a scene that was
#: a JPEG measured 1.11-1.17 (three gentler-shake text photos, and lai_text_02_w2 1.14)
#: before the grid had to be in line with the photo's first row or column, or show on
#: both axes: the cut cost two of the three 2.2 and 4.9 dB and gained the third 0.8 dB
#: (BENCHMARKS.md, section 4, session 57). On the PNG benchmark the cut
#: for every photo cost too much to be the rule (section 4, session 12).
BLOCKY = 1.10
COMPRESSED_BAND = 0.3
#: Rows of each fine patch whose rolling-shutter timings are averaged (fractions of the
#: patch side from its centre), with weights 1/4, 1/2, 1/4.
FINE_ROWS = (-0.15, 0.0, 0.15)


def fine_samples(path: float, scale: float) -> int:
    """Trace samples per PSF at the fine working ``scale`` for a blur path of ``path``
    full-resolution px: one per 0.5 working px with 30 % to spare, 32 to 400."""
    return int(np.clip(np.ceil(1.3 * path * scale / 0.5), 32, 400))


def spectral_band(blockiness: float) -> float:
    """The top of the band the criterion reads (cycles per photo pixel): all of it, or
    :data:`COMPRESSED_BAND` for a photo whose 8 px block grid (JPEG's) exceeds
    :data:`BLOCKY`."""
    return COMPRESSED_BAND if blockiness > BLOCKY else np.inf


class CalibrationFit:
    """The fitting context of one calibration: working scales, the patches at the fine and
    coarse scales (:attr:`fine`, :attr:`coarse`), the frame registration, the free
    coordinates with their bounds, steps and priors; and each step of the search (see the
    docstring of :mod:`gyrodeblur.calibrate`, Search).

    Parameter vectors ``x`` are those of :class:`gyrodeblur.calibration_search.SearchSpace`;
    :meth:`refine` and :meth:`refine_winner` return what
    :func:`gyrodeblur.calibration_search.lm_refine` does: ``(x, objective, Gauss-Newton
    Hessian, per-patch scores)``."""

    def __init__(self, photos, search: SearchSpace, fix: set, bias_prior: BiasPrior,
                 n_patches: int, n_mappings: int, say):
        self.search, self.fix, self.bias_prior, self.say = search, fix, bias_prior, say
        self.basins: list = []          # (x, objective) of the winner's full refinements
        self.theta0 = Corrections(axes=photos[0].cap.axes)
        # working scales and patches from the blur at the given parameters
        probe = [search.tau_lo, 0.5 * search.tau_lo, 0.0, 0.5 * search.tau_hi, search.tau_hi]
        extent, path = psf_extent_and_path(photos, self.theta0, sorted(set(probe)))
        extent = max(extent, 2.0)
        small = min(min(ph.H, ph.W) for ph in photos)
        s_f, P_f = working_patch(extent, small)
        s_c, P_c = working_patch(extent, small, _COARSE_EXTENT, _COARSE_PATCH)
        if P_f < SMALLEST_PATCH or P_c < 32:
            raise InputError(None, f"the photos are too small ({small} px) for the blur "
                                   f"(~{extent:.0f} px) to be calibrated")
        per = max(3, int(np.ceil(n_patches / len(photos))))
        centres = patch_centres(photos, per, int(round(P_f / s_f)))
        if not centres:
            raise InputError(None, "no textured, unsaturated patch found for calibration")
        # a JPEG's quantisation empties the top of the spectrum, which would read as blur
        self.blockiness = max(ph.blockiness() for ph in photos)
        self.band = spectral_band(self.blockiness)
        n_fine = fine_samples(path, s_f)
        self.fine = PatchSpectra(photos, centres, s_f, P_f, rows=FINE_ROWS, across=True,
                                 n_samples=n_fine, band=self.band)
        self._phase_args = (photos, per, s_f, P_f, n_fine)
        self._phase = None
        self.coarse = PatchSpectra(photos, centres, s_c, P_c, rows=(0.0,), envelope=False,
                                   n_samples=int(np.clip(np.ceil(1.3 * path * s_c / 0.7), 24, 200)),
                                   band=self.band)
        u = np.array([y / photos[i].H for i, _, y in self.fine.points])
        # pivot row of the (time shift, readout) parametrisation: the mean patch row, so the
        # two are nearly uncorrelated; with the offset fixed the time shift stays 0
        self.ubar = 0.0 if "offset" in fix else float(u.mean())
        self.uc = u - 0.5
        say(f"calibrating on {len(centres)} patches of {P_f} px at scale {self.fine.scale:.2f} "
            f"(coarse: {P_c} px at {self.coarse.scale:.2f}; blur ~{extent:.0f} px), "
            f"{n_mappings} axis mapping(s)")
        self.reg = FrameRegistration(photos, extent) if len(photos) > 1 else None
        if self.reg is not None and self.reg.pairs:
            for a_, b_, d, sig, q in self.reg.pairs:
                say(f"  photos {a_ + 1} -> {b_ + 1}: image motion ({d[0]:+.1f}, {d[1]:+.1f}) px "
                    f"(phase correlation, prominence {q:.1f}), weight 1/{sig:.1f} px")
        # the search grids, the free coordinates, their bounds, steps and priors
        if search.tau_hi > search.tau_lo:
            self.taus = np.arange(search.tau_lo, search.tau_hi + 1e-9, _COARSE_STEP)
        else:
            self.taus = np.array([search.tau_lo])
        if search.readout_unknown:          # readouts of 0-40 ms, as corrections
            self.kappas = np.linspace(0.0, 0.8 * UNKNOWN_READOUT_MAX, 8) - search.r0
        elif "readout" in fix or search.r0 == 0:
            self.kappas = np.array([0.0])
        else:
            self.kappas = search.r0 * np.linspace(-0.35, 0.35, 8)
        self.fgrid = [1.0] if "focal" in fix else [0.8, 0.87, 0.94, 1.0, 1.07, 1.15, 1.25]
        self.idx = [X_NAMES.index(k) for k in search.free()]
        self.lo, self.hi = search.bounds(self.ubar)
        self.hs = np.array([0.0005, 0.001, 0.01, 0.004, 0.004, 0.004])    # finite differences
        self.caps = np.array([0.004, max(0.15 * search.r0, 0.004), 0.08, 0.03, 0.03, 0.03])
        self.prior_sig = np.array([np.inf, max(_PRIOR_READOUT * search.r0, 0.002), _PRIOR_FOCAL,
                                   PRIOR_BIAS, PRIOR_BIAS, PRIOR_BIAS])
        self.prior_mu = np.zeros(6)
        if search.readout_unknown:          # no given value: a weak prior over likely ones
            self.caps[1] = 0.006
            self.prior_mu[1] = UNKNOWN_READOUT_PRIOR[0] - search.r0
            self.prior_sig[1] = UNKNOWN_READOUT_PRIOR[1]

    # -- pieces -------------------------------------------------------------------------
    def theta_of(self, M):
        return lambda v: self.search.theta_of(v, M, self.ubar)

    def prior_for(self, M):
        """(mean, sd, temperature) of the priors for mapping ``M``: the bias's combines
        the given bias with the log's typical rate, when the log is long enough."""
        mu, sig = self.prior_mu.copy(), self.prior_sig.copy()
        mu[3:6], sig[3:6] = self.bias_prior.for_mapping(M)
        return mu, sig, _TEMPERATURE

    def extra_for(self, M):
        """The frame registration's residuals for mapping ``M`` (``None`` without one)."""
        reg = self.reg
        if reg is None or not reg.pairs:
            return None
        return lambda v: reg.residuals(self.search.theta_of(v, M, self.ubar))

    def moved_bias(self, M, bias_step=None) -> np.ndarray:
        """The prior's bias under mapping ``M`` (rad/s, camera frame), moved by
        ``bias_step`` when given."""
        bias = self.bias_prior.for_mapping(M)[0]
        return bias if bias_step is None else bias + bias_step

    def start_vec(self, tau0, kap, M, fo=1.0, bias_step=None):
        """A start from a line fit (time shift ``tau0`` at the middle row, readout error
        ``kap``), focal scale ``fo`` and the prior's bias (moved by ``bias_step``, rad/s,
        camera frame, when given)."""
        x = np.zeros(6)
        x[3:6] = self.moved_bias(M, bias_step)
        x[1] = kap
        x[0] = 0.0 if "offset" in self.fix else tau0 + kap * (0.5 - self.ubar)
        x[2] = np.log(fo)
        return np.clip(x, self.lo, self.hi)

    def phase_patches(self) -> PatchSpectra:
        """The patches the mirror twin's phase test is scored on: as the fine ones, but
        up to :data:`_TWIN_PATCH_FACTOR` times as many (made once, when first needed)."""
        if self._phase is None:
            photos, per, s_f, P_f, n_fine = self._phase_args
            centres = patch_centres(photos, _TWIN_PATCH_FACTOR * per, int(round(P_f / s_f)))
            self._phase = PatchSpectra(photos, centres, s_f, P_f, rows=FINE_ROWS,
                                       n_samples=n_fine, envelope=False, band=self.band)
        return self._phase

    def refine(self, M, x0, iters, which=None):
        """Levenberg-Marquardt under mapping ``M`` from ``x0``: (x, f, F, scores)."""
        return lm_refine(self.fine, self.theta_of(M), x0, self.idx if which is None else which,
                         self.lo, self.hi, self.hs, self.caps, self.prior_for(M), iters=iters,
                         extra=self.extra_for(M))

    def given_objective(self, M, readout=None) -> tuple[float, np.ndarray]:
        """The objective of the given parameters under mapping ``M`` (the bias the prior's),
        and their vector. A readout that was not given (0 only as a placeholder) is no
        given parameter: theirs is the best for them (the given time offset held), of
        :data:`_UNKNOWN_READOUT_SCAN` (those the bounds allow) and the minimum of a
        parabola through the best and its neighbours, so that keeping the given
        parameters does not make the photo a global shutter's. Given ``readout`` (a
        readout correction, s: the best found's), the best within
        :data:`JUDGED_READOUT_REACH` of it, as near as the bounds allow: there they are
        judged against the best found (see :data:`JUDGED_READOUT_REACH`)."""
        x0 = np.clip(np.r_[0.0, 0.0, 0.0, self.bias_prior.for_mapping(M)[0]], self.lo, self.hi)
        f = self._given_with_readout(M, x0)
        if not (self.search.readout_unknown and 1 in self.idx):
            return f(0.0)
        if readout is not None:         # the bounds on the readout, and on the time shift
            lo = max(self.lo[1], (x0[0] - self.hi[0]) / self.ubar if self.ubar > 0 else -np.inf)
            hi = min(self.hi[1], (x0[0] - self.lo[0]) / self.ubar if self.ubar > 0 else np.inf)
            reach = JUDGED_READOUT_REACH * np.linspace(-1.0, 1.0, 5)
            return self._best_readout(f, np.unique(np.clip(readout + reach, lo, hi)))
        kappas = np.array(_UNKNOWN_READOUT_SCAN) - self.search.r0
        # the readouts the bounds allow with the given offset held
        tau = x0[0] - self.ubar * kappas
        ok = ((kappas >= self.lo[1]) & (kappas <= self.hi[1])
              & (tau >= self.lo[0]) & (tau <= self.hi[0]))
        return self._best_readout(f, kappas[ok] if ok.any() else np.array([0.0]))

    @staticmethod
    def _best_readout(f, kappas: np.ndarray) -> tuple[float, np.ndarray]:
        """``f`` (:meth:`_given_with_readout`) at the best of the readout corrections
        ``kappas`` (ascending) and the minimum of a parabola through the best and its
        neighbours."""
        scores = [f(k)[0] for k in kappas]
        if len(kappas) >= 3:             # a parabola through the best and its neighbours
            i = int(np.clip(np.argmin(scores) - 1, 0, len(kappas) - 3))
            curv, slope, _ = np.polyfit(kappas[i:i + 3], scores[i:i + 3], 2)
            if curv > 0:                 # convex: its vertex, within the three
                k = float(np.clip(-slope / (2 * curv), kappas[i], kappas[i + 2]))
                kappas, scores = np.r_[kappas, k], scores + [f(k)[0]]
        return f(kappas[int(np.argmin(scores))])

    def _given_with_readout(self, M, x0):
        """``kappa -> (objective, x)``: the given parameters ``x0`` under mapping ``M``
        with the readout correction ``kappa`` (s), the given time offset held."""
        def f(kappa):
            x = x0.copy()
            x[1] = kappa
            x[0] = x0[0] - self.ubar * kappa           # the given offset held
            return objective(self.fine, self.theta_of(M), x, self.idx, self.prior_for(M),
                             self.extra_for(M)), x
        return f

    # -- steps --------------------------------------------------------------------------
    def coarse_rankings(self, cand, steps, bias_steps=(None,), envelopes=(False, True),
                        stride: int = 1) -> list[list]:
        """Per coarse criterion (flat, then fitted envelope; or those of ``envelopes``), the
        mappings' rows ``(score, time shift, readout error, 1.0, M, others, bias step)``
        (see :meth:`coarse_row`), best first (the rows computed by ``steps``, a
        :class:`gyrodeblur.calibration_workers.StepRunner`). With several ``bias_steps``
        (rad/s, camera frame, each added to the prior's bias; ``None``: none) each
        mapping's row is its best over them; ``stride`` > 1 takes every stride-th time
        shift of the coarse grid."""
        jobs = [(tuple(envelopes), M, b, stride) for M in cand for b in bias_steps]
        rows = steps.map("coarse_rows", jobs)
        per = len(cand) * len(bias_steps)
        rankings = []
        for k, envelope in enumerate(envelopes):
            mine = [r[k] for r in rows]
            best = [min(mine[j:j + len(bias_steps)], key=lambda r: r[0])
                    for j in range(0, per, len(bias_steps))]
            scored = sorted(best, key=lambda r: r[0])
            rankings.append(scored)
            ranking = relative_ranking(scored)
            moved = ", the bias moved by up to a prior sd" if len(bias_steps) > 1 else ""
            self.say(f"coarse ranking ({'fitted' if envelope else 'flat'} envelope{moved}): "
                     + ", ".join(f"{a} {c:+.0f}" for a, c in ranking[:6]))
        return rankings

    def coarse_row(self, envelope: bool, M, bias_step=None, stride: int = 1) -> tuple:
        """Mapping ``M``'s row of a coarse ranking (per-patch envelopes fitted to each
        evaluation or flat) at the prior's bias plus ``bias_step`` (rad/s, camera frame;
        ``None``: none): the per-patch costs over the time shifts combined along the
        readout line, ``(score, time shift, readout error, 1.0, M, others, bias_step)``.
        ``others``: over a wide offset range (:data:`WIDE_SPAN`), the ``(time shift,
        readout error)`` of up to :data:`WIDE_MINIMA` - 1 further distinct minima; else
        empty. ``stride`` > 1 takes every stride-th time shift of the coarse grid."""
        return self.coarse_rows((envelope,), M, bias_step, stride)[0]

    def coarse_rows(self, envelopes, M, bias_step=None, stride: int = 1) -> list[tuple]:
        """:meth:`coarse_row` under each of ``envelopes`` (``True``: fitted, ``False``:
        flat), the coarse spectra made once for all of them (each row as
        :meth:`coarse_row` alone makes it)."""
        taus = self.taus[::stride]
        theta = self.theta0.copy(axes=M, bias=self.moved_bias(M, bias_step))
        rows = []
        for C in self.coarse.costs_under(envelopes, theta, taus):
            tot, tau0, kap = line_fit(C, taus, self.uc, self.kappas)
            others = ()
            if taus[-1] - taus[0] > WIDE_SPAN:
                minima = line_fit_minima(C, taus, self.uc, self.kappas, WIDE_MINIMA, WIDE_APART)
                others = tuple((t, k) for _, t, k in minima if abs(t - tau0) > WIDE_APART)
            rows.append((tot, tau0, kap, 1.0, M, others, bias_step))
        return rows

    def candidates(self, rows, steps) -> list:
        """The coarse ``rows`` (``(score, time shift, readout error, 1.0, M, others, bias
        step)``) at the working scale: each mapping's starts (:meth:`candidate_starts`, from
        its coarse minimum and from ``others``, its further minima over a wide range, at the
        prior's bias moved by its bias step), then from all of
        them Levenberg-Marquardt, 4 iterations, in one batch of ``steps`` (a
        :class:`gyrodeblur.calibration_workers.StepRunner`), so that no mapping's starts
        wait for each other. Per mapping, in the order of ``rows``: (objective, x, M, the
        other starts' results)."""
        # a mapping's coarse minimum, and over a wide range its further distinct ones
        jobs = [(k, (t, kap, r[4], r[6])) for k, r in enumerate(rows)
                for t, kap in ((r[1], r[2]),) + r[5]]
        starts = [[] for _ in rows]
        for (k, _), xs in zip(jobs, steps.map("candidate_starts", [job for _, job in jobs])):
            starts[k] += xs
        refined = iter(steps.map("refine", [(r[4], x0, 4) for r, xs in zip(rows, starts)
                                            for x0 in xs]))
        out = []
        for r, xs in zip(rows, starts):
            M = r[4]
            mine = [next(refined)[:2] for _ in xs]
            x, fx = min(mine, key=lambda t: t[1])       # the first of equals
            alts = [xa for xa, _ in mine]
            self.say(f"  candidate {axes_to_letters(M) or 'given'}: time shift {x[0] * 1e3:+.1f} ms, "
                     f"readout {x[1] * 1e3:+.1f} ms, focal x{np.exp(x[2]):.3f}: objective {fx:.1f}")
            out.append((fx, x, M, [a for a in alts if a is not x]))
        return out

    def candidate_starts(self, tau0, kap, M, bias_step=None) -> list:
        """Mapping ``M``'s starts at the working scale: per-patch time shifts x focal grid
        with the envelopes held from the coarse start (``tau0``, ``kap``), combined along
        the readout line; the best few that differ in time shift (at the pivot row) or
        readout, as parameter vectors (the refinement from the best line fit alone can stop
        in the wrong basin)."""
        search = self.search
        if "offset" in self.fix:
            tm = np.array([0.0])
        else:
            tm = np.arange(tau0 - 0.016, tau0 + 0.0161, _COARSE_STEP)
            tm = tm[(tm >= search.tau_lo - 1e-9) & (tm <= search.tau_hi + 1e-9)]
            if tm.size == 0:
                tm = np.array([float(np.clip(tau0, search.tau_lo, search.tau_hi))])
        x_start = self.start_vec(tau0, kap, M, bias_step=bias_step)
        self.fine.set_envelope(search.theta_of(x_start, M, self.ubar))
        starts = []
        for fo in self.fgrid:
            C = self.fine.costs(self.theta0.copy(axes=M, focal=fo, bias=x_start[3:6]),
                                taus=tm, rows=(0.0,))
            for kp in self.kappas:
                tot, t0, k1 = line_fit(C, tm, self.uc, [kp])
                starts.append((tot, t0, k1, fo))
        starts.sort(key=lambda r: r[0])
        chosen = [starts[0]]
        for r in starts[1:]:
            if len(chosen) >= _CANDIDATE_STARTS:
                break
            if all(abs((r[1] - c[1]) + (r[2] - c[2]) * (0.5 - self.ubar)) > _DISTINCT_SHIFT
                   or abs(r[2] - c[2]) > _DISTINCT_READOUT for c in chosen):
                chosen.append(r)
        return [self.start_vec(c[1], c[2], M, c[3], bias_step) for c in chosen]

    def refine_winner(self, M, x, alts, steps):
        """The winning mapping's refinement from its best start, its other starts, the
        given focal length and bias, and time shifts around its own: the lowest objective
        (x, f, F, scores). Every basin reached is kept in :attr:`basins`. Independent
        refinements run side by side in ``steps`` (a
        :class:`gyrodeblur.calibration_workers.StepRunner`)."""
        self.basins = []
        # The winner's other starts, refined as far: four iterations do not always tell which
        # basin is lowest (a time shift 5 ms off can lead after four and trail after fourteen).
        best = _lowest_of(steps.map("refine_fully", [(M, x)] + [(M, xa) for xa in alts]))
        # Focal length and a bias along the motion trade off (see Criterion), and the valley
        # between them holds several local minima: the coarse start's focal guess can leave
        # the refinement in one far from the given values. So the winner is refined once more
        # from the given focal length and bias (the prior's: with a long log, the log's; first
        # with the focal length held, so that the bias settles on its own), and the lower
        # objective is kept.
        idx, lo, hi = self.idx, self.lo, self.hi
        b_prior = self.bias_prior.for_mapping(M)[0]
        x = best[0]
        if any(j >= 2 for j in idx) and np.any(x[2:] != np.r_[0.0, b_prior]):
            xs = x.copy()
            xs[2:] = np.r_[0.0, b_prior]
            xs = steps.map("refine", [(M, np.clip(xs, lo, hi), 6, [j for j in idx if j != 2])])[0][0]
            best = _lowest(best, steps.map("refine_fully", [(M, xs)])[0])
        # Last, time shifts around the winner's, every _SCAN_STEP up to _SCAN_REACH away, from
        # the given (prior) values of the other parameters: the coarse start's line fits can
        # miss a nearby basin that the fine cost prefers; the best _SCAN_REFINED are refined
        # as far.
        if "offset" not in self.fix:
            x = best[0]
            starts, tried = [], {round(float(x[0]), 6)}
            r_start = x[1] if self.search.readout_unknown else 0.0   # no given value to try
            for dt in np.arange(-_SCAN_REACH, _SCAN_REACH + 1e-9, _SCAN_STEP):
                xs0 = np.clip(np.r_[x[0] + dt, r_start, 0.0, b_prior], lo, hi)
                if round(float(xs0[0]), 6) in tried:   # the winner's own, or clipped to a bound
                    continue
                tried.add(round(float(xs0[0]), 6))
                starts.append(xs0)
            best = self._scan(M, starts, best, steps)
        # And readout times across the prior's range at the winner's mid-row time: with the
        # rows between well timed, a readout 30-40 % off can sit in a basin of its own
        # (the top and bottom patches then fit other parts of the trace).
        if "readout" not in self.fix and (self.search.r0 > 0 or self.search.readout_unknown):
            x, r0, starts = best[0], self.search.r0, []
            if self.search.readout_unknown:    # readouts across the searched range
                scan = np.array(_UNKNOWN_READOUT_SCAN) - r0
                near = 0.4 * (_UNKNOWN_READOUT_SCAN[1] - _UNKNOWN_READOUT_SCAN[0])
            else:
                scan, near = np.array(_READOUT_SCAN) * r0, 0.05 * r0
            for dr in scan:
                if abs(dr - x[1]) < near:
                    continue
                xs0 = x.copy()
                xs0[1] = dr
                starts.append(np.clip(xs0, lo, hi))
            best = self._scan(M, starts, best, steps)
        return best

    def _scan(self, M, starts, best, steps):
        """``starts`` refined four iterations each, the best :data:`_SCAN_REFINED` of them
        refined as far as the winner: the lowest objective of those and ``best``."""
        scan = sorted((r[:2] for r in steps.map("refine", [(M, xs0, 4) for xs0 in starts])),
                      key=lambda r: r[1])
        return _lowest_of([best] + steps.map("refine_fully",
                                             [(M, xs0) for xs0, _ in scan[:_SCAN_REFINED]]))

    def refine_fully(self, M, x0):
        """:meth:`refine` as far as the winner (ten iterations), the basin reached kept in
        :attr:`basins` as ``(x, objective)``."""
        r = self.refine(M, x0, 10)
        self.basins.append((r[0], r[1]))
        return r

    def offset_rivals(self, M, x, f) -> list[tuple[float, float, float]]:
        """Of :attr:`basins`, those whose time offset correction lies more than
        :data:`OFFSET_APART` from ``x``'s and whose objective is within
        :data:`OFFSET_RIVAL_NATS` of ``f``: ``(offset correction (s), readout correction
        (s), objective - f)``, one per offset (the lowest), best first. (A basin of another
        readout at the same mid-frame timing has another offset too: the offset is the
        first row's.)"""
        if "offset" in self.fix:
            return []
        at = self.search.theta_of(x, M, self.ubar).offset
        rivals = []
        for xb, fb in sorted(self.basins, key=lambda b: b[1]):
            tb = self.search.theta_of(xb, M, self.ubar)
            if (abs(tb.offset - at) > OFFSET_APART and fb - f < OFFSET_RIVAL_NATS
                    and all(abs(tb.offset - o) > OFFSET_APART for o, _, _ in rivals)):
                rivals.append((tb.offset, tb.readout, float(fb - f)))
        return rivals

    def mirror_twin(self, M, x, f, given_biases):
        """Mapping ``M`` at ``x`` (objective ``f``) against its mirror twin: by the frame
        registration at the same parameters when there is one, else refined from them and
        judged by :func:`_phase_prefers_twin`.

        Returns
        -------
        taken : ndarray (3, 3)
            The mapping taken.
        twin : tuple or None
            The twin's refinement when the twin is taken.
        note : str
            What was compared, and the decision.
        tie : tuple or None
            ``(other, objective gap, z)`` when the phase decided a tie it could not
            settle (the two objectives within :data:`_TWIN_TIE_NATS` and the phase's
            preference for the mapping taken under :data:`_TWIN_CLEAR_SIGMAS` standard
            errors), or when the two judges disagree (the objective keeps the winner by
            :data:`_TWIN_TIE_NATS` or more, while the phase prefers the twin by
            :data:`_TWIN_CLEAR_SIGMAS` standard errors or more: ``z`` is then negative).
            ``other`` is the mapping left, ``objective gap`` its objective minus the taken
            one's (tempered nats), ``z`` the phase's preference for the taken one
            (standard errors). ``None`` otherwise; the caller reports a gap under its
            confidence margin as an uncertain mapping.
        """
        Mt = TWIN @ M
        xt = np.clip(_twin_parameters(x, given_biases, self.fix), self.lo, self.hi)
        th_w = self.search.theta_of(x, M, self.ubar)
        th_t = self.search.theta_of(xt, Mt, self.ubar)
        self.fine.set_envelope(th_w)
        c_w = self.fine.cost(th_w)          # (the spectra the envelope fit just computed)
        per_patch = (self.fine.cost(th_t) - c_w) / len(self.fine.points)
        msg = (f"mirror twin {axes_to_letters(Mt)} at the same parameters: spectra "
               f"{per_patch:+.1f} nats/patch")
        reg = self.reg
        tie = None
        if reg is not None and reg.pairs:
            r_w = float(np.sum(reg.residuals(th_w) ** 2))
            r_t = float(np.sum(reg.residuals(th_t) ** 2))
            msg += f", registration chi2 {r_w:.1f} vs {r_t:.1f}"
            twin = self.refine(Mt, xt, 6) if r_t < r_w else None
        else:
            twin = self.refine(Mt, xt, 6)
            th_r = self.search.theta_of(twin[0], Mt, self.ubar)
            ph = self.phase_patches()
            d = np.log(ph.sparsity(th_r) / ph.sparsity(th_w))
            margin, sem = _mean_and_error(d)
            gain = twin[1] - f
            msg += (f"; refined, objective {gain:+.1f}, sparsity {margin:+.4f} +- "
                    f"{sem:.4f} (log ratio; {int((d > 0).sum())}/{d.size} patches prefer "
                    f"{axes_to_letters(M)})")
            taken = _phase_prefers_twin(gain, d)
            z = _phase_z(d)
            if _unsettled_tie(gain, d):
                tie = (M, -gain, -z) if taken else (Mt, gain, z)
            elif not taken and z <= -_TWIN_CLEAR_SIGMAS:    # the two judges disagree
                tie = (Mt, gain, z)
            if not taken:
                twin = None
        if twin is not None:
            msg += f": {axes_to_letters(Mt)} taken"
            M = Mt
        return M, twin, msg, tie


def working_patch(extent: float, small: int, target: float = _TARGET_EXTENT,
                  largest: int = _PATCH) -> tuple[float, int]:
    """The working scale at which PSFs of ``extent`` px span at most ``target`` px, and the
    patch side there: ``largest`` px, or less (a multiple of 16) where the photos' shorter
    side, ``small`` px, holds less."""
    scale = min(1.0, target / extent)
    return scale, int(min(largest, 16 * (small * scale // 16)))


def in_twin_pair(M, N) -> bool:
    """Whether mapping ``N`` is ``M`` or its mirror twin (``TWIN @ M``)."""
    return bool(np.allclose(M, N) or np.allclose(TWIN @ M, N))


def with_twin(top: list, everything: list) -> list:
    """``top`` (coarse rows, the mapping their fifth item) plus the best row holding the
    mirror twin of its first mapping, when that is not already in."""
    if not top:
        return top
    tw = TWIN @ top[0][4]
    if any(np.allclose(tw, r[4]) for r in top):
        return list(top)
    return list(top) + [r for r in everything if np.allclose(r[4], tw)][:1]


def relative_ranking(scored: list) -> list[tuple[str, float]]:
    """``(letters, score relative to the best)`` of a coarse ranking's rows (best first)."""
    return [(axes_to_letters(r[4]) or "given", float(r[0] - scored[0][0])) for r in scored]


def shortlist(rankings: list) -> list:
    """The coarse rankings' rows merged, each ranking's best in turn, each mapping once.

    The two coarse criteria fail on different scenes (a flat 1/f^2 spectrum is misled by
    oriented texture, a fitted envelope soaks up part of a long blur)."""
    short = []
    for pair in zip(*rankings):
        for r in pair:
            if not any(np.allclose(r[4], q[4]) for q in short):
                short.append(r)
    return short


def _lowest(a: tuple, b: tuple) -> tuple:
    """Of two refinements ``(x, objective, ...)``, the one with the lower objective (``a``
    on a tie)."""
    return b if b[1] < a[1] else a


def _lowest_of(refinements: list) -> tuple:
    """The refinement with the lowest objective (the first of equals)."""
    best = refinements[0]
    for r in refinements[1:]:
        best = _lowest(best, r)
    return best


def _mean_and_error(d: np.ndarray) -> tuple[float, float]:
    """Mean of ``d`` and its standard error (infinite for fewer than two values)."""
    d = np.asarray(d, float)
    sem = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else np.inf
    return float(d.mean()), sem


def _phase_prefers_twin(gain: float, log_ratio: np.ndarray) -> bool:
    """Whether the mirror twin replaces the winner when no frame registration decides: the
    refined twin's objective is not worse by :data:`_TWIN_TIE_NATS` or more (``gain``, twin
    minus winner, tempered nats), and the per-patch log sparsity ratios (twin over winner)
    favour the twin by :data:`_TWIN_SIGMAS` standard errors of their mean."""
    margin, sem = _mean_and_error(log_ratio)
    return bool(gain < _TWIN_TIE_NATS and margin + _TWIN_SIGMAS * sem < 0)


def _phase_z(log_ratio: np.ndarray) -> float:
    """The phase's preference for the winner over its twin: the mean of the per-patch log
    sparsity ratios (twin over winner) in standard errors (0 without a standard error:
    a single patch, or identical ratios)."""
    margin, sem = _mean_and_error(log_ratio)
    return margin / sem if 0 < sem < np.inf else 0.0


def _unsettled_tie(gain: float, log_ratio: np.ndarray) -> bool:
    """Whether the twin step was a tie that the phase could not settle: the refined
    objectives within :data:`_TWIN_TIE_NATS` (``gain``, twin minus winner) and the phase's
    preference, either way, under :data:`_TWIN_CLEAR_SIGMAS` standard errors."""
    return bool(abs(gain) < _TWIN_TIE_NATS and abs(_phase_z(log_ratio)) < _TWIN_CLEAR_SIGMAS)


def _twin_parameters(x: np.ndarray, given_biases, fix=()) -> np.ndarray:
    """The parameter vector under which the mirror twin's camera rates are the winner's,
    x and y negated.

    The time shift, readout and focal scale stay. Each photo's bias is its given one
    (``given_biases``, rad/s, camera frame) plus the shared correction ``x[3:6]``, and is
    mirrored as well: exactly when the photos' given biases are equal, else in the least
    squares sense over the photos (one correction cannot mirror several biases). A fixed
    bias (``"bias"`` in ``fix``) stays as given: the twin's PSFs are then the reflections
    turned by twice its x and y components.
    """
    xt = np.array(x, float)
    if "bias" not in fix:
        b = np.mean(np.asarray(given_biases, float).reshape(-1, 3), axis=0)
        xt[3:6] = TWIN @ xt[3:6] + (TWIN - np.eye(3)) @ b
    return xt
