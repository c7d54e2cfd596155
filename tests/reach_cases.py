"""A wall 4 m ahead, a small box and two totems in the camera frame (OpenCV, metres): the
hand-built scene whose truth's reach each renderer traces (Mitsuba in tests/test_reach.py,
Blender in tests/test_cycles_reach.py), the hand computations and the checks each trace
passes."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import camera
from scenes.reach import MIN_PARALLAX

W, H = 200, 150
K = camera.intrinsics(W, H, 60)
P1, P2 = np.array([-0.4, 0.0, 1.5]), np.array([0.4, 0.0, 1.5])
R, ETA = 0.1, 1.5
WALL_Z = 4.0
BOX_C, BOX_H = np.array([-0.4, -0.3, 2.2]), 0.1     # a cube's centre and half side


def pixel(X) -> tuple[int, int]:
    """The pixel (u, v) nearest the image of camera-frame point ``X``."""
    return tuple(np.rint(camera.project(K, np.asarray(X, float)[None])[0]).astype(int))


def on_wall(u, v) -> np.ndarray:
    """The point of the plane z = WALL_Z that pixel (u, v)'s centre sees."""
    d = camera.pixel_rays(K, np.float64(u), np.float64(v))
    return d * WALL_Z / d[2]


def angle(X) -> float:
    """The angle at X between the two totems' centres."""
    a, b = P1 - X, P2 - X
    return float(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))


def crosses(a, b, centre=BOX_C, half=BOX_H) -> bool:
    """Does the segment a-b pass through the axis-aligned cube (slab test; by default
    the box)?"""
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (centre - half - a) / d, (centre + half - a) / d
    lo, hi = np.nanmax(np.minimum(t0, t1)), np.nanmin(np.maximum(t0, t1))
    return bool(lo <= hi and hi >= 0 and lo <= 1)


def check_wall_both_see(reach) -> None:
    """A wall point two totems see, no box between: in the reach, at its depth and at
    the parallax of the totems' centres in their mean spacing."""
    u, v = pixel([-0.3, 0.3, WALL_Z])
    X = on_wall(u, v)
    assert not crosses(P1, X) and not crosses(P2, X)
    assert reach.n_totems[v, u] == 2
    assert reach.depth[v, u] == pytest.approx(WALL_Z, rel=1e-5)
    assert reach.parallax[v, u] == pytest.approx(angle(X) / reach.spacing.mean(), rel=1e-4)
    assert reach.parallax[v, u] >= MIN_PARALLAX and reach.in_reach()[v, u]


def check_box_hides_from_one(reach) -> None:
    """The box's shadow from the left totem on the wall, which the camera sees: one
    totem sees it, out of the reach."""
    X = P1 + (BOX_C - P1) * (WALL_Z - P1[2]) / (BOX_C[2] - P1[2])
    assert crosses(P1, X) and not crosses(P2, X)
    assert not crosses(np.zeros(3), X)
    u, v = pixel(X)
    assert reach.depth[v, u] == pytest.approx(WALL_Z, rel=1e-5)
    assert reach.n_totems[v, u] == 1 and not reach.in_reach()[v, u]
