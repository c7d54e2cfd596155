"""Totem poses from masks drawn the way people draw them: from the mask alone and from
the photo's edges (``inverse.rim``), against the truth.

    python benchmarks/pose_masks.py SCENE... [--families a,b] [--seed N] [--jpeg Q]

For each synthetic scene folder (with ``truth/totem_pose.npy``) and each mask family of
``scenes.drawn_masks`` (also ``exact``: the rendered masks, and ``auto``: the masks
``totems masks`` proposes), prints the pose error as a percentage of the totem's
distance, median and worst, for the mask's own pose and for the photo's. ``--jpeg Q``:
the photo through a JPEG of quality Q first. Seconds per photo; no fit.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from inverse import pose, rim
from scenes import drawn_masks, folder
from scenes.errors import BadInput


def photo(scene, jpeg: int | None) -> np.ndarray:
    if jpeg is None:
        return np.asarray(scene.image, np.float32)
    from scenes import jpeg as jpeg_mod

    return jpeg_mod.decode(jpeg_mod.encode(scene.image, quality=jpeg)).astype(np.float32)


def errors(scene_dir: Path, families, rng, jpeg=None) -> dict:
    """{family: [(mask error %, photo error %) per totem]} for one scene folder."""
    scene, truth = folder.read_scene(scene_dir), folder.read_truth(scene_dir)
    K = np.asarray(scene.K, np.float64)
    img = photo(scene, jpeg)
    R = np.broadcast_to(np.asarray(scene.radius, np.float64), (scene.n_totems,))
    out = {}
    for name in families:
        if name == "auto":
            from scenes.detect_masks import propose_masks

            try:
                masks = propose_masks(img, n=scene.n_totems, K=K)
            except BadInput:
                out[name] = [(np.nan, np.nan)] * scene.n_totems
                continue
        elif name == "exact":
            masks = np.asarray(scene.masks, bool)
        else:
            masks = np.stack([drawn_masks.family(name, m, rng) for m in scene.masks])
        rows = []
        for j, m in enumerate(masks):
            P_true = truth.totem_pose[j]
            dist = np.linalg.norm(P_true)
            try:
                P_mask = pose.initial_pose(m[None], K, R[j])[0]
            except BadInput:
                rows.append((np.nan, np.nan))
                continue
            P_photo = rim.refine_centres(img, P_mask[None], R[j:j + 1], K)[0]
            rows.append((100 * np.linalg.norm(P_mask - P_true) / dist,
                         100 * np.linalg.norm(P_photo - P_true) / dist))
        out[name] = rows
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--families",
                   default=",".join(["exact"] + list(drawn_masks.FAMILIES) + ["auto"]))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jpeg", type=int, default=None)
    args = p.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    fams = args.families.split(",")
    table = {f: [] for f in fams}
    t0 = time.perf_counter()
    for s in args.scenes:
        for f, rows in errors(s, fams, rng, args.jpeg).items():
            table[f] += rows
    print("| masks | from the mask: median / worst (% of distance) | from the photo | n |")
    print("|---|---|---|---|")
    both = []
    for f, rows in table.items():
        a = np.array(rows, float).reshape(-1, 2)
        ok = np.isfinite(a).all(1)
        both.append(a[ok])
        if not ok.any():
            print(f"| {f} | refused | refused | 0 of {len(a)} |")
            continue
        print(f"| {f} | {np.median(a[ok, 0]):.2f} / {a[ok, 0].max():.2f} | "
              f"{np.median(a[ok, 1]):.2f} / {a[ok, 1].max():.2f} | {ok.sum()} of {len(a)} |")
    a = np.concatenate(both)
    print(f"| all | {np.median(a[:, 0]):.2f} / {a[:, 0].max():.2f} | "
          f"{np.median(a[:, 1]):.2f} / {a[:, 1].max():.2f} | {len(a)} |")
    print(f"{time.perf_counter() - t0:.0f} s for {len(args.scenes)} photos")
    return 0


if __name__ == "__main__":
    sys.exit(main())
