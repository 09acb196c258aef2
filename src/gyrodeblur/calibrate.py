"""Self-calibration: fit the few parameters that turn a gyro log into a photo's PSFs.

What a gyro log gets wrong is low-dimensional: the clock offset between gyro and camera,
a constant gyro bias (3 components), the rolling-shutter readout time, the focal length
(a scale), and the axis mapping (one of the 24 proper signed axis permutations; from a
phone's log in its device axes, one of the 8 its own camera can have). We keep
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
estimates is ~100x what its curvature claims), so it is divided by a temperature (100,
``calibration_fit._TEMPERATURE``) before weak Gaussian priors around the given values are added: readout +-30 %, focal
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
The steps are :class:`gyrodeblur.calibration_fit.CalibrationFit`'s; :func:`calibrate` runs
them in order and decides what to keep (5) and what to report.

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
   Before the winner is chosen, the coarse ranking is run again with the bias moved by
   one prior sd either way on x and y (the eight such points, the fitted envelope only,
   every other time shift, one mapping of each mirror-twin pair;
   :func:`_with_bias_widened`): a bias a few hundredths of a rad/s off can reshape a
   short blur enough to keep the right mapping out of the first shortlist. When the best
   two mappings among the first candidates are within :data:`AXES_CONFIDENT_NATS` of each
   other, its best five join them (on the 24-case benchmark, session 33: right mapping
   22 -> 23/24, offsets within 3 ms 21 -> 22/24); else only mappings not refined yet
   that score better with the bias moved than any mapping did at the given bias
   (session 34: on a smoother synthetic hand shake a wrong mapping had won by 37 nats,
   the right one ranking 4th at the given bias, 0.043 rad/s off, and first by far with
   it moved). The second ranking costs about 1-2 s. A mapping that only it found
   (neither the first candidates' best nor its twin) stands on a bias a prior sd or more
   from the given one, and is reported as uncertain as the first candidates were close
   (on the benchmark the one wrong mapping left, on a fence of vertical bars, won that
   way by 16 nats).
3. ``|H|`` cannot tell a PSF from its point reflection, and negating the camera's x and y
   rates (a proper rotation too) nearly reflects every PSF: only roll, perspective and the
   rolling shutter separate the two. The winner's "mirror twin" starts from the same
   parameters, its bias mirrored with the rates unless the bias is fixed (a bias is a
   rate: left as it is, it would turn the twin's PSFs, not reflect them). The frame
   registration below decides at those parameters when there is one; else the twin is
   refined (six iterations: roll and the rolling shutter do not mirror, so its optimum
   lies a little away) and taken when its objective is less than 2 tempered nats worse
   than the winner's (the spectra cannot tell them apart) and the phase (normalised
   gradient sparsity of the Wiener-deconvolved patches) prefers it by two standard errors,
   measured on three times the fit's patches.
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
   switched to a mapping that scored the same), and must already have beaten the given
   mapping's own candidate by as much before the winner's refinement
   (:func:`standing_candidate`): the given parameters' objective also pays for what else
   is wrong with them. A noisy gyro makes its PSFs' fine
   structure noisy, and a fit then gains objective by following that noise (at 0.02 rad/s
   per sample, gains of 3-17 with no better PSFs); so the margin grows with the log's
   white-noise level (:func:`gyrodeblur.gyrolog.rate_noise`, scaled to a 200 Hz log: the
   angle the noise adds over an exposure grows with ``sigma sqrt(dt)``) above the
   chapter's typical phone gyro, 0.007 rad/s: ``margin = 10 max(1, noise / 0.007)``
   (in proportion, not with the variance: that kept real 5 ms offset errors under 0.02
   rad/s noise). Its limit (a held-out audit, session 65): the gains of following noise
   overlap those of real corrections, which are then kept wrong (an 8 ms offset under
   0.02 rad/s at 50 Hz gained 34.7 against a margin of 58; a 0.04 rad/s bias under 0.02
   at 200 Hz 12.5 against 29, for 6-8 dB); and at 50 Hz a hand shake's own motion near
   the band's edge reads as noise (the shared log averaged to 52 Hz: 0.021). The margin of 10
   is for all six continuous coordinates free (offset, readout, focal, bias); with some
   fixed it shrinks to the same odds of moving a right capture (twice the gain is about
   chi-square with as many degrees of freedom as are free): 4.5 with one free, 7.0 with
   three. On the benchmark with one parameter free and the rest right (session 13), 10
   kept readout errors of up to 8 ms that the photo itself preferred to correct. Given
   parameters that explain a photo worse than no blur at all (by more than
   :data:`~gyrodeblur.blur_evidence.WRONG_BLUR_MARGIN`) are not kept, whatever the
   margin, where the best found explains every photo better than no blur (by
   :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN`; :func:`_rejected_by_photos`);
   parameters kept only for the margin the noise raised
   (the best found gains more than the unraised margin) are warned of. A readout that was
   not given is no given parameter: where the best found has the given mapping, the
   given parameters (their offset held) are judged at their best readout within
   :data:`~gyrodeblur.calibration_fit.JUDGED_READOUT_REACH` (6 ms) of the best found's,
   and kept with the readout that suits them best anywhere in 0-45 ms. Until session 66
   they were judged at that one too, and an offset error hid in it: a longer readout
   with a later offset (or a shorter with an earlier) keeps the middle rows' times right
   while the top and bottom rows are off, and scored nearly as well as the truth (a
   held-out audit: a 12 ms offset error kept with 45 ms for a true 25, 19.9 dB against
   30.1).

The independent steps (the coarse mappings, the candidates, the winner's other starts and
scans) run side by side in worker processes (:mod:`gyrodeblur.calibration_workers`), each
from fresh warm starts, so the result does not depend on how many there are (the 24-case
benchmark on 2 cores: 15.9 s a photo, 20.8 s one step after another before; 12 MP: 18.6 s,
25.3 s before).

Uncertainties are one-sigma marginals of the Laplace approximation of the tempered
objective (priors included). The axis mapping's confidence is the objective gap to the
best other candidate mapping; below :data:`AXES_CONFIDENT_NATS` (8) the mapping is reported
as uncertain, with a note that says what to do (on the benchmark every wrong mapping was
below 5 and every gap from 8.9 up was right).

Last, the calibrated PSFs must explain the patches better than no blur at all (each with
its own fitted envelope) by :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN`; a sharp
photo, or a log or exposure start that belong to another shot, gets a warning rather than
confident estimates.

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
from scipy.special import gammaincinv

from .arguments import is_count
from .axes import PHONE_AXIS_LETTERS, PROPER_AXIS_LETTERS, axes_to_letters, parse_axes
from .bias_prior import BiasPrior, logs_with_captures
from .blur_evidence import NO_BLUR_MARGIN, WRONG_BLUR_MARGIN
from .calibration_fit import (_TEMPERATURE, _TWIN_CLEAR_SIGMAS, BLOCKY, OFFSET_APART,
                              OFFSET_RIVAL_NATS, TWIN, CalibrationFit, in_twin_pair,
                              relative_ranking, shortlist, with_twin)
from .calibration_patches import CalibrationPhoto
from .calibration_search import SearchSpace
from .calibration_workers import StepRunner, available_workers, on_one_blas_thread
from .capture import (EXIF_START_TOLERANCE, EXIF_WHOLE_SECOND_TOLERANCE, UNKNOWN_READOUT_MAX,
                      UNKNOWN_READOUT_PRIOR, Capture)
from .errors import InputError
from .images import check_image
from .gyrolog import naming_log, rate_noise, saturation_warning, step_warning

__all__ = ["calibrate", "CalibrationResult", "PARAMETERS", "AXES_CONFIDENT_NATS",
           "OFFSET_APART", "OFFSET_RIVAL_NATS", "standing_candidate", "DEFAULT_OFFSET_RANGE",
           "EXIF_START_OFFSET_RANGE", "EXIF_WHOLE_SECOND_OFFSET_RANGE", "exif_offset_range",
           "MAX_OFFSET_RANGE",
           "searched_mappings"]

#: Parameters that can be estimated (and fixed with ``fix=``).
PARAMETERS = ("offset", "bias", "readout", "focal", "axes")


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
        the objective gap to the best other candidate mapping, tempered nats; for a
        mapping that only the widened coarse ranking found, at most the gap between the
        first candidates, see :func:`_with_bias_widened`). Fixed
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
    blur_gain : float
        How much better (tempered nats, per :data:`_N_PATCHES` patches) the calibrated
        PSFs explain the patches than no blur at all, for the photo where that is least;
        under :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN` the notes warn that the
        photo shows little of the blur the log implies (``nan`` when not measured).
    offset_rivals : list of (float, float, float)
        Other basins of the winning mapping that the search reached: their time offset
        (s), readout time (s) and how much higher their objective is (tempered nats), for
        offsets more than ``OFFSET_APART`` from the estimate and within
        ``OFFSET_RIVAL_NATS`` of it, best first. Empty when the offset is unambiguous as
        far as the search saw, fixed, or when the given parameters were kept.
    prior_distance : float
        How far the estimates lie from the given values in units of the priors' typical
        errors: the sum of the squared z-scores of the free readout, focal and bias
        coordinates (chi-square with as many degrees of freedom for errors of the priors'
        size); beyond its 95 % quantile the notes warn (0 when the given parameters were
        kept or none of them is free).
    kept_given : bool
        The given parameters were kept (step 5 of :func:`calibrate`): the best found
        improved the objective by less than the keep margin, so the "after" values are
        the given ones (the bias the log's, where it was taken from the log; the readout,
        where none was given, the one that suits them), not estimates the photo pinned
        down.
    """

    captures: list
    estimates: dict
    ranking: list = field(default_factory=list)
    scale: float = 1.0
    fixed: set = field(default_factory=set)
    seconds: float = 0.0
    notes: list = field(default_factory=list)
    offset_rivals: list = field(default_factory=list)
    blur_gain: float = float("nan")
    prior_distance: float = 0.0
    kept_given: bool = False

    @property
    def capture(self) -> Capture:
        return self.captures[0]


