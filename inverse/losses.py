"""The fit's regularisers and pose term, on Dr.Jit arrays (the photometric term and
the distortion live beside the rendering, in :mod:`inverse.fit` and
:func:`inverse.integrator.distortion`)."""

from __future__ import annotations

import numpy as np

from inverse.outline import outline_loss, outline_targets, outline_weights
from scenes import backend

__all__ = ["TotalVariation", "outline_term", "support_cells", "support_term"]


class TotalVariation:
    """Squared-difference total variation of a grid tensor ``(D, H, W, C)``: the mean
    over all pairs of neighbours along the three grid axes (Plenoxels).

    Its gradient, ``2 / count * sum_j (x_i - x_j)`` over each cell's (up to) six
    neighbours, is computed directly by gathers and attached with ``dr.replace_grad``:
    differentiating the pairs' gathers made scatter-adds over every pair, a ninth of a
    fit's step (docs/decisions.md, "fit: the step's kernels halved").
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
                pos = (i // stride) % n                        # the cell's index on the axis
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


def support_cells(frame, plane, shape) -> tuple[np.ndarray, np.ndarray]:
    """The density cells ``(nr, nt, ns)`` the support plane crosses along each camera
    column (the column's ray meets ``N . X = h`` in front of the camera within the grid's
    depth range), one per such column, and the cells in front of them on those columns
    (between the camera and the plane): two arrays of flat indices.

    ``frame`` a :class:`inverse.grid.FrustumFrame`; ``plane`` an
    :class:`inverse.support.SupportPlane` (camera frame, metres).
    """
    nr, nt, ns = shape[:3]
    s = (np.arange(ns) + 0.5) / ns
    t = (np.arange(nt) + 0.5) / nt
    S, T = np.meshgrid(s, t)                                     # (nt, ns)
    u = frame.u_range[0] + S * (frame.u_range[1] - frame.u_range[0])
    v = frame.v_range[0] + T * (frame.v_range[1] - frame.v_range[0])
    K = frame.K
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    den = d @ plane.normal                                        # z = h / (N . d)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(den < 0, plane.offset / den, np.inf)
    ok = np.isfinite(z) & (z > frame.near) & (z < frame.far)
    r = (1.0 / frame.near - 1.0 / np.where(ok, z, frame.near)) \
        / (1.0 / frame.near - 1.0 / frame.far)
    k = np.clip((r * nr).astype(np.int64), 0, nr - 1)
    jt, js = np.nonzero(ok)
    on = (k[jt, js] * nt + jt) * ns + js
    kk = np.arange(nr)[:, None]
    front = kk < k[jt, js][None, :]                               # (nr, columns)
    before = ((kk * nt + jt[None, :]) * ns + js[None, :])[front]
    return on.astype(np.int64), before.astype(np.int64)


def support_term(frame, plane, shape, *, free: float, tau: float = 3.0):
    """The support-plane prior: a function of the raw density tensor (``mi.TensorXf``,
    ``shape``) giving the mean squared shortfall of the cells the plane crosses
    (:func:`support_cells`) below the raw density that makes one cell's optical depth
    along its column ``tau`` (``softplus(x) * DELTA_SCALE / nr = tau``), plus the mean
    squared excess of the cells in front of it above ``free`` (raw density): a surface
    there, seen through empty space, which the photometric term may still move where the
    totems disagree (an object on the table, a table's edge)."""
    from inverse.integrator import DELTA_SCALE

    dr, mi = backend.modules()
    nr = shape[0]
    target = float(np.log(np.expm1(tau * nr / DELTA_SCALE)))     # inverse softplus
    on, before = support_cells(frame, plane, shape)
    on_dr = backend.upload(mi.UInt32, on, np.uint32)
    before_dr = backend.upload(mi.UInt32, before, np.uint32)
    n_on, n_before = float(max(1, len(on))), float(max(1, len(before)))

    def term(tensor):
        x = dr.gather(mi.Float, tensor.array, on_dr)
        y = dr.gather(mi.Float, tensor.array, before_dr)
        return dr.sum(dr.square(dr.maximum(target - x, 0.0))) / n_on \
            + dr.sum(dr.square(dr.maximum(y - free, 0.0))) / n_before

    return term
