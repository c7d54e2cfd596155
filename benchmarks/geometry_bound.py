"""How good can the camera view from the totem pixels be? The view splatted from the
totem rays at the TRUE depth, with the true totem centres, against the bench's recon.

    python benchmarks/geometry_bound.py SET BENCH_OUT

For each untouched scene of SET with ground truth, and its ``joint`` run in BENCH_OUT
(``totems bench``), prints the recon L1 of the run and of the true-depth splat, both
over the run's protected region (totem pixels excluded): the first minus the second is
what the fit's geometry costs; the second is what the totems' sampling allows with
this simple splat (:func:`inverse.view.splat.splat_image`, linear between the rays'
pixels). The third column is how bright the totem rays are against the truth where
they meet the surface the camera sees (mean sRGB of the rays over the truth's there,
the glass's reflection taken off as the fit starts):
above 1, the rays carry light the model does not take off, and any view splatted or
fitted from them is that much too bright. The fourth is the same splat of the truth's
own colours where the rays land: what the totems' sampling alone allows, were the
rays' colours exact.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def true_depth_view(scene, truth, desc) -> tuple[np.ndarray, float, np.ndarray]:
    """The camera view splatted from the totem rays (true centres) at the true depth,
    the rays' brightness against the truth where they meet that surface (ratio of
    mean sRGB over the rays that meet it inside the image), and the view splatted the
    same way from the truth's colours at the pixels those rays meet."""
    from inverse import sphere
    from inverse.grid import frame_for_scene
    from inverse.rays import totem_pixels
    from inverse.view.splat import _pixels, splat_image, surface_hits
    from scenes import backend
    from scenes.colour import linear_to_srgb, srgb_to_linear
    from scenes.synthetic.render import depth_map

    mi = backend.modules()[1]

    W, H = scene.size
    K = np.asarray(scene.K, np.float64)
    n = scene.masks.shape[0]
    P = np.asarray(truth.totem_pose, np.float64)
    radius = np.broadcast_to(np.asarray(scene.radius, np.float64), (n,))
    ior = np.broadcast_to(np.asarray(scene.ior, np.float64), (n,))
    pixels = totem_pixels(scene, K, 1)
    u, v, jt, d = pixels.u, pixels.v, pixels.totem, pixels.d_cam
    f32 = lambda a: mi.Float(np.asarray(a, np.float32))  # noqa: E731
    path = sphere.totem_path(mi.Point3f(0.0), mi.Vector3f(*[f32(d[:, i]) for i in range(3)]),
                             mi.Point3f(*[f32(P[jt, i]) for i in range(3)]),
                             f32(radius[jt]), f32(ior[jt]))
    o = np.asarray(path.E, np.float64).T.reshape(-1, 3)
    d_out = np.asarray(path.d_out, np.float64).T.reshape(-1, 3)
    T = np.asarray(path.T, np.float64).ravel()
    keep = np.asarray(path.valid, bool).ravel() & (T > 0.05)
    # Undo the glass: its front reflection (Fresnel R times the mean radiance, the fit's
    # starting ambient) and its transmittance.
    obs = srgb_to_linear(np.asarray(scene.image, np.float64)[v, u])
    refl = 1.0 - np.sqrt(np.clip(T, 0.0, 1.0))
    lin = np.clip(obs - refl[:, None] * obs[keep].mean(0), 0.0, None)
    lin = lin / np.maximum(T, 0.05)[:, None]
    frame = frame_for_scene(K, (W, H), P, radius)
    z = depth_map(desc)
    # The true depth on a map over the frame's range, about a cell per pixel.
    (u0, u1), (v0, v1) = frame.u_range, frame.v_range
    ns, nt = int(round(u1 - u0)), int(round(v1 - v0))
    cols = np.clip(np.round(u0 + (np.arange(ns) + 0.5) / ns * (u1 - u0)), 0, W - 1)
    rows = np.clip(np.round(v0 + (np.arange(nt) + 0.5) / nt * (v1 - v0)), 0, H - 1)
    depth = np.minimum(z[rows.astype(int)][:, cols.astype(int)], frame.far)
    uu, vv, _, hit = surface_hits(o[keep], d_out[keep], frame, depth)
    view = linear_to_srgb(np.clip(splat_image(uu, vv, lin[keep], (W, H), hit=hit), 0, 1))
    ui, vi, met = _pixels(uu, vv, hit, (W, H))
    rays = linear_to_srgb(np.clip(lin[keep][met], 0, None))
    there = np.asarray(truth.clean, np.float64)[vi[met], ui[met]]
    sampled = splat_image(uu[met], vv[met], srgb_to_linear(there), (W, H))
    sampled = linear_to_srgb(np.clip(sampled, 0, 1))
    return view, float(rays.mean() / max(there.mean(), 1e-9)), sampled


def main(argv=None) -> int:
    from scenes import folder

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("set", type=Path)
    p.add_argument("bench_out", type=Path)
    args = p.parse_args(argv)
    rows = []
    for sd in sorted(x for x in args.set.iterdir() if (x / "truth" / "scene.json").is_file()):
        run = args.bench_out / "runs" / f"{sd.name}-joint" / "verify"
        if (sd / "manip_mask.png").exists() or not (run / "recon.png").is_file():
            continue
        scene, truth = folder.read_scene(sd), folder.read_truth(sd)
        desc = json.loads((sd / "truth" / "scene.json").read_text())
        seen = folder.read_mask(run / "protect_mask.png") & ~scene.masks.any(0)
        clean = np.asarray(truth.clean, np.float64)
        fitted = np.abs(folder.read_image(run / "recon.png") - clean).mean(2)[seen].mean()
        view, bright, sampled = true_depth_view(scene, truth, desc)
        bound = np.abs(view - clean).mean(2)[seen].mean()
        exact = np.abs(sampled - clean).mean(2)[seen].mean()
        rows.append((sd.name, fitted, bound, bright, exact))
        print(f"{sd.name:12s} recon L1 {fitted:.3f}   true-depth splat {bound:.3f}   "
              f"ray brightness {bright:.2f}   exact colours {exact:.3f}", flush=True)
    for preset in sorted({r[0].rsplit("-", 1)[0] for r in rows}):
        sel = [r for r in rows if r[0].rsplit("-", 1)[0] == preset]
        print(f"{preset:12s} mean recon L1 {np.mean([r[1] for r in sel]):.3f}   "
              f"true-depth splat {np.mean([r[2] for r in sel]):.3f}   "
              f"ray brightness {np.mean([r[3] for r in sel]):.2f}   "
              f"exact colours {np.mean([r[4] for r in sel]):.3f}   (n={len(sel)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
