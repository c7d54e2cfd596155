"""inverse/exact_gather: lookups whose gradient is summed in fixed point, so two backward
passes on two threads give the same gradient to the bit, within the stated bound of the
exact (float64) sum."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import backend

dr, mi = backend.modules()

N_LANES = 262_144          # a fit step's lanes (4096 rays x 64 samples)


def _lanes(seed=0):
    rng = np.random.default_rng(seed)
    # Ray-ordered lanes: 4096 segments of 64 samples, as a fit's march reads the grid.
    a, b = rng.random((4096, 3)), rng.random((4096, 3))
    t = (np.arange(64) + 0.5) / 64
    points = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 3)
    # On a lattice of 2**-12 (and grids of powers of two), so that float32 finds the
    # cells and weights exactly and the float64 sum below is the sum of the same terms.
    points = np.round(points * 4096) / 4096
    return points, (rng.standard_normal(N_LANES) * 1e-3).astype(np.float32)


def _gradient(texture, points, weights, *, threads, deferred=False):
    """The gradient of ``sum_k weights_k * sum_c grid_at(texture, p_k)_c`` with respect
    to the texture's tensor, on ``threads`` threads (float64 numpy)."""
    from inverse import exact_gather

    n = dr.thread_count()
    dr.sync_thread()
    dr.set_thread_count(threads)
    try:
        x = texture.tensor()
        dr.enable_grad(x)
        texture.update_inplace()
        vals = exact_gather.grid_at(texture, backend.upload(mi.Point3f, points))
        loss = dr.sum(sum(vals) * backend.upload(mi.Float, weights))
        if deferred:
            exact_gather.backward(loss)
        else:
            dr.backward(loss)
        g = dr.grad(x)
        dr.eval(g)
        dr.sync_thread()
        return np.array(g.numpy(), np.float64).ravel()
    finally:
        dr.set_thread_count(n)


def _exact(grid_shape, points, weights):
    """The same gradient summed in float64: each lane's corner weights added with
    ``np.add.at``; how many contributions each cell takes, and the sum of their lanes'
    ``|weights|``."""
    *cells, C = grid_shape
    sizes = cells[::-1]
    lo, w = [], []
    for a, n in enumerate(sizes):
        f = points[:, a] * n - 0.5
        b = np.floor(f)
        lo.append(b.astype(np.int64))
        w.append(f - b)
    grad = np.zeros(int(np.prod(cells)))
    count = np.zeros(int(np.prod(cells)))
    total = np.zeros(int(np.prod(cells)))
    for corner in range(2 ** len(sizes)):
        flat = np.zeros(len(points), np.int64)
        wt = np.ones(len(points))
        for axis in reversed(range(len(sizes))):
            up = (corner >> axis) & 1
            i = np.clip(lo[axis] + up, 0, sizes[axis] - 1)
            flat = flat * sizes[axis] + i
            wt = wt * (w[axis] if up else 1.0 - w[axis])
        np.add.at(grad, flat, wt * weights)
        np.add.at(total, flat, np.abs(weights))
        np.add.at(count, flat, 1.0)
    return np.repeat(grad, C), np.repeat(count, C), np.repeat(total, C)


@pytest.mark.parametrize("kind", ["density", "colour"])
def test_two_threads_give_the_same_gradient_to_the_bit_within_the_bound(kind):
    """Twice on two threads and once on one: the same bits. Against the float64 sum:
    within ``m * 2**-(FRAC_BITS + 1)`` for a cell of ``m`` contributions, plus float32's
    rounding of each contribution (a lerp's adjoint ``g - t g`` is off by up to an ulp
    of its lane's ``g`` at each of the three axes) and of the result."""
    from inverse.exact_gather import FRAC_BITS

    rng = np.random.default_rng(1)
    points, weights = _lanes()
    if kind == "density":
        grid = rng.standard_normal((32, 64, 64, 1)).astype(np.float32)
        tex = lambda: mi.Texture3f(backend.upload(mi.TensorXf, grid))  # noqa: E731
    else:                       # the fit's colour: one slice deep, three channels
        grid = rng.random((128, 128, 3)).astype(np.float32)
        tex = lambda: mi.Texture2f(backend.upload(mi.TensorXf, grid))  # noqa: E731
    g = [_gradient(tex(), points, weights, threads=t) for t in (2, 2, 1)]
    assert np.array_equal(g[0], g[1]) and np.array_equal(g[0], g[2])
    exact, count, total = _exact(grid.shape, points, weights.astype(np.float64))
    bound = count * 2.0 ** -(FRAC_BITS + 1) + total * 3 * 2.0 ** -23 + np.abs(exact) * 2.0 ** -24
    assert np.all(np.abs(g[0] - exact) <= bound)
    assert count.max() > 50 and np.abs(exact).max() > 1e-3   # the case is not trivial


def test_the_deferred_sum_and_the_values_match_the_plain_lookup():
    """Inside ``exact_gather.backward`` the sum reaches the tensor after the traversal:
    the same bits as in the op's own backward; the values are the texture's own
    ``eval`` to float32's rounding of the position (1e-5 on a grid of 160 cells)."""
    from inverse.exact_gather import grid_at

    rng = np.random.default_rng(2)
    points, weights = _lanes(3)
    grid = rng.random((120, 160, 3)).astype(np.float32)
    make = lambda: mi.Texture2f(backend.upload(mi.TensorXf, grid))  # noqa: E731
    a = _gradient(make(), points, weights, threads=2, deferred=True)
    b = _gradient(make(), points, weights, threads=2)
    assert np.array_equal(a, b)
    tex = make()
    p = backend.upload(mi.Point3f, points)
    ours = np.array([v.numpy() for v in grid_at(tex, p)])
    theirs = np.array(tex.eval(mi.Point2f(p.x, p.y))).reshape(3, -1)
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
