"""benchmarks/thresholds.py: the verdict's thresholds from held-out untouched checks."""

import importlib.util
import json
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "thresholds.py"
_spec = importlib.util.spec_from_file_location("thresholds", _PATH)
thresholds = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(thresholds)


def test_rule_is_a_quarter_above_the_largest_score():
    scores = {"a": {"RANGE": 0.02, "UNSEEN": 0.004}, "b": {"RANGE": 0.08, "UNSEEN": 0.001}}
    got = thresholds.thresholds(scores, 1.25)
    assert got["RANGE"] == pytest.approx((0.1, 0.08, "b"))
    assert got["UNSEEN"] == pytest.approx((0.005, 0.004, "a"))


def test_finished_checks_are_read_not_rerun(tmp_path, capsys):
    cal, out = tmp_path / "cal", tmp_path / "out"
    for name, s in (("box-11", 0.03), ("envmap-11", 0.09)):
        (cal / name).mkdir(parents=True)
        (cal / name / "image.png").write_bytes(b"")     # never read: the report exists
        rep = out / name / "verify" / "report.json"
        rep.parent.mkdir(parents=True)
        rep.write_text(json.dumps({"verdict": "consistent", "scores": {
            "RANGE": {"score": s, "threshold": 0.14}, "UNSEEN": {"score": s / 10,
                                                                 "threshold": 0.041}}}))
    assert thresholds.main([str(cal), str(out), "--jobs", "1", "--factor", "2"]) == 0
    text = capsys.readouterr().out
    assert "RANGE: largest 0.0900 (envmap-11) -> threshold 0.1800" in text
    assert "UNSEEN: largest 0.0090 (envmap-11) -> threshold 0.0180" in text


def test_no_scene_folders_is_exit_2(tmp_path, capsys):
    assert thresholds.main([str(tmp_path), str(tmp_path / "out")]) == 2
    assert "no scene folders" in capsys.readouterr().err


def test_reverify_verifies_every_scene_again_with_its_fit(tmp_path, monkeypatch, capsys):
    cal, out = tmp_path / "cal", tmp_path / "out"
    calls = []

    def fake_run(cmd, **kw):                 # stands for `python -m verify.cli verify`
        calls.append(cmd[3:5])
        name = Path(cmd[4]).name
        rep = out / name / "verify" / "report.json"
        rep.write_text(json.dumps({"verdict": "consistent", "scores": {
            "UNSEEN": {"score": 0.05, "threshold": 0.06}}}))
        return type("Done", (), {"returncode": 0, "stdout": "", "stderr": ""})()

    for name in ("box-11", "box-12"):
        (cal / name).mkdir(parents=True)
        (cal / name / "image.png").write_bytes(b"")
        rep = out / name / "verify" / "report.json"
        rep.parent.mkdir(parents=True)
        rep.write_text(json.dumps({"verdict": "consistent", "scores": {
            "UNSEEN": {"score": 0.01, "threshold": 0.041}}}))
    monkeypatch.setattr(thresholds.subprocess, "run", fake_run)
    assert thresholds.main([str(cal), str(out), "--jobs", "1", "--reverify"]) == 0
    assert sorted(c[1] for c in calls) == [str(cal / "box-11"), str(cal / "box-12")]
    assert all(c[0] == "verify" for c in calls)
    assert "UNSEEN: largest 0.0500 (box-11) -> threshold 0.0625" in capsys.readouterr().out
