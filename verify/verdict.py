"""Image-level verdict: is the photo consistent with what its totems saw?

The score is how far the worst patches stand out from the image's own patches. A
reconstruction from totem pixels is never exact: its error varies from scene to scene
(blur, resolution of the grid, parts seen by one totem only), so an absolute L1 level
that passes every untouched photo would miss most edits. Instead each image is its own
reference:

    s_p      patch L1 (mean |I - C| over the patch's protected, non-totem pixels,
             sRGB in [0, 1]) for the patches mostly inside the protected region
    med      median of s_p over those patches
    sigma    max(1.4826 * MAD(s_p), SCALE_FLOOR)      (robust standard deviation)
    z_p      (s_p - med) / sigma
    score    mean of the top-k z_p,  k = max(TOP_K_MIN, ceil(TOP_K_FRACTION * #patches))

and the photo is *inconsistent* when ``score > VERDICT_THRESHOLD``. The floor on sigma
keeps a near-perfect reconstruction (MAD -> 0) from turning sensor noise into huge z; it
also means a spot must differ by at least ``threshold * SCALE_FLOOR`` in mean colour.
The median makes a global colour/exposure offset between photo and recon harmless.
Limits: an edit covering more than about half of the protected region moves the median
itself and is under-scored; an edit outside the protected region is never seen. The
grid's patches overlap heavily (on a 150-px crop the vertical stride is 3 px), so a
40-px edit touches about a third of the patches and widens the MAD: measured on
320 x 240 renders of the presets with a blurred "recon" (clean view down-sampled 4x / 8x
and back, standing in for a coarse grid), untouched photos (6 scenes) scored 0.8-5.6 /
1.1-9.1 and a 40-px random-colour square 2.4-26.4: calibrate on real fits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scenes.errors import BadInput

VERDICT_THRESHOLD = 6.0
"""Score above which a photo is reported inconsistent (robust z of the worst patches).

