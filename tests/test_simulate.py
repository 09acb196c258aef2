"""Blur synthesis (warping) against PSF rendering (splatting): two independent models."""

import numpy as np
import pytest
from scipy import ndimage
from skimage import data, transform

from gyrodeblur.psf import render_psf
from gyrodeblur.simulate import (_add_spline_samples, _row_homographies, _spline_coefficients,
                                 add_noise, quantize_8bit, simulate_blur, warp_samples)


@pytest.fixture(scope="module")
def scene():
    return transform.resize(data.astronaut(), (240, 320), anti_aliasing=True).astype(np.float32)


def _centroid(p):
    r = p.shape[0] // 2
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (p * xx).sum(), (p * yy).sum()


def _psf_for_pixel(cap, x, y):
    """PSF of the scene points whose light lands on (x, y): rendered at x minus its mean
    offset (a fixed point, found in three steps); the PSF varies across its own support
    under roll, so the pixel's own PSF is only a first-order stand-in."""
    px, py = x, y
    for _ in range(3):
        p = render_psf(cap, px, py)
        cx, cy = _centroid(p)
        px, py = x - cx, y - cy
    return p


def test_simulate_matches_psf_convolution_with_roll(make_capture, scene):
    cap = make_capture([-0.3, 0.5, 2.0], readout=0.02)       # strong roll + rolling shutter
    blurred = simulate_blur(scene, cap, transfer="linear")
    rng = np.random.default_rng(0)
    errs, effect = [], []
    for x, y in rng.integers([40, 40], [280, 200], size=(40, 2)):
        p = _psf_for_pixel(cap, x, y)
        r = p.shape[0] // 2
        crop = scene[y - r:y + r + 1, x - r:x + r + 1]
        conv = (crop[::-1, ::-1] * p[..., None]).sum((0, 1))
        errs.append(np.abs(conv - blurred[y, x]).max())
        effect.append(np.abs(blurred[y, x] - scene[y, x]).max())
    assert np.mean(errs) < 0.05 * np.mean(effect)
    assert np.percentile(errs, 90) < 0.02


def test_row_bands_in_threads_give_the_single_thread_result(make_capture, scene, monkeypatch):
    """The warps run in row bands, one per core; every pixel sums the same samples in the
    same order, so the threads change nothing, to the last bit, for either sampling."""
    import gyrodeblur.bands as bands

    cap = make_capture([-0.3, 0.5, 2.0], readout=0.02)
    for order in (1, 3):
        monkeypatch.setattr(bands, "usable_cpus", lambda: 3)      # 3 bands of 80 rows
        threaded = simulate_blur(scene, cap, order=order, transfer="linear")
        monkeypatch.setattr(bands, "usable_cpus", lambda: 1)
        single = simulate_blur(scene, cap, order=order, transfer="linear")
        assert np.array_equal(threaded, single)
        assert np.abs(threaded - scene).max() > 0.1       # and it did blur


def test_zero_motion_is_identity(make_capture, scene):
    cap = make_capture([0, 0, 0])
    assert np.abs(simulate_blur(scene, cap, transfer="linear") - scene).max() < 1e-5


def test_sample_count_follows_speed(make_capture):
    slow = warp_samples(make_capture([0, 0.5, 0]))
    fast = warp_samples(make_capture([0, 2.0, 0]))
    assert 3.5 < fast / slow < 4.5                    # four times the rate, four times the steps
    assert warp_samples(make_capture([0, 0.1, 0])) == 8       # the floor
    # fastest pixel moves < 0.5 px per step: 300 px * 2 rad/s * 0.03 s = 18 px -> >= 36 steps
    assert fast >= 36


def test_noise_snr_and_quantisation(scene):
    noisy = add_noise(scene, 40.0, seed=3)
    snr = 20 * np.log10(scene.std() / (noisy - scene).std())
    assert abs(snr - 40) < 0.2
    q = quantize_8bit(noisy)
    assert q.min() >= 0 and q.max() <= 1
    assert np.allclose(q * 255, np.round(q * 255), atol=1e-4)
    assert np.array_equal(add_noise(scene, 30, seed=1), add_noise(scene, 30, seed=1))


