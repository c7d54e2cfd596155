"""benchmarks/cycles/truth_reach.py and blender_trace.py: the truth's reach of a Cycles
scene, its rays traced by Blender. On a hand-built scene (a wall, a box, two totems, the
world beside the wall) the reach is the hand-computed one; the traced depth and objects
are Cycles' own (its depth pass, its first-hit ids) there and on a drawn scene; folders
of one scene share one trace.

The tests that run Blender need ``make cycles-env`` (``.venv-cycles`` with bpy) and are
skipped otherwise.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cycles import convert, truth_reach
from benchmarks.cycles.blender_camera import blender_from_opencv
from reach_cases import (BOX_C, BOX_H, ETA, H, K, P1, P2, WALL_Z, W, R,
                         check_box_hides_from_one, check_wall_both_see, crosses, pixel)
from scenes import folder
from scenes.errors import BadInput

ROOT = Path(__file__).resolve().parents[1]
PY = ROOT / ".venv-cycles" / "bin" / "python"

WALL_C, WALL_H = np.array([-1.8, 0.0, WALL_Z + 2.0]), 2.0   # a cube: face z = 4, x <= 0.2


def _has_bpy() -> bool:
    if not PY.is_file():
        return False
    r = subprocess.run([str(PY), "-c", "import bpy"], capture_output=True, timeout=120)
    return r.returncode == 0


HAS_BPY = _has_bpy()


def needs_bpy(test):
    """Slow, and skipped where there is no ``.venv-cycles`` with bpy."""
    return pytest.mark.slow(pytest.mark.skipif(not HAS_BPY, reason="no .venv-cycles "
                                               "with bpy (make cycles-env)")(test))


def hand_desc() -> dict:
    """The camera at Blender's world origin with its OpenCV frame the world's axes (so
    every point below is both), a wall, a small box behind the left totem that hides a
    patch of the wall from it alone, nothing right of the wall (the world)."""
    grey = {"texture": "plain", "c1": [0.5] * 3, "c2": [0.5] * 3, "scale": 1.0,
            "roughness": 0.5}
    cam = dict(blender_from_opencv(K, np.eye(4), width=W, height=H), width=W, height=H)

    def cube(centre, half):
        return {"shape": "cube", "size": 2 * half, "location": list(centre), "yaw": 0.0,
                "material": grey}

    return {"format": 1, "kind": "test", "seed": 0, "camera": cam, "support_z": 0.0,
            "key": {"radius": R, "ior": ETA},
            "totems": [{"centre": P1.tolist(), "resting": False},
                       {"centre": P2.tolist(), "resting": False}],
            "objects": [cube(WALL_C, WALL_H), cube(BOX_C, BOX_H)],
            "floor": None, "walls": None, "table": None,
            "world": {"colour": [0.05, 0.05, 0.05], "strength": 1.0}, "lights": [],
            "pipeline": {"view_transform": "Standard", "denoise": False,
                         "filter": "GAUSSIAN", "filter_width": 1.5, "samples": 1,
                         "sampling_seed": 1, "metered_ev": 0.0}}


def _render(out: Path, *args) -> Path:
    r = subprocess.run([str(PY), str(ROOT / "benchmarks" / "cycles" / "render.py"),
                        str(out), "--depth", *args], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return out


@pytest.fixture(scope="module")
def hand(tmp_path_factory):
    """The hand-built scene rendered (with Cycles' depth), its folder, its reach."""
    tmp = tmp_path_factory.mktemp("cycles-reach")
    (tmp / "desc.json").write_text(json.dumps(hand_desc()))
    rdir = _render(tmp / "render", "--desc", str(tmp / "desc.json"))
    scene = convert.write_untouched(rdir, tmp / "scene")
    reach, hits = truth_reach.cycles_reach(truth_reach.read_cycles_scene(scene))
    return {"render": rdir, "scene": scene, "reach": reach, "hits": hits}


@needs_bpy
def test_a_wall_two_totems_see_is_in_reach_at_its_parallax(hand):
    check_wall_both_see(hand["reach"])


@needs_bpy
def test_a_patch_the_box_hides_from_one_totem_is_out_of_reach(hand):
    check_box_hides_from_one(hand["reach"])


@needs_bpy
def test_the_world_beside_the_wall_is_a_backdrop_both_totems_see(hand):
    reach = hand["reach"]
    X = np.array([1.6, 0.0, WALL_Z])
    d = X / np.linalg.norm(X)
    for start in (np.zeros(3), P1, P2):       # every line along d passes the wall by
        assert not crosses(start, start + 100.0 * d, WALL_C, WALL_H)
    u, v = pixel(X)
    assert np.isinf(reach.depth[v, u]) and reach.backdrop[v, u]
    assert reach.n_totems[v, u] == 2 and reach.in_reach()[v, u]


@needs_bpy
def test_the_trace_is_cycles_own_depth_and_objects(hand):
    """Against Cycles' depth pass and first-hit ids (render.py --depth): every pixel but
    the totems' meets what Cycles' camera ray meets, at its depth; the totems' pixels are
    the folder's masks and left out of the reach."""
    reach, hits = hand["reach"], hand["hits"]
    masks = folder.read_scene(hand["scene"]).masks
    assert np.array_equal(reach.excluded, masks.any(axis=0))
    assert not (reach.in_reach() & reach.excluded).any()
    _agrees_with_cycles(hand["render"], reach, hits, tolerance=1e-4, share=1.0)
    assert set(np.unique(hits["rays"].totem)) == {0, 1}


def _agrees_with_cycles(rdir, reach, hits, *, tolerance, share):
    """The traced depth within ``tolerance`` (relative) of Cycles' depth pass, and the
    object the camera ray meets Cycles' id, on at least ``share`` of the pixels outside
    the totems."""
    depth = np.load(rdir / "depth.npy")
    ids = np.load(rdir / "ids.npy")
    out = ~reach.excluded
    assert np.array_equal(reach.excluded, (ids >= 100) & (ids < 200))
    z = reach.depth.astype(np.float64)
    finite = np.isfinite(depth)
    same = np.isinf(z)
    same[finite] = np.abs(z[finite] - depth[finite]) <= tolerance * depth[finite]
    assert same[out].mean() >= share, same[out].mean()
    index = np.maximum(hits["camera_index"].reshape(ids.shape), 0)
    assert (index == ids)[out].mean() >= share


@needs_bpy
def test_a_drawn_scene_traced_is_cycles_own_depth_and_objects(tmp_path):
    """A room of seed 103 (walls, floor, primitives with smooth shading), 160x120; its
    totems block some of one another's rays."""
    rdir = _render(tmp_path / "render", "--seed", "103", "--small")
    scene = convert.write_untouched(rdir, tmp_path / "scene")
    reach, hits = truth_reach.cycles_reach(truth_reach.read_cycles_scene(scene))
    _agrees_with_cycles(rdir, reach, hits, tolerance=1e-4, share=0.999)
    inside = reach.in_reach()
    assert 0.1 < inside.mean() < 1.0 and (reach.n_totems >= 2).any()
    # a totem ray blocked by a totem ends on another sphere's surface, and is not used
    index, rays = hits["totem_index"], hits["rays"]
    blocked = (index >= 100) & (index < 200)
    assert blocked.any() and not (hits["used"] & blocked).any()
    centers = np.array([t["center"] for t in folder.read_truth(scene).scene["totems"]])
    gap = np.linalg.norm(hits["totem_Y"][blocked][:, None] - centers[None], axis=-1)
    radius = folder.read_scene(scene).radius[0]
    np.testing.assert_allclose(gap.min(axis=1), radius, rtol=1e-4)
    assert not (gap.argmin(axis=1) == rays.totem[blocked]).any()


@needs_bpy
def test_folders_of_one_scene_share_one_trace(hand, tmp_path, monkeypatch):
    """A copy of the folder (as an edit or a recapture holds its source's truth) gets
    the same reach from one trace; ``missing`` leaves folders that have one alone; the
    command line writes them and refuses a folder that is no Cycles scene."""
    copy = tmp_path / "copy"
    shutil.copytree(hand["scene"], copy)
    calls = []
    trace = truth_reach.blender_trace
    monkeypatch.setattr(truth_reach, "blender_trace",
                        lambda *a, **k: calls.append(1) or trace(*a, **k))
    written = truth_reach.write_reaches([hand["scene"], copy])
    assert len(calls) == 1 and written == [hand["scene"] / "truth" / "reach.npz",
                                           copy / "truth" / "reach.npz"]
    for d in (hand["scene"], copy):
        got = folder.read_truth(d).reach
        for k, val in hand["reach"].to_dict().items():
            np.testing.assert_array_equal(getattr(got, k), val)
    assert truth_reach.write_reaches([hand["scene"], copy], missing=True) == []
    assert len(calls) == 1
    (copy / "truth" / "reach.npz").unlink()
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "cycles" /
                                                "truth_reach.py"), str(copy)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (copy / "truth" / "reach.npz").is_file()


