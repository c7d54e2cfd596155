"""The calibrated verdict on a bench: false alarms per channel, catches and ROC per kind.

    totems bench SET --out BENCH --jobs 2 --no-table1
    python benchmarks/roc.py BENCH [--plot docs/roc.png]

From a bench's runs (``bench.json``: each photo's ``statistic``, kind, preset and
name, the channel after a ``+``), judged by a calibration (``--calibration``, default
the shipped one: p-value below its alpha), prints:

- untouched photos over the verdict's own line (1) and over the calibration's line
  (p-value below its alpha), per channel, per preset and per placement, with the exact
  binomial 95 % interval of the rate, and the photos (untouched and edited) called
  unverifiable;
- per kind and channel, manipulated photos caught at each line, with interval;
- per kind, the image-level ROC AUC of the statistic, manipulated photos against every
  untouched one, with a 95 % bootstrap interval (2000 resamples of each class);
- per kind and channel, the mean patch AP of each judging metric;
- per kind and preset, the AUC against that preset's untouched photos (where the
  statistic separates and where the preset's own scores swamp an edit), and the edits
  caught at the verdict's line (an unverifiable edit is missed);
- per kind, the edits caught by how much of the edit the totems establish (the share
  of its pixels the verdict judges, ``metrics.manip_judged``): what a user may expect
  of an edit inside the report's judged region, and what lies outside it; and by the
  share of the edit in the truth's reach (``metrics.manip_in_reach``): what physics
  allows, which no fit can shrink;
- per preset and placement, what the truth's reach says of the evidence map (the
  reach's share of the photo, the share of it judged, the share of the judged two
  totems truly see, the view's depth error over it).

``--thresholds RANGE=T,UNSEEN=T,ABSENT=T`` judges the runs at other thresholds than
those they were verified at, from each run's per-metric scores (:func:`rejudge`; the
thresholds move no score, so no verify is needed). ``--plot`` draws the ROC curves per
kind. Refuses (exit 2) a bench holding photos of the set the calibration was made from
(its ``source.set``): a figure is never reported on what set the line. Seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import sets  # noqa: E402

from verify.verdict.calibration import clopper_pearson, load, statistic_of
from verify.verdict.verdict import MAX_HOLDOUT, MIN_JUDGED, THRESHOLDS

JUDGES = ("L1", "RANGE", "UNSEEN", "ABSENT")


def load_runs(bench_dirs) -> list[dict]:
    """The joint runs of one or more benches that finished, with their channel."""
    rows = []
    for d in bench_dirs:
        for r in json.loads((Path(d) / "bench.json").read_text())["runs"]:
            if r.get("mode") != "joint" or r.get("status") != "ok":
                continue
            t = statistic_of(r)
            if t is None:
                raise SystemExit(f"{r['name']}: no statistic in its report")
            rows.append({**r, "statistic": t,
                         "channel": r["name"].partition("+")[2] or "pristine"})
    return rows


def calibration_photos(rows: list[dict], cal) -> list[str]:
    """The names of the rows whose scene (``truth/scene.json``: preset and seed) is of
    the set the calibration ``cal`` was made from: figures must not be reported on what
    set the line."""
    set_name = cal.source.get("set")
    if set_name not in sets.SEEDS:
        return []
    out = []
    for r in rows:
        sj = Path(r["scene"]) / "truth" / "scene.json"
        if not sj.is_file():
            continue
        desc = json.loads(sj.read_text())
        preset, seed = desc.get("preset"), desc.get("seed")
        if preset is not None and seed is not None \
                and int(seed) in sets.seeds_of(set_name, preset):
            out.append(r["name"])
    return out


def rejudge(rows: list[dict], thresholds: dict) -> list[dict]:
    """The rows as the verdict calls them at ``thresholds`` ({metric: threshold}, the
    others as they were): statistic the largest score over its threshold (0 where no
    metric judged): unverifiable where the fit's ``holdout`` L1 is over
    ``MAX_HOLDOUT``, else inconsistent above 1, else unverifiable where the run was or
    its ``judged_fraction`` is under ``MIN_JUDGED``, else consistent (docs/contract.md,
    "Verdict")."""
    out = []
    for r in rows:
        scores = {m: v["score"] for m, v in (r.get("scores") or {}).items()
                  if isinstance(v, dict) and v.get("score") is not None}
        limits = {m: float(thresholds.get(m) or r["scores"][m].get("threshold")
                           or THRESHOLDS[m]) for m in scores}
        t = max((s / limits[m] for m, s in scores.items()), default=0.0)
        judged = r.get("judged_fraction", (r.get("metrics") or {}).get("judged_fraction"))
        thin = (not scores or r["verdict"] == "unverifiable"
                or (judged is not None and judged < MIN_JUDGED))
        held = (r.get("holdout") or {}).get("L1")
        verdict = ("unverifiable" if held is not None and held > MAX_HOLDOUT
                   else "inconsistent" if t > 1.0 else "unverifiable" if thin
                   else "consistent")
        out.append({**r, "statistic": t, "score": t, "threshold": 1.0, "verdict": verdict})
    return out


def parse_thresholds(text: str) -> dict:
    """``RANGE=0.3,UNSEEN=0.1`` -> {"RANGE": 0.3, "UNSEEN": 0.1}; SystemExit on a
    metric the verdict does not judge by or a threshold that is not positive."""
    out = {}
    for item in filter(None, text.split(",")):
        m, _, v = item.partition("=")
        try:
            value = float(v)
        except ValueError:
            value = -1.0
        if m not in THRESHOLDS or not value > 0:
            raise SystemExit(f"roc: --thresholds wants METRIC=VALUE with METRIC one of "
                             f"{', '.join(THRESHOLDS)} and VALUE > 0, not {item!r}")
        out[m] = value
    return out


def _rate(flags) -> str:
    flags = list(flags)
    k, n = int(sum(flags)), len(flags)
    if n == 0:
        return "–"
    lo, hi = clopper_pearson(k, n)
    return f"{k} of {n} ({100 * k / n:.0f} %, {100 * lo:.0f}-{100 * hi:.0f} %)"


def _key(run, key: str) -> str:
    """The run's channel or preset, or its preset and placement ("box resting")."""
    if key == "placement":
        return f"{run['preset']} {run.get('placement') or 'floating'}"
    return run[key]


