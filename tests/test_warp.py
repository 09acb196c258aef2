"""The alignment warp (:mod:`gyrodeblur.warp`): against a plain reference, in tiles and
beyond OpenCV's size limit, beside clipped lights, and its bilinear sample map."""

from __future__ import annotations

import numpy as np
import pytest


def _reference_warp(image, displacement):
    """The warp written plainly: whole-image sample positions, a quintic B-spline per
    channel in float64 (sharper than any interpolation the warp may use)."""
    from scipy import ndimage

    ys, xs, d = displacement
    H, W = image.shape[:2]
    gy = np.arange(H) * (len(ys) - 1) / ys[-1]
    gx = np.arange(W) * (len(xs) - 1) / xs[-1]
    grid = np.stack(np.meshgrid(gy, gx, indexing="ij"))
    coords = np.stack([np.arange(H)[:, None] + ndimage.map_coordinates(d[..., 1], grid, order=1),
                       np.arange(W)[None, :] + ndimage.map_coordinates(d[..., 0], grid, order=1)])
    return np.stack([ndimage.map_coordinates(image[..., c].astype(np.float64), coords, order=5,
                                             mode="mirror") for c in range(image.shape[2])], -1)


@pytest.mark.parametrize("channels", [3, 1, 5])
def test_alignment_warp_matches_a_plain_one_across_bands(monkeypatch, channels):
    from scipy import ndimage

    import gyrodeblur.warp as wp

    rng = np.random.default_rng(3)
    img = ndimage.gaussian_filter(rng.random((300, 410, channels)), (1.5, 1.5, 0)).astype(np.float32)
    field = (np.linspace(0, 299, 5), np.linspace(0, 409, 6), rng.normal(0, 4, (5, 6, 2)))
    ref = _reference_warp(img, field)
    whole = wp.warp_by_displacement(img, field)
    monkeypatch.setattr(wp, "_WARP_TILE", (128, 96))  # 3 x 5 tiles, the last ones short
    out = wp.warp_by_displacement(img, field)
    # the same samples (bit-exact on noise: test_alignment_warp_in_tiles_is_the_whole_warp_
    # to_the_bit); the margin allows a remap whose rounding to its 1/32 px grid depended on
    # the tile's origin (a rare sample a step over: ~3e-3 at a slope of ~0.1 per px)
    assert np.abs(out - whole).max() < 5e-3 and np.abs(out - whole).mean() < 1e-5
    assert out.dtype == np.float32 and out.shape == img.shape
    err = np.abs(out - ref)[8:-8, 8:-8]   # mirrored borders: the reference mirrors exactly
    assert err.max() < 0.004 and np.sqrt((err ** 2).mean()) < 6e-4  # bicubic: 0.0056, 0.0012
    if channels == 1:
        np.testing.assert_array_equal(wp.warp_by_displacement(img[..., 0], field), out[..., 0])
    # moved the right way: content at x + c(x) lands on x
    assert np.sqrt(((out - img) ** 2).mean()) > 10 * np.sqrt((err ** 2).mean())


def test_alignment_warp_takes_photos_wider_than_opencv_remap_does():
    from gyrodeblur.warp import warp_by_displacement

    W = 33000                                      # remap alone stops at 32767 px
    img = np.tile(np.sin(np.arange(W) / 7.0).astype(np.float32), (6, 1))
    field = (np.array([0.0, 5.0]), np.array([0.0, W - 1.0]), np.tile([2.0, 0.0], (2, 2, 1)))
    out = warp_by_displacement(img, field)          # every pixel samples x + 2
    np.testing.assert_allclose(out[:, :-2], img[:, 2:], atol=1e-5)
    np.testing.assert_allclose(out[:, -2:], img[:, -3:-1][:, ::-1], atol=1e-5)  # W -> W - 2