def test_alpha_is_not_blurred_and_bad_arguments_are_refused(make_capture, scene):
    cap = make_capture([0.0, 0.5, 0.0])
    alpha = np.zeros((240, 320, 1), np.float32)
    alpha[:, 160:] = 1.0
    out = simulate_blur(np.concatenate([scene, alpha], axis=2), cap, snr_db=30, seed=2,
                        quantize=True, transfer="linear")
    assert np.array_equal(out[..., 3:], alpha)
    assert np.array_equal(out[..., :3], simulate_blur(scene, cap, snr_db=30, seed=2,
                                                      quantize=True, transfer="linear"))
    for bad in ({"n_samples": -3}, {"n_samples": 0}, {"n_samples": 2.5}, {"n_samples": True},
                {"snr_db": float("nan")}):
        with pytest.raises(ValueError, match=f"{next(iter(bad))} must be"):
            simulate_blur(scene, cap, **bad)


@pytest.mark.parametrize("order", [1, 3])
def test_spline_sampler_is_map_coordinates_with_mirrored_border(order):
    """The sampler (coefficients, mirror padding, fold, taps, weights) against scipy's
    ``map_coordinates(mode="reflect")`` at random positions, a third of them outside the
    frame (near it, and up to 1e5 px away), and on the frame's edges and half-pixels."""
    rng = np.random.default_rng(order)
    H, W = 13, 17
    img = rng.random((H, W, 2)).astype(np.float32)
    x = np.concatenate([rng.uniform(-0.5, W - 0.5, 400), rng.uniform(-2 * W, 3 * W, 150),
                        rng.uniform(-1e5, 1e5, 50), [-0.5, W - 0.5, 0, W - 1, -3, W + 2.5]])
    y = np.concatenate([rng.uniform(-0.5, H - 0.5, 400), rng.uniform(-2 * H, 3 * H, 150),
                        rng.uniform(-1e5, 1e5, 50), [H - 0.5, -0.5, H + 1, 2.5, 0, H - 1]])
    x, y = x.reshape(2, -1), y.reshape(2, -1)                 # any shape
    assert ((x < -0.5) | (x > W - 0.5) | (y < -0.5) | (y > H - 0.5)).mean() > 0.3
    out = np.zeros((2,) + x.shape, np.float32)
    _add_spline_samples(_spline_coefficients(img, order), x, y, order, out)
    for c in range(2):
        ref = ndimage.map_coordinates(img[..., c].astype(np.float64), [y, x], order=order,
                                      mode="reflect")
        np.testing.assert_allclose(out[c], ref, rtol=0, atol=2e-6)
    with pytest.raises(ValueError, match="infinity"):        # not an IndexError, nor zeros
        _add_spline_samples(_spline_coefficients(img, order), x, np.where(x > 5, np.inf, y),
                            order, out)


@pytest.mark.parametrize("order", [1, 3])
def test_simulate_is_the_mean_of_map_coordinates_warps(make_capture, order):
    """The whole synthesis (rows in chunks and bands, channels, rolling shutter) against
    its definition, written with scipy's sampler: grey and RGB."""
    cap = make_capture([-0.4, 0.6, 1.5], width=64, height=48, f=60.0, readout=0.02)
    rng = np.random.default_rng(5)
    rgb = ndimage.gaussian_filter(rng.random((48, 64, 3)), (1, 1, 0)).astype(np.float32)
    n = 5
    xs = np.arange(64.0)[None, :]
    ys = np.arange(48.0)[:, None]
    for img in (rgb, rgb[..., 1]):
        ref = np.zeros(img.shape)
        for j in range(n):
            h = _row_homographies(cap, (j + 0.5) / n)[:, None]
            den = h[..., 2, 0] * xs + h[..., 2, 1] * ys + h[..., 2, 2]
            sx = (h[..., 0, 0] * xs + h[..., 0, 1] * ys + h[..., 0, 2]) / den
            sy = (h[..., 1, 0] * xs + h[..., 1, 1] * ys + h[..., 1, 2]) / den
            for c in range(1 if img.ndim == 2 else 3):
                plane = img if img.ndim == 2 else img[..., c]
                warped = ndimage.map_coordinates(plane.astype(np.float64), [sy, sx],
                                                 order=order, mode="reflect")
                if img.ndim == 2:
                    ref += warped / n
                else:
                    ref[..., c] += warped / n
        out = simulate_blur(img, cap, n_samples=n, order=order, transfer="linear")
        assert out.shape == img.shape and out.dtype == np.float32
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-5)
        assert np.abs(out - img).max() > 0.05                   # and it did blur


# ------------------------------------------------ from a mutation audit (session 43)