# ----------------------------------------------------------------------------- settings

#: Objective gap (tempered nats) to the next best mapping under which the chosen axis
#: mapping is reported as uncertain. On the 24-case calibration benchmark (session 4) the
#: three wrong mappings had gaps of 3.6-4.9, every gap of 8.9 or more was right, and five
#: right ones (blurs of 3-6 px) were below 3.
AXES_CONFIDENT_NATS = 8.0
_N_PATCHES = 9             # patches per photo, by default, ...
_MAX_PATCHES = 18          # ... or this many shared out (rounded up to >= 3 per photo)
#: With the given axis mapping, the given parameters are kept unless the best found lowers
#: the (tempered) objective by at least this much: a correct capture on a photo with little
#: blur is left alone rather than moved along directions the photo cannot tell apart.
#: (With all six continuous coordinates free; fewer free, see :func:`_keep_margin`.)
_KEEP_MARGIN = 10.0
#: ... and a different mapping is taken only when it lowers it by at least this much (odds of
#: about 7 to 1 for the mapping the user gave). Until session 8 any gain would do: a right
#: capture of a 3 px blur was switched to a wrong mapping by 0.4 and lost 19 dB. The full
#: margin of 10 was tried: two benchmark photos of 3-4 px blur then kept the wrong mapping
#: they were given, which the right one beat by 4.2 and 6.7.
_KEEP_MAPPING_NATS = 2.0
#: rad/s per sample at :data:`_TYPICAL_GYRO_RATE` samples a second: gyro noise above this
#: raises the keep margin (in proportion).
_TYPICAL_GYRO_NOISE = 0.007
_TYPICAL_GYRO_RATE = 200.0
_CANDIDATES = 5            # mappings refined at full working scale (+ the best's twin)
#: Estimates whose squared prior z-scores sum beyond this quantile of the chi-square
#: distribution (degrees of freedom: the prior-bound coordinates free) get a warning. On
#: the 24-case benchmark, whose injected errors are at most one prior sd, the right
#: mappings' sums were 0.2-3.9 and the wrong mapping's on the fence of vertical bars 12.2
#: (13.2 on a synthetic hand shake): a wrong answer that explains the blur by pushing
#: bias, readout and focal length far from the given values.
_FAR_QUANTILE = 0.95
#: Seconds searched, by default, on each side of the given time offset (tens of ms is
#: the typical error of a phone's gyro and camera timestamps).
DEFAULT_OFFSET_RANGE = 0.04
#: Seconds searched, by default, on each side of an exposure start that is a photo's EXIF
#: capture time (:attr:`~gyrodeblur.capture.Capture.exposure_start_from_exif`): that
#: marks the exposure only to tens or hundreds of milliseconds.
EXIF_START_OFFSET_RANGE = EXIF_START_TOLERANCE
#: The same for an EXIF time to the second, taken at its middle
#: (:attr:`~gyrodeblur.capture.Capture.exif_time_to_the_second`).
EXIF_WHOLE_SECOND_OFFSET_RANGE = EXIF_WHOLE_SECOND_TOLERANCE