def test_alignment_warp_keeps_clipped_plateaus_clipped():
    """A clipped block moved by a sub-pixel warp stays one flat block at the clip value
    (Lanczos lobes would leave its rim below it, and the deconvolution would no longer
    see one clipped streak), with no dark halo of undershoot beside it if it is small
    enough to be a light; away from it the warp is the plain Lanczos one."""
    from gyrodeblur.warp import _CLIPPED_REACH, CLIPPED, warp_by_displacement

    img = np.full((64, 80, 3), 0.05, np.float32)
    img[20:34, 24:45] = 1.0
    ys, xs = np.array([0.0, 63.0]), np.array([0.0, 79.0])
    field = (ys, xs, np.tile([0.37, -0.61], (2, 2, 1)))
    block = 14 * 21
    plain = warp_by_displacement(img, field)
    kept = warp_by_displacement(img, field, clipped=CLIPPED, light_area=block)
    assert (plain[..., 0] >= CLIPPED).sum() < 0.8 * block        # the rim dips below the clip
    at_clip = kept[..., 0] >= CLIPPED
    assert abs(at_clip.sum() - block) <= 14 + 21 and np.all(kept[at_clip] == 1.0)
    assert plain.min() < 0.0                                    # Lanczos undershoots...
    assert kept.min() >= 0.05 - 1e-6                            # ...clamped, it does not
    r = _CLIPPED_REACH + 2                                      # + the sub-pixel shift
    far = np.ones((64, 80), bool)
    far[20 - r:34 + r, 24 - r:45 + r] = False
    np.testing.assert_array_equal(kept[far], plain[far])
    # a blob bigger than light_area is an ordinary edge: plain Lanczos beside it
    big = warp_by_displacement(img, field, clipped=CLIPPED, light_area=block - 1)
    np.testing.assert_array_equal(big[~at_clip], plain[~at_clip])


def test_alignment_warp_clamps_beside_a_light_at_the_frame_edge():
    """Samples that fall outside the photo beside a clipped blob at its edge are clamped
    to the range of the two pixels they mirror between (the warp mirrors the photo about
    its edge pixels), not of pixels one further in (which moved 24 of these 96 samples)."""
    from gyrodeblur.warp import CLIPPED, warp_by_displacement

    W = 80
    ramp = np.linspace(0.05, 0.6, W, dtype=np.float32) ** 2  # varies along x only
    img = np.repeat(np.tile(ramp, (64, 1))[..., None], 3, axis=2)
    img[30:33, 0:3] = 1.0                                   # a light at the left edge
    ys, xs = np.array([0.0, 63.0]), np.array([0.0, W - 1.0])
    rows = [27, 28, 34, 35]     # clamped (within 4 px of the light), ramp pixels only
    for shift in (-1.6, -0.4):  # the first columns sample left of the photo
        field = (ys, xs, np.tile([shift, 0.0], (2, 2, 1)))
        plain = warp_by_displacement(img, field, clipped=CLIPPED)
        kept = warp_by_displacement(img, field, clipped=CLIPPED, light_area=9)
        s = np.arange(8) + shift
        f = np.floor(s).astype(int)
        pair = np.abs(np.stack([f, f + 1]))                 # mirrored about pixel 0
        lo, hi = ramp[pair].min(axis=0), ramp[pair].max(axis=0)
        expected = np.clip(plain[rows][:, :8], lo[None, :, None], hi[None, :, None])
        np.testing.assert_allclose(kept[rows][:, :8], expected, atol=1e-6)


def test_alignment_warp_in_tiles_is_the_whole_warp_to_the_bit(monkeypatch):
    """Each tile reads a window of the photo wide enough for all eight Lanczos taps of its
    samples: on sharp detail (noise) the tiled warp is the whole one exactly."""
    import gyrodeblur.warp as wp

    rng = np.random.default_rng(5)
    img = rng.random((200, 230, 2)).astype(np.float32)
    field = (np.linspace(0, 199, 4), np.linspace(0, 229, 5), rng.normal(0, 3, (4, 5, 2)))
    whole = wp.warp_by_displacement(img, field)
    monkeypatch.setattr(wp, "_WARP_TILE", (64, 48))
    np.testing.assert_array_equal(wp.warp_by_displacement(img, field), whole)


def test_alignment_warp_clamps_beside_a_light_at_the_right_edge():
    """As at the left edge: samples beyond the last column are clamped to the two pixels
    they mirror between (about the last pixel)."""
    from gyrodeblur.warp import CLIPPED, warp_by_displacement

    W = 80
    ramp = np.linspace(0.05, 0.6, W, dtype=np.float32) ** 2
    img = np.repeat(np.tile(ramp, (64, 1))[..., None], 3, axis=2)
    img[30:33, W - 3:] = 1.0                                # a light at the right edge
    ys, xs = np.array([0.0, 63.0]), np.array([0.0, W - 1.0])
    rows = [27, 28, 34, 35]
    for shift in (1.6, 0.4):   # the last columns sample right of the photo
        field = (ys, xs, np.tile([shift, 0.0], (2, 2, 1)))
        plain = warp_by_displacement(img, field, clipped=CLIPPED)
        kept = warp_by_displacement(img, field, clipped=CLIPPED, light_area=9)
        s = np.arange(W - 8, W) + shift
        f = np.floor(s).astype(int)
        pair = (W - 1) - np.abs((W - 1) - np.stack([f, f + 1]))  # mirrored about W - 1
        lo, hi = ramp[pair].min(axis=0), ramp[pair].max(axis=0)
        expected = np.clip(plain[rows][:, -8:], lo[None, :, None], hi[None, :, None])
        np.testing.assert_allclose(kept[rows][:, -8:], expected, atol=1e-6)


