"""A tiny Cycles render (benchmarks/cycles, run in .venv-cycles): a marker on the pixel
K puts it on, and a sphere's Cycles silhouette equal to the analytic one.

Runs only where ``make cycles-env`` has made ``.venv-cycles`` with bpy; skipped
otherwise.
"""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cycles.blender_camera import look_matrix
from benchmarks.cycles.convert import read_render, sphere_masks
from scenes import camera

ROOT = Path(__file__).resolve().parents[1]
PY = ROOT / ".venv-cycles" / "bin" / "python"


def _has_bpy() -> bool:
    if not PY.is_file():
        return False
    r = subprocess.run([str(PY), "-c", "import bpy"], capture_output=True, timeout=120)
    return r.returncode == 0


pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not _has_bpy(), reason="no .venv-cycles with bpy "
                                 "(make cycles-env)")]


def _desc(W=160, H=120):
    """A dark world, one emissive marker off the axis, one glass totem; a camera turned
    and tilted, with a principal point off the centre (shift)."""
    cam = {"lens": 30.0, "sensor_width": 36.0, "sensor_fit": "AUTO", "shift_x": 0.041,
           "shift_y": -0.027, "width": W, "height": H,
           "matrix_world": look_matrix([0.2, -0.1, 1.0], 9.0, 11.0).tolist()}
    M = np.asarray(cam["matrix_world"])

    def ahead(x, y, d):                  # a point d along the view, offset in its frame
        return (M[:3, 3] + d * (M[:3, :3] @ np.array([x, y, -1.0]))).tolist()

    return {"format": 1, "kind": "test", "seed": 0, "camera": cam, "support_z": 0.0,
            "key": {"radius": 0.12, "ior": 1.5},
            "totems": [{"centre": ahead(0.2, -0.12, 1.6), "resting": False}],
            "markers": [{"centre": ahead(-0.21, 0.13, 2.0), "radius": 0.03,
                         "strength": 5.0}],
            "objects": [], "floor": None, "walls": None, "table": None,
            "world": {"colour": [0.0, 0.0, 0.0], "strength": 0.0}, "lights": [],
            "pipeline": {"view_transform": "Standard", "denoise": False,
                         "filter": "GAUSSIAN", "filter_width": 1.5, "samples": 256,
                         "sampling_seed": 1, "metered_ev": 0.0}}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cycles")
    (tmp / "desc.json").write_text(json.dumps(_desc()))
    r = subprocess.run([str(PY), str(ROOT / "benchmarks" / "cycles" / "render.py"),
                        str(tmp / "out"), "--desc", str(tmp / "desc.json"), "--linear",
                        "--depth"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return tmp / "out"


def test_marker_lands_on_its_pixel(rendered):
    rec = read_render(rendered)
    w2c = rec["w2c"]
    P = w2c[:3, :3] @ np.asarray(rec["description"]["markers"][0]["centre"]) + w2c[:3, 3]
    u, v = camera.project(rec["K"], P)
    lin = np.load(rendered / "linear.npy").sum(axis=-1)
    iu, iv = int(round(u)), int(round(v))
    win = lin[iv - 6:iv + 7, iu - 6:iu + 7]                 # the marker and its blur
    assert win.sum() > 0 and lin.sum() - win.sum() < 1e-3 * win.sum()
    yy, xx = np.mgrid[iv - 6:iv + 7, iu - 6:iu + 7]
    centroid = np.array([(xx * win).sum(), (yy * win).sum()]) / win.sum()
    assert np.hypot(*(centroid - [u, v])) < 0.05, (centroid, (u, v))


def test_sphere_mask_is_the_analytic_silhouette(rendered):
    rec = read_render(rendered)
    ids = np.load(rendered / "ids.npy")
    exact = sphere_masks(rec["K"], rec["centres"], 0.12, ids.shape)[0]
    cycles = ids == rec["totem_index"]
    assert exact.sum() > 300                                 # a sphere of some size
    outline = exact ^ np.roll(exact, 1, 0) | exact ^ np.roll(exact, 1, 1)
    assert (exact != cycles).sum() <= 0.02 * outline.sum(), (exact != cycles).sum()


def test_depth_is_the_first_surface_without_the_totems(rendered):
    """render.py --depth: at the marker's pixel, the camera-frame z where that pixel
    centre's ray meets the marker's sphere (in closed form); where the totem stands,
    nothing (it is hidden, the world behind it empty)."""
    rec = read_render(rendered)
    depth = np.load(rendered / "depth.npy")
    marker = rec["description"]["markers"][0]
    P = rec["w2c"][:3, :3] @ np.asarray(marker["centre"]) + rec["w2c"][:3, 3]
    u, v = np.rint(camera.project(rec["K"], P)).astype(int)
    d = camera.pixel_rays(rec["K"], np.float64(u), np.float64(v))
    b = d @ P
    t = b - np.sqrt(b * b - (P @ P - marker["radius"] ** 2))
    assert depth[v, u] == pytest.approx(t * d[2], rel=1e-5)
    tu, tv = np.rint(camera.project(rec["K"], rec["centres"][0])).astype(int)
    assert np.isinf(depth[tv, tu])
    assert np.isfinite(depth).sum() < 0.05 * depth.size      # the marker alone


def test_small_set_is_scene_folders(tmp_path):
    """make_cycles_set.py --small: an untouched folder every reader takes, with exact
    masks, true centres that project into them, and the truth's reach; edited copies
    whose totem pixels are the untouched photo's, with their source's reach."""
    from scenes import folder

    r = subprocess.run([str(ROOT / ".venv" / "bin" / "python"),
                        str(ROOT / "benchmarks" / "cycles" / "make_cycles_set.py"),
                        str(tmp_path), "--seed", "101", "--count", "1", "--small"],
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    name = "cycles-yard-s101"
    scene, truth = folder.read_scene(tmp_path / name), folder.read_truth(tmp_path / name)
    assert truth.scene["renderer"] == "cycles" and "objects" not in truth.scene
    assert truth.scene["cycles"]["mask_check"]["pixels_differing"] == [0] * scene.n_totems
    uv = camera.project(scene.K, truth.totem_pose)
    for m, (u, v) in zip(scene.masks, uv):            # each centre inside its own mask
        assert m[int(round(v)), int(round(u))]
    reach = truth.reach
    assert np.array_equal(reach.excluded, scene.masks.any(axis=0)) and reach.in_reach().any()
    for kind in ("color", "splice", "remove"):
        edited = folder.read_scene(tmp_path / f"{name}-{kind}")
        totems = scene.masks.any(axis=0)
        assert edited.manip_mask.any() and not (edited.manip_mask & totems).any()
        assert np.array_equal(edited.image[totems], scene.image[totems])
        theirs = folder.read_truth(tmp_path / f"{name}-{kind}").reach
        for k, val in reach.to_dict().items():
            np.testing.assert_array_equal(getattr(theirs, k), val)


def test_ablation_switches_reach_blender():
    """``--glass refraction`` gives the totems a Refraction BSDF, ``--totem-shadows off``
    hides them from shadow and diffuse rays; by default Glass, and seen by every ray;
    ``--glass coated`` the refraction mixed with black by the Fresnel reflectance."""
    code = (
        "import sys, json; sys.path.insert(0, sys.argv[1]); import blender_scene as bs\n"
        "d = json.loads(sys.argv[2]); out = []\n"
        "for glass, shadows in ((None, None), ('refraction', False), ('coated', None)):\n"
        "    e = dict(d); e.update({k: v for k, v in (('glass', glass),\n"
        "        ('totem_shadows', shadows)) if v is not None})\n"
        "    t = bs.build(e)['totems'][0]\n"
        "    mat = [n for n in t.modifiers[0].node_group.nodes\n"
        "           if n.bl_idname == 'GeometryNodeSetMaterial'][0].inputs['Material']\n"
        "    names = [n.bl_idname for n in mat.default_value.node_tree.nodes]\n"
        "    links = sorted((l.from_node.bl_idname, l.to_node.bl_idname, l.to_socket.identifier)\n"
        "                   for l in mat.default_value.node_tree.links)\n"
        "    out.append([names, t.visible_shadow, t.visible_diffuse, t.visible_glossy, links])\n"
        "print(json.dumps(out))\n")
    r = subprocess.run([str(PY), "-c", code, str(ROOT / "benchmarks" / "cycles"),
                        json.dumps(_desc())], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    default, ablated, coated = json.loads(r.stdout.strip().splitlines()[-1])
    assert "ShaderNodeBsdfGlass" in default[0] and default[1:4] == [True, True, True]
    assert "ShaderNodeBsdfRefraction" in ablated[0] and "ShaderNodeBsdfGlass" not in \
        ablated[0]
    assert ablated[1:4] == [False, False, True]             # other totems still seen
    assert "ShaderNodeBsdfGlass" not in coated[0] and coated[1:4] == [True, True, True]
    assert ["ShaderNodeFresnel", "ShaderNodeMixShader", "Fac"] in coated[4]
    assert ["ShaderNodeBsdfRefraction", "ShaderNodeMixShader", "Shader"] in coated[4]
    assert ["ShaderNodeEmission", "ShaderNodeMixShader", "Shader_001"] in coated[4]
    assert ["ShaderNodeMixShader", "ShaderNodeOutputMaterial", "Surface"] in coated[4]
