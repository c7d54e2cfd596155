"""Totem pose from the mask and the photo together, each weighed by what it is worth.

Both say where the sphere's outline lies: the mask's outline (:mod:`inverse.pose.pose`) and
the photo's edges near it. In the three numbers that move an outline, ``x = (du, dv,
g)`` pixels (its axis's image moved by (du, dv), its size grown by g), the photo
measures the mask's error arc by arc:

    o_a = n_a . (du, dv) + g + b + e_a,

``o_a`` the offset along the outward normal ``n_a`` of the edge nearest the outline on
arc ``a`` (the nearest local peak of the blurred photo's step across it, not the
strongest: the rim's reflection band puts a stronger edge 1.5-4 px inside on some
arcs), ``b`` the edge's own bias (:func:`edge_bias_px`, a function of the outline's
radius) and ``e_a`` the arcs' scatter.
A robust least-squares fit over the arcs (:func:`fit_offsets`) gives ``x_p`` and its
covariance ``S_p``, to which the bias's spread from totem to totem is added.

How much the mask lies on the silhouette is a share ``p`` in [0, 1], the product of
three smooth tails (:func:`edge_share`): the nearest edges agree on the mask's size (``g``
within ``CONFIRM_SD`` sd), tightly (the arcs' scatter within :data:`TIGHT_WIDTHS` of the
edge's own width: a pixel filter, a blur or JPEG that widens the edge widens the scatter
its peaks show, so a wide edge is allowed more), and the rim's strongest edge
(:mod:`inverse.pose.rim`) is not outside them. Two estimates are weighed by ``p``: on the
edge, the mask's error is taken to be only what the photo shows beyond ``CONFIRM_SD``
sd, ``s_m^2 = max(0, x_p^2 - CONFIRM_SD^2 S_p)``, so a pixel-exact mask keeps its own
pose; off it, ``x_p`` is measured from the rim's strongest edge and the mask's error is
at least a drawn mask's slop, ``s_m^2 = max(x_p^2, MASK_SIGMA_PX^2)``. Either way the
mask's outline residual beyond a pixel mask's steps (a polygon's chords) adds to
``s_m^2``, and the outline moves by ``w x_p`` with the inverse-variance weight ``w =
s_m^2 / (s_m^2 + S_p)``; the two moves are mixed by ``p``.

How sure: on the edge the outline's variance is ``w S_p + (1 - w) x_p^2`` (the photo
right, or the mask right but off by what the photo saw), off it ``w S_p + (1 - w)
min(x_p^2, S_p)``; the mixture's variance adds ``q (1 - q)`` times the squared gap
between the two moves, ``q`` being ``p`` kept within :data:`AMBIGUITY` of 0 and 1 (which
edge is the silhouette is never certain where two lie apart); plus the mask outline's
own, mapped to the centre by the Jacobian of ``x -> P``: one sd along the line of sight
and across it.

The photo's totems share evidence (:func:`weigh_photo`, :mod:`inverse.pose.shared`): their
masks were drawn alike, and the band or a shadow takes the edge on few totems at once, so
the others say where to seek a rim whose own edges both missed it (:func:`from_offset`),
which of a totem's edges is the silhouette and, for masks drawn by a tool, how far off its
size is.

Figures, what was tried and dropped: docs/decisions.md, "pose: the mask and the photo
weighed", "pose: the mask's share weighed softly, and a sd that covers", "pose: the
edge's bias by the outline's radius, and the photo's totems pooled", "pose: clean masks
drawn alike share their size" and "pose: the rim sought from the photo's shared size offset".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from inverse.pose import pose, shared, rim
from inverse.pose.shared import AMBIGUITY, SHARED_SD_PX, shared_shares
from scenes import camera, silhouette

__all__ = ["ARCS", "WINDOW_PX", "STEP_PX", "PEAK_FRACTION", "EDGE_BIAS_PX",
           "EDGE_BIAS_PER_PX", "EDGE_BIAS_RADII_PX", "EDGE_BIAS_SD_PX", "ITERATIONS",
           "CONFIRM_SD", "CONFIRM_SOFT_SD", "SHAPE_QUANT_PX", "TIGHT_WIDTHS",
           "TIGHT_SOFT_WIDTHS", "NEAR_ITERATIONS", "REFINE_ITERATIONS", "REFINE_WINDOW_PX",
           "OUTER_PX", "OUTER_SOFT_PX", "AMBIGUITY", "SHARED_SD_PX", "move_of",
           "edge_share", "POSE_FROM", "uncertainty_record", "initial_centres",
           "CombinedPose", "edge_offsets", "edge_bias_px", "fit_offsets", "photo_move",
           "Evidence", "size_profile", "totem_evidence", "weigh", "shared_shares",
           "from_offset", "weigh_photo", "combine_centre", "combined_poses"]

ARCS = 12              # arcs the outline is cut into (each one edge offset)
WINDOW_PX = 3.0        # how far along each normal the nearest edge is looked for (pixels)
STEP_PX = 0.25         # the profile's sampling step along the normal (pixels)
PEAK_FRACTION = 0.3    # a local peak counts when at least this fraction of its arc's top
EDGE_BIAS_PX = 0.12    # where the nearest edge lies from the silhouette (pixels, outward)
EDGE_BIAS_PER_PX = -0.009  # ... less this per pixel of the outline's radius (the band)
EDGE_BIAS_RADII_PX = (10.0, 65.0)  # the radii that bias was measured over (pixels)
EDGE_BIAS_SD_PX = 0.2   # that bias's spread from totem to totem (pixels, 1 sd)
EDGE_LATERAL_SD_PX = 0.5  # the nearest edge's sideways offset from totem to totem (1 sd)
ITERATIONS = 3         # re-measurements from the moved outline
NEAR_ITERATIONS = 2    # the same from the mask's outline, for the edge nearest it
REFINE_ITERATIONS = 2  # the same from the rim's strongest edge, ...
REFINE_WINDOW_PX = 1.0  # ... looking this far along each normal
OUTER_PX = 0.5         # the rim's edge this far outside the nearest: the mask is inside,
OUTER_SOFT_PX = 0.25   # ... its share falling by exp(-1/2) every this much further (px)
SHAPE_QUANT_PX = 0.25  # rms distance of a pixel-exact mask's outline from a smooth one
TIGHT_WIDTHS = 0.2     # the arcs' edges agree on the outline's size to this (1 sd, in
TIGHT_SOFT_WIDTHS = 0.1  # units of the edge's width), the share falling every this much
CONFIRM_SD = 2.0       # the photo moves the mask's outline only beyond this many sd,
CONFIRM_SOFT_SD = 0.25  # ... and the mask's share falls by exp(-1/2) every this much


@dataclass
class CombinedPose:
    """One totem's centre and what it rests on. Lengths in metres, outline in pixels."""

    center: np.ndarray      # (3,) camera frame
    sd_along: float         # 1 sd of the centre along the line of sight
    sd_across: float        # 1 sd across it (each of the two lateral directions)
    mask_center: np.ndarray  # (3,) the mask's own pose
    photo_move: np.ndarray  # (3,) x_p: the photo's edge less the mask's outline (du, dv,
    #                         g) px, of the likelier hypothesis (on the edge: p >= 0.5)
    photo_cov: np.ndarray   # (3, 3) its covariance S_p
    weight: np.ndarray      # (3,) w: 0 keeps the mask's outline, 1 takes the photo's
    shape_rms_px: float     # the mask outline's rms distance from the best sphere outline
    edge_share: float = 0.0  # p: how much the mask's outline lies on the photo's edges


