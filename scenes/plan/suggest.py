"""Which totem to move where: the best single move over a small grid, by the plan's own
prediction.

Each totem in turn is tried at each point of a grid of image positions (the frame's
width and height in even steps, the whole disc in view) and distances (its own times a
few factors), the others staying put; a move is scored by the share of the subject
region in the predicted reach (:mod:`scenes.plan.predict`), on a sample of the region's
pixels. A screen then a refinement: the coarse grid first, then a finer one around the
best move found. The reach of a placement is the union, over pairs of totems, of what
both see with a parallax of at least :data:`~scenes.reach.MIN_PARALLAX`, so moving one
totem only changes its own pairs: what each other pair covers is computed once. The
move kept is scored again with :func:`scenes.reach.reach_map` over all the totems, as
the plan itself is.

Frames and units: the OpenCV camera frame, metres; pixels (u, v), centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.plan.predict import (Plane, TotemRays, check_placement, disc_pixels,
                                 entry_distance, plane_hits, plane_reach, seen_by, sent_on,
                                 totem_image, totem_rays)
from scenes.reach import MIN_PARALLAX, pair_parallax

__all__ = ["SAMPLES", "COARSE", "DISTANCE_FACTORS", "MIN_GAIN", "Move", "sample_pixels",
           "region_share", "best_move"]

SAMPLES = 2000
"""About this many of the region's pixels score a move (a share to about a point)."""

COARSE = (6, 4)
"""Image positions tried per totem: columns x rows, evenly over the frame."""

DISTANCE_FACTORS = (0.6, 1.0, 1.6)
"""Distances tried per position, as factors of the totem's own."""

MIN_GAIN = 0.01
"""A move that widens the reach over the subject by less than this share is no move."""


@dataclass
class Move:
    """A suggested move.

    Attributes
    ----------
    totem : which totem (its index).
    center : (3,) where it would stand, metres.
    uv : (2,) its image position there, pixels.
    distance : its centre's distance from the camera there, metres.
    share : the share of the subject region in the reach after the move.
    before : the same share before it (the same sample of pixels).
    """

    totem: int
    center: np.ndarray
    uv: np.ndarray
    distance: float
    share: float
    before: float

    @property
    def gain(self) -> float:
        return self.share - self.before


def sample_pixels(region, samples: int = SAMPLES) -> tuple[np.ndarray, np.ndarray, int]:
    """(u, v, step): the region's pixels (``region`` (H, W) bool) on every ``step``-th
    row and column, ``step`` the smallest that leaves about ``samples`` of them."""
    step = max(1, int(np.floor(np.sqrt(max(region.sum(), 1) / samples))))
    v, u = np.nonzero(region[::step, ::step])
    return u * step, v * step, step


def _points(K, u, v, plane: Plane):
    view = camera.pixel_rays(K, u, v)
    X = plane_hits(np.zeros_like(view), view, plane)
    return view[None], X[None]


def region_share(K, size, centers, radius, ior, plane: Plane, u, v, region=None) -> float:
    """The share of pixels (u, v) in the reach of the totems, by
    :func:`scenes.reach.reach_map` over all of them (the plan's rule; the subject the
    ``plane`` within ``region``)."""
    labels = totem_image(K, size, centers, radius)
    rays = totem_rays(K, labels, centers, radius, ior)
    view, X = _points(K, u, v, plane)
    r = plane_reach(view, X, (labels[v, u] >= 0)[None], np.asarray(centers, np.float64),
                    rays, plane, K=K, region=region)
    return float(r.in_reach()[0].mean())


