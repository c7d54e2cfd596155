"""Make a synthetic totem-protected scene folder (layout: ``shared/CONTRACT.md``).

``image.png`` is the path-traced photo with the glass totems; ``truth/clean.png`` is
the same camera, scene and sampler seed without them (so their noise agrees wherever
no light path met a totem); the masks come from the renderer's own camera rays.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from scenes import folder, presets, render
from scenes.errors import BadInput


def make_scene(out, *, preset: str = "box", seed: int = 1, size=(640, 480),
               n_totems: int = 4, spp: int = 64, radius: float = presets.TOTEM_RADIUS,
               ior: float = presets.TOTEM_IOR, progress: bool = False) -> Path:
    """Render a random scene of ``preset`` and write its folder at ``out``.

    Parameters
    ----------
    out : the folder to create (must not exist, or be empty).
    preset : "box" or "envmap" (:mod:`scenes.presets`).
    seed : the scene's random seed (same seed, same scene and same pixels).
    size : (W, H) in pixels.
    n_totems : number of glass spheres (>= 1).
    spp : samples per pixel of both renders.
    radius, ior : the totems' radius (m) and index of refraction: the key.
    progress : show a progress bar on stderr.

    Returns
    -------
    Path of the folder, holding image.png, calib.npy, totem_masks/, totems.json and
    truth/ (clean.png, totem_pose.npy, scene.json with the description and timings).
    """
    out = Path(out)
    if int(n_totems) < 1:
        raise BadInput(f"a scene needs at least one totem, got {n_totems}")
    if not 1 <= int(spp) <= 65536:
        raise BadInput(f"samples per pixel must be 1..65536, got {spp}")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise BadInput(f"output folder exists and is not empty: {out}")
    desc = presets.describe(preset, seed, size=size, n_totems=n_totems, radius=radius,
                            ior=ior)
    bar = _bar(progress, 3)
    timings = {}
    t0 = time.perf_counter()
    sampler_seed = int(seed) % 2**31
    image = render.render(desc, spp=spp, seed=sampler_seed)
    timings["photo_s"] = round(time.perf_counter() - t0, 2)
    bar.update()
    t0 = time.perf_counter()
    clean = render.render(desc, spp=spp, seed=sampler_seed, totems=False)
    timings["clean_s"] = round(time.perf_counter() - t0, 2)
    bar.update()
    ids = render.shape_ids(desc)
    masks = np.stack([ids == render.totem_id(j) for j in range(len(desc["totems"]))])
    bar.update()
    bar.close()
    empty = [j for j, m in enumerate(masks) if m.sum() < 20]
    if empty:
        raise BadInput(f"totems {empty} cover fewer than 20 pixels at {size[0]}x{size[1]}; "
                       "use a larger size")
    # left to right by mask centroid, as folder.read_scene orders them
    order = np.argsort([np.nonzero(m)[1].mean() for m in masks], kind="stable")
    masks = masks[order]
    pose = np.array([t["center"] for t in desc["totems"]], float)[order]
    record = dict(desc, spp=int(spp), sampler=render.sampler_type(spp),
                  sampler_seed=sampler_seed, timings=timings)
    truth = folder.Truth(clean=clean, totem_pose=pose, scene=record)
    return folder.write_scene(out, image=image, K=np.asarray(desc["K"], float),
                              masks=masks, radius=float(radius), ior=float(ior), truth=truth)


def _bar(enabled: bool, total: int):
    from tqdm import tqdm

    return tqdm(total=total, desc="rendering", unit="step", disable=not enabled,
                leave=False)
