"""The calibration criterion: how well the PSFs of a parameter set explain patch spectra.

A patch (linear-light luminance, downscaled so that the largest PSF spans ~32 px) is
modelled as ``g = h * u + n`` with a Gaussian image ``u`` and white noise ``n``. Its
Hann-windowed periodogram ``P(w)`` is then exponentially distributed around

    ``M(w) = a (E(w) |H(w)|^2 |A(w)|^2 / |D(w)|^2 + rho)``

(``D`` the discrete gradient: a Gaussian gradient prior; ``A`` the resampling filter), and
``-log p(g | h) = sum_w P/M + log M`` (Whittle): the chapter's marginal ``p(h | g)``
(eq. 6.7) for a Gaussian prior, which penalises too little blur and too much alike. The
scale ``a`` is profiled in closed form, the noise ratio ``rho`` by Newton steps. The sum
runs over frequencies up to 0.42 cycles per working-scale pixel, and up to ``band`` cycles
per photo pixel for a JPEG whose compression emptied the top of the band
(:data:`gyrodeblur.calibration_fit.BLOCKY`).

Real patches are not isotropic ``1/f^2`` textures: edges and oriented texture make the
spectrum anisotropic, optics and resampling soften it, and a fixed prior then trades those
differences against the blur. So ``E`` is a smooth per-patch envelope,
``log E = c . phi(w)`` with ``phi`` = {1, log f, f^2, cos 2a, sin 2a, cos 4a, sin 4a,
log f cos 2a, log f sin 2a}, fitted to ``P ~ E S + s`` on 4x4-binned spectra (weighted
least squares, then damped Fisher scoring) at a given parameter set and then held while
the parameters move (refitted every few steps). What is left to the PSF is mostly the fine
structure of ``|H|^2``, its zeros and ripples. ``|H|`` comes from the exact trace of the
patch centre's pixel, mapped by the inverse of the photo's local warp there (the rolling
shutter shears and stretches the patch, and its blur with it:
:meth:`PatchSpectra.displacements`), rendered as a sum of narrow Gaussians (0.75 px): the
cost is a smooth function of the parameters (bilinear splatting makes it jagged, because
its low-pass changes with the PSF's sub-pixel position). A patch's kernel changes across
it: its rows are exposed at different times (rolling shutter), and a roll or a fast pan
at a wide angle turns or stretches the trace from one side to the other. So the search's
fine patches (``across``) average ``|H|^2`` over 2 x 2 points of the patch, each at its own
row's time, placed where their second moments match the Hann window power's
(:data:`_ACROSS`); other patches average it over three rows of the centre. The blur test
(:meth:`PatchSpectra.gain_over_no_blur`) averages it over 5 x 5 points of a patch whose
kernel changes across it by more than :data:`_KERNEL_CHANGE`.

See :mod:`gyrodeblur.calibrate` for how the criterion is searched.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from .calibration_patches import CalibrationPhoto
from .capture import Capture
from .fftutils import usable_cpus
from .orientation import Orientation, quat_conjugate, quat_multiply, quat_to_matrix
from .psf import offsets_under_rotation

__all__ = ["Corrections", "PatchSpectra", "whittle_profiled", "envelope_basis"]

_SPLAT_SIGMA = 0.75        # px: Gaussian splat of the PSF trace
_FMAX = 0.42               # cycles/px: frequencies kept (splat aliasing beyond)
_FMIN_BINS = 2.5           # frequencies below this many bins are dropped (window leakage)
_ENVELOPE_ITERS = 3        # Fisher-scoring steps of an envelope fitted per evaluation ...
_ENVELOPE_ITERS_HELD = 6   # ... and of one fitted to be held
_FLOOR_MAX_STEP = 3.0      # largest change of the log noise floor per envelope-fit step
                           # (normal steps: up to about 2.3)
#: Time shifts whose spectra are made at once by :meth:`PatchSpectra.costs` (a wide offset
#: search's coarse grid has one every 2 ms: +-0.5 s held 0.76 GB at once, +-5 s would hold
#: about 8 GB per worker; the default +-40 ms grid has 41)
_TAU_CHUNK = 128
_WARP_STEP = 2.0           # px: finite-difference step of the local warp (full resolution)
_WARP_SAMPLES = 8          # times over the exposure at which the local warp is averaged
#: px (working scale): a kernel that changes across its patch by more than this (roll,
#: perspective at a wide angle: :meth:`PatchSpectra.kernel_change`) is modelled, in the
#: blur test, by its ``|H|^2`` averaged over :data:`_SPREAD_OFFSETS` of the patch
_KERNEL_CHANGE = 0.5
#: offsets (x the patch side) of the points in x and in y at which the blur test averages
#: a varying kernel's ``|H|^2``, weighted as the Hann window's power there (cos^4):
#: a second moment of 0.02 the side squared, the window power's own. 3 points a side
#: left up to 9 nats of the gain on a 3 rad/s roll; 7 points change it by under 0.4
_SPREAD_OFFSETS = (-0.3, -0.15, 0.0, 0.15, 0.3)
#: offset (x the patch side) in x and in y of the 2 x 2 points at which a patch made
#: ``across`` reads its ``|H|^2`` (weighted equally, each at its own row's time): the Hann
#: window power's second moment, 1/12 - 5 / (8 pi^2) = 0.02 the side squared, so a kernel
#: that changes smoothly across the patch is averaged as the window weighs it, to second
#: order, for 4 OTFs (the three rows of the centre that they replace saw no change in x).
#: The demo's exact capture (a 16 px blur, the kernel changing 0.52 px across its patches)
#: scored 14 tempered nats worse than the calibration's optimum with the centre's rows,
#: 4 with these points (session 51)
_ACROSS = float(np.sqrt(1 / 12 - 5 / (8 * np.pi ** 2)))


@dataclass
class Corrections:
    """Corrections shared by all photos: deltas to each capture's own values."""

    axes: np.ndarray            # absolute mapping (3x3)
    offset: float = 0.0         # s, added to each capture's time_offset
    readout: float = 0.0        # s, added to each capture's readout_time
    focal: float = 1.0          # scale of the focal length
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))   # rad/s, added

    def copy(self, **kw) -> "Corrections":
        d = dict(axes=self.axes, offset=self.offset, readout=self.readout, focal=self.focal,
                 bias=np.array(self.bias, float))
        d.update(kw)
        return Corrections(**d)

    def apply(self, cap: Capture) -> Capture:
        return cap.replace(time_offset=cap.time_offset + self.offset,
                           readout_time=max(0.0, cap.readout_time + self.readout),
                           camera=cap.camera.with_focal_scale(self.focal),
                           bias=cap.bias + self.bias, axes=self.axes,
                           exposure_start_from_exif=False,     # calibrated now
                           readout_time_unknown=False, exif_time_to_the_second=False)


