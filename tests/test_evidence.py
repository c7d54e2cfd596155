"""verify.evidence: rays marched through the camera's depth map meet the surface on its
pixel; parallax is the angle between totems in their rays' spacings; a near wall two
totems see is resolved, the same wall far away or seen by one totem is not."""

import numpy as np
import pytest

from inverse.rays import TotemRays
from scenes.camera import project
from verify import evidence

K = np.array([[200.0, 0.0, 79.5], [0.0, 200.0, 59.5], [0.0, 0.0, 1.0]])
SIZE = (160, 120)                     # W, H


def _wall(z: float) -> np.ndarray:
    W, H = SIZE
    return np.full((H, W), z)


def test_a_ray_meets_a_wall_on_the_pixel_of_its_intersection():
    o = np.array([[0.3, 0.1, 0.5], [-0.2, 0.0, 0.8]])
    d = np.array([[-0.2, -0.05, 1.0], [0.15, 0.1, 1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = evidence.ray_hits(o, d, _wall(3.0), K, near=0.01, far=20.0, n_steps=2000)
    for k in range(2):
        X = o[k] + (3.0 - o[k, 2]) / d[k, 2] * d[k]           # the ray's point at z = 3
        u, v = np.rint(project(K, X)).astype(int)
        assert hits[k] == v * SIZE[0] + u


def test_an_occluder_stops_the_rays_that_cross_it_and_not_those_behind_it():
    depth = _wall(4.0)
    depth[40:80, 60:100] = 1.5                               # a box in front of the wall
    # a ray into the box's face: it meets it inside the box's pixels
    X_box = np.array([0.05, 0.02, 1.5])
    o = np.array([[0.4, 0.1, 0.2]])
    d = (X_box - o) / np.linalg.norm(X_box - o)
    hit = evidence.ray_hits(o, d, depth, K, near=0.01, far=20.0)[0]
    u, v = hit % SIZE[0], hit // SIZE[0]
    assert 60 <= u < 100 and 40 <= v < 80
    assert np.abs(np.array([u, v]) - project(K, X_box)).max() <= 1.5    # within a step
    # a ray passing far behind the box (seen from the camera) goes on to the wall
    X_wall = np.array([-1.5, 0.0, 4.0])
    o2 = np.array([[1.0, 0.0, 2.5]])
    d2 = (X_wall - o2) / np.linalg.norm(X_wall - o2)
    hit2 = evidence.ray_hits(o2, d2, depth, K, near=0.01, far=20.0, n_steps=1000)[0]
    assert hit2 == int(np.rint(project(K, X_wall))[1] * SIZE[0]
                       + np.rint(project(K, X_wall))[0])


def test_a_ray_that_leaves_the_image_meets_nothing():
    o = np.array([[0.0, 0.0, 1.0]])
    d = np.array([[1.0, 0.0, 0.0]])                          # sideways, out of the view
    assert evidence.ray_hits(o, d, _wall(3.0), K, near=0.01, far=20.0)[0] == -1


def test_parallax_is_the_angle_between_totems_in_spacings():
    X = np.array([[0.0, 0.0, 2.0]])
    centers = np.array([[-0.2, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.5, 0.0]])
    spacing = np.array([0.01, 0.03, 0.02])
    seen = np.array([[True], [True], [False]])
    want = 2 * np.arctan(0.2 / 2.0) / 0.02
    assert evidence.pair_parallax(X, centers, spacing, seen)[0] == pytest.approx(want)
    assert evidence.pair_parallax(X, centers, spacing, ~seen)[0] == 0.0   # one totem


def test_angular_spacing_of_a_regular_fan_is_its_step():
    step = np.radians(1.5)
    a = np.arange(-10, 11) * step
    d = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], -1)
    sp = evidence.angular_spacing(d, np.zeros(len(d), int), 2)
    assert sp[0] == pytest.approx(step, rel=1e-6) and np.isnan(sp[1])


def _fans(centers, target, half_angle=0.12, n=41):
    """Rays from each centre in a square fan about the direction to ``target``."""
    o, d, tot = [], [], []
    a = np.linspace(-half_angle, half_angle, n)
    for j, c in enumerate(centers):
        axis = (target - c) / np.linalg.norm(target - c)
        e1 = np.cross(axis, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        for x in a:
            for y in a:
                v = axis + np.tan(x) * e1 + np.tan(y) * e2
                o.append(c)
                d.append(v / np.linalg.norm(v))
                tot.append(j)
    m = len(tot)
    return TotemRays(np.array(o), np.array(d), np.full((m, 3), 0.5), np.array(tot),
                     np.ones(m))


def test_a_near_wall_two_totems_see_is_resolved_a_far_one_or_one_totem_is_not():
    centers = np.array([[-0.25, 0.1, 1.0], [0.25, 0.1, 1.0]])
    near = evidence.evidence_map(_fans(centers, np.array([0.0, 0.0, 2.5])), centers,
                                 _wall(2.5), K)
    H, W = SIZE[1], SIZE[0]
    centre = (slice(H // 2 - 8, H // 2 + 8), slice(W // 2 - 8, W // 2 + 8))
    assert (near.n_totems[centre] == 2).all() and near.resolved[centre].all()
    assert near.parallax[centre].min() > evidence.MIN_PARALLAX
    far = evidence.evidence_map(_fans(centers, np.array([0.0, 0.0, 300.0])), centers,
                                _wall(300.0), K)
    assert (far.n_totems[centre] == 2).all() and not far.resolved.any()
    one = evidence.evidence_map(_fans(centers[:1], np.array([0.0, 0.0, 2.5])),
                                centers[:1], _wall(2.5), K)
    assert one.n_totems.max() == 1 and not one.resolved.any()
