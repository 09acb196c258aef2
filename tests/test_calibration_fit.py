"""Tests of the calibration's search steps (gyrodeblur.calibration_fit): the shortlist of
mappings, the mirror twin's parameters and the phase tie-break; and the steps themselves on
stand-in criteria (a mapping's starts, its candidate, the winner's further starts, offset
rivals, the twin tie). The search as a whole (and the twin step on a blurred photo) is
tested in test_calibrate.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gyrodeblur.axes import parse_axes
from gyrodeblur.calibration_fit import (TWIN, _phase_prefers_twin, _twin_parameters,
                                        _unsettled_tie, relative_ranking, shortlist,
                                        with_twin)
from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.gyrolog import GyroLog
from gyrodeblur.spectral_criterion import Corrections


def _capture() -> Capture:
    """A 384x256 capture with a wobbling 200 Hz log (rad/s) and an identity mapping."""
    t = np.arange(0.0, 1.2, 1 / 200)
    w = np.stack([0.5 * np.sin(2 * np.pi * 3 * t), 0.7 * np.cos(2 * np.pi * 2 * t),
                  0.2 * np.sin(2 * np.pi * 4 * t)], 1)
    return Capture(0.5, 0.04, 0.03, Camera.centred(384, 256, 500.0), GyroLog(t, w), axes="Xyz")


def _row(score, letters):
    """A coarse-ranking row: (score, time shift, readout error, focal, mapping, further
    minima)."""
    return (score, 0.0, 0.0, 1.0, parse_axes(letters), ())


def test_the_shortlist_takes_each_ranking_in_turn_and_each_mapping_once():
    flat = [_row(0, "Xyz"), _row(5, "yXZ"), _row(9, "xYz")]
    fitted = [_row(0, "yXZ"), _row(3, "ZXY"), _row(4, "Xyz")]
    got = [r[4] for r in shortlist([flat, fitted])]
    want = [parse_axes(a) for a in ("Xyz", "yXZ", "ZXY", "xYz")]
    assert len(got) == len(want)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    assert relative_ranking(fitted)[1] == ("ZXY", 3.0)


def test_the_best_mappings_twin_joins_the_candidates_once():
    everything = [_row(0, "Xyz"), _row(2, "yXZ"), _row(7, "xYz"), _row(8, "YxZ")]
    top = with_twin(everything[:2], everything)
    assert len(top) == 3
    np.testing.assert_array_equal(top[-1][4], TWIN @ parse_axes("Xyz"))
    assert len(with_twin(top, everything)) == 3        # already in: not added again
    assert with_twin([], everything) == []


def test_the_mirror_twin_is_compared_with_its_bias_mirrored():
    """Negating the camera's x and y rates reflects the PSFs only if the bias is negated with
    them: the twin's parameters give exactly the winner's camera rates, x and y negated; with
    photos of unequal given biases, as nearly as one shared correction can; a fixed bias stays."""
    base = _capture()
    caps = [base.replace(bias=np.array([0.03, -0.01, 0.02])),
            base.replace(bias=np.array([-0.05, 0.04, 0.02]))]
    x = np.array([0.004, -0.002, 0.05, 0.01, 0.04, -0.03])
    M = parse_axes("Xyz")

    def rates(v, axes, cap):
        th = Corrections(axes=axes, offset=v[0], readout=v[1], focal=float(np.exp(v[2])),
                    bias=np.asarray(v[3:6], float))
        return th.apply(cap).camera_rates()[1]

    def miss(v, cap):               # twin's rates against the winner's reflected
        return rates(v, TWIN @ M, cap) - rates(x, M, cap) @ TWIN

    xt = _twin_parameters(x, [caps[0].bias])
    np.testing.assert_allclose(xt[:3], x[:3])
    np.testing.assert_allclose(miss(xt, caps[0]), 0.0, atol=1e-12)
    # left as it is, the bias turns the twin's rates away from the reflection
    assert np.abs(miss(x, caps[0])).max() > 0.05
    # unequal given biases: the misses cancel over the photos, and each is smaller than
    # with the first photo's bias alone
    xt2 = _twin_parameters(x, [c.bias for c in caps])
    m0, m1 = miss(xt2, caps[0])[0], miss(xt2, caps[1])[0]
    np.testing.assert_allclose(m0 + m1, 0.0, atol=1e-12)
    worst_first = max(np.abs(miss(xt, c)[0]).max() for c in caps)
    assert max(np.abs(m0).max(), np.abs(m1).max()) < worst_first
    # a fixed bias is not changed
    np.testing.assert_array_equal(_twin_parameters(x, [caps[0].bias], fix={"bias"}), x)


def test_the_twin_needs_a_clear_phase_preference():
    """Without frame registration the twin replaces the winner only when the spectra cannot
    tell the two apart (its refined objective less than 2 tempered nats worse) and the
    phase prefers it by two standard errors, not by a coin toss."""
    clear = np.array([-0.05, -0.04, -0.06, -0.03, -0.05])
    toss = np.array([0.02, -0.03, 0.01, -0.04, 0.015, -0.02, -0.01, 0.01, -0.03])   # mean < 0
    assert _phase_prefers_twin(-0.8, clear)
    assert _phase_prefers_twin(0.0, clear)
    assert _phase_prefers_twin(0.5, clear)               # a tie the spectra cannot break
    assert not _phase_prefers_twin(-0.8, toss)
    assert not _phase_prefers_twin(2.5, clear)           # the refined twin scores worse
    assert not _phase_prefers_twin(-0.8, clear[:1])      # one patch: no standard error


def test_a_twin_tie_the_phase_cannot_settle_is_unsettled():
    """A tie of the objectives that the phase decides by under three standard errors, either
    way, is reported (calibrate warns that the mapping is uncertain); a clear phase, or a
    clear objective, is not."""
    clear = np.array([-0.05, -0.04, -0.06, -0.03, -0.05])          # ~9 errors for the twin
    weak = np.array([-0.05, 0.01, -0.04, -0.02, 0.02, -0.03, 0.0, -0.01])   # ~1.7 errors
    assert _unsettled_tie(0.3, weak)
    assert _unsettled_tie(-1.5, -weak)                   # the winner kept by a weak phase
    assert _unsettled_tie(0.3, weak[:1])                 # one patch: no evidence
    assert not _unsettled_tie(0.3, clear)
    assert not _unsettled_tie(0.3, -clear)
    assert not _unsettled_tie(2.5, weak)                 # the objectives are not tied



def _ratios_at(z: float, n: int = 9) -> np.ndarray:
    """``n`` per-patch log ratios whose mean is exactly ``z`` standard errors of itself."""
    e = np.linspace(-1.0, 1.0, n)
    e = (e - e.mean()) / e.std(ddof=1)
    return e + z / np.sqrt(n)


def test_the_twin_rules_sit_at_two_and_three_standard_errors_and_two_nats():
    """The thresholds themselves, just either side: the twin replaces the winner from two
    standard errors of phase preference and under 2 nats of objective; a tie is unsettled
    under three standard errors either way."""
    assert _phase_prefers_twin(0.0, _ratios_at(-2.1))
    assert not _phase_prefers_twin(0.0, _ratios_at(-1.9))
    assert _phase_prefers_twin(1.9, _ratios_at(-5.0))
    assert not _phase_prefers_twin(2.1, _ratios_at(-5.0))
    for sign in (1.0, -1.0):
        assert _unsettled_tie(0.0, _ratios_at(2.9 * sign))
        assert not _unsettled_tie(0.0, _ratios_at(3.1 * sign))
    assert _unsettled_tie(1.9, _ratios_at(0.5)) and _unsettled_tie(-1.9, _ratios_at(0.5))
    assert not _unsettled_tie(2.1, _ratios_at(0.5))
    assert not _unsettled_tie(-2.1, _ratios_at(0.5))


def test_the_line_fit_finds_distinct_minima_best_first():
    """Two patches whose cost curves dip at two time shifts 0.2 s apart (a far basin
    leads the coarse grid): both minima come back, best first, each at its readout
    error; the slope beside the best is not a minimum of its own."""
    from gyrodeblur.calibration_search import line_fit, line_fit_minima
    taus = np.arange(-0.3, 0.3 + 1e-9, 0.002)
    u = np.array([-0.25, 0.25])                     # patch rows about the pivot

    def dip(at, depth, width=0.004):
        return -depth * np.exp(-0.5 * ((taus - at) / width) ** 2)

    # the readout error kap shifts patch j's dip by kap * u_j: dips at tau0 - kap u_j
    kap = 0.008
    C = np.stack([dip(0.10 - kap * u[0], 5) + dip(-0.10, 4),
                  dip(0.10 - kap * u[1], 5) + dip(-0.10, 4)], 1)
    kappas = np.array([-0.008, 0.0, 0.008])
    got = line_fit_minima(C, taus, u, kappas, 3, 0.02)
    assert got[0][:3] == line_fit(C, taus, u, kappas)
    assert got[0][1] == pytest.approx(0.10, abs=1e-9) and got[0][2] == pytest.approx(kap)
    assert got[1][1] == pytest.approx(-0.10, abs=1e-9) and got[1][2] == 0.0
    assert got[1][0] > got[0][0]
    # the rest of the curve is flat ground: no third minimum there, nor on a dip's slope
    assert len(got) == 2
    assert line_fit_minima(np.zeros_like(C), taus, u, kappas, 3, 0.02) == []
    one = C[:1]
    assert line_fit_minima(one, taus[:1], u, kappas, 3, 0.02) == [line_fit(one, taus[:1], u,
                                                                            kappas)]


def test_the_time_shift_is_the_pivot_rows_whatever_the_readout():
    """The search's first coordinate is the time shift at the pivot row ``ubar`` (the mean
    patch row), so that it and the readout correction are nearly uncorrelated: in the
    corrected capture the pivot row is read against the log exactly ``x[0]`` earlier
    than in the given one, whatever the readout correction, while other rows move with
    the readout."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.calibration_search import SearchSpace

    cap = _capture()
    photos = [CalibrationPhoto(np.full((256, 384), 0.5, np.float32), cap, "linear", 0)]
    search = SearchSpace(photos, set(), 0.04)

    def log_time(c, u):               # where on the log the row at fraction u starts
        return c.exposure_start + c.readout_time * u - c.time_offset

    for ubar in (0.2, 0.5, 0.8):
        for kappa in (-0.01, 0.0, 0.012):
            x = np.array([0.004, kappa, 0.03, 0.0, 0.0, 0.0])
            got = search.theta_of(x, cap.axes, ubar).apply(cap)
            assert log_time(got, ubar) == pytest.approx(log_time(cap, ubar) - 0.004, abs=1e-12)
            assert log_time(got, 1.0) - log_time(got, 0.0) == pytest.approx(0.03 + kappa)


