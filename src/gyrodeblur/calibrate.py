"""Self-calibration: fit the few parameters that turn a gyro log into a photo's PSFs.

What a gyro log gets wrong is low-dimensional: the clock offset between gyro and camera,
a constant gyro bias (3 components), the rolling-shutter readout time, the focal length
(a scale), and the axis mapping (one of the 24 proper signed axis permutations). We keep
the physics and fit only these, from the blurred photo(s) themselves: every candidate
parameter set gives, through the rotation-only model of :mod:`gyrodeblur.psf`, the PSF of
each of a few textured patches, and each patch's spectrum says how well that PSF explains
it. No free-form kernel is estimated.

Criterion
---------
Each patch is scored by the Whittle likelihood of its periodogram under a Gaussian image
with a smooth per-patch spectral envelope, blurred by the PSF the parameters imply, plus
white noise (:mod:`gyrodeblur.spectral_criterion`; patches chosen by
:mod:`gyrodeblur.calibration_patches`).

The Whittle cost over-counts (neighbouring frequencies of a windowed patch are correlated
and images are not Gaussian; on the benchmark cases the patch-to-patch spread of the
estimates is ~100x what its curvature claims), so it is divided by :data:`_TEMPERATURE`
before weak Gaussian priors around the given values are added: readout +-30 %, focal
+-10 %, bias +-0.05 rad/s. They matter where the photo cannot tell, mainly focal length
against a bias along a nearly uniform motion (a constant rate ``w`` with focal ``f`` and
``w + b`` with ``f w / (w + b)`` give the same blur).

A bias barely shows in one exposure (0.03 rad/s over 20 ms lengthens a PSF by half a
pixel at f = 1000 px), yet it moves the deblurred image, which is referenced to the first
row's start: by f b t at a row exposed t later. A long gyro log (8 s or more near the
photos) says more, and its typical rate becomes a prior on the bias
(:mod:`gyrodeblur.bias_prior`).

Search
------
1. Coarse (half the working scale, 64 px, one row per patch): for every allowed mapping,
   each patch's cost on a 2 ms grid of time shifts; a mapping's score is the best sum over
   patches along ``shift = offset + readout error x row`` (8 readout errors up to +-35 %),
   so a wrong readout does not hide the right mapping. Two rankings: with the flat
   ``1/f^2`` spectrum (misled by strongly oriented texture) and with an envelope fitted per
   evaluation (which soaks up part of a long blur); they fail on different scenes, so the
   shortlist alternates between them (on the 24-case benchmark: right mapping 21/24
   rather than 19/24 with the flat one alone, offset within 3 ms 18/24 rather than 16/24).
2. Candidates (the best five of that shortlist and the flat ranking's best one's mirror
   twin), at the working scale: starts from per-patch time shifts x 7 focal scales
   (0.8-1.25) x 8 readout errors along the same lines, envelopes held from the coarse start;
   from each of the best three that differ in time shift or readout, Levenberg-Marquardt
   (Gauss-Newton on the Whittle cost with the scale and noise profiled out,
   finite-difference Jacobians of the model spectra) on every free parameter, 4 iterations,
   the best of the three standing for the mapping. The best objective wins and is
   refined for 10 more, and so are its other starts (up to two; after four iterations the
   lowest is not always the basin that ends lowest). The focal-bias valley has several
   local minima, and the start's focal guess can strand the refinement in one far from
   the given values (focal errors of 11-28 % on 5 of the 24 benchmark cases, each with a
   higher objective than the truth refined); so the winner is also refined from its time
   shift and readout with the given focal length and bias (the bias first, the focal length
   held), and the lower objective is kept. Last, time shifts every 2 ms up to 6 ms either
   side of the winner's are started from the given values of the other parameters (four
   iterations each) and the best two refined fully: the coarse line fits can miss a nearby
   basin that the fine cost prefers. So are readout times every 10 % of the given one
   across +-30 %, at the winner's mid-row time, focal length and bias: with the middle rows
   well timed, a readout 30-40 % off can hold a basin of its own (on the 36-case benchmark:
   offsets within 3 ms 27 -> 28/36, mean PSNR gap -3.29 -> -3.13 dB, 12 % more time).
3. ``|H|`` cannot tell a PSF from its point reflection, and negating the camera's x and y
   rates (a proper rotation too) nearly reflects every PSF: only roll, perspective and the
   rolling shutter separate the two. The winner's "mirror twin" is compared at the same
   parameters, its bias mirrored with the rates unless the bias is fixed (a bias is a
   rate: left as it is, it would turn the twin's PSFs, not reflect them): by the frame
   registration below when there is one; else the twin is taken when the spectra do not
   prefer the winner by :data:`_TWIN_NATS` nats per patch or more and the phase
   (normalised gradient sparsity of the Wiener-deconvolved patches) prefers the twin, by
   two standard errors over the patches.
4. Several photos of one session share every correction (each keeps its own exposure
   start and given values); each photo has its own patches (9 each, or 18 shared out), so
   that one with little blur does not take the patches of one that says more (on the
   calibration benchmark's two-photo sessions: the right mapping for 24 of 24 photos and a
   median offset error of 0.44 ms, against 22/24 and 1.65 ms one photo at a time).
   Consecutive photos less than a second apart are also registered to each other once
   (phase correlation of the whole frames): the gyro predicts that image motion (mean
   displacement of the blurred image of a grid of scene points), which pins the sign of
   the motion and the focal length, and weakly the time offset, where blur alone is
   ambiguous (a straight pan).

5. When the best mapping is the given one, the given parameters are kept unless the best
   found lowers the tempered objective by :data:`_KEEP_MARGIN`: a correct capture on a
   photo that says little (small blur) is left alone rather than moved along directions
   the photo cannot tell apart. Another mapping must lower it by
   :data:`_KEEP_MAPPING_NATS` (a right capture of a few pixels' blur was otherwise
   switched to a mapping that scored the same). A noisy gyro makes its PSFs' fine
   structure noisy, and a fit then gains objective by following that noise (at 0.02 rad/s
   per sample, gains of 3-17 with no better PSFs); so the margin grows with the log's
   white-noise level (:func:`gyrodeblur.gyrolog.rate_noise`) above the chapter's typical phone gyro,
   0.007 rad/s: ``margin = 10 max(1, noise / 0.007)`` (in proportion, not with the
   variance: that kept real 5 ms offset errors under 0.02 rad/s noise).

Uncertainties are one-sigma marginals of the Laplace approximation of the tempered
objective (priors included). The axis mapping's confidence is the objective gap to the
best other candidate mapping; below :data:`AXES_CONFIDENT_NATS` (8) the mapping is reported
as uncertain, with a note that says what to do (on the benchmark every wrong mapping was
below 5 and every gap from 8.9 up was right).

Limits (measured, see ``benchmarks/calibration.py``): blur of a few pixels carries almost
no information; scenes dominated by horizontal and vertical edges can prefer a mapping
that turns the blur by 90 degrees; focal length and bias trade off along nearly uniform
motion; the time offset is weakly determined where the gyro rate is nearly constant; a
photo softer than its pixel grid (upscaled, heavily denoised) has an empty top octave that
reads as blur, and is calibrated shrunk (``downscale``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .axes import PROPER_AXIS_LETTERS, axes_to_letters, parse_axes
from .bias_prior import PRIOR_BIAS, BiasPrior, logs_with_captures
from .calibration_patches import CalibrationPhoto, select_patch_centres
from .calibration_search import (X_NAMES, SearchSpace, line_fit, lm_refine, objective,
                                 psf_extent_and_path)
from .capture import Capture
from .errors import InputError
from .frame_registration import FrameRegistration
from .gyrolog import rate_noise
from .spectral_criterion import Corrections, PatchSpectra

__all__ = ["calibrate", "CalibrationResult", "PARAMETERS", "AXES_CONFIDENT_NATS",
           "OFFSET_APART", "OFFSET_RIVAL_NATS"]

#: Parameters that can be estimated (and fixed with ``fix=``).
PARAMETERS = ("offset", "bias", "readout", "focal", "axes")
#: The mirror twin of a mapping ``M`` is ``TWIN @ M``: the camera's x and y rates negated
#: (a proper rotation), which nearly reflects every PSF (see Search, 3).
TWIN = np.diag([-1.0, -1.0, 1.0])


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    captures : list of Capture
        The corrected captures, one per photo (``capture`` is the first).
    estimates : dict
        ``name -> (before, after, uncertainty)`` for ``offset`` (s), ``readout`` (s),
        ``focal`` (scale), ``bias`` (rad/s, 3-vector), ``axes`` (letters; "uncertainty" =
        the objective gap to the best other candidate mapping, tempered nats). Fixed
        parameters have ``before == after`` and uncertainty ``None``; the others a
        one-sigma figure.
    ranking : list of (letters, cost)
        Axis mappings by coarse score (nats), best first, relative to the best.
    scale : float
        Working scale of the fine stage (relative to the photos as calibrated: after
        ``downscale``).
    fixed : set of str
        The parameters that were not estimated.
    seconds : float
        Wall-clock time of the calibration.
    notes : list of str
        Decisions worth reporting (twin tie-break, registration, patches).
    offset_rivals : list of (float, float, float)
        Other basins of the winning mapping that the search reached: their time offset
        (s), readout time (s) and how much higher their objective is (tempered nats), for
        offsets more than ``OFFSET_APART`` from the estimate and within
        ``OFFSET_RIVAL_NATS`` of it, best first. Empty when the offset is unambiguous as
        far as the search saw, fixed, or when the given parameters were kept.
    """

    captures: list
    estimates: dict
    ranking: list = field(default_factory=list)
    scale: float = 1.0
    fixed: set = field(default_factory=set)
    seconds: float = 0.0
    notes: list = field(default_factory=list)
    offset_rivals: list = field(default_factory=list)

    @property
    def capture(self) -> Capture:
        return self.captures[0]


