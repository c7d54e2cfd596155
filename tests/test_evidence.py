"""verify.metrics.evidence: parallax is the angle between totems in their rays' spacings; a
near textured wall two totems see is resolved, the same wall seen by one totem, or by two
that disagree on its colours, is not."""

import numpy as np
import pytest

from inverse.grid import FrustumFrame
from inverse.rays import TotemRays
from verify.metrics import evidence

K = np.array([[600.0, 0.0, 159.5], [0.0, 600.0, 119.5], [0.0, 0.0, 1.0]])
SIZE = (320, 240)                     # W, H: a 30 degree view


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


def _frame(far: float) -> FrustumFrame:
    W, H = SIZE
    return FrustumFrame(K, (-0.5, W - 0.5), (-0.5, H - 0.5), 0.5, far)


def _texture(X: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Linear RGB of a wall's texture at points X (k, 3): smooth, of three periods
    (``scale`` x 0.31-0.53 m) that never repeat together, so two places seldom share a
    colour."""
    x, y = X[:, 0] / scale, X[:, 1] / scale
    return np.stack([0.5 + 0.4 * np.sin(2 * np.pi * x / 0.31),
                     0.5 + 0.4 * np.sin(2 * np.pi * (x + y) / 0.53),
                     0.5 + 0.4 * np.sin(2 * np.pi * y / 0.37)], -1)


def _fans(centers, wall_z, step=0.01, n=81, other=False):
    """Rays from each centre in a square fan (angular spacing ``step``) about the
    camera's axis, each carrying the colour of the wall at ``z = wall_z`` where it
    meets it (``other``: the second totem sees another wall, its channels turned)."""
    o, d, tot, col = [], [], [], []
    a = (np.arange(n) - n // 2) * step
    aa, bb = np.meshgrid(a, a)
    for j, c in enumerate(centers):
        dj = np.stack([np.tan(aa), np.tan(bb), np.ones_like(aa)], -1).reshape(-1, 3)
        dj /= np.linalg.norm(dj, axis=1, keepdims=True)
        X = c + (wall_z - c[2]) / dj[:, 2:3] * dj
        o.append(np.repeat(c[None], len(dj), 0))
        d.append(dj)
        tot.append(np.full(len(dj), j))
        col.append(_texture(X)[:, [1, 2, 0]] if other and j == 1 else _texture(X))
    o, d, tot, col = map(np.concatenate, (o, d, tot, col))
    return TotemRays(o, d, col, tot, np.ones(len(tot)))


def test_a_near_textured_wall_two_totems_see_is_resolved():
    centers = np.array([[-0.25, 0.1, 1.0], [0.25, 0.1, 1.0]])
    ev = evidence.evidence_map(_fans(centers, 2.5), centers, _frame(50.0), SIZE)
    H, W = SIZE[1], SIZE[0]
    centre = (slice(H // 2 - 20, H // 2 + 20), slice(W // 2 - 20, W // 2 + 20))
    assert ev.resolved[centre].mean() > 0.9
    assert (ev.n_totems[centre][ev.resolved[centre]] == 2).all()
    assert np.median(ev.parallax[centre]) > evidence.MIN_PARALLAX


def test_one_totem_or_two_that_disagree_do_not_resolve_a_wall():
    centers = np.array([[-0.25, 0.1, 1.0], [0.25, 0.1, 1.0]])
    one = evidence.evidence_map(_fans(centers[:1], 2.5), centers[:1], _frame(50.0), SIZE)
    assert one.n_totems.max() <= 1 and not one.resolved.any()
    # the second totem sees another wall: they seldom agree
    apart = evidence.evidence_map(_fans(centers, 2.5, other=True), centers,
                                  _frame(50.0), SIZE)
    ok = evidence.evidence_map(_fans(centers, 2.5), centers, _frame(50.0), SIZE)
    assert apart.resolved.mean() < 0.5 * ok.resolved.mean()     # chance: a fifth


def test_the_map_puts_a_textured_wall_at_its_depth_within_its_interval():
    centers = np.array([[-0.25, 0.1, 1.0], [0.25, 0.1, 1.0]])
    ev = evidence.evidence_map(_fans(centers, 2.5), centers, _frame(50.0), SIZE)
    z, lo, hi = ev.depth[ev.resolved], ev.depth_lo[ev.resolved], ev.depth_hi[ev.resolved]
    assert np.isnan(ev.depth[~ev.resolved]).all()
    assert np.median(np.abs(z - 2.5) / 2.5) < 0.05
    assert ((lo <= 2.5) & (hi >= 2.5)).mean() > 0.8
    assert (lo <= z).all() and (z <= hi).all()
