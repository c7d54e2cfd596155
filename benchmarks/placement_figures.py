"""The figures of docs/placement.md, from the placement study's rows.

    python benchmarks/placement_figures.py STUDY.json docs/

``STUDY.json`` is ``placement_study.py --json``'s file. Writes ``placement_factors.png``
(the truth's share of the subject in the reach against each factor, from the study's
base and tight rows, with the plan's prediction) and ``placement_reach.png`` (the
truth's reach over three placements, traced again here: a good one, a row too tight, a
resting row whose field of view stops below the subject's head).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

LABELS = {"n": "totems", "spread": "row's width (share of the frame)",
          "share": "distance (share of the subject's)", "height": "height above the floor (m)",
          "radius": "radius (m)", "subject": "subject's distance (m)",
          "stagger": "stagger in depth (m)"}


def factors_figure(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(LABELS)
    fig, axes = plt.subplots(2, 4, figsize=(11, 5), constrained_layout=True)
    for ax, name in zip(axes.ravel(), names + ["resting"]):
        for base, colour in (("base", "tab:green"), ("tight", "tab:orange"),
                             ("resting", "tab:brown")):
            factor = "share" if name == "resting" else name
            if (name == "resting") != (base == "resting"):
                continue
            sel = [r for r in rows if r["base"] == base and r["factor"] == factor
                   and r["fits"]]
            if not sel:
                continue
            xs = [0.0 if r[factor] == "rest" else float(r[factor]) for r in sel]
            ax.plot(xs, [100 * r["truth"] for r in sel], "o-", color=colour,
                    label={"base": "60 % row", "tight": "25 % row",
                           "resting": "resting row"}[base])
            ax.plot(xs, [100 * r["plan_fronto"] for r in sel], "x", color="k", ms=5)
        ax.set_xlabel(LABELS.get(name, "resting row: distance (share)")
                      + (" (0: resting)" if name == "height" else ""), fontsize=8)
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        if name in ("n", "share"):
            ax.set_ylabel("subject in the reach (%)", fontsize=8)
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("share of a person-sized board in the truth's reach (dots) and what "
                 "totems plan predicts from the subject's distance (x), one factor at a "
                 "time", fontsize=9)
    fig.savefig(path, dpi=80)


def reach_figure(path: Path) -> None:
    import cv2

    from scenes import backend, folder
    from scenes.plan.files import IN_REACH, SHORT
    from scenes.synthetic.trace import camera_points, tracer, truth_reach

    import placement_study as study

    backend.use()
    panels = []
    for title, p in (("good: 60 % of the width, half way", study.BASE),
                     ("too tight: 15 % of the width", replace(study.BASE, spread=0.15)),
                     ("resting on the floor", replace(study.BASE, height="rest"))):
        desc = study.describe(p)
        reach, _ = truth_reach(desc)
        ids = camera_points(desc, tracer(desc, totems=False))[2]
        shade = np.choose(np.clip(ids + 1, 0, 4), [0.9, 0.35, 0.55, 0.8, 0.45])
        out = np.repeat(shade[..., None], 3, axis=2) * 255.0
        inside = reach.in_reach()
        short = (reach.n_totems >= 2) & ~inside & ~reach.excluded
        for m, col in ((inside, IN_REACH), (short, SHORT)):
            out[m] = 0.45 * out[m] + 0.55 * np.array(col, float)
        out[reach.excluded] = (0, 230, 230)
        out = (out + 0.5).astype(np.uint8)
        board = (ids == 2).astype(np.uint8)
        contours, _ = cv2.findContours(board, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, (255, 255, 255), 2, cv2.LINE_AA)
        share = inside[ids == 2].mean()
        small = cv2.resize(out, (320, 240), interpolation=cv2.INTER_AREA)
        cv2.putText(small, title, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1,
                    cv2.LINE_AA)
        cv2.putText(small, f"subject in reach: {100 * share:.0f} %", (6, 34),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        panels.append(small)
    folder.write_image(path, np.concatenate(panels, axis=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    rows = json.loads(args.study.read_text())["factors"]
    factors_figure(rows, args.out / "placement_factors.png")
    reach_figure(args.out / "placement_reach.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
