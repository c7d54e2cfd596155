"""Totem pose from the photo's own edges: the mask only says where to look.

A sphere's outline in the image is the image of the cone of rays tangent to it
(:mod:`inverse.pose.pose`); its distance follows from the outline's size, so a mask drawn a
pixel too large moves the sphere by about ``distance / radius_px`` (2 % at 30-50 px).
Here the outline is fitted to the photo instead: the sphere (centre ``P``, radius ``R``
from the key) whose outline the image's gradient crosses most strongly,

    score(P) = mean_k |dI/dn|(x_k(P)),   x_k the outline's points, n their normals,

with ``I`` the photo blurred by ``SIGMA_PX`` (colour norm of the directional
derivative). The search starts from the mask's pose and covers outline moves of up to
``SHIFT_PX`` sideways and ``GROW_PX`` in size (a grid, then Nelder-Mead), so it finds
the rim wherever a person's mask put it within that reach.

The strongest edge near a glass sphere's rim lies on or just inside its silhouette
(the rim reflects more as the incidence grows grazing); see docs/decisions.md, "pose:
the rim from the photo's edges". On some totems the inner edge of the rim's reflection
band, 1.5-4 px inside, is the stronger; the mask is evidence too, so the size search
weighs each size's edge by a Gaussian of its distance from the mask's own outline
(``MASK_SIGMA_PX``, the slop of a mask as people draw it); see docs/decisions.md, "pose:
the edge weighed by the mask's size".
"""

from __future__ import annotations

import numpy as np

from scenes import camera, silhouette

__all__ = ["SIGMA_PX", "SHIFT_PX", "GROW_PX", "N_POINTS", "MASK_SIGMA_PX", "READ_PX",
           "outline", "edge_score", "refine_centre", "refine_centres"]

SIGMA_PX = 1.0       # blur before the derivative (pixels)
SHIFT_PX = 2.5       # how far sideways the search moves the mask's outline (pixels)
GROW_PX = 4.5        # how far the search grows or shrinks the mask's outline (pixels)
N_POINTS = 180       # outline points scored
MASK_SIGMA_PX = 2.0  # how far a mask's outline lies from the silhouette (pixels, 1 sd)
READ_PX = int(np.ceil(SHIFT_PX + GROW_PX + 4 * SIGMA_PX))
"""How far outside a mask the search reads the photo (pixels): the reach plus the
blur's support; the fit's fingerprint covers that band."""


def outline(P, R: float, K, n: int = N_POINTS):
    """Points (n, 2) and unit outward normals (n, 2), pixels, of the image of the cone
    tangent to the sphere (``P`` (3,) camera frame, metres; radius ``R`` metres)."""
    P = np.asarray(P, np.float64)
    uv = camera.project(K, P[None])[0]
    half = np.arcsin(np.clip(R / np.linalg.norm(P), 0.0, 1.0))
    return silhouette.cone_points((uv[0], uv[1], K[0, 0] * np.tan(half)), K, n)


def edge_score(P, R: float, K, grad) -> float:
    """Mean step of the blurred photo across the sphere's outline (sRGB per pixel);
    ``grad`` = (d/dx, d/dy) of :func:`scenes.silhouette.gradients`."""
    pts, nrm = outline(P, R, K)
    return float(np.mean(silhouette.edge_at(pts, nrm, *grad)))


def _moved(P0, R: float, K, x) -> np.ndarray:
    """The centre whose outline is ``P0``'s moved by ``x = (dx, dy, grow)`` pixels:
    its axis through the pixel ``P0`` projects to plus (dx, dy), its half-angle larger
    by ``grow / fx``, its distance what the key's radius then implies."""
    uv = camera.project(K, np.asarray(P0, np.float64)[None])[0] + x[:2]
    axis = camera.pixel_rays(K, np.array([uv[0]]), np.array([uv[1]]))[0]
    half = np.arcsin(np.clip(R / np.linalg.norm(P0), 0.0, 1.0)) + x[2] / K[0, 0]
    return axis * (R / np.sin(np.clip(half, 1e-4, 1.4)))


def refine_centre(P0, R: float, K, grad, *, shift_px: float = SHIFT_PX,
                  grow_px: float = GROW_PX,
                  mask_sigma_px: float = MASK_SIGMA_PX) -> np.ndarray:
    """The centre (3,) metres whose outline the photo's edges support best, within
    ``shift_px`` sideways and ``grow_px`` in size of ``P0``'s outline; the size is
    chosen first, by its edge times ``exp(-g^2 / (2 mask_sigma_px^2))`` for an outline
    ``g`` pixels larger than ``P0``'s."""
    from scipy.optimize import minimize

    K = np.asarray(K, np.float64)
    reach = np.array([shift_px, shift_px, grow_px])

    def cost(x):                       # the search stays within the reach
        if np.any(np.abs(x) > reach):
            return 1.0
        return -edge_score(_moved(P0, R, K, x), R, K, grad)

    # The size first, about the mask's centre: a circle the size of the rim but
    # off-centre can line up with edges inside the glass, a concentric one seldom does.
    g = np.arange(-grow_px + 0.5, grow_px - 0.49, 0.25)
    edge = np.array([edge_score(_moved(P0, R, K, np.array([0.0, 0.0, x])), R, K, grad)
                     for x in g])
    weighed = edge * np.exp(-0.5 * (g / mask_sigma_px) ** 2)
    x0 = np.array([0.0, 0.0, g[np.argmax(weighed if edge.max() > 0 else edge)]])
    reach = np.array([shift_px, shift_px, min(grow_px, abs(x0[2]) + 1.0)])
    simplex = x0 + np.vstack([np.zeros(3), 0.3 * np.eye(3)])
    res = minimize(cost, x0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-8})
    return _moved(P0, R, K, res.x)


def refine_centres(image, centers, radius, K) -> np.ndarray:
    """:func:`refine_centre` for every totem: ``image`` (H, W, 3) sRGB [0, 1],
    ``centers`` (n, 3) metres (e.g. :func:`inverse.pose.pose.initial_pose` of the masks),
    ``radius`` (n,) metres. Returns (n, 3) metres, camera frame."""
    grad = silhouette.gradients(np.ascontiguousarray(np.asarray(image, np.float32)),
                                SIGMA_PX)
    R = np.broadcast_to(np.asarray(radius, np.float64), (len(centers),))
    return np.stack([refine_centre(P, float(r), K, grad) for P, r in zip(centers, R)])