# ----------------------------------------------------------------------------- settings

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
#: Objective gap (tempered nats) to the next best mapping under which the chosen axis
#: mapping is reported as uncertain. On the 24-case calibration benchmark (session 4) the
#: three wrong mappings had gaps of 3.6-4.9, every gap of 8.9 or more was right, and five
#: right ones (blurs of 3-6 px) were below 3.
AXES_CONFIDENT_NATS = 8.0
#: Another basin of the chosen mapping whose time offset lies more than ``OFFSET_APART``
#: (s) from the estimate and whose objective is within ``OFFSET_RIVAL_NATS`` of it is
#: reported: the photo cannot tell the two offsets apart.
OFFSET_APART = 0.003
OFFSET_RIVAL_NATS = 2.0
#: Spectral cost gap (nats per patch) under which mirror twins are told apart by phase.
_TWIN_NATS = 40.0
#: ... and the phase must prefer the twin by this many standard errors of its mean over
#: the patches (a blur of a few pixels has hardly any phase: a coin toss keeps the winner;
#: with a single patch there is no standard error, and the phase never swaps).
_TWIN_SIGMAS = 2.0
_TARGET_EXTENT = 32.0      # px: working scale makes the largest PSF about this long
_PATCH = 128               # px: patch side at working scale
_COARSE_EXTENT = 16.0      # px: the same for the coarse search
_COARSE_PATCH = 64
_COARSE_STEP = 0.002       # s: time-shift grid of the coarse search
_N_PATCHES = 9             # patches per photo, by default, ...
_MAX_PATCHES = 18          # ... or this many shared out (rounded up to >= 3 per photo)
#: With the given axis mapping, the given parameters are kept unless the best found lowers
#: the (tempered) objective by at least this much: a correct capture on a photo with little
#: blur is left alone rather than moved along directions the photo cannot tell apart.
_KEEP_MARGIN = 10.0
#: ... and a different mapping is taken only when it lowers it by at least this much (odds of
#: about 7 to 1 for the mapping the user gave). Until session 8 any gain would do: a right
#: capture of a 3 px blur was switched to a wrong mapping by 0.4 and lost 19 dB. The full
#: margin of 10 was tried: two benchmark photos of 3-4 px blur then kept the wrong mapping
#: they were given, which the right one beat by 4.2 and 6.7.
_KEEP_MAPPING_NATS = 2.0
#: rad/s per sample: gyro noise above this raises the keep margin (in proportion).
_TYPICAL_GYRO_NOISE = 0.007
_CANDIDATES = 5            # mappings refined at full working scale (+ the best's twin)


