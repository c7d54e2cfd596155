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

Whether the totems rest there is then up to the photo (:mod:`inverse.fit`): the plane
is only a hypothesis until the totems' rays agree on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SupportPlane", "plane_from_centres", "ray_plane", "MAX_RESIDUAL"]

MAX_RESIDUAL = 0.05
"""Largest rms residual ``N . P_j - R_j - h`` (in units of the mean radius) for four or
more totems to be taken as resting on one plane: a twentieth of a radius (3-5 mm),
above the initial pose's error along the normal (about a millimetre) and below what
floating totems placed near one height by chance reach (the box seed 1: 0.095)."""


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
