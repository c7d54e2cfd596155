"""Verify a scene against its fit: region, heatmaps, verdict, metrics, and the files.

``verify_scene`` turns a scene and a fit into a :class:`Report` (values only);
``write_verify`` writes the ``verify/`` files of the contract, report.html
(:mod:`verify.report.html_report`) among them. The key (totem radius and IoR) is used for
the silhouettes of ``mask_iou`` and is never written: the report carries only
``folder.key_fingerprint``, and report.html draws the silhouettes as outlines.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from inverse.grid import FrustumFrame
from scenes import folder
from scenes.camera import sphere_silhouette
from scenes.errors import BadInput
from verify.metrics import absence, agreement, corroborate, evidence, patches, region
from verify.metrics import resolution, tone
from verify.metrics.truth import truth_metrics
from verify.report import html_report
from verify.report.findings import Report
from verify.verdict import verdict as verdict_mod

__all__ = ["VIS_FLOOR", "Report", "sphere_silhouette", "mask_iou", "verify_scene",
           "vis_max", "write_verify"]

VIS_FLOOR = {"L1": 0.2, "SSIM": 0.5, "CHROMA": 0.1, "RANGE": 0.1, "CORROB": 0.1,
             "UNSEEN": 0.1, "ABSENT": 0.1}
"""Smallest top of the colour scale of the heatmap pictures (heatmap.npy units).

