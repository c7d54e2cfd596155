"""Tests of inverse/splat and inverse/stereo: rays meet a depth map where they pass
behind it, splatting rebuilds the camera view, and leave-one-totem-out prefers the
true geometry."""

from __future__ import annotations

import numpy as np

from inverse.grid import frame_for_scene
from inverse.rays import TotemRays
from inverse.view.splat import holdout_error, splat_image, surface_hits
from inverse.view.sweep import slice_depths
from inverse.view.view import choose_view, stereo_weight
from scenes import camera
from plane_cases import CENTERS, RADIUS, H, K, W, rays_onto_plane, texture

FRAME = frame_for_scene(K, (W, H), CENTERS, np.full(4, RADIUS))


def _plane_map(z, res=(60, 80)):
    return np.full(res, float(z))


def test_rays_meet_a_plane_at_its_projected_point():
    z_plane = 2.5
    o, d, _, _ = rays_onto_plane(z_plane)
    u, v, z, hit = surface_hits(o, d, FRAME, _plane_map(z_plane), n_steps=512)
    t = (z_plane - o[:, 2]) / d[:, 2]
    uv = camera.project(K, o + t[:, None] * d)
    inside = hit & (np.abs(uv[:, 0] - W / 2) < W / 3) & (np.abs(uv[:, 1] - H / 2) < H / 3)
    assert inside.sum() > 1000
    # The planes are 512 steps even in inverse depth: the hit lies on the first one
    # at or behind the surface, so within a step of it.
    dz = z_plane ** 2 * (1 / FRAME.near - 1 / FRAME.far) / 512
    assert np.all((z[inside] >= z_plane - 1e-9) & (z[inside] <= z_plane + 2 * dz))
    assert np.median(np.hypot(u - uv[:, 0], v - uv[:, 1])[inside]) < 1.0


def test_a_ray_that_meets_nothing_stops_at_the_far_backdrop():
    o = np.array([[0.0, 0.0, 1.0]])
    d = np.array([[0.0, 0.0, 1.0]])
    u, v, z, hit = surface_hits(o, d, FRAME, _plane_map(np.inf), n_steps=64)
    assert hit[0] and z[0] == slice_depths(FRAME, 64)[-1]
    assert np.allclose([u[0], v[0]], K[:2, 2], atol=1e-6)


def test_splat_keeps_each_value_at_its_pixel_and_fills_between():
    rng = np.random.default_rng(5)
    n = 3000
    u = rng.integers(0, W, n).astype(float)
    v = rng.integers(0, H, n).astype(float)
    values = np.stack([u / W, v / H, np.full(n, 0.5)], 1)
    img = splat_image(u, v, values, (W, H))
    assert img.shape == (H, W, 3)
    assert np.allclose(img[v.astype(int), u.astype(int)], values)
    yy, xx = np.mgrid[0:H, 0:W]
    assert np.abs(img[..., 0] - xx / W).mean() < 0.03
    assert np.abs(img[..., 1] - yy / H).mean() < 0.03


def test_holdout_error_is_least_at_the_true_depth():
    z_plane = 3.0
    o, d, js, col = rays_onto_plane(z_plane)
    errs = {z: holdout_error(o, d, col, js, FRAME, _plane_map(z), (W, H))[0]
            for z in (1.8, 3.0, 6.0)}
    assert errs[3.0] < 0.7 * min(errs[1.8], errs[6.0])


