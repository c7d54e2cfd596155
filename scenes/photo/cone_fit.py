"""A sphere's outline fitted over a wide basin around a rough one (``totems masks``).

The outline of a sphere seen by a camera of intrinsics ``K`` is the image of its tangent
cone, three parameters q = (u0, v0, s): the cone's axis is the ray through pixel (u0, v0)
and its half-angle arctan(s / K[0, 0]) (:func:`scenes.silhouette.cone_points`). Started
within a tenth of a radius, :func:`scenes.silhouette.fit_cone` finds it; started from a
circle of the coarse search (up to a third of a radius and a quarter of the size off),
Nelder-Mead settles on the nearest contour, often the inner edge of the rim's dark
band. :func:`refit_cone` first scores a wide grid of cones around the start (all at
once), then runs Nelder-Mead from the best few (:func:`scenes.silhouette.cone_fit_q`,
the fit of :func:`scenes.silhouette.fit_cone` over a wider grid): the true
silhouette is the contour whose image gradient lines up best with its normal (see
docs/decisions.md, 'masks: a wide fit around each candidate').

Units: pixels, OpenCV's convention (pixel centres at integers, x right, y down).
"""

from __future__ import annotations

import numpy as np

from scenes import silhouette

__all__ = ["WIDE_SHIFTS", "WIDE_SIZES", "N_POINTS", "refit_cone"]

WIDE_SHIFTS = (-0.24, -0.12, 0.0, 0.12, 0.24)
"""Centre shifts of the grid, in units of the start's radius, along x and along y."""

WIDE_SIZES = (0.8, 0.87, 0.94, 1.0, 1.07, 1.15, 1.24)
"""Sizes of the grid, times the start's radius ``s``."""

N_POINTS = 120
"""Points along each outline of the grid."""


def refit_cone(field, q0, K, shape, polish=None, *, keep: int = 3):
    """The tangent cone q = (u0, v0, s) best aligned with the image gradient in a wide
    basin around ``q0``: the grid :data:`WIDE_SHIFTS` x :data:`WIDE_SHIFTS` x
    :data:`WIDE_SIZES` around it scored at once, Nelder-Mead from the ``keep`` best,
    then (with ``polish`` = d/dx, d/dy of :func:`scenes.silhouette.gradients`) moved to
    the steepest mean step across it, sub-pixel. Returns (cv2 ellipse ((cx, cy), (A, B),
    angle_deg) of the outline, q, its alignment before the step) or None when
    the result is not a usable sphere outline (:func:`scenes.silhouette.sphere_like`
    around ``q0``, 0.4 radii and 0.75-1.3 of its size, not cut by the frame)."""
    u0, v0, s = (float(v) for v in q0[:3])
    start = (u0, v0, abs(s))
    q, aligned = silhouette.cone_fit_q(field, start, K, polish, shifts=WIDE_SHIFTS,
                                       sizes=WIDE_SIZES, keep=keep, n=N_POINTS)
    if not np.isfinite(q).all() or q[2] <= 2:
        return None
    ell = silhouette.sphere_like(silhouette.cone_ellipse(q, K), start, shape)
    return None if ell is None else (ell, q, aligned)
