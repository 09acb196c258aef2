"""Tests of gyrodeblur.images (the one check of image arrays) and of the public functions
that rely on it: wrong dtypes, shapes and NaN pixels are refused, not misread."""

import numpy as np
import pytest

from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.deblur import deblur, deblur_blind
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog
from gyrodeblur.images import check_image, check_psf, to_photo_layout, to_sensor_layout
from gyrodeblur.metrics import psnr, ssim
from gyrodeblur.simulate import simulate_blur
from gyrodeblur.sparse import sparse_deconvolve
from gyrodeblur.wiener import wiener_deconvolve


def _capture(w=96, h=64) -> Capture:
    t = np.arange(0.0, 1.0, 1 / 200)
    rates = np.stack([0.3 * np.sin(7 * t), 0.5 * np.cos(5 * t), 0.1 * np.sin(3 * t)], 1)
    return Capture(0.4, 0.03, 0.02, Camera.centred(w, h, 100.0), GyroLog(t, rates))


@pytest.fixture
def image():
    return np.random.default_rng(0).random((64, 96, 3)).astype(np.float32)


def test_a_valid_float_image_passes_without_a_copy(image):
    assert check_image(image) is image
    assert check_image(image.astype(np.float64)).dtype == np.float32
    assert check_image(image, dtype=np.float64).dtype == np.float64


@pytest.mark.parametrize("bad,match", [
    (lambda im: (im * 255).astype(np.uint8), "dtype uint8 .*divide 8-bit values by 255"),
    (lambda im: im > 0.5, "dtype bool"),
    (lambda im: im.astype(np.complex64), "dtype complex64"),
    (lambda im: im.transpose(2, 0, 1), r"at most 4 channels last, got \(3, 64, 96\)"),
    (lambda im: im[0, :, 0], r"shape \(H, W\)"),
    (lambda im: im[:1], "1 pixels; need at least 2x2|96x1 pixels"),
    (lambda im: np.where(np.arange(96) == 5, np.nan, im[..., 0]), "64 NaN or infinite"),
])
def test_what_is_refused_and_named(image, bad, match):
    with pytest.raises(InputError, match=match):
        check_image(bad(image), "photo")


def test_public_functions_refuse_integer_and_nan_images(image):
    """uint8 would come out nearly white, and one NaN spreads over its patch: refused."""
    cap = _capture()
    psf = np.ones((3, 3), np.float32) / 9
    u8 = (image * 255).astype(np.uint8)
    nan = image.copy()
    nan[10, 10, 0] = np.nan
    for bad in (u8, nan):
        for call in (lambda im: deblur(im, cap, method="wiener", grid=(2, 2)),
                     lambda im: deblur_blind(im, 5),
                     lambda im: simulate_blur(im, cap, transfer="linear"),
                     lambda im: wiener_deconvolve(im, psf),
                     lambda im: sparse_deconvolve(im, psf, noise_sigma=0.01)):
            with pytest.raises(InputError):
                call(bad)
    with pytest.raises(TypeError, match="capture must be a Capture"):
        deblur(image, None)


def test_method_options_are_checked_before_any_work(image):
    cap = _capture()
    with pytest.raises(TypeError, match="unknown option.*bogus"):
        deblur(image, cap, bogus=1)
    with pytest.raises(TypeError, match="unknown option.*phi"):
        deblur(image, cap, phi=0.01)                 # a Wiener option, given to sparse
    with pytest.raises(TypeError):
        deblur(image, cap, method="wiener", grid=(2, 2), iterations=3)
    for kw in ({"noise_sigma": np.nan}, {"noise_sigma": -1.0}, {"weight": np.inf},
               {"iterations": 2.5}, {"iterations": -1}):
        with pytest.raises(InputError, match="method 'sparse'"):   # a ValueError too
            deblur(image, cap, grid=(2, 2), **kw)
    # the README example's noise_sigma, with the method switched to Wiener: said plainly
    with pytest.raises(TypeError, match="noise_sigma for method 'wiener' \\(known: phi\\)"):
        deblur(image, cap, method="wiener", grid=(2, 2), noise_sigma=0.01)
    with pytest.raises(InputError, match="^phi: "):
        deblur(image, cap, method="wiener", grid=(2, 2), phi=-1.0)


