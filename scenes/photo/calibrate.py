"""Camera calibration from checkerboard photos (``totems calib``).

The totem physics assumes a pinhole camera, so real photos are undistorted first
(paper, Sec. 5 "Real images": "We correct radial distortion in the collected
images"). This module finds the lens model ``K_raw, dist`` from photos of a
printed checkerboard (Zhang's method, as OpenCV implements it) and chooses the
intrinsics ``K`` of the undistorted images.

``calib.npy`` convention (readable by the NeRF path, which uses ``'mtx'`` as the K of
``image.png`` and ``'roi'`` to crop the undistortion's black border):

- ``'mtx'``     (3, 3) K of the *undistorted* image, pixel-centre convention;
- ``'dist'``    (5,) OpenCV distortion coefficients k1, k2, p1, p2, k3 of the lens;
- ``'roi'``     [x, y, w, h] the rectangle of the undistorted image with valid pixels;
- ``'mtx_raw'`` (3, 3) the lens' K in the raw (distorted) photo, used to undistort.

A ``calib.npy`` without ``'mtx_raw'`` (e.g. the NeRF path's own) is taken to mean
``mtx_raw == mtx``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

__all__ = ["DETECT_MAX_SIDE", "board_points", "find_corners", "calibrate",
           "undistorted_K", "valid_roi", "write_calib"]

DETECT_MAX_SIDE = 1600    # corners are found on a copy at most this wide, then refined


def board_points(board: tuple[int, int], square: float) -> np.ndarray:
    """Inner-corner positions on the board plane, (cols*rows, 3) float32, metres (z = 0).

    Ordered as ``cv2.findChessboardCorners`` returns them: row by row, x fastest.
    """
    cols, rows = board
    x, y = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([x.ravel(), y.ravel(), np.zeros(cols * rows)], -1).astype(
        np.float32) * np.float32(square)


def find_corners(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of the checkerboard in an 8-bit grey image, (m, 1, 2)
    float32 pixels, or None when the whole board is not found.

    Large photos are searched on a downscaled copy and refined at full resolution.
    """
    import cv2

    H, W = gray.shape
    scale = min(1.0, DETECT_MAX_SIDE / max(H, W))
    small = gray if scale == 1.0 else cv2.resize(gray, (round(W * scale), round(H * scale)),
                                                 interpolation=cv2.INTER_AREA)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(small, tuple(board), flags=flags)
    if not found:
        return None
    corners = corners / scale
    # the refinement window: about a third of the smallest corner spacing
    grid = corners.reshape(board[1], board[0], 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    win = int(np.clip(spacing / 3.0, 2, 11 / scale))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners.astype(np.float32), (win, win), (-1, -1), criteria)