def _yawing(exposure, readout, on, off=1.0, *, rate=2.0, log_hz=1000, size=(320, 240)):
    """A capture whose first row starts at 0.05 s (f = 300 px) and whose camera yaws at
    ``rate`` rad/s from ``on`` to ``off`` s, still otherwise (logged at ``log_hz``)."""
    from gyrodeblur.camera import Camera
    from gyrodeblur.capture import Capture
    from gyrodeblur.gyrolog import GyroLog

    t = np.arange(0.0, 0.2, 1 / log_hz)
    w = np.zeros((t.size, 3))
    w[(t >= on) & (t < off), 1] = rate
    return Capture(0.05, exposure, readout, Camera.centred(*size, 300.0), GyroLog(t, w))


def test_sample_count_sees_the_motion_of_the_lower_rows():
    """Kills M6 (``warp_samples`` timing every probe by row 0's exposure). The camera is
    still while the top rows are exposed and yaws at 2 rad/s from just after; with a
    30 ms readout the bottom rows move 6 px during their 10 ms exposure, so the samples
    must be at least 6 / 0.5 = 12 to keep every pixel's step under 0.5 px."""
    cap = _yawing(0.01, 0.03, 0.065)
    assert warp_samples(cap) >= 12


# ------------------------------------------------ from a mutation audit (session 46)

def test_sample_count_sees_the_lower_rows_of_a_portrait_frame():
    """Kills ``warp_samples`` timing its probes by their column, not their row: in a
    120 x 320 portrait frame the columns reach only row 119's timing. The camera yaws at
    2 rad/s from 25 ms after the first row starts; with a 30 ms readout only rows below
    ~160 are exposed then (up to 6 px each), so the samples must be at least 12."""
    cap = _yawing(0.01, 0.03, 0.075, size=(120, 320))
    assert warp_samples(cap) >= 12


def test_sample_count_sees_a_jolt_in_the_last_moment_of_the_exposure():
    """A 10 rad/s jolt in the last millisecond of a 64 ms exposure turns the camera by
    0.01 rad, 3 px or more at f = 300: at most 0.5 px per step needs 6 samples in that
    millisecond, 384 in all. Kills the speed probe leaving out the exposure's last 1/64
    (the jolt unseen: 29 samples)."""
    cap = _yawing(0.064, 0.0, 0.113, rate=10.0, log_hz=10000)
    assert warp_samples(cap) >= 384


def _row_steps(cap, n):
    """Each row's largest step (px) of the frame's middle column between the ``n`` time
    samples that :func:`simulate_blur` takes, each row at its own time."""
    xy = []
    for s in (np.arange(n) + 0.5) / n:
        p = _row_homographies(cap, s) @ np.array([cap.camera.width / 2, 0.0, 1.0])
        xy.append(p[:, :2] / p[:, 2:])
    return np.abs(np.diff(xy, axis=0)).max(axis=(0, 2))


def test_sample_count_sees_a_turn_between_the_probe_rows_of_a_short_exposure():
    """A 1 ms exposure under a 40 ms readout: each row sees its own millisecond of the
    motion, and a 20 rad/s turn 4-5 ms after the first row starts (logged at 1 kHz) blurs
    rows 7-41 only, by up to 6 px at f = 300: between the first two of five evenly spread
    probe rows, rows 0 and 60, which saw nothing (8 samples, steps of 0.84 px). The count
    keeps every row's steps under 0.5 px."""
    cap = _yawing(0.001, 0.04, 0.054, 0.0555, rate=20.0)
    steps = _row_steps(cap, warp_samples(cap))
    still = (np.arange(240) < 5) | (np.arange(240) > 45)
    assert steps.max() > 0.1 and steps[still].max() < 1e-9
    assert steps.max() <= 0.5, steps.max()


def test_sample_count_sees_a_jolt_shorter_than_its_probes_step():
    """A 30 rad/s jolt of 0.4 ms (logged at 10 kHz) in the middle of a 64 ms exposure,
    within one of the 64 steps of a probe timed by the exposure alone: that probe reads
    its turn as spread over the step and takes too few samples (steps of 0.8 px). Timed
    by the log's samples as well, every step stays under 0.5 px."""
    cap = _yawing(0.064, 0.0, 0.0803, 0.0807, rate=30.0, log_hz=10000)
    assert _row_steps(cap, warp_samples(cap)).max() <= 0.5


