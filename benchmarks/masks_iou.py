"""How well ``totems masks`` finds the totems: IoU of each proposed mask with the truth.

    python benchmarks/masks_iou.py SCENE... [--jpeg Q] [--hints]

For each synthetic scene folder, the masks are proposed the way ``totems masks`` does
(``scenes.detect_masks.find_totems`` with the camera's K; as many as the key lists,
or ``--n`` = the true count when the key gives one radius for all), matched to the true
masks (``totem_masks/``, rendered) by the largest total IoU, and each true totem's IoU
printed (0 when it was not found). The summary gives the share of totems at IoU >= 0.95
per preset (the folder name before the first '-') and over all. ``--jpeg Q``: the photo
through a JPEG of quality Q first (folders already holding a JPEG are read as they are).
``--hints``: one click per totem as a person gives it (``totems masks --hint X,Y``): the
true mask's centroid moved by up to a third of its radius in a random direction.
Seconds per photo.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from scenes import detect_masks, folder

GOOD_IOU = 0.95


def iou_matrix(found: np.ndarray, true: np.ndarray) -> np.ndarray:
    """(k, n) IoU of every found mask with every true mask (bool (k, H, W), (n, H, W))."""
    f = found.reshape(len(found), -1).astype(np.float64)
    t = true.reshape(len(true), -1).astype(np.float64)
    inter = f @ t.T
    union = f.sum(1)[:, None] + t.sum(1)[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1), 0.0)


def matched_iou(found: np.ndarray, true: np.ndarray) -> np.ndarray:
    """(n,) each true mask's IoU with the found mask matched to it (0 if none)."""
    out = np.zeros(len(true))
    if len(found) == 0:
        return out
    m = iou_matrix(found, true)
    rows, cols = linear_sum_assignment(-m)
    out[cols] = m[rows, cols]
    return out


def clicks(masks: np.ndarray, rng) -> np.ndarray:
    """(n, 2) a point inside each mask as a person clicks it: the centroid moved by up to
    a third of the mask's radius."""
    out = []
    for m in masks:
        v, u = np.nonzero(m)
        r = np.sqrt(m.sum() / np.pi) * rng.uniform(0, 1 / 3)
        a = rng.uniform(0, 2 * np.pi)
        out.append((u.mean() + r * np.cos(a), v.mean() + r * np.sin(a)))
    return np.array(out)


def scene_iou(scene_dir: Path, jpeg: int | None = None, rng=None) -> np.ndarray:
    """Each true totem's IoU with the mask ``totems masks`` would propose for it (with
    ``rng``: given one click per totem)."""
    scene = folder.read_scene(scene_dir)
    img = np.asarray(scene.image, np.float32)
    if jpeg is not None and scene.jpeg is None:
        from scenes import jpeg as jpeg_mod

        img = jpeg_mod.decode(jpeg_mod.encode(img, quality=jpeg)).astype(np.float32)
    listed = detect_masks.expected_totems(scene_dir)
    told = None if listed is not None else scene.n_totems
    hints = None if rng is None else clicks(np.asarray(scene.masks, bool), rng)
    found = detect_masks.find_totems(img, n=told, K=np.asarray(scene.K, float), hints=hints)
    want = scene.n_totems if hints is not None else listed or told
    if len(found) > want:
        found = sorted(found, key=lambda t: -t[1])[:want]
    masks = detect_masks.ellipse_masks(found, img.shape[:2])
    return matched_iou(np.asarray(masks, bool), np.asarray(scene.masks, bool))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--jpeg", type=int, default=None)
    p.add_argument("--hints", action="store_true")
    args = p.parse_args(argv)
    rng = np.random.default_rng(0) if args.hints else None
    by_preset = defaultdict(list)
    t0 = time.perf_counter()
    for s in args.scenes:
        iou = scene_iou(s, args.jpeg, rng)
        by_preset[s.name.split("-")[0]] += list(iou)
        print(f"{s.name}: " + " ".join(f"{v:.3f}" for v in iou), flush=True)
    print(f"\n| preset | totems | IoU >= {GOOD_IOU} | median IoU | worst |")
    print("|---|---|---|---|---|")
    every = []
    for name, v in sorted(by_preset.items()):
        v = np.array(v)
        every.append(v)
        print(f"| {name} | {len(v)} | {np.mean(v >= GOOD_IOU):.0%} | {np.median(v):.3f} | "
              f"{v.min():.3f} |")
    v = np.concatenate(every)
    print(f"| all | {len(v)} | {np.mean(v >= GOOD_IOU):.0%} | {np.median(v):.3f} | "
          f"{v.min():.3f} |")
    print(f"{time.perf_counter() - t0:.0f} s for {len(args.scenes)} photos")
    return 0


if __name__ == "__main__":
    sys.exit(main())