class _Screen:
    """What each totem sees of the sample points, and what each pair covers, for the
    placement as it stands; then the share a move of one totem leaves."""

    def __init__(self, K, size, centers, radius, ior, plane, u, v, region):
        self.K, self.size, self.plane, self.u, self.v = K, size, plane, u, v
        self.region = region
        self.centers = np.asarray(centers, np.float64)
        self.radius, self.ior = np.asarray(radius, np.float64), np.asarray(ior, np.float64)
        self.view, self.X = _points(K, u, v, plane)
        n, k = len(self.centers), len(u)
        labels = totem_image(K, size, self.centers, self.radius)
        rays = totem_rays(K, labels, self.centers, self.radius, self.ior)
        self.none = np.zeros((1, k), bool)        # hidden pixels are dropped at the end
        self.seen, self.spacing = np.zeros((n, k), bool), np.zeros(n)
        self.hides = np.zeros((n, k), bool)       # which sample pixels each totem hides
        for j in range(n):
            s, self.spacing[j] = seen_by(self.view, self.X, self.none, self.centers[j],
                                         rays.of(j), plane, K=K, region=region)
            self.seen[j] = s[0]
            self.hides[j] = np.isfinite(entry_distance(K, u, v, self.centers[j],
                                                       self.radius[j]))
        self.pair = {}
        for i in range(n):
            for j in range(i + 1, n):
                self.pair[i, j] = self._covers(self.centers[[i, j]], self.spacing[[i, j]],
                                               self.seen[[i, j]])

    def _covers(self, centers, spacing, seen) -> np.ndarray:
        return pair_parallax(self.X[0], centers, spacing, seen) >= MIN_PARALLAX

    def share(self, j: int, P) -> float | None:
        """The sample's share in the reach with totem ``j`` at ``P``; None where the
        placement cannot be, or the totem would hide part of the subject region."""
        centers = self.centers.copy()
        centers[j] = P
        R = self.radius[j]
        try:
            check_placement(self.K, self.size, centers, self.radius, self.plane)
        except BadInput:
            return None
        u, v, t = disc_pixels(self.K, self.size, P, R)
        if self.region[v, u].any():
            return None
        others = [(centers[i], self.radius[i]) for i in range(len(centers)) if i != j]
        for Pi, Ri in others:                     # its pixels another totem hides
            front = entry_distance(self.K, u, v, Pi, Ri) >= t
            u, v, t = u[front], v[front], t[front]
        o, d = sent_on(self.K, u, v, P, R, self.ior[j], others)
        if len(d) < 8:
            return 0.0
        seen_j, spacing_j = seen_by(self.view, self.X, self.none, P,
                                    TotemRays(o, d, np.zeros(len(d), np.int64)), self.plane,
                                    K=self.K, region=self.region)
        covered = np.zeros(len(self.u), bool)
        for (a, b), c in self.pair.items():
            if j not in (a, b):
                covered |= c
        for i in range(len(centers)):
            if i != j:
                covered |= self._covers(np.stack([P, centers[i]]),
                                        np.array([spacing_j, self.spacing[i]]),
                                        np.stack([seen_j[0], self.seen[i]]))
        hidden = self.hides[np.arange(len(centers)) != j].any(0)
        return float((covered & ~hidden).mean())


def _candidates(K, size, P, R, us, vs, factors):
    """Centres for a totem of radius ``R`` now at ``P``: at image positions ``us`` x
    ``vs`` (pixels), each at its distance times ``factors``."""
    dist = float(np.linalg.norm(P))
    for u in us:
        for v in vs:
            d = camera.pixel_rays(K, np.float64(u), np.float64(v))
            for f in factors:
                yield d * dist * f


def best_move(K, size, centers, radius, ior, plane: Plane, region, *,
              samples: int = SAMPLES) -> Move | None:
    """The single move of one totem that widens the predicted reach over ``region``
    ((H, W) bool) the most, or None when none widens it by :data:`MIN_GAIN`.

    ``centers`` (n, 3) m, ``radius`` and ``ior`` (n,), the camera ``K`` of ``size``
    (W, H) px, the subject's ``plane``.
    """
    W, H = size
    centers = np.asarray(centers, np.float64)
    u, v, _ = sample_pixels(region, samples)
    if len(u) == 0:
        return None
    screen = _Screen(K, size, centers, radius, ior, plane, u, v, region)
    before = region_share(K, size, centers, radius, ior, plane, u, v, region)
    best = (before + MIN_GAIN, None, None)
    cols, rows = COARSE
    du, dv = (W - 1) / (cols + 1), (H - 1) / (rows + 1)
    for j in range(len(centers)):
        us = du * np.arange(1, cols + 1)
        vs = dv * np.arange(1, rows + 1)
        for P in _candidates(K, size, centers[j], radius[j], us, vs, DISTANCE_FACTORS):
            s = screen.share(j, P)
            if s is not None and s > best[0]:
                best = (s, j, P)
    if best[1] is None:
        return None
    # a finer grid around the best: half a step each way, distances a quarter apart
    j, P0 = best[1], best[2]
    u0, v0 = camera.project(K, P0)
    for P in _candidates(K, size, P0, radius[j], u0 + du * np.array([-0.5, 0.0, 0.5]),
                         v0 + dv * np.array([-0.5, 0.0, 0.5]), (0.8, 1.0, 1.25)):
        s = screen.share(j, P)
        if s is not None and s > best[0]:
            best = (s, j, P)
    s, j, P = best
    moved = centers.copy()
    moved[j] = P
    after = region_share(K, size, moved, radius, ior, plane, u, v, region)
    if after - before < MIN_GAIN:
        return None
    return Move(totem=int(j), center=P, uv=camera.project(K, P),
                distance=float(np.linalg.norm(P)), share=after, before=before)
