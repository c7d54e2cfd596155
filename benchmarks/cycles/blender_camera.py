"""Blender's camera as the contract's pinhole (``docs/contract.md``, "Frames and units").

Pure numpy, imported by the Cycles generator (inside ``.venv-cycles``) and by the
converter and tests (the package's venv), so both sides agree on one conversion.

Blender: a camera looks down its local -Z with +Y up and +X right; ``matrix_world`` maps
camera to world (metres); the sensor's size (mm) and ``shift_x``/``shift_y`` (fractions)
apply to the larger image side under ``sensor_fit`` AUTO (the width for HORIZONTAL, the
height for VERTICAL); a positive shift moves the view right / up. Pixel (u, v), u from the
left, v from the top, is sampled around film coordinate (u + 0.5, v + 0.5): the contract's
pixel centre (u, v) is half a pixel before it, as with Mitsuba's film.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FLIP", "opencv_from_blender", "blender_from_opencv", "look_matrix"]

# OpenCV camera axes from Blender's: x kept, y and z reversed (y down, z forward).
FLIP = np.diag([1.0, -1.0, -1.0])


def _fit_side(width: int, height: int, sensor_fit: str, sensor_width: float,
              sensor_height: float) -> tuple[float, float]:
    """(sensor size in mm, image size in px) of the side the sensor is fitted to."""
    fit = sensor_fit.upper()
    if fit == "AUTO":
        return sensor_width, float(max(width, height))
    if fit == "HORIZONTAL":
        return sensor_width, float(width)
    if fit == "VERTICAL":
        return sensor_height, float(height)
    raise ValueError(f"unknown sensor_fit {sensor_fit!r}")


def opencv_from_blender(*, width: int, height: int, lens: float,
                        sensor_width: float = 36.0, sensor_height: float = 24.0,
                        sensor_fit: str = "AUTO",
                        shift_x: float = 0.0, shift_y: float = 0.0,
                        matrix_world) -> tuple[np.ndarray, np.ndarray]:
    """The contract's ``K`` (3x3, pixels) and world-to-camera (4x4, OpenCV camera frame,
    metres) of a Blender perspective camera with square pixels.

    ``lens`` and the sensor sizes in mm; ``matrix_world`` (4x4) camera-to-world, rigid.
    """
    M = np.asarray(matrix_world, dtype=np.float64).reshape(4, 4)
    R = M[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("matrix_world must be a rotation and a translation (no scale)")
    sensor, side = _fit_side(width, height, sensor_fit, sensor_width, sensor_height)
    f = lens / sensor * side
    cx = (width - 1) / 2.0 - shift_x * side
    cy = (height - 1) / 2.0 + shift_y * side
    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    w2c = np.eye(4)
    w2c[:3, :3] = FLIP @ R.T
    w2c[:3, 3] = -FLIP @ R.T @ M[:3, 3]
    return K, w2c


def blender_from_opencv(K, world_to_camera, *, width: int, height: int,
                        sensor_width: float = 36.0) -> dict:
    """The Blender camera (sensor_fit AUTO) that images like ``K`` and
    ``world_to_camera``: ``lens`` (mm), ``sensor_width`` (mm), ``shift_x``, ``shift_y``,
    ``matrix_world`` (4x4 list). Needs square pixels (fx == fy) and no skew."""
    K = np.asarray(K, dtype=np.float64)
    if abs(K[0, 0] - K[1, 1]) > 1e-9 * K[0, 0] or abs(K[0, 1]) > 1e-12:
        raise ValueError("Blender's camera needs square pixels and no skew")
    side = float(max(width, height))
    T = np.asarray(world_to_camera, dtype=np.float64)
    R_cv, t_cv = T[:3, :3], T[:3, 3]
    R = (FLIP @ R_cv).T                      # camera-to-world rotation, Blender axes
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = -R_cv.T @ t_cv
    return {"lens": float(K[0, 0] * sensor_width / side), "sensor_width": sensor_width,
            "sensor_fit": "AUTO",
            "shift_x": float(((width - 1) / 2.0 - K[0, 2]) / side),
            "shift_y": float((K[1, 2] - (height - 1) / 2.0) / side),
            "matrix_world": M.tolist()}


def look_matrix(location, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Camera-to-world (4x4, Blender axes, world +Z up) of a level camera at ``location``
    turned ``yaw_deg`` from +Y towards +X and tilted ``pitch_deg`` down."""
    yaw, pitch = np.radians(yaw_deg), np.radians(pitch_deg)
    fwd = np.array([np.cos(pitch) * np.sin(yaw), np.cos(pitch) * np.cos(yaw),
                    -np.sin(pitch)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = right, up, -fwd, location
    return M
