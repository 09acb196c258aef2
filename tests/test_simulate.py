"""Blur synthesis (warping) against PSF rendering (splatting): two independent models."""

import numpy as np
import pytest
from skimage import data, transform

from gyrodeblur.psf import render_psf
from gyrodeblur.simulate import add_noise, quantize_8bit, simulate_blur, warp_samples


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
    blurred = simulate_blur(scene, cap)
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
        monkeypatch.setattr(bands, "FFT_WORKERS", 3)      # 3 bands of 80 rows
        threaded = simulate_blur(scene, cap, order=order)
        monkeypatch.setattr(bands, "FFT_WORKERS", 1)
        single = simulate_blur(scene, cap, order=order)
        assert np.array_equal(threaded, single)
        assert np.abs(threaded - scene).max() > 0.1       # and it did blur


def test_zero_motion_is_identity(make_capture, scene):
    cap = make_capture([0, 0, 0])
    assert np.abs(simulate_blur(scene, cap) - scene).max() < 1e-5


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
                        quantize=True)
    assert np.array_equal(out[..., 3:], alpha)
    assert np.array_equal(out[..., :3], simulate_blur(scene, cap, snr_db=30, seed=2,
                                                      quantize=True))
    for bad in ({"n_samples": -3}, {"n_samples": 0}, {"n_samples": 2.5}, {"n_samples": True},
                {"snr_db": float("nan")}):
        with pytest.raises(ValueError, match=f"{next(iter(bad))} must be"):
            simulate_blur(scene, cap, **bad)