def _mitsuba_like(tmp_path) -> Path:
    d = tmp_path / "mitsuba" / "truth"
    d.mkdir(parents=True)
    (d / "scene.json").write_text(json.dumps({"format": 1, "objects": [], "totems": []}))
    return d.parent


def test_a_folder_that_is_no_cycles_scene_is_bad_input(tmp_path):
    with pytest.raises(BadInput, match="not a Cycles scene"):
        truth_reach.read_cycles_scene(_mitsuba_like(tmp_path))
    with pytest.raises(BadInput, match="no truth/scene.json"):
        truth_reach.read_cycles_scene(tmp_path)


def test_scene_reach_refuses_a_cycles_scene_and_names_the_tool(tmp_path):
    d = tmp_path / "cycles" / "truth"
    d.mkdir(parents=True)
    (d / "scene.json").write_text(json.dumps({"renderer": "cycles", "cycles": {}}))
    done = subprocess.run([sys.executable, "-m", "verify.cli", "scene", "reach",
                           str(d.parent)], capture_output=True, text=True)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "benchmarks/cycles/truth_reach.py" in done.stderr


def test_a_failed_trace_says_blenders_last_line():
    """Blender's trace run by a python without bpy: RuntimeError naming what failed."""
    e = np.zeros((1, 3))
    with pytest.raises(RuntimeError, match="No module named 'bpy'"):
        truth_reach.blender_trace({}, camera_o=e, camera_d=e + [0, 0, 1], totem_o=e,
                                  totem_d=e + [0, 0, 1], python=sys.executable)
