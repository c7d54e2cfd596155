"""`totems bench`: runs check over every scene, keeps going past a broken one, fits a
photo and its copies edited outside the totems once, writes bench.json, bench.csv and
bench.md."""

import csv
import io
import json
import shutil

import pytest

from scenes.synthetic.make import make_scene
from scenes.tamper.tamper import tamper
from test_cli import totems

pytestmark = pytest.mark.slow


def test_bench_records_a_failing_scene_and_completes_the_others(tmp_path):
    root = tmp_path / "set"
    scene = make_scene(root / "box-1", preset="box", seed=1, size=(160, 120), spp=4)
    tamper(scene, root / "box-1-color", kind="color", seed=1)
    broken = root / "box-1-broken"
    shutil.copytree(scene, broken)
    (broken / "totems.json").write_text(json.dumps({"radius": -0.1, "ior": 1.52}))

    out = tmp_path / "bench"
    proc = totems("bench", root, "--out", out, "--no-table1")
    assert proc.returncode == 0, proc.stderr
    for name in ("bench.json", "bench.csv", "bench.md"):
        assert (out / name).is_file()

    bench = json.loads((out / "bench.json").read_text())
    runs = {r["name"]: r for r in bench["runs"]}
    assert set(runs) == {"box-1", "box-1-color", "box-1-broken"}
    assert runs["box-1-broken"]["status"] == "failed"
    assert "radius" in runs["box-1-broken"]["error"]
    for name in ("box-1", "box-1-color"):
        r = runs[name]
        assert r["status"] == "ok" and r["verdict"] in ("consistent", "inconsistent",
                                                        "unverifiable")
        assert r["metrics"]["recon_L1"] is not None
    assert runs["box-1-color"]["kind"] == "color"
    # The colour edit leaves the totems alone: it reuses box-1's fit instead of fitting.
    assert runs["box-1-color"]["fit_from"] == "box-1" and "fit_from" not in runs["box-1"]
    assert bench["fits"] == 2
    stages = bench["summary"]["time_per_stage_s"]
    assert "verify" in stages and all(k in ("fit", "verify") or "_s" in k
                                      for k in stages)      # times only, no ray counts
    assert runs["box-1-color"]["metrics"]["patch_ap_L1"] is not None

    rows = list(csv.DictReader((out / "bench.csv").open()))
    assert {r["name"]: r["status"] for r in rows} == {
        "box-1": "ok", "box-1-color": "ok", "box-1-broken": "failed"}
    held = {r["name"]: r["holdout_L1"] for r in rows}     # the fit's, shared by the copy
    assert float(held["box-1"]) == pytest.approx(runs["box-1"]["holdout"]["L1"])
    assert held["box-1-color"] == held["box-1"] and held["box-1-broken"] == ""
    md = (out / "bench.md").read_text()
    assert "Failed runs" in md and "box-1-broken" in md and "| color |" in md

    # --reverify: the same verdicts from the fit already there, which is left untouched
    fit_json = out / "runs" / "box-1-joint" / "fit" / "fit.json"
    before = fit_json.read_bytes(), fit_json.stat().st_mtime_ns
    proc = totems("bench", root, "--out", out, "--no-table1", "--reverify")
    assert proc.returncode == 0, proc.stderr
    again = json.loads((out / "bench.json").read_text())
    rerun = {r["name"]: r for r in again["runs"]}
    assert rerun["box-1"]["reverified"] and again["fits"] == 1     # only the broken one
    assert (fit_json.read_bytes(), fit_json.stat().st_mtime_ns) == before
    for name in ("box-1", "box-1-color"):
        assert rerun[name]["verdict"] == runs[name]["verdict"]
        assert rerun[name]["metrics"]["recon_L1"] == pytest.approx(   # recon.png: 8 bit
            runs[name]["metrics"]["recon_L1"], abs=1e-3)
    assert "verified again" in (out / "bench.md").read_text()


def test_the_csv_carries_the_totem_check():
    from verify.batch.bench import csv_text

    run = {"name": "a", "verdict": "inconsistent", "inconsistent_reasons": ["photo", "totem"],
           "totem_check": {"named": [0, 2], "totems": [{"lead": 1.5}, {"lead": -1.5},
                                                       {"lead": None}]}}
    (row,) = csv.DictReader(io.StringIO(csv_text([run])))
    assert row["inconsistent_reasons"] == "photo;totem" and row["totems_named"] == "0;2"
    assert float(row["totem_lead"]) == 1.5
    (bare,) = csv.DictReader(io.StringIO(csv_text([{"name": "b"}])))
    assert bare["totems_named"] == "" and bare["totem_lead"] == ""
