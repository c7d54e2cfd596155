"""Pinhole camera in the OpenCV frame (+x right, +y down, +z forward; metres).

Pixel (u, v) (column, row, from 0) sits at image coordinate (u, v): the pixel centre,
as in OpenCV and the NeRF path. Mitsuba's film puts pixel u's centre at u + 0.5; the
sensor built here compensates with the principal-point offset so that a 3D point
lands on the pixel that ``K`` predicts.
"""

from __future__ import annotations

import numpy as np

__all__ = ["intrinsics", "scale_intrinsics", "project", "pixel_rays", "sphere_silhouette",
           "mitsuba_sensor"]


def intrinsics(width: int, height: int, fov_x_deg: float) -> np.ndarray:
    """3x3 ``K`` with square pixels, principal point at the image centre.

    The centre is ((W - 1) / 2, (H - 1) / 2) in the pixel-centre convention.
    """
    fx = 0.5 * width / np.tan(0.5 * np.radians(fov_x_deg))
    return np.array([[fx, 0.0, (width - 1) / 2.0],
                     [0.0, fx, (height - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def scale_intrinsics(K: np.ndarray, scale: float) -> np.ndarray:
    """``K`` of the image resized by ``scale`` (both axes; ``cv2.resize`` with
    ``fx = fy = scale``): fx, fy and the skew times ``scale``, and the principal point
    mapped with the pixel-centre convention, ``c' = (c + 0.5) scale - 0.5`` (pixel u
    spans [u - 0.5, u + 0.5], so the image's edge -0.5 stays at -0.5)."""
    s = float(scale)
    S = np.array([[s, 0.0, 0.5 * (s - 1.0)], [0.0, s, 0.5 * (s - 1.0)], [0.0, 0.0, 1.0]])
    return S @ np.asarray(K, dtype=np.float64)


def project(K: np.ndarray, X: np.ndarray, z=None) -> np.ndarray:
    """Project camera-frame points ``X`` (..., 3) in metres to pixels (..., 2).

    ``u = (fx x + skew y) / z + cx``, ``v = fy y / z + cy``. ``z`` (broadcast against
    ``X[..., 2]``) is the points' depth when it is known exactly, e.g. a depth plane's
    that the points were put on; by default ``X[..., 2]``.
    """
    X = np.asarray(X, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    z = X[..., 2] if z is None else z
    u = (K[0, 0] * X[..., 0] + K[0, 1] * X[..., 1]) / z + K[0, 2]
    v = K[1, 1] * X[..., 1] / z + K[1, 2]
    return np.stack([u, v], axis=-1)


def pixel_rays(K: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit directions (..., 3), camera frame, of the rays through pixels (u, v)."""
    Kinv = np.linalg.inv(np.asarray(K, dtype=np.float64))
    uv1 = np.stack([np.asarray(u, float), np.asarray(v, float), np.ones(np.shape(u))], -1)
    d = uv1 @ Kinv.T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def sphere_silhouette(center, radius: float, K: np.ndarray,
                      shape: tuple[int, int]) -> np.ndarray:
    """Pixels covered by a sphere's image: (H, W) bool.

    A pixel is inside when its centre's ray makes an angle < asin(R / |P|) with the
    direction of the centre P (camera frame, metres); the whole image when the camera
    is inside the sphere.
    """
    H, W = shape
    P = np.asarray(center, dtype=np.float64)
    dist = np.linalg.norm(P)
    if dist <= radius:
        return np.ones((H, W), bool)
    v, u = np.mgrid[0:H, 0:W]
    d = pixel_rays(K, u, v)
    cos_half = np.sqrt(1.0 - (radius / dist) ** 2)
    return d @ (P / dist) > cos_half


def mitsuba_sensor(K: np.ndarray, width: int, height: int, spp: int = 16,
                   filter_type: str = "box") -> dict:
    """A Mitsuba ``perspective`` sensor dict that images like ``K`` (OpenCV frame).

    Assumes square pixels (fx == fy). Mitsuba looks down +z with up -y, which makes
    its world frame the OpenCV camera frame.
    """
    from scenes import backend

    mi = backend.modules()[1]
    K = np.asarray(K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if abs(fx - fy) > 1e-6 * fx:
        raise ValueError("mitsuba_sensor needs square pixels (fx == fy)")
    fov = np.degrees(2.0 * np.arctan(width / (2.0 * fx)))
    return {
        "type": "perspective",
        "fov": float(fov),
        "fov_axis": "x",
        "principal_point_offset_x": float(-(cx + 0.5 - width / 2.0) / width),
        "principal_point_offset_y": float(-(cy + 0.5 - height / 2.0) / height),
        "near_clip": 0.01,
        "far_clip": 1000.0,
        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1],
                                                   up=[0, -1, 0]),
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                 "rfilter": {"type": filter_type}, "pixel_format": "rgb"},
    }
