"""The truth's reach of Cycles scene folders (package's venv; Blender traces the rays).

    .venv/bin/python benchmarks/cycles/truth_reach.py SCENE... [--missing]

What ``totems scene make`` writes for a Mitsuba scene (``scenes/synthetic/trace.py``),
from the folder's ``truth/scene.json`` alone: the camera's ray through each pixel centre
(:func:`scenes.camera.pixel_rays` with its K) and each totem pixel's ray refracted through
its true sphere (:func:`scenes.refraction.exit_rays`; the pixels are the sphere's exact
silhouette, as the folder's masks) are traced by Blender in the scene rebuilt from its
description (``blender_trace.py``, run in ``.venv-cycles`` as ``render.py`` is): the
camera's rays without the totems, the totem rays with them (one that meets a totem is
blocked). :func:`scenes.reach.reach_map` turns where they land into
``truth/reach.npz``, written atomically; nothing else of the folder is touched. Edited
and recaptured copies hold their source's description, so they get the source's reach,
what their totems show (a ``-remove`` copy's object is still there); folders of one
scene are traced once. The package never imports bpy nor runs Blender, so
``totems scene reach`` refuses a Cycles scene and points here.

Exit 2 with one line for a folder that is not a Cycles scene or a missing
``.venv-cycles``; 1 when Blender's trace fails (its last line in the message).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.cycles.convert import sphere_masks  # noqa: E402
from scenes import camera, folder  # noqa: E402
from scenes.errors import BadInput  # noqa: E402
from scenes.reach import COS_EVIDENCE, SUPERSAMPLE, Reach, reach_map  # noqa: E402
from scenes.refraction import MIN_TRANSMITTANCE, ExitRays, exit_rays  # noqa: E402

__all__ = ["read_cycles_scene", "scene_rays", "blender_trace", "cycles_reach",
           "write_reaches"]

PY = ROOT / ".venv-cycles" / "bin" / "python"
SCRIPT = Path(__file__).with_name("blender_trace.py")
OFFSET = 1e-5
"""Metres a totem ray starts past its exit point, off the glass it leaves."""


def read_cycles_scene(scene_dir) -> dict:
    """``truth/scene.json`` of a Cycles scene folder (``renderer`` "cycles", with the
    description Blender rebuilds it from); :class:`BadInput` otherwise."""
    scene = folder.read_scene_json(scene_dir, missing="the truth's reach is traced in a "
                                   "Cycles scene made by make_cycles_set.py")
    if scene.get("renderer") != "cycles" or "description" not in scene.get("cycles", {}):
        raise BadInput(f"{Path(scene_dir) / 'truth' / 'scene.json'} is not a Cycles "
                       "scene's (a Mitsuba scene's reach is written by `totems scene "
                       "reach`)")
    return scene


def scene_rays(scene: dict) -> tuple[np.ndarray, np.ndarray, ExitRays]:
    """The rays a Cycles scene's reach is traced from (OpenCV camera frame, metres).

    Returns
    -------
    view : (H, W, 3) each pixel centre's unit ray from the camera's centre (``K``).
    masks : (n, H, W) bool, each totem's exact silhouette (the folder's masks), left to
        right as ``scene["totems"]``.
    rays : :class:`scenes.refraction.ExitRays` of every totem pixel through its sphere.
    """
    K = np.asarray(scene["K"], np.float64)
    W, H = (int(s) for s in scene["size"])
    v, u = np.mgrid[0:H, 0:W]
    view = camera.pixel_rays(K, u, v)
    t = scene["totems"]
    centers = np.array([x["center"] for x in t], np.float64)
    radius = np.array([x["radius"] for x in t], np.float64)
    masks = sphere_masks(K, centers, radius, (H, W))
    return view, masks, exit_rays(K, masks, centers, radius, [x["ior"] for x in t],
                                  supersample=SUPERSAMPLE)


def blender_trace(description: dict, *, camera_o, camera_d, totem_o, totem_d,
                  python=PY) -> dict:
    """Where rays first meet the scene of a Cycles ``description``, by Blender
    (``blender_trace.py`` in ``python``): camera-frame rays (m, 3) each, metres; the
    camera rays traced without the totems, the totem rays with them.

    Returns ``blender_trace.py``'s arrays: ``camera_Y``, ``camera_normal``,
    ``camera_index``, ``totem_*`` likewise, ``K``, ``totem_base``, ``marker_base``.
    Raises RuntimeError with Blender's last line when the trace fails.
    """
    with tempfile.TemporaryDirectory(prefix="cycles-trace-") as tmp:
        tmp = Path(tmp)
        (tmp / "desc.json").write_text(json.dumps(description))
        np.savez(tmp / "rays.npz", camera_o=camera_o, camera_d=camera_d, totem_o=totem_o,
                 totem_d=totem_d)
        done = subprocess.run([str(python), str(SCRIPT), str(tmp / "desc.json"),
                               str(tmp / "rays.npz"), str(tmp / "hits.npz")],
                              capture_output=True, text=True)
        if done.returncode != 0:
            said = (done.stderr or done.stdout).strip().splitlines() or ["no output"]
            raise RuntimeError(f"Blender's trace failed ({said[-1]})")
        with np.load(tmp / "hits.npz") as z:
            return {k: z[k] for k in z.files}


def cycles_reach(scene: dict, *, cos_min: float = COS_EVIDENCE,
                 python=PY) -> tuple[Reach, dict]:
    """The truth's reach of a Cycles scene (its ``truth/scene.json``) from the totem rays
    that entered their sphere at an incidence cosine of at least ``cos_min`` (by default
    the rays the evidence map reads), transmit more than ``MIN_TRANSMITTANCE`` and meet no
    other totem; and the trace (:func:`blender_trace`'s arrays with ``rays``, the
    :class:`ExitRays` traced, and ``used``, the ones the reach took)."""
    view, masks, rays = scene_rays(scene)
    H, W = masks.shape[1:]
    cam = view.reshape(-1, 3)
    hits = blender_trace(scene["cycles"]["description"], camera_o=np.zeros_like(cam),
                         camera_d=cam, totem_o=rays.o + OFFSET * rays.d, totem_d=rays.d,
                         python=python)
    K = np.asarray(scene["K"], np.float64)
    if not np.allclose(hits["K"], K, rtol=1e-6, atol=1e-6):
        raise BadInput("the camera Blender builds from cycles.description is not "
                       "scene.json's K: the folder's truth does not hold together")
    index = hits["totem_index"]
    blocked = (index >= hits["totem_base"]) & (index < hits["marker_base"])
    used = (rays.T > MIN_TRANSMITTANCE) & ~blocked & (rays.cos_in >= cos_min)
    centers = np.array([x["center"] for x in scene["totems"]], np.float64)
    reach = reach_map(view, hits["camera_Y"].reshape(H, W, 3), masks.any(axis=0), centers,
                      o=rays.o[used], d=rays.d[used], Y=hits["totem_Y"][used],
                      normal=hits["totem_normal"][used], totem=rays.totem[used],
                      supersample=SUPERSAMPLE)
    return reach, dict(hits, rays=rays, used=used)


def write_reaches(scene_dirs, *, missing: bool = False, python=PY,
                  log=None) -> list[Path]:
    """Trace the truth's reach of Cycles scene folders into their ``truth/reach.npz``
    (each written atomically), once per scene: folders whose ``scene.json`` holds the
    same scene (an untouched photo, its edits, their recaptures) share one trace.
    ``missing``: only folders without one. Returns the files written; ``log(line)``
    hears of each scene traced."""
    groups: dict[str, list[Path]] = {}
    scenes = {}
    for d in map(Path, scene_dirs):
        scene = read_cycles_scene(d)
        if missing and (d / "truth" / "reach.npz").is_file():
            continue
        key = json.dumps(scene, sort_keys=True)
        groups.setdefault(key, []).append(d)
        scenes[key] = scene
    written = []
    for key, dirs in groups.items():
        t0 = time.perf_counter()
        reach, _ = cycles_reach(scenes[key], python=python)
        for d in dirs:
            path = d / "truth" / "reach.npz"
            folder.write_npz(path, **reach.to_dict())
            written.append(path)
        if log:
            share = reach.in_reach()[~reach.excluded].mean()
            log(f"{dirs[0].name}: reach {share:.2f} of the photo, traced in "
                f"{time.perf_counter() - t0:.1f} s, written to "
                f"{len(dirs)} folder{'s' * (len(dirs) > 1)}")
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="+", metavar="scene")
    ap.add_argument("--missing", action="store_true",
                    help="only the folders without truth/reach.npz")
    a = ap.parse_args(argv)
    if not PY.is_file():
        print(f"error: no {PY}: run `make cycles-env` first", file=sys.stderr)
        return 2
    try:
        write_reaches(a.scenes, missing=a.missing, log=print)
    except BadInput as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
