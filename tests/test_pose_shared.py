"""inverse/pose/shared: what the totems of one photo share. Masks drawn alike by a tool
err alike, so a totem whose edges disagree with the others' is read against theirs; a
polygon's or a stroke's error is its own."""

from __future__ import annotations

import numpy as np

from inverse.pose import combined, shared
from scenes import camera

K = camera.intrinsics(320, 240, 60.0)
P0, R0 = np.array([0.1, -0.05, 1.1]), 0.1


def _evidence(g_near, g_rim, *, shape_rms=0.2, sd=0.25):
    """A totem's evidence: its nearest edge puts the silhouette ``g_near`` px outside
    the mask's outline, the rim's strongest edge ``g_rim`` px, each measured to ``sd``
    px; ``shape_rms`` the mask outline's rms from a conic (0.2: a pixel-exact mask)."""
    S = np.diag([0.5 ** 2, 0.5 ** 2, sd ** 2])
    return combined.Evidence(
        mask_center=P0, shape_rms_px=shape_rms, extra2=0.0, width=1.2,
        x_near=np.array([0.0, 0.0, g_near]), S_near=S,
        x_rim=np.array([0.0, 0.0, g_rim]), x_far=np.array([0.0, 0.0, g_rim]), S_far=S,
        rim_center=P0)


def _size(c):
    return combined.move_of(c.mask_center, c.center, R0, K)[2]


def test_a_clean_mask_whose_edges_lie_off_the_others_takes_their_size():
    """Exact masks on their edges, and one whose nearest and strongest edges agree, to
    0.25 px, 1 px inside it (the band): its size is the others' (within 0.2 px), less
    sure than theirs. Masks drawn as polygons keep their own sizes, and so do clean
    masks whose others disagree among themselves."""
    for others, rms, pooled in (((0.0, 0.05, -0.05), 0.2, True),
                                ((0.0, 0.05, -0.05), 0.8, False),
                                ((0.0, 0.9, -0.8), 0.2, False)):
        ev = [_evidence(-1.0, -1.0, shape_rms=rms)] + \
            [_evidence(g, g, shape_rms=rms) for g in others]
        poses = combined.weigh_photo(ev, np.full(4, R0), K)
        if pooled:
            assert abs(_size(poses[0])) < 0.2, _size(poses[0])
            assert poses[0].sd_along > 1.5 * max(c.sd_along for c in poses[1:])
        else:
            assert abs(_size(poses[0]) + 1.0) < 0.1, _size(poses[0])


def test_masks_confirmed_exact_keep_a_size_the_edge_moved_within_the_knee():
    """Three exact masks sure of their edges confirm how the photo's masks were drawn:
    a fourth whose nearest and strongest edges agree 0.6 px inside (a band or a shadow,
    within the knee's 2 sd) keeps its mask's size (within 0.15 px), and says it is less
    sure than they are. Without the others sure (shares a half), the edge moves it."""
    ev = [_evidence(-0.6, -0.6)] + [_evidence(g, g) for g in (0.0, 0.05, -0.05)]
    R = np.full(4, R0)
    own = [combined.edge_share(e.x_near, e.S_near, e.width, e.x_rim) for e in ev]
    assert own[0] < 0.9 and min(own[1:]) >= shared.SURE_SHARE
    poses = combined.weigh_photo(ev, R, K)
    assert abs(_size(poses[0])) < 0.15, _size(poses[0])
    assert poses[0].sd_along > max(c.sd_along for c in poses[1:])
    priors = shared.shared_sizes(ev, [0.0] * 4, [0.5] * 4)
    assert priors[0] is not None and not priors[0].confirmed
    moved = combined.weigh(ev[0], R0, K, p=own[0], prior=priors[0])
    assert _size(moved) < -0.3, _size(moved)


def test_the_pull_grows_smoothly_with_the_gap():
    """Within the knee a totem keeps its size; beyond it the pull grows without a jump
    and ends at the others' size."""
    prior = (0.0, shared.TIGHT_SD_PX ** 2)
    gaps = np.linspace(0.0, 2.0, 201)
    g = np.array([shared.pooled(x, 0.05, 0.25 ** 2, prior)[0] for x in gaps])
    knee = shared.POOL_KNEE_SD * np.sqrt(0.25 ** 2 + prior[1])
    np.testing.assert_allclose(g[gaps <= knee], gaps[gaps <= knee])
    assert abs(g[-1]) < 0.01 and np.abs(np.diff(g)).max() < 0.05


