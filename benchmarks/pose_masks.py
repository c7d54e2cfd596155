"""Totem poses from masks drawn the way people draw them: from the mask alone, from the
photo's rim (``inverse.pose.rim``) and from both weighed (``inverse.pose.combined``, the
default), against the truth.

    python benchmarks/pose_masks.py SCENE... [--families a,b] [--seed N] [--jpeg Q]

For each synthetic scene folder (with ``truth/totem_pose.npy``) and each mask family of
``scenes.photo.drawn_masks`` (also ``exact``: the rendered masks, and ``auto``: the masks
``totems masks`` proposes), prints the pose error as a percentage of the totem's
distance, median and worst, for the mask's own pose, the photo's rim and the two weighed
(each photo's totems pooled, as ``totems fit`` does), and how often the weighed pose's
reported uncertainty covers its true error (the true centre inside the 95 % ellipsoid
of its sd along the line of sight and across it).
``--jpeg Q``: the photo through a JPEG of quality Q first. Seconds per photo; no fit.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from inverse.pose import pose, combined, rim
from scenes import silhouette
from scenes import folder
from scenes.errors import BadInput
from scenes.photo import drawn_masks


def photo(scene, jpeg: int | None) -> np.ndarray:
    if jpeg is None:
        return np.asarray(scene.image, np.float32)
    from scenes import jpeg as jpeg_mod

    return jpeg_mod.decode(jpeg_mod.encode(scene.image, quality=jpeg)).astype(np.float32)


def errors(scene_dir: Path, families, rng, jpeg=None) -> dict:
    """{family: [(mask error %, rim error %, combined error %, covered 0/1, combined sd
    along the line of sight %) per totem]} for one scene folder."""
    scene, truth = folder.read_scene(scene_dir), folder.read_truth(scene_dir)
    K = np.asarray(scene.K, np.float64)
    img = photo(scene, jpeg)
    R = np.broadcast_to(np.asarray(scene.radius, np.float64), (scene.n_totems,))
    grad = silhouette.gradients(np.ascontiguousarray(img), rim.SIGMA_PX)
    out = {}
    for name in families:
        if name == "auto":
            from scenes.photo.detect_masks import propose_masks

            try:
                masks = propose_masks(img, n=scene.n_totems, K=K)
            except BadInput:
                out[name] = [(np.nan,) * 5] * scene.n_totems
                continue
        elif name == "exact":
            masks = np.asarray(scene.masks, bool)
        else:
            masks = np.stack([drawn_masks.family(name, m, rng) for m in scene.masks])
        evidence = []                  # the pose's own path: every totem, then pooled
        for j, m in enumerate(masks):
            try:
                pose.initial_pose(m[None], K, R[j])
                evidence.append(combined.totem_evidence(m, R[j], K, grad, j=j))
            except BadInput:
                evidence.append(None)
        weighed = combined.weigh_photo(evidence, R, K, grad)
        rows = []
        for j, (ev, c) in enumerate(zip(evidence, weighed)):
            if ev is None:
                rows.append((np.nan,) * 5)
                continue
            P_true = truth.totem_pose[j]
            dist = np.linalg.norm(P_true)
            rows.append((100 * np.linalg.norm(ev.mask_center - P_true) / dist,
                         100 * np.linalg.norm(ev.rim_center - P_true) / dist,
                         100 * np.linalg.norm(c.center - P_true) / dist,
                         covered(c, P_true),
                         100 * c.sd_along / dist))
        out[name] = rows
    return out


def covered(c, P_true) -> float:
    """1 when the true centre lies inside the 95 % ellipsoid of the combined pose's sd
    along the line of sight and across it (chi-square, 3 degrees of freedom), else 0."""
    e = P_true - c.center
    los = c.center / np.linalg.norm(c.center)
    along = e @ los
    across2 = e @ e - along ** 2
    chi2 = along ** 2 / max(c.sd_along, 1e-12) ** 2 \
        + across2 / max(c.sd_across, 1e-12) ** 2
    return float(chi2 <= 7.815)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--families",
                   default=",".join(["exact"] + list(drawn_masks.FAMILIES) + ["auto"]))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jpeg", type=int, default=None)
    p.add_argument("--rows", type=Path, default=None,
                   help="also write every totem's row as JSON {scene: {family: rows}}")
    args = p.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    fams = args.families.split(",")
    table = {f: [] for f in fams}
    t0 = time.perf_counter()
    per_scene = {}
    for s in args.scenes:
        per_scene[str(s)] = errors(s, fams, rng, args.jpeg)
        for f, rows in per_scene[str(s)].items():
            table[f] += rows
    if args.rows is not None:
        import json

        args.rows.write_text(json.dumps(per_scene, default=float))
    print("| masks | mask: median / worst (% of distance) | rim | weighed | covered | "
          "sd along: median | n |")
    print("|---|---|---|---|---|---|---|")

    def line(name, a):
        ok = np.isfinite(a).all(1)
        if not ok.any():
            return f"| {name} | refused | refused | refused | | | 0 of {len(a)} |"
        b = a[ok]
        cells = " | ".join(f"{np.median(b[:, k]):.2f} / {b[:, k].max():.2f}"
                           for k in range(3))
        return (f"| {name} | {cells} | {100 * b[:, 3].mean():.0f} % | "
                f"{np.median(b[:, 4]):.2f} | {ok.sum()} of {len(a)} |")

    arrays = [np.array(rows, float).reshape(-1, 5) for rows in table.values()]
    for f, a in zip(table, arrays):
        print(line(f, a))
    print(line("all", np.concatenate(arrays)))
    print(f"{time.perf_counter() - t0:.0f} s for {len(args.scenes)} photos")
    return 0


if __name__ == "__main__":
    sys.exit(main())
