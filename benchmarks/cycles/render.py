"""Render one Cycles totem scene to an intermediate folder (with .venv-cycles' python).

    .venv-cycles/bin/python benchmarks/cycles/render.py OUT --seed N
        [--kind room|yard|table] [--size WxH | --small] [--samples N] [--remove]
        [--linear] [--depth] [--no-clean] [--view AgX|Filmic|Standard] [--denoise on|off]
        [--filter BOX|GAUSSIAN|BLACKMAN_HARRIS] [--filter-width PX]
        [--glass glass|refraction|coated] [--totem-shadows on|off]
    .venv-cycles/bin/python benchmarks/cycles/render.py OUT --desc DESC.json [...]

Writes OUT/: photo.png (the camera's photo: its view transform, denoiser and pixel
filter), clean.png (the same without the totems), ids.npy (the object each pixel centre
sees first, ``blender_scene.render_ids``), removed.png with ``--remove`` (the photo
without one object; ``convert.py`` keeps the totems' pixels), linear.npy with
``--linear`` (the scene-linear photo), depth.npy with ``--depth`` (Cycles' own depth of
the first surface each pixel centre shows without the totems, camera-frame z in metres,
inf for none: ``blender_scene.render_depth``, a check of ``blender_trace.py``), and
render.json last (the description, Blender's
camera as it held it, timings). The scene folder is written from it by ``convert.py``
in the package's venv.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402  (bpy's own numpy)

import blender_scene as bs  # noqa: E402
import design  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    design.scene_options(ap)
    ap.add_argument("--desc", help="a description (JSON), not one drawn from --seed")
    ap.add_argument("--remove", action="store_true",
                    help="also render without one object (for the camera's view)")
    ap.add_argument("--linear", action="store_true", help="also the scene-linear photo")
    ap.add_argument("--depth", action="store_true",
                    help="also Cycles' depth of the scene without the totems (checks)")
    ap.add_argument("--no-clean", action="store_true",
                    help="no clean.png (an ablation of the totems alone, whose clean "
                         "view is the unablated render's)")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args(argv)
    W, H = (160, 120) if a.small else (int(v) for v in a.size.lower().split("x"))
    samples = 16 if a.small else a.samples
    if a.desc:
        with open(a.desc) as f:
            desc = json.load(f)
    else:
        desc = design.describe(a.seed, kind=a.kind, size=(W, H), samples=samples)
    desc = design.ablate(desc, a)
    os.makedirs(a.out, exist_ok=True)
    out = os.path.abspath(a.out)
    times = {}
    t0 = time.perf_counter()
    parts = bs.build(desc, threads=a.threads)
    times["build_s"] = time.perf_counter() - t0

    def timed(key, fn, *args):
        t = time.perf_counter()
        r = fn(*args)
        times[key] = round(time.perf_counter() - t, 2)
        return r

    p = desc["pipeline"]
    if "metered_ev" not in p:            # a camera's auto exposure, then its bias
        p["metered_ev"] = timed("meter_s", bs.meter, os.path.join(out, "meter.exr"), p)
        os.remove(os.path.join(out, "meter.exr"))
    p = dict(p, exposure=p.get("exposure", 0.0) + p["metered_ev"])
    timed("photo_s", bs.render_png, os.path.join(out, "photo.png"), p)
    if a.linear:
        lin = timed("linear_s", bs.render_linear, os.path.join(out, "linear.exr"), p)
        np.save(os.path.join(out, "linear.npy"), lin)
        os.remove(os.path.join(out, "linear.exr"))
    ids = timed("ids_s", bs.render_ids, os.path.join(out, "ids.exr"))
    np.save(os.path.join(out, "ids.npy"), ids)
    os.remove(os.path.join(out, "ids.exr"))
    removed = None
    if a.remove:
        removed = _removable(desc, parts, ids)
        if removed is not None:
            obj = parts["objects"][removed]
            bs.set_visible(obj, render=False)
            timed("removed_s", bs.render_png, os.path.join(out, "removed.png"), p)
            bs.set_visible(obj, render=True)
    for t in parts["totems"]:
        bs.set_visible(t, render=False)
    if not a.no_clean:
        timed("clean_s", bs.render_png, os.path.join(out, "clean.png"), p)
    if a.depth:
        depth = timed("depth_s", bs.render_depth, os.path.join(out, "depth.exr"))
        np.save(os.path.join(out, "depth.npy"), depth)
        os.remove(os.path.join(out, "depth.exr"))
    import bpy

    record = {"format": 1, "description": desc, "camera": bs.camera_params(),
              "blender": bpy.app.version_string, "times": times,
              "remove_asked": bool(a.remove),
              "removed_index": None if removed is None else int(removed + 1),
              "totem_index": bs.TOTEM_INDEX, "marker_index": bs.MARKER_INDEX}
    tmp = os.path.join(out, ".render.json")
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1)
    os.replace(tmp, os.path.join(out, "render.json"))
    return 0


def _removable(desc, parts, ids) -> int | None:
    """The removable object with the most directly seen pixels above the totems."""
    totem_rows = np.nonzero((ids >= bs.TOTEM_INDEX) & (ids < bs.MARKER_INDEX))[0]
    top = totem_rows.min() if totem_rows.size else ids.shape[0]
    best, count = None, 150
    for i, o in enumerate(desc.get("objects", [])):
        n = int((ids[:top] == i + 1).sum())
        if o.get("removable") and n > count:
            best, count = i, n
    return best


if __name__ == "__main__":
    sys.exit(main())
