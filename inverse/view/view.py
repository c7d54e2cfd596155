"""The camera view re-rendered from the fit: the grid's render, or plane-sweep stereo's
splat, whichever predicts held-out totems better, pixel by pixel.

The grid explains the totem pixels well but its geometry is weakly determined (a far
backdrop explains each ray on its own); stereo between the totems
(:func:`inverse.view.sweep.plane_sweep`) finds textured surfaces the grid missed and fails
under a smooth sky. Leave-one-totem-out (:func:`inverse.view.splat.holdout_errors`) tells
them apart from the totem pixels alone (see docs/decisions.md, "The camera view: grid or
stereo").

Public
------
``render_view(itg, frame, size)``, ``render_grid(grid, size)``: the grid's view and depth;
``column_depth(density, frame)``: the grid's surface depth per column;
``peak_points(...)``: where the totem rays end in the grid;
``choose_view(rays, frame, grid_depth, grid_view, grid_points, size, ...) -> StereoView``;
``stereo_weight(grid_errors, stereo_errors, size, *, prefer_stereo) -> (H, W)``;
``preference(grid, stereo, margin, band) -> [0, 1]``: the whole view's leaning to stereo.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inverse.grid import FrustumFrame, cells_to_pixels
from inverse.integrator import DELTA_SCALE
from inverse.rays import TotemRays
from inverse.view.splat import blur, error_map, holdout_errors, splat_image
from inverse.view.sweep import plane_sweep, slice_colours
from scenes import backend
from scenes.camera import pixel_rays, project
from scenes.colour import linear_to_srgb

__all__ = ["StereoView", "choose_view", "stereo_weight", "render_view", "render_grid",
           "column_depth", "peak_points", "COS_SWEEP"]

COS_SWEEP = 0.5
"""The stereo's cost uses only rays that entered their sphere at an incidence cosine of
at least this: rim rays are blurred and mixed with reflection."""


def _display(x):
    return linear_to_srgb(np.clip(x, 0.0, 1.0))


@dataclass
class StereoView:
    """Outcome of :func:`choose_view`.

    Attributes
    ----------
    chosen : the geometry with the least hold-out error over the whole view (a stereo
        map's divided by ``margin``): "grid" or a stereo map ("stereo",
        "stereo_far1": see ``far_biases``).
    holdout : {name: leave-one-totem-out L1 (sRGB)} for every candidate.
    stereo_share : fraction of the image taken from the stereo view (0 = the grid's);
        pixels with too few held-out rays to choose lean as the whole view does
        (:func:`preference`: continuous across the margin).
    recon : (H, W, 3) sRGB [0, 1]: per pixel, the grid's view or the view splatted at
        the best stereo map, whichever's held-out totems erred less nearby.
    depth : (H, W) metres, the same blend of the two depths.
    points : (m, 3) camera-frame metres, where the rays end in the geometry each pixel
        took (the protected region's evidence).
    """

    chosen: str
    holdout: dict = field(default_factory=dict)
    stereo_share: float = 0.0
    recon: np.ndarray | None = None
    depth: np.ndarray | None = None
    points: np.ndarray | None = None


def _resize_nearest(values, shape) -> np.ndarray:
    rows = np.minimum((np.arange(shape[0]) + 0.5) / shape[0] * values.shape[0],
                      values.shape[0] - 1).astype(int)
    cols = np.minimum((np.arange(shape[1]) + 0.5) / shape[1] * values.shape[1],
                      values.shape[1] - 1).astype(int)
    return values[rows][:, cols]


def _points_where(points, K, weight, take_high: bool):
    """The points whose pixel has ``weight > 0.5`` (or ``<= 0.5``)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    H, W = weight.shape
    front = points[:, 2] > 0
    uv = np.full((len(points), 2), -1.0)
    uv[front] = project(K, points[front])
    ui, vi = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
    inside = front & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
    w = np.full(len(points), 0.0)
    w[inside] = weight[vi[inside], ui[inside]]
    keep = inside & ((w > 0.5) if take_high else (w <= 0.5))
    return points[keep]


def preference(grid: float, stereo: float, margin: float = 0.9, band: float = 0.05) -> float:
    """How much the whole view leans to stereo, in [0, 1], from the two geometries'
    held-out errors: 1 when ``stereo / margin`` is below the grid's by more than
    ``band`` (relative), 0 when above by more, linear between. Continuous, so that a
    fit's last bits cannot swap one whole view for the other."""
    if not (np.isfinite(stereo) and stereo > 0):
        return 0.0
    if not (np.isfinite(grid) and grid > 0):
        return 1.0
    ratio = stereo / margin / grid
    return float(np.clip((1.0 + band - ratio) / (2.0 * band), 0.0, 1.0))


def stereo_weight(grid_errors, stereo_errors, size, *, prefer_stereo: float,
                  sigma: float = 16.0, min_rays: float = 0.05,
                  margin: float = 1.0) -> np.ndarray:
    """Per pixel, how much of the view comes from stereo (H, W) in [0, 1].

    ``grid_errors``, ``stereo_errors``: (errors, u, v, ...) of
    :func:`inverse.view.splat.holdout_errors` for each geometry. A pixel takes the geometry
    whose held-out rays landing nearby (Gaussian of ``sigma`` px) erred less (stereo's
    error counted as ``1 / margin`` times what it is); where
    either has fewer than ``min_rays`` such rays, the whole view's leaning
    (``prefer_stereo`` in [0, 1], :func:`preference`). The choice is then smoothed
    (``sigma / 2``) so the two views meet without a seam.
    """
    err_g, n_g = error_map(*grid_errors[:3], size, sigma=sigma)
    err_s, n_s = error_map(*stereo_errors[:3], size, sigma=sigma)
    known = (n_g > min_rays) & (n_s > min_rays)
    weight = np.where(known, err_s < margin * err_g, prefer_stereo).astype(np.float64)
    return np.clip(blur(weight, sigma / 2), 0.0, 1.0)


def choose_view(rays: TotemRays, frame: FrustumFrame, grid_depth, grid_view, grid_points,
                size, *, res=(120, 160), n_slices: int = 64,
                cos_sweep: float = COS_SWEEP, far_biases=(0.0, 1.0), sigma: float = 16.0,
                min_rays: float = 0.05, sweep: dict | None = None,
                margin: float = 0.9) -> StereoView:
    """Compare the grid's geometry with stereo maps, globally and pixel by pixel.

    Parameters
    ----------
    rays : the totem pixels' rays leaving the glass (:class:`inverse.rays.TotemRays`).
    cos_sweep : the sweep's cost uses the rays with ``cos_in >= cos_sweep``.
    frame : the grid's frame; maps cover its ``(s, t)`` range.
    grid_depth : (nt', ns') depth (metres) of the fitted grid's surface per column.
    grid_view, grid_points : the grid's render of the camera view (H, W, 3) sRGB and
        its rays' end points (k, 3), camera frame, metres.
    size : (W, H) of the photo.
    res, n_slices : the stereo maps' cells (rows, columns) and depth slices.
    far_biases : one stereo map per value (see :func:`plane_sweep`'s ``far_bias``).
    sigma : px, the Gaussian that spreads each held-out ray's error around where it
        lands; a pixel takes the stereo view where that local error is lower.
    min_rays : below this many held-out rays per pixel (after the Gaussian) for
        either geometry, a pixel follows the whole-view choice.
    sweep : further keywords of :func:`inverse.view.sweep.plane_sweep` (``sigma``, ``p1``,
        ``p2``; its defaults if None).
    margin : stereo wins, for the whole view and pixel by pixel, only where its
        held-out error is below ``margin`` times the grid's: the totems stand close
        together, so a depth wrong for the camera can still suit them (see
        docs/decisions.md, "Stereo margin 0.9").
    """
    o, d, radiance, totem = rays.o, rays.d, rays.radiance, rays.totem
    W, H = size
    maps = {"grid": _resize_nearest(np.asarray(grid_depth, np.float64), res)}
    good = rays.cos_in >= cos_sweep
    if len(np.unique(totem[good])) >= 2:
        colour = _display(radiance[good])
        sweep = dict(sweep or {})
        # One slice_colours for every far bias (only the cost differs between them),
        # with the sweep's own defaults for what the caller leaves out.
        shared = slice_colours(o[good], d[good], colour, totem[good], frame, res,
                               n_slices=n_slices,
                               **{k: sweep[k] for k in ("sigma", "min_weight") if k in sweep})
        for bias in far_biases:
            name = "stereo" if bias == 0 else f"stereo_far{bias:g}"
            maps[name] = plane_sweep(o[good], d[good], colour, totem[good], frame,
                                     res, n_slices=n_slices, far_bias=bias,
                                     colours=shared, **sweep).depth
    errors = {k: holdout_errors(o, d, radiance, totem, frame, D, size,
                                to_display=_display) for k, D in maps.items()}
    holdout = {k: float(np.nanmean(e[0])) if np.isfinite(e[0]).any() else float("inf")
               for k, e in errors.items()}
    chosen = min(holdout, key=lambda k: holdout[k] / (1.0 if k == "grid" else margin))
    grid_view = np.asarray(grid_view, np.float32)
    stereo_names = [k for k in maps if k != "grid"]
    if not stereo_names:
        return StereoView(chosen, holdout, 0.0, grid_view,
                          cells_to_pixels(maps["grid"], frame, size, nearest=True).astype(np.float32),
                          np.asarray(grid_points, np.float64))
    best = min(stereo_names, key=holdout.get)
    weight = stereo_weight(errors["grid"], errors[best], size,
                           prefer_stereo=preference(holdout["grid"], holdout[best], margin),
                           sigma=sigma, min_rays=min_rays,
                           margin=margin)
    _, u, v, z, hit = errors[best]
    stereo_view = _display(splat_image(u, v, radiance, size, hit=hit))
    recon = weight[..., None] * stereo_view + (1 - weight[..., None]) * grid_view
    inside = hit & (u >= -0.5) & (u < W - 0.5) & (v >= -0.5) & (v < H - 0.5)
    stereo_points = pixel_rays(frame.K, u[inside], v[inside])
    stereo_points = stereo_points / stereo_points[:, 2:3] * z[inside, None]
    points = np.concatenate([_points_where(stereo_points, frame.K, weight, True),
                             _points_where(grid_points, frame.K, weight, False)])
    depth = weight * cells_to_pixels(maps[best], frame, size, nearest=True) \
        + (1 - weight) * cells_to_pixels(maps["grid"], frame, size, nearest=True)
    return StereoView(chosen, holdout, float(weight.mean()),
                      np.clip(recon, 0.0, 1.0).astype(np.float32),
                      depth.astype(np.float32), points)


def column_depth(density, frame: FrustumFrame) -> np.ndarray:
    """Depth (metres) where each camera column of a raw density grid (nr, nt, ns, 1)
    reaches transmittance 1/2 (the far plane if it never does), (nt, ns)."""
    dens = np.asarray(density, np.float64)[..., 0]
    nr = dens.shape[0]
    tau = np.cumsum(np.logaddexp(0.0, dens) * DELTA_SCALE / nr, axis=0)
    k = np.where(tau[-1] > np.log(2.0), np.argmax(tau > np.log(2.0), axis=0), nr - 1)
    return frame.depth_at((k + 0.5) / nr)


def render_view(itg, frame: FrustumFrame, size, *, n: int = 128, rows_per_chunk=None):
    """The camera view re-rendered from the grid (no totems).

    Returns
    -------
    recon : (H, W, 3) float32 sRGB [0, 1].
    depth : (H, W) float32 metres, the weight-averaged depth along each column.
    """
    dr = backend.modules()[0]
    W, H = size
    rows_per_chunk = rows_per_chunk or max(1, 2_000_000 // (W * n))
    recon = np.zeros((H, W, 3), np.float32)
    depth = np.zeros((H, W), np.float32)
    for r0 in range(0, H, rows_per_chunk):
        r1 = min(H, r0 + rows_per_chunk)
        vv, uu = np.mgrid[r0:r1, 0:W]
        s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
        with dr.suspend_grad():
            C, w, m = itg.render_columns(s, t, n=n)
        C = np.asarray(C).T
        w = np.asarray(w).reshape(-1, n)
        m = np.asarray(m).reshape(-1, n)
        z = frame.depth_at(m)
        recon[r0:r1] = linear_to_srgb(C).reshape(r1 - r0, W, 3)
        depth[r0:r1] = ((w * z).sum(1) / np.maximum(w.sum(1), 1e-8)).reshape(r1 - r0, W)
    return recon, depth


def peak_points(frame, w, m, g0, g1, n, valid):
    """Camera-frame point of highest weight along each valid totem ray, (m, 3) metres."""
    w = w.reshape(-1, n)
    k = np.argmax(w, axis=1)
    rows = np.arange(w.shape[0])
    mm = m.reshape(-1, n)[rows, k]
    a = g0.T.reshape(-1, n, 3)[rows, k]
    b = g1.T.reshape(-1, n, 3)[rows, k]
    g = a + mm[:, None] * (b - a)
    pts = frame.from_unit(g)
    return pts[valid & np.all(np.isfinite(pts), axis=1)]


def render_grid(grid: dict, size, *, n: int = 128):
    """Re-render the camera view from a saved grid (``load_fit(...).grid``).

    Returns (recon sRGB (H, W, 3) float32, depth (H, W) metres).
    """
    from inverse.integrator import integrator_class

    mi = backend.modules()[1]
    frame = FrustumFrame.from_dict(grid)
    itg = integrator_class()(mi.Properties()).setup(frame, grid["density"], grid["colour"])
    return render_view(itg, frame, size, n=n)
