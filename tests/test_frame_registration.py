"""Image motion between photos (:mod:`gyrodeblur.frame_registration`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from gyrodeblur.frame_registration import phase_shift


@pytest.mark.parametrize("d", [(3.4, -2.2), (-7.0, 0.6), (0.0, 0.0)])
def test_phase_shift_finds_a_known_translation(d):
    """``b(x) = a(x - d)``: the shift comes back as ``(dx, dy)`` to a fraction of a pixel,
    with a clear peak."""
    rng = np.random.default_rng(1)
    a = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    b = ndimage.shift(a, (d[1], d[0]), order=3, mode="reflect")
    found, prominence = phase_shift(a, b)
    assert np.allclose(found, d, atol=0.3), found
    assert prominence > 3.0


def test_phase_shift_of_differently_blurred_photos_reads_the_centroid_difference():
    """Photo a blurred by a 21 px streak to the right (centroid +10 px), photo b by a 31 px
    streak to the left (centroid -15 px) and moved by (7, -3): low-passed inside the
    streaks' main spectral lobe, the shift is the content's plus the centroids'
    difference, (7 - 15 - 10, -3)."""
    rng = np.random.default_rng(4)
    u = ndimage.gaussian_filter(rng.normal(size=(256, 320)), 1.0)

    def streak(img, start, stop):
        k = np.zeros(img.shape)
        k[0, np.arange(start, stop + 1) % img.shape[1]] = 1.0
        return np.real(np.fft.ifft2(np.fft.fft2(img) * np.fft.fft2(k / k.sum())))

    a = streak(u, 0, 20)
    b = np.roll(streak(u, -30, 0), (-3, 7), axis=(0, 1))
    found, prominence = phase_shift(a, b, lowpass=0.25 / 31)
    assert np.allclose(found, (-18.0, -3.0), atol=0.6), found    # at 0.1: -13.0
    assert prominence > 3.0


def test_phase_shift_of_unrelated_images_has_no_clear_peak():
    rng = np.random.default_rng(2)
    a = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    b = ndimage.gaussian_filter(rng.normal(size=(200, 260)), 2.0)
    assert phase_shift(a, b)[1] < 3.0


def _pair(d=(0.0, 0.0), w=(0.0, 0.2, 0.0), size=(700, 1000), f=500.0):
    """Two photos 0.2 s apart on a log of steady rate ``w`` (rad/s, camera frame), the
    second the first shifted by ``d`` (x, y) px."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import GyroLog

    rng = np.random.default_rng(4)
    a = 0.5 + 0.1 * ndimage.gaussian_filter(rng.normal(size=size), 3.0)
    b = ndimage.shift(a, (d[1], d[0]), order=3, mode="reflect")
    t = np.arange(0.0, 2.0, 0.005)
    log = GyroLog(t, np.tile(w, (t.size, 1)))
    cam = Camera.centred(size[1], size[0], f)
    caps = [Capture(s, 0.01, 0.0, cam, log) for s in (0.8, 1.0)]
    return [CalibrationPhoto(np.clip(img, 0, 1), c, "linear", i)
            for i, (img, c) in enumerate(zip((a, b), caps))]


def test_the_measured_motion_is_in_full_resolution_pixels():
    """Measured on thumbnails (here halved), reported in the photos' pixels."""
    from gyrodeblur.frame_registration import FrameRegistration

    reg = FrameRegistration(_pair(d=(-14.0, 6.0)), extent=10.0)
    assert len(reg.pairs) == 1
    a, b, d, sigma, q = reg.pairs[0]
    assert (a, b) == (0, 1) and np.allclose(d, (-14.0, 6.0), atol=1.0), d


