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
