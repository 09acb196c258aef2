"""Camera orientation from angular velocity, integrated on SO(3).

The gyro measures the body's angular velocity ``w`` (rad/s, camera frame). The camera's
orientation ``R(t)`` maps camera-frame vectors at time ``t`` to the reference frame (the
camera at the reference time): ``dR/dt = R [w]_x``. We integrate with unit quaternions
composed in the body frame, ``q_{k+1} = q_k (x) exp(phi_k / 2)`` with the rotation vector
``phi_k = (w_k + w_{k+1}) / 2 * (t_{k+1} - t_k)`` (the mean rate over the interval: exact
for a constant rate, second order otherwise). Between samples the orientation is the
geodesic (slerp) ``q_k (x) exp(s phi_k / 2)``, ``s`` in [0, 1], so any time can be asked
for. Eq. 6.17 of the chapter (summing angles per axis) is the small-angle limit of this.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "Orientation",
    "quat_multiply",
    "quat_conjugate",
    "quat_from_rotvec",
    "quat_to_matrix",
    "rotvec_to_matrix",
]


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions ``(..., 4)`` stored as ``(w, x, y, z)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bw - ax * bx - ay * by - az * bz
    out[..., 1] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 2] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate of quaternions ``(..., 4)`` stored as ``(w, x, y, z)``: the inverse
    rotation, for unit quaternions."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_from_rotvec(v: np.ndarray) -> np.ndarray:
    """Unit quaternion ``exp(v / 2)`` for rotation vectors ``v`` of shape ``(..., 3)`` (rad)."""
    v = np.asarray(v, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(a/2)/a, with its Taylor series near 0
    small = angle < 1e-8
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), v * k], axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from unit quaternions ``(..., 4)`` (w, x, y, z)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def rotvec_to_matrix(v: np.ndarray) -> np.ndarray:
    """Rotation matrices for rotation vectors ``(..., 3)`` (rad, right-hand rule)."""
    return quat_to_matrix(quat_from_rotvec(v))


class Orientation:
    """Camera orientation over time, relative to a reference time.

    Parameters
    ----------
    t : ndarray (N,)
        Sample times, seconds, strictly increasing (camera clock).
    omega : ndarray (N, 3)
        Angular velocity, rad/s, camera frame (x right, y down, z forward).
    t_ref : float
        Reference time (s): ``matrices(t_ref)`` is the identity. Usually the exposure
        start of the first row.

    Notes
    -----
    ``matrices(t)`` returns ``R(t)``, mapping camera-frame vectors at ``t`` into the
    reference camera frame. A scene point seen at pixel ``x0`` at the reference time is
    seen at ``K R(t)^T K^-1 x0`` at time ``t``.
    """

    def __init__(self, t: np.ndarray, omega: np.ndarray, t_ref: float):
        t = np.asarray(t, dtype=np.float64)
        omega = np.asarray(omega, dtype=np.float64)
        if t.ndim != 1 or t.size < 2 or omega.shape != (t.size, 3):
            raise ValueError("need N >= 2 times and an (N, 3) array of rates")
        dt = np.diff(t)
        if not (np.all(np.isfinite(t)) and np.all(dt > 0)):
            raise ValueError("sample times must be finite and strictly increasing")
        if not np.all(np.isfinite(omega)):
            raise ValueError("rates must be finite (no NaN or infinity)")
        if not np.isfinite(t_ref):
            raise ValueError(f"t_ref must be a finite time in seconds, got {t_ref!r}")
        self.t = t
        self.t_ref = float(t_ref)
        self._phi = 0.5 * (omega[1:] + omega[:-1]) * dt[:, None]      # (N-1, 3) rad
        self._q = _compose(quat_from_rotvec(self._phi))
        q_ref = self._interp(np.array([self.t_ref]))[0]
        self._q_ref_inv = quat_conjugate(q_ref)

    def _interp(self, times: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, self.t.size - 2)
        s = (times - self.t[k]) / (self.t[k + 1] - self.t[k])
        return quat_multiply(self._q[k], quat_from_rotvec(self._phi[k] * s[..., None]))

    def quaternions(self, times) -> np.ndarray:
        """Orientation relative to ``t_ref`` as unit quaternions ``(..., 4)`` (w, x, y, z).

        Times outside the samples are extrapolated with the first/last interval's rate.
        """
        times = np.asarray(times, dtype=np.float64)
        return quat_multiply(self._q_ref_inv, self._interp(times))

    def matrices(self, times) -> np.ndarray:
        """``R(t)`` relative to ``t_ref``, shape ``times.shape + (3, 3)``."""
        return quat_to_matrix(self.quaternions(times))


def _compose(steps: np.ndarray) -> np.ndarray:
    """The running products ``q_0 = 1``, ``q_{k+1} = q_k (x) steps_k``, each renormalised:
    ``(N + 1, 4)`` from ``(N, 4)``. Sequential by nature, so in Python floats: a numpy call
    per step of a few-element array costs ~40x more."""
    out = [(1.0, 0.0, 0.0, 0.0)]
    w, x, y, z = out[0]
    for bw, bx, by, bz in steps.tolist():
        w, x, y, z = (w * bw - x * bx - y * by - z * bz,
                      w * bx + x * bw + y * bz - z * by,
                      w * by - x * bz + y * bw + z * bx,
                      w * bz + x * by - y * bx + z * bw)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
        out.append((w, x, y, z))
    return np.array(out, dtype=np.float64)
