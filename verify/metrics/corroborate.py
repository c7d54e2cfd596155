"""Corroboration: at some depth along a pixel's camera ray, do two totems see its colour?

L1, SSIM and CHROMA judge the photo against *one* camera view rebuilt from the totems,
so every error of that view's geometry (an object put at the wrong depth, or missed)
reads as an edit, and the threshold has to sit above it. This test asks each pixel a
weaker question that needs no chosen geometry: is there a depth ``z`` along its camera
ray at which at least ``min_totems`` totems' rays, crossing that depth there, carry the
photo's hue? An authentic pixel has one, its surface's depth, whatever the fit chose;
a colour pasted where the totems saw none has none.

Per camera cell ``c`` (``CELL_PX`` square, over the fit's frustum) and depth slice ``k``
(even in inverse depth), :func:`inverse.view.sweep.slice_colours` gives each totem's mean
colour ``mu_jk(c)`` where it has rays. With ``chroma`` the colour minus its grey level
(:func:`verify.metrics.patches.chroma`: the totems' brightness is off by Fresnel and
reflection)
and ``I(c)`` the photo blurred to the rays' footprint::

    e_jk(c) = mean over channels |chroma(I(c)) - chroma(mu_jk(c))|
    E(c)    = min over k of the ``min_totems``-th smallest e_jk(c) over the totems j
              that land in c at slice k, or, where one totem alone lands there,
              its own e_jk(c)

A point only one totem's rays reach is that totem's to explain: no other viewpoint
says anything of it, and an object near the totems is often seen by one of them alone,
near its rim (see docs/decisions.md, 'corroborate: one totem explains a point it alone
reaches'). Where two land, two must agree. ``E`` is NaN where no slice has a totem
landing: those pixels cannot be corroborated, and they take no part in the patch
scores.

Limits: a forger who paints a hue that the totems see somewhere along the pixel's ray
(the floor's colour over a removed object, a sky-coloured splice under a sky the glass
reflects) is not caught by this test; nor at the farthest slices, where every totem
looks along the pixel's own direction, a hue they see that way from where they stand.
Brightness alone is not judged here (RANGE does). Every depth along the ray counts, behind the
stereo surface too, since that surface is wrong where the sweep fails (see
docs/decisions.md, 'corroborate: every depth along the ray').

Two ways the totems can explain a pixel's hue: the view rebuilt from them shows it
nearby (CHROMA, :func:`verify.metrics.patches.chroma_distance`), or two of them see it at
one depth along the pixel's ray (CORROB, here). An authentic pixel needs one of them, so
:func:`unseen` takes the smaller distance: a pixel is suspicious only where neither
explains it (see docs/decisions.md, 'corroborate: UNSEEN, the smaller of CHROMA and
CORROB').

Public
------
``corroboration(o, d, radiance, totem, cos_in, frame, image, ...) -> (H, W)``
``unseen(chroma_distance, corroboration) -> (H, W)``
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from inverse.grid import FrustumFrame, cell_centres, cells_to_pixels
from inverse.rays import TotemRays
from inverse.view.sweep import slice_colours
from scenes.colour import linear_to_srgb
from scenes.reach import COS_EVIDENCE
from verify.metrics.patches import chroma
from verify.metrics.resolution import blur_varying

__all__ = ["CELL_PX", "N_SLICES", "SIGMA_CELLS", "COS_EVIDENCE", "MIN_TOTEMS",
           "map_res", "cell_centres", "cell_errors", "corroboration", "ray_slices", "unseen"]

CELL_PX = 5.2
"""Side (pixels) of the map's cells over the fit's frustum: the fit's stereo maps have
this size at 640 x 480 (160 columns over the 832 px the frame spans). The cells keep
their size in pixels at every image size, so each holds about as many totem rays (the
totem pixels scale with the image too)."""

N_SLICES = 64
"""Depth slices, even in inverse depth from the frame's near to its far plane."""

SIGMA_CELLS = 1.5
"""Gaussian spread (cells) of each ray's splat; the photo is blurred to match."""

MIN_TOTEMS = 2
"""How many totems must see the photo's hue at one depth: one can match by chance along
its whole ray; two are stereo."""


def map_res(frame: FrustumFrame, cell_px: float = CELL_PX) -> tuple[int, int]:
    """(nt, ns) cells of about ``cell_px`` pixels over the frame's range."""
    return (max(2, round((frame.v_range[1] - frame.v_range[0]) / cell_px)),
            max(2, round((frame.u_range[1] - frame.u_range[0]) / cell_px)))


def _sample(image_c, uu, vv):
    """Bilinear samples (nt, ns, C) of an (H, W, C) map at pixel coordinates."""
    return np.stack([ndimage.map_coordinates(image_c[..., c], [vv, uu], order=1,
                                             mode="nearest")
                     for c in range(image_c.shape[2])], axis=-1)


