"""Tests of the fit's step made cheaper (inverse/integrator.density_at, the total
variation's gradient by a stencil): each against the plain computation it replaces,
values and gradients, to float precision."""

from __future__ import annotations

import numpy as np

from scenes import backend

dr, mi = backend.modules()


def _grad(x, f):
    """The gradient of ``f(x)`` (a scalar mi.Float) with respect to the flat ``x``."""
    x = mi.Float(x)
    dr.enable_grad(x)
    y = f(x)
    dr.backward(y)
    return np.asarray(y)[0], np.asarray(dr.grad(x))


def test_density_at_is_the_textures_trilinear_lookup_with_its_gradient():
    from inverse.integrator import density_at

    rng = np.random.default_rng(3)
    shape = (5, 7, 9, 1)
    grid = rng.normal(size=shape).astype(np.float32)
    # Points inside, on the faces and corners, and outside the unit cube (clamped).
    p = rng.uniform(-0.1, 1.1, (4000, 3)).astype(np.float32)
    p[:8] = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    P = mi.Point3f(*[mi.Float(p[:, a]) for a in range(3)])
    v = mi.Float(rng.normal(size=len(p)).astype(np.float32))

    def ours(x):
        return dr.sum(v * density_at(mi.Texture3f(mi.TensorXf(x, shape)), P))

    def texture(x):
        return dr.sum(v * mi.Texture3f(mi.TensorXf(x, shape)).eval(P)[0])

    y0, g0 = _grad(grid.ravel(), texture)
    y1, g1 = _grad(grid.ravel(), ours)
    lookups = np.asarray(density_at(mi.Texture3f(mi.TensorXf(grid)), P))
    expected = np.asarray(mi.Texture3f(mi.TensorXf(grid)).eval(P)[0])
    assert np.abs(lookups - expected).max() <= 1e-6 * np.abs(expected).max()
    assert abs(y1 - y0) <= 1e-5 * abs(y0)
    assert np.abs(g1 - g0).max() <= 1e-5 * np.abs(g0).max()
    # A cell centre reads its own value; halfway between two centres, their mean.
    c = np.array([[(2 + 0.5) / 9, (3 + 0.5) / 7, (1 + 0.5) / 5],
                  [(2 + 1.0) / 9, (3 + 0.5) / 7, (1 + 0.5) / 5]], np.float32)
    Pc = mi.Point3f(*[mi.Float(c[:, a]) for a in range(3)])
    got = np.asarray(density_at(mi.Texture3f(mi.TensorXf(grid)), Pc))
    assert np.allclose(got, [grid[1, 3, 2, 0], grid[1, 3, 2:4, 0].mean()], atol=1e-6)


def test_total_variation_and_its_stencil_gradient_against_numpy():
    from inverse.fit.losses import TotalVariation

    rng = np.random.default_rng(5)
    for shape in ((4, 5, 6, 1), (1, 6, 7, 3), (2, 1, 3, 3)):
        x = rng.normal(size=shape).astype(np.float64)
        pairs = [np.diff(x, axis=a) for a in range(3)]
        count = sum(d.size for d in pairs)
        value = sum(np.square(d).sum() for d in pairs) / count
        grad = np.zeros_like(x)
        for a, d in enumerate(pairs):                  # d/dx of (x[k+1] - x[k])^2
            hi = [slice(None)] * 4
            lo = [slice(None)] * 4
            hi[a], lo[a] = slice(1, None), slice(None, -1)
            grad[tuple(hi)] += 2 * d
            grad[tuple(lo)] -= 2 * d
        grad /= count
        tv = TotalVariation(shape)
        y, g = _grad(x.astype(np.float32).ravel(),
                     lambda t: tv(mi.TensorXf(t, shape[:3] + (shape[3],))))
        assert abs(y - value) <= 1e-5 * value
        assert np.abs(g - grad.ravel()).max() <= 1e-5 * np.abs(grad).max()
        # Without gradients it is the plain value.
        assert abs(np.asarray(tv(mi.TensorXf(x.astype(np.float32))))[0] - value) <= 1e-5 * value


def test_a_step_gives_the_loss_and_gradients_of_the_texture_lookup(monkeypatch):
    """The whole photometric + distortion + TV loss of a batch of totem rays, and its
    gradients in the grids and the centres, with the density read by ``density_at`` and
    by ``mi.Texture3f.eval`` (the plain step): equal to float rounding."""
    from inverse import integrator
    from inverse.fit.batches import DeviceRays, photo_terms
    from inverse.fit.losses import TotalVariation
    from inverse.grid import frame_for_scene
    from inverse.rays import TotemPixels
    from scenes import camera

    W, H = 80, 60
    K = camera.intrinsics(W, H, 60.0)
    centers = np.array([[-0.25, 0.1, 1.4], [0.25, 0.12, 1.5]])
    radius, ior = np.array([0.1, 0.1]), np.array([1.52, 1.52])
    rng = np.random.default_rng(2)
    frame = frame_for_scene(K, (W, H), centers, radius)
    density = rng.normal(-1.0, 1.5, (6, 8, 10, 1)).astype(np.float32)
    colour = rng.random((1, 8, 10, 3)).astype(np.float32)
    vv, uu = np.mgrid[0:H, 0:W]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    j = np.argmin([np.linalg.norm(np.cross(d, P / np.linalg.norm(P)), axis=1)
                   for P in centers], axis=0)
    hit = np.linalg.norm(np.cross(d, centers[j] / np.linalg.norm(centers[j], axis=1)[:, None]),
                         axis=1) < 0.6 * radius[j] / np.linalg.norm(centers[j], axis=1)
    pixels = TotemPixels(u=uu.ravel()[hit], v=vv.ravel()[hit], d_cam=d[hit], totem=j[hit],
                         observed=rng.random((hit.sum(), 3)).astype(np.float32))
    rays = DeviceRays.upload(pixels, np.full(hit.sum(), 0.04))
    ambient = mi.Float([0.1, 0.2, 0.3])

    def loss_and_grads():
        itg = integrator.integrator_class()(mi.Properties())
        itg.setup(frame, density, colour, centers, radius, ior)
        itg.n_samples = 32
        params = mi.traverse(itg)
        for k in ("density", "colour", "centers"):
            dr.enable_grad(params[k])
        params.update()
        photo, dist = photo_terms(itg, rays, ambient)
        loss = photo + 1e-2 * dist + 0.01 * TotalVariation(density.shape)(params["density"])
        dr.backward(loss)
        return [np.asarray(loss)[0]] + [np.asarray(dr.grad(params[k])).ravel()
                                         for k in ("density", "colour", "centers")]

    ours = loss_and_grads()
    monkeypatch.setattr(integrator, "density_at", lambda tex, p: tex.eval(p)[0])
    plain = loss_and_grads()
    assert ours[0] > 0 and abs(ours[0] - plain[0]) <= 1e-6 * plain[0]
    for a, b in zip(ours[1:], plain[1:]):
        assert np.abs(b).max() > 0
        assert np.abs(a - b).max() <= 1e-4 * np.abs(b).max()