def test_stereo_replaces_a_wrong_grid_geometry_and_rebuilds_the_view():
    z_plane = 3.0
    o, d, js, col = rays_onto_plane(z_plane)
    cos_in = np.ones(len(o))
    lin = col ** 2.2                     # any radiance; the view is compared in display
    wrong = np.full((30, 40), FRAME.far)             # a far backdrop, as fits settle
    flat = np.full((H, W, 3), 0.5, np.float32)       # and a grey view from it
    rays = TotemRays(o, d, lin, js, cos_in)
    view = choose_view(rays, FRAME, wrong, flat, np.zeros((0, 3)), (W, H), res=(45, 60),
                       far_biases=(0.0,))
    assert view.chosen == "stereo" and view.stereo_share > 0.5
    assert view.holdout["stereo"] < view.holdout["grid"]
    # Where the totems see the plane, the splatted view is the plane's texture.
    rows, cols = slice(int(0.35 * H), int(0.6 * H)), slice(int(0.3 * W), int(0.7 * W))
    vv, uu = np.mgrid[rows, cols]
    X = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    X = X / X[:, 2:3] * z_plane
    truth = texture(X[:, 0], X[:, 1])
    from scenes.colour import linear_to_srgb
    got = view.recon[rows, cols].reshape(-1, 3)
    expect = linear_to_srgb(np.clip(truth ** 2.2, 0, 1))
    spread = np.abs(expect - expect.mean(0)).mean()
    assert np.abs(got - expect).mean() < 0.5 * spread
    # Its points lie on the plane.
    assert np.median(np.abs(view.points[:, 2] - z_plane)) < 0.1
    # A right grid geometry is kept.
    kept = choose_view(rays, FRAME, np.full((30, 40), z_plane), flat, np.zeros((0, 3)),
                       (W, H), res=(45, 60), far_biases=(0.0,))
    assert kept.holdout["grid"] <= 1.05 * kept.holdout["stereo"]


def test_each_pixel_takes_the_geometry_whose_held_out_rays_erred_less_nearby():
    z_plane = 3.0
    o, d, js, col = rays_onto_plane(z_plane)
    lin = col ** 2.2
    from scenes.colour import linear_to_srgb
    vv, uu = np.mgrid[0:H, 0:W]
    X = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    truth = linear_to_srgb(np.clip(texture(*(X[:, :2] / X[:, 2:3] * z_plane).T) ** 2.2, 0, 1))
    truth = truth.reshape(H, W, 3).astype(np.float32)
    # The grid is right left of u = 0.55 W (depth and view) and a far backdrop beyond.
    s_cut = FRAME.pixel_to_st(0.55 * W, 0)[0]
    grid_depth = np.full((30, 40), z_plane)
    grid_depth[:, int(s_cut * 40):] = FRAME.far
    grid_view = truth.copy()
    grid_view[:, int(0.55 * W):] = 0.5
    view = choose_view(TotemRays(o, d, lin, js, np.ones(len(o))), FRAME, grid_depth,
                       grid_view, np.zeros((0, 3)), (W, H), res=(45, 60), far_biases=(0.0,))
    rows = slice(int(0.35 * H), int(0.6 * H))
    right = (rows, slice(int(0.62 * W), int(0.7 * W)))
    left = (rows, slice(int(0.3 * W), int(0.48 * W)))
    grey = np.abs(0.5 - truth[right]).mean()
    assert np.abs(view.recon[right] - truth[right]).mean() < 0.6 * grey
    assert np.abs(view.recon[left] - truth[left]).mean() < 0.6 * np.abs(
        truth[left] - truth[left].mean((0, 1))).mean()
    assert 0.0 < view.stereo_share < 1.0