def exif_offset_range(captures) -> float:
    """Seconds :func:`calibrate` searches, by default, on each side of exposure starts
    that are the photos' EXIF times: :data:`EXIF_WHOLE_SECOND_OFFSET_RANGE` where any is
    to the whole second, else :data:`EXIF_START_OFFSET_RANGE`."""
    return (EXIF_WHOLE_SECOND_OFFSET_RANGE
            if any(cap.exif_time_to_the_second for cap in captures)
            else EXIF_START_OFFSET_RANGE)


#: The widest range :func:`calibrate` takes (s, each side): the coarse ranking scans it
#: every 2 ms for each axis mapping, and a wide range costs about ``_SECONDS_PER_SPAN`` s
#: per second of log searched on one photo, so 5 s either side is about two and a half
#: minutes on 2 cores (give the exposure start to a second or better).
MAX_OFFSET_RANGE = 5.0
#: Calibration seconds per second of time shifts searched beyond the default's, one photo,
#: 2 cores (session 54, a 1024 x 680 benchmark photo: 11.3 s at +-40 ms, 37.9 s at +-1 s;
#: session 39 measured 52, before the workers' BLAS kept to one thread each).
_SECONDS_PER_SPAN = 14.0
_RANGE_SLACK = 0.001       # s: a log that cuts the asked range by less is not mentioned


