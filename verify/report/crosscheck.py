"""Our fit beside a NeRF-path run of the same scene (``totems crosscheck``).

Reads the NeRF path's experiment folder (``jingweim/totems`` run.py) as it writes it::

    LOGDIR/loss.txt                       "[TRAIN] Iter: i Totem{j+1}: [x y z]" lines
                                          (joint-pose runs; metres, OpenCV camera frame)
    LOGDIR/args.txt                       "name = value" lines (totem_radius, ior_totem)
    LOGDIR/render_<step>/camera_view.png  its re-rendered camera view, at 1/4 resolution
    LOGDIR/detect_<step>/intermediate/protect_mask/protect_mask.png   (1/4 res., whole)
    LOGDIR/detect_<step>/intermediate/protect_mask.png                (cropped to roi)
    LOGDIR/detect_<step>/results/L1/heatmap.npy                       (30, 30)

and compares: totem centres (metres), the two reconstructions where both protect, and
the two heatmaps (Pearson correlation, overlap of their top-10% cells).
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

__all__ = ["TOTEM_LINE", "TOP_FRACTION", "NerfRun", "parse_loss_txt", "read_nerf_log",
           "heatmap_agreement", "crosscheck", "write_crosscheck"]

TOTEM_LINE = re.compile(r"\[TRAIN\] Iter:\s*(\d+)\s+Totem(\d+):\s*\[([^\]]*)\]")
TOP_FRACTION = 0.10


@dataclass
class NerfRun:
    """What a NeRF-path run left in its log folder (None where it did not write it)."""

    path: Path
    camera_view: np.ndarray | None         # (h, w, 3) sRGB [0, 1]
    protect: np.ndarray | None             # (h', w') bool
    protect_cropped: bool                  # True: the roi-cropped detect file
    heatmap: np.ndarray | None             # (30, 30) patch L1
    centers: np.ndarray | None             # (n, 3) last learned centres, metres
    centers_iter: int | None
    args: dict = field(default_factory=dict)


def _latest(logdir: Path, prefix: str, rel: str) -> Path | None:
    """LOGDIR/<prefix>_<step>/<rel> of the largest step that has it."""
    found = sorted((p for p in logdir.glob(f"{prefix}_*") if (p / rel).is_file()),
                   key=lambda p: int(re.sub(r"\D", "", p.name) or 0))
    return found[-1] / rel if found else None


def parse_loss_txt(text: str) -> tuple[np.ndarray | None, int | None]:
    """Last reported learned totem centres in a NeRF-path ``loss.txt``: ((n, 3), iter)."""
    last: dict[int, dict[int, np.ndarray]] = {}
    for it, j, vec in TOTEM_LINE.findall(text):
        v = np.array(vec.replace(",", " ").split(), dtype=float)
        if v.shape == (3,):
            last.setdefault(int(it), {})[int(j) - 1] = v
    n = max((len(g) for g in last.values()), default=0)
    for it in sorted(last, reverse=True):         # the last report that names every totem
        got = last[it]
        if sorted(got) == list(range(n)):
            return np.stack([got[j] for j in range(len(got))]), it
    return None, None


def read_nerf_log(logdir) -> NerfRun:
    """Read a NeRF-path experiment folder (see the module docstring)."""
    logdir = Path(logdir)
    if not logdir.is_dir():
        raise BadInput(f"NeRF-path log folder not found: {logdir}")
    cam = _latest(logdir, "render", "camera_view.png")
    whole = _latest(logdir, "detect", "intermediate/protect_mask/protect_mask.png")
    cropped = _latest(logdir, "detect", "intermediate/protect_mask.png")
    heat = _latest(logdir, "detect", "results/L1/heatmap.npy")
    centers, it = None, None
    if (logdir / "loss.txt").is_file():
        centers, it = parse_loss_txt((logdir / "loss.txt").read_text(errors="replace"))
    args = {}
    if (logdir / "args.txt").is_file():
        for line in (logdir / "args.txt").read_text(errors="replace").splitlines():
            if " = " in line:
                k, v = line.split(" = ", 1)
                args[k.strip()] = v.strip()
    if cam is None and heat is None and centers is None:
        raise BadInput(f"{logdir} has no render_*/camera_view.png, detect_*/results/L1/"
                       f"heatmap.npy or totem lines in loss.txt: not a NeRF-path run")
    heatmap = None
    if heat is not None:
        heatmap = np.asarray(folder.safe_load_npy(heat), float)
        if heatmap.ndim != 2:
            raise BadInput(f"{heat} is not a 2-D heatmap")
    protect_path = whole or cropped
    return NerfRun(logdir,
                   folder.read_image(cam, what="NeRF camera view") if cam else None,
                   folder.read_mask(protect_path, what="NeRF protect mask")
                   if protect_path else None,
                   protect_path is not None and whole is None, heatmap, centers, it, args)


def _resize(a: np.ndarray, size: tuple[int, int], nearest: bool = False) -> np.ndarray:
    import cv2

    if a.shape[1] == size[0] and a.shape[0] == size[1]:
        return a
    if a.dtype == bool:
        return cv2.resize(a.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    return cv2.resize(a.astype(np.float32), size,
                      interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)


def _roi(scene) -> list[int] | None:
    try:
        roi = folder.read_calib(folder.find_calib(scene.path)).get("roi")
    except BadInput:
        return None
    return None if roi is None else [int(v) for v in np.ravel(roi)[:4]]


def heatmap_agreement(a: np.ndarray, b: np.ndarray, top: float = TOP_FRACTION) -> dict:
    """Pearson r of two heatmaps, and IoU of their top-``top`` cells (and where only
    one of them ranks a cell in its top: [row, col] lists)."""
    if a.shape != b.shape:
        raise BadInput(f"heatmaps differ in shape: {a.shape} vs {b.shape}")
    ok = np.isfinite(a) & np.isfinite(b)
    x, y = a[ok], b[ok]
    r = float(np.corrcoef(x, y)[0, 1]) if x.std() > 0 and y.std() > 0 else None
    k = max(1, int(round(top * ok.sum())))
    ta = np.zeros(a.shape, bool)
    tb = np.zeros(a.shape, bool)
    idx = np.flatnonzero(ok)
    ta.flat[idx[np.argsort(-x, kind="stable")[:k]]] = True
    tb.flat[idx[np.argsort(-y, kind="stable")[:k]]] = True
    return {"pearson": r, "top_iou": float((ta & tb).sum() / (ta | tb).sum()),
            "top_cells": k, "only_ours": np.argwhere(ta & ~tb).tolist(),
            "only_nerf": np.argwhere(tb & ~ta).tolist()}


def crosscheck(scene, ours, our_heatmap, our_protect, nerf: NerfRun) -> dict:
    """Compare our fit with a NeRF-path run of the same scene.

    Parameters
    ----------
    scene : scenes.folder.Scene the two runs fitted.
    ours : FitResult-like with ``centers`` (n, 3) metres and ``recon`` (H, W, 3) sRGB.
    our_heatmap : (30, 30) our patch-L1 heatmap (NeRF-path format) or None.
    our_protect : (H, W) bool our protected region, or None.
    nerf : :func:`read_nerf_log` of its run.

    Returns a JSON-ready dict (plus ``"_images"`` for :func:`write_crosscheck`):
    ``totems`` per totem centre difference (m), ``recon`` mean L1 between the two
    reconstructions where both protect (and each against the photo), ``heatmap``
    agreement, and ``notes`` about what could not be compared.
    """
    notes, out = [], {"nerf_log": str(nerf.path), "scene": str(scene.path)}
    centers = np.asarray(ours.centers, float)
    nerf_c, src = nerf.centers, "loss.txt"
    if nerf_c is None and scene.initial_pose is not None:
        nerf_c, src = scene.initial_pose, "initial_totem_pose.npy (fixed-pose NeRF run)"
    if nerf_c is not None and len(nerf_c) != len(centers):
        notes.append(f"NeRF run has {len(nerf_c)} totems, the scene {len(centers)}")
        nerf_c = None
    if nerf_c is not None:
        d = centers - nerf_c
        out["totems"] = [{"ours": c.tolist(), "nerf": n.tolist(), "delta": dd.tolist(),
                          "distance_m": float(np.linalg.norm(dd))}
                         for c, n, dd in zip(centers, nerf_c, d)]
        out["centre_distance_mean_m"] = float(np.linalg.norm(d, axis=1).mean())
        out["nerf_centres_from"] = src + (f" iter {nerf.centers_iter}"
                                          if nerf.centers_iter is not None else "")
    else:
        notes.append("no NeRF totem centres (loss.txt without totem lines)")
    key_r = nerf.args.get("totem_radius")
    if key_r is not None and not np.allclose(float(key_r), scene.radius):
        notes.append(f"NeRF run used radius {key_r} m, the scene's key {scene.radius.tolist()}")

    images = {}
    if nerf.camera_view is not None:
        h, w = nerf.camera_view.shape[:2]
        recon = _resize(np.asarray(ours.recon, np.float32), (w, h))
        photo = _resize(scene.image, (w, h))
        totem = _resize(scene.masks.any(0), (w, h))
        both = ~totem
        if our_protect is not None:
            both &= _resize(np.asarray(our_protect, bool), (w, h))
        nerf_protect = nerf.protect
        if nerf_protect is not None and nerf.protect_cropped:
            roi = _roi(scene)
            ds = scene.image.shape[1] / w
            full = np.zeros((h, w), bool)
            if roi is not None:
                x, y = int(round(roi[0] / ds)), int(round(roi[1] / ds))
                ph, pw = nerf_protect.shape
                full[y:y + ph, x:x + pw] = nerf_protect[:h - y, :w - x]
                nerf_protect = full
            else:
                notes.append("NeRF protect mask is cropped to roi but no roi is known")
                nerf_protect = None
        if nerf_protect is not None:
            both &= _resize(nerf_protect, (w, h))
        diff = np.abs(recon - nerf.camera_view).mean(-1)
        out["recon"] = {"size": [w, h], "pixels_compared": int(both.sum()),
                        "L1_ours_vs_nerf": float(diff[both].mean()) if both.any() else None,
                        "L1_ours_vs_photo": float(np.abs(recon - photo).mean(-1)[both].mean())
                        if both.any() else None,
                        "L1_nerf_vs_photo": float(np.abs(nerf.camera_view - photo).mean(-1)
                                                  [both].mean()) if both.any() else None,
                        "disagree_fraction": float((diff[both] > 0.1).mean())
                        if both.any() else None}
        images.update(ours=recon, nerf=nerf.camera_view, diff=np.where(both, diff, np.nan))
    else:
        notes.append("no NeRF camera_view.png (run it with --render_only --render_cam)")
    if nerf.heatmap is not None and our_heatmap is not None:
        out["heatmap"] = heatmap_agreement(np.asarray(our_heatmap, float), nerf.heatmap)
        images.update(heat_ours=np.asarray(our_heatmap, float), heat_nerf=nerf.heatmap)
    else:
        notes.append("no heatmap to compare (NeRF: run --detect_only; ours: totems verify)")
    out["notes"] = notes
    out["_images"] = images
    return out


def write_crosscheck(result: dict, out_dir) -> Path:
    """Write ``report.json`` and ``crosscheck.png`` (ours | NeRF | |difference| |
    heatmaps) into ``out_dir``, each atomically."""
    from matplotlib.figure import Figure    # no pyplot: the caller's backend is left alone

    out_dir = Path(out_dir)
    images = result.get("_images", {})
    folder.write_json(out_dir / "report.json", {k: v for k, v in result.items()
                                                if k != "_images"})
    panels = [(k, t) for k, t in (("ours", "ours (recon)"), ("nerf", "NeRF path"),
                                  ("diff", "|ours - NeRF|, both protect"),
                                  ("heat_ours", "our L1 heatmap"),
                                  ("heat_nerf", "NeRF L1 heatmap")) if k in images]
    if panels:
        fig = Figure(figsize=(3.2 * len(panels), 2.8), dpi=100)
        axes = fig.subplots(1, len(panels))
        for ax, (k, title) in zip(np.atleast_1d(axes), panels):
            img = images[k]
            if img.ndim == 3:
                ax.imshow(np.clip(img, 0, 1))
            else:
                ax.imshow(img, cmap="jet" if k.startswith("heat") else "magma")
            ax.set_title(title, fontsize=9)
            ax.axis("off")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
        folder.write_bytes(out_dir / "crosscheck.png", buf.getvalue())
    return out_dir
