"""Properties of the Wiener deconvolution (gyrodeblur.wiener)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from gyrodeblur.errors import InputError
from gyrodeblur.fftutils import convolve_fft, psf_to_otf, smooth_periodic_pad
from gyrodeblur.wiener import (
    apply_spectral_filter,
    normalize_range,
    wiener_deconvolve,
    wiener_fft_shape,
    wiener_filter,
)


def _texture(shape, seed=0):
    """Non-periodic test scene: smooth texture, hard steps, a ramp; values in [0.1, 0.9]."""
    rng = np.random.default_rng(seed)
    h, w = shape[:2]
    noise = ndimage.gaussian_filter(rng.random(shape), sigma=(1.5, 1.5) + (0,) * (len(shape) - 2))
    noise = (noise - noise.min()) / (noise.max() - noise.min())
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    ramp = (0.6 * yy + 0.4 * xx)
    steps = ((np.arange(w)[None, :] // 12 + np.arange(h)[:, None] // 16) % 2).astype(float)
    if len(shape) == 3:
        ramp, steps = ramp[..., None], steps[..., None]
    img = 0.35 * noise + 0.3 * steps + 0.35 * ramp
    return (0.1 + 0.8 * (img - img.min()) / (img.max() - img.min())).astype(np.float32)


def _shift_blur(image, shifts):
    """Independent forward model: average of copies shifted by ``shifts`` (dy, dx).

    ``ndimage.shift(u, s)(x) = u(x - s)``, i.e. content moves by ``+s``, which is a PSF with
    mass at offset ``+s``. Borders replicate the edge pixel (not periodic).
    """
    acc = np.zeros(image.shape, np.float64)
    for s in shifts:
        full = tuple(s) + (0,) * (image.ndim - 2)
        acc += ndimage.shift(image.astype(np.float64), full, order=1, mode="nearest")
    return (acc / len(shifts)).astype(np.float32)


def _line_psf(shifts, size):
    """PSF matching :func:`_shift_blur`: bilinear splat of every shift, centred."""
    psf = np.zeros((size, size))
    c = size // 2
    for dy, dx in shifts:
        y0, x0 = int(np.floor(dy)), int(np.floor(dx))
        fy, fx = dy - y0, dx - x0
        for oy, wy in ((0, 1 - fy), (1, fy)):
            for ox, wx in ((0, 1 - fx), (1, fx)):
                if wy * wx > 0:
                    psf[c + y0 + oy, c + x0 + ox] += wy * wx
    return psf / psf.sum()


def _psnr(a, b, border=0):
    sl = (slice(border, a.shape[0] - border), slice(border, a.shape[1] - border))
    mse = np.mean((a[sl].astype(np.float64) - b[sl]) ** 2)
    return 10 * np.log10(1.0 / mse)


def test_delta_psf_returns_input():
    img = _texture((40, 56, 3))
    delta = np.zeros((5, 5))
    delta[2, 2] = 1
    out = wiener_deconvolve(img, delta, phi=1e-6)
    np.testing.assert_allclose(out, img, atol=1e-4)


def test_delta_psf_default_phi_scales_contrast_only():
    # Eq. 6.18 with H = 1: every non-DC frequency is scaled by 1/(1+phi); DC is kept.
    img = _texture((40, 56))
    delta = np.ones((1, 1))
    out = wiener_deconvolve(img, delta, phi=0.01, taper=False)
    mean = img.mean(dtype=np.float64)
    np.testing.assert_allclose(out, mean + (img - mean) / 1.01, atol=1e-5)


@pytest.mark.parametrize("taper", [True, False])
def test_flat_image_stays_flat(taper):
    img = np.full((33, 47, 3), 0.37, np.float32)
    psf = _line_psf([(0.3 * t, t) for t in np.linspace(-5, 5, 21)], 13)
    out = wiener_deconvolve(img, psf, taper=taper)
    np.testing.assert_allclose(out, 0.37, atol=1e-5)


def test_dc_bin_of_filter_is_inverse_gain():
    psf = _line_psf([(0.5 * t, t) for t in range(0, 4)], 9)      # one-sided: H is complex
    filt = wiener_filter(psf_to_otf(psf, (32, 32)), 0.01)
    assert filt.dtype == np.complex64
    assert filt[0, 0] == pytest.approx(1.0, abs=1e-6)
    # Elsewhere it is the chapter's formula.
    otf = psf_to_otf(psf, (32, 32))
    expect = np.conj(otf) / (np.abs(otf) ** 2 + 0.01)
    np.testing.assert_allclose(filt.ravel()[1:], expect.ravel()[1:], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("shifts", [
    [(0, t) for t in range(-4, 5)],                              # horizontal, integer
    [(0.45 * t, 0.9 * t) for t in np.linspace(-5, 5, 21)],       # diagonal, sub-pixel
    [(0, t) for t in range(0, 7)],                               # one-sided stroke
    [(2.5 * np.sin(t), 0.8 * t) for t in np.linspace(0, 6, 25)],  # curved, one-sided
])
def test_restores_better_than_blurred(shifts):
    sharp = _texture((96, 128, 3), seed=1)
    blurred = _shift_blur(sharp, shifts)
    psf = _line_psf(shifts, 15)
    out = wiener_deconvolve(blurred, psf, phi=0.002)
    gain = _psnr(out, sharp, border=8) - _psnr(blurred, sharp, border=8)
    assert gain > 3.0, gain


def test_a_one_sided_blur_is_undone_only_the_right_way_round():
    """The kernel turned 180 degrees (convolution taken for correlation, or the filter's
    conjugate dropped) makes a one-sided stroke worse than the blurred photo."""
    sharp = _texture((96, 128, 3), seed=1)
    shifts = [(0, t) for t in range(0, 7)]
    blurred = _shift_blur(sharp, shifts)
    psf = _line_psf(shifts, 15)
    right = _psnr(wiener_deconvolve(blurred, psf, phi=0.002), sharp, border=8)
    turned = _psnr(wiener_deconvolve(blurred, psf[::-1, ::-1].copy(), phi=0.002), sharp, border=8)
    assert right > _psnr(blurred, sharp, border=8) + 5 > turned + 5, (right, turned)


def test_taper_reduces_border_error():
    sharp = _texture((90, 120), seed=2)  # ramp + steps: strongly non-periodic
    shifts = [(0.5 * t, t) for t in range(-6, 7)]
    blurred = _shift_blur(sharp, shifts)
    psf = _line_psf(shifts, 15)
    band = np.zeros(sharp.shape, bool)
    band[:12], band[-12:], band[:, :12], band[:, -12:] = True, True, True, True

    def border_rmse(out):
        return float(np.sqrt(np.mean((out[band] - sharp[band]) ** 2)))

    tapered = border_rmse(wiener_deconvolve(blurred, psf, phi=0.005, taper=True))
    periodic = border_rmse(wiener_deconvolve(blurred, psf, phi=0.005, taper=False))
    assert tapered < 0.6 * periodic, (tapered, periodic)


@pytest.mark.parametrize("shape", [(30, 41), (30, 41, 3), (30, 41, 1)])
def test_shapes_and_float32(shape):
    img = _texture(shape)
    psf = _line_psf([(0, t) for t in range(-2, 3)], 5)
    out = wiener_deconvolve(img, psf)
    assert out.shape == img.shape
    assert out.dtype == np.float32
    assert out.flags.c_contiguous


def test_float64_input_gives_float32_and_same_values():
    img = _texture((30, 41, 3))
    psf = _line_psf([(t, 0) for t in range(-2, 3)], 7)
    out64 = wiener_deconvolve(img.astype(np.float64), psf)
    assert out64.dtype == np.float32
    np.testing.assert_array_equal(out64, wiener_deconvolve(img, psf))


def test_channels_are_independent():
    img = _texture((30, 41, 3))
    psf = _line_psf([(t, t) for t in range(-2, 3)], 7)
    out = wiener_deconvolve(img, psf)
    for c in range(3):
        np.testing.assert_allclose(out[..., c], wiener_deconvolve(img[..., c], psf), atol=1e-6)


def test_fft_shape_is_padded_by_psf_size():
    assert wiener_fft_shape((100, 130, 3), (31, 21), taper=False) == (100, 130)
    fy, fx = wiener_fft_shape((100, 130, 3), (31, 21))
    assert fy >= 131 and fx >= 151


def test_apply_spectral_filter_matches_entry_point():
    img = _texture((30, 41, 3))
    psf = _line_psf([(0, t) for t in range(-3, 4)], 7)
    filt = wiener_filter(psf_to_otf(psf / psf.sum(), (30, 41)), 0.01)
    out = apply_spectral_filter(img, filt)
    np.testing.assert_allclose(out, wiener_deconvolve(img, psf, taper=False), atol=1e-6)
    with pytest.raises(ValueError):
        apply_spectral_filter(img, filt[:, :-1])


def test_psf_normalised_to_unit_sum():
    img = _texture((30, 41))
    psf = _line_psf([(0, t) for t in range(-3, 4)], 7)
    np.testing.assert_allclose(wiener_deconvolve(img, 5 * psf), wiener_deconvolve(img, psf),
                               atol=1e-6)


def test_normalize_clips_outliers_and_maps_to_input_range():
    img = _texture((64, 80, 3), seed=3)
    shifts = [(0, t) for t in range(-5, 6)]
    blurred = _shift_blur(img, shifts)
    raw = wiener_deconvolve(blurred, _line_psf(shifts, 13), phi=0.001)
    out = wiener_deconvolve(blurred, _line_psf(shifts, 13), phi=0.001, normalize=True)
    assert out.dtype == np.float32
    assert out.min() == pytest.approx(blurred.min(), abs=1e-6)
    assert out.max() == pytest.approx(blurred.max(), abs=1e-6)
    lo, hi = np.percentile(raw, (0.1, 99.9))
    gain = (blurred.max() - blurred.min()) / (hi - lo)
    expect = blurred.min() + (np.clip(raw, lo, hi) - lo) * gain
    np.testing.assert_allclose(out, expect, atol=1e-5)
    # Flat result: only clipped, never divided by zero.
    flat = np.full((8, 8), 0.5, np.float32)
    np.testing.assert_array_equal(normalize_range(flat, flat), flat)


@pytest.mark.parametrize("phi", [0, -0.1, float("nan"), float("inf"), "0.01", True])
def test_bad_phi_raises_input_error(phi):
    with pytest.raises(InputError, match="^phi: "):
        wiener_deconvolve(np.zeros((8, 8), np.float32), np.ones((3, 3)), phi=phi)


@pytest.mark.parametrize("psf", [np.ones((4, 3)), np.ones((3,)), np.zeros((3, 3)),
                                 np.full((3, 3), np.nan)])
def test_bad_psf_raises(psf):
    with pytest.raises(ValueError):
        wiener_deconvolve(np.zeros((8, 8), np.float32), psf)


def test_bad_image_raises():
    with pytest.raises(ValueError):
        wiener_deconvolve(np.zeros((2, 8, 8, 3), np.float32), np.ones((3, 3)))


@pytest.mark.parametrize("psf_shape, fft_shape", [((31, 31), (720, 720)), ((5, 9), (33, 48)),
                                                  ((1, 1), (8, 9)), ((15, 3), (15, 7)),
                                                  ((131, 5), (160, 40))])
def test_psf_to_otf_matches_a_padded_fft(psf_shape, fft_shape):
    """Against the definition: the PSF zero-padded, its centre rolled to (0, 0), rfft2."""
    psf = np.random.default_rng(0).random(psf_shape).astype(np.float32)
    psf /= psf.sum()
    padded = np.zeros(fft_shape)
    padded[:psf_shape[0], :psf_shape[1]] = psf
    padded = np.roll(padded, (-(psf_shape[0] // 2), -(psf_shape[1] // 2)), axis=(0, 1))
    otf = psf_to_otf(psf, fft_shape)
    assert otf.dtype == np.complex64 and otf.shape == (fft_shape[0], fft_shape[1] // 2 + 1)
    np.testing.assert_allclose(otf, np.fft.rfft2(padded), atol=2e-6)


def test_convolution_moves_content_by_the_psfs_offset_in_every_channel():
    """Convention (module docstring): a PSF whose mass sits at offset ``+d`` from its centre
    moves content by ``+d`` (circularly); a colour image is convolved channel by channel,
    exactly as each channel alone."""
    rng = np.random.default_rng(0)
    img = rng.random((12, 17, 3)).astype(np.float32)
    psf = np.zeros((5, 7), np.float32)
    psf[2 + 1, 3 + 2] = 1.0                      # offset (+1 row, +2 columns)
    want = np.roll(img, (1, 2), axis=(0, 1))
    np.testing.assert_allclose(convolve_fft(img, psf), want, atol=1e-6)
    np.testing.assert_allclose(convolve_fft(img[..., 1], psf), want[..., 1], atol=1e-6)
    blur = rng.random((5, 7)).astype(np.float32)
    colour = convolve_fft(img, blur)
    for c in range(3):
        np.testing.assert_allclose(colour[..., c], convolve_fft(img[..., c], blur), atol=1e-6)


def test_smooth_padding_commutes_with_flipping_the_image():
    """The added band cross-fades from a mirror of the far border into a mirror of the near
    one (weights symmetric about its middle), so padding a flipped image gives the flipped
    periodic signal: the band of the flipped image is the padded band flipped, along each
    axis, and the image keeps its place."""
    rng = np.random.default_rng(1)
    img = rng.random((9, 11, 2)).astype(np.float32)
    shape = (16, 19)
    out = smooth_periodic_pad(img, shape)
    assert out.shape == shape + (2,) and out.dtype == np.float32
    np.testing.assert_array_equal(out[:9, :11], img)
    for axis, n in ((0, 9), (1, 11)):
        flipped = smooth_periodic_pad(np.flip(img, axis), shape)
        band = np.take(out, np.arange(n, shape[axis]), axis=axis)
        fband = np.take(flipped, np.arange(n, shape[axis]), axis=axis)
        np.testing.assert_allclose(fband, np.flip(band, axis), atol=1e-6)
    # first and last added samples sit next to the border they continue
    np.testing.assert_allclose(out[9, :11], img[8], atol=0.05)
    np.testing.assert_allclose(out[-1, :11], img[0], atol=0.05)


def test_shapes_that_do_not_fit_are_refused():
    with pytest.raises(ValueError, match="shorter than the image"):
        smooth_periodic_pad(np.zeros((8, 8), np.float32), (7, 10))
    with pytest.raises(ValueError, match="shorter than the image"):
        smooth_periodic_pad(np.zeros((8, 8), np.float32), (10, 7))
    for shape in ((4, 9), (9, 4)):
        with pytest.raises(ValueError, match="does not fit"):
            psf_to_otf(np.ones((5, 5)) / 25, shape)


def test_a_photos_phi_is_the_chapters_unless_its_noise_asks_for_more():
    """``photo_phi``: 0.01 for a clean photo and a flat one; for a noisy photo three
    times its noise-to-signal ratio, the noise measured on the photo itself."""
    from gyrodeblur.wiener import DEFAULT_PHI, PHOTO_PHI_FACTOR, photo_phi

    clean = _texture((96, 128))
    assert photo_phi(clean) == DEFAULT_PHI
    assert photo_phi(np.full((32, 32), 0.4, np.float32)) == DEFAULT_PHI
    rng = np.random.default_rng(3)
    sigma = 0.05
    noisy = (clean + rng.normal(0.0, sigma, clean.shape)).astype(np.float32)
    expected = PHOTO_PHI_FACTOR * sigma ** 2 / float(np.var(noisy))
    assert expected > 5 * DEFAULT_PHI
    assert photo_phi(noisy) == pytest.approx(expected, rel=0.15)


def test_the_fft_threads_follow_a_cap_or_affinity_set_after_import(monkeypatch):
    """The FFTs' threads, the row bands and the patches' threads are counted at each call,
    not once at import: a process pool's initializer that sets ``GYRODEBLUR_THREADS`` (or
    the affinity) after the worker imported gyrodeblur is obeyed."""
    import os

    import scipy.fft as sfft

    from gyrodeblur.bands import for_row_bands
    from gyrodeblur.fftutils import THREADS_ENV

    asked = []
    real = sfft.rfft2

    def spy(*args, workers=None, **kwargs):
        asked.append(workers)
        return real(*args, workers=workers, **kwargs)

    monkeypatch.setattr(sfft, "rfft2", spy)
    image = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    psf = np.zeros((3, 3), np.float32)
    psf[1, 1] = 1.0
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2}, raising=False)
    for cap, want in (("", 3), ("1", 1), ("2", 2)):
        monkeypatch.setenv(THREADS_ENV, cap)
        asked.clear()
        convolve_fft(image, psf)
        wiener_deconvolve(image, psf, phi=0.01)
        assert want in asked and set(asked) <= {1, want}, (cap, asked)  # an OTF's: 1
        bands = []
        for_row_bands(lambda r0, r1: bands.append((r0, r1)), 9, min_rows=1)
        assert len(bands) == want, (cap, bands)


def test_the_fft_threads_are_the_cpus_this_process_may_use(monkeypatch):
    """``usable_cpus`` counts the CPUs of the process's affinity mask (``taskset``, a
    container's cpuset), not the machine's cores: a process held to 2 of 64 cores must not
    start 64 FFT threads. Without an affinity mask (not Linux) the machine's count, and
    one CPU when that is unknown. ``GYRODEBLUR_THREADS`` caps the count (several
    processes at once); a value that is not a whole number >= 1 is ignored, with a
    warning."""
    import os

    from gyrodeblur.fftutils import THREADS_ENV, usable_cpus
    monkeypatch.delenv(THREADS_ENV, raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3, 5, 7}, raising=False)
    assert usable_cpus() == 3
    monkeypatch.setenv(THREADS_ENV, "2")
    assert usable_cpus() == 2
    monkeypatch.setenv(THREADS_ENV, "8")
    assert usable_cpus() == 3                       # a cap, not a count
    import warnings

    import gyrodeblur.fftutils as fftutils
    monkeypatch.setattr(fftutils, "_SAID_BAD_CAPS", set())
    for bad in ("0", "two", "-1", "1.5"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.warns(UserWarning, match=f"GYRODEBLUR_THREADS={bad!r} is not a whole"):
            assert usable_cpus() == 3
        with warnings.catch_warnings():     # read at every call, said once a value
            warnings.simplefilter("error")
            assert usable_cpus() == 3
    monkeypatch.delenv(THREADS_ENV)
    monkeypatch.delattr(os, "sched_getaffinity")
    assert usable_cpus() == 64
    monkeypatch.setattr(os, "cpu_count", lambda: None)
    assert usable_cpus() == 1
    monkeypatch.undo()
    if hasattr(os, "sched_setaffinity"):        # a process held to one CPU, from its start
        import subprocess
        import sys
        code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
                "from gyrodeblur.fftutils import usable_cpus; print(usable_cpus())")
        env = {k: v for k, v in os.environ.items() if k != THREADS_ENV}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True, env=env)
        assert out.stdout.strip() == "1"
