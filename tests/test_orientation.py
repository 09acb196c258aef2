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
    # between samples too (slerp)
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


def test_body_frame_composition_order():
    # rotate about x, then about the (new) body y: R = Rx @ Ry
    t = np.array([0.0, 1.0, 1.0 + 1e-9, 2.0])
    w = np.array([[0.5, 0, 0], [0.5, 0, 0], [0, 0.7, 0], [0, 0.7, 0]])
    o = Orientation(t, w, 0.0)
    expected = Rotation.from_rotvec([0.5, 0, 0]).as_matrix() @ Rotation.from_rotvec([0, 0.7, 0]).as_matrix()
    assert np.abs(o.matrices(2.0) - expected).max() < 1e-6


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
