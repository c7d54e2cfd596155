"""A plan's picture and its folder: plan.png (the reach over the frame or the test
photo), reach.npz (the predicted reach's arrays, as ``truth/reach.npz`` holds the
truth's) and plan.json (``docs/contract.md``), each written atomically, plan.json last so
that a half-written folder never looks finished."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes import camera, folder
from scenes.plan.plan import Plan
from scenes.reach import MIN_PARALLAX

__all__ = ["IN_REACH", "SHORT", "picture", "summary_line", "write_plan"]

IN_REACH = (40, 200, 70)
"""plan.png's colour (sRGB 8-bit) where the subject is in the reach."""

SHORT = (235, 160, 20)
"""Its colour where two totems see the subject but from too close together (a parallax
under :data:`~scenes.reach.MIN_PARALLAX`)."""


def picture(plan: Plan, background=None) -> np.ndarray:
    """plan.png: (H, W, 3) uint8 at the working size. Over ``background`` ((H, W, 3)
    sRGB in [0, 1] at the working size, the test photo) or a plain grey frame: the
    reach tinted green, what two totems see from too close together amber, both more
    strongly inside the subject region, whose outline is drawn white; each totem's
    outline and number in cyan, and the suggested move as a magenta circle where the
    totem would go, with an arrow from where it stands."""
    import cv2

    W, H = plan.size
    base = np.full((H, W, 3), 0.55) if background is None else np.asarray(background)
    out = np.clip(0.35 + 0.5 * base, 0, 1) * 255.0
    reach = plan.prediction.reach
    inside = reach.in_reach()
    short = (reach.n_totems >= 2) & ~inside & ~reach.excluded
    for m, col in ((inside, IN_REACH), (short, SHORT)):
        for where, a in ((m & plan.region, 0.65), (m & ~plan.region, 0.3)):
            out[where] = (1 - a) * out[where] + a * np.array(col, float)
    out = (out + 0.5).astype(np.uint8)
    thick = max(1, round(min(H, W) / 320))
    contours, _ = cv2.findContours(plan.region.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(out, contours, -1, (255, 255, 255), thick, lineType=cv2.LINE_AA)
    labels = plan.prediction.labels
    for j in range(len(plan.centers)):
        m = (labels == j).astype(np.uint8)
        if not m.any():
            continue
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, (0, 230, 230), thick, lineType=cv2.LINE_AA)
        ys, xs = np.nonzero(m)
        cv2.putText(out, str(j), (int(xs.max()) + 2 * thick, int(ys.min()) + 4 * thick),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4 * thick, (0, 230, 230), thick,
                    cv2.LINE_AA)
    move = plan.move
    if move is not None:
        a = camera.project(plan.K, plan.centers[move.totem])
        b = move.uv
        r = plan.K[0, 0] * plan.radius[move.totem] / move.distance
        cv2.arrowedLine(out, _pt(a), _pt(b), (255, 0, 255), thick, cv2.LINE_AA,
                        tipLength=min(0.3, 12.0 / max(np.hypot(*(b - a)), 1.0)))
        cv2.circle(out, _pt(b), max(2, int(round(r))), (255, 0, 255), thick, cv2.LINE_AA)
    return out


def _pt(uv) -> tuple[int, int]:
    return int(round(float(uv[0]))), int(round(float(uv[1])))


def summary_line(plan: Plan) -> str:
    """One line: the share in reach, what two totems see, the move and its gain."""
    line = (f"{100 * plan.share:.0f}% of the subject in the reach ({len(plan.centers)} "
            f"totems; two see {100 * plan.seen_by_two:.0f}% of it, a parallax of "
            f"{MIN_PARALLAX:g} needed)")
    m = plan.move
    if m is None:
        return line + "; no single move widens it"
    u, v = plan.photo_uv(m.uv)
    return (line + f"; move totem {m.totem} to pixel {u:.0f},{v:.0f} at {m.distance:.2f} "
            f"m: {100 * m.share:.0f}% (+{100 * m.gain:.0f} points)")


def write_plan(plan: Plan, out, *, background=None, extra: dict | None = None) -> Path:
    """Write ``out/plan.png``, ``out/reach.npz`` then ``out/plan.json`` (its
    :meth:`Plan.to_json` and ``extra``), each atomically; returns ``out``."""
    out = Path(out)
    folder.write_image(out / "plan.png", picture(plan, background))
    folder.write_npz(out / "reach.npz", **plan.prediction.reach.to_dict(),
                     region=plan.region)
    folder.write_json(out / "plan.json", {**plan.to_json(), "summary": summary_line(plan),
                                          **(extra or {})})
    return out
