"""The support plane: the plane that totems resting on a table, a floor or the ground
touch, found from their centres and radii alone.

A sphere of radius ``R_j`` resting on a plane ``{X : N . X = h}`` (camera frame, OpenCV,
metres; ``N`` the unit normal pointing up, out of the table, towards the totems) has its
centre ``P_j`` one radius above it:

    N . P_j - R_j = h        for every resting totem j.

Three totems fix ``N`` and ``h`` up to a choice of two (:func:`plane_from_centres`);
a fourth or more over-determine them, and their residual says whether the totems rest
on one plane at all. The plane is evidence the key already holds (the radii), not a
tuned constant. The camera must see the plane from the totems' side (``h < 0``: the
camera centre lies above it), and a camera held upright sees a table's normal pointing
up the image (``N_y < 0``), which chooses between the two solutions of three totems.

:func:`plane_view` uses the plane for the camera view: the totems' rays are splatted
where they first meet either the fit's chosen surface or the plane, so a table seen at
grazing angles is placed where it is, not at the depth that explains each ray alone.
Three floating totems also fix such a plane, so the fit uses it only when told the
totems rest (``FitSettings.resting``, ``totems fit --resting``), and then for the view
alone: the protected region stays where the fit's own rays end, since the plane's end
points keep only the little of the table the totems saw (see docs/decisions.md, "fit:
resting totems cap the view, not the region").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.camera import pixel_rays

__all__ = ["SupportPlane", "plane_from_centres", "ray_plane", "plane_view", "MAX_RESIDUAL",
           "COS_VIEW"]

MAX_RESIDUAL = 0.05
"""Largest rms residual ``N . P_j - R_j - h`` (in units of the mean radius) for four or
more totems to be taken as resting on one plane: a twentieth of a radius (3-5 mm),
above the initial pose's error along the normal (about a millimetre) and below what
floating totems placed near one height by chance reach (the box seed 1: 0.095)."""

COS_VIEW = 0.3
"""Rays entering their sphere at an incidence cosine below this are left out of the
plane's view: near the rim the glass blurs and mixes in reflection (as
:mod:`verify.metrics.evidence`)."""


@dataclass(frozen=True)
class SupportPlane:
    """A plane ``N . X = h`` in the camera frame (metres), ``N`` unit, pointing up.

    Attributes
    ----------
    normal : (3,) unit normal, towards the totems.
    offset : ``h`` (metres); the camera centre lies ``-h`` above the plane.
    residual : rms of ``N . P_j - R_j - h`` over the totems, metres (0 for three).
    """

    normal: np.ndarray
    offset: float
    residual: float

    def contact_points(self, centers, radius) -> np.ndarray:
        """Where each totem touches the plane, (n, 3) metres: ``P_j - R_j N``."""
        return np.asarray(centers, float) - np.asarray(radius, float)[:, None] * self.normal

    def to_dict(self) -> dict:
        """Plain numbers (``fit.json`` ``geometry.support``)."""
        return {"normal": [round(float(x), 6) for x in self.normal],
                "offset": round(float(self.offset), 6),
                "residual": round(float(self.residual), 6)}

    def depth(self, d) -> np.ndarray:
        """Distance along the camera rays ``d`` (m, 3) to the plane (m,), metres; inf
        where the ray does not meet it in front of the camera."""
        return ray_plane(np.zeros(3), d, self.normal, self.offset)

    def pixel_depth(self, K, u, v) -> np.ndarray:
        """Camera-frame ``z`` (metres) where the rays through pixels ``u``, ``v`` (any
        shape; OpenCV centres) meet the plane; inf where they do not, in front."""
        d = pixel_rays(K, u, v)
        t = self.depth(d.reshape(-1, 3)).reshape(d.shape[:-1])
        return t * d[..., 2]

    @classmethod
    def from_dict(cls, d: dict) -> "SupportPlane":
        """The plane from :meth:`to_dict`'s numbers (``fit.json`` ``geometry.support``)."""
        return cls(np.asarray(d["normal"], np.float64), float(d["offset"]),
                   float(d.get("residual", 0.0)))


def ray_plane(o, d, normal, offset) -> np.ndarray:
    """``t`` with ``N . (o + t d) = h`` for rays ``o + t d`` (t > 0); inf where parallel
    or behind. ``o`` (3,) or (m, 3), ``d`` (m, 3); returns (m,)."""
    o = np.asarray(o, float)
    d = np.asarray(d, float)
    num = offset - o @ normal
    den = d @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(den) > 1e-12, num / den, np.inf)
    return np.where(np.isfinite(t) & (t > 0), t, np.inf)


def _solve_three(P, R) -> list[np.ndarray]:
    """The unit normals ``N`` with ``N . (P_j - P_0) = R_j - R_0`` (j = 1, 2): a line
    meeting the unit sphere in zero, one or two points."""
    A = np.stack([P[1] - P[0], P[2] - P[0]])
    b = np.array([R[1] - R[0], R[2] - R[0]])
    m = np.cross(A[0], A[1])                    # the line's direction
    if np.linalg.norm(m) < 1e-12:
        return []                               # the three centres on one line
    m = m / np.linalg.norm(m)
    x0 = np.linalg.lstsq(A, b, rcond=None)[0]   # the point of the line nearest 0
    disc = 1.0 - x0 @ x0
    if disc < 0:
        return []
    s = np.sqrt(disc)
    return [x0 + s * m, x0 - s * m]


