"""Totem pose from its mask and the key: the sphere's centre in the camera frame.

A sphere of radius ``R`` centred at ``P`` (OpenCV camera frame, metres) is seen inside
the right circular cone of rays ``d`` with ``angle(d, P) <= alpha``, where
``sin(alpha) = R / |P|``. Its image is exactly a conic (the cone cut by the image
plane), so the mask's outline gives the cone's axis and half-angle, and the key's ``R``
gives the distance ``|P| = R / sin(alpha)``.

Two methods:

``"conic"``
    Sub-pixel outline of the mask -> direct least-squares ellipse -> back-projected cone
    ``Q = K^T C K`` -> axis and half-angle from its eigen-decomposition (closed form), then
    refined by least squares on the tangent-cone residual of every outline ray,
    ``angle(d_k, P) - asin(R / |P|)`` (the numpy twin of :mod:`inverse.fit.outline`).
``"cone"``
    The paper's supplementary "Totem pose" initialisation: the mean of the unit
    boundary rays as the axis, the cone's circle radius ``T = R cos(theta)``, the
    slant height, similar triangles.

The outline is the 0.5 iso-contour of the binary mask (marching squares, no blur): each
point is the midpoint between a white and a black pixel centre, where the true edge
lies on average. The centres of the white boundary pixels (``cv2.findContours``) lie
half a pixel inside the edge and would shrink the cone; a blur before the contour biases
curved outlines inwards by about ``sigma^2 / (2 r)``.

References
----------
Ma et al., "Totems: Physical Objects for Verifying Visual Integrity", supplementary
section "Totem pose" (the ``"cone"`` method and the tangent-ray geometry).
Halir and Flusser, "Numerically stable direct least squares fitting of ellipses", 1998.
"""

from __future__ import annotations

import numpy as np

from scenes import camera
from scenes.errors import BadInput

__all__ = ["METHODS", "MIN_GAP_M", "MAX_DISTANCE_M", "MIN_AREA_PX", "SPECK_FRACTION",
           "ROUND_TOL_PX", "ROUND_TOL_REL", "mask_outline_uv", "mask_outline_rays",
           "tangent_residuals", "fit_ellipse", "cone_from_conic", "pose_from_cone",
           "pose_conic", "pose_cone", "initial_pose"]

METHODS = ("conic", "cone")

MIN_GAP_M = 0.01          # the sphere's nearest point must be this far from the camera
MAX_DISTANCE_M = 100.0    # a centre further away means the key's radius is not in metres
MIN_AREA_PX = 12          # smaller masks hold too few outline points for a pose
SPECK_FRACTION = 0.01     # extra blobs smaller than this fraction of the totem are ignored
ROUND_TOL_PX = 0.4        # allowed rms outline residual: ROUND_TOL_PX + ROUND_TOL_REL * r
ROUND_TOL_REL = 0.03


# --------------------------------------------------------------------------- outline

def _clean_mask(mask, j: int = 0) -> np.ndarray:
    """The totem's single filled blob as a bool (H, W) array; BadInput if unusable."""
    from scipy import ndimage

    m = np.asarray(mask)
    if m.ndim != 2:
        raise BadInput(f"totem mask {j} must be a 2-D image, got shape {m.shape}")
    m = m.astype(bool)
    if not m.any():
        raise BadInput(f"totem mask {j} is empty: draw the totem in white on black")
    if m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any():
        raise BadInput(f"totem mask {j} touches the image border: the sphere is cut off, "
                       "take the photo with every totem wholly in view")
    m = ndimage.binary_fill_holes(m)
    labels, n = ndimage.label(m)
    if n > 1:
        areas = np.bincount(labels.ravel())[1:]
        big = areas >= SPECK_FRACTION * areas.max()
        if big.sum() > 1:
            raise BadInput(f"totem mask {j} has {int(big.sum())} separate blobs: "
                           "give one mask per totem")
        m = labels == (1 + int(np.argmax(areas)))
    if m.sum() < MIN_AREA_PX:
        raise BadInput(f"totem mask {j} has {int(m.sum())} pixels, fewer than "
                       f"{MIN_AREA_PX}: too small to locate the sphere")
    return m


def mask_outline_uv(mask, *, j: int = 0) -> np.ndarray:
    """Sub-pixel outline of a totem mask, (m, 2) pixel coordinates (u, v).

    Pixel (u, v) sits at image coordinate (u, v) (contract). Each point is where the
    outline crosses the segment between a white and a black pixel centre (the 0.5
    iso-contour, marching squares). Holes are filled and specks dropped first; the
    closing duplicate point is removed.

    Raises
    ------
    BadInput
        Empty mask, mask touching the border, several blobs, or too small.
    """
    from skimage import measure

    m = _clean_mask(mask, j)
    contours = measure.find_contours(m.astype(np.float32), 0.5)
    rc = max(contours, key=len)[:-1]          # the one outer contour (holes are filled)
    return rc[:, ::-1].copy()                  # (row, col) -> (u, v)