@pytest.mark.parametrize("grid", [(2, 2, 2), (2.5, 3.7), (True, True), (2,), 2.5, ("a", "b")])
def test_a_grid_is_two_positive_integers(image, grid):
    with pytest.raises(InputError, match="^grid: "):
        deblur(image, _capture(), method="wiener", grid=grid)


def test_a_grid_too_fine_for_the_photo_is_refused(image):
    with pytest.raises(InputError, match="too many"):
        deblur(image, _capture(), method="wiener", grid=(40, 40))


def test_a_small_photo_works_with_the_default_grid():
    """The automatic grid never asks for more patches than the photo holds."""
    small = np.random.default_rng(1).random((64, 96)).astype(np.float32)
    out = deblur(small, _capture())
    assert out.shape == small.shape and np.isfinite(out).all()


def test_metrics_refuse_mismatched_or_integer_images(image):
    with pytest.raises(ValueError, match="differ in shape"):
        psnr(image, image[..., :1])
    with pytest.raises(ValueError, match="differ in shape"):
        ssim(image[..., :1], image)
    with pytest.raises(InputError, match="uint8"):
        psnr((image * 255).astype(np.uint8), (image * 255).astype(np.uint8))
    with pytest.raises(ValueError, match="border"):
        psnr(image, image, border=-1)
    with pytest.raises(ValueError, match="too few"):
        ssim(image[:6, :6], image[:6, :6])
    assert psnr(image, image) == float("inf")


def test_capture_and_log_keep_their_own_copies():
    t = np.arange(0.0, 1.0, 0.01)
    w = np.zeros((t.size, 3))
    bias = np.array([0.01, 0.0, 0.0])
    cap = Capture(0.4, 0.03, 0.0, Camera.centred(96, 64, 100.0), GyroLog(t, w), bias=bias)
    t[:] = t[::-1].copy()
    bias[0] = 5.0
    assert np.all(np.diff(cap.log.t) > 0) and cap.bias[0] == 0.01
    with pytest.raises(TypeError, match="camera must be a Camera"):
        Capture(0.4, 0.03, 0.0, None, GyroLog(np.arange(3.0), np.zeros((3, 3))))
    with pytest.raises(InputError, match="whole number"):
        Camera(100.0, 100.0, 47.5, 31.5, 96.5, 64)


def test_review_findings_stay_fixed(image):
    """0-255 floats are named as such; the shrunk path of calibrate checks too; a generator
    of captures is one list; SSIM's 11 px window is checked; max_gap must be a number."""
    from gyrodeblur.calibrate import PARAMETERS, calibrate
    cap = _capture()
    with pytest.raises(InputError, match="values up to 2.*divide 8-bit values by 255"):
        deblur(image * 255, cap)
    with pytest.raises(InputError, match="dtype uint8"):
        calibrate([(image * 255).astype(np.uint8)], cap, downscale=0.5)
    res = calibrate([image], (c for c in [cap]), fix=PARAMETERS)       # nothing to estimate
    assert res.capture.time_offset == cap.time_offset
    with pytest.raises(ValueError, match="too few"):
        ssim(image[:9, :9], image[:9, :9])
    with pytest.raises(InputError, match="max_gap"):
        cap.replace(max_gap=None)


