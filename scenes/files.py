"""Single files of a scene folder: guarded reads, atomic writes (used by
:mod:`scenes.folder`, whose names they also are).

Folders to verify come from strangers: ``calib.npy`` is a pickle, so it is read with a
restricted unpickler that admits only dicts, lists, tuples, numbers, strings and numpy
arrays; image files are checked for type and size before they are decoded. Every
problem is a :class:`BadInput` with one line saying what is wrong. Outputs are written
atomically (a temporary file renamed into place), so an interrupted run never leaves a
file that looks finished.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import pickle
import shutil
import tempfile
from pathlib import Path

import numpy as np

from scenes.errors import BadInput

__all__ = ["MAX_PIXELS", "MAX_FILE_BYTES", "IMAGE_FORMATS", "read_image", "read_mask",
           "write_image", "write_bytes", "write_json", "write_npy", "write_npz",
           "staged_folder", "safe_load_npy", "read_calib", "write_calib"]

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


def _readable(path, what: str) -> Path:
    """``path`` as a Path, BadInput unless it is a file of at most MAX_FILE_BYTES."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{what} not found: {path}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise BadInput(f"{what} is larger than {MAX_FILE_BYTES >> 20} MB: {path}")
    return path


def _decode(path, what: str, mode: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    path = _readable(path, what)
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
    """Write float [0, 1] (H, W, 3) sRGB, or bool/uint8 (H, W), as PNG, atomically;
    zlib's fastest level (a check writes some twenty pictures: four times faster than the
    default, files a sixth larger)."""
    from PIL import Image

    arr = np.asarray(image)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8) * 255
    elif arr.dtype != np.uint8:
        arr = (np.clip(np.nan_to_num(arr), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG", compress_level=1)
    write_bytes(path, buf.getvalue())


# --------------------------------------------------------------------------- atomic output

def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file renamed into place, with the
    permissions an ordinary ``open`` would give (mkstemp's are owner-only)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@functools.lru_cache(maxsize=1)
def _umask() -> int:
    """The process's umask, read once (reading it means setting it and putting it back,
    which is not safe while other threads create files)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


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
    path = _readable(path, "file")
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
    undistorted image); see ``scenes/photo/calibrate.py``.
    """
    calib = {"mtx": np.asarray(K, dtype=np.float64)}
    if mtx_raw is not None:
        calib["mtx_raw"] = np.asarray(mtx_raw, dtype=np.float64)
    if dist is not None:
        calib["dist"] = np.asarray(dist, dtype=np.float64)
    if roi is not None:
        calib["roi"] = list(roi)
    write_npy(path, calib, allow_pickle=True)
