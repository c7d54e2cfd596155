"""Make a synthetic totem-protected scene folder (layout: ``docs/contract.md``).

``image.png`` is the path-traced photo with the glass totems; ``truth/clean.png`` is
the same camera, scene and sampler seed without them (so their noise agrees wherever
no light path met a totem); the masks come from the renderer's own camera rays.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput
from scenes.synthetic import presets, render, trace
from scenes.synthetic.preset_parts import sphere_outline

__all__ = ["make_scene", "hidden_totems"]

CAMERA_STREAM = 1          # the camera noise's generator: (sampler seed, this)
MIN_VISIBLE = 0.5
"""A totem the camera sees less of than this fraction of its disc is hidden."""
MIN_DRAWN = 3
"""Hidden totems are left out of a drawn key while at least this many remain."""


def make_scene(out, *, preset: str = "box", seed: int = 1, size=(640, 480),
               n_totems: int | None = None, spp: int = 64, radius: float | None = None,
               ior: float | None = None, camera: bool = False,
               progress: bool = False, placement: str | None = None) -> Path:
    """Render a random scene of ``preset`` and write its folder at ``out``.

    Parameters
    ----------
    out : the folder to create (must not exist, or be empty).
    preset : one of ``presets.PRESETS``.
    seed : the scene's random seed (same seed, same scene and same pixels).
    size : (W, H) in pixels.
    n_totems : number of glass spheres (>= 1); None: the preset's.
    spp : samples per pixel of both renders.
    radius, ior : the totems' radius (m) and index of refraction, the key, for all
        totems; None: the preset's (:func:`scenes.synthetic.presets.describe`).
        ``totems.json`` holds one entry when all totems share it, else one per totem, left
        to right.
    camera : a realistic camera: photon and read noise on the linear render, before
        the sRGB tone curve (:func:`scenes.channel.channel.photon_noise`, seeded by
        ``seed``); the photo only, ``truth/clean.png`` stays the scene. Off by default, so
        scenes made before it keep their pixels.
    progress : show a progress bar on stderr.
    placement : how the totems stand (:mod:`scenes.synthetic.placement`: floating,
        resting on the floor, ground or table, or on thin stands); None: the preset's.

    Returns
    -------
    Path of the folder, holding image.png, calib.npy, totem_masks/, totems.json and
    truth/ (clean.png, totem_pose.npy, scene.json with the description and timings,
    reach.npz: what the totems truly see, :func:`scenes.synthetic.trace.truth_reach`).
    """
    out = Path(out)
    if n_totems is not None and int(n_totems) < 1:
        raise BadInput(f"a scene needs at least one totem, got {n_totems}")
    if not 1 <= int(spp) <= 65536:
        raise BadInput(f"samples per pixel must be 1..65536, got {spp}")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise BadInput(f"output folder exists and is not empty: {out}")
    desc = presets.describe(preset, seed, size=size, n_totems=n_totems, radius=radius,
                            ior=ior, placement=placement)
    if n_totems is None:                    # a drawn count: hidden totems are left out
        desc = _without_hidden(desc)
    bar = _bar(progress, 3)
    timings = {}
    t0 = time.perf_counter()
    sampler_seed = int(seed) % 2**31
    if camera:
        from scenes.channel.channel import FULL_WELL_E, READ_NOISE_E, photon_noise
        from scenes.colour import linear_to_srgb

        linear = render.render(desc, spp=spp, seed=sampler_seed, linear=True)
        rng = np.random.default_rng([sampler_seed, CAMERA_STREAM])
        image = linear_to_srgb(photon_noise(linear, rng))
        extra = {"camera": {"full_well_e": FULL_WELL_E, "read_noise_e": READ_NOISE_E}}
    else:
        image = render.render(desc, spp=spp, seed=sampler_seed)
        extra = {}
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
    t0 = time.perf_counter()
    reach, _ = trace.truth_reach(desc)
    reach.spacing = reach.spacing[order]
    timings["reach_s"] = round(time.perf_counter() - t0, 2)
    record = dict(desc, spp=int(spp), sampler=render.sampler_type(spp),
                  sampler_seed=sampler_seed, timings=timings, **extra)
    truth = folder.Truth(clean=clean, totem_pose=pose, scene=record, reach=reach)
    radius, ior = _key(desc["totems"], order)
    return folder.write_scene(out, image=image, K=np.asarray(desc["K"], float),
                              masks=masks, radius=radius, ior=ior, truth=truth)


def hidden_totems(desc: dict, ids: np.ndarray, *, min_visible: float = MIN_VISIBLE) -> list:
    """The totems of ``desc`` of which the camera sees less than ``min_visible`` of the
    disc they would cover alone: ``ids`` (H, W) :func:`scenes.synthetic.render.shape_ids`
    against the area of each sphere's outline (pixels)."""
    K = np.asarray(desc["K"], float)
    hidden = []
    for j, t in enumerate(desc["totems"]):
        uv = sphere_outline(K, t["center"], t["radius"])
        area = 0.5 * abs(np.dot(uv[:, 0], np.roll(uv[:, 1], 1))
                         - np.dot(uv[:, 1], np.roll(uv[:, 0], 1)))
        if np.count_nonzero(ids == render.totem_id(j)) < min_visible * area:
            hidden.append(j)
    return hidden


def _without_hidden(desc: dict) -> dict:
    """``desc`` without the totems an object hides (:func:`hidden_totems`), while at
    least ``MIN_DRAWN`` remain; the description records them (``hidden_totems``)."""
    hidden = hidden_totems(desc, render.shape_ids(desc))
    if not hidden or len(desc["totems"]) - len(hidden) < MIN_DRAWN:
        return desc
    kept = [t for j, t in enumerate(desc["totems"]) if j not in hidden]
    return dict(desc, totems=kept, hidden_totems=[desc["totems"][j] for j in hidden])


def _key(totems: list, order) -> tuple:
    """The key as ``folder.write_scene`` takes it: one (radius m, ior) when every
    totem shares it, else per-totem arrays in the masks' ``order``."""
    radius = np.array([t["radius"] for t in totems], float)[order]
    ior = np.array([t["ior"] for t in totems], float)[order]
    if np.all(radius == radius[0]) and np.all(ior == ior[0]):
        return float(radius[0]), float(ior[0])
    return radius, ior


def _bar(enabled: bool, total: int):
    from tqdm import tqdm

    return tqdm(total=total, desc="rendering", unit="step", disable=not enabled,
                leave=False)