def test_psfs_are_checked_and_normalised_the_same_way_by_every_deconvolution():
    """One PSF check for Wiener, the sparse method and blind's initial kernel: odd sides,
    finite, a positive sum; the result sums to 1 (a PSF given unnormalised deconvolves as
    the normalised one would)."""
    from gyrodeblur.blind import blind_deconvolve

    k = check_psf(np.full((1, 5), 2.0))
    assert k.dtype == np.float32 and k.sum() == pytest.approx(1.0)
    assert k[0, 0] == pytest.approx(0.2)
    assert check_psf([[1, 3, -1]], dtype=np.float64).tolist() == [[1 / 3, 1.0, -1 / 3]]
    img = np.random.default_rng(0).random((32, 32)).astype(np.float32)
    bad = {"odd sides": np.ones((4, 5)), "NaN or infinite": np.array([[1.0, np.nan, 1.0]]),
           "positive finite sum": np.array([[1.0, -2.0, 0.0]]),
           "not an array": [[1, "a", 2]], "complex": np.ones((3, 3), complex)}
    for msg, psf in bad.items():
        for deconvolve in (wiener_deconvolve, sparse_deconvolve):
            with pytest.raises(InputError, match=f"PSF .*{msg}|PSF is {msg}"):
                deconvolve(img, psf)
    with pytest.raises(InputError, match="init_psf must be a 2-D array with odd sides"):
        blind_deconvolve(img, kernel_size=5, init_psf=np.ones((2, 2)))
    with pytest.raises(InputError, match="positive finite sum, got inf"):
        check_psf(np.full((1, 3), 1e308))                      # an overflowing sum
    ref = wiener_deconvolve(img, np.full((1, 5), 0.2))
    np.testing.assert_allclose(wiener_deconvolve(img, np.full((1, 5), 7.0)), ref, atol=1e-6)


@pytest.mark.parametrize("degrees", [0, 90, 180, 270])
def test_sensor_layout_undoes_a_clockwise_export_turn_and_back(degrees):
    sensor = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)   # rows, cols, RGBA
    exported = np.rot90(sensor, -(degrees // 90))         # an export turning clockwise
    back = to_sensor_layout(exported, degrees)
    np.testing.assert_array_equal(back, sensor)
    np.testing.assert_array_equal(to_photo_layout(back, degrees), exported)
    assert back.flags.c_contiguous


@pytest.mark.parametrize("bad,match", [
    (lambda im: (im * 32767).astype(np.int16), "dtype int16 .*divide 8-bit values by 255"),
    (lambda im: im[None], r"at most 4 channels last, got \(1, 64, 96, 3\)"),
    (lambda im: im[..., :0], r"at most 4 channels last, got \(64, 96, 0\)"),
])
def test_more_that_is_refused_and_how_it_is_named(image, bad, match):
    """Signed integers get the scaling hint too; a 4-D array and an image of no channels
    are not images."""
    with pytest.raises(InputError, match=match):
        check_image(bad(image), "photo")


def test_the_limits_themselves_are_accepted(image):
    """One to four channels (RGBA included), a side of exactly ``min_size``, and values of
    exactly ``max_value`` and ``min_value`` pass; one pixel beyond a limit does not."""
    from gyrodeblur.images import PHOTO_MAX, PHOTO_MIN

    for c in (1, 2, 3, 4):
        rgba = np.dstack([image] * 2)[..., :c]
        assert check_image(rgba).shape == (64, 96, c)
    assert check_image(image[:16, :16], min_size=16).shape[:2] == (16, 16)
    with pytest.raises(InputError, match="need at least 16x16"):
        check_image(image[:15, :16], min_size=16)
    edge = image.copy()
    edge[0, 0, 0], edge[0, 1, 0] = PHOTO_MAX, PHOTO_MIN
    assert check_image(edge, max_value=PHOTO_MAX, min_value=PHOTO_MIN) is edge


def test_a_psf_needs_both_sides_odd_and_a_sum_above_zero():
    """A 3 x 4 kernel has no centre sample, and one that sums to zero cannot be
    normalised (it came out all NaN or infinite)."""
    with pytest.raises(InputError, match=r"odd sides, got shape \(3, 4\)"):
        check_psf(np.ones((3, 4)))
    with pytest.raises(InputError, match="positive finite sum, got 0"):
        check_psf(np.array([[1.0, -1.0, 0.0]]))
