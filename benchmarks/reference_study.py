"""The verdict's statistic with its median reference (today's) and without (the top-k
mean alone, monotone in every patch), and the fit's held-out totem error, per preset and
placement, from a bench's runs (docs/decisions.md, "verdict: the median reference against
none, resting totems, the held-out error").

    python benchmarks/reference_study.py BENCH_OUT/bench.json

Without the reference a metric's score is its score plus its median (report.json
``scores``), so no run is verified again. Prints untouched photos over the line, AUC of
colour patches and splices, and the edited photos that score below their untouched one.
"""

import json
import sys
from pathlib import Path

import numpy as np

from roc import auc

bench = json.loads(Path(sys.argv[1]).read_text())
rows = []
for r in bench["runs"]:
    if r.get("status") != "ok" or r.get("mode") != "joint":
        continue
    vdir = Path(r["verify"])
    rep = json.loads((vdir / "report.json").read_text())
    leader = vdir.parent.parent / f"{r['fit_from']}-joint" if r.get("fit_from") \
        else vdir.parent                       # the run whose fit this one reuses
    geometry = json.loads((leader / "fit" / "fit.json").read_text())["geometry"]
    h = geometry["holdout_L1"][geometry["chosen"]]
    s = rep["scores"]
    stat_med = rep["statistic"]
    stat_abs = max((v["score"] + v["median"]) / v["threshold"] for v in s.values())
    rows.append(dict(name=r["name"], preset=r["preset"], placement=r.get("placement"),
                     kind=r["kind"], med=stat_med, abs=stat_abs, h=h,
                     recon=rep["metrics"].get("recon_L1"),
                     medians={m: v["median"] for m, v in s.items()}))

groups = sorted({(r["preset"], r["placement"]) for r in rows})
print(f"{'preset':9s} {'placement':9s} n  FA(med) FA(abs)  h med/max    AUCcol med/abs  AUCspl med/abs")
for key in groups + [("all", "all")]:
    sel = [r for r in rows if key == ("all", "all") or (r["preset"], r["placement"]) == key]
    un = [r for r in sel if r["kind"] == "none"]
    out = []
    for stat in ("med", "abs"):
        out.append(sum(r[stat] > 1 for r in un))
    hs = [r["h"] for r in un]
    a = {k: [auc([r[st] for r in un], [r[st] for r in sel if r["kind"] == k]) for st in ("med", "abs")]
         for k in ("color", "splice")}
    print(f"{key[0]:9s} {key[1]:9s} {len(un):2d} {out[0]:5d} {out[1]:7d}   {np.median(hs):.3f}/{max(hs):.3f}"
          f"   {a['color'][0]:.2f}/{a['color'][1]:.2f}   {a['splice'][0]:.2f}/{a['splice'][1]:.2f}")
# edited photos scoring below their own untouched photo (the forger's gain)
untouched = {(r["preset"], r["placement"], r["name"].split("-")[1]): r
             for r in rows if r["kind"] == "none"}
edited = [r for r in rows if r["kind"] != "none"
          and (r["preset"], r["placement"], r["name"].split("-")[1]) in untouched]
for stat in ("med", "abs"):
    below = [(r["name"], round(r[stat], 3),
              round(untouched[(r["preset"], r["placement"], r["name"].split("-")[1])][stat], 3))
             for r in edited
             if r[stat] < untouched[(r["preset"], r["placement"], r["name"].split("-")[1])][stat]]
    print(f"{stat}: edited photos below their untouched photo {len(below)} of {len(edited)}; "
          f"caught at the line {sum(r[stat] > 1 for r in edited)}")
    for x in below:
        print("   ", *x)