def calibrate(images, captures, *, fix=(), offset_range: float = 0.04,
              transfer: str = "srgb", n_patches: int | None = None, say=None,
              mappings=None, downscale: float = 1.0) -> CalibrationResult:
    """Estimate time offset, gyro bias, readout time, focal scale and axis mapping.

    Parameters
    ----------
    images : list of ndarray
        Blurred photos (float in [0, 1], (H, W) or (H, W, C)), one per capture.
    captures : Capture or list of Capture
        Their capture descriptions (one shared, or one per photo, any resolution with the
        photo's aspect ratio); the photos share the unknown corrections (one camera, one
        gyro, one session): one time-offset change, one readout change, one focal scale,
        one bias change and one axis mapping for all.
    fix : iterable of str
        Parameters not to estimate, from :data:`PARAMETERS`.
    offset_range : float
        Seconds searched on each side of the given time offset.
    transfer : str
        Transfer curve of the photos' values (``"srgb"`` or ``"linear"``).
    n_patches : int, optional
        Patches in all (spread over the photos, and over each frame; rounded up to a
        whole number per photo, at least 3). Default: 9 per photo, or 18 shared out when
        that is fewer (a photo with little blur says little: it must not crowd out the
        patches of the others).
    say : callable(str), optional
        Progress messages.
    mappings : list of str, optional
        Axis mappings to consider (default: all 24 proper signed permutations).
    downscale : float
        Calibrate on the photos shrunk by this factor (0 < ``downscale`` <= 1, area
        averaging). For photos softer than their pixel grid (upscaled, or heavily
        denoised): the spectral criterion reads an empty top octave as blur. The corrected
        captures keep the given ones' resolution.

    Returns
    -------
    CalibrationResult
    """
    t_start = time.perf_counter()
    images = list(images)
    if not images:
        raise InputError(None, "no photo to calibrate on")
    if isinstance(captures, Capture):
        captures = [captures] * len(images)
    captures = list(captures)
    if len(captures) != len(images):
        raise InputError("--capture", f"{len(images)} photos but {len(captures)} captures")
    fix = checked_fix(fix)
    say_ = say or (lambda msg: None)
    if not 0 < downscale <= 1:
        raise InputError("--downscale", f"must be in (0, 1], got {downscale!r}")
    work_caps = captures
    if downscale < 1:
        images, work_caps = _shrunk_photos(images, captures, downscale)
    if n_patches is None:
        n_patches = min(_N_PATCHES * len(images), _MAX_PATCHES)
    photos = [CalibrationPhoto(img, cap, transfer, i)
              for i, (img, cap) in enumerate(zip(images, work_caps))]
    search = SearchSpace(photos, fix, offset_range)
    c0 = photos[0].cap
    notes: list[str] = []

    def note(msg: str, indent: str = "") -> None:
        notes.append(msg)
        say_(indent + msg)

    # the bias that the log's typical rate implies, when the log is long (hand motion
    # averages out over seconds; a gyro's bias does not)
    b_given = np.mean([np.asarray(cap.bias, float) for cap in captures], axis=0)
    bias_prior, msg = BiasPrior(b_given), None
    if "bias" not in fix:
        bias_prior, msg = BiasPrior.from_logs(captures, c0.axes, b_given)
    if msg:
        note(msg)

    given_letters = axes_to_letters(c0.axes)
    cand = _candidate_mappings(c0.axes, fix, mappings)
    fit = _Fit(photos, search, fix, bias_prior, n_patches, len(cand), say_)

    # 1. coarse: every mapping x time shifts per patch, combined along a line (time offset +
    #    readout error x row); the two rankings take turns in the shortlist
    rankings = fit.coarse_rankings(cand)
    ranking = _relative(rankings[-1])
    short = _shortlist(rankings)
    # 2. candidates at full working scale, the best refined further
    top = _with_twin(short[:_CANDIDATES], rankings[0])
    results = sorted((fit.candidate(r[1], r[2], r[4]) for r in top), key=lambda r: r[0])
    _, x, M, alts = results[0]
    x, fx, Fm, sc = fit.refine_winner(M, x, alts)
    gap = float(min(r[0] for r in results[1:]) - fx) if len(results) > 1 else np.nan
    if np.isfinite(gap) and gap < 0:        # a runner-up's refinement was cut short
        gap = 0.0

    # the given parameters (with a long log, its bias) stay unless the photo(s) clearly
    # prefer others
    kept = False
    if fit.idx or len(cand) > 1:
        f_given, x0 = fit.given_objective(c0.axes)
        noise = _gyro_noise_level(captures)
        margin = _keep_margin(noise)
        if not np.allclose(M, c0.axes):
            margin *= _KEEP_MAPPING_NATS / _KEEP_MARGIN
        if np.isfinite(noise) and margin > _KEEP_MARGIN:
            note(f"gyro noise {noise:.4f} rad/s per sample: the given parameters are "
                 f"kept unless the objective improves by {margin:.0f}", "  ")
        if f_given - fx < margin:
            from_log = " (the bias from the log)" if np.any(np.abs(x0[3:6]) > 1e-4) else ""
            found = c0.time_offset + search.theta_of(x, M, fit.ubar).offset
            msg = (f"kept the given parameters{from_log}: the best found "
                   f"({axes_to_letters(M) or 'given'}, time offset {found * 1e3:+.1f} ms) "
                   f"improves the objective by only {f_given - fx:.1f} (< {margin:g})")
            x, M, fx = x0, c0.axes, f_given
            _, _, Fm, sc = fit.refine(M, x, 0)
            kept = True
            note(msg, "  ")
            others = [r[0] for r in results if not np.allclose(r[2], M)]
            gap = float(min(others) - fx) if others else np.nan

    # other offsets the photo(s) cannot tell from the chosen one: the winner's refinements
    # reached their basins (scored under the winner's mapping; a mirror twin taken below
    # starts from the winner's parameters)
    rivals = [] if kept else [(c0.time_offset + o, max(0.0, c0.readout_time + r), df)
                              for o, r, df in fit.offset_rivals(M, x, fx)]
    if rivals:
        alt = ", ".join(f"{o * 1e3:+.1f} ms (readout {r * 1e3:.1f} ms, {df:+.1f})"
                        for o, r, df in rivals[:3])
        alt += f" and {len(rivals) - 3} more" if len(rivals) > 3 else ""
        note(f"warning: the time offset is ambiguous: other offsets score within "
             f"{OFFSET_RIVAL_NATS:g} of the best: {alt}. Give the offset (--time-offset) if it "
             f"is known, or calibrate on several photos of the session", "  ")

    # 3. the mirror twin at the same parameters: |H| nearly equal; if the spectra cannot
    #    tell them apart, the phase (sparsity of the deconvolved patches) decides.
    if "axes" not in fix and len(cand) > 1 and not kept:
        M, twin, msg = fit.mirror_twin(M, x, [cap.bias for cap in captures])
        if twin is not None:
            x, fx, Fm, sc = twin
        note(msg, "  ")

    if "axes" not in fix and np.isfinite(gap) and gap < AXES_CONFIDENT_NATS:
        others = [r for r in results if not np.allclose(r[2], M)]
        runner = min(others, key=lambda r: r[0])[2] if others else None
        note(f"warning: the axis mapping is uncertain: the next best"
             f"{' (' + (axes_to_letters(runner) or 'given') + ')' if runner is not None else ''}"
             f" scores only {gap:.1f} worse (< {AXES_CONFIDENT_NATS:g}); the blur says little"
             f" about its direction. Give the mapping (--orientation) if it is known, or"
             f" calibrate on several photos of the session", "  ")

    theta = search.theta_of(x, M, fit.ubar)
    unc = _uncertainties(x, fit.idx, Fm, sc, fit.ubar)
    out_caps = []
    for cap in captures:
        try:
            out_caps.append(theta.apply(cap))
        except InputError as exc:
            raise InputError(cap.source, f"calibrated parameters are not usable: {exc.problem}") from None
    cb = c0
    est = {
        "offset": (cb.time_offset, cb.time_offset + theta.offset,
                   None if "offset" in fix else unc.get("offset")),
        "readout": (cb.readout_time, max(0.0, cb.readout_time + theta.readout),
                    None if "readout" in fix else unc.get("readout")),
        "focal": (1.0, theta.focal, None if "focal" in fix else unc.get("focal")),
        "bias": (np.array(cb.bias), cb.bias + theta.bias,
                 None if "bias" in fix else np.array([unc.get(f"bias{i}", np.nan) for i in range(3)])),
        "axes": (given_letters or np.round(cb.axes, 6).tolist(),
                 axes_to_letters(M) or np.round(M, 6).tolist(),
                 None if "axes" in fix else gap),
    }
    secs = time.perf_counter() - t_start
    notes.append(f"{fit.coarse.evaluations} coarse and {fit.fine.evaluations} fine cost "
                 f"evaluations, {secs:.1f} s")
    return CalibrationResult(out_caps, est, ranking, fit.fine.scale, fix, secs, notes, rivals)