def calibrate(images, board=(9, 6), square: float = 0.025, *, alpha: float = 0.0,
              min_views: int = 3) -> dict:
    """Calibrate a camera from photos of a checkerboard.

    Parameters
    ----------
    images : list of paths (PNG/JPEG/TIFF), all from the same camera at the same size.
    board : (cols, rows) number of *inner* corners of the board.
    square : side of one square, metres (sets the unit of the board poses only).
    alpha : ``cv2.getOptimalNewCameraMatrix`` free scaling of the undistorted image's K:
        0 keeps only valid pixels (no black border; the default, so every pixel of
        ``image.png`` is a real one), 1 keeps every source pixel (black border; crop
        with ``roi`` as the NeRF path does).
    min_views : fewest photos in which the board must be found.

    Returns
    -------
    dict with ``mtx`` (3, 3) K of the undistorted image, ``dist`` (5,), ``roi``
    [x, y, w, h], ``mtx_raw`` (3, 3) the lens' K, ``rms`` reprojection error in pixels,
    ``size`` (W, H), ``used`` list of the photos in which the board was found.

    Raises BadInput when fewer than ``min_views`` photos show the whole board.
    """
    import cv2

    cols, rows = (int(v) for v in board)
    if cols < 2 or rows < 2:
        raise BadInput(f"board must have at least 2x2 inner corners, got {cols}x{rows}")
    if cols == rows:
        raise BadInput(f"board {cols}x{rows} is square, so its orientation is ambiguous; "
                       f"use a board with different numbers of inner corners")
    if not (np.isfinite(square) and square > 0):
        raise BadInput(f"square must be a positive length in metres, got {square}")
    images = [Path(p) for p in images]
    if len(images) < min_views:
        raise BadInput(f"need at least {min_views} checkerboard photos, got {len(images)}")

    obj = board_points((cols, rows), square)
    obj_pts, img_pts, used, size = [], [], [], None
    for path in images:
        rgb = folder.read_image(path, what="checkerboard photo")
        gray = cv2.cvtColor((rgb * 255.0 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY)
        if size is None:
            size = (gray.shape[1], gray.shape[0])
        elif size != (gray.shape[1], gray.shape[0]):
            raise BadInput(f"{path.name} is {gray.shape[1]}x{gray.shape[0]} but the first "
                           f"photo is {size[0]}x{size[1]}; calibrate one camera setting")
        corners = find_corners(gray, (cols, rows))
        if corners is not None:
            obj_pts.append(obj)
            img_pts.append(corners)
            used.append(str(path))
    if len(used) < min_views:
        raise BadInput(f"the {cols}x{rows} inner-corner board was found in {len(used)} of "
                       f"{len(images)} photos, need {min_views}; check --board (inner "
                       f"corners, COLSxROWS) and that the whole board is in view")

    rms, K_raw, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None)
    K = undistorted_K(K_raw, dist, size, alpha=alpha)
    return {"mtx": K, "dist": np.asarray(dist, float).ravel(),
            "roi": valid_roi(K_raw, dist, K, size), "mtx_raw": np.asarray(K_raw, float),
            "rms": float(rms), "size": size, "used": used}


def undistorted_K(K_raw, dist, size, *, alpha: float = 0.0) -> np.ndarray:
    """The K of the undistorted image, square pixels (fx == fy, as the renderer needs).

    ``cv2.getOptimalNewCameraMatrix`` scales x and y separately; its larger focal
    length (alpha < 0.5: no black border) or smaller (alpha >= 0.5: every source pixel
    kept) is used for both axes.
    """
    import cv2

    K, _ = cv2.getOptimalNewCameraMatrix(np.asarray(K_raw, float), np.asarray(dist, float),
                                         tuple(size), alpha, tuple(size))
    f = max(K[0, 0], K[1, 1]) if alpha < 0.5 else min(K[0, 0], K[1, 1])
    K = np.asarray(K, float).copy()
    K[0, 0] = K[1, 1] = f
    return K


def valid_roi(K_raw, dist, K, size) -> list[int]:
    """[x, y, w, h]: a rectangle of the undistorted image (K) where every pixel has a
    source pixel in the raw photo (the part the NeRF path keeps with ``roi``)."""
    from scenes.photo.ingest import undistort

    W, H = size
    valid = undistort(np.ones((H, W), bool), K_raw, dist, K, nearest=True)
    for scale in np.linspace(1.0, 0.02, 99):     # largest centred box of the image's shape
        w, h = max(1, round(W * scale)), max(1, round(H * scale))
        x0, y0 = (W - w) // 2, (H - h) // 2
        x1, y1 = x0 + w, y0 + h
        if valid[y0:y1, x0:x1].all():
            break
    else:
        return [0, 0, 0, 0]
    grown = True
    while grown:                                 # then push each side out while valid
        grown = False
        if x0 > 0 and valid[y0:y1, x0 - 1].all():
            x0, grown = x0 - 1, True
        if x1 < W and valid[y0:y1, x1].all():
            x1, grown = x1 + 1, True
        if y0 > 0 and valid[y0 - 1, x0:x1].all():
            y0, grown = y0 - 1, True
        if y1 < H and valid[y1, x0:x1].all():
            y1, grown = y1 + 1, True
    return [int(x0), int(y0), int(x1 - x0), int(y1 - y0)]


def write_calib(calib: dict, path) -> Path:
    """Write the result of :func:`calibrate` as ``calib.npy`` (atomically)."""
    path = Path(path)
    folder.write_calib(path, calib["mtx"], dist=calib.get("dist"), roi=calib.get("roi"),
                       mtx_raw=calib.get("mtx_raw"))
    return path
