"""Automatic totem masks for a photo (``totems masks``).

A spherical totem images as an ellipse close to a circle (the cone of rays tangent to
a sphere cut by the image plane; paper, supplementary "Totem pose initialisation").
Candidates come from a circle Hough transform; each is then refined to the sphere's
silhouette: along rays from the candidate centre, the outermost strong step of the
image (a sub-pixel peak of the radial derivative) marks the edge, an ellipse is fitted
to those points with outliers dropped, and the mask is the set of pixel centres inside
the ellipse. Masks drawn by hand are always preferred: :func:`write_masks` never
replaces them, and writes a picture for a person to check either kind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

N_RAYS = 180
MIN_SUPPORT = 0.6        # fraction of rays that must find the fitted edge
MIN_AXIS_RATIO = 0.75    # a sphere seen by a normal lens: minor/major axis of its image
MIN_SCORE = 2.5          # step across the contour over the gradient around it
MAX_CANDIDATES = 16


def _gray(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 luma of an sRGB image in [0, 1] (or already grey)."""
    img = np.asarray(image, np.float32)
    if img.ndim == 2:
        return img
    return img[..., :3] @ np.array([0.299, 0.587, 0.114], np.float32)


def _candidates(gray: np.ndarray, r_min: float, r_max: float) -> np.ndarray:
    """Circle candidates (m, 3): centre x, y and radius in pixels."""
    import cv2

    g8 = (np.clip(gray, 0, 1) * 255 + 0.5).astype(np.uint8)
    g8 = cv2.GaussianBlur(g8, (0, 0), 1.0)
    found = []
    for param2 in (0.8, 0.6):       # "circle perfectness": strict first, then looser
        c = cv2.HoughCircles(g8, cv2.HOUGH_GRADIENT_ALT, dp=1.5, minDist=r_min,
                             param1=60, param2=param2, minRadius=int(r_min),
                             maxRadius=int(np.ceil(r_max)))
        if c is not None:
            found.append(c.reshape(-1, 3))
        c = cv2.HoughCircles(g8, cv2.HOUGH_GRADIENT, dp=1, minDist=r_min, param1=100,
                             param2=max(10, int(r_min)), minRadius=int(r_min),
                             maxRadius=int(np.ceil(r_max)))
        if c is not None:
            found.append(c.reshape(-1, 3)[:20])
    if not found:
        return np.zeros((0, 3))
    kept = []                           # Hough's order is by votes: keep distinct ones
    for c in np.concatenate(found):
        if all(np.hypot(*(c[:2] - k[:2])) > 0.3 * k[2] or abs(c[2] - k[2]) > 0.3 * k[2]
               for k in kept):
            kept.append(c)
    return np.array(kept[:MAX_CANDIDATES])


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


def _edge_along(p, gx, gy, n: int = 120) -> np.ndarray:
    """|dI/dn| (n,): the image's step across the ellipse p, at n points (colour norm)."""
    import cv2

    pts, nrm = _ellipse_points(p, n)
    X, Y = pts[None, :, 0].astype(np.float32), pts[None, :, 1].astype(np.float32)
    sx = cv2.remap(gx, X, Y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
    sy = cv2.remap(gy, X, Y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
    return np.linalg.norm(sx * nrm[:, :1] + sy * nrm[:, 1:], axis=-1)


def _contrast(p, gx, gy) -> float:
    """Mean step across the ellipse p over the mean step across scaled copies of it."""
    cx, cy, a, b, ang = p
    around = np.concatenate([_edge_along((cx, cy, a * f, b * f, ang), gx, gy)
                             for f in (0.6, 0.7, 0.8, 1.25, 1.4, 1.55)])
    return float(_edge_along(p, gx, gy).mean() / (around.mean() + 1e-6))


def _refine(img: np.ndarray, cand, shape):
    """Fit an ellipse to the silhouette near a candidate circle (cx, cy, r).

    The ellipse (cx, cy, a, b, angle) maximising the mean image step across it is found
    coarse to fine (blur 2, 1, 0.5 px; Nelder-Mead): a whole contour is fitted at once,
    so texture edges that cross it do not pull it away. Returns (ellipse as cv2
    ((cx, cy), (2a, 2b), angle_deg), score) or None. The score is the step across the
    ellipse over the mean gradient near it (a contour, not texture: > 1).
    """
    from scipy.optimize import minimize

    cx, cy, r = (float(v) for v in cand)
    p, best = None, None
    for sigma in (2.0, 1.0, 0.5):
        gx, gy = _gradients(img, sigma)
        starts = [p] if p is not None else [np.array([cx, cy, r * f, r * f, 0.0])
                                            for f in (0.85, 1.0, 1.15)]
        fits = [minimize(lambda q: -_edge_along(q, gx, gy).mean(), s0, method="Nelder-Mead",
                         options=dict(xatol=0.02, fatol=1e-7, maxiter=300)) for s0 in starts]
        best = min(fits, key=lambda f: f.fun)
        p = best.x
        if sigma == 2.0 and _contrast(p, gx, gy) < 0.5 * MIN_SCORE:
            return None                 # no contour here: skip the finer fits
    cx, cy, a, b, ang = p
    a, b = abs(a), abs(b)
    H, W = shape
    if not (np.isfinite(p).all() and min(a, b) > 3) or min(a, b) / max(a, b) < MIN_AXIS_RATIO:
        return None
    R = max(a, b)
    if cx - R < -0.2 * R or cy - R < -0.2 * R or cx + R > W - 1 + 0.2 * R \
            or cy + R > H - 1 + 0.2 * R:
        return None                     # cut by the frame: not a usable totem
    on = _edge_along(p, gx, gy)
    support = np.mean(on > 0.5 * np.median(on))
    score = _contrast(p, gx, gy)
    if support < MIN_SUPPORT:
        return None
    return ((cx, cy), (2 * a, 2 * b), float(np.degrees(ang))), score


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
                  r_max: float | None = None) -> np.ndarray:
    """Propose totem masks for a photo.

    Parameters
    ----------
    image : (H, W, 3) float sRGB in [0, 1] (as ``folder.read_image``).
    n : number of totems in the photo, when known (the best ``n`` are kept); otherwise
        every candidate that passes the checks.
    r_min, r_max : range of totem radii in the image, pixels (default 1.5% to 25% of
        the shorter side).

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
    gray = _gray(img)
    colour = np.ascontiguousarray(img[..., :3])

    found = []                           # (ellipse, score)
    for cand in _candidates(gray, r_min, r_max):
        out = _refine(colour, cand, (H, W))
        if out is None:
            continue
        ell, score = out
        if score < MIN_SCORE:
            continue
        (cx, cy), (A, B), _ = ell
        if not r_min * 0.8 <= 0.25 * (A + B) <= r_max * 1.2:
            continue
        dup = [k for k, (e, _) in enumerate(found)
               if np.hypot(e[0][0] - cx, e[0][1] - cy) < 0.5 * max(e[1]) / 2 + 0.5 * max(A, B) / 2]
        if dup:
            k = dup[0]
            if score > found[k][1]:
                found[k] = (ell, score)
            continue
        found.append((ell, score))
    if not found:
        raise BadInput("no totem found in the photo; draw its masks by hand "
                       "(totem_masks/totem_000.png, white = totem)")
    found.sort(key=lambda t: -t[1])
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
            masks = propose_masks(image, n=n)
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