def test_the_search_space_covers_the_shifts_the_log_allows():
    """The log (0 .. 1.195 s, offset 0) must cover each photo's window (start 0.5 s, 40 ms
    exposure, a readout searched up to 1.6 times the given 30 ms, 5 ms slack): time shifts
    from ``0.5 + 0.048 + 0.005 + 0.04 - 1.195`` to ``0.5``, cut to the offset range; a fixed
    offset allows none but 0, a log that cannot cover that slack at any shift is refused; the vector's focal
    coordinate is the log of the scale, its last three the bias correction."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.calibration_search import SearchSpace
    from gyrodeblur.errors import InputError
    from gyrodeblur.gyrolog import GyroLog

    cap = _capture()
    photos = [CalibrationPhoto(np.full((256, 384), 0.5, np.float32), cap, "linear", 0)]
    s = SearchSpace(photos, set(), 1.0)
    assert s.tau_lo == pytest.approx(0.593 - cap.log.t[-1]) and s.tau_hi == pytest.approx(0.5)
    assert (SearchSpace(photos, set(), 0.2).tau_lo, SearchSpace(photos, set(), 0.2).tau_hi) == (-0.2, 0.2)
    assert (SearchSpace(photos, {"offset"}, 1.0).tau_lo, SearchSpace(photos, {"offset"}, 1.0).tau_hi) == (0, 0)
    t = np.arange(0.49, 0.5801, 0.005)                # covers the window, not its slack
    short = cap.replace(log=GyroLog(t, np.zeros((t.size, 3))))
    with pytest.raises(InputError, match="does not cover"):
        SearchSpace([CalibrationPhoto(photos[0].image, short, "linear", 0)], set(), 0.5)
    th = s.theta_of(np.array([0.0, 0.0, np.log(1.1), 0.01, -0.02, 0.03]), cap.axes, 0.5)
    assert th.focal == pytest.approx(1.1)
    np.testing.assert_array_equal(th.bias, [0.01, -0.02, 0.03])


class _Quadratic:
    """A stand-in criterion: cost ``0.5 |A (v - v_star)|^2`` (exactly Gauss-Newton)."""

    def __init__(self, A, v_star):
        self.A, self.v_star, self.moves = A, v_star, []

    def set_envelope(self, theta):
        pass

    def cost(self, v):
        self.moves.append(np.array(v))
        r = self.A @ (v - self.v_star)
        return 0.5 * float(r @ r)

    def gauss_newton(self, theta_of, v, idx, hs):
        r = self.A @ (v - self.v_star)
        J = self.A[:, idx]
        return 0.5 * float(r @ r), J.T @ r, J.T @ J, (J.T @ r)[None]


def test_levenberg_marquardt_finds_the_posterior_mode_of_a_quadratic():
    """On a quadratic cost tempered by ``T`` with Gaussian priors the objective is
    quadratic: the refinement ends at its exact minimum, reports the objective there and
    its Hessian ``A^T A / T + diag(1 / sigma^2)``; each trial step stays within the caps;
    :func:`objective` is the same objective."""
    from gyrodeblur.calibration_search import lm_refine, objective

    rng = np.random.default_rng(0)
    A = rng.normal(size=(8, 3))
    v_star = np.array([0.3, -0.2, 0.1])
    T = 4.0
    mu, sig = np.zeros(3), np.array([0.5, np.inf, 0.2])
    prec = np.where(np.isfinite(sig), 1 / sig ** 2, 0.0)
    H = A.T @ A / T + np.diag(prec)
    want = np.linalg.solve(H, A.T @ A @ v_star / T + prec * mu)
    spectra = _Quadratic(A, v_star)
    caps = np.full(3, 0.05)
    x, f, F, sc = lm_refine(spectra, lambda v: v, np.zeros(3), [0, 1, 2], np.full(3, -1.0),
                            np.full(3, 1.0), np.full(3, 1e-6), caps, (mu, sig, T), iters=60,
                            tol=0.0)
    np.testing.assert_allclose(x, want, atol=1e-6)
    np.testing.assert_allclose(F, H, rtol=1e-12)
    assert f == pytest.approx(objective(spectra, lambda v: v, x, [0, 1, 2], (mu, sig, T)), rel=1e-12)
    r = A @ (x - v_star)
    assert f == pytest.approx(0.5 * r @ r / T + 0.5 * np.sum(prec * (x - mu) ** 2), rel=1e-9)
    steps = np.diff(np.array([np.zeros(3)] + spectra.moves[:1]), axis=0)
    assert np.abs(steps).max() <= 0.05 + 1e-12


def test_equal_line_totals_keep_the_first_kappa():
    """Patches all on the pivot row: the readout error moves none of them, every ``kappa``
    totals the same, and both line fits report the first ``kappa`` at the same minimum."""
    from gyrodeblur.calibration_search import line_fit, line_fit_minima

    taus = np.arange(-0.05, 0.05 + 1e-9, 0.002)
    C = np.stack([(taus - 0.01) ** 2, 2 * (taus - 0.01) ** 2], 1)
    u = np.zeros(2)
    kappas = np.array([0.0, -0.01, 0.01])
    best = line_fit(C, taus, u, kappas)
    assert best[1] == pytest.approx(0.01) and best[2] == 0.0
    assert line_fit_minima(C, taus, u, kappas, 1, 0.02)[0] == best


def test_the_psf_extent_is_the_median_over_the_time_shifts():
    """A camera whose pitch rate grows with time (1 rad/s at the exposure, 20 ms, f 500 px):
    its largest PSF extent is about ``f w T`` = 10 px, and asked over three time shifts
    the median of their extents is the middle shift's."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.calibration_search import psf_extent_and_path
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.spectral_criterion import Corrections

    t = np.arange(0.0, 1.2, 0.005)
    w = np.stack([2 * t, np.zeros_like(t), np.zeros_like(t)], 1)
    cap = Capture(0.5, 0.02, 0.0, Camera.centred(384, 256, 500.0), GyroLog(t, w))
    photos = [CalibrationPhoto(np.full((256, 384), 0.5, np.float32), cap, "linear", 0)]
    th = Corrections(axes=np.eye(3))
    ext, path = psf_extent_and_path(photos, th, [0.0])
    assert ext == pytest.approx(10.0, rel=0.1) and path == pytest.approx(ext, rel=0.02)
    assert psf_extent_and_path(photos, th, [-0.2, 0.0, 0.2]) == (ext, path)


