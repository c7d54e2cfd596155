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

Conventions: images (H, W, 3) sRGB in [0, 1]; ``pixels`` (H, W) bool.
"""

from __future__ import annotations

import numpy as np

from scenes.colour import linear_to_srgb, srgb_to_linear

__all__ = ["GAIN_RANGE", "MIN_PIXELS", "FLOOR", "match_gain"]

GAIN_RANGE = (0.5, 2.0)
"""The gain allowed per channel (linear light: an exposure of +-1 stop)."""
MIN_PIXELS = 2000
"""Fewer judged pixels than this: the view is left as it is."""
FLOOR = 0.01
"""Pixels darker than this (linear) in the photo or the view do not vote: their ratio is
noise."""


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
