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
A patch (linear-light luminance, downscaled so that the largest PSF spans ~32 px) is
modelled as ``g = h * u + n`` with a Gaussian image ``u`` and white noise ``n``. Its
Hann-windowed periodogram ``P(w)`` is then exponentially distributed around

    ``M(w) = a (E(w) |H(w)|^2 |A(w)|^2 / |D(w)|^2 + rho)``

(``D`` the discrete gradient: a Gaussian gradient prior; ``A`` the resampling filter), and
``-log p(g | h) = sum_w P/M + log M`` (Whittle): the chapter's marginal ``p(h | g)``
(eq. 6.7) for a Gaussian prior, which penalises too little blur and too much alike. The
scale ``a`` is profiled in closed form, the noise ratio ``rho`` by Newton steps.

Real patches are not isotropic ``1/f^2`` textures: edges and oriented texture make the
spectrum anisotropic, optics and resampling soften it, and a fixed prior then trades those
differences against the blur. So ``E`` is a smooth per-patch envelope,
``log E = c . phi(w)`` with ``phi`` = {1, log f, f^2, cos 2a, sin 2a, cos 4a, sin 4a,
log f cos 2a, log f sin 2a}, fitted to ``P ~ E S + s`` on 4x4-binned spectra (weighted
least squares, then damped Fisher scoring) at a given parameter set and then held while
the parameters move (refitted every few steps). What is left to the PSF is mostly the fine
structure of ``|H|^2``, its zeros and ripples. ``|H|`` comes from the exact trace of the
patch centre, rendered as a sum of narrow Gaussians (0.75 px): the cost is a smooth
function of the parameters (bilinear splatting makes it jagged, because its low-pass
changes with the PSF's sub-pixel position). A patch spans rows exposed at different times
(rolling shutter), so ``|H|^2`` is averaged over three of its rows.

The Whittle cost over-counts (neighbouring frequencies of a windowed patch are correlated
and images are not Gaussian; on the benchmark cases the patch-to-patch spread of the
estimates is ~100x what its curvature claims), so it is divided by :data:`_TEMPERATURE`
before weak Gaussian priors around the given values are added: readout +-30 %, focal
+-10 %, bias +-0.05 rad/s. They matter where the photo cannot tell, mainly focal length
against a bias along a nearly uniform motion (a constant rate ``w`` with focal ``f`` and
``w + b`` with ``f w / (w + b)`` give the same blur).

A bias barely shows in one exposure (0.03 rad/s over 20 ms lengthens a PSF by half a
pixel at f = 1000 px), yet it moves the deblurred image, which is referenced to the first
row's start: by f b t at a row exposed t later. A long log says more: over seconds, the
rate of a hand-held camera averages out, and a gyro's bias does not. So when the logs hold
:data:`_REST_MIN_SECONDS` s or more within :data:`_REST_SPAN` s of the photos, their typical
rate (:func:`gyrodeblur.gyrolog.median_rate`: the median of 1 s block means, which a few
seconds of deliberate motion barely move, with an error bar from their spread; to that, in
quadrature, what the camera's own turning may leave: 0.05 rad over the log's length, at
least :data:`_REST_FLOOR`) becomes a second Gaussian on the bias, combined with the given
bias's. Each candidate mapping turns it into its own camera frame, and the searches start
from its centre; the "given parameters" that are kept unless the photo prefers others
carry it. But a given bias is either right (a calibrated gyro, ``"auto"`` from the same
log) or off, and moving a right one by the log's own error (the hand's mean rate) would
only add that error: so the log's rate first decides, by its likelihood ratio, how likely
the given bias is to be off (even odds before), and the prior is the mixture of "right"
and "off" (:func:`_bias_from_log`). (On the benchmark's correct captures with 10 s of the
shaken trace either side, centring on the log always cost 0.6-4 dB on five of the photos
that calibration otherwise leaves alone.) A typical rate more than
:data:`_REST_MAX_RATE` from the given bias on an axis is a pan, not a bias, and is not
used (said in the notes); a slower steady pan is indistinguishable from a bias and is
taken for one. Figures with 10 s of the (deliberately shaken) source trace on each side
of each photo (``--log-seconds 10``, with and without ``--no-errors``): BENCHMARKS.md
section 4.

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
   basin that the fine cost prefers.
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
best other candidate mapping; below :data:`_AXES_CONFIDENT_NATS` (8) the mapping is reported
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

import argparse
import os
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from scipy import ndimage

from .axes import PROPER_AXIS_LETTERS, axes_to_letters, parse_axes
from .capture import Capture
from .errors import InputError
from .gyrolog import GyroLog, median_rate, rate_noise
from .orientation import Orientation, quat_multiply, quat_to_matrix
from .tonecurve import get_transfer_curve

__all__ = ["calibrate", "CalibrationResult", "PARAMETERS", "calibrate_command",
           "format_estimates", "fixed_parameters"]

#: Parameters that can be estimated (and fixed with ``fix=``).
PARAMETERS = ("offset", "bias", "readout", "focal", "axes")

_TWIN = np.diag([-1.0, -1.0, 1.0])
_SPLAT_SIGMA = 0.75        # px: Gaussian splat of the PSF trace
_FMAX = 0.42               # cycles/px: frequencies kept (splat aliasing beyond)
_FMIN_BINS = 2.5           # frequencies below this many bins are dropped (window leakage)
_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


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
    """

    captures: list
    estimates: dict
    ranking: list = field(default_factory=list)
    scale: float = 1.0
    fixed: set = field(default_factory=set)
    seconds: float = 0.0
    notes: list = field(default_factory=list)

    @property
    def capture(self) -> Capture:
        return self.captures[0]


# ----------------------------------------------------------------------------- parameters

@dataclass
class _Theta:
    """Corrections shared by all photos: deltas to each capture's own values."""

    axes: np.ndarray            # absolute mapping (3x3)
    offset: float = 0.0         # s, added to each capture's time_offset
    readout: float = 0.0        # s, added to each capture's readout_time
    focal: float = 1.0          # scale of the focal length
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))   # rad/s, added

    def copy(self, **kw) -> "_Theta":
        d = dict(axes=self.axes, offset=self.offset, readout=self.readout, focal=self.focal,
                 bias=np.array(self.bias, float))
        d.update(kw)
        return _Theta(**d)

    def apply(self, cap: Capture) -> Capture:
        return cap.replace(time_offset=cap.time_offset + self.offset,
                           readout_time=max(0.0, cap.readout_time + self.readout),
                           camera=cap.camera.with_focal_scale(self.focal),
                           bias=cap.bias + self.bias, axes=self.axes)


# ----------------------------------------------------------------------------- photos

class _Photo:
    """A blurred photo, its full-resolution capture, and cheap access to its pixels."""

    def __init__(self, image, capture: Capture, transfer: str, index: int):
        img = np.asarray(image)
        if img.ndim not in (2, 3):
            raise InputError(None, f"photo {index + 1}: expected an (H, W) or (H, W, C) array")
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[..., :3]
        self.image = img
        self.H, self.W = img.shape[:2]
        self.cap = capture.scaled_to(self.W, self.H)
        self.curve = get_transfer_curve(transfer)
        self.index = index

    def gray(self, y0, y1, x0, x1) -> np.ndarray:
        """Linear-light luminance of a crop (float64)."""
        c = np.asarray(self.image[y0:y1, x0:x1], np.float32)
        lin = self.curve.decode(c)
        return (lin.mean(axis=2) if lin.ndim == 3 else lin).astype(np.float64)

    def thumbnail(self, max_side: int = 512):
        """Block-averaged encoded luminance and saturated fraction, and the block size."""
        k = max(1, int(np.ceil(max(self.H, self.W) / max_side)))
        h, w = self.H // k, self.W // k
        img = np.asarray(self.image[:h * k, :w * k], np.float32)
        if img.ndim == 3:
            sat = img.max(axis=2) > 0.98
            img = img.mean(axis=2)
        else:
            sat = img > 0.98
        th = img.reshape(h, k, w, k).mean(axis=(1, 3))
        st = sat.reshape(h, k, w, k).mean(axis=(1, 3))
        return th, st, k