# ------------------------------------------------ the steps on stand-in criteria

def _theta_of(x, M, ubar):
    from gyrodeblur.calibration_search import SearchSpace
    return SearchSpace.theta_of(None, x, M, ubar)


def test_offset_rivals_are_other_basins_within_two_nats_the_lowest_of_each_offset():
    """Basins of the winner's mapping (objectives against the winner's -100): those whose
    first-row offset lies more than 3 ms away and scores within 2 nats, one per offset
    (the lowest), best first; none with the offset fixed."""
    from gyrodeblur.calibration_fit import CalibrationFit

    def basin(shift, readout, f):
        return np.r_[shift, readout, 0.0, 0.0, 0.0, 0.0], f

    basins = [basin(0.0, 0.0, -100.0),            # the winner
              basin(0.010, 0.0, -98.5),           # the same offset as the next, higher
              basin(0.002, 0.0, -99.9),           # within 3 ms
              basin(-0.010, 0.004, -99.0),        # offset -0.008 (the first row's)
              basin(0.0105, 0.0, -99.2),
              basin(0.020, 0.0, -97.9)]           # 2.1 nats behind
    fit = SimpleNamespace(fix=set(), ubar=0.5, basins=basins,
                          search=SimpleNamespace(theta_of=_theta_of))
    got = CalibrationFit.offset_rivals(fit, np.eye(3), np.zeros(6), -100.0)
    assert [tuple(np.round(r, 9)) for r in got] == [(0.0105, 0.0, 0.8), (-0.008, 0.004, 1.0)]
    fit.fix = {"offset"}
    assert CalibrationFit.offset_rivals(fit, np.eye(3), np.zeros(6), -100.0) == []