def _candidate_mappings(given: np.ndarray, fix: set, mappings) -> list[np.ndarray]:
    """The axis mappings to consider: the given one alone when fixed; else ``mappings``
    (letters; default all 24 proper signed permutations), plus the given matrix when it is
    not one of them (a measured, not quite permutation, mapping)."""
    if "axes" in fix:
        return [given]
    letters = list(mappings) if mappings else list(PROPER_AXIS_LETTERS)
    cand = [parse_axes(s) for s in letters]
    if axes_to_letters(given) is None:
        cand.append(given)
    return cand


def _with_twin(top: list, everything: list) -> list:
    """``top`` (rows whose last item is a mapping) plus the best row holding the mirror
    twin of its first mapping, when that is not already in."""
    if not top:
        return top
    tw = TWIN @ top[0][-1]
    if any(np.allclose(tw, r[-1]) for r in top):
        return list(top)
    return list(top) + [r for r in everything if np.allclose(r[-1], tw)][:1]


def _relative(scored: list) -> list[tuple[str, float]]:
    """``(letters, score relative to the best)`` of a coarse ranking's rows (best first)."""
    return [(axes_to_letters(r[4]) or "given", float(r[0] - scored[0][0])) for r in scored]


def _shortlist(rankings: list) -> list:
    """The coarse rankings' rows merged, each ranking's best in turn, each mapping once.

    The two coarse criteria fail on different scenes (a flat 1/f^2 spectrum is misled by
    oriented texture, a fitted envelope soaks up part of a long blur)."""
    short = []
    for pair in zip(*rankings):
        for r in pair:
            if not any(np.allclose(r[4], q[4]) for q in short):
                short.append(r)
    return short


