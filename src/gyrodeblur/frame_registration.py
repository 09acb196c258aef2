"""Image motion between consecutive photos of a session, measured and predicted.

Blur alone cannot tell a straight pan's direction (a PSF and its point reflection have the
same spectrum) and barely tells the focal length from a bias. Two photos taken less than a
second apart can: the image moved between them by an amount the gyro predicts for any
parameter set. The motion is measured once (phase correlation of the whole frames) and
compared with the prediction (mean displacement of the blurred image of a grid of scene
points), pixel units of the full-resolution photos.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from .calibration_patches import CalibrationPhoto
from .orientation import Orientation, quat_conjugate, quat_multiply, quat_to_matrix
from .spectral_criterion import Corrections

__all__ = ["FrameRegistration", "phase_shift"]

#: Low-pass of the phase correlation between photos (cycles per thumbnail pixel) times
#: the blur extent (thumbnail pixels): well inside the PSFs' main spectral lobe.
_LOWPASS_BLUR = 0.25

#: Fixed-point steps for the row a point's light lands on (2-3 converge to 0.01 px while
#: content crosses rows more slowly than the shutter sweeps them).
_LANDING_STEPS = 4


def phase_shift(a: np.ndarray, b: np.ndarray, lowpass: float = 0.1) -> tuple[np.ndarray, float]:
    """Translation ``d`` (x, y) with ``b(x) ~ a(x - d)`` by phase correlation, and the
    peak's prominence (peak over the 99.9th percentile).

    The whitened cross-power is low-passed (Gaussian) at 0.1 cycles/px, so that JPEG block
    edges, which do not move, do not win, and the prominence is measured there. The shift
    is read off the peak low-passed at ``lowpass`` (cycles/px; at most 0.1): two photos
    blurred differently differ in phase by the difference of their PSFs, which is the
    difference of their centroids only well inside the PSFs' main spectral lobe (beyond it
    the phase jumps by pi where the OTF changes sign: on the calibration benchmark's bursts
    the 0.1-peak was up to 15 px away from it)."""
    h, w = a.shape
    win = np.outer(np.hanning(h), np.hanning(w))
    A = sfft.fft2((a - a.mean()) * win)
    Bf = sfft.fft2((b - b.mean()) * win)
    R = Bf * np.conj(A)
    R /= np.maximum(np.abs(R), 1e-12)
    f2 = sfft.fftfreq(h)[:, None] ** 2 + sfft.fftfreq(w)[None, :] ** 2
    r = np.real(sfft.ifft2(R * np.exp(-f2 / (2 * 0.1 ** 2))))
    prominence = float(r.max() / max(np.percentile(r, 99.9), 1e-12))
    if lowpass < 0.1:
        r = np.real(sfft.ifft2(R * np.exp(-f2 / (2 * lowpass ** 2))))
    iy, ix = np.unravel_index(int(np.argmax(r)), r.shape)
    peak = r[iy, ix]

    def sub(v0, v1, v2):
        den = v0 - 2 * v1 + v2
        return 0.0 if den >= 0 else 0.5 * (v0 - v2) / den

    dy = iy + sub(r[(iy - 1) % h, ix], peak, r[(iy + 1) % h, ix])
    dx = ix + sub(r[iy, (ix - 1) % w], peak, r[iy, (ix + 1) % w])
    dy = dy - h if dy > h / 2 else dy
    dx = dx - w if dx > w / 2 else dx
    return np.array([dx, dy]), prominence


class FrameRegistration:
    """Image motion between photos of one session: measured once (phase correlation of
    the whole frames), predicted from the gyro for any parameter set (mean displacement
    of the blurred image of a grid of scene points)."""

    def __init__(self, photos: list[CalibrationPhoto], extent: float, max_dt: float = 1.0):
        self.photos = photos
        self.pairs = []
        order = sorted(range(len(photos)), key=lambda i: photos[i].cap.exposure_start)
        for a, b in zip(order[:-1], order[1:]):
            pa, pb = photos[a], photos[b]
            dt = pb.cap.exposure_start - pa.cap.exposure_start
            if (pa.W, pa.H) != (pb.W, pb.H) or not 0 < dt <= max_dt:
                continue
            ta, _, k = pa.thumbnail()
            tb, _, _ = pb.thumbnail()
            d, q = phase_shift(ta.astype(np.float64), tb.astype(np.float64),
                               min(0.1, _LOWPASS_BLUR * k / max(extent, 1.0)))
            if q < 3.0:
                continue
            # The measured shift's error, read off the blur-adapted low-pass: on 24
            # synthetic bursts (benchmarks/calibration.py --burst) the residuals at the
            # true parameters were 0.4 px rms per axis for blurs under 12 px, 0.9 px for
            # 12-24 px and 1.9 px for 24-60 px (at the former fixed 0.1 low-pass: 0.6, 3.9
            # and 6.6 px).
            sigma = max(2.0, 0.1 * extent)
            self.pairs.append((a, b, d * k, sigma, q))

    def predict(self, theta: Corrections, a: int, b: int) -> np.ndarray:
        pa, pb = self.photos[a], self.photos[b]
        ca, cb = pa.cap, pb.cap
        n = 16
        s = (np.arange(n) + 0.5) / n
        t_a, t_b = ca.exposure_start, cb.exposure_start
        lo = t_a - theta.offset - 0.01
        hi = t_b + cb.readout_time * 1.7 + cb.exposure_time - theta.offset + 0.01
        t = ca.log.t + ca.time_offset
        i0 = max(int(np.searchsorted(t, lo)) - 2, 0)
        i1 = min(int(np.searchsorted(t, hi)) + 2, t.size)
        w = ca.log.omega[i0:i1] @ theta.axes.T - (ca.bias + theta.bias)
        O = Orientation(t[i0:i1], w, t_a)
        qref = quat_conjugate(O.quaternions(np.array([t_a - theta.offset]))[0])
        cam = ca.camera.with_focal_scale(theta.focal)
        gx, gy = np.meshgrid([0.25, 0.5, 0.75], [0.25, 0.5, 0.75])
        px = gx.ravel() * (pa.W - 1)
        py = gy.ravel() * (pa.H - 1)
        ray = cam.rays(px, py)

        def centroid(times):                       # times (P, n), camera clock
            q = quat_multiply(qref, O.quaternions(times - theta.offset))
            R = quat_to_matrix(q)
            d = np.einsum("pnji,pj->pni", R, ray)  # R^T ray
            return cam.project(d).mean(1)

        def landed(t0, readout, exposure, height, row):
            """Mean position of each point's light, timed by the row it lands on (the
            fixed point of row -> centroid over that row's exposure), as the PSFs are
            (:func:`gyrodeblur.psf.landing_pixel`); a point whose iteration does not
            settle (skew over 1) keeps the timing of the row it starts on, as there."""
            def over_exposure_of(rows):
                return centroid(t0 + readout * np.clip(rows, 0, height - 1)[:, None] / height
                                + exposure * s[None, :])

            first = c = over_exposure_of(row)
            step = np.abs(c[:, 1] - row)
            for _ in range(_LANDING_STEPS - 1):
                if step.max() < 0.01:
                    break
                row = c[:, 1]
                c = over_exposure_of(row)
                step = np.abs(c[:, 1] - row)
            return np.where((step <= 0.5)[:, None], c, first)

        ro_a = max(0.0, ca.readout_time + theta.readout)
        ro_b = max(0.0, cb.readout_time + theta.readout)
        c_a = landed(t_a, ro_a, ca.exposure_time, pa.H, py)
        row_b = centroid(np.full((px.size, 1), t_b))[:, 1]      # where they are at t_b
        c_b = landed(t_b, ro_b, cb.exposure_time, pb.H, row_b)
        return (c_b - c_a).mean(0)

    def residuals(self, theta: Corrections) -> np.ndarray:
        out = []
        for a, b, d, sigma, _ in self.pairs:
            out.append((d - self.predict(theta, a, b)) / sigma)
        return np.concatenate(out) if out else np.zeros(0)
