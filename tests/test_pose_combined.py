"""inverse/pose/combined: the mask and the photo weighed. An exact mask keeps the mask's
pose, a mask drawn a few pixels off is corrected by the photo's edges, and the reported
uncertainty says which case it is in."""

from __future__ import annotations

import numpy as np
import pytest

from inverse.pose import pose, combined
from scenes import camera, folder
from scenes.photo import drawn_masks

W, H = 320, 240
K = camera.intrinsics(W, H, 60.0)


def _disc(P, R, *, band_px=None):
    """The sphere (P, R) drawn as its exact image, bright on a dark ground, anti-aliased
    (a 0.5 px blur), optionally with a darker disc ``band_px`` inside the rim (the
    inner edge of a rim's reflection band, weaker than the silhouette); and its exact
    mask (pixel centres inside the tangent cone)."""
    from scipy.ndimage import gaussian_filter

    vv, uu = np.mgrid[0:H, 0:W]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    ang = np.arccos(np.clip(d @ (P / np.linalg.norm(P)), -1, 1)).reshape(H, W)
    half = np.arcsin(R / np.linalg.norm(P))
    img = 0.2 + 0.6 * (ang < half)
    if band_px is not None:
        img = img - 0.3 * (ang < np.arctan(np.tan(half) - band_px / K[0, 0]))
    img = gaussian_filter(np.repeat(img[..., None], 3, 2), (0.5, 0.5, 0))
    return img.astype(np.float32), ang < half


def _err(P, P_true):
    return float(np.linalg.norm(P - P_true) / np.linalg.norm(P_true))


P0, R0 = np.array([0.1, -0.05, 1.1]), 0.1


def test_an_exact_mask_keeps_its_own_pose():
    img, mask = _disc(P0, R0, band_px=3.0)
    c = combined.combined_poses(img, mask[None], K, R0)[0]
    P_mask = pose.initial_pose(mask[None], K, R0)[0]
    assert _err(c.center, P_mask) < 1e-3 and _err(c.center, P0) < 1e-3
    assert c.weight[2] < 0.5                     # the size is the mask's


@pytest.mark.parametrize("grow", [2, -2])
def test_a_mask_drawn_two_pixels_off_is_corrected_by_the_edge(grow):
    img, mask = _disc(P0, R0)
    drawn = drawn_masks.grown(mask, grow)
    c = combined.combined_poses(img, drawn[None], K, R0)[0]
    assert _err(c.mask_center, P0) > 0.03         # the mask alone is 3 % or more off ...
    assert _err(c.center, P0) < 0.006, _err(c.center, P0)  # ... the weighed pose is not
    assert c.weight[2] > 0.9                      # and it says the size is the photo's


def test_the_uncertainty_covers_the_error_and_grows_with_a_shifted_mask():
    img, mask = _disc(P0, R0)
    exact = combined.combined_poses(img, mask[None], K, R0)[0]
    rng = np.random.default_rng(3)
    moved = combined.combined_poses(img, drawn_masks.shifted(mask, 2, rng)[None],
                                         K, R0)[0]
    assert moved.sd_across > 2 * exact.sd_across
    for c in (exact, moved):
        e = P0 - c.center
        los = c.center / np.linalg.norm(c.center)
        assert abs(e @ los) <= 3 * c.sd_along
        assert np.sqrt(max(e @ e - (e @ los) ** 2, 0)) <= 3 * c.sd_across


def test_a_photo_without_edges_leaves_the_masks_pose_and_says_so():
    _, mask = _disc(P0, R0)
    flat = np.full((H, W, 3), 0.5, np.float32)
    c = combined.combined_poses(flat, mask[None], K, R0)[0]
    np.testing.assert_allclose(c.center, c.mask_center)
    sure = combined.combined_poses(_disc(P0, R0)[0], mask[None], K, R0)[0]
    assert c.sd_along > 5 * sure.sd_along and np.isfinite(c.sd_along)


def test_the_outline_move_is_the_inverse_of_rims():
    from inverse.pose import rim

    x = np.array([1.5, -0.7, 2.0])
    P = rim._moved(P0, R0, K, x)
    np.testing.assert_allclose(combined.move_of(P0, P, R0, K), x, atol=1e-9)


