"""scenes.reach and scenes.synthetic.trace: the truth's reach. A wall two totems see is in
it, at the parallax its geometry gives; a part of the wall a box hides from one totem is
not; a backdrop both totems see along the camera's direction is; the file round trips
and the metrics read off it count what they say."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from reach_cases import (BOX_C, BOX_H, ETA, H, K, P1, P2, WALL_Z, W, R, angle,
                         check_box_hides_from_one, check_wall_both_see, on_wall, pixel)
from scenes import camera, folder
from scenes.reach import Reach, angular_spacing, reach_map

WALL_X = (-2.0, 0.2)            # the wall's left and right edges; beyond x = 0.2, nothing
WALL_Y = 1.6                    # half its height


def _affine(scale, t):
    M = np.diag([*scale, 1.0])
    M[:3, 3] = t
    return M.tolist()


def tiny_desc() -> dict:
    """A wall on the left, nothing on the right (a backdrop), two totems, and a small box
    behind the left totem that hides a patch of the wall from it alone."""
    cx, hw = 0.5 * (WALL_X[0] + WALL_X[1]), 0.5 * (WALL_X[1] - WALL_X[0])
    grey = {"type": "diffuse", "rgb": [0.5, 0.5, 0.5]}
    return {"format": 1, "size": [W, H], "K": K.tolist(), "envmap": None, "lights": [],
            "objects": [{"id": 0, "name": "wall", "kind": "rectangle", "material": grey,
                         "to_world": _affine([hw, WALL_Y, 1.0], [cx, 0.0, WALL_Z])},
                        {"id": 1, "name": "box", "kind": "cube", "material": grey,
                         "to_world": _affine([BOX_H] * 3, BOX_C)}],
            "totems": [{"center": P1.tolist(), "radius": R, "ior": ETA},
                       {"center": P2.tolist(), "radius": R, "ior": ETA}]}


def _past_wall(P, direction) -> bool:
    """Does the line from P along ``direction`` pass the wall's plane beside it?"""
    x, y, _ = P + direction * (WALL_Z - P[2]) / direction[2]
    return not (WALL_X[0] <= x <= WALL_X[1] and abs(y) <= WALL_Y)


@pytest.fixture(scope="module")
def traced():
    from scenes import backend
    from scenes.synthetic.trace import truth_reach

    backend.use()
    return truth_reach(tiny_desc())


def test_a_wall_two_totems_see_is_in_reach_at_its_parallax(traced):
    check_wall_both_see(traced[0])


def test_a_patch_a_box_hides_from_one_totem_is_out_of_reach(traced):
    check_box_hides_from_one(traced[0])


def test_a_backdrop_both_totems_see_along_its_direction_is_in_reach(traced):
    reach, _ = traced
    X = np.array([1.6, 0.0, WALL_Z])              # beside the wall: nothing behind
    d = X / np.linalg.norm(X)
    assert _past_wall(np.zeros(3), d) and _past_wall(P1, d) and _past_wall(P2, d)
    u, v = pixel(X)
    assert np.isinf(reach.depth[v, u]) and reach.backdrop[v, u]
    assert reach.n_totems[v, u] == 2 and reach.in_reach()[v, u]


def test_the_totems_own_pixels_are_no_surface_to_judge(traced):
    reach, hits = traced
    u, v = pixel(P1)
    assert reach.excluded[v, u] and not reach.in_reach()[v, u]
    assert set(np.unique(hits.totem)) == {0, 1}
    assert np.all(hits.T[hits.sent_on()] > 0.05)


