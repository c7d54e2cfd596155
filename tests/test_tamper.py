"""scenes/tamper: forged copies change pixels only inside their mask, are repeatable,
never touch the input, and the perfect forger's removal equals a render without the
object."""

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import folder
from scenes.errors import BadInput
from scenes.tamper import edits2d
from scenes.tamper.tamper import KINDS, parse_region, tamper

SIZE = (160, 120)
SPP = 8


# --------------------------------------------------------------------------- fixtures

def pixels(path) -> np.ndarray:
    """The 8-bit values of a PNG (read_image gives k / 255)."""
    return np.rint(folder.read_image(path) * 255).astype(np.uint8)


def folder_hash(path: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        h.update(str(p.relative_to(path)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def make_synthetic(out, seed=1, size=SIZE):
    """A rendered box scene with truth/."""
    from scenes.synthetic.make import make_scene

    return make_scene(out, preset="box", seed=seed, size=size, spp=SPP)


def make_photo(out):
    """A 'real photo' folder: no truth/, a textured image, two round totem masks."""
    W, H = SIZE
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[:H, :W]
    image = (0.5 + 0.25 * np.sin(xx / 7.0)[..., None] * [1, 0.5, -1]
             + 0.05 * rng.standard_normal((H, W, 3))).clip(0, 1)
    masks = [(xx - 40) ** 2 + (yy - 95) ** 2 < 14 ** 2,
             (xx - 120) ** 2 + (yy - 95) ** 2 < 14 ** 2]
    K = np.array([[140.0, 0, (W - 1) / 2], [0, 140.0, (H - 1) / 2], [0, 0, 1]])
    return folder.write_scene(out, image=image, K=K, masks=masks, radius=0.05, ior=1.5)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return make_synthetic(tmp_path_factory.mktemp("syn") / "scene")


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    return make_photo(tmp_path_factory.mktemp("photo") / "scene")


def check_edit(src: Path, out: Path, *, allow_totems=False):
    """Changed pixels lie inside manip_mask (plus the listed totem edits), the mask
    is non-empty, the totems are untouched unless allowed. Returns (changed, mask)."""
    a, b = pixels(src / "image.png"), pixels(out / "image.png")
    assert a.shape == b.shape
    mask = folder.read_mask(out / "manip_mask.png")
    changed = (a != b).any(axis=-1)
    assert mask.any() and changed.any()
    allowed = mask.copy()
    scene = folder.read_scene(src)
    totems = scene.masks.any(axis=0)
    record = json.loads((out / "truth" / "tamper.json").read_text())
    if allow_totems:
        tm = folder.read_mask(out / "truth" / "tamper_totem_mask.png")
        assert not (tm & ~totems).any()                  # totem edits stay in totems
        assert record["totem_changed_pixels"] == int(tm.sum())
        allowed |= tm
    assert not (changed & ~allowed).any(), "pixels changed outside the mask"
    assert not (mask & totems).any()
    if not allow_totems:
        assert not (changed & totems).any()
    assert record["changed_pixels"] == int(mask.sum())
    # Everything else of the folder is copied as it was.
    for rel in ("totems.json", "calib.npy", "totem_masks/totem_000.png"):
        assert (out / rel).read_bytes() == (src / rel).read_bytes()
    return changed, mask, record


# --------------------------------------------------------------------------- 2D kinds

@pytest.mark.parametrize("kind", ["color", "splice"])
def test_2d_kinds_on_synthetic_scene_edit_above_the_totems(synthetic, tmp_path, kind):
    out = tamper(synthetic, tmp_path / kind, kind=kind, seed=3)
    changed, mask, record = check_edit(synthetic, out)
    assert record["kind"] == kind and record["seed"] == 3
    # Above the totems, a few per cent of the image (the paper's sizes).
    top = np.nonzero(folder.read_scene(synthetic).masks.any(axis=(0, 2)))[0].min()
    assert np.nonzero(mask)[0].max() < top
    assert 0.005 < mask.mean() < 0.12


@pytest.mark.parametrize("kind", ["color", "splice", "inpaint"])
def test_2d_kinds_on_photo_stay_in_the_region(photo, tmp_path, kind):
    region = (30, 10, 90, 60)
    before = folder_hash(photo)
    out = tamper(photo, tmp_path / kind, kind=kind, seed=0, region=region)
    changed, mask, _ = check_edit(photo, out)
    x, y, w, h = region
    inside = np.zeros_like(mask)
    inside[y:y + h, x:x + w] = True
    assert not (mask & ~inside).any()
    assert folder_hash(photo) == before
    assert not (out / "truth" / "clean.png").exists()       # no truth invented


def test_inpaint_of_a_region_mask_fills_exactly_it(photo, tmp_path):
    H, W = SIZE[1], SIZE[0]
    region = np.zeros((H, W), bool)
    region[20:40, 60:90] = True
    out = tamper(photo, tmp_path / "o", kind="inpaint", region=region)
    changed, mask, _ = check_edit(photo, out)
    assert np.array_equal(mask, region)


@pytest.mark.parametrize("method", ["telea", "ns"])
def test_inpaint_removes_a_thing_from_a_plain_background(method):
    img = np.full((30, 40, 3), 77, np.uint8)
    img[10:18, 12:25] = np.random.default_rng(1).integers(0, 256, (8, 13, 3))
    hole = np.zeros((30, 40), bool)
    hole[9:19, 11:26] = True
    out, fp = edits2d.inpaint(img, hole, method=method)
    assert np.abs(out.astype(int) - 77).max() <= 3       # the noise (0-255) is gone
    assert np.array_equal(fp, hole)


def test_inpaint_from_truth_removes_a_real_object(synthetic, tmp_path):
    from scenes.synthetic import render

    out = tamper(synthetic, tmp_path / "o", kind="inpaint", seed=1)
    changed, mask, record = check_edit(synthetic, out)
    truth = folder.read_truth(synthetic)
    seen = render.shape_ids(truth.scene, totems=True) == record["object"]["id"]
    assert seen.any() and np.all(mask[seen])            # the whole object is filled


def test_same_seed_same_forgery(photo, synthetic, tmp_path):
    for kind in ("color", "splice"):
        a = tamper(synthetic, tmp_path / f"{kind}a", kind=kind, seed=7)
        b = tamper(synthetic, tmp_path / f"{kind}b", kind=kind, seed=7)
        c = tamper(synthetic, tmp_path / f"{kind}c", kind=kind, seed=8)
        for name in ("image.png", "manip_mask.png"):
            assert (a / name).read_bytes() == (b / name).read_bytes()
        assert (a / "image.png").read_bytes() != (c / "image.png").read_bytes()


# --------------------------------------------------------------------------- 3D kinds

@pytest.mark.slow
def test_remove_equals_a_render_without_the_object(synthetic, tmp_path):
    from scenes.synthetic import render
    from scenes.tamper.tamper3d import render8, render_settings

    before = folder_hash(synthetic)
    out = tamper(synthetic, tmp_path / "rm", kind="remove", seed=0)
    changed, mask, record = check_edit(synthetic, out)
    assert folder_hash(synthetic) == before
    desc = folder.read_truth(synthetic).scene
    rs = render_settings(desc)
    oid = record["object"]["id"]
    # An independent render of the scene without the object, same sampler.
    ref = render8(desc, spp=rs["spp"], seed=rs["seed"], exclude_ids=[oid])
    got = pixels(out / "image.png")
    totems = folder.read_scene(synthetic).masks.any(axis=0)
    d = np.abs(got.astype(int) - ref).max(axis=-1)[~totems]
    assert np.mean(d) < 0.5 and np.percentile(d, 99.5) <= 16
    assert np.array_equal(got[mask], ref[mask])
    seen = render.shape_ids(desc, totems=True) == oid
    assert np.all(mask[seen & ~totems])
    # the source pixels were the object, not its background: they really changed
    assert changed[seen].mean() > 0.5


@pytest.mark.slow
def test_insert_adds_a_visible_object_and_keeps_the_totems(synthetic, tmp_path):
    from scenes.synthetic import render

    out = tamper(synthetic, tmp_path / "ins", kind="insert", seed=0)
    changed, mask, record = check_edit(synthetic, out)
    desc = folder.read_truth(synthetic).scene
    new = dict(desc, objects=desc["objects"] + [record["object"]])
    seen = render.shape_ids(new, totems=True) == record["object"]["id"]
    totems = folder.read_scene(synthetic).masks.any(axis=0)
    assert (seen & ~totems).sum() >= 20
    assert np.all(mask[seen & ~totems])
    assert changed[seen & ~totems].mean() > 0.5


@pytest.mark.slow
def test_shift_moves_the_object_in_camera_and_totem_views(tmp_path):
    # Large enough that the object is more than a speck in the totem views.
    scene = make_synthetic(tmp_path / "s", seed=2, size=(320, 240))
    out = tamper(scene, tmp_path / "sh", kind="shift", seed=0)
    changed, mask, record = check_edit(scene, out, allow_totems=True)
    edited = [e for e in record["totem_edits"] if e["visible"]]
    assert edited and all(e["pixels"] > 0 for e in edited)
    tm = folder.read_mask(out / "truth" / "tamper_totem_mask.png")
    assert changed[tm].any()
    dx, dy = record["shift_px"]
    assert (dx, dy) != (0, 0)
    a, b = pixels(scene / "image.png"), pixels(out / "image.png")
    # Pixels pasted at the new place are the old place's (a pure translation).
    totems = folder.read_scene(scene).masks.any(axis=0)
    H, W = mask.shape
    ys, xs = np.nonzero(mask & ~totems)
    src_y, src_x = ys - dy, xs - dx
    ok = (src_y >= 0) & (src_y < H) & (src_x >= 0) & (src_x < W)
    same = (b[ys[ok], xs[ok]] == a[src_y[ok], src_x[ok]]).all(axis=-1)
    assert same.sum() > 0.3 * mask.sum()


# --------------------------------------------------------------------------- bad input

def test_kinds_needing_truth_refuse_a_photo(photo, tmp_path):
    for kind in ("remove", "insert", "shift"):
        with pytest.raises(BadInput, match="truth"):
            tamper(photo, tmp_path / kind, kind=kind)
        assert not (tmp_path / kind).exists()
    with pytest.raises(BadInput, match="region"):
        tamper(photo, tmp_path / "inp", kind="inpaint")


def test_cli_remove_on_a_photo_is_exit_2_one_line(photo, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "verify.cli", "tamper", str(photo),
                           str(tmp_path / "o"), "--kind", "remove"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("region", [(-1, 0, 10, 10), (0, 0, 0, 5), (150, 100, 20, 20),
                                    (1.5, 2, 3, 4), ("a", 1, 2, 3), (1, 2, 3),
                                    np.ones((5, 5), bool), np.zeros((120, 160), bool)])
def test_bad_region_is_bad_input(photo, tmp_path, region):
    with pytest.raises(BadInput):
        tamper(photo, tmp_path / "o", kind="color", region=region)
    assert not (tmp_path / "o").exists()


def test_region_on_the_totems_only_is_bad_input():
    totems = np.zeros((120, 160), bool)
    totems[80:110, 20:60] = True
    with pytest.raises(BadInput):
        parse_region((25, 85, 10, 10), (120, 160), totems)
    assert parse_region((25, 70, 10, 20), (120, 160), totems).sum() == 100


def test_unknown_kind_and_existing_output(photo, tmp_path):
    with pytest.raises(BadInput, match="kind"):
        tamper(photo, tmp_path / "o", kind="blur")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(BadInput, match="exists"):
        tamper(photo, tmp_path / "full", kind="color")
    with pytest.raises(BadInput):
        tamper(photo, photo, kind="color")
    assert set(KINDS) == {"color", "splice", "inpaint", "shift", "remove", "insert",
                          "totem-retouch", "consistent-paste", "erase-everywhere", "rekey"}


def test_interrupted_run_leaves_nothing_that_looks_finished(photo, tmp_path, monkeypatch):
    def boom(*a, **k):
        raise KeyboardInterrupt

    before = folder_hash(photo)
    monkeypatch.setattr(folder, "write_json", boom)    # the last file written
    with pytest.raises(KeyboardInterrupt):
        tamper(photo, tmp_path / "o", kind="color")
    assert not (tmp_path / "o").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".o.")]
    assert folder_hash(photo) == before


def test_forging_a_forgery_adds_the_masks(photo, tmp_path):
    a = tamper(photo, tmp_path / "a", kind="color", seed=1, region=(10, 5, 50, 40))
    b = tamper(a, tmp_path / "b", kind="color", seed=2, region=(90, 5, 50, 40))
    ma, mb = (folder.read_mask(p / "manip_mask.png") for p in (a, b))
    assert np.all(mb[ma]) and mb.sum() > ma.sum()
    rec = json.loads((b / "truth" / "tamper.json").read_text())
    assert rec["history"][0]["seed"] == 1


# --------------------------------------------------------------------------- edits2d

def test_move_pixels_is_a_translation_with_the_hole_filled():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)
    mask = np.zeros((40, 50), bool)
    mask[10:18, 5:12] = True
    out, fp = edits2d.move_pixels(img, mask, 20, 3)
    assert np.array_equal(out[13:21, 25:32], img[10:18, 5:12])
    assert np.array_equal(out[~fp], img[~fp])
    assert fp.sum() == 2 * mask.sum()
    within = np.zeros_like(mask)
    within[:, :28] = True                                 # the paste is clipped
    out2, fp2 = edits2d.move_pixels(img, mask, 20, 3, within=within)
    assert not fp2[:, 28:].any() and np.array_equal(out2[:, 28:], img[:, 28:])


def test_composite_is_exact_where_alpha_is_zero_and_blends_elsewhere():
    img = np.full((4, 4, 3), 100, np.uint8)
    fg = np.full((4, 4, 3), 200, np.uint8)
    alpha = np.zeros((4, 4))
    alpha[1, 1], alpha[2, 2] = 1.0, 0.5
    out, fp = edits2d.composite(img, fg, alpha)
    assert out[1, 1, 0] == 200 and out[2, 2, 0] == 150 and out[0, 0, 0] == 100
    assert fp.sum() == 2


def test_astronaut_cutout_is_a_person_sized_blob():
    rgb, matte = edits2d.astronaut_cutout()
    assert rgb.shape[:2] == matte.shape
    assert 0.4 < matte.mean() < 0.9                   # a silhouette, not the box
    from scipy import ndimage as ndi
    assert ndi.label(matte)[1] == 1                   # one piece
    # orange suit: the matte's mean colour is red-dominant, unlike the background
    assert rgb[matte].mean(axis=0)[0] > rgb[~matte].mean(axis=0)[0]


@pytest.mark.slow
def test_the_rerendering_kinds_give_the_same_bytes_for_the_same_seed(tmp_path):
    """remove, insert and shift re-render the scene: twice with one seed, the same
    photo and mask byte for byte (shift once differed on a busy machine)."""
    scene = make_synthetic(tmp_path / "s", seed=2, size=(160, 120))
    for kind in ("remove", "insert", "shift"):
        a = tamper(scene, tmp_path / f"{kind}a", kind=kind, seed=3)
        b = tamper(scene, tmp_path / f"{kind}b", kind=kind, seed=3)
        for name in ("image.png", "manip_mask.png"):
            assert (a / name).read_bytes() == (b / name).read_bytes(), (kind, name)
