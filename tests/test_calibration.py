"""verify/calibration and benchmarks/calibrate_verdict: p-values from untouched photos.

The tail model must give the false-alarm rate it is set for on samples it was not fitted
on, p-values below the 1/(n+1) a rank allows, and an interval that covers a known rate;
the verdict calls a photo inconsistent exactly when its p-value is below alpha; and the
calibration refuses photos of another set.
"""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from scenes.errors import BadInput
from scenes.synthetic.presets import PRESETS
from verify.metrics import patches
from verify.verdict import calibration, verdict
from verify_cases import make_scene

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "calibrate_verdict.py"
_spec = importlib.util.spec_from_file_location("calibrate_verdict", _PATH)
calibrate_verdict = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(calibrate_verdict)


@pytest.mark.parametrize("dist", [stats.gamma(2.0, scale=0.3), stats.lognorm(0.5),
                                  stats.genpareto(0.2)])
def test_the_line_holds_its_rate_on_fresh_samples(dist):
    rng = np.random.default_rng(1)
    rates = []
    for _ in range(40):
        cal = calibration.fit_tail(dist.rvs(120, random_state=rng))
        assert cal.p_value(cal.line()) == pytest.approx(cal.alpha, rel=1e-6)
        rates.append(dist.sf(cal.line()))          # the true false-alarm rate it gives
    # Set for 1 %: over many calibrations the true rate averages near it, never wild.
    assert 0.004 < np.mean(rates) < 0.02, np.mean(rates)
    assert max(rates) < 0.05


def test_p_values_fall_with_the_statistic_and_below_the_rank():
    t = stats.gamma(2.0, scale=0.3).rvs(120, random_state=np.random.default_rng(2))
    cal = calibration.fit_tail(t)
    grid = np.linspace(0.0, 3 * t.max(), 200)
    p = np.array([cal.p_value(x) for x in grid])
    assert np.all(np.diff(p) <= 1e-12) and p[0] == pytest.approx(1.0)
    assert cal.p_value(2 * t.max()) < 1 / (cal.n + 1)
    with pytest.raises(BadInput):
        cal.p_value(float("nan"))
    back = calibration.Calibration.from_json(json.loads(json.dumps(cal.to_json())))
    assert back.line() == pytest.approx(cal.line(), rel=1e-5)


def test_a_short_tail_is_not_bounded():
    # Uniform statistics have a bounded tail (xi < 0); the model keeps xi = 0, so a
    # statistic past the largest still has a p-value above zero.
    cal = calibration.fit_tail(np.linspace(0.0, 1.0, 100))
    assert cal.xi == 0.0 and 0.0 < cal.p_value(1.5) < cal.alpha


def test_clopper_pearson_and_held_out_groups():
    lo, hi = calibration.clopper_pearson(0, 60)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 60), rel=1e-6)
    lo, hi = calibration.clopper_pearson(5, 100)
    assert lo < 0.05 < hi
    t = stats.gamma(2.0, scale=0.3).rvs(150, random_state=np.random.default_rng(3))
    t[:30] += 5.0                                    # one group far above the others
    held = calibration.leave_one_group_out(t, np.repeat(list("abcde"), 30))
    assert held["a"] == (30, 30) and held["all"][1] == 150
    assert sum(held[g][0] for g in "bcde") <= 4


def test_the_verdict_reports_the_p_values_beside_its_line():
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    cal = calibration.fit_tail(np.linspace(0.1, 2.0, 50))
    base = np.zeros((10, 10))
    for bump in (0.05, 0.3, 0.6):
        s = base.copy()
        s[0, :3] += bump
        d = verdict.decide({"RANGE": s}, np.ones_like(s), g, thresholds={"RANGE": 0.1},
                           calibration=cal)
        assert d.statistic == pytest.approx(bump / 0.1) == pytest.approx(d.score)
        assert d.p_value == pytest.approx(cal.p_value(d.statistic))
        assert d.line_p_value == pytest.approx(cal.p_value(1.0))
        assert (d.verdict == "inconsistent") == (d.score > 1.0)
        assert (d.p_value < d.line_p_value) == (d.score > 1.0)


def _bench(tmp_path, rows, unverifiable=()):
    """A bench folder of finished checks: (name, preset, seed, statistic) each, the
    statistic a number or {metric: score} (the report's per-metric scores); the photos
    named in ``unverifiable`` were called so."""
    runs = []
    for name, preset, seed, stat in rows:
        scene = tmp_path / "set" / name
        (scene / "truth").mkdir(parents=True)
        (scene / "truth" / "scene.json").write_text(json.dumps(
            {"preset": preset, "seed": seed, "totems": [{}] * 4}))
        rep = tmp_path / "bench" / "runs" / f"{name}-joint" / "verify" / "report.json"
        rep.parent.mkdir(parents=True)
        rep.write_text(json.dumps(
            ({"statistic": stat} if not isinstance(stat, dict) else
             {"statistic": max(v / verdict.THRESHOLDS[m] for m, v in stat.items()),
              "scores": {m: {"score": v} for m, v in stat.items()}})
            | {"verdict": "unverifiable" if name in unverifiable else "consistent"}))
        runs.append({"scene": str(scene), "name": name, "mode": "joint", "status": "ok"})
    (tmp_path / "bench" / "bench.json").write_text(json.dumps({"runs": runs}))
    return tmp_path / "bench"


