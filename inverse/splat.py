"""The camera view from the totem rays and a depth map: splatting, and choosing the map.

Given a depth map of the camera view (metres per grid column, over the frame's
``(s, t)`` range), each refracted totem ray meets the surface where it first passes
behind it; that point's camera pixel receives the ray's radiance. Splatting every
ray there and interpolating between the rays' pixels (linearly over their Delaunay
triangulation; pull-push beyond it) rebuilds the camera view at the photo's resolution,
with no colour grid in between.

Which depth map is right is judged on the totem pixels alone, by leave-one-totem-out:
the other totems' rays, splatted at the map, predict each held-out totem's pixels.
A wrong map sends the totems' colours to different places, so they disagree (see
docs/decisions.md, "The camera view: grid or stereo").

Public functions
----------------
``surface_hits(o, d, frame, depth, n_steps) -> (u, v, z, hit)``;
``splat_image(u, v, values, size, at=None) -> (H, W, C)`` (or the values at pixels);
``holdout_errors(o, d, radiance, totem, frame, depth, size) -> (errors, u, v, z, hit)``;
``holdout_error(...) -> (mean error, fraction landing)``;
``error_map(errors, u, v, size) -> (mean error map, ray density)``.
"""

from __future__ import annotations

import numpy as np

from inverse.grid import FrustumFrame
from scenes.camera import project
from inverse.sweep import pull_push, slice_depths

__all__ = ["surface_hits", "splat_image", "holdout_errors", "holdout_error",
           "error_map"]


def surface_hits(o, d, frame: FrustumFrame, depth, *, n_steps: int = 256):
    """Where each ray first passes behind the depth map.

    Parameters
    ----------
    o, d : (m, 3) ray origins (metres) and unit directions, camera frame.
    frame : the map's frame.
    depth : (nt, ns) surface depth (camera-frame z, metres) per map cell.
    n_steps : depth planes the rays are tested at (even in inverse depth).

    Returns
    -------
    u, v : (m,) camera pixel coordinates of the hit (OpenCV centres), NaN if none.
    z : (m,) depth of the hit, metres.
    hit : (m,) bool. A ray still in the frame at the last plane stops there (the far
        backdrop, as the grid renderer treats it); a ray that leaves the frame's
        sides first has no hit.
    """
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    depth = np.asarray(depth, np.float64)
    nt, ns = depth.shape
    K = frame.K
    m = o.shape[0]
    u_hit = np.full(m, np.nan)
    v_hit = np.full(m, np.nan)
    z_hit = np.full(m, np.nan)
    hit = np.zeros(m, bool)
    dz = np.where(np.abs(d[:, 2]) > 1e-9, d[:, 2], 1e-9)
    planes = slice_depths(frame, n_steps)
    for i, zk in enumerate(planes):
        t = (zk - o[:, 2]) / dz
        X = o + t[:, None] * d
        u, v = project(K, X, zk).T
        s, r = frame.pixel_to_st(u, v)
        col, row = np.floor(s * ns), np.floor(r * nt)
        inside = (t > 0) & (col >= 0) & (col < ns) & (row >= 0) & (row < nt)
        surf = np.full(m, np.inf)
        surf[inside] = depth[row[inside].astype(int), col[inside].astype(int)]
        new = ~hit & inside & ((zk >= surf) | (i == n_steps - 1))
        u_hit[new], v_hit[new], z_hit[new] = u[new], v[new], zk
        hit |= new
    return u_hit, v_hit, z_hit, hit


def _pixels(u, v, hit, size):
    """Integer pixel of each hit inside the image, and which hits are inside."""
    W, H = size
    ok = hit & (u >= -0.5) & (u < W - 0.5) & (v >= -0.5) & (v < H - 0.5)
    ui = np.where(ok, np.round(np.nan_to_num(u)), 0).astype(np.int64)
    vi = np.where(ok, np.round(np.nan_to_num(v)), 0).astype(np.int64)
    return ui, vi, ok


def _pixel_means(u, v, values, size, hit):
    """The rays averaged per pixel: flat pixel index (k,), mean values (k, C), and the
    ray count per pixel (H * W,)."""
    W, H = size
    ui, vi, ok = _pixels(u, v, hit, size)
    flat = vi[ok] * W + ui[ok]
    weight = np.bincount(flat, minlength=W * H).astype(np.float64)
    total = np.stack([np.bincount(flat, values[ok, c], W * H)
                      for c in range(values.shape[1])], -1)
    idx = np.nonzero(weight > 0)[0]
    return idx, total[idx] / weight[idx, None], weight


