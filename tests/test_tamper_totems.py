"""scenes/tamper, the forgers who edit the totems too (issue 61): each kind changes only
what it says, the adaptive forger with no key error is the perfect forger to the 8-bit
level, and bad input is one line and exit 2."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import camera, folder, masks
from scenes.errors import BadInput
from scenes.tamper import edits2d, forger
from scenes.tamper.tamper import KINDS, TOTEM_KINDS, tamper

SIZE = (160, 120)
SPP = 8


def pixels(path) -> np.ndarray:
    """The 8-bit values of a PNG (read_image gives k / 255)."""
    return np.rint(folder.read_image(path) * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """A rendered box scene with truth/ (four totems)."""
    from scenes.synthetic.make import make_scene

    return make_scene(tmp_path_factory.mktemp("syn") / "scene", preset="box", seed=1,
                      size=SIZE, spp=SPP)


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """A 'real photo' folder: no truth/, a textured image, two round totem masks."""
    W, H = SIZE
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[:H, :W]
    image = (0.5 + 0.25 * np.sin(xx / 5.0 + yy / 9.0)[..., None] * [1, 0.5, -1]
             + 0.05 * rng.standard_normal((H, W, 3))).clip(0, 1)
    disc = [(xx - 40) ** 2 + (yy - 95) ** 2 < 14 ** 2,
            (xx - 120) ** 2 + (yy - 95) ** 2 < 14 ** 2]
    K = np.array([[140.0, 0, (W - 1) / 2], [0, 140.0, (H - 1) / 2], [0, 0, 1]])
    return folder.write_scene(tmp_path_factory.mktemp("photo") / "scene", image=image, K=K,
                              masks=disc, radius=0.05, ior=1.5)


def edited(src: Path, out: Path):
    """(changed (H, W) bool, manip_mask, totem mask written, totems, record)."""
    a, b = pixels(src / "image.png"), pixels(out / "image.png")
    changed = (a != b).any(axis=-1)
    manip = folder.read_mask(out / "manip_mask.png")
    tm_path = out / "truth" / "tamper_totem_mask.png"
    tm = folder.read_mask(tm_path) if tm_path.is_file() else np.zeros_like(manip)
    totems = folder.read_scene(src).masks.any(axis=0)
    record = json.loads((out / "truth" / "tamper.json").read_text())
    for rel in ("totems.json", "calib.npy", "totem_masks/totem_000.png"):
        assert (out / rel).read_bytes() == (src / rel).read_bytes()
    assert not (manip & totems).any() and not (tm & ~totems).any()
    assert record["changed_pixels"] == int(manip.sum())
    return changed, manip, tm, totems, record


# --------------------------------------------------------------------------- totem-retouch

@pytest.mark.parametrize("tool", ["clone", "blur", "recolour"])
def test_totem_retouch_changes_only_the_named_totem(synthetic, tmp_path, tool):
    out = tamper(synthetic, tmp_path / "o", kind="totem-retouch", seed=4, tool=tool,
                 totems=[1])
    changed, manip, tm, totems, record = edited(synthetic, out)
    m1 = folder.read_scene(synthetic).masks[1]
    assert changed.any() and not (changed & ~(tm & m1)).any()      # totem 1 only
    assert not manip.any() and record["bbox"] is None                # view untouched
    assert record["totems_edited"] and record["totem_changed_pixels"] == int(tm.sum())
    (e,) = record["totem_edits"]
    assert e["totem"] == 1 and e["tool"] == tool and 0 < e["pixels"] <= m1.sum()
    a, b = pixels(synthetic / "image.png"), pixels(out / "image.png")
    H, W = m1.shape
    v, u = np.mgrid[0:H, 0:W]
    feather = max(1.0, e["radius_px"] / 6)
    inner = m1 & (np.hypot(u - e["centre_px"][0], v - e["centre_px"][1])
                  <= e["radius_px"] - feather)                  # the brush's core
    assert inner.sum() >= 3
    if tool == "clone":                 # the core is the source moved, exactly
        dx, dy = e["offset_px"]
        inner &= masks.shift_mask(m1, dx, dy)
        ys, xs = np.nonzero(inner)
        assert inner.any() and np.array_equal(b[ys, xs], a[ys - dy, xs - dx])
    elif tool == "blur":                # smoother than it was
        lap = lambda im: np.abs(np.diff(im.astype(float), axis=1))[inner[:, 1:]].mean()
        assert lap(b) < lap(a)
    else:                               # other hues
        assert np.abs(b[changed].astype(int) - a[changed]).max() > 30


def test_totem_retouch_drawn_per_seed_also_on_a_photo(photo, tmp_path):
    a = tamper(photo, tmp_path / "a", kind="totem-retouch", seed=1)
    b = tamper(photo, tmp_path / "b", kind="totem-retouch", seed=1)
    c = tamper(photo, tmp_path / "c", kind="totem-retouch", seed=2)
    assert (a / "image.png").read_bytes() == (b / "image.png").read_bytes()
    assert (a / "image.png").read_bytes() != (c / "image.png").read_bytes()
    changed, manip, tm, totems, record = edited(photo, a)
    assert changed.any() and not (changed & ~tm).any() and not manip.any()
    assert len(record["totem_edits"]) == 1            # of two totems, one stays as it was
    # a forgery of it adds its totem mask to the first
    d = tamper(a, tmp_path / "d", kind="totem-retouch", seed=3,
               totems=[1 - record["totem_edits"][0]["totem"]])
    tm2 = folder.read_mask(d / "truth" / "tamper_totem_mask.png")
    assert np.all(tm2[tm]) and tm2.sum() > tm.sum()
    assert json.loads((d / "truth" / "tamper.json").read_text())["history"][0]["seed"] == 1


# --------------------------------------------------------------------------- consistent-paste

def test_consistent_paste_splices_the_view_and_each_totem_upside_down(synthetic, tmp_path):
    out = tamper(synthetic, tmp_path / "o", kind="consistent-paste", seed=2)
    changed, manip, tm, totems, record = edited(synthetic, out)
    assert manip.any() and tm.any()
    assert not (changed & ~(manip | tm)).any()
    # the camera view is the splice of the recorded cutout, exactly
    x, y, w, h = record["box"]
    rgb, matte = edits2d.astronaut_cutout()
    small, cover = edits2d.scaled_cutout(rgb, matte, h, flip=record["flip"])
    want, fp = edits2d.splice(pixels(synthetic / "image.png"), small, cover, x, y,
                              feather_px=record["feather_px"], keep=totems)
    got = pixels(out / "image.png")
    assert np.array_equal(got[~totems], want[~totems]) and np.array_equal(fp & ~totems, manip)
    # each totem holds a small person on the far side of its disc's centre (the person
    # stands above the totems: in the glass, below the centre), a tenth of the size
    scene = folder.read_scene(synthetic)
    for e in record["totem_edits"]:
        m = scene.masks[e["totem"]]
        cx, cy, r = forger.disc(m)
        if e["pixels"]:
            ys, xs = np.nonzero(tm & m)
            assert ys.mean() > cy and (tm & m).sum() < 0.5 * m.sum()
            assert 0.03 < e["scale"] < 0.3
    assert sum(e["visible"] for e in record["totem_edits"]) >= 3


# --------------------------------------------------------------------------- erase-everywhere

def test_erase_everywhere_fills_the_object_in_the_view_and_in_every_totem(synthetic, tmp_path):
    from scenes.synthetic import render, trace

    out = tamper(synthetic, tmp_path / "o", kind="erase-everywhere", seed=0)
    changed, manip, tm, totems, record = edited(synthetic, out)
    oid = record["object"]["id"]
    desc = folder.read_truth(synthetic).scene
    seen = render.shape_ids(desc, totems=True) == oid
    t = trace.tracer(desc)
    hits = trace.totem_hits(desc, trace.camera_points(desc, t)[2], t)
    refracted = np.zeros_like(seen)
    sel = hits.hit_id == oid
    refracted[hits.v[sel], hits.u[sel]] = True
    refracted &= totems
    grow = max(1, round(0.004 * SIZE[0]))
    assert np.all(manip[seen & ~totems]) and not (manip & ~masks.dilate(seen, grow)).any()
    assert refracted.any() and np.all(tm[refracted])
    assert not (tm & ~masks.dilate(refracted, record["totem_grow_px"])).any()
    assert not (changed & ~(manip | tm)).any()
    assert changed[refracted].mean() > 0.5          # the object's image really went
    assert sum(e["visible"] for e in record["totem_edits"]) >= 2


# --------------------------------------------------------------------------- rekey

@pytest.mark.slow
def test_rekey_without_error_is_the_perfect_forger_to_the_bit(synthetic, tmp_path):
    from scenes.synthetic import render
    from scenes.tamper.tamper3d import render8, render_settings

    plain = tamper(synthetic, tmp_path / "remove", kind="remove", seed=0)
    oid = json.loads((plain / "truth" / "tamper.json").read_text())["object"]["id"]
    desc = folder.read_truth(synthetic).scene
    seen = render.shape_ids(desc, totems=True) == oid
    out = tamper(synthetic, tmp_path / "rekey", kind="rekey", seed=0, region=seen,
                 key_error="ior=0,radius=0,pose=exact")
    changed, manip, tm, totems, record = edited(synthetic, out)
    assert record["edit"] == "remove" and record["object"]["id"] == oid
    rs = render_settings(desc)
    perfect = render8(desc, spp=rs["spp"], seed=rs["seed"], exclude_ids=[oid])
    got = pixels(out / "image.png")
    # the camera view is the plain remove's, the totems the render without the object
    assert np.array_equal(got[~totems], pixels(plain / "image.png")[~totems])
    assert np.array_equal(got[totems], perfect[totems])
    assert tm.any() and np.array_equal(tm, changed & totems)
    assert all(e["center_error_m"] == 0 for e in record["totems"])
    assert np.array_equal(manip, folder.read_mask(plain / "manip_mask.png"))


@pytest.mark.slow
def test_rekey_with_a_key_error_draws_the_change_through_other_glass(synthetic, tmp_path):
    exact = tamper(synthetic, tmp_path / "exact", kind="rekey", seed=1, edit="insert",
                   key_error="pose=exact")
    out = tamper(synthetic, tmp_path / "off", kind="rekey", seed=1, edit="insert",
                 key_error="ior=0.05,radius=0.05")
    changed, manip, tm, totems, record = edited(synthetic, out)
    a, b = pixels(exact / "image.png"), pixels(out / "image.png")
    assert np.array_equal(a[~totems], b[~totems])              # the view: the same edit
    assert not (changed & ~(manip | tm)).any()
    assert (np.abs(a.astype(int) - b).max(axis=-1)[totems] > 16).sum() >= 5
    desc = folder.read_truth(synthetic).scene
    true = sorted(desc["totems"], key=lambda t: camera.project(
        np.asarray(desc["K"]), np.asarray(t["center"])[None])[0, 0])
    for e, t in zip(record["totems"], true):
        assert e["guessed"]["ior"] == pytest.approx(t["ior"] + 0.05)
        assert e["guessed"]["radius"] == pytest.approx(t["radius"] * 1.05)
        # posed from the mask with the guessed radius: about 5 % further away
        assert e["center_error_m"] == pytest.approx(0.05 * np.linalg.norm(t["center"]),
                                                    rel=0.3)
    assert record["key_error"] == {"ior": 0.05, "radius": 0.05, "pose": "mask"}


# --------------------------------------------------------------------------- the forger

def test_the_naive_glass_turns_and_shrinks_about_the_disc():
    s = forger.naive_scale(10.0, 140.0)
    assert s == pytest.approx(1.5 / (2 * 0.5) * 10 / 140)
    q = forger.naive_image_point([[70.0, 20.0], [50.0, 90.0]], (50.0, 90.0), 10.0, 140.0)
    assert np.allclose(q[0], [50 - 20 * s, 90 + 70 * s]) and np.allclose(q[1], [50, 90])
    assert forger.naive_scale(10.0, 140.0, ior=1.6) < s     # denser glass, smaller picture


def test_guessed_spheres_keep_the_outline_and_scale_with_the_radius():
    K = camera.intrinsics(*SIZE, 60)
    true = [{"center": [0.3, 0.2, 1.5], "radius": 0.1, "ior": 1.52}]
    m = camera.sphere_silhouette(np.array(true[0]["center"]), 0.1, K, SIZE[::-1])[None]
    exact = forger.guessed_spheres(m, K, true, forger.parse_key_error("pose=exact"))
    assert exact[0] == {"center": [0.3, 0.2, 1.5], "radius": 0.1, "ior": 1.52}
    g = forger.guessed_spheres(m, K, true, forger.parse_key_error("ior=-0.02,radius=0.1"))
    assert g[0]["radius"] == pytest.approx(0.11) and g[0]["ior"] == pytest.approx(1.50)
    assert np.allclose(g[0]["center"], np.multiply(true[0]["center"], 1.1), rtol=0.01)
    with pytest.raises(BadInput, match="not glass"):
        forger.guessed_spheres(m, K, true, forger.parse_key_error("ior=-0.6"))


@pytest.mark.parametrize("spec", ["ior", "ior=abc", "ior=0.02;radius=0.03", "foo=1",
                                  "pose=guess", "ior=nan", "radius=-1", "ior=0.1,ior=0.2",
                                  "ior=2"])
def test_a_malformed_key_error_is_bad_input(spec):
    with pytest.raises(BadInput, match="key-error"):
        forger.parse_key_error(spec)


def test_key_error_parts_and_defaults():
    assert forger.parse_key_error(None) == forger.KeyGuess(0.0, 0.0, "mask")
    g = forger.parse_key_error(" ior=0.02 , radius=-0.03 ")
    assert (g.ior, g.radius, g.pose, g.exact) == (0.02, -0.03, "mask", False)
    assert forger.parse_key_error("pose=exact").exact
    assert forger.parse_key_error({"radius": "0.01"}).radius == 0.01


# --------------------------------------------------------------------------- bad input

def test_the_new_kinds_are_kinds_and_their_options_belong_to_them(photo, tmp_path):
    assert set(TOTEM_KINDS) <= set(KINDS) and KINDS[:6] == (
        "color", "splice", "inpaint", "shift", "remove", "insert")   # the seeds' streams
    for kind, opts in (("color", {"key_error": "ior=0.01"}), ("splice", {"tool": "blur"}),
                       ("rekey", {"totems": [0]}), ("totem-retouch", {"edit": "remove"})):
        with pytest.raises(BadInput, match="applies to"):
            tamper(photo, tmp_path / "o", kind=kind, **opts)
    with pytest.raises(BadInput, match="--totem"):
        tamper(photo, tmp_path / "o", kind="totem-retouch", totems=[2])
    with pytest.raises(BadInput, match="region"):
        tamper(photo, tmp_path / "o", kind="totem-retouch", region=(10, 10, 20, 20))
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, says", [
    (["--kind", "erase-everywhere"], "truth/scene.json"),
    (["--kind", "rekey", "--key-error", "ior=0.02,radius=0.03"], "truth/scene.json"),
    (["--kind", "rekey", "--key-error", "ior=0.02,radius"], "--key-error must be"),
    (["--kind", "totem-retouch", "--totem", "5"], "--totem must name"),
])
def test_cli_bad_input_is_exit_2_one_line(photo, tmp_path, args, says):
    proc = subprocess.run([sys.executable, "-m", "verify.cli", "tamper", str(photo),
                           str(tmp_path / "o"), *args],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert says in lines[0]
    assert not (tmp_path / "o").exists()