The pictures are scaled to the largest kept patch, as the NeRF path scales per image,
but never below this floor, so an untouched photo with a good reconstruction stays in
the cold colours instead of having its noise stretched to red.
"""


# --------------------------------------------------------------------------- geometry

def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (H, W) bool masks (0 when both are empty)."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0


# --------------------------------------------------------------------------- verify

def verify_scene(scene: folder.Scene, fit, *, truth: folder.Truth | None = None,
                 thresholds: dict | None = None, versions: dict | None = None,
                 region_shape: str = "filled", calibration="shipped") -> Report:
    """Compare the photo with the fit's re-rendered camera view.

    Parameters
    ----------
    scene : the scene folder (photo, K, totem masks, key, optional manip_mask).
    fit : a FitResult (or anything with ``recon`` (H, W, 3) sRGB [0, 1],
        ``totem_points`` (m, 3) camera frame m, ``centers`` (n, 3), ``initial`` (n, 3)
        or None, optional ``timings`` dict).
    truth : ground truth of a synthetic scene, for the metrics read off it
        (:func:`verify.metrics.truth.truth_metrics`; else null).
    thresholds : {metric: scale} overriding ``verdict.THRESHOLDS``.
    The totems are also checked against each other
    (:func:`verify.metrics.agreement.totem_agreement`, with the key's radius and IoR to put
    each ray back on its pixel) when the fit has its rays.
    calibration : the verdict's calibration (:func:`verify.verdict.verdict.decide`): the
        shipped one by default, a :class:`verify.verdict.calibration.Calibration`, or None.
    versions : extra version info for the report (e.g. ``backend.describe()``).
    region_shape : "filled" (default) or "hull", the paper's protected region
        (:func:`verify.metrics.region.protected_region`).

    Raises
    ------
    BadInput when the fit does not belong to the scene or the protected region is empty.
    """
    t0 = time.perf_counter()
    image = np.asarray(scene.image, dtype=np.float32)
    H, W = image.shape[:2]
    recon = _check_fit(scene, fit)
    totem_mask = np.asarray(scene.masks, bool).any(axis=0)

    protected = region.protected_region(fit.totem_points, scene.K, (W, H),
                                        n_totem_pixels=int(totem_mask.sum()),
                                        shape=region_shape)
    grid = patches.patch_grid(totem_mask)             # heatmap.npy's, the NeRF path's
    judging = verdict_mod.judging_grid((H, W))         # the verdict's, the whole photo
    seen = protected & ~totem_mask
    rays = getattr(fit, "rays", None)    # None: a fit from before they were kept
    frame = None if rays is None else FrustumFrame.from_dict(fit.grid)
    slices = None if rays is None else corroborate.ray_slices(rays, frame)
    ev = None if rays is None else evidence.evidence_map(
        rays, fit.centers, frame, (W, H), slices=slices,
        plane=evidence.support_plane(getattr(fit, "geometry", None)))
    # each metric judges the protected pixels where its evidence holds (sRGB [0, 1]),
    # where a patch of the verdict's grid can judge them
    judged = verdict_mod.judgeable(seen if ev is None else seen & ev.resolved, judging)
    # the view at the photo's exposure and white balance, read off the judged pixels
    # (the photo compared at the evidence's resolution: verify.metrics.resolution)
    fitted = recon
    spacing = resolution.ray_spacing(fit.totem_points, scene.K, (W, H))
    blurred = patches.blur_varying(image, resolution.photo_sigma(spacing))
    recon, tone_found = tone.match_gain(blurred, recon, judged)
    errors = _pixel_errors(scene, fit, image, blurred, recon, totem_mask, ev, slices,
                           spacing, gain=(tone_found or {}).get("gain"))
    heat = patches.heatmaps(errors, grid, valid=~totem_mask)
    keep = patches.patch_fraction(seen, grid) > 0
    where = metric_pixels(judged, seen, ev, judging)
    inside = {}
    for m, e in errors.items():
        inside.update(patches.patch_scores({m: e}, judging, where.get(m, judged)))
    cover = {m: patches.patch_fraction(where.get(m, judged), judging) for m in inside}
    judged_fraction = float(judged.sum() / max((~totem_mask).sum(), 1))
    holdout = fit_holdout(fit)
    agree = None if rays is None else agreement.totem_agreement(
        rays, fit.centers, scene.radius, scene.ior, scene.K, frame, image, scene.masks)
    decision = verdict_mod.decide(inside, cover, judging, thresholds=thresholds,
                                  calibration=calibration, judged_fraction=judged_fraction,
                                  holdout=holdout,
                                  totem_lead=None if agree is None else agree.lead)

    metrics = edit_metrics(scene.manip_mask, heat, grid, keep, judged)
    metrics.update(truth_metrics(truth, fitted=fitted, centers=fit.centers, seen=seen,
                                 judged=judged, totem_mask=totem_mask,
                                 manip=scene.manip_mask,
                                 depth=getattr(fit, "recon_depth", None),
                                 totem_depth=None if ev is None or ev.depth is None
                                 else (ev.depth, ev.depth_lo, ev.depth_hi)))

    totems, silhouettes = _totems(scene, fit)

    timing = {f"fit_{k}": float(v) for k, v in (getattr(fit, "timings", None) or {}).items()
              if isinstance(v, (int, float)) and not isinstance(v, bool)}
    timing["verify"] = time.perf_counter() - t0
    return Report(
        verdict=decision.verdict, score=decision.score, threshold=decision.threshold,
        protected=protected, protected_fraction=float(protected.mean()), recon=recon,
        image=image, totem_mask=totem_mask, grid=grid, heatmaps=heat, keep=keep,
        decision=decision, totems=totems, metrics=metrics,
        key_fingerprint=folder.key_fingerprint(scene.radius, scene.ior), region=region_shape,
        timing_s=timing, versions={**_versions(), **(versions or {})},
        skipped=_skipped(decision, scene.n_totems),
        silhouettes=np.stack(silhouettes) if silhouettes else None,
        scene_name=Path(scene.path).resolve().name, scale=getattr(scene, "scale", 1),
        judged=judged, judged_fraction=judged_fraction, evidence=ev, tone=tone_found,
        holdout=holdout, judging=judging, agreement=agree)


def edit_metrics(manip_mask, heat: dict, grid, keep, judged) -> dict:
    """The metrics read off ``manip_mask.png`` (None without it): each heatmap's patch
    AP against the edited patches (``keep`` the patches scored), the share of the edit
    judged; ``recon_L1`` and ``pose_L1`` None until the truth fills them."""
    metrics = {**{f"patch_ap_{name}": None for name in patches.METRICS},
               "recon_L1": None, "pose_L1": None, "manip_judged": None}
    if manip_mask is None:
        return metrics
    manip = np.asarray(manip_mask, bool)
    metrics["manip_judged"] = float((manip & judged).sum() / manip.sum()) \
        if manip.any() else None
    labels = patches.patch_labels(manip_mask, grid)
    for name in heat:
        metrics[f"patch_ap_{name}"] = patches.patch_ap(heat[name], labels, keep)
    return metrics


def _pixel_errors(scene, fit, image, blurred, recon, totem_mask, ev, slices,
                  spacing, gain=None) -> dict:
    """Every metric's per-pixel map (:mod:`verify.metrics.patches`), CORROB and ABSENT from
    the totem rays when the fit has them (ABSENT inside the depth interval of the evidence
    map ``ev``; CORROB from ``slices``,
    :func:`verify.metrics.corroborate.ray_slices`), UNSEEN from CHROMA and CORROB, RANGE
    forgiven where the totems' rays, brought to the photo's exposure by the view's tone
    ``gain`` (3,), see the photo's colour along the pixel's ray (as CORROB, on the
    values); the photo blurred to the rays' ``spacing`` (H, W) px
    (:mod:`verify.metrics.resolution`), as ``blurred`` already is."""
    hue = resolution.chroma_factor(getattr(scene, "jpeg", None))
    hue_sigma = resolution.photo_sigma(spacing, hue)
    errors = patches.pixel_errors(image, recon, sigma=resolution.photo_sigma(spacing),
                                  chroma_sigma=hue_sigma, blurred=blurred)
    rays = getattr(fit, "rays", None)
    if rays is not None:          # the two tests that read the totem rays themselves
        frame = FrustumFrame.from_dict(fit.grid)
        errors["CORROB"] = corroborate.corroboration(rays, frame, image,
                                                     photo_sigma=hue_sigma, slices=slices)
        values = corroborate.corroboration(rays, frame, image, hue=False, gain=gain)
        errors["RANGE"] = np.fmin(np.asarray(errors["RANGE"], np.float64), values)
        errors["ABSENT"] = absence.absence(
            rays, frame, image, totem_mask, scene.K, getattr(fit, "recon_depth", None),
            centers=fit.centers, spacing=None if ev is None else ev.spacing,
            min_parallax=0.0 if ev is None else evidence.MIN_PARALLAX,
            interval=None if ev is None or ev.depth is None
            else (ev.depth_lo, ev.depth_hi))
    errors["UNSEEN"] = corroborate.unseen(errors["CHROMA"],
                                          errors.get("CORROB", np.nan))
    return errors


def metric_pixels(judged, seen, ev, judging) -> dict:
    """The pixels (H, W) bool a metric judges where they differ from ``judged``: ABSENT
    the protected non-totem pixels ``seen`` (it judges the points in front of the
    surface its three totems resolve), RANGE the judged pixels whose depth the totems
    resolve to :data:`verify.verdict.verdict.RANGE_MIN_PARALLAX` (it reads the view's colour
    at the pixel), kept where a patch of ``judging`` can judge them."""
    if ev is None:
        return {"ABSENT": seen}
    deep = verdict_mod.judgeable(judged & (ev.parallax >= verdict_mod.RANGE_MIN_PARALLAX),
                                 judging)
    return {"ABSENT": seen, "RANGE": deep}


def fit_holdout(fit) -> float | None:
    """The fit's leave-one-totem-out error (sRGB L1) of its best view geometry, from
    fit.json's ``geometry.holdout_L1`` (None for a fit without it)."""
    errors = [float(v) for v in ((getattr(fit, "geometry", None) or {})
                                 .get("holdout_L1") or {}).values()
              if v is not None and np.isfinite(float(v))]
    return min(errors) if errors else None


