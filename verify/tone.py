"""The rebuilt view brought to the photo's exposure and white balance before it is
compared.

The fit reads the totem pixels as sRGB of scene-linear light; a camera whose tone curve
is not sRGB (a view transform: AgX, Filmic), or a glass whose reflection the one
ambient colour misses, gives a rebuilt view too bright or tinted everywhere alike.
:func:`match_gain` scales the view's linear light per channel by the median ratio of the
photo's to the view's over the judged pixels, which a local edit (a minority of the
pixels) does not move and which, unlike a line fitted to the pixel pairs, the view's
blur and misplaced edges do not pull towards flat (a gain is a ratio of two medians'
worth of pixels, not a slope).

A gain read off the photo outside the totems can be steered by whoever edits it, so
:func:`least_score` is the rule that keeps a forger from gaining by editing more: the
view is tried at each exposure of a fixed set and compared where the score is least.
At any one gain, editing more of the photo never lowers the score, so neither does its
least over a fixed set of gains (the median ratio of :func:`match_gain` has no such
bound). A change of the whole photo's exposure within the set is still not seen: the
totem pixels cannot fix it, since the fit matches them (their gain is 0.99-1.07).

Conventions: images (H, W, 3) sRGB in [0, 1]; ``pixels`` (H, W) bool.
"""

from __future__ import annotations

import numpy as np

from scenes.colour import linear_to_srgb, srgb_to_linear

__all__ = ["GAIN_RANGE", "MIN_PIXELS", "FLOOR", "EXPOSURES", "match_gain", "at_gain",
           "least_score"]

GAIN_RANGE = (0.5, 2.0)
"""The gain allowed per channel (linear light: an exposure of +-1 stop)."""
MIN_PIXELS = 2000
"""Fewer judged pixels than this: the view is left as it is."""
FLOOR = 0.01
"""Pixels darker than this (linear) in the photo or the view do not vote: their ratio is
noise."""
EXPOSURES = tuple(2.0 ** (k / 3) for k in range(-3, 2))
"""The exposures :func:`least_score` tries (linear light, -1 to +1/3 stop in thirds):
the Cycles table-s107 needs -1 stop, the Mitsuba views a third of a stop up."""


def match_gain(image: np.ndarray, recon: np.ndarray, pixels: np.ndarray
               ) -> tuple[np.ndarray, dict]:
    """The view ``recon`` with its linear light scaled per channel by
    ``g_c = exp(median(log(photo_c / recon_c)))`` over ``pixels`` (the photo already at
    the view's resolution), ``g_c`` held to ``GAIN_RANGE``; back in sRGB, clipped.

    Returns the view (float32) and ``{"gain": [g] * 3, "pixels": n}`` (gain 1 where
    fewer than ``MIN_PIXELS`` pixels vote)."""
    image = np.asarray(image, np.float64)
    recon = np.asarray(recon, np.float64)
    if image.shape != recon.shape or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image and recon must be (H, W, 3) alike, got {image.shape} "
                         f"and {recon.shape}")
    sel = np.asarray(pixels, bool)
    p_lin = srgb_to_linear(np.clip(image[sel], 0, 1))
    r_lin = srgb_to_linear(np.clip(recon, 0, 1))
    gains = []
    for c in range(3):
        ok = (p_lin[:, c] > FLOOR) & (r_lin[sel][:, c] > FLOOR)
        g = float(np.exp(np.median(np.log(p_lin[ok, c] / r_lin[sel][ok, c])))) \
            if ok.sum() >= MIN_PIXELS else 1.0
        gains.append(float(np.clip(g, *GAIN_RANGE)))
    out = linear_to_srgb(np.clip(r_lin * np.array(gains), 0.0, 1.0))
    return np.asarray(out, np.float32), {"gain": gains, "pixels": int(sel.sum())}


def at_gain(recon: np.ndarray, gain) -> np.ndarray:
    """The view ``recon`` (H, W, 3) sRGB with its linear light times ``gain`` (a number
    or one per channel), back in sRGB, clipped to [0, 1]; float32."""
    r_lin = srgb_to_linear(np.clip(np.asarray(recon, np.float64), 0, 1))
    g = np.broadcast_to(np.asarray(gain, np.float64), (3,))
    return np.asarray(linear_to_srgb(np.clip(r_lin * g, 0.0, 1.0)), np.float32)


def least_score(recon: np.ndarray, score_at, *, gains=EXPOSURES):
    """The view at the gain of ``gains`` whose score is least.

    Parameters
    ----------
    recon : (H, W, 3) sRGB, the fit's view.
    score_at : callable, view (H, W, 3) sRGB -> (score, payload); the score the verdict
        would give the photo against that view.
    gains : the exposures tried (numbers, linear light), fixed in advance: a gain chosen
        from a set that does not depend on the photo keeps the score's monotonicity.

    Returns
    -------
    ``(view, payload, {"gain": [g] * 3, "scores": {g: score}})`` of the least score; of
    equal scores the gain nearest 1 (an untouched photo keeps its exposure).
    """
    if not len(gains) or min(float(g) for g in gains) <= 0:
        raise ValueError(f"gains must be positive numbers, got {gains!r}")
    order = sorted({float(g) for g in gains}, key=lambda g: (abs(np.log(g)), g))
    best, scores = None, {}
    for g in order:
        view = at_gain(recon, g)
        score, payload = score_at(view)
        scores[round(g, 4)] = float(score)
        if best is None or score < best[0]:
            best = (score, g, view, payload)
    _, g, view, payload = best
    return view, payload, {"gain": [g] * 3, "scores": scores}
