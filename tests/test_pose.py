"""Pose initialisation against spheres at known centres.

Masks are rendered independently of the code under test: a pixel is white when the ray
through its centre (contract: pixel (u, v) at image coordinate (u, v)) meets the sphere,
by the ray/sphere discriminant here and by Mitsuba's own sphere in one test.
"""

import numpy as np
import pytest

from inverse.pose import pose
from scenes import camera
from scenes.errors import BadInput

W, H = 320, 240
K = camera.intrinsics(W, H, 60.0)


def sphere_mask(K, size, P, R):
    """Pixels whose centre ray hits the sphere (P, R): discriminant of |t d - P| = R."""
    w, h = size
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], -1)
    b = d @ P
    return b * b - (d * d).sum(-1) * (P @ P - R * R) > 0


# Off-centre spheres (elliptical images) and centred ones, 1-2 m away, two sizes.
POSES = [((0.0, 0.0, 1.5), 0.1), ((0.55, 0.3, 1.2), 0.1), ((-0.8, -0.35, 1.8), 0.1),
         ((0.7, -0.45, 2.0), 0.08), ((-0.3, 0.3, 1.0), 0.05), ((0.9, 0.5, 1.9), 0.12),
         ((-0.5, 0.05, 1.3), 0.07), ((0.2, -0.5, 1.7), 0.1)]


def _errors(method):
    err = []
    for P, R in POSES:
        P = np.array(P)
        est = pose.initial_pose(sphere_mask(K, (W, H), P, R), K, R, method=method)[0]
        e = est - P
        depth = e @ P / np.linalg.norm(P)
        lateral = e - depth * P / np.linalg.norm(P)
        err.append((np.linalg.norm(e), abs(depth), np.linalg.norm(lateral)))
    return np.array(err)


def test_conic_within_2cm_and_better_laterally_than_cone():
    conic, cone = _errors("conic"), _errors("cone")
    print(f"\nconic |e| max {conic[:, 0].max() * 1e3:.2f} mm, mean {conic[:, 0].mean() * 1e3:.2f}"
          f" mm; lateral mean {conic[:, 2].mean() * 1e3:.2f} mm"
          f"\ncone  |e| max {cone[:, 0].max() * 1e3:.2f} mm, mean {cone[:, 0].mean() * 1e3:.2f}"
          f" mm; lateral mean {cone[:, 2].mean() * 1e3:.2f} mm")
    assert conic[:, 0].max() < 0.02                   # the requirement
    assert conic[:, 0].mean() < 0.006
    assert cone[:, 0].max() < 0.03
    # the mean boundary ray is not the cone axis for an off-centre (elliptical) image
    assert conic[:, 2].mean() < 0.5 * cone[:, 2].mean()


def _cone_rays(P, R, n=400):
    """Exact tangent rays of sphere (P, R), uniform around the cone."""
    a = P / np.linalg.norm(P)
    alpha = np.arcsin(R / np.linalg.norm(P))
    e1 = np.cross(a, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    return np.cos(alpha) * a + np.sin(alpha) * (np.cos(phi) * e1 + np.sin(phi) * e2)


@pytest.mark.parametrize("P", [(0.0, 0.0, 1.5), (0.6, -0.4, 1.2), (-1.0, 0.3, 1.1)])
def test_exact_outline_gives_exact_centre(P):
    P, R = np.array(P), 0.1
    rays = _cone_rays(P, R)
    uv = camera.project(K, rays)
    axis, alpha, ellipticity = pose.cone_from_conic(pose.fit_ellipse(uv), K)
    np.testing.assert_allclose(pose.pose_from_cone(axis, alpha, R), P, atol=1e-9)
    assert ellipticity < 1e-9
    P_fit, rms = pose.pose_conic(rays, K, R, uv=uv)
    np.testing.assert_allclose(P_fit, P, atol=1e-9)
    # the paper's method is exact only when rays are spread evenly around the cone
    np.testing.assert_allclose(pose.pose_cone(rays, R), P, atol=1e-9)


def test_paper_cone_is_biased_by_uneven_outline_sampling():
    """Points even in the image (as a mask gives) are uneven on an off-axis cone."""
    P, R = np.array([-1.0, 0.3, 1.1]), 0.1
    uv = camera.project(K, _cone_rays(P, R, 4000))
    step = np.r_[0, np.cumsum(np.linalg.norm(np.diff(uv, axis=0), axis=1))]
    even = np.linspace(0, step[-1], 400, endpoint=False)
    uv = np.stack([np.interp(even, step, uv[:, 0]), np.interp(even, step, uv[:, 1])], 1)
    rays = camera.pixel_rays(K, uv[:, 0], uv[:, 1])
    assert np.linalg.norm(pose.pose_conic(rays, K, R, uv=uv)[0] - P) < 1e-5
    assert np.linalg.norm(pose.pose_cone(rays, R) - P) > 1e-3


def test_outline_is_half_a_pixel_outside_white_pixel_centres():
    """A centred disk of radius 20 px: the outline's mean radius is 20, not 19.5."""
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    c = np.array([160.3, 120.7])
    mask = (u - c[0]) ** 2 + (v - c[1]) ** 2 < 20.0 ** 2
    uv = pose.mask_outline_uv(mask)
    r = np.linalg.norm(uv - c, axis=1)
    assert abs(r.mean() - 20.0) < 0.05
    assert r.std() < 0.3


def test_outline_rays_are_tangent_to_the_sphere():
    P, R = np.array([0.4, 0.2, 1.4]), 0.1
    rays = pose.mask_outline_rays(sphere_mask(K, (W, H), P, R), K)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-12)
    res_px = pose.tangent_residuals(P, R, rays) * K[0, 0]
    assert np.sqrt(np.mean(res_px ** 2)) < 0.3      # pixel quantisation only
    assert abs(res_px.mean()) < 0.05                 # and no bias


