"""The evidence map: what the totems establish at each pixel of the photo.

The verdict may only judge a pixel where the totems' rays support it. Per pixel ``p``
of the camera view, with ``X(p)`` the surface point at the fit's depth there
(``FitResult.recon_depth``, camera-frame ``z``, metres):

``n_totems``  how many totems saw that surface: a totem sees it when one of its rays,
              leaving the glass and marched through the camera's depth map, first
              meets the surface the camera sees at ``p`` (:func:`ray_hits`; a surface
              hidden from the totem by a nearer one the camera sees is not reached);
``parallax``  from how far apart they saw it: the largest angle at ``X(p)`` between two
              of those totems' centres, in units of their rays' angular spacing
              (:func:`angular_spacing`). Triangulated from two totems, the surface's
              depth is known to about ``1 / parallax`` of itself, so a surface seen
              with a parallax below ``MIN_PARALLAX`` (a far backdrop, the horizon, a
              wall every totem sees from one side) has no resolved depth.

A pixel's surface is *resolved* when at least ``MIN_TOTEMS`` totems saw it with a
parallax of at least ``MIN_PARALLAX``. RANGE and UNSEEN judge only resolved pixels
(:mod:`verify.verdict`); ABSENT judges the points in front of the surface where its
three totems resolve depth (:func:`verify.absence.absence`, ``min_parallax``).

Screen-space marching is how real-time renderers trace reflections against a depth
buffer; it needs no geometry beyond the view the fit already rebuilt, and it sees the
occlusions that view holds. Limits: it does not know what the camera does not see (a
ray passing behind an object from the camera's side is taken to continue), nor the
totems' own occlusion of each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from inverse.rays import TotemRays
from scenes.camera import pixel_rays

__all__ = ["MIN_TOTEMS", "MIN_PARALLAX", "COS_EVIDENCE", "CELL_PX", "N_STEPS",
           "THICKNESS", "Evidence", "angular_spacing", "pair_parallax", "ray_hits",
           "evidence_map"]

MIN_TOTEMS = 2
"""Totems that must see a surface for its pixels to be judged: one sees any colour."""

MIN_PARALLAX = 4.0
"""Parallax (rays' angular spacings) at which a surface's depth counts as resolved:
triangulated to about a quarter of its distance."""

COS_EVIDENCE = 0.3
"""Rays that entered their sphere at an incidence cosine below this are not evidence:
near the rim the glass mixes in reflection and blurs (as :mod:`verify.corroborate`)."""

CELL_PX = 8
"""Side (pixels) of the cells a totem's hits are counted in: about twice the spacing of
its rays' hits in a 640 x 480 photo, so a surface a totem sees holds a hit per cell."""

N_STEPS = 192
"""Samples along each ray, spaced evenly in log distance from the glass."""

THICKNESS = 0.05
"""A ray meets the camera's surface where it passes behind it by at most this fraction
of the surface's depth (and at most one step): more is passing behind an occluder."""


@dataclass
class Evidence:
    """The evidence map of one photo (see the module docstring).

    Attributes
    ----------
    n_totems : (H, W) int, totems that saw the surface at each pixel.
    parallax : (H, W) float, the largest parallax between two of them, in rays'
        angular spacings (0 where fewer than two).
    resolved : (H, W) bool, ``n_totems >= MIN_TOTEMS`` and ``parallax >= MIN_PARALLAX``.
    spacing : (n,) each totem's rays' angular spacing, radians (NaN for a totem with
        fewer than two rays).
    """

    n_totems: np.ndarray
    parallax: np.ndarray
    resolved: np.ndarray
    spacing: np.ndarray


def angular_spacing(d: np.ndarray, totem: np.ndarray, n: int) -> np.ndarray:
    """Median angle (radians) between each totem's ray directions and their nearest
    neighbour: the totem's angular resolution. ``d`` (m, 3) unit, ``totem`` (m,) in
    ``range(n)``; NaN for a totem with fewer than two rays."""
    out = np.full(n, np.nan)
    for j in range(n):
        dj = d[totem == j]
        if len(dj) >= 2:
            dist, _ = cKDTree(dj).query(dj, k=2)
            out[j] = 2.0 * np.arcsin(np.clip(np.median(dist[:, 1]) / 2.0, 0.0, 1.0))
    return out


def pair_parallax(X: np.ndarray, centers: np.ndarray, spacing: np.ndarray,
                  seen: np.ndarray) -> np.ndarray:
    """Largest parallax between two totems that see each point.

    Parameters
    ----------
    X : (k, 3) camera-frame points, metres.
    centers : (n, 3) totem centres, metres.
    spacing : (n,) each totem's angular spacing, radians.
    seen : (n, k) bool, which totems see each point.

    Returns
    -------
    (k,) the largest over pairs (i, j) seeing the point of the angle at ``X`` between
    ``centers[i]`` and ``centers[j]`` divided by the pair's mean spacing; 0 where fewer
    than two totems see it.
    """
    X = np.asarray(X, np.float64)
    to_c = np.asarray(centers, np.float64)[:, None, :] - X[None]           # (n, k, 3)
    to_c /= np.maximum(np.linalg.norm(to_c, axis=-1, keepdims=True), 1e-12)
    best = np.zeros(len(X))
    n = len(centers)
    for i in range(n):
        for j in range(i + 1, n):
            scale = 0.5 * (spacing[i] + spacing[j])
            if not np.isfinite(scale) or scale <= 0:
                continue
            cos = np.clip((to_c[i] * to_c[j]).sum(-1), -1.0, 1.0)
            p = np.where(seen[i] & seen[j], np.arccos(cos) / scale, 0.0)
            best = np.maximum(best, p)
    return best


def ray_hits(o: np.ndarray, d: np.ndarray, depth: np.ndarray, K: np.ndarray, *,
             near: float, far: float, n_steps: int = N_STEPS,
             thickness: float = THICKNESS, chunk: int = 4096) -> np.ndarray:
    """The pixel where each ray first meets the surface the camera sees.

    Parameters
    ----------
    o, d : (m, 3) rays' origins (metres) and unit directions, camera frame (OpenCV).
    depth : (H, W) the camera view's depth map (camera-frame ``z``, metres).
    K : (3, 3) intrinsics (pixel (u, v) at image coordinate (u, v)).
    near, far : the distances (metres) the march covers, from each origin.
    n_steps, thickness : see the module constants.

    Returns
    -------
    (m,) int64 flat pixel index ``v * W + u`` of the hit, -1 where the ray meets no
    surface of the view (it leaves the image, or passes only behind occluders).
    """
    H, W = depth.shape
    K = np.asarray(K, np.float64)
    t = np.geomspace(near, far, n_steps)
    step = t[1] / t[0] - 1.0                         # relative spacing of the samples
    out = np.full(len(o), -1, np.int64)
    for a in range(0, len(o), chunk):
        oo, dd = o[a:a + chunk], d[a:a + chunk]
        P = oo[:, None, :] + t[None, :, None] * dd[:, None, :]        # (c, n, 3)
        z = P[..., 2]
        front = z > 1e-6
        zs = np.where(front, z, 1.0)
        u = np.rint((K[0, 0] * P[..., 0] + K[0, 1] * P[..., 1]) / zs + K[0, 2])
        v = np.rint(K[1, 1] * P[..., 1] / zs + K[1, 2])
        inside = front & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        idx = np.where(inside, v * W + u, 0).astype(np.int64)
        D = depth.ravel()[idx]
        behind = z - D
        hit = inside & (behind >= 0) & (behind <= np.maximum(thickness, step) * D)
        first = np.argmax(hit, axis=1)
        any_hit = hit[np.arange(len(oo)), first]
        out[a:a + chunk] = np.where(any_hit, idx[np.arange(len(oo)), first], -1)
    return out


def evidence_map(rays: TotemRays, centers: np.ndarray, depth: np.ndarray, K: np.ndarray,
                 *, cell_px: int = CELL_PX, min_totems: int = MIN_TOTEMS,
                 min_parallax: float = MIN_PARALLAX,
                 cos_evidence: float = COS_EVIDENCE) -> Evidence:
    """The evidence map of a photo from its fit.

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`).
    centers : (n, 3) fitted totem centres, camera frame, metres.
    depth : (H, W) the fit's camera-view depth (``FitResult.recon_depth``), metres.
    K : (3, 3) intrinsics.
    cell_px, min_totems, min_parallax, cos_evidence : see the module constants.
    """
    depth = np.asarray(depth, np.float64)
    H, W = depth.shape
    centers = np.asarray(centers, np.float64)
    n = len(centers)
    rays = rays.entering_at_least(cos_evidence)
    spacing = angular_spacing(rays.d, rays.totem, n)
    finite = depth[np.isfinite(depth) & (depth > 0)]
    far = 4.0 * float(finite.max()) if finite.size else 100.0
    hits = ray_hits(rays.o, rays.d, np.where(np.isfinite(depth), depth, np.inf), K,
                    near=0.01, far=far)
    # hits counted per cell and totem; a cell next to a hit counts as seen (the hits
    # sample the surface at about the cells' spacing)
    gh, gw = -(-H // cell_px), -(-W // cell_px)
    seen = np.zeros((n, gh, gw), bool)
    ok = hits >= 0
    cy, cx = hits[ok] // W // cell_px, hits[ok] % W // cell_px
    seen[rays.totem[ok], cy, cx] = True
    seen = ndimage.binary_dilation(seen, structure=np.ones((1, 3, 3), bool))
    count = seen.sum(axis=0)
    # each cell's surface point, at the depth of its centre pixel
    vc = np.minimum(np.arange(gh) * cell_px + cell_px // 2, H - 1)
    uc = np.minimum(np.arange(gw) * cell_px + cell_px // 2, W - 1)
    vv, uu = np.meshgrid(vc, uc, indexing="ij")
    r = pixel_rays(K, uu.ravel(), vv.ravel())
    zc = depth[vv.ravel(), uu.ravel()]
    X = r / r[:, 2:3] * np.where(np.isfinite(zc), zc, 1e6)[:, None]
    par = pair_parallax(X, centers, spacing, seen.reshape(n, -1)).reshape(gh, gw)
    par = np.where(np.isfinite(zc).reshape(gh, gw), par, 0.0)
    up = (np.arange(H)[:, None] // cell_px, np.arange(W)[None, :] // cell_px)
    n_totems, parallax = count[up], par[up]
    resolved = (n_totems >= min_totems) & (parallax >= min_parallax)
    return Evidence(n_totems.astype(np.int64), parallax, resolved, spacing)
