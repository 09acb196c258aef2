"""PSFs against analytic camera motions."""

import numpy as np
import pytest
from scipy import ndimage
from scipy.signal import convolve2d, fftconvolve

from gyrodeblur.psf import (displacement_field, landing_pixel, lanczos_splat, psf_field, render_psf,
                            splat)
from gyrodeblur.simulate import simulate_blur


def _support(psf, rel=0.05):
    """Offsets of the PSF's mass: samples over ``rel`` of its peak (the windowed sinc's
    lobes beyond a streak's ends stay under 2 % of it)."""
    r = psf.shape[0] // 2
    ys, xs = np.nonzero(psf > rel * psf.max())
    return xs.min() - r, xs.max() - r, ys.min() - r, ys.max() - r


def _centroid(psf):
    r = psf.shape[0] // 2
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (psf * xx).sum(), (psf * yy).sum()


def test_zero_motion_gives_delta(make_capture):
    cap = make_capture([0, 0, 0])
    p = render_psf(cap, 100, 80)
    assert p.shape[0] == p.shape[1] and p.shape[0] % 2 == 1
    assert np.isclose(p.sum(), 1)
    assert p[p.shape[0] // 2, p.shape[1] // 2] > 0.999


def test_yaw_streak_length_and_direction(make_capture):
    f, T, rate = 300.0, 0.03, 1.0
    cap = make_capture([0, rate, 0], f=f, exposure=T)
    cx, cy = cap.camera.cx, cap.camera.cy
    p = render_psf(cap, cx, cy)
    x0, x1, y0, y1 = _support(p)
    length = f * np.tan(rate * T)
    # positive w_y (camera yaws right) moves content towards -x
    assert x1 == 0 and y0 == 0 and y1 == 0
    assert abs((x1 - x0) - length) <= 0.5 + 1e-9 or abs(-x0 - np.ceil(length)) == 0
    # mass centre halfway along the streak
    mx, _ = _centroid(p)
    assert abs(mx + length / 2) < 0.1
    assert np.isclose(p.sum(), 1)


def test_yaw_streak_first_moment_is_exact(make_capture):
    """The content at the principal point moves by ``-f tan(w t)``: its mean over the
    exposure, ``f ln(cos(w T)) / (w T)``, is the PSF's first moment (a uniform streak's
    ``-L/2`` only to first order: at 2 rad/s the two differ by 0.02 px). The gather kernel
    is the motion seen from the pixel the light lands on, 20 px off the axis, which
    moves the moment by another 0.01 px."""
    for rate in (0.5, 2.0):
        cap = make_capture([0, rate, 0], f=500.0, exposure=0.04)
        p = render_psf(cap, cap.camera.cx, cap.camera.cy)
        x0, _, _, _ = _support(p)
        L = 500 * np.tan(rate * 0.04)
        assert abs(-x0 - L) < 1.0        # the splat adds < 1 px at the far end
        mx, my = _centroid(p)
        assert abs(mx - 500 * np.log(np.cos(rate * 0.04)) / (rate * 0.04)) < 0.015
        assert abs(my) < 1e-3


def test_pitch_moves_content_vertically(make_capture):
    # positive w_x (right-hand rule about x, y down, z forward) turns the optical axis
    # towards -y: the camera tilts up, so content moves down (+y)
    cap = make_capture([0.8, 0, 0])
    mx, my = _centroid(render_psf(cap, cap.camera.cx, cap.camera.cy))
    assert my > 2 and abs(mx) < 1e-3


def test_roll_arcs_grow_with_radius(make_capture):
    cap = make_capture([0, 0, 2.0], width=400, height=300, f=300.0)
    cx, cy = cap.camera.cx, cap.camera.cy
    centre = render_psf(cap, cx, cy)
    assert centre[centre.shape[0] // 2, centre.shape[1] // 2] > 0.99
    lengths = []
    for r in (40, 80, 160):
        p = render_psf(cap, cx + r, cy)
        x0, x1, y0, y1 = _support(p)
        lengths.append(np.hypot(x1 - x0, y1 - y0))
        # at (cx + r, cy) a roll moves content along y (tangentially)
        assert (y1 - y0) > (x1 - x0) or r < 80
    ang = 2.0 * 0.03
    for r, L in zip((40, 80, 160), lengths):
        assert abs(L - r * ang) < 1.5
    assert lengths[0] < lengths[1] < lengths[2]
    # which way: the camera turns its x axis towards its y axis (right-hand rule about z
    # forward), so the scene turns the other way, and content right of centre moves up
    # by half the arc on average (160 px x 0.06 rad / 2 = 4.8 px)
    mx, my = _centroid(render_psf(cap, cx + 160, cy))
    assert abs(my + 160 * ang / 2) < 0.2 and abs(mx) < 0.2


def test_rolling_shutter_changes_with_row(make_capture):
    glob = make_capture([0.0, 0.8, 0.0], readout=0.0)
    roll = make_capture([0.0, 0.8, 0.0], readout=0.03)
    x = glob.camera.cx
    pg = [render_psf(glob, x, y) for y in (10, 120, 230)]
    pr = [render_psf(roll, x, y) for y in (10, 120, 230)]
    # global shutter: same PSF on every row (away from roll, constant rate = same shape)
    for p in pg[1:]:
        assert p.shape == pg[0].shape and np.abs(p - pg[0]).max() < 0.02
    # rolling shutter: later rows start later, so the trace starts further along the motion
    c = [_centroid(p) for p in pr]
    w_y, f, dt = 0.8, 300.0, 0.03 * 220 / 240
    assert c[0][0] > c[1][0] > c[2][0]
    assert abs((c[0][0] - c[2][0]) - f * np.tan(w_y * dt)) < 0.5
    # row 10 starts 10/240 of the readout later than row 0
    shift = _centroid(pg[0])[0] - _centroid(pr[0])[0]
    assert abs(shift - f * np.tan(w_y * 0.03 * 10 / 240)) < 0.05


def test_row_y_starts_y_over_h_of_the_readout_later():
    """The timing to within a fraction of a row, on a fast yaw (1000 px, 2 rad/s, 50 ms
    readout: a row's delay moves a trace by 0.4 px): row 0 is exposed with the global
    shutter's timing, and the middle row's trace is the stretch of ``-f tan(w t)`` from
    ``120/240`` of the readout on. Timing rows by ``(y + 0.5) / H`` or ``y / (H - 1)``
    would be 0.21 px off on either row."""
    from conftest import constant_rate_capture

    f, w, T, readout, H = 1000.0, 2.0, 0.03, 0.05, 240

    def mean_x(d):                     # mean of f tan(w t) over [d, d + T]
        return f * np.log(np.cos(w * d) / np.cos(w * (d + T))) / (w * T)

    glob = constant_rate_capture([0, w, 0], f=f, exposure=T, readout=0.0)
    roll = constant_rate_capture([0, w, 0], f=f, exposure=T, readout=readout)
    x = glob.camera.cx
    for y in (0, 120):
        shift = _centroid(render_psf(glob, x, y))[0] - _centroid(render_psf(roll, x, y))[0]
        assert abs(shift - (mean_x(y / H * readout) - mean_x(0.0))) < 0.05, (y, shift)


def test_field_and_splat_properties(make_capture):
    cap = make_capture([0.2, -0.5, 1.0], readout=0.02)
    pts = [(10, 10), (300, 20), (160, 120), (20, 230)]
    field = psf_field(cap, pts)
    assert len(field.psfs) == 4
    for p, (x, y) in zip(field.psfs, pts):
        assert p.dtype == np.float32 and p.shape[0] % 2 == 1 and np.isclose(p.sum(), 1, atol=1e-5)
        np.testing.assert_array_equal(p, render_psf(cap, x, y))     # each at its (x, y)
    s = splat(np.array([[0.25, -0.5]]))
    r = s.shape[0] // 2
    assert np.isclose(s[r, r], 0.75 * 0.5) and np.isclose(s[r - 1, r + 1], 0.25 * 0.5)


@pytest.mark.parametrize("freq", [(0.1, 0.15), (0.0, 0.3), (0.25, 0.2)])
def test_a_psf_moves_a_band_limited_image_without_damping_it(freq):
    """A 6 px horizontal streak half a pixel below the grid, convolved with a band-limited
    pattern ``cos(2 pi f . x)``, must give the pattern's time average along the streak,
    ``mean_t cos(2 pi f . (x - o_t))`` (worked out here by quadrature, no PSF involved),
    at every frequency up to 0.3 cycles/px: within 3 % of the amplitude with the
    windowed sinc (Lanczos-3 damps 14 % at 0.35 and 35 % at 0.4 cycles/px). The bilinear
    splat damps the vertical half-pixel shift by ``cos(pi f_y)``: 41 % of the amplitude
    lost at 0.3 cycles/px."""
    fx, fy = freq
    t = (np.arange(4000) + 0.5) / 4000
    offsets = np.stack([6.0 * t, np.full_like(t, 0.5)], axis=1)
    y, x = np.mgrid[0:64, 0:64].astype(np.float64)
    u = np.cos(2 * np.pi * (fx * x + fy * y))
    phase = np.mean(np.exp(-2j * np.pi * (fx * offsets[:, 0] + fy * offsets[:, 1])))
    expected = np.real(np.exp(2j * np.pi * (fx * x + fy * y)) * phase)
    for render, tol in ((lanczos_splat, 0.03), (splat, None)):
        h = render(offsets[::40]).astype(np.float64)           # 100 points, 0.06 px apart
        r = h.shape[0] // 2
        got = convolve2d(u, h, mode="same")[r:-r, r:-r]
        err = np.abs(got - expected[r:-r, r:-r]).max()
        if tol is not None:
            assert err < tol, (render.__name__, err)
        elif fy >= 0.3:                                        # the test can tell them apart
            assert err > 0.3, err


def test_psf_is_timed_by_the_row_its_light_lands_on(make_capture):
    # The camera tilts up fast (content moves down, +y, at ~600 px/s) while the rows are
    # read top to bottom: the light of a point seen at row y0 at the reference time is
    # recorded 14-26 rows lower, when those rows are exposed. Against the warping forward
    # model (simulate_blur: each row at its own time, no PSF involved), the PSF rendered
    # at a point must describe the blur where its light lands; timed by the point's own
    # row instead, it is off by the displacement times the readout rate (~1-2 px here).
    cap = make_capture([2.0, 0.0, 0.0], readout=0.03, exposure=0.03)
    rng = np.random.default_rng(0)
    u = ndimage.gaussian_filter(rng.normal(size=(240, 320)), 2.0)
    u = (0.5 + 0.3 * u / u.std()).astype(np.float32)
    g = simulate_blur(u, cap, transfer="linear")
    for x0, y0 in [(160, 40), (160, 120), (100, 180)]:
        p = np.round(landing_pixel(cap, x0, y0)).astype(int)
        assert p[1] - y0 > 10                          # the light lands well below y0
        win = (slice(p[1] - 8, p[1] + 9), slice(p[0] - 8, p[0] + 9))
        err = {}
        for row in (None, y0):                         # None: the landing row's timing
            model = fftconvolve(u, render_psf(cap, x0, y0, row=row), mode="same")
            err[row] = np.sqrt(((model[win] - g[win]) ** 2).mean()) / g[win].std()
        assert err[None] < 0.2 and err[None] < 0.4 * err[y0], (x0, y0, err)


def test_displacement_field_is_where_the_light_lands(make_capture):
    # Warping the photo blurred by the forward model (simulate_blur, no PSF) by the field
    # must leave each pixel's blur centred on it: the warped photo then matches the sharp
    # one convolved with the centred PSF. With the old own-row timing the residual was
    # 0.14-0.47 of the signal; the field is also each PSF's mean.
    from gyrodeblur.warp import warp_by_displacement
    cap = make_capture([2.0, 0.3, 0.5], readout=0.03, exposure=0.03)
    rng = np.random.default_rng(1)
    u = ndimage.gaussian_filter(rng.normal(size=(240, 320)), 2.0)
    u = (0.5 + 0.3 * u / u.std()).astype(np.float32)
    field = displacement_field(cap)
    warped = warp_by_displacement(simulate_blur(u, cap, transfer="linear"), field)
    for x, y in [(100, 60), (200, 120), (160, 170)]:
        psf = render_psf(cap, x, y, centred=True)
        model = fftconvolve(u, psf, mode="same")
        win = (slice(y - 8, y + 9), slice(x - 8, x + 9))
        err = np.sqrt(((model[win] - warped[win]) ** 2).mean()) / warped[win].std()
        assert err < 0.08, (x, y, err)
    ys, xs, d = field
    for i, j in [(0, 0), (2, 3), (len(ys) - 1, len(xs) - 1)]:
        psf = render_psf(cap, xs[j], ys[i], max_step=0.05)
        r = psf.shape[0] // 2
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        assert np.allclose([(psf * xx).sum(), (psf * yy).sum()], d[i, j], atol=0.05)
    assert (d[..., 1] > 0).all()                     # a pitch up moves content down


def test_a_fold_falls_back_to_the_points_own_row_and_a_fast_counter_tilt_does_not(
        make_capture):
    # A telephoto tilting fast with a short exposure. Content moving down, along the
    # shutter's sweep, faster than it (skew 1.2): the forward model records the point on
    # a hundred rows (the map folds), there is no one landing, and the PSF is timed by the
    # point's own row (a clear PSF, not an error or a wild landing pixel). Moving up,
    # against the sweep, as fast: the fixed point diverges (it gave up, the PSF 26 px
    # off), but the landing is unique, and it is where the forward model puts the light.
    down = make_capture([4.0, 0.0, 0.0], f=2400.0, exposure=0.002, readout=0.03)
    assert np.allclose(landing_pixel(down, 160.0, 40.0), (160.0, 40.0))
    psf = render_psf(down, 160.0, 40.0)
    _, my = _centroid(psf)                           # own row: mid-exposure 6 ms after
    assert np.isclose(psf.sum(), 1.0)               # the first row's start
    assert abs(my - 2400 * np.tan(4.0 * (0.03 * 40 / 240 + 0.001))) < 1.0
    up = make_capture([-4.0, 0.0, 0.0], f=2400.0, exposure=0.002, readout=0.03)
    dot = np.zeros((240, 320), np.float32)
    dot[40, 160] = 1.0
    g = simulate_blur(dot, up, order=1, transfer="linear")
    g[40:] = 0                       # the copy the mirrored border sends up from below
    yy, xx = np.mgrid[:240, :320]
    light = np.array([(g * xx).sum(), (g * yy).sum()]) / g.sum()
    assert light[1] < 20
    assert np.allclose(landing_pixel(up, 160.0, 40.0), light, atol=0.2)
    ok = make_capture([-0.5, 0.0, 0.0], f=300.0, exposure=0.03, readout=0.03)
    assert landing_pixel(ok, 160.0, 120.0)[1] < 120.0 - 3      # converged, moved up


def test_a_point_whose_light_leaves_the_frame_keeps_its_own_row(make_capture):
    # Content moving down at half the shutter's sweep: the light of the lower rows' points
    # lands below the frame (the solution lies hundreds of pixels down). Their PSFs are
    # timed by their own rows, and every row's PSF renders (a root outside the frame gave
    # "the blur would span 664 px").
    cap = make_capture([3.0, 0.0, 0.0], f=1080.0, exposure=0.003, readout=0.04)
    assert np.allclose(landing_pixel(cap, 160.0, 230.0), (160.0, 230.0))
    for y in range(0, 240, 20):
        psf = render_psf(cap, 160.0, float(y))
        assert np.isclose(psf.sum(), 1.0)
    ys, xs, d = displacement_field(cap, step=30)
    assert np.all(np.isfinite(d)) and np.abs(d).max() < 240


def test_a_fast_tilt_lands_each_point_where_the_forward_model_puts_its_light(make_capture):
    # Skew 0.54 (content crosses 0.54 rows per row the shutter sweeps): the fixed point
    # shrinks its error by only that much a step. After eight steps the points were
    # 0.3-0.8 px short when content moves down, and with content moving up the lower
    # rows' points had not settled and fell back to their own rows: PSFs and alignment
    # field tens of pixels off (a deblur of the lower half came out worse than its input).
    # Each point's light, blurred by the warping forward model (no PSF), must be where
    # landing_pixel says, and the PSF's mean offset must say the same.
    yy, xx = np.mgrid[:240, :320]
    for rate, points in (([3.0, 0.0, 0.0], [(160, 30), (160, 60), (90, 80)]),
                         ([-3.0, 0.0, 0.0], [(160, 150), (240, 175)])):
        cap = make_capture(rate, f=1080.0, exposure=0.003, readout=0.04)
        for x0, y0 in points:
            dot = np.zeros((240, 320), np.float32)
            dot[y0, x0] = 1.0
            g = simulate_blur(dot, cap, order=1, transfer="linear")
            if rate[0] < 0:           # content moves up: leave out the copy that the
                g[y0:] = 0            # mirrored border sends up from below the frame
            light = np.array([(g * xx).sum(), (g * yy).sum()]) / g.sum()
            p = landing_pixel(cap, x0, y0)
            assert np.allclose(p, light, atol=0.1), (x0, y0, p, light)
            assert abs(y0 - p[1]) > 20                 # a long way from its own row
            mx, my = _centroid(render_psf(cap, x0, y0))
            assert np.allclose([x0 + mx, y0 + my], light, atol=0.15), (x0, y0, mx, my)
    ys, xs, d = displacement_field(cap, step=30)
    mid = len(xs) // 2
    column = np.stack([np.full(len(ys), float(xs[mid])), ys], -1)
    assert np.allclose(d[:, mid], landing_pixel(cap, column[:, 0], ys) - column, atol=1e-6)
    assert np.all(np.diff(d[:, mid, 1]) < -5)          # ever further up, to the last row


def test_psf_pictures_draw_the_sinc_lobes_below_zero_black():
    """A PSF off the pixel grid rings below zero; its picture (``psf`` command, the demo's
    field) must draw those samples black, not cast NaN (the square-root stretch of a
    negative value) into the image."""
    import warnings

    from gyrodeblur.psf import PSFField
    from gyrodeblur.psfplot import field_image, psf_image

    p = lanczos_splat(np.array([[0.4, 0.5], [2.4, 1.5]]))
    assert p.min() < 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        one = psf_image(p, zoom=1)
        field = field_image(PSFField(np.array([[50.0, 40.0]]), [p], (1, 1)), 100, 80,
                            canvas_width=100)
    assert one.dtype == np.uint8 and np.all(one[..., 1][p < 0] == 0)
    assert one[..., 1].max() == 255 and field.max() == 255


# ------------------------------------------------ from a mutation audit (session 43)

def test_a_long_streak_is_sampled_finely_enough_to_render_smoothly():
    """Kills P6 (``_adaptive_trace`` keeping its first 64 samples whatever their spacing).
    A 100 px yaw streak at a steady rate deposits nearly equal light on every pixel
    along it (the rate of ``f tan(w t)`` changes by 1 % over 0.1 rad); with 64 samples
    ~1.6 px apart the windowed sincs ripple by a third from pixel to pixel."""
    from conftest import constant_rate_capture
    from gyrodeblur.psf import render_psf

    cap = constant_rate_capture([0, 1.0, 0], f=1000.0, exposure=0.1, duration=0.3)
    p = render_psf(cap, cap.camera.cx, cap.camera.cy).astype(np.float64)
    row = p[p.shape[0] // 2]
    along = np.nonzero(row > 0.5 * row.max())[0]
    assert len(along) >= 99                                    # 100.3 px long
    inner = row[along[0] + 4:along[-1] - 3]                    # clear of the ends' lobes
    assert np.abs(np.diff(inner)).max() < 0.01 * inner.mean()  # measured 9e-5 (P6: 0.33)


def test_every_splatted_point_carries_its_weight_whatever_its_subpixel_position():
    """Kills P7 (the per-point normalisation of the Lanczos taps dropped). The raw taps
    of a point between pixels sum to less than 1 (0.994 per axis half-way), so without
    the normalisation a trace's points would count more or less by their sub-pixel
    phase. A splat of several points is the weighted mean of their single splats."""
    from gyrodeblur.psf import lanczos_splat

    pts = np.array([[0.0, 0.0], [0.5, 0.25], [-1.3, 2.7]])
    wts = np.array([1.0, 3.0, 2.0])
    both = lanczos_splat(pts, wts, radius=7).astype(np.float64)
    each = sum(w * lanczos_splat(p[None], radius=7).astype(np.float64)
               for p, w in zip(pts, wts)) / wts.sum()
    np.testing.assert_allclose(both, each, atol=1e-6)


def test_psf_variation_of_a_pure_roll_is_the_same_down_and_across():
    """Kills P12 (the across-columns finite difference divided by the row spacing). Under
    a roll about the principal point (fx = fy, global shutter) every trace is linear in
    its point, ``d(x0) = A_t (x0 - c)`` with ``A_t`` a scaled rotation, so the change per
    pixel is the same along x and y, and about the roll angle (0.06 rad). Probes 3 x 9
    make the row and column spacings differ threefold."""
    from conftest import constant_rate_capture
    from gyrodeblur.psf import psf_variation

    cap = constant_rate_capture([0.0, 0.0, 2.0], exposure=0.03)
    down, across = psf_variation(cap, probes=(3, 9), per_axis=True)
    assert across == pytest.approx(down, rel=1e-2)
    assert down == pytest.approx(np.sin(2.0 * 0.03), rel=0.05)


def test_landing_pixel_never_returns_a_root_where_the_map_folds():
    """Kills P4 (the fold test ``fold < 1`` dropped from ``_landing_by_newton``). A pitch
    whose rate ramps from -7 to +1.5 rad/s over the readout (telephoto, 3 ms exposure):
    below row ~180 content moves along the sweep faster than the shutter, so the map
    ``p -> p - g(p)`` folds there and a point can have two roots (row 208: 176.8, where
    it does not fold, and 235.4, where it does). A landing pixel is either a root where
    ``dg_y/dp_y < 1`` or, failing that, the point itself (documented fallback); checked
    with the gather offsets computed here from the capture's rotations."""
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.psf import landing_pixel, offsets_under_rotation

    t = np.arange(0.0, 0.2, 1 / 400)
    w = np.zeros((t.size, 3))
    w[:, 0] = -7.0 + 500.0 * np.clip(t - 0.05, 0, None)
    cap = Capture(0.05, 0.003, 0.03, Camera.centred(320, 240, 1200.0), GyroLog(t, w))

    def mean_offset_y(px, py):                  # g_y at pixel p, timed by p's own row
        times = cap.row_start(py) + cap.exposure_time * (np.arange(32) + 0.5) / 32
        R = cap.orientation.matrices(times)
        return offsets_under_rotation(cap.camera, R, px, py)[..., 1].mean()

    ys = np.arange(150.0, 236.0, 2.0)
    p = landing_pixel(cap, np.full(ys.shape, 160.0), ys)
    moved = np.abs(p[:, 1] - ys) > 1e-9
    assert moved.any() and (~moved).any()       # both cases occur here
    for (px, py), y0, m in zip(p, ys, moved):
        if not m:
            continue
        assert abs(y0 + mean_offset_y(px, py) - py) < 1e-2, (y0, py)       # a root
        slope = (mean_offset_y(px, py + 0.05) - mean_offset_y(px, py - 0.05)) / 0.1
        assert slope < 1.0, (y0, py, slope)


def test_a_forced_radius_that_cuts_the_trace_is_warned_of_or_refused(make_capture):
    """``radius=`` shorter than the blur cuts the PSF and renormalises what is left: no
    longer the blur, so it says so; one that holds less than half the trace is refused
    (under a rolling shutter what it held could sum to 0 or below); a radius holding the
    trace says nothing."""
    import warnings

    from gyrodeblur.errors import InputError

    cap = make_capture([0, 1.0, 0], f=300.0, exposure=0.03)          # a 9 px streak
    cx, cy = cap.camera.cx, cap.camera.cy
    with pytest.warns(UserWarning, match=r"beyond radius=6, which holds 7\d % of its trace"):
        cut = render_psf(cap, cx, cy, radius=6)
    assert cut.shape == (13, 13) and np.isclose(cut.sum(), 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        whole = render_psf(cap, cx, cy, radius=12)
    assert whole.shape == (25, 25) and np.isclose(whole.sum(), 1)
    assert cut.max() > 1.2 * whole.max()          # the streak's mass piled into 13 x 13
    with pytest.raises(InputError, match=r"radius=2, which holds \d+ % of its trace: leave"):
        render_psf(cap, cx, cy, radius=2)
    # a lower row's trace starts away from its pixel (the camera turned before the row began)
    rolling = make_capture([0, 1.0, 0], f=300.0, exposure=0.03, readout=0.03)
    with pytest.raises(InputError, match=r"radius=4, which holds \d+ % of its trace: leave"):
        render_psf(rolling, cx, rolling.camera.height - 1, radius=4)


def test_a_point_far_outside_the_frame_is_refused_as_such(make_capture):
    from gyrodeblur.errors import InputError

    cap = make_capture([0, 1.0, 0], f=300.0, exposure=0.03)
    w, h = cap.camera.width, cap.camera.height
    with pytest.raises(InputError, match="more than a frame outside"):
        render_psf(cap, 1e6, 0)
    with pytest.raises(InputError, match="more than a frame outside"):
        render_psf(cap, -w - 1, h / 2)
    assert np.isclose(render_psf(cap, -w / 2, -h / 2).sum(), 1)   # outside, within a frame


# ------------------------------------------------ from a mutation audit (session 44)

def test_a_psf_picture_is_enlarged_square_root_stretched_and_marks_its_centre():
    """Kills ``psf_image`` without its square-root stretch, its default zoom (~256 px)
    or its centre mark: a tail at a quarter of the peak draws at half grey, and the red
    dot lies in the centre sample's block."""
    from gyrodeblur.psfplot import psf_image

    p = np.zeros((3, 3))
    p[1, 1], p[1, 0] = 1.0, 0.25
    one = psf_image(p, zoom=1)
    assert one[1, 0, 1] == 127 and one[0, 0, 1] == 0
    big = psf_image(p)
    assert big.shape == (255, 255, 3)                     # 85 x 3: ~256 px by default
    red = np.argwhere((big == (255, 0, 0)).all(axis=2))
    assert len(red) == 1 and np.all((85 <= red) & (red < 170)), red


def test_a_field_picture_keeps_the_frame_s_aspect_and_draws_each_psf_at_its_point():
    """Kills ``field_image`` with a square canvas, x and y swapped, boxes pasted from their
    centres, or a zoom that lets neighbouring boxes overlap: on a 2 x 2 field of a
    200 x 100 frame each PSF (a bright dot) is drawn centred on its point, and the four
    framed boxes stay apart."""
    from gyrodeblur.psf import PSFField
    from gyrodeblur.psfplot import field_image

    small, large = np.zeros((5, 5)), np.zeros((9, 9))
    small[2, 2] = large[4, 4] = 1.0
    pts = np.array([[50.0, 25.0], [150.0, 25.0], [50.0, 75.0], [150.0, 75.0]])
    img = field_image(PSFField(pts, [small, large, large, small], (2, 2)), 200, 100,
                      canvas_width=400)
    assert img.shape == (200, 400, 3)
    white = (img == 255).all(axis=2)
    blobs, n = ndimage.label(white)
    assert n == 4
    for (x, y), centre in zip(pts, ndimage.center_of_mass(white, blobs, range(1, 5))):
        assert np.allclose(centre, (2 * y, 2 * x), atol=1.5), (x, y, centre)
    frames = (img == (70, 110, 160)).all(axis=2)
    assert ndimage.label(frames, np.ones((3, 3)))[1] == 4          # no two boxes touch


def test_a_psf_fields_grid_must_hold_its_points(make_capture):
    """``psf_field(points, grid=)``: the grid's rows x columns are the points' count (a
    grid that did not fit was stored as given, and a plot or a patch layout read from it
    went wrong later)."""
    from gyrodeblur.errors import InputError
    from gyrodeblur.psf import psf_field

    cap = make_capture([0.0, 0.3, 0.0], width=64, height=48, f=60.0)
    pts = [(x, y) for y in (10.0, 30.0) for x in (10.0, 30.0, 50.0)]
    assert psf_field(cap, pts, grid=(2, 3)).grid == (2, 3)
    assert psf_field(cap, pts).grid is None
    for bad in ((3, 3), (6,), (2.5, 3), "2x3", (0, 6), (2, 3, 1)):
        with pytest.raises(InputError, match="grid must be"):
            psf_field(cap, pts, grid=bad)


def test_a_psf_too_large_for_the_frame_is_said_as_a_psf_not_as_a_blur(make_capture):
    """render_psf refuses a PSF wider than the frame; the message gives the PSF's side
    (twice the blur's reach from its point, rolling-shutter shift included) as the PSF's,
    with that reach, not as the length of the blur, which is shorter."""
    from gyrodeblur.errors import InputError
    from gyrodeblur.psf import trace
    small = make_capture([0.3, 1.0, 0.5], width=40, height=30, f=500.0, exposure=0.04,
                         readout=0.01)
    pts = trace(small, 19.5, 14.5, 200)
    reach = np.abs(pts - [19.5, 14.5]).max()
    assert np.ptp(pts, axis=0).max() < 40 < 2 * reach          # the blur fits, the PSF not
    with pytest.raises(InputError, match=f"the PSF centred on its point \\(its blur reaching "
                                         f"{reach:.0f} px from it\\) at \\(20, 14\\) would span "
                                         f"{2 * reach:.0f} px, more than the 40x30 frame"):
        render_psf(small, 19.5, 14.5)
