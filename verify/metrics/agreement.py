"""The totems checked against each other: each totem's view predicted from the others'.

Every totem sees the scene again from where it stands; where two other totems agree on
what lies along one of its rays, that ray must see it too. A forger who retouches one
totem (a patch cloned, blurred or recoloured), or paints something into each totem where
no key tells them it belongs, makes a totem whose view the others contradict there.

Per ray (:func:`ray_discord`): the ray's line is cut by the depth slices of
:func:`inverse.view.sweep.slice_colours` (over :mod:`verify.metrics.corroborate`'s map),
and at each slice point the totem's own mean colour there is compared with the mean of
the *other* totems that land there, where at least ``MIN_OTHERS`` of them do and agree
(their spread at most ``OTHERS_AGREE``). The ray's discord is the smallest, over those
depths, of the hue difference (the colour less its grey level, as CORROB's) divided by
the others' spread plus ``FLOOR``: a ray is in discord only when at *no* depth along it
do agreeing others see its hue. No depth is taken from the fit, whose view the totem
under test shaped too. Hue, not brightness: each totem's Fresnel loss and reflected
ambient, and the light's highlights on the glass, move brightness between totems, and
brightness discord of untouched totems rose as high as that of edits (see
docs/decisions/verify-metrics.md, 'agreement: each totem predicted from the others').

Which rays are evidence: those that entered the glass at an incidence cosine of at least
``COS_AGREEMENT`` (near the rim the glass blurs and mixes in reflection) and whose pixel
is not a highlight (every channel at least ``HIGHLIGHT``, grown by ``HIGHLIGHT_GROW_PX``:
the reflection of a light on the glass, which no other totem sees there). A totem's
pixel is put back on its ray by :func:`ray_pixels` (the sphere traced backwards).

Per totem (:func:`disc_contrast`): the rays' discord drawn at their pixels, averaged by a
Gaussian of ``SIGMA_DISC`` of the disc's radius (a region a quarter to half the disc
across, as a hand retouch is), less the average over ``SURROUND_DISC`` of it (a totem
whose whole view disagrees, one that alone sees an object close to it, is told by its
region standing out of its own surround); where rays are missing the Gaussian counts them
as agreeing, up to ``COVER`` of the disc (a thin band of discord at the edge of what the
others predict weighs as the band it is). A totem's ``score`` is its worst region's
contrast, and its ``lead`` how far that stands above the other totems' (their median,
so that two totems retouched alike do not hide each other): a photo whose totems all
disagree somewhere leads with none. The verdict names a totem whose lead
is over :data:`verify.verdict.verdict.TOTEM_LEAD`.

Limits (measured on the development set, docs/decisions/verify-metrics.md): a retouch that
keeps the hue (a blur, a clone of like texture, a grey or white paste) is not seen; nor is
one where fewer than two other totems see the same scene (a totem's view of what lies
below or beside the camera's frame, the far backdrop outside the frustum); with two
totems there is never a second other, so nothing is judged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from inverse.grid import FrustumFrame
from inverse.rays import TotemRays
from inverse.view.sweep import SliceColours, pixel_lines, slice_colours
from scenes import camera
from scenes.colour import linear_to_srgb
from scenes.refraction import entry_points
from verify.metrics.corroborate import N_SLICES, SIGMA_CELLS, map_res

__all__ = ["COS_AGREEMENT", "HIGHLIGHT", "HIGHLIGHT_GROW_PX", "MIN_OTHERS", "OTHERS_AGREE",
           "FLOOR", "DISCORD_CAP", "SIGMA_DISC", "SURROUND_DISC", "COVER", "Along",
           "Agreement", "ray_pixels", "highlights", "others_along", "ray_discord",
           "disc_contrast", "leads", "totem_agreement"]

COS_AGREEMENT = 0.5
"""Rays that entered their sphere at an incidence cosine below this are not evidence
(the stereo's own rule, :data:`inverse.view.view.COS_SWEEP`)."""

HIGHLIGHT = 0.7
"""A totem pixel all of whose channels are at least this (sRGB) is a highlight."""

HIGHLIGHT_GROW_PX = 2
"""Highlights are grown by this many pixels (their halo)."""

MIN_OTHERS = 2
"""Other totems that must land at a slice point and agree there to predict a ray."""

OTHERS_AGREE = 0.05
"""Largest spread (sRGB, rms over the landing others and the channels) at which the
other totems at a point are taken to see one surface."""

FLOOR = 0.03
"""Added to the others' spread (sRGB): two agreeing totems' spread is itself noisy."""

DISCORD_CAP = 5.0
"""A ray's discord counts at most this much in a region's average."""

SIGMA_DISC = 0.15
"""The region's Gaussian, in units of the disc's radius (the radius of a circle of the
mask's area)."""

SURROUND_DISC = 0.8
"""The surround's Gaussian, in units of the disc's radius."""

COVER = 0.8
"""A region's average divides by at least this share of the Gaussian's weight on the
disc: missing rays count as agreeing beyond it."""


@dataclass
class Along:
    """What each ray meets at each depth slice (:func:`others_along`): ``own`` (m, k, 3)
    its totem's mean sRGB colour at the slice point (NaN where it does not land there),
    ``mean`` (m, k, 3) the other totems' mean colour, ``spread`` (m, k) their rms spread
    (sRGB, over them and the channels), ``count`` (m, k) how many of them land."""

    own: np.ndarray
    mean: np.ndarray
    spread: np.ndarray
    count: np.ndarray


@dataclass
class Agreement:
    """The totems checked against each other (see the module docstring).

    Attributes
    ----------
    score : (n,) each totem's worst region's contrast (discord units: hue difference
        over the others' spread), NaN where no region of it is predicted.
    lead : (n,) ``score`` less the median of the other totems' scores (:func:`leads`;
        NaN where either is unknown, or with fewer than two scored totems).
    centre : (n, 2) the worst region's centre, pixel (u, v) of the photo (NaN where none).
    radius : (n,) the region's radius in pixels (twice its Gaussian's sigma).
    judged : (n,) the share of each totem's mask whose pixel has a prediction.
    contrast : (H, W) each totem's contrast map over its disc (NaN elsewhere), for the
        pictures.
    """

    score: np.ndarray
    lead: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    judged: np.ndarray
    contrast: np.ndarray


def ray_pixels(rays: TotemRays, centers, radius, ior, K) -> np.ndarray:
    """Each ray's totem pixel, (m, 2) image coordinates (u, v) (OpenCV centres).

    The ray leaving the glass at ``rays.o`` along ``rays.d`` is traced back through its
    sphere (:func:`scenes.refraction.entry_points`) to where the camera ray entered it,
    which projects through ``K`` to the pixel. ``centers`` (n, 3) the fitted centres,
    camera frame, metres; ``radius`` (n,) metres and ``ior`` (n,), the key's.
    """
    n = len(np.asarray(centers).reshape(-1, 3))
    R = np.broadcast_to(np.asarray(radius, np.float64), (n,))[rays.totem]
    eta = np.broadcast_to(np.asarray(ior, np.float64), (n,))[rays.totem]
    P = np.asarray(centers, np.float64).reshape(n, 3)[rays.totem]
    return camera.project(K, entry_points(rays.o, rays.d, P, R, eta))


def highlights(image, masks, *, level: float = HIGHLIGHT,
               grow: int = HIGHLIGHT_GROW_PX) -> np.ndarray:
    """(H, W) bool: totem pixels (``masks`` (n, H, W)) of the sRGB ``image`` (H, W, 3)
    whose every channel is at least ``level``, grown by ``grow`` pixels."""
    bright = np.asarray(image).min(axis=-1) >= level
    if grow > 0 and bright.any():
        bright = ndimage.binary_dilation(bright, iterations=grow)
    return bright & np.asarray(masks, bool).any(axis=0)


def others_along(rays: TotemRays, slices: SliceColours, frame: FrustumFrame) -> Along:
    """What each ray meets at each slice of ``slices`` (over ``frame``'s map; made of
    these rays): its own totem's colour there and the other totems' (:class:`Along`).

    Each ray's line (not only its part beyond the glass's surface: the slices are the
    totems' lines too) is cut with each depth plane ``z_k`` in front of its exit point;
    the point's map cell is the one its pixel falls in.
    """
    n_tot, nk, nt, ns = slices.land.shape
    m = len(rays)
    au, bu, av, bv, dz = pixel_lines(rays.o, rays.d, frame.K)
    own = np.full((m, nk, 3), np.nan, np.float32)
    mean = np.full((m, nk, 3), np.nan, np.float32)
    spread = np.full((m, nk), np.nan, np.float32)
    count = np.zeros((m, nk), np.int16)
    idx = np.arange(m)
    mine = rays.totem                        # the slices were made of these rays
    for k, z in enumerate(np.asarray(slices.z, np.float64)):
        s, t = frame.pixel_to_st(au + bu / z, av + bv / z)
        col, row = np.floor(s * ns).astype(np.int64), np.floor(t * nt).astype(np.int64)
        ok = ((z - rays.o[:, 2]) / dz > 0) & (col >= 0) & (col < ns) & (row >= 0) \
            & (row < nt)
        col, row = np.clip(col, 0, ns - 1), np.clip(row, 0, nt - 1)
        mu = slices.colour[:, k, row, col]                     # (n_tot, m, 3)
        land = slices.land[:, k, row, col] & ok[None]
        self_ = land[mine, idx]
        own[self_, k] = mu[mine[self_], idx[self_]]
        land[mine, idx] = False
        n = land.sum(axis=0)
        w = land[..., None]
        mu_w = np.where(w, mu, 0.0)
        avg = mu_w.sum(axis=0) / np.maximum(n, 1)[:, None]
        var = (np.where(w, mu - avg[None], 0.0) ** 2).sum(axis=(0, 2)) \
            / (3.0 * np.maximum(n, 1))
        has = n > 0
        mean[has, k] = avg[has]
        spread[has, k] = np.sqrt(var[has])
        count[:, k] = n
    return Along(own, mean, spread, count)


def ray_discord(along: Along, *, min_others: int = MIN_OTHERS, agree: float = OTHERS_AGREE,
                floor: float = FLOOR) -> np.ndarray:
    """Each ray's discord with the other totems, (m,) (see the module docstring): the
    least, over the slice points where at least ``min_others`` others land and agree
    (spread <= ``agree``) and its own totem lands, of the rms hue difference between its
    totem's colour and theirs over ``spread + floor``. NaN where no slice point
    qualifies."""
    own = along.own - along.own.mean(axis=-1, keepdims=True)          # hue: less grey
    others = along.mean - along.mean.mean(axis=-1, keepdims=True)
    diff = np.sqrt(np.mean((own - others) ** 2, axis=-1))              # (m, k), NaN
    # where either is missing
    usable = (along.count >= min_others) & (along.spread <= agree) & np.isfinite(diff)
    z = np.where(usable, diff / (np.nan_to_num(along.spread, nan=np.inf) + floor),
                 np.inf)
    best = z.min(axis=1) if z.shape[1] else np.full(len(z), np.inf)
    return np.where(np.isfinite(best), best, np.nan).astype(np.float64)


def disc_contrast(values, uv, mask, *, sigma_frac: float = SIGMA_DISC,
                  surround_frac: float = SURROUND_DISC, cover: float = COVER,
                  cap: float = DISCORD_CAP):
    """One totem's regions: the contrast of each region's mean discord with its surround.

    Parameters
    ----------
    values : (k,) the totem's rays' discord (NaN: no prediction).
    uv : (k, 2) their pixels (u, v) in the photo.
    mask : (H, W) bool, the totem's pixels.

    Returns
    -------
    contrast : (H, W) float64, NaN off the disc and where too few rays lie to judge (the
        region's rays weigh less than half a ``cover`` of its Gaussian on the disc).
    sigma : the region's Gaussian, pixels.
    judged : the share of the mask's pixels holding a ray with a value.
    """
    mask = np.asarray(mask, bool)
    H, W = mask.shape
    contrast = np.full((H, W), np.nan)
    r_disc = float(np.sqrt(mask.sum() / np.pi))
    sigma = max(1.0, sigma_frac * r_disc)
    ok = np.isfinite(values)
    ui = np.clip(np.round(uv[:, 0]).astype(np.int64), 0, W - 1)
    vi = np.clip(np.round(uv[:, 1]).astype(np.int64), 0, H - 1)
    ok &= mask[vi, ui]
    if not ok.any():
        return contrast, sigma, 0.0
    rows, cols = np.nonzero(mask)
    pad = int(np.ceil(3 * max(sigma, surround_frac * r_disc)))
    y0, y1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, H)
    x0, x1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, W)
    val = np.zeros((y1 - y0, x1 - x0))
    wt = np.zeros_like(val)
    np.add.at(val, (vi[ok] - y0, ui[ok] - x0), np.minimum(values[ok], cap))
    np.add.at(wt, (vi[ok] - y0, ui[ok] - x0), 1.0)
    disc = mask[y0:y1, x0:x1].astype(np.float64)
    g = {name: ndimage.gaussian_filter(a, sigma, mode="constant")
         for name, a in (("val", val), ("wt", wt), ("disc", disc))}
    region = g["val"] / np.maximum(np.maximum(g["wt"], cover * g["disc"]), 1e-12)
    s2 = max(sigma, surround_frac * r_disc)
    sv = ndimage.gaussian_filter(val, s2, mode="constant")
    sw = ndimage.gaussian_filter(wt, s2, mode="constant")
    surround = sv / np.maximum(sw, 1e-12)
    keep = disc.astype(bool) & (g["disc"] > 0.5) & (g["wt"] >= 0.5 * cover * g["disc"]) \
        & (sw > 1e-9)
    contrast[y0:y1, x0:x1] = np.where(keep, region - surround, np.nan)
    judged = float(np.count_nonzero(wt > 0) / max(mask.sum(), 1))
    return contrast, sigma, judged


