"""The Cycles scene description (benchmarks/cycles/design.py, pure numpy): the ablation
switches change only what they name, and leave the drawn scene as it was by default."""

import argparse
import json

import pytest

from benchmarks.cycles import design


def _args(*argv):
    ap = argparse.ArgumentParser()
    design.scene_options(ap)
    return ap.parse_args(list(argv))


def test_defaults_leave_the_scene_as_drawn():
    desc = design.describe(101, size=(160, 120), samples=16)
    before = json.dumps(desc, sort_keys=True)
    out = design.ablate(desc, _args("--seed", "101"))
    assert json.dumps(out, sort_keys=True) == before
    assert "glass" not in out and "totem_shadows" not in out      # Blender's defaults


def test_each_switch_changes_what_it_names_only():
    desc = design.describe(103, size=(160, 120), samples=16)
    before = json.dumps(desc, sort_keys=True)
    out = design.ablate(desc, _args("--view", "Standard", "--denoise", "off",
                                    "--filter", "BOX", "--filter-width", "1.0",
                                    "--glass", "refraction", "--totem-shadows", "off"))
    assert json.dumps(desc, sort_keys=True) == before                # input untouched
    p = out["pipeline"]
    assert (p["view_transform"], p["denoise"], p["filter"], p["filter_width"]) == \
        ("Standard", False, "BOX", 1.0)
    assert out["glass"] == "refraction" and out["totem_shadows"] is False
    rest = {k: v for k, v in p.items()
            if k not in ("view_transform", "denoise", "filter", "filter_width")}
    assert rest == {k: v for k, v in desc["pipeline"].items() if k in rest}
    assert out["totems"] == desc["totems"] and out["camera"] == desc["camera"]


def test_filter_width_must_be_positive():
    with pytest.raises(ValueError):
        design.ablate(design.describe(101, size=(160, 120)), _args("--filter-width", "0"))