def mask_outline_rays(mask, K, *, j: int = 0) -> np.ndarray:
    """Unit camera-frame directions (m, 3) of the rays through a mask's outline.

    Each is a ray tangent to the sphere if the mask is exact; these feed the tangent-cone
    residual (:func:`tangent_residuals`, :func:`inverse.fit.outline.outline_loss`).
    """
    uv = mask_outline_uv(mask, j=j)
    return camera.pixel_rays(K, uv[:, 0], uv[:, 1])


# --------------------------------------------------------------------------- geometry

def tangent_residuals(P, R, rays) -> np.ndarray:
    """Angle (radians) by which each ray misses being tangent to the sphere (P, R).

    ``angle(d_k, P) - asin(R / |P|)``: zero for rays on the tangent cone, positive
    outside it. ``P`` (3,) camera frame in metres, ``R`` metres, ``rays`` (m, 3) unit.
    """
    P = np.asarray(P, dtype=np.float64)
    dist = np.linalg.norm(P)
    cos_t = np.clip(rays @ (P / dist), -1.0, 1.0)
    return np.arccos(cos_t) - np.arcsin(np.clip(R / dist, 0.0, 1.0))


def fit_ellipse(uv) -> np.ndarray:
    """Direct least-squares ellipse through 2-D points, as a symmetric 3x3 conic ``C``.

    ``[u v 1] C [u v 1]^T = 0`` on the ellipse, negative inside, ``C`` scaled to unit
    Frobenius norm. Points are centred and scaled before the fit (Halir and Flusser's
    stable form of Fitzgibbon's ellipse-specific fit).
    """
    uv = np.asarray(uv, dtype=np.float64)
    mean = uv.mean(0)
    s = np.sqrt(2.0) / np.sqrt(((uv - mean) ** 2).sum(1).mean())
    x, y = ((uv - mean) * s).T
    D1 = np.stack([x * x, x * y, y * y], 1)
    D2 = np.stack([x, y, np.ones_like(x)], 1)
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    T = -np.linalg.solve(S3, S2.T)
    M = S1 + S2 @ T
    M = np.stack([M[2] / 2.0, -M[1], M[0] / 2.0])
    w, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4.0 * V[0] * V[2] - V[1] ** 2       # > 0 only for the ellipse solution
    a1 = V[:, np.argmax(cond)]
    a, b, c, d, e, f = np.concatenate([a1, T @ a1])
    C = np.array([[a, b / 2, d / 2], [b / 2, c, e / 2], [d / 2, e / 2, f]])
    N = np.array([[s, 0.0, -s * mean[0]], [0.0, s, -s * mean[1]], [0.0, 0.0, 1.0]])
    C = N.T @ C @ N                              # back to pixel coordinates
    if C[0, 0] < 0:
        C = -C
    return C / np.linalg.norm(C)


def cone_from_conic(C, K):
    """Axis (3,) and half-angle (radians) of the right circular cone closest to ``C``.

    The cone of rays ``d`` through the image conic ``C`` is ``d^T Q d = 0`` with
    ``Q = K^T C K``. A right circular cone with unit axis ``a`` and half-angle ``alpha``
    is ``Q ~ cos^2(alpha) I - a a^T``: eigenvalues ``cos^2`` (twice) and ``-sin^2`` (on
    ``a``), so ``tan^2(alpha) = -lambda_a / lambda_perp``.

    Returns
    -------
    axis : (3,) unit, camera frame, z > 0
    alpha : float, radians
    ellipticity : float, ``|l1 - l2| / |l1 + l2|`` of the two same-sign eigenvalues; 0
        for a sphere's image (large when the conic is no sphere's image)
    """
    K = np.asarray(K, dtype=np.float64)
    Q = K.T @ np.asarray(C, dtype=np.float64) @ K
    w, V = np.linalg.eigh(Q)
    signs = np.sign(w)
    if (signs > 0).sum() == 1:               # make two eigenvalues positive, one negative
        w, signs = -w, -signs
    if (signs > 0).sum() != 2:
        return None, None, np.inf
    i = int(np.argmin(w))
    perp = np.delete(w, i)
    axis = V[:, i] * np.sign(V[2, i])
    alpha = np.arctan(np.sqrt(-w[i] / perp.mean()))
    return axis, float(alpha), float(abs(perp[0] - perp[1]) / perp.sum())


def pose_from_cone(axis, alpha, R) -> np.ndarray:
    """Centre (3,) of the sphere of radius ``R`` inscribed in the cone: ``a R / sin(alpha)``."""
    return np.asarray(axis) * (R / np.sin(alpha))