def test_the_calibration_refuses_the_benchmarks_seeds(tmp_path, capsys):
    ok = [(f"{p}-{s}" + ("+jpeg75" if s > 14 else ""), p, s, 0.01 * s * (1 + k))
          for k, p in enumerate(("box", "envmap", "window")) for s in range(11, 19)]
    bench = _bench(tmp_path / "a", ok)
    out = tmp_path / "cal.json"
    assert calibrate_verdict.main([str(bench), "--write", str(out)]) == 0
    cal = calibration.load(out)
    assert cal.n == 24 and cal.source["channels"] == ["jpeg75", "pristine"]
    assert cal.source["seeds"] == "11-18"
    printed = capsys.readouterr().out
    assert "| box | 8 |" in printed and "| jpeg75 | 12 |" in printed

    bench = _bench(tmp_path / "b", ok + [("box-3", "box", 3, 0.2)])
    assert calibrate_verdict.main([str(bench)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "box seed 3 belongs to benchmark" in err


def test_the_calibration_takes_its_own_cycles_seeds_only(tmp_path, capsys):
    rows = [(f"{p}-{s}", p, s, 0.01 * s * (1 + k))
            for k, p in enumerate(("box", "envmap")) for s in range(11, 19)]
    cyc = [(f"cycles-room-s{s}", "cycles-room", s, 0.002 * s) for s in (201, 203, 207)]
    assert calibrate_verdict.main([str(_bench(tmp_path / "a", rows + cyc))]) == 0
    assert "| cycles-room | 3 |" in capsys.readouterr().out
    dev = [("cycles-room-s103", "cycles-room", 103, 0.3)]        # development's seed
    assert calibrate_verdict.main([str(_bench(tmp_path / "b", rows + dev))]) == 2
    assert "cycles-room seed 103 belongs to development" in capsys.readouterr().err


def test_a_set_of_one_channel_calibrates_without_holding_it_out(tmp_path, capsys):
    rows = [(f"{p}-{s}", p, s, 0.01 * s * (1 + k))
            for k, p in enumerate(("box", "envmap", "window")) for s in range(11, 19)]
    assert calibrate_verdict.main([str(_bench(tmp_path, rows))]) == 0
    printed = capsys.readouterr().out
    assert "| window | 8 |" in printed and "| pristine |" not in printed


def test_a_group_of_high_untouched_scores_is_seen_pulling_the_line_up(tmp_path, capsys):
    rng = np.random.default_rng(7)
    rows = [(f"{p}-{s}", p, s, float(rng.gamma(2.0, 0.1)))
            for p in ("box", "envmap", "window") for s in range(11, 19)]
    rows += [(f"tabletop-{s}", "tabletop", s, float(1.0 + rng.gamma(2.0, 0.3)))
             for s in range(11, 15)]
    t = np.array([r[3] for r in rows])
    groups = [r[1] for r in rows]
    pull = calibration.line_without(t, groups, alpha=0.05)
    others = calibration.fit_tail(t[np.array(groups) != "tabletop"]).line(0.05)
    assert pull["tabletop"] == pytest.approx(others)
    assert pull["tabletop"] < 0.8 * pull["all"]                  # the high group lifts it
    assert abs(pull["box"] - pull["all"]) < abs(pull["tabletop"] - pull["all"])
    assert calibrate_verdict.main([str(_bench(tmp_path, rows))]) == 0
    printed = capsys.readouterr().out
    assert "line at p = 0.05 without it" in printed
    assert "| tabletop | 4 |" in printed and f"| {pull['tabletop']:.3f} |" in printed


def test_unverifiable_photos_do_not_set_the_line(tmp_path, capsys):
    rng = np.random.default_rng(3)
    rows = [(f"{p}-{s}", p, s, float(rng.gamma(2.0, 0.1)))
            for p in ("box", "envmap", "window") for s in range(11, 19)]
    high = [("box-11-resting", "box", 11, 2.0), ("window-12-resting", "window", 12, 1.5)]
    out_all, out_judged = tmp_path / "all.json", tmp_path / "judged.json"
    assert calibrate_verdict.main([str(_bench(tmp_path / "a", rows + high)),
                                   "--write", str(out_all)]) == 0
    assert calibrate_verdict.main([str(_bench(tmp_path / "b", rows + high,
                                              unverifiable={h[0] for h in high})),
                                   "--write", str(out_judged)]) == 0
    assert "left out 2 unverifiable photo(s)" in capsys.readouterr().out
    judged = calibration.load(out_judged)
    assert judged.n == len(rows) and judged.source["unverifiable_left_out"] == 2
    assert judged.line(0.05) == pytest.approx(
        calibration.fit_tail([r[3] for r in rows]).line(0.05))
    assert judged.line(0.05) < calibration.load(out_all).line(0.05)


def test_the_statistics_are_computed_at_the_shipped_thresholds(tmp_path):
    rows = [(f"{p}-{s}", p, s, {"RANGE": 0.02 * s * (1 + k), "UNSEEN": 0.01 * s})
            for k, p in enumerate(("box", "envmap", "window")) for s in range(11, 19)]
    bench = _bench(tmp_path, rows)
    for rep in bench.glob("runs/*/verify/report.json"):   # verified at other thresholds
        d = json.loads(rep.read_text())
        rep.write_text(json.dumps({**d, "statistic": 3.0 * d["statistic"]}))
    out = tmp_path / "cal.json"
    assert calibrate_verdict.main([str(bench), "--write", str(out)]) == 0
    cal = calibration.load(out)
    want = sorted(max(v / verdict.THRESHOLDS[m] for m, v in r[3].items()) for r in rows)
    np.testing.assert_allclose(sorted(cal.statistics), want, rtol=1e-5)
    assert cal.source["thresholds"] == verdict.THRESHOLDS


def test_per_metric_thresholds_put_each_metric_on_its_own_spread(tmp_path, capsys):
    rng = np.random.default_rng(3)
    rows = []
    for k, p in enumerate(("box", "envmap", "window", "outdoor", "tabletop")):
        for s in range(11, 19):            # RANGE's untouched scores ten times UNSEEN's
            u = rng.lognormal(0.0, 0.4, 3)
            rows.append((f"{p}-{s}", p, s, {"RANGE": 0.1 * u[0], "UNSEEN": 0.01 * u[1],
                                            "ABSENT": 0.02 * u[2]}))
    out = tmp_path / "cal.json"
    bench = _bench(tmp_path / "a", rows)
    assert calibrate_verdict.main([str(bench), "--per-metric", "0.9", "--line-at", "0.05",
                                   "--write", str(out)]) == 0
    chosen = calibration.load(out).source["thresholds"]
    q = {m: np.quantile([r[3][m] for r in rows], 0.9) for m in chosen}
    assert chosen["RANGE"] / chosen["UNSEEN"] == pytest.approx(q["RANGE"] / q["UNSEEN"],
                                                                rel=0.05)
    assert chosen["UNSEEN"] < 0.5 * verdict.THRESHOLDS["UNSEEN"]
    cal = calibration.load(out)
    assert cal.p_value(1.0) == pytest.approx(0.05, rel=0.05)
    over = sum(max(v / chosen[m] for m, v in r[3].items()) > 1 for r in rows)
    assert 0 < over <= 5                   # about 5 % of 40 over the line
    assert "thresholds RANGE" in capsys.readouterr().out

    no_absent = [(n, p, s, {m: v for m, v in d.items() if m != "ABSENT"})
                 for n, p, s, d in rows]
    assert calibrate_verdict.main([str(_bench(tmp_path / "b", no_absent)), "--per-metric",
                                   "0.9", "--line-at", "0.05"]) == 2
    assert "no photo was judged by ABSENT" in capsys.readouterr().err


def test_the_shipped_calibration_reads_and_puts_the_line_near_five_percent():
    import sets

    cal = calibration.load()
    assert cal.n >= 20 and cal.source["set"] == "calibration"
    # the seeds it was made from are the calibration set's: each scene where the file
    # lists them (calibrations since 2026-12-07), else the range's ends
    scenes = [s.split(":") for s in cal.source.get("scenes", [])]
    for preset, seed in scenes:
        assert sets.owner(preset, int(seed)) == "calibration", (preset, seed)
    first, last = map(int, cal.source["seeds"].split("-"))
    assert any(sets.owner(p, first) == "calibration" for p in cal.source["presets"])
    assert any(sets.owner(p, last) == "calibration" for p in cal.source["presets"])
    presets = set(cal.source["presets"])
    assert set(PRESETS) <= presets
    assert all(p in PRESETS or p.startswith("cycles-") for p in presets)
    assert cal.p_value(cal.line()) == pytest.approx(calibration.ALPHA, rel=1e-6)
    # the verdict's line (score 1): the word and the p-value agree, about 5 %
    assert 0.02 <= cal.p_value(1.0) <= 0.1
    # statistics computed at thresholds the verdict no longer uses would misplace p
    from verify.verdict.verdict import THRESHOLDS
    assert cal.source.get("thresholds", THRESHOLDS) == THRESHOLDS