def _totems(scene: folder.Scene, fit) -> tuple[list, list]:
    """report.json's ``totems`` (centre, initial centre, mask_iou, pose_sd_mm along and
    across the line of sight) and each fitted sphere's silhouette (H, W) bool."""
    H, W = np.asarray(scene.image).shape[:2]
    centers = np.asarray(fit.centers, dtype=np.float64)
    initial = getattr(fit, "initial", None)
    initial = None if initial is None else np.asarray(initial, dtype=np.float64)
    unc = getattr(fit, "pose_uncertainty", None) or []
    totems, silhouettes = [], []
    for j, mask in enumerate(np.asarray(scene.masks, bool)):
        sil = sphere_silhouette(centers[j], float(scene.radius[j]), scene.K, (H, W))
        silhouettes.append(sil)
        totems.append({
            "center": [round(float(x), 6) for x in centers[j]],
            "initial": None if initial is None else [round(float(x), 6)
                                                     for x in initial[j]],
            "mask_iou": round(mask_iou(mask, sil), 6),
            "pose_sd_mm": [unc[j]["along_mm"], unc[j]["across_mm"]] if j < len(unc)
            else None})
    return totems, silhouettes


def _skipped(decision, n_totems: int) -> dict:
    """{metric: why} for the verdict's metrics that judged no patch of this photo."""
    out = {}
    for m in verdict_mod.THRESHOLDS:
        if m in decision.scores:
            continue
        if m == "ABSENT" and n_totems < absence.MIN_TOTEMS:
            out[m] = (f"needs {absence.MIN_TOTEMS} totems to see one point; "
                      f"the photo has {n_totems}")
        else:
            out[m] = "no patch of the protected region has a value"
    return out