def totem_agreement(rays: TotemRays, centers, radius, ior, K, frame: FrustumFrame, image,
                    masks, *, cos_min: float = COS_AGREEMENT) -> Agreement:
    """Each totem's view checked against the other totems' (see the module docstring).

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`).
    centers : (n, 3) the fitted centres, camera frame, metres; ``radius``, ``ior`` the
        key's, one per totem (or one for all).
    K : (3, 3) the photo's intrinsics; ``frame`` the fit's frustum frame.
    image : (H, W, 3) the photo, sRGB [0, 1]; ``masks`` (n, H, W) bool, the totems.
    cos_min : rays entering below this incidence cosine are not evidence.
    """
    masks = np.asarray(masks, bool)
    n, H, W = masks.shape
    nan = np.full(n, np.nan)
    empty = Agreement(nan.copy(), nan.copy(), np.full((n, 2), np.nan), nan.copy(),
                      np.zeros(n), np.full((H, W), np.nan))
    rays = rays.entering_at_least(cos_min)
    if len(rays) == 0 or rays.n_totems() < MIN_OTHERS + 1:
        return empty
    uv = ray_pixels(rays, centers, radius, ior, K)
    ui = np.clip(np.round(uv[:, 0]).astype(np.int64), 0, W - 1)
    vi = np.clip(np.round(uv[:, 1]).astype(np.int64), 0, H - 1)
    keep = ~highlights(image, masks)[vi, ui]
    rays, uv = rays.select(keep), uv[keep]
    if rays.n_totems() < MIN_OTHERS + 1:
        return empty
    colour = linear_to_srgb(np.clip(rays.radiance, 0.0, 1.0))
    slices = slice_colours(rays.o, rays.d, colour, rays.totem, frame, map_res(frame),
                           n_slices=N_SLICES, sigma=SIGMA_CELLS)
    discord = ray_discord(others_along(rays, slices, frame))
    out = empty
    for j in range(n):
        sel = rays.totem == j
        c, sigma, judged = disc_contrast(discord[sel], uv[sel], masks[j])
        out.judged[j] = judged
        out.radius[j] = 2.0 * sigma
        if np.isfinite(c).any():
            a, b = np.unravel_index(np.nanargmax(c), c.shape)
            out.score[j] = float(c[a, b])
            out.centre[j] = (float(b), float(a))
            out.contrast[masks[j]] = c[masks[j]]
    out.lead[:] = leads(out.score)
    return out


def leads(score) -> np.ndarray:
    """Each totem's ``score`` (n,) less the median of the other totems' scores (NaN
    where its own or all others' are NaN): how far its worst region stands above the
    rest. The median, not the largest, so that two totems retouched alike do not hide
    each other."""
    score = np.asarray(score, np.float64)
    out = np.full(score.shape, np.nan)
    for j in np.nonzero(np.isfinite(score))[0]:
        others = np.delete(score, j)
        others = others[np.isfinite(others)]
        if others.size:
            out[j] = score[j] - np.median(others)
    return out