def _unverifiable(run) -> bool:
    return run["verdict"] == "unverifiable"


def _called(run) -> bool:
    """Whether the verdict itself called the photo inconsistent (its own line)."""
    return run["verdict"] == "inconsistent"


def auc(neg, pos) -> float:
    """ROC AUC of ``pos`` above ``neg``: the chance a manipulated photo outscores an
    untouched one, ties counted half (Mann-Whitney)."""
    neg, pos = np.asarray(neg, float), np.asarray(pos, float)
    return float(((pos[:, None] > neg[None]) + 0.5 * (pos[:, None] == neg[None])).mean())


def auc_interval(neg, pos, *, n_boot: int = 2000, seed: int = 0):
    """ROC AUC of ``pos`` above ``neg`` and its 95 % bootstrap interval."""
    neg, pos = np.asarray(neg, float), np.asarray(pos, float)
    rng = np.random.default_rng(seed)
    boots = [auc(rng.choice(neg, neg.size), rng.choice(pos, pos.size))
             for _ in range(n_boot)]
    return auc(neg, pos), tuple(float(q) for q in np.percentile(boots, [2.5, 97.5]))


def tables(rows: list[dict], cal) -> str:
    """The figures as markdown, photos judged by the calibration ``cal``."""
    untouched = [r for r in rows if r["kind"] == "none"]
    edited = [r for r in rows if r["kind"] != "none"]
    alpha, line = cal.alpha, cal.line()
    own = {r["threshold"] for r in rows}
    out = [f"calibrated line: statistic {line:.3f} (p = {alpha}; calibration of {cal.n} "
           f"photos); the verdict's own line: {', '.join(f'{t:g}' for t in sorted(own))} "
           f"(p = {', '.join(f'{cal.p_value(t):.2f}' for t in sorted(own))})", ""]
    for key in ("channel", "preset", "placement"):
        out += [f"| untouched, by {key} | over the verdict's line (95 % interval) "
                f"| over the {100 * alpha:g} % line | unverifiable, all photos |",
                "|---|---|---|---|"]
        by, every = defaultdict(list), defaultdict(list)
        for r in untouched:
            by[_key(r, key)].append(r)
        for r in rows:
            every[_key(r, key)].append(r)
        out += [f"| {k} | {_rate(_called(r) for r in v)} | "
                f"{_rate(r['statistic'] > line for r in v)} | "
                f"{_rate(_unverifiable(r) for r in every[k])} |" for k, v in sorted(by.items())]
        out += [f"| all | {_rate(_called(r) for r in untouched)} | "
                f"{_rate(r['statistic'] > line for r in untouched)} | "
                f"{_rate(_unverifiable(r) for r in rows)} |", ""]
    neg = [r["statistic"] for r in untouched]
    out += ["| kind | channel | caught at the verdict's line | at the "
            f"{100 * alpha:g} % line | AUC (95 % interval) | "
            + " | ".join(f"AP {m}" for m in JUDGES) + " |",
            "|---|---|---|---|---|" + "---|" * len(JUDGES)]
    for kind in sorted({r["kind"] for r in edited}):
        mine = [r for r in edited if r["kind"] == kind]
        for ch in sorted({r["channel"] for r in mine}) + ["all"]:
            rs = [r for r in mine if ch in ("all", r["channel"])]
            auc = ""
            if neg and rs:
                a, (lo, hi) = auc_interval(neg, [r["statistic"] for r in rs])
                auc = f"{a:.3f} ({lo:.3f}-{hi:.3f})"
            aps = []
            for m in JUDGES:
                v = [r["metrics"].get(f"patch_ap_{m}") for r in rs]
                v = [x for x in v if x is not None]
                aps.append(f"{np.mean(v):.3f}" if v else "–")
            out.append(f"| {kind} | {ch} | {_rate(_called(r) for r in rs)} "
                       f"| {_rate(r['statistic'] > line for r in rs)} | "
                       f"{auc} | " + " | ".join(aps) + " |")
    return "\n".join(out + [""] + _by_preset(untouched, edited) + [""]
                     + by_coverage(edited) + [""]
                     + by_coverage(edited, "manip_in_reach", "in the truth's reach")
                     + [""] + by_reach(rows))


