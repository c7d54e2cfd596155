"""The photo against what its totems see at each surface's depth, from several depth maps
(issue 60, items 2 and 3): what the geometry buys the verdict.

    python benchmarks/surface_study.py BENCH [--out CSV] [--slices N] [--far M]

For each photo of a bench (``totems bench``; its scene's ``truth/reach.npz``), the
fit's totem rays are swept (:func:`verify.metrics.corroborate.ray_slices`, ``N`` slices to
``M`` metres) and read at one depth per cell of the map: the truth's (the cell's median
true depth: the oracle), semi-global matching's on the totems' colour agreement, or the
fit's view depth. There each totem that lands gives a colour; the photo is compared
with their mean, ``e`` (sRGB, mean over channels), and with their spread, ``z = e / (s +
S0)``, on the cells where two totems land with a parallax of MIN_PARALLAX. The
statistic is the worst patch of the verdict's grid (patches at least half judged).
Prints one line a photo and, per depth source and residual, the AUC of each kind of edit
against the untouched photos.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

S0 = 0.02
SOURCES = ("truth", "sgm", "fit")


def cell_depth(depth_px, frame, res):
    """(nt, ns) the median of a (H, W) depth map over each map cell (NaN where none)."""
    from inverse.grid import FrustumFrame  # noqa: F401
    H, W = depth_px.shape
    nt, ns = res
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
    col = np.clip((np.asarray(s) * ns).astype(int), 0, ns - 1)
    row = np.clip((np.asarray(t) * nt).astype(int), 0, nt - 1)
    cell = row * ns + col
    z = depth_px.ravel()
    ok = np.isfinite(z)
    out = np.full(nt * ns, np.nan)
    order = np.argsort(cell[ok], kind="stable")
    cs, zs = cell[ok][order], z[ok][order]
    starts = np.r_[0, np.flatnonzero(np.diff(cs)) + 1]
    for a, b in zip(starts, np.r_[starts[1:], len(cs)]):
        out[cs[a]] = np.median(zs[a:b])
    return out.reshape(nt, ns)


def at_depth(sc, par, z_cells):
    """Each totem's colour at each cell's depth ``z_cells`` (nt, ns): the slice nearest in
    inverse depth. Returns colours (n, nt, ns, 3), landing (n, nt, ns) bool and the
    parallax there (nt, ns)."""
    inv = 1.0 / np.asarray(sc.z, np.float64)
    zc = np.where(np.isfinite(z_cells), z_cells, sc.z[-1])
    k = np.abs(inv[:, None, None] - 1.0 / zc[None]).argmin(axis=0)          # (nt, ns)
    col = np.take_along_axis(sc.colour, k[None, None, ..., None], 1)[:, 0]
    land = np.take_along_axis(sc.land, k[None, None], 1)[:, 0] & np.isfinite(z_cells)[None]
    p = np.take_along_axis(par, k[None], 0)[0]
    return col, land, p


def sgm_depth(sc, par, min_parallax):
    from inverse.view.sweep import semi_global
    n_land, _, var = sc.consistency
    ok = (n_land >= 2) & (par >= min_parallax)
    fill = float(np.median(var[ok])) if ok.any() else 1.0
    c = np.where(ok, var, fill) / max(fill, 1e-12)
    k = np.argmin(semi_global(c, 0.3, 3.0), axis=0)
    return np.where(ok.any(axis=0), np.asarray(sc.z)[k], np.nan)


def study(sd: Path, fit_dir: Path, n_slices: int, far: float) -> dict:
    from inverse.fit.files import load_fit
    from inverse.grid import FrustumFrame, cells_to_pixels
    from scenes import folder
    from scenes.colour import linear_to_srgb, srgb_to_linear
    from scenes.reach import MIN_PARALLAX
    from verify.metrics import corroborate, evidence, patches, resolution
    from verify.verdict.verdict import judging_grid

    truth, scene = folder.read_truth(sd), folder.read_scene(sd)
    fit = load_fit(fit_dir)
    H, W = scene.image.shape[:2]
    frame = FrustumFrame.from_dict(fit.grid)
    frame = dataclasses.replace(frame, far=min(frame.far, far))
    rays = fit.rays.entering_at_least(corroborate.COS_EVIDENCE)
    sc = corroborate.ray_slices(fit.rays, frame, n_slices=n_slices)
    res = sc.land.shape[2:]
    spacing = evidence.angular_spacing(rays.d, rays.totem, len(fit.centers))
    par = evidence.slice_parallax(sc, frame, fit.centers, spacing)
    spx = resolution.ray_spacing(fit.totem_points, scene.K, (W, H))
    blurred = patches.blur_varying(np.asarray(scene.image, np.float64),
                                   resolution.photo_sigma(spx))
    uu, vv = corroborate.cell_centres(frame, res)
    photo = corroborate._sample(blurred.astype(np.float32), uu, vv).astype(np.float64)
    depths = {"truth": cell_depth(np.where(truth.reach.backdrop, np.nan,
                                           truth.reach.depth.astype(np.float64)), frame, res),
              "sgm": sgm_depth(sc, par, MIN_PARALLAX),
              "fit": cell_depth(np.asarray(fit.recon_depth, np.float64), frame, res)}
    grid = judging_grid((H, W))
    totem_px = scene.masks.any(axis=0)
    out = {}
    for name, zc in depths.items():
        col, land, p = at_depth(sc, par, zc)
        n = land.sum(0)
        judged = (n >= 2) & (p >= MIN_PARALLAX)
        mu = (col * land[..., None]).sum(0) / np.maximum(n, 1)[..., None]
        spread = np.sqrt(((col - mu[None]) ** 2 * land[..., None]).sum(0).mean(-1)
                         / np.maximum(n - 1, 1))
        # exposure: per channel median ratio in linear light over the judged cells
        if judged.sum() > 50:
            ratio = srgb_to_linear(np.clip(photo[judged], 1e-3, 1)) / \
                np.maximum(srgb_to_linear(np.clip(mu[judged], 1e-3, 1)), 1e-4)
            g = np.clip(np.exp(np.median(np.log(np.maximum(ratio, 1e-4)), axis=0)), 0.5, 2)
        else:
            g = np.ones(3)
        mu_g = linear_to_srgb(np.clip(srgb_to_linear(np.clip(mu, 0, 1)) * g, 0, 1))
        e = np.abs(photo - mu_g).mean(-1)
        z = e / (spread + S0)
        for kind, m in (("e", e), ("z", z)):
            cells = np.where(judged, m, np.nan)
            px = cells_to_pixels(cells, frame, (W, H), nearest=True)
            px = np.where(totem_px, np.nan, px)
            ok = np.isfinite(px)
            sc_p = patches.patch_means(np.nan_to_num(px), grid, ok)
            cov = patches.patch_fraction(ok, grid)
            vals = sc_p[cov >= 0.5]
            out[f"{name}_{kind}"] = float(np.nanmax(vals)) if np.isfinite(vals).any() \
                else np.nan
        zt = depths["truth"]
        both = np.isfinite(zt) & np.isfinite(zc)
        out[f"{name}_deperr"] = float(np.median(np.abs(zc[both] - zt[both]) / zt[both])) \
            if both.any() else np.nan
        out[f"{name}_judged"] = float(judged.mean())
    return out


def auc(neg, pos) -> float:
    neg, pos = np.asarray(neg, float), np.asarray(pos, float)
    neg, pos = neg[np.isfinite(neg)], pos[np.isfinite(pos)]
    if not len(neg) or not len(pos):
        return np.nan
    return float(((pos[:, None] > neg[None]) + 0.5 * (pos[:, None] == neg[None])).mean())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", type=Path)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--slices", type=int, default=128)
    p.add_argument("--far", type=float, default=100.0)
    args = p.parse_args(argv)
    rows = []
    runs = json.loads((args.bench / "bench.json").read_text())["runs"]
    for run in runs:
        if run.get("mode") != "joint" or run.get("status") != "ok":
            continue
        sd = Path(run["scene"])
        fit_dir = args.bench / "runs" / f"{run.get('fit_from') or run['name']}-joint" / "fit"
        if not fit_dir.is_dir() or not (sd / "truth" / "reach.npz").is_file():
            continue
        tj = sd / "truth" / "tamper.json"
        kind = json.loads(tj.read_text())["kind"] if tj.is_file() else "none"
        row = {"name": sd.name, "kind": kind, "preset": run.get("preset"),
               **study(sd, fit_dir, args.slices, args.far)}
        rows.append(row)
        print(" ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in row.items()), flush=True)
    keys = [k for k in rows[0] if k.endswith(("_e", "_z"))]
    neg = defaultdict(list)
    for r in rows:
        if r["kind"] == "none":
            for k in keys:
                neg[k].append(r[k])
    print("\nAUC against the untouched photos")
    for kind in sorted({r["kind"] for r in rows} - {"none"}):
        pos = [r for r in rows if r["kind"] == kind]
        print(f"{kind:10s} ({len(pos)}) " + "  ".join(
            f"{k} {auc(neg[k], [r[k] for r in pos]):.2f}" for k in keys))
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