def test_the_working_scale_band_and_trace_samples():
    """The working scale shrinks the largest PSF to 32 px (never enlarges), the patch is
    128 px or what the photo holds (a multiple of 16); a trace has a sample per half
    working pixel and 30 % to spare, 32 to 400; the band is cut above 1.10 blockiness
    (the benchmark's PNGs measure up to 1.086; the false positive named, 1.144, is cut)."""
    from gyrodeblur.calibration_fit import (COMPRESSED_BAND, fine_samples, spectral_band,
                                            working_patch)
    assert working_patch(10.0, 1000) == (1.0, 128)
    assert working_patch(64.0, 1000) == (0.5, 128)
    assert working_patch(64.0, 200) == (0.5, 96)
    assert fine_samples(100.0, 1.0) == 260 and fine_samples(100.0, 0.5) == 130
    assert fine_samples(1.0, 1.0) == 32 and fine_samples(1000.0, 1.0) == 400
    assert spectral_band(1.086) == np.inf and spectral_band(1.144) == COMPRESSED_BAND


def test_of_equal_objectives_the_first_refinement_stands():
    from gyrodeblur.calibration_fit import _lowest_of
    a, b, c = (np.zeros(6), -5.0), (np.ones(6), -5.0), (np.full(6, 2.0), -5.1)
    assert _lowest_of([a, b]) is a and _lowest_of([b, a]) is b
    assert _lowest_of([a, c, b]) is c


