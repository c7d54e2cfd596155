"""The working resolution: a photo larger than :data:`WORKING_PIXELS` is fitted and
judged at an integer fraction of its size.

A phone's 12 Mpx photo holds no more evidence than its totems' rays resolve, and the
verdict already compares the photo at that resolution (:mod:`verify.resolution`): a
totem ray lands every few pixels of a 640 x 480 view, so a larger photo only multiplies
the cost. ``check``, ``fit`` and ``verify`` read a scene folder, then take the
:func:`working_scene` of it: the photo averaged over ``f x f`` blocks (``f`` the smallest
integer that brings it under the limit), the masks as the blocks they cover at least
half of, ``K`` for the coarser pixels (OpenCV centres: ``u' = (u + 0.5) / f - 0.5``).
The verify outputs are then at the working size and say the factor
(``report.json`` ``working_scale``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from scenes.folder import Scene, Truth, read_scene

__all__ = ["WORKING_PIXELS", "working_factor", "scale_intrinsics", "block_mean",
           "working_scene", "working_truth", "read_working_scene"]

WORKING_PIXELS = 1280 * 960
"""The most pixels a photo is fitted and judged at."""


def working_factor(size, max_pixels: int = WORKING_PIXELS) -> int:
    """The smallest integer ``f`` with ``(W / f) * (H / f) <= max_pixels``; ``size`` (W, H)."""
    W, H = size
    f = max(1, math.ceil(math.sqrt(W * H / max_pixels)))
    while (W // f) * (H // f) > max_pixels:
        f += 1
    return f


def scale_intrinsics(K, f: int) -> np.ndarray:
    """``K`` (3, 3) for pixels ``f`` times larger, OpenCV pixel-centre convention: the
    point at pixel ``(u, v)`` lands at ``((u + 0.5) / f - 0.5, (v + 0.5) / f - 0.5)``."""
    K = np.asarray(K, np.float64)
    S = np.array([[1.0 / f, 0.0, 0.5 / f - 0.5], [0.0, 1.0 / f, 0.5 / f - 0.5],
                  [0.0, 0.0, 1.0]])
    return S @ K


def block_mean(a, f: int) -> np.ndarray:
    """The mean of ``a`` (H, W, ...) over ``f x f`` blocks (H // f, W // f, ...) float64;
    the last ``H % f`` rows and ``W % f`` columns are left out."""
    a = np.asarray(a, np.float64)
    H, W = a.shape[0] // f * f, a.shape[1] // f * f
    a = a[:H, :W]
    return a.reshape(H // f, f, W // f, f, *a.shape[2:]).mean(axis=(1, 3))


def working_scene(scene: Scene, max_pixels: int = WORKING_PIXELS) -> Scene:
    """``scene`` at the working resolution (itself when it is not over ``max_pixels``).

    The image is block-averaged (sRGB values, as a camera's downscale does), each mask
    keeps the blocks it covers at least half of, the manipulation mask those it touches
    at all; the JPEG record is dropped (its 8 px blocks and chroma subsampling are
    averaged away). ``scale`` says the factor.
    """
    f = working_factor(scene.size, max_pixels)
    if f == 1:
        return scene
    masks = np.stack([block_mean(m, f) >= 0.5 for m in np.asarray(scene.masks, bool)])
    manip = None if scene.manip_mask is None else block_mean(scene.manip_mask, f) > 0
    return dataclasses.replace(
        scene, image=block_mean(scene.image, f).astype(np.float32),
        K=scale_intrinsics(scene.K, f), masks=masks, manip_mask=manip, jpeg=None,
        scale=f * scene.scale)


def read_working_scene(path) -> Scene:
    """:func:`scenes.folder.read_scene` of ``path``, at the working resolution."""
    return working_scene(read_scene(path))


def working_truth(truth: Truth | None, max_pixels: int = WORKING_PIXELS) -> Truth | None:
    """``truth`` with its clean view at the working resolution of a photo its size."""
    if truth is None:
        return None
    clean = np.asarray(truth.clean)
    f = working_factor((clean.shape[1], clean.shape[0]), max_pixels)
    if f == 1:
        return truth
    return dataclasses.replace(truth, clean=block_mean(clean, f).astype(np.float32))
