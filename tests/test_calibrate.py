"""scenes/calibrate: a known camera is recovered from rendered checkerboard views."""

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from scenes import folder
from scenes.errors import BadInput
from scenes.photo.calibrate import board_points, calibrate, write_calib

BOARD = (8, 5)          # inner corners
SQUARE = 0.03           # metres
PPM = 2000.0            # board texture pixels per metre


def _board_texture():
    """The printed board: (cols+1) x (rows+1) squares and a white margin of one square.

    Board-plane point (X, Y) (metres, first inner corner at 0) sits at texture pixel
    ((X + 2 * SQUARE) * PPM, (Y + 2 * SQUARE) * PPM).
    """
    cols, rows = BOARD
    s = int(SQUARE * PPM)
    tex = np.full(((rows + 5) * s, (cols + 5) * s), 255, np.uint8)
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                tex[(j + 1) * s:(j + 2) * s, (i + 1) * s:(i + 2) * s] = 0
    return tex


def _rotation(rx, ry, rz):
    R, _ = cv2.Rodrigues(np.radians([rx, ry, rz]))
    return R


def _render_view(tex, K, R, t, size):
    """Image of the board with plane-to-camera pose (R, t): homography K [r1 r2 t]."""
    H_plane = K @ np.column_stack([R[:, 0], R[:, 1], t])
    tex_from_plane = np.array([[PPM, 0, 2 * SQUARE * PPM], [0, PPM, 2 * SQUARE * PPM],
                               [0, 0, 1]])
    H = H_plane @ np.linalg.inv(tex_from_plane)
    img = cv2.warpPerspective(tex, H, size, flags=cv2.INTER_AREA,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=160)
    return np.repeat(img[..., None], 3, axis=2)


def _views(K, size, tmp_path):
    centre = board_points(BOARD, SQUARE).mean(0)
    paths = []
    for k, (rx, ry, rz, z) in enumerate([(0, 0, 0, 0.5), (25, 0, 5, 0.55), (-25, 10, -5, 0.5),
                                         (0, 30, 10, 0.6), (10, -30, 0, 0.55),
                                         (-20, -20, 15, 0.6), (30, 20, -10, 0.6)]):
        R = _rotation(rx, ry, rz)
        t = np.array([0.0, 0.0, z]) - R @ centre     # board centre on the optical axis
        p = tmp_path / f"board_{k}.png"
        folder.write_image(p, _render_view(_board_texture(), K, R, t, size))
        paths.append(p)
    return paths


def test_recovers_known_intrinsics(tmp_path):
    size = (640, 480)
    K = np.array([[700.0, 0, 330.0], [0, 700.0, 236.0], [0, 0, 1]])
    calib = calibrate(_views(K, size, tmp_path), board=BOARD, square=SQUARE)
    assert len(calib["used"]) == 7
    assert calib["rms"] < 0.5
    fx, fy, cx, cy = calib["mtx_raw"][[0, 1, 0, 1], [0, 1, 2, 2]]
    assert fx == pytest.approx(700.0, rel=0.01) and fy == pytest.approx(700.0, rel=0.01)
    assert cx == pytest.approx(330.0, rel=0.01) and cy == pytest.approx(236.0, rel=0.01)
    # no lens distortion rendered: the undistorted image keeps (nearly) the same K
    assert np.allclose(calib["mtx"], K, rtol=0.02)
    write_calib(calib, tmp_path / "calib.npy")
    back = folder.read_calib(tmp_path / "calib.npy")
    assert np.allclose(back["mtx"], calib["mtx"]) and np.allclose(back["dist"], calib["dist"])
    assert np.allclose(back["mtx_raw"], calib["mtx_raw"])
    assert list(back["roi"]) == calib["roi"]


def test_no_board_is_bad_input(tmp_path):
    rng = np.random.default_rng(0)
    paths = []
    for k in range(3):
        p = tmp_path / f"noise_{k}.png"
        folder.write_image(p, rng.random((120, 160, 3)))
        paths.append(p)
    with pytest.raises(BadInput, match="found in 0 of 3"):
        calibrate(paths, board=BOARD, square=SQUARE)


def test_square_board_refused(tmp_path):
    with pytest.raises(BadInput, match="ambiguous"):
        calibrate([tmp_path / "a.png"] * 3, board=(6, 6), square=0.02)
