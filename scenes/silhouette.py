"""A sphere's outline in the image and the image's edges along it.

The outline of a spherical totem is the image of the cone of rays tangent to it: with
the camera's K, three parameters (:func:`cone_points`); without it, an ellipse
(:func:`ellipse_points`). The cone fitted to an outline's points
(:func:`cone_from_outline`) and a radius give the sphere (:func:`sphere_from_circle`).
The image is read along either by its step across the contour (:func:`edge_at`, from
:func:`gradients`) and by how well its gradient lines up with the contour's normal
(:func:`orientation_at`, from :func:`orientation_field`). Pixel coordinates are
OpenCV's (pixel centres at integers), (x, y) = (column, row).
"""

from __future__ import annotations

import numpy as np

__all__ = ["orientation_field", "gradients", "ellipse_points", "remap", "edge_at",
           "orientation_at", "edge_along", "orientation_along", "cone_points",
           "cones_points", "cone_fit_q", "cone_ellipse", "cone_from_outline",
           "sphere_from_circle",
           "ellipse_mask", "MIN_AXIS_RATIO", "GRID_SHIFTS", "GRID_SIZES", "fit_cone",
           "fit_ellipse", "sphere_like", "support", "busyness", "alignment", "arc_support"]

MIN_AXIS_RATIO = 0.75    # a sphere seen by a normal lens: minor/major axis of its image
GRID_SHIFTS = (-0.1, 0.0, 0.1)              # cone starts: centre shifts, in radii,
GRID_SIZES = (0.85, 0.95, 1.05, 1.15)       # and sizes, times the candidate's radius


def orientation_field(img: np.ndarray, sigma: float = 1.0):
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


