"""The evidence map: what the totems establish at each pixel of the photo.

The verdict may only judge a pixel where the totems' rays support it. A pixel's camera
ray is cut by depth slices (even in inverse depth, :func:`inverse.view.sweep.slice_colours`
over the cells of :mod:`verify.metrics.corroborate`'s map); at each slice point the rays of
each totem that pass there carry a colour. The totems establish the pixel's surface
where, at some depth along its ray:

- at least ``MIN_TOTEMS`` totems' rays pass (one sees any colour it likes),
- two of them see the point from far enough apart that its depth is fixed: their
  *parallax*, the angle at the point between the totems' centres divided by their
  rays' angular spacing (:func:`scenes.reach.angular_spacing`), is at least
  ``MIN_PARALLAX`` (triangulated from two totems, a depth is known to about
  ``1 / parallax`` of itself; the rule is :mod:`scenes.reach`'s, which also gives the
  truth's reach of a synthetic scene),
- and they agree on what they see there (the spread of their sRGB colours at most
  ``AGREE``): they saw one surface.

Per pixel: ``n_totems`` the most totems meeting these at one depth, ``parallax`` the
largest parallax among them, ``resolved`` whether any depth meets them. Only the totem
pixels enter, so no edit outside the totems changes the map. A backdrop far away (the
sky, the horizon) is seen by every totem along one direction, with no parallax, and is
not resolved; nor is a surface the totems see in different places (a painting hidden
from them behind an object). Limits: each totem's colour at a slice point is the mean
of its rays there, so in front of a finely textured surface, or anywhere before a
surface of one colour, the totems can agree on a blur they did not see at one point;
the map then says more is established than is. So can totems that all see the dark: a
window the resting totems cannot see is judged where they agree on the dark room (see
docs/decisions.md, 'evidence: agreement counted only where the totems see texture').
Any one of 64 depths may agree: two totems that see unrelated smooth colours agree
somewhere on about a fifth of the photo's cells (``tests/test_evidence.py``). UNSEEN
judges the resolved pixels, RANGE those resolved to twice the parallax
(:mod:`verify.verdict.verdict`); ABSENT judges the slice points
whose landing totems resolve depth (:func:`verify.metrics.absence.absence`,
``min_parallax``).

Where it is resolved the map also holds the depth the totems establish there, with its
interval (:func:`inverse.view.depth.established_depth` on the same slices; with resting
totems' support plane as a prior when one is given). The fit's own depth was not used
for the map: its grid often puts a near floor at the far plane
(a far backdrop explains each ray on its own), and the map built on it judged a fifth
of the photo (see docs/decisions.md, 'evidence: the totems' agreement, not the fit's
depth').
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inverse.grid import FrustumFrame, cells_to_pixels
from inverse.rays import TotemRays
from inverse.view.depth import established_depth, plane_slice
from inverse.view.support import SupportPlane
from scenes.camera import pixel_rays
from scenes.reach import (COS_EVIDENCE, MIN_PARALLAX, MIN_TOTEMS, angular_spacing,
                          pair_parallax)
from verify.metrics.corroborate import cell_centres, ray_slices

__all__ = ["MIN_TOTEMS", "MIN_PARALLAX", "AGREE", "COS_EVIDENCE", "Evidence",
           "angular_spacing", "pair_parallax", "slice_parallax", "evidence_map",
           "support_plane"]

AGREE = 0.03
"""Largest spread (sRGB, root mean square over the landing totems and the channels) at
which the totems at a point are taken to see one surface there: 0.02 and 0.05 each
separated the development set's edits less (see docs/decisions.md)."""

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
    depth, depth_lo, depth_hi : (H, W) float, the depth the totems establish
        (camera-frame ``z``, metres) and its interval, NaN where not resolved; where the
        support plane was chosen, the plane's own depth at the pixel (None: not made).
    """

    n_totems: np.ndarray
    parallax: np.ndarray
    resolved: np.ndarray
    spacing: np.ndarray
    depth: np.ndarray | None = None
    depth_lo: np.ndarray | None = None
    depth_hi: np.ndarray | None = None


def slice_parallax(sc, frame, centers: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(nk, nt, ns) the largest parallax (:func:`pair_parallax`) between two totems
    landing at each slice point of ``sc`` (:class:`inverse.view.sweep.SliceColours`) over
    ``frame``'s cells."""
    nk, nt, ns = sc.land.shape[1:]
    uu, vv = cell_centres(frame, (nt, ns))
    r = pixel_rays(frame.K, uu.ravel(), vv.ravel())
    r = r / r[:, 2:3]
    n = len(centers)
    out = np.zeros((nk, nt, ns))
    for k, z in enumerate(np.asarray(sc.z, np.float64)):
        seen = np.zeros((n, nt * ns), bool)
        m = min(n, len(sc.land))
        seen[:m] = sc.land[:m, k].reshape(m, -1)
        if seen.sum(axis=0).max() >= 2:
            out[k] = pair_parallax(r * z, centers, spacing, seen).reshape(nt, ns)
    return out


