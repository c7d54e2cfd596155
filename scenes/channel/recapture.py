"""A scene folder's photo through the capture channel (``totems recapture``).

``recapture(scene_dir, out, channel)`` writes a copy of ``scene_dir`` whose photo went
through :mod:`scenes.channel.channel` (a camera, then a messenger). The photo is written as
the channel leaves it: ``image.jpg``, the JPEG's bytes exactly as encoded, when the last
step is a JPEG; ``image.png`` otherwise; the source's photo file as it is when the
channel does nothing. With a resize, what is drawn on the photo's pixel grid follows
it: ``calib.npy``'s K (:func:`scenes.camera.scale_intrinsics`; 'roi' scaled too), the
totem masks (area > 1/2), ``manip_mask.png`` (any area), ``totem_masks_check.png``,
``truth/clean.png``, ``truth/tamper_totem_mask.png`` and ``truth/scene.json``'s size
and K, so the truth stays the copy's. Every other file of the folder, ``totem_masks/``
and ``truth/`` is copied as it is; other folders (such as ``totems-out/``) are not.

The copy holds no record of the channel that fit or verify could read: the record is
``truth/recapture.json``, which neither reads. The input folder is never modified; the
copy is built under a temporary name and renamed when complete.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from scenes import camera, folder
from scenes.channel import channel as channel_mod
from scenes.channel.channel import Channel
from scenes.errors import BadInput

__all__ = ["FORMAT", "recapture"]

FORMAT = 1
_MIN_MASK_PX = 20                  # as folder.read_scene requires


def recapture(scene_dir, out, channel: Channel | None = None) -> dict:
    """Write a copy of the scene folder ``scene_dir`` at ``out``, its photo recaptured.

    Parameters
    ----------
    scene_dir : a scene folder (``docs/contract.md``), photo ``image.png`` or
        ``image.jpg``.
    out : the new folder; must not exist (or be empty), nor lie inside ``scene_dir``.
    channel : the channel's settings (:class:`scenes.channel.channel.Channel`); None, the
        default, changes nothing (the photo file is copied as it is).

    Returns
    -------
    {"scene": out, "photo": file name written, "size": [W, H], "steps": the steps run}.

    Raises
    ------
    BadInput for a scene that cannot be read, settings out of range, a resize that
    leaves the photo or a totem mask too small, or ``out`` inside ``scene_dir``.
    """
    scene_dir, out = Path(scene_dir), Path(out)
    channel = channel if channel is not None else Channel()
    if not scene_dir.is_dir():
        raise BadInput(f"scene folder not found: {scene_dir}")
    src, dst = scene_dir.resolve(), out.resolve()
    if dst == src or src in dst.parents:
        raise BadInput("the output folder must lie outside the scene folder "
                       "(inputs are never modified)")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise BadInput(f"output folder exists and is not empty: {out}")
    scene = folder.read_scene(scene_dir)
    photo = folder.photo_path(scene_dir)
    steps = channel_mod.plan(channel, scene.size)
    rng = None
    if any(name == "noise" for name, _ in steps):
        rng = channel_mod.noise_rng(_setup(scene), channel.seed)
    scale = next((v for name, v in steps if name == "resize"), None)

    files = _copy_files(scene_dir, photo)
    if not steps:
        name, image = photo.name, scene.image
        files[name] = photo.read_bytes()
    else:
        image, data = channel_mod.apply(scene.image, steps, rng=rng)
        name = "image.jpg" if data is not None else "image.png"
        files[name] = data if data is not None else _image_writer(image)
    if scale is not None:
        _resize_files(files, scene_dir, scale, image.shape[:2])
    record = _record(files.get("truth/recapture.json"), scene_dir, photo, channel, steps,
                     scene.size, image, name)
    files["truth/recapture.json"] = lambda path: folder.write_json(path, record)
    with folder.staged_folder(out) as tmp:
        for rel, data in files.items():
            if callable(data):
                data(tmp / rel)
            else:
                folder.write_bytes(tmp / rel, data)
    return {"scene": str(out), "photo": name, "size": [image.shape[1], image.shape[0]],
            "steps": steps}


# --------------------------------------------------------------------------- helpers

def _setup(scene: folder.Scene) -> bytes:
    """What the noise is seeded by: the photo's size, K and totem masks (what an edit
    outside the totems leaves as it is), as bytes."""
    W, H = scene.size
    return b"".join([np.array([W, H], "<i8").tobytes(),
                     np.round(np.asarray(scene.K, "<f8"), 9).tobytes(),
                     np.packbits(np.asarray(scene.masks, bool)).tobytes()])


def _copy_files(scene_dir: Path, photo: Path) -> dict:
    """The folder's files but the photo, by relative path: top-level files (hidden
    ones and other photo names left out), ``totem_masks/*.png`` and ``truth/*``;
    ``calib.npy`` found as ``read_scene`` finds it (here or up to two folders above)."""
    files = {}
    for p in sorted(scene_dir.iterdir()):
        if p.is_file() and not p.name.startswith(".") and p.name not in folder.PHOTO_NAMES:
            files[p.name] = p.read_bytes()
    files["calib.npy"] = folder.find_calib(scene_dir).read_bytes()
    return {**files, **folder.read_parts(scene_dir)}


def _image_writer(image):
    """A function writing ``image`` (sRGB float or a bool mask) as PNG to a path."""
    return lambda path: folder.write_image(path, image)


def _resize_files(files: dict, scene_dir: Path, scale: float, shape) -> None:
    """Resize in ``files`` what is drawn on the photo's pixel grid (module docstring)."""
    H, W = shape
    calib = folder.read_calib(folder.find_calib(scene_dir))
    mtx_raw = calib.get("mtx_raw")
    if mtx_raw is None and "dist" in calib:
        mtx_raw = calib["mtx"]           # the raw photo's lens stays as it was
    roi = calib.get("roi")
    if roi is not None:
        roi = [round(float(v) * scale) for v in np.ravel(roi)]
    K = camera.scale_intrinsics(calib["mtx"], scale)
    dist = calib.get("dist")
    files["calib.npy"] = lambda path: folder.write_calib(path, K, dist, roi, mtx_raw)
    for rel in [r for r in files if r.startswith("totem_masks/")]:
        m = channel_mod.resize_mask(folder.read_mask(scene_dir / rel, what="totem mask"),
                                    scale, threshold=0.5)
        if m.sum() < _MIN_MASK_PX:
            raise BadInput(f"{rel} keeps {m.sum()} pixels at {W}x{H} (a scene needs "
                           f"{_MIN_MASK_PX}); resize less")
        files[rel] = _image_writer(m)
    for rel, threshold in (("manip_mask.png", 0.0), ("truth/tamper_totem_mask.png", 0.0)):
        if rel in files:
            m = folder.read_mask(scene_dir / rel, what=rel)
            files[rel] = _image_writer(channel_mod.resize_mask(m, scale,
                                                              threshold=threshold))
    for rel in ("totem_masks_check.png", "truth/clean.png"):
        if rel in files:
            img = folder.read_image(scene_dir / rel, what=rel)
            files[rel] = _image_writer(channel_mod.resize(img, scale))
    if "truth/scene.json" in files:
        desc = json.loads(files["truth/scene.json"])
        if "size" in desc:
            desc["size"] = [W, H]
        if "K" in desc:
            desc["K"] = camera.scale_intrinsics(desc["K"], scale).tolist()
        files["truth/scene.json"] = lambda path: folder.write_json(path, desc)


def _record(previous: bytes | None, scene_dir: Path, photo: Path, channel: Channel,
            steps, size, image, name: str) -> dict:
    """``truth/recapture.json``: what was applied; a recapture of a recapture keeps the
    earlier records in ``history``."""
    record = {"format": FORMAT,
              "source": {"folder": scene_dir.name, "photo": photo.name,
                         "photo_sha256": hashlib.sha256(photo.read_bytes()).hexdigest(),
                         "size": list(size)},
              "channel": {k: list(v) if isinstance(v, tuple) else v
                          for k, v in asdict(channel).items()},
              "steps": steps, "photo": name, "size": [image.shape[1], image.shape[0]]}
    if previous:
        prev = json.loads(previous)
        record["history"] = prev.get("history", []) + [{k: v for k, v in prev.items()
                                                        if k != "history"}]
    return record
