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
itself of about its size (a large floor circle around a totem no longer hides it; see
docs/decisions.md, 'masks: ranking by ring score and contour support').

With K and the key's index of refraction, each fitted outline's score is also scaled by
what a glass sphere of the key would show there (:func:`glass_factor`,
:mod:`scenes.photo.glass`): the rest of the photo, inverted; an opaque ball or a ring of
texture shows something else. Then the best :data:`REFIT` fits are re-fitted over a wide
basin around them (:mod:`scenes.photo.cone_fit`; a cone fit settles on the nearest contour,
often the inner edge of the rim's dark band) and ranked by their outline's alignment times
:func:`glass_factor` (:func:`_fitted_keyed`). When only the key's list says how many
totems there are, the best that many whose final score reaches :data:`MIN_KEYED` and
glass score :data:`MIN_GLASS` count (without K, those whose ring score reaches
:data:`MIN_SCORE`; see docs/decisions.md, 'masks: what the key predicts through the
glass' and 'masks: a wide fit around each candidate').

Floors of grass, coins and checkers make rings that can outrank a totem whose edge is
faint against the floor it shows; such a mask must be drawn by hand.
Masks drawn by hand are always preferred: :func:`write_masks` never
replaces them, and writes a picture for a person to check either kind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes import folder, silhouette
from scenes.errors import BadInput
from scenes.photo import cone_fit, glass

__all__ = ["find_totems", "ellipse_masks", "radius_range", "glass_factor",
           "MIN_SUPPORT_FIT", "MIN_SCORE", "MAX_CANDIDATES", "WORK_SIZE", "GLASS_WEIGHT",
           "GLASS_RANK", "REFIT", "MIN_KEYED", "MIN_GLASS", "HINT_POOL", "HINT_FITS",
           "propose_masks", "draw_check", "write_masks"]

MIN_SUPPORT_FIT = 0.05   # worst-quarter edge alignment of a fitted contour (silhouette.support)
MIN_SCORE = 0.2          # circle score (see _candidates) of a totem when n is not given
MAX_CANDIDATES = 48
WORK_SIZE = 240          # candidates are searched on a copy with this shorter side
GLASS_WEIGHT = 2.0       # a fitted outline's alignment times exp(GLASS_WEIGHT * glass score)
GLASS_RANK = 4.0         # first ranking of the fits: arc support times exp(GLASS_RANK * g)
REFIT = 24               # the best this many first fits are re-fitted over a wide basin
MIN_KEYED = 0.7          # final score of a totem when only the key's list says how many,
MIN_GLASS = 0.05         # and its glass score (glass.glass_scores)
HINT_POOL = 400          # ring candidates searched around a hint,
HINT_FITS = 16           # the best this many that hold it fitted


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
    a, b = silhouette.orientation_field(img)
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


def propose_masks(image: np.ndarray, *, n: int | None = None, r_min: float | None = None,
                  r_max: float | None = None, K: np.ndarray | None = None,
                  hints=None, ior=None) -> np.ndarray:
    """Propose totem masks for a photo.

    Parameters
    ----------
    image : (H, W, 3) float sRGB in [0, 1] (as ``folder.read_image``).
    n : number of totems in the photo, when known (the best ``n`` are kept); otherwise
        every candidate that passes the checks.
    r_min, r_max : range of totem radii in the image, pixels (default 1.5% to 25% of
        the shorter side).
    K : (3, 3) OpenCV intrinsics of the photo, when known: each silhouette is then
        fitted as a sphere's tangent cone (3 parameters, :func:`silhouette.fit_cone`) rather
        than a free ellipse (5).
    hints : (k, 2) pixel points (x, y), one inside each totem: the search is made
        around each (one totem a hint) instead of over the whole photo.
    ior : the key's indices of refraction; with ``K``, candidates are also ranked by
        what a glass sphere of the key would show inside them (:func:`glass_factor`).

    Returns
    -------
    (n, H, W) bool, left to right by centroid x.

    Raises BadInput when no totem (or fewer than ``n``) is found.
    """
    found = find_totems(image, n=n, r_min=r_min, r_max=r_max, K=K, hints=hints, ior=ior)
    if not found:
        raise BadInput("no totem found in the photo; draw its masks by hand "
                       "(totem_masks/totem_000.png, white = totem)")
    if n is not None and len(found) < n:
        raise BadInput(f"found {len(found)} totems but {n} were expected; draw the "
                       f"missing masks by hand (totem_masks/, white = totem)")
    return ellipse_masks(found, np.shape(image)[:2])


def radius_range(shape, r_min: float | None = None, r_max: float | None = None):
    """The searched totem radii in pixels: by default 1.5% (at least 5 px) to 25% of
    the photo's shorter side."""
    short = min(shape[:2])
    return (max(5.0, 0.015 * short) if r_min is None else float(r_min),
            0.25 * short if r_max is None else float(r_max))


def find_totems(image: np.ndarray, *, n: int | None = None, r_min: float | None = None,
                r_max: float | None = None, K: np.ndarray | None = None,
                hints=None, ior=None, min_score: float | None = None) -> list:
    """The totems found in a photo, as (cv2 ellipse, score), left to right; at most
    ``n`` (every one that passes the checks when None), or one per hint (see
    :func:`propose_masks` for the parameters). May find fewer than asked.

    ``ior``: the key's indices of refraction (one, or one per totem); with ``K`` each
    fitted outline's score is scaled by what the key predicts through the glass
    (:func:`glass_factor`). ``min_score``: only outlines whose final score reaches it
    count (:data:`MIN_KEYED` when only the key's list says how many there are), and
    with ``K`` and ``ior`` only those whose glass score reaches :data:`MIN_GLASS` (the
    glass shows something of the photo)."""
    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[2] < 3:
        raise BadInput("propose_masks needs an (H, W, 3) colour photo")
    colour = np.ascontiguousarray(img[..., :3])
    r_min, r_max = radius_range(colour.shape, r_min, r_max)
    K = None if K is None else np.asarray(K, float)
    if hints is not None and len(hints):
        found = [_best_near(colour, h, r_min, r_max, K, ior)
                 for h in np.asarray(hints, float)]
        found = [f for f in found if f is not None]
    else:
        keep = MAX_CANDIDATES if n is None else max(MAX_CANDIDATES, 4 * n)
        cands = _search(colour, r_min, r_max, keep)
        if n is None:
            cands = cands[cands[:, 3] >= MIN_SCORE]
        found = _fitted(colour, cands, K, ior)
        if min_score is not None:
            found = [f for f in found if f[1] >= min_score]
            if found and K is not None and ior is not None:   # and shows the photo
                g = glass.outline_scores(colour, [e for e, _ in found], K, ior)
                found = [f for f, gi in zip(found, g) if gi >= MIN_GLASS]
        found = _apart(found)
        found = found if n is None else found[:n]
    return sorted(found, key=lambda t: t[0][0][0])


def ellipse_masks(found, shape) -> np.ndarray:
    """(k, H, W) bool masks of :func:`find_totems`'s ellipses."""
    H, W = shape[:2]
    return np.stack([silhouette.ellipse_mask(e, (H, W)) for e, _ in found]) if found \
        else np.zeros((0, H, W), bool)


def _search(colour, r_min, r_max, keep) -> np.ndarray:
    """Circle candidates (m, 4) of :func:`_candidates`, on a copy about
    :data:`WORK_SIZE` px high, in the photo's pixels."""
    import cv2

    scale = min(1.0, WORK_SIZE / min(colour.shape[:2]))
    small = colour if scale == 1.0 else cv2.resize(colour, None, fx=scale, fy=scale,
                                                   interpolation=cv2.INTER_AREA)
    cands = _candidates(small, max(4.0, r_min * scale), r_max * scale, keep)
    cands[:, :3] /= scale
    return cands


def _edge_fields(colour):
    """What the outline fits read from the photo (H, W, 3): the gradient's orientation
    field (:func:`silhouette.orientation_field`), its derivatives d/dx, d/dy after a
    0.7 px blur, and their colour norm (H, W)."""
    field = silhouette.orientation_field(colour, 1.0)
    polish = silhouette.gradients(colour, 0.7)
    return field, polish, np.sqrt((polish[0] ** 2 + polish[1] ** 2).sum(-1))


def _fitted(colour, cands, K, ior=None) -> list:
    """Each candidate fitted to the silhouette and scored, (ellipse, score), best first;
    candidates whose fitted contour is not an edge all the way round are dropped. With
    ``K`` and the key's ``ior``, :func:`_fitted_keyed` instead."""
    if K is not None and ior is not None:
        return _fitted_keyed(colour, cands, K, ior)
    H, W = colour.shape[:2]
    field, polish, edge = _edge_fields(colour)
    found = []
    for cand in cands:
        ell = (silhouette.fit_ellipse(field, cand, (H, W), polish) if K is None
               else silhouette.fit_cone(field, cand, K, (H, W), polish))
        if ell is None:                  # keep the circle when the fit fails
            ell = ((cand[0], cand[1]), (2 * cand[2], 2 * cand[2]), 0.0)
        support = silhouette.support(ell, field)
        if support >= MIN_SUPPORT_FIT:  # both the coarse ring score and the fitted edge
            score = np.sqrt(max(cand[3], 0.0) * support)
            found.append((ell, score * np.clip(silhouette.busyness(ell, edge), 0.5, 1.3)))
    return sorted(found, key=lambda t: -t[1])


def _fitted_keyed(colour, cands, K, ior) -> list:
    """With the camera's ``K`` and the key's ``ior``: each candidate's tangent cone
    fitted (:func:`silhouette.fit_cone`) and ranked by the alignment of all but its
    worst arc (:func:`silhouette.arc_support`) times the busyness times
    ``exp(GLASS_RANK * g)`` (``g`` :func:`glass.glass_scores`); the best :data:`REFIT`
    re-fitted over a wide basin (:func:`cone_fit.refit_cone`, kept when better aligned)
    and scored by their alignment (:func:`silhouette.alignment`) times
    :func:`glass_factor`. (ellipse, score), best first. See docs/decisions.md, 'masks:
    a wide fit around each candidate'."""
    H, W = colour.shape[:2]
    field, polish, edge = _edge_fields(colour)
    first = []
    for cand in cands:
        ell = silhouette.fit_cone(field, cand, K, (H, W), polish)
        if ell is not None:
            first.append((ell, max(silhouette.arc_support(ell, field), 0.0)
                          * np.clip(silhouette.busyness(ell, edge), 0.5, 1.3)))
    if not first:
        return []
    g = glass.outline_scores(colour, [e for e, _ in first], K, ior)
    first = sorted(((e, s * np.exp(GLASS_RANK * gi)) for (e, s), gi in zip(first, g)),
                   key=lambda t: -t[1])[:REFIT]
    final = []
    for ell, _ in first:
        (cx, cy), (A, B), _ = ell
        res = cone_fit.refit_cone(field, (cx, cy, 0.25 * (A + B)), K, (H, W), polish)
        al = silhouette.alignment(ell, field)
        al_res = -np.inf if res is None else silhouette.alignment(res[0], field)
        if al_res > al:
            ell, al = res[0], al_res
        final.append((ell, max(al, 0.0)))
    g = glass_factor(colour, [e for e, _ in final], K, ior)
    return sorted(((e, s * f) for (e, s), f in zip(final, g)), key=lambda t: -t[1])


def glass_factor(colour, ellipses, K, ior) -> np.ndarray:
    """(k,) ``exp(GLASS_WEIGHT * g)`` for each fitted outline (cv2 ellipses), ``g``
    :func:`scenes.photo.glass.glass_scores` of its circle: how well the colours inside
    correlate with the photo where the key's sphere would send those pixels' rays. A
    glass sphere of the key shows the rest of the photo, inverted; an opaque ball or a
    ring of texture does not (the correlation is near 0 or below)."""
    return np.exp(GLASS_WEIGHT * glass.outline_scores(colour, ellipses, K, ior))


def _apart(found) -> list:
    """Greedily, best first, the ellipses that overlap no better one."""
    chosen = []
    for ell, score in found:
        (cx, cy), (A, B), _ = ell
        if all(np.hypot(e[0][0] - cx, e[0][1] - cy) > 0.5 * (max(e[1]) + max(A, B)) * 0.9
               for e, _ in chosen):
            chosen.append((ell, score))
    return chosen


def _best_near(colour, hint, r_min, r_max, K, ior=None):
    """The best totem whose fitted outline holds the pixel ``hint`` (x, y), or None: the
    best :data:`HINT_FITS` of the window's :data:`HINT_POOL` ring candidates that hold
    the hint are fitted (the best rings of a textured floor seldom hold it)."""
    H, W = colour.shape[:2]
    x, y = hint
    if not (0 <= x < W and 0 <= y < H):
        raise BadInput(f"hint {x:g},{y:g} lies outside the {W}x{H} photo")
    half = int(np.ceil(2.2 * r_max)) + 4
    x0, y0 = max(0, int(x) - half), max(0, int(y) - half)
    crop = np.ascontiguousarray(colour[y0:int(y) + half + 1, x0:int(x) + half + 1])
    cands = _search(crop, r_min, min(r_max, 0.45 * min(crop.shape[:2])), HINT_POOL)
    cands[:, 0] += x0
    cands[:, 1] += y0
    holds = np.hypot(cands[:, 0] - x, cands[:, 1] - y) < cands[:, 2]
    fitted = [f for f in _fitted(colour, cands[holds][:HINT_FITS], K, ior)
              if np.hypot(f[0][0][0] - x, f[0][0][1] - y) < 0.5 * max(f[0][1])]
    return fitted[0] if fitted else None


def draw_check(image: np.ndarray, masks: np.ndarray, *, hints=None) -> np.ndarray:
    """The photo with each mask's outline and number drawn on it (and a cross at each
    hint), (H, W, 3) uint8."""
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
    for x, y in ([] if hints is None else np.asarray(hints, float)):
        cv2.drawMarker(out, (int(round(x)), int(round(y))), (255, 255, 255),
                       cv2.MARKER_CROSS, 6 * thick, thick)
    return out


def _scene_K(scene_dir) -> np.ndarray | None:
    """The scene's intrinsics from its calib.npy (or one above it), or None."""
    try:
        return folder.read_calib(folder.find_calib(scene_dir))["mtx"]
    except BadInput:
        return None


def write_masks(scene_dir, masks: np.ndarray | None = None, *, n: int | None = None,
                hints=None, radii=None) -> dict:
    """Give a scene folder totem masks, unless it has some, and a picture to check them.

    ``totem_masks/*.png`` already there (e.g. drawn by hand) are used as given, never
    overwritten; otherwise ``masks`` (or :func:`find_totems` of the photo, with
    ``hints`` and ``radii`` = (min, max) px) are written as ``totem_masks/totem_000.png``...
    (the folder appears complete or not at all). The number wanted is ``n``, else one
    per hint, else as many as the key lists (:func:`scenes.folder.expected_totems`). When fewer are
    found, no mask is written and the summary says so (``complete`` false, ``found``,
    ``expected``, ``searched``). ``totem_masks_check.png`` (outlines over the photo) is
    (re)written either way.

    Returns {"proposed": bool, "complete": bool, "n": int, "masks": [paths],
    "check": path} (and ``found``, ``expected``, ``searched`` when incomplete).
    """
    scene_dir = Path(scene_dir)
    image = folder.read_image(folder.photo_path(scene_dir), what="photo")
    mask_dir = scene_dir / "totem_masks"
    existing = sorted(mask_dir.glob("*.png")) if mask_dir.is_dir() else []
    check = scene_dir / "totem_masks_check.png"
    if existing:
        masks = np.stack([folder.read_mask(f, what="totem mask") for f in existing])
        if masks.shape[1:] != image.shape[:2]:
            raise BadInput(f"the masks in {mask_dir} are not the size of the photo")
        order = np.argsort([np.nonzero(m)[1].mean() if m.any() else 0 for m in masks],
                           kind="stable")
        masks, files, proposed = masks[order], [existing[i] for i in order], False
    elif masks is None:
        # --n or the hints say how many there are; the key's list only how many are
        # wanted: then, with K and the key's IoR, the best that many whose final score
        # reaches MIN_KEYED count, else those whose ring score passes MIN_SCORE
        told = n or (len(hints) if hints is not None and len(hints) else None)
        want = told or folder.expected_totems(scene_dir)
        K, ior = _scene_K(scene_dir), folder.key_iors(scene_dir)
        keyed = bool(want and not told and K is not None and ior is not None)
        r_lo, r_hi = radius_range(image.shape, *(radii or (None, None)))
        found = find_totems(image, n=want if keyed else told, r_min=r_lo, r_max=r_hi, K=K,
                            hints=hints, ior=ior, min_score=MIN_KEYED if keyed else None)
        if want is not None and len(found) > want:
            found = sorted(sorted(found, key=lambda t: -t[1])[:want],
                           key=lambda t: t[0][0][0])
        masks = ellipse_masks(found, image.shape)
        if not found or (want is not None and len(found) < want):
            folder.write_image(check, draw_check(image, masks, hints=hints))
            where = (f"around the {len(hints)} hints" if hints is not None and len(hints)
                     else "over the whole photo")
            return {"proposed": True, "complete": False, "n": 0, "masks": [],
                    "check": str(check), "found": len(found), "expected": want,
                    "searched": f"{where}, totem radii {r_lo:.0f}-{r_hi:.0f} px"}
    if not existing:
        masks = np.asarray(masks, bool)
        if masks.ndim != 3 or masks.shape[1:] != image.shape[:2]:
            raise BadInput("masks must be (n, H, W) the size of the photo")
        with folder.staged_folder(mask_dir) as tmp:
            for j, m in enumerate(masks):
                folder.write_image(tmp / f"totem_{j:03d}.png", m)
        files = [mask_dir / f"totem_{j:03d}.png" for j in range(len(masks))]
        proposed = True
    folder.write_image(check, draw_check(image, masks, hints=hints))
    return {"proposed": proposed, "complete": True, "n": int(len(masks)),
            "masks": [str(f) for f in files], "check": str(check)}
