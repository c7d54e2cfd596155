"""verify.metrics.region: the protected region lies where the totems' points project."""

import numpy as np
import pytest

from scenes.errors import BadInput
from verify.metrics import region
from verify_cases import H, K, PROTECT_BOX, W, box_mask, points_in_box


def _iou(a, b):
    return (a & b).sum() / (a | b).sum()


def test_counts_match_projection_by_hand():
    # three points whose pixels are known: (u, v) = K X / z, rounded
    X = np.array([[0.0, 0.0, 2.0], [0.5, -0.25, 2.5], [0.5, -0.25, 2.5],
                  [0.0, 0.0, -1.0],            # behind the camera: dropped
                  [50.0, 0.0, 1.0]])           # outside the image: dropped
    c = region.project_counts(X, K, (W, H))
    fx, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    assert c.sum() == 3
    assert c[int(round(cy)), int(round(cx))] == 1
    assert c[int(round(cy - fx * 0.1)), int(round(cx + fx * 0.2))] == 2


def test_region_is_where_points_project():
    pts = points_in_box(PROTECT_BOX, 6000)
    R = region.protected_region(pts, K, (W, H), 6000)
    assert _iou(R, box_mask(PROTECT_BOX)) > 0.95


def test_isolated_points_do_not_grow_the_region():
    pts = np.concatenate([points_in_box(PROTECT_BOX, 6000),
                          points_in_box((290, 200, 318, 238), 5, seed=3),
                          points_in_box((0, 200, 20, 238), 5, seed=4)])
    R = region.protected_region(pts, K, (W, H), len(pts))
    assert not R[200:, 290:].any() and not R[200:, :20].any()
    assert _iou(R, box_mask(PROTECT_BOX)) > 0.95


def test_fewer_totem_pixels_keep_the_region():
    # far totems give fewer points; the relative threshold keeps the same region,
    # where a fixed density (the paper's 10 % of a box) would lose it entirely
    many = region.protected_region(points_in_box(PROTECT_BOX, 8000), K, (W, H), 8000)
    few = region.protected_region(points_in_box(PROTECT_BOX, 1000, seed=5), K, (W, H), 1000)
    assert _iou(many, few) > 0.9
    density_of_few = 1000 / ((PROTECT_BOX[2] - PROTECT_BOX[0]) * (PROTECT_BOX[3] - PROTECT_BOX[1]))
    assert density_of_few < 0.1


def test_two_clusters_stay_apart_unless_the_paper_hull_is_asked():
    a, b = (20, 20, 80, 80), (220, 100, 300, 160)
    pts = np.concatenate([points_in_box(a, 3000), points_in_box(b, 3000, seed=1)])
    R = region.protected_region(pts, K, (W, H), 6000)
    assert R[50, 50] and R[130, 260]
    assert not R[90, 150]                  # between the clusters: not seen, not protected
    hull = region.protected_region(pts, K, (W, H), 6000, shape="hull")
    assert hull[50, 50] and hull[130, 260]
    assert hull[90, 150]                   # between the clusters, on the segment
    assert not hull[150, 40] and not hull[10, 300]   # off the hull


def test_a_ring_of_points_protects_its_inside():
    # holes are filled: a region seen all around is protected inside too
    ring = np.concatenate([points_in_box(b, 1500, seed=i) for i, b in enumerate(
        [(60, 40, 260, 70), (60, 170, 260, 200), (60, 70, 90, 170), (230, 70, 260, 170)])])
    R = region.protected_region(ring, K, (W, H), len(ring))
    assert R[120, 160] and not R[10, 10]


def test_empty_region_is_bad_input():
    behind = np.array([[0.0, 0.0, -2.0]] * 10)
    with pytest.raises(BadInput, match="protected region is empty"):
        region.protected_region(behind, K, (W, H), 10)
    with pytest.raises(BadInput):
        region.protected_region(np.zeros((4, 2)), K, (W, H), 4)