def edge_offsets(P, R: float, K, grad, *, arcs: int = ARCS,
                 window_px: float = WINDOW_PX):
    """Each arc's mean outward normal (arcs, 2), the offset (arcs,) pixels, outward
    positive, of the edge nearest the outline of the sphere (``P`` (3,) metres, ``R``
    metres) on that arc: the nearest local peak of the arc's mean step profile that
    reaches :data:`PEAK_FRACTION` of the arc's top (NaN where there is none), and that
    peak's width (arcs,) pixels, ``sqrt(-p / p'')`` (a Gaussian profile's sd)."""
    pts, nrm = rim.outline(P, R, K)
    ts = np.arange(-window_px, window_px + 1e-9, STEP_PX)
    prof = np.stack([silhouette.edge_at(pts + t * nrm, nrm, *grad) for t in ts], 1)
    m = len(pts) // arcs * arcs
    prof = prof[:m].reshape(arcs, -1, len(ts)).mean(1)            # (arcs, T)
    normals = nrm[:m].reshape(arcs, -1, 2).mean(1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets, widths = np.full(arcs, np.nan), np.full(arcs, np.nan)
    for a, p in enumerate(prof):
        inner = p[1:-1]
        peak = (inner >= p[:-2]) & (inner > p[2:]) & (inner >= PEAK_FRACTION * p.max())
        idx = np.flatnonzero(peak) + 1
        if idx.size and p.max() > 0:
            i = idx[np.argmin(np.abs(ts[idx]))]
            # sub-sample peak: the parabola through the three samples
            den = p[i - 1] - 2 * p[i] + p[i + 1]
            offsets[a] = ts[i] + (0.5 * STEP_PX * (p[i - 1] - p[i + 1]) / den if den < 0
                                  else 0.0)
            if den < 0:
                widths[a] = STEP_PX * np.sqrt(-p[i] / den)
    return normals, offsets, widths


def fit_offsets(normals, offsets) -> tuple[np.ndarray, np.ndarray]:
    """``x = (du, dv, g)`` pixels from the arcs' offsets, ``o_a = n_a . (du, dv) + g``,
    by iteratively reweighted least squares (Tukey's biweight, scale from the median
    absolute residual), and its covariance (3, 3) pixels squared (the residuals' robust
    scale, at least a quarter pixel, through the weighted design; infinite when fewer
    than four arcs have an edge)."""
    ok = np.isfinite(offsets)
    A = np.column_stack([normals[ok], np.ones(ok.sum())])
    o = offsets[ok]
    if len(o) < 4:
        return np.zeros(3), np.diag([np.inf] * 3)          # no edge: no evidence
    w = np.ones(len(o))
    for _ in range(8):
        Aw = A * w[:, None]
        x = np.linalg.lstsq(Aw.T @ A, Aw.T @ o, rcond=None)[0]
        r = o - A @ x
        s = max(1.4826 * np.median(np.abs(r)), 0.25)
        u = r / (4.685 * s)
        w = np.where(np.abs(u) < 1, (1 - u ** 2) ** 2, 0.0)
        if w.sum() < 4:
            w = np.ones(len(o))
    Aw = A * w[:, None]
    n_eff = max(w.sum() - 3, 1.0)
    s2 = max((w * r ** 2).sum() / n_eff, 0.25 ** 2)
    cov = s2 * np.linalg.pinv(Aw.T @ A) * len(o) / max(w.sum(), 1.0)
    return x, cov


def move_of(P0, P, R: float, K) -> np.ndarray:
    """The outline move ``x`` (3,) pixels that takes ``P0``'s outline to ``P``'s (the
    inverse of ``rim._moved``)."""
    uv = camera.project(K, np.stack([P0, P]))
    half = np.arcsin(np.clip(R / np.linalg.norm([P0, P], axis=1), 0.0, 1.0))
    return np.array([*(uv[1] - uv[0]), K[0, 0] * (half[1] - half[0])])


_REACH = np.array([rim.SHIFT_PX, rim.SHIFT_PX, rim.GROW_PX])
_BIAS_SD = np.array([EDGE_LATERAL_SD_PX, EDGE_LATERAL_SD_PX, EDGE_BIAS_SD_PX])


def edge_bias_px(P, R: float, K) -> float:
    """Where the photo's nearest edge lies from the silhouette of the sphere (``P`` (3,)
    metres, ``R`` metres), pixels outward: a little outside on small outlines, inside on
    large ones, where the rim's reflection band (a fixed fraction of the radius) pulls
    it in."""
    r_px = K[0, 0] * np.tan(np.arcsin(np.clip(R / np.linalg.norm(P), 0.0, 1.0)))
    return EDGE_BIAS_PX + EDGE_BIAS_PER_PX * float(np.clip(r_px, *EDGE_BIAS_RADII_PX))


def photo_move(P0, R: float, K, grad, *, start=None, iterations: int = ITERATIONS,
               window_px: float = WINDOW_PX):
    """The photo's nearest edge as a move ``x`` (3,) pixels of ``P0``'s outline (du, dv,
    g, the edge bias taken off), its covariance (3, 3) and the edge's median width
    (pixels, NaN without an edge): measured from ``start`` (a move, default none), the
    outline moved there, measured again."""
    x = np.zeros(3) if start is None else np.asarray(start, np.float64).copy()
    cov, width = np.diag([np.inf] * 3), np.nan
    bias = edge_bias_px(P0, R, K)
    for _ in range(iterations):
        normals, off, wid = edge_offsets(rim._moved(P0, R, K, x), R, K, grad,
                                         window_px=window_px)
        dx, found = fit_offsets(normals, off - bias)
        if not np.all(np.isfinite(found)) and np.all(np.isfinite(cov)):
            break             # no edge this time: keep the last measurement
        cov = found
        width = float(np.nanmedian(wid)) if np.isfinite(wid).any() else np.nan
        x = np.clip(x + dx, -_REACH, _REACH)   # within the rim search's reach (READ_PX)
        if np.abs(dx).max() < 0.05:
            break
    return x, cov + np.diag(_BIAS_SD ** 2), width


def _tail(u: float, knee: float, soft: float) -> float:
    """1 up to ``knee``, then ``exp(-(u - knee)^2 / (2 soft^2))``."""
    return float(np.exp(-0.5 * (max(u - knee, 0.0) / soft) ** 2))


def edge_share(x_n, S_n, width: float, x_r) -> float:
    """How much the mask's outline lies on the silhouette, p in [0, 1]: the edges nearest
    it (``x_n`` (3,) px, ``S_n`` (3, 3) px^2, :func:`photo_move` from the mask's outline)
    agree on its size within ``CONFIRM_SD`` sd, their scatter is within ``TIGHT_WIDTHS``
    of the edge's ``width`` (px), and the rim's strongest edge ``x_r`` (3,) px is at most
    ``OUTER_PX`` outside them; each test a smooth tail beyond its knee."""
    if not np.all(np.isfinite(S_n)):
        return 0.0                                 # no edge near the mask
    scatter = np.sqrt(max(S_n[2, 2] - EDGE_BIAS_SD_PX ** 2, 0.0))
    width = width if np.isfinite(width) and width > 0 else 1.0
    return (_tail(abs(x_n[2]) / np.sqrt(S_n[2, 2]), CONFIRM_SD, CONFIRM_SOFT_SD)
            * _tail(scatter / width, TIGHT_WIDTHS, TIGHT_SOFT_WIDTHS)
            * _tail(x_r[2] - x_n[2], OUTER_PX, OUTER_SOFT_PX))


def _weighed(x_p, S, on_edge: bool, extra2: float):
    """The outline move (3,), its variance (3,) and the photo's weight (3,) for one
    hypothesis: the mask on the silhouette (``on_edge``) or off it; ``extra2`` (px^2) the
    mask outline's own variance beyond the edge's."""
    S_p = np.diag(S)
    if on_edge:               # the mask is off only where the photo says so beyond doubt
        s_m2 = np.maximum(x_p ** 2 - CONFIRM_SD ** 2 * S_p, 0.0)
    else:                     # off an edge: a drawn mask's slop, or what the photo saw
        s_m2 = np.maximum(x_p ** 2, rim.MASK_SIGMA_PX ** 2)
    s_m2 = s_m2 + extra2
    if not np.all(np.isfinite(S_p)):   # no edge: the mask's pose, as sure as a drawn one
        return np.zeros(3), np.maximum(s_m2, rim.MASK_SIGMA_PX ** 2 + extra2), np.zeros(3)
    w = s_m2 / (s_m2 + S_p)
    # the photo right (its variance) or the mask right (then off by what the photo saw;
    # off an edge, by at most the photo's own spread)
    seen = x_p ** 2 if on_edge else np.minimum(x_p ** 2, S_p)
    return w * x_p, w * S_p + (1 - w) * seen + extra2, w


def _jacobian(P0, R, K, x, h=0.05) -> np.ndarray:
    """d centre / d x (3, 3), metres per pixel, by central differences."""
    return np.stack([(rim._moved(P0, R, K, x + h * e) - rim._moved(P0, R, K, x - h * e))
                     / (2 * h) for e in np.eye(3)], 1)


@dataclass
class Evidence:
    """What the mask and the photo say of one totem's outline, before weighing: moves
    ``x`` (3,) pixels of the mask's outline (du, dv, g) and their covariances (3, 3)."""

    mask_center: np.ndarray  # (3,) metres, the mask's own pose
    shape_rms_px: float      # the mask outline's rms distance from the best sphere outline
    extra2: float            # the mask outline's own variance beyond a pixel mask's (px^2)
    x_near: np.ndarray       # the edge nearest the mask's outline (:func:`photo_move`)
    S_near: np.ndarray
    width: float             # that edge's median width (px)
    x_rim: np.ndarray        # the rim's strongest edge (:mod:`inverse.pose.rim`), bias off
    x_far: np.ndarray        # ... refined by the nearest peaks
    S_far: np.ndarray
    rim_center: np.ndarray   # (3,) metres, the rim's own pose (``--pose-from photo``)
    size_edge: np.ndarray | None = None  # the edge at each shared.SIZE_GRID_PX
    size_lateral: np.ndarray | None = None  # (2,) px, the sideways move it was read at


def _lateral(x_n, S_n, width, x_r, x_f) -> np.ndarray:
    """The sideways move (2,) px of the likelier edge: the nearest's where the mask's own
    share (:func:`edge_share`) is at least a half, else the rim's."""
    return (x_n if edge_share(x_n, S_n, width, x_r) >= 0.5 else x_f)[:2].copy()


def size_profile(P0, R: float, K, grad, lateral) -> np.ndarray:
    """The photo's mean step (sizes,) across the outline of ``P0`` moved sideways by
    ``lateral`` (2,) px and grown by each size of :data:`inverse.pose.shared.SIZE_GRID_PX`
    (the edge's bias taken off, so a size is the silhouette's offset)."""
    g = shared.SIZE_GRID_PX + edge_bias_px(P0, R, K)
    P = np.array([rim._moved(P0, R, K, np.array([*lateral, x])) for x in g])
    half = np.arcsin(np.clip(R / np.linalg.norm(P, axis=1), 0.0, 1.0))
    qs = np.column_stack([camera.project(K, P), K[0, 0] * np.tan(half)])
    pts, nrm = silhouette.cones_points(qs, K, rim.N_POINTS)    # every size's outline at once
    step = silhouette.edge_at(pts.reshape(-1, 2), nrm.reshape(-1, 2), *grad)
    return step.reshape(len(g), -1).mean(axis=1)


def totem_evidence(mask, R: float, K, grad, *, j: int = 0) -> Evidence:
    """:class:`Evidence` of one totem from its mask (H, W) bool and the photo's gradients
    ``grad`` (:func:`scenes.silhouette.gradients`, ``rim.SIGMA_PX``)."""
    K = np.asarray(K, np.float64)
    uv = pose.mask_outline_uv(mask, j=j)
    rays = camera.pixel_rays(K, uv[:, 0], uv[:, 1])
    P_m, shape_rms = pose.pose_conic(rays, K, R, uv=uv)
    # the mask pose's own spread: the outline's residual over its independent points
    # (a pixel outline's steps are correlated over about four)
    quant_px = max(shape_rms, 0.1) / np.sqrt(max(len(uv) / 4.0, 1.0))
    extra2 = max(shape_rms ** 2 - SHAPE_QUANT_PX ** 2, 0.0) + quant_px ** 2
    # the edge nearest the mask's outline: does the mask lie on the silhouette?
    x_n, S_n, width = photo_move(P_m, R, K, grad, iterations=NEAR_ITERATIONS)
    # the rim's strongest edge near the mask (inverse.pose.rim), its bias taken off, refined
    # by the nearest peaks
    P_r = rim.refine_centre(P_m, R, K, grad)
    x_r = move_of(P_m, P_r, R, K)
    x_r[2] -= edge_bias_px(P_m, R, K)
    x_f, S_f, _ = photo_move(P_m, R, K, grad, start=x_r, iterations=REFINE_ITERATIONS,
                             window_px=REFINE_WINDOW_PX)
    # the edge's strength along the outline's size (the likelier edge's sideways move),
    # for the photo's shared offset (:func:`inverse.pose.shared.shared_offset`)
    lateral = _lateral(x_n, S_n, width, x_r, x_f)
    size_edge = size_profile(P_m, R, K, grad, lateral)
    return Evidence(mask_center=P_m, shape_rms_px=float(shape_rms), extra2=extra2,
                    x_near=x_n, S_near=S_n, width=width, x_rim=x_r, x_far=x_f, S_far=S_f,
                    rim_center=P_r, size_edge=size_edge,
                    size_lateral=lateral)


def weigh(ev: Evidence, R: float, K, *, p: float | None = None,
          prior=None) -> CombinedPose:
    """:class:`CombinedPose` from one totem's :class:`Evidence`: the on-edge and the
    off-edge moves mixed by the mask's share ``p`` (default :func:`edge_share` of the
    evidence alone); the size then pulled to the photo's other totems' ``prior``
    (:func:`inverse.pose.shared.pooled`; default none)."""
    K = np.asarray(K, np.float64)
    P_m, extra2 = ev.mask_center, ev.extra2
    x_n, S_n, x_f, S_f = ev.x_near, ev.S_near, ev.x_far, ev.S_far
    if p is None:
        p = edge_share(x_n, S_n, ev.width, ev.x_rim)
    x1, v1, w1 = _weighed(x_n, S_n, True, extra2)
    x0, v0, w0 = _weighed(x_f, S_f, False, extra2)
    q = min(max(p, AMBIGUITY), 1.0 - AMBIGUITY)
    x = p * x1 + (1 - p) * x0
    post = p * v1 + (1 - p) * v0 + q * (1 - q) * (x1 - x0) ** 2
    w = p * w1 + (1 - p) * w0
    x_p, S = (x_n, S_n) if p >= 0.5 else (x_f, S_f)
    if prior is not None:
        x[2], post[2] = shared.pooled(x[2], post[2], S[2, 2], prior)
    J = _jacobian(P_m, R, K, x)
    C = J @ np.diag(post) @ J.T                               # centre covariance, m^2
    P = rim._moved(P_m, R, K, x)
    los = P / np.linalg.norm(P)
    along = float(np.sqrt(max(los @ C @ los, 0.0)))
    across = float(np.sqrt(max(0.5 * (np.trace(C) - los @ C @ los), 0.0)))
    return CombinedPose(center=P, sd_along=along, sd_across=across, mask_center=P_m,
                        photo_move=x_p, photo_cov=S, weight=w,
                        shape_rms_px=ev.shape_rms_px, edge_share=p)


def from_offset(e: Evidence, g: float, R: float, K, grad) -> Evidence:
    """``e`` with its rim's edge (``x_rim``, ``x_far``, ``S_far``) sought again from the
    photo's shared size offset ``g`` px (:func:`inverse.pose.shared.shared_offset`), the
    nearest peaks within ``REFINE_WINDOW_PX``, where both its own edges (nearest and
    rim's) lie on one side of ``g`` and farther than that: the band or a shadow took
    both, so the photo's offset is a hypothesis its own evidence lacks."""
    own = np.array([e.x_near[2], e.x_far[2]]) - g
    if np.abs(own).min() <= REFINE_WINDOW_PX or own.min() < 0 < own.max():
        return e                # its own edges lie there already, or on both sides
    start = np.array([*e.size_lateral, g])
    x, S, _ = photo_move(e.mask_center, R, K, grad, start=start,
                         iterations=REFINE_ITERATIONS, window_px=REFINE_WINDOW_PX)
    if not np.all(np.isfinite(S)):
        return e
    return replace(e, x_rim=np.array([*e.x_rim[:2], g]), x_far=x, S_far=S)


def weigh_photo(evidence, R, K, grad=None) -> list:
    """Every totem's :class:`CombinedPose` (None where its evidence is None) from one
    photo's :class:`Evidence` list, ``R`` (n,) metres: with the photo's gradients
    ``grad``, each clean mask's rim sought again from the photo's shared size offset
    (:func:`from_offset`); each share weighed with the photo's others
    (:func:`inverse.pose.shared.shared_shares`), then each clean mask's size pulled to
    the others' where its edge lies far from theirs, or weighed with theirs where they
    confirm the masks exact (:func:`inverse.pose.shared.shared_sizes`)."""
    g = None if grad is None else shared.shared_offset(evidence, REFINE_WINDOW_PX)
    if g is not None:
        evidence = [from_offset(e, g, R[j], K, grad) if shared.clean(e) else e
                    for j, e in enumerate(evidence)]
    own = [None if e is None else edge_share(e.x_near, e.S_near, e.width, e.x_rim)
           for e in evidence]
    p = shared_shares(evidence, own)
    first = [None if e is None else weigh(e, R[j], K, p=p[j])
             for j, e in enumerate(evidence)]
    sizes = [np.nan if c is None else move_of(c.mask_center, c.center, R[j], K)[2]
             for j, c in enumerate(first)]
    priors = shared.shared_sizes(evidence, sizes, own)
    return [c if c is None or prior is None else weigh(e, R[j], K, p=p[j], prior=prior)
            for j, (e, c, prior) in enumerate(zip(evidence, first, priors))]


def combine_centre(mask, R: float, K, grad, *, j: int = 0) -> CombinedPose:
    """:class:`CombinedPose` of one totem alone from its mask (H, W) bool and the photo's
    gradients ``grad`` (:func:`scenes.silhouette.gradients`, ``rim.SIGMA_PX``)."""
    return weigh(totem_evidence(mask, R, K, grad, j=j), R, K)


def combined_poses(image, masks, K, radius) -> list[CombinedPose]:
    """Every totem's :class:`CombinedPose`, weighed with the photo's others
    (:func:`weigh_photo`): ``image`` (H, W, 3) sRGB [0, 1], ``masks``
    (n, H, W) bool, ``K`` (3, 3), ``radius`` (n,) or one, metres. BadInput for an
    unusable mask or key (:func:`inverse.pose.pose.initial_pose` checks them first)."""
    masks = np.asarray(masks, bool)
    if masks.ndim == 2:
        masks = masks[None]
    R = np.broadcast_to(np.asarray(radius, np.float64), (len(masks),))
    pose.initial_pose(masks, K, R)                  # the masks' and key's checks
    grad = silhouette.gradients(np.ascontiguousarray(np.asarray(image, np.float32)),
                                rim.SIGMA_PX)
    ev = [totem_evidence(m, float(r), K, grad, j=j) for j, (m, r) in
          enumerate(zip(masks, R))]
    return weigh_photo(ev, R, K, grad)


POSE_FROM = ("both", "photo", "mask")
"""``both``: the mask and the photo weighed (the default); ``photo``: the rim's strongest
edge near each mask (:mod:`inverse.pose.rim`); ``mask``: the mask's outline alone."""


def uncertainty_record(c: CombinedPose) -> dict:
    """fit.json's ``pose_uncertainty`` entry of one totem: 1 sd along the line of sight
    and across it in millimetres, and the share of the outline's size taken from the
    mask (1: the mask's, 0: the photo's)."""
    return {"along_mm": round(1e3 * c.sd_along, 2),
            "across_mm": round(1e3 * c.sd_across, 2),
            "mask_share": round(float(1.0 - c.weight[2]), 3)}


def initial_centres(image, masks, K, radius, pose_from: str = "both"):
    """The fit's initial centres (n, 3) metres from the masks and the photo, and each
    one's :func:`uncertainty_record` (None unless ``pose_from`` is "both", the default;
    "photo" and "mask" are overrides, :data:`POSE_FROM`). BadInput for another value or
    unusable masks."""
    from scenes.errors import BadInput

    if pose_from not in POSE_FROM:
        raise BadInput(f"pose_from must be one of {', '.join(POSE_FROM)}, "
                       f"got {pose_from!r}")
    if pose_from == "both":
        poses = combined_poses(image, masks, K, radius)
        return np.stack([c.center for c in poses]), [uncertainty_record(c) for c in poses]
    centers = pose.initial_pose(masks, K, radius)
    if pose_from == "photo":
        centers = rim.refine_centres(image, centers, radius, K)
    return centers, None
