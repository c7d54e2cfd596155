"""Scene folders from strangers: every malformed folder is one line of BadInput."""

import os
import json

import numpy as np
import pytest

from scenes import camera
from scenes import folder
from scenes.errors import BadInput

W, H = 64, 48


def _disk(cx, cy, r):
    yy, xx = np.mgrid[:H, :W]
    return (xx - cx) ** 2 + (yy - cy) ** 2 <= r ** 2


@pytest.fixture
def good(tmp_path):
    """A small valid folder (no rendering): a gradient photo and two disk masks."""
    image = np.dstack([np.linspace(0, 1, W)[None].repeat(H, 0)] * 3).astype(np.float32)
    masks = np.stack([_disk(15, 34, 7), _disk(45, 34, 8)])
    K = camera.intrinsics(W, H, 60.0)
    return folder.write_scene(tmp_path / "scene", image=image, K=K, masks=masks,
                              radius=0.1, ior=1.52)


def _bad(path, *words):
    with pytest.raises(BadInput) as err:
        folder.read_scene(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.strip() == msg and len(msg) < 300
    for w in words:
        assert w in msg, msg
    return msg


def test_good_folder_reads(good):
    s = folder.read_scene(good)
    assert s.masks.shape == (2, H, W) and s.size == (W, H)
    assert np.allclose(s.K, camera.intrinsics(W, H, 60.0))
    assert np.allclose(s.radius, [0.1, 0.1]) and np.allclose(s.ior, [1.52, 1.52])


def test_missing_masks(good):
    for f in (good / "totem_masks").iterdir():
        f.unlink()
    _bad(good, "mask")


def test_key_lists_more_totems_than_masks(good):
    folder.write_json(good / "totems.json", [{"radius": 0.1, "ior": 1.5}] * 3)
    _bad(good, "3 totems", "2 masks")


def test_mask_of_another_size(good):
    folder.write_image(good / "totem_masks" / "totem_001.png",
                       np.ones((H + 2, W), bool))
    _bad(good, "totem_001.png", f"{W}x{H}")


def test_empty_mask(good):
    folder.write_image(good / "totem_masks" / "totem_000.png", np.zeros((H, W), bool))
    _bad(good, "totem_000.png")


def test_mask_that_is_not_an_image(good):
    (good / "totem_masks" / "totem_000.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    _bad(good, "totem_000.png")


def test_missing_photo(good):
    (good / "image.png").unlink()
    _bad(good, "image.png")


def test_calib_without_mtx(good):
    folder.write_npy(good / "calib.npy", {"K": np.eye(3)}, allow_pickle=True)
    _bad(good, "mtx")


def test_calib_with_a_bad_matrix(good):
    folder.write_npy(good / "calib.npy", {"mtx": np.eye(2)}, allow_pickle=True)
    _bad(good, "mtx")
    folder.write_npy(good / "calib.npy", {"mtx": np.diag([-500.0, 500.0, 1.0])},
                     allow_pickle=True)
    _bad(good, "mtx")


@pytest.mark.parametrize("key,word", [
    ({"radius": -0.1, "ior": 1.52}, "radius"),
    ({"radius": 0.1, "ior": 0.9}, "ior"),
    ({"radius": "big", "ior": 1.5}, "number"),
    ({"ior": 1.5}, "radius"),
])
def test_bad_key(good, key, word):
    folder.write_json(good / "totems.json", key)
    _bad(good, word)


def test_key_not_json(good):
    (good / "totems.json").write_text("{radius: 0.1")
    _bad(good, "JSON")


class _Payload:
    """Unpickling this writes a marker file: the proof that code ran."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('ran')",))


def test_calib_whose_pickle_would_run_code(good, tmp_path):
    marker = tmp_path / "pwned"
    calib = {"mtx": camera.intrinsics(W, H, 60.0), "x": _Payload(marker)}
    np.save(good / "calib.npy", np.array(calib, dtype=object), allow_pickle=True)
    # the payload is live: a plain unpickler runs it
    data = (good / "calib.npy").read_bytes()
    np.load(good / "calib.npy", allow_pickle=True)
    assert marker.exists()
    marker.unlink()
    msg = _bad(good, "calib.npy")
    assert not marker.exists(), msg
    assert (good / "calib.npy").read_bytes() == data      # input left untouched
    # a pickle of a dict of plain arrays is still accepted
    K = np.diag([50.0, 50.0, 1.0])
    K[:2, 2] = [W / 2, H / 2]
    np.save(good / "calib.npy", np.array({"mtx": K}, dtype=object), allow_pickle=True)
    assert np.array_equal(folder.read_scene(good).K, K)


def test_scene_folder_that_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    _bad(tmp_path / "f", "not found")


def test_read_truth_absent_is_none(good):
    assert folder.read_truth(good) is None
    assert json.loads((good / "totems.json").read_text())["radius"] == 0.1


def test_written_files_get_ordinary_permissions(tmp_path):
    # Atomic writes go through mkstemp (owner-only); the file must end as open() makes it.
    old = os.umask(0o022)
    try:
        folder.write_json(tmp_path / "a.json", {"x": 1})
    finally:
        os.umask(old)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o644
