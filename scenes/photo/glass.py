"""What a glass sphere of the key shows, tested on a candidate circle in the photo.

A totem refracts the camera's rays twice and sends them back into the scene the camera
sees: inside its outline the photo holds a small, inverted copy of the rest of the
photo. Given a candidate circle, the camera's ``K`` and the key (radius ``R`` in metres,
index of refraction ``eta``), the sphere's centre follows from the circle (the cone of
rays tangent to it, :func:`scenes.silhouette.sphere_from_circle`), each pixel inside it
is traced through the sphere (Snell at both surfaces), and the colour the photo shows
where the refracted ray lands is correlated with the colour inside the circle
(:func:`glass_scores`). An opaque ball or a ring of texture shows something else.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres;
pixels (u, v) with pixel centres at integers. Colours are the photo's sRGB in [0, 1].
The rays go through the sphere by :func:`scenes.refraction.refract_sphere`.
"""

from __future__ import annotations

import numpy as np

from scenes import camera
from scenes.refraction import refract_sphere

__all__ = ["RHO_MAX", "DEPTHS", "SIGMA_PX",
           "SIGMA_INSIDE_PX", "disc_pattern", "glass_scores", "outline_scores"]

RHO_MAX = 0.85
"""Pixels inside this fraction of the circle's radius are traced: nearer the rim the
rays graze the glass, their exit swings with the pose and reflections take over."""

DEPTHS = (1.25, 1.6, 2.0, 2.6, 3.5, 5.0, 8.0, 16.0)
"""Where the refracted rays are read: the scene point along each at this many times the
sphere's distance from the camera (a scene behind the totems, one depth for all rays)."""

SIGMA_PX = 2.0
"""Blur (pixels) of the photo where the refracted rays land: a totem pixel sees a patch
of the scene several photo pixels wide."""

SIGMA_INSIDE_PX = 1.0
"""Blur (pixels) of the photo inside the circle, read at about 250 points."""


def disc_pattern(n_points: int = 256) -> np.ndarray:
    """(m, 2) points of a hexagonal grid inside the disc of radius :data:`RHO_MAX`,
    about ``n_points`` of them, in units of a circle's radius."""
    step = RHO_MAX * np.sqrt(2 * np.pi / (np.sqrt(3) * n_points))
    n = int(np.ceil(RHO_MAX / step)) + 1
    j, i = np.mgrid[-n:n + 1, -n:n + 1].astype(np.float64)
    x, y = (i + 0.5 * (j % 2)) * step, j * step * np.sqrt(3) / 2
    keep = np.hypot(x, y) <= RHO_MAX
    return np.stack([x[keep], y[keep]], -1)


