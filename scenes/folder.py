"""Read and write a scene folder (layout: ``shared/CONTRACT.md``); the only module
that touches its files.

Folders to verify come from strangers: ``calib.npy`` is a pickle, so it is read with a
restricted unpickler that admits only dicts, lists, tuples, numbers, strings and numpy
arrays; image files are checked for type and size before they are decoded. Every
problem is a :class:`BadInput` with one line saying what is wrong.

Outputs are written atomically (a temporary file renamed into place), so an
interrupted run never leaves a file that looks finished.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import pickle
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.errors import BadInput

MAX_PIXELS = 40_000_000          # a 40 Mpx photo; larger is refused before decoding
MAX_FILE_BYTES = 200 * 2**20
IMAGE_FORMATS = {"PNG", "JPEG", "TIFF", "BMP", "WEBP"}


# --------------------------------------------------------------------------- images

def read_image(path, *, what: str = "image") -> np.ndarray:
    """Read an 8-bit image as float32 sRGB in [0, 1], shape (H, W, 3).

    Raises BadInput for a missing, oversized, malformed or non-image file.
    """
    return _decode(path, what, mode="RGB").astype(np.float32) / 255.0


def read_mask(path, *, what: str = "mask") -> np.ndarray:
    """Read a binary mask (white = True), shape (H, W) bool."""
    return _decode(path, what, mode="L") > 127


def _decode(path, what: str, mode: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{what} not found: {path}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise BadInput(f"{what} is larger than {MAX_FILE_BYTES >> 20} MB: {path}")
    try:
        with Image.open(path) as im:
            if im.format not in IMAGE_FORMATS:
                raise BadInput(f"{what} is not a PNG/JPEG/TIFF image: {path}")
            if im.width * im.height > MAX_PIXELS:
                raise BadInput(f"{what} has {im.width}x{im.height} pixels, "
                               f"more than {MAX_PIXELS}: {path}")
            if im.mode in ("I;16", "I", "F") and mode == "RGB":
                raise BadInput(f"{what} must be 8-bit, got mode {im.mode}: {path}")
            arr = np.asarray(im.convert(mode))
    except BadInput:
        raise
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
        raise BadInput(f"{what} is unreadable ({exc.__class__.__name__}): {path}") from None
    return arr


def write_image(path, image: np.ndarray) -> None:
    """Write float [0, 1] (H, W, 3) sRGB, or bool/uint8 (H, W), as PNG, atomically."""
    from PIL import Image

    arr = np.asarray(image)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8) * 255
    elif arr.dtype != np.uint8:
        arr = (np.clip(np.nan_to_num(arr), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    write_bytes(path, buf.getvalue())


# --------------------------------------------------------------------------- atomic output

def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file renamed into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_json(path, obj) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    write_bytes(path, (json.dumps(obj, indent=2, default=_json_default) + "\n").encode())


def write_npy(path, array, *, allow_pickle: bool = False) -> None:
    """``np.save`` to ``path``, atomically."""
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=allow_pickle)
    write_bytes(path, buf.getvalue())


def write_npz(path, **arrays) -> None:
    """``np.savez_compressed`` to ``path``, atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    write_bytes(path, buf.getvalue())


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