def _select_centres(photo: _Photo, n: int, footprint: int) -> list[tuple[float, float]]:
    """Centres (full-res x, y) of up to ``n`` textured, unsaturated windows of side
    ``footprint`` spread over a grid of cells (best isotropic texture per cell: the
    smaller eigenvalue of the structure tensor), then the best remaining anywhere."""
    th, sat, k = photo.thumbnail()
    h, w = th.shape
    win = max(3, int(round(footprint / k)))
    win = min(win, h, w)
    gy, gx = np.gradient(th.astype(np.float64))
    jxx = ndimage.uniform_filter(gx * gx, win, mode="nearest")
    jyy = ndimage.uniform_filter(gy * gy, win, mode="nearest")
    jxy = ndimage.uniform_filter(gx * gy, win, mode="nearest")
    lam_min = 0.5 * (jxx + jyy - np.sqrt((jxx - jyy) ** 2 + 4 * jxy ** 2))
    satf = ndimage.uniform_filter(sat, win, mode="nearest")
    # clipped highlights break the linear model: avoid them, but a page of text on white
    # paper has little else, so they are penalised rather than excluded up to 30 %
    score = np.where(satf > 0.3, -1.0, lam_min * (1 - 3 * satf))
    if not (score > 0).any():                    # nothing else: take what there is
        score = lam_min * (1 - 0.9 * satf)
    half = win / 2
    ylo, yhi = int(np.ceil(half)) - 1, int(np.floor(h - half))
    xlo, xhi = int(np.ceil(half)) - 1, int(np.floor(w - half))
    if yhi < ylo:
        ylo = yhi = h // 2
    if xhi < xlo:
        xlo = xhi = w // 2
    valid = np.full(score.shape, -np.inf)
    valid[ylo:yhi + 1, xlo:xhi + 1] = score[ylo:yhi + 1, xlo:xhi + 1]
    aspect = photo.W / photo.H
    cols = max(1, int(round(np.sqrt(n * aspect))))
    rows = max(1, int(np.ceil(n / cols)))
    yb = np.linspace(ylo, yhi + 1, rows + 1).astype(int)
    xb = np.linspace(xlo, xhi + 1, cols + 1).astype(int)
    Y, X = np.mgrid[0:h, 0:w]
    taken: list = []
    radius = 0.7 * win
    found = []

    def pick(y0, y1, x0, x1) -> bool:
        sub = valid[y0:y1, x0:x1].copy()
        for (ty, tx) in taken:
            sub[np.hypot(Y[y0:y1, x0:x1] - ty, X[y0:y1, x0:x1] - tx) < radius] = -np.inf
        if not np.isfinite(sub).any():
            return False
        j = int(np.argmax(sub))
        v = float(sub.flat[j])
        if not v > 0:
            return False
        yy, xx = np.unravel_index(j, sub.shape)
        taken.append((y0 + yy, x0 + xx))
        found.append((v, (x0 + xx + 0.5) * k - 0.5, (y0 + yy + 0.5) * k - 0.5))
        return True

    for r in range(rows):                        # the best window of each cell ...
        for c in range(cols):
            if len(found) < n:
                pick(yb[r], max(yb[r + 1], yb[r] + 1), xb[c], max(xb[c + 1], xb[c] + 1))
    while len(found) < n and pick(0, h, 0, w):   # ... then the best anywhere else
        pass
    found.sort(key=lambda f: -f[0])
    return [(x, y) for _, x, y in found[:n]]


# ----------------------------------------------------------------------------- the model

