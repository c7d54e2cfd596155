"""`totems verify` / `totems check` end to end on a rendered scene, as a user runs them.

An untouched 320 x 240 box scene is consistent (exit 0); the same photo with a large
colour patch pasted above the totems is inconsistent (exit 1) and the report names
patches on it. Both again through a JPEG of quality 75: the untouched copy stays
consistent with a p-value that is not small, the patch is still found with a small one
(below 5 % and below the threshold's own). A fit is tied to the totem pixels, masks, camera and key: the untouched
photo's fit serves a copy edited outside the totems, and is refused (exit 2, one line)
for a photo whose totem pixels changed. The fit keeps the totem rays, which judge the
patch on their own (CORROB); a fit folder written before it kept them still verifies.
"""

import json
import shutil

import numpy as np
import pytest

from scenes import folder
from scenes.synthetic.make import make_scene
from test_cli import assert_one_line_error, totems

SQUARE = (8, 96, 72, 160)   # x0, y0, x1, y1: 64 px above the totems, on the wall and floor
                            # the totems establish (box 31, a development seed)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return make_scene(tmp_path_factory.mktemp("check") / "box-31", preset="box", seed=31,
                      size=(320, 240), spp=16)


@pytest.fixture(scope="module")
def tampered(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("check") / "box-31-square"
    shutil.copytree(scene, out)
    image = folder.read_image(out / "image.png")
    x0, y0, x1, y1 = SQUARE
    image[y0:y1, x0:x1] = (1.0, 0.0, 1.0)
    mask = np.zeros(image.shape[:2], bool)
    mask[y0:y1, x0:x1] = True
    folder.write_image(out / "image.png", image)
    folder.write_image(out / "manip_mask.png", mask)
    return out


@pytest.fixture(scope="module")
def verified(scene, tmp_path_factory):
    """``totems verify`` with no fit yet: it fits, then verifies (out folder, process)."""
    out = tmp_path_factory.mktemp("check") / "out"
    return out, totems("verify", scene, "--out", out)


def test_verify_without_a_fit_fits_and_passes_the_untouched_photo(verified):
    out, proc = verified
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (out / "fit" / "fit.json").is_file()
    report = json.loads((out / "verify" / "report.json").read_text())
    assert report["verdict"] == "consistent"
    assert report["score"] <= report["threshold"]
    assert report["p_value"] > 0.05
    assert 0.1 < report["protected_fraction"] <= 1.0


def test_through_jpeg_75_the_untouched_copy_passes_and_the_patch_is_found(
        scene, tampered, tmp_path):
    plain, edited = tmp_path / "jpeg75", tmp_path / "square-jpeg75"
    for src, dst in ((scene, plain), (tampered, edited)):
        proc = totems("recapture", src, dst, "--jpeg", 75)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert (dst / "image.jpg").is_file()
    proc = totems("check", plain, "--out", tmp_path / "a")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "a" / "verify" / "report.json").read_text())
    assert report["verdict"] == "consistent" and report["p_value"] > 0.05
    # The square lies above the totems: the JPEG copies share their totem pixels, so the
    # untouched copy's fit serves the edited one.
    proc = totems("verify", edited, "--fit", tmp_path / "a" / "fit", "--out", tmp_path / "b")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "b" / "verify" / "report.json").read_text())
    assert report["verdict"] == "inconsistent"
    assert report["p_value"] < min(0.05, report["line_p_value"])
    assert "p = " in proc.stdout


def test_a_pasted_colour_patch_is_inconsistent_and_named(tampered, tmp_path):
    out = tmp_path / "out"
    proc = totems("check", tampered, "--out", out)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((out / "verify" / "report.json").read_text())
    assert report["verdict"] == "inconsistent" and report["score"] > report["threshold"]
    x0, y0, x1, y1 = SQUARE
    assert report["drivers"]
    for d in report["drivers"]:
        bx0, by0, bx1, by1 = d["box"]
        assert bx0 < x1 and bx1 > x0 and by0 < y1 and by1 > y0, d
    assert report["metrics"]["patch_ap_L1"] > 0.8


