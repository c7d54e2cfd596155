"""benchmarks/roc.py: the image-level AUC and its interval."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "roc.py"
_spec = importlib.util.spec_from_file_location("roc", _PATH)
roc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(roc)


def test_auc_by_ranks_matches_the_area_under_the_curve():
    from sklearn.metrics import roc_auc_score

    rng = np.random.default_rng(0)
    neg = np.round(rng.normal(0.0, 1.0, 40), 1)        # rounded: ties across classes
    pos = np.round(rng.normal(0.8, 1.0, 25), 1)
    y = np.r_[np.zeros(neg.size), np.ones(pos.size)]
    assert roc.auc(neg, pos) == pytest.approx(roc_auc_score(y, np.r_[neg, pos]))
    assert roc.auc([0.0, 1.0], [2.0, 3.0]) == 1.0 and roc.auc([1.0], [1.0]) == 0.5


def test_auc_interval_holds_the_estimate_and_narrows_with_more_photos():
    rng = np.random.default_rng(1)
    small = roc.auc_interval(rng.normal(0, 1, 20), rng.normal(1, 1, 20), n_boot=500)
    large = roc.auc_interval(rng.normal(0, 1, 400), rng.normal(1, 1, 400), n_boot=500)
    for a, (lo, hi) in (small, large):
        assert lo <= a <= hi
    assert large[1][1] - large[1][0] < small[1][1] - small[1][0]
    assert 0.70 < large[0] < 0.80          # Phi(1 / sqrt 2) = 0.760


def test_auc_within_each_preset_uses_that_presets_untouched_photos():
    # Pooled, box's high untouched scores hide nothing and envmap's edits look weak;
    # within each preset the box edit is not separated and the envmap one is.
    rows = [{"kind": "none", "preset": "box", "statistic": s} for s in (3.0, 4.0)]
    rows += [{"kind": "none", "preset": "envmap", "statistic": s} for s in (0.1, 0.2)]
    rows += [{"kind": "color", "preset": "box", "statistic": 3.5},
             {"kind": "color", "preset": "envmap", "statistic": 1.0}]
    untouched = [r for r in rows if r["kind"] == "none"]
    edited = [r for r in rows if r["kind"] != "none"]
    for r in rows:
        r["verdict"] = "inconsistent" if r["statistic"] > 1.0 else "consistent"
    header, _, color, _, _, _, caught = roc._by_preset(untouched, edited)
    assert header.split(" | ")[1:] == ["box", "envmap |"]
    assert color == "| color | 0.50 (1) | 1.00 (1) |"
    assert caught == "| color pristine | 1 of 1 | 0 of 1 |"      # each at its own line


def test_untouched_rates_by_placement_and_unverifiable_photos():
    from verify.verdict.calibration import fit_tail

    def run(kind, preset, placement, verdict, t):
        return {"kind": kind, "preset": preset, "placement": placement, "verdict": verdict,
                "statistic": t, "threshold": 1.0, "channel": "pristine", "metrics": {}}
    rows = [run("none", "box", "floating", "consistent", 0.2),
            run("none", "box", "resting", "inconsistent", 1.5),
            run("none", "box", "resting", "unverifiable", 0.1),
            run("color", "box", "resting", "unverifiable", 0.3)]
    cal = fit_tail(np.linspace(0.05, 1.2, 40))
    text = roc.tables(rows, cal)
    assert "| box resting | 1 of 2 (50 %" in text
    line = [x for x in text.splitlines() if x.startswith("| box resting |")][0]
    assert line.endswith("| 2 of 3 (67 %, 9-99 %) |")          # both unverifiable photos



def _run(verdict, judged, **scores):
    return {"name": "x", "kind": "none", "verdict": verdict, "judged_fraction": judged,
            "scores": {m: {"score": s, "threshold": 0.2} for m, s in scores.items()}}


def test_rejudge_calls_each_run_as_the_verdict_would_at_other_thresholds():
    rows = [_run("consistent", 0.5, RANGE=0.15, UNSEEN=0.05),     # 0.75 of the line
            _run("inconsistent", 0.5, RANGE=0.30),                # 1.5
            _run("unverifiable", 0.02, UNSEEN=0.05),              # too little judged
            _run("inconsistent", 0.02, UNSEEN=0.30)]              # over it, little judged
    same = roc.rejudge(rows, {})
    assert [r["statistic"] for r in same] == pytest.approx([0.75, 1.5, 0.25, 1.5])
    assert [r["verdict"] for r in same] == [r["verdict"] for r in rows]
    low = roc.rejudge(rows, {"RANGE": 0.1, "UNSEEN": 0.04})
    assert [r["verdict"] for r in low] == ["inconsistent"] * 4
    high = roc.rejudge(rows, {"RANGE": 1.0, "UNSEEN": 1.0})
    assert [r["verdict"] for r in high] == ["consistent", "consistent", "unverifiable",
                                            "unverifiable"]
    assert high[1]["statistic"] == pytest.approx(0.3)
    # a fit whose totems do not predict each other leaves any photo unverifiable
    gated = [{**r, "holdout": {"L1": roc.MAX_HOLDOUT + 0.01}} for r in rows]
    assert {r["verdict"] for r in roc.rejudge(gated, {"RANGE": 0.1})} == {"unverifiable"}
    kept = [{**r, "holdout": {"L1": roc.MAX_HOLDOUT - 0.01}} for r in rows]
    assert [r["verdict"] for r in roc.rejudge(kept, {})] == [r["verdict"] for r in rows]


def test_parse_thresholds_refuses_an_unknown_metric_or_a_threshold_not_above_zero():
    assert roc.parse_thresholds("RANGE=0.3,UNSEEN=0.1") == {"RANGE": 0.3, "UNSEEN": 0.1}
    for bad in ("L1=0.3", "RANGE=0", "RANGE=x", "RANGE"):
        with pytest.raises(SystemExit):
            roc.parse_thresholds(bad)


def test_edits_caught_by_the_share_of_the_edit_judged():
    def run(judged, verdict):
        return {"kind": "color", "verdict": verdict, "metrics": {"manip_judged": judged}}
    edited = [run(0.0, "consistent"), run(0.1, "inconsistent"), run(0.3, "consistent"),
              run(0.6, "inconsistent"), run(1.0, "inconsistent"), run(None, "consistent"),
              {"kind": "splice", "verdict": "consistent", "metrics": {"manip_judged": 0.5}}]
    header, _, color, splice = roc.by_coverage(edited)
    assert header.split(" | ")[1:] == ["0-25 % judged", "25-50 % judged",
                                       "50 % or more |"]
    cells = color.split(" | ")[1:]
    assert cells[0].startswith("1 of 2") and cells[1].startswith("0 of 1")
    assert cells[2].startswith("2 of 2")            # 1.0 falls in the last bin
    assert splice.split(" | ")[1:][2].startswith("0 of 1") and "–" in splice


def test_edits_caught_by_the_share_in_the_truths_reach_and_the_reach_by_preset():
    def run(share, verdict, preset="box"):
        return {"kind": "remove", "verdict": verdict, "preset": preset,
                "metrics": {"manip_in_reach": share, "reach_fraction": 0.6,
                            "reach_judged": share, "judged_seen": 0.9,
                            "depth_error": 0.1 if share is not None else None}}
    edited = [run(0.1, "consistent"), run(0.7, "inconsistent"), run(0.9, "consistent")]
    header, _, remove = roc.by_coverage(edited, "manip_in_reach", "in the truth's reach")
    assert header.startswith("| caught, by the share of the edit in the truth's reach")
    cells = remove.split(" | ")[1:]
    assert cells[0].startswith("0 of 1") and cells[2].startswith("1 of 2")
    rows = roc.by_reach(edited + [run(None, "consistent", "envmap")])
    assert rows[0].split(" | ")[2:] == list(roc.REACH_FIGURES[:-1]) + ["totem_depth_bound |"]
    box = next(r for r in rows if r.startswith("| box floating"))
    assert box.split(" | ")[1:4] == ["3", "0.60", "0.70"]   # photos, medians
    assert roc.by_reach([{"kind": "none", "metrics": {}}]) == []


def test_roc_refuses_photos_of_the_set_that_set_the_line(tmp_path, capsys):
    """A bench holding a calibration seed's photo is refused in one line (exit 2); the
    same bench of another set's seeds is reported."""
    import json

    from verify.verdict.calibration import fit_tail

    cal = fit_tail(np.linspace(0.1, 1.0, 40))
    cal.source["set"] = "calibration"
    cal_path = tmp_path / "cal.json"
    cal_path.write_text(json.dumps(cal.to_json()))

    def bench(seed, where):
        scene = tmp_path / where / f"box-{seed}"
        (scene / "truth").mkdir(parents=True)
        (scene / "truth" / "scene.json").write_text(json.dumps({"preset": "box", "seed": seed}))
        runs = [{"name": f"box-{seed}", "scene": str(scene), "mode": "joint", "status": "ok",
                 "kind": "none", "preset": "box", "placement": "floating",
                 "verdict": "consistent", "score": 0.5, "threshold": 1.0, "statistic": 0.5,
                 "metrics": {}}]
        out = tmp_path / where / "bench"
        out.mkdir()
        (out / "bench.json").write_text(json.dumps({"runs": runs}))
        return str(out)

    assert roc.main([bench(12, "cal"), "--calibration", str(cal_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "calibration set" in err and "box-12" in err
    assert roc.main([bench(31, "dev"), "--calibration", str(cal_path)]) == 0
