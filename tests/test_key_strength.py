"""benchmarks/key_strength.py: the adaptive forger's catches per key level, read from a
bench and the photos' truth/tamper.json."""

import importlib.util
import json
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "key_strength.py"
_spec = importlib.util.spec_from_file_location("key_strength", _PATH)
ks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ks)

EXACT = {"ior": 0.0, "radius": 0.0, "pose": "exact"}
MASK = {"ior": 0.0, "radius": 0.0, "pose": "mask"}
K5 = {"ior": 0.05, "radius": 0.05, "pose": "mask"}


def photo(root: Path, name: str, source: str, key=None, *, verdict="consistent",
          statistic=0.5, reasons=(), holdout=0.05, status="ok") -> dict:
    """A photo folder with its truth/tamper.json, and its bench.json run."""
    d = root / name
    (d / "truth").mkdir(parents=True)
    rec = {"kind": "rekey" if key else "remove", "source": {"folder": source},
           **({"key_error": key} if key else {})}
    (d / "truth" / "tamper.json").write_text(json.dumps(rec))
    return {"name": name, "scene": str(d), "kind": rec["kind"], "mode": "joint",
            "status": status, "verdict": verdict, "statistic": statistic,
            "inconsistent_reasons": list(reasons), "holdout": {"L1": holdout},
            "preset": "box", "threshold": 1.0}


@pytest.fixture
def bench(tmp_path):
    runs = [
        # the key held: never caught
        photo(tmp_path, "a-exact", "a", EXACT, statistic=0.4, holdout=0.04),
        photo(tmp_path, "b-exact", "b", EXACT, statistic=0.6, holdout=0.06),
        # the key from the masks: one caught by a totem
        photo(tmp_path, "a-mask", "a", MASK, verdict="inconsistent", statistic=0.7,
              reasons=["totem"]),
        photo(tmp_path, "b-mask", "b", MASK, statistic=0.8),
        # 5 % off: two caught of three, one unverifiable
        photo(tmp_path, "a-k5", "a", K5, verdict="inconsistent", statistic=1.5,
              reasons=["photo"], holdout=0.10),
        photo(tmp_path, "b-k5", "b", K5, verdict="inconsistent", statistic=2.5,
              reasons=["photo", "totem"], holdout=0.12),
        photo(tmp_path, "c-k5", "c", K5, verdict="unverifiable", statistic=0.9,
              holdout=0.20),
        photo(tmp_path, "d-k5", "d", K5, status="failed"),
        # the plain removals: of a and b kept, of z (no rekey photo) left out
        photo(tmp_path, "a-remove", "a", statistic=0.3),
        photo(tmp_path, "b-remove", "b", verdict="inconsistent", statistic=1.2,
              reasons=["photo"]),
        photo(tmp_path, "z-remove", "z", verdict="inconsistent", statistic=9.0,
              reasons=["photo"]),
        {"name": "a", "scene": str(tmp_path / "a"), "kind": "none", "mode": "joint",
         "status": "ok", "verdict": "consistent", "statistic": 0.2},
    ]
    out = tmp_path / "bench"
    out.mkdir()
    (out / "bench.json").write_text(json.dumps({"runs": runs}))
    return out


def rows_of(bench: Path) -> list[dict]:
    runs = []
    for r in ks.load_runs([bench]):
        lv = ks.level_of(r)
        if lv is not None:
            runs.append({**r, "level": lv})
    return ks.table(runs)


def test_table_counts_each_level_in_order_with_its_interval(bench):
    from verify.verdict.calibration import clopper_pearson

    rows = rows_of(bench)
    assert [t["level"] for t in rows] == [(0.0, 0.0, "exact"), (0.0, 0.0, "mask"),
                                         (0.05, 0.05, "mask"), (None, None, "none")]
    exact, mask, k5, none = rows
    assert (exact["n"], exact["caught"], exact["lo"]) == (2, 0, 0.0)
    assert exact["hi"] == pytest.approx(clopper_pearson(0, 2)[1]) and exact["hi"] < 1
    assert (mask["caught"], mask["by_totem"], mask["by_photo"]) == (1, 1, 0)
    # the failed run is left out: three photos, two caught, one unverifiable
    assert (k5["n"], k5["caught"], k5["unverifiable"]) == (3, 2, 1)
    assert (k5["by_photo"], k5["by_totem"]) == (2, 1)
    assert (k5["lo"], k5["hi"]) == pytest.approx(clopper_pearson(2, 3))
    assert k5["lo"] == pytest.approx(0.0943, abs=1e-3)
    assert k5["median_statistic"] == 1.5 and k5["median_holdout"] == 0.12
    # the forger without a key: only the sources that have rekey photos
    assert none["n"] == 2 and none["caught"] == 1 and none["sources"] == ["a", "b"]
    assert none["label"] == "no key (totems untouched)"


def test_main_prints_the_table_and_draws_the_curve(bench, tmp_path, capsys):
    png = tmp_path / "curve.png"
    assert ks.main([str(bench), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "| index +0.05, radius +5 %, centres from the masks | 3 | 2 of 3 (9-99 %)" in out
    assert "1 rekey or remove runs failed" in out
    # each scene's statistic per level beside its untouched photo's (a's: 0.2)
    assert "| a | 0.20 | 0.40 | 0.70 * | 1.50 * | 0.30 |" in out
    assert "| c | – | – | – | 0.90 (u) | – |" in out
    assert png.is_file() and png.stat().st_size > 1000