def _plane_rays(P, n=41, half=0.3):
    """A totem's rays fanned out over a square of directions, landing on z = WALL_Z."""
    a = np.linspace(-half, half, n)
    ax, ay = np.meshgrid(a, a)
    d = np.stack([np.tan(ax), np.tan(ay), np.ones_like(ax)], -1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    Y = P + d * ((WALL_Z - P[2]) / d[:, 2])[:, None]
    return np.repeat(P[None], len(d), 0), d, Y


def test_reach_map_counts_each_totem_within_its_rays_footprint():
    """Two totems fan rays onto a plane: where both fans land the plane is seen twice, at
    the parallax of the two centres in their spacing; beyond both fans, by neither."""
    v, u = np.mgrid[0:H, 0:W]
    view = camera.pixel_rays(K, u, v)
    X = view * (WALL_Z / view[..., 2])[..., None]
    o1, d1, Y1 = _plane_rays(P1)
    o2, d2, Y2 = _plane_rays(P2)
    o, d, Y = np.concatenate([o1, o2]), np.concatenate([d1, d2]), np.concatenate([Y1, Y2])
    normal = np.tile([0.0, 0.0, -1.0], (len(d), 1))
    totem = np.repeat([0, 1], len(d1))
    r = reach_map(view, X, np.zeros((H, W), bool), np.stack([P1, P2]), o=o, d=d, Y=Y,
                  normal=normal, totem=totem)
    spacing = angular_spacing(d, totem, 2)
    np.testing.assert_allclose(r.spacing, spacing)
    centre = pixel([0.0, 0.0, WALL_Z])
    theta = angle(on_wall(*centre))
    assert r.n_totems[centre[1], centre[0]] == 2
    assert r.parallax[centre[1], centre[0]] == pytest.approx(theta / spacing.mean(), rel=1e-5)
    # each fan covers x in P_x +- tan(0.3) * 2.5 m on the plane (plus its footprint)
    edge = np.tan(0.3) * (WALL_Z - P1[2])
    only_right = pixel([P1[0] + edge + 0.15, 0.0, WALL_Z])
    assert r.n_totems[only_right[1], only_right[0]] == 1
    corner = pixel([0.0, -(edge + 0.15), WALL_Z])
    assert r.n_totems[corner[1], corner[0]] == 0


def test_reach_round_trips_through_the_truth_folder(tmp_path):
    rng = np.random.default_rng(0)
    reach = Reach(depth=rng.uniform(1, 5, (H, W)).astype(np.float32),
                  n_totems=rng.integers(0, 4, (H, W)).astype(np.uint8),
                  parallax=rng.uniform(0, 9, (H, W)).astype(np.float32),
                  backdrop=rng.random((H, W)) < 0.1, excluded=rng.random((H, W)) < 0.05,
                  spacing=np.array([0.03, 0.04]))
    truth = folder.Truth(clean=np.zeros((H, W, 3)), totem_pose=np.stack([P1, P2]),
                         scene={}, reach=reach)
    folder.write_scene(tmp_path / "s", image=np.zeros((H, W, 3)), K=K,
                       masks=np.zeros((2, H, W), bool), radius=R, ior=ETA, truth=truth)
    back = folder.read_truth(tmp_path / "s").reach
    for k, val in reach.to_dict().items():
        np.testing.assert_array_equal(getattr(back, k), val)
    (tmp_path / "s" / "truth" / "reach.npz").write_bytes(b"not a zip")
    with pytest.raises(folder.BadInput, match="reach"):
        folder.read_truth(tmp_path / "s")


def test_truth_metrics_count_the_reach_from_both_sides():
    from verify.metrics.truth import truth_metrics

    n = np.zeros((H, W), np.uint8)
    n[:, : W // 2] = 2                         # the left half is seen by two totems...
    parallax = np.where(n == 2, 6.0, 0.0).astype(np.float32)
    parallax[:, : W // 4] = 1.0                # ...its left quarter without depth
    depth = np.full((H, W), 3.0, np.float32)
    reach = Reach(depth=depth, n_totems=n, parallax=parallax, backdrop=np.zeros((H, W), bool),
                  excluded=np.zeros((H, W), bool), spacing=np.array([0.03, 0.03]))
    truth = folder.Truth(clean=np.zeros((H, W, 3)), totem_pose=np.stack([P1, P2]),
                         scene={}, reach=reach)
    judged = np.zeros((H, W), bool)
    judged[:, W // 4: W // 2 + W // 4] = True    # half the reach, and as much outside it
    manip = np.zeros((H, W), bool)
    manip[10:20, W // 4: W // 4 + 20] = True
    view_depth = np.full((H, W), 3.3)
    # the totems give a depth 2 % off on the reach's left half; its interval holds the
    # truth on the left quarter of the reach only
    cols = np.arange(W)[None, :].repeat(H, 0)
    a, b = W // 4, W // 2                      # the reach's columns
    mid, q = (a + b) // 2, (3 * a + b) // 4
    z = np.where(cols < mid, 3.06, np.nan)
    lo = np.where(cols < q, 2.95, 3.02)
    hi = np.where(cols < q, 3.05, 3.1)
    m = truth_metrics(truth, fitted=np.zeros((H, W, 3)), centers=np.stack([P1, P2]),
                      seen=np.ones((H, W), bool), judged=judged,
                      totem_mask=np.zeros((H, W), bool), manip=manip, depth=view_depth,
                      totem_depth=(z, lo, hi))
    assert m["reach_fraction"] == pytest.approx(0.25)
    assert m["reach_judged"] == pytest.approx(1.0)
    assert m["judged_seen"] == pytest.approx(0.5)
    assert m["manip_in_reach"] == pytest.approx(1.0)
    assert m["depth_error"] == pytest.approx(0.1)
    assert m["totem_depth_error"] == pytest.approx(0.02)
    assert m["totem_depth_given"] == pytest.approx((mid - a) / (b - a))
    assert m["totem_depth_within"] == pytest.approx((q - a) / (mid - a))
    assert m["recon_L1"] == 0.0 and m["pose_L1"] == 0.0


def test_the_depth_bound_is_the_reach_s_median_inverse_parallax_backdrop_left_out():
    from verify.metrics.truth import truth_metrics

    cols = np.arange(W)[None, :].repeat(H, 0)
    n = np.full((H, W), 2, np.uint8)
    parallax = np.where(cols < W // 3, 5.0, 20.0).astype(np.float32)   # a third near
    backdrop = cols >= 3 * W // 4                  # a far backdrop: parallax 0, in reach
    parallax[backdrop] = 0.0
    reach = Reach(depth=np.full((H, W), 3.0, np.float32), n_totems=n, parallax=parallax,
                  backdrop=backdrop, excluded=np.zeros((H, W), bool),
                  spacing=np.array([0.03, 0.03]))
    truth = folder.Truth(clean=np.zeros((H, W, 3)), totem_pose=np.stack([P1, P2]),
                         scene={}, reach=reach)
    m = truth_metrics(truth, fitted=np.zeros((H, W, 3)), centers=np.stack([P1, P2]),
                      seen=np.ones((H, W), bool), judged=np.ones((H, W), bool),
                      totem_mask=np.zeros((H, W), bool))
    # the reach off the backdrop: W // 3 columns at 1/5, the rest of 3 W / 4 at 1/20
    assert m["totem_depth_bound"] == pytest.approx(1 / 20)
    parallax[:, : W // 2] = 5.0                    # now two thirds of it at 1/5
    assert truth_metrics(truth, fitted=np.zeros((H, W, 3)), centers=np.stack([P1, P2]),
                         seen=np.ones((H, W), bool), judged=np.ones((H, W), bool),
                         totem_mask=np.zeros((H, W), bool))["totem_depth_bound"] == \
        pytest.approx(1 / 5)


@pytest.mark.slow
def test_scene_make_writes_the_reach_and_scene_reach_writes_it_again(tmp_path):
    from scenes.synthetic.make import make_scene

    scene = make_scene(tmp_path / "box", preset="box", seed=3, size=(160, 120), spp=4)
    made = folder.read_truth(scene).reach
    inside = made.in_reach()
    assert made.depth.shape == (120, 160) and 0.3 < inside.mean() < 1.0
    masks = folder.read_scene(scene).masks.any(axis=0)
    assert not inside[masks].any() and made.excluded[masks].mean() > 0.9
    (scene / "truth" / "reach.npz").unlink()
    done = subprocess.run([sys.executable, "-m", "verify.cli", "scene", "reach", str(scene),
                           "--json"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["written"] == [str(scene / "truth" / "reach.npz")]
    again = folder.read_truth(scene).reach
    for k, val in made.to_dict().items():
        np.testing.assert_array_equal(getattr(again, k), val)
    bad = subprocess.run([sys.executable, "-m", "verify.cli", "scene", "reach",
                          str(tmp_path)], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_a_supersampled_pixel_sends_its_rays_through_its_subpixels():
    from scenes.refraction import exit_rays

    P = np.array([0.1, 0.05, 1.5])
    u0, v0 = pixel(P + [0.03, 0.02, 0.0])           # a pixel inside the sphere's image
    mask = np.zeros((1, H, W), bool)
    mask[0, v0, u0] = True
    one = exit_rays(K, mask, [P], 0.1, 1.5)
    four = exit_rays(K, mask, [P], 0.1, 1.5, supersample=2)
    assert len(one.u) == 1 and len(four.u) == 4
    assert set(four.u) == {u0} and set(four.v) == {v0}
    spread = np.linalg.norm(four.d - one.d, axis=1)
    assert np.all(spread > 0) and np.allclose(four.d.mean(0), one.d[0], atol=0.1 * spread.max())
