"""Plane-sweep stereo between the totems: a depth and colour map of the camera view.

The totems see the scene from a few nearby viewpoints (their refracted rays start at
the sphere exits). A surface point at depth ``z`` is where the rays of *several*
totems that see the same colour meet. The frustum grid's depth slices are
fronto-parallel planes ``z = z_k`` (even in inverse depth), so the sweep runs in the
grid's own frame (:mod:`inverse.grid`): for each slice, every totem ray is cut with
the plane, the point is projected into the camera (grid cell ``(t, s)``) and the
ray's colour is splatted there (bilinear), per totem. Per totem, the splats are
spread by a Gaussian (normalised convolution: mean colour where the totem has rays,
nothing elsewhere). The photo-consistency cost of a cell is the variance of the
totems' mean colours there (where >= 2 totems land; elsewhere neutral), aggregated by
semi-global matching; each column's depth is the slice of least aggregated cost. The
colour map is the totems' consensus colour at that depth, holes filled by pull-push.

Everything is numpy over all rays at once (loops over slices and totems only).
Colours are whatever the caller splats (here: sRGB of the Fresnel-corrected radiance).

Public functions
----------------
``slice_depths(frame, n) -> (n,) z`` metres, slice centres even in inverse depth;
``plane_sweep(o, d, colour, totem, frame, res, *, ...) -> SweepResult``;
``slice_colours(o, d, colour, totem, frame, res, *, ...) -> SliceColours`` what each
totem sees at each slice (the sweep's first half);
``semi_global(cost, p1, p2) -> cost`` aggregation of a (slices, rows, cols) volume;
``pull_push(values, weight) -> values`` hole filling of a 2-D map;
``pixel_lines(o, d, K)`` each ray's pixel as affine in inverse depth;
``blur_cells(maps, sigma)`` the splats' Gaussian over map cells.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from inverse.grid import FrustumFrame

__all__ = ["SweepResult", "slice_depths", "pixel_lines", "blur_cells", "pull_push",
           "semi_global", "SliceColours", "slice_colours", "plane_sweep"]


@dataclass
class SweepResult:
    """Outcome of :func:`plane_sweep` on an ``(nt, ns)`` map of grid columns.

    Attributes
    ----------
    r : (nt, ns) unit inverse-depth coordinate of the surface per column (grid ``r``).
    depth : (nt, ns) metres, camera-frame ``z`` of the surface.
    colour : (nt, ns, C) consensus colour at that depth (holes filled).
    confident : (nt, ns) bool, at least two totems land in the cell at the chosen depth.
    cost : (n_slices, nt, ns) aggregated cost volume.
    z : (n_slices,) slice depths, metres.
    """

    r: np.ndarray
    depth: np.ndarray
    colour: np.ndarray
    confident: np.ndarray
    cost: np.ndarray
    z: np.ndarray


def slice_depths(frame: FrustumFrame, n: int) -> np.ndarray:
    """Depths (metres) of ``n`` slice centres, even in the grid's inverse depth ``r``."""
    return frame.depth_at((np.arange(n) + 0.5) / n)


def pixel_lines(o, d, K):
    """Each ray's camera pixel on the depth plane ``z`` as ``(au + bu / z, av + bv / z)``.

    A ray ``o + t d`` (camera frame, metres) meets the plane at ``t = (z - o_z) / d_z``;
    its pixel is affine in ``1 / z``, so the coefficients (m,) are computed once for all
    planes. Returns ``au, bu, av, bv`` (pixels, pixel metres) and the clamped ``d_z``.
    """
    K = np.asarray(K, np.float64)
    dz = np.where(np.abs(d[:, 2]) > 1e-6, d[:, 2], 1e-6)
    ax, ay = d[:, 0] / dz, d[:, 1] / dz                   # x / z as z -> infinity
    bx, by = o[:, 0] - o[:, 2] * ax, o[:, 1] - o[:, 2] * ay
    au = K[0, 0] * ax + K[0, 1] * ay + K[0, 2]
    bu = K[0, 0] * bx + K[0, 1] * by
    av = K[1, 1] * ay + K[1, 2]
    bv = K[1, 1] * by
    return au, bu, av, bv, dz