def test_a_blur_longer_than_the_frame_is_refused_before_the_work(make_capture):
    """Wrong capture values (an exposure in ms read as s) would ask for thousands of
    samples of a meaningless blur: the sample count refuses them, naming the blur's span."""
    from gyrodeblur.errors import InputError

    cap = make_capture([0.0, 2.0, 0.0], exposure=1.0, duration=1.5)   # 300 px * 2 rad/s * 1 s
    with pytest.raises(InputError, match="across the frame"):
        warp_samples(cap)
    with pytest.raises(InputError, match="across the frame"):
        simulate_blur(np.zeros((240, 320), np.float32), cap, transfer="linear")


def test_quantisation_rounds_to_the_nearest_level():
    x = np.array([0.4, 0.6, 127.49, 127.51, 254.4, 254.6], np.float32) / 255
    np.testing.assert_array_equal(quantize_8bit(x) * 255,
                                  np.float32([0, 1, 127, 128, 254, 255]))
    np.testing.assert_array_equal(quantize_8bit(np.float32([-0.3, 1.7])), [0.0, 1.0])


def test_synthesis_quantises_when_asked_and_is_linear_in_linear_light(make_capture):
    """``quantize=True`` gives 8-bit levels within half a level of the unquantised blur;
    linear synthesis is a linear operator, so a zero-mean texture keeps its negative
    values (blur(-x) = -blur(x)), unclipped."""
    cap = make_capture([-0.4, 0.6, 1.5], width=64, height=48, f=60.0, readout=0.02)
    rng = np.random.default_rng(4)
    img = ndimage.gaussian_filter(rng.random((48, 64)), 1).astype(np.float32)
    plain = simulate_blur(img, cap, n_samples=5, transfer="linear")
    q = simulate_blur(img, cap, n_samples=5, quantize=True, transfer="linear")
    np.testing.assert_array_equal(q * 255, np.round(q * 255))
    assert np.abs(q - plain).max() <= 0.5 / 255 + 1e-6
    zero_mean = img - img.mean()
    out = simulate_blur(zero_mean, cap, n_samples=5, transfer="linear")
    assert out.min() < -0.05
    np.testing.assert_allclose(simulate_blur(-zero_mean, cap, n_samples=5, transfer="linear"),
                               -out, atol=1e-6)


def test_a_photo_at_another_scale_is_blurred_by_the_capture_rescaled(make_capture):
    """As ``deblur`` does: a scene at half the camera's size is blurred by the capture's
    intrinsics halved (the same result as ``capture.scaled_to``), and one of another
    aspect ratio is refused, naming the sharp image."""
    from gyrodeblur.errors import InputError

    cap = make_capture([0.1, 0.4, 0.2], width=128, height=96, f=120.0, readout=0.01)
    small = transform.resize(data.camera(), (48, 64), anti_aliasing=True).astype(np.float32)
    got = simulate_blur(small, cap, transfer="linear")
    assert np.array_equal(got, simulate_blur(small, cap.scaled_to(64, 48), transfer="linear"))
    assert np.abs(got - small).max() > 0.05                    # it did blur
    with pytest.raises(InputError, match="sharp image: .*aspect ratio differs"):
        simulate_blur(small[:, :60], cap, transfer="linear")