def test_arcs_offsets_give_the_move():
    """Offsets drawn from a known move (and one arc on a stray edge) are fitted back."""
    phi = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    n = np.stack([np.cos(phi), np.sin(phi)], 1)
    x = np.array([0.8, -0.4, 1.3])
    o = n @ x[:2] + x[2] + np.random.default_rng(0).normal(0, 0.05, 12)
    o[4] += 2.5
    fitted, cov = combined.fit_offsets(n, o)
    np.testing.assert_allclose(fitted, x, atol=0.1)
    assert np.all(np.sqrt(np.diag(cov)) < 0.3)


def test_pose_from_is_checked():
    from scenes.errors import BadInput

    img, mask = _disc(P0, R0)
    with pytest.raises(BadInput, match="pose_from"):
        combined.initial_centres(img, mask[None], K, R0, "rim")
    for how in combined.POSE_FROM:
        centers, sd = combined.initial_centres(img, mask[None], K, R0, how)
        assert centers.shape == (1, 3) and (sd is None) == (how != "both")


# ------------------------------------------------------------------ a rendered scene

@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from scenes.synthetic.make import make_scene

    out = make_scene(tmp_path_factory.mktemp("pose_combined") / "s", preset="envmap",
                     seed=2, size=(640, 480), spp=16)
    return folder.read_scene(out), folder.read_truth(out)


def _weighed(scene, family, seed=0):
    sc, truth = scene
    rng = np.random.default_rng(seed)
    masks = np.asarray(sc.masks, bool) if family == "exact" else \
        np.stack([drawn_masks.family(family, m, rng) for m in sc.masks])
    poses = combined.combined_poses(sc.image, masks, sc.K, sc.radius)
    dist = np.linalg.norm(truth.totem_pose, axis=1)
    err = np.array([np.linalg.norm(c.center - P)
                    for c, P in zip(poses, truth.totem_pose)])
    return poses, 100 * err / dist, masks


@pytest.mark.slow
def test_exact_masks_on_a_render_give_the_masks_pose(scene):
    sc = scene[0]
    poses, err, masks = _weighed(scene, "exact")
    P_mask = pose.initial_pose(masks, sc.K, sc.radius)
    d = np.linalg.norm(P_mask, axis=1)
    assert np.all(np.linalg.norm([c.center for c in poses] - P_mask, axis=1) / d < 1e-3)
    assert np.median(err) < 0.1 and err.max() < 0.5, err    # the targets


@pytest.mark.slow
@pytest.mark.parametrize("family", ["grown2", "poly12"])
def test_drawn_masks_on_a_render_come_within_half_a_percent(scene, family):
    _, err, _ = _weighed(scene, family)
    assert err.max() < 0.5, err


@pytest.mark.slow
def test_a_shifted_mask_on_a_render_is_less_sure(scene):
    exact, _, _ = _weighed(scene, "exact")
    moved, _, _ = _weighed(scene, "shift2", seed=1)
    assert np.median([m.sd_across / e.sd_across for m, e in zip(moved, exact)]) > 1.5


def test_the_masks_share_falls_smoothly_with_the_scatter_in_edge_widths():
    """The share of an outline whose nearest edges agree on its size falls without a
    jump as their scatter grows, and the same scatter counts less on a wider edge (a
    pixel filter or JPEG widens the edge and the scatter of its peaks)."""
    x_n, x_r = np.array([0.1, -0.1, 0.05]), np.zeros(3)

    def share(scatter, width):
        S = np.diag([0.3, 0.3, scatter ** 2 + combined.EDGE_BIAS_SD_PX ** 2])
        return combined.edge_share(x_n, S, width, x_r)

    s = np.linspace(0.0, 1.0, 201)
    p = np.array([share(x, 1.2) for x in s])
    assert p[0] == 1.0 and p[-1] < 0.01
    assert np.all(np.diff(p) <= 1e-12) and np.abs(np.diff(p)).max() < 0.05
    assert share(0.33, 1.6) > share(0.33, 1.2) + 0.2
    # the rim's strongest edge well outside the nearest: the mask sits on the band
    assert combined.edge_share(x_n, np.diag([0.3, 0.3, 0.05]), 1.2,
                                    np.array([0.0, 0.0, 2.0])) < 0.01


