"""Automatic totem masks for a photo (``totems masks``).

A spherical totem images as an ellipse close to a circle (the cone of rays tangent to
a sphere cut by the image plane; paper, supplementary "Totem pose initialisation").
Candidates: for every centre and radius, how well the image gradient lines up with the
normal of a ring, in the worst of four quarters (:func:`_candidates`, FFT correlations
on a copy about 240 px high). Each candidate is fitted to the silhouette (an ellipse
maximising that alignment, then the steepest step, sub-pixel) and kept when the fitted
contour is an edge all the way round, scored by the circle score times how much
busier the inside is than the outside (a glass sphere shows a minified scene); the
best ``n`` that do not overlap are the totems, and the mask is the set of pixel centres
inside each ellipse.

With the camera's K (``calib.npy``), the silhouette is fitted as what it is, the image
of the cone of rays tangent to a sphere (three parameters: axis and half-angle, not an
ellipse's five), which no longer settles on an ellipse tilted by texture.

Candidates are ranked by the geometric mean of the coarse ring score and the fitted
contour's support, times the busyness; a candidate only suppresses a shifted copy of
itself of about its size (a large floor circle around a totem no longer hides it).

Measured at 640x480 on rendered scenes, seeds 1-5, with K (totems found at IoU >= 0.95
with the true masks): envmap 20 of 20 (IoU 0.983-0.999); box 15 of 20 (0.96-0.996),
seeds 1, 2 and 4 missing one totem, seed 5 (a checkerboard floor) two: floors of grass,
coins and checkers make rings that outrank a totem whose edge is faint against the floor
it shows, and such a mask must be drawn by hand. Before the ranking and suppression
above (16 candidates): envmap 19 of 20, box 10 of 20. About 20 s a photo.
Masks drawn by hand are always preferred: :func:`write_masks` never
replaces them, and writes a picture for a person to check either kind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

MIN_SUPPORT_FIT = 0.05   # worst-quarter edge alignment of a fitted contour (_support)
MIN_AXIS_RATIO = 0.75    # a sphere seen by a normal lens: minor/major axis of its image
MIN_SCORE = 0.2          # circle score (see _candidates) of a totem when n is not given
MAX_CANDIDATES = 48
WORK_SIZE = 240          # candidates are searched on a copy with this shorter side
GRID_SHIFTS = (-0.1, 0.0, 0.1)              # cone starts: centre shifts, in radii,
GRID_SIZES = (0.85, 0.95, 1.05, 1.15)       # and sizes, times the candidate's radius


def _orientation_field(img: np.ndarray, sigma: float = 1.0):
    """Doubled-angle gradient orientation (cos 2t, sin 2t) of a colour image, each
    pixel weighted by its edge strength saturated at the 90th percentile (so a strong
    texture edge counts no more than a faint silhouette edge)."""
    import cv2

    sm = cv2.GaussianBlur(img, (0, 0), sigma)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    if gx.ndim == 3:
        jxx, jyy, jxy = (gx * gx).sum(-1), (gy * gy).sum(-1), (gx * gy).sum(-1)
    else:
        jxx, jyy, jxy = gx * gx, gy * gy, gx * gy
    e2 = jxx + jyy
    sat = np.minimum(np.sqrt(e2) / (np.percentile(np.sqrt(e2), 90) + 1e-6), 1.0)
    k = sat / (e2 + 1e-12)
    return (jxx - jyy) * k, 2 * jxy * k


def _candidates(img: np.ndarray, r_min: float, r_max: float, keep: int) -> np.ndarray:
    """Circle candidates (m, 4): centre x, y, radius (pixels of ``img``) and score.

    For every centre and radius (7% steps) the mean of cos(2 phi) over a thin ring, phi
    the angle between the image gradient and the ring's normal, is computed in each of
    four sectors (right, bottom, left, top) as FFT correlations. A sphere's silhouette
    is an edge all the way round; floor tiles and texture line up with a circle over a
    part of it only, so the score is the worst sector, less the same measure on rings
    0.78 and 1.25 times as large (texture that lines up with every circle).
    """
    import scipy.fft as sf
    from scipy.ndimage import maximum_filter

    step = 1.07
    radii = r_min * step ** np.arange(
        int(np.log(r_max / r_min) / np.log(step)) + 1)
    i_in = int(np.round(np.log(0.78) / np.log(step)))
    i_out = int(np.round(np.log(1.25) / np.log(step)))
    all_r = radii[0] * step ** np.arange(i_in, len(radii) + i_out)
    a, b = _orientation_field(img)
    H, W = a.shape
    pad = int(np.ceil(all_r.max() + 3 * (0.8 + 0.04 * all_r.max()))) + 1
    Hp, Wp = sf.next_fast_len(H + pad), sf.next_fast_len(W + pad)
    zf = sf.fft2((a - 1j * b).astype(np.complex64), (Hp, Wp))
    y = np.fft.fftfreq(Hp, 1 / Hp)[:, None].astype(np.float32)
    x = np.fft.fftfreq(Wp, 1 / Wp)[None, :].astype(np.float32)
    rho, th = np.hypot(x, y), np.arctan2(y, x)
    e2 = np.exp(-2j * th).astype(np.complex64)
    sectors = [(np.maximum(np.cos(th - 0.5 * np.pi * j), 0) ** 2).astype(np.float32)
               for j in range(4)]
    S = np.empty((len(all_r), 4, H, W), np.float32)
    for k, r in enumerate(all_r):
        near = np.abs(rho - r) < 4 * (0.8 + 0.04 * r)
        w = np.zeros_like(rho)
        w[near] = np.exp(-0.5 * ((rho[near] - r) / (0.8 + 0.04 * r)) ** 2)
        for j, sec in enumerate(sectors):
            ws = w * sec
            kf = sf.fft2(ws * (e2 / ws.sum()))
            S[k, j] = sf.ifft2(zf * np.conj(kf)).real[:H, :W]
    off = -i_in
    C = np.empty((len(radii), H, W), np.float32)
    for k in range(len(radii)):
        c = S[k + off] - np.maximum(np.maximum(S[k + off + i_in], S[k + off + i_out]), 0)
        C[k] = c.min(0) * np.sqrt(radii[k] / 20.0)
    peak = (C == maximum_filter(C, size=(5, 7, 7))) & (C > 0)
    pk = np.argwhere(peak)
    vals = C[tuple(pk.T)]
    out = []
    for i in np.argsort(-vals):
        (k, v, u), r = pk[i], radii[pk[i][0]]
        if any(np.hypot(u - q[0], v - q[1]) < 0.5 * min(r, q[2])
               and max(r, q[2]) < 1.25 * min(r, q[2]) for q in out):
            continue                    # a shifted copy of a better candidate
        out.append((u, v, r, vals[i]))
        if len(out) >= keep:
            break
    return np.array(out, float).reshape(-1, 4)


def _gradients(img: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Image derivatives d/dx, d/dy (per channel, per pixel) after a Gaussian blur."""
    import cv2

    sm = cv2.GaussianBlur(img, (0, 0), sigma)
    return (cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3) / 8.0,
            cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3) / 8.0)