def test_a_dropout_inside_the_exposure_is_warned_of_and_one_beside_it_is_not(make_capture):
    """As deblur() does: the blur made across a 30 ms dropout inside the exposure window
    (0.05-0.09 s of the log's clock) is made from interpolated motion, and said to be; the
    same dropout after the window is not named."""
    import dataclasses
    import warnings

    from gyrodeblur.gyrolog import GyroLog
    cap = make_capture((0.0, 0.3, 0.0), readout=0.01)
    t = cap.log.t
    image = np.random.default_rng(2).random((cap.camera.height, cap.camera.width))

    def dropped(after):                               # a 30 ms step from the sample at `after`
        keep = ~((t > after + 1e-6) & (t < after + 0.03 - 1e-6))
        return dataclasses.replace(cap, log=GyroLog(t[keep], cap.log.omega[keep]))

    with pytest.warns(UserWarning, match=r"gap of 30\.0 ms in the gyro log at 0\.060000 s, "
                                         r"inside the exposure: .* the blur is made from "
                                         r"that interpolation"):
        simulate_blur(image.astype(np.float32), dropped(0.06), seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate_blur(image.astype(np.float32), dropped(0.1), seed=0)


@pytest.mark.parametrize("snr,black", [(40.0, False), (30.0, False), (10.0, False),
                                       (40.0, True)])
def test_snr_db_is_the_encoded_photos_with_the_noise_added_as_light(make_capture, snr,
                                                                    black):
    """snr_db is what the returned sRGB photo shows (std(photo) / std(noise), within 0.3
    dB; at 10 dB too, and with half the photo black, where the clipping at black takes
    part of the noise), though the noise is added to the blurred light, as a sensor's: so
    the dark pixels, where the curve is steep, get more of it than the bright ones."""
    cap = make_capture((0.1, 0.4, 0.0), readout=0.01)
    sharp = transform.resize(data.astronaut(), (cap.camera.height, cap.camera.width),
                             anti_aliasing=True).astype(np.float32)
    if black:
        sharp[:, :cap.camera.width // 2] = 0.0
    clean = simulate_blur(sharp, cap)
    noisy = simulate_blur(sharp, cap, snr_db=snr, seed=4)
    err = noisy - clean
    assert 20 * np.log10(clean.std() / err.std()) == pytest.approx(snr, abs=0.3)
    dark, bright = clean < 0.15, clean > 0.6
    assert dark.mean() > 0.05 and bright.mean() > 0.05
    assert err[dark].std() > 3 * err[bright].std()


def test_shot_noise_grows_with_the_light_and_leaves_the_read_noise_as_it_was(make_capture):
    """``full_well``: each pixel's light L becomes Poisson(L * full_well) / full_well, so
    its variance is L / full_well (measured on flat bands of three levels, in linear
    light, where a blur changes nothing); the read noise of ``snr_db`` is drawn as
    without it (a seed gives the same), and bad counts are refused before the work."""
    cap = make_capture((0.0, 0.3, 0.0), width=240, height=180, f=200.0)
    levels = (0.05, 0.2, 0.8)
    sharp = np.repeat(np.repeat(np.array(levels, np.float32), 60)[:, None], 240, axis=1)
    clean = simulate_blur(sharp, cap, transfer="linear")
    shot = simulate_blur(sharp, cap, transfer="linear", full_well=400.0, seed=2)
    for k, level in enumerate(levels):
        band = (shot - clean)[60 * k + 15:60 * k + 45, 20:-20]
        assert abs(band.mean()) < 0.05 * np.sqrt(level / 400.0)
        assert band.var() == pytest.approx(level / 400.0, rel=0.1), level
    read = simulate_blur(sharp, cap, transfer="linear", snr_db=30.0, seed=5)
    both = simulate_blur(sharp, cap, transfer="linear", snr_db=30.0, seed=5, full_well=1e9)
    assert np.abs(both - read).max() < 1e-3 < np.abs(read - clean).max()   # ~3e-5 of shot
    assert np.array_equal(simulate_blur(sharp, cap, transfer="linear", full_well=400.0,
                                        seed=2), shot)
    for bad in (0.5, np.nan, 1e12):
        with pytest.raises(ValueError, match="full_well must be"):
            simulate_blur(sharp, cap, full_well=bad)
    with pytest.raises(TypeError, match="full_well must be a number"):
        simulate_blur(sharp, cap, full_well="400")


def test_noise_and_levels_refuse_what_is_not_a_float_image():
    """``add_noise`` took 8-bit values as they were (noise on 0-255) and ``snr_db=nan``
    into an all-NaN image; ``quantize_8bit`` turned 8-bit values nearly white."""
    from gyrodeblur.errors import InputError
    from gyrodeblur.simulate import add_noise, quantize_8bit

    img = np.full((16, 16), 0.5, np.float32)
    img[::2] = 0.2
    for f in (lambda a: add_noise(a, 40.0, seed=0), quantize_8bit):
        with pytest.raises(InputError, match="image must hold floating-point values"):
            f((img * 255).astype(np.uint8))
        with pytest.raises(InputError, match="image has 1 NaN"):
            f(np.where(np.arange(256).reshape(16, 16) == 7, np.nan, img))
    for snr in (float("nan"), 1000.0):
        with pytest.raises(ValueError, match="snr_db must"):
            add_noise(img, snr)
    noisy = add_noise(img, 20.0, seed=1)            # std(img) / 10 = 0.015
    assert noisy.dtype == np.float32 and abs(float(np.std(noisy - img)) - 0.015) < 0.002
    q = quantize_8bit(img.astype(np.float64) + 0.001)
    assert q.dtype == np.float32 and np.allclose(q * 255, np.round(q * 255), atol=1e-4)
    assert np.abs(q - (img + 0.001)).max() <= 0.5 / 255 + 1e-7
