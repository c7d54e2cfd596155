"""inverse/rim and scenes/drawn_masks: the pose from the photo's edges, when the mask is
drawn the way people draw it, lands near the truth where the mask's own pose does not."""

from __future__ import annotations

import numpy as np
import pytest

from inverse.pose import pose, rim
from scenes import folder
from scenes.photo import drawn_masks


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from scenes.synthetic.make import make_scene

    out = make_scene(tmp_path_factory.mktemp("rim") / "s", preset="envmap", seed=2,
                     size=(640, 480), spp=16)
    return folder.read_scene(out), folder.read_truth(out)


def _errors(scene, truth, family, seed=0):
    """Pose errors (% of the distance) from the mask and from the photo, per totem."""
    rng = np.random.default_rng(seed)
    K = np.asarray(scene.K)
    R = np.broadcast_to(np.asarray(scene.radius, float), (scene.n_totems,))
    masks = np.stack([drawn_masks.family(family, m, rng) for m in scene.masks])
    P_mask = pose.initial_pose(masks, K, R)
    P_photo = rim.refine_centres(scene.image, P_mask, R, K)
    dist = np.linalg.norm(truth.totem_pose, axis=1)
    return (100 * np.linalg.norm(P_mask - truth.totem_pose, axis=1) / dist,
            100 * np.linalg.norm(P_photo - truth.totem_pose, axis=1) / dist)


@pytest.mark.slow
@pytest.mark.parametrize("family", ["grown2", "poly12"])
def test_the_photo_corrects_a_hand_drawn_mask(scene, family):
    from_mask, from_photo = _errors(*scene, family)
    assert np.median(from_mask) > 1.5                 # the mask alone is far off ...
    assert np.median(from_photo) <= 0.6 and from_photo.max() <= 1.2, from_photo
    assert np.all(from_photo < from_mask)             # ... the photo brings each back


def test_the_outline_is_the_spheres_silhouette():
    """The outline points are rays tangent to the sphere (its tangent cone)."""
    from scenes import camera

    K = camera.intrinsics(320, 240, 60.0)
    P, R = np.array([0.2, 0.1, 1.5]), 0.1
    pts, nrm = rim.outline(P, R, K, n=64)
    rays = camera.pixel_rays(K, pts[:, 0], pts[:, 1])
    assert np.abs(pose.tangent_residuals(P, R, rays)).max() < 1e-6
    # normals point away from the centre's image
    c = camera.project(K, P[None])[0]
    assert np.all(((pts - c) * nrm).sum(1) > 0)


def test_the_rim_is_found_on_a_drawn_disc():
    """A bright disc drawn as the sphere's exact image on a dark ground: starting from
    a centre 3 % too far (its outline 1-2 px too small), the search finds the rim."""
    from scenes import camera

    W, H = 320, 240
    K = camera.intrinsics(W, H, 60.0)
    P, R = np.array([-0.1, 0.05, 1.2]), 0.08
    vv, uu = np.mgrid[0:H, 0:W]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    inside = (d @ (P / np.linalg.norm(P))) > np.cos(np.arcsin(R / np.linalg.norm(P)))
    img = np.where(inside.reshape(H, W, 1), 0.8, 0.2) * np.ones((1, 1, 3))
    from scipy.ndimage import gaussian_filter
    img = gaussian_filter(img, (0.5, 0.5, 0)).astype(np.float32)   # anti-aliased edge
    found = rim.refine_centres(img, (P * 1.03)[None], np.array([R]), K)[0]
    assert np.linalg.norm(found - P) / np.linalg.norm(P) < 0.005


def _band_disc(W, H, K, P, R, band_px, steps):
    """A disc drawn as the sphere's exact image with a darker disc ``band_px`` inside it
    (the inner edge of a rim's reflection band): ``steps`` = (the silhouette's step,
    the band edge's step), anti-aliased."""
    from scipy.ndimage import gaussian_filter
    from scenes import camera

    vv, uu = np.mgrid[0:H, 0:W]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    ang = np.arccos(np.clip(d @ (P / np.linalg.norm(P)), -1, 1)).reshape(H, W)
    half = np.arcsin(R / np.linalg.norm(P))
    inner = np.arctan(np.tan(half) - band_px / K[0, 0])
    img = 0.5 - steps[0] * (ang < half) - steps[1] * (ang < inner)
    return gaussian_filter(np.repeat(img[..., None], 3, 2), (0.5, 0.5, 0)).astype(np.float32)


def test_the_mask_tells_the_silhouette_from_a_stronger_band_inside():
    """An inner edge 4 px inside a 28 px silhouette, 1.6 times as strong (as on window
    seed 11's totems): from the exact mask, or one grown by 2 px, the search keeps the
    silhouette; by the edge alone (no weight for the mask's size) it takes the band,
    over 10 % too far."""
    from scenes import camera, silhouette

    W, H = 320, 240
    K = camera.intrinsics(W, H, 60.0)
    P, R = np.array([0.1, 0.05, 1.0]), 0.1
    img = _band_disc(W, H, K, P, R, 4.0, (0.1, 0.16))
    grad = silhouette.gradients(img, rim.SIGMA_PX)
    err = lambda Q: np.linalg.norm(Q - P) / np.linalg.norm(P)
    for start in (P, P * 0.94):                           # exact, and about 2 px larger
        assert err(rim.refine_centre(start, R, K, grad)) < 0.01
    assert err(rim.refine_centre(P, R, K, grad, mask_sigma_px=np.inf)) > 0.1


def test_drawn_mask_families_differ_as_described():
    from scenes import camera

    K = camera.intrinsics(320, 240, 60.0)
    vv, uu = np.mgrid[0:240, 0:320]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    P = np.array([0.0, 0.1, 1.2])
    mask = ((d @ (P / np.linalg.norm(P))) > np.cos(np.arcsin(0.1 / 1.2))).reshape(240, 320)
    rng = np.random.default_rng(1)
    assert drawn_masks.grown(mask, 2).sum() > mask.sum() > drawn_masks.grown(mask, -2).sum()
    poly = drawn_masks.polygon(mask, 8, rng)
    assert poly.sum() < mask.sum() and (poly & ~mask).sum() < 0.02 * mask.sum()
    cut = drawn_masks.occluded(mask, 0.1, rng)
    assert abs(1 - cut.sum() / mask.sum() - 0.1) < 0.02
