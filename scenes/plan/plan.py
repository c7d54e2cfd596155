"""A plan before the shot: the reach a placement of totems predicts over the subject, and
the single move that widens it most (``totems plan``).

The photo will be judged at the working resolution (:mod:`scenes.working`), where the
totems' rays are as far apart as the verdict reads them, so the plan is made there;
pixel positions in and out are the photo's own. The subject is a plane
(:mod:`scenes.plan.predict` says what that leaves out) within its region, the pixels
given or the whole frame above the highest totem: a totem ray that would meet the plane
outside the region passes the subject by, as a ray beside a person does.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres;
pixels (u, v) with centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.plan.predict import (Plane, Prediction, check_placement, grid_points, predict,
                                 seen_shares, totem_image)
from scenes.plan.suggest import Move, best_move, sample_pixels
from scenes.reach import COS_EVIDENCE, MIN_PARALLAX
from scenes.working import block_mean, scale_intrinsics, working_factor

__all__ = ["APPROXIMATION", "MIN_ABOVE", "Plan", "region_box", "above_totems", "make_plan"]

APPROXIMATION = ("the subject is taken as a plane within its region, and nothing but the "
                 "totems hides it from them: a subject with depth, or a chair, the floor "
                 "under resting totems or a stand's post between a totem and the "
                 "subject, is not modelled")


@dataclass
class Plan:
    """The reach a placement predicts over the subject, at the working resolution.

    Attributes
    ----------
    K : (3, 3) the camera at the working resolution; ``size`` its (W, H) px.
    scale : the photo's pixels per working pixel along each axis (1: the same).
    centers : (n, 3) totem centres, metres; ``radius``, ``ior`` (n,) the key.
    plane : the subject's plane.
    region : (H, W) bool, the subject region (working pixels) whose rays meet the plane.
    region_from : how the region was given ("box", "mask" or "above the totems").
    prediction : the reach (:class:`scenes.plan.predict.Prediction`, every pixel).
    share : the share of the region in the reach.
    seen_by_two : the share of the region two totems see, whatever their parallax.
    sees : (n,) the share of the region each totem sees.
    move : the move that widens the share most, or None.
    """

    K: np.ndarray
    size: tuple[int, int]
    scale: int
    centers: np.ndarray
    radius: np.ndarray
    ior: np.ndarray
    plane: Plane
    region: np.ndarray
    region_from: str
    prediction: Prediction
    share: float
    seen_by_two: float
    sees: np.ndarray
    move: Move | None

    def photo_uv(self, uv) -> np.ndarray:
        """Working pixels (..., 2) as the photo's pixels (centres at integers)."""
        return (np.asarray(uv, np.float64) + 0.5) * self.scale - 0.5

    def to_json(self) -> dict:
        """plan.json's fields (``docs/contract.md``)."""
        uv = self.photo_uv(camera.project(self.K, self.centers))
        v, u = np.nonzero(self.region)
        box = self.photo_uv(np.array([[u.min(), v.min()], [u.max(), v.max()]]))
        out = {
            "share": round(self.share, 4),
            "seen_by_two": round(self.seen_by_two, 4),
            "region": {"from": self.region_from, "pixels": int(self.region.sum()),
                       "box": [round(box[0, 0]), round(box[0, 1]),
                               round(box[1, 0] - box[0, 0] + self.scale),
                               round(box[1, 1] - box[0, 1] + self.scale)]},
            "subject": {"model": "plane", "point": _r(self.plane.point),
                        "normal": _r(self.plane.normal)},
            "totems": [{"uv": _r(uv[j], 1), "distance": round(float(np.linalg.norm(P)), 4),
                        "center": _r(P), "radius": float(self.radius[j]),
                        "ior": float(self.ior[j]), "sees": round(float(self.sees[j]), 4)}
                       for j, P in enumerate(self.centers)],
            "move": None,
            "size": [int(self.size[0] * self.scale), int(self.size[1] * self.scale)],
            "working_size": [int(self.size[0]), int(self.size[1])],
            "working_scale": int(self.scale),
            "rule": {"min_parallax": MIN_PARALLAX, "cos_evidence": COS_EVIDENCE},
            "approximation": APPROXIMATION,
        }
        m = self.move
        if m is not None:
            out["move"] = {"totem": m.totem,
                           "from": {"uv": _r(uv[m.totem], 1),
                                    "distance": round(float(np.linalg.norm(
                                        self.centers[m.totem])), 4)},
                           "to": {"uv": _r(self.photo_uv(m.uv), 1),
                                  "distance": round(m.distance, 4), "center": _r(m.center)},
                           "share": round(m.share, 4), "before": round(m.before, 4),
                           "gain": round(m.gain, 4)}
        return out