class _Fit:
    """The fitting context of one calibration: working scales, the patches at the fine and
    coarse scales (:attr:`fine`, :attr:`coarse`), the frame registration, the free
    coordinates with their bounds, steps and priors; and each step of the search (see the
    module docstring, Search).

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
        s_f = min(1.0, _TARGET_EXTENT / extent)
        s_c = min(1.0, _COARSE_EXTENT / extent)
        small = min(min(ph.H, ph.W) for ph in photos)
        P_f = int(min(_PATCH, 16 * (small * s_f // 16)))
        P_c = int(min(_COARSE_PATCH, 16 * (small * s_c // 16)))
        if P_f < 48 or P_c < 32:
            raise InputError(None, f"the photos are too small ({small} px) for the blur "
                                   f"(~{extent:.0f} px) to be calibrated")
        per = max(3, int(np.ceil(n_patches / len(photos))))
        centres = []
        for i, ph in enumerate(photos):
            centres += [(i, x, y) for x, y in select_patch_centres(ph, per, int(round(P_f / s_f)))]
        if not centres:
            raise InputError(None, "no textured, unsaturated patch found for calibration")
        self.fine = PatchSpectra(photos, centres, s_f, P_f, rows=(-0.15, 0.0, 0.15),
                                 n_samples=int(np.clip(np.ceil(1.3 * path * s_f / 0.5), 32, 400)))
        self.coarse = PatchSpectra(photos, centres, s_c, P_c, rows=(0.0,), envelope=False,
                                   n_samples=int(np.clip(np.ceil(1.3 * path * s_c / 0.7), 24, 200)))
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
        if "readout" in fix or search.r0 == 0:
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

    # -- pieces -------------------------------------------------------------------------
    def theta_of(self, M):
        return lambda v: self.search.theta_of(v, M, self.ubar)

    def prior_for(self, M):
        """(mean, sd, temperature) of the priors for mapping ``M``: the bias's combines
        the given bias with the log's typical rate, when the log is long enough."""
        mu, sig = np.zeros(6), self.prior_sig.copy()
        mu[3:6], sig[3:6] = self.bias_prior.for_mapping(M)
        return mu, sig, _TEMPERATURE

    def extra_for(self, M):
        """The frame registration's residuals for mapping ``M`` (``None`` without one)."""
        reg = self.reg
        if reg is None or not reg.pairs:
            return None
        return lambda v: reg.residuals(self.search.theta_of(v, M, self.ubar))

    def start_vec(self, tau0, kap, M, fo=1.0):
        """A start from a line fit (time shift ``tau0`` at the middle row, readout error
        ``kap``), focal scale ``fo`` and the prior's bias."""
        x = np.zeros(6)
        x[3:6] = self.bias_prior.for_mapping(M)[0]
        x[1] = kap
        x[0] = 0.0 if "offset" in self.fix else tau0 + kap * (0.5 - self.ubar)
        x[2] = np.log(fo)
        return np.clip(x, self.lo, self.hi)

    def refine(self, M, x0, iters, which=None):
        """Levenberg-Marquardt under mapping ``M`` from ``x0``: (x, f, F, scores)."""
        return lm_refine(self.fine, self.theta_of(M), x0, self.idx if which is None else which,
                         self.lo, self.hi, self.hs, self.caps, self.prior_for(M), iters=iters,
                         extra=self.extra_for(M))

    def given_objective(self, M) -> tuple[float, np.ndarray]:
        """The objective of the given parameters under mapping ``M`` (the bias the prior's),
        and their vector."""
        x0 = np.clip(np.r_[0.0, 0.0, 0.0, self.bias_prior.for_mapping(M)[0]], self.lo, self.hi)
        return objective(self.fine, self.theta_of(M), x0, self.idx, self.prior_for(M),
                         self.extra_for(M)), x0

    # -- steps --------------------------------------------------------------------------
    def coarse_rankings(self, cand) -> list[list]:
        """Per coarse criterion (flat, then fitted envelope), the mappings' rows
        ``(score, time shift, readout error, 1.0, M)``, best first."""
        rankings = []
        for envelope in (False, True):
            self.coarse.envelope = envelope
            scored = []
            for M in cand:
                C = self.coarse.costs(self.theta0.copy(axes=M, bias=self.bias_prior.for_mapping(M)[0]),
                                      taus=self.taus)
                tot, tau0, kap = line_fit(C, self.taus, self.uc, self.kappas)
                scored.append((tot, tau0, kap, 1.0, M))
            scored.sort(key=lambda r: r[0])
            rankings.append(scored)
            ranking = _relative(scored)
            self.say(f"coarse ranking ({'fitted' if envelope else 'flat'} envelope): "
                     + ", ".join(f"{a} {c:+.0f}" for a, c in ranking[:6]))
        return rankings

    def candidate(self, tau0, kap, M):
        """Mapping ``M`` at the working scale: per-patch time shifts x focal grid with the
        envelopes held from the coarse start, combined along the readout line; from the
        best few distinct starts, Levenberg-Marquardt. Returns (objective, x, M, the other
        starts' results)."""
        search = self.search
        if "offset" in self.fix:
            tm = np.array([0.0])
        else:
            tm = np.arange(tau0 - 0.016, tau0 + 0.0161, _COARSE_STEP)
            tm = tm[(tm >= search.tau_lo - 1e-9) & (tm <= search.tau_hi + 1e-9)]
            if tm.size == 0:
                tm = np.array([float(np.clip(tau0, search.tau_lo, search.tau_hi))])
        self.fine.set_envelope(search.theta_of(self.start_vec(tau0, kap, M), M, self.ubar))
        starts = []
        for fo in self.fgrid:
            C = self.fine.costs(self.theta0.copy(axes=M, focal=fo,
                                                 bias=self.bias_prior.for_mapping(M)[0]),
                                taus=tm, rows=(0.0,))
            for kap in self.kappas:
                tot, t0, kp = line_fit(C, tm, self.uc, [kap])
                starts.append((tot, t0, kp, fo))
        # the best few starts that differ in time shift (at the pivot row) or readout: the
        # refinement from the best line fit alone can stop in the wrong basin
        starts.sort(key=lambda r: r[0])
        chosen = [starts[0]]
        for r in starts[1:]:
            if len(chosen) >= _CANDIDATE_STARTS:
                break
            if all(abs((r[1] - c[1]) + (r[2] - c[2]) * (0.5 - self.ubar)) > _DISTINCT_SHIFT
                   or abs(r[2] - c[2]) > _DISTINCT_READOUT for c in chosen):
                chosen.append(r)
        fx, alts = np.inf, []
        for best in chosen:
            x1, f1, _, _ = self.refine(M, self.start_vec(best[1], best[2], M, best[3]), 4)
            alts.append(x1)
            if f1 < fx:
                x, fx = x1, f1
        self.say(f"  candidate {axes_to_letters(M) or 'given'}: time shift {x[0] * 1e3:+.1f} ms, "
                 f"readout {x[1] * 1e3:+.1f} ms, focal x{np.exp(x[2]):.3f}: objective {fx:.1f}")
        return fx, x, M, [a for a in alts if a is not x]

    def refine_winner(self, M, x, alts):
        """The winning mapping's refinement from its best start, its other starts, the
        given focal length and bias, and time shifts around its own: the lowest objective
        (x, f, F, scores). Every basin reached is kept in :attr:`basins`."""
        self.basins = []
        best = self.refine_fully(M, x)
        # The winner's other starts, refined as far: four iterations do not always tell which
        # basin is lowest (a time shift 5 ms off can lead after four and trail after fourteen).
        for xa in alts:
            best = _lowest(best, self.refine_fully(M, xa))
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
            xs = self.refine(M, np.clip(xs, lo, hi), 6, [j for j in idx if j != 2])[0]
            best = _lowest(best, self.refine_fully(M, xs))
        # Last, time shifts around the winner's, every _SCAN_STEP up to _SCAN_REACH away, from
        # the given (prior) values of the other parameters: the coarse start's line fits can
        # miss a nearby basin that the fine cost prefers; the best _SCAN_REFINED are refined
        # as far.
        if "offset" not in self.fix:
            x = best[0]
            starts, tried = [], {round(float(x[0]), 6)}
            for dt in np.arange(-_SCAN_REACH, _SCAN_REACH + 1e-9, _SCAN_STEP):
                xs0 = np.clip(np.r_[x[0] + dt, 0.0, 0.0, b_prior], lo, hi)
                if round(float(xs0[0]), 6) in tried:   # the winner's own, or clipped to a bound
                    continue
                tried.add(round(float(xs0[0]), 6))
                starts.append(xs0)
            best = self._scan(M, starts, best)
        # And readout times across the prior's range at the winner's mid-row time: with the
        # rows between well timed, a readout 30-40 % off can sit in a basin of its own
        # (the top and bottom patches then fit other parts of the trace).
        if "readout" not in self.fix and self.search.r0 > 0:
            x, r0, starts = best[0], self.search.r0, []
            for fr in _READOUT_SCAN:
                if abs(fr * r0 - x[1]) < 0.05 * r0:
                    continue
                xs0 = x.copy()
                xs0[1] = fr * r0
                starts.append(np.clip(xs0, lo, hi))
            best = self._scan(M, starts, best)
        return best

    def _scan(self, M, starts, best):
        """``starts`` refined four iterations each, the best :data:`_SCAN_REFINED` of them
        refined as far as the winner: the lowest objective of those and ``best``."""
        scan = sorted((self.refine(M, xs0, 4)[:2] for xs0 in starts), key=lambda r: r[1])
        for xs0, _ in scan[:_SCAN_REFINED]:
            best = _lowest(best, self.refine_fully(M, xs0))
        return best

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

    def mirror_twin(self, M, x, given_biases):
        """Mapping ``M`` at ``x`` against its mirror twin at the same parameters (by the
        frame registration when there is one, else by :func:`_phase_prefers_twin`).
        Returns the mapping taken, its refinement when it is the twin (else ``None``), and
        a note that says why."""
        Mt = TWIN @ M
        xt = np.clip(_twin_parameters(x, given_biases, self.fix), self.lo, self.hi)
        th_w = self.search.theta_of(x, M, self.ubar)
        th_t = self.search.theta_of(xt, Mt, self.ubar)
        per_patch = (self.fine.cost(th_t) - self.fine.cost(th_w)) / len(self.fine.points)
        d = np.log(self.fine.sparsity(th_t) / self.fine.sparsity(th_w))
        margin, sem = _mean_and_error(d)
        msg = (f"mirror twin {axes_to_letters(Mt)} at the same parameters: spectra "
               f"{per_patch:+.1f} nats/patch, sparsity {margin:+.4f} +- {sem:.4f} (log ratio; "
               f"{int((d > 0).sum())}/{d.size} patches prefer {axes_to_letters(M)})")
        reg = self.reg
        if reg is not None and reg.pairs:
            r_w = float(np.sum(reg.residuals(th_w) ** 2))
            r_t = float(np.sum(reg.residuals(th_t) ** 2))
            msg += f", registration chi2 {r_w:.1f} vs {r_t:.1f}"
            swap = r_t < r_w
        else:
            swap = _phase_prefers_twin(per_patch, d)
        twin = None
        if swap:
            twin = self.refine(Mt, xt, 6)
            msg += f": {axes_to_letters(Mt)} taken"
            M = Mt
        return M, twin, msg


