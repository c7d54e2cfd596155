"""How near the totems put each surface: candidate depth maps against the true depth
(issue 60, item 2).

    python benchmarks/depth_study.py BENCH [--out CSV] [--slices N] [--far M]

For each untouched photo of a bench (``totems bench``; its scene's ``truth/reach.npz``),
every candidate depth map is read at the pixels in the truth's reach (the
backdrop left out) and its median relative error ``|z - z_true| / z_true`` printed, with
the share of those pixels it gives a depth at all, and the share within 5 %:

- ``fit``: the fit's own view depth (``recon_depth``);
- ``wta``: per cell of the evidence map's grid, the slice where the landing totems'
  colours agree best (at least two, parallax at least MIN_PARALLAX);
- ``front``: the nearest slice where they agree within AGREE (the evidence map's test);
- ``sgm``: the agreement cost aggregated by semi-global matching, then the best slice.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

CANDIDATES = ("fit", "wta", "front", "sgm")


def _refine(cost, k, z):
    """The depth at the parabola's vertex through the cost at slices k-1, k, k+1 (in
    inverse depth), per cell; ``z`` (nk,) the slices' depths."""
    nk = len(z)
    km, kp = np.clip(k - 1, 0, nk - 1), np.clip(k + 1, 0, nk - 1)
    c0 = np.take_along_axis(cost, k[None], 0)[0]
    cm = np.take_along_axis(cost, km[None], 0)[0]
    cp = np.take_along_axis(cost, kp[None], 0)[0]
    den = cm - 2 * c0 + cp
    ok = np.isfinite(den) & (den > 1e-12) & (k > 0) & (k < nk - 1)
    off = np.where(ok, 0.5 * (cm - cp) / np.where(ok, den, 1.0), 0.0)
    inv = 1.0 / z
    step = np.gradient(inv)
    return 1.0 / (inv[k] + np.clip(off, -0.5, 0.5) * step[k])


def candidates(fit, scene, *, n_slices: int = 64, far: float | None = None) -> dict:
    """Each candidate's (H, W) depth map (NaN where it gives none), metres; the sweep
    over ``n_slices`` slices to ``far`` metres (default the fit's frame's)."""
    from inverse.grid import FrustumFrame, cells_to_pixels
    from inverse.view.sweep import semi_global
    from scenes.reach import MIN_PARALLAX
    from verify.metrics import corroborate, evidence

    H, W = scene.image.shape[:2]
    import dataclasses

    frame = FrustumFrame.from_dict(fit.grid)
    if far is not None:
        frame = dataclasses.replace(frame, far=min(frame.far, far))
    rays = fit.rays.entering_at_least(corroborate.COS_EVIDENCE)
    sc = corroborate.ray_slices(fit.rays, frame, n_slices=n_slices)
    spacing = evidence.angular_spacing(rays.d, rays.totem, len(fit.centers))
    par = evidence.slice_parallax(sc, frame, fit.centers, spacing)
    n_land, _, var = sc.consistency
    ok = (n_land >= 2) & (par >= MIN_PARALLAX)
    z = np.asarray(sc.z, np.float64)
    cost = np.where(ok, var, np.inf)
    out = {"fit": np.asarray(fit.recon_depth, np.float64)}
    k = np.argmin(cost, axis=0)
    has = np.isfinite(cost.min(axis=0))
    out["wta"] = np.where(has, _refine(cost, k, z), np.nan)
    agree = ok & (var <= 3.0 * evidence.AGREE ** 2)
    kf = np.argmax(agree, axis=0)
    out["front"] = np.where(agree.any(axis=0), z[kf], np.nan)
    fill = float(np.median(var[ok])) if ok.any() else 1.0
    c = np.where(ok, var, fill) / max(fill, 1e-12)
    agg = semi_global(c, 0.3, 3.0)
    ks = np.argmin(agg, axis=0)
    out["sgm"] = np.where(ok.any(axis=0), _refine(agg, ks, z), np.nan)
    for name in ("wta", "front", "sgm"):
        out[name] = cells_to_pixels(out[name], frame, (W, H), nearest=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", type=Path)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--slices", type=int, default=64)
    p.add_argument("--far", type=float, default=None)
    args = p.parse_args(argv)
    from inverse.fit.files import load_fit
    from scenes import folder

    import json

    rows = []
    for run in json.loads((args.bench / "bench.json").read_text())["runs"]:
        sd = Path(run["scene"])
        fit_dir = args.bench / "runs" / f"{run['name']}-joint" / "fit"
        if run.get("mode") != "joint" or run.get("kind") != "none" or not fit_dir.is_dir():
            continue
        truth, scene = folder.read_truth(sd), folder.read_scene(sd)
        fit = load_fit(fit_dir)
        if truth is None or truth.reach is None or fit.rays is None:
            continue
        r = truth.reach
        at = r.in_reach() & ~r.backdrop & np.isfinite(r.depth)
        zt = r.depth.astype(np.float64)
        for name, zc in candidates(fit, scene, n_slices=args.slices, far=args.far).items():
            given = at & np.isfinite(zc)
            err = np.abs(zc[given] - zt[given]) / zt[given]
            row = {"name": sd.name, "preset": run["preset"],
                   "placement": run.get("placement"), "candidate": name, "given": given.sum() / max(at.sum(), 1),
                   "median_rel_err": float(np.median(err)) if err.size else np.nan,
                   "within_5pc": float((err <= 0.05).mean()) if err.size else np.nan}
            rows.append(row)
            print(f"{sd.name:22s} {name:6s} given {row['given']:.2f}  median "
                  f"{row['median_rel_err']:.3f}  within 5 % {row['within_5pc']:.2f}", flush=True)
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
