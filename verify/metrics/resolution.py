"""The evidence's resolution: how finely the totems resolve each part of the camera view,
and the photo blurred to it before the two are compared.

The camera view rebuilt from the totems holds no detail finer than the spacing of the
totem rays that land there, and a JPEG photo's totem pixels carry their hue at half
that resolution again (4:2:0 or 4:2:2 chroma subsampling, read from the file). A photo
compared at its own resolution shows texture and saturated small objects the rebuilt
view cannot have, which reads as an edit. So the photo is blurred first, per pixel, by
a Gaussian whose sigma follows the rays' local spacing (see docs/decisions.md, 'verify:
the photo blurred to the evidence's resolution')::

    s(p)      = 1 / sqrt(rho(p))      ray spacing (px), rho the totem points per pixel
                                      over a BOX_PX box around p
    sigma(p)  = min(MAX_SIGMA_PX, f * max(MIN_SIGMA_PX, SPACING_GAIN * s(p)))

with ``f`` = :func:`chroma_factor` for the hue (1 for brightness). An edit much larger
than ``sigma`` keeps its colour; one smaller than the rays' spacing was never
verifiable.

Public
------
``ray_spacing(points, K, size) -> (H, W)``; ``chroma_factor(jpeg) -> float``;
``photo_sigma(spacing, factor) -> (H, W)``; ``blur_varying(image, sigma) -> image``;
``gaussian(image, sigma) -> image``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from verify.metrics.region import BOX_PX, project_counts

__all__ = ["SPACING_GAIN", "MIN_SIGMA_PX", "MAX_SIGMA_PX", "LEVELS", "ray_spacing",
           "chroma_factor", "photo_sigma", "blur_varying", "gaussian"]

SPACING_GAIN = 1.5
"""Blur sigma per pixel of ray spacing: the spacing counts every totem's points, while
the view's detail at a pixel comes from the few totems that see it."""

MIN_SIGMA_PX = 3.0
"""Smallest blur (pixels), and the photo's one blur where no spacing is given
(:data:`verify.metrics.patches.CHROMA_BLUR_PX`)."""

MAX_SIGMA_PX = 22.5
"""Largest blur (pixels), a third of a patch: sparser rays than that protect little."""

LEVELS = tuple(MIN_SIGMA_PX * 1.5 ** k for k in range(6))
"""Blurs (pixels, 3 to 23, a factor 1.5 apart) computed in full; a pixel's own is
interpolated between the two around it, linearly in log sigma."""


def ray_spacing(points: np.ndarray, K: np.ndarray, size: tuple[int, int], *,
                box: int = BOX_PX) -> np.ndarray:
    """Mean spacing (pixels) of the totem points projected around each pixel.

    ``points`` (m, 3) camera-frame metres (the fit's ``totem_points``), ``K`` (3, 3),
    ``size`` (W, H). Returns (H, W) float64: ``1 / sqrt(rho)`` with ``rho`` the points per
    pixel over the ``box``-pixel square around it (inf where none lands).
    """
    rho = ndimage.uniform_filter(project_counts(points, K, size), size=box)
    rho = np.where(rho > 0.5 / box ** 2, rho, 0.0)     # the filter's round-off: no point
    with np.errstate(divide="ignore"):
        return 1.0 / np.sqrt(rho)


def chroma_factor(jpeg) -> float:
    """How much coarser the photo's hue is than its brightness: 2 for a JPEG whose chroma
    is subsampled (4:2:0, 4:2:2), 1 otherwise (``jpeg`` a :class:`scenes.jpeg.JpegInfo`
    or None)."""
    return 2.0 if jpeg is not None and jpeg.subsampling in ("4:2:0", "4:2:2") else 1.0


def photo_sigma(spacing: np.ndarray, factor: float = 1.0) -> np.ndarray:
    """The photo's blur (pixels) per pixel from the rays' spacing (module docstring)."""
    s = np.nan_to_num(SPACING_GAIN * np.asarray(spacing, np.float64), nan=np.inf)
    return np.minimum(MAX_SIGMA_PX, float(factor) * np.maximum(MIN_SIGMA_PX, s))


def blur_varying(image: np.ndarray, sigma) -> np.ndarray:
    """``image`` (H, W, C) blurred by a Gaussian whose sigma (pixels) varies per pixel.

    ``sigma`` is a number (one Gaussian) or an (H, W) map; each pixel takes the blend,
    linear in log sigma, of the two ``LEVELS`` around its own (clipped to them).
    """
    image = np.asarray(image, np.float64)
    if np.ndim(sigma) == 0:
        return gaussian(image, float(sigma))
    levels = np.asarray(LEVELS)
    x = np.interp(np.log(np.clip(sigma, levels[0], levels[-1])), np.log(levels),
                  np.arange(levels.size))
    i0 = np.minimum(np.floor(x).astype(np.int64), levels.size - 2)
    t = x - i0
    out = np.zeros_like(image)
    for i, s in enumerate(levels):
        w = np.where(i0 == i, 1.0 - t, 0.0) + np.where(i0 + 1 == i, t, 0.0)
        if w.any():
            out += w[..., None] * gaussian(image, s)
    return out


def gaussian(image: np.ndarray, sigma: float) -> np.ndarray:
    """``image`` (H, W, C) blurred by a Gaussian of ``sigma`` pixels across rows and
    columns, as ``scipy.ndimage.gaussian_filter`` (mirrored edges, 4 sigma) gives it, by
    OpenCV's separable filter in float32 (about 1e-7 of the values off; three times
    faster than in float64), returned as float64."""
    import cv2

    image = np.asarray(image, np.float64)
    if sigma <= 0:
        return image.copy()
    r = int(4.0 * sigma + 0.5)
    out = cv2.GaussianBlur(image.astype(np.float32), (2 * r + 1, 2 * r + 1), sigma,
                           sigmaY=sigma, borderType=cv2.BORDER_REFLECT)
    return out.reshape(image.shape).astype(np.float64)
