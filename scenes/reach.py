"""The reach of a photo's totems: which camera pixels' surfaces two or more totems see, and
from how far apart.

A totem sees a surface point where one of its rays, refracted through the glass and sent
on into the scene, lands on it. Given where the camera's pixels land (their surface
points) and where the totems' rays land, both traced by some renderer through the same
scene, a pixel is *seen* by a totem when one of its rays lands within that ray's
footprint of the pixel's point: an ellipse on the surface, the ray's path length times
its own angular spacing (to its fourth nearest neighbour) across, stretched by the
incidence along (:func:`_in_footprints`). A pixel
whose camera ray leaves the scene (a backdrop at infinity) is seen by a totem with a ray
along the same direction, within its spacing. The *parallax* between two totems that see
a point is the angle at the point between their centres in units of their mean spacing
(:func:`pair_parallax`): triangulated from them, its depth is known to about
``1 / parallax`` of itself. A pixel is in the reach where two totems see it and their
parallax is at least ``MIN_PARALLAX`` (its depth established), or where it is a backdrop
two totems see along the camera's own direction (its colour established, no depth to
establish).

This is the evidence map's rule (:mod:`verify.metrics.evidence`) applied to where the
rays truly land, not to where a fit put them: the truth's reach of a synthetic scene
(:mod:`scenes.synthetic.trace`) and the plan of a placement before the shot. Frames and
units: the OpenCV camera frame, metres; angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["MIN_PARALLAX", "MIN_TOTEMS", "COS_EVIDENCE", "MIN_COS_FOOTPRINT", "SUPERSAMPLE", "Reach", "angular_spacing",
           "pair_parallax", "reach_map"]

MIN_TOTEMS = 2
"""Totems that must see a surface: one sees any colour."""

MIN_PARALLAX = 4.0
"""Parallax (rays' angular spacings) at which a surface's depth counts as resolved:
triangulated to about a quarter of its distance."""

COS_EVIDENCE = 0.3
"""Rays that entered their sphere at an incidence cosine below this are not evidence:
near the rim the glass mixes in reflection and blurs, and each ray's footprint is wide."""

SUPERSAMPLE = 4
"""Rays a totem pixel sends, a side, when the truth's reach is traced: 4 x 4 finds the
reach as 8 x 8 does to 2-3 % of the photo's pixels, one ray a pixel to 7 % (it claims
more: docs/decisions/scenes-synthetic.md)."""

MIN_COS_FOOTPRINT = 0.05
"""A ray's footprint stretches as ``1 / cos`` along the surface it meets at incidence
cosine ``cos``, to this cosine at most (a ray grazing a surface closer than 3 degrees
sees only a smear of it)."""


@dataclass
class Reach:
    """What a photo's totems see of its camera view (see the module docstring).

    Attributes
    ----------
    depth : (H, W) float32, camera-frame z of the first surface along each pixel's ray,
        metres (inf for a backdrop at infinity).
    n_totems : (H, W) uint8, totems that see each pixel's surface.
    parallax : (H, W) float32, the largest parallax between two of them, in rays'
        angular spacings (0 where fewer than two, and for a backdrop).
    backdrop : (H, W) bool, pixels whose surface the totems see along the camera's own
        direction (a backdrop at infinity, or so far that its depth is not theirs to tell).
    excluded : (H, W) bool, pixels that are no surface to judge (the totems themselves).
    spacing : (n,) each totem's rays' angular spacing, radians.
    """

    depth: np.ndarray
    n_totems: np.ndarray
    parallax: np.ndarray
    backdrop: np.ndarray
    excluded: np.ndarray
    spacing: np.ndarray

    def in_reach(self, min_parallax: float = MIN_PARALLAX,
                 min_totems: int = MIN_TOTEMS) -> np.ndarray:
        """(H, W) bool: seen by ``min_totems`` totems, with their depth resolved to
        ``min_parallax`` or as a backdrop."""
        seen = (self.n_totems >= min_totems) & ~self.excluded
        return seen & ((self.parallax >= min_parallax) | self.backdrop)

    def to_dict(self) -> dict:
        """Arrays for ``truth/reach.npz``."""
        return {"depth": self.depth.astype(np.float32),
                "n_totems": self.n_totems.astype(np.uint8),
                "parallax": self.parallax.astype(np.float32),
                "backdrop": self.backdrop.astype(bool),
                "excluded": self.excluded.astype(bool),
                "spacing": self.spacing.astype(np.float64)}

    @classmethod
    def from_dict(cls, z) -> "Reach":
        """Inverse of :meth:`to_dict` (accepts an ``np.load`` result)."""
        return cls(**{k: np.asarray(z[k]) for k in
                      ("depth", "n_totems", "parallax", "backdrop", "excluded", "spacing")})


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


def _local_spacing(d: np.ndarray, totem: np.ndarray, n: int, k: int = 4) -> np.ndarray:
    """(m,) each ray's own angular spacing, radians: the angle to its ``k``-th nearest
    neighbour among its totem's rays (on a grid stretched by the glass, the 4th nearest
    lies along the long axis: a footprint that wide leaves no gap). NaN for a totem with
    too few rays."""
    out = np.full(len(d), np.nan)
    for j in range(n):
        mine = np.flatnonzero(totem == j)
        if len(mine) > k:
            dist, _ = cKDTree(d[mine]).query(d[mine], k=k + 1)
            out[mine] = 2.0 * np.arcsin(np.clip(dist[:, k] / 2.0, 0.0, 1.0))
    return out


def _in_footprints(X, Y, o, d, normal, spacing, k: int = 8) -> np.ndarray:
    """(p,) bool: points ``X`` (p, 3) inside the footprint of one of the rays that left
    ``o`` along ``d`` with angular ``spacing`` and landed at ``Y`` on a surface of unit
    ``normal`` (each (m, 3) / (m,)).

    A ray's footprint on the surface is an ellipse: ``r = t * spacing`` across the ray's
    plane of incidence, ``r / cos`` along it (``t`` the path length, ``cos`` the
    incidence cosine, held to ``MIN_COS_FOOTPRINT``); a point is in it where it lies on
    that surface (within ``r`` of its plane) and inside the ellipse. The ``k`` nearest
    landing points of each point are tried."""
    t = np.linalg.norm(Y - o, axis=1)
    cos = np.maximum(np.nan_to_num(np.abs((normal * d).sum(1))), MIN_COS_FOOTPRINT)
    r = t * spacing
    along = _unit(d - (d * normal).sum(1, keepdims=True) * normal)   # in the surface
    across = np.cross(normal, along)
    k = min(k, len(Y))
    dist, idx = cKDTree(Y).query(X, k=k, distance_upper_bound=float(np.max(r / cos)))
    dist, idx = dist.reshape(len(X), k), idx.reshape(len(X), k)
    found = np.zeros(len(X), bool)
    for c in range(k):
        ok = np.isfinite(dist[:, c]) & ~found        # a point already inside is done
        i = idx[ok, c]
        delta = X[ok] - Y[i]
        a = (delta * along[i]).sum(1) * cos[i] / r[i]
        b = (delta * across[i]).sum(1) / r[i]
        h = np.abs((delta * normal[i]).sum(1)) / r[i]
        found[np.flatnonzero(ok)[(a * a + b * b <= 1.0) & (h <= 1.0)]] = True
    return found


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def reach_map(view: np.ndarray, X: np.ndarray, excluded: np.ndarray, centers: np.ndarray,
              *, o: np.ndarray, d: np.ndarray, Y: np.ndarray, normal: np.ndarray,
              totem: np.ndarray, supersample: int = 1) -> Reach:
    """The reach of a photo's totems from where the camera's and the totems' rays land.

    Parameters
    ----------
    view : (H, W, 3) each camera pixel's unit ray direction (from the camera's centre).
    X : (H, W, 3) each camera pixel's surface point, camera frame, metres; NaN where its
        ray leaves the scene (a backdrop at infinity).
    excluded : (H, W) bool, pixels that are no surface to judge (the totems' own).
    centers : (n, 3) totem centres, metres.
    o, d : (m, 3) the totem rays leaving the glass: exit points (metres) and unit
        directions (only the rays the glass sends on: transmitting, not blocked).
    Y : (m, 3) where each lands, metres; NaN where it leaves the scene.
    normal : (m, 3) the surface's unit normal there (either side; NaN where it left).
    totem : (m,) int, the totem each ray left, in ``range(n)``.
    supersample : the rays sample each totem pixel ``s x s`` times; the parallax's unit
        stays one pixel's angular spacing, ``s`` times their :func:`angular_spacing`.

    Returns
    -------
    :class:`Reach`.
    """
    X = np.asarray(X, np.float64)
    H, W = X.shape[:2]
    centers = np.asarray(centers, np.float64)
    o, d, Y, normal = (np.asarray(a, np.float64) for a in (o, d, Y, normal))
    totem = np.asarray(totem, np.int64)
    n = len(centers)
    spacing = angular_spacing(d, totem, n) * int(supersample)
    excluded = np.asarray(excluded, bool)
    pts = X.reshape(-1, 3)
    surface = np.isfinite(pts).all(1) & ~excluded.ravel()
    far = ~np.isfinite(pts).all(1) & ~excluded.ravel()
    view = _unit(np.asarray(view, np.float64).reshape(-1, 3))
    seen = np.zeros((n, H * W), bool)
    along = np.zeros((n, H * W), bool)         # sees it along the camera's direction
    local = _local_spacing(d, totem, n)
    for j in range(n):
        if not np.isfinite(spacing[j]):
            continue
        mine = totem == j
        landed = mine & np.isfinite(Y).all(1)
        if landed.any() and surface.any():
            seen[j, surface] = _in_footprints(pts[surface], Y[landed], o[landed],
                                              d[landed], normal[landed], local[landed])
        left = mine & ~np.isfinite(Y).all(1)
        if left.any() and far.any():
            dist, k = cKDTree(d[left]).query(view[far], k=1)
            ok = np.isfinite(dist)
            hit = np.zeros(far.sum(), bool)
            hit[ok] = dist[ok] <= 2.0 * np.sin(0.5 * local[left][k[ok]])
            seen[j, far] = hit
    par = np.zeros(H * W)
    par[surface] = pair_parallax(pts[surface], centers, spacing, seen[:, surface])
    # a surface seen along the camera's own direction by each totem that sees it: the
    # angle at the point between the camera and the totem under one of its spacings
    for j in range(n):
        if np.isfinite(spacing[j]) and seen[j, surface].any():
            to_c = _unit(centers[j] - pts[surface])
            ang = np.arccos(np.clip((to_c * -view[surface]).sum(1), -1.0, 1.0))
            along[j, surface] = seen[j, surface] & (ang < spacing[j])
    n_seen = seen.sum(0)
    backdrop = far | (surface & (n_seen > 0) & (along.sum(0) == n_seen))
    par[backdrop] = 0.0
    depth = np.where(np.isfinite(pts).all(1), pts[:, 2], np.inf)
    return Reach(depth=depth.reshape(H, W).astype(np.float32),
                 n_totems=n_seen.reshape(H, W).astype(np.uint8),
                 parallax=par.reshape(H, W).astype(np.float32),
                 backdrop=backdrop.reshape(H, W), excluded=excluded.copy(),
                 spacing=spacing)
