"""What perfect geometry buys: each photo judged against what its totems saw at each pixel's
true surface (issue 60, the oracle).

    python benchmarks/surface_oracle.py CHECKED... [--out CSV]

For each checked synthetic scene folder (``totems check`` run, ``truth/scene.json`` and
``truth/reach.npz`` there): the fit's own totem rays are traced in the true scene
(:func:`scenes.synthetic.trace.tracer`), so each ends where it truly lands; each camera
pixel in the truth's reach takes the colours of the rays that land within their
footprint of its true surface point, per totem, and the photo is compared with their
mean there, judged against their spread (:func:`surface_residuals`). The statistic is the
worst patch of the verdict's grid. Prints, per kind of edit, the statistic's AUC against
the untouched photos and the share caught at a line set on the untouched photos; and per
photo a CSV row. With perfect geometry and this metric, what would be caught: the upper
bound a fit's geometry can approach.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

FIELDS = ("name", "kind", "preset", "placement", "reach_fraction", "manip_in_reach",
          "stat_abs", "stat_z", "stat_view")


def surface_colours(X, Y, totem, colour, footprint, n_totems):
    """Per camera pixel surface point ``X`` (k, 3), each totem's mean colour of the rays
    landing within their footprint of it: (n_totems, k, 3) and counts (n_totems, k).
    ``Y`` (m, 3) landing points, ``totem`` (m,), ``colour`` (m, 3), ``footprint`` (m,)
    metres."""
    k = len(X)
    mean = np.zeros((n_totems, k, 3))
    count = np.zeros((n_totems, k))
    for j in range(n_totems):
        mine = np.flatnonzero(totem == j)
        if len(mine) < 2:
            continue
        tree = cKDTree(Y[mine])
        dist, idx = tree.query(X, k=8, distance_upper_bound=float(footprint[mine].max()))
        ok = np.isfinite(dist)
        idx_c = np.where(ok, idx, 0)
        ok &= dist <= footprint[mine][idx_c]
        w = ok.astype(np.float64)
        count[j] = w.sum(1)
        mean[j] = (w[..., None] * colour[mine][idx_c]).sum(1) / np.maximum(count[j], 1)[:, None]
    return mean, count


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    from scenes import backend, camera, folder
    from scenes.colour import linear_to_srgb
    from scenes.reach import COS_EVIDENCE
    from scenes.synthetic.trace import tracer
    from inverse.fit.files import load_fit
    from verify.metrics import resolution, patches
    from verify.verdict.verdict import judging_grid

    backend.use()
    rows = []
    for sd in args.scenes:
        truth = folder.read_truth(sd)
        scene = folder.read_scene(sd)
        rep = json.loads((sd / "totems-out/verify/report.json").read_text())
        fit = load_fit(sd / "totems-out/fit") if (sd / "totems-out/fit").is_dir() else None
        if truth is None or truth.reach is None or fit is None or fit.rays is None:
            print(f"skip {sd.name}", file=sys.stderr)
            continue
        desc = truth.scene
        trace = tracer(desc)
        rays = fit.rays.entering_at_least(COS_EVIDENCE)
        Y, N, ids = trace(rays.o + 1e-5 * rays.d, rays.d)
        landed = np.isfinite(Y).all(1) & (ids > -1000)
        H, W = scene.image.shape[:2]
        v, u = np.mgrid[0:H, 0:W]
        view = camera.pixel_rays(scene.K, u, v)
        z = truth.reach.depth.astype(np.float64)
        X = view * (z / view[..., 2])[..., None]
        inside = truth.reach.in_reach() & ~truth.reach.backdrop & np.isfinite(z)
        n = len(fit.centers)
        from scenes.reach import _local_spacing
        loc = _local_spacing(rays.d, rays.totem, n)
        t = np.linalg.norm(Y - rays.o, axis=1)
        cos = np.abs((N * rays.d).sum(1))
        foot = t * loc / np.maximum(np.nan_to_num(cos), 0.2)
        sel = landed & np.isfinite(foot)
        srgb = linear_to_srgb(np.clip(rays.radiance, 0, 1))
        mean, count = surface_colours(X[inside], Y[sel], rays.totem[sel], srgb[sel],
                                      foot[sel], n)
        seen = count > 0
        nseen = seen.sum(0)
        pred = (mean * seen[..., None]).sum(0) / np.maximum(nseen, 1)[:, None]
        spread = np.sqrt(((mean - pred[None]) ** 2 * seen[..., None]).sum(0).mean(1)
                         / np.maximum(nseen - 1, 1))
        spacing = resolution.ray_spacing(fit.totem_points, scene.K, (W, H))
        blurred = patches.blur_varying(np.asarray(scene.image, np.float64),
                                       resolution.photo_sigma(spacing))
        photo = blurred[inside]
        ok = nseen >= 2
        # exposure: per channel median ratio in linear light over the pixels judged
        from scenes.colour import srgb_to_linear
        pl, rl = srgb_to_linear(photo[ok]), srgb_to_linear(pred[ok])
        g = np.exp(np.median(np.log(np.maximum(pl, 1e-3) / np.maximum(rl, 1e-3)), axis=0))
        g = np.clip(g, 0.5, 2.0)
        pred_g = linear_to_srgb(np.clip(srgb_to_linear(pred) * g, 0, 1))
        e = np.abs(photo - pred_g).mean(1)
        ez = e / (spread + 0.03)
        E = np.full((H, W), np.nan)
        EZ = np.full((H, W), np.nan)
        idx = np.flatnonzero(inside.ravel())[ok]
        E.ravel()[idx] = e[ok]
        EZ.ravel()[idx] = ez[ok]
        grid = judging_grid((H, W))
        judged = np.isfinite(E)
        stats = {}
        for name, m in (("stat_abs", E), ("stat_z", EZ)):
            sc = patches.patch_scores({name: np.nan_to_num(m)}, grid, judged)[name]
            cov = patches.patch_fraction(judged, grid)
            vals = np.asarray(sc, float)[np.asarray(cov) >= 0.5]
            stats[name] = float(np.nanmax(vals)) if np.isfinite(vals).any() else np.nan
        # the perfect view (truth's clean image) against the photo, same pixels
        clean = np.asarray(truth.clean, np.float64)
        ev = np.abs(patches.blur_varying(clean, resolution.photo_sigma(spacing)) - blurred).mean(2)
        ev = np.where(judged, ev, 0.0)
        sc = patches.patch_scores({"v": ev}, grid, judged)["v"]
        cov = patches.patch_fraction(judged, grid)
        vals = np.asarray(sc, float)[np.asarray(cov) >= 0.5]
        stats["stat_view"] = float(np.nanmax(vals)) if np.isfinite(vals).any() else np.nan
        kind = "none"
        tj = sd / "truth" / "tamper.json"
        if tj.is_file():
            kind = json.loads(tj.read_text())["kind"]
        m = rep["metrics"]
        row = {"name": sd.name, "kind": kind, "preset": desc.get("preset"),
               "placement": desc.get("placement", ""), "reach_fraction": m.get("reach_fraction"),
               "manip_in_reach": m.get("manip_in_reach"), **stats}
        rows.append(row)
        print(" ".join(f"{k}={v}" if not isinstance(v, float) else f"{k}={v:.3f}"
                       for k, v in row.items()), flush=True)
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