def test_the_predicted_motion_follows_the_gyro():
    """A steady yaw to the right (w_y > 0) moves content towards -x. The prediction is the
    mean over a 3 x 3 grid of points (a quarter of the frame in from each side) of where
    the turn by 0.2 rad/s x 0.2 s takes each one, worked out here with a rotation matrix
    (a point's new camera coordinates are R^T times its old ones); the residual of that
    motion, measured, is ~0."""
    from gyrodeblur.frame_registration import FrameRegistration
    from gyrodeblur.spectral_criterion import Corrections

    f, th = 500.0, 0.04
    x = (np.array([0.25, 0.5, 0.75]) * 999 - 499.5) / f
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    p = R.T @ np.stack([x, np.zeros(3), np.ones(3)])
    expected = float(np.mean(f * (p[0] / p[2] - x)))           # about -23 px
    photos = _pair(d=(expected, 0.0))
    reg = FrameRegistration(photos, extent=10.0)
    theta = Corrections(axes=np.eye(3))
    pred = reg.predict(theta, 0, 1)
    assert pred[0] == pytest.approx(expected, abs=0.2) and abs(pred[1]) < 0.2, (pred, expected)
    assert len(reg.pairs) == 1                                  # the residual is measured
    assert np.all(np.abs(reg.residuals(theta)) < 0.5)


def test_the_predicted_motion_is_timed_by_the_rows_the_light_lands_on():
    """Under a rolling shutter a point's light is recorded during the exposure of the row
    it lands on, which a fast tilt moves away from the row it starts on; the PSFs are
    timed so (:func:`gyrodeblur.psf.landing_pixel`) and the predicted motion between two
    photos must be too. Steady pitch at 1 rad/s (content moves down at ~800 px/s), a 50 ms
    readout over 400 rows, a long exposure then a short one: the mean of the landing
    pixels' motion, worked out with ``landing_pixel`` and a rotation matrix for the 50 ms
    between the photos. Timing the first photo by the points' own rows is 1.3 px off."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.frame_registration import FrameRegistration
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.psf import landing_pixel
    from gyrodeblur.spectral_criterion import Corrections

    f, wx, size = 800.0, 1.0, (400, 600)
    t = np.arange(0.0, 2.0, 0.002)
    cam = Camera.centred(size[1], size[0], f)
    log = GyroLog(t, np.tile((wx, 0.0, 0.0), (t.size, 1)))
    cap_a = Capture(0.80, 0.050, 0.050, cam, log)
    cap_b = Capture(0.85, 0.010, 0.050, cam, log)
    img = np.full(size, 0.5)
    photos = [CalibrationPhoto(img, c, "linear", i) for i, c in enumerate((cap_a, cap_b))]
    reg = FrameRegistration(photos, extent=10.0)
    pred = reg.predict(Corrections(axes=np.eye(3)), 0, 1)

    gx, gy = np.meshgrid([0.25, 0.5, 0.75], [0.25, 0.5, 0.75])
    px, py = gx.ravel() * (size[1] - 1), gy.ravel() * (size[0] - 1)
    th = wx * (cap_b.exposure_start - cap_a.exposure_start)
    R = np.array([[1, 0, 0], [0, np.cos(th), -np.sin(th)], [0, np.sin(th), np.cos(th)]])
    ray = np.stack([(px - cam.cx) / f, (py - cam.cy) / f, np.ones(px.size)])
    q = R.T @ ray                                     # the points' rays at b's start
    bx, by = cam.cx + f * q[0] / q[2], cam.cy + f * q[1] / q[2]
    expected = (landing_pixel(cap_b, bx, by) - landing_pixel(cap_a, px, py)).mean(0)
    own_row_a = np.mean([landing_pixel(cap_a, x, y, row=y) - landing_pixel(cap_a, x, y)
                         for x, y in zip(px, py)], axis=0)
    assert abs(own_row_a[1]) > 1.0                     # the test can tell the two apart
    assert np.allclose(pred, expected, atol=0.25), (pred, expected)


def test_the_predicted_motion_moves_with_the_time_offset_as_the_capture_does():
    """A time-offset correction means what the corrected capture's offset means (the log
    read that much earlier): on a log whose rate changes (a steady rate would hide it), the
    motion predicted under ``Corrections(offset=d, readout=r)`` is that predicted for the
    captures corrected by ``d`` and ``r`` (:meth:`Corrections.apply`), and differs from the
    prediction at no correction."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.frame_registration import FrameRegistration
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.spectral_criterion import Corrections

    t = np.arange(0.0, 2.0, 0.002)
    w = np.stack([0.6 * np.sin(2 * np.pi * 1.3 * t), 0.8 * np.cos(2 * np.pi * 1.1 * t),
                  0.2 * np.sin(2 * np.pi * 0.7 * t)], 1)
    cam = Camera.centred(600, 400, 500.0)
    caps = [Capture(s, 0.02, 0.03, cam, GyroLog(t, w)) for s in (0.8, 1.1)]
    img = np.full((400, 600), 0.5)

    def predicted(captures, theta):
        photos = [CalibrationPhoto(img, c, "linear", i) for i, c in enumerate(captures)]
        return FrameRegistration(photos, extent=10.0).predict(theta, 0, 1)

    eye = Corrections(axes=np.eye(3))
    shifted = eye.copy(offset=0.03, readout=0.01)
    moved = predicted(caps, shifted)
    np.testing.assert_allclose(moved, predicted([shifted.apply(c) for c in caps], eye),
                               atol=0.05)
    assert np.abs(moved - predicted(caps, eye)).max() > 2.0


