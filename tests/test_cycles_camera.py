"""Blender's camera as the contract's K and world-to-camera (benchmarks/cycles)."""

import numpy as np
import pytest

from benchmarks.cycles.blender_camera import (blender_from_opencv, look_matrix,
                                              opencv_from_blender)
from benchmarks.cycles.convert import sphere_masks
from scenes import camera


def _view_frame_pixel(X_world, cam):
    """Where Blender puts a world point, by its own recipe (``world_to_camera_view``):
    the point in the camera's local frame divided by its depth, placed in the camera's
    view frame at unit distance (sensor/lens wide on the fitted side, shifted by
    shift x sensor/lens), then 0..1 from the left / bottom; the pixel index is that times
    the size, minus the half pixel between film edge and pixel centre."""
    W, H = cam["width"], cam["height"]
    p = np.linalg.inv(np.asarray(cam["matrix_world"]))[:3] @ np.append(X_world, 1.0)
    x, y = p[0] / -p[2], p[1] / -p[2]
    side = cam["sensor_width"] / cam["lens"]                 # AUTO fit, W >= H
    half_w, half_h = side / 2, side / 2 * H / W
    sx, sy = cam["shift_x"] * side, cam["shift_y"] * side
    fx = (x - (sx - half_w)) / (2 * half_w)
    fy = (y - (sy - half_h)) / (2 * half_h)
    return np.array([fx * W - 0.5, (1 - fy) * H - 0.5])


def _cam(W=640, H=480, lens=28.0, shift=(0.02, -0.015), yaw=7.0, pitch=12.0):
    return {"width": W, "height": H, "lens": lens, "sensor_width": 36.0,
            "sensor_fit": "AUTO", "shift_x": shift[0], "shift_y": shift[1],
            "matrix_world": look_matrix([0.3, -0.2, 1.1], yaw, pitch).tolist()}


@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.03, -0.02), (-0.025, 0.03)])
def test_known_point_lands_on_its_pixel(shift):
    cam = _cam(shift=shift)
    K, w2c = opencv_from_blender(**cam)
    rng = np.random.default_rng(3)
    for _ in range(20):
        ahead = np.asarray(cam["matrix_world"])[:3, :3] @ [rng.uniform(-0.6, 0.6),
                                                           rng.uniform(-0.4, 0.4), -1.0]
        X = np.asarray(cam["matrix_world"])[:3, 3] + rng.uniform(1, 5) * ahead
        Xc = w2c[:3, :3] @ X + w2c[:3, 3]
        assert Xc[2] > 0                                     # OpenCV: +z forward
        np.testing.assert_allclose(camera.project(K, Xc), _view_frame_pixel(X, cam),
                                   atol=1e-9)


def test_frame_corners_are_the_image_edges():
    """The view frame's corners are the film's corners: pixel coordinates -0.5 and
    W - 0.5 (the contract's image span)."""
    cam = _cam(shift=(0.0, 0.0))
    K, _ = opencv_from_blender(**cam)
    side = cam["sensor_width"] / cam["lens"]
    ray_left_top = np.array([-side / 2, -side / 2 * 480 / 640, 1.0])   # OpenCV frame
    np.testing.assert_allclose(camera.project(K, ray_left_top), [-0.5, -0.5], atol=1e-9)


def test_round_trip():
    cam = _cam()
    K, w2c = opencv_from_blender(**cam)
    back = blender_from_opencv(K, w2c, width=640, height=480)
    for k in ("lens", "shift_x", "shift_y"):
        assert back[k] == pytest.approx(cam[k], abs=1e-12)
    np.testing.assert_allclose(back["matrix_world"], cam["matrix_world"], atol=1e-12)
    K2, w2c2 = opencv_from_blender(width=640, height=480, **back)
    np.testing.assert_allclose(K2, K, atol=1e-9)
    np.testing.assert_allclose(w2c2, w2c, atol=1e-12)


def test_sensor_fit_vertical_and_portrait():
    """VERTICAL fits the sensor height to the image height; AUTO fits the larger side."""
    M = look_matrix([0, 0, 1], 0, 0)
    K, _ = opencv_from_blender(width=480, height=640, lens=30, sensor_width=36,
                               sensor_fit="AUTO", matrix_world=M)
    assert K[0, 0] == pytest.approx(30 / 36 * 640)
    K, _ = opencv_from_blender(width=640, height=480, lens=30, sensor_height=24,
                               sensor_fit="VERTICAL", matrix_world=M)
    assert K[1, 1] == pytest.approx(30 / 24 * 480)


def test_scaled_matrix_refused():
    M = look_matrix([0, 0, 1], 0, 0)
    M[:3, :3] *= 1.1
    with pytest.raises(ValueError):
        opencv_from_blender(width=64, height=48, lens=30, matrix_world=M)


def test_sphere_mask_is_the_silhouette_cone():
    """A sphere on the axis: its mask is the disc of radius f tan(asin(R / d)) about
    the principal point (an independent formula for the silhouette cone)."""
    K = camera.intrinsics(200, 160, 60.0)
    R, d = 0.1, 1.0
    m = sphere_masks(K, [[0.0, 0.0, d]], R, (160, 200))[0]
    v, u = np.mgrid[0:160, 0:200]
    r_px = K[0, 0] * np.tan(np.arcsin(R / d))
    rr = np.hypot(u - K[0, 2], v - K[1, 2])
    assert np.all(m[rr < r_px - 1e-6]) and not np.any(m[rr > r_px + 1e-6])
