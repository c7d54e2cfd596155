"""What the totems of one photo share when their poses are weighed: how the masks were drawn.

Masks drawn in one photo share how they were drawn (pixel-exact from a renderer, a brush
a few pixels too wide, a polygon's chords), while the rim's reflection band or a shadow
takes the photo's edge on few totems at once. So each totem's evidence
(:class:`inverse.pose.combined.Evidence`) is read against the photo's other totems':

- where to seek the silhouette (:func:`shared_offset`): the clean masks' edge profiles
  along the outline's size, summed, peak at the one pixel offset tool-drawn masks share,
  while each band lies at a fraction of its own radius; a totem whose own edges both lie
  beyond :data:`inverse.pose.combined.REFINE_WINDOW_PX` on one side of that offset has
  its rim sought again from there (:func:`inverse.pose.combined.from_offset`).

- which edge is the silhouette (:func:`shared_shares`): where a totem's nearest edge and
  its rim's strongest edge disagree on the size, the one nearer the size error the others
  show wins. Where at least two others' masks are clean conics that lie on the silhouette
  beyond doubt (share at least :data:`SURE_SHARE`, their nearest edge the rim's strongest
  too, within :data:`AGREE_PX`), that error is their nearest edges' (spread at least
  :data:`TIGHT_SD_PX`), else the others' rims' (at least :data:`SHARED_SD_PX`).
- the size itself (:func:`shared_sizes`, :func:`pooled`): where the masks are clean conics
  (outline within :data:`CLEAN_SHAPE_PX` rms of a sphere's) and the others' weighed sizes
  agree within :data:`POOL_SD_PX`, a totem whose photo edge puts its mask's size error
  more than :data:`POOL_KNEE_SD` sd from theirs is pulled to theirs: its edge is taken to
  be the band's or a shadow's, not its mask to be drawn unlike the others. Where at least
  :data:`MIN_SURE` others are sure of their edges (the masks are confirmed exact), every
  clean mask's size is weighed with theirs by inverse variance, however near its edge
  (its weight at most the knee's): an exact mask never loses to its own band or shadow. A polygon or a hand stroke (an outline
  further from a conic) errs by a fraction of each radius, not by shared pixels, and
  keeps its own size.

Sizes are the outline's growth ``g`` in pixels (:mod:`inverse.pose.combined`). Figures,
what was tried and dropped: docs/decisions.md, "pose: the edge's bias by the outline's
radius, and the photo's totems pooled", "pose: clean masks drawn alike share their
size" and "pose: the rim sought from the photo's shared size offset".
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from inverse.pose import rim

__all__ = ["AMBIGUITY", "SHARED_SD_PX", "CLEAN_SHAPE_PX", "SURE_SHARE", "AGREE_PX",
           "TIGHT_SD_PX", "POOL_SD_PX", "POOL_KNEE_SD", "POOL_SOFT_SD", "SIZE_GRID_PX",
           "MIN_SHARED", "MIN_SUPPORT", "MIN_SURE", "SizePrior", "shared_offset",
           "consensus", "clean", "shared_shares", "shared_sizes", "pooled"]

AMBIGUITY = 0.1        # a share counts as if within this of 0 and 1 (never certain)
SHARED_SD_PX = 0.3     # the least spread of the others' rims' size among a photo's totems
CLEAN_SHAPE_PX = 0.4   # a mask outline this close to a conic (rms px) was drawn by a tool
SURE_SHARE = 0.8       # a clean mask whose share is at least this, ...
AGREE_PX = 0.5         # ... and whose nearest and strongest edges agree this well, is sure
TIGHT_SD_PX = 0.15     # the least spread of clean masks' size error among a photo's totems
POOL_SD_PX = 0.5       # sizes are pooled only where the others agree this well (1 sd)
POOL_KNEE_SD = 2.0     # a size this many sd from the others' is pulled to theirs, ...
POOL_SOFT_SD = 0.5     # ... its own weight falling by exp(-1/2) every this much further
SIZE_GRID_PX = np.arange(-4.0, 4.01, 0.25)  # the sizes the shared offset is sought over
MIN_SHARED = 3         # clean masks a photo needs for a shared offset, ...
MIN_SUPPORT = 2        # ... and masks with an edge of their own there
MIN_SURE = 2           # others sure of their edges that confirm the masks exact


def shared_offset(evidence, window_px: float) -> float | None:
    """The photo's shared size offset (px, the silhouette less the masks' outlines),
    or None: the size at which the clean masks' edge profiles (``size_edge``), each
    divided by its own top, sum highest, where at least :data:`MIN_SHARED` clean masks
    give profiles and at least :data:`MIN_SUPPORT` of them have an edge of their own
    (nearest or rim's, ``x_near`` or ``x_far``) within ``window_px`` of it. Tool-drawn
    masks of one photo lie at one pixel offset from their silhouettes, while the rim's
    band lies at a fraction of each radius, so the silhouettes add up and the bands
    smear."""
    ev = [e for e in evidence
          if clean(e) and e.size_edge is not None and e.size_edge.max() > 0]
    if len(ev) < MIN_SHARED:
        return None
    g = float(SIZE_GRID_PX[int(np.argmax(np.sum([e.size_edge / e.size_edge.max()
                                                  for e in ev], 0)))])
    support = sum(min(abs(e.x_near[2] - g), abs(e.x_far[2] - g)) <= window_px for e in ev)
    return g if support >= MIN_SUPPORT else None


def consensus(values, floor_px: float) -> tuple[float, float]:
    """The others' median and its spread squared (px, px^2): the median absolute
    deviation as a sd, at least ``floor_px``."""
    v = np.asarray(values, np.float64)
    mu = float(np.median(v))
    return mu, max(floor_px ** 2, (1.4826 * float(np.median(np.abs(v - mu)))) ** 2)


def clean(e) -> bool:
    """The mask's outline lies within :data:`CLEAN_SHAPE_PX` rms of a conic."""
    return e is not None and e.shape_rms_px <= CLEAN_SHAPE_PX


def _sure(e, p) -> bool:
    return clean(e) and p is not None and p >= SURE_SHARE and \
        abs(e.x_near[2] - e.x_far[2]) <= AGREE_PX


def shared_shares(evidence, shares) -> list:
    """Each totem's share ``p`` weighed again by what the photo's other totems say of
    their masks' size error (the module's docstring): the likelihood ratio of the edge
    nearest the mask (``x_near``) against the rim's strongest edge refined (``x_far``)
    under the others' size error moves ``p`` as a share kept within :data:`AMBIGUITY` of
    0 and 1 would (a ratio of 1 leaves it). ``evidence``: a list of
    :class:`inverse.pose.combined.Evidence` or None (an unusable mask), ``shares`` the
    same length; returns the new shares (None where the evidence is)."""
    g_rim = np.array([e.x_rim[2] if e is not None else np.nan for e in evidence])
    out = []
    for j, (e, p) in enumerate(zip(evidence, shares)):
        others = np.delete(g_rim, j)
        others = others[np.isfinite(others)]
        if e is None or len(others) < 2:           # no photo to share with
            out.append(p)
            continue
        sure = [f.x_near[2] for i, f in enumerate(evidence)
                if i != j and _sure(f, shares[i])]
        mu, tau2 = consensus(sure, TIGHT_SD_PX) if clean(e) and len(sure) >= 2 else \
            consensus(others, SHARED_SD_PX)
        log_like = []                  # the near edge's, then the rim's (refined)
        for x, S in ((e.x_near, e.S_near), (e.x_far, e.S_far)):
            v = tau2 + (S[2, 2] if np.isfinite(S[2, 2]) else rim.MASK_SIGMA_PX ** 2)
            log_like.append(-0.5 * (x[2] - mu) ** 2 / v - 0.5 * np.log(v))
        q = min(max(p, AMBIGUITY), 1.0 - AMBIGUITY)
        odds = np.log(q / (1 - q)) + log_like[0] - log_like[1]
        moved = 1.0 / (1.0 + np.exp(-np.clip(odds, -50, 50))) - q
        out.append(float(min(max(p + moved, 0.0), 1.0)))
    return out


class SizePrior(NamedTuple):
    """The photo's other totems' size error (px) for one totem: median ``mu``, spread
    squared ``tau2`` (px^2), and whether at least :data:`MIN_SURE` of them are sure of
    their edges (``confirmed``: the masks were drawn exact)."""

    mu: float
    tau2: float
    confirmed: bool = False


def shared_sizes(evidence, sizes, shares=None) -> list:
    """Each totem's :class:`SizePrior` from the photo's others, or None: only for a
    clean mask (:data:`CLEAN_SHAPE_PX`) with at least two clean others whose weighed
    sizes ``sizes`` (one px value a totem, NaN where none) agree within
    :data:`POOL_SD_PX`; ``shares`` (each mask's own share, or None) tell which others
    are sure of their edges."""
    g = np.array([s if clean(e) else np.nan for e, s in zip(evidence, sizes)], np.float64)
    shares = [None] * len(evidence) if shares is None else shares
    out = []
    for j, e in enumerate(evidence):
        others = np.delete(g, j)
        others = others[np.isfinite(others)]
        prior = consensus(others, TIGHT_SD_PX) if clean(e) and len(others) >= 2 else None
        if prior is None or prior[1] > POOL_SD_PX ** 2:
            out.append(None)
            continue
        sure = sum(_sure(f, shares[i]) for i, f in enumerate(evidence) if i != j)
        out.append(SizePrior(*prior, confirmed=sure >= MIN_SURE))
    return out


def pooled(g: float, var: float, S_edge: float, prior) -> tuple[float, float]:
    """A totem's size ``g`` px and its variance ``var`` px^2 pulled to the others'
    ``prior`` (a :class:`SizePrior` or ``(mu, tau2)``, :func:`shared_sizes`) as far as
    the photo's edge that set it (variance ``S_edge`` px^2) lies beyond
    :data:`POOL_KNEE_SD` sd of it: its own weight ``t`` is 1 up to the knee, then falls
    as a Gaussian tail; for confirmed exact masks at most the inverse-variance weight
    ``tau2 / (tau2 + var)``. The variance is the mixture's, counting the gap between
    the two (with ``t`` kept within :data:`AMBIGUITY` of 0 and 1 on the knee's side)."""
    mu, tau2, confirmed = SizePrior(*prior)
    if not np.isfinite(S_edge):
        return g, var                              # no edge: nothing to doubt
    z = abs(g - mu) / np.sqrt(S_edge + tau2)
    t = float(np.exp(-0.5 * (max(z - POOL_KNEE_SD, 0.0) / POOL_SOFT_SD) ** 2))
    if confirmed and tau2 / (tau2 + var) < t:
        t = tau2 / (tau2 + var)
        return mu + t * (g - mu), t * var + t * (1 - t) * (g - mu) ** 2
    q = min(max(t, AMBIGUITY), 1.0 - AMBIGUITY)
    return mu + t * (g - mu), t * var + (1 - t) * tau2 + q * (1 - q) * (g - mu) ** 2
