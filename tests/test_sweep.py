"""Tests of inverse/sweep: plane-sweep stereo finds the depth of a textured plane seen
through totems, and pull-push hole filling."""

from __future__ import annotations

import numpy as np

from inverse import backend, camera
from inverse.grid import frame_for_scene
from inverse.sweep import plane_sweep, pull_push, slice_depths

backend.use()

import mitsuba as mi  # noqa: E402

from inverse.sphere import totem_rays  # noqa: E402

W, H = 240, 180
K = camera.intrinsics(W, H, 60.0)
CENTERS = np.array([[-0.48, 0.25, 1.18], [-0.16, 0.26, 1.34], [0.17, 0.30, 1.52],
                    [0.58, 0.34, 1.33]])
RADIUS = 0.1


def _texture(x, y):
    """A smooth colour texture on the plane (metres -> [0, 1] RGB)."""
    rng = np.random.default_rng(0)
    f = rng.normal(0.0, 2.5, (8, 2))
    ph = rng.random((8, 3)) * 6.0
    return np.stack([0.5 + 0.5 * np.mean([np.sin(f[i, 0] * x + f[i, 1] * y + ph[i, c])
                                          for i in range(8)], 0) for c in range(3)], -1)


def _rays_onto_plane(z_plane):
    """Refracted totem rays (exit point, direction), totem index and the colour of the
    plane ``z = z_plane`` where each ray meets it."""
    vv, uu = np.mgrid[0:H, 0:W]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    js = np.full(len(d), -1)
    for j, P in enumerate(CENTERS):
        b = d @ P
        js[(b ** 2 - (P @ P - RADIUS ** 2) > 0) & (js < 0)] = j
    d, js = d[js >= 0], js[js >= 0]
    P = CENTERS[js].astype(np.float32)
    o, do, _, ok = totem_rays(mi.Point3f(0.0), mi.Vector3f(*d.T.astype(np.float32)),
                              mi.Point3f(*P.T), RADIUS, 1.52)
    o = np.asarray(o, np.float64).T.reshape(-1, 3)
    do = np.asarray(do, np.float64).T.reshape(-1, 3)
    t = (z_plane - o[:, 2]) / do[:, 2]
    ok = np.asarray(ok, bool).ravel() & (t > 0)
    X = o + t[:, None] * do
    return o[ok], do[ok], js[ok], _texture(X[ok, 0], X[ok, 1])


def test_sweep_finds_a_textured_plane_depth():
    z_plane = 3.0
    o, d, js, col = _rays_onto_plane(z_plane)
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
    truth = _texture(X[..., 0], X[..., 1])
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