def _by_preset(untouched: list[dict], edited: list[dict]) -> list[str]:
    """Markdown rows: per kind, the AUC within each preset (its untouched photos as
    negatives), every channel; then per kind and channel, the edits each preset's
    verdict caught."""
    presets = sorted({r["preset"] for r in untouched})
    out = ["| AUC within the preset | " + " | ".join(presets) + " |",
           "|---|" + "---|" * len(presets)]
    for kind in sorted({r["kind"] for r in edited}):
        cells = []
        for p in presets:
            neg = [r["statistic"] for r in untouched if r["preset"] == p]
            pos = [r["statistic"] for r in edited
                   if r["kind"] == kind and r["preset"] == p]
            cells.append(f"{auc(neg, pos):.2f} ({len(pos)})" if neg and pos else "–")
        out.append(f"| {kind} | " + " | ".join(cells) + " |")
    out += ["", "| caught at the verdict's line | " + " | ".join(presets) + " |",
            "|---|" + "---|" * len(presets)]
    for kind, ch in sorted({(r["kind"], r.get("channel", "pristine")) for r in edited}):
        cells = []
        for p in presets:
            mine = [_called(r) for r in edited if r["kind"] == kind and r["preset"] == p
                    and r.get("channel", "pristine") == ch]
            cells.append(f"{sum(mine)} of {len(mine)}" if mine else "–")
        out.append(f"| {kind} {ch} | " + " | ".join(cells) + " |")
    return out


COVERAGE_BINS = (0.0, 0.25, 0.5, 1.0)
"""Edges of the bins of an edit's judged share (the last bin holds 1)."""


def by_coverage(edited: list[dict], key: str = "manip_judged",
                what: str = "judged") -> list[str]:
    """Markdown rows: per kind, the edits caught at the verdict's line in each bin of
    a share of the edit's pixels (``metrics.<key>``: by default the share the verdict
    judged; ``manip_in_reach`` the share in the truth's reach), with the binomial
    interval; an edit without that share is left out."""
    edges = COVERAGE_BINS
    n_bins = len(edges) - 1
    names = [f"{100 * lo:g}-{100 * hi:g} % {what}" if hi < 1 else f"{100 * lo:g} % or more"
             for lo, hi in zip(edges[:-1], edges[1:])]
    out = [f"| caught, by the share of the edit {what} | " + " | ".join(names) + " |",
           "|---|" + "---|" * n_bins]
    for kind in sorted({r["kind"] for r in edited}):
        by_bin = [[] for _ in range(n_bins)]
        for r in edited:
            share = (r.get("metrics") or {}).get(key)
            if r["kind"] == kind and share is not None:
                i = int(np.searchsorted(edges, float(share), side="right")) - 1
                by_bin[min(i, n_bins - 1)].append(_called(r))
        out.append(f"| {kind} | " + " | ".join(_rate(b) for b in by_bin) + " |")
    return out