class _Stage:
    """Patches of the photos at one working scale, and the cost of a parameter set."""

    def __init__(self, photos: list[_Photo], centres, scale: float, size: int, *,
                 rows=(0.0,), n_samples: int = 128, envelope: bool = True):
        self.photos = photos
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
        mask = (rad >= _FMIN_BINS / P) & (rad <= _FMAX)
        mask &= ~((fyh < 0) & ((fxh == 0) | np.isclose(fxh, 0.5)))   # redundant halves
        self.mask = mask
        self._build_smoother(prior_ext)
        win1 = np.hanning(P + 2)[1:-1]
        self.win = np.outer(win1, win1)
        # envelope basis and 4x4 bins
        r = rad[mask]
        self._rad_masked = r
        a = np.arctan2(fyh, fxh)[mask]
        self.Phi = _basis(r, a)
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
        self._rho_warm: dict = {}
        self.E = None
        self.envelope = envelope
        self.evaluations = 0

    # -- geometry ---------------------------------------------------------------------
    def _orientation(self, i: int, theta: _Theta, lo: float, hi: float) -> Orientation:
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

    def displacements(self, theta: _Theta, items) -> np.ndarray:
        """``(B, n, 2)`` trace of each item ``(photo, x, y, row, tau)`` relative to
        ``(x, y)``, in working-scale pixels (full-resolution coordinates in)."""
        n = self.n
        out = np.empty((len(items), n, 2))
        s = (np.arange(n) + 0.5) / n
        groups: dict = {}
        for b, it in enumerate(items):
            groups.setdefault(it[0], []).append(b)
        for i, idx in groups.items():
            cap = self.photos[i].cap
            arr = np.array([items[b][1:] for b in idx], float)
            taus = arr[:, 3] + theta.offset
            tref = cap.exposure_start
            readout = max(0.0, cap.readout_time + theta.readout)
            T = tref + readout * arr[:, 2:3] / cap.camera.height + cap.exposure_time * s[None, :]
            O = self._orientation(i, theta, min(T.min(), tref) - taus.max(),
                                  max(T.max(), tref) - taus.min())
            qref = O.quaternions(tref - taus) * _CONJ
            q = O.quaternions(T - taus[:, None])
            R = quat_to_matrix(quat_multiply(qref[:, None, :], q))       # (b, n, 3, 3)
            c = cap.camera
            fx, fy = c.fx * theta.focal, c.fy * theta.focal
            ray = np.stack([(arr[:, 0] - c.cx) / fx, (arr[:, 1] - c.cy) / fy,
                            np.ones(len(idx))], 1)
            d = np.einsum("bnji,bj->bni", R, ray)
            out[idx, :, 0] = (fx * d[..., 0] / d[..., 2] + c.cx - arr[:, 0:1]) * self.scale
            out[idx, :, 1] = (fy * d[..., 1] / d[..., 2] + c.cy - arr[:, 1:2]) * self.scale
        return out

    def otf(self, disp: np.ndarray) -> np.ndarray:
        """Complex OTF ``(B, P, P//2+1)`` of Gaussian-splatted traces (sum 1)."""
        P = self.size
        B, n, _ = disp.shape
        R = 2
        offs = np.arange(-R, R + 1)
        cx = np.floor(disp[..., 0] + 0.5)
        cy = np.floor(disp[..., 1] + 0.5)
        k2 = -0.5 / _SPLAT_SIGMA ** 2
        wx = np.exp(k2 * ((cx[..., None] + offs) - disp[..., 0, None]) ** 2)
        wy = np.exp(k2 * ((cy[..., None] + offs) - disp[..., 1, None]) ** 2)
        ix = (cx.astype(np.int64)[..., None] + offs) % P
        iy = (cy.astype(np.int64)[..., None] + offs) % P
        idx = (np.arange(B) * P * P)[:, None, None, None] + iy[..., :, None] * P + ix[..., None, :]
        w = wy[..., :, None] * wx[..., None, :]
        k = np.bincount(idx.ravel(), w.ravel(), minlength=B * P * P).reshape(B, P, P)
        k /= np.maximum(k.sum(axis=(1, 2), keepdims=True), 1e-30)
        return sfft.rfft2(k.astype(np.float32), axes=(1, 2), workers=2)

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

    def spectra(self, theta: _Theta, taus=None, rows=None, keep_otf=False):
        """Model spectra ``S`` ``(n_tau * n_patch, N)`` (and the centre-row OTFs)."""
        rows = self.rows if rows is None else np.asarray(rows, float)
        rw = self.row_w if rows is self.rows else np.ones(len(rows)) / len(rows)
        tl = [0.0] if taus is None else list(taus)
        items = [(i, x, y, y + r * self.F, tau)
                 for tau in tl for (i, x, y) in self.points for r in rows]
        H = self.otf(self.displacements(theta, items))
        h2 = (H.real ** 2 + H.imag ** 2).reshape(len(tl) * len(self.points), len(rows), *H.shape[1:])
        h2 = np.tensordot(rw.astype(np.float32), h2, axes=([0], [1]))
        S = self.model(h2)
        if keep_otf:
            mid = len(rows) // 2
            return S, H.reshape(len(tl) * len(self.points), len(rows), *H.shape[1:])[:, mid]
        return S

    # -- likelihood -------------------------------------------------------------------
    def costs(self, theta: _Theta, taus=None, rows=None) -> np.ndarray:
        """Per-patch costs, ``(n_patch,)`` or ``(n_tau, n_patch)`` when ``taus`` (extra
        time shifts) is given: the Whittle cost of the patch periodograms under the model
        spectra with their envelopes, profiled over the scale and the noise."""
        S = self.spectra(theta, taus, rows=rows)
        if self.E is not None:
            S = S * np.tile(self.E, (S.shape[0] // len(self.points), 1))
        elif self.envelope:
            S = S * self.fast_envelope(S)
        c = self._whittle(S)
        self.evaluations += 1
        c = c.reshape(-1, len(self.points))
        return c if taus is not None else c[0]

    def cost(self, theta: _Theta) -> float:
        return float(self.costs(theta).sum())

    def set_envelope(self, theta: _Theta | None) -> None:
        """Fit the patch envelopes at ``theta`` and hold them (``None``: let every
        evaluation fit its own)."""
        if theta is None:
            self.E = None
            return
        S = self.spectra(theta)
        E = self.fast_envelope(S, iters=_ENVELOPE_ITERS_HELD)
        self.E = E / E.mean(1, keepdims=True)

    def _whittle(self, S: np.ndarray, params: bool = False):
        reps = S.shape[0] // len(self.points)
        Pw = np.tile(self.power, (reps, 1))
        warm = self._rho_warm.get(S.shape[0])
        if warm is None:
            warm = np.tile(self._rho_init, reps)
        c, a, rho, x = _whittle_flat(S, Pw, warm=warm, params=True)
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
        so that the envelope is a smooth function of ``S``)."""
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
                th = th - np.linalg.solve(F, g[..., None])[..., 0]
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
    def sparsity(self, theta: _Theta) -> np.ndarray:
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


def _basis(r: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Envelope basis at frequencies of radius ``r`` (cycles/px) and angle ``a``."""
    lr = np.log(r / 0.1)
    return np.stack([np.ones_like(r), lr, (r / 0.25) ** 2, np.cos(2 * a), np.sin(2 * a),
                     np.cos(4 * a), np.sin(4 * a), lr * np.cos(2 * a), lr * np.sin(2 * a)], 1)


def _whittle_flat(S: np.ndarray, Pw: np.ndarray, grid=np.geomspace(1e-7, 1.0, 8),
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


# ----------------------------------------------------------------------------- registration

def _phase_shift(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Translation ``d`` (x, y) with ``b(x) ~ a(x - d)`` by phase correlation (whitened
    cross-power, Gaussian low-pass at 0.1 cycles/px so that JPEG block edges, which do not
    move, do not win), and the peak's prominence (peak over the 99.9th percentile)."""
    h, w = a.shape
    win = np.outer(np.hanning(h), np.hanning(w))
    A = sfft.fft2((a - a.mean()) * win)
    Bf = sfft.fft2((b - b.mean()) * win)
    R = Bf * np.conj(A)
    R /= np.maximum(np.abs(R), 1e-12)
    fy = sfft.fftfreq(h)[:, None]
    fx = sfft.fftfreq(w)[None, :]
    R *= np.exp(-(fx ** 2 + fy ** 2) / (2 * 0.1 ** 2))    # JPEG blocks and noise: low-pass
    r = np.real(sfft.ifft2(R))
    iy, ix = np.unravel_index(int(np.argmax(r)), r.shape)
    peak = r[iy, ix]

    def sub(v0, v1, v2):
        den = v0 - 2 * v1 + v2
        return 0.0 if den >= 0 else 0.5 * (v0 - v2) / den

    dy = iy + sub(r[(iy - 1) % h, ix], peak, r[(iy + 1) % h, ix])
    dx = ix + sub(r[iy, (ix - 1) % w], peak, r[iy, (ix + 1) % w])
    dy = dy - h if dy > h / 2 else dy
    dx = dx - w if dx > w / 2 else dx
    return np.array([dx, dy]), float(peak / max(np.percentile(r, 99.9), 1e-12))


class _Registration:
    """Image motion between photos of one session: measured once (phase correlation of
    the whole frames), predicted from the gyro for any parameter set (mean displacement
    of the blurred image of a grid of scene points)."""

    def __init__(self, photos: list[_Photo], extent: float, max_dt: float = 1.0):
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
            d, q = _phase_shift(ta.astype(np.float64), tb.astype(np.float64))
            if q < 3.0:
                continue
            sigma = 2.0 + 0.03 * extent
            self.pairs.append((a, b, d * k, sigma, q))

    def predict(self, theta: _Theta, a: int, b: int) -> np.ndarray:
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
        qref = O.quaternions(np.array([t_a - theta.offset]))[0] * _CONJ
        cam = ca.camera
        fx, fy = cam.fx * theta.focal, cam.fy * theta.focal
        gx, gy = np.meshgrid([0.25, 0.5, 0.75], [0.25, 0.5, 0.75])
        px = gx.ravel() * (pa.W - 1)
        py = gy.ravel() * (pa.H - 1)
        ray = np.stack([(px - cam.cx) / fx, (py - cam.cy) / fy, np.ones(px.size)], 1)

        def centroid(times):                       # times (P, n), camera clock
            q = quat_multiply(qref, O.quaternions(times - theta.offset))
            R = quat_to_matrix(q)
            d = np.einsum("pnji,pj->pni", R, ray)
            return np.stack([(fx * d[..., 0] / d[..., 2] + cam.cx).mean(1),
                             (fy * d[..., 1] / d[..., 2] + cam.cy).mean(1)], 1)

        ro_a = max(0.0, ca.readout_time + theta.readout)
        ro_b = max(0.0, cb.readout_time + theta.readout)
        c_a = centroid(t_a + ro_a * py[:, None] / pa.H + ca.exposure_time * s[None, :])
        row_b = centroid(np.full((px.size, 1), t_b))[:, 1]
        c_b = centroid(t_b + ro_b * np.clip(row_b, 0, pb.H - 1)[:, None] / pb.H
                       + cb.exposure_time * s[None, :])
        return (c_b - c_a).mean(0)

    def residuals(self, theta: _Theta) -> np.ndarray:
        out = []
        for a, b, d, sigma, _ in self.pairs:
            out.append((d - self.predict(theta, a, b)) / sigma)
        return np.concatenate(out) if out else np.zeros(0)


# ----------------------------------------------------------------------------- search

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
_PRIOR_BIAS = 0.05
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
#: Objective gap (tempered nats) to the next best mapping under which the chosen axis
#: mapping is reported as uncertain. On the 24-case calibration benchmark (session 4) the
#: three wrong mappings had gaps of 3.6-4.9, every gap of 8.9 or more was right, and five
#: right ones (blurs of 3-6 px) were below 3.
_AXES_CONFIDENT_NATS = 8.0
#: Spectral cost gap (nats per patch) under which mirror twins are told apart by phase.
_TWIN_NATS = 40.0
#: ... and the phase must prefer the twin by this many standard errors of its mean over
#: the patches (a blur of a few pixels has hardly any phase: a coin toss keeps the winner;
#: with a single patch there is no standard error, and the phase never swaps).
_TWIN_SIGMAS = 2.0
_ENVELOPE_ITERS = 3
_ENVELOPE_ITERS_HELD = 6
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
#: The bias from the log's typical rate (see :func:`_rest_rate`): seconds of log used on
#: each side of the photos' exposures; the shortest log that counts (s); what a hand-held
#: camera's own rate may leave in it, added to the statistical error in quadrature: a net
#: turn of _REST_TURN rad over the log's seconds, at least _REST_FLOOR rad/s; and the
#: largest difference from the given bias taken for a bias (rad/s; more is motion).
_REST_SPAN = 30.0
_REST_MIN_SECONDS = 8.0
_REST_TURN = 0.05
_REST_FLOOR = 0.005
_REST_MAX_RATE = 0.1
_X_NAMES = ("tmid", "readout", "focal", "bias0", "bias1", "bias2")


class _Search:
    """Everything :func:`calibrate` needs between its stages."""

    def __init__(self, photos: list[_Photo], fix: set, offset_range: float, say):
        self.photos = photos
        self.fix = fix
        self.say = say or (lambda msg: None)
        self.offset_range = float(offset_range)
        c0 = photos[0].cap
        self.r0 = c0.readout_time
        self.tau_lo, self.tau_hi = self._coverage()

    # -- admissible time shifts -------------------------------------------------------
    def _coverage(self) -> tuple[float, float]:
        """Time shifts (added to every capture's offset) for which the log covers every
        photo's exposure with a 30 % longer readout (a bit of slack for the search)."""
        lo, hi = -np.inf, np.inf
        for ph in self.photos:
            c = ph.cap
            span = c.readout_time * 1.6 + 0.005 + c.exposure_time
            t0 = c.log.t[0] + c.time_offset
            t1 = c.log.t[-1] + c.time_offset
            hi = min(hi, c.exposure_start - t0)               # window start after log start
            lo = max(lo, c.exposure_start + span - t1)        # window end before log end
        lo = max(lo, -self.offset_range)
        hi = min(hi, self.offset_range)
        if "offset" in self.fix:
            lo, hi = 0.0, 0.0
        if lo > hi:
            raise InputError(self.photos[0].cap.source,
                             "the gyro log does not cover the exposure window at any time "
                             "offset in the search range")
        return lo, hi

    # -- vector <-> theta -------------------------------------------------------------
    def free(self) -> list[str]:
        out = []
        if "offset" not in self.fix:
            out.append("tmid")
        if "readout" not in self.fix:
            out.append("readout")
        if "focal" not in self.fix:
            out.append("focal")
        if "bias" not in self.fix:
            out += ["bias0", "bias1", "bias2"]
        return out

    def theta_of(self, x: np.ndarray, axes: np.ndarray, ubar: float) -> _Theta:
        return _Theta(axes=axes, offset=float(x[0] + ubar * x[1]), readout=float(x[1]),
                      focal=float(np.exp(x[2])), bias=np.array(x[3:6], float))

    def bounds(self, ubar: float):
        r0 = self.r0
        rlo, rhi = (-r0, 0.6 * r0 + 0.003) if r0 > 0 else (0.0, 0.05)
        lo = np.array([self.tau_lo - 0.01, max(rlo, -0.6 * r0), np.log(0.7), -0.2, -0.2, -0.2])
        hi = np.array([self.tau_hi + 0.01, rhi, np.log(1.4), 0.2, 0.2, 0.2])
        return lo, hi


def _extent_and_path(photos, theta: _Theta, taus) -> tuple[float, float]:
    """Typical largest PSF extent and path length (full-res px) over a 3x3 grid of
    points of each photo, the median over ``taus``."""
    geo = _Stage(photos, [], 1.0, 16, n_samples=96)
    ext, path = [], []
    for tau in taus:
        items = [(i, fx * (ph.W - 1), fy * (ph.H - 1), fy * (ph.H - 1), tau)
                 for i, ph in enumerate(photos) for fx in (0.1, 0.5, 0.9) for fy in (0.1, 0.5, 0.9)]
        d = geo.displacements(theta, items)
        ext.append(float(np.max(np.ptp(d, axis=1))))
        path.append(float(np.max(np.sum(np.hypot(*np.diff(d, axis=1).transpose(2, 0, 1)), 1))))
    return float(np.median(ext)), float(np.median(path))


def _with_twin(top: list, everything: list) -> list:
    """``top`` (rows whose last item is a mapping) plus the best row holding the mirror
    twin of its first mapping, when that is not already in."""
    if not top:
        return top
    tw = _TWIN @ top[0][-1]
    if any(np.allclose(tw, r[-1]) for r in top):
        return list(top)
    return list(top) + [r for r in everything if np.allclose(r[-1], tw)][:1]


def _line_fit(C: np.ndarray, taus: np.ndarray, u: np.ndarray, kappas) -> tuple[float, float, float]:
    """Best ``sum_i C_i(tau0 - kappa u_i)`` over ``tau0`` in ``taus`` and ``kappa`` in
    ``kappas`` (each patch's cost curve ``C[:, i]`` interpolated linearly, held constant
    beyond the grid)."""
    if len(taus) == 1:
        return float(C.sum()), float(taus[0]), 0.0
    best = (np.inf, float(taus[0]), 0.0)
    for kap in kappas:
        tot = np.zeros(len(taus))
        for j in range(C.shape[1]):
            tot += np.interp(taus - kap * u[j], taus, C[:, j])
        i = int(np.argmin(tot))
        if tot[i] < best[0]:
            best = (float(tot[i]), float(taus[i]), float(kap))
    return best


def _objective(stage: _Stage, theta_of, x, idx, prior, extra=None) -> float:
    """The objective of :func:`_gn_refine` at ``x`` (envelopes fitted there)."""
    mu, sig, T = prior
    prec = np.where(np.isfinite(sig), 1.0 / np.where(np.isfinite(sig), sig, 1.0) ** 2, 0.0)
    stage.set_envelope(theta_of(x))
    f = stage.cost(theta_of(x)) / T + 0.5 * float(np.sum(prec[idx] * (x[idx] - mu[idx]) ** 2))
    if extra is not None:
        f += 0.5 * float(np.sum(extra(x) ** 2))
    return f


def _gn_refine(stage: _Stage, theta_of, x, idx, lo, hi, hs, caps, prior, *, iters: int = 8,
               refit_every: int = 2, tol: float = 0.01, extra=None):
    """Levenberg-Marquardt on ``cost / T + prior`` with the patch envelopes held (refitted
    every ``refit_every`` iterations); steps capped per coordinate (``caps``).

    ``prior = (mu, sigma, T)``: independent Gaussian priors on the coordinates (``sigma``
    inf = flat) and the temperature ``T`` dividing the Whittle cost.

    Returns ``x``, the objective, its Gauss-Newton Hessian and the per-patch scores (both
    for the free coordinates ``idx``, tempered)."""
    mu, sig, T = prior
    idx = list(idx)
    x = np.array(x, float)
    prec = np.where(np.isfinite(sig), 1.0 / np.where(np.isfinite(sig), sig, 1.0) ** 2, 0.0)

    def pen(v):
        p = 0.5 * float(np.sum(prec[idx] * (v[idx] - mu[idx]) ** 2))
        if extra is not None:
            p += 0.5 * float(np.sum(extra(v) ** 2))
        return p

    def terms(v):
        c, g, F, sc = stage.gauss_newton(theta_of, v, idx, hs)
        g = g / T + prec[idx] * (v[idx] - mu[idx])
        F = F / T + np.diag(prec[idx])
        if extra is not None:
            r0 = extra(v)
            if r0.size:
                J = np.empty((r0.size, len(idx)))
                for k, j in enumerate(idx):
                    y = v.copy()
                    y[j] += hs[j]
                    J[:, k] = (extra(y) - r0) / hs[j]
                g = g + J.T @ r0
                F = F + J.T @ J
        return c / T + pen(v), g, F, sc / T

    stage.set_envelope(theta_of(x))
    lam = 1e-3
    for it in range(iters):
        if it and it % refit_every == 0:
            stage.set_envelope(theta_of(x))
        if not idx:
            break
        c, g, F, _ = terms(x)
        moved = False
        for _ in range(5):
            A = F + lam * np.diag(np.diag(F)) + 1e-12 * np.eye(len(idx))
            try:
                d = -np.linalg.solve(A, g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            shrink = min(1.0, float(np.min(caps[idx] / np.maximum(np.abs(d), 1e-300))))
            y = x.copy()
            y[idx] = np.clip(x[idx] + shrink * d, lo[idx], hi[idx])
            fy = stage.cost(theta_of(y)) / T + pen(y)
            if fy < c:
                moved = True
                break
            lam *= 10
        if not moved:
            break
        x = y
        lam = max(lam / 10, 1e-6)
        if c - fy < tol:
            break
    stage.set_envelope(theta_of(x))
    c, g, F, sc = terms(x)
    return x, c, F, sc


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
    fix = _checked_fix(fix)
    say_ = say or (lambda msg: None)
    if not 0 < downscale <= 1:
        raise InputError("--downscale", f"must be in (0, 1], got {downscale!r}")
    work_caps = captures
    if downscale < 1:
        images, work_caps = _shrunk_photos(images, captures, downscale)
    if n_patches is None:
        n_patches = min(_N_PATCHES * len(images), _MAX_PATCHES)
    photos = [_Photo(img, cap, transfer, i) for i, (img, cap) in enumerate(zip(images, work_caps))]
    search = _Search(photos, fix, offset_range, say_)
    c0 = photos[0].cap
    theta0 = _Theta(axes=c0.axes)
    notes: list[str] = []

    # the bias that the log's typical rate implies, when the log is long (hand motion
    # averages out over seconds; a gyro's bias does not)
    rest = None
    b_given = np.mean([np.asarray(cap.bias, float) for cap in captures], axis=0)
    if "bias" not in fix:
        m_log, se_log, secs_log = _rest_rate(captures)
        if secs_log >= _REST_MIN_SECONDS:
            if np.max(np.abs(m_log - c0.axes.T @ b_given)) > _REST_MAX_RATE:
                notes.append(f"the gyro log's typical rate over {secs_log:.0f} s, "
                             f"{_vec(m_log)} rad/s (log axes), is motion, not a bias: "
                             f"the bias is not taken from it")
            else:
                floor = max(_REST_FLOOR, _REST_TURN / secs_log)
                rest = (m_log, np.hypot(se_log, floor))
                off = _bias_from_log(c0.axes @ m_log - b_given, (c0.axes ** 2) @ rest[1] ** 2)[2]
                notes.append(f"the gyro log's typical rate over {secs_log:.0f} s: "
                             f"{_vec(m_log)} +- {_vec(rest[1])} rad/s (log axes), a prior "
                             f"on the bias (the given bias is off with probability {off:.2f})")
            say_(notes[-1])

    def rest_bias(M):
        """Prior mean and sd of the bias correction (rad/s, camera frame) for mapping
        ``M``: the given bias, either right or off by up to ~_PRIOR_BIAS (even odds),
        weighed against the log's typical rate (:func:`_bias_from_log`)."""
        if rest is None:
            return np.zeros(3), np.full(3, _PRIOR_BIAS)
        return _bias_from_log(M @ rest[0] - b_given, (M ** 2) @ rest[1] ** 2)[:2]

    # candidate mappings
    given_letters = axes_to_letters(c0.axes)
    if "axes" in fix:
        cand = [c0.axes]
    else:
        letters = list(mappings) if mappings else list(PROPER_AXIS_LETTERS)
        cand = [parse_axes(s) for s in letters]
        if given_letters is None:
            cand.append(c0.axes)

    # working scales and patches from the blur at the given parameters
    probe = [search.tau_lo, 0.5 * search.tau_lo, 0.0, 0.5 * search.tau_hi, search.tau_hi]
    extent, path = _extent_and_path(photos, theta0, sorted(set(probe)))
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
        centres += [(i, x, y) for x, y in _select_centres(ph, per, int(round(P_f / s_f)))]
    if not centres:
        raise InputError(None, "no textured, unsaturated patch found for calibration")
    stage = _Stage(photos, centres, s_f, P_f, rows=(-0.15, 0.0, 0.15),
                   n_samples=int(np.clip(np.ceil(1.3 * path * s_f / 0.5), 32, 400)))
    coarse = _Stage(photos, centres, s_c, P_c, rows=(0.0,), envelope=False,
                    n_samples=int(np.clip(np.ceil(1.3 * path * s_c / 0.7), 24, 200)))
    u = np.array([y / photos[i].H for i, _, y in stage.points])
    # pivot row of the (time shift, readout) parametrisation: the mean patch row, so the
    # two are nearly uncorrelated; with the offset fixed the time shift stays 0
    ubar = 0.0 if "offset" in fix else float(u.mean())
    uc = u - 0.5
    say_(f"calibrating on {len(centres)} patches of {P_f} px at scale {stage.scale:.2f} "
         f"(coarse: {P_c} px at {coarse.scale:.2f}; blur ~{extent:.0f} px), {len(cand)} axis "
         f"mapping(s)")
    reg = _Registration(photos, extent) if len(photos) > 1 else None
    if reg is not None and reg.pairs:
        for a_, b_, d, sig, q in reg.pairs:
            say_(f"  photos {a_ + 1} -> {b_ + 1}: image motion ({d[0]:+.1f}, {d[1]:+.1f}) px "
                 f"(phase correlation, prominence {q:.1f}), weight 1/{sig:.1f} px")

    def extra_for(M):
        if reg is None or not reg.pairs:
            return None
        return lambda v: reg.residuals(search.theta_of(v, M, ubar))

    # 1. coarse: every mapping x time shifts per patch, combined along a line (time offset +
    #    readout error x row); then the best few again over a grid of focal scales.
    if search.tau_hi > search.tau_lo:
        taus = np.arange(search.tau_lo, search.tau_hi + 1e-9, _COARSE_STEP)
    else:
        taus = np.array([search.tau_lo])
    if "readout" in fix or search.r0 == 0:
        kappas = np.array([0.0])
    else:
        kappas = search.r0 * np.linspace(-0.35, 0.35, 8)
    fgrid = [1.0] if "focal" in fix else [0.8, 0.87, 0.94, 1.0, 1.07, 1.15, 1.25]
    rankings = []
    for envelope in (False, True):
        coarse.envelope = envelope
        scored = []
        for M in cand:
            C = coarse.costs(theta0.copy(axes=M, bias=rest_bias(M)[0]), taus=taus)
            tot, tau0, kap = _line_fit(C, taus, uc, kappas)
            scored.append((tot, tau0, kap, 1.0, M))
        scored.sort(key=lambda r: r[0])
        rankings.append(scored)
        ranking = [(axes_to_letters(r[4]) or "given", float(r[0] - scored[0][0])) for r in scored]
        say_(f"coarse ranking ({'fitted' if envelope else 'flat'} envelope): "
             + ", ".join(f"{a} {c:+.0f}" for a, c in ranking[:6]))
    # The two coarse criteria fail on different scenes (a flat 1/f^2 spectrum is misled by
    # oriented texture, a fitted envelope soaks up part of a long blur): the shortlist
    # takes the best of each in turn.
    short = []
    for pair in zip(*rankings):
        for r in pair:
            if not any(np.allclose(r[4], q[4]) for q in short):
                short.append(r)
    # 2. candidates at full working scale: Levenberg-Marquardt on every free parameter from
    #    the coarse start; the best is refined further.
    free = search.free()
    idx = [_X_NAMES.index(k) for k in free]
    lo, hi = search.bounds(ubar)
    hs = np.array([0.0005, 0.001, 0.01, 0.004, 0.004, 0.004])          # finite differences
    caps = np.array([0.004, max(0.15 * search.r0, 0.004), 0.08, 0.03, 0.03, 0.03])
    prior_sig = np.array([np.inf, max(_PRIOR_READOUT * search.r0, 0.002), _PRIOR_FOCAL,
                          _PRIOR_BIAS, _PRIOR_BIAS, _PRIOR_BIAS])

    def prior_for(M):
        """(mean, sd, temperature) of the priors for mapping ``M``: the bias's combines
        the given bias with the log's typical rate, when the log is long enough."""
        mu, sig = np.zeros(6), prior_sig.copy()
        mu[3:6], sig[3:6] = rest_bias(M)
        return mu, sig, _TEMPERATURE

    def start_vec(tau0, kap, M, fo=1.0):
        x = np.zeros(6)
        x[3:6] = rest_bias(M)[0]
        x[1] = kap
        x[0] = 0.0 if "offset" in fix else tau0 + kap * (0.5 - ubar)
        x[2] = np.log(fo)
        return np.clip(x, lo, hi)

    def candidate(tau0, kap, M):
        # start: per-patch time shifts x focal grid with the envelopes held from the
        # coarse start, combined along the readout line; then Levenberg-Marquardt
        if "offset" in fix:
            tm = np.array([0.0])
        else:
            tm = np.arange(tau0 - 0.016, tau0 + 0.0161, _COARSE_STEP)
            tm = tm[(tm >= search.tau_lo - 1e-9) & (tm <= search.tau_hi + 1e-9)]
            if tm.size == 0:
                tm = np.array([float(np.clip(tau0, search.tau_lo, search.tau_hi))])
        stage.set_envelope(search.theta_of(start_vec(tau0, kap, M), M, ubar))
        starts = []
        for fo in fgrid:
            C = stage.costs(theta0.copy(axes=M, focal=fo, bias=rest_bias(M)[0]), taus=tm,
                            rows=(0.0,))
            for kap in kappas:
                tot, t0, kp = _line_fit(C, tm, uc, [kap])
                starts.append((tot, t0, kp, fo))
        # the best few starts that differ in time shift (at the pivot row) or readout: the
        # refinement from the best line fit alone can stop in the wrong basin
        starts.sort(key=lambda r: r[0])
        chosen = [starts[0]]
        for r in starts[1:]:
            if len(chosen) >= _CANDIDATE_STARTS:
                break
            if all(abs((r[1] - c[1]) + (r[2] - c[2]) * (0.5 - ubar)) > _DISTINCT_SHIFT
                   or abs(r[2] - c[2]) > _DISTINCT_READOUT for c in chosen):
                chosen.append(r)
        fx, alts = np.inf, []
        for best in chosen:
            x1 = start_vec(best[1], best[2], M, best[3])
            x1, f1, _, _ = _gn_refine(stage, lambda v: search.theta_of(v, M, ubar), x1, idx, lo,
                                      hi, hs, caps, prior_for(M), iters=4, extra=extra_for(M))
            alts.append(x1)
            if f1 < fx:
                x, fx = x1, f1
        say_(f"  candidate {axes_to_letters(M) or 'given'}: time shift {x[0] * 1e3:+.1f} ms, "
             f"readout {x[1] * 1e3:+.1f} ms, focal x{np.exp(x[2]):.3f}: objective {fx:.1f}")
        return fx, x, M, [a for a in alts if a is not x]

    top = _with_twin(short[:_CANDIDATES], rankings[0])
    results = [candidate(r[1], r[2], r[4]) for r in top]
    results.sort(key=lambda r: r[0])
    fx, x, M, alts = results[0]

    def refine(x0, iters, which=idx):
        """Levenberg-Marquardt for the winning mapping ``M``: (x, f, F, scores)."""
        return _gn_refine(stage, lambda v: search.theta_of(v, M, ubar), x0, which, lo, hi,
                          hs, caps, prior_for(M), iters=iters, extra=extra_for(M))

    x, fx, Fm, sc = refine(x, 10)
    # The winner's other starts, refined as far: four iterations do not always tell which
    # basin is lowest (a time shift 5 ms off can lead after four and trail after fourteen).
    # Then (see below) two more kinds of start; the lowest objective is kept throughout.
    for xa in alts:
        xa, fa, Fa, sca = refine(xa, 10)
        if fa < fx:
            x, fx, Fm, sc = xa, fa, Fa, sca
    # Focal length and a bias along the motion trade off (see Criterion), and the valley
    # between them holds several local minima: the coarse start's focal guess can leave
    # the refinement in one far from the given values. So the winner is refined once more
    # from the given focal length and bias (the prior's: with a long log, the log's; first
    # with the focal length held, so that the bias settles on its own), and the lower
    # objective is kept.
    b_prior = rest_bias(M)[0]
    if any(j >= 2 for j in idx) and np.any(x[2:] != np.r_[0.0, b_prior]):
        xs = x.copy()
        xs[2:] = np.r_[0.0, b_prior]
        xs = refine(np.clip(xs, lo, hi), 6, [j for j in idx if j != 2])[0]
        xa, fa, Fa, sca = refine(xs, 10)
        if fa < fx:
            x, fx, Fm, sc = xa, fa, Fa, sca
    # Last, time shifts around the winner's, every _SCAN_STEP up to _SCAN_REACH away, from the
    # given (prior) values of the other parameters: the coarse start's line fits can miss a
    # nearby basin that the fine cost prefers; the best _SCAN_REFINED are refined as far.
    if "offset" not in fix:
        scan, tried = [], {round(float(x[0]), 6)}
        for dt in np.arange(-_SCAN_REACH, _SCAN_REACH + 1e-9, _SCAN_STEP):
            xs0 = np.clip(np.r_[x[0] + dt, 0.0, 0.0, b_prior], lo, hi)
            if round(float(xs0[0]), 6) in tried:      # the winner's own, or clipped to a bound
                continue
            tried.add(round(float(xs0[0]), 6))
            scan.append(refine(xs0, 4)[:2])
        scan.sort(key=lambda r: r[1])
        for xs0, _ in scan[:_SCAN_REFINED]:
            xa, fa, Fa, sca = refine(xs0, 10)
            if fa < fx:
                x, fx, Fm, sc = xa, fa, Fa, sca
    gap = float(min(r[0] for r in results[1:]) - fx) if len(results) > 1 else np.nan
    if np.isfinite(gap) and gap < 0:        # a runner-up's refinement was cut short
        gap = 0.0

    # the given parameters (with a long log, its bias) stay unless the photo(s) clearly
    # prefer others
    kept = False
    if idx or len(cand) > 1:
        x0 = np.clip(np.r_[0.0, 0.0, 0.0, rest_bias(c0.axes)[0]], lo, hi)
        f_given = _objective(stage, lambda v: search.theta_of(v, c0.axes, ubar), x0,
                             idx, prior_for(c0.axes), extra_for(c0.axes))
        noise = _gyro_noise(captures)
        margin = _keep_margin(noise)
        if not np.allclose(M, c0.axes):
            margin *= _KEEP_MAPPING_NATS / _KEEP_MARGIN
        if np.isfinite(noise) and margin > _KEEP_MARGIN:
            notes.append(f"gyro noise {noise:.4f} rad/s per sample: the given parameters are "
                         f"kept unless the objective improves by {margin:.0f}")
            say_("  " + notes[-1])
        if f_given - fx < margin:
            from_log = " (the bias from the log)" if np.any(np.abs(x0[3:6]) > 1e-4) else ""
            msg = (f"kept the given parameters{from_log}: "
                   f"the best found ({axes_to_letters(M) or 'given'}) improves the objective "
                   f"by only {f_given - fx:.1f} (< {margin:g})")
            x, M, fx = x0, c0.axes, f_given
            _, _, Fm, sc = _gn_refine(stage, lambda v: search.theta_of(v, M, ubar), x, idx,
                                      lo, hi, hs, caps, prior_for(M), iters=0,
                                      extra=extra_for(M))
            kept = True
            notes.append(msg)
            say_("  " + msg)
            others = [r[0] for r in results if not np.allclose(r[2], M)]
            gap = float(min(others) - fx) if others else np.nan

    # 3. the mirror twin at the same parameters: |H| nearly equal; if the spectra cannot
    #    tell them apart, the phase (sparsity of the deconvolved patches) decides.
    if "axes" not in fix and len(cand) > 1 and not kept:
        Mt = _TWIN @ M
        xt = np.clip(_twin_parameters(x, [cap.bias for cap in captures], fix), lo, hi)
        th_w = search.theta_of(x, M, ubar)
        th_t = search.theta_of(xt, Mt, ubar)
        per_patch = (stage.cost(th_t) - stage.cost(th_w)) / len(stage.points)
        d = np.log(stage.sparsity(th_t) / stage.sparsity(th_w))
        margin, sem = _mean_and_error(d)
        msg = (f"mirror twin {axes_to_letters(Mt)} at the same parameters: spectra "
               f"{per_patch:+.1f} nats/patch, sparsity {margin:+.4f} +- {sem:.4f} (log ratio; "
               f"{int((d > 0).sum())}/{d.size} patches prefer {axes_to_letters(M)})")
        if reg is not None and reg.pairs:
            r_w = float(np.sum(reg.residuals(th_w) ** 2))
            r_t = float(np.sum(reg.residuals(th_t) ** 2))
            msg += f", registration chi2 {r_w:.1f} vs {r_t:.1f}"
            swap = r_t < r_w
        else:
            swap = _phase_prefers_twin(per_patch, d)
        if swap:
            x, fx, Fm, sc = _gn_refine(stage, lambda v: search.theta_of(v, Mt, ubar),
                                       xt, idx, lo, hi, hs, caps, prior_for(Mt),
                                       iters=6, extra=extra_for(Mt))
            msg += f": {axes_to_letters(Mt)} taken"
            M = Mt
        notes.append(msg)
        say_("  " + msg)

    if "axes" not in fix and np.isfinite(gap) and gap < _AXES_CONFIDENT_NATS:
        others = [r for r in results if not np.allclose(r[2], M)]
        runner = min(others, key=lambda r: r[0])[2] if others else None
        msg = (f"warning: the axis mapping is uncertain: the next best"
               f"{' (' + (axes_to_letters(runner) or 'given') + ')' if runner is not None else ''}"
               f" scores only {gap:.1f} worse (< {_AXES_CONFIDENT_NATS:g}); the blur says little"
               f" about its direction. Give the mapping (--orientation) if it is known, or"
               f" calibrate on several photos of the session")
        notes.append(msg)
        say_("  " + msg)

    theta = search.theta_of(x, M, ubar)
    unc = _uncertainties(x, idx, Fm, sc, ubar)
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
    notes.append(f"{coarse.evaluations} coarse and {stage.evaluations} fine cost evaluations, "
                 f"{secs:.1f} s")
    return CalibrationResult(out_caps, est, ranking, stage.scale, fix, secs, notes)


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
        xt[3:6] = _TWIN @ xt[3:6] + (_TWIN - np.eye(3)) @ b
    return xt


def _bias_from_log(d: np.ndarray, var_log: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The prior on the bias correction from the log: mean, sd (rad/s, camera frame) and
    the probability that the given bias is off.

    ``d``: the log's typical rate minus the given bias, ``var_log`` its variance, per
    axis. A given bias is taken to be either right or off by a Gaussian amount of sd
    :data:`_PRIOR_BIAS`, at even odds; ``d`` decides between the two (its likelihood
    ratio, all axes together), and the prior is the moment-matched mixture of "right" (no
    correction) and "off" (the given bias's Gaussian combined with the log's). A log that
    bears the given bias out leaves it where it is, with the log's precision: moving a
    right bias by the log's own error (the hand's mean rate) would only add that error.
    """
    var_off = var_log + _PRIOR_BIAS ** 2
    llr = 0.5 * float(np.sum(np.log(var_log / var_off) + d ** 2 / var_log - d ** 2 / var_off))
    p_off = float(1.0 / (1.0 + np.exp(-np.clip(llr, -50.0, 50.0))))
    p_log, p_given = 1.0 / var_log, 1.0 / _PRIOR_BIAS ** 2
    mu_off = p_log * d / (p_given + p_log)
    var = 1.0 / (p_given + p_log) + p_off * (1.0 - p_off) * mu_off ** 2
    return p_off * mu_off, np.sqrt(var), p_off


def _rest_rate(captures) -> tuple[np.ndarray, np.ndarray, float]:
    """Typical rate of the captures' gyro logs (rad/s, log axes), its standard error and
    the seconds it spans (:func:`gyrodeblur.gyrolog.median_rate`): the samples within
    :data:`_REST_SPAN` s of any photo's exposure, pooled over the photos (one session
    shares one gyro clock; a sample logged twice counts once)."""
    ts, ws = [], []
    for log, caps in _by_log(captures):
        near = np.zeros(len(log.t), bool)
        for c in caps:
            t0, t1 = (v - c.time_offset for v in c.window)
            near |= (log.t >= t0 - _REST_SPAN) & (log.t <= t1 + _REST_SPAN)
        ts.append(log.t[near])
        ws.append(log.omega[near])
    t, first = np.unique(np.concatenate(ts), return_index=True)
    if t.size < 2:
        nan = np.full(3, np.nan)
        return nan, nan.copy(), 0.0
    return median_rate(GyroLog(t, np.concatenate(ws)[first]))


def _by_log(captures):
    """``(log, [captures using it])`` for each distinct gyro log."""
    groups: dict[int, tuple] = {}
    for c in captures:
        groups.setdefault(id(c.log), (c.log, []))[1].append(c)
    return list(groups.values())


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:+.4f}" for x in np.asarray(v, float)) + ")"


def _gyro_noise(captures) -> float:
    """The largest white-noise level (rad/s per sample) of the captures' gyro logs."""
    levels = [rate_noise(log) for log, _ in _by_log(captures)]
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


# ----------------------------------------------------------------------------- CLI glue

def format_estimates(est: dict) -> list[str]:
    """Human-readable lines: each parameter before -> after (+- uncertainty, or fixed)."""
    lines = []
    b, a, u = est["offset"]
    lines.append(f"  time offset  {b * 1e3:+8.2f} ms -> {a * 1e3:+8.2f} ms  ({_pm(u, 1e3, 'ms')})")
    b, a, u = est["readout"]
    lines.append(f"  readout      {b * 1e3:8.2f} ms -> {a * 1e3:8.2f} ms  ({_pm(u, 1e3, 'ms')})")
    b, a, u = est["focal"]
    lines.append(f"  focal scale  {b:8.4f}    -> {a:8.4f}     ({_pm(u, 1, '')})")
    b, a, u = est["bias"]
    vec = lambda v: "[" + ", ".join(f"{x:+.4f}" for x in v) + "]"
    unc = "fixed" if u is None else "+- [" + ", ".join(_fmt(v, 1) for v in u) + "]"
    lines.append(f"  gyro bias    {vec(b)} -> {vec(a)} rad/s  ({unc})")
    b, a, gap = est["axes"]
    if gap is None:
        conf = "fixed"
    elif not np.isfinite(gap):
        conf = "only candidate"
    else:
        conf = f"next best mapping: objective {gap:+.1f} higher"
        if gap < _AXES_CONFIDENT_NATS:
            conf += ": uncertain"
    lines.append(f"  axes         {b} -> {a}  ({conf})")
    return lines


def _pm(u, mult, unit) -> str:
    if u is None:
        return "fixed"
    return f"+- {_fmt(u, mult)}{(' ' + unit) if unit else ''}"


def _fmt(u, mult) -> str:
    if u is None or not np.isfinite(u):
        return "?"
    return f"{u * mult:.2g}"


#: Capture options whose value, given on the command line, fixes a parameter.
_FIXING_OPTIONS = (("time_offset", "offset"), ("bias", "bias"), ("readout_time", "readout"),
                   ("fx", "focal"), ("fy", "focal"), ("orientation", "axes"))


def _checked_fix(names) -> set[str]:
    """``names`` (empty ones dropped) as a set, each one of :data:`PARAMETERS`."""
    fix = {n for n in names if n}
    unknown = fix - set(PARAMETERS)
    if unknown:
        raise InputError("--fix", f"unknown parameter(s) {', '.join(sorted(unknown))}; "
                                  f"known: {', '.join(PARAMETERS)}")
    return fix


def fixed_parameters(args) -> set[str]:
    """Parameters the user fixes on the command line: those named by ``--fix``, and those
    whose value is given explicitly (``--time-offset``, ``--bias``, ``--readout-time``,
    ``--fx``/``--fy``, ``--orientation``): a value stated on the command line is taken as
    known, not as a starting guess."""
    fix = _checked_fix(f.strip() for f in (getattr(args, "fix", None) or "").split(","))
    for option, name in _FIXING_OPTIONS:
        if getattr(args, option, None) is not None:
            fix.add(name)
    return fix


def calibrate_command(args, say, load_capture) -> None:
    """`gyrodeblur calibrate PHOTO... --capture C.json[,C2.json...] -o OUT.json`.

    Several photos of one session are calibrated together; each needs its own exposure
    start, so ``--capture`` may list one description per photo (comma-separated, or the
    option repeated). The
    corrected description written is the first photo's (the corrections are shared)."""
    from .imageio import check_destination, read_photo

    fix = fixed_parameters(args)
    photos = [read_photo(p) for p in args.photos]
    check_destination(args.output, None, args.overwrite, image=False)
    given = args.capture if isinstance(args.capture, list) else [args.capture or ""]
    paths = [c for entry in given for c in entry.split(",") if c] or given[:1]
    if len(paths) not in (1, len(photos)):
        raise InputError("--capture", f"{len(paths)} capture descriptions for {len(photos)} "
                                      "photos: give one, or one per photo (comma-separated)")
    if len(paths) == 1 and len(photos) > 1:
        say(f"note: all {len(photos)} photos take their exposure start from {paths[0]}; give "
            "one capture per photo (--capture a.json,b.json,... or --capture repeated) if "
            "they were taken at different times")
    caps = []
    for k, ph in enumerate(photos):
        a = argparse.Namespace(**vars(args))
        a.capture = paths[k] if len(paths) > 1 else paths[0]
        caps.append(load_capture(a, ph, say))
    res = calibrate([p.pixels for p in photos], caps, fix=fix, say=say,
                    downscale=args.downscale)
    say(f"calibration of {len(photos)} photo(s) in {res.seconds:.1f} s (before -> after, "
        f"one-sigma uncertainty):")
    for line in format_estimates(res.estimates):
        say(line)
    src = caps[0].source
    gyro_rel = caps[0].gyro_spec.get("path")
    if gyro_rel is not None and os.path.isabs(gyro_rel):
        pass                                     # an absolute path stays as it is
    elif src and src != "capture" and gyro_rel is not None:
        gyro_abs = os.path.join(os.path.dirname(os.path.abspath(src)), gyro_rel)
        gyro_rel = os.path.relpath(gyro_abs, os.path.dirname(os.path.abspath(args.output)))
    elif gyro_rel is not None and not os.path.isabs(gyro_rel):
        gyro_rel = os.path.relpath(os.path.abspath(gyro_rel),
                                   os.path.dirname(os.path.abspath(args.output)))
    tmp = args.output + ".part"
    try:
        res.capture.save(tmp, gyro_path=gyro_rel)
        os.replace(tmp, args.output)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    say(f"wrote {args.output}")
