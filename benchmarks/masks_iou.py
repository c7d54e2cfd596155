"""How well ``totems masks`` finds the totems: IoU of each proposed mask with the truth.

    python benchmarks/masks_iou.py SCENE... [--jpeg Q] [--hints] [--without-glass]

For each synthetic scene folder, the masks are proposed the way ``totems masks`` does
(``scenes.photo.detect_masks.find_totems`` with the camera's K and the key's IoR; as many as
the key lists, those whose score reaches ``MIN_KEYED``, or ``--n`` = the true count
when the key gives one radius for all), matched to the true masks (``totem_masks/``,
rendered) by the largest total IoU, and each true totem's IoU printed (0 when it was
not found). The summary gives, per preset (the folder name before the first '-'), per
channel (the name after '+', e.g. ``jpeg75``; else pristine) and over all, the share of
totems at IoU >= 0.95, and splits the others into found but imprecise (IoU >= 0.5: the
right totem, its outline off) and not found (below 0.5: no mask on it, or one on
something else). The photos are only read: nothing is written into their folders.
``--jpeg Q``: the photo through a JPEG of quality Q first (folders already holding a
JPEG are read as they are). ``--hints``: one click per totem as a person gives it
(``totems masks --hint X,Y``): the true mask's centroid moved by up to a third of its
radius in a random direction. ``--without-glass``: the detector before the glass test
(no IoR; a key's list gated by the ring score). Seconds per photo.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from scenes import folder
from scenes.photo import detect_masks

GOOD_IOU = 0.95
FOUND_IOU = 0.5     # a mask at least this close to a totem is on it, however imprecise


def classify(iou) -> dict:
    """Counts of totems by IoU: ``good`` (>= GOOD_IOU), ``imprecise`` (found,
    >= FOUND_IOU but below GOOD_IOU), ``missed`` (below FOUND_IOU), ``n``."""
    v = np.asarray(iou, float)
    good = int(np.sum(v >= GOOD_IOU))
    found = int(np.sum(v >= FOUND_IOU))
    return {"good": good, "imprecise": found - good, "missed": len(v) - found, "n": len(v)}


def summary_rows(by_group: dict) -> list[str]:
    """Markdown rows: group, totems, share at IoU >= GOOD_IOU, found but imprecise,
    not found, median and worst IoU; the last row over all groups."""
    groups = [(name, np.asarray(v, float)) for name, v in sorted(by_group.items())]
    groups.append(("all", np.concatenate([v for _, v in groups])))
    rows = []
    for name, v in groups:
        c = classify(v)
        rows.append(f"| {name} | {c['n']} | {c['good'] / c['n']:.0%} | {c['imprecise']} | "
                    f"{c['missed']} | {np.median(v):.3f} | {v.min():.3f} |")
    return rows


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


def scene_iou(scene_dir: Path, jpeg: int | None = None, rng=None, *,
              glass: bool = True) -> np.ndarray:
    """Each true totem's IoU with the mask ``totems masks`` would propose for it (with
    ``rng``: given one click per totem; ``glass`` False: without the key's IoR)."""
    scene = folder.read_scene(scene_dir)
    img = np.asarray(scene.image, np.float32)
    if jpeg is not None and scene.jpeg is None:
        from scenes import jpeg as jpeg_mod

        img = jpeg_mod.decode(jpeg_mod.encode(img, quality=jpeg)).astype(np.float32)
    listed = folder.expected_totems(scene_dir)
    told = None if listed is not None else scene.n_totems
    hints = None if rng is None else clicks(np.asarray(scene.masks, bool), rng)
    want = scene.n_totems if hints is not None else listed or told
    keyed = hints is None and listed is not None and glass   # only the key's list
    found = detect_masks.find_totems(                         # says how many
        img, n=want if glass else told, K=np.asarray(scene.K, float), hints=hints,
        ior=scene.ior if glass else None,
        min_score=detect_masks.MIN_KEYED if keyed else None)
    if len(found) > want:
        found = sorted(found, key=lambda t: -t[1])[:want]
    masks = detect_masks.ellipse_masks(found, img.shape[:2])
    return matched_iou(np.asarray(masks, bool), np.asarray(scene.masks, bool))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--jpeg", type=int, default=None)
    p.add_argument("--hints", action="store_true")
    p.add_argument("--without-glass", action="store_true")
    args = p.parse_args(argv)
    rng = np.random.default_rng(0) if args.hints else None
    by_preset, by_channel = defaultdict(list), defaultdict(list)
    t0 = time.perf_counter()
    seconds = []
    for s in args.scenes:
        t = time.perf_counter()
        iou = scene_iou(s, args.jpeg, rng, glass=not args.without_glass)
        seconds.append(time.perf_counter() - t)
        by_preset[s.name.split("-")[0]] += list(iou)
        channel = s.name.split("+")[1] if "+" in s.name else (
            f"jpeg{args.jpeg}" if args.jpeg else "pristine")
        by_channel[channel] += list(iou)
        print(f"{s.name}: " + " ".join(f"{v:.3f}" for v in iou)
              + f"  ({seconds[-1]:.1f} s)", flush=True)
    head = (f"| {{}} | totems | IoU >= {GOOD_IOU} | found, imprecise | not found | "
            f"median IoU | worst |")
    for what, groups in (("preset", by_preset), ("channel", by_channel)):
        print("\n" + head.format(what))
        print("|---|---|---|---|---|---|---|")
        print("\n".join(summary_rows(groups)))
    print(f"{time.perf_counter() - t0:.0f} s for {len(args.scenes)} photos "
          f"(median {np.median(seconds):.1f} s a photo)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
