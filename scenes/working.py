"""The working resolution: a photo larger than :data:`WORKING_PIXELS` is fitted and
judged at the integer fraction of its size that comes nearest it.

The verdict's line was calibrated on 640 x 480 photos and its patches, map cells and
blurs are sized in pixels, so a photo is judged at about that size (see
docs/decisions.md, "working: every photo judged at the size the verdict was calibrated
at"). ``check``, ``fit`` and ``verify`` read a scene folder, then take the
:func:`working_scene` of it: the photo averaged over ``f x f`` blocks, the masks as
the blocks they cover at least half of, ``K`` for the coarser pixels (OpenCV centres:
``u' = (u + 0.5) / f - 0.5``).
The verify outputs are then at the working size and say the factor
(``report.json`` ``working_scale``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenes.folder import Scene, Truth, read_scene

__all__ = ["WORKING_PIXELS", "working_factor", "scale_intrinsics", "block_mean",
           "working_scene", "working_truth", "read_working_scene"]

WORKING_PIXELS = 640 * 480
"""The pixels a photo is fitted and judged at, as near as an integer fraction of its size
comes: the size the verdict's line was calibrated at."""


def working_factor(size, pixels: int = WORKING_PIXELS) -> int:
    """The integer ``f`` for which ``(W // f) * (H // f)`` is nearest ``pixels`` in ratio
    (the smaller ``f`` on a tie); 1 for a photo of at most ``pixels``. ``size`` (W, H)."""
    W, H = size
    if W * H <= pixels:
        return 1
    f = 1
    while (W // (f + 1)) * (H // (f + 1)) >= pixels:
        f += 1
    over, under = (W // f) * (H // f), (W // (f + 1)) * (H // (f + 1))
    return f if under <= 0 or over * under <= pixels * pixels else f + 1


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


def working_scene(scene: Scene, pixels: int = WORKING_PIXELS) -> Scene:
    """``scene`` at the working resolution (itself when :func:`working_factor` is 1).

    The image is block-averaged (sRGB values, as a camera's downscale does), each mask
    keeps the blocks it covers at least half of, the manipulation mask those it touches
    at all; the JPEG record is dropped (its 8 px blocks and chroma subsampling are
    averaged away). ``scale`` says the factor.
    """
    f = working_factor(scene.size, pixels)
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


def working_truth(truth: Truth | None, pixels: int = WORKING_PIXELS) -> Truth | None:
    """``truth`` with its clean view (and its reach) at the working resolution of a
    photo its size: a block of the reach keeps the mean of its pixels' counts and
    parallax, and is a backdrop or excluded where at least half its pixels are."""
    if truth is None:
        return None
    clean = np.asarray(truth.clean)
    f = working_factor((clean.shape[1], clean.shape[0]), pixels)
    if f == 1:
        return truth
    reach = truth.reach
    if reach is not None:
        with np.errstate(invalid="ignore"):
            reach = dataclasses.replace(
                reach, depth=block_mean(reach.depth, f).astype(np.float32),
                n_totems=np.rint(block_mean(reach.n_totems, f)).astype(np.uint8),
                parallax=block_mean(reach.parallax, f).astype(np.float32),
                backdrop=block_mean(reach.backdrop, f) >= 0.5,
                excluded=block_mean(reach.excluded, f) >= 0.5)
    return dataclasses.replace(truth, clean=block_mean(clean, f).astype(np.float32),
                               reach=reach)
