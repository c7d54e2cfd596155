"""What the forgers share: an edit, the scene it is made on, where it goes.

The editors of :mod:`scenes.tamper.tamper` (2D: ``color``, ``splice``, ``inpaint``,
``consistent-paste``, ``erase-everywhere``), of :mod:`scenes.tamper.tamper3d` (re-rendering:
``remove``, ``insert``, ``shift``), of :mod:`scenes.tamper.totem2d` (``totem-retouch``,
and the totem halves of ``consistent-paste`` and ``erase-everywhere``) and of
:mod:`scenes.tamper.rekey` (``rekey``) are functions ``(Source, rng) -> Edit``. They
import this one; ``tamper`` loads the others only when their kind is asked for, and none
of them imports ``tamper``.

The pixel tools themselves (pasting, cloning, moving) are in
:mod:`scenes.tamper.edits2d`; a selection's box or its dilation in :mod:`scenes.masks`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes import folder, masks
from scenes.errors import BadInput

__all__ = ["Edit", "Source", "pick_object", "target_zone"]


@dataclass
class Edit:
    """What an editor did: the new 8-bit image, the changed camera pixels, a record."""

    image: np.ndarray                       # (H, W, 3) uint8 sRGB
    mask: np.ndarray                        # (H, W) bool, changed camera-view pixels
    record: dict = field(default_factory=dict)
    totem_mask: np.ndarray | None = None    # (H, W) bool, edited totem pixels (the
                                            # kinds that edit the totems: shift, ...)


@dataclass
class Source:
    """The scene being forged, as the editors see it."""

    path: Path
    image: np.ndarray           # (H, W, 3) uint8 sRGB, the file's values
    scene: folder.Scene
    truth: folder.Truth | None
    totems: np.ndarray          # (H, W) bool, union of the totem masks
    region: np.ndarray | None   # (H, W) bool, where the user asked for the edit
    options: dict = field(default_factory=dict)   # the kind's own options, as given
                                                  # (None or absent: drawn per seed)

    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape[:2]


def target_zone(totems: np.ndarray) -> np.ndarray:
    """Where a forger edits when not told: the middle of the image above the totems.

    The totems protect the part of the scene they see, which is what lies above them
    in the picture (the paper's patch grid is also laid above the totems).
    Returns (H, W) bool.
    """
    H, W = totems.shape
    top = masks.bbox(totems)[1] if totems.any() else H
    y0, y1 = int(0.08 * H), int(top - 0.02 * H)
    if y1 - y0 < 0.2 * H:                         # totems high up: use the whole middle
        y0, y1 = int(0.1 * H), int(0.9 * H)
    zone = np.zeros((H, W), bool)
    zone[y0:y1, int(0.15 * W):int(0.85 * W)] = True
    return zone & ~totems


def pick_object(src: Source, rng, *, ids=None, only=None):
    """A removable object of the scene visible in the camera view (not through a
    totem), preferring the region, else one seen above the totems.

    ``ids`` is ``render.shape_ids(desc, totems=True)`` if the caller has it already
    (it is rendered otherwise); ``only``, if given, the object ids to choose among.
    Needs ``src.truth``.

    Returns (object dict, (H, W) bool of its directly seen pixels).
    """
    from scenes.synthetic import render  # Mitsuba: loaded only when a scene is re-rendered

    desc = src.truth.scene
    if ids is None:
        ids = render.shape_ids(desc, totems=True)
    want = src.region if src.region is not None else target_zone(src.totems)
    H, W = src.shape
    cands, weights = [], []
    for obj in desc["objects"]:
        if not obj.get("removable") or (only is not None and obj["id"] not in only):
            continue
        seen = ids == obj["id"]
        n_seen, n_want = int(seen.sum()), int((seen & want).sum())
        if n_seen >= max(20, 5e-4 * H * W) and n_want > 0:
            cands.append(obj)
            weights.append(n_want)
    if not cands:
        raise BadInput("no removable object of the scene "
                       + ("that a totem sees " if only is not None else "")
                       + "is visible "
                       + ("in the region" if src.region is not None else
                          "above the totems") + "; try another scene or region")
    if src.region is not None:
        obj = cands[int(np.argmax(weights))]
    else:   # a clearly visible one: at least a quarter the size of the largest
        big = [o for o, w in zip(cands, weights) if w >= 0.25 * max(weights)]
        obj = big[int(rng.integers(0, len(big)))]
    return obj, ids == obj["id"]