Aim: a false-alarm rate of at most 5 % (1 untouched photo in 20) on untouched photos
fitted with the default fit settings. How it is calibrated: run ``totems check`` on the
untouched benchmark scenes (``totems bench``, both presets, several seeds and totem
layouts), take the scores of those photos, and set the threshold to the larger of their
95th percentile and ``4.0`` (a Gaussian null's max over a few hundred correlated patches),
rounded up; then report the detection rate on the tampered copies at that threshold.
The value 6.0 is the provisional choice before that calibration: the unit tests'
untouched cases score below 1, a 0.1 colour change over a 64-px square scores > 10.
"""

SCALE_FLOOR = 0.01
"""Lower bound on the robust spread of patch L1, sRGB [0, 1] (about 2.5 levels of 8 bit)."""

TOP_K_FRACTION = 0.01
TOP_K_MIN = 3
"""The score averages the top ``max(TOP_K_MIN, ceil(TOP_K_FRACTION * n))`` patch z."""

MIN_COVER = 0.5
"""A patch enters the verdict when at least this fraction of it is protected, non-totem."""

MAX_DRIVERS = 8
"""At most this many (non-overlapping) patches are named as drivers in the report."""


@dataclass
class Verdict:
    """The image-level decision and what drove it.

    Attributes
    ----------
    verdict : "consistent" or "inconsistent".
    score, threshold : the robust z score of the worst patches and the threshold.
    median, sigma : centre and spread of the patch L1 distribution, sRGB [0, 1].
    z : (G, G) robust z per patch (NaN for patches not used).
    used : (G, G) bool, patches that entered the verdict.
    drivers : list of dicts {row, col, box [x0, y0, x1, y1], L1, z, ...}, worst first.
    """

    verdict: str
    score: float
    threshold: float
    median: float
    sigma: float
    z: np.ndarray
    used: np.ndarray
    drivers: list = field(default_factory=list)


def robust_z(scores: np.ndarray, used: np.ndarray, *,
             floor: float = SCALE_FLOOR) -> tuple[np.ndarray, float, float]:
    """Robust z of ``scores`` over the ``used`` entries: (z, median, sigma).

    ``sigma = max(1.4826 * MAD, floor)``; z is NaN where not used.
    """
    s = np.asarray(scores, dtype=np.float64)[used]
    med = float(np.median(s))
    sigma = max(1.4826 * float(np.median(np.abs(s - med))), float(floor))
    z = np.full(np.shape(scores), np.nan)
    z[used] = (np.asarray(scores, dtype=np.float64)[used] - med) / sigma
    return z, med, sigma


def top_k(n: int) -> int:
    """How many of the ``n`` used patches the score averages."""
    return min(n, max(TOP_K_MIN, math.ceil(TOP_K_FRACTION * n)))


def decide(patch_l1: np.ndarray, cover: np.ndarray, grid, *,
           threshold: float | None = None, extra: dict | None = None) -> Verdict:
    """The verdict from patch scores.

    Parameters
    ----------
    patch_l1 : (G, G) mean |I - C| over each patch's protected non-totem pixels, sRGB
        [0, 1] (NaN where a patch has none).
    cover : (G, G) fraction of each patch that is protected and not totem.
    grid : the :class:`verify.patches.PatchGrid` (for the drivers' pixel boxes).
    threshold : overrides ``VERDICT_THRESHOLD``.
    extra : {name: (G, G)} other patch scores to list beside each driver (e.g. SSIM).

    Raises
    ------
    BadInput when no patch above the totems overlaps the protected region.
    """
    threshold = VERDICT_THRESHOLD if threshold is None else float(threshold)
    finite = np.isfinite(patch_l1)
    used = finite & (cover >= MIN_COVER)
    if not used.any():
        used = finite & (cover > 0)
    if not used.any():
        raise BadInput("the protected region does not reach the image above the totems; "
                       "this photo cannot be verified (move the totems lower or nearer)")
    z, med, sigma = robust_z(patch_l1, used)
    k = top_k(int(used.sum()))
    score = float(np.sort(z[used])[::-1][:k].mean())
    verdict = "inconsistent" if score > threshold else "consistent"
    drivers = name_drivers(z, used, grid, patch_l1, threshold,
                           k if verdict == "consistent" else MAX_DRIVERS, extra or {})
    return Verdict(verdict, score, threshold, med, sigma, z, used, drivers)


def name_drivers(z, used, grid, patch_l1, threshold, limit, extra) -> list[dict]:
    """The patches that drove the verdict, worst first, without near-duplicates.

    For an inconsistent photo: patches with z above the threshold; for a consistent one:
    the worst ones (what came closest). Patches overlapping an already named patch by
    more than a third (IoU) are skipped, so each driver is a distinct place.
    """
    order = np.argsort(np.where(used, z, -np.inf), axis=None)[::-1]
    chosen, out = [], []
    for flat in order[:max(50, 4 * limit)]:
        a, b = np.unravel_index(flat, z.shape)
        if not used[a, b] or len(out) >= limit:
            break
        if out and out[0]["z"] > threshold and z[a, b] <= threshold:
            break
        box = grid.box(a, b)
        if any(_iou(box, c) > 1 / 3 for c in chosen):
            continue
        chosen.append(box)
        d = {"row": int(a), "col": int(b), "box": box, "z": round(float(z[a, b]), 3),
             "L1": round(float(patch_l1[a, b]), 5)}
        for name, h in extra.items():
            d[name] = round(float(h[a, b]), 5)
        out.append(d)
    return out


def _iou(p, q) -> float:
    w = max(0, min(p[2], q[2]) - max(p[0], q[0]))
    h = max(0, min(p[3], q[3]) - max(p[1], q[1]))
    inter = w * h
    union = (p[2] - p[0]) * (p[3] - p[1]) + (q[2] - q[0]) * (q[3] - q[1]) - inter
    return inter / union if union > 0 else 0.0