def splat_image(u, v, values, size, *, hit=None, at=None) -> np.ndarray:
    """Average ``values`` (m, C) into the pixels ``(u, v)`` and interpolate between them.

    Between the pixels that rays reached, the values are interpolated linearly over
    their Delaunay triangulation (``scipy.interpolate.LinearNDInterpolator``); outside
    its hull, pull-push fills in. (Pull-push everywhere kept each sample pixel exact in
    a blur of its coarser levels: a pattern of dots; see docs/decisions.md, 'splat:
    linear interpolation, not pull-push everywhere'.)

    ``size`` = (W, H); ``hit`` (m,) bool selects the rays (default: finite ``u``).
    ``at`` = (ui, vi) integer pixels: return only the values there, (k, C), instead of
    the whole image. Returns (H, W, C) float64 (or (k, C)).
    """
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import QhullError

    W, H = size
    values = np.asarray(values, np.float64)
    hit = np.isfinite(u) if hit is None else np.asarray(hit, bool)
    idx, mean, weight = _pixel_means(u, v, values, size, hit)
    if at is None:
        vq, uq = np.divmod(np.arange(W * H), W)
    else:
        uq, vq = (np.asarray(a, np.int64) for a in at)
    out = np.full((uq.size, values.shape[1]), np.nan)
    if idx.size >= 3:
        pts = np.stack([idx % W, idx // W], 1).astype(np.float64)
        try:
            out = LinearNDInterpolator(pts, mean)(np.stack([uq, vq], 1).astype(np.float64))
        except QhullError:                   # all samples on a line: pull-push alone
            pass
    gap = ~np.all(np.isfinite(out), axis=1)
    if gap.any():
        full = np.zeros((W * H, values.shape[1]))
        full[idx] = mean
        filled = pull_push(full.reshape(H, W, -1), weight.reshape(H, W))
        out[gap] = filled[vq[gap], uq[gap]]
    return out if at is not None else out.reshape(H, W, -1)


def holdout_errors(o, d, radiance, totem, frame: FrustumFrame, depth, size, *,
                   to_display=None, n_steps: int = 256):
    """Leave-one-totem-out errors of a depth map, per ray.

    For each totem, the other totems' rays are splatted at ``depth``
    (:func:`splat_image`) and the held-out totem's rays read that image where they
    meet the surface. ``radiance`` (m, 3) is what each ray carries (e.g. linear RGB);
    ``to_display`` maps it to the space the error is taken in (e.g. linear -> sRGB;
    default none).

    Returns
    -------
    errors : (m,) mean absolute error over channels; NaN where the ray does not meet
        the surface inside the image.
    u, v, z, hit : where each ray meets the surface (:func:`surface_hits`), so a
        caller that splats at the same map need not cast the rays again.
    """
    radiance = np.asarray(radiance, np.float64)
    totem = np.asarray(totem)
    u, v, z, hit = surface_hits(o, d, frame, depth, n_steps=n_steps)
    ui, vi, ok = _pixels(u, v, hit, size)
    show = to_display or (lambda x: x)
    errors = np.full(len(totem), np.nan)
    for j in np.unique(totem):
        held = totem == j
        test = held & ok
        if test.any():
            pred = splat_image(u, v, radiance, size, hit=hit & ~held,
                               at=(ui[test], vi[test]))
            errors[test] = np.abs(show(pred) - show(radiance[test])).mean(1)
    return errors, u, v, z, hit


def holdout_error(o, d, radiance, totem, frame: FrustumFrame, depth, size, *,
                  to_display=None, n_steps: int = 256) -> tuple[float, float]:
    """Mean of :func:`holdout_errors` over the rays that meet the surface in the image,
    and the fraction of rays that do."""
    errors = holdout_errors(o, d, radiance, totem, frame, depth, size,
                                  to_display=to_display, n_steps=n_steps)[0]
    seen = np.isfinite(errors)
    return (float(errors[seen].mean()) if seen.any() else float("inf")), float(seen.mean())


def error_map(errors, u, v, size, *, sigma: float = 16.0):
    """Per-ray errors spread over the image where the rays land: (mean error (H, W),
    ray density (H, W), rays per pixel after a Gaussian of ``sigma`` px)."""
    from scipy import ndimage

    W, H = size
    ok = np.isfinite(errors)
    ui, vi, inside = _pixels(u, v, ok, size)
    total = np.zeros((H, W))
    count = np.zeros((H, W))
    np.add.at(total, (vi[inside], ui[inside]), errors[inside])
    np.add.at(count, (vi[inside], ui[inside]), 1.0)
    total = ndimage.gaussian_filter(total, sigma)
    count = ndimage.gaussian_filter(count, sigma)
    return total / np.maximum(count, 1e-12), count
