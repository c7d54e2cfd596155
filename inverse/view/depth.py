"""The depth the totems establish: per cell of a sweep's map, the depth slice where the
totems that land there agree best, smoothed by semi-global matching, with an interval.

The cost of a cell at a slice is the variance of the landing totems' colours
(:attr:`inverse.view.sweep.SliceColours.consistency`) where at least two land with
enough parallax, the median cost elsewhere (it says nothing there); costs are in units of
that median. Semi-global matching (:func:`inverse.view.sweep.semi_global`) prefers depth
maps smooth but for a few edges. Resting totems add a prior: their support plane
(:mod:`inverse.view.support`) costs ``prior`` less at its own slice and the two beside it,
except where the totems agree more than a slice in front of it (the plane is hidden
there: by a wall below the horizon, an object on the table). The interval is the run of
slices around the chosen one whose aggregated cost lies within ``tol`` of its least: the
depths the totems cannot tell apart.

Public functions
----------------
``established_depth(var, n_land, parallax, z, ...) -> EstablishedDepth`` per cell;
``plane_slice(plane, frame, res, z) -> (k, depth)`` the plane's slice per cell;
``slice_window(z, frame, res, lo, hi) -> (nk, nt, ns) bool`` the slices inside each
cell's interval.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inverse.grid import FrustumFrame, cell_centres
from inverse.view.sweep import semi_global

__all__ = ["EstablishedDepth", "established_depth", "plane_slice", "slice_window", "PRIOR",
           "TOL", "P1", "P2"]

P1, P2 = 0.3, 3.0
"""Semi-global matching's penalties, in median costs (the stereo view's,
:func:`inverse.view.sweep.plane_sweep`)."""

PRIOR = 0.5
"""The support plane's bonus, in median costs: half the typical disagreement, so a plane
wins where the totems cannot tell it from its neighbours and loses where they see a
surface elsewhere (docs/decisions/inverse-view.md, "depth: the support plane as a
prior")."""

TOL = 3.0
"""Aggregated cost (median costs) within which slices count as equally good: the
interval's width."""


@dataclass(frozen=True)
class EstablishedDepth:
    """Per cell of an ``(nt, ns)`` map: the depth (camera-frame ``z``, metres), its
    interval ``lo`` <= ``z`` <= ``hi`` (metres), NaN where no two totems land with the
    parallax asked at any slice; ``on_plane`` (bool) where the support plane was chosen."""

    z: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    on_plane: np.ndarray


def plane_slice(plane, frame: FrustumFrame, res, z) -> tuple[np.ndarray, np.ndarray]:
    """Where ``plane`` (:class:`inverse.view.support.SupportPlane`) meets each cell
    centre's camera ray: the nearest of the slices ``z`` (metres, (nk,)) in inverse depth,
    and the depth itself (metres); -1 and NaN where the ray misses it (above the
    horizon) or meets it outside the slices' range."""
    zp = plane.pixel_depth(frame.K, *cell_centres(frame, res))
    z = np.asarray(z, np.float64)
    inside = np.isfinite(zp) & (zp >= z.min()) & (zp <= z.max())
    inv = 1.0 / np.where(inside, zp, 1.0)
    k = np.argmin(np.abs(1.0 / z[:, None, None] - inv[None]), axis=0)
    return np.where(inside, k, -1), np.where(inside, zp, np.nan)


def slice_window(z, frame: FrustumFrame, res, lo, hi, *, slack: float = 1.0) -> np.ndarray:
    """(nk, nt, ns) bool: the slices ``z`` (metres, (nk,), even in inverse depth) inside
    each cell's interval ``lo`` <= z <= ``hi`` (metres, (H, W) maps over the photo such
    as :class:`verify.metrics.evidence.Evidence`'s, read at the pixel of the cell's
    centre), widened by ``slack`` slices in inverse depth; none where the interval is
    unknown (NaN) or the centre lies outside the photo."""
    z = np.asarray(z, np.float64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    H, W = lo.shape
    uu, vv = cell_centres(frame, res)
    u, v = np.rint(uu).astype(np.int64), np.rint(vv).astype(np.int64)
    inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    u, v = np.clip(u, 0, W - 1), np.clip(v, 0, H - 1)
    a, b = lo[v, u], hi[v, u]
    known = inside & np.isfinite(a) & np.isfinite(b) & (a > 0)
    inv = 1.0 / z
    step = float(np.abs(np.diff(inv)).mean()) if len(z) > 1 else 0.0
    near = 1.0 / np.where(known, a, 1.0) + slack * step      # the largest inverse depth
    far = 1.0 / np.where(known, b, 1.0) - slack * step
    within = (inv[:, None, None] <= near[None]) & (inv[:, None, None] >= far[None])
    return within & known[None]


def _vertex(cost, k, z):
    """The depth at the parabola's vertex through ``cost`` at slices k-1, k, k+1 (in
    inverse depth), per cell; ``z`` (nk,) the slices' depths (metres)."""
    nk = len(z)
    c0 = np.take_along_axis(cost, k[None], 0)[0]
    cm = np.take_along_axis(cost, np.clip(k - 1, 0, nk - 1)[None], 0)[0]
    cp = np.take_along_axis(cost, np.clip(k + 1, 0, nk - 1)[None], 0)[0]
    den = cm - 2 * c0 + cp
    ok = np.isfinite(den) & (den > 1e-12) & (k > 0) & (k < nk - 1)
    off = np.where(ok, 0.5 * (cm - cp) / np.where(ok, den, 1.0), 0.0)
    inv = 1.0 / z
    return 1.0 / (inv[k] + np.clip(off, -0.5, 0.5) * np.gradient(inv)[k])


def _half_step(z, k, side):
    """The depth half a slice beyond slice ``k`` (per cell; ``side`` -1 nearer, +1
    farther), in inverse depth, kept between the first and last slice."""
    inv = 1.0 / np.asarray(z, np.float64)          # decreasing: z increases with k
    step = np.gradient(inv)[k]                     # negative
    return 1.0 / np.clip(inv[k] + side * 0.5 * step, inv[-1], inv[0])


def _interval(cost, k, tol):
    """The first and last slice of the run around ``k`` (per cell) whose ``cost`` lies
    within ``tol`` of ``cost[k]``."""
    nk = cost.shape[0]
    near = cost <= np.take_along_axis(cost, k[None], 0) + tol
    idx = np.arange(nk)[:, None, None]
    # the run is bounded by the nearest slice on each side that is not near
    below = np.where(~near & (idx < k[None]), idx, -1).max(axis=0) + 1
    above = np.where(~near & (idx > k[None]), idx, nk).min(axis=0) - 1
    return below, above


def established_depth(var, n_land, parallax, z, *, min_parallax: float,
                      agree_var: float | None = None, plane_k=None,
                      prior: float = PRIOR, tol: float = TOL, p1: float = P1,
                      p2: float = P2) -> EstablishedDepth:
    """The depth the totems establish per cell (see the module docstring).

    Parameters
    ----------
    var : (nk, nt, ns) the landing totems' colour variance (summed over channels).
    n_land : (nk, nt, ns) how many totems land.
    parallax : (nk, nt, ns) the largest parallax between two landing totems, in their
        rays' spacings (:func:`verify.metrics.evidence.slice_parallax`).
    z : (nk,) the slices' depths, metres, increasing.
    min_parallax : the parallax a slice needs to count.
    agree_var : the variance under which the totems agree (for the plane's visibility
        test); None: the plane's bonus applies wherever it has a slice.
    plane_k : (nt, ns) the support plane's slice per cell (:func:`plane_slice`; -1 where
        none), or None for no prior.
    prior, tol, p1, p2 : the plane's bonus, the interval's tolerance and the matching's
        penalties, all in median costs.
    """
    var = np.asarray(var, np.float64)
    z = np.asarray(z, np.float64)
    nk = len(z)
    ok = (np.asarray(n_land) >= 2) & (np.asarray(parallax) >= min_parallax)
    fill = float(np.median(var[ok])) if ok.any() else 1.0
    cost = np.where(ok, var, fill) / max(fill, 1e-12)
    if plane_k is not None:
        kp = np.asarray(plane_k)
        bonus = kp >= 0
        if agree_var is not None:
            agree = ok & (var <= agree_var)
            idx = np.arange(nk)[:, None, None]
            hidden = (agree & (idx < kp[None] - 1)).any(axis=0)
            bonus &= ~hidden
        for dk in (-1, 0, 1):
            kk = np.clip(kp + dk, 0, nk - 1)[None]
            cur = np.take_along_axis(cost, kk, 0)
            np.put_along_axis(cost, kk, np.where(bonus[None], cur - prior, cur), 0)
        cost -= min(float(cost.min()), 0.0)
    agg = semi_global(cost, p1, p2)
    k = np.argmin(agg, axis=0)
    has = ok.any(axis=0)
    lo_k, hi_k = _interval(agg, k, tol)
    on_plane = np.zeros(k.shape, bool) if plane_k is None else \
        has & (np.asarray(plane_k) >= 0) & (np.abs(k - np.asarray(plane_k)) <= 1)
    depth = np.where(has, _vertex(agg, k, z), np.nan)
    return EstablishedDepth(depth, np.where(has, _half_step(z, lo_k, -1), np.nan),
                            np.where(has, _half_step(z, hi_k, +1), np.nan), on_plane)
