"""The presets beyond box and envmap: totems where the truth says, the key, the camera."""

import json

import numpy as np
import pytest

from scenes import camera, folder
from scenes.errors import BadInput
from scenes.synthetic import make, presets, render, textures

NEW = ("outdoor", "window", "tabletop")


def _polygon_area(uv) -> float:
    x, y = uv[:, 0], uv[:, 1]
    return 0.5 * abs(x @ np.roll(y, -1) - y @ np.roll(x, -1))


@pytest.mark.parametrize("preset", NEW)
@pytest.mark.parametrize("seed", [1, 2])
def test_totems_render_where_the_truth_says(preset, seed):
    """Each true centre projects into its own mask; each mask's area is the sphere's
    silhouette's (the outline through K, independent of the renderer's rays)."""
    W, H = 320, 240
    desc = presets.describe(preset, seed, size=(W, H))
    K = np.asarray(desc["K"])
    masks = render.totem_masks(desc)
    assert masks.shape == (len(desc["totems"]), H, W)
    assert not np.any(masks.sum(0) > 1)
    xs = []
    for m, t in zip(masks, desc["totems"]):
        u, v = np.rint(camera.project(K, t["center"])).astype(int)
        assert m[v, u], (preset, seed, t)
        area = _polygon_area(presets.sphere_outline(K, t["center"], t["radius"], n=256))
        assert abs(m.sum() - area) / area < 0.03, (m.sum(), area)
        assert not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())
        xs.append(np.nonzero(m)[1].mean())
    assert np.all(np.diff(xs) > 0)            # numbered left to right


@pytest.mark.parametrize("preset", NEW)
def test_key_camera_and_seed(preset):
    """3-6 totems (tabletop 3-4) of radius 6-12 cm (tabletop 6-8) and IoR 1.45-1.55
    each; principal point off-centre by 1-5 % a side; the same seed the same scene at
    every size; the key given on the command line replaces the drawn one."""
    a = presets.describe(preset, 7, size=(160, 120))
    assert a == presets.describe(preset, 7, size=(160, 120))
    assert a["objects"] != presets.describe(preset, 8, size=(160, 120))["objects"]
    n = len(a["totems"])
    r = np.array([t["radius"] for t in a["totems"]])
    eta = np.array([t["ior"] for t in a["totems"]])
    hi_n, hi_r = (4, 0.08) if preset == "tabletop" else (6, 0.12)
    assert 3 <= n <= hi_n and np.all((r >= 0.06) & (r <= hi_r))
    assert np.all((eta >= 1.45) & (eta <= 1.55))
    K = np.asarray(a["K"])
    off = np.abs([(K[0, 2] - 79.5) / 160, (K[1, 2] - 59.5) / 120])
    assert np.all((off >= 0.01 - 1e-9) & (off <= 0.05 + 1e-9)), off
    big = presets.describe(preset, 7, size=(640, 480))
    assert big["objects"] == a["objects"] and big["lights"] == a["lights"]
    assert np.allclose([t["center"] for t in big["totems"]],
                       [t["center"] for t in a["totems"]], atol=1e-5)
    fixed = presets.describe(preset, 7, size=(160, 120), n_totems=3, radius=0.07, ior=1.5)
    assert [(t["radius"], t["ior"]) for t in fixed["totems"]] == [(0.07, 1.5)] * 3
    assert fixed["objects"] == a["objects"]   # the totems' streams are their own
    ids = [o["id"] for o in a["objects"]] + [li["id"] for li in a["lights"]]
    assert sorted(ids) == list(range(len(ids)))
    assert any(o["removable"] for o in a["objects"])
    assert any(o["name"] in ("floor", "ground", "table") for o in a["objects"])


@pytest.mark.parametrize("preset", NEW)
def test_scene_folder_key_and_same_bytes(preset, tmp_path):
    """make_scene writes the description's key, per totem, left to right; the same
    seed twice gives the same image.png bytes."""
    out = [make.make_scene(tmp_path / f"s{i}", preset=preset, seed=3, size=(160, 120),
                           spp=2) for i in range(2)]
    assert (out[0] / "image.png").read_bytes() == (out[1] / "image.png").read_bytes()
    desc = presets.describe(preset, 3, size=(160, 120))
    key = json.loads((out[0] / "totems.json").read_text())
    assert key == [{"radius": t["radius"], "ior": t["ior"]} for t in desc["totems"]]
    scene = folder.read_scene(out[0])
    assert np.allclose(scene.K, desc["K"])
    truth = folder.read_truth(out[0])
    assert np.allclose(truth.totem_pose, [t["center"] for t in desc["totems"]])


def test_unknown_and_bad_arguments():
    with pytest.raises(BadInput):
        presets.describe("garden", 1)
    with pytest.raises(BadInput):
        presets.describe("outdoor", 1, radius=0.5)
    with pytest.raises(BadInput):
        textures.procedural("velvet:1")


@pytest.mark.parametrize("kind", textures.KINDS)
def test_procedural_textures_tile_and_repeat(kind):
    """The same name gives the same pixels; the wrap-around seam is no harsher than
    the texture's own neighbouring columns and rows."""
    img = textures.procedural(f"{kind}:5").astype(float)
    assert np.array_equal(img, textures.procedural(f"{kind}:5"))
    assert not np.array_equal(img, textures.procedural(f"{kind}:6"))
    for axis in (0, 1):
        inner = np.abs(np.diff(img, axis=axis)).mean()
        seam = np.abs(np.take(img, 0, axis) - np.take(img, -1, axis)).mean()
        assert seam < 2.0 * inner + 1.0, (kind, axis, seam, inner)
