import numpy as np
from scipy.spatial.transform import Rotation

from gyrodeblur.orientation import Orientation, quat_from_rotvec, quat_to_matrix


def test_constant_rate_integrates_exactly():
    rng = np.random.default_rng(1)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    t = np.arange(201) / 200.0                        # 1 s at 200 Hz
    w = np.tile(axis * 1.3, (t.size, 1))
    o = Orientation(t, w, t_ref=0.0)
    R = o.matrices(1.0)
    expected = Rotation.from_rotvec(axis * 1.3).as_matrix()
    angle_err = np.linalg.norm(Rotation.from_matrix(R.T @ expected).as_rotvec())
    assert angle_err < 1e-6
    # between samples too
    R = o.matrices(0.4337)
    expected = Rotation.from_rotvec(axis * 1.3 * 0.4337).as_matrix()
    assert np.abs(R - expected).max() < 1e-9


def test_reference_time_is_identity_and_relative():
    t = np.linspace(0, 1, 101)
    w = np.stack([np.sin(5 * t), np.cos(3 * t), 0.2 * t], axis=1)
    o = Orientation(t, w, t_ref=0.37)
    assert np.abs(o.matrices(0.37) - np.eye(3)).max() < 1e-12
    o0 = Orientation(t, w, t_ref=0.0)
    # R_ref(t) = R0(t_ref)^T R0(t)
    expect = o0.matrices(0.37).T @ o0.matrices(0.8)
    assert np.abs(o.matrices(0.8) - expect).max() < 1e-12


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def test_body_frame_composition_order():
    # a rate whose axis turns: R(t) solves dR/dt = R [w]_x (body frame); the space-frame
    # product, dR/dt = [w]_x R, differs from it by more than 0.05 here
    from scipy.integrate import solve_ivp

    def rate(t):
        return np.array([1.5 * np.cos(3 * t), 2.0 * np.sin(2 * t), 0.8])

    def solve(body):
        def deriv(t, r):
            R = r.reshape(3, 3)
            return (R @ _skew(rate(t)) if body else _skew(rate(t)) @ R).ravel()
        sol = solve_ivp(deriv, (0, 1.0), np.eye(3).ravel(), rtol=1e-11, atol=1e-12)
        return sol.y[:, -1].reshape(3, 3)

    t = np.arange(1001) / 1000.0                     # 1 kHz
    o = Orientation(t, np.stack([rate(x) for x in t]), 0.0)
    assert np.abs(o.matrices(1.0) - solve(True)).max() < 1e-6
    assert np.abs(solve(True) - solve(False)).max() > 0.05


def test_a_smooth_rate_logged_at_50_hz_is_followed_between_samples():
    # hand tremor at 8 Hz about x, logged at 50 Hz: the angle at any time, against its
    # integral in closed form. Holding each interval's mean rate (slerp between samples)
    # is off by 14 % of the swing; the cubic rate by 1.5 %
    A, f = 0.5, 8.0
    t = np.arange(26) / 50.0
    w = np.zeros((t.size, 3))
    w[:, 0] = A * np.sin(2 * np.pi * f * t)
    o = Orientation(t, w, 0.0)
    tq = np.linspace(0.0, 0.5, 1001)
    angle = Rotation.from_matrix(o.matrices(tq)).as_rotvec()
    exact = A / (2 * np.pi * f) * (1 - np.cos(2 * np.pi * f * tq))
    assert np.abs(angle[:, 0] - exact).max() < 0.03 * exact.max()
    assert np.abs(angle[:, 1:]).max() < 1e-12


def test_samples_close_in_time_do_not_make_the_path_swing():
    # an irregular log (events delivered in bursts: two samples 10 us apart, their rates
    # differing by sensor noise) stays within the angle the rates allow
    rng = np.random.default_rng(3)
    t = np.sort(np.r_[np.arange(40) / 200.0, np.arange(1, 40, 4) / 200.0 + 1e-5])
    w = np.tile([0.3, -0.2, 0.1], (t.size, 1)) + rng.normal(0, 0.05, (t.size, 3))
    o = Orientation(t, w, 0.0)
    tq = np.linspace(0.0, t[-1], 4001)
    rv = Rotation.from_matrix(o.matrices(tq)).as_rotvec()
    steps = np.linalg.norm(np.diff(rv, axis=0), axis=1) / np.diff(tq)     # rad/s
    assert steps.max() < np.linalg.norm(w, axis=1).max() * 1.1


def test_quaternion_helpers_match_scipy():
    v = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0], [1e-10, 0, 0]])
    assert np.allclose(quat_to_matrix(quat_from_rotvec(v)), Rotation.from_rotvec(v).as_matrix(),
                       atol=1e-12)


def test_bad_samples_are_refused_not_turned_into_nan_rotations():
    import pytest
    t = np.arange(10) / 200.0
    w = np.tile([0.1, 0.2, 0.3], (10, 1))
    with pytest.raises(ValueError, match="strictly increasing"):
        Orientation(t[::-1], w, 0.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        Orientation(np.r_[t[:5], t[4:9]], w, 0.0)
    bad = w.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="rates must be finite"):
        Orientation(t, bad, 0.0)
    with pytest.raises(ValueError, match="t_ref must be a finite"):
        Orientation(t, w, np.nan)
    assert np.allclose(Orientation(t, w, 0.0).matrices(0.0), np.eye(3))


# ------------------------------------------------ from a mutation audit (session 43)

def test_rates_are_held_beyond_the_log_at_each_end():
    """Kills O6 (extrapolation before the first sample turned the wrong way:
    ``self.t[0] - times``) and O10 (the first and last samples' rates swapped).

    Before the first sample the orientation follows the first sample's rate backwards
    in time, after the last one the last sample's rate, as the docstring says. The rate
    keeps its axis here (so the integral is exact) but doubles from first to last."""
    from gyrodeblur.orientation import Orientation

    axis = np.array([0.3, -0.8, 0.5])
    axis /= np.linalg.norm(axis)
    t = 0.1 + np.arange(21) / 200.0                      # 0.1 .. 0.2 s
    w = axis * (1.0 + 10.0 * (t - 0.1))[:, None]         # 1 rad/s -> 2 rad/s
    o = Orientation(t, w, t_ref=0.1)
    before = Rotation.from_rotvec(axis * 1.0 * (0.07 - 0.1)).as_matrix()
    np.testing.assert_allclose(o.matrices(0.07), before, atol=1e-12)
    after = o.matrices(0.2) @ Rotation.from_rotvec(axis * 2.0 * 0.03).as_matrix()
    np.testing.assert_allclose(o.matrices(0.23), after, atol=1e-12)