def glass_scores(inside, around, circles, K, etas, *, pattern=None) -> np.ndarray:
    """How well the inside of each circle looks like a glass sphere of the key.

    Parameters
    ----------
    inside : (H, W, 3) float32 sRGB, the photo lightly blurred (read inside the circles).
    around : (H, W, 3) float32 sRGB, the photo blurred by :data:`SIGMA_PX` (read where
        the refracted rays land).
    circles : (m, 3) pixels, each circle's centre (u0, v0) and radius s, taken as the
        image of the sphere's tangent cone
        (:func:`scenes.silhouette.sphere_from_circle`).
    K : (3, 3) OpenCV intrinsics.
    etas : the key's indices of refraction (one or several; the radius does not matter:
        a sphere R times as large seen R times as far shows the same picture).
    pattern : (n, 2) points in units of the radius (default :func:`disc_pattern`).

    Returns
    -------
    (m,) the best over ``etas`` and :data:`DEPTHS` of the correlation (over the traced
    pixels and the three channels, each channel's best plane over the disc taken out:
    a smooth ramp matches any other) between the colours inside the circle and where
    their refracted rays land in the photo; in [-1, 1], near 0 for what is not glass of
    that key. Rays that land outside the photo or within 1.1 radii of the circle's
    centre are left out; a circle with fewer than a quarter of its rays left scores 0
    at that depth.
    """
    H, W = inside.shape[:2]
    K = np.asarray(K, np.float64)
    c = np.asarray(circles, np.float64).reshape(-1, 3)
    pat = disc_pattern() if pattern is None else np.asarray(pattern, np.float64)
    m, n = len(c), len(pat)
    pts = c[:, None, :2] + c[:, None, 2:3] * pat[None]            # (m, n, 2)
    obs = _sample(inside, pts)                                   # (m, n, 3)
    d = camera.pixel_rays(K, pts[..., 0], pts[..., 1])           # (m, n, 3)
    axis = camera.pixel_rays(K, c[:, 0], c[:, 1])                # (m, 3)
    dist = 1.0 / np.sin(np.arctan(np.abs(c[:, 2]) / K[0, 0]))    # |P| for R = 1
    P = axis * dist[:, None]
    best = np.zeros(m)
    for eta in sorted(set(float(e) for e in np.ravel(etas))):
        E, d_out, valid = refract_sphere(d.reshape(-1, 3), np.repeat(P, n, 0), 1.0, eta)
        E, d_out, valid = E.reshape(m, n, 3), d_out.reshape(m, n, 3), valid.reshape(m, n)
        for k in DEPTHS:
            # the point along each exit ray at k times the sphere's distance
            t = _reach(E.reshape(-1, 3), d_out.reshape(-1, 3),
                       np.repeat(k * dist, n)).reshape(m, n)
            X = E + t[..., None] * d_out
            uv = camera.project(K, X)
            ok = valid & (X[..., 2] > 1e-6)
            ok &= (uv[..., 0] > 0) & (uv[..., 0] < W - 1) & (uv[..., 1] > 0) \
                & (uv[..., 1] < H - 1)
            ok &= np.hypot(uv[..., 0] - c[:, None, 0], uv[..., 1] - c[:, None, 1]) \
                > 1.1 * c[:, None, 2]
            pred = _sample(around, np.where(ok[..., None], uv, 0.0))
            best = np.maximum(best, _correlation(obs, pred, ok, max(8, n // 4), pat))
    return best


def outline_scores(photo, ellipses, K, etas) -> np.ndarray:
    """(k,) :func:`glass_scores` of each outline's circle, the outlines given as cv2
    ellipses ((cx, cy), (A, B), angle) in pixels and ``photo`` (H, W, 3) float32 sRGB
    unblurred (blurred here by :data:`SIGMA_INSIDE_PX` and :data:`SIGMA_PX`)."""
    import cv2

    inside = cv2.GaussianBlur(photo, (0, 0), SIGMA_INSIDE_PX)
    around = cv2.GaussianBlur(photo, (0, 0), SIGMA_PX)
    circles = np.array([(e[0][0], e[0][1], 0.25 * (e[1][0] + e[1][1])) for e in ellipses])
    return glass_scores(inside, around, circles, K, etas)


def _sample(img, pts):
    """Bilinear samples (..., 3) of ``img`` at pixel points (..., 2) (x, y)."""
    import cv2

    shp = pts.shape[:-1]
    flat = pts.reshape(-1, 2).astype(np.float32)
    cols = 4096                                 # cv2.remap takes maps under 32767 wide
    pad = -len(flat) % cols
    flat = np.concatenate([flat, np.zeros((pad, 2), np.float32)]).reshape(-1, cols, 2)
    out = cv2.remap(img, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE).reshape(-1, img.shape[2])
    return out[:len(out) - pad].reshape(*shp, img.shape[2]).astype(np.float64)


def _correlation(a, b, ok, min_count, pat):
    """Correlation per row of (m, n, 3) ``a`` and ``b`` over the points ``ok`` (m, n)
    and the channels, after each channel's best plane in the pattern's coordinates
    ``pat`` (n, 2) is taken out of each (a smooth ramp matches any other); 0 where
    fewer than ``min_count`` points are ok."""
    w = ok[..., None].astype(np.float64)
    A = np.concatenate([np.ones((len(pat), 1)), pat], 1)             # (n, 3)
    a, b = _residual(a, w, A), _residual(b, w, A)
    den = np.sqrt((a * a).sum((1, 2)) * (b * b).sum((1, 2)))
    r = np.where(den > 0, (a * b).sum((1, 2)) / np.maximum(den, 1e-12), 0.0)
    return np.where(ok.sum(1) >= min_count, r, 0.0)


def _residual(y, w, A):
    """``y`` (m, n, c) less its weighted least-squares fit by the columns of ``A`` (n, k),
    weights ``w`` (m, n, 1); zero where the weight is."""
    AtA = np.einsum("mn,ni,nj->mij", w[..., 0], A, A) + 1e-9 * np.eye(A.shape[1])
    Aty = np.einsum("mn,ni,mnc->mic", w[..., 0], A, y)
    coef = np.linalg.solve(AtA, Aty)                                   # (m, k, c)
    return (y - np.einsum("ni,mic->mnc", A, coef)) * w


def _reach(E, d, dist):
    """Ray parameter t >= 0 at which E + t d is ``dist`` metres from the camera (the
    far root; 0 when the ray starts further out)."""
    b = (E * d).sum(1)
    c = (E * E).sum(1) - dist * dist
    return np.maximum(-b + np.sqrt(np.maximum(b * b - c, 0.0)), 0.0)
