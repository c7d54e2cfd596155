"""Read and write a scene folder (layout: ``docs/contract.md``); with
:mod:`scenes.files` (the single files: guarded reads, atomic writes, whose functions
are also this module's), the only code that touches its files.

Folders to verify come from strangers: every problem is a :class:`BadInput` with one
line saying what is wrong, and outputs appear whole or not at all.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.errors import BadInput
from scenes.files import (IMAGE_FORMATS, MAX_FILE_BYTES, MAX_PIXELS, read_calib,
                          read_image, read_mask, safe_load_npy, staged_folder, write_bytes,
                          write_calib, write_image, write_json, write_npy, write_npz)
from scenes.jpeg import JpegInfo
from scenes.reach import Reach

__all__ = ["MAX_PIXELS", "MAX_FILE_BYTES", "IMAGE_FORMATS", "read_image", "read_mask",
           "write_image", "write_bytes", "write_json", "write_npy", "write_npz",
           "staged_folder", "safe_load_npy", "read_calib", "write_calib", "read_key",
           "expected_totems", "key_iors",
           "key_fingerprint", "Scene", "find_calib", "PHOTO_NAMES", "photo_path",
           "read_jpeg_info", "read_parts", "read_scene", "Truth", "read_truth", "read_reach",
           "read_scene_json",
           "write_scene"]

PHOTO_NAMES = ("image.png", "image.jpg", "image.jpeg")   # the photo: exactly one of them


# --------------------------------------------------------------------------- the key

def read_key(path, n_totems: int, *, what: str = "masks") -> tuple[np.ndarray, np.ndarray]:
    """Read ``totems.json``: radius (m) and IoR, one value for all or one per totem.

    Returns (radius, ior), each of shape (n_totems,). ``what`` names the totems counted
    (a photo's masks, a plan's totems) when the key lists another number.
    """
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"key not found: {path} (totems.json with radius and ior)")
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f"{path} is not valid JSON ({exc})") from None
    entries = data if isinstance(data, list) else [data] * n_totems
    if len(entries) != n_totems:
        raise BadInput(f"{path} lists {len(entries)} totems but there are "
                       f"{n_totems} {what}")
    radius, ior = [], []
    for e in entries:
        if not isinstance(e, dict) or "radius" not in e or "ior" not in e:
            raise BadInput(f"{path} must give 'radius' (m) and 'ior' for each totem")
        r, n = _check_key(e["radius"], e["ior"], where=str(path))
        radius.append(r)
        ior.append(n)
    return np.array(radius), np.array(ior)


def expected_totems(scene_dir) -> int | None:
    """How many totems the scene's key lists (``totems.json`` as a list), or None when
    it gives one radius and IoR for all (or there is no key)."""
    data = _key_entries(scene_dir)
    return len(data) if isinstance(data, list) else None


def key_iors(scene_dir) -> list | None:
    """The indices of refraction the scene's key gives (one, or one per totem), or None
    when there is no readable key."""
    data = _key_entries(scene_dir)
    entries = data if isinstance(data, list) else [data]
    try:
        iors = [float(e["ior"]) for e in entries]
    except (TypeError, KeyError, ValueError):
        return None
    return iors if iors and all(1.0 < v < 4.0 for v in iors) else None


def _key_entries(scene_dir):
    """``totems.json`` as parsed JSON, or None when it is missing or not JSON (read
    before the masks are known, so nothing is checked against them)."""
    try:
        return json.loads((Path(scene_dir) / "totems.json").read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None


def _check_key(radius, ior, *, where: str) -> tuple[float, float]:
    """One totem's key as floats: radius in (0, 10) metres, ior in (1, 4)."""
    try:
        r, n = float(radius), float(ior)
    except (TypeError, ValueError):
        raise BadInput(f"{where}: radius and ior must be numbers") from None
    if not (np.isfinite(r) and 0.0 < r < 10.0):
        raise BadInput(f"{where}: radius must be a positive length in metres, got {r}")
    if not (np.isfinite(n) and 1.0 < n < 4.0):
        raise BadInput(f"{where}: ior must lie in (1, 4), got {n}")
    return r, n


def key_fingerprint(radius, ior) -> str:
    """A short, non-reversible fingerprint of the key (safe to share in reports)."""
    import hashlib

    text = json.dumps([[round(float(r), 9) for r in np.ravel(radius)],
                       [round(float(n), 9) for n in np.ravel(ior)]])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


# --------------------------------------------------------------------------- the folder

