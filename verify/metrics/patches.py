"""Patch heatmaps between the photo and the re-rendered camera view, and patch AP.

The layout is the NeRF path's (``run_detect_helpers.py`` of jingweim/totems) so that
heatmaps compare one to one:

- the image is cropped to the rows above the totems, ``[0, y_valid)``, where ``y_valid``
  is the top row of the highest totem pixel;
- a 30 x 30 grid of 64 x 64 patches: top-left corners
  ``y0 = linspace(0, y_valid - 64, 30).astype(int)``,
  ``x0 = linspace(0, W - 64, 30).astype(int)``; ``heatmap[a, b]`` is the patch at
  rows ``y0[a]:y0[a]+64``, columns ``x0[b]:x0[b]+64`` (row-major, as the image);
- ``L1/heatmap.npy`` is the mean over the patch's pixels and channels of
  ``|I - C|`` with colours scaled to [-1, 1] as the NeRF path does, i.e.
  ``NERF_L1_SCALE`` (= 2) times the mean absolute sRGB difference in [0, 1];
- ``SSIM/heatmap.npy`` is the patch mean of ``1 - SSIM`` (the SSIM map of Wang et al.,
  Gaussian window sigma 1.5, on sRGB in [0, 1], averaged over channels), in [0, 2]:
  higher is more suspicious, like L1.
- ``CHROMA/heatmap.npy`` (ours, not the NeRF path's) is the mean over the patch's
  worst tenth of pixels (``TOP_FRACTION``, as for CORROB and UNSEEN) of
  :func:`chroma_distance`: how far the photo's hue, blurred to the evidence's resolution
  (:mod:`verify.metrics.resolution`), lies outside what the reconstruction shows within
  ``CHROMA_RADIUS_PX``, sRGB [0, 1]. It ignores the two errors a
  reconstruction from the totems makes everywhere (brightness, and edges a few pixels
  off) and keeps the one an edit makes (a colour that is not there).
- ``CORROB/heatmap.npy`` (ours) is the worst tenth's mean of
  :func:`verify.metrics.corroborate.corroboration`: how far the photo's hue is from what two
  totems saw at the best depth along the pixel's ray, sRGB [0, 1]; it needs no
  reconstruction, only the totem rays.
- ``RANGE/heatmap.npy`` (ours, the verdict's brightness guard) is the patch mean of
  :func:`range_distance`: CHROMA's test on the colour itself (brightness included),
  how far the photo's RGB lies outside the range the reconstruction shows within
  ``CHROMA_RADIUS_PX``; it forgives the view's edges a few pixels off, as L1 does not.
- ``UNSEEN/heatmap.npy`` (ours, the verdict's) is the worst tenth's mean of
  :func:`verify.metrics.corroborate.unseen`, per pixel the smaller of CHROMA and CORROB: a
  hue that neither the rebuilt view nor the totem rays explain.
- ``ABSENT/heatmap.npy`` (ours, the verdict's) is the worst tenth's mean of
  :func:`verify.metrics.absence.absence`: a hue three totems saw at a point in front of the
  surface that the photo shows nowhere along their lines of sight (a removed object).

Heatmaps hold all 900 patches, as the NeRF path's; which patches are *kept* (overlap the
protected region) is a separate array. Totem pixels never enter a patch score (above the
totems there are none, but a patch size shrunk for a small image could reach them).

Patch AP (supplementary "Patch-level detection"): a kept patch is manipulated when more
than 10 % of its pixels are in ``manip_mask``; AP is sklearn's ``average_precision_score``
of the patch scores. (The NeRF path's released code scores *pixels* of the resized
heatmap instead; the contract and the paper's tables use patches.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.errors import BadInput
from verify.metrics.resolution import MIN_SIGMA_PX, blur_varying

__all__ = ["GRID", "PATCH_PX", "MIN_PATCH_PX", "NERF_L1_SCALE", "MANIP_FRACTION",
           "CHROMA_RADIUS_PX", "TOP_FRACTION", "POOLED_BY_WORST", "CHROMA_BLUR_PX",
           "METRICS", "PatchGrid", "patch_grid", "patch_fraction", "patch_means",
           "patch_top_means", "patch_scores", "pixel_errors", "chroma",
           "chroma_distance", "range_distance", "outside_range", "heatmaps",
           "patch_labels", "patch_ap", "to_pixels", "luma", "colorize", "heatmap_vis",
           "heatmap_overlay"]

GRID = 30
"""Patches per side of the grid (paper: 30 x 30)."""

PATCH_PX = 64
"""Patch side in pixels (paper: K = 64)."""

MIN_PATCH_PX = 8
"""Smallest patch side accepted when the image above the totems is shorter than 64 px."""

NERF_L1_SCALE = 2.0
"""L1 in ``heatmap.npy`` is on colours scaled to [-1, 1] (NeRF path): 2 x the [0, 1] L1."""

MANIP_FRACTION = 0.10
"""A patch is manipulated when more than this fraction of its pixels is in manip_mask."""

CHROMA_RADIUS_PX = 16
"""How far (pixels) the reconstruction may be off: the photo's chroma is compared with the
range of the reconstruction's chroma over a (2r+1)-pixel square. 16, a quarter of a
patch: a smaller radius favours inpainting, removals and shifts, a larger one colour
patches, splices and insertions (see docs/decisions.md, 'patches: CHROMA with a 16 px
radius')."""

TOP_FRACTION = MANIP_FRACTION
"""The hue metrics' patch score is the mean of the patch's worst ``TOP_FRACTION`` of
counted pixels (:func:`patch_top_means`), not of all of them: a patch is labelled
manipulated when a tenth of it is, and an edit of that size would otherwise be diluted
ten times by the untouched rest. RANGE keeps the mean: pooled by its worst pixels it
reads every edge the rebuilt view misplaces (see docs/decisions.md, 'patches: worst
tenth of pixels for the hue metrics')."""

POOLED_BY_WORST = ("CHROMA", "CORROB", "UNSEEN", "ABSENT")
"""Metrics whose patch score is :func:`patch_top_means`; the others (L1 and SSIM as the
NeRF path writes them, RANGE) are patch means."""

CHROMA_BLUR_PX = MIN_SIGMA_PX
"""Gaussian sigma (pixels) applied to the photo first when no map of the rays' spacing is
given (:mod:`verify.metrics.resolution` gives one per pixel, at least this): the
reconstruction has no detail finer than its totem rays' spacing (about 3 px at 640x480), so
neither should the photo it is compared with."""

METRICS = ("L1", "SSIM", "CHROMA", "RANGE", "CORROB", "UNSEEN", "ABSENT")
"""Every heatmap verify writes; CORROB (:mod:`verify.metrics.corroborate`) and ABSENT
(:mod:`verify.metrics.absence`) need the fit's totem rays and are not written for a fit
saved without them (UNSEEN is then CHROMA's)."""


@dataclass(frozen=True)
class PatchGrid:
    """The 30 x 30 patch grid above the totems.

    Attributes
    ----------
    rows : (G,) int, top row ``y0`` of each grid row of patches.
    cols : (G,) int, left column ``x0`` of each grid column.
    size : patch side in pixels.
    y_valid : rows ``[0, y_valid)`` lie above the totems (the cropped image).
    shape : (H, W) of the full image.
    """

    rows: np.ndarray
    cols: np.ndarray
    size: int
    y_valid: int
    shape: tuple[int, int]

    @property
    def n(self) -> int:
        return len(self.rows)

    def box(self, a: int, b: int) -> list[int]:
        """Pixel box ``[x0, y0, x1, y1]`` (end exclusive) of patch (row a, column b)."""
        y0, x0 = int(self.rows[a]), int(self.cols[b])
        return [x0, y0, x0 + self.size, y0 + self.size]


def patch_grid(totem_mask: np.ndarray, *, grid: int = GRID,
               patch: int = PATCH_PX) -> PatchGrid:
    """The NeRF path's patch grid over the image above the totems.

    Parameters
    ----------
    totem_mask : (H, W) bool, union of the totem masks.
    grid : patches per side.
    patch : patch side in pixels; shrunk to fit (down to ``MIN_PATCH_PX``) when the
        image above the totems is smaller, which only happens for small test images.

    Raises
    ------
    BadInput when less than ``MIN_PATCH_PX`` rows lie above the totems.
    """
    totem_mask = np.asarray(totem_mask, dtype=bool)
    H, W = totem_mask.shape
    ys = np.nonzero(totem_mask.any(axis=1))[0]
    y_valid = int(ys.min()) if len(ys) else H
    size = min(int(patch), y_valid, W)
    if size < MIN_PATCH_PX:
        raise BadInput(f"only {y_valid} image rows lie above the totems; patches need "
                       f"at least {MIN_PATCH_PX} (place totems lower in the frame)")
    rows = np.linspace(0, y_valid - size, grid).astype(int)
    cols = np.linspace(0, W - size, grid).astype(int)
    return PatchGrid(rows, cols, size, y_valid, (H, W))


def _box_sums(values: np.ndarray, grid: PatchGrid) -> np.ndarray:
    """Sum of ``values`` (H, W) over every patch of the grid, (G, G), via an integral image."""
    S = np.zeros((values.shape[0] + 1, values.shape[1] + 1), dtype=np.float64)
    S[1:, 1:] = np.cumsum(np.cumsum(values, axis=0, dtype=np.float64), axis=1)
    y0, x0 = grid.rows[:, None], grid.cols[None, :]
    y1, x1 = y0 + grid.size, x0 + grid.size
    return S[y1, x1] - S[y0, x1] - S[y1, x0] + S[y0, x0]


def patch_fraction(mask: np.ndarray, grid: PatchGrid) -> np.ndarray:
    """Fraction of each patch's pixels where ``mask`` (H, W) is True, (G, G) in [0, 1]."""
    return _box_sums(np.asarray(mask, dtype=np.float64), grid) / grid.size ** 2


def patch_means(values: np.ndarray, grid: PatchGrid, weights=None) -> np.ndarray:
    """Mean of ``values`` (H, W) over each patch, counting only pixels where ``weights``
    and where the value is finite (NaN: not known there).

    Returns (G, G) float64, NaN for a patch with no counted pixel.
    """
    values = np.asarray(values, dtype=np.float64)
    w = np.ones(values.shape) if weights is None else np.asarray(weights, np.float64)
    known = np.isfinite(values)
    w = np.where(known, w, 0.0)
    values = np.where(known, values, 0.0)
    num = _box_sums(values * w, grid)
    den = _box_sums(w, grid)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def patch_top_means(values: np.ndarray, grid: PatchGrid, weights=None, *,
                    fraction: float = TOP_FRACTION) -> np.ndarray:
    """Mean of the largest ``fraction`` of each patch's counted pixels.

    A pixel counts where ``weights`` (H, W) bool (default all) and its value is finite;
    of a patch's ``n`` counted pixels the ``max(1, ceil(fraction * n))`` largest are
    averaged. Returns (G, G) float64, NaN for a patch with no counted pixel.
    """
    values = np.asarray(values, dtype=np.float64)
    w = np.ones(values.shape, bool) if weights is None else np.asarray(weights, bool)
    v = np.where(w & np.isfinite(values), values, -np.inf).astype(np.float32)
    s = grid.size
    windows = np.lib.stride_tricks.sliding_window_view(v, (s, s))
    stack = windows[np.ix_(grid.rows, grid.cols)].reshape(grid.n, grid.n, s * s)
    n = np.isfinite(stack).sum(axis=-1)
    k = np.maximum(1, np.ceil(fraction * n - 1e-9)).astype(int)
    kmax = int(k.max())
    if kmax < stack.shape[-1]:                   # only the kmax largest are needed
        stack = -np.partition(-stack, kmax - 1, axis=-1)[..., :kmax]
    stack = -np.sort(-stack, axis=-1)                      # largest first, -inf last
    sums = np.cumsum(np.where(np.isfinite(stack), stack, 0.0), axis=-1, dtype=np.float64)
    top = np.take_along_axis(sums, (k - 1)[..., None], axis=-1)[..., 0] / k
    return np.where(n > 0, top, np.nan)


def patch_scores(errors: dict[str, np.ndarray], grid: PatchGrid,
                 valid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each metric's (G, G) patch score over the ``valid`` (H, W) bool pixels (default
    all), in the metric's own units: the patch mean, or for ``POOLED_BY_WORST`` the
    mean of the patch's worst ``TOP_FRACTION``."""
    return {name: (patch_top_means(err, grid, valid) if name in POOLED_BY_WORST
                   else patch_means(err, grid, valid))
            for name, err in errors.items()}


def pixel_errors(image: np.ndarray, recon: np.ndarray, *, sigma=CHROMA_BLUR_PX,
                 chroma_sigma=None, blurred=None) -> dict[str, np.ndarray]:
    """Per-pixel disagreement maps between photo and reconstruction.

    Parameters
    ----------
    image, recon : (H, W, 3) sRGB in [0, 1].
    sigma, chroma_sigma : the photo's blur (pixels, a number or an (H, W) map,
        :mod:`verify.metrics.resolution`) before RANGE and before CHROMA (default
        ``sigma``).
    blurred : the photo already blurred by ``sigma``
        (:func:`verify.metrics.resolution.blur_varying`), when the caller has it; CHROMA
        reads it too where ``chroma_sigma`` is the same (a chroma is linear in the colour).

    Returns
    -------
    {"L1": (H, W) mean over channels of |image - recon| (sRGB, [0, 1]),
     "SSIM": (H, W) 1 - SSIM map averaged over channels, [0, 2],
     "CHROMA": (H, W) :func:`chroma_distance`, sRGB [0, 1],
     "RANGE": (H, W) :func:`range_distance`, sRGB [0, 1]}.
    """
    from skimage.metrics import structural_similarity

    image = np.asarray(image, dtype=np.float64)
    recon = np.asarray(recon, dtype=np.float64)
    if image.shape != recon.shape or image.ndim != 3 or image.shape[2] != 3:
        raise BadInput(f"reconstruction is {recon.shape[:2]} but the photo is "
                       f"{image.shape[:2]}; refit this scene")
    l1 = np.abs(image - recon).mean(axis=2)
    if min(image.shape[:2]) < 7:
        raise BadInput("the image is smaller than the 7 px SSIM window")
    _, S = structural_similarity(image, recon, channel_axis=2, data_range=1.0, full=True,
                                 gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False)
    photo = blur_varying(image, sigma) if blurred is None else np.asarray(blurred)
    same = chroma_sigma is None or np.array_equal(chroma_sigma, sigma)
    hue_photo = photo if same else blur_varying(image, chroma_sigma)
    return {"L1": l1, "SSIM": 1.0 - S.mean(axis=2),
            "CHROMA": chroma_distance(hue_photo, recon, sigma=0.0),
            "RANGE": range_distance(photo, recon, sigma=0.0)}


def chroma(rgb: np.ndarray) -> np.ndarray:
    """A colour minus its grey level, ``rgb - mean(rgb)`` per pixel (same units and
    shape): what is left when brightness is taken away."""
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb - rgb.mean(axis=-1, keepdims=True)


def chroma_distance(image: np.ndarray, recon: np.ndarray, *,
                    radius: int = CHROMA_RADIUS_PX, sigma=CHROMA_BLUR_PX) -> np.ndarray:
    """How far each photo pixel's chroma lies outside the reconstruction's nearby range.

    The photo's :func:`chroma` is blurred by a Gaussian of ``sigma`` px (a number, or
    an (H, W) map, :func:`verify.metrics.resolution.blur_varying`); the
    reconstruction's gives, per channel, a lowest and a highest value over the
    ``(2 radius + 1)``-pixel square around the pixel. The distance is how far the photo's
    value falls outside ``[lowest, highest]``, averaged over the channels: zero wherever
    the photo's hue appears in the reconstruction within ``radius`` px, whatever the
    brightness.

    The box of per-channel ranges is loose in a colourful neighbourhood (a pastel on red
    next to green passes), but where the reconstruction is sharp it still matches the
    blurred photo's edge between two colours, as the nearest chroma would not (see
    docs/decisions.md, 'patches: the box of ranges, not the nearest chroma').

    Parameters
    ----------
    image, recon : (H, W, 3) sRGB in [0, 1].

    Returns
    -------
    (H, W) float64, sRGB units, >= 0.
    """
    return outside_range(chroma(image), chroma(recon), radius=radius, sigma=sigma)


def range_distance(image: np.ndarray, recon: np.ndarray, *,
                   radius: int = CHROMA_RADIUS_PX, sigma=CHROMA_BLUR_PX) -> np.ndarray:
    """How far each photo pixel's colour lies outside the reconstruction's nearby range.

    :func:`chroma_distance` on the sRGB values themselves: brightness counts too, so a
    grey, black or white patch (no hue) is seen, while the view's edges a few pixels
    off and its blur are forgiven within ``radius`` px (L1 counts them everywhere).
    Parameters and result as :func:`chroma_distance`: sRGB in [0, 1], (H, W) >= 0.

    The converse (the view's colour outside the photo's range) is not tested: the
    photo's sharp texture spans the blurred view's colours (see docs/decisions.md,
    'patches: no converse range test').
    """
    return outside_range(image, recon, radius=radius, sigma=sigma)


def outside_range(photo: np.ndarray, recon: np.ndarray, *, radius: int,
                  sigma) -> np.ndarray:
    """Per pixel, how far ``photo`` (blurred by a Gaussian of ``sigma`` px, a number or
    an (H, W) map) falls outside ``[lowest, highest]`` of ``recon`` over the
    ``(2 radius + 1)``-pixel square around it, per channel, averaged over the channels.
    Both (H, W, C), same units."""
    from scipy import ndimage

    photo = blur_varying(photo, sigma)
    recon = np.asarray(recon, np.float64)
    k = (2 * int(radius) + 1, 2 * int(radius) + 1, 1)
    low = ndimage.minimum_filter(recon, size=k, mode="nearest")
    high = ndimage.maximum_filter(recon, size=k, mode="nearest")
    return np.maximum(np.maximum(low - photo, photo - high), 0.0).mean(axis=2)


def heatmaps(errors: dict[str, np.ndarray], grid: PatchGrid,
             valid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """NeRF-path heatmaps, (G, G) per metric, from :func:`pixel_errors`.

    ``valid`` (H, W) bool selects the pixels that count (default all); pass
    ``~totem_mask`` for the files, or ``protected & ~totem_mask`` for the verdict.
    Each is :func:`patch_scores`' (a patch mean, or the worst tenth's mean for the hue
    metrics); L1 is returned in NeRF units (x ``NERF_L1_SCALE``), SSIM as 1 - SSIM.
    """
    return {name: h * NERF_L1_SCALE if name == "L1" else h
            for name, h in patch_scores(errors, grid, valid).items()}


def patch_labels(manip_mask: np.ndarray, grid: PatchGrid,
                 fraction: float = MANIP_FRACTION) -> np.ndarray:
    """(G, G) bool: patches with more than ``fraction`` of their pixels manipulated."""
    return patch_fraction(manip_mask, grid) > fraction


def patch_ap(scores: np.ndarray, labels: np.ndarray, keep: np.ndarray) -> float | None:
    """Average precision of patch ``scores`` for ``labels`` over the ``keep`` patches.

    All three are (G, G). Returns None when no kept patch is manipulated (AP undefined).
    Patches with a NaN score are dropped.
    """
    from sklearn.metrics import average_precision_score

    keep = np.asarray(keep, bool) & np.isfinite(scores)
    y = np.asarray(labels, bool)[keep]
    if not y.any():
        return None
    return float(average_precision_score(y, np.asarray(scores)[keep]))


# --------------------------------------------------------------------------- pictures

def to_pixels(heat: np.ndarray, grid: PatchGrid) -> np.ndarray:
    """Heatmap (G, G) interpolated to the cropped image, (y_valid, W).

    Each patch value sits at its patch's centre; bilinear in between, constant beyond
    the outermost centres. NaN patches count as 0.
    """
    heat = np.nan_to_num(np.asarray(heat, dtype=np.float64))
    ri = np.unique(grid.rows, return_index=True)[1]
    ci = np.unique(grid.cols, return_index=True)[1]
    h = heat[np.ix_(ri, ci)]
    i0, i1, wy = _linear(np.arange(grid.y_valid), grid.rows[ri] + (grid.size - 1) / 2.0)
    j0, j1, wx = _linear(np.arange(grid.shape[1]), grid.cols[ci] + (grid.size - 1) / 2.0)
    top = h[i0][:, j0] * (1 - wx) + h[i0][:, j1] * wx
    bottom = h[i1][:, j0] * (1 - wx) + h[i1][:, j1] * wx
    return top * (1 - wy)[:, None] + bottom * wy[:, None]


def _linear(q: np.ndarray, c: np.ndarray):
    """Indices and weight of clamped linear interpolation of queries ``q`` on knots ``c``."""
    q = np.clip(np.asarray(q, dtype=np.float64), c[0], c[-1])
    i1 = np.clip(np.searchsorted(c, q, side="right"), 1, max(len(c) - 1, 1))
    i0 = i1 - 1
    if len(c) == 1:
        return np.zeros(len(q), int), np.zeros(len(q), int), np.zeros(len(q))
    w = (q - c[i0]) / (c[i1] - c[i0])
    return i0, i1, np.clip(w, 0.0, 1.0)


def luma(image) -> np.ndarray:
    """(H, W) float32 grey level of an sRGB image (H, W, 3) (Rec. 601 weights): the
    pictures' grey under their colours."""
    return np.asarray(image, dtype=np.float32) @ np.array([0.299, 0.587, 0.114],
                                                          dtype=np.float32)


def colorize(values: np.ndarray, vmax: float, cmap: str = "turbo") -> np.ndarray:
    """Map ``values`` in [0, vmax] through a matplotlib colour map, (..., 3) sRGB [0, 1]."""
    import matplotlib

    t = np.clip(np.nan_to_num(values) / max(float(vmax), 1e-12), 0.0, 1.0)
    return matplotlib.colormaps[cmap](t)[..., :3].astype(np.float32)


def heatmap_vis(heat: np.ndarray, grid: PatchGrid, vmax: float) -> np.ndarray:
    """The colour picture of a heatmap over the cropped image, (y_valid, W, 3) sRGB."""
    return colorize(to_pixels(heat, grid), vmax)


def heatmap_overlay(image: np.ndarray, heat: np.ndarray, grid: PatchGrid,
                    protected: np.ndarray, totem_mask: np.ndarray, vmax: float, *,
                    alpha: float = 0.6, dim: float = 0.6) -> np.ndarray:
    """The photo in grey with the heatmap's colours inside the protected region.

    Parameters
    ----------
    image : (H, W, 3) sRGB [0, 1].
    heat : (G, G) heatmap; grid : its :class:`PatchGrid`.
    protected, totem_mask : (H, W) bool.
    vmax : value mapped to the top of the colour map.
    alpha : weight of the colours; dim : brightness of the grey outside the region.

    Returns
    -------
    (H, W, 3) sRGB [0, 1]. Outside the protected region, below the patch grid and on the
    totems the photo is grey and dimmed.
    """
    grey = luma(image)
    out = np.repeat(grey[..., None] * dim, 3, axis=2)
    yv = grid.y_valid
    colour = heatmap_vis(heat, grid, vmax)
    show = np.asarray(protected, bool)[:yv] & ~np.asarray(totem_mask, bool)[:yv]
    top = (1.0 - alpha) * grey[:yv, :, None] + alpha * colour
    out[:yv][show] = top[show]
    return out