def test_identical_phase_ratios_have_no_standard_error():
    """Every patch's ratio the same: no standard error to count the preference in, so the
    phase does not settle a tie (and nothing divides by zero)."""
    from gyrodeblur.calibration_fit import _phase_z
    same = np.full(6, -0.0625)
    assert _phase_z(same) == 0.0 and _unsettled_tie(0.3, same)


def test_an_unsettled_twin_tie_is_told_from_the_mapping_taken():
    """The tie the twin step reports is ``(the mapping left, its objective minus the
    taken one's, the phase's preference for the taken one in standard errors)``: the twin
    refined 0.5 worse and preferred by 2.5 standard errors is taken, the winner left 0.5
    better and disfavoured by 2.5; preferred by 3.5 it is a clear decision; disfavoured by
    1, the winner stays with the twin 0.5 behind."""
    from gyrodeblur.calibration_fit import CalibrationFit
    M = parse_axes("Xyz")
    Mt = TWIN @ M

    def twin_step(log_ratio):
        fit = SimpleNamespace(fix=set(), lo=np.full(6, -1.0), hi=np.full(6, 1.0), ubar=0.5,
                              reg=None, search=SimpleNamespace(theta_of=_theta_of))
        fit.fine = SimpleNamespace(points=[0] * 9, set_envelope=lambda th: None,
                                   cost=lambda th: 0.0)
        fit.refine = lambda N, x, iters: (x, -99.5, None, None)
        fit.phase_patches = lambda: SimpleNamespace(sparsity=lambda th: np.exp(log_ratio)
                                                    if np.allclose(th.axes, Mt) else 1.0)
        return CalibrationFit.mirror_twin(fit, M, np.zeros(6), -100.0, [np.zeros(3)])

    taken, twin, _, tie = twin_step(_ratios_at(-2.5))
    assert np.array_equal(taken, Mt) and twin[1] == -99.5
    assert np.array_equal(tie[0], M) and tie[1] == pytest.approx(-0.5)
    assert tie[2] == pytest.approx(2.5)
    assert twin_step(_ratios_at(-3.5))[3] is None
    taken, twin, _, tie = twin_step(_ratios_at(1.0))
    assert np.array_equal(taken, M) and twin is None
    assert np.array_equal(tie[0], Mt) and tie[1:] == pytest.approx((0.5, 1.0))


def test_a_twin_the_phase_clearly_prefers_but_the_objective_does_not_is_reported():
    """The objective keeping the winner by more than a tie while the phase prefers the
    twin by 3 standard errors or more: the two judges disagree, and the twin step says so
    (a 2.5 px blur's wrong mapping had gone unwarned, its twin 4.5 worse and preferred by
    9.6 errors). The winner stays; the report carries the twin, its objective gap and the
    phase's (negative) preference for the winner. With the phase for the winner, or
    weakly for the twin, nothing is reported."""
    from gyrodeblur.calibration_fit import CalibrationFit
    M = parse_axes("Xyz")
    Mt = TWIN @ M

    def twin_step(log_ratio, gain=4.5):
        fit = SimpleNamespace(fix=set(), lo=np.full(6, -1.0), hi=np.full(6, 1.0), ubar=0.5,
                              reg=None, search=SimpleNamespace(theta_of=_theta_of))
        fit.fine = SimpleNamespace(points=[0] * 9, set_envelope=lambda th: None,
                                   cost=lambda th: 0.0)
        fit.refine = lambda N, x, iters: (x, -100.0 + gain, None, None)
        fit.phase_patches = lambda: SimpleNamespace(sparsity=lambda th: np.exp(log_ratio)
                                                    if np.allclose(th.axes, Mt) else 1.0)
        return CalibrationFit.mirror_twin(fit, M, np.zeros(6), -100.0, [np.zeros(3)])

    taken, twin, _, tie = twin_step(_ratios_at(-9.6))
    assert np.array_equal(taken, M) and twin is None
    assert np.array_equal(tie[0], Mt) and tie[1:] == pytest.approx((4.5, -9.6))
    assert twin_step(_ratios_at(-2.5))[3] is None       # a weak preference: no conflict
    assert twin_step(_ratios_at(9.6))[3] is None        # both judges for the winner