def _r(a, nd: int = 4) -> list:
    return [round(float(x), nd) for x in np.ravel(a)]


def region_box(box, size) -> np.ndarray:
    """(H, W) bool of the box (x, y, w, h) in pixels of a frame of ``size`` (W, H);
    BadInput when it holds no pixel of the frame."""
    W, H = size
    x, y, w, h = (int(round(c)) for c in box)
    mask = np.zeros((H, W), bool)
    mask[max(y, 0):max(y + h, 0), max(x, 0):max(x + w, 0)] = True
    if not mask.any():
        raise BadInput(f"the subject region {x},{y},{w},{h} holds no pixel of the {W}x{H} "
                       "frame")
    return mask


def above_totems(labels) -> np.ndarray:
    """(H, W) bool: the rows above the highest totem's image (``labels``,
    :func:`scenes.plan.predict.totem_image`)."""
    rows = np.flatnonzero((labels >= 0).any(1))
    mask = np.zeros(labels.shape, bool)
    mask[:rows.min() if len(rows) else labels.shape[0]] = True
    return mask


MIN_ABOVE = 0.05
"""The frame above the totems must be at least this share of it to stand for the subject."""


def make_plan(K, size, centers, radius, ior, plane: Plane, *, region=None,
              region_from: str = "mask", suggest: bool = True) -> Plan:
    """The plan of totems (``centers`` (n, 3) m; ``radius``, ``ior`` (n,) the key) seen by
    a camera ``K`` (pixels of a photo of ``size`` (W, H)), over a subject on ``plane``.

    ``region``: (H, W) bool in the photo's pixels (``region_from`` says how it was
    given), or None for the frame above the totems. BadInput for a placement no photo
    can have (:func:`scenes.plan.predict.check_placement`) or a region that sees no
    subject.
    """
    W, H = (int(s) for s in size)
    f = working_factor((W, H))
    Kw, sw = scale_intrinsics(K, f), (W // f, H // f)
    n = len(np.asarray(centers))
    centers = np.asarray(centers, np.float64)
    radius = np.broadcast_to(np.asarray(radius, np.float64), (n,)).copy()
    ior = np.broadcast_to(np.asarray(ior, np.float64), (n,)).copy()
    check_placement(Kw, sw, centers, radius, plane)
    if region is None:
        how, mask = "above the totems", above_totems(totem_image(Kw, sw, centers, radius))
        if mask.mean() < MIN_ABOVE:
            raise BadInput("a totem stands at the top of the frame, so there is no frame "
                           "above the totems: give the subject's region (--subject-region)")
    else:
        region = np.asarray(region, bool)
        if region.shape != (H, W):
            raise BadInput(f"the subject region is {region.shape[1]}x{region.shape[0]} but "
                           f"the frame is {W}x{H}")
        how = region_from
        mask = region if f == 1 else block_mean(region, f) >= 0.5
    meets = np.isfinite(grid_points(Kw, sw, plane)[1][..., 2])
    if not (mask & meets).any():
        raise BadInput("the subject is behind the camera: no pixel of the subject region "
                       "sees its plane in front")
    mask = mask & meets
    pred = predict(Kw, sw, centers, radius, ior, plane, region=mask)
    inside = pred.reach.in_reach()[mask]
    u, v, _ = sample_pixels(mask)
    sees = seen_shares(Kw, sw, centers, radius, ior, plane, u, v, region=mask)
    move = best_move(Kw, sw, centers, radius, ior, plane, mask) if suggest else None
    return Plan(K=Kw, size=sw, scale=f, centers=centers, radius=radius, ior=ior,
                plane=plane, region=mask, region_from=how, prediction=pred,
                share=float(inside.mean()),
                seen_by_two=float((pred.reach.n_totems[mask] >= 2).mean()), sees=sees,
                move=move)

