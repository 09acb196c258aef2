"""Camera orientation from angular velocity, integrated on SO(3).

The gyro measures the body's angular velocity ``w`` (rad/s, camera frame). The camera's
orientation ``R(t)`` maps camera-frame vectors at time ``t`` to the reference frame (the
camera at the reference time): ``dR/dt = R [w]_x``. Between samples the rate is a cubic
Hermite curve through them, its slopes the central differences of the neighbouring samples
(Catmull-Rom: local, so a sample moves the curve only in the two intervals either side,
and two samples close in time cannot make it swing); within interval ``k`` the
orientation is ``q_k (x) exp(phi_k(t) / 2)``, ``phi_k(t)`` the integral of that rate from
``t_k`` (exact for a rate that keeps its axis; the neglected commutator term, about
``h^3 |w x dw/dt| / 12``, is 7e-6 rad over a 20 ms interval of a shaking hand's
0.7 rad/s turning at 15 rad/s^2: a hundredth of a pixel at a 1000 px focal length), and
the intervals compose in the body frame,
``q_{k+1} = q_k (x) exp(phi_k(t_{k+1}) / 2)``. Eq. 6.17 of the chapter (summing angles per
axis) is the small-angle limit of this.

A rate held constant over each interval (its two samples' mean, integrated by slerp) is
the simpler choice and exact for a constant rate, as this one is; but a phone's hand shake
has power up to 20-30 Hz, and logs are often taken at 50-100 Hz. The benchmark cases
deblurred with the shared 210 Hz log decimated (``benchmarks/gyro_rate.py``, every 2nd or
4th sample) lost 1.50 dB at 105 Hz and 6.97 dB at 52 Hz against the full log with the
held rate, 0.10 and 2.13 dB with the cubic one.
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
        self._omega = omega
        h = dt[:, None]
        slope = np.empty_like(omega)                    # rad/s^2: central differences
        if t.size > 2:
            slope[1:-1] = (omega[2:] - omega[:-2]) / (t[2:] - t[:-2])[:, None]
        slope[0] = (omega[1] - omega[0]) / dt[0]
        slope[-1] = (omega[-1] - omega[-2]) / dt[-1]
        # the rate on interval k in Hermite form: w_k, h m_k, w_k+1, h m_k+1 (rad/s)
        self._hermite = np.stack([omega[:-1], h * slope[:-1], omega[1:], h * slope[1:]])
        self._h = dt
        self._q = _compose(quat_from_rotvec(self._rotvec(np.arange(t.size - 1), np.ones(t.size - 1))))
        q_ref = self._interp(np.array([self.t_ref]))[0]
        self._q_ref_inv = quat_conjugate(q_ref)

    def _rotvec(self, k: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Rotation vector (rad) turned from ``t_k`` to ``t_k + s (t_k+1 - t_k)``, ``s`` in
        [0, 1]: the integral of interval ``k``'s cubic Hermite rate."""
        s2 = s * s
        s3 = s2 * s
        s4 = s3 * s
        basis = np.stack([s - s3 + 0.5 * s4,                # integrals of the Hermite basis
                          0.5 * s2 - 2.0 * s3 / 3.0 + 0.25 * s4,
                          s3 - 0.5 * s4,
                          0.25 * s4 - s3 / 3.0])
        c = self._hermite[:, k]                          # (4, ..., 3)
        return self._h[k][..., None] * np.einsum("j...,j...c->...c", basis, c)

    def _interp(self, times: np.ndarray) -> np.ndarray:
        n = self.t.size
        k = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, n - 2)
        s = np.clip((times - self.t[k]) / self._h[k], 0.0, 1.0)
        q = quat_multiply(self._q[k], quat_from_rotvec(self._rotvec(k, s)))
        # beyond the samples: the first (last) sample's rate, held
        before = times < self.t[0]
        after = times > self.t[-1]
        if before.any() or after.any():
            ext = np.where(before, times - self.t[0], np.where(after, times - self.t[-1], 0.0))
            w = np.where(before[..., None], self._omega[0], self._omega[-1])
            edge = np.where(before[..., None], self._q[0], self._q[-1])
            q = np.where((before | after)[..., None],
                         quat_multiply(edge, quat_from_rotvec(w * ext[..., None])), q)
        return q

    def quaternions(self, times) -> np.ndarray:
        """Orientation relative to ``t_ref`` as unit quaternions ``(..., 4)`` (w, x, y, z).

        Times outside the samples are extrapolated with the first (last) sample's rate.
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
