"""The totems checked against each other, end to end as a user runs `totems check`: on a
rendered 320 x 240 box scene with four totems, one totem retouched (a patch of it
recoloured, the camera view untouched) is named in report.json and report.html, the
photo is inconsistent with the reason "totem" (exit 1), and the region named lies in the
retouched patch; the untouched photo names no totem and stays consistent (exit 0)."""

import json

import numpy as np
import pytest

from scenes import folder
from scenes.synthetic.make import make_scene
from scenes.tamper.tamper import tamper
from test_cli import totems

pytestmark = pytest.mark.slow

RETOUCHED = 1          # the second totem from the left


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("totemcheck")
    plain = make_scene(root / "box-1", preset="box", seed=1, size=(320, 240), spp=16)
    edited = tamper(plain, root / "box-1-recolour", kind="totem-retouch", seed=1,
                    tool="recolour", totems=[RETOUCHED])
    return plain, edited


@pytest.fixture(scope="module")
def checked(scenes, tmp_path_factory):
    """(exit code, stdout, report.json, report.html) of `totems check` on each photo."""
    out = {}
    for name, scene in zip(("plain", "edited"), scenes):
        dst = tmp_path_factory.mktemp("out") / name
        proc = totems("check", scene, "--out", dst)
        assert proc.returncode in (0, 1), proc.stdout + proc.stderr
        out[name] = (proc.returncode, proc.stdout,
                     json.loads((dst / "verify" / "report.json").read_text()),
                     (dst / "verify" / "report.html").read_text())
    return out


def test_a_retouched_totem_is_named_and_the_photo_inconsistent(checked):
    code, stdout, report, html = checked["edited"]
    assert code == 1 and report["verdict"] == "inconsistent"
    assert "totem" in report["inconsistent_reasons"]
    check = report["totem_check"]
    assert check["named"] == [RETOUCHED]
    t = check["totems"][RETOUCHED]
    assert t["named"] and t["lead"] > check["line"]
    assert all(not o["named"] for o in check["totems"] if o["totem"] != RETOUCHED)
    assert f"totem {RETOUCHED + 1} from the left disagrees" in stdout
    assert "The totems checked against each other" in html
    assert f"Totem {RETOUCHED + 1} disagrees with the other totems" in html


def test_the_region_named_lies_in_the_retouched_patch(scenes, checked):
    patch = folder.read_mask(scenes[1] / "truth" / "tamper_totem_mask.png")
    u, v = checked["edited"][2]["totem_check"]["totems"][RETOUCHED]["where"]["centre_px"]
    assert patch[int(round(v)), int(round(u))]
    rec = json.loads((scenes[1] / "truth" / "tamper.json").read_text())["totem_edits"][0]
    assert np.hypot(u - rec["centre_px"][0], v - rec["centre_px"][1]) < rec["radius_px"]


def test_the_untouched_photo_names_no_totem(checked):
    code, stdout, report, html = checked["plain"]
    assert code == 0 and report["verdict"] == "consistent"
    assert report["totem_check"]["named"] == [] and report["inconsistent_reasons"] == []
    assert all(t["lead"] is None or t["lead"] < report["totem_check"]["line"]
               for t in report["totem_check"]["totems"])
    assert "No totem's view stands out from the others'" in html
    assert "disagrees with the other totems" not in stdout
