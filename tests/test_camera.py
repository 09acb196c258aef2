import numpy as np
import pytest

from gyrodeblur.camera import MAX_SIDE, Camera
from gyrodeblur.errors import InputError
from gyrodeblur.orientation import rotvec_to_matrix


def test_rays_and_projection_are_the_intrinsic_matrix_and_its_inverse():
    cam = Camera(800.0, 760.0, 319.5, 251.0, 640, 480)
    x, y = np.array([[0.0, 639.0], [100.0, 400.0]]), np.array([[0.0, 479.0], [20.0, 300.0]])
    rays = cam.rays(x, y)
    assert rays.shape == (2, 2, 3)
    homog = np.stack([x, y, np.ones_like(x)], -1)
    assert np.allclose(rays, homog @ cam.K_inv.T)
    assert np.allclose(cam.project(3.0 * rays), np.stack([x, y], -1))   # any depth
    assert np.allclose(cam.rays(cam.cx, cam.cy), [0, 0, 1])


def test_a_yaw_to_the_right_moves_the_scene_left_by_f_tan_angle():
    # the camera turns by +0.05 rad about y: a scene direction seen at the centre is then
    # at R^T ray in the new camera frame, f tan(0.05) px to the left (-x)
    cam = Camera.centred(640, 480, 700.0)
    R = rotvec_to_matrix(np.array([0.0, 0.05, 0.0]))
    moved = cam.project(R.T @ cam.rays(cam.cx, cam.cy))
    assert moved == pytest.approx([cam.cx - 700.0 * np.tan(0.05), cam.cy])


@pytest.mark.parametrize("width, problem", [(10 ** 20, "is not a sensor's"),
                                            (10 ** 400, "whole number of pixels"),
                                            (MAX_SIDE + 1, "is not a sensor's")])
def test_an_absurd_image_size_is_refused_not_overflowed(width, problem):
    """A width from a bad JSON (1e20 read as a whole number) is an InputError, not a
    TypeError from numpy on an integer beyond float64."""
    with pytest.raises(InputError, match=problem):
        Camera(100.0, 100.0, 50.0, 40.0, width, 80)
    assert Camera(100.0, 100.0, 50.0, 40.0, MAX_SIDE, 80).width == MAX_SIDE


# ------------------------------------------------ from a mutation audit (session 43)

def test_centred_puts_the_principal_point_at_the_exact_image_centre():
    """Kills C2 (``Camera.centred`` with ``c = size / 2``, half a pixel off the centre of
    the OpenCV pixel grid). The exact centre of a W x H image is ((W-1)/2, (H-1)/2), and
    a centred camera stays centred when the photo is resized (``scaled_to``)."""
    from gyrodeblur.camera import Camera

    cam = Camera.centred(640, 480, 500.0)
    assert (cam.cx, cam.cy) == (319.5, 239.5)
    np.testing.assert_array_equal(cam.rays(319.5, 239.5), [0.0, 0.0, 1.0])
    big = cam.scaled_to(1280, 960)
    ref = Camera.centred(1280, 960, 1000.0)
    assert (big.cx, big.cy, big.fx, big.fy) == pytest.approx((ref.cx, ref.cy, ref.fx, ref.fy))


def test_focal_scale_scales_the_image_of_every_direction_about_the_principal_point():
    """Kills C4 (``with_focal_scale`` scaling fx only). A longer focal length magnifies
    about the principal point, by the same factor along x and y."""
    from gyrodeblur.camera import Camera

    cam = Camera(800.0, 760.0, 319.5, 251.0, 640, 480)
    ray = np.array([0.1, -0.2, 1.0])
    d0 = cam.project(ray) - (cam.cx, cam.cy)
    d1 = cam.with_focal_scale(1.5).project(ray) - (cam.cx, cam.cy)
    np.testing.assert_allclose(d1, 1.5 * d0, rtol=1e-12)
