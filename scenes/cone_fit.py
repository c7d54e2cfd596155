"""A sphere's outline fitted over a wide basin around a rough one (``totems masks``).

The outline of a sphere seen by a camera of intrinsics ``K`` is the image of its tangent
cone, three parameters q = (u0, v0, s): the cone's axis is the ray through pixel (u0, v0)
and its half-angle arctan(s / K[0, 0]) (:func:`scenes.silhouette.cone_points`). Started
within a tenth of a radius, :func:`scenes.silhouette.fit_cone` finds it; started from a
circle of the coarse search (up to a third of a radius and a quarter of the size off),
Nelder-Mead settles on the nearest contour, often the inner edge of the rim's dark
band. :func:`refit_cone` first scores a wide grid of cones around the start (all at
once, :func:`cone_grid_alignment`), then runs Nelder-Mead from the best few: the true
silhouette is the contour whose image gradient lines up best with its normal (see
docs/decisions.md, 'masks: a wide fit around each candidate').

Units: pixels, OpenCV's convention (pixel centres at integers, x right, y down).
"""

from __future__ import annotations

import numpy as np

from scenes import camera, silhouette

__all__ = ["WIDE_SHIFTS", "WIDE_SIZES", "N_POINTS", "cone_grid_points",
           "cone_grid_alignment", "refit_cone"]

WIDE_SHIFTS = (-0.24, -0.12, 0.0, 0.12, 0.24)
"""Centre shifts of the grid, in units of the start's radius, along x and along y."""

WIDE_SIZES = (0.8, 0.87, 0.94, 1.0, 1.07, 1.15, 1.24)
"""Sizes of the grid, times the start's radius ``s``."""

N_POINTS = 120
"""Points along each outline of the grid."""


def cone_grid_points(qs, K, n: int = N_POINTS):
    """Points (m, n, 2) and unit outward normals (m, n, 2), pixels, of the images of
    the tangent cones ``qs`` (m, 3) = (u0, v0, s) for intrinsics ``K`` (3, 3): a batch
    of :func:`scenes.silhouette.cone_points`."""
    qs = np.asarray(qs, np.float64).reshape(-1, 3)
    K = np.asarray(K, np.float64)
    axis = camera.pixel_rays(K, qs[:, 0], qs[:, 1])                      # (m, 3)
    h = np.where((np.abs(axis[:, 1]) < 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    e1 = np.cross(h, axis)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = (np.cos(t)[None, :, None] * e1[:, None] + np.sin(t)[None, :, None] * e2[:, None])

    def image(alpha):
        X = np.cos(alpha)[:, None, None] * axis[:, None] + np.sin(alpha)[:, None, None] * ring
        return camera.project(K, X.reshape(-1, 3)).reshape(len(qs), n, 2)

    alpha = np.arctan(np.abs(qs[:, 2]) / K[0, 0])
    pts = image(alpha)
    nrm = image(alpha + 1e-4) - pts
    return pts, nrm / np.linalg.norm(nrm, axis=2, keepdims=True)


def cone_grid_alignment(qs, K, field, n: int = N_POINTS) -> np.ndarray:
    """(m,) the mean of cos(2 phi) along each cone's image, phi the angle between the
    image gradient and the outline's normal (``field`` from
    :func:`scenes.silhouette.orientation_field`): 1 for an outline that is an edge all
    the way round, about 0 on texture."""
    pts, nrm = cone_grid_points(qs, K, n)
    m = len(pts)
    al = silhouette.orientation_at(pts.reshape(-1, 2), nrm.reshape(-1, 2), *field)
    return al.reshape(m, n).mean(1)


def refit_cone(field, q0, K, shape, polish=None, *, keep: int = 3):
    """The tangent cone q = (u0, v0, s) best aligned with the image gradient in a wide
    basin around ``q0``: the grid :data:`WIDE_SHIFTS` x :data:`WIDE_SHIFTS` x
    :data:`WIDE_SIZES` around it scored at once, Nelder-Mead from the ``keep`` best,
    then (with ``polish`` = d/dx, d/dy of :func:`scenes.silhouette.gradients`) moved to
    the steepest mean step across it, sub-pixel. Returns (cv2 ellipse ((cx, cy), (A, B),
    angle_deg) of the outline, q, its alignment before the step) or None when
    the result is not a usable sphere outline (:func:`scenes.silhouette.sphere_like`
    around ``q0``, 0.4 radii and 0.75-1.3 of its size, not cut by the frame)."""
    import cv2
    from scipy.optimize import minimize

    u0, v0, s = (float(v) for v in q0[:3])
    r = abs(s)
    grid = np.array([(u0 + du * r, v0 + dv * r, k * r) for du in WIDE_SHIFTS
                     for dv in WIDE_SHIFTS for k in WIDE_SIZES])
    score = cone_grid_alignment(grid, K, field)
    starts = grid[np.argsort(-score)[:keep]]

    def cost(q):
        return -cone_grid_alignment(q[None], K, field)[0] if q[2] > 2 else 0.0

    fits = [minimize(cost, q, method="Nelder-Mead",
                     options=dict(xatol=0.02, fatol=1e-6, maxiter=300)) for q in starts]
    best = min(fits, key=lambda f: f.fun)
    q = best.x
    if polish is not None:              # sub-pixel: the steepest step near that contour
        gx, gy = polish
        q = minimize(lambda q: -silhouette.edge_at(*silhouette.cone_points(q, K), gx, gy)
                     .mean() if q[2] > 2 else 0.0, q, method="Nelder-Mead",
                     options=dict(xatol=0.01, fatol=1e-8, maxiter=300)).x
    if not np.isfinite(q).all() or q[2] <= 2:
        return None
    (ex, ey), (A, B), ang = cv2.fitEllipse(
        silhouette.cone_points(q, K, 90)[0].astype(np.float32))
    ell = silhouette.sphere_like((float(ex), float(ey), A / 2.0, B / 2.0, np.radians(ang)),
                                 (u0, v0, r), shape)
    return None if ell is None else (ell, q, -float(best.fun))