@on_one_blas_thread
def calibrate(images, captures, *, fix=(), offset_range: float | None = None,
              transfer="srgb", n_patches: int | None = None, say=None,
              mappings=None, downscale: float = 1.0,
              workers: int | None = None) -> CalibrationResult:
    """Estimate time offset, gyro bias, readout time, focal scale and axis mapping.

    Parameters
    ----------
    images : list of ndarray
        Blurred photos (float in [0, 1], (H, W) or (H, W, C)), one per capture (a single
        array is one photo).
    captures : Capture or list of Capture
        Their capture descriptions (one per photo, any resolution with the photo's aspect
        ratio; one shared only where each photo's start is its EXIF time: photos of one
        session started at one time on one log are refused); the photos share the unknown
        corrections (one camera, one gyro, one session): one time-offset change, one
        readout change, one focal scale, one bias change and one axis mapping for all.
    fix : iterable of str, or str
        Parameters not to estimate, from :data:`PARAMETERS` (a string: comma-separated).
    offset_range : float, optional
        Seconds searched on each side of the given time offset (default
        :data:`DEFAULT_OFFSET_RANGE`, 40 ms; more than 0, at most
        :data:`MAX_OFFSET_RANGE`), as far as the gyro log covers it (a note says where
        it stops); the refinement may end up to 10 ms beyond. Where the two clocks are
        known only roughly, give more. The coarse ranking scans the range every 2 ms for
        each axis mapping, and over more than 0.1 s each candidate mapping is started
        from its three best distinct coarse minima: about 30 s more per second on each
        side, on 2 cores (a 1024 x 680 photo: 38 s for +-1 s against 11 s for the
        default). Refused with the offset fixed. Where a capture's exposure start is its
        photo's EXIF time (``exposure_start_from_exif``), the default is
        :data:`EXIF_START_OFFSET_RANGE`, 1 s (:data:`EXIF_WHOLE_SECOND_OFFSET_RANGE`,
        1.5 s, for a time to the second); several photos with such starts, whose
        errors differ, are refused as a session unless the offset is fixed.
    transfer : str or TransferCurve, or a list of them
        Transfer curve of the photos' values (``"srgb"``, ``"linear"`` or a
        :class:`~gyrodeblur.tonecurve.TransferCurve`, e.g. from
        :func:`gyrodeblur.icc.photo_transfer_curve`): one for all photos, or one each.
    n_patches : int, optional
        Patches in all (spread over the photos, and over each frame; rounded up to a
        whole number per photo, at least 3). Default: 9 per photo, or 18 shared out when
        that is fewer (a photo with little blur says little: it must not crowd out the
        patches of the others).
    say : callable(str), optional
        Progress messages.
    mappings : {"phone", "all"} or list of str, optional
        Axis mappings to consider: ``"all"``, the 24 proper signed permutations;
        ``"phone"``, the 8 of them possible for a phone's own camera from the phone's
        device axes (:data:`gyrodeblur.axes.PHONE_AXIS_LETTERS`: the camera looks along
        the device's z axis); or a list of mappings (letters). Default: ``"phone"`` where
        every capture's log is a phone app's or an Android sensor dump, in the device's
        axes (:attr:`GyroLog.in_device_axes <gyrodeblur.gyrolog.GyroLog.in_device_axes>`),
        else ``"all"``. Give ``"all"`` for a phone's log and a photo from another camera
        fixed to it. A given mapping outside the set is not kept.
    downscale : float
        Calibrate on the photos shrunk by this factor (0 < ``downscale`` <= 1, area
        averaging). For photos softer than their pixel grid (upscaled, or heavily
        denoised): the spectral criterion reads an empty top octave as blur. The corrected
        captures keep the given ones' resolution. The command line takes it from a
        photo's digital zoom (:func:`gyrodeblur.calibrate_cli.calibration_downscale`).
    workers : int, optional
        Processes that refine independent starts side by side (Linux; default: the CPUs
        available, at most :data:`gyrodeblur.calibration_workers.MAX_WORKERS`; 1: none).
        The result is the same for any number. Called while the process runs other Python
        threads (a pipeline calibrating in threads), the steps run one after another in
        the caller: a fork beside a running thread can deadlock. BLAS runs on one thread
        throughout (the process's setting is restored after; left alone beside other
        Python threads): see :func:`gyrodeblur.calibration_workers.on_one_blas_thread`.

    Returns
    -------
    CalibrationResult
    """
    t_start = time.perf_counter()
    images = [images] if isinstance(images, np.ndarray) else list(images)   # one photo
    if not images:
        raise InputError(None, "no photo to calibrate on")
    if isinstance(captures, Capture):
        captures = [captures] * len(images)
    captures = list(captures) if captures is not None else None
    if captures is None or not all(isinstance(c, Capture) for c in captures):
        raise TypeError("captures must be a Capture or a list of them, one per photo")
    if len(captures) != len(images):
        raise InputError.of_argument(
            "captures", f"{len(images)} photos but {len(captures)} captures")
    _refuse_repeated_images(images)
    _refuse_one_start(captures)
    fix = checked_fix(fix)
    mappings, why_mappings = searched_mappings(mappings, captures, fix)
    say_ = say or (lambda msg: None)
    if isinstance(downscale, bool) or not isinstance(downscale, (int, float, np.number)) \
            or not 0 < downscale <= 1:
        raise InputError.of_argument("downscale", f"must be in (0, 1], got {downscale!r}")
    if workers is not None and not is_count(workers):
        raise InputError.of_argument("workers", f"must be a whole number >= 1, got {workers!r}")
    from_exif = [cap.exposure_start_from_exif for cap in captures]
    if len(captures) > 1 and any(from_exif) and "offset" not in fix:
        which = ", ".join(str(k + 1) for k, f in enumerate(from_exif) if f)
        raise InputError.of_argument(
            "captures", f"photo{'s' if sum(from_exif) > 1 else ''} {which} of "
                        f"this session start{'' if sum(from_exif) > 1 else 's'} at the EXIF "
                        "capture time, which is off by its own amount in each photo, while a "
                        "session shares one time offset: no offset would fit them all. "
                        "Calibrate such photos one at a time, or give their exposure starts "
                        "on the gyro log's clock")
    unknown = [cap.readout_time_unknown for cap in captures]
    if any(unknown) and not all(unknown) and "readout" not in fix:
        which = ", ".join(cap.source or f"photo {k + 1}'s capture"
                          for k, cap in enumerate(captures) if cap.readout_time_unknown)
        raise InputError.of_argument(
            "captures", f"{which} give{'s' if sum(unknown) == 1 else ''} no "
                        "readout_time while the other descriptions of this session do, and "
                        "a session shares one readout correction: give a readout_time in "
                        "every description (or in none)")
    widened = offset_range is None and "offset" not in fix and any(from_exif)
    if offset_range is None:
        if not widened:
            offset_range = DEFAULT_OFFSET_RANGE
        else:
            offset_range = exif_offset_range(captures)
    elif "offset" in fix:
        raise InputError.of_argument(
            "offset_range", "the time offset is fixed ('offset' in fix; on the command "
                            "line --fix offset or --time-offset): there is no range to "
                            "search")
    if isinstance(offset_range, bool) or not (isinstance(offset_range, (int, float, np.number))
                                              and 0 < offset_range <= MAX_OFFSET_RANGE):
        raise InputError.of_argument(
            "offset_range", f"must be seconds in (0, {MAX_OFFSET_RANGE:g}] on "
                            f"each side of the given time offset (to keep the "
                            f"offset, fix it), got {offset_range!r}")
    if n_patches is not None and not is_count(n_patches):
        raise InputError(None, f"n_patches must be a whole number >= 1, got {n_patches!r}")
    work_caps = captures
    if downscale < 1:
        images, work_caps = _shrunk_photos(images, captures, downscale)
    if n_patches is None:
        n_patches = min(_N_PATCHES * len(images), _MAX_PATCHES)
    transfers = (list(transfer) if isinstance(transfer, (list, tuple))
                 else [transfer] * len(images))
    if len(transfers) != len(images):
        raise InputError.of_argument(
            "transfer", f"{len(transfers)} transfer curves for {len(images)} "
                        "photos: give one, or one per photo")
    photos = [CalibrationPhoto(img, cap, curve, i)
              for i, (img, cap, curve) in enumerate(zip(images, work_caps, transfers))]
    notes: list[str] = []

    def note(msg: str, indent: str = "") -> None:
        notes.append(msg)
        say_(indent + msg)

    search = SearchSpace(photos, fix, offset_range)
    c0 = photos[0].cap
    if search.readout_unknown:
        say_(f"readout time not given: searching 0-{UNKNOWN_READOUT_MAX * 1e3:.0f} ms, "
             f"under a weak prior of {UNKNOWN_READOUT_PRIOR[0] * 1e3:.0f} +- "
             f"{UNKNOWN_READOUT_PRIOR[1] * 1e3:.0f} ms (--readout-time fixes it)")

    asked = (f"+-{offset_range * 1e3:.0f} ms around the exposure start taken from EXIF, "
             f"or the nearest one the log covers; --offset-range sets another range"
             if widened
             else f"asked: +-{offset_range * 1e3:.0f} ms")
    if "offset" not in fix and (search.tau_lo > -offset_range + _RANGE_SLACK
                                or search.tau_hi < offset_range - _RANGE_SLACK):
        note(f"the gyro log covers the exposure only for time offsets "
             f"{search.tau_lo * 1e3:+.0f} to {search.tau_hi * 1e3:+.0f} ms from the given one "
             f"({asked}): searched there")
    elif offset_range > DEFAULT_OFFSET_RANGE:
        extra = _SECONDS_PER_SPAN * (search.tau_hi - search.tau_lo - 2 * DEFAULT_OFFSET_RANGE)
        why = " (an exposure start from EXIF; --offset-range sets another range)"
        say_(f"searching time offsets within +-{offset_range * 1e3:.0f} ms of the given one"
             f"{why if widened else ''}: about {extra:.0f} s more than the default "
             f"+-{DEFAULT_OFFSET_RANGE * 1e3:.0f} ms (on 2 cores)")

    for said in dict.fromkeys(_clipped_logs(search)):      # each log's once
        note(f"warning: {said}")

    # the bias that the log's typical rate implies, when the log is long (hand motion
    # averages out over seconds; a gyro's bias does not)
    b_given = np.mean([np.asarray(cap.bias, float) for cap in captures], axis=0)
    bias_prior, msg = BiasPrior(b_given), None
    if "bias" not in fix:
        bias_prior, msg = BiasPrior.from_logs(captures, c0.axes, b_given)
    if msg:
        note(msg)

    given_letters = axes_to_letters(c0.axes)
    if why_mappings:
        note(why_mappings)
    cand = _candidate_mappings(c0.axes, fix, mappings)
    given_searched = any(np.allclose(c0.axes, m) for m in cand)
    fit = CalibrationFit(photos, search, fix, bias_prior, n_patches, len(cand), say_)
    if fit.fine.band_cuts:
        note(f"the photos show JPEG's 8 px blocks (strength {fit.blockiness:.2f} > {BLOCKY:g}): "
             f"frequencies above {fit.band:g} cycles/px are left out, where compression "
             f"removed detail that would read as blur")

    # 1. coarse: every mapping x time shifts per patch, combined along a line (time offset +
    #    readout error x row); the two rankings take turns in the shortlist
    steps = StepRunner(fit, available_workers() if workers is None else workers)
    rankings = fit.coarse_rankings(cand, steps)
    ranking = relative_ranking(rankings[-1])
    short = shortlist(rankings)
    # 2. candidates at full working scale, the best refined further
    top = with_twin(short[:_CANDIDATES], rankings[0])
    results = sorted(fit.candidates(top, steps), key=lambda r: r[0])
    first_best, gap_first = results[0][2], None
    if "bias" not in fix and len(cand) > 1:
        results, gap_first = _with_bias_widened(fit, cand, steps, results, rankings[-1][0][0],
                                                bias_prior, say_)
    noise = _gyro_noise_level(captures)
    mapping_margin = _keep_margin(noise) * _KEEP_MAPPING_NATS / _KEEP_MARGIN
    best, chosen = results[0], standing_candidate(results, c0.axes, mapping_margin)
    _, x, M, alts = chosen
    if chosen is not best:
        note(f"the given mapping's best ({chosen[0]:.1f}) is within {mapping_margin:.3g} of "
             f"{axes_to_letters(best[2]) or 'given'}'s ({best[0]:.1f}): it stands", "  ")
    x, fx, Fm, sc = fit.refine_winner(M, x, alts, steps)
    gap = _gap_to_other_mappings(results, M, fx)
    if np.isfinite(gap) and gap < 0:        # a runner-up's refinement was cut short
        gap = 0.0

    # what the warnings advise: more photos of the session than were given
    more_photos = ("several photos of the session" if len(images) == 1 else
                   f"more photos of the session than these {len(images)}")
    # the given parameters (with a long log, its bias) stay unless the photo(s) clearly
    # prefer others
    kept = False
    if (fit.idx or len(cand) > 1) and given_searched:
        f_given, x0 = fit.given_objective(c0.axes)
        # a readout not given is no given parameter: under the best found's mapping the
        # given ones are judged near its readout (at their best anywhere, an offset error
        # hid in it); kept, at their best anywhere. (Kept instead at the window's readout
        # where it scored better, by hundredths of a nat, right captures lost up to 1.4 dB)
        f_judged = f_given
        if search.readout_unknown and np.allclose(M, c0.axes):
            f_judged = fit.given_objective(c0.axes, readout=x[1])[0]
        if np.allclose(M, c0.axes):
            margin = _keep_margin(noise, len(fit.idx))
            quiet = _keep_margin(float("nan"), len(fit.idx))     # the margin unraised
        else:           # another mapping: the odds of 7 to 1, however many are free
            margin, quiet = mapping_margin, _KEEP_MAPPING_NATS
        if np.isfinite(noise) and noise > _TYPICAL_GYRO_NOISE:
            note(f"gyro noise {noise:.4f} rad/s per sample, scaled to a {_TYPICAL_GYRO_RATE:g} "
                 f"Hz log: the given parameters are kept unless the objective improves by "
                 f"{margin:.0f}", "  ")
        keep = f_judged - fx < margin
        if keep:                      # unless the photos reject the given parameters
            rejected = _rejected_by_photos(fit, search, x0, c0.axes, x, M, len(images))
            if rejected:
                note(rejected, "  ")
                keep = False
        if keep:
            from_log = " (the bias from the log)" if np.any(np.abs(x0[3:6]) > 1e-4) else ""
            found = c0.time_offset + search.theta_of(x, M, fit.ubar).offset
            best_found = f"{axes_to_letters(M) or 'given'}, time offset {found * 1e3:+.1f} ms"
            gain = f_judged - fx
            msg = (f"kept the given parameters{from_log}: the best found ({best_found}) "
                   f"improves the objective by only {gain:.1f} (< {margin:.3g})")
            x, M, fx = x0, c0.axes, f_given
            _, _, Fm, sc = fit.refine(M, x, 0)
            kept = True
            note(msg, "  ")
            gap = _gap_to_other_mappings(results, M, fx)
            if gain >= quiet:      # kept only for the margin the noise raised
                prefer = "the photo prefers" if len(images) == 1 else "the photos prefer"
                note(f"warning: the given parameters were kept only because the gyro log "
                     f"reads as noisy ({noise:.4f} rad/s per sample at "
                     f"{_TYPICAL_GYRO_RATE:g} Hz): {prefer} the best found ({best_found}) "
                     f"by {gain:.1f}, more than the "
                     f"{quiet:.3g} that takes it under a quiet gyro, less than the "
                     f"{margin:.3g} that this noise can give by chance. A log of 50-100 Hz "
                     f"can read its own motion as noise: if the gyro is quieter, give what "
                     f"you know (--time-offset, --bias, --readout-time, --fx, --orientation) "
                     f"or calibrate on {more_photos}", "  ")

    these_photos = "this photo's" if len(images) == 1 else "these photos'"

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
             f"is known, or calibrate on {more_photos}", "  ")

    # 3. the mirror twin (|H| nearly equal): the frame registration decides at the same
    #    parameters, else the twin is refined and the phase (sparsity of the deconvolved
    #    patches) must prefer it as well.
    tie = None
    if "axes" not in fix and len(cand) > 1 and not kept:
        M, twin, msg, tie = fit.mirror_twin(M, x, fx, [cap.bias for cap in captures])
        if twin is not None:
            x, fx, Fm, sc = twin
        note(msg, "  ")
        if tie is not None:          # a tie the phase could not settle: the twin is the
            tie_gap = max(tie[1], 0.0)   # next best unless another mapping scores closer
            others = [r for r in results if not in_twin_pair(M, r[2])]
            if others and min(r[0] for r in others) - fx < tie_gap:
                tie = None
            else:
                gap = min(gap, tie_gap) if np.isfinite(gap) else tie_gap

    # a mapping that only the widened ranking found stands on a bias far from the given
    # one: it is as uncertain as the first candidates were close
    wide_only = gap_first is not None and not kept and not in_twin_pair(first_best, M)
    if wide_only and not gap <= gap_first:
        gap = gap_first
    if "axes" not in fix and np.isfinite(gap) and gap < AXES_CONFIDENT_NATS:
        rival = _best_other_mapping(results, M)
        runner = None if rival is None else rival[2]
        if tie is not None and tie[2] <= -_TWIN_CLEAR_SIGMAS:
            why = (f" its mirror twin {axes_to_letters(tie[0])} scores {tie[1]:.1f} worse, "
                   f"but the phase of the deconvolved patches prefers it by "
                   f"{-tie[2]:.1f} standard errors: the two disagree")
        elif tie is not None:
            phase_for = axes_to_letters(M if tie[2] >= 0 else tie[0])
            why = (f" its mirror twin {axes_to_letters(tie[0])} explains the blur about as "
                   f"well (objective {tie[1]:+.1f}), and the phase of the deconvolved "
                   f"patches prefers {phase_for} by only {abs(tie[2]):.1f} standard errors")
        elif wide_only:
            why = (f" {axes_to_letters(M) or 'the mapping found'} won only once the search "
                   f"moved the bias by a prior sd (at the given bias the best mappings were "
                   f"within {gap_first:.1f} of each other)")
        else:
            why = ((" the next best" if gap >= 0 else " another mapping")
                   + (f" ({axes_to_letters(runner) or 'given'})" if runner is not None else "")
                   + (f" scores only {gap:.1f} worse (< {AXES_CONFIDENT_NATS:g})" if gap >= 0
                      else f" scores {-gap:.1f} better, by less than the margin kept for the "
                           "given one"))
        note("warning: the axis mapping is uncertain:" + why + f"; {these_photos} blur does "
             "not tell the mappings apart surely. Give the mapping (--orientation) if it is "
             f"known, or calibrate on {more_photos}", "  ")

    far = 0.0 if kept else _prior_distance(fit, M, x)
    if far > 0 and far > _chi2_quantile(_FAR_QUANTILE, len(_prior_bound(fit))):
        note(f"warning: the estimates lie far from the given values for errors of the "
             f"priors' size (moved by {_far_terms(fit, M, x)}; the squared z-scores sum to "
             f"{far:.1f}, "
             f"which {100 * (1 - _FAR_QUANTILE):.0f} % of such errors exceed): a wrong mapping "
             f"or time offset can explain the blur this way (a periodic texture such as a "
             f"fence or grille invites it). Check them, and give what you know "
             f"(--orientation, --fx, --readout-time, --bias)", "  ")
    theta = search.theta_of(x, M, fit.ubar)
    unc = _uncertainties(x, fit.idx, Fm, sc, fit.ubar)
    gains = _gains_per_photo(fit.fine, theta, len(images))
    blur_gain = float(np.nanmin(gains)) if np.isfinite(gains).any() else float("nan")
    weak = [k + 1 for k, g in enumerate(gains) if g < NO_BLUR_MARGIN]
    if weak:
        which = ("the photo shows" if len(images) == 1 else
                 f"photo{'s' if len(weak) > 1 else ''} {', '.join(map(str, weak))} show"
                 + ("" if len(weak) > 1 else "s"))
        note(f"warning: {which} little of the blur the gyro log implies: no blur at all "
             f"explains the patches {'better' if blur_gain < 0 else 'about as well'} (the "
             f"calibrated PSFs gain only {blur_gain:+.1f} nats over none). If a photo is "
             "sharp, or the log, the exposure start or the photo belong to another shot, "
             "the estimates mean nothing", "  ")
    out_caps = []
    for cap in captures:
        try:
            got = theta.apply(cap)
            if "readout" in fix and cap.readout_time_unknown:    # not estimated: still not known
                got = got.replace(readout_time_unknown=True)
            out_caps.append(got)
        except InputError as exc:
            raise InputError(cap.source, f"calibrated parameters are not usable: {exc.problem}") from None
    for said in dict.fromkeys(naming_log(got.log, said) for got in out_caps
                              if (said := step_warning(got.log, *got.log_window)) is not None):
        note(f"warning: {said}")
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
    return CalibrationResult(out_caps, est, ranking, fit.fine.scale, fix, secs, notes, rivals,
                             blur_gain, far, kept)