def cell_errors(mu, land, photo_chroma, *, min_totems: int = MIN_TOTEMS,
                alone: bool = True, hue: bool = True) -> np.ndarray:
    """``E`` per cell from the slice colours (see the module docstring).

    Parameters
    ----------
    mu : (n_tot, n_slices, nt, ns, 3) totems' sRGB colours per slice and cell.
    land : (n_tot, n_slices, nt, ns) bool, where each totem has rays.
    photo_chroma : (nt, ns, 3) the photo's chroma at the cells (with ``hue`` False,
        its sRGB values).
    min_totems : totems that must agree where several land.
    alone : a slice point one totem alone lands at is explained by it.
    hue : compare chroma (the colour less its grey level); False: the values.

    Returns
    -------
    (nt, ns) float64, sRGB units, NaN where no slice can explain the cell.
    """
    mu = np.asarray(mu, np.float32)                # (totems, slices, cells): float32
    land = np.asarray(land, bool)
    if hue:
        mu = mu - mu.mean(axis=-1, keepdims=True)
    e = np.abs(mu - np.asarray(photo_chroma, np.float32)[None, None]).mean(axis=-1)
    e = np.where(land, e, np.inf)
    best = np.partition(e, min_totems - 1, axis=0)[min_totems - 1]   # (slices, cells)
    if alone:
        best = np.minimum(best, np.where(land.sum(axis=0) == 1, e.min(axis=0), np.inf))
    best = best.min(axis=0).astype(np.float64)                         # (nt, ns)
    return np.where(np.isfinite(best), best, np.nan)


def corroboration(rays: TotemRays, frame: FrustumFrame, image, *,
                  cell_px: float = CELL_PX, n_slices: int = N_SLICES,
                  sigma: float = SIGMA_CELLS, cos_evidence: float = COS_EVIDENCE,
                  min_totems: int = MIN_TOTEMS, photo_sigma=None,
                  slices=None, hue: bool = True, gain=None) -> np.ndarray:
    """How far each photo pixel's hue is from what ``min_totems`` totems saw along its ray.

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`).
    frame : the fit's frustum frame: the map covers its ``(s, t)`` range and depths.
    image : (H, W, 3) the photo, sRGB [0, 1].
    cell_px, n_slices, sigma, cos_evidence, min_totems : see the module constants.
    photo_sigma : the photo's blur (pixels, a number or an (H, W) map,
        :mod:`verify.metrics.resolution`), never less than the rays' splat ``sigma *
        cell_px`` (the default).
    slices : :func:`ray_slices` of these rays with these settings, when already made
        (the evidence map reads the same).
    hue : compare hues (chroma); False: the sRGB values, brightness included, the rays'
        radiance first multiplied by ``gain``.
    gain : (3,) linear gain per channel that brings the rays to the photo's exposure
        (:mod:`verify.metrics.tone`); None: 1.

    Returns
    -------
    (H, W) float64, sRGB units >= 0; NaN where it cannot be told.
    """
    image = np.asarray(image, np.float64)
    H, W = image.shape[:2]
    rays = rays.entering_at_least(cos_evidence)
    if rays.n_totems() < min_totems:
        return np.full((H, W), np.nan)
    res = map_res(frame, cell_px)
    sc = slices if slices is not None else ray_slices(
        rays, frame, cell_px=cell_px, n_slices=n_slices, sigma=sigma, gain=gain)
    splat_px = sigma * cell_px
    blurred = blur_varying(chroma(image) if hue else image,
                           splat_px if photo_sigma is None
                           else np.maximum(photo_sigma, splat_px))
    uu, vv = cell_centres(frame, res)
    E = cell_errors(sc.colour, sc.land, _sample(blurred, uu, vv), min_totems=min_totems,
                    hue=hue)
    return cells_to_pixels(E, frame, (W, H))


def ray_slices(rays: TotemRays, frame: FrustumFrame, *, cell_px: float = CELL_PX,
               n_slices: int = N_SLICES, sigma: float = SIGMA_CELLS,
               cos_evidence: float = COS_EVIDENCE, gain=None):
    """Each totem's mean sRGB colour per depth slice and cell of the map
    (:func:`inverse.view.sweep.slice_colours`), from its rays entering at an incidence
    cosine of at least ``cos_evidence``, their radiance times ``gain`` (3,) when given."""
    rays = rays.entering_at_least(cos_evidence)
    radiance = rays.radiance if gain is None else rays.radiance * np.asarray(gain, float)
    colour = linear_to_srgb(np.clip(radiance, 0.0, 1.0))
    return slice_colours(rays.o, rays.d, colour, rays.totem, frame,
                         map_res(frame, cell_px), n_slices=n_slices, sigma=sigma)


def unseen(chroma_distance, corroboration) -> np.ndarray:
    """The smaller of the two explanations' distances, per pixel (sRGB units).

    ``chroma_distance`` (H, W) from the rebuilt view
    (:func:`verify.metrics.patches.chroma_distance`), ``corroboration`` (H, W) from the
    totem rays (:func:`corroboration`); where the latter is NaN (too few totems) the former
    alone.
    """
    return np.fmin(np.asarray(chroma_distance, np.float64),
                   np.asarray(corroboration, np.float64))