def evidence_map(rays: TotemRays, centers: np.ndarray, frame: FrustumFrame, size, *,
                 min_totems: int = MIN_TOTEMS, min_parallax: float = MIN_PARALLAX,
                 agree: float = AGREE, cos_evidence: float = COS_EVIDENCE,
                 slices=None, plane=None) -> Evidence:
    """The evidence map of a photo from its totem rays (see the module docstring).

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`).
    centers : (n, 3) fitted totem centres, camera frame, metres.
    frame : the fit's frustum frame: the map covers its cells and depths.
    size : (W, H) of the photo in pixels.
    min_totems, min_parallax, agree, cos_evidence : see the module constants.
    slices : :func:`verify.metrics.corroborate.ray_slices` of these rays, when already made
        (CORROB reads the same).
    plane : the support plane resting totems touch
        (:class:`inverse.view.support.SupportPlane`), a prior for the depth; None: none.
    """
    centers = np.asarray(centers, np.float64)
    rays = rays.entering_at_least(cos_evidence)
    spacing = angular_spacing(rays.d, rays.totem, len(centers))
    sc = slices if slices is not None else ray_slices(rays, frame,
                                                      cos_evidence=cos_evidence)
    par = slice_parallax(sc, frame, centers, spacing)
    n_land, _, var = sc.consistency              # var: summed over the 3 channels
    ok = (n_land >= min_totems) & (par >= min_parallax) & (var <= 3.0 * agree ** 2)
    n_cell = np.where(ok, n_land, 0).max(axis=0).astype(np.float64)
    p_cell = np.where(ok, par, 0.0).max(axis=0)
    W, H = size
    n_totems = np.rint(cells_to_pixels(n_cell, frame, (W, H), nearest=True))
    parallax = cells_to_pixels(p_cell, frame, (W, H), nearest=True)
    resolved = (n_totems >= min_totems) & (parallax >= min_parallax)
    depth = _depth(sc, par, var, frame, (W, H), resolved, min_parallax, agree, plane)
    return Evidence(n_totems.astype(np.int64), parallax, resolved, spacing, *depth)


def support_plane(geometry: dict | None) -> SupportPlane | None:
    """The support plane a fit took its resting totems to touch (``fit.json``
    ``geometry.support``: ``totems fit --resting``), or None."""
    sp = (geometry or {}).get("support")
    return SupportPlane.from_dict(sp) if sp else None


def _depth(sc, par, var, frame, size, resolved, min_parallax, agree, plane):
    """The established depth and its interval per pixel (metres, NaN where not
    resolved), the plane's own depth where it was chosen."""
    W, H = size
    res = var.shape[1:]
    kp, _ = (None, None) if plane is None else plane_slice(plane, frame, res, sc.z)
    est = established_depth(var, sc.consistency[0], par, sc.z, min_parallax=min_parallax,
                            agree_var=3.0 * agree ** 2, plane_k=kp)
    out = [cells_to_pixels(a, frame, (W, H), nearest=True) for a in (est.z, est.lo, est.hi)]
    if plane is not None:
        on = cells_to_pixels(est.on_plane.astype(np.float64), frame, (W, H),
                             nearest=True) > 0.5
        v, u = np.mgrid[0:H, 0:W]
        zp = plane.pixel_depth(frame.K, u, v)
        out[0] = np.where(on & np.isfinite(zp), zp, out[0])
    return tuple(np.where(resolved, a, np.nan).astype(np.float32) for a in out)