def test_masks_sure_of_their_edges_outvote_a_rim_pulled_aside():
    """Exact masks whose nearest edge is also their rim's strongest (share 1) say how
    the photo's masks were drawn: a mask whose rim's strongest edge lies 0.8 px outside
    (background beyond a weak silhouette) keeps its nearest edge. Masks whose nearest
    edge is not their rim's (a halo at a grown mask's outline, the rim 1.5 px inside)
    are not sure, and the others' rims decide, as before."""
    exact = [_evidence(0.0, 0.8)] + [_evidence(g, g + 0.2) for g in (0.0, 0.05, -0.05)]
    assert shared.shared_shares(exact, [0.3, 1.0, 1.0, 1.0])[0] > 0.9
    assert shared.shared_shares(exact, [0.3, 0.5, 0.5, 0.5])[0] < 0.8
    grown = [_evidence(0.0, -1.5)] + [_evidence(g, -1.5) for g in (0.0, -0.05, 0.05)]
    assert shared.shared_shares(grown, [0.7, 1.0, 1.0, 1.0])[0] < 0.1


def _profiled(g_sil, g_band, *, shape_rms=0.2, band=1.3):
    """Evidence whose edge profile along the size peaks at the silhouette ``g_sil`` px
    and, ``band`` times as strongly, at the band ``g_band`` px; its own nearest and rim's
    edges both on the band."""
    x = shared.SIZE_GRID_PX
    prof = np.exp(-0.5 * ((x - g_sil) / 0.5) ** 2) + band * np.exp(-0.5 * ((x - g_band) / 0.5) ** 2)
    e = _evidence(g_band, g_band, shape_rms=shape_rms)
    e.size_edge, e.size_lateral = prof, np.zeros(2)
    return e


def test_the_shared_offset_is_where_the_silhouettes_add_up_not_the_bands():
    """Masks shrunk 2 px alike: each totem's band (a fraction of its radius) is its
    strongest edge, at a different size on each, but the silhouettes at +2 px add up.
    Without two totems whose own edges lie there, or with fewer than three clean masks
    (polygons' error is their own), there is no shared offset."""
    ev = [_profiled(2.0, g) for g in (-1.0, 0.0, 0.5)] + [_profiled(2.0, 1.6)] * 2
    g = shared.shared_offset(ev, 1.0)
    assert g is not None and abs(g - 2.0) <= 0.25, g
    assert shared.shared_offset(ev[:3], 1.0) is None          # no own edge there
    polys = [_profiled(2.0, g, shape_rms=0.8) for g in (-1.0, 0.0, 0.5, 1.6, 1.6)]
    assert shared.shared_offset(polys, 1.0) is None


def test_a_rim_whose_own_edges_missed_the_shared_offset_is_sought_there():
    """A bright disc whose dark band lies 3 px inside its silhouette, a mask drawn on
    the band: sought from the photo's offset (+3 px) the rim finds the silhouette; a
    totem with an edge of its own near the offset, or on both sides of it, is left."""
    from inverse.pose import rim
    from scenes import silhouette

    uv = camera.project(K, P0[None])[0]
    r = K[0, 0] * np.tan(np.arcsin(R0 / np.linalg.norm(P0)))
    yy, xx = np.mgrid[0:240, 0:320] + 0.5
    d = np.hypot(xx - uv[0], yy - uv[1])
    img = np.where(d < r, 0.8, 0.2) * np.where(np.abs(d - (r - 3.0)) < 0.5, 0.0, 1.0)
    img = np.repeat(img[..., None], 3, -1).astype(np.float32)
    grad = silhouette.gradients(img, rim.SIGMA_PX)
    P_m = rim._moved(P0, R0, K, np.array([0.0, 0.0, -3.0]))    # the mask on the band
    e = _evidence(0.0, 0.0)
    e.mask_center, e.size_lateral = P_m, np.zeros(2)
    found = combined.from_offset(e, 3.0, R0, K, grad)
    assert abs(found.x_far[2] - 3.0) < 0.35, found.x_far
    assert found.x_rim[2] == 3.0
    for near, far in ((2.5, 0.0), (3.5, 2.0)):                  # near it / both sides
        e2 = _evidence(near, far)
        e2.mask_center, e2.size_lateral = P_m, np.zeros(2)
        assert combined.from_offset(e2, 3.0, R0, K, grad) is e2