@dataclass(frozen=True)
class Scene:
    """A scene folder in memory. Never holds ``truth/``: fit and verify do not see it.

    Attributes
    ----------
    image : (H, W, 3) float32, sRGB in [0, 1].
    K : (3, 3) intrinsics, OpenCV pixel-centre convention.
    masks : (n, H, W) bool, totems left to right by mask centroid x.
    radius, ior : (n,) the key: radius in metres, index of refraction.
    initial_pose : (n, 3) camera-frame centres in metres, or None.
    manip_mask : (H, W) bool ground truth of a manipulation, or None.
    jpeg : what the photo's file says about its JPEG compression (its quantisation
        tables, the quality they match, its chroma subsampling), read from the file
        alone; None when the photo is not a JPEG.
    scale : the photo's pixels per pixel of this scene along each axis: 1 as read, more
        at the working resolution (:mod:`scenes.working`).
    """

    path: Path
    image: np.ndarray
    K: np.ndarray
    masks: np.ndarray
    radius: np.ndarray
    ior: np.ndarray
    initial_pose: np.ndarray | None = None
    manip_mask: np.ndarray | None = None
    jpeg: JpegInfo | None = None
    scale: int = 1

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.image.shape[1], self.image.shape[0]

    @property
    def n_totems(self) -> int:
        return self.masks.shape[0]


def find_calib(path: Path, levels: int = 2) -> Path:
    """``SCENE/calib.npy``, or one in the ``levels`` folders above (shared by a data set:
    the NeRF path keeps ``data-compiled/calib.npy`` two levels above each case)."""
    path = Path(path).resolve()
    for p in [path, *path.parents][:levels + 1]:
        if (p / "calib.npy").is_file():
            return p / "calib.npy"
    raise BadInput(f"no calib.npy in {path} or the {levels} folders above it")


def photo_path(path) -> Path:
    """The scene folder's photo: ``image.png``, or ``image.jpg`` / ``image.jpeg`` as a
    camera writes it; exactly one of them (two are refused: which is the photo?).
    Its pixels are read as stored: an EXIF orientation is not applied, as K and the
    masks refer to the stored pixel grid."""
    path = Path(path)
    found = [path / n for n in PHOTO_NAMES if (path / n).is_file()]
    if not found:
        raise BadInput(f"photo not found: {path / 'image.png'} (or image.jpg)")
    if len(found) > 1:
        raise BadInput(f"{path} holds {' and '.join(p.name for p in found)}: keep only "
                       f"the photo to check")
    return found[0]


def read_jpeg_info(path) -> JpegInfo | None:
    """What an image file says about its JPEG compression (:class:`scenes.jpeg.JpegInfo`:
    quantisation tables, the quality they match, chroma subsampling), or None when the
    file is not a JPEG by content. Read from the file's headers alone."""
    from PIL import Image, UnidentifiedImageError

    from scenes import jpeg

    try:
        with Image.open(path) as im:
            return jpeg.info(im)
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise BadInput(f"photo is unreadable ({exc.__class__.__name__}): {path}") from None


def read_parts(path) -> dict[str, bytes]:
    """The bytes of a scene folder's totem masks and truth files, by their path in the
    folder (``totem_masks/totem_000.png``, ``truth/scene.json``...), for a copy."""
    path = Path(path)
    parts = {f"totem_masks/{p.name}": p.read_bytes()
             for p in sorted((path / "totem_masks").glob("*.png"))}
    if (path / "truth").is_dir():
        parts.update({f"truth/{p.name}": p.read_bytes()
                      for p in sorted((path / "truth").iterdir())
                      if p.is_file() and not p.name.startswith(".")})
    return parts


def read_scene(path, *, default_key: tuple[float, float] | None = None) -> Scene:
    """Read a scene folder and check that its parts agree.

    ``default_key`` (radius m, ior) is used when the folder has no ``totems.json``
    (the NeRF path's data set keeps the key in its configs); otherwise it is required.
    """
    path = Path(path)
    if not path.is_dir():
        raise BadInput(f"scene folder not found: {path}")
    photo = photo_path(path)
    image = read_image(photo, what="photo")
    if not np.all(np.isfinite(image)):
        raise BadInput(f"photo has non-finite values: {photo}")
    H, W = image.shape[:2]
    K = read_calib(find_calib(path))["mtx"]
    mask_dir = path / "totem_masks"
    files = sorted(mask_dir.glob("*.png")) if mask_dir.is_dir() else []
    if not files:
        raise BadInput(f"no totem masks in {mask_dir} (totem_000.png, ...)")
    masks = []
    for f in files:
        m = read_mask(f, what="totem mask")
        if m.shape != (H, W):
            raise BadInput(f"totem mask {f.name} is {m.shape[1]}x{m.shape[0]} but the "
                           f"photo is {W}x{H}")
        if m.sum() < 20:
            raise BadInput(f"totem mask {f.name} has no totem pixels (white = totem)")
        masks.append(m)
    order = np.argsort([np.nonzero(m)[1].mean() for m in masks], kind="stable")
    masks = np.stack([masks[i] for i in order])
    if default_key is not None and not (path / "totems.json").is_file():
        radius, ior = _check_key(*default_key, where="the key")
        radius, ior = np.full(len(masks), radius), np.full(len(masks), ior)
    else:
        radius, ior = read_key(path / "totems.json", len(masks))
    initial = None
    if (path / "initial_totem_pose.npy").is_file():
        initial = np.asarray(safe_load_npy(path / "initial_totem_pose.npy"), dtype=float)
        if initial.shape != (len(masks), 3) or not np.all(np.isfinite(initial)):
            raise BadInput(f"initial_totem_pose.npy must be ({len(masks)}, 3) finite")
    manip = None
    if (path / "manip_mask.png").is_file():
        manip = read_mask(path / "manip_mask.png", what="manipulation mask")
        if manip.shape != (H, W):
            raise BadInput("manip_mask.png is not the size of the photo")
    return Scene(path, image, K, masks, radius, ior, initial, manip, read_jpeg_info(photo))