def _splat(o, d, colour, totem, frame, z, res, n_tot):
    """Bilinear splats of every ray at every slice: weights (n_tot, nk, nt, ns) and
    colour sums (n_tot, nk, nt, ns, C), float32, C-contiguous."""
    nt, ns = res
    nk = len(z)
    C = colour.shape[1]
    au, bu, av, bv, dz = pixel_lines(o, d, frame.K)
    du = frame.u_range[1] - frame.u_range[0]
    dv = frame.v_range[1] - frame.v_range[0]
    # cell-centred coordinates fs = as + bs / z (and ft), per ray
    a_s = (au - frame.u_range[0]) / du * ns - 0.5
    b_s = bu / du * ns
    a_t = (av - frame.v_range[0]) / dv * nt - 0.5
    b_t = bv / dv * nt
    plane = n_tot * nt * ns
    cell0 = totem.astype(np.int64) * (nt * ns)
    wsum = np.empty((n_tot, nk, nt, ns), np.float32)
    csum = np.empty((n_tot, nk, nt, ns, C), np.float32)
    for k in range(nk):              # slices, not rays
        fs = a_s + b_s / z[k]
        ft = a_t + b_t / z[k]
        ok = ((z[k] - o[:, 2]) / dz > 0) & (fs > -1) & (fs < ns) & (ft > -1) & (ft < nt)
        fs, ft, ck = fs[ok], ft[ok], colour[ok]
        i0, j0 = np.floor(fs).astype(np.int64), np.floor(ft).astype(np.int64)
        a, b = fs - i0, ft - j0
        idx, wts = [], []
        for di, dj, wgt in ((0, 0, (1 - a) * (1 - b)), (1, 0, a * (1 - b)),
                            (0, 1, (1 - a) * b), (1, 1, a * b)):
            ii, jj = i0 + di, j0 + dj
            keep = (ii >= 0) & (ii < ns) & (jj >= 0) & (jj < nt)
            idx.append(np.where(keep, cell0[ok] + jj * ns + ii, plane))  # outside: spare
            wts.append(wgt)
        idx, wts = np.concatenate(idx), np.concatenate(wts)
        cols = np.tile(ck, (4, 1))
        wsum[:, k] = np.bincount(idx, wts, plane + 1)[:plane].reshape(n_tot, nt, ns)
        for c in range(C):
            csum[:, k, ..., c] = np.bincount(idx, wts * cols[:, c],
                                             plane + 1)[:plane].reshape(n_tot, nt, ns)
    return wsum, csum


def blur_cells(maps: np.ndarray, sigma: float, *, channels: bool = False,
               truncate: float = 2.5) -> np.ndarray:
    """Gaussian of ``sigma`` cells over the map axes of ``maps``: (..., nt, ns), or
    (..., nt, ns, C) with ``channels``; zero outside the map (``scipy.ndimage``'s
    ``gaussian_filter`` with ``mode="constant"``, to float32 rounding); float32 out.
    OpenCV filters map by map, three times faster than ndimage over the volume."""
    import cv2

    r = int(truncate * sigma + 0.5)
    x = np.arange(-r, r + 1)
    kernel = np.exp(-0.5 * x ** 2 / sigma ** 2)
    kernel = (kernel / kernel.sum()).astype(np.float32)
    maps = np.ascontiguousarray(maps, np.float32)
    lead = maps.shape[:-3] if channels else maps.shape[:-2]
    flat = maps.reshape((-1,) + maps.shape[len(lead):])
    out = np.empty_like(flat)
    for i in range(len(flat)):
        cv2.sepFilter2D(flat[i], -1, kernel, kernel, dst=out[i],
                        borderType=cv2.BORDER_CONSTANT)
    return out.reshape(maps.shape)


def _box3(img: np.ndarray) -> np.ndarray:
    """Mean over each pixel's 3 x 3 neighbours, the edge repeated (as ndimage's
    ``uniform_filter(size=(3, 3, 1), mode="nearest")``), (H, W, C) float64."""
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    rows = p[:-2] + p[1:-1] + p[2:]
    return (rows[:, :-2] + rows[:, 1:-1] + rows[:, 2:]) / 9.0


def pull_push(values: np.ndarray, weight: np.ndarray, *, levels: int = 8) -> np.ndarray:
    """Fill a 2-D map where ``weight`` is 0 from its weighted neighbours (pull-push).

    ``values`` (H, W, C), ``weight`` (H, W) >= 0. Known values are kept where
    ``weight >= 1``; elsewhere they blend with the coarser levels' estimate.
    """
    values = np.asarray(values, dtype=np.float64)
    w = np.clip(np.asarray(weight, dtype=np.float64), 0.0, None)
    pyr = [(values * w[..., None], w)]
    for _ in range(levels):
        vw, ww = pyr[-1]
        if min(ww.shape) < 2:
            break
        H2, W2 = (ww.shape[0] + 1) // 2, (ww.shape[1] + 1) // 2
        pad = ((0, 2 * H2 - ww.shape[0]), (0, 2 * W2 - ww.shape[1]))
        wp = np.pad(ww, pad)
        vp = np.pad(vw, pad + ((0, 0),))
        w2 = wp[0::2, 0::2] + wp[1::2, 0::2] + wp[0::2, 1::2] + wp[1::2, 1::2]
        v2 = vp[0::2, 0::2] + vp[1::2, 0::2] + vp[0::2, 1::2] + vp[1::2, 1::2]
        s = np.minimum(w2, 1.0) / np.maximum(w2, 1e-12)      # clamp the confidence at 1
        pyr.append((v2 * s[..., None], w2 * s))
    vw, ww = pyr[-1]
    est = vw / np.maximum(ww, 1e-12)[..., None]
    for vw, ww in reversed(pyr[:-1]):
        up = np.repeat(np.repeat(est, 2, 0), 2, 1)[:ww.shape[0], :ww.shape[1]]
        up = _box3(up)
        a = np.minimum(ww, 1.0)[..., None]
        est = a * vw / np.maximum(ww, 1e-12)[..., None] + (1 - a) * up
    return est