def _with_bias_widened(fit, cand, steps, results, bar, bias_prior,
                       say) -> tuple[list, float | None]:
    """``results`` (candidate rows ``(objective, x, M, alts)``, best first) and the
    candidates of a second coarse ranking with the bias moved (:func:`_bias_steps`); and
    the first candidates' gap between their best two mappings (``None`` when nothing was
    added).

    The first coarse ranking is made at the given bias (the prior's), and a bias that is off
    by a few hundredths of a rad/s changes a short blur's shape enough to push the right
    mapping out of the shortlist. So the coarse ranking runs again with the bias moved by
    one prior sd either way on x and y (the fitted envelope only, every other time shift,
    one mapping of each mirror-twin pair). When the best two mappings among the first
    candidates are within :data:`AXES_CONFIDENT_NATS` of each other, its best five join
    them; else only mappings not yet refined whose moved bias scores better than any
    mapping did at the given bias (``bar``: the first fitted-envelope ranking's best score),
    at most five. The first one added brings its mirror twin. Two benchmark photos whose
    right mapping the first shortlist missed: lai_manmade_02_w0 (7 px of blur, the given
    bias 0.045 rad/s off along y; a wrong mapping won by 8 nats, and from the truth's basin
    the right one wins by 16) and, on a smoother synthetic hand shake, lai_manmade_02_w1
    (11 px, the given bias 0.043 rad/s off; a wrong mapping won by 37 nats, and the moved
    bias ranks the right one first by 600 coarse nats)."""
    gap = _gap_to_other_mappings(results, results[0][2], results[0][0])
    close = bool(np.isfinite(gap) and gap < AXES_CONFIDENT_NATS)
    wide = shortlist(fit.coarse_rankings(_one_of_each_twin_pair(cand), steps,
                                         bias_steps=_bias_steps(bias_prior, results[0][2]),
                                         envelopes=(True,), stride=2))
    if close:
        more = wide[:_CANDIDATES]
    else:
        more = [r for r in wide if r[0] < bar
                and not any(in_twin_pair(r[4], q[2]) for q in results)][:_CANDIDATES]
    if not more:
        return results, None
    say("  " + (f"the best mappings are within {gap:.1f} of each other" if close else
                f"{', '.join(axes_to_letters(q[4]) or 'given' for q in more)} "
                f"score{'s' if len(more) == 1 else ''} better with the bias moved than any "
                f"mapping at the given one")
        + ": candidates from the coarse ranking with the bias moved by one prior sd")
    r = more[0]                 # and its mirror twin, the bias step mirrored as well
    if not any(np.allclose(TWIN @ r[4], q[4]) for q in more):
        more.append(r[:4] + (TWIN @ r[4], r[5], None if r[6] is None else TWIN @ r[6]))
    return sorted(results + fit.candidates(more, steps), key=lambda r: r[0]), gap


