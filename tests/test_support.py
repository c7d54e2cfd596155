"""The support plane from resting totems (inverse/support.py) and its prior's cells
(inverse/losses.support_cells), against planes and spheres built by hand."""

import numpy as np
import pytest

from inverse.grid import frame_for_scene
from inverse.losses import support_cells
from inverse.support import plane_from_centres, ray_plane


def _resting(normal, offset, radius, spots):
    """Spheres of ``radius`` resting on ``N . X = h`` at in-plane points ``spots``."""
    N = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) - N[0] * N        # in-plane x: the camera's x
    a /= np.linalg.norm(a)
    b = np.cross(N, a)
    b *= np.sign(b[2])                              # in-plane y: away from the camera
    base = offset * N                               # the plane's point nearest the camera
    return np.array([base + x * a + y * b + r * N for (x, y), r in zip(spots, radius)])


# a table 0.45 m below the camera's centre, tilted towards it (as tabletop's)
N_TABLE = np.array([0.03, -0.82, -0.57])
N_TABLE /= np.linalg.norm(N_TABLE)


@pytest.mark.parametrize("radius", [(0.07, 0.07, 0.07), (0.06, 0.075, 0.08)])
def test_three_resting_totems_give_their_plane(radius):
    C = _resting(N_TABLE, -0.45, radius, [(-0.2, 0.5), (0.05, 0.7), (0.25, 0.6)])
    plane = plane_from_centres(C, radius)
    assert plane is not None
    np.testing.assert_allclose(plane.normal, N_TABLE, atol=1e-9)
    assert plane.offset == pytest.approx(-0.45, abs=1e-9)
    # each totem touches the plane one radius below its centre
    touch = plane.contact_points(C, radius)
    np.testing.assert_allclose(touch @ N_TABLE, -0.45, atol=1e-9)


def test_four_resting_totems_with_a_millimetre_of_pose_error():
    rng = np.random.default_rng(3)
    R = np.array([0.1, 0.1, 0.1, 0.1])
    C = _resting([0, -1, -0.25], -1.0, R, [(-0.4, 2), (0.1, 2.5), (0.5, 2.2), (0, 3)])
    C += rng.normal(0, 0.001, C.shape)
    plane = plane_from_centres(C, R)
    assert plane is not None and plane.residual < 0.002
    N = np.array([0, -1, -0.25]) / np.linalg.norm([0, -1, -0.25])
    assert np.degrees(np.arccos(plane.normal @ N)) < 2.0


def test_floating_totems_at_different_heights_have_no_plane():
    R = np.full(4, 0.1)
    C = _resting([0, -1, 0], -1.0, R, [(-0.4, 2), (0.1, 2.5), (0.5, 2.2), (0, 3)])
    C[1] += [0, -0.3, 0]                            # one totem 30 cm up in the air
    assert plane_from_centres(C, R) is None
    assert plane_from_centres(C[:2], R[:2]) is None  # two never fix a plane


def test_a_plane_above_the_camera_is_refused():
    # totems on a shelf above the camera: the camera sees the shelf from below
    R = np.full(3, 0.07)
    C = _resting([0, -1, 0], 0.3, R, [(-0.2, 1), (0, 1.3), (0.2, 1.1)])
    assert plane_from_centres(C, R) is None


def test_ray_plane_distance():
    d = np.array([[0, 0.6, 0.8], [0, -0.6, 0.8]])
    t = ray_plane(np.zeros(3), d, np.array([0, -1.0, 0]), -0.3)   # the plane y = 0.3
    assert t[0] == pytest.approx(0.5)
    assert np.isinf(t[1])                           # looks up, away from it


def test_support_cells_hold_the_plane_crossing():
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    R = np.full(3, 0.07)
    C = _resting(N_TABLE, -0.45, R, [(-0.2, 0.5), (0.05, 0.7), (0.25, 0.6)])
    plane = plane_from_centres(C, R)
    frame = frame_for_scene(K, (320, 240), C, R)
    shape = (48, 30, 40)
    idx, before = support_cells(frame, plane, shape)
    assert len(before) > 0
    k, rest = np.divmod(idx, shape[1] * shape[2])
    jt, js = np.divmod(rest, shape[2])
    # one cell per column, only in columns that look down at the table
    assert len(np.unique(rest)) == len(idx) > 0.3 * shape[1] * shape[2]
    # the cell's depth range holds the plane's depth on the column's centre ray
    g_lo = np.stack([(js + 0.5) / shape[2], (jt + 0.5) / shape[1], k / shape[0]], 1)
    g_hi = g_lo.copy()
    g_hi[:, 2] = (k + 1) / shape[0]
    X_lo, X_hi = frame.from_unit(g_lo), frame.from_unit(g_hi)
    below_lo = X_lo @ plane.normal - plane.offset
    below_hi = X_hi @ plane.normal - plane.offset
    assert np.all(below_lo * below_hi <= 1e-12)     # the plane lies between the two ends
