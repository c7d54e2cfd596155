"""The fit's regularisers and pose term, on Dr.Jit arrays (the photometric term and
the distortion live beside the rendering, in :mod:`inverse.fit.fit` and
:func:`inverse.integrator.distortion`)."""

from __future__ import annotations

import numpy as np

from inverse.fit.outline import outline_loss, outline_targets, outline_weights
from scenes import backend

__all__ = ["TotalVariation", "outline_term"]


class TotalVariation:
    """Squared-difference total variation of a grid tensor ``(D, H, W, C)``: the mean
    over all pairs of neighbours along the three grid axes (Plenoxels).

    Its gradient, ``2 / count * sum_j (x_i - x_j)`` over each cell's (up to) six
    neighbours, is computed directly by gathers and attached with ``dr.replace_grad``:
    differentiating the pairs' gathers made scatter-adds over every pair, a ninth of a
    fit's step (docs/decisions.md, "fit: the optimisation in about half the time").
    """

    def __init__(self, shape):
        D, Hh, Ww, C = shape
        self.shape = (D, Hh, Ww, C)
        self.count = float(max(1, (D - 1) * Hh * Ww * C + D * (Hh - 1) * Ww * C
                               + D * Hh * (Ww - 1) * C))

    def __call__(self, tensor):
        dr, mi = backend.modules()
        x = tensor.array
        D, Hh, Ww, C = self.shape
        with dr.suspend_grad():
            xd = dr.detach(x)
            i = dr.arange(mi.UInt32, D * Hh * Ww * C)
            value, grad = mi.Float(0.0), mi.Float(0.0)
            for stride, n in ((C, Ww), (C * Ww, Hh), (C * Ww * Hh, D)):
                pos = (i // stride) % n                # the cell's index on the axis
                for up in (True, False):
                    ok = pos < n - 1 if up else pos > 0
                    j = dr.select(ok, i + stride if up else i - stride, i)
                    diff = dr.select(ok, xd - dr.gather(mi.Float, xd, j, ok), 0.0)
                    grad += diff
                    if up:
                        value += dr.square(diff)               # each pair once
            value = dr.sum(value) / self.count
            grad = grad * (2.0 / self.count)
        if not dr.grad_enabled(x):
            return value
        return dr.replace_grad(value, dr.sum(grad * x))


def outline_term(masks, K, radius, *, outlines=None):
    """The pose term: a function of the flat centres (``mi.Float``, x of every totem,
    then y, then z; metres) giving :func:`inverse.fit.outline.outline_loss` over the masks'
    outlines (or ``outlines``, one (m, 2) array of pixels per totem), in pixels squared
    (scaled by ``fx``)."""
    from scenes.camera import pixel_rays

    dr, mi = backend.modules()
    if outlines is None:
        rays, ray_totem = outline_targets(masks, K)
    else:
        rays = np.concatenate([pixel_rays(K, uv[:, 0], uv[:, 1]) for uv in outlines])
        ray_totem = np.concatenate([np.full(len(uv), j, np.int32)
                                    for j, uv in enumerate(outlines)])
    rays_dr = backend.upload(mi.Vector3f, rays)
    idx_dr = backend.upload(mi.UInt32, ray_totem, np.uint32)
    R = backend.upload(mi.Float, radius)
    weights = backend.upload(mi.Float, outline_weights(ray_totem))
    n = len(radius)
    fx = float(K[0, 0])

    def term(centers_flat):
        i = dr.arange(mi.UInt32, n)
        P = mi.Point3f(*[dr.gather(mi.Float, centers_flat, i + a * n,
                                     mode=dr.ReduceMode.Direct) for a in range(3)])
        return outline_loss(P, R, rays_dr, idx_dr, scale=fx, weights=weights)

    return term

