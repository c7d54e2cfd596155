"""benchmarks/surface_study.py: the oracle's variants scored on cached arrays."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "surface_study.py"
_spec = importlib.util.spec_from_file_location("surface_study", _PATH)
ss = importlib.util.module_from_spec(_spec)
sys.modules["surface_study"] = ss                # its dataclasses look their module up
_spec.loader.exec_module(ss)


def _arrays(offsets=(0.0, 0.0), photo_value=0.4, H=256, W=384, res=(24, 32)):
    """Cached arrays of a flat grey scene two totems see everywhere at parallax 10, each
    totem's colour ``photo_value + offset``; every pixel maps to a cell, none a totem's."""
    nt, ns = res
    col = np.stack([np.full((nt, ns, 3), photo_value + o, np.float32) for o in offsets])
    land = np.ones((len(offsets), nt, ns), bool)
    rows = np.minimum(np.arange(H) * nt // H, nt - 1)
    cols = np.minimum(np.arange(W) * ns // W, ns - 1)
    cell = (rows[:, None] * ns + cols[None, :]).astype(np.int32)
    z = np.full(res, 3.0)
    return {"truth_col": col, "truth_land": land, "truth_par": np.full(res, 10.0),
            "photo": np.full((nt, ns, 3), photo_value, np.float32),
            "white": np.full(res, photo_value, np.float32), "zt": z, "zmin": z,
            "zmax": z, "reach": np.ones(res), "cell": cell,
            "totem_px": np.zeros((H, W), bool)}


def test_variant_labels_round_trip():
    v = ss.Variant.parse("gain=totem,white=0.9,edge=0.1,resid=chroma,sigma=75")
    assert (v.gain, v.white, v.edge, v.resid, v.sigma) == ("totem", 0.9, 0.1, "chroma", 75)
    assert ss.Variant.parse(v.label()) == v
    assert ss.Variant.parse("baseline").label() == "baseline"


def test_per_totem_gain_takes_away_a_steady_totem_offset():
    arr = _arrays(offsets=(-0.05, 0.05))
    # Each totem off by 0.05 the opposite way: their mean is the photo's, their spread
    # is not; with a gain per totem both agree with the photo.
    base = ss.score(arr, ss.Variant())
    tot = ss.score(arr, ss.Variant(gain="totem"))
    assert base["e"] == pytest.approx(0.0, abs=2e-3)
    assert tot["e"] == pytest.approx(0.0, abs=1e-6)
    assert tot["z"] < base["z"] + 1e-6


def test_highlights_and_depth_edges_are_left_out():
    arr = _arrays()
    arr["photo"][2:5, 3:7] = 0.95                    # a light the totems see dimmer
    arr["white"][2:5, 3:7] = 0.95
    hit = ss.score(arr, ss.Variant())
    assert hit["e"] > 0.1
    assert ss.score(arr, ss.Variant(white=0.9))["e"] == pytest.approx(0.0, abs=1e-6)
    arr2 = _arrays()
    arr2["photo"][6:9, 8:12] = 0.1                   # a mismatch across a depth edge
    arr2["zmax"] = arr2["zmax"].copy()
    arr2["zmax"][7, 9:11] = 6.0
    assert ss.score(arr2, ss.Variant())["e"] > 0.1
    assert ss.score(arr2, ss.Variant(edge=0.1))["e"] == pytest.approx(0.0, abs=1e-6)


def test_hue_residual_forgives_brightness_only():
    arr = _arrays()
    arr["photo"][:] = 0.5                            # brighter, same grey
    assert ss.score(arr, ss.Variant(resid="chroma"))["e"] == pytest.approx(0.0, abs=1e-6)
    arr["photo"][2:8, 2:8] = (0.6, 0.4, 0.4)         # a redder patch
    assert ss.score(arr, ss.Variant(resid="chroma"))["e"] > 0.05


def test_change_is_the_edit_at_the_photos_blur_and_zero_for_the_source():
    src = _arrays()
    edit = _arrays()
    edit["photo"][2:10, 2:10] = 0.7
    assert ss.change(src, src, ss.Variant()) == 0.0
    assert ss.change(edit, src, ss.Variant()) > 0.1
