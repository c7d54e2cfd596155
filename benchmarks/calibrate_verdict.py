"""Calibrate the verdict on the calibration set's untouched photos: the shipped p-values.

    python benchmarks/make_set.py --set calibration --out CAL --jobs 2
    totems bench CAL --out BENCH --jobs 2 --no-table1      # or --reverify after verify/
    python benchmarks/calibrate_verdict.py BENCH... [--write verify/verdict/calibration.json]
        [--set development --skip-edited] [--line-at 0.05] [--per-metric 0.9]

Reads every untouched photo's per-metric scores (``report.json`` ``scores``) from benches
of the calibration set, leaves out those the verdict called unverifiable (never called
inconsistent, they are no false alarm the line must hold back; docs/decisions.md,
"verdict: calibrated on the photos it judges"), and computes the statistic at
``verify/verdict/verdict.py``'s thresholds
(so a change of thresholds is calibrated without checking the photos again; a report
without scores keeps its ``statistic``), refuses photos that are manipulated or whose
seed belongs to another set (``benchmarks/sets.py``: a figure is never reported on what
it was calibrated on), fits the tail (``verify.verdict.calibration.fit_tail``) and prints
the line, the statistics per preset and per channel, the false alarms at ``ALPHA`` when each
preset (and each channel) is held out, with 95 % intervals, and where the line at
``--line-at`` (default ``LINE_AT``) would fall without each (how far it pulls the line).
``--write`` stores the calibration the package ships.

``--per-metric Q`` (with ``--line-at P``) chooses the thresholds themselves: each
metric's at the ``Q`` quantile of its untouched scores, all times one factor that puts
the line at p = P (:func:`per_metric_thresholds`); the statistics are then those at
these thresholds (rounded as shipped), which ``verify/verdict/verdict.py`` must be given.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from collections import defaultdict
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import sets  # noqa: E402

from scenes import folder  # noqa: E402
from scenes.errors import BadInput  # noqa: E402
from verify.verdict import calibration  # noqa: E402
from verify.verdict.verdict import THRESHOLDS  # noqa: E402

LINE_AT = 0.05
"""The p-value the verdict's line (score 1) is put at (docs/decisions.md, 'verdict: the
line put back at p = 0.05'): the report's column of where each group pulls it."""


def collect(bench_dir) -> list[dict]:
    """One row per checked photo of a bench: name, preset, seed, channel, totems,
    statistic, and whether it was manipulated."""
    bench_dir = Path(bench_dir)
    try:
        runs = json.loads((bench_dir / "bench.json").read_text())["runs"]
    except (OSError, ValueError, KeyError) as e:
        raise BadInput(f"{bench_dir} holds no bench.json of a finished bench: {e}") from None
    rows = []
    for run in runs:
        if run.get("mode") != "joint":
            continue
        if run.get("status") != "ok":
            raise BadInput(f"{run.get('name')}: its check failed ({run.get('error')}); "
                           f"a calibration needs every photo")
        scene = Path(run["scene"])
        report = json.loads((bench_dir / "runs" / f"{run['name']}-joint" / "verify"
                             / "report.json").read_text())
        desc = json.loads((scene / "truth" / "scene.json").read_text())
        rows.append({"name": run["name"], "preset": desc["preset"], "seed": desc["seed"],
                     "channel": run["name"].partition("+")[2] or "pristine",
                     "totems": len(desc["totems"]),
                     "manipulated": (scene / "manip_mask.png").is_file(),
                     "statistic": calibration.statistic_of(report),
                     "scores": metric_scores(report),
                     "unverifiable": report.get("verdict") == "unverifiable"})
    return rows


def metric_scores(report: dict) -> dict:
    """{metric: score} of a report.json, each metric the verdict judged by (its own
    units, before its threshold)."""
    return {m: float(v["score"]) for m, v in (report.get("scores") or {}).items()
            if m in THRESHOLDS and isinstance(v, dict) and v.get("score") is not None}


def statistic_at(scores: dict, thresholds: dict) -> float:
    """The verdict's statistic at ``thresholds``: the largest score over its threshold,
    0 where no metric judged (as :func:`verify.verdict.verdict.decide`)."""
    return max((s / thresholds[m] for m, s in scores.items()), default=0.0)


def per_metric_thresholds(rows: list[dict], quantile: float, line_at: float) -> dict:
    """Thresholds that put each metric's untouched tail on one footing: each metric's
    ``quantile`` of the rows' scores, times the one factor at which the line (1) falls
    at p = ``line_at`` of the rows' statistics; rounded to 3 decimals."""
    scale = {}
    for m in THRESHOLDS:
        vals = [r["scores"][m] for r in rows if m in r["scores"]]
        if not vals:
            raise BadInput(f"no photo was judged by {m}; its threshold cannot be chosen")
        scale[m] = float(np.quantile(vals, quantile))
        if scale[m] <= 0:
            raise BadInput(f"{m}'s {quantile} quantile is 0 on these photos")
    z = [statistic_at(r["scores"], scale) for r in rows]
    factor = calibration.fit_tail(z).line(line_at)
    return {m: round(factor * v, 3) for m, v in scale.items()}