def _check_fit(scene, fit) -> np.ndarray:
    """The fit's recon as float32 after checking that the fit matches the scene."""
    H, W = scene.image.shape[:2]
    recon = np.asarray(fit.recon, dtype=np.float32)
    if recon.shape != (H, W, 3):
        raise BadInput(f"the fit's recon is {recon.shape} but the photo is {(H, W, 3)}; "
                       f"the fit belongs to another scene: refit it")
    if not np.all(np.isfinite(recon)):
        raise BadInput("the fit's recon has non-finite values; refit the scene")
    centers = np.asarray(fit.centers, dtype=np.float64)
    if centers.shape != (scene.n_totems, 3) or not np.all(np.isfinite(centers)):
        raise BadInput(f"the fit has totem centres of shape {centers.shape} but the scene "
                       f"has {scene.n_totems} totems; refit it")
    return np.clip(recon, 0.0, 1.0)


def _versions() -> dict:
    import importlib.metadata as md

    out = {}
    for dist in ("totems", "numpy", "scipy", "scikit-image", "scikit-learn"):
        try:
            out[dist] = md.version(dist)
        except md.PackageNotFoundError:
            pass
    return out


# --------------------------------------------------------------------------- files

def vis_max(report: Report, name: str) -> float:
    """Top of heatmap ``name``'s colour scale (heatmap.npy units): its largest kept
    patch, at least ``VIS_FLOOR[name]``."""
    heat = report.heatmaps[name]
    vals = heat[report.keep & np.isfinite(heat)]
    return max(float(vals.max()) if vals.size else 0.0, VIS_FLOOR[name])


def write_verify(report: Report, out_dir) -> Path:
    """Write the verify/ files of the contract into ``out_dir``; report.json last.

    Each file is written atomically; report.html just before report.json, after the
    pictures, so a folder with a report.json is complete. Returns the path of
    report.json.
    """
    out = Path(out_dir)
    folder.write_image(out / "protect_mask.png", report.protected)
    if report.evidence is not None:
        folder.write_image(out / "judged_mask.png", report.judged)
        depth = {} if report.evidence.depth is None else {
            "depth": report.evidence.depth, "depth_lo": report.evidence.depth_lo,
            "depth_hi": report.evidence.depth_hi}
        folder.write_npz(out / "evidence.npz", n_totems=report.evidence.n_totems
                         .astype(np.uint8), parallax=report.evidence.parallax
                         .astype(np.float32), judged=report.judged, **depth)
    folder.write_image(out / "recon.png", report.recon)
    overlays = {}
    for name, heat in report.heatmaps.items():
        vmax = vis_max(report, name)
        overlays[name] = (vmax, patches.heatmap_overlay(
            report.image, heat, report.grid, report.protected, report.totem_mask, vmax))
        folder.write_npy(out / name / "heatmap.npy", heat.astype(np.float64))
        folder.write_image(out / name / "heatmap_vis.png",
                           patches.heatmap_vis(heat, report.grid, vmax))
        folder.write_image(out / name / "heatmap_overlay.png", overlays[name][1])
    page = html_report.render_report(report, overlays)
    folder.write_bytes(out / "report.html", page.encode("utf-8"))
    folder.write_json(out / "report.json", report.to_json())
    return out / "report.json"
