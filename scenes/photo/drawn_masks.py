"""Totem masks as people draw them: the exact mask changed the way a hand-drawn one
differs (for tests and the pose benchmark, ``benchmarks/pose_masks.py``).

Each function takes an exact (H, W) bool mask and returns a new one; pixel (u, v) is
at image coordinate (u, v) (docs/contract.md). ``rng`` is a ``numpy.random.Generator``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["grown", "shifted", "polygon", "radially_jittered", "occluded", "FAMILIES",
           "family"]


def grown(mask, px: int) -> np.ndarray:
    """Dilated by ``px`` pixels (a negative ``px`` erodes): a mask drawn too large or
    too small."""
    from scipy import ndimage

    op = ndimage.binary_dilation if px > 0 else ndimage.binary_erosion
    return op(mask, iterations=abs(int(px))) if px else mask.copy()


def shifted(mask, px: float, rng) -> np.ndarray:
    """Moved by ``px`` pixels (rounded to whole pixels) in a random direction."""
    a = rng.uniform(0.0, 2.0 * np.pi)
    dx, dy = int(round(px * np.cos(a))), int(round(px * np.sin(a)))
    return np.roll(np.roll(mask, dy, 0), dx, 1)


def _rim(mask) -> np.ndarray:
    """The mask's outline (m, 2) (u, v): its 0.5 iso-contour between pixel centres."""
    from skimage import measure

    rc = max(measure.find_contours(np.asarray(mask, np.float32), 0.5), key=len)
    return rc[:-1, ::-1].copy()


def _fill(shape, poly) -> np.ndarray:
    """The pixel centres inside a polygon (k, 2) of (u, v) points."""
    from skimage.draw import polygon as fill

    out = np.zeros(shape, bool)
    rr, cc = fill(poly[:, 1], poly[:, 0], shape)
    out[rr, cc] = True
    return out


def _rim_points(mask, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` rim points (n, 2) evenly spread in angle from a random start, and the
    rim's centroid (2,)."""
    uv = _rim(mask)
    c = uv.mean(0)
    angle = np.arctan2(uv[:, 1] - c[1], uv[:, 0] - c[0])
    want = np.linspace(-np.pi, np.pi, n, endpoint=False) + rng.uniform(0, 2 * np.pi / n)
    idx = [int(np.argmin(np.abs(np.angle(np.exp(1j * (angle - t)))))) for t in want]
    return uv[idx], c


def polygon(mask, n: int, rng, jitter_px: float = 0.5) -> np.ndarray:
    """A polygon of ``n`` points clicked on the rim (evenly spread, random start), each
    off by Gaussian ``jitter_px`` pixels: a person's outline tool."""
    p, _ = _rim_points(mask, n, rng)
    return _fill(mask.shape, p + rng.normal(0.0, jitter_px, (n, 2)))


def radially_jittered(mask, n: int, rng, jitter_px: float = 1.0) -> np.ndarray:
    """A polygon of ``n`` rim points (evenly spread) each moved in or out along the
    radius by Gaussian ``jitter_px`` pixels."""
    p, c = _rim_points(mask, n, rng)
    r = (p - c) / np.linalg.norm(p - c, axis=1, keepdims=True)
    return _fill(mask.shape, p + r * rng.normal(0.0, jitter_px, (n, 1)))


def occluded(mask, fraction: float, rng) -> np.ndarray:
    """The mask less a cap cut off by a straight edge (an object in front of the rim),
    the cap holding about ``fraction`` of the mask's pixels."""
    v, u = np.nonzero(mask)
    a = rng.uniform(0.0, 2.0 * np.pi)
    s = u * np.cos(a) + v * np.sin(a)
    cut = np.quantile(s, 1.0 - fraction)
    out = mask.copy()
    out[v[s > cut], u[s > cut]] = False
    return out


FAMILIES = {
    "grown1": lambda m, rng: grown(m, 1), "grown2": lambda m, rng: grown(m, 2),
    "grown3": lambda m, rng: grown(m, 3), "shrunk1": lambda m, rng: grown(m, -1),
    "shrunk2": lambda m, rng: grown(m, -2), "shrunk3": lambda m, rng: grown(m, -3),
    "shift1": lambda m, rng: shifted(m, 1, rng), "shift2": lambda m, rng: shifted(m, 2, rng),
    "poly8": lambda m, rng: polygon(m, 8, rng), "poly12": lambda m, rng: polygon(m, 12, rng),
    "poly16": lambda m, rng: polygon(m, 16, rng),
    "radial12": lambda m, rng: radially_jittered(m, 12, rng),
    "occluded10": lambda m, rng: occluded(m, 0.10, rng),
}
"""The families: those the pose was developed on, and (``radial12``, ``occluded10``)
two it was not."""


def family(name: str, mask, rng) -> np.ndarray:
    """The exact ``mask`` changed as family ``name`` (a key of :data:`FAMILIES`)."""
    return FAMILIES[name](np.asarray(mask, bool), rng)