def _start_fit(ubar, fix=()):
    """What :meth:`CalibrationFit.start_vec` reads of a fit: the prior's bias 0."""
    return SimpleNamespace(fix=set(fix), ubar=ubar, lo=np.full(6, -1.0), hi=np.full(6, 1.0),
                           moved_bias=lambda M, step=None: np.zeros(3))


def test_a_start_times_every_row_as_its_line_fit_does():
    """A line fit puts row ``u`` at time shift ``tau0 - kappa (u - 1/2)``: the start made
    from it reads every row of the corrected capture that much earlier on the log, whatever
    the pivot row, and scales the focal length as asked; with the offset fixed, the pivot
    row stays where it was."""
    from gyrodeblur.calibration_fit import CalibrationFit
    cap = _capture()
    tau0, kap = 0.004, 0.01

    def log_time(c, u):
        return c.exposure_start + c.readout_time * u - c.time_offset

    for ubar in (0.2, 0.5, 0.9):
        x = CalibrationFit.start_vec(_start_fit(ubar), tau0, kap, cap.axes, 1.1)
        got = _theta_of(x, cap.axes, ubar).apply(cap)
        for u in (0.0, 0.3, 1.0):
            assert log_time(got, u) == pytest.approx(log_time(cap, u) - (tau0 - kap * (u - 0.5)),
                                                     abs=1e-12)
        assert got.camera.fx == pytest.approx(1.1 * cap.camera.fx)
    x = CalibrationFit.start_vec(_start_fit(0.0, {"offset"}), tau0, kap, cap.axes)
    assert x[0] == 0.0 and _theta_of(x, cap.axes, 0.0).offset == 0.0


def _starts_of(dips, width, ubar, uc, kappas):
    """:meth:`CalibrationFit.candidate_starts` at time shift 0 where each focal scale's
    patch costs are dips (``dips``: focal -> (time shift, depth)) ``width`` s wide."""
    from gyrodeblur.calibration_fit import CalibrationFit
    from gyrodeblur.spectral_criterion import Corrections

    def costs(theta, taus, rows):
        at, depth = dips[round(theta.focal, 6)]
        curve = -depth * np.exp(-0.5 * ((taus - at) / width) ** 2)
        return np.stack([curve] * len(uc), 1)

    fit = _start_fit(ubar)
    fit.search = SimpleNamespace(tau_lo=-0.04, tau_hi=0.04, theta_of=_theta_of)
    fit.fine = SimpleNamespace(set_envelope=lambda th: None, costs=costs)
    fit.theta0, fit.fgrid = Corrections(axes=np.eye(3)), list(dips)
    fit.uc, fit.kappas = np.asarray(uc), np.asarray(kappas)
    fit.start_vec = lambda *args, **kw: CalibrationFit.start_vec(fit, *args, **kw)
    return CalibrationFit.candidate_starts(fit, 0.0, 0.0, np.eye(3))


def test_a_mappings_starts_are_its_best_line_fits_more_than_4_ms_apart():
    """Per-focal cost curves that dip at 0 (deepest), 2, 10, -12 and 14 ms: the starts are
    the three best that lie more than 4 ms from each better one (2 ms is the same basin as
    0), each with its focal scale. Apart means at the pivot row: patches at row 0.9 whose
    focal 1.1 dips 2.9 ms late fit best 6 ms late with a readout 6 ms longer, which puts
    the pivot row 3.6 ms late, not a start of its own (nor is 6 ms of readout)."""
    starts = _starts_of({1.0: (0.0, 3.0), 1.1: (0.002, 2.0), 1.2: (0.010, 1.0),
                         1.3: (-0.012, 0.5), 1.4: (0.014, 0.2)}, 0.003, 0.5, [-0.25, 0.25],
                        [0.0])
    assert [round(x[0], 9) for x in starts] == [0.0, 0.010, -0.012]
    np.testing.assert_allclose([np.exp(x[2]) for x in starts], [1.0, 1.2, 1.3])
    starts = _starts_of({1.0: (0.0, 3.0), 1.1: (0.0029, 2.0), 1.2: (-0.010, 1.0)}, 0.001,
                        0.9, [0.4, 0.4], [0.0, 0.006])
    assert [round(x[0], 9) for x in starts] == [0.0, -0.010] and [x[1] for x in starts] == [0, 0]
    np.testing.assert_allclose([np.exp(x[2]) for x in starts], [1.0, 1.2])


