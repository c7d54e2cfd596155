"""scenes/ingest: a photo distorted by a known lens comes back as the pinhole image."""

import json

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from scenes import folder
from scenes.errors import BadInput
from scenes.photo.calibrate import undistorted_K, valid_roi
from scenes.photo.ingest import ingest

W, H = 320, 240
K_RAW = np.array([[300.0, 0, 161.0], [0, 300.0, 118.0], [0, 0, 1]])
DIST = np.array([-0.25, 0.08, 0.001, -0.001, 0.0])


def _pinhole_scene(K):
    """A smooth texture and a disk, as a pinhole camera K would see them."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    img = np.stack([0.5 + 0.4 * np.sin(u / 9.0) * np.cos(v / 13.0),
                    0.5 + 0.4 * np.cos((u + v) / 17.0),
                    0.5 + 0.3 * np.sin(v / 7.0)], -1)
    disk = (u - 230.0) ** 2 + (v - 70.0) ** 2 < 30.0 ** 2
    return img, disk


def _distort(img, K):
    """The raw photo: raw pixel p shows the pinhole pixel K * undistort(K_RAW, DIST, p)."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    pts = np.stack([u.ravel(), v.ravel()], -1)[:, None, :]
    src = cv2.undistortPoints(pts, K_RAW, DIST, P=K).reshape(H, W, 2)
    interp = cv2.INTER_NEAREST if img.dtype == bool else cv2.INTER_LINEAR
    out = cv2.remap(img.astype(np.float32), src[..., 0], src[..., 1], interp)
    return out > 0.5 if img.dtype == bool else out


@pytest.fixture
def lens(tmp_path):
    K = undistorted_K(K_RAW, DIST, (W, H))
    roi = valid_roi(K_RAW, DIST, K, (W, H))
    assert K[0, 0] == K[1, 1] and roi == [0, 0, W, H]     # alpha 0: no black border
    folder.write_calib(tmp_path / "calib.npy", K, dist=DIST, roi=roi, mtx_raw=K_RAW)
    folder.write_json(tmp_path / "totems.json", {"radius": 0.05, "ior": 1.5})
    return K, tmp_path / "calib.npy", tmp_path / "totems.json"


def test_undistorts_back_to_pinhole(tmp_path, lens):
    K, calib, key = lens
    truth, disk = _pinhole_scene(K)
    raw = _distort(truth, K)
    folder.write_image(tmp_path / "raw.png", raw)
    (tmp_path / "masks").mkdir()
    folder.write_image(tmp_path / "masks" / "a.png", _distort(disk, K))

    out = ingest(tmp_path / "raw.png", calib, key, tmp_path / "scene",
                 masks_dir=tmp_path / "masks")
    scene = folder.read_scene(out)
    assert np.allclose(scene.K, K)
    inner = np.s_[10:-10, 10:-10]
    err = np.abs(scene.image - truth)[inner].mean()
    err_raw = np.abs(raw - truth)[inner].mean()
    assert err < 0.015, err                 # two bilinear resamplings + 8-bit rounding
    assert err_raw > 5 * err                # the lens visibly moved pixels
    m = scene.masks[0]
    assert (m & disk).sum() / (m | disk).sum() > 0.97
    assert (out / "raw.png").is_file()      # the camera's file is kept (as the NeRF path)
    assert not (tmp_path / "raw.png.part").exists()


def test_list_key_before_masks(tmp_path, lens):
    K, calib, _ = lens
    folder.write_image(tmp_path / "raw.png", np.full((H, W, 3), 0.5))
    key = tmp_path / "key.json"
    key.write_text(json.dumps([{"radius": 0.05, "ior": 1.5}, {"radius": 0.04, "ior": 1.4}]))
    out = ingest(tmp_path / "raw.png", calib, key, tmp_path / "scene")
    assert json.loads((out / "totems.json").read_text())[1]["radius"] == 0.04
    assert not (out / "totem_masks").exists()


def test_bad_inputs(tmp_path, lens):
    K, calib, key = lens
    folder.write_image(tmp_path / "small.png", np.zeros((60, 80, 3)))
    with pytest.raises(BadInput, match="principal point"):
        ingest(tmp_path / "small.png", calib, key, tmp_path / "s1")
    folder.write_image(tmp_path / "raw.png", np.zeros((H, W, 3)))
    bad = tmp_path / "bad.json"
    bad.write_text('{"radius": -1, "ior": 1.5}')
    with pytest.raises(BadInput, match="radius"):
        ingest(tmp_path / "raw.png", calib, bad, tmp_path / "s2")
    assert not (tmp_path / "s2").exists()