@contextlib.contextmanager
def staged_folder(out):
    """Build a folder under a temporary name; rename it to ``out`` only on success.

    Yields the temporary path. ``out`` must not exist (or be an empty folder).
    """
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise BadInput(f"output folder exists and is not empty: {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".part"))
    try:
        yield tmp
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# --------------------------------------------------------------------------- calib.npy

_SAFE_GLOBALS = {
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
    ("numpy", "ndarray"), ("numpy", "dtype"),
    ("builtins", "dict"), ("builtins", "list"), ("builtins", "tuple"),
    ("builtins", "int"), ("builtins", "float"), ("builtins", "complex"),
    ("builtins", "str"), ("builtins", "bytes"), ("builtins", "bool"),
    ("collections", "OrderedDict"), ("_codecs", "encode"),
}


class _RestrictedUnpickler(pickle.Unpickler):
    """Admits only plain containers, numbers, strings and numpy arrays."""

    def find_class(self, module, name):
        if (module, name) in _SAFE_GLOBALS:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refused global {module}.{name}")


def safe_load_npy(path):
    """Load a ``.npy`` file, unpickling object arrays with the restricted unpickler.

    Returns the array, or for a 0-d object array (``np.save(dict)``) the object.
    """
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"file not found: {path}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise BadInput(f"file too large: {path}")
    try:
        with open(path, "rb") as f:
            version = np.lib.format.read_magic(f)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read_header(f)
            if not dtype.hasobject:
                f.seek(0)
                return np.load(f, allow_pickle=False)
            obj = _RestrictedUnpickler(f).load()
    except pickle.UnpicklingError as exc:
        raise BadInput(f"{path.name} holds objects that are not plain data ({exc}); "
                       f"refused without running it") from None
    except Exception as exc:
        raise BadInput(f"{path.name} is not a readable .npy file "
                       f"({exc.__class__.__name__}): {path}") from None
    if isinstance(obj, np.ndarray) and obj.dtype.hasobject and obj.shape == ():
        return obj.item()
    return obj


def read_calib(path) -> dict:
    """Read a NeRF-path ``calib.npy``: dict with 'mtx' (3x3 K), optional 'dist', 'roi'."""
    calib = safe_load_npy(path)
    if not isinstance(calib, dict) or "mtx" not in calib:
        raise BadInput(f"{path} must hold a dict with 'mtx' (the 3x3 intrinsics K)")
    K = np.asarray(calib["mtx"], dtype=np.float64) if _is_numeric(calib["mtx"]) else None
    if K is None or K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 \
            or K[1, 1] <= 0:
        raise BadInput(f"{path}: 'mtx' must be a finite 3x3 matrix with fx, fy > 0")
    out = {"mtx": K}
    for key in ("dist", "roi", "mtx_raw"):
        if key in calib and calib[key] is not None:
            out[key] = np.asarray(calib[key], dtype=np.float64)
    return out


def _is_numeric(x) -> bool:
    try:
        np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


def write_calib(path, K: np.ndarray, dist=None, roi=None, mtx_raw=None) -> None:
    """Write ``calib.npy`` as the NeRF path does (a pickled dict).

    ``mtx_raw``: the lens' K in the raw photo, when it differs from ``K`` (the K of the
    undistorted image); see ``scenes/calibrate.py``.
    """
    calib = {"mtx": np.asarray(K, dtype=np.float64)}
    if mtx_raw is not None:
        calib["mtx_raw"] = np.asarray(mtx_raw, dtype=np.float64)
    if dist is not None:
        calib["dist"] = np.asarray(dist, dtype=np.float64)
    if roi is not None:
        calib["roi"] = list(roi)
    write_npy(path, calib, allow_pickle=True)


# --------------------------------------------------------------------------- the key

def read_key(path, n_totems: int) -> tuple[np.ndarray, np.ndarray]:
    """Read ``totems.json``: radius (m) and IoR, one value for all or one per totem.

    Returns (radius, ior), each of shape (n_totems,).
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
                       f"{n_totems} masks")
    radius, ior = [], []
    for e in entries:
        if not isinstance(e, dict) or "radius" not in e or "ior" not in e:
            raise BadInput(f"{path} must give 'radius' (m) and 'ior' for each totem")
        r, n = _check_key(e["radius"], e["ior"], where=str(path))
        radius.append(r)
        ior.append(n)
    return np.array(radius), np.array(ior)


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
    """

    path: Path
    image: np.ndarray
    K: np.ndarray
    masks: np.ndarray
    radius: np.ndarray
    ior: np.ndarray
    initial_pose: np.ndarray | None = None
    manip_mask: np.ndarray | None = None

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


def read_scene(path, *, default_key: tuple[float, float] | None = None) -> Scene:
    """Read a scene folder and check that its parts agree.

    ``default_key`` (radius m, ior) is used when the folder has no ``totems.json``
    (the NeRF path's data set keeps the key in its configs); otherwise it is required.
    """
    path = Path(path)
    if not path.is_dir():
        raise BadInput(f"scene folder not found: {path}")
    image = read_image(path / "image.png", what="photo")
    if not np.all(np.isfinite(image)):
        raise BadInput(f"photo has non-finite values: {path / 'image.png'}")
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
    return Scene(path, image, K, masks, radius, ior, initial, manip)


@dataclass(frozen=True)
class Truth:
    """Ground truth of a synthetic scene (``truth/``); only metrics and tests read it."""

    clean: np.ndarray            # (H, W, 3) sRGB [0, 1], the camera view without totems
    totem_pose: np.ndarray       # (n, 3) true centres, camera frame, metres
    scene: dict                  # everything needed to render the scene again


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
    return Truth(clean, pose, scene)


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
        for rel, data in (extra_files or {}).items():
            write_bytes(tmp / rel, data)
    return out
