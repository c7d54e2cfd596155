"""benchmarks/sets.py and make_set.py: three sets on disjoint seeds, built resumably."""

import importlib.util
import sys
from pathlib import Path

import pytest

from scenes.synthetic.presets import PRESETS
from scenes.tamper.tamper import KINDS

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "make_set.py"
_spec = importlib.util.spec_from_file_location("make_set", _PATH)
make_set = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_set)
sets = sys.modules["sets"]


def test_overlap_is_refused():
    sets.check_disjoint()                      # the sets as they are
    with pytest.raises(ValueError, match="box seed 5"):
        sets.check_disjoint({"a": {"box": range(1, 6)}, "b": {"box": range(5, 9)}}, {})
    with pytest.raises(ValueError, match="envmap seed 21"):
        sets.check_disjoint({"a": {"envmap": range(20, 23)}})     # a reserved seed
    sets.check_disjoint({"a": {"box": range(1, 6)}, "b": {"envmap": range(1, 6)}}, {})


def test_every_set_uses_only_its_own_seeds():
    owner = {}
    for name in sets.SETS:
        for p in sets.photos(name):
            assert p.seed in sets.SEEDS[name][p.preset]
            assert owner.setdefault((p.preset, p.seed), name) == name


def test_calibration_has_100_untouched_photos_over_every_preset_and_channel():
    photos = sets.photos("calibration")
    assert len(photos) >= 100 and all(p.kind == "none" for p in photos)
    assert {p.preset for p in photos} == set(PRESETS)
    assert {p.channel for p in photos} == set(sets.CHANNELS)


def test_benchmark_has_20_photos_per_kind_pristine_and_at_jpeg75():
    photos = sets.photos("benchmark")
    assert set(sets.SCENE_KINDS + sets.TOTEM_EDITS) == set(KINDS) - {"rekey"}
    for kind in sets.SCENE_KINDS + sets.TOTEM_EDITS:
        for channel in ("pristine", "jpeg75"):
            n = sum(p.kind == kind and p.channel == channel for p in photos)
            assert n >= 20, (kind, channel, n)
    untouched = {p.channel for p in photos if p.kind == "none"}
    assert untouched == set(sets.CHANNELS)
    # the standard set (box and envmap seeds 1-5, every kind, pristine) is part of it
    names = {p.name for p in photos}
    assert {f"{pr}-{s}-{k}" for pr in ("box", "envmap") for s in range(1, 6)
            for k in sets.SCENE_KINDS} <= names


def test_names_and_stages(tmp_path):
    """A photo's folder name says scene, kind and channel; what exists is not redone."""
    p = sets.Photo("window", 12, "splice", "jpeg75")
    assert (p.scene, p.source, p.name) == ("window-12", "window-12-splice",
                                           "window-12-splice+jpeg75")
    assert sets.Photo("box", 1, n_totems=2).name == "box-1-2totems"
    todo = make_set.tasks([p], tmp_path)
    assert [len(todo[s]) for s in ("make", "tamper", "recapture")] == [1, 1, 1]
    (tmp_path / "window-12").mkdir()
    (tmp_path / "window-12-splice").mkdir()
    todo = make_set.tasks([p], tmp_path)
    assert [len(todo[s]) for s in ("make", "tamper", "recapture")] == [0, 0, 1]


def test_standard_set_and_options_as_before(capsys, tmp_path):
    photos = make_set.standard_photos(["box", "envmap"], range(1, 6), sets.SCENE_KINDS,
                                      False)
    assert len(photos) == 70 and {p.channel for p in photos} == {"pristine"}
    assert make_set.main([str(tmp_path), "--first-seed", "11", "--seeds", "8",
                          "--kinds", "", "--dry-run"]) == 0
    assert "16 photos (standard set" in capsys.readouterr().out
    assert make_set.main([str(tmp_path), "--set", "calibration", "--small",
                          "--presets", "tabletop", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "(calibration, 320x240): 2 to make, 0 to tamper, 4 to recapture" in out
    with pytest.raises(SystemExit):
        make_set.main([str(tmp_path), "--set", "benchmark", "--seeds", "3"])


def test_each_sets_cycles_scenes_are_its_own():
    """Cycles seeds are disjoint across sets (as a preset of their own), and
    make_set.py --cycles asks make_cycles_set.py for exactly the set's seeds."""
    sets.check_disjoint()
    with pytest.raises(ValueError, match="cycles seed 5"):
        sets.check_disjoint({"a": {"cycles": range(1, 6)}, "b": {"cycles": range(5, 9)}},
                            {})
    for name, (seeds, edits, remove) in sets.CYCLES.items():
        argv = make_set.cycles_command(Path("out"), name)
        assert argv[:5] == ["out", "--seed", str(seeds.start), "--count", str(len(seeds))]
        assert argv[argv.index("--edits") + 1] == (",".join(edits) or "none")
        assert ("--no-remove" in argv) is (not remove)
        assert argv[argv.index("--samples") + 1] == str(make_set.CYCLES_SAMPLES) == "64"
    assert len(sets.CYCLES["benchmark"][0]) >= 5 and len(sets.CYCLES["calibration"][0]) >= 5
    small = make_set.cycles_command(Path("o"), "benchmark", small=True)
    assert small[4] == "2" and small[-1] == "--small" and "--samples" not in small


def test_cycles_photos_of_the_set_are_recaptured_in_its_channels(tmp_path, monkeypatch):
    """The benchmark's Cycles photos (untouched and edited, its own seeds only) gain a
    +jpeg75 copy seeded by their seed; one found is kept; calibration's gain none."""
    calls = []
    monkeypatch.setattr(make_set, "recapture",
                        lambda src, dst, ch, *, seed: calls.append((src.name, dst.name, ch,
                                                                    seed)))
    for name in ("cycles-room-s301", "cycles-room-s301-color", "cycles-yard-s303-remove",
                 "cycles-room-s301+jpeg75", "cycles-room-s201", "box-1",
                 "cycles-yard-s304-splice+jpeg75", "cycles-yard-s304-splice"):
        (tmp_path / name).mkdir()
    lines = make_set.recapture_cycles(tmp_path, "benchmark")
    assert sorted(calls) == [
        ("cycles-room-s301-color", "cycles-room-s301-color+jpeg75", "jpeg75", 301),
        ("cycles-yard-s303-remove", "cycles-yard-s303-remove+jpeg75", "jpeg75", 303)]
    assert len(lines) == 2 and all(ln.startswith("recaptured ") for ln in lines)
    calls.clear()
    assert make_set.recapture_cycles(tmp_path, "calibration") == [] and calls == []


def test_a_seed_whose_scene_cannot_be_made_is_skipped_with_its_reason(tmp_path):
    """At 32x24 no totem covers 20 pixels: the scene is refused, the set goes on, and
    nothing that looks like a scene is left behind."""
    photo = sets.Photo("envmap", 31)
    line = make_set.make_one(str(tmp_path), photo, (32, 24), 1)
    assert line.startswith(f"skipped {photo.scene}: ") and "fewer than 20 pixels" in line
    assert not (tmp_path / photo.scene / "photo.png").exists()
