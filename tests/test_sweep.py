"""Tests of inverse/sweep: plane-sweep stereo finds the depth of a textured plane seen
through totems, and pull-push hole filling."""

from __future__ import annotations

import numpy as np

from inverse.grid import frame_for_scene
from inverse.view.sweep import plane_sweep, pull_push, semi_global, slice_depths
from plane_cases import CENTERS, RADIUS, H, K, W, rays_onto_plane, texture


def test_sweep_finds_a_textured_plane_depth():
    z_plane = 3.0
    o, d, js, col = rays_onto_plane(z_plane)
    frame = frame_for_scene(K, (W, H), CENTERS, np.full(4, RADIUS))
    n = 48
    sw = plane_sweep(o, d, col, js, frame, (45, 60), n_slices=n)
    z = slice_depths(frame, n)
    k_true = int(np.argmin(np.abs(z - z_plane)))
    k = sw.r * n - 0.5
    # Where the camera sees the plane through several totems (the image centre).
    s, t = frame.pixel_to_st(np.array([0.3 * W, 0.7 * W]), np.array([0.3 * H, 0.6 * H]))
    rows = slice(int(t[0] * 45), int(t[1] * 45))
    cols = slice(int(s[0] * 60), int(s[1] * 60))
    centre = k[rows, cols]
    assert abs(np.median(centre) - k_true) <= 1.0
    assert np.mean(np.abs(centre - k_true) <= 2) > 0.8
    assert np.allclose(sw.depth, 1.0 / (1.0 / frame.near - sw.r * (1.0 / frame.near
                                                                   - 1.0 / frame.far)))
    # The swept colour there is the plane's texture at the camera ray's hit point.
    st = np.stack(np.meshgrid((np.arange(60) + 0.5) / 60, (np.arange(45) + 0.5) / 45), -1)
    X = frame.from_unit(np.concatenate([st, np.zeros(st.shape[:2] + (1,))], -1))
    X = X / X[..., 2:3] * z_plane
    truth = texture(X[..., 0], X[..., 1])
    err = np.abs(sw.colour - truth)[rows, cols].mean()
    # Blurred by the splat spread (a few rays per sigma disc), but it is the texture.
    assert err < 0.65 * np.abs(truth[rows, cols] - truth[rows, cols].mean((0, 1))).mean()


def test_pull_push_keeps_known_values_and_fills_holes():
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:40, 0:50]
    field = np.stack([0.01 * xx + 0.02 * yy, 0.5 + 0 * xx, 0.3 + 0.01 * yy], -1)
    w = (rng.random((40, 50)) < 0.2).astype(float)
    w[10:25, 15:35] = 0.0                               # a large hole
    out = pull_push(field * w[..., None], w)
    assert np.allclose(out[w >= 1], field[w >= 1])
    hole = w == 0
    assert np.all(np.isfinite(out))
    assert np.abs(out[hole] - field[hole]).mean() < 0.1 * np.ptp(field[..., 0])
    assert np.allclose(out[..., 1], 0.5)


def test_semi_global_matching_recovers_a_piecewise_constant_label_from_noise():
    rng = np.random.default_rng(3)
    K_, H_, W_ = 16, 30, 40
    labels = np.where(np.arange(W_)[None, :] < 20, 4, 11) * np.ones((H_, 1), int)
    cost = rng.random((K_, H_, W_))                        # pure noise ...
    np.put_along_axis(cost, labels[None], 0.1, 0)          # ... the truth lower
    raw = np.argmin(cost, 0)
    agg = np.argmin(semi_global(cost, 0.3, 1.0), 0)
    assert np.mean(raw == labels) < 0.6
    assert np.mean(agg == labels) > 0.95
    # The aggregation keeps the edge: columns next to it on either side are right.
    assert np.mean(agg[:, 18] == 4) > 0.9 and np.mean(agg[:, 21] == 11) > 0.9


def test_the_shared_consistency_is_the_landing_totems_mean_and_variance():
    from inverse.view.sweep import SliceColours

    rng = np.random.default_rng(2)
    n_tot, nk, nt, ns = 4, 5, 6, 7
    colour = rng.random((n_tot, nk, nt, ns, 3)).astype(np.float32)
    land = rng.random((n_tot, nk, nt, ns)) < 0.6
    sc = SliceColours(colour, land, np.ones_like(land, float), np.arange(nk), 1.0)
    n_land, mean, var = sc.consistency
    assert sc.consistency[0] is n_land                       # computed once
    for k, i, j in [(0, 0, 0), (2, 3, 4), (4, 5, 6), (1, 2, 3)]:
        c = colour[land[:, k, i, j], k, i, j].astype(np.float64)
        assert n_land[k, i, j] == len(c)
        if len(c):
            assert np.allclose(mean[k, i, j], c.mean(0), atol=1e-6)
            assert np.isclose(var[k, i, j], ((c - c.mean(0)) ** 2).sum(1).mean(),
                              atol=1e-6)


def test_blur_cells_is_ndimages_gaussian_with_zero_outside():
    from scipy import ndimage

    from inverse.view.sweep import blur_cells

    rng = np.random.default_rng(3)
    maps = rng.uniform(0, 1, (2, 5, 12, 17)).astype(np.float32)
    for sigma in (0.7, 1.9):
        want = ndimage.gaussian_filter(maps, (0, 0, sigma, sigma), mode="constant",
                                       truncate=2.5)
        assert np.allclose(blur_cells(maps, sigma), want, atol=1e-6)
        colour = np.repeat(maps[..., None], 3, -1) * np.array([1.0, 0.5, 2.0], np.float32)
        want_c = ndimage.gaussian_filter(colour, (0, 0, sigma, sigma, 0), mode="constant",
                                         truncate=2.5)
        assert np.allclose(blur_cells(colour, sigma, channels=True), want_c, atol=1e-6)


def test_a_rays_pixel_on_a_depth_plane_is_affine_in_inverse_depth():
    from scenes.camera import project

    from inverse.view.sweep import pixel_lines

    rng = np.random.default_rng(4)
    K = np.array([[500.0, 0.3, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
    o = rng.normal(0, 0.2, (50, 3)) + [0, 0, 1.5]
    d = rng.normal(0, 0.3, (50, 3)) + [0, 0, 1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    au, bu, av, bv, _ = pixel_lines(o, d, K)
    for z in (2.0, 7.5):
        t = (z - o[:, 2]) / d[:, 2]
        uv = project(K, o + t[:, None] * d)
        assert np.allclose(au + bu / z, uv[:, 0]) and np.allclose(av + bv / z, uv[:, 1])