def _unique_pairs(a: np.ndarray, b: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray],
                                                           np.ndarray]:
    """The distinct pairs ``(a[k], b[k])`` (two arrays) and, for each ``k``, the index of
    its pair among them."""
    u, back = np.unique(np.stack([a, b], axis=1), axis=0, return_inverse=True)
    return (u[:, 0], u[:, 1]), back.ravel()


class PatchSpectra:
    """Patches of the photos at one working scale, and the cost of a parameter set."""

    def __init__(self, photos: list[CalibrationPhoto], centres, scale: float, size: int, *,
                 rows=(0.0,), n_samples: int = 128, envelope: bool = True,
                 band: float = np.inf, across: bool = False):
        self.photos = photos
        #: ``|H|^2`` read at 2 x 2 points across each patch (:data:`_ACROSS`), not at ``rows``
        #: of its centre (which a call's own ``rows`` and ``keep_otf`` still use)
        self.across = bool(across)
        P = self.size = int(size)
        F = self.F = max(P, int(round(P / scale))) if scale < 1 else P
        self.scale = P / F
        self.rows = np.asarray(rows, float)
        self.row_w = np.ones(len(rows)) / len(rows) if len(rows) != 3 else np.array([0.25, 0.5, 0.25])
        self.n = int(n_samples)
        # frequency bookkeeping on the rfft half-plane, extended by one column each side
        fy = sfft.fftfreq(P)
        fxe = np.arange(-1, P // 2 + 2) / P
        self.fy = fy
        FY, FX = np.meshgrid(fy, fxe, indexing="ij")
        d2 = 4 * np.sin(np.pi * FY) ** 2 + 4 * np.sin(np.pi * FX) ** 2
        sig_o = max(0.0, (1 / self.scale - 1) / 2) * self.scale   # anti-alias filter, out px
        a2 = np.exp(-4 * np.pi ** 2 * sig_o ** 2 * (FX ** 2 + FY ** 2))
        prior_ext = a2 / np.maximum(d2, 1e-12)
        fyh, fxh = FY[:, 1:-1], FX[:, 1:-1]
        rad = np.hypot(fyh, fxh)
        self.band = float(band)
        # frequencies kept: up to _FMAX of the working scale, and up to ``band`` cycles per
        # full-resolution pixel (what a compressed photo still holds)
        self.band_cuts = self.band / self.scale < _FMAX       # whether ``band`` removes any
        mask = (rad >= _FMIN_BINS / P) & (rad <= min(_FMAX, self.band / self.scale))
        mask &= ~((fyh < 0) & ((fxh == 0) | np.isclose(fxh, 0.5)))   # redundant halves
        self.mask = mask
        self._build_smoother(prior_ext)
        win1 = np.hanning(P + 2)[1:-1]
        self.win = np.outer(win1, win1)
        # envelope basis and 4x4 bins
        r = rad[mask]
        self._rad_masked = r
        a = np.arctan2(fyh, fxh)[mask]
        self.Phi = envelope_basis(r, a)
        b = 4
        lab = ((np.arange(P)[:, None] // b) * (P // b + 2) + np.arange(fxh.shape[1])[None, :] // b)
        lab = np.broadcast_to(lab, mask.shape)[mask]
        _, self.bin_of = np.unique(lab, return_inverse=True)
        self.nbins = int(self.bin_of.max()) + 1
        self.bin_cnt = np.bincount(self.bin_of, minlength=self.nbins).astype(float)
        self.Phi_bin = np.stack([np.bincount(self.bin_of, self.Phi[:, j], self.nbins)
                                 for j in range(self.Phi.shape[1])], 1) / self.bin_cnt[:, None]
        # the patches
        self.points, self.power, self.pbin, self.G = [], [], [], []
        from skimage.transform import resize
        wsum = (self.win ** 2).sum()
        for (i, x, y) in centres:
            ph = photos[i]
            x0 = int(round(x - (F - 1) / 2))
            y0 = int(round(y - (F - 1) / 2))
            x0 = min(max(x0, 0), ph.W - F)
            y0 = min(max(y0, 0), ph.H - F)
            crop = ph.gray(y0, y0 + F, x0, x0 + F)
            if F != P:
                crop = resize(crop, (P, P), order=1, anti_aliasing=True, mode="reflect")
            G = sfft.rfft2((crop - crop.mean()) * self.win)
            pw = (np.abs(G) ** 2 / wsum)[mask]
            self.points.append((i, x0 + (F - 1) / 2, y0 + (F - 1) / 2))
            self.power.append(pw)
            self.pbin.append(np.bincount(self.bin_of, pw, self.nbins) / self.bin_cnt)
            self.G.append(G)
        self.power = np.stack(self.power) if self.power else np.zeros((0, mask.sum()))
        self.pbin = np.stack(self.pbin) if self.pbin else np.zeros((0, self.nbins))
        self._prepare_fast_envelope()
        self._orient_cache: dict = {}
        self._last_spectra: tuple = (None, None)    # (key, result) of the latest call
        self._rho_warm: dict = {}
        self.E = None
        self.envelope = envelope
        self.evaluations = 0
        # threads of the OTFs' FFTs (the results do not depend on it)
        self.fft_threads = min(2, usable_cpus())

    # -- geometry ---------------------------------------------------------------------
    def _orientation(self, i: int, theta: Corrections, lo: float, hi: float) -> Orientation:
        cap = self.photos[i].cap
        key = (i, theta.axes.tobytes(), tuple(np.round(theta.bias, 12)))
        hit = self._orient_cache.get(key)
        if hit is not None and hit[0] <= lo and hit[1] >= hi:
            return hit[2]
        t = cap.log.t + cap.time_offset
        lo2, hi2 = lo - 0.05, hi + 0.05
        i0 = max(int(np.searchsorted(t, lo2)) - 2, 0)
        i1 = min(int(np.searchsorted(t, hi2)) + 2, t.size)
        if i1 - i0 < 2:
            i0, i1 = max(0, i1 - 2), max(i1, 2)
        w = cap.log.omega[i0:i1] @ theta.axes.T - (cap.bias + theta.bias)
        O = Orientation(t[i0:i1], w, cap.exposure_start)
        if len(self._orient_cache) > 64:
            self._orient_cache.clear()
        self._orient_cache[key] = (lo2, hi2, O)
        return O

    def displacements(self, theta: Corrections, items) -> np.ndarray:
        """``(B, n, 2)`` blur kernel of each item ``(photo, x, y, row, tau)`` as the
        spectrum of a patch centred on pixel ``(x, y)`` sees it, in working-scale pixels
        (full-resolution coordinates in; ``row`` times the exposure).

        The kernel of the pixel ``p`` itself is the gather form ``p - x0_p(t)``
        (``x0_p(t) = K R(t) K^-1 p``, the reference-time position of the scene point that
        ``p`` records at ``t``, over its row's exposure). Around ``p`` the photo is also
        warped: nearby pixels see scene points ``x0_p(t) + M(t) dp`` (``M = dx0_p/dp``:
        the rotation's own roll and perspective terms and, with a rolling shutter, the
        image velocity times the readout rate, a shear or a stretch of several per cent,
        which dominates), so the patch is the blurred scene resampled
        by ``M``'s mean ``Mbar``, and its spectrum shows the kernel mapped by
        ``Mbar^-1``. Without that map the criterion took the stretch for a focal error (1.5 to
        3.2 % on 11 of the benchmark's 24 cases, the rest true, its sign following the
        shake)."""
        n, m, h = self.n, _WARP_SAMPLES, _WARP_STEP
        out = np.empty((len(items), n, 2))
        s = (np.arange(n) + 0.5) / n
        sw = (np.arange(m) + 0.5) / m
        # the local warp from the pixel's neighbours h px either side in x (its own row
        # times) and in y (h rows later and earlier), at fewer times than the kernel: it is
        # a mean over the exposure
        rows_w = np.array([0.0, h, -h])
        groups: dict = {}
        for b, it in enumerate(items):
            groups.setdefault(it[0], []).append(b)
        for i, idx in groups.items():
            x, y, row, tau = np.array([items[b][1:] for b in idx], float).T
            B = len(idx)
            cap = self.photos[i].cap
            readout = max(0.0, cap.readout_time + theta.readout)
            # items on one row with one time shift (a patch's points across it in x) share
            # their rotations: each pair's made once
            (row_u, tau_u), back = _unique_pairs(row, tau)
            t_row = cap.exposure_start + readout * row_u / cap.camera.height      # (U,)
            T = np.concatenate([
                t_row[:, None] + cap.exposure_time * s,
                (t_row[:, None, None] + readout * rows_w[:, None] / cap.camera.height
                 + cap.exposure_time * sw).reshape(len(t_row), 3 * m)], axis=1)
            R = self._rotations(theta, i, T, tau_u)[back]
            cam = cap.camera.with_focal_scale(theta.focal)
            # p - x0_p(t) of the pixel and of its four neighbours (full-resolution px)
            o = offsets_under_rotation(cam, R[:, :n], x, y)
            Rw = R[:, n:].reshape(B, 3, m, 3, 3)[:, [0, 0, 1, 2]]
            ow = offsets_under_rotation(cam, Rw, x[:, None] + [h, -h, 0, 0],
                                        y[:, None] + [0, 0, h, -h])
            dx = (ow[:, 0] - ow[:, 1]).mean(1) / (2 * h)    # d offsets / dp, exposure mean
            dy = (ow[:, 2] - ow[:, 3]).mean(1) / (2 * h)
            Mbar = np.eye(2)[None] - np.stack([dx, dy], axis=-1)        # d x0_p / dp
            out[idx] = (o @ np.linalg.inv(Mbar).transpose(0, 2, 1)) * self.scale
        return out

    def _rotations(self, theta: Corrections, i: int, T: np.ndarray, tau: np.ndarray):
        """``R(t)`` ``(B, k, 3, 3)`` relative to the exposure start (camera frame) at the
        camera times ``T`` ``(B, k)`` (s) of photo ``i``, its ``B`` patches' own time shifts
        ``tau`` (s) added to the offset: the scene point that pixel ``p`` records at ``t``
        lies at ``K R(t) K^-1 p`` at the reference time."""
        cap = self.photos[i].cap
        taus = tau + theta.offset
        tref = cap.exposure_start
        O = self._orientation(i, theta, min(T.min(), tref) - taus.max(),
                              max(T.max(), tref) - taus.min())
        qref = quat_conjugate(O.quaternions(tref - taus))
        q = O.quaternions(T - taus[:, None])
        return quat_to_matrix(quat_multiply(qref[:, None, :], q))

    def otf(self, disp: np.ndarray) -> np.ndarray:
        """Complex OTF ``(B, P, P//2+1)`` of Gaussian-splatted traces ``disp``
        ``(B, n, 2)`` (px; each kernel sums to 1, its origin at the patch's origin)."""
        P = self.size
        H, corner = self._box_transform(disp)
        fy = sfft.fftfreq(P)
        fx = sfft.rfftfreq(P)
        ramp_y = np.exp(-2j * np.pi * corner[:, 1, None] * fy).astype(np.complex64)
        ramp_x = np.exp(-2j * np.pi * corner[:, 0, None] * fx).astype(np.complex64)
        return H * ramp_y[:, :, None] * ramp_x[:, None, :]

    def otf_power(self, disp: np.ndarray) -> np.ndarray:
        """``|H|^2`` ``(B, P, P//2+1)`` (float32) of :meth:`otf`'s kernels, which does not
        depend on where a kernel lies (the phase ramp of :meth:`otf` left out)."""
        H, _ = self._box_transform(disp)
        return H.real ** 2 + H.imag ** 2

    def _box_transform(self, disp: np.ndarray):
        """The transform ``(B, P, P//2+1)`` of each splatted trace moved (circularly) to
        the corner of the smallest box that holds every kernel of the batch, and the
        corner ``(B, 2)`` (x, y; integer px) it was moved from.

        A 5 x 5 Gaussian splat is an outer product of 5 weights in y and 5 in x, so a
        kernel is ``Wy^T Wx`` (``Wy``: ``(n, box rows)``, ``Wx``: ``(n, box columns)``,
        5 weights in each of the trace's ``n`` rows), made by a small matrix product rather
        than a histogram of ``25 n`` taps; only the box's rows are transformed along x
        (zero-padded to ``P``) before the full transform along y. A kernel wider than the
        patch wraps, as the circular transform sees it."""
        P = self.size
        B, n, _ = disp.shape
        if B == 0:
            return np.zeros((0, P, P // 2 + 1), np.complex64), np.zeros((0, 2), np.int64)
        R = 2
        offs = np.arange(-R, R + 1)
        c = np.floor(disp + 0.5)
        g = np.exp((-0.5 / _SPLAT_SIGMA ** 2) * ((c[..., None] + offs) - disp[..., None]) ** 2)
        ic = c.astype(np.int64)
        corner = ic.min(axis=1) - R                                      # (B, 2)
        ic -= corner[:, None, :]
        hx, hy = np.minimum(ic.max(axis=(0, 1)) + R + 1, P)
        # each kernel sums to 1: the y weights carry the normalisation
        tot = (g[..., 0, :].sum(-1) * g[..., 1, :].sum(-1)).sum(1)        # (B,)
        gy = g[..., 1, :] / np.maximum(tot, 1e-30)[:, None, None]
        base = np.arange(B * n).reshape(B, n, 1)
        Wx = np.zeros(B * n * hx, np.float32)
        Wx[(base * hx + (ic[..., 0, None] + offs) % P).ravel()] = g[..., 0, :].ravel()
        Wy = np.zeros(B * n * hy, np.float32)
        Wy[(base * hy + (ic[..., 1, None] + offs) % P).ravel()] = gy.ravel()
        k = np.matmul(Wy.reshape(B, n, hy).transpose(0, 2, 1), Wx.reshape(B, n, hx))
        X = sfft.rfft(k, n=P, axis=2, workers=self.fft_threads)
        return sfft.fft(X, n=P, axis=1, workers=self.fft_threads), corner

    def model(self, h2: np.ndarray) -> np.ndarray:
        """``|H|^2 |A|^2 / |D|^2`` smoothed by the Hann window's power kernel, masked:
        ``(B, P, P//2+1)`` -> ``(B, N)`` (a precomputed sparse operator)."""
        B = h2.shape[0]
        flat = h2.reshape(B, -1).T                      # (P*(P/2+1), B)
        return np.asarray(self._smooth_op @ flat, dtype=np.float64).T

    def _build_smoother(self, prior_ext: np.ndarray) -> None:
        from scipy import sparse
        P = self.size
        K = P // 2 + 1
        ky, kx = np.nonzero(self.mask)
        rows, cols, vals = [], [], []
        w = {-1: 1 / 6, 0: 2 / 3, 1: 1 / 6}
        out = np.arange(ky.size)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                sy = (ky + dy) % P
                sx = kx + dx
                pe = prior_ext[sy, sx + 1]              # extended grid has a column offset of 1
                my = np.where((sx < 0) | (sx > P // 2), (-sy) % P, sy)
                mx = np.where(sx < 0, 1, np.where(sx > P // 2, P // 2 - 1, sx))
                rows.append(out)
                cols.append(my * K + mx)
                vals.append(w[dy] * w[dx] * pe)
        self._smooth_op = sparse.csr_matrix(
            (np.concatenate(vals).astype(np.float32), (np.concatenate(rows), np.concatenate(cols))),
            shape=(ky.size, P * K))

    def spectra(self, theta: Corrections, taus=None, rows=None, keep_otf=False,
                spread=False):
        """Model spectra ``S`` ``(n_tau * n_patch, N)`` (and the centre-row OTFs).

        ``spread``: each patch's ``|H|^2`` averaged over points across the patch
        (:data:`_SPREAD_OFFSETS` in x and y, each with its own row's time) rather than over
        :attr:`rows` of its centre (or, patches made ``across``, over their 2 x 2 points):
        for a kernel that changes across the patch by more than those points follow.

        The latest call's result is kept (read-only) and returned again for the same
        arguments: the search asks for the spectra at one point several times in a row (a
        step's trial cost, then the next step's Jacobian base and envelope fit there)."""
        key = (theta.axes.tobytes(), theta.offset, theta.readout, theta.focal,
               np.asarray(theta.bias, float).tobytes(),
               None if taus is None else np.asarray(taus, float).tobytes(),
               None if rows is None else np.asarray(rows, float).tobytes(), bool(keep_otf),
               bool(spread))
        if self._last_spectra[0] == key:
            return self._last_spectra[1]
        out = self._spectra(theta, taus, rows, keep_otf, spread)
        for a in (out if keep_otf else (out,)):
            a.flags.writeable = False
        self._last_spectra = (key, out)
        return out

    def _spectra(self, theta: Corrections, taus, rows, keep_otf, spread):
        rows = self.rows if rows is None else np.asarray(rows, float)
        rw = self.row_w if rows is self.rows else np.ones(len(rows)) / len(rows)
        tl = [0.0] if taus is None else list(taus)
        F = self.F
        if spread:
            o = np.asarray(_SPREAD_OFFSETS)
            w = np.cos(np.pi * o) ** 4
            rw = np.outer(w, w).ravel() / w.sum() ** 2
            items = self._points_across(o, tl)
        elif self.across and rows is self.rows and not keep_otf:
            rw = np.full(4, 0.25)
            items = self._points_across((-_ACROSS, _ACROSS), tl)
        else:
            items = [(i, x, y, y + r * F, tau)
                     for tau in tl for (i, x, y) in self.points for r in rows]
        disp = self.displacements(theta, items)
        if keep_otf:
            H = self.otf(disp)
            h2 = H.real ** 2 + H.imag ** 2
        else:
            h2 = self.otf_power(disp)
        h2 = h2.reshape(len(tl) * len(self.points), len(rw), *h2.shape[1:])
        h2 = np.tensordot(rw.astype(np.float32), h2, axes=([0], [1]))
        S = self.model(h2)
        if keep_otf:
            mid = len(rw) // 2
            return S, H.reshape(len(tl) * len(self.points), len(rw), *H.shape[1:])[:, mid]
        return S

    def _points_across(self, offsets, taus) -> list:
        """Items ``(photo, x, y, row, tau)`` of :meth:`displacements` at the points of each
        patch ``offsets`` (x the patch side) from its centre in y and in x, each read at its
        own row's time, for each time shift of ``taus``: rows of points, a row per y."""
        F = self.F
        return [(i, x + c * F, y + r * F, y + r * F, tau) for tau in taus
                for (i, x, y) in self.points for r in offsets for c in offsets]

    def kernel_change(self, theta: Corrections) -> float:
        """The largest change (working-scale px, the kernel's mean position left out)
        between a patch's kernel at its centre and at the 8 points 0.15 of the patch side
        away from it in x, in y or both: roll and, at a wide angle, perspective make the
        kernel vary across a patch, which the centre's kernel alone does not model."""
        if not self.points:
            return 0.0
        items = self._points_across((-0.15, 0.0, 0.15), [0.0])
        d = self.displacements(theta, items).reshape(len(self.points), 9, self.n, 2)
        d = d - d.mean(axis=2, keepdims=True)
        return float(np.hypot(*np.moveaxis(d - d[:, 4:5], -1, 0)).max())

    # -- likelihood -------------------------------------------------------------------
    def costs(self, theta: Corrections, taus=None, rows=None) -> np.ndarray:
        """Per-patch costs, ``(n_patch,)`` or ``(n_tau, n_patch)`` when ``taus`` (extra
        time shifts) is given: the Whittle cost of the patch periodograms under the model
        spectra with their envelopes, profiled over the scale and the noise. More than
        :data:`_TAU_CHUNK` time shifts are taken that many at a time (each shift's costs
        are its own; the memory stays that of one chunk: about 1.5 MB per shift)."""
        return self.costs_under((self.envelope,), theta, taus, rows)[0]

    def costs_under(self, envelopes, theta: Corrections, taus=None, rows=None) -> list:
        """:meth:`costs` under each of ``envelopes`` (``True``: fitted to each evaluation,
        ``False``: flat; an envelope held by :meth:`set_envelope` stands for either), the
        model spectra made once for all of them: each equals :meth:`costs` called with
        :attr:`envelope` set to it, from the same warm starts (each envelope follows its
        own chain of them; the last one's is kept). One evaluation per envelope."""
        self.evaluations += len(envelopes)
        batches = [None]
        if taus is not None:
            taus = np.asarray(taus, float)
            batches = [taus[k:k + _TAU_CHUNK] for k in range(0, max(len(taus), 1), _TAU_CHUNK)]
        chains = [dict(self._rho_warm) for _ in envelopes]
        out: list = [[] for _ in envelopes]
        try:
            for tl in batches:
                S = self.spectra(theta, tl, rows=rows)
                for k, envelope in enumerate(envelopes):
                    self._rho_warm = chains[k]
                    out[k].append(self._costs_of(S, envelope))
        finally:
            if chains:
                self._rho_warm = chains[-1]
        return [np.concatenate(c) if taus is not None else c[0][0] for c in out]

    def _costs_of(self, S: np.ndarray, envelope: bool) -> np.ndarray:
        """The costs ``(n_tau, n_patch)`` of model spectra ``S`` (a batch of time shifts),
        under the held envelopes, or with ``envelope`` fitted to them, or flat."""
        if self.E is not None:
            S = S * np.tile(self.E, (S.shape[0] // len(self.points), 1))
        elif envelope:
            S = S * self.fast_envelope(S)
        return self._whittle(S).reshape(-1, len(self.points))

    def cost(self, theta: Corrections) -> float:
        return float(self.costs(theta).sum())

    def set_envelope(self, theta: Corrections | None) -> None:
        """Fit the patch envelopes at ``theta`` and hold them (``None``: let every
        evaluation fit its own)."""
        if theta is None:
            self.E = None
            return
        S = self.spectra(theta)
        E = self.fast_envelope(S, iters=_ENVELOPE_ITERS_HELD)
        self.E = E / E.mean(1, keepdims=True)

    # -- state between evaluations ------------------------------------------------------
    def held_state(self) -> tuple:
        """What later evaluations depend on besides their arguments: the held envelopes,
        whether each evaluation fits its own, the noise ratios that warm-start the next
        profile, the orientations cached, the latest spectra, and the evaluation count.
        For :meth:`restore`."""
        return (self.E, self.envelope, dict(self._rho_warm), dict(self._orient_cache),
                self._last_spectra, self.evaluations)

    def restore(self, state: tuple) -> None:
        """Back to a :meth:`held_state`."""
        (self.E, self.envelope, warm, orient, self._last_spectra, self.evaluations) = state
        self._rho_warm, self._orient_cache = dict(warm), dict(orient)

    def start_afresh(self) -> None:
        """Forget the warm starts and caches (not the held envelopes): the evaluations that
        follow then depend only on their arguments and the envelopes, whatever ran before
        (the warm start of the noise ratio and an orientation integrated over a wider window
        move a cost in its last digits)."""
        self._rho_warm, self._orient_cache = {}, {}
        self._last_spectra = (None, None)

    def _whittle(self, S: np.ndarray, params: bool = False):
        reps = S.shape[0] // len(self.points)
        Pw = np.tile(self.power, (reps, 1))
        warm = self._rho_warm.get(S.shape[0])
        if warm is None:
            warm = np.tile(self._rho_init, reps)
        c, a, rho, x = whittle_profiled(S, Pw, warm=warm, params=True)
        self._rho_warm[S.shape[0]] = x
        return (c, a, rho) if params else c

    def _prepare_fast_envelope(self) -> None:
        """Per patch, the fixed weighted least-squares map from ``log S`` (binned) to the
        envelope coefficients: ``c = G (log(P - s) - log S)`` on bins where the signal
        dominates the noise floor ``s`` (weights from the data alone, so ``c`` is a linear,
        smooth function of ``log S``)."""
        from scipy import sparse
        N = int(self.mask.sum())
        self._bin_op = sparse.csr_matrix(
            (1.0 / self.bin_cnt[self.bin_of], (self.bin_of, np.arange(N))), shape=(self.nbins, N))
        Phi = self.Phi_bin
        k = Phi.shape[1]
        rb = np.sqrt(np.bincount(self.bin_of, self.Phi[:, 0] * 0 + self._rad_masked ** 2,
                                 self.nbins) / self.bin_cnt)
        G, Y, R, NS = [], [], [], []
        for pb in self.pbin:
            outer = pb[rb > 0.3]
            s = np.percentile(outer, 20) if outer.size else np.percentile(pb, 5)
            w = np.clip((pb - 2 * s) / pb, 0, 1) ** 2 * self.bin_cnt
            A = Phi.T @ (w[:, None] * Phi) + 1e-6 * np.eye(k)
            G.append(np.linalg.solve(A, Phi.T * w[None, :]))
            Y.append(np.log(np.maximum(pb - s, 0.1 * pb)))
            R.append(np.log(max(s, 1e-30) / max(pb.mean(), 1e-30)))
            NS.append(s)
        self._env_G = np.stack(G) if G else np.zeros((0, k, self.nbins))
        self._env_Y = np.stack(Y) if Y else np.zeros((0, self.nbins))
        self._rho_init = np.array(R)
        self._noise = np.array(NS)

    def fast_envelope(self, S: np.ndarray, iters: int | None = None) -> np.ndarray:
        """Envelopes ``(B, N)`` for model spectra ``S`` (B a multiple of the patches):
        the weighted least-squares start, then a fixed number of damped Fisher-scoring
        steps of the Whittle likelihood of ``P ~ E S + s`` on the binned spectra (fixed,
        so that the envelope is a smooth function of ``S``). A step that would change the
        log noise floor ``s`` by more than :data:`_FLOOR_MAX_STEP` is shrunk to that (the
        whole step, in proportion: a continuous cap, so the envelope stays a continuous
        function of ``S``; normal steps stay under it): a floor driven towards zero loses
        its Fisher information, and an uncapped step then threw it 30 e-folds up, and that
        patch's cost thousands of nats up, at isolated parameter values (a focal length 3 %
        off but not 2.5 or 3.5 %), which trapped the search."""
        iters = _ENVELOPE_ITERS if iters is None else iters
        npt = len(self.points)
        reps = S.shape[0] // npt
        Sb = np.maximum(np.asarray(self._bin_op @ S.T).T, 1e-300)            # (B, nb)
        y = (self._env_Y[None] - np.log(Sb).reshape(reps, npt, -1)).transpose(1, 2, 0)
        c = np.matmul(self._env_G, y).transpose(2, 0, 1).reshape(S.shape[0], -1)
        if iters:
            Pb = np.tile(self.pbin, (reps, 1))
            Phi = self.Phi_bin
            k = Phi.shape[1]
            cnt = self.bin_cnt[None, :]
            ls = np.log(np.maximum(np.tile(self._noise, reps), 1e-30))
            th = np.concatenate([c, ls[:, None]], 1)
            eye = np.eye(k + 1)
            for _ in range(iters):
                m1 = np.exp(np.clip(th[:, :k] @ Phi.T, -60, 60)) * Sb
                sn = np.exp(np.clip(th[:, -1], -80, 10))[:, None]
                M = m1 + sn
                Z = np.concatenate([(m1 / M)[:, :, None] * Phi[None], (sn / M)[:, :, None]], 2)
                Zt = np.transpose(Z, (0, 2, 1))
                g = np.matmul(Zt, (cnt * (1 - Pb / M))[:, :, None])[..., 0]
                F = np.matmul(Zt * cnt[:, None, :], Z)
                F = F + 0.1 * F * eye + 1e-6 * eye
                step = np.linalg.solve(F, g[..., None])[..., 0]
                floor = np.abs(step[:, -1])
                th = th - step * (_FLOOR_MAX_STEP / np.maximum(floor, _FLOOR_MAX_STEP))[:, None]
            c = th[:, :k]
        return np.exp(np.clip(c @ self.Phi.T, -60, 60))

    def gauss_newton(self, theta_of, x, idx, hs):
        """Cost, gradient, Fisher matrix (scale and noise profiled out) and per-patch
        scores at ``x`` for the coordinates ``idx`` (forward differences of the model
        spectra, steps ``hs``)."""
        def model(v):
            S = self.spectra(theta_of(v))
            if self.E is not None:
                return S * self.E
            return S * self.fast_envelope(S) if self.envelope else S

        S0 = model(x)
        c, a, rho = self._whittle(S0, params=True)
        M0 = S0 + rho[:, None]
        r = self.power / (a[:, None] * M0)
        J = []
        for j in idx:
            y = x.copy()
            y[j] += hs[j]
            J.append((model(y) - S0) / hs[j] / M0)
        if not J:
            return float(c.sum()), np.zeros(0), np.zeros((0, 0)), np.zeros((len(self.points), 0))
        J = np.stack(J)                                          # (K, B, N)
        U = np.stack([np.ones_like(M0), 1.0 / M0], 0)            # nuisances: log a, rho
        UU = np.einsum("pbn,qbn->bpq", U, U)
        UJ = np.einsum("pbn,kbn->bpk", U, J)
        coef = np.linalg.solve(UU + 1e-30 * np.eye(2), UJ)      # (B, 2, K)
        Jt = J - np.einsum("pbn,bpk->kbn", U, coef)
        scores = np.einsum("kbn,bn->bk", J, 1 - r)                # per patch gradient
        F = np.einsum("kbn,lbn->kl", Jt, Jt)
        self.evaluations += 1
        return float(c.sum()), scores.sum(0), F, scores

    # -- phase: sparsity of deconvolved patches ---------------------------------------
    def gain_over_no_blur(self, theta: Corrections) -> np.ndarray:
        """Per patch, how much better (untempered nats) the PSFs of ``theta`` explain the
        patch than no blur at all (a point, splatted as the traces are), each with an
        envelope fitted to it: near zero or below, the patch shows none of that blur.
        Where the kernel changes across a patch by more than :data:`_KERNEL_CHANGE`
        (:meth:`kernel_change`), its ``|H|^2`` is averaged over the patch (``spread``
        of :meth:`spectra`): under a 1.5-3 rad/s roll the centre's kernel alone made a
        true capture score 46-160 nats worse than no blur. (The search's cost averages
        it over 2 x 2 points, ``across``, which follow a smaller change to second order.)"""
        S_blur = self.spectra(theta, spread=self.kernel_change(theta) > _KERNEL_CHANGE)
        S_none = self.model(self.otf_power(np.zeros((len(self.points), 1, 2))))
        return self._gain_over(S_none, S_blur)

    def psf_gain_over_no_blur(self, psf: np.ndarray) -> np.ndarray:
        """Per patch, how much better (untempered nats) one pixel kernel ``psf`` explains
        the patch than no blur at all (a delta), each with an envelope fitted to it: the
        counterpart of :meth:`gain_over_no_blur` for a kernel that is not a trace (a blind
        estimate).

        ``psf``: odd square, centred on its centre sample, at the photo's resolution. Its
        transfer function is evaluated exactly at the working scale's frequencies
        (``H(f) = sum_x psf(x) exp(-2 pi i f . x)``, ``f`` in cycles per photo pixel), so
        no resampling of the kernel adds its own blur; the patches' resampling filter is
        in the model for both."""
        k = np.asarray(psf, np.float64)
        r = k.shape[0] // 2
        d = np.arange(-r, r + 1)
        fy = sfft.fftfreq(self.size) * self.scale          # cycles per photo pixel
        fx = sfft.rfftfreq(self.size) * self.scale
        Ey = np.exp(-2j * np.pi * np.outer(fy, d))
        Ex = np.exp(-2j * np.pi * np.outer(fx, d))
        H = Ey @ k @ Ex.T
        B = len(self.points)
        h2 = np.repeat(((H.real ** 2 + H.imag ** 2)[None]).astype(np.float32), B, axis=0)
        S_psf = self.model(h2)
        S_none = self.model(np.ones_like(h2))
        return self._gain_over(S_none, S_psf)

    def _gain_over(self, S_none: np.ndarray, S_blur: np.ndarray) -> np.ndarray:
        """Per patch, the Whittle cost of model spectra ``S_none`` minus that of ``S_blur``,
        each with an envelope fitted to it (untempered nats)."""
        c_blur, c_none = (self._whittle(S * self.fast_envelope(S)) for S in (S_blur, S_none))
        return c_none - c_blur

    def sparsity(self, theta: Corrections) -> np.ndarray:
        """Per patch, normalised gradient sparsity ``|grad u|_1 / |grad u|_2`` (x sqrt n)
        of the Wiener-deconvolved patch (Gaussian-model optimal filter)."""
        S, H = self.spectra(theta, keep_otf=True)
        P = self.size
        u = sfft.fftfreq(P)[:, None]
        v = sfft.rfftfreq(P)[None, :]
        d2 = 4 * np.sin(np.pi * u) ** 2 + 4 * np.sin(np.pi * v) ** 2
        out = []
        for j in range(len(self.points)):
            Hj = H[j]
            ps = np.abs(Hj) ** 2
            nsr = self._nsr(j, ps, d2)
            U = np.conj(Hj) * self.G[j] / (ps + nsr * d2 + 1e-12)
            img = sfft.irfft2(U, s=(P, P))
            m = P // 4
            c = img[m:-m, m:-m]
            gy, gx = np.gradient(c)
            g = np.hypot(gx, gy)
            out.append(g.sum() / np.sqrt((g ** 2).sum() * g.size + 1e-30))
        return np.asarray(out)

    def _nsr(self, j, ps, d2) -> float:
        """Noise-to-signal ratio of patch ``j`` under the flat model (a rough Wiener NSR)."""
        m = self.mask
        S = (ps * np.where(d2 > 0, 1 / np.maximum(d2, 1e-12), 0))[m]
        P = self.power[j]
        best = (np.inf, 1e-3)
        for r in np.geomspace(1e-6, 1.0, 13):
            rho = r * S.mean()
            Mm = S + rho
            c = P.size * np.log(np.mean(P / Mm)) + np.log(Mm).sum()
            if c < best[0]:
                best = (c, rho)
        return float(best[1])


def envelope_basis(r: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Envelope basis at frequencies of radius ``r`` (cycles/px) and angle ``a``."""
    lr = np.log(r / 0.1)
    return np.stack([np.ones_like(r), lr, (r / 0.25) ** 2, np.cos(2 * a), np.sin(2 * a),
                     np.cos(4 * a), np.sin(4 * a), lr * np.cos(2 * a), lr * np.sin(2 * a)], 1)


def whittle_profiled(S: np.ndarray, Pw: np.ndarray, grid=np.geomspace(1e-7, 1.0, 8),
                  params: bool = False, warm: np.ndarray | None = None):
    """Whittle cost of ``P ~ a (S + rho)`` profiled over ``a`` (closed form) and ``rho``
    (``log rho`` by Newton steps from a grid, or from ``warm``, the previous solution).
    Returns the costs, and with ``params`` also ``a``, ``rho`` and ``log(rho / mean S)``."""
    B, N = S.shape
    scale = np.maximum(S.mean(1), 1e-300)
    lg = np.log(grid)
    if warm is None or warm.shape != (B,):
        best = np.full(B, np.inf)
        x = np.zeros(B)
        for k, r in enumerate(grid):
            M0 = S + (r * scale)[:, None]
            c = N * np.log(np.mean(Pw / M0, 1)) + np.sum(np.log(M0), 1)
            better = c < best
            best[better] = c[better]
            x[better] = lg[k]
        iters = 3
    else:
        x = np.clip(warm, lg[0] - 2, lg[-1])
        iters = 4
    for _ in range(iters):
        rho = np.exp(x) * scale
        inv = 1.0 / (S + rho[:, None])
        q1 = Pw * inv
        a = q1.mean(1)
        q2 = (q1 * inv).mean(1)
        q3 = (q1 * inv * inv).mean(1)
        c_r = -N * q2 / a + inv.sum(1)
        c_rr = N * (2 * q3 / a - (q2 / a) ** 2) - (inv * inv).sum(1)
        c_x = rho * c_r
        c_xx = rho * c_r + rho ** 2 * c_rr
        step = np.where(c_xx > 0, -c_x / np.where(c_xx > 0, c_xx, 1.0), -np.sign(c_x) * 0.5)
        x = np.clip(x + np.clip(step, -1.0, 1.0), lg[0] - 2, lg[-1])
    rho = np.exp(x) * scale
    M0 = S + rho[:, None]
    a = np.mean(Pw / M0, 1)
    c = N * np.log(a) + np.sum(np.log(M0), 1) + N
    if params:
        return c, a, rho, x
    return c, x
