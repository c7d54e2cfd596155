"""JPEG as cameras and messengers write it: encode, decode, and what a file carries.

Encoding is Pillow's (libjpeg's, or libjpeg-turbo's): baseline, the IJG tables scaled
for ``quality`` (``jpeg_set_quality``), chroma subsampled 4:2:0 or kept 4:4:4. What a
JPEG file itself says about its compression (:class:`JpegInfo`: its quantisation tables,
the libjpeg quality they match, its chroma subsampling) is read from the file alone, so
a verifier may use it for any photo, never from a record of how it was made.
"""

from __future__ import annotations

import functools
import io
from dataclasses import dataclass

import numpy as np

from scenes.errors import BadInput

__all__ = ["CHROMA", "JpegInfo", "encode", "decode", "info", "libjpeg_tables"]

CHROMA = {"444": 0, "422": 1, "420": 2}        # Pillow's ``subsampling`` codes
_SAMPLING = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0"}


@dataclass(frozen=True)
class JpegInfo:
    """What a JPEG file says about its own compression.

    Attributes
    ----------
    quality : the libjpeg quality (1-100) whose tables are nearest the file's (sum of
        absolute differences over the luma and chroma tables).
    exact : the file's tables are libjpeg's at ``quality`` exactly (a file written with
        another encoder's tables, e.g. a camera's own, gives False).
    subsampling : "4:4:4", "4:2:2", "4:2:0", "grey" (one channel) or "other".
    luma, chroma : the quantisation tables as the file stores them (64 ints each, in
        Pillow's order); ``chroma`` is None for a grey JPEG.
    """

    quality: int
    exact: bool
    subsampling: str
    luma: tuple[int, ...]
    chroma: tuple[int, ...] | None


def encode(image: np.ndarray, *, quality: int, chroma: str = "420") -> bytes:
    """JPEG bytes of an sRGB image.

    Parameters
    ----------
    image : (H, W, 3) float sRGB in [0, 1] (rounded to 8 bits, as ``folder.write_image``)
        or uint8.
    quality : 1-100, libjpeg's scale (Pillow's ``quality``).
    chroma : "420" (chroma halved both ways, what cameras and messengers write) or
        "444" (full-resolution chroma); "422" too.
    """
    from PIL import Image

    if not (isinstance(quality, (int, np.integer)) and 1 <= int(quality) <= 100):
        raise BadInput(f"JPEG quality must be a whole number 1-100, got {quality!r}")
    if str(chroma) not in CHROMA:
        raise BadInput(f"chroma subsampling must be one of {', '.join(CHROMA)}, "
                       f"got {chroma!r}")
    arr = np.asarray(image)
    if arr.dtype != np.uint8:
        arr = (np.clip(np.nan_to_num(arr), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="JPEG", quality=int(quality),
                              subsampling=CHROMA[str(chroma)])
    return buf.getvalue()


def decode(data: bytes) -> np.ndarray:
    """Decode JPEG bytes to (H, W, 3) float32 sRGB in [0, 1] (values k / 255)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGB")).astype(np.float32) / 255.0


def info(im) -> JpegInfo | None:
    """:class:`JpegInfo` of an open Pillow image, or None when it is not a JPEG."""
    from PIL import JpegImagePlugin

    if getattr(im, "format", None) != "JPEG":
        return None
    tables = getattr(im, "quantization", None) or {}
    if not tables:
        return None
    ids = sorted(tables)
    luma = tuple(int(v) for v in tables[ids[0]])
    chroma = tuple(int(v) for v in tables[ids[1]]) if len(ids) > 1 else None
    if im.mode == "L":
        sampling = "grey"
    else:
        sampling = _SAMPLING.get(JpegImagePlugin.get_sampling(im), "other")
    quality, exact = _nearest_quality(luma, chroma)
    return JpegInfo(quality, exact, sampling, luma, chroma)


@functools.lru_cache(maxsize=None)
def libjpeg_tables(quality: int) -> tuple[np.ndarray, np.ndarray]:
    """(luma, chroma) quantisation tables (64 ints each) that Pillow writes at
    ``quality``, read back from an 8 x 8 image it encodes (so they are this libjpeg's
    own, in the order :func:`info` reads them)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 8)).save(buf, format="JPEG", quality=int(quality))
    with Image.open(io.BytesIO(buf.getvalue())) as im:
        q = im.quantization
    return np.array(q[0], int), np.array(q[1], int)


def _nearest_quality(luma, chroma) -> tuple[int, bool]:
    luma = np.asarray(luma, int)
    best, best_d = 1, None
    for q in range(1, 101):
        L, C = libjpeg_tables(q)
        d = int(np.abs(luma - L).sum())
        if chroma is not None:
            d += int(np.abs(np.asarray(chroma, int) - C).sum())
        if best_d is None or d < best_d:
            best, best_d = q, d
    return best, best_d == 0
