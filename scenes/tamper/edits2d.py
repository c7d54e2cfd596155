"""Pixel edits of a photograph: the forger's 2D tools.

Every function takes 8-bit sRGB images (H, W, 3) uint8 and returns a new uint8 image
with the bool footprint of what it touched, so that pixels outside the footprint are the
input's bit for bit (the manipulation mask of a tampered scene is that footprint).
Colours are never linearised: a forger's tools work on the 8-bit sRGB values.
Selections ((H, W) bool) are grown, moved and boxed by :mod:`scenes.masks`.

References
----------
The manipulations of the totems paper, Sec. 5 "Image manipulations": randomly coloured
patches, image splicing of a person, Photoshop content-aware fill (here OpenCV's
inpainting, Telea 2004 or Navier-Stokes), and the reference shift.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from scipy import ndimage as ndi

from scenes.masks import bbox, shift_mask

__all__ = ["INPAINT_METHODS", "astronaut_cutout", "blur_within", "clone_fill",
           "composite", "disc_alpha", "feathered_alpha", "inpaint", "move_pixels",
           "paste_patches", "recolour", "scaled_cutout", "shifted", "splice"]

INPAINT_METHODS = {"telea": cv2.INPAINT_TELEA, "ns": cv2.INPAINT_NS}


def _check_image(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) uint8 image, got {image.dtype} "
                         f"{image.shape}")
    return image


# --------------------------------------------------------------------------- edits

def paste_patches(image, boxes, colors, *, keep=None):
    """Paste flat-coloured rectangles.

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB.
    boxes : sequence of (x, y, w, h) in pixels (column, row of the top-left corner).
    colors : sequence of (r, g, b) 8-bit sRGB, one per box.
    keep : optional (H, W) bool, pixels never to paint (e.g. totems).

    Returns
    -------
    out : (H, W, 3) uint8; footprint : (H, W) bool, the painted pixels.
    """
    image = _check_image(image)
    out = image.copy()
    footprint = np.zeros(image.shape[:2], bool)
    for (x, y, w, h), c in zip(boxes, colors):
        footprint[y:y + h, x:x + w] = True
        out[y:y + h, x:x + w] = np.asarray(c, np.uint8)
    if keep is not None:
        footprint &= ~np.asarray(keep, bool)
        out = np.where(footprint[..., None], out, image)
    return out, footprint


def composite(image, fg, alpha):
    """Alpha-blend ``fg`` over ``image`` in 8-bit sRGB (what an editor's layer does).

    Parameters
    ----------
    image, fg : (H, W, 3) uint8 sRGB.
    alpha : (H, W) float in [0, 1], the layer's opacity.

    Returns
    -------
    out : (H, W, 3) uint8, ``round(alpha fg + (1 - alpha) image)`` where alpha > 0 and
    ``image`` exactly elsewhere; footprint : (H, W) bool, alpha > 0.
    """
    image = _check_image(image)
    fg = _check_image(fg)
    alpha = np.clip(np.asarray(alpha, np.float32), 0.0, 1.0)
    footprint = alpha > 0
    a = alpha[..., None]
    blend = np.rint(a * fg + (1.0 - a) * image).astype(np.uint8)
    out = np.where(footprint[..., None], blend, image)
    return out, footprint


def inpaint(image, mask, *, method: str = "telea", radius: float = 5.0):
    """Fill ``mask`` from its surroundings (the stand-in for content-aware fill).

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB.
    mask : (H, W) bool, pixels to replace.
    method : "telea" (Telea 2004, fast marching) or "ns" (Navier-Stokes).
    radius : neighbourhood radius in pixels.

    Returns
    -------
    out : (H, W, 3) uint8 equal to ``image`` outside ``mask``; footprint : ``mask``.
    """
    image = _check_image(image)
    mask = np.asarray(mask, bool)
    if method not in INPAINT_METHODS:
        raise ValueError(f"inpaint method must be one of {sorted(INPAINT_METHODS)}")
    filled = cv2.inpaint(np.ascontiguousarray(image), mask.astype(np.uint8) * 255,
                         float(radius), INPAINT_METHODS[method])
    out = np.where(mask[..., None], filled, image)
    return out, mask.copy()


def clone_fill(image, mask, *, avoid=None, feather_px: float = 3.0):
    """Fill ``mask`` with texture copied from one offset of the image (a clone stamp),
    its seam blended into an inpainted fill: content-aware fill in its simplest form.

    The offset is chosen among sideways moves past the hole's box (along a row, a
    floor or a wall facing the camera keeps its depth, so texture keeps its scale)
    as the one whose copy of the hole's surrounding ring best matches the ring
    (mean absolute difference), with the copied pixels inside the image and at most
    15% of them in ``mask`` or ``avoid`` (those get the inpainted fill). Falls back
    to :func:`inpaint` when no offset fits.

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB.
    mask : (H, W) bool, pixels to replace.
    avoid : optional (H, W) bool, pixels never copied from (e.g. totems).
    feather_px : depth (pixels) over which the clone fades in from the hole's edge.

    Returns
    -------
    out : (H, W, 3) uint8 equal to ``image`` outside ``mask``; footprint : ``mask``;
    offset : (dx, dy) used, or None for the inpainting fallback.
    """
    image = _check_image(image)
    mask = np.asarray(mask, bool)
    H, W = mask.shape
    bad = mask if avoid is None else mask | np.asarray(avoid, bool)
    # the smooth fill draws on the allowed surroundings only, never on ``avoid``
    smooth = np.where(mask[..., None], inpaint(image, bad)[0], image)
    if not mask.any():
        return smooth, mask.copy(), None
    ring = ndi.binary_dilation(mask, iterations=3) & ~bad
    ys, xs = np.nonzero(mask)
    x0, y0, w, h = bbox(mask)
    offsets = [(s * (w + k), 0) for s in (-1, 1)
               for k in (2, 6, 12, 24, 48, w // 2, w, 2 * w)]
    best, best_cost = None, np.inf
    ry, rx = np.nonzero(ring)
    for dx, dy in offsets:
        if x0 + dx < 0 or y0 + dy < 0 or x0 + w + dx > W or y0 + h + dy > H:
            continue                           # the copied pixels leave the image
        sy, sx = ys + dy, xs + dx
        if bad[sy, sx].mean() > 0.15:          # mostly allowed pixels to copy
            continue
        ok = (ry + dy >= 0) & (ry + dy < H) & (rx + dx >= 0) & (rx + dx < W)
        if not ok.any():
            continue
        cost = np.abs(image[ry[ok] + dy, rx[ok] + dx].astype(np.int16)
                      - image[ry[ok], rx[ok]]).mean()
        if cost < best_cost:
            best, best_cost = (dx, dy), cost
    if best is None:
        return smooth, mask.copy(), None
    dx, dy = best
    clone = image.copy()
    my, mx = np.nonzero(mask)
    clone[my, mx] = image[my + dy, mx + dx]
    usable = mask.copy()                       # where the copied pixel is allowed
    usable[my, mx] = ~bad[my + dy, mx + dx]
    depth = ndi.distance_transform_edt(usable)
    a = np.clip(depth / max(feather_px, 1e-6), 0.0, 1.0)[..., None]
    blend = np.rint(a * clone + (1.0 - a) * smooth).astype(np.uint8)
    out = np.where(mask[..., None], blend, image)
    return out, mask.copy(), (int(dx), int(dy))


def move_pixels(image, mask, dx: int, dy: int, *, within=None, method: str = "clone"):
    """Cut the pixels of ``mask``, fill the hole, paste them back (dx, dy) pixels away.

    The forger's "move" tool: the object's own pixels are copied unchanged, the hole it
    leaves is inpainted from its surroundings.

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB.
    mask : (H, W) bool, the pixels of the thing moved.
    dx, dy : integer shift in pixels (right, down).
    within : optional (H, W) bool; pixels outside it are never written (e.g. to keep
        an edit inside one totem's view).
    method : hole fill: "clone" (:func:`clone_fill`, copying only from ``within``) or
        an inpainting method of :func:`inpaint`.

    Returns
    -------
    out : (H, W, 3) uint8; footprint : (H, W) bool, the pixels written.
    """
    image = _check_image(image)
    mask = np.asarray(mask, bool)
    allowed = np.ones(mask.shape, bool) if within is None else np.asarray(within, bool)
    if method == "clone":
        filled, _, _ = clone_fill(image, mask & allowed, avoid=~allowed)
    else:
        filled, _ = inpaint(image, mask & allowed, method=method)
    src = mask
    dst = shift_mask(mask, dx, dy)
    ys, xs = np.nonzero(dst)
    pasted = filled.copy()
    pasted[ys, xs] = image[ys - dy, xs - dx]
    dst &= allowed
    out = np.where(dst[..., None], pasted, filled)
    footprint = (src | dst) & allowed
    out = np.where(footprint[..., None], out, image)
    return out, footprint


def shifted(image, dx: int, dy: int):
    """``image`` moved by (dx, dy) pixels (right, down): the clone stamp's source layer,
    whose pixel (x, y) is the input's (x - dx, y - dy) (the edge repeated beyond it).
    (H, W, 3) uint8 in and out."""
    image = _check_image(image)
    H, W = image.shape[:2]
    ys = np.clip(np.arange(H) - int(dy), 0, H - 1)
    xs = np.clip(np.arange(W) - int(dx), 0, W - 1)
    return image[ys][:, xs].copy()


def blur_within(image, within, sigma_px: float):
    """A Gaussian blur (sigma in pixels) that reads only the pixels of ``within`` (an
    editor's blur of a selection: nothing outside it bleeds in), in 8-bit sRGB.

    Returns (H, W, 3) uint8, the blurred values at every pixel of ``within`` (a pixel
    with no ``within`` pixel in reach keeps its own); the input elsewhere.
    """
    image = _check_image(image)
    w = np.asarray(within, bool)
    wf = w.astype(np.float32)
    num = ndi.gaussian_filter(image.astype(np.float32) * wf[..., None],
                              (sigma_px, sigma_px, 0))
    den = ndi.gaussian_filter(wf, sigma_px)[..., None]
    blurred = np.where(den > 1e-6, num / np.maximum(den, 1e-6), image)
    out = np.rint(np.clip(blurred, 0, 255)).astype(np.uint8)
    return np.where(w[..., None], out, image)


def recolour(image, hue_deg: float, saturation: float):
    """An editor's hue/saturation layer: every pixel's hue turned by ``hue_deg``
    degrees and its saturation raised to at least ``saturation`` (0-1), so grey turns
    coloured too; value kept. (H, W, 3) uint8 sRGB in and out."""
    image = _check_image(image)
    hsv = cv2.cvtColor(image.astype(np.float32) / 255.0, cv2.COLOR_RGB2HSV)
    hsv[..., 0] = np.mod(hsv[..., 0] + float(hue_deg), 360.0)
    hsv[..., 1] = np.maximum(hsv[..., 1], float(saturation))
    rgb = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    return np.rint(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)


def disc_alpha(shape, centre, radius_px: float, feather_px: float):
    """A round brush's opacity: 1 inside the disc of ``radius_px`` about ``centre``
    (u, v) pixels, falling linearly to 0 over ``feather_px`` across its edge, quantised
    down to multiples of 1/255 (as :func:`feathered_alpha`). Returns (H, W) float32."""
    H, W = shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    dist = np.hypot(u - float(centre[0]), v - float(centre[1]))
    a = np.clip((float(radius_px) - dist) / max(float(feather_px), 1e-6) + 0.5, 0.0, 1.0)
    return np.floor(a * 255.0) / 255.0


def feathered_alpha(cover, feather_px: float):
    """A soft-edged opacity from a matte: the feather of an editor's selection.

    Parameters
    ----------
    cover : (h, w) float in [0, 1] (or bool), the matte.
    feather_px : Gaussian sigma of the edge blur, pixels (0: no feather).

    Returns
    -------
    (h, w) float32 in [0, 1], zero beyond 2 sigma outside the matte, quantised down to
    multiples of 1/255 so that alpha > 0 is where the blend may change a pixel.
    """
    m = np.asarray(cover, np.float32)
    if feather_px > 0:
        m = ndi.gaussian_filter(m, feather_px, truncate=2.0)
    return np.floor(np.clip(m, 0.0, 1.0) * 255.0) / 255.0


# --------------------------------------------------------------------------- the person

@functools.lru_cache(maxsize=1)
def astronaut_cutout():
    """A person cut from another photograph: scikit-image's ``astronaut`` (NASA, public
    domain), segmented by GrabCut seeded with a head/torso prior.

    Returns
    -------
    rgb : (h, w, 3) uint8 sRGB, cropped to the person; matte : (h, w) bool.
    Deterministic (OpenCV's RNG is seeded).
    """
    from skimage import data

    full = data.astronaut()
    s = cv2.resize(full, (256, 256), interpolation=cv2.INTER_AREA)
    gc = np.full(s.shape[:2], cv2.GC_BGD, np.uint8)
    gc[8:256, 12:187] = cv2.GC_PR_FGD
    cv2.ellipse(gc, (112, 50), (28, 36), 0, 0, 360, cv2.GC_FGD, -1)     # head
    gc[80:130, 90:140] = cv2.GC_FGD                                      # neck ring
    gc[150:230, 40:150] = cv2.GC_FGD                                     # torso
    cv2.setRNGSeed(0)
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.grabCut(s[:, :, ::-1].copy(), gc, None, bgd, fgd, 5, cv2.GC_INIT_WITH_MASK)
    m = (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)
    lab, n = ndi.label(m)
    if n > 1:
        m = lab == 1 + int(np.argmax(np.bincount(lab.ravel())[1:]))
    m = ndi.binary_fill_holes(m)
    # Full-resolution matte, cropped to the person's bounding box.
    M = cv2.resize(m.astype(np.uint8), full.shape[1::-1], interpolation=cv2.INTER_LINEAR) > 0
    x0, y0, w, h = bbox(M)
    return full[y0:y0 + h, x0:x0 + w].copy(), M[y0:y0 + h, x0:x0 + w].copy()


def scaled_cutout(rgb, matte, height_px: int, *, flip: bool = False):
    """Resize a cutout to ``height_px`` rows (area filter), optionally mirrored.

    Returns rgb (h, w, 3) uint8 and a coverage (h, w) float32 in [0, 1].
    """
    h, w = matte.shape
    height_px = max(int(height_px), 4)
    width_px = max(int(round(w * height_px / h)), 4)
    small = cv2.resize(rgb, (width_px, height_px), interpolation=cv2.INTER_AREA)
    cover = cv2.resize(matte.astype(np.float32), (width_px, height_px),
                       interpolation=cv2.INTER_AREA)
    if flip:
        small, cover = small[:, ::-1].copy(), cover[:, ::-1].copy()
    return small, cover


def splice(image, rgb, cover, x: int, y: int, *, feather_px: float = 1.5, keep=None):
    """Paste a cutout with a soft edge, its top-left corner at pixel (x, y).

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB, the photo.
    rgb : (h, w, 3) uint8 sRGB, the cutout; cover : (h, w) float in [0, 1], its matte.
    feather_px : softness of the edge (pixels).
    keep : optional (H, W) bool, pixels never written (e.g. the totems, which then
        appear in front of the pasted person).

    Returns
    -------
    out : (H, W, 3) uint8; footprint : (H, W) bool, the pixels the layer covers.
    """
    image = _check_image(image)
    H, W = image.shape[:2]
    # The layer: the cutout on a canvas padded by the feather's reach, its colours
    # extended past the matte's edge so the soft edge blends with the person's colours.
    p = int(np.ceil(2.0 * feather_px)) + 1
    cover = np.pad(np.asarray(cover, np.float32), p)
    rgb = np.pad(rgb, ((p, p), (p, p), (0, 0)), mode="edge")
    inside = cover > 0.5
    if inside.any():   # colour outside the matte = nearest colour inside it
        _, (iy, ix) = ndi.distance_transform_edt(~inside, return_indices=True)
        rgb = rgb[iy, ix]
    x, y = x - p, y - p
    h, w = cover.shape
    ys0, xs0 = max(y, 0), max(x, 0)
    ys1, xs1 = min(y + h, H), min(x + w, W)
    if ys1 <= ys0 or xs1 <= xs0:
        return image.copy(), np.zeros((H, W), bool)
    fg = np.zeros_like(image)
    alpha = np.zeros((H, W), np.float32)
    fg[ys0:ys1, xs0:xs1] = rgb[ys0 - y:ys1 - y, xs0 - x:xs1 - x]
    alpha[ys0:ys1, xs0:xs1] = feathered_alpha(cover, feather_px)[ys0 - y:ys1 - y,
                                                                 xs0 - x:xs1 - x]
    if keep is not None:
        alpha[np.asarray(keep, bool)] = 0.0
    return composite(image, fg, alpha)