def _clipped_logs(search: SearchSpace) -> list[str]:
    """:func:`gyrodeblur.gyrolog.saturation_warning`'s sentence, naming the log, for each
    photo whose log looks clipped anywhere the search may place its exposure (the time
    shifts it admits, the longest readout it tries)."""
    out = []
    for ph in search.photos:
        c = ph.cap
        said = saturation_warning(c.log, *search.log_span(c),
                                  what="where the search may place the exposure")
        if said is not None:
            out.append(naming_log(c.log, said))
    return out


def _one_of_each_twin_pair(cand: list) -> list:
    """The mappings of ``cand`` less the mirror twin (``TWIN @ M``) of any before it."""
    out = []
    for M in cand:
        if not any(in_twin_pair(M, N) for N in out):
            out.append(M)
    return out


def _bias_steps(bias_prior, M) -> list:
    """The bias steps (rad/s, camera frame) of the widened coarse ranking: the eight
    points one prior sd (under mapping ``M``) either way or none on each of the x and y
    axes, bar none on both. Pitch and yaw bias change a PSF's length and direction; a
    roll bias hardly shows at the coarse scale."""
    sd = bias_prior.for_mapping(M)[1]
    return [np.array([i * sd[0], j * sd[1], 0.0])
            for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j]


def _prior_bound(fit) -> list[int]:
    """The free coordinates that a prior holds (readout, focal, bias; not the offset)."""
    return [j for j in fit.idx if j >= 1]


