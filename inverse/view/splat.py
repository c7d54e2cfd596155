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
``error_map(errors, u, v, size) -> (mean error map, ray density)``;
``blur(image, sigma)`` a Gaussian over a 2-D map.
"""

from __future__ import annotations

import numpy as np

from inverse.grid import FrustumFrame
from inverse.view.sweep import pixel_lines, pull_push, slice_depths

__all__ = ["surface_hits", "splat_image", "linear_at", "holdout_errors", "holdout_error",
           "error_map", "blur"]


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
    au, bu, av, bv, dz = pixel_lines(o, d, K)
    flat = np.append(depth.ravel(), np.inf)          # the spare cell: outside the map
    planes = slice_depths(frame, n_steps)
    for i, zk in enumerate(planes):
        u, v = au + bu / zk, av + bv / zk
        s, r = frame.pixel_to_st(u, v)
        col, row = np.floor(s * ns), np.floor(r * nt)
        inside = ((zk - o[:, 2]) / dz > 0) & (col >= 0) & (col < ns) & (row >= 0) & (row < nt)
        cell = np.where(inside, row * ns + col, nt * ns).astype(np.int64)
        new = ~hit & inside & ((zk >= flat[cell]) | (i == n_steps - 1))
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


def _triangles(px, size) -> np.ndarray:
    """Delaunay triangles (k, 3) of distinct integer pixels ``px`` (n, 2) = (u, v), by
    OpenCV's ``Subdiv2D`` (ten times faster than qhull on pixels, whose many co-circular
    quadruples it must resolve); those touching its outer virtual vertices dropped."""
    import cv2

    W, H = size
    sub = cv2.Subdiv2D((0, 0, W, H))
    sub.insert(px.astype(np.float32))
    corners = sub.getTriangleList().reshape(-1, 3, 2)
    inside = np.all((corners[..., 0] >= 0) & (corners[..., 0] < W)
                    & (corners[..., 1] >= 0) & (corners[..., 1] < H), axis=1)
    corners = np.round(corners[inside]).astype(np.int64)
    lookup = np.full(W * H, -1, np.int64)
    lookup[px[:, 1] * W + px[:, 0]] = np.arange(len(px))
    return lookup[corners[..., 1] * W + corners[..., 0]]


def _barycentric(P, x, y):
    """Barycentric coordinates (k, 3) of points (x, y) in triangles ``P`` (k, 3, 2);
    NaN for a degenerate triangle."""
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    den = np.where(den != 0, den, np.nan)
    l0 = ((b[:, 1] - c[:, 1]) * (x - c[:, 0]) + (c[:, 0] - b[:, 0]) * (y - c[:, 1])) / den
    l1 = ((c[:, 1] - a[:, 1]) * (x - c[:, 0]) + (a[:, 0] - c[:, 0]) * (y - c[:, 1])) / den
    return np.stack([l0, l1, 1.0 - l0 - l1], 1)


def _neighbours(tri) -> np.ndarray:
    """(k, 3): the triangle across the edge opposite each corner, -1 on the hull."""
    n = int(tri.max()) + 1
    ends = np.stack([tri[:, [1, 2]], tri[:, [2, 0]], tri[:, [0, 1]]], 1)   # (k, 3, 2)
    key = (ends.min(-1) * n + ends.max(-1)).ravel()
    order = np.argsort(key, kind="stable")
    same = key[order[1:]] == key[order[:-1]]
    out = np.full(key.size, -1, np.int64)
    a, b = order[:-1][same], order[1:][same]
    out[a], out[b] = b // 3, a // 3
    return out.reshape(-1, 3)


def _walk(px, tri, start, x, y, *, max_steps: int = 64):
    """The triangle holding each point (x, y), walking from ``start`` across the edge
    opposite the most negative barycentric coordinate; -1 once a walk leaves the hull.
    Returns (triangle (k,), barycentric coordinates (k, 3))."""
    nbr = _neighbours(tri)
    t = start.copy()
    lam = _barycentric(px[tri[t]].astype(np.float64), x, y)
    for _ in range(max_steps):
        bad = np.nonzero(np.nan_to_num(lam.min(1), nan=-1.0) < -1e-9)[0]
        if not bad.size:
            break
        nxt = nbr[t[bad], np.argmin(np.nan_to_num(lam[bad], nan=0.0), 1)]
        gone = nxt < 0
        t[bad[gone]], lam[bad[gone]] = -1, np.inf
        move = bad[~gone]
        t[move] = nxt[~gone]
        lam[move] = _barycentric(px[tri[t[move]]].astype(np.float64), x[move], y[move])
    lam[t >= 0] = np.where(lam[t >= 0].min(1, keepdims=True) < -1e-9, np.nan, lam[t >= 0])
    return t, lam


def linear_at(px, values, uq, vq, size) -> np.ndarray:
    """Values (n, C) at distinct integer pixels ``px`` (n, 2) interpolated linearly over
    their Delaunay triangulation at integer pixels ``(uq, vq)``: (k, C), NaN outside it.

    OpenCV fills every triangle into an index image, which gives each query a triangle
    at or near its own (a filled outline strays half a pixel); a short walk across
    edges (:func:`_walk`) then finds the one that holds it exactly.
    """
    import cv2

    W, H = size
    out = np.full((len(uq), values.shape[1]), np.nan)
    tri = _triangles(px, size) if len(px) >= 3 else np.zeros((0, 3), np.int64)
    if not len(tri):
        return out
    cover = np.full((H, W), -1, np.int32)
    for i, poly in enumerate(px[tri].astype(np.int32)):
        cv2.fillConvexPoly(cover, poly, i)
    start = cover[vq, uq].astype(np.int64)
    near = np.nonzero(start >= 0)[0]
    t, lam = _walk(px, tri, start[near], uq[near].astype(np.float64),
                   vq[near].astype(np.float64))
    ok = (t >= 0) & np.all(np.isfinite(lam), 1)
    out[near[ok]] = np.einsum("kj,kjc->kc", lam[ok], values[tri[t[ok]]])
    return out


def splat_image(u, v, values, size, *, hit=None, at=None) -> np.ndarray:
    """Average ``values`` (m, C) into the pixels ``(u, v)`` and interpolate between them.

    Between the pixels that rays reached, the values are interpolated linearly over
    their Delaunay triangulation (:func:`linear_at`); outside its hull, pull-push fills
    in. (Pull-push everywhere kept each sample pixel exact in a blur of its coarser
    levels: a pattern of dots; see docs/decisions.md, 'splat: linear interpolation, not
    pull-push everywhere'.)

    ``size`` = (W, H); ``hit`` (m,) bool selects the rays (default: finite ``u``).
    ``at`` = (ui, vi) integer pixels: return only the values there, (k, C), instead of
    the whole image. Returns (H, W, C) float64 (or (k, C)).
    """
    W, H = size
    values = np.asarray(values, np.float64)
    hit = np.isfinite(u) if hit is None else np.asarray(hit, bool)
    idx, mean, weight = _pixel_means(u, v, values, size, hit)
    if at is None:
        vq, uq = np.divmod(np.arange(W * H), W)
    else:
        uq, vq = (np.asarray(a, np.int64) for a in at)
    px = np.stack([idx % W, idx // W], 1)
    out = linear_at(px, mean, uq, vq, size)
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


def blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """A 2-D map (H, W) blurred by a Gaussian of ``sigma`` px, float64: the same as
    ``scipy.ndimage.gaussian_filter`` (mirrored edges, 4 sigma), by OpenCV's separable
    filter, several times faster at the view's 16 px."""
    import cv2

    r = int(4.0 * sigma + 0.5)
    return cv2.GaussianBlur(np.asarray(image, np.float64), (2 * r + 1, 2 * r + 1), sigma,
                            sigmaY=sigma, borderType=cv2.BORDER_REFLECT)


def error_map(errors, u, v, size, *, sigma: float = 16.0):
    """Per-ray errors spread over the image where the rays land: (mean error (H, W),
    ray density (H, W), rays per pixel after a Gaussian of ``sigma`` px)."""
    W, H = size
    ok = np.isfinite(errors)
    ui, vi, inside = _pixels(u, v, ok, size)
    flat = vi[inside] * W + ui[inside]
    total = blur(np.bincount(flat, errors[inside], W * H).reshape(H, W), sigma)
    count = blur(np.bincount(flat, minlength=W * H).astype(np.float64).reshape(H, W), sigma)
    return total / np.maximum(count, 1e-12), count