def _ellipse_points(p, n: int = 120):
    """Points (n, 2) and unit outward normals (n, 2) of the ellipse
    p = (cx, cy, a, b, angle_rad) (semi-axes a, b in pixels)."""
    cx, cy, a, b, ang = p
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c, s = np.cos(ang), np.sin(ang)
    ex, ey = a * np.cos(t), b * np.sin(t)
    nx_, ny_ = np.cos(t) / a, np.sin(t) / b
    nx, ny = c * nx_ - s * ny_, s * nx_ + c * ny_
    nn = np.hypot(nx, ny)
    return (np.stack([cx + c * ex - s * ey, cy + s * ex + c * ey], -1),
            np.stack([nx / nn, ny / nn], -1))


def _remap(field, pts) -> np.ndarray:
    """Bilinear samples of an image-shaped ``field`` at points (n, 2) = (x, y) pixels."""
    import cv2

    X = pts[None, :, 0].astype(np.float32)
    Y = pts[None, :, 1].astype(np.float32)
    return cv2.remap(field, X, Y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]


def _edge_at(pts, nrm, gx, gy) -> np.ndarray:
    """|dI/dn| (n,): the image's step across a contour at its points ``pts`` (n, 2) with
    unit normals ``nrm`` (n, 2) (colour norm; ``gx``, ``gy`` from :func:`_gradients`)."""
    sx, sy = _remap(gx, pts), _remap(gy, pts)
    return np.linalg.norm(sx * nrm[:, :1] + sy * nrm[:, 1:], axis=-1)


