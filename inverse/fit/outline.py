"""Outline term of the joint fit: each sphere's tangent cone on its mask's outline.

A ray ``d_k`` through the outline of totem ``j``'s mask is tangent to the sphere
``(P_j, R_j)`` when its angle to the centre equals the cone's half-angle:

    theta_k = angle(d_k, P_j),    alpha_j = asin(R_j / |P_j|),    r_k = theta_k - alpha_j.

The loss is the mean over totems of the mean over their outline rays of ``(s r_k)^2``,
radians squared (``scale = fx`` makes it pixels squared). Unlike the paper's
bounding-box IoU (supplementary, "Totem IoU loss"), every outline ray contributes and
the term is smooth in ``P_j``. It pins the direction of ``P_j`` firmly and its distance
weakly: moving a sphere sideways by ``dx`` turns the rays by ``dx / |P|``, moving it away
by ``dz`` shrinks the cone by only ``tan(alpha) dz / |P|``.

The numpy twin is :func:`inverse.pose.pose.tangent_residuals` (the pose initialisation
minimises the same residual).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from inverse.exact_gather import gather
from inverse.pose import pose
from scenes import backend

if TYPE_CHECKING:                    # annotations only: Dr.Jit loads at the first use
    import mitsuba as mi

__all__ = ["outline_targets", "outline_residuals", "outline_weights", "outline_loss"]


def outline_targets(masks, K) -> tuple[np.ndarray, np.ndarray]:
    """Outline rays of all totem masks, ready for :func:`outline_loss`.

    Returns ``rays`` (m, 3) unit camera-frame directions and ``ray_totem`` (m,) int32,
    the totem index of each ray. BadInput for an unusable mask (see
    :func:`inverse.pose.pose.mask_outline_uv`).
    """
    masks = np.asarray(masks)
    if masks.ndim == 2:
        masks = masks[None]
    rays = [pose.mask_outline_rays(m, K, j=j) for j, m in enumerate(masks)]
    ray_totem = np.concatenate([np.full(len(r), j, np.int32) for j, r in enumerate(rays)])
    return np.concatenate(rays), ray_totem


def _as_centers(centers):
    """Centres as something ``dr.gather(mi.Vector3f, ., idx)`` reads per totem."""
    mi = backend.modules()[1]
    if isinstance(centers, (mi.Point3f, mi.Vector3f, mi.Array3f)):
        return mi.Vector3f(centers)
    if isinstance(centers, mi.Float):            # flat [x0, y0, z0, x1, ...]
        return centers
    arr = np.asarray(centers, dtype=np.float32).reshape(-1, 3)
    return mi.Vector3f(arr.T)


def outline_residuals(centers, radius, rays, ray_totem) -> mi.Float:
    """Tangent-cone residual ``theta_k - alpha_j`` of each outline ray, radians (m,).

    Parameters
    ----------
    centers : mi.Point3f / mi.Vector3f with n entries, a flat mi.Float of 3n values, or
        (n, 3) numpy; camera frame, metres. Gradients flow to Dr.Jit inputs.
    radius : float or (n,) sphere radii, metres
    rays : (m, 3) numpy or mi.Vector3f, unit camera-frame directions of outline points
    ray_totem : (m,) ints (numpy or mi.UInt32), the totem of each ray
    """
    dr, mi = backend.modules()
    C = _as_centers(centers)
    d = rays if isinstance(rays, mi.Vector3f) else backend.upload(mi.Vector3f, rays)
    idx = ray_totem if isinstance(ray_totem, mi.UInt32) else \
        backend.upload(mi.UInt32, ray_totem, np.uint32)
    R_all = radius if isinstance(radius, mi.Float) else \
        backend.upload(mi.Float, np.atleast_1d(radius))
    R = dr.gather(mi.Float, R_all, idx, mode=dr.ReduceMode.Direct) \
        if dr.width(R_all) > 1 else R_all

    # Per ray its totem's centre; the adjoint summed in fixed point, the same on any
    # number of threads (inverse.exact_gather).
    if isinstance(C, mi.Vector3f):
        P = mi.Vector3f(*[gather(C[a], [idx])[0] for a in range(3)])
    else:
        P = mi.Vector3f(*gather(C, [idx], channels=3))
    dist = dr.norm(P)
    theta = dr.atan2(dr.norm(dr.cross(d, P)), dr.dot(d, P))   # angle(d_k, P_j), stable
    alpha = dr.asin(R / dist)                                   # tangent cone half-angle
    return theta - alpha


def outline_weights(ray_totem) -> np.ndarray:
    """Each outline ray's weight in :func:`outline_loss` (m,): every totem weighs the
    same, its rays equally."""
    tid = np.asarray(ray_totem).astype(np.int64).ravel()
    if tid.size == 0:
        raise ValueError("outline_loss needs at least one outline ray")
    count = np.bincount(tid)
    return 1.0 / (np.count_nonzero(count) * count[tid])


def outline_loss(centers, radius, rays, ray_totem, *, scale: float = 1.0,
                 weights=None) -> mi.Float:
    """Mean over totems of the mean squared tangent-cone residual of their outline rays.

    Differentiable in ``centers`` (see :func:`outline_residuals` for the arguments).
    ``scale`` multiplies the residuals: 1 gives radians squared, ``fx`` about pixels
    squared. ``weights``: :func:`outline_weights` already uploaded (a fit's steps
    reuse them). Returns a mi.Float of width 1.
    """
    dr, mi = backend.modules()
    if weights is None:
        weights = backend.upload(mi.Float, outline_weights(ray_totem))
    r = outline_residuals(centers, radius, rays, ray_totem) * scale
    return dr.sum(weights * dr.square(r))
