"""A textured plane seen through four totems: the refracted rays and the colour each
one carries (shared by the stereo tests)."""

from __future__ import annotations

import numpy as np

from inverse.sphere import totem_rays
from scenes import backend, camera

mi = backend.modules()[1]

W, H = 240, 180
K = camera.intrinsics(W, H, 60.0)
CENTERS = np.array([[-0.48, 0.25, 1.18], [-0.16, 0.26, 1.34], [0.17, 0.30, 1.52],
                    [0.58, 0.34, 1.33]])
RADIUS = 0.1


def texture(x, y):
    """A smooth colour texture on the plane (metres -> [0, 1] RGB)."""
    rng = np.random.default_rng(0)
    f = rng.normal(0.0, 2.5, (8, 2))
    ph = rng.random((8, 3)) * 6.0
    return np.stack([0.5 + 0.5 * np.mean([np.sin(f[i, 0] * x + f[i, 1] * y + ph[i, c])
                                          for i in range(8)], 0) for c in range(3)], -1)


def rays_onto_plane(z_plane):
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
    return o[ok], do[ok], js[ok], texture(X[ok, 0], X[ok, 1])