def _prior_z(fit, M, x) -> np.ndarray:
    """``x``'s z-scores under mapping ``M``'s priors, on :func:`_prior_bound`'s
    coordinates."""
    mu, sig, _ = fit.prior_for(M)
    j = _prior_bound(fit)
    return (np.asarray(x)[j] - mu[j]) / sig[j]


def _chi2_quantile(q: float, dof: int) -> float:
    """The ``q`` quantile of a chi-square distribution of ``dof`` degrees of freedom, as
    ``scipy.stats.chi2.ppf`` gives it (the same expression), without importing
    ``scipy.stats`` (a second of every command's start on a 2-core VM)."""
    return float(2.0 * gammaincinv(dof / 2.0, q))


def _prior_distance(fit, M, x) -> float:
    """The sum of ``x``'s squared prior z-scores (chi-square for errors of the priors'
    size)."""
    z = _prior_z(fit, M, x)
    return float(z @ z)


def _far_terms(fit, M, x) -> str:
    """The estimates that lie a prior sd or more from the given values, in words."""
    z = dict(zip(_prior_bound(fit), _prior_z(fit, M, x)))
    mu = fit.prior_for(M)[0]
    out = []
    if abs(z.get(1, 0.0)) >= 1:
        out.append(f"readout {x[1] * 1e3:+.1f} ms ({z[1]:+.1f} sd)")
    if abs(z.get(2, 0.0)) >= 1:
        out.append(f"focal x{np.exp(x[2]):.3f} ({z[2]:+.1f} sd)")
    b = [k for k in (3, 4, 5) if abs(z.get(k, 0.0)) >= 1]
    if b:
        out.append("bias " + ", ".join(f"{'xyz'[k - 3]} {x[k] - mu[k]:+.3f} rad/s "
                                       f"({z[k]:+.1f} sd)" for k in b)
                   + " (camera frame)")
    return "; ".join(out) or "each within a prior sd, but all of them at once"


def _rejected_by_photos(fit, search, x_given, M_given, x, M, n_photos: int) -> str:
    """Why the given parameters may not be kept however little the best found gains on
    them (``""``: they may be). The keep margin protects a right capture from a fit that
    follows the photos' or the gyro's noise; a capture whose PSFs explain some photo worse
    than no blur at all, by more than :data:`~gyrodeblur.blur_evidence.WRONG_BLUR_MARGIN`,
    is not that photo's (or the photo is sharp), and keeping it makes the deblurred photo
    worse than its input. It is left when the best found explains every photo better than
    no blur by :data:`~gyrodeblur.blur_evidence.NO_BLUR_MARGIN`. (A held-out audit: a
    100 Hz log with 0.01 rad/s of noise, 12 ms off, a 26 px blur; the best found was 0.6
    ms off and beat the given by 18.3 against a margin of 22.4; kept, the photo went 17.2
    -> 16.5 dB, at the found offset 31.1.)"""
    given = _gains_per_photo(fit.fine, search.theta_of(x_given, M_given, fit.ubar), n_photos)
    found = _gains_per_photo(fit.fine, search.theta_of(x, M, fit.ubar), n_photos)
    if not (np.isfinite(given).any() and np.isfinite(found).any()):
        return ""
    worst, least = float(np.nanmin(given)), float(np.nanmin(found))
    if worst >= WRONG_BLUR_MARGIN or least < NO_BLUR_MARGIN:
        return ""
    which = "the photo" if n_photos == 1 else f"photo {int(np.nanargmin(given)) + 1}"
    return (f"the given parameters are not kept: no blur at all explains {which} better "
            f"than their PSFs (they gain {worst:+.1f} nats over none; the best found gains "
            f"at least {least:+.1f} on every photo)")


def _gains_per_photo(spectra, theta, n_photos: int) -> np.ndarray:
    """Per photo, how much better (tempered nats, per :data:`_N_PATCHES` patches) the PSFs
    of ``theta`` explain its patches than no blur at all (``nan`` for a photo without
    patches)."""
    g = spectra.gain_over_no_blur(theta) / _TEMPERATURE
    owner = np.array([i for i, _, _ in spectra.points])
    out = np.full(n_photos, np.nan)
    for k in range(n_photos):
        mine = owner == k
        if mine.any():
            out[k] = g[mine].sum() * _N_PATCHES / mine.sum()
    return out


def standing_candidate(results: list, given: np.ndarray, margin: float) -> tuple:
    """The candidate that goes on to the winner's refinement: the best of ``results``
    (rows ``(objective, x, M, ...)``, best first), unless the given mapping's own row is
    within ``margin`` (tempered nats) of it.

    The odds for the mapping the user gave (:data:`_KEEP_MAPPING_NATS`, raised with the
    gyro's noise) are odds against another mapping *at its best*: both candidates have had
    the same refinement. The given parameters' objective, which the keep rule compares
    with, also pays for whatever else is wrong with them (an offset, a noisy gyro's samples
    that a fit can follow), and so let a mirror twin 2.5 nats better than the right
    mapping's own fit replace it under 0.05 rad/s of gyro noise (on lai_manmade_02_w1 of
    the calibration benchmark: PSNR 22.8 -> 12.2 dB)."""
    best = results[0]
    own = [r for r in results if np.allclose(r[2], given)]
    if own and own[0] is not best and own[0][0] - best[0] < margin:
        return own[0]
    return best


def _best_other_mapping(results: list, M: np.ndarray):
    """The best candidate row ``(objective, x, M, ...)`` of a mapping other than ``M``
    (``None`` when there is none)."""
    rows = [r for r in results if not np.allclose(r[2], M)]
    return min(rows, key=lambda r: r[0]) if rows else None


def _gap_to_other_mappings(results: list, M: np.ndarray, objective: float) -> float:
    """How much worse (tempered nats) the best other mapping's candidate scores than
    ``objective`` (``nan`` when there is no other)."""
    rival = _best_other_mapping(results, M)
    return np.nan if rival is None else float(rival[0] - objective)