def semi_global(cost: np.ndarray, p1: float, p2: float) -> np.ndarray:
    """Semi-global matching (Hirschmueller 2008): ``cost`` (K, H, W) aggregated along
    the four axis-aligned paths. A neighbour one label away costs ``p1`` more, any
    larger jump ``p2``; so a depth map that is smooth, with a few sharp edges, wins
    over per-cell noise. Returns the summed path costs, (K, H, W)."""
    C = np.moveaxis(np.asarray(cost, np.float64), 0, -1)          # (H, W, K)

    def along_x(C):
        L = np.empty_like(C)
        L[:, 0] = C[:, 0]
        for x in range(1, C.shape[1]):
            prev = L[:, x - 1]
            low = prev.min(axis=1, keepdims=True)
            up = np.pad(prev[:, 1:], ((0, 0), (0, 1)), constant_values=np.inf)
            down = np.pad(prev[:, :-1], ((0, 0), (1, 0)), constant_values=np.inf)
            step = np.minimum(prev, np.minimum(up, down) + p1)
            L[:, x] = C[:, x] + np.minimum(step, low + p2) - low
        return L

    total = along_x(C) + along_x(C[:, ::-1])[:, ::-1]
    Ct = np.transpose(C, (1, 0, 2))
    total += np.transpose(along_x(Ct) + along_x(Ct[:, ::-1])[:, ::-1], (1, 0, 2))
    return np.moveaxis(total, -1, 0)


@dataclass
class SliceColours:
    """What each totem sees at each depth slice, over an ``(nt, ns)`` map of grid columns.

    Attributes
    ----------
    colour : (n_tot, n_slices, nt, ns, C) the mean colour of totem j's rays that cross
        slice k inside the cell (spread by the Gaussian), where ``land``.
    land : (n_tot, n_slices, nt, ns) bool, totem j has rays there.
    weight : (n_tot, n_slices, nt, ns) their spread splat weight.
    z : (n_slices,) slice depths, metres.
    peak : one ray's peak spread weight (``weight / peak`` counts rays).
    """

    colour: np.ndarray
    land: np.ndarray
    weight: np.ndarray
    z: np.ndarray
    peak: float

    @cached_property
    def consistency(self):
        """Per slice and cell: the landing totems' count ``n_land`` (nk, nt, ns), their
        mean colour (nk, nt, ns, C) and the variance of their colours (nk, nt, ns),
        summed over channels; computed once, shared by every sweep of these colours."""
        n_land = self.land.sum(0)
        s1 = np.zeros(self.colour.shape[1:], np.float32)
        s2 = np.zeros(self.land.shape[1:], np.float32)
        for mu, land in zip(self.colour, self.land):      # totems, not cells
            mu = np.where(land[..., None], mu, 0.0)
            s1 += mu
            s2 += np.einsum("...c,...c->...", mu, mu)
        count = np.maximum(n_land, 1).astype(np.float32)
        mean = s1 / count[..., None]
        var = np.maximum(s2 / count - np.einsum("...c,...c->...", mean, mean), 0.0)
        return n_land, mean, var