def _shrunk_photos(images, captures, factor: float):
    """The photos resized by ``factor`` (< 1, area averaging, float32) and their captures
    scaled to the sizes they got (checked against the full-size photos first: rounding
    the size may change the aspect ratio slightly, which the scaled cameras follow)."""
    out_imgs, out_caps = [], []
    for img, cap in zip(images, captures):
        img = np.asarray(img)
        h, w = img.shape[:2]
        full = cap.scaled_to(w, h, source=cap.source)    # the photo fits its capture
        small = _shrunk(img, factor)
        hs, ws = small.shape[:2]
        if min(hs, ws) < 64:
            raise InputError("--downscale", f"{factor:g} shrinks a {w}x{h} photo to {ws}x{hs}: "
                                            "too small to calibrate on")
        cam = full.camera.scaled_to(ws, hs, tolerance=1.0)
        out_imgs.append(small)
        out_caps.append(cap.replace(camera=cam))
    return out_imgs, out_caps


def _shrunk(image: np.ndarray, factor: float) -> np.ndarray:
    """``image`` resized by ``factor`` (< 1) with area averaging, float32."""
    import cv2

    h, w = image.shape[:2]
    size = (max(1, int(round(w * factor))), max(1, int(round(h * factor))))
    img = np.ascontiguousarray(image, dtype=np.float32)
    if img.ndim == 3 and img.shape[2] > 4:
        return np.stack([cv2.resize(img[..., c], size, interpolation=cv2.INTER_AREA)
                         for c in range(img.shape[2])], axis=2)
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def _lowest(a: tuple, b: tuple) -> tuple:
    """Of two refinements ``(x, objective, ...)``, the one with the lower objective (``a``
    on a tie)."""
    return b if b[1] < a[1] else a