def test_the_winners_further_starts():
    """The winner's refinements, recorded on a stand-in criterion (a quadratic bowl;
    "refined" starts stay put): its start and other starts refined fully; from the given
    focal length and the prior's bias, the focal length held first; time shifts 2, 4, 6 ms
    either side of the best from the given readout, focal length and bias, the best two
    refined fully; readout corrections of -30 to +30 % of the given 30 ms but the one
    within 5 % of the best's, the best two refined fully; the lowest wins."""
    from gyrodeblur.calibration_fit import CalibrationFit
    b_prior = np.array([0.02, -0.01, 0.0])
    bottom = np.r_[-0.0035, 0.0055, 0.0, b_prior]
    weights = np.array([1e4, 1e3, 1.0, 1.0, 1.0, 1.0])
    calls = []

    class Steps:
        def map(self, method, arglist):
            out = []
            for args in arglist:
                calls.append((method, np.array(args[1])) + tuple(args[2:]))
                x0 = np.array(args[1])
                out.append((x0, float(weights @ (x0 - bottom) ** 2), None, None))
            return out

    prior = SimpleNamespace(for_mapping=lambda M: (b_prior, None))
    fit = SimpleNamespace(idx=[0, 1, 2, 3, 4, 5], lo=np.full(6, -1.0), hi=np.full(6, 1.0),
                          fix=set(), bias_prior=prior,
                          search=SimpleNamespace(readout_unknown=False, r0=0.03))
    fit._scan = lambda *args: CalibrationFit._scan(fit, *args)
    x = np.r_[0.001, 0.002, 0.05, 0.01, 0.0, 0.0]
    xa = np.r_[0.009, 0.0, 0.0, 0.0, 0.0, 0.0]
    best = CalibrationFit.refine_winner(fit, np.eye(3), x, [xa], Steps())

    def starts(method, k0, k1):
        assert all(c[0] == method for c in calls[k0:k1]), calls[k0:k1]
        return [c[1] for c in calls[k0:k1]]

    np.testing.assert_array_equal(starts("refine_fully", 0, 2), [x, xa])
    given = np.r_[x[:2], 0.0, b_prior]                       # x is the best so far
    assert calls[2][0] == "refine" and calls[2][2:] == (6, [0, 1, 3, 4, 5])
    np.testing.assert_array_equal(calls[2][1], given)
    np.testing.assert_array_equal(starts("refine_fully", 3, 4), [given])
    shifts = starts("refine", 4, 10)
    np.testing.assert_allclose([s[0] for s in shifts],
                               0.001 + np.array([-0.006, -0.004, -0.002, 0.002, 0.004, 0.006]),
                               atol=1e-12)
    assert all(np.array_equal(s[1:], np.r_[0.0, 0.0, b_prior]) for s in shifts)
    assert all(c[2] == 4 for c in calls[4:10])
    np.testing.assert_allclose([s[0] for s in starts("refine_fully", 10, 12)],
                               [-0.003, -0.005], atol=1e-12)           # the best two
    readouts = starts("refine", 12, 18)
    np.testing.assert_allclose([s[1] for s in readouts],
                               0.03 * np.array([-0.3, -0.2, -0.1, 0.1, 0.2, 0.3]), atol=1e-12)
    assert all(s[0] == pytest.approx(-0.003) for s in readouts)
    np.testing.assert_allclose([s[1] for s in starts("refine_fully", 18, 20)], [0.006, 0.003],
                               atol=1e-12)
    assert len(calls) == 20
    np.testing.assert_allclose(best[0], np.r_[-0.003, 0.006, 0.0, b_prior], atol=1e-12)


def test_a_candidate_is_its_mappings_lowest_start():
    """Each mapping's starts (from its coarse minimum and, over a wide range, its further
    minima) refined four iterations: the candidate is the lowest, the others kept as its
    other starts, in the order of the rows."""
    from gyrodeblur.calibration_fit import CalibrationFit
    M1, M2 = parse_axes("Xyz"), parse_axes("YXz")
    rows = [(0.0, 0.001, 0.0, 1.0, M1, ((0.2, 0.0),), None),
            (1.0, -0.002, 0.0, 1.0, M2, (), None)]

    class Steps:
        def map(self, method, arglist):
            if method == "candidate_starts":      # two starts per minimum
                return [[np.full(6, t), np.full(6, t + 0.5)] for t, _, _, _ in arglist]
            assert method == "refine"
            return [(x0, float((x0[0] - 0.2) ** 2), None, None) for _, x0, _ in arglist]

    fit = SimpleNamespace(say=lambda msg: None)
    (f1, x1, N1, alts1), (f2, x2, N2, alts2) = CalibrationFit.candidates(fit, rows, Steps())
    assert np.array_equal(N1, M1) and np.array_equal(N2, M2)
    assert f1 == 0.0 and x1[0] == 0.2                    # the far minimum's start
    assert sorted(a[0] for a in alts1) == [0.001, 0.501, 0.7]
    assert x2[0] == -0.002 and [a[0] for a in alts2] == [0.498]


def _textured_fit(cap, fix=(), n_patches=9, img=None, offset_range=0.04):
    """A :class:`CalibrationFit` on a photo of noise texture (or ``img``) under ``cap``."""
    from gyrodeblur.bias_prior import BiasPrior
    from gyrodeblur.calibration_fit import CalibrationFit
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.calibration_search import SearchSpace
    if img is None:
        img = np.random.default_rng(1).uniform(0.2, 0.8, (256, 384)).astype(np.float32)
    photos = [CalibrationPhoto(img, cap, "linear", 0)]
    return CalibrationFit(photos, SearchSpace(photos, set(fix), offset_range), set(fix),
                          BiasPrior(np.zeros(3)), n_patches, 1, lambda msg: None)