def searched_mappings(mappings, captures, fix=()) -> tuple[list, str | None]:
    """The axis mappings :func:`calibrate` searches (letters or matrices, as given;
    ``mappings`` as :func:`calibrate` takes it) and, for the user, why a default narrowed
    them or that the given mapping is left out (``None`` where there is nothing to say).
    """
    default = mappings is None
    if default:
        mappings = "phone" if all(cap.log.in_device_axes for cap in captures) else "all"
    if isinstance(mappings, str):
        key = mappings.strip().lower()
        if key not in ("phone", "all"):
            raise InputError.of_argument(
                "mappings", f"'phone', 'all' or a list of axis mappings, got {mappings!r}")
        mappings = list(PHONE_AXIS_LETTERS if key == "phone" else PROPER_AXIS_LETTERS)
    mappings = list(mappings)
    try:                                              # refused before any work
        matrices = [parse_axes(m) for m in mappings]
    except InputError as exc:
        raise InputError.of_argument("mappings", exc.problem) from None
    if "axes" in fix or not mappings:
        return mappings, None
    narrowed = default and mappings == list(PHONE_AXIS_LETTERS)
    why = (f"the gyro log is a phone's, in its device axes: searching the "
           f"{len(PHONE_AXIS_LETTERS)} axis mappings of a camera looking along the device's z "
           "axis, out of its back or its screen (--mappings all, mappings='all': all 24)"
           if narrowed else None)
    given = axes_to_letters(captures[0].axes)      # a measured matrix is searched as well
    if given is not None and not any(np.allclose(captures[0].axes, m) for m in matrices):
        left = (f"the given axis mapping {given} is not among those searched"
                + (": a phone's camera does not look along the device's x or y axis"
                   if narrowed else ""))
        why = left if why is None else f"{why}; {left}"
    return mappings, why


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


def repeated_photo(images) -> tuple[int, int] | None:
    """The first pair ``(i, j)``, ``i < j``, of photos with equal pixels (the same array,
    or a copy: two exposures never are), or ``None``."""
    import hashlib
    if len(images) < 2:                  # one photo (deblur --refine): nothing to compare
        return None
    seen = {}
    for k, img in enumerate(images):
        a = np.asarray(img)
        key = (a.shape, a.dtype.str, hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest())
        if key in seen:
            return seen[key], k
        seen[key] = k
    return None


def _refuse_repeated_images(images) -> None:
    """The same photo twice would count its evidence twice: every uncertainty shrinks by
    sqrt 2 and the mapping's margin doubles with nothing learnt."""
    pair = repeated_photo(images)
    if pair is not None:
        raise InputError(None, f"photos {pair[0] + 1} and {pair[1] + 1} hold the same pixels: "
                               "one photo counted twice would seem twice as sure")


def _refuse_one_start(captures) -> None:
    """A session's photos are taken at different times: two whose descriptions start them
    at one time on one gyro log (one description given for several photos, not their EXIF
    times) would be calibrated on one stretch of the log, which only one of them shows."""
    seen: dict = {}
    for k, cap in enumerate(captures):
        if cap.exposure_start_from_exif:
            continue
        key = (cap.exposure_start - cap.time_offset, id(cap.log) if cap.log.source is None
               else cap.log.source)
        if key in seen:
            raise InputError.of_argument(
                "captures", f"photos {seen[key] + 1} and {k + 1} start exposing at the same "
                            f"time ({cap.exposure_start:.6f} s) on the same gyro log, and "
                            "a session's photos are taken at different times: give each "
                            "its own exposure_start (one capture description per photo, "
                            "--capture a.json,b.json)")
        seen[key] = k


def _shrunk_photos(images, captures, factor: float):
    """The photos resized by ``factor`` (< 1, area averaging, float32) and their captures
    scaled to the sizes they got (checked against the full-size photos first: rounding
    the size may change the aspect ratio slightly, which the scaled cameras follow)."""
    out_imgs, out_caps = [], []
    for k, (img, cap) in enumerate(zip(images, captures)):
        img = check_image(img, f"photo {k + 1}")
        h, w = img.shape[:2]
        full = cap.scaled_to(w, h, source=cap.source)    # the photo fits its capture
        small = _shrunk(img, factor)
        hs, ws = small.shape[:2]
        if min(hs, ws) < 64:
            raise InputError.of_argument(
                "downscale", f"{factor:g} shrinks a {w}x{h} photo to {ws}x{hs}: "
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


def _gyro_noise_level(captures) -> float:
    """The largest white-noise level of the captures' gyro logs, as rad/s per sample at
    :data:`_TYPICAL_GYRO_RATE` samples a second.

    What a PSF feels of white rate noise is the angle it adds up to over the exposure, a
    random walk of ``sigma sqrt(dt T)``: a log sampled at 1 kHz with 0.01 rad/s per sample
    turns a PSF as little as one at 200 Hz with 0.0045. So each log's level
    (:func:`gyrodeblur.gyrolog.rate_noise`) is scaled by ``sqrt(200 Hz / its rate)``."""
    levels = []
    for log, _ in logs_with_captures(captures):
        levels.append(rate_noise(log) * np.sqrt(_TYPICAL_GYRO_RATE * log.sample_interval))
    levels = [v for v in levels if np.isfinite(v)]
    return max(levels) if levels else float("nan")


def _keep_margin(noise: float, n_free: int = 6) -> float:
    """Objective gain needed to leave the given parameters (same mapping), for a gyro
    with white noise ``noise`` rad/s per sample (``nan``: unknown, the base margin) and
    ``n_free`` free coordinates (offset, readout, focal, three bias components; fewer when
    some are fixed). :data:`_KEEP_MARGIN` is the margin with all six free; with fewer, the
    same false-alarm odds under a right capture (twice the gain ~ chi-square with
    ``n_free`` degrees of freedom): 4.5 nats for one free coordinate, 7.0 for three."""
    from scipy.special import gammaincc, gammainccinv

    base = _KEEP_MARGIN
    if 0 < n_free < 6:       # half the chi-square(n_free) quantile at chi-square(6)'s odds
        base = float(gammainccinv(n_free / 2, gammaincc(3, _KEEP_MARGIN)))
    if not np.isfinite(noise):
        return base
    return base * max(1.0, noise / _TYPICAL_GYRO_NOISE)


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
    """``names`` (empty ones dropped; ``None`` or ``"a,b"`` as well as a list) as a set,
    each one of :data:`PARAMETERS`."""
    if names is None:
        names = ()
    elif isinstance(names, str):
        names = names.split(",")
    elif isinstance(names, bytes) or not hasattr(names, "__iter__"):
        raise InputError.of_argument("fix", f"must name parameters (a list, or 'a,b'), got "
                                            f"{names!r}; known: {', '.join(PARAMETERS)}")
    fix = {n.strip() if isinstance(n, str) else n for n in names}
    fix.discard("")
    fix.discard(None)
    unknown = fix - set(PARAMETERS)
    if unknown:
        raise InputError.of_argument("fix", f"unknown parameter(s) {', '.join(sorted(unknown))}; "
                                            f"known: {', '.join(PARAMETERS)}")
    return fix