def _mean_and_error(d: np.ndarray) -> tuple[float, float]:
    """Mean of ``d`` and its standard error (infinite for fewer than two values)."""
    d = np.asarray(d, float)
    sem = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else np.inf
    return float(d.mean()), sem


def _phase_prefers_twin(per_patch: float, log_ratio: np.ndarray) -> bool:
    """Whether the mirror twin replaces the winner when no frame registration decides:
    its spectra (cost, nats per patch, twin minus winner) do not favour the winner by
    :data:`_TWIN_NATS` or more, and the per-patch log sparsity ratios (twin over winner)
    favour the twin by :data:`_TWIN_SIGMAS` standard errors of their mean."""
    margin, sem = _mean_and_error(log_ratio)
    return bool(per_patch < _TWIN_NATS and margin + _TWIN_SIGMAS * sem < 0)


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


def _gyro_noise_level(captures) -> float:
    """The largest white-noise level (rad/s per sample) of the captures' gyro logs."""
    levels = [rate_noise(log) for log, _ in logs_with_captures(captures)]
    levels = [v for v in levels if np.isfinite(v)]
    return max(levels) if levels else float("nan")


def _keep_margin(noise: float) -> float:
    """Objective gain needed to leave the given parameters (same mapping), for a gyro
    with white noise ``noise`` rad/s per sample (``nan``: unknown, the base margin)."""
    if not np.isfinite(noise):
        return _KEEP_MARGIN
    return _KEEP_MARGIN * max(1.0, noise / _TYPICAL_GYRO_NOISE)