def slice_colours(o, d, colour, totem, frame: FrustumFrame, res, *, n_slices: int = 64,
                  sigma: float | None = 1.5, min_weight: float = 0.3) -> SliceColours:
    """Every totem's rays cut with every depth slice and projected into the camera.

    Parameters as :func:`plane_sweep`: rays ``o``, ``d`` (m, 3) camera frame, metres;
    ``colour`` (m, C); ``totem`` (m,); the map's ``res`` (nt, ns); ``sigma`` in cells
    (None: from the ray density, about 4 rays of a totem inside one sigma disc); a totem
    lands in a cell where its spread weight exceeds ``min_weight`` of one ray's peak.
    """
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    colour = np.asarray(colour, np.float64)
    totem = np.asarray(totem, np.int64)
    nt, ns = int(res[0]), int(res[1])
    n_tot = int(totem.max()) + 1 if totem.size else 1
    z = slice_depths(frame, n_slices)
    wsum, csum = _splat(o, d, colour, totem, frame, z, (nt, ns), n_tot)
    if sigma is None:
        # Rays of one totem per cell at the middle slice -> sigma holding ~4 rays.
        per_cell = wsum[:, n_slices // 2].sum((1, 2)) / (nt * ns)
        rho = max(float(np.median(per_cell[per_cell > 0])) if np.any(per_cell > 0)
                  else 1e-3, 1e-3)
        sigma = float(np.clip(np.sqrt(4.0 / (np.pi * rho)), 0.5, 4.0))
    wsum = blur_cells(wsum, sigma)
    csum = blur_cells(csum, sigma, channels=True)
    peak = 1.0 / (2 * np.pi * sigma ** 2)
    land = wsum > min_weight * peak
    mu = csum / np.maximum(wsum, 1e-12)[..., None]
    return SliceColours(mu, land, wsum, z, peak)


def plane_sweep(o, d, colour, totem, frame: FrustumFrame, res, *, n_slices: int = 64,
                sigma: float | None = 1.5, min_weight: float = 0.3, p1: float = 0.3,
                p2: float = 3.0, far_bias: float = 0.0,
                colours: SliceColours | None = None) -> SweepResult:
    """Depth and colour of each grid column from the totems' parallax.

    Parameters
    ----------
    o, d : (m, 3) refracted rays leaving the totems (exit point, metres, and unit
        direction), camera frame. Rays near a sphere's rim carry blurred colours mixed
        with reflections: leave them out (``inverse.view.view.choose_view`` keeps incidence
        cosine >= 0.5; see docs/decisions.md, 'sweep: rim rays left out of the cost').
    colour : (m, C) colour each ray carries (e.g. sRGB of the radiance).
    totem : (m,) int, the totem each ray left.
    frame : the grid frame; the sweep's map covers its ``(s, t)`` range.
    res : (nt, ns) rows and columns of the map.
    n_slices : depth slices, even in inverse depth between ``frame.near`` and ``far``.
    sigma : Gaussian spread of each totem's splats, in cells; None = from the ray
        density (about 4 rays of a totem inside one sigma disc).
    min_weight : a totem "lands" in a cell where its spread splat weight exceeds this
        fraction of one ray's peak.
    p1, p2 : semi-global matching penalties (:func:`semi_global`) in units of the
        median cost.
    far_bias : added to the normalised cost of the nearest slice, falling linearly to
        0 at the farthest: where the colours agree at every depth, prefer far.
    colours : :func:`slice_colours` of these rays already computed with the same
        ``res``, ``n_slices``, ``sigma`` and ``min_weight`` (sweeps that differ only in
        ``far_bias`` or the penalties share it); computed here if None.

    The cost of a cell at a slice is the variance of the landing totems' mean colours
    where at least two land; where fewer land it says nothing, so it is the median
    cost (a fixed penalty there would favour depths where the totems' footprints
    overlap, not where they agree).
    """
    sc = colours if colours is not None else slice_colours(
        o, d, colour, totem, frame, res, n_slices=n_slices, sigma=sigma,
        min_weight=min_weight)
    wsum, z, peak = sc.weight, sc.z, sc.peak
    n_land, mean, var = sc.consistency                           # (nk, nt, ns)
    defined = n_land >= 2
    fill = float(np.median(var[defined])) if defined.any() else 1.0
    cost = np.where(defined, var, fill) / max(fill, 1e-12)
    cost = cost + far_bias * (1.0 - (np.arange(n_slices) + 0.5) / n_slices)[:, None, None]
    if p2 > 0:
        cost = semi_global(cost, p1, p2)
    k_best = np.argmin(cost, axis=0)
    confident = np.take_along_axis(defined, k_best[None], 0)[0]
    # Colour: the landing totems' consensus at the chosen slice, holes filled.
    mean_k = np.take_along_axis(mean, k_best[None, ..., None], 0)[0]
    n_k = np.take_along_axis(n_land, k_best[None], 0)[0]
    w_col = np.take_along_axis(wsum, k_best[None, None], 1)[:, 0].sum(0)
    known = (n_k >= 1).astype(np.float64) * np.minimum(w_col / peak, 1.0)
    col = pull_push(mean_k, known)
    r = (k_best + 0.5) / n_slices
    depth = frame.depth_at(r)
    return SweepResult(r=r, depth=depth, colour=col, confident=confident, cost=cost, z=z)