def _orientation_at(pts, nrm, a, b) -> np.ndarray:
    """cos(2 phi) (n,) at the points of a contour, phi the angle between the image
    gradient and the contour's normal, weighted by saturated edge strength
    (``a``, ``b`` from :func:`_orientation_field`)."""
    c2 = nrm[:, 0] ** 2 - nrm[:, 1] ** 2
    s2 = 2 * nrm[:, 0] * nrm[:, 1]
    return _remap(a, pts) * c2 + _remap(b, pts) * s2


def _edge_along(p, gx, gy, n: int = 120) -> np.ndarray:
    """:func:`_edge_at` on the ellipse p = (cx, cy, a, b, angle_rad)."""
    return _edge_at(*_ellipse_points(p, n), gx, gy)


def _orientation_along(p, a, b, n: int = 180) -> np.ndarray:
    """:func:`_orientation_at` on the ellipse p = (cx, cy, a, b, angle_rad)."""
    return _orientation_at(*_ellipse_points(p, n), a, b)


def _cone_points(q, K, n: int = 180):
    """Image of the cone of rays tangent to a sphere: points (n, 2) and unit outward
    normals (n, 2).

    q = (u0, v0, s): the cone's axis is the ray through pixel (u0, v0), its half-angle
    is arctan(s / f) (s in pixels, f = K[0, 0]); K (3, 3) OpenCV intrinsics. A sphere's
    silhouette is exactly this curve (an ellipse elongated away from the principal
    point), whatever the sphere's radius: three parameters instead of an ellipse's five.
    """
    from scenes.camera import pixel_rays, project

    u0, v0, s = q
    axis = pixel_rays(K, u0, v0)
    h = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(h, axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2

    def image(alpha):
        return project(K, np.cos(alpha) * axis + np.sin(alpha) * ring)

    alpha = np.arctan(abs(s) / K[0, 0])
    pts = image(alpha)
    nrm = image(alpha + 1e-4) - pts
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _refine_cone(field, cand, K, shape, polish=None):
    """:func:`_refine` for a camera of known intrinsics ``K``: the silhouette is fitted
    as a sphere's tangent cone (:func:`_cone_points`, three parameters), by Nelder-Mead
    from the two best of a grid of shifts (:data:`GRID_SHIFTS` radii) and sizes
    (:data:`GRID_SIZES`) around the candidate circle. Returns the cone's image as a
    cv2 ellipse, or None (as :func:`_refine`).
    """
    import cv2
    from scipy.optimize import minimize

    a_f, b_f = field
    cx, cy, r = (float(v) for v in cand[:3])

    def cost(q):
        return -_orientation_at(*_cone_points(q, K), a_f, b_f).mean() if q[2] > 2 else 0.0

    grid = [np.array([cx + du * r, cy + dv * r, k * r]) for du in GRID_SHIFTS
            for dv in GRID_SHIFTS for k in GRID_SIZES]
    starts = sorted(grid, key=cost)[:2]
    fits = [minimize(cost, q0, method="Nelder-Mead",
                     options=dict(xatol=0.02, fatol=1e-6, maxiter=300)) for q0 in starts]
    q = min(fits, key=lambda f: f.fun).x
    if polish is not None:              # sub-pixel: the steepest step near that contour
        gx, gy = polish
        q = minimize(lambda q: -_edge_at(*_cone_points(q, K), gx, gy).mean()
                     if q[2] > 2 else 0.0, q, method="Nelder-Mead",
                     options=dict(xatol=0.01, fatol=1e-8, maxiter=300)).x
    if not np.isfinite(q).all():
        return None
    (ex, ey), (A, B), ang = cv2.fitEllipse(_cone_points(q, K, 90)[0].astype(np.float32))
    ell = (float(ex), float(ey), A / 2.0, B / 2.0, np.radians(ang))
    return _accept(ell, cand, shape)


def _refine(field, cand, shape, polish=None):
    """Fit an ellipse to the silhouette near a candidate circle (cx, cy, r).

    The ellipse (cx, cy, a, b, angle) along which the image gradient is best aligned
    with the normal (saturated strength, :func:`_orientation_along`) is found by
    Nelder-Mead from the circle: a whole contour is fitted at once, so texture edges
    that cross it do not pull it away. With ``polish`` = (d/dx, d/dy) of the image
    (:func:`_gradients`), the ellipse is then moved to the largest mean step across it
    (sub-pixel; the saturated alignment is flat across a rim a few pixels wide).
    Returns the ellipse as cv2 ((cx, cy), (2a, 2b), angle_deg), or None when the fit
    leaves the candidate, is not sphere-like or is cut by the frame.
    """
    from scipy.optimize import minimize

    a_f, b_f = field
    cx, cy, r = (float(v) for v in cand[:3])
    p0 = np.array([cx, cy, r, r * 1.01, 0.1])
    p = minimize(lambda q: -_orientation_along(q, a_f, b_f).mean()
                 if min(abs(q[2]), abs(q[3])) > 2 else 0.0, p0, method="Nelder-Mead",
                 options=dict(xatol=0.02, fatol=1e-6, maxiter=600)).x
    if polish is not None:              # sub-pixel: the steepest step near that contour
        gx, gy = polish
        p = minimize(lambda q: -_edge_along(q, gx, gy, 180).mean()
                     if min(abs(q[2]), abs(q[3])) > 2 else 0.0, p, method="Nelder-Mead",
                     options=dict(xatol=0.01, fatol=1e-8, maxiter=600)).x
    return _accept(p, cand, shape)


def _accept(p, cand, shape):
    """The fitted ellipse p = (cx, cy, a, b, angle_rad) as cv2 ((cx, cy), (2a, 2b),
    angle_deg), or None when it left the candidate circle (cx, cy, r), is not
    sphere-like, or is cut by the frame of ``shape`` (H, W)."""
    cx, cy, a, b, ang = p
    a, b = abs(a), abs(b)
    r = float(cand[2])
    H, W = shape
    if not (np.isfinite(p).all() and min(a, b) > 3) or min(a, b) / max(a, b) < MIN_AXIS_RATIO:
        return None
    if np.hypot(cx - cand[0], cy - cand[1]) > 0.4 * r or not 0.75 < (a + b) / (2 * r) < 1.3:
        return None                     # wandered off to another contour
    R = max(a, b)
    if cx - R < -0.2 * R or cy - R < -0.2 * R or cx + R > W - 1 + 0.2 * R \
            or cy + R > H - 1 + 0.2 * R:
        return None                     # cut by the frame: not a usable totem
    return ((cx, cy), (2 * a, 2 * b), float(np.degrees(ang)))


def _support(ell, field) -> float:
    """Alignment of the gradient with the normal of the ellipse ell (cv2 form), less the
    same on copies 0.78 and 1.25 times as large, in the worst of four quarters: > 0
    when the fitted contour is an edge all the way round."""
    (cx, cy), (A, B), ang = ell
    a, b, t = A / 2.0, B / 2.0, np.radians(ang)
    on = _orientation_along((cx, cy, a, b, t), *field, 120).reshape(4, -1).mean(1)
    near = np.stack([_orientation_along((cx, cy, a * f, b * f, t), *field, 120)
                     .reshape(4, -1).mean(1) for f in (0.78, 1.25)]).max(0)
    return float((on - np.maximum(near, 0)).min())


def _busyness(ell, edge: np.ndarray) -> float:
    """Mean gradient magnitude ``edge`` inside the ellipse (0.8 of its size) over that
    in the ring 1.2-1.8 times its size. A glass sphere shows a minified view of the
    scene, busier than the floor around it; a circle inscribed in a floor tile or an
    opaque ball is smoother inside than out."""
    (cx, cy), (A, B), ang = ell
    R = 0.9 * max(A, B)
    H, W = edge.shape
    x0, x1 = int(max(0, cx - R)), int(min(W, cx + R + 1))
    y0, y1 = int(max(0, cy - R)), int(min(H, cy + R + 1))
    v, u = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
    x, y = c * (u - cx) + s * (v - cy), -s * (u - cx) + c * (v - cy)
    rho = np.hypot(x / (A / 2.0), y / (B / 2.0))
    e = edge[y0:y1, x0:x1]
    inner, outer = e[rho < 0.8], e[(rho > 1.2) & (rho < 1.8)]
    if inner.size == 0 or outer.size == 0:
        return 1.0
    return float(inner.mean() / (outer.mean() + 1e-6))


def ellipse_mask(ell, shape) -> np.ndarray:
    """(H, W) bool: pixel centres (u, v) inside the ellipse ((cx, cy), (A, B), angle_deg)
    (full axes A, B in pixels, as cv2)."""
    (cx, cy), (A, B), ang = ell
    H, W = shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
    x, y = c * (u - cx) + s * (v - cy), -s * (u - cx) + c * (v - cy)
    return (x / (A / 2.0)) ** 2 + (y / (B / 2.0)) ** 2 < 1.0


def propose_masks(image: np.ndarray, *, n: int | None = None, r_min: float | None = None,
                  r_max: float | None = None, K: np.ndarray | None = None) -> np.ndarray:
    """Propose totem masks for a photo.

    Parameters
    ----------
    image : (H, W, 3) float sRGB in [0, 1] (as ``folder.read_image``).
    n : number of totems in the photo, when known (the best ``n`` are kept); otherwise
        every candidate that passes the checks.
    r_min, r_max : range of totem radii in the image, pixels (default 1.5% to 25% of
        the shorter side).
    K : (3, 3) OpenCV intrinsics of the photo, when known: each silhouette is then
        fitted as a sphere's tangent cone (3 parameters, :func:`_refine_cone`) rather
        than a free ellipse (5).

    Returns
    -------
    (n, H, W) bool, left to right by centroid x.

    Raises BadInput when no totem (or fewer than ``n``) is found.
    """
    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[2] < 3:
        raise BadInput("propose_masks needs an (H, W, 3) colour photo")
    H, W = img.shape[:2]
    short = min(H, W)
    r_min = max(5.0, 0.015 * short) if r_min is None else float(r_min)
    r_max = 0.25 * short if r_max is None else float(r_max)
    import cv2

    colour = np.ascontiguousarray(img[..., :3])
    scale = min(1.0, WORK_SIZE / short)        # candidates on a small copy, fits at full size
    small = colour if scale == 1.0 else cv2.resize(colour, None, fx=scale, fy=scale,
                                                   interpolation=cv2.INTER_AREA)
    keep = MAX_CANDIDATES if n is None else max(MAX_CANDIDATES, 4 * n)
    cands = _candidates(small, max(4.0, r_min * scale), r_max * scale, keep)
    cands[:, :3] /= scale

    if n is None:
        cands = cands[cands[:, 3] >= MIN_SCORE]
    K = None if K is None else np.asarray(K, float)
    field = _orientation_field(colour, 1.0)
    polish = _gradients(colour, 0.7)
    edge = np.sqrt((polish[0] ** 2 + polish[1] ** 2).sum(-1))
    found = []                           # (ellipse, score), best first
    for cand in cands:
        ell = (_refine(field, cand, (H, W), polish) if K is None
               else _refine_cone(field, cand, K, (H, W), polish))
        if ell is None:                  # keep the circle when the fit fails
            ell = ((cand[0], cand[1]), (2 * cand[2], 2 * cand[2]), 0.0)
        support = _support(ell, field)
        if support >= MIN_SUPPORT_FIT:  # both the coarse ring score and the fitted edge
            score = np.sqrt(max(cand[3], 0.0) * support)
            found.append((ell, score * np.clip(_busyness(ell, edge), 0.5, 1.3)))
    found.sort(key=lambda t: -t[1])
    chosen = []                          # greedy: best first, no two overlapping
    for ell, score in found:
        (cx, cy), (A, B), _ = ell
        if all(np.hypot(e[0][0] - cx, e[0][1] - cy) > 0.5 * (max(e[1]) + max(A, B)) * 0.9
               for e, _ in chosen):
            chosen.append((ell, score))
    found = chosen
    if not found:
        raise BadInput("no totem found in the photo; draw its masks by hand "
                       "(totem_masks/totem_000.png, white = totem)")
    if n is not None:
        if len(found) < n:
            raise BadInput(f"found {len(found)} totems but {n} were expected; draw the "
                           f"missing masks by hand (totem_masks/, white = totem)")
        found = found[:n]
    found.sort(key=lambda t: t[0][0][0])
    return np.stack([ellipse_mask(e, (H, W)) for e, _ in found])


def draw_check(image: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """The photo with each mask's outline and number drawn on it, (H, W, 3) uint8."""
    import cv2

    out = (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8).copy()
    H, W = out.shape[:2]
    thick = max(1, round(min(H, W) / 400))
    colours = [(255, 40, 40), (40, 220, 40), (60, 120, 255), (255, 220, 0), (255, 0, 255),
               (0, 230, 230)]
    for j, m in enumerate(masks):
        contours, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_NONE)
        col = colours[j % len(colours)]
        cv2.drawContours(out, contours, -1, col, thick, lineType=cv2.LINE_AA)
        ys, xs = np.nonzero(m)
        cv2.putText(out, str(j), (int(xs.mean()) - 4 * thick, int(ys.min()) - 3 * thick),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4 * thick, col, thick, cv2.LINE_AA)
    return out


def _scene_K(scene_dir) -> np.ndarray | None:
    """The scene's intrinsics from its calib.npy (or one above it), or None."""
    try:
        return folder.read_calib(folder.find_calib(scene_dir))["mtx"]
    except BadInput:
        return None


def write_masks(scene_dir, masks: np.ndarray | None = None, *, n: int | None = None) -> dict:
    """Give a scene folder totem masks, unless it has some, and a picture to check them.

    ``totem_masks/*.png`` already there (e.g. drawn by hand) are used as given, never
    overwritten; otherwise ``masks`` (or :func:`propose_masks` of the photo) are written
    as ``totem_masks/totem_000.png``... (the folder appears complete or not at all).
    ``totem_masks_check.png`` (outlines over the photo) is (re)written either way.

    Returns {"proposed": bool, "n": int, "masks": [paths], "check": path}.
    """
    scene_dir = Path(scene_dir)
    image = folder.read_image(scene_dir / "image.png", what="photo")
    mask_dir = scene_dir / "totem_masks"
    existing = sorted(mask_dir.glob("*.png")) if mask_dir.is_dir() else []
    if existing:
        masks = np.stack([folder.read_mask(f, what="totem mask") for f in existing])
        if masks.shape[1:] != image.shape[:2]:
            raise BadInput(f"the masks in {mask_dir} are not the size of the photo")
        order = np.argsort([np.nonzero(m)[1].mean() if m.any() else 0 for m in masks],
                           kind="stable")
        masks, files, proposed = masks[order], [existing[i] for i in order], False
    else:
        if masks is None:
            masks = propose_masks(image, n=n, K=_scene_K(scene_dir))
        masks = np.asarray(masks, bool)
        if masks.ndim != 3 or masks.shape[1:] != image.shape[:2]:
            raise BadInput("masks must be (n, H, W) the size of the photo")
        with folder.staged_folder(mask_dir) as tmp:
            for j, m in enumerate(masks):
                folder.write_image(tmp / f"totem_{j:03d}.png", m)
        files = [mask_dir / f"totem_{j:03d}.png" for j in range(len(masks))]
        proposed = True
    check = scene_dir / "totem_masks_check.png"
    folder.write_image(check, draw_check(image, masks))
    return {"proposed": proposed, "n": int(len(masks)), "masks": [str(f) for f in files],
            "check": str(check)}