REACH_FIGURES = ("reach_fraction", "reach_judged", "judged_seen", "depth_error",
                 "totem_depth_error", "totem_depth_given", "totem_depth_within",
                 "totem_depth_bound")


def by_reach(rows: list[dict]) -> list[str]:
    """Markdown rows: per preset and placement, the medians (and the photos that have
    them) of what the truth's reach says of the evidence map: the reach's share of the
    photo, the share of it judged, the share of the judged that two totems truly see,
    the view's median relative depth error over it, and the same of the depth the totems
    establish, the share of the reach it is given on, the share of those whose true
    depth lies in its interval, and the precision the rays' spacing allows there
    (``verify.metrics.truth``)."""
    by = defaultdict(list)
    for r in rows:
        if (r.get("metrics") or {}).get("reach_fraction") is not None:
            by[_key(r, "placement")].append(r["metrics"])
    if not by:
        return []
    out = ["| truth's reach, medians | photos | " + " | ".join(REACH_FIGURES) + " |",
           "|---|---|" + "---|" * len(REACH_FIGURES)]
    for k, ms in sorted(by.items()) + [("all", [m for v in by.values() for m in v])]:
        cells = []
        for f in REACH_FIGURES:
            v = [m[f] for m in ms if m.get(f) is not None]
            cells.append(f"{np.median(v):.2f}" if v else "–")
        out.append(f"| {k} | {len(ms)} | " + " | ".join(cells) + " |")
    return out


def plot(rows: list[dict], path: Path) -> None:
    """ROC curves of the statistic per kind (every channel), untouched as negatives."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from sklearn.metrics import roc_curve

    neg = [r["statistic"] for r in rows if r["kind"] == "none"]
    fig, ax = plt.subplots(figsize=(5, 5), dpi=100)
    for kind in sorted({r["kind"] for r in rows} - {"none"}):
        pos = [r["statistic"] for r in rows if r["kind"] == kind]
        y = np.r_[np.zeros(len(neg)), np.ones(len(pos))]
        fpr, tpr, _ = roc_curve(y, np.r_[neg, pos])
        auc, (lo, hi) = auc_interval(neg, pos)
        ax.plot(fpr, tpr, label=f"{kind} (AUC {auc:.2f}, {lo:.2f}-{hi:.2f}; {len(pos)})")
    ax.plot([0, 1], [0, 1], color="0.8", lw=1)
    ax.set(xlabel=f"false alarms (untouched, {len(neg)} photos)", ylabel="caught",
           title="image-level ROC of the verdict's statistic")
    ax.legend(loc="lower right", fontsize=8)
    save_figure(fig, path)


def save_figure(fig, path: Path) -> None:
    """Write a matplotlib figure to ``path`` (its folder made) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", nargs="+", type=Path)
    p.add_argument("--plot", type=Path, default=None)
    p.add_argument("--calibration", type=Path, default=None,
                   help="a calibration.json (default: the package's)")
    p.add_argument("--thresholds", default=None, metavar="M=T,...",
                   help="judge at these thresholds (RANGE, UNSEEN, ABSENT) instead of "
                        "those the runs were verified at")
    args = p.parse_args(argv)
    rows = load_runs(args.bench)
    cal = load(args.calibration)
    seen = calibration_photos(rows, cal)
    if seen:
        print(f"roc: {len(seen)} photos ({', '.join(seen[:3])}{', ...' if len(seen) > 3 else ''})"
              f" are of the {cal.source['set']} set, whose seeds set the verdict's line: "
              f"figures are never reported on them; bench another set", file=sys.stderr)
        return 2
    if args.thresholds:
        rows = rejudge(rows, parse_thresholds(args.thresholds))
    print(tables(rows, cal))
    if args.plot:
        plot(rows, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