# ------------------------------------------------ from a mutation audit (session 44)

def test_pairs_are_consecutive_in_time_close_enough_and_clearly_related():
    """Kills ``FrameRegistration`` pairing photos in the order given, ignoring ``max_dt``,
    and keeping a pair without a clear correlation peak: photos are paired in the order
    of their exposure starts, at most ``max_dt`` apart, and only where the peak stands
    out (prominence 3)."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.frame_registration import FrameRegistration

    photos = _pair(d=(-14.0, 6.0))
    reg = FrameRegistration(photos[::-1], extent=10.0)          # given latest first
    assert [p[:2] for p in reg.pairs] == [(1, 0)]
    assert np.allclose(reg.pairs[0][2], (-14.0, 6.0), atol=1.0)
    assert FrameRegistration(photos, extent=10.0, max_dt=0.1).pairs == []   # 0.2 s apart
    rng = np.random.default_rng(9)
    other = 0.5 + 0.1 * ndimage.gaussian_filter(rng.normal(size=(700, 1000)), 3.0)
    unrelated = CalibrationPhoto(np.clip(other, 0, 1), photos[1].cap, "linear", 1)
    assert FrameRegistration([photos[0], unrelated], extent=10.0).pairs == []


def test_the_predicted_motion_under_bias_and_focal_corrections_is_the_corrected_capture_s():
    """Kills the prediction dropping the capture's own gyro bias, negating the correction's
    and ignoring its focal scale: as for the time offset, the motion predicted under
    ``Corrections(bias=b, focal=s)`` is that predicted for the captures corrected by them
    (:meth:`Corrections.apply`: biases add), and differs from no correction."""
    from gyrodeblur.calibration_patches import CalibrationPhoto
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.frame_registration import FrameRegistration
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.spectral_criterion import Corrections

    t = np.arange(0.0, 2.0, 0.002)
    w = np.stack([0.3 * np.sin(2 * np.pi * 1.3 * t), 0.4 + 0 * t, 0.1 * np.cos(t)], 1)
    cam = Camera.centred(600, 400, 500.0)
    caps = [Capture(s, 0.02, 0.0, cam, GyroLog(t, w), bias=np.array([0.05, -0.08, 0.02]))
            for s in (0.8, 1.1)]
    img = np.full((400, 600), 0.5)

    def predicted(captures, theta):
        photos = [CalibrationPhoto(img, c, "linear", i) for i, c in enumerate(captures)]
        return FrameRegistration(photos, extent=10.0).predict(theta, 0, 1)

    eye = Corrections(axes=np.eye(3))
    for corrected in (eye.copy(bias=np.array([0.1, 0.2, -0.05])), eye.copy(focal=1.2)):
        moved = predicted(caps, corrected)
        np.testing.assert_allclose(moved, predicted([corrected.apply(c) for c in caps], eye),
                                   atol=0.05)
        assert np.abs(moved - predicted(caps, eye)).max() > 2.0
    unbiased = [c.replace(bias=np.zeros(3), log=GyroLog(t, w - c.bias)) for c in caps]
    np.testing.assert_allclose(predicted(caps, eye), predicted(unbiased, eye), atol=0.05)
