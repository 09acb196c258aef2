"""Tests of the calibration's search steps (gyrodeblur.calibration_fit): the shortlist of
mappings, the mirror twin's parameters and the phase tie-break. The search as a whole (and
the twin step on a blurred photo) is tested in test_calibrate.py."""

from __future__ import annotations

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
