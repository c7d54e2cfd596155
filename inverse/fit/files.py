"""What a fit gives (:class:`FitResult`), its folder (``fit/``, see docs/contract.md)
and the fingerprint that ties a fit to the scenes it serves.

:func:`write_fit` writes each file atomically and ``fit.json`` last; :func:`load_fit`
reads a folder back into a :class:`FitResult`, or raises BadInput with the one line to
show. Fits written before ``totem_rays.npz`` existed load without rays.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inverse.grid import FrustumFrame
from inverse.pose.rim import READ_PX
from inverse.rays import TotemRays
from scenes import backend, folder
from scenes.errors import BadInput
from scenes.masks import bbox

__all__ = ["FitResult", "FIT_FILES", "scene_fingerprint", "fit_timings", "write_fit",
           "load_fit"]

FIT_FILES = ("totem_pose.npy", "initial_totem_pose.npy", "grid.npz", "recon.png",
             "totem_views.png", "fit.json", "totem_points.npy", "totem_rays.npz")



@dataclass
class FitResult:
    """The outcome of a fit (its files: docs/contract.md, "Outputs of fit")."""

    centers: np.ndarray            # (n, 3) fitted centres, camera frame, metres
    initial: np.ndarray            # (n, 3) initial centres
    recon: np.ndarray              # (H, W, 3) sRGB [0, 1] float32, the re-rendered camera view
    recon_depth: np.ndarray | None  # (H, W) metres, depth along camera rays
    totem_points: np.ndarray       # (m, 3) camera-frame points where totem rays end
    totem_pred: np.ndarray         # (H, W, 3) sRGB fitted colour at totem pixels, 0 elsewhere
    grid: dict                     # density, colour, frame (np arrays)
    history: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    scene_fingerprint: str = ""
    geometry: dict = field(default_factory=dict)  # chosen geometry, hold-out errors
    ambient: list = field(default_factory=list)   # fitted linear RGB the glass reflects
    rays: TotemRays | None = None  # the totem pixels' rays leaving the glass
    pose_uncertainty: list | None = None  # per totem {along_mm, across_mm, mask_share}


def pixels_read(masks, *, initial_pose: bool = False) -> np.ndarray:
    """(H, W) bool: the photo's pixels a fit reads, inside the totem ``masks`` (n, H, W)
    and, unless an initial pose is given, within ``rim.READ_PX`` of them (city-block
    distance), where the rims are looked for."""
    read = np.asarray(masks, bool).any(0)
    if not initial_pose:
        from scipy.ndimage import binary_dilation

        read = binary_dilation(read, iterations=READ_PX)
    return read


def scene_fingerprint(scene: folder.Scene) -> str:
    """Hash of what a fit depends on: the pixels it reads, masks, K, key and any initial
    pose.

    The fit reads the photo inside the totem masks and, to find the rims, within
    ``rim.READ_PX`` of them (unless an initial pose is given), so a photo edited
    elsewhere (the forger's case) shares the fit of the original, while a fit of another
    scene, of a photo whose totem pixels or rims changed, or made with another key,
    differs. The key enters only through a hash, so the fingerprint can be shared.
    """
    masks = np.asarray(scene.masks, bool)
    read = pixels_read(masks, initial_pose=scene.initial_pose is not None)
    totem_px = np.asarray(scene.image)[read]
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.round(totem_px * 255).astype(np.uint8)).tobytes())
    h.update(np.packbits(masks).tobytes())
    h.update(repr(masks.shape).encode())
    h.update(np.round(np.asarray(scene.K, np.float64), 6).tobytes())
    h.update(folder.key_fingerprint(scene.radius, scene.ior).encode())
    if scene.initial_pose is not None:      # a given initial pose replaces the masks' one
        h.update(np.round(np.asarray(scene.initial_pose, np.float64), 6).tobytes())
    return h.hexdigest()[:16]


def fit_timings(step_times, settings, **figures) -> dict:
    """fit.json's ``timings``: the stages' seconds, the steps' first, steady and total
    time, and an estimate of the kernel compile time (each stage's first step compiles
    new kernels). ``settings`` is the fit's :class:`inverse.fit.fit.FitSettings`
    (its ``stages`` and ``n_samples``); ``figures`` the stages' seconds and counts."""
    steady = float(np.median(step_times[1:])) if len(step_times) > 1 else None
    timings = {
        "pose_init_s": figures["t_pose"],
        "first_step_s": step_times[0] if step_times else None,
        "steady_step_s": steady,
        "optimise_s": float(np.sum(step_times)),
        "render_s": figures["t_render"],
        "stereo_s": figures["t_stereo"],
        "total_s": figures["t_total"],
        "n_rays": int(figures["n_rays"]),
        "pose_accepted": figures["pose_accepted"],
        "n_samples": int(settings.n_samples),
    }
    firsts, i = [], 0
    for _, s in settings.stages:
        if s:
            firsts.append(step_times[i])
        i += int(s)
    if steady is not None:
        timings["compile_s_estimate"] = float(sum(max(0.0, f - steady) for f in firsts))
    return timings


def _totem_views(scene_image, totem_pred, masks) -> np.ndarray:
    """Observed (top) and fitted (bottom) totem pixels, cropped to the masks' box."""
    any_m = np.asarray(masks, bool).any(0)
    x, y, w, h = bbox(any_m)
    pad = 4
    v0, v1 = max(0, y - pad), min(any_m.shape[0], y + h + pad)
    u0, u1 = max(0, x - pad), min(any_m.shape[1], x + w + pad)
    obs = np.where(any_m[..., None], scene_image, 0.0)[v0:v1, u0:u1]
    fit = totem_pred[v0:v1, u0:u1]
    return np.concatenate([obs, np.ones((2, u1 - u0, 3)), fit], 0)


def write_fit(result: FitResult, out_dir, *, scene: folder.Scene | None = None) -> None:
    """Write the fit/ files of the contract (plus ``totem_points.npy`` and
    ``totem_rays.npz``), each atomically.

    ``totem_views.png`` shows observed over fitted totem pixels when ``scene`` is given,
    else the fitted totem pixels alone.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folder.write_npy(out / "totem_pose.npy", np.asarray(result.centers, np.float64))
    folder.write_npy(out / "initial_totem_pose.npy", np.asarray(result.initial, np.float64))
    folder.write_npy(out / "totem_points.npy", np.asarray(result.totem_points, np.float64))
    grid = {k: np.asarray(v) for k, v in result.grid.items()}
    if result.recon_depth is not None:
        grid["recon_depth"] = np.asarray(result.recon_depth, np.float32)
    grid["totem_pred"] = np.asarray(result.totem_pred, np.float32)
    folder.write_npz(out / "grid.npz", **grid)
    if result.rays is not None:
        folder.write_npz(out / "totem_rays.npz", **result.rays.to_dict())
    folder.write_image(out / "recon.png", result.recon)
    if scene is not None:
        views = _totem_views(scene.image, result.totem_pred, scene.masks)
    else:
        mask = np.any(result.totem_pred > 0, axis=2)
        views = _totem_views(result.totem_pred, result.totem_pred, mask[None])
    folder.write_image(out / "totem_views.png", views)
    folder.write_json(out / "fit.json", {
        "scene_fingerprint": result.scene_fingerprint,
        "centers": np.asarray(result.centers).tolist(),
        "initial": np.asarray(result.initial).tolist(),
        "history": result.history, "timings": result.timings,
        "geometry": result.geometry, "ambient": list(result.ambient),
        "pose_uncertainty": result.pose_uncertainty, "settings": result.settings, "versions": backend.describe()})


def load_fit(fit_dir) -> FitResult:
    """Read a fit/ folder written by :func:`write_fit`. BadInput if missing or corrupt."""
    d = Path(fit_dir)
    if not d.is_dir():
        raise BadInput(f"fit folder not found: {d} (run `totems fit` first)")
    for name in ("totem_pose.npy", "initial_totem_pose.npy", "grid.npz", "recon.png",
                 "fit.json", "totem_points.npy"):
        if not (d / name).is_file():
            raise BadInput(f"fit folder {d} lacks {name}: run `totems fit` again")
    try:
        meta = json.loads((d / "fit.json").read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f"{d / 'fit.json'} is not valid JSON ({exc})") from None
    centers = np.asarray(folder.safe_load_npy(d / "totem_pose.npy"), dtype=np.float64)
    initial = np.asarray(folder.safe_load_npy(d / "initial_totem_pose.npy"), np.float64)
    points = np.asarray(folder.safe_load_npy(d / "totem_points.npy"), dtype=np.float64)
    if centers.ndim != 2 or centers.shape[1] != 3 or centers.shape != initial.shape \
            or not np.all(np.isfinite(centers)):
        raise BadInput(f"{d}: totem_pose.npy / initial_totem_pose.npy must be (n, 3) finite")
    if points.ndim != 2 or points.shape[1] != 3:
        raise BadInput(f"{d}: totem_points.npy must be (m, 3)")
    try:
        with np.load(d / "grid.npz", allow_pickle=False) as z:
            grid = {k: z[k] for k in z.files}
    except Exception as exc:
        raise BadInput(f"{d / 'grid.npz'} is unreadable ({exc.__class__.__name__})") from None
    for k in ("density", "colour"):
        if k not in grid or grid[k].ndim != 4:
            raise BadInput(f"{d / 'grid.npz'} lacks a 4-D '{k}' grid")
    FrustumFrame.from_dict(grid)               # validates the frame
    recon = folder.read_image(d / "recon.png", what="fit recon.png")
    depth = grid.pop("recon_depth", None)
    totem_pred = grid.pop("totem_pred", None)
    if totem_pred is None:
        totem_pred = np.zeros_like(recon)
    rays = None
    if (d / "totem_rays.npz").is_file():       # fits written before it have none
        try:
            with np.load(d / "totem_rays.npz", allow_pickle=False) as z:
                rays = TotemRays.from_dict(z)
        except Exception as exc:
            raise BadInput(f"{d / 'totem_rays.npz'} is unreadable "
                           f"({exc.__class__.__name__}): run `totems fit` again") from None
    return FitResult(centers=centers, initial=initial, recon=recon, recon_depth=depth,
                     totem_points=points, totem_pred=totem_pred, grid=grid,
                     history=meta.get("history", {}), timings=meta.get("timings", {}),
                     settings=meta.get("settings", {}),
                     scene_fingerprint=str(meta.get("scene_fingerprint", "")),
                     geometry=meta.get("geometry", {}), rays=rays,
                     ambient=list(meta.get("ambient", [])),
                     pose_uncertainty=meta.get("pose_uncertainty"))