@pytest.mark.slow
def test_exact_masks_on_a_photo_through_a_pixel_filter_keep_the_masks_pose(scene):
    """A 1.5 px (full width at half maximum) Gaussian filter widens every edge: the exact
    masks keep their pose to 0.1 % of the distance."""
    from scipy.ndimage import gaussian_filter

    sc = scene[0]
    s = 1.5 / 2.355
    img = gaussian_filter(np.asarray(sc.image, np.float32), (s, s, 0))
    masks = np.asarray(sc.masks, bool)
    poses = combined.combined_poses(img, masks, sc.K, sc.radius)
    P_mask = pose.initial_pose(masks, sc.K, sc.radius)
    d = np.linalg.norm(P_mask, axis=1)
    assert np.all(np.linalg.norm([c.center for c in poses] - P_mask, axis=1) / d < 1e-3)


def _evidence(g_near, g_rim, *, lateral=(0.0, 0.0)):
    """A totem's :class:`Evidence` whose nearest edge puts the silhouette ``g_near`` px
    outside the mask's outline (moved by ``lateral``) and the rim's strongest edge
    ``g_rim`` px outside it, each measured to 0.25 px."""
    S = np.diag([0.5 ** 2, 0.5 ** 2, 0.25 ** 2])
    return combined.Evidence(
        mask_center=P0, shape_rms_px=0.2, extra2=0.0, width=1.2,
        x_near=np.array([*lateral, g_near]), S_near=S,
        x_rim=np.array([0.0, 0.0, g_rim]), x_far=np.array([0.0, 0.0, g_rim]), S_far=S,
        rim_center=P0)


def test_the_photos_other_totems_decide_between_the_near_edge_and_the_rim():
    """Where a totem's nearest edge and its rim's strongest edge disagree on the size,
    the share goes to the one the photo's other totems' rims agree with: exact masks
    whose rims lie on them keep a mask whose rim took the band 2 px inside; masks drawn
    3 px too large drop a mask whose nearest edges lie on a shadow outside."""
    exact = [_evidence(0.0, -2.0)] + [_evidence(0.0, g) for g in (0.1, -0.1, 0.0)]
    grown = [_evidence(0.0, -3.0, lateral=(2.0, 0.0))] + \
        [_evidence(-0.2, g) for g in (-2.9, -3.1, -3.0)]
    for photo, rises in ((exact, True), (grown, False)):
        p = combined.shared_shares(photo, [0.5] * 4)
        assert (p[0] > 0.9) if rises else (p[0] < 0.1), p
    # a totem alone, or an unusable mask beside it, has no photo to share with
    assert combined.shared_shares([exact[0]], [0.3]) == [0.3]
    assert combined.shared_shares([exact[0], None, exact[1]], [0.3, None, 0.8]) == \
        [0.3, None, 0.8]


def test_the_edge_bias_follows_the_outline_radius():
    """The nearest edge's bias: outside the silhouette on a small outline, inside on a
    large one (the band pulls it, a fraction of the radius), never extrapolated beyond
    the radii it was measured on."""
    def bias(dist):                          # the outline's radius is f tan(asin(R / d))
        return combined.edge_bias_px(np.array([0.0, 0.0, dist]), R0, K)

    f = K[0, 0]
    r_px = [f * np.tan(np.arcsin(R0 / d)) for d in (4.0, 2.0, 1.0, 0.4)]
    b = [bias(d) for d in (4.0, 2.0, 1.0, 0.4)]
    assert r_px[0] < 10 and r_px[-1] > 65         # the ends are clamped ...
    lo, hi = combined.EDGE_BIAS_RADII_PX
    assert b[0] == pytest.approx(combined.EDGE_BIAS_PX
                                 + combined.EDGE_BIAS_PER_PX * lo)
    assert b[-1] == pytest.approx(combined.EDGE_BIAS_PX
                                  + combined.EDGE_BIAS_PER_PX * hi)
    assert b[0] > 0 > b[-1] and np.all(np.diff(b) < 0)   # ... and it falls with the size
