"""inverse.view.depth: the slice where the totems agree is the depth, smoothed; the support
plane of resting totems wins where the totems cannot tell depths apart, and not where
they agree on a surface in front of it; the plane's slice is where its ray meets it."""

import numpy as np
import pytest

from inverse.grid import FrustumFrame
from inverse.view.depth import established_depth, plane_slice
from inverse.view.support import SupportPlane

NK, NT, NS = 32, 12, 16
Z = 1.0 / np.linspace(1.0, 0.02, NK)                  # 1 to 50 m, even in inverse depth


def _volume(k_true=None, rng=None):
    """A cost volume (variances) of two landing totems: flat (0.01, with a little noise)
    or least (1e-5) at ``k_true`` in every cell."""
    rng = rng or np.random.default_rng(0)
    var = 0.01 * (1 + 0.05 * rng.standard_normal((NK, NT, NS)))
    if k_true is not None:
        var[k_true] = 1e-5
    return var, np.full((NK, NT, NS), 2), np.full((NK, NT, NS), 10.0)


def test_the_slice_where_the_totems_agree_is_the_depth():
    var, n, par = _volume(k_true=20)
    est = established_depth(var, n, par, Z, min_parallax=4.0)
    assert np.allclose(est.z, Z[20], rtol=0.05)
    assert (est.lo <= est.z).all() and (est.z <= est.hi).all()
    assert not est.on_plane.any()


def test_no_depth_where_too_few_totems_land_or_too_little_parallax():
    var, n, par = _volume(k_true=20)
    n[:, :4] = 1
    par[:, 4:8] = 1.0
    est = established_depth(var, n, par, Z, min_parallax=4.0)
    assert np.isnan(est.z[:8]).all() and np.isfinite(est.z[8:]).all()


def test_the_plane_wins_where_the_totems_cannot_tell_depths_apart():
    var, n, par = _volume()
    kp = np.full((NT, NS), 12)
    est = established_depth(var, n, par, Z, min_parallax=4.0, plane_k=kp,
                            agree_var=3 * 0.03 ** 2)
    assert est.on_plane.all()
    assert np.allclose(est.z, Z[12], rtol=0.1)
    free = established_depth(var, n, par, Z, min_parallax=4.0)
    assert not np.allclose(free.z, Z[12], rtol=0.1)


def test_the_plane_loses_where_the_totems_agree_on_a_surface_in_front_of_it():
    var, n, par = _volume()
    var[5, :, :8] = 1e-5                       # an object in front, on the left half
    kp = np.full((NT, NS), 12)
    est = established_depth(var, n, par, Z, min_parallax=4.0, plane_k=kp,
                            agree_var=3 * 0.03 ** 2)
    assert not est.on_plane[:, :6].any() and est.on_plane[:, 10:].all()
    assert np.allclose(est.z[:, :6], Z[5], rtol=0.05)


def test_the_planes_slice_is_where_each_cell_ray_meets_it():
    K = np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]])
    frame = FrustumFrame(K, (-0.5, 159.5), (-0.5, 119.5), 1.0, 50.0)
    floor = SupportPlane(np.array([0.0, -np.cos(0.1), -np.sin(0.1)]), -0.5, 0.0)
    k, zp = plane_slice(floor, frame, (NT, NS), Z)
    v = -0.5 + (np.arange(NT) + 0.5) / NT * 120.0
    u = -0.5 + (np.arange(NS) + 0.5) / NS * 160.0
    d = np.stack([(u[None, :] - 79.5) / 300.0 + 0 * v[:, None],
                  (v[:, None] - 59.5) / 300.0 + 0 * u[None, :], np.ones((NT, NS))], -1)
    X = zp[..., None] * d                      # the cell ray's point at that depth
    met = np.isfinite(zp)
    assert met.any() and (~met).any()          # the horizon crosses the map
    assert np.allclose(X[met] @ floor.normal, floor.offset, atol=1e-9)
    assert (k[~met] == -1).all()
    inv = 1.0 / Z
    assert (np.abs(inv[k[met]] - 1.0 / zp[met]) <= np.abs(np.diff(inv)).max() / 2 + 1e-12).all()


def test_slice_window_holds_the_slices_of_each_cells_interval_and_one_beside():
    from inverse.grid import FrustumFrame, cell_centres
    from inverse.view.depth import slice_window
    from inverse.view.sweep import slice_depths

    K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    frame = FrustumFrame(K=K, u_range=(-0.5, 63.5), v_range=(-0.5, 47.5), near=0.5,
                         far=20.0)
    res = (6, 8)
    z = slice_depths(frame, 32)
    lo = np.full((48, 64), 2.0)
    hi = np.full((48, 64), 3.0)
    uu, vv = cell_centres(frame, res)
    lo[int(round(vv[0, 0])), int(round(uu[0, 0]))] = np.nan     # one cell unknown
    win = slice_window(z, frame, res, lo, hi, slack=0.0)
    inside = (z >= 2.0) & (z <= 3.0)
    assert inside.any() and not inside.all()
    assert (win[:, 1, 1] == inside).all()
    assert not win[:, 0, 0].any()                               # unknown: none
    wide = slice_window(z, frame, res, lo, hi, slack=1.0)
    assert wide[:, 1, 1].sum() == inside.sum() + 2              # one more each side
    assert (wide[:, 1, 1] >= win[:, 1, 1]).all()