def test_the_search_grids_and_priors():
    """The module docstring's grids and priors: readout errors up to +-35 % (8), focal
    scales 0.8-1.25 (7; the given one alone when fixed, so every start holds it), priors of
    +-30 % on the readout (at least 2 ms: a global shutter's 0 is held near 0), +-10 % on
    the focal length, PRIOR_BIAS on the bias and none on the time shift; an unknown readout
    under its own weak prior; at least 3 patches a photo."""
    from gyrodeblur.bias_prior import PRIOR_BIAS
    from gyrodeblur.capture import UNKNOWN_READOUT_PRIOR
    cap = _capture()
    fit = _textured_fit(cap)
    np.testing.assert_allclose(fit.kappas, 0.03 * np.linspace(-0.35, 0.35, 8))
    np.testing.assert_allclose(fit.fgrid, [0.8, 0.87, 0.94, 1.0, 1.07, 1.15, 1.25])
    mu, sig, _ = fit.prior_for(cap.axes)
    np.testing.assert_array_equal(mu, np.zeros(6))
    np.testing.assert_allclose(sig, [np.inf, 0.009, 0.1, PRIOR_BIAS, PRIOR_BIAS, PRIOR_BIAS])
    assert _textured_fit(cap.replace(readout_time=0.0)).prior_for(cap.axes)[1][1] == 0.002
    unknown = _textured_fit(cap.replace(readout_time=0.0, readout_time_unknown=True))
    mu, sig, _ = unknown.prior_for(cap.axes)
    assert (mu[1], sig[1]) == UNKNOWN_READOUT_PRIOR
    held = _textured_fit(cap, fix={"focal", "readout"})
    assert held.fgrid == [1.0] and np.array_equal(held.kappas, [0.0])
    assert all(x[2] == 0.0 for x in held.candidate_starts(0.0, 0.0, cap.axes))
    assert len(_textured_fit(cap, n_patches=1).fine.points) == 3


@pytest.mark.parametrize("readout", [0.021, 0.041])
def test_the_given_parameters_of_a_readout_not_given_have_their_best_readout(readout):
    """A readout left out is 0 only as a placeholder: the "given parameters" that
    calibration keeps when the photo prefers nothing else clearly are the given ones with
    the readout that suits them best (the given time offset held), not a global shutter's.
    The photo: noise texture blurred under a readout between the scanned ones; found
    within 2 ms (the scan's step is 6 ms). With a time-offset range too narrow for the
    longest readouts at the given offset, those are not tried, and the offset still holds.
    A readout that was given stays as given."""
    from scipy import ndimage

    from gyrodeblur.simulate import simulate_blur
    cap = _capture().replace(readout_time=readout)
    rng = np.random.default_rng(3)
    scene = ndimage.gaussian_filter(rng.uniform(0, 1, (256, 384)), 1.0).astype(np.float32)
    blurred = simulate_blur(scene, cap, transfer="linear")
    unknown = cap.replace(readout_time=0.0, readout_time_unknown=True)
    for offset_range in (0.04, 0.003):
        fit = _textured_fit(unknown, fix={"axes"}, img=blurred, offset_range=offset_range)
        f, x = fit.given_objective(cap.axes)
        theta = fit.theta_of(cap.axes)(x)
        assert theta.offset == pytest.approx(0.0, abs=1e-12) and theta.focal == 1.0
        if offset_range == 0.04:
            assert abs(theta.readout - readout) < 0.002, theta.readout
            f0 = fit._given_with_readout(cap.axes, x * 0)(0.0)[0]  # a global shutter's
            assert f < f0
        else:                   # x[0] = -ubar readout must stay within the offset bounds
            assert fit.lo[0] <= x[0] <= fit.hi[0] and theta.readout > 0.005
        # judged against the best found: the best readout within JUDGED_READOUT_REACH of
        # its (here 27 ms), the offset held, as near as the bounds allow
        f27, x27 = fit.given_objective(cap.axes, readout=0.027)
        theta = fit.theta_of(cap.axes)(x27)
        assert theta.offset == pytest.approx(0.0, abs=1e-12) and fit.lo[0] <= x27[0] <= fit.hi[0]
        if offset_range == 0.04:        # the true readout, or the window's nearer end
            assert abs(theta.readout - np.clip(readout, 0.021, 0.033)) < 0.002, theta.readout
        else:
            top = -fit.lo[0] / fit.ubar        # the readout that puts x[0] at its bound
            assert 0.021 - 1e-9 <= theta.readout <= top + 1e-9 < 0.033
    given = _textured_fit(cap, fix={"axes"}, img=blurred)
    _, x = given.given_objective(cap.axes)
    assert x[0] == 0.0 and x[1] == 0.0