def test_mitsuba_sphere_mask():
    """Mask from Mitsuba's own ray/sphere intersection of the contract's pixel rays."""
    from scenes import backend

    mi = backend.modules()[1]

    P, R = np.array([-0.45, 0.25, 1.6]), 0.1
    scene = mi.load_dict({"type": "scene",
                          "s": {"type": "sphere", "center": P.tolist(), "radius": R}})
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    d = camera.pixel_rays(K, u.ravel(), v.ravel())
    ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(d.T.astype(np.float32)))
    mask = np.asarray(scene.ray_intersect(ray).is_valid()).reshape(H, W)
    assert (mask != sphere_mask(K, (W, H), P, R)).sum() <= 2
    est = pose.initial_pose(mask[None], K, [R])
    assert est.shape == (1, 3)
    assert np.linalg.norm(est[0] - P) < 0.01


def test_several_masks_and_radii():
    Ps = np.array([[-0.5, 0.2, 1.5], [0.0, 0.25, 1.2], [0.5, 0.2, 1.6]])
    R = np.array([0.1, 0.06, 0.12])
    masks = np.stack([sphere_mask(K, (W, H), p, r) for p, r in zip(Ps, R)])
    est = pose.initial_pose(masks, K, R)
    assert np.abs(est - Ps).max() < 0.02
    # the key's scale: every distance scales with the radius
    np.testing.assert_allclose(pose.initial_pose(masks, K, 2 * R), 2 * est, rtol=1e-6)


def _bad(mask, radius=0.1, **kw):
    with pytest.raises(BadInput) as exc:
        pose.initial_pose(mask, K, radius, **kw)
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_bad_masks():
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    empty = np.zeros((H, W), bool)
    assert "empty" in _bad(empty)
    square = empty.copy()
    square[100:140, 140:180] = True
    assert "not round" in _bad(square)
    pacman = ((u - 160) ** 2 + (v - 120) ** 2 < 30 ** 2) & ~((u > 160) & (abs(v - 120) < 9))
    assert "not round" in _bad(pacman)
    wide = ((u - 160) / 40.0) ** 2 + ((v - 120) / 20.0) ** 2 < 1   # no sphere images so
    assert "not round" in _bad(wide)
    two = ((u - 80) ** 2 + (v - 120) ** 2 < 15 ** 2) | ((u - 240) ** 2 + (v - 120) ** 2 < 15 ** 2)
    assert "blobs" in _bad(two)
    cut = (u - 4) ** 2 + (v - 120) ** 2 < 15 ** 2
    assert "border" in _bad(cut)
    tiny = empty.copy()
    tiny[100:103, 100:103] = True
    assert "fewer than" in _bad(tiny)
    assert "(n, H, W)" in _bad(np.zeros((1, 2, H, W), bool))


def test_bad_keys_and_arguments():
    P, R = np.array([0.1, 0.1, 1.5]), 0.1
    mask = sphere_mask(K, (W, H), P, R)
    assert "metres" in _bad(mask, 100.0)            # radius in mm: ~1.5 km away
    assert "touch the camera" in _bad(mask, 0.0005)
    assert "positive" in _bad(mask, -0.1)
    assert "positive" in _bad(mask, float("nan"))
    assert "radii" in _bad(np.stack([mask, mask]), [0.1, 0.1, 0.1])
    assert "method" in _bad(mask, method="bbox")
    # a speck of segmentation noise beside the totem is ignored, not an error
    noisy = mask.copy()
    noisy[10, 10] = True
    np.testing.assert_allclose(pose.initial_pose(noisy, K, R), pose.initial_pose(mask, K, R))