def _refine(P, R, N):
    """Least squares of ``N . P_j - R_j = h`` over all totems from a start ``N``
    (Gauss-Newton on the sphere), and the rms residual."""
    for _ in range(20):
        h = np.mean(P @ N - R)
        r = P @ N - R - h
        J = P - P.mean(0)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        step -= (step @ N) * N                  # stay on the unit sphere
        N = N + step
        N = N / np.linalg.norm(N)
        if np.linalg.norm(step) < 1e-12:
            break
    h = float(np.mean(P @ N - R))
    return N, h, float(np.sqrt(np.mean(np.square(P @ N - R - h))))


def plane_from_centres(centers, radius, *, max_residual: float = MAX_RESIDUAL):
    """The plane the totems rest on, or None when they cannot rest on one.

    Parameters
    ----------
    centers : (n, 3) totem centres, camera frame, metres (n >= 3).
    radius : (n,) or scalar, metres.
    max_residual : the rms residual allowed for four or more totems, in mean radii.

    Returns
    -------
    :class:`SupportPlane`, or None: fewer than three totems, centres on one line, no
    plane with the camera above it and its normal up the image (``N_y < 0``), or
    (four or more totems) a residual above ``max_residual``.
    """
    P = np.asarray(centers, float).reshape(-1, 3)
    R = np.broadcast_to(np.asarray(radius, float), (len(P),)).astype(float)
    if len(P) < 3 or not np.all(np.isfinite(P)):
        return None
    best = None
    for i in range(len(P) - 2):                 # starts from consecutive triples
        for N in _solve_three(P[i:i + 3], R[i:i + 3]):
            N, h, res = _refine(P, R, N)
            if h >= 0 or N[1] >= 0:             # camera below it, or normal down the image
                continue
            if best is None or res < best.residual:
                best = SupportPlane(N, h, res)
    if best is None or best.residual > max_residual * float(R.mean()):
        return None
    return best


def plane_view(rays, frame, plane: SupportPlane, recon, depth, points, size, *,
               res=(120, 160), cos_min: float = COS_VIEW):
    """The camera view with its depth capped by the support plane.

    Where a camera column meets the plane before the chosen surface (``depth``), the
    view is the totem rays (``cos_in >= cos_min``) splatted where they first pass behind
    the capped depth map (:func:`inverse.view.splat.surface_hits`, a map of ``res`` cells);
    elsewhere ``recon`` is kept.

    Parameters
    ----------
    rays : :class:`inverse.rays.TotemRays` (camera frame, metres; linear radiance).
    frame : the grid's :class:`inverse.grid.FrustumFrame`.
    recon, depth : (H, W, 3) sRGB and (H, W) metres, the chosen view and its depth.
    points : (k, 3) camera-frame metres, where the rays end in the chosen geometry.
    size : (W, H).

    Returns
    -------
    recon (H, W, 3) float32 sRGB, depth (H, W) float32 metres, points (k', 3) metres,
    and the share of the image whose depth the plane capped.
    """
    from inverse.grid import cells_to_pixels
    from inverse.view.splat import splat_image, surface_hits
    from scenes.camera import pixel_rays, project
    from scenes.colour import linear_to_srgb

    W, H = size
    K = frame.K
    nt, ns = res
    S, T = np.meshgrid((np.arange(ns) + 0.5) / ns, (np.arange(nt) + 0.5) / nt)
    u = frame.u_range[0] + S * (frame.u_range[1] - frame.u_range[0])
    v = frame.v_range[0] + T * (frame.v_range[1] - frame.v_range[0])
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    z_plane = ray_plane(np.zeros(3), d_cam.reshape(-1, 3), plane.normal,
                        plane.offset).reshape(nt, ns)          # d_cam has z = 1: t = z
    chosen = np.asarray(depth, np.float64)[np.clip(np.rint(v).astype(int), 0, H - 1),
                                           np.clip(np.rint(u).astype(int), 0, W - 1)]
    chosen = np.where(np.isfinite(chosen) & (chosen > 0), chosen, frame.far)
    capped = np.clip(np.minimum(chosen, z_plane), frame.near, frame.far)
    good = rays.cos_in >= cos_min
    uh, vh, zh, hit = surface_hits(rays.o[good], rays.d[good], frame, capped)
    view = linear_to_srgb(np.clip(splat_image(uh, vh, rays.radiance[good], size, hit=hit),
                                  0.0, 1.0))
    on = cells_to_pixels((z_plane < chosen).astype(np.float64), frame, size,
                         nearest=True) > 0.5
    out = np.where(on[..., None], view, recon).astype(np.float32)
    new_depth = np.where(on, cells_to_pixels(capped, frame, size, nearest=True), depth)
    inside = hit & (uh >= -0.5) & (uh < W - 0.5) & (vh >= -0.5) & (vh < H - 0.5)
    X = pixel_rays(K, uh[inside], vh[inside])
    X = X / X[:, 2:3] * zh[inside, None]

    def landing(P):                                     # whether P projects into ``on``
        P = np.asarray(P, np.float64).reshape(-1, 3)
        uv = np.full((len(P), 2), -1.0)
        front = P[:, 2] > 0
        uv[front] = project(K, P[front])
        ui, vi = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
        ok = front & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
        res_ = np.zeros(len(P), bool)
        res_[ok] = on[vi[ok], ui[ok]]
        return res_, ok

    in_new, _ = landing(X)
    old = np.asarray(points, np.float64).reshape(-1, 3)
    in_old, ok_old = landing(old)
    pts = np.concatenate([X[in_new], old[ok_old & ~in_old]])
    return out, new_depth.astype(np.float32), pts, float(on.mean())