def _uncertainties(x, idx, F, scores, ubar) -> dict:
    """One-sigma marginal uncertainties from the tempered Gauss-Newton Hessian of the
    objective (priors included): the posterior's Laplace approximation."""
    if not idx:
        return {}
    try:
        cov = np.linalg.inv(F)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(F)
    cov = 0.5 * (cov + cov.T)
    pos = {j: k for k, j in enumerate(idx)}
    var = np.maximum(np.diag(cov), 0)
    out = {}
    if 0 in pos and 1 in pos:
        a = np.zeros(len(idx))
        a[pos[0]] = 1.0
        a[pos[1]] = ubar
        out["offset"] = float(np.sqrt(max(a @ cov @ a, 0)))
    elif 0 in pos:
        out["offset"] = float(np.sqrt(var[pos[0]]))
    if 1 in pos:
        out["readout"] = float(np.sqrt(var[pos[1]]))
    if 2 in pos:
        out["focal"] = float(np.exp(x[2]) * np.sqrt(var[pos[2]]))
    for k in range(3):
        if 3 + k in pos:
            out[f"bias{k}"] = float(np.sqrt(var[pos[3 + k]]))
    return out


def checked_fix(names) -> set[str]:
    """``names`` (empty ones dropped) as a set, each one of :data:`PARAMETERS`."""
    fix = {n for n in names if n}
    unknown = fix - set(PARAMETERS)
    if unknown:
        raise InputError("--fix", f"unknown parameter(s) {', '.join(sorted(unknown))}; "
                                  f"known: {', '.join(PARAMETERS)}")
    return fix