def test_alignment_warp_clipping_rules():
    """A clipped line half a pixel off the grid comes out two pixels wide at the clip
    value; a diagonal streak is one blob (8-connected), so one longer than light_area is
    no point light; a photo with values above 1 is warped as it is."""
    from gyrodeblur.warp import CLIPPED, warp_by_displacement

    ys, xs = np.array([0.0, 39.0]), np.array([0.0, 49.0])
    img = np.full((40, 50), 0.2, np.float32)
    img[:, 20] = 1.0
    half = (ys, xs, np.tile([0.5, 0.0], (2, 2, 1)))
    out = warp_by_displacement(img, half, clipped=CLIPPED)
    np.testing.assert_array_equal(np.flatnonzero(out[20] == 1.0), [19, 20])
    diagonal = np.full((40, 50), 0.2, np.float32)
    diagonal[np.arange(10, 22), np.arange(15, 27)] = 1.0         # 12 px, corner to corner
    shift = (ys, xs, np.tile([0.37, -0.61], (2, 2, 1)))
    np.testing.assert_array_equal(
        warp_by_displacement(diagonal, shift, clipped=CLIPPED, light_area=9),
        warp_by_displacement(diagonal, shift, clipped=CLIPPED))
    bright = diagonal * 2                                        # linear, no clip ceiling
    np.testing.assert_array_equal(
        warp_by_displacement(bright, shift, clipped=CLIPPED, light_area=20),
        warp_by_displacement(bright, shift))


def test_the_alignment_grid_is_interpolated_bilinearly():
    """The warp's sample map: bilinear interpolation of the displacement grid, in a fixed
    order of two-tap sums (no matrix product, whose result depends on BLAS threads)."""
    from gyrodeblur.warp import _interpolate_grid, _linear_taps
    rng = np.random.default_rng(3)
    grid = rng.normal(0, 3, (5, 7)).astype(np.float32)
    ty, tx = np.linspace(-0.5, 4.5, 23), np.linspace(0, 6, 31)     # clamped at the ends
    got = _interpolate_grid(grid, _linear_taps(ty, 5), _linear_taps(tx, 7))
    from scipy.interpolate import RegularGridInterpolator
    ref = RegularGridInterpolator((np.arange(5), np.arange(7)), grid.astype(np.float64))
    yy, xx = np.meshgrid(np.clip(ty, 0, 4), tx, indexing="ij")
    np.testing.assert_allclose(got, ref((yy, xx)), atol=1e-5)
    one = _interpolate_grid(grid[:1, :1], _linear_taps(ty, 1), _linear_taps(tx, 1))
    np.testing.assert_array_equal(one, np.full((23, 31), grid[0, 0]))


def test_alignment_warp_refuses_what_is_not_a_photo_and_its_field():
    """An 8-bit photo came back scaled 0-255, a NaN pixel or displacement spread NaN or
    stopped inside OpenCV, and another frame's field warped the photo as if it fitted."""
    from gyrodeblur.errors import InputError
    from gyrodeblur.warp import warp_by_displacement

    rng = np.random.default_rng(3)
    img = rng.random((60, 80, 3)).astype(np.float32)
    field = (np.linspace(0, 59, 4), np.linspace(0, 79, 5), rng.normal(0, 2, (4, 5, 2)))
    assert warp_by_displacement(img, field).shape == img.shape
    with pytest.raises(InputError, match="image must hold floating-point values"):
        warp_by_displacement((img * 255).astype(np.uint8), field)
    nan = img.copy()
    nan[3, 3, 0] = np.nan
    with pytest.raises(InputError, match="image has 1 NaN"):
        warp_by_displacement(nan, field)
    ys, xs, d = field
    with pytest.raises(ValueError, match="a field for another size of photo"):
        warp_by_displacement(img[:30, :40], field)
    for bad in ((ys, xs, d[..., :1]), (ys, xs, d * np.nan),
                (np.array([0, 10, 40, 59.0]), xs, d)):        # not evenly spaced
        with pytest.raises(ValueError, match="displacement must be a grid"):
            warp_by_displacement(img, bad)
