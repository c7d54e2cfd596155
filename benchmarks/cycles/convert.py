"""A Cycles render folder (``render.py``'s output) to scene folders (package's venv).

The scene folder is written by :func:`scenes.folder.write_scene`, so its format lives in
one place. K and the totems' camera-frame centres come from Blender's camera as it held
it (:func:`blender_camera.opencv_from_blender`); each totem mask is the sphere's exact
silhouette at pixel centres (:func:`sphere_masks`), checked against Cycles' own
first-hit object ids (``ids.npy``), the count of pixels they differ by recorded in
``truth/scene.json`` (``cycles.mask_check``).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from benchmarks.cycles.blender_camera import opencv_from_blender
from inverse.fit.files import pixels_read
from scenes import camera, folder
from scenes.masks import bbox

__all__ = ["sphere_masks", "read_render", "write_untouched", "write_removed"]


def sphere_masks(K, centres, radius, shape) -> np.ndarray:
    """(n, H, W) bool: each sphere's silhouette at pixel centres (camera frame, metres;
    :func:`scenes.camera.sphere_silhouette`)."""
    radii = np.broadcast_to(radius, (len(centres),))
    return np.stack([camera.sphere_silhouette(P, float(R), K, shape)
                     for P, R in zip(np.asarray(centres, float), radii)])


def read_render(render_dir) -> dict:
    """``render.json`` with K, world-to-camera and the totems' camera-frame centres."""
    render_dir = Path(render_dir)
    rec = json.loads((render_dir / "render.json").read_text())
    cam = rec["camera"]
    K, w2c = opencv_from_blender(**cam)
    desc = rec["description"]
    world = np.array([t["centre"] for t in desc["totems"]], float)
    rec["K"], rec["w2c"] = K, w2c
    rec["centres"] = world @ w2c[:3, :3].T + w2c[:3, 3]
    return rec


def _png(path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def _scene_json(rec: dict, order, mask_check) -> dict:
    desc, cam = rec["description"], rec["camera"]
    K, W = rec["K"], cam["width"]
    key = desc["key"]
    return {"format": 1, "renderer": "cycles", "preset": f"cycles-{desc['kind']}",
            "seed": desc["seed"], "size": [cam["width"], cam["height"]],
            "K": K.tolist(),
            "fov_x_deg": float(np.degrees(2 * np.arctan(W / 2 / K[0, 0]))),
            "world_to_camera": rec["w2c"].tolist(),
            "totems": [{"center": rec["centres"][j].tolist(), "radius": key["radius"],
                        "ior": key["ior"], "resting": desc["totems"][j]["resting"]}
                       for j in order],
            "spp": desc["pipeline"]["samples"], "timings": rec["times"],
            "cycles": {"blender": rec["blender"], "camera": cam, "description": desc,
                       "mask_check": mask_check}}


def _masks(rec: dict, ids: np.ndarray):
    """The exact masks left to right, their order, and per totem the pixels where
    Cycles' first hit disagrees with the analytic silhouette."""
    H, W = ids.shape
    key = rec["description"]["key"]
    masks = sphere_masks(rec["K"], rec["centres"], key["radius"], (H, W))
    order = np.argsort([np.nonzero(m)[1].mean() for m in masks], kind="stable")
    check = [int((masks[j] != (ids == rec["totem_index"] + j)).sum()) for j in order]
    return masks[order], order, check


def write_untouched(render_dir, out) -> Path:
    """The untouched scene folder of a render: image.png = photo.png, truth/clean.png,
    exact masks, the key, truth/totem_pose.npy (camera frame, left to right)."""
    rec = read_render(render_dir)
    ids = np.load(Path(render_dir) / "ids.npy")
    masks, order, check = _masks(rec, ids)
    key = rec["description"]["key"]
    truth = folder.Truth(_png(Path(render_dir) / "clean.png"), rec["centres"][order],
                         _scene_json(rec, order, {"pixels_differing": check}))
    return folder.write_scene(out, image=_png(Path(render_dir) / "photo.png"), K=rec["K"],
                              masks=masks, radius=key["radius"], ior=key["ior"],
                              truth=truth)


def write_removed(render_dir, scene_dir, out, *, grow: int = 2,
                  level: int = 4) -> Path | None:
    """An object removed from the camera's view only: outside the totems, the photo
    takes the render without the object (its shadow and light gone with it) where that
    render differs by more than ``level`` of 255 in a channel, or lies within ``grow``
    px of the object's own pixels; the totem pixels stay the photo's, so the totems
    still see it (the preset ``remove``'s perfect forger). Within the band a fit reads
    around the totems (:func:`inverse.fit.files.pixels_read`) only the object's own
    pixels change, not the two renders' noise, so the copy shares its photo's fit unless
    the object lies there, as a forger's would. None when there is none.

    Written as a tampered copy of ``scene_dir`` (manip_mask.png, truth/tamper.json of
    kind ``remove``, ``renderer`` "cycles")."""
    from scipy import ndimage

    rec = json.loads((Path(render_dir) / "render.json").read_text())
    if rec.get("removed_index") is None \
            or not (Path(render_dir) / "removed.png").is_file():
        return None
    ids = np.load(Path(render_dir) / "ids.npy")
    scene = folder.read_scene(scene_dir)
    totems = scene.masks.any(axis=0)
    src = folder.photo_path(scene_dir)
    photo = _png(src)
    removed = _png(Path(render_dir) / "removed.png")
    differs = np.abs(removed.astype(int) - photo).max(axis=-1) > level
    seen = ndimage.binary_dilation(ids == rec["removed_index"], iterations=grow)
    read = pixels_read(scene.masks, initial_pose=scene.initial_pose is not None)
    take = (differs & ~read) | (seen & ~totems)
    image = np.where(take[..., None], removed, photo)
    changed = np.any(image != photo, axis=-1)
    record = {"format": 1, "editor": "cycles, rendered without the object",
              "kind": "remove",
              "renderer": "cycles", "seed": rec["description"]["seed"],
              "object_index": rec["removed_index"],
              "source": {"folder": Path(scene_dir).name,
                         "image_sha256": hashlib.sha256(src.read_bytes()).hexdigest()},
              "changed_pixels": int(changed.sum()),
              "changed_fraction": round(float(changed.mean()), 6),
              "bbox": list(bbox(changed)), "totems_edited": False}
    truth = folder.read_truth(scene_dir)
    parts = folder.read_parts(scene_dir)
    extra = {k: v for k, v in parts.items() if k.startswith("truth/")
             and k not in ("truth/clean.png", "truth/totem_pose.npy", "truth/scene.json")}
    extra["truth/tamper.json"] = json.dumps(record, indent=1).encode()
    return folder.write_scene(out, image=image, K=scene.K, masks=scene.masks,
                              radius=float(scene.radius[0]), ior=float(scene.ior[0]),
                              truth=truth, manip_mask=changed, extra_files=extra)
