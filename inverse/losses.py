"""The fit's regularisers and pose term, on Dr.Jit arrays (the photometric term and
the distortion live beside the rendering, in :mod:`inverse.fit` and
:func:`inverse.integrator.distortion`)."""

from __future__ import annotations

import numpy as np

from inverse.outline import outline_loss, outline_targets, outline_weights
from scenes import backend

__all__ = ["TotalVariation", "outline_term"]


class TotalVariation:
    """Squared-difference total variation of a grid tensor ``(D, H, W, C)``: the mean
    over all pairs of neighbours along the three grid axes (Plenoxels)."""

    def __init__(self, shape):
        mi = backend.modules()[1]
        D, Hh, Ww, C = shape
        idx = np.arange(D * Hh * Ww * C).reshape(D, Hh, Ww, C)
        a = [idx[1:].ravel(), idx[:, 1:].ravel(), idx[:, :, 1:].ravel()]
        b = [idx[:-1].ravel(), idx[:, :-1].ravel(), idx[:, :, :-1].ravel()]
        self.a = [backend.upload(mi.UInt32, x, np.uint32) for x in a if x.size]
        self.b = [backend.upload(mi.UInt32, x, np.uint32) for x in b if x.size]
        self.count = float(max(1, sum(x.size for x in a)))

    def __call__(self, tensor):
        dr, mi = backend.modules()
        x = tensor.array
        total = mi.Float(0.0)
        for a, b in zip(self.a, self.b):
            total += dr.sum(dr.square(dr.gather(mi.Float, x, a) - dr.gather(mi.Float, x, b)))
        return total / self.count


def outline_term(masks, K, radius, *, outlines=None):
    """The pose term: a function of the flat centres (``mi.Float``, x of every totem,
    then y, then z; metres) giving :func:`inverse.outline.outline_loss` over the masks'
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
