"""Absence: did three totems see, at one point in front of the surface, a hue the photo
shows nowhere along their lines of sight?

UNSEEN (:mod:`verify.metrics.corroborate`) asks whether the photo's hue at a pixel is
explained by the totems. An object removed or inpainted away leaves a hue that is: the
background's, which the totems see too. This test asks the converse, per totem ray.

A ray leaving totem ``j`` at ``o`` in direction ``d`` (camera frame) is, in the photo,
the image line from ``o``'s pixel to ``d``'s vanishing point: every point the ray can
have met projects onto it. When ``d`` points into the view the whole ray stays inside
the camera's frustum, so whatever it met is in the picture unless something nearer
hides it from the camera. Its *absence* is how far its hue is from the nearest one on
that line::

    a_r = min over the line's pixels p of  mean over channels |chroma(c_r) - chroma(I(p))|

(``I`` the photo blurred by ``SIGMA_PX``, totem pixels left out; ``chroma`` the colour
minus its grey level, as CHROMA and CORROB use). Where the photo still shows what the
ray saw, ``a_r`` is near 0 wherever along the line it is. A ray with a large ``a_r``
says what it met is not in the photo, but not where along its line: the totems that
see the missing thing do, at the depth where their rays cross. So per camera cell
``c`` and depth slice ``k`` (as CORROB's, :func:`inverse.view.sweep.slice_colours`), with
``a_jk(c)`` the mean absence of totem ``j``'s rays through it::

    A(c) = max over k in front of the surface of the third largest a_jk(c) over the
           totems j that land in c at slice k  (``MIN_TOTEMS`` = 3)

"In front of the surface": at most ``BEHIND_SLICES`` slices behind the fit's depth at
``c`` (``FitResult.recon_depth``). Behind it lie points the totems see around an
object's side and the camera does not (it sees the object), which would read as
missing; a removed object was in front of what the photo now shows (see
docs/decisions.md, 'ABSENT: only in front of the surface'). ``A`` is NaN where no slice
has three totems landing.

Three totems, the whole line and hue alone: no variant tried (two or four totems, fewer
rim rays, more blur, a shorter line, the grey level, no dark rays) flagged more than one
further edit without flagging an untouched photo too (see docs/decisions.md, 'ABSENT:
three totems, not two', and the ABSENT entries above it).

Limits: a removed object whose hue appears elsewhere along the totems' lines of sight
(the grass of the box scenes, a second object of the same colour) is not missed;
neither is one that fewer than three totems saw. The totems stand in a row, so the rays
meet at a shallow angle and the map smears a missing object along the direction away
from the totems.

Public
------
``line_absence(o, d, colour, image, valid, K) -> (m,)``
``in_view(d, K, size) -> (m,) bool``
``absence(o, d, radiance, totem, cos_in, frame, image, totem_mask, K, depth) -> (H, W)``
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from inverse.grid import FrustumFrame, cells_to_pixels
from inverse.rays import TotemRays
from inverse.view.depth import slice_window
from inverse.view.sweep import slice_colours
from scenes.camera import project
from scenes.colour import linear_to_srgb
from verify.metrics import corroborate, evidence
from verify.metrics.patches import chroma
from verify.metrics.resolution import gaussian

__all__ = ["SIGMA_PX", "STEP_PX", "MAX_SAMPLES", "BEHIND_SLICES", "MIN_TOTEMS",
           "INTERVAL_SLACK", "line_absence", "in_view", "absence"]

SIGMA_PX = 3.0
"""Gaussian sigma (pixels) of the photo's chroma before it is read along the lines: the
totem rays carry no detail finer than their spacing (about 3 px at 640 x 480)."""

STEP_PX = 1.5
"""Spacing (pixels) of the samples along each ray's image line (half the blur's FWHM)."""

MAX_SAMPLES = 800
"""At most this many samples per line (1200 px at ``STEP_PX``: longer than a 640 x 480
view's diagonal)."""

BEHIND_SLICES = 3
"""Slices behind the fit's surface depth still judged (the depth is a grid's weighted
mean, off by a few slices at edges)."""

MIN_TOTEMS = 3
"""How many totems must miss what they saw at one point: two cross by chance where
each sees, past an object's edge, something the camera does not; three seldom do."""


INTERVAL_SLACK = 1.0
"""Slices either side of the established depth's interval still judged (the interval
holds the true depth on about half the reach)."""


def line_absence(o, d, colour, image, valid, K, *, step_px: float = STEP_PX,
                 max_samples: int = MAX_SAMPLES) -> np.ndarray:
    """How far each ray's hue is from the nearest hue on its image line.

    Parameters
    ----------
    o, d : (m, 3) ray origins (metres, in front of the camera) and directions with
        ``d_z > 0``, camera frame.
    colour : (m, 3) sRGB each ray carries.
    image : (H, W, 3) the photo's sRGB, already blurred as wanted.
    valid : (H, W) bool, the pixels that may be read (not the totems').
    K : (3, 3) intrinsics (OpenCV).

    Returns
    -------
    (m,) float64, sRGB units; NaN for a ray whose line has no valid pixel.
    """
    H, W = valid.shape
    p0 = project(K, o)                    # the ray's start ...
    p1 = project(K, d)                    # ... and its vanishing point (d_z > 0)
    target = chroma(colour)
    photo = chroma(image)
    best = np.full(len(p0), np.inf)
    if not len(p0):
        return best
    n = int(min(max_samples, np.ceil(np.linalg.norm(p1 - p0, axis=1).max() / step_px))) + 1
    s = np.linspace(0.0, 1.0, n)
    for a in range(0, n, 64):
        f = s[a:a + 64][None, :, None]
        p = p0[:, None] + f * (p1 - p0)[:, None]              # (m, k, 2) pixels
        u = np.rint(p[..., 0]).astype(np.int64)
        v = np.rint(p[..., 1]).astype(np.int64)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        u, v = np.clip(u, 0, W - 1), np.clip(v, 0, H - 1)
        e = np.abs(photo[v, u] - target[:, None]).mean(axis=-1)
        best = np.minimum(best, np.where(inside & valid[v, u], e, np.inf).min(axis=1))
    return np.where(np.isfinite(best), best, np.nan)


def in_view(d, K, size) -> np.ndarray:
    """(m,) bool: directions whose vanishing point lies in the image (the ray, leaving a
    point inside the frustum, then stays inside it)."""
    W, H = size
    p = np.asarray(d, np.float64) @ np.asarray(K, np.float64).T
    ok = p[:, 2] > 1e-9
    u = p[:, 0] / np.where(ok, p[:, 2], 1.0)
    v = p[:, 1] / np.where(ok, p[:, 2], 1.0)
    return ok & (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= H - 0.5)


def absence(rays: TotemRays, frame: FrustumFrame, image, totem_mask, K, depth, *,
            sigma_px: float = SIGMA_PX, behind_slices: float = BEHIND_SLICES,
            cell_px: float = corroborate.CELL_PX, n_slices: int = corroborate.N_SLICES,
            sigma: float = corroborate.SIGMA_CELLS,
            cos_evidence: float = corroborate.COS_EVIDENCE,
            min_totems: int = MIN_TOTEMS, centers=None, spacing=None,
            min_parallax: float = 0.0, interval=None,
            interval_slack: float = INTERVAL_SLACK) -> np.ndarray:
    """``A`` per photo pixel (see the module docstring).

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`);
        those entering their sphere at an incidence cosine below ``cos_evidence``, or
        whose vanishing point is outside the photo, are not used.
    frame : the fit's frustum frame (the cells and slices of CORROB's map).
    image : (H, W, 3) the photo, sRGB [0, 1].
    totem_mask : (H, W) bool, the totems' pixels (never read).
    K : (3, 3) intrinsics.
    depth : (H, W) the fit's surface depth (camera-frame z, metres), or None to judge
        every slice.
    centers, spacing, min_parallax : the totems' centres (n, 3), metres, their rays'
        angular spacings (n,), radians, and the parallax (in those spacings,
        :mod:`verify.metrics.evidence`) two of the totems landing at a point must see it
        with for the point to be judged; 0 (default) judges every point.
    interval : (lo, hi) each (H, W), the depth interval the totems establish (metres,
        NaN where none: :class:`verify.metrics.evidence.Evidence`); the points judged
        are those inside it, widened by ``interval_slack`` slices. None: every depth.

    Returns
    -------
    (H, W) float64, sRGB units >= 0; NaN where fewer than ``min_totems`` totems land.
    """
    image = np.asarray(image, np.float64)
    H, W = image.shape[:2]
    K = np.asarray(K, np.float64)
    rays = rays.select((rays.cos_in >= cos_evidence) & in_view(rays.d, K, (W, H)))
    o, d, totem = rays.o, rays.d, rays.totem
    if rays.n_totems() < min_totems:
        return np.full((H, W), np.nan)
    colour = linear_to_srgb(np.clip(rays.radiance, 0.0, 1.0))
    blurred = gaussian(image, sigma_px)
    a = line_absence(o, d, colour, blurred, ~np.asarray(totem_mask, bool), K)
    ok = np.isfinite(a)
    if len(np.unique(totem[ok])) < min_totems:
        return np.full((H, W), np.nan)
    res = corroborate.map_res(frame, cell_px)
    sc = slice_colours(o[ok], d[ok], a[ok, None], totem[ok], frame, res,
                       n_slices=n_slices, sigma=sigma)
    per = np.where(sc.land, sc.colour[..., 0], -np.inf)       # (n_tot, nk, nt, ns)
    if depth is not None:
        uu, vv = corroborate.cell_centres(frame, res)
        z = np.asarray(depth, np.float64)
        z = np.where(np.isfinite(z) & (z > 0), z, np.inf)
        zc = ndimage.map_coordinates(z, [vv, uu], order=0, mode="nearest")
        inv = 1.0 / np.asarray(sc.z, np.float64)
        step = abs(inv[1] - inv[0]) if len(inv) > 1 else 0.0
        behind = inv[:, None, None] < 1.0 / zc[None] - behind_slices * step
        per = np.where(behind[None], -np.inf, per)
    if min_parallax > 0 and centers is not None:
        resolved = evidence.slice_parallax(sc, frame, centers, spacing) >= min_parallax
        per = np.where(resolved[None], per, -np.inf)
    if interval is not None:
        window = slice_window(sc.z, frame, res, *interval, slack=interval_slack)
        per = np.where(window[None], per, -np.inf)
    kth = -np.sort(-per, axis=0)[min_totems - 1]               # (nk, nt, ns)
    cells = kth.max(axis=0)
    return cells_to_pixels(np.where(np.isfinite(cells), cells, np.nan), frame, (W, H))