def check_rows(rows: list[dict], set_name: str = "calibration") -> None:
    """Refuse rows a calibration must not see: a photo twice, manipulated photos,
    statistics missing (a bench of older code: rerun it with ``--reverify``) and seeds
    outside the set."""
    if not rows:
        raise BadInput("no checked photo to calibrate on")
    names = [r["name"] for r in rows]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise BadInput(f"{twice[0]} is in two benches; a photo counts once")
    for r in rows:
        if r["manipulated"]:
            raise BadInput(f"{r['name']} is manipulated; the calibration takes untouched "
                           f"photos only")
        if r["statistic"] is None:
            raise BadInput(f"{r['name']}: report.json has no statistic; verify again "
                           f"with this code (totems bench --reverify)")
        if r["seed"] not in sets.seeds_of(set_name, r["preset"]):
            other = sets.owner(r["preset"], r["seed"])
            raise BadInput(f"{r['name']}: {r['preset']} seed {r['seed']} belongs to "
                           f"{other or 'no set'}, not the {set_name} set; "
                           f"a calibration never sees another set's seeds")


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        return ""


def report(rows: list[dict], cal: calibration.Calibration, *,
           line_at: float = LINE_AT) -> str:
    """The figures as markdown; per group, the line at p = ``line_at`` fitted without it
    (how far the group pulls the line up)."""
    t = np.array([r["statistic"] for r in rows])
    lines = [f"line {cal.line():.3f} at p = {cal.alpha} (tail from u = {cal.u:.3f}, "
             f"k = {cal.k} of n = {cal.n}, xi = {cal.xi:.3f}, sigma = {cal.sigma:.3f}); "
             f"largest untouched {t.max():.3f} (p = {cal.p_value(t.max()):.3g})", ""]
    for key in ("preset", "channel"):
        groups = [r[key] for r in rows]
        if len(set(groups)) < 2:          # nothing to hold out
            continue
        held = calibration.leave_one_group_out(t, groups, alpha=cal.alpha)
        pull = calibration.line_without(t, groups, alpha=line_at)
        lines += [f"| {key} | photos | median | largest | false alarms, {key} held out "
                  f"| line at p = {line_at:g} without it |",
                  "|---|---|---|---|---|---|"]
        by = defaultdict(list)
        for r in rows:
            by[r[key]].append(r["statistic"])
        for name, vals in sorted(by.items()):
            k, n = held[name]
            lines.append(f"| {name} | {len(vals)} | {np.median(vals):.3f} | "
                         f"{max(vals):.3f} | {k} of {n} | {pull[name]:.3f} |")
        k, n, (lo, hi) = held["all"]
        lines += [f"| all | {n} | {np.median(t):.3f} | {t.max():.3f} | {k} of {n} "
                  f"({100 * k / n:.1f} %, 95 % interval {100 * lo:.1f}-{100 * hi:.1f} %) "
                  f"| {pull['all']:.3f} (with every {key}) |", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", type=Path, nargs="+",
                   help="output folders of `totems bench` on the set")
    p.add_argument("--write", type=Path, default=None,
                   help="write the calibration here "
                        "(the package's: verify/verdict/calibration.json)")
    p.add_argument("--set", default="calibration", choices=sorted(sets.SEEDS),
                   help="the set the photos belong to (default calibration; another set "
                        "gives an interim calibration, named so in its source)")
    p.add_argument("--skip-edited", action="store_true",
                   help="leave out the manipulated photos of the benches (a set with edits)")
    p.add_argument("--line-at", type=float, default=None, metavar="P",
                   help="also print the factor to multiply the thresholds by so that the "
                        "line (score 1) falls at p = P, and give each group's pull on the "
                        "line at that P (default 0.05)")
    p.add_argument("--per-metric", type=float, default=None, metavar="Q",
                   help="with --line-at: choose each metric's threshold at the Q quantile "
                        "of its untouched scores, all times one factor for the line at P, "
                        "and calibrate the statistics at those thresholds")
    args = p.parse_args(argv)
    if args.per_metric is not None and (args.line_at is None
                                        or not 0.0 < args.per_metric < 1.0):
        p.error("--per-metric Q needs 0 < Q < 1 and --line-at P")
    try:
        rows = [row for bench in args.bench for row in collect(bench)]
        if args.skip_edited:
            rows = [r for r in rows if not r["manipulated"]]
        check_rows(rows, args.set)
        left_out = sorted(r["name"] for r in rows if r.get("unverifiable"))
        rows = [r for r in rows if not r.get("unverifiable")]
        if not rows:
            raise BadInput("every photo is unverifiable; nothing to calibrate on")
        chosen = (per_metric_thresholds(rows, args.per_metric, args.line_at)
                  if args.per_metric is not None else dict(THRESHOLDS))
        rows = [{**r, "statistic": statistic_at(r["scores"], chosen)} if r["scores"] else r
                for r in rows]
    except BadInput as e:
        print(f"calibrate_verdict: {e}", file=sys.stderr)
        return 2
    seeds = sorted({r["seed"] for r in rows})
    if left_out:
        print(f"left out {len(left_out)} unverifiable photo(s), which the verdict never "
              f"calls inconsistent: {', '.join(left_out)}")
    source = {"set": args.set, "photos": len(rows), "unverifiable_left_out": len(left_out),
              "seeds": f"{seeds[0]}-{seeds[-1]}",
              "scenes": sorted({f"{r['preset']}:{r['seed']}" for r in rows}),
              "presets": sorted({r["preset"] for r in rows}),
              "channels": sorted({r["channel"] for r in rows}),
              "totems": sorted({r["totems"] for r in rows}),
              "commit": _commit(), "date": date.today().isoformat(),
              "thresholds": chosen}
    cal = calibration.fit_tail([r["statistic"] for r in rows], source=source)
    print(report(rows, cal, line_at=LINE_AT if args.line_at is None else args.line_at))
    if args.per_metric is not None:
        print("thresholds " + ", ".join(f"{m} {v:.3f}" for m, v in chosen.items())
              + f" (each metric's {args.per_metric:g} quantile, one factor; the line at "
              f"p = {cal.p_value(1.0):.3f}); verify/verdict/verdict.py's: "
              + ", ".join(f"{m} {v:.3f}" for m, v in THRESHOLDS.items()))
    elif args.line_at is not None:
        print(f"thresholds x {cal.line(args.line_at):.4f} put the line at p = {args.line_at}")
    if args.write:
        folder.write_json(args.write, cal.to_json())
        print(f"wrote {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
