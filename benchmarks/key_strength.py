"""The key's strength (issue 61): how often the adaptive forger is caught as its guess
of the key grows worse.

    python benchmarks/make_rekey.py REKEY SCENE...       # the photos
    totems bench SETDIR REKEY --out BENCH --jobs 2 --no-table1
    python benchmarks/key_strength.py BENCH... [--plot docs/key_strength.png]

Reads the benches' joint runs (``bench.json``) of ``rekey`` photos, each photo's key
error from its folder's ``truth/tamper.json`` (``key_error`` {ior, radius, pose}), and of
the plain ``remove`` photos of the same source scenes (the forger without a key, who
leaves the totems untouched: the curve's naive end). Prints, per key level: the photos,
those caught at the verdict's line (inconsistent, with the exact binomial 95 % interval
of ``benchmarks/roc.py``), how (the statistic over the line, "photo"; a totem named by
the totem check, "totem"), those unverifiable, the statistic's median and the fit's
leave-one-totem-out L1 (``holdout``) median; then each scene's statistic per level beside
its untouched photo's (found in the same benches). ``--plot`` draws the share caught per level
with its interval. A failed run is left out and counted. Seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from roc import load_runs, save_figure  # noqa: E402

from verify.verdict.calibration import clopper_pearson  # noqa: E402

NO_KEY = "none"
"""The level of the plain removal: no key, the totems untouched."""


def level_of(run: dict) -> dict | None:
    """A run's key level ``{"ior", "radius", "pose"}`` (``pose`` "none" for the plain
    removal), and its source scene, from its folder's truth/tamper.json; None for
    another kind."""
    if run["kind"] not in ("rekey", "remove"):
        return None
    rec = json.loads((Path(run["scene"]) / "truth" / "tamper.json").read_text())
    key = rec.get("key_error") if run["kind"] == "rekey" else \
        {"ior": None, "radius": None, "pose": NO_KEY}
    return {**key, "source": rec["source"]["folder"]}


def label(level: tuple, *, short: bool = False) -> str:
    """The words for a level ``(ior, radius, pose)``; ``short``: a figure's tick, over
    lines."""
    ior, radius, pose = level
    if pose == NO_KEY:
        return "no key\n(totems\nuntouched)" if short else "no key (totems untouched)"
    if ior == 0 and radius == 0:
        if pose == "exact":
            return "key held" if short else "the key held"
        return "key,\ncentres from\nmasks" if short else "the key, centres from the masks"
    if short:
        return f"index {ior:+.2g}\nradius {100 * radius:+.2g} %"
    centres = "true outline" if pose == "exact" else "masks"
    return f"index {ior:+.3g}, radius {100 * radius:+.3g} %, centres from the {centres}"


def _order(level: tuple) -> tuple:
    """Levels by growing error: the key held, the pose's error, then the key's, the
    forger without a key last."""
    ior, radius, pose = level
    if pose == NO_KEY:
        return (2, 0.0, 0.0, "")
    return (0 if ior == 0 and radius == 0 else 1, abs(radius), abs(ior),
            "" if pose == "exact" else pose)


def table(runs: list[dict]) -> list[dict]:
    """Per key level, by growing error, the rekey and plain-removal runs (each with
    ``level`` {ior, radius, pose, source} and bench.json's ``verdict``, ``statistic``,
    ``inconsistent_reasons``, ``holdout``): the plain removals only of the source
    scenes that have rekey runs.

    Returns dicts: ``level`` (ior, radius, pose), ``label``, ``n``, ``caught`` (the
    verdict inconsistent), ``lo``, ``hi`` (its 95 % interval), ``by_photo``,
    ``by_totem`` (the reasons; a photo may have both), ``unverifiable``,
    ``median_statistic``, ``median_holdout``, ``sources``."""
    keyed = [r for r in runs if r.get("level") is not None]
    sources = {r["level"]["source"] for r in keyed if r["level"]["pose"] != NO_KEY}
    groups: dict = {}
    for r in keyed:
        lv = r["level"]
        if lv["pose"] == NO_KEY and lv["source"] not in sources:
            continue
        groups.setdefault((lv["ior"], lv["radius"], lv["pose"]), []).append(r)
    out = []
    for level in sorted(groups, key=_order):
        rs = groups[level]
        n = len(rs)
        caught = sum(r["verdict"] == "inconsistent" for r in rs)
        lo, hi = clopper_pearson(caught, n)
        reasons = [r.get("inconsistent_reasons") or [] for r in rs]
        held = [h for h in ((r.get("holdout") or {}).get("L1") for r in rs) if h is not None]
        out.append({"level": level, "label": label(level), "n": n, "caught": caught,
                    "lo": lo, "hi": hi,
                    "by_photo": sum("photo" in x for x in reasons),
                    "by_totem": sum("totem" in x for x in reasons),
                    "unverifiable": sum(r["verdict"] == "unverifiable" for r in rs),
                    "median_statistic": float(np.median([r["statistic"] for r in rs])),
                    "median_holdout": float(np.median(held)) if held else None,
                    "sources": sorted({r["level"]["source"] for r in rs})})
    return out


def per_scene(runs: list[dict], untouched: dict, rows: list[dict]) -> str:
    """Each source scene's statistic at each level of ``rows`` (``table``'s), beside its
    untouched photo's (``untouched``: name -> bench run), as markdown; a photo the verdict
    called inconsistent is marked *, unverifiable (u)."""
    def cell(r):
        if r is None:
            return "–"
        mark = {"inconsistent": " *", "unverifiable": " (u)"}.get(r["verdict"], "")
        return f"{r['statistic']:.2f}{mark}"

    at = {(r["level"]["source"], (r["level"]["ior"], r["level"]["radius"],
                                  r["level"]["pose"])): r for r in runs
          if r.get("level") is not None}
    sources = sorted({s for t in rows for s in t["sources"]})
    lines = ["| scene | untouched | " + " | ".join(t["label"] for t in rows) + " |",
             "|---|---|" + "---|" * len(rows)]
    for src in sources:
        lines.append(f"| {src} | {cell(untouched.get(src))} | "
                     + " | ".join(cell(at.get((src, t["level"]))) for t in rows) + " |")
    return "\n".join(lines)


def markdown(rows: list[dict]) -> str:
    """The table as markdown."""
    lines = ["| key level | photos | caught at the line (95 % interval) | by the statistic "
             "| a totem named | unverifiable | statistic, median | holdout L1, median |",
             "|---|---|---|---|---|---|---|---|"]
    for t in rows:
        hold = "–" if t["median_holdout"] is None else f"{t['median_holdout']:.3f}"
        lines.append(f"| {t['label']} | {t['n']} | {t['caught']} of {t['n']} "
                     f"({100 * t['lo']:.0f}-{100 * t['hi']:.0f} %) | {t['by_photo']} "
                     f"| {t['by_totem']} | {t['unverifiable']} "
                     f"| {t['median_statistic']:.2f} | {hold} |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path, runs=()) -> None:
    """The share caught per level with its 95 % interval, levels by growing error; with
    ``runs`` (``table``'s input), beside it each scene's statistic per level."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.arange(len(rows))
    share = np.array([t["caught"] / t["n"] for t in rows])
    lo = np.array([t["lo"] for t in rows])
    hi = np.array([t["hi"] for t in rows])
    fig, axes = plt.subplots(1, 2 if runs else 1, figsize=(13.5 if runs else 7.5, 4.2),
                             dpi=100, squeeze=False)
    ax = axes[0, 0]
    ax.errorbar(x, share, yerr=[share - lo, hi - share], fmt="o", capsize=4, color="C0")
    for xi, t in zip(x, rows):
        ax.annotate(f"{t['caught']}/{t['n']}", (xi, t["caught"] / t["n"]),
                    textcoords="offset points", xytext=(8, -3), fontsize=8)
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("share caught at the verdict's line (95 % interval)")
    ax.set_title("the adaptive forger's removals caught")
    if runs:
        at = {(r["level"]["source"], (r["level"]["ior"], r["level"]["radius"],
                                      r["level"]["pose"])): r["statistic"] for r in runs
              if r.get("level") is not None}
        bx = axes[0, 1]
        for k, src in enumerate(sorted({s for t in rows for s in t["sources"]})):
            ys = [at.get((src, t["level"]), np.nan) for t in rows]
            bx.plot(x, ys, "o-", color=f"C{k % 10}", lw=1, ms=4, label=src)
        bx.axhline(1.0, color="0.3", lw=1, ls="--")
        bx.set_ylabel("the verdict's statistic (the line at 1)")
        bx.set_title("each scene's statistic")
        bx.legend(fontsize=7, ncol=2)
    for a in axes[0]:
        a.set_xticks(x, [label(t["level"], short=True) for t in rows], fontsize=8)
        a.set_xlim(-0.5, len(rows) - 0.5)
        a.grid(axis="y", color="0.9")
    save_figure(fig, path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", nargs="+", type=Path)
    p.add_argument("--plot", type=Path, default=None)
    args = p.parse_args(argv)
    runs, untouched = [], {}
    for r in load_runs(args.bench):
        lv = level_of(r)
        if lv is not None:
            runs.append({**r, "level": lv})
        elif r["kind"] == "none":
            untouched[r["name"]] = r
    failed = sum(1 for d in args.bench
                 for r in json.loads((d / "bench.json").read_text())["runs"]
                 if r.get("mode") == "joint" and r.get("status") != "ok"
                 and r.get("kind") in ("rekey", "remove"))
    rows = table(runs)
    if not rows:
        print("key_strength: no rekey runs in these benches", file=sys.stderr)
        return 2
    print(markdown(rows))
    print("\nThe statistic per scene (* inconsistent, (u) unverifiable; the line at 1):\n")
    print(per_scene(runs, untouched, rows))
    sources = sorted({s for t in rows for s in t["sources"]})
    print(f"\n{len(sources)} source scenes: {', '.join(sources)}"
          + (f"; {failed} rekey or remove runs failed and are left out" if failed else ""))
    if args.plot:
        plot(rows, args.plot, runs)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
