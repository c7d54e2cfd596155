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
- ``sgm``: the agreement cost aggregated by semi-global matching, then the best slice;
- ``plane`` (totems resting only): the support plane the totems touch
  (:func:`inverse.view.support.plane_from_centres`, from the fitted centres and the key's
  radius), where it lies in front of the camera;
- ``sgm+plane`` (totems resting only): ``sgm``, snapped to the plane where the two lie
  within ``--snap`` of each other (the floor or table at its plane, what stands on it
  or lies beyond its edge where stereo puts it);
- ``agree+plane`` (totems resting only): per cell of the map, the plane where the
  totems agree at its depth (within a slice, the evidence's AGREE) and at no slice more
  than one in front of it; ``sgm`` elsewhere;
- ``sgm-prior`` (totems resting only): semi-global matching of the cost less ``--prior``
  (in units of the median cost) at the plane's slice and its neighbours, then snapped
  to the plane where it chose those (a surface prior, not a rule on the result);
- ``prior+front`` (totems resting only): ``sgm-prior`` with the bonus only where no
  slice more than one in front of the plane's has the totems agreeing (``front``): a
  plane hidden behind a surface the totems agree on is not preferred.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

CANDIDATES = ("fit", "wta", "front", "sgm", "plane", "sgm+plane", "agree+plane", "sgm-prior", "prior+front")


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


def candidates(fit, scene, *, n_slices: int = 64, far: float | None = None,
               resting: bool = False, snap: float = 0.2, prior: float = 0.5) -> dict:
    """Each candidate's (H, W) depth map (NaN where it gives none), metres; the sweep
    over ``n_slices`` slices to ``far`` metres (default the fit's frame's); with
    ``resting``, the support plane's and SGM snapped to it within ``snap`` (relative)."""
    from inverse.grid import FrustumFrame, cell_centres, cells_to_pixels
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
    if resting:
        from inverse.view.support import plane_from_centres
        plane = plane_from_centres(fit.centers, scene.radius)
        if plane is not None:
            v, u = np.mgrid[0:H, 0:W]
            zp = plane.pixel_depth(scene.K, u, v)
            zp = np.where(np.isfinite(zp), zp, np.nan)
            out["plane"] = zp
            near = np.abs(out["sgm"] - zp) <= snap * zp
            out["sgm+plane"] = np.where(near, zp, out["sgm"])
            zc = plane.pixel_depth(scene.K, *cell_centres(frame, cost.shape[1:]))
            inv = 1.0 / z
            kp = np.argmin(np.abs(inv[:, None, None] - 1.0 / np.where(zc > 0, zc, np.inf)),
                           axis=0)
            at = np.zeros_like(agree[0])
            for dk in (-1, 0, 1):
                kk = np.clip(kp + dk, 0, len(z) - 1)
                at |= np.take_along_axis(agree, kk[None], 0)[0]
            front_ok = ~agree.any(axis=0) | (kf >= kp - 1)
            take = at & front_ok & np.isfinite(zc) & (zc > 0)
            take_px = cells_to_pixels(take.astype(float), frame, (W, H), nearest=True) > 0.5
            out["agree+plane"] = np.where(take_px & np.isfinite(zp), zp, out["sgm"])
            has_p = np.isfinite(zc) & (zc > 0)
            for name, where in (("sgm-prior", has_p), ("prior+front", has_p & front_ok)):
                cp = c.copy()
                for dk in (-1, 0, 1):
                    kk = np.clip(kp + dk, 0, len(z) - 1)
                    cur = np.take_along_axis(cp, kk[None], 0)[0]
                    np.put_along_axis(cp, kk[None], np.where(where, cur - prior, cur)[None], 0)
                agg_p = semi_global(cp - cp.min(), 0.3, 3.0)
                kq = np.argmin(agg_p, axis=0)
                on = has_p & (np.abs(kq - kp) <= 1)
                zq = np.where(ok.any(axis=0), _refine(agg_p, kq, z), np.nan)
                zq_px = cells_to_pixels(zq, frame, (W, H), nearest=True)
                on_px = cells_to_pixels(on.astype(float), frame, (W, H), nearest=True) > 0.5
                out[name] = np.where(on_px & np.isfinite(zp), zp, zq_px)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", type=Path)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--slices", type=int, default=64)
    p.add_argument("--far", type=float, default=None)
    p.add_argument("--snap", type=float, default=0.2,
                   help="sgm+plane: relative distance within which SGM snaps to the plane")
    p.add_argument("--prior", type=float, default=0.5,
                   help="sgm-prior: the plane's bonus, in median costs")
    p.add_argument("--only", default=None, help="comma-separated photo names")
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
        if args.only and run["name"] not in args.only.split(","):
            continue
        truth, scene = folder.read_truth(sd), folder.read_scene(sd)
        fit = load_fit(fit_dir)
        if truth is None or truth.reach is None or fit.rays is None:
            continue
        r = truth.reach
        at = r.in_reach() & ~r.backdrop & np.isfinite(r.depth)
        zt = r.depth.astype(np.float64)
        resting = run.get("placement") == "resting" or run["preset"] == "tabletop"
        for name, zc in candidates(fit, scene, n_slices=args.slices, far=args.far,
                                   resting=resting, snap=args.snap,
                                   prior=args.prior).items():
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
