"""Selections of the image: (H, W) bool masks, their bounding box, growth, shift and
outline.

The one place where a mask's bounding box, or its growth by a radius, is computed (the
forger's tools, the fit's crop of the totems and the protected region all use it).
Pixels: column x to the right, row y down, as the image's own array indices.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

__all__ = ["bbox", "dilate", "outline", "shift_mask"]


def bbox(mask) -> tuple[int, int, int, int]:
    """The bounding box ``(x, y, w, h)`` of the True pixels of an (H, W) bool mask, in
    pixels (column, row of the top-left corner, width, height).

    Raises ValueError for a mask with no True pixel.
    """
    ys, xs = np.nonzero(np.asarray(mask))
    if ys.size == 0:
        raise ValueError("the bounding box of an empty mask")
    return int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), \
        int(ys.max() - ys.min() + 1)


def dilate(mask, r: int):
    """``mask`` grown by ``r`` pixels with a disc (an editor's "expand selection");
    a copy of it for ``r <= 0``."""
    if r <= 0:
        return mask.copy()
    y, x = np.ogrid[-r:r + 1, -r:r + 1]
    return ndi.binary_dilation(mask, structure=(x * x + y * y) <= r * r)


def shift_mask(mask, dx: int, dy: int):
    """``mask`` translated by (dx, dy) pixels (right, down), zero-filled at the edges."""
    mask = np.asarray(mask, bool)
    H, W = mask.shape
    out = np.zeros_like(mask)
    ys, xs = np.nonzero(mask)
    ys, xs = ys + dy, xs + dx
    ok = (ys >= 0) & (ys < H) & (xs >= 0) & (xs < W)
    out[ys[ok], xs[ok]] = True
    return out


def outline(mask) -> np.ndarray:
    """The sub-pixel outline of a mask's largest blob (holes filled), (m, 2) pixel
    coordinates (u, v): where it crosses the segments between white and black pixel
    centres (the 0.5 iso-contour, marching squares), the closing point not repeated.

    Raises ValueError for a mask with no True pixel.
    """
    from skimage import measure

    m = ndi.binary_fill_holes(np.asarray(mask, bool))
    lab, n = ndi.label(m)
    if n == 0:
        raise ValueError("the outline of an empty mask")
    m = lab == 1 + int(np.argmax(np.bincount(lab.ravel())[1:]))
    rc = max(measure.find_contours(np.pad(m, 1).astype(np.float32), 0.5), key=len)
    if np.allclose(rc[0], rc[-1]):
        rc = rc[:-1]
    return rc[:, ::-1] - 1.0