def test_the_fit_serves_edits_outside_the_totems_only(verified, scene, tampered,
                                                      tmp_path):
    fit_dir = verified[0] / "fit"
    proc = totems("verify", tampered, "--fit", fit_dir, "--out", tmp_path / "a")
    assert proc.returncode == 1, proc.stdout + proc.stderr

    inside = tmp_path / "totem-edited"
    shutil.copytree(scene, inside)
    image = folder.read_image(inside / "image.png")
    v, u = np.nonzero(folder.read_mask(next((inside / "totem_masks").glob("*.png"))))
    image[v[len(v) // 2], u[len(u) // 2]] = 1.0 - image[v[len(v) // 2], u[len(u) // 2]]
    folder.write_image(inside / "image.png", image)
    line = assert_one_line_error(totems("verify", inside, "--fit", fit_dir,
                                        "--out", tmp_path / "b"))
    assert "another scene" in line


def test_the_totem_rays_judge_the_square_and_a_fit_without_them_still_verifies(
        verified, tampered, tmp_path):
    fit_dir = verified[0] / "fit"
    assert (fit_dir / "totem_rays.npz").is_file()
    proc = totems("verify", tampered, "--fit", fit_dir, "--out", tmp_path / "a")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "a" / "verify" / "report.json").read_text())
    unseen = report["scores"]["UNSEEN"]
    assert unseen["score"] > unseen["threshold"]
    assert report["metrics"]["patch_ap_CORROB"] > 0.8
    assert (tmp_path / "a" / "verify" / "CORROB" / "heatmap.npy").is_file()
    # A fit folder from before fits kept their rays: no CORROB, UNSEEN is CHROMA's.
    old = tmp_path / "old-fit"
    shutil.copytree(fit_dir, old)
    (old / "totem_rays.npz").unlink()
    proc = totems("verify", tampered, "--fit", old, "--out", tmp_path / "b")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "b" / "verify" / "report.json").read_text())
    assert report["metrics"]["patch_ap_CORROB"] is None
    assert not (tmp_path / "b" / "verify" / "CORROB").exists()
    assert report["metrics"]["patch_ap_UNSEEN"] == report["metrics"]["patch_ap_CHROMA"]


def test_a_square_one_totem_sees_is_not_judged_and_the_report_says_so(
        verified, tampered, tmp_path):
    """The same square: judged and caught where the totems resolve the surface; with the
    rays of one totem only (no surface seen twice), not judged: unverifiable, exit 4,
    none of its pixels judged and no driver on it."""
    fit_dir = verified[0] / "fit"
    proc = totems("verify", tampered, "--fit", fit_dir, "--out", tmp_path / "all")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "all" / "verify" / "report.json").read_text())
    assert report["metrics"]["manip_judged"] > 0.25 and report["judged_fraction"] > 0.2
    judged = folder.read_mask(tmp_path / "all" / "verify" / "judged_mask.png")
    assert judged.mean() == pytest.approx(report["judged_fraction"], abs=0.05)

    one = tmp_path / "one-totem-fit"
    shutil.copytree(fit_dir, one)
    rays = dict(np.load(one / "totem_rays.npz"))
    keep = rays["totem"] == 0
    np.savez(one / "totem_rays.npz", **{k: v[keep] for k, v in rays.items()})
    proc = totems("verify", tampered, "--fit", one, "--out", tmp_path / "one")
    assert proc.returncode == 4, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "one" / "verify" / "report.json").read_text())
    assert report["verdict"] == "unverifiable" and report["judged_fraction"] == 0.0
    assert report["metrics"]["manip_judged"] == 0.0
    x0, y0, x1, y1 = SQUARE
    assert not any(d["box"][0] < x1 and d["box"][2] > x0 and d["box"][1] < y1
                   and d["box"][3] > y0 for d in report["drivers"])
    page = (tmp_path / "one" / "verify" / "report.html").read_text()
    assert "Unverifiable" in page


def _enlarged(src, out, f: int = 4):
    """A copy of the scene folder ``src`` with every pixel repeated f x f (a photo over
    the working size: 1280 x 960 from 320 x 240), K for those pixels."""
    from scenes.working import scale_intrinsics

    s = folder.read_scene(src)
    up = np.ones((f, f))
    big = lambda a: np.kron(a, up[..., None] if np.ndim(a) == 3 else up)  # noqa: E731
    K = np.linalg.inv(scale_intrinsics(np.eye(3), f)) @ s.K
    return folder.write_scene(out, image=big(s.image), K=K,
                              masks=[big(m) > 0 for m in s.masks], radius=s.radius,
                              ior=s.ior, manip_mask=None if s.manip_mask is None
                              else big(s.manip_mask) > 0)


def test_a_photo_over_the_working_size_is_judged_at_a_fraction_of_it(scene, tampered,
                                                                       tmp_path):
    for src, code in ((scene, 0), (tampered, 1)):
        big = _enlarged(src, tmp_path / f"big-{src.name}")
        out = tmp_path / f"out-{src.name}"
        proc = totems("check", big, "--out", out, "--quiet")
        assert proc.returncode == code, proc.stdout + proc.stderr
        report = json.loads((out / "verify" / "report.json").read_text())
        assert report["working_scale"] == 2
        recon = folder.read_image(out / "verify" / "recon.png")
        assert recon.shape == (480, 640, 3)                          # as calibrated
        assert folder.read_image(big / "image.png").shape == (960, 1280, 3)    # untouched
        if code:
            x0, y0, x1, y1 = (2 * np.array(SQUARE)).astype(int)     # at the working size
            hit = [d for d in report["drivers"]
                   if d["box"][0] < x1 and d["box"][2] > x0 and d["box"][1] < y1
                   and d["box"][3] > y0]
            assert hit, report["drivers"]
