"""A camera photo to a scene folder (``totems ingest``).

The photo (and any totem masks drawn on it) is undistorted with the calibration's lens
model so that the pinhole model of the totem physics holds (paper, Sec. 5 "Real
images"); the scene folder's ``calib.npy`` then holds the K of the undistorted image.
The NeRF path's data set was made the same way ("image.png: undistorted using
calib.npy", "totem_masks/: annotated+undistorted").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

__all__ = ["RESERVED", "undistort_maps", "undistort", "ingest"]

RESERVED = {*folder.PHOTO_NAMES, "calib.npy", "totems.json", "manip_mask.png",
            "initial_totem_pose.npy", "totem_masks_check.png"}


def undistort_maps(K_raw, dist, K, size):
    """For each pixel of the undistorted image (K, size = (W, H)), where to sample the
    raw photo (lens K_raw, OpenCV ``dist``): two (H, W) float32 maps, pixels."""
    import cv2

    return cv2.initUndistortRectifyMap(np.asarray(K_raw, float), np.asarray(dist, float),
                                       None, np.asarray(K, float), tuple(size), cv2.CV_32FC1)


def undistort(image, K_raw, dist, K, *, nearest: bool = False) -> np.ndarray:
    """Undistort an image (H, W[, C]) to the pinhole camera K (same size).

    Bilinear for photos (as ``cv2.undistort``), nearest-neighbour for masks (so a mask
    stays binary). Pixels with no source are black (False for masks).
    """
    import cv2

    arr = np.asarray(image)
    H, W = arr.shape[:2]
    mx, my = undistort_maps(K_raw, dist, K, (W, H))
    src = arr.astype(np.uint8) if arr.dtype == bool else arr
    out = cv2.remap(src, mx, my, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.astype(bool) if arr.dtype == bool else out


def _lens(calib_path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_raw, dist, K) from a ``calib.npy``; no 'dist' means an undistorted camera."""
    calib = folder.read_calib(calib_path)
    K = calib["mtx"]
    K_raw = calib.get("mtx_raw", K)
    dist = calib.get("dist", np.zeros(5))
    if K_raw.shape != (3, 3) or not np.all(np.isfinite(K_raw)):
        raise BadInput(f"{calib_path}: 'mtx_raw' must be a finite 3x3 matrix")
    if dist.ndim > 2 or dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise BadInput(f"{calib_path}: 'dist' must hold 4, 5, 8, 12 or 14 finite OpenCV "
                       f"distortion coefficients")
    return K_raw, dist.ravel(), K


def _checked_key(key_path, n_masks: int) -> tuple[bytes, float, float]:
    """The key file checked (one entry, or one per totem), as bytes to copy, and its
    first (radius, ior)."""
    key_path = Path(key_path)
    try:
        data = json.loads(key_path.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        data = None                      # read_key below says what is wrong
    n = n_masks or (len(data) if isinstance(data, list) and data else 1)
    radius, ior = folder.read_key(key_path, n)
    return (json.dumps(data, indent=2) + "\n").encode(), float(radius[0]), float(ior[0])


def ingest(photo, calib_path, key_path, out, *, masks_dir=None) -> Path:
    """Write a scene folder at ``out`` from a camera photo.

    Parameters
    ----------
    photo : path of the photo as the camera wrote it (JPEG/PNG/TIFF, 8-bit sRGB).
    calib_path : ``calib.npy`` from :func:`scenes.photo.calibrate.calibrate` (or the NeRF
        path's): the lens model and the K of the undistorted image.
    key_path : ``totems.json``, the defender's key (radius in metres, IoR), one entry
        for all totems or one per totem.
    out : the new scene folder (must not exist, or be empty).
    masks_dir : optional folder of totem masks drawn on the *raw* photo (PNG, white =
        totem, photo size); undistorted nearest-neighbour and numbered left to right.
        Without it the folder has no ``totem_masks/``; ``totems masks OUT`` proposes them.

    Returns the scene folder. The raw photo is kept beside ``image.png`` as the NeRF
    path's data set does.
    """
    photo = Path(photo)
    image = folder.read_image(photo, what="photo")
    H, W = image.shape[:2]
    K_raw, dist, K = _lens(calib_path)
    if not (0 <= K[0, 2] < W and 0 <= K[1, 2] < H):
        raise BadInput(f"the calibration's principal point ({K[0, 2]:.0f}, {K[1, 2]:.0f}) "
                       f"lies outside the {W}x{H} photo; was it calibrated at another size?")

    masks = []
    if masks_dir is not None:
        files = sorted(Path(masks_dir).glob("*.png"))
        if not files:
            raise BadInput(f"no totem masks (*.png) in {masks_dir}")
        for f in files:
            m = folder.read_mask(f, what="totem mask")
            if m.shape != (H, W):
                raise BadInput(f"totem mask {f.name} is {m.shape[1]}x{m.shape[0]} but the "
                               f"photo is {W}x{H}")
            m = undistort(m, K_raw, dist, K, nearest=True)
            if m.sum() < 20:
                raise BadInput(f"totem mask {f.name} has no totem pixels after "
                               f"undistortion (white = totem)")
            masks.append(m)
        order = np.argsort([np.nonzero(m)[1].mean() for m in masks], kind="stable")
        masks = [masks[i] for i in order]

    key_bytes, radius, ior = _checked_key(key_path, len(masks))
    raw_name = photo.name if photo.name.lower() not in RESERVED else f"raw_{photo.name}"
    undistorted = undistort(image, K_raw, dist, K)
    # write_scene writes totems.json from (radius, ior); the file is then replaced by the
    # key as given, which may list one entry per totem before the masks exist
    return folder.write_scene(out, image=undistorted, K=K, masks=masks,
                              radius=radius, ior=ior,
                              extra_files={"totems.json": key_bytes,
                                           raw_name: photo.read_bytes()})