@dataclass(frozen=True)
class Truth:
    """Ground truth of a synthetic scene (``truth/``); only metrics and tests read it."""

    clean: np.ndarray            # (H, W, 3) sRGB [0, 1], the camera view without totems
    totem_pose: np.ndarray       # (n, 3) true centres, camera frame, metres
    scene: dict                  # everything needed to render the scene again
    reach: Reach | None = None   # what the totems truly see (truth/reach.npz), if traced


def read_truth(path) -> Truth | None:
    """Read ``SCENE/truth/``, or None when the scene has none (a real photo).

    A tampered photo's ``truth/`` holds only the record of the edit (``tamper.json``):
    it has no scene truth, so None too.
    """
    t = Path(path) / "truth"
    if not t.is_dir() or not any((t / f).is_file()
                                 for f in ("clean.png", "totem_pose.npy", "scene.json")):
        return None
    clean = read_image(t / "clean.png", what="truth/clean.png")
    pose = np.asarray(safe_load_npy(t / "totem_pose.npy"), dtype=float)
    scene = json.loads((t / "scene.json").read_text()) if (t / "scene.json").is_file() \
        else {}
    return Truth(clean, pose, scene, read_reach(t / "reach.npz"))


def read_scene_json(scene_dir, *, missing: str) -> dict:
    """``SCENE/truth/scene.json``, parsed; a :class:`BadInput` saying ``missing`` (what
    would have made one) when there is none, and one when it is not JSON."""
    path = Path(scene_dir) / "truth" / "scene.json"
    if not path.is_file():
        raise BadInput(f"no truth/scene.json in {scene_dir}: {missing}")
    try:
        return json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f"{path} is not valid JSON ({exc})") from None


def read_reach(path) -> Reach | None:
    """``truth/reach.npz`` (:class:`scenes.reach.Reach`), or None when there is none."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            return Reach.from_dict(z)
    except Exception as exc:
        raise BadInput(f"{path} is not a readable reach file "
                       f"({exc.__class__.__name__})") from None


def write_scene(out, *, image, K, masks, radius, ior, truth: Truth | None = None,
                manip_mask=None, initial_pose=None, extra_files: dict | None = None) -> Path:
    """Write a complete scene folder at ``out`` (staged, renamed when complete).

    ``radius`` and ``ior`` are scalars (one key for all totems) or per-totem lists.
    ``extra_files`` maps relative paths to bytes (e.g. ``truth/tamper.json``).
    """
    out = Path(out)
    with staged_folder(out) as tmp:
        write_image(tmp / "image.png", image)
        write_calib(tmp / "calib.npy", K)
        for i, m in enumerate(masks):
            write_image(tmp / "totem_masks" / f"totem_{i:03d}.png", np.asarray(m, bool))
        if np.ndim(radius) == 0 and np.ndim(ior) == 0:
            key = {"radius": float(radius), "ior": float(ior)}
        else:
            r = np.broadcast_to(radius, (len(masks),))
            n = np.broadcast_to(ior, (len(masks),))
            key = [{"radius": float(a), "ior": float(b)} for a, b in zip(r, n)]
        write_json(tmp / "totems.json", key)
        if manip_mask is not None:
            write_image(tmp / "manip_mask.png", np.asarray(manip_mask, bool))
        if initial_pose is not None:
            write_npy(tmp / "initial_totem_pose.npy", np.asarray(initial_pose, float))
        if truth is not None:
            write_image(tmp / "truth" / "clean.png", truth.clean)
            write_npy(tmp / "truth" / "totem_pose.npy", np.asarray(truth.totem_pose, float))
            write_json(tmp / "truth" / "scene.json", truth.scene)
            if truth.reach is not None:
                write_npz(tmp / "truth" / "reach.npz", **truth.reach.to_dict())
        for rel, data in (extra_files or {}).items():
            write_bytes(tmp / rel, data)
    return out