def gradients(img: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Image derivatives d/dx, d/dy (per channel, per pixel) after a Gaussian blur."""
    import cv2

    sm = cv2.GaussianBlur(img, (0, 0), sigma)
    return (cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3) / 8.0,
            cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3) / 8.0)


def ellipse_points(p, n: int = 120):
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


def remap(field, pts) -> np.ndarray:
    """Bilinear samples of an image-shaped ``field`` at points (n, 2) = (x, y) pixels."""
    import cv2

    X = pts[None, :, 0].astype(np.float32)
    Y = pts[None, :, 1].astype(np.float32)
    return cv2.remap(field, X, Y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]


def edge_at(pts, nrm, gx, gy) -> np.ndarray:
    """|dI/dn| (n,): the image's step across a contour at its points ``pts`` (n, 2) with
    unit normals ``nrm`` (n, 2) (colour norm; ``gx``, ``gy`` from :func:`gradients`)."""
    sx, sy = remap(gx, pts), remap(gy, pts)
    return np.linalg.norm(sx * nrm[:, :1] + sy * nrm[:, 1:], axis=-1)


def orientation_at(pts, nrm, a, b) -> np.ndarray:
    """cos(2 phi) (n,) at the points of a contour, phi the angle between the image
    gradient and the contour's normal, weighted by saturated edge strength
    (``a``, ``b`` from :func:`orientation_field`)."""
    c2 = nrm[:, 0] ** 2 - nrm[:, 1] ** 2
    s2 = 2 * nrm[:, 0] * nrm[:, 1]
    return remap(a, pts) * c2 + remap(b, pts) * s2


def edge_along(p, gx, gy, n: int = 120) -> np.ndarray:
    """:func:`edge_at` on the ellipse p = (cx, cy, a, b, angle_rad)."""
    return edge_at(*ellipse_points(p, n), gx, gy)


def orientation_along(p, a, b, n: int = 180) -> np.ndarray:
    """:func:`orientation_at` on the ellipse p = (cx, cy, a, b, angle_rad)."""
    return orientation_at(*ellipse_points(p, n), a, b)


def cone_points(q, K, n: int = 180):
    """Image of the cone of rays tangent to a sphere: points (n, 2) and unit outward
    normals (n, 2).

    q = (u0, v0, s): the cone's axis is the ray through pixel (u0, v0), its half-angle
    is arctan(s / f) (s in pixels, f = K[0, 0]); K (3, 3) OpenCV intrinsics. A sphere's
    silhouette is exactly this curve (an ellipse elongated away from the principal
    point), whatever the sphere's radius: three parameters instead of an ellipse's five.
    """
    pts, nrm = cones_points(np.asarray(q, np.float64)[None], K, n)
    return pts[0], nrm[0]


def cones_points(qs, K, n: int = 180):
    """:func:`cone_points` of many cones ``qs`` (m, 3) at once: points (m, n, 2) and unit
    outward normals (m, n, 2), pixels."""
    from scenes.camera import pixel_rays, project

    qs = np.asarray(qs, np.float64).reshape(-1, 3)
    K = np.asarray(K, np.float64)
    axis = pixel_rays(K, qs[:, 0], qs[:, 1])                                # (m, 3)
    h = np.where((np.abs(axis[:, 1]) < 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    e1 = np.cross(h, axis)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.cos(t)[None, :, None] * e1[:, None] + np.sin(t)[None, :, None] * e2[:, None]

    def image(alpha):
        X = np.cos(alpha)[:, None, None] * axis[:, None] + np.sin(alpha)[:, None, None] * ring
        return project(K, X.reshape(-1, 3)).reshape(len(qs), n, 2)

    alpha = np.arctan(np.abs(qs[:, 2]) / K[0, 0])
    pts = image(alpha)
    nrm = image(alpha + 1e-4) - pts
    return pts, nrm / np.linalg.norm(nrm, axis=2, keepdims=True)


def ellipse_mask(ell, shape) -> np.ndarray:
    """(H, W) bool: pixel centres (u, v) inside the ellipse ((cx, cy), (A, B), angle_deg)
    (full axes A, B in pixels, as cv2)."""
    (cx, cy), (A, B), ang = ell
    H, W = shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
    x, y = c * (u - cx) + s * (v - cy), -s * (u - cx) + c * (v - cy)
    return (x / (A / 2.0)) ** 2 + (y / (B / 2.0)) ** 2 < 1.0


# --------------------------------------------------------------------------- fitting

def fit_cone(field, cand, K, shape, polish=None):
    """:func:`fit_ellipse` for a camera of known intrinsics ``K``: the silhouette is fitted
    as a sphere's tangent cone (:func:`cone_points`, three parameters), by Nelder-Mead
    from the two best of a grid of shifts (:data:`GRID_SHIFTS` radii) and sizes
    (:data:`GRID_SIZES`) around the candidate circle. Returns the cone's image as a
    cv2 ellipse, or None (as :func:`fit_ellipse`).
    """
    q, _ = cone_fit_q(field, cand, K, polish, shifts=GRID_SHIFTS, sizes=GRID_SIZES,
                      keep=2, n=180)
    if not np.isfinite(q).all():
        return None
    return sphere_like(cone_ellipse(q, K), cand, shape)


def cone_fit_q(field, cand, K, polish, *, shifts, sizes, keep: int, n: int):
    """The tangent cone q = (u0, v0, s) whose image's normals the gradient ``field``
    lines up with best, by Nelder-Mead from the ``keep`` best of the grid ``shifts``
    (radii) x ``shifts`` x ``sizes`` (times the radius) around the circle ``cand``
    (cx, cy, r), each outline read at ``n`` points; then, with ``polish`` (d/dx, d/dy
    of :func:`gradients`), moved to the steepest mean step across it. Returns (q, the
    alignment before that step)."""
    from scipy.optimize import minimize

    cx, cy, r = (float(v) for v in cand[:3])

    def alignment_of(qs):
        qs = np.asarray(qs, np.float64).reshape(-1, 3)
        pts, nrm = cones_points(qs, K, n)
        al = orientation_at(pts.reshape(-1, 2), nrm.reshape(-1, 2), *field)
        return np.where(qs[:, 2] > 2, al.reshape(len(qs), n).mean(1), 0.0)

    grid = np.array([(cx + du * r, cy + dv * r, k * r) for du in shifts
                     for dv in shifts for k in sizes])
    starts = grid[np.argsort(-alignment_of(grid), kind="stable")[:keep]]
    fits = [minimize(lambda q: -alignment_of(q)[0], q0, method="Nelder-Mead",
                     options=dict(xatol=0.02, fatol=1e-6, maxiter=300)) for q0 in starts]
    best = min(fits, key=lambda f: f.fun)
    q = best.x
    if polish is not None:              # sub-pixel: the steepest step near that contour
        gx, gy = polish
        q = minimize(lambda q: -edge_at(*cone_points(q, K), gx, gy).mean()
                     if q[2] > 2 else 0.0, q, method="Nelder-Mead",
                     options=dict(xatol=0.01, fatol=1e-8, maxiter=300)).x
    return q, -float(best.fun)


def cone_ellipse(q, K):
    """The image of the tangent cone ``q`` as (cx, cy, a, b, angle_rad), pixels: the
    ellipse cv2 fits to 90 of its points."""
    import cv2

    (ex, ey), (A, B), ang = cv2.fitEllipse(cone_points(q, K, 90)[0].astype(np.float32))
    return (float(ex), float(ey), A / 2.0, B / 2.0, np.radians(ang))


def cone_from_outline(uv, K) -> np.ndarray:
    """The tangent cone q = (u0, v0, s) whose image passes nearest the outline points
    ``uv`` (m, 2) pixels (e.g. :func:`scenes.masks.outline` of a totem's mask), ``K``
    (3, 3) OpenCV intrinsics.

    Least squares on the angle between each point's ray and the cone: ``angle(d_k, a) -
    arctan(s / fx)``, ``a`` the ray through pixel (u0, v0), started from the points'
    mean and mean distance to it. The cone is the sphere's whatever its radius
    (:func:`sphere_from_circle` gives the centre for a radius).

    Returns (3,) float64: u0, v0, s in pixels.
    """
    from scipy.optimize import least_squares

    from scenes.camera import pixel_rays

    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    K = np.asarray(K, np.float64)
    d = pixel_rays(K, uv[:, 0], uv[:, 1])
    c = uv.mean(0)
    q0 = np.array([c[0], c[1], np.linalg.norm(uv - c, axis=1).mean()])

    def residual(q):
        axis = pixel_rays(K, q[0], q[1])
        return np.arccos(np.clip(d @ axis, -1.0, 1.0)) - np.arctan(abs(q[2]) / K[0, 0])

    q = least_squares(residual, q0, method="lm", xtol=1e-12, ftol=1e-12).x
    return np.array([q[0], q[1], abs(q[2])])


def sphere_from_circle(u0: float, v0: float, s: float, K, R: float) -> np.ndarray:
    """The centre (3,) metres, camera frame, of the sphere of radius ``R`` (metres) whose
    tangent cone has its axis through pixel (``u0``, ``v0``) and half-angle
    ``arctan(s / fx)`` (``s`` pixels, as :func:`cone_points`): ``|P| = R / sin(alpha)``.
    A sphere ``k`` times as large ``k`` times as far has the same outline."""
    from scenes.camera import pixel_rays

    K = np.asarray(K, np.float64)
    axis = pixel_rays(K, np.float64(u0), np.float64(v0))
    alpha = np.arctan(abs(float(s)) / K[0, 0])
    return axis * (R / np.sin(alpha))


def fit_ellipse(field, cand, shape, polish=None):
    """Fit an ellipse to the silhouette near a candidate circle (cx, cy, r).

    The ellipse (cx, cy, a, b, angle) along which the image gradient is best aligned
    with the normal (saturated strength, :func:`orientation_along`) is found by
    Nelder-Mead from the circle: a whole contour is fitted at once, so texture edges
    that cross it do not pull it away. With ``polish`` = (d/dx, d/dy) of the image
    (:func:`gradients`), the ellipse is then moved to the largest mean step across it
    (sub-pixel; the saturated alignment is flat across a rim a few pixels wide).
    Returns the ellipse as cv2 ((cx, cy), (2a, 2b), angle_deg), or None when the fit
    leaves the candidate, is not sphere-like or is cut by the frame.
    """
    from scipy.optimize import minimize

    a_f, b_f = field
    cx, cy, r = (float(v) for v in cand[:3])
    p0 = np.array([cx, cy, r, r * 1.01, 0.1])
    p = minimize(lambda q: -orientation_along(q, a_f, b_f).mean()
                 if min(abs(q[2]), abs(q[3])) > 2 else 0.0, p0, method="Nelder-Mead",
                 options=dict(xatol=0.02, fatol=1e-6, maxiter=600)).x
    if polish is not None:              # sub-pixel: the steepest step near that contour
        gx, gy = polish
        p = minimize(lambda q: -edge_along(q, gx, gy, 180).mean()
                     if min(abs(q[2]), abs(q[3])) > 2 else 0.0, p, method="Nelder-Mead",
                     options=dict(xatol=0.01, fatol=1e-8, maxiter=600)).x
    return sphere_like(p, cand, shape)


def sphere_like(p, cand, shape):
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


def support(ell, field) -> float:
    """Alignment of the gradient with the normal of the ellipse ell (cv2 form), less the
    same on copies 0.78 and 1.25 times as large, in the worst of four quarters: > 0
    when the fitted contour is an edge all the way round."""
    (cx, cy), (A, B), ang = ell
    a, b, t = A / 2.0, B / 2.0, np.radians(ang)
    on = orientation_along((cx, cy, a, b, t), *field, 120).reshape(4, -1).mean(1)
    near = np.stack([orientation_along((cx, cy, a * f, b * f, t), *field, 120)
                     .reshape(4, -1).mean(1) for f in (0.78, 1.25)]).max(0)
    return float((on - np.maximum(near, 0)).min())


def busyness(ell, edge: np.ndarray) -> float:
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


def alignment(ell, field, n: int = 180) -> float:
    """Mean of cos(2 phi) along the ellipse ell (cv2 form), phi the angle between the
    image gradient and the ellipse's normal (``field`` from :func:`orientation_field`):
    near 1 for an outline that is an edge all the way round, near 0 on texture."""
    (cx, cy), (A, B), ang = ell
    return float(orientation_along((cx, cy, A / 2.0, B / 2.0, np.radians(ang)), *field,
                                   n).mean())


def arc_support(ell, field, *, parts: int = 8, missing: int = 1) -> float:
    """:func:`support` that lets ``missing`` of ``parts`` arcs go: the alignment along
    each arc of the ellipse ell (cv2 form) less that on copies 0.78 and 1.25 times as
    large, the (``missing`` + 1)-th worst arc. A totem's rim can vanish over an arc
    where the glass shows the same floor as beside it, or where it touches the floor."""
    (cx, cy), (A, B), ang = ell
    a, b, t = A / 2.0, B / 2.0, np.radians(ang)
    n = 20 * parts
    on = orientation_along((cx, cy, a, b, t), *field, n).reshape(parts, -1).mean(1)
    near = np.stack([orientation_along((cx, cy, a * f, b * f, t), *field, n)
                     .reshape(parts, -1).mean(1) for f in (0.78, 1.25)]).max(0)
    return float(np.sort(on - np.maximum(near, 0))[missing])
