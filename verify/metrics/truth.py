"""What a synthetic scene's truth says of one verification: the fit against the true view,
pose and depth, and the judged pixels against the truth's reach.

The truth's reach (``truth/reach.npz``, :mod:`scenes.reach`) is what the totems truly see:
physics allows judging there and nowhere else, whatever the fit does. So it measures the
evidence map from both sides (how much of the reach it judges, how much of what it judges
two totems truly see) and tells, for an edit, whether it lay where the totems could have
seen it at all. Only metrics read the truth; the verdict never does.
"""

from __future__ import annotations

import numpy as np

from scenes.folder import Truth
from scenes.reach import MIN_TOTEMS

__all__ = ["TRUTH_METRICS", "truth_metrics"]

TRUTH_METRICS = ("recon_L1", "pose_L1", "reach_fraction", "reach_judged", "judged_seen",
                 "manip_in_reach", "depth_error", "totem_depth_error", "totem_depth_given",
                 "totem_depth_within", "totem_depth_bound")
"""report.json's metrics read off the truth (null where the truth does not hold them)."""


def _share(part: np.ndarray, whole: np.ndarray) -> float | None:
    n = int(whole.sum())
    return float((part & whole).sum() / n) if n else None


def truth_metrics(truth: Truth | None, *, fitted: np.ndarray, centers, seen: np.ndarray,
                  judged: np.ndarray, totem_mask: np.ndarray, manip=None,
                  depth=None, totem_depth=None) -> dict:
    """The metrics of :data:`TRUTH_METRICS` (each None where it cannot be read).

    Parameters
    ----------
    truth : the scene's truth at the photo's working size, or None.
    fitted : (H, W, 3) the rebuilt view, sRGB [0, 1], as the fit gave it.
    centers : (n, 3) fitted totem centres, camera frame, metres.
    seen : (H, W) bool, the protected pixels outside the totems.
    judged : (H, W) bool, the pixels the verdict judges.
    totem_mask : (H, W) bool, the totems' pixels.
    manip : (H, W) bool, the edited pixels, or None.
    depth : (H, W) the view's depth (camera-frame z, metres), or None.
    totem_depth : (z, lo, hi) each (H, W), the depth the totems establish and its
        interval (metres, NaN where none: :class:`verify.metrics.evidence.Evidence`), or
        None.

    Returns
    -------
    dict: ``recon_L1`` mean absolute sRGB error of the view over ``seen``; ``pose_L1``
    mean L1 distance of the centres, metres; ``reach_fraction`` the share of the photo
    (totems left out) in the truth's reach; ``reach_judged`` the share of the reach that
    is judged; ``judged_seen`` the share of the judged pixels whose surface two totems
    truly see; ``manip_in_reach`` the share of the edit in the reach; ``depth_error`` the
    median relative error of ``depth`` over the reach, ``|z - z_true| / z_true`` (a
    backdrop's pixels left out); ``totem_depth_error`` the same of the totems' depth
    over the reach's pixels where it is given, ``totem_depth_given`` the share of the
    reach (backdrop left out) where it is, ``totem_depth_within`` the share of those
    whose true depth lies inside its interval; ``totem_depth_bound`` the median over the
    reach (backdrop left out) of ``1 / parallax``: two totems' rays one angular spacing
    apart fix a depth to about that share of itself, the precision the rays' spacing
    allows without matching finer than a ray (:mod:`verify.metrics.evidence`).
    """
    out = dict.fromkeys(TRUTH_METRICS)
    if truth is None:
        return out
    image_shape = np.shape(fitted)[:2]
    clean = np.asarray(truth.clean, dtype=np.float64)
    if clean.shape[:2] == image_shape and seen.any():
        out["recon_L1"] = float(np.abs(fitted - clean).mean(axis=2)[seen].mean())
    true_pose = np.asarray(truth.totem_pose, dtype=np.float64)
    if true_pose.shape == np.shape(centers):
        out["pose_L1"] = float(np.abs(np.asarray(centers, float) - true_pose)
                               .sum(axis=1).mean())
    reach = truth.reach
    if reach is None or reach.depth.shape != image_shape:
        return out
    photo = ~np.asarray(totem_mask, bool)
    inside = reach.in_reach() & photo
    out["reach_fraction"] = _share(inside, photo)
    out["reach_judged"] = _share(np.asarray(judged, bool), inside)
    out["judged_seen"] = _share((reach.n_totems >= MIN_TOTEMS) & photo,
                                np.asarray(judged, bool))
    if manip is not None:
        out["manip_in_reach"] = _share(inside, np.asarray(manip, bool))
    z_true = reach.depth.astype(np.float64)
    area = inside & ~reach.backdrop & np.isfinite(z_true)     # the reach with a depth
    if area.any():
        out["totem_depth_bound"] = float(np.median(1.0 / reach.parallax[area]))
    if depth is not None and np.shape(depth) == image_shape:
        at = area & np.isfinite(depth)
        if at.any():
            err = np.abs(np.asarray(depth, np.float64)[at] - z_true[at]) / z_true[at]
            out["depth_error"] = float(np.median(err))
    if totem_depth is not None and np.shape(totem_depth[0]) == image_shape:
        z, lo, hi = (np.asarray(a, np.float64) for a in totem_depth)
        at = area & np.isfinite(z)
        out["totem_depth_given"] = _share(at, area)
        if at.any():
            out["totem_depth_error"] = float(np.median(np.abs(z[at] - z_true[at])
                                                       / z_true[at]))
            out["totem_depth_within"] = float(((z_true[at] >= lo[at])
                                               & (z_true[at] <= hi[at])).mean())
    return out