def pose_conic(rays, K, R, uv=None) -> tuple[np.ndarray, float]:
    """Centre from an outline by the conic closed form refined on the tangent residual.

    Returns the centre (3,) in metres and the rms residual in pixels (angle times the
    mean focal length); ``inf`` residual when the outline is no sphere's image.
    """
    from scipy.optimize import least_squares

    K = np.asarray(K, dtype=np.float64)
    if uv is None:
        uv = camera.project(K, rays)
    axis, alpha, _ = cone_from_conic(fit_ellipse(uv), K)
    if axis is None:                        # not an ellipse: start from the paper's cone
        P0 = pose_cone(rays, R)
    else:
        P0 = pose_from_cone(axis, alpha, R)
    scale = np.linalg.norm(P0)
    sol = least_squares(lambda x: tangent_residuals(x * scale, R, rays), P0 / scale,
                        method="lm", xtol=1e-12, ftol=1e-12)
    P = sol.x * scale
    f = 0.5 * (K[0, 0] + K[1, 1])
    rms_px = float(np.sqrt(np.mean(sol.fun ** 2)) * f)
    return P, rms_px


def pose_cone(rays, R) -> np.ndarray:
    """The paper's initialisation (supplementary, "Totem pose"), in closed form.

    Axis ``d_c`` = normalised mean of the unit boundary rays; ``theta_k`` = angle of
    ray k to it; circle radius ``T = mean R sin(pi/2 - theta_k)``; the slant height
    ``t`` makes the mean distance of ``t d_k`` to their centroid ``C`` equal ``T``
    (linear in ``t``); then ``|P C| = T^2 / |O C|`` and ``P = d_c (|O C| + |P C|)``.
    """
    d = np.asarray(rays, dtype=np.float64)
    d_c = d.mean(0)
    d_c /= np.linalg.norm(d_c)
    theta = np.arccos(np.clip(d @ d_c, -1.0, 1.0))
    T = np.mean(R * np.sin(np.pi / 2 - theta))
    spread = np.linalg.norm(d - d.mean(0), axis=1).mean()   # mean |d_k t - C| / t
    t_est = T / spread
    OC = np.linalg.norm(d.mean(0) * t_est)
    PC = T ** 2 / OC
    return d_c * (PC + OC)


# --------------------------------------------------------------------------- public

def initial_pose(masks, K, radius, *, method: str = "conic") -> np.ndarray:
    """Initial totem centres from their masks and the key's radii.

    Parameters
    ----------
    masks : (n, H, W) bool, one mask per totem (white = totem), left to right
    K : (3, 3) intrinsics, pixel (u, v) at image coordinate (u, v)
    radius : float or (n,) sphere radii in metres (the key)
    method : ``"conic"`` (ellipse -> cone, refined; default, the more accurate) or
        ``"cone"`` (the paper's supplementary initialisation)

    Returns
    -------
    (n, 3) float64 centres, OpenCV camera frame, metres.

    Raises
    ------
    BadInput
        A mask that is empty, cut by the border, in several blobs, too small or not
        round; a radius that is not positive or that puts the sphere at an impossible
        distance (touching the camera, or over ``MAX_DISTANCE_M`` away). Spheres whose
        masks do not overlap cannot overlap in 3-D whatever the radii, so the key's
        scale itself cannot be checked from masks alone.
    """
    if method not in METHODS:
        raise BadInput(f"unknown pose method {method!r}: use one of {', '.join(METHODS)}")
    masks = np.asarray(masks)
    if masks.ndim == 2:
        masks = masks[None]
    if masks.ndim != 3 or masks.shape[0] == 0:
        raise BadInput(f"totem masks must be (n, H, W) with n >= 1, got shape {masks.shape}")
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise BadInput("K must be a finite 3x3 intrinsics matrix with positive fx, fy")
    n = masks.shape[0]
    R = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)) if np.ndim(radius) == 0 \
        else np.asarray(radius, dtype=np.float64)
    if R.shape != (n,):
        raise BadInput(f"the key gives {R.size} radii for {n} totem masks: give one radius "
                       "or one per totem")
    if not np.all(np.isfinite(R)) or np.any(R <= 0):
        raise BadInput(f"totem radius must be a positive number of metres, got {R.tolist()}")

    centers = np.empty((n, 3))
    for j in range(n):                      # one small fit per totem (n is 1..6)
        uv = mask_outline_uv(masks[j], j=j)
        rays = camera.pixel_rays(K, uv[:, 0], uv[:, 1])
        P_conic, rms_px = pose_conic(rays, K, R[j], uv=uv)
        r_px = np.linalg.norm(uv - uv.mean(0), axis=1).mean()
        if not np.isfinite(rms_px) or rms_px > ROUND_TOL_PX + ROUND_TOL_REL * r_px:
            raise BadInput(f"totem mask {j} is not round: its outline is {rms_px:.1f} px "
                           "(rms) from the best sphere outline; redraw it around the sphere")
        P = P_conic if method == "conic" else pose_cone(rays, R[j])
        _check_distance(P, R[j], j)
        centers[j] = P
    return centers


def _check_distance(P, R, j):
    dist = float(np.linalg.norm(P))
    if dist - R < MIN_GAP_M or P[2] <= 0:
        raise BadInput(f"totem {j} of radius {R:g} m would touch the camera "
                       f"(centre {dist:.3f} m away): check the key's radius")
    if dist > MAX_DISTANCE_M:
        raise BadInput(f"totem {j} of radius {R:g} m would be {dist:.0f} m away, more than "
                       f"{MAX_DISTANCE_M:g} m: is the key's radius in metres?")