def test_stereo_weight_follows_the_local_held_out_errors():
    rng = np.random.default_rng(7)
    n = 4000
    u = rng.uniform(0, W, n)
    v = rng.uniform(0, H / 2, n)                     # no rays in the lower half
    left = u < W / 2
    grid = (np.where(left, 0.01, 0.08), u, v)        # the grid errs on the right ...
    stereo = (np.where(left, 0.05, 0.02), u, v)      # ... stereo on the left
    for prefer in (False, True):
        w = stereo_weight(grid, stereo, (W, H), prefer_stereo=prefer, sigma=8.0)
        assert w.shape == (H, W)
        assert w[: H // 3, : W // 3].max() < 0.1
        assert w[: H // 3, 2 * W // 3:].min() > 0.9
        # Where no held-out ray landed, the whole view's choice.
        assert np.allclose(w[-H // 6:], float(prefer), atol=0.05)


def test_stereo_must_beat_the_grid_by_the_margin():
    rng = np.random.default_rng(8)
    n = 4000
    u = rng.uniform(0, W, n)
    v = rng.uniform(0, H, n)
    grid = (np.full(n, 0.10), u, v)
    stereo = (np.full(n, 0.09), u, v)                # 10 % better everywhere
    taken = stereo_weight(grid, stereo, (W, H), prefer_stereo=False, margin=1.0)
    kept = stereo_weight(grid, stereo, (W, H), prefer_stereo=False, margin=0.8)
    inner = (slice(H // 4, 3 * H // 4), slice(W // 4, 3 * W // 4))
    assert taken[inner].min() > 0.9 and kept[inner].max() < 0.1
    # The whole view's choice follows the same rule: a stereo map at the true depth
    # against a grid at the true depth too; stereo's hold-out is not 20 % lower.
    z_plane = 3.0
    o, d, js, col = rays_onto_plane(z_plane)
    flat = np.full((H, W, 3), 0.5, np.float32)
    view = choose_view(TotemRays(o, d, col ** 2.2, js, np.ones(len(o))), FRAME,
                       np.full((30, 40), z_plane), flat, np.zeros((0, 3)), (W, H),
                       res=(45, 60), far_biases=(0.0,), margin=0.8)
    assert view.chosen == "grid"
    assert view.holdout["stereo"] > 0.8 * view.holdout["grid"]


def test_splat_interpolates_linearly_between_rays_and_reads_pixels_alike():
    # Rays on a coarse lattice carrying a linear ramp: between them the splat is the
    # ramp itself (pull-push alone would blur it towards its coarse levels' mean).
    vv, uu = np.mgrid[10:H - 10:12, 10:W - 10:12]
    u, v = uu.ravel().astype(float), vv.ravel().astype(float)
    values = np.stack([u / W, v / H], 1)
    img = splat_image(u, v, values, (W, H))
    rows, cols = slice(20, H - 30), slice(20, W - 30)
    yy, xx = np.mgrid[rows, cols]
    assert np.abs(img[rows, cols, 0] - xx / W).max() < 1e-6
    assert np.abs(img[rows, cols, 1] - yy / H).max() < 1e-6
    # Outside the rays' hull it is still filled; reading pixels gives the same values.
    assert np.all(np.isfinite(img))
    pick = (np.array([0, 5, W - 1, 100]), np.array([0, H - 1, 3, 50]))
    assert np.allclose(splat_image(u, v, values, (W, H), at=pick), img[pick[1], pick[0]])


def test_linear_interpolation_is_exact_for_a_plane_and_covers_the_hull():
    """Any triangle holding a pixel reproduces a linear function exactly, so a query
    placed in the wrong triangle would show; the hull must be scipy's (qhull's)."""
    from scipy.spatial import Delaunay

    from inverse.view.splat import linear_at

    rng = np.random.default_rng(7)
    flat = np.unique(rng.integers(0, W * H, 2500))
    px = np.stack([flat % W, flat // W], 1)
    plane = (0.25 + 0.01 * px[:, 0] - 0.02 * px[:, 1])[:, None]
    vq, uq = np.divmod(np.arange(W * H), W)
    got = linear_at(px, plane, uq, vq, (W, H))[:, 0]
    inside = Delaunay(px.astype(float)).find_simplex(np.stack([uq, vq], 1).astype(float)) >= 0
    assert np.array_equal(np.isfinite(got), inside)
    assert np.allclose(got[inside], 0.25 + 0.01 * uq[inside] - 0.02 * vq[inside], atol=1e-9)


def test_blur_is_ndimages_gaussian_on_a_map():
    from scipy import ndimage

    from inverse.view.splat import blur

    img = np.random.default_rng(2).uniform(0, 1, (H, W))
    for sigma in (8.0, 16.0):
        assert np.allclose(blur(img, sigma), ndimage.gaussian_filter(img, sigma), atol=1e-12)


def test_the_whole_views_leaning_to_stereo_is_continuous_across_the_margin():
    """A fit's last bits must not swap one whole view for the other: the leaning moves
    from 1 to 0 over the band around the margin, never by a jump."""
    from inverse.view.view import preference

    grid = 0.05
    ratios = np.linspace(0.8, 1.2, 401)
    lean = np.array([preference(grid, r * 0.9 * grid, margin=0.9, band=0.05) for r in ratios])
    assert lean[0] == 1.0 and lean[-1] == 0.0
    assert np.all(np.diff(lean) <= 0) and np.max(np.abs(np.diff(lean))) < 0.02
    assert abs(preference(grid, 0.9 * grid, margin=0.9) - 0.5) < 1e-12
    assert preference(grid, np.inf) == 0.0 and preference(np.inf, grid) == 1.0
