"""`totems recapture` and JPEG scene folders: the channel writes what it says.

The JPEG's quality and chroma subsampling are read back from the written file and its
luma table checked against the JPEG standard's (Annex K, scaled as the IJG library
does); a resize scales K with the pixel-centre convention (checked on a ramp, whose
area average is known) and keeps the masks on the totems (the true centres project
inside them, and they agree with masks rendered at the smaller size); the input folder
is left byte for byte; one seed gives one file; an untouched photo and its edited
copy get one noise pattern; a folder with image.jpg is read, tampered, benched and
checked end to end.
"""

import hashlib
import json
import shutil

import numpy as np
import pytest
from test_cli import assert_one_line_error, totems

from scenes import camera, folder, jpeg
from scenes.channel import channel
from scenes.channel.channel import Channel
from scenes.channel.recapture import recapture
from scenes.errors import BadInput
from scenes.synthetic import render
from scenes.synthetic.make import make_scene

# JPEG standard (ITU T.81) Annex K.1, luminance, natural (row-major) order
ANNEX_K_LUMA = np.array([
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55,
    14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62,
    18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99])


def ijg_luma(quality: int) -> np.ndarray:
    """The IJG library's luma table at ``quality`` (jcparam.c, jpeg_quality_scaling)."""
    scale = 5000 // quality if quality < 50 else 200 - 2 * quality
    return np.clip((ANNEX_K_LUMA * scale + 50) // 100, 1, 255)


def tree_hash(path) -> dict:
    return {str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(path.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return make_scene(tmp_path_factory.mktemp("rc") / "box-1", preset="box", seed=1,
                      size=(160, 120), spp=4)


# --------------------------------------------------------------------------- JPEG

@pytest.mark.parametrize("quality", [50, 75, 95])
def test_the_jpeg_quality_is_read_back_from_the_file(scene, tmp_path, quality):
    out = tmp_path / "r"
    summary = recapture(scene, out, Channel(jpeg=(quality,)))
    assert summary["photo"] == "image.jpg"
    assert sorted(p.name for p in out.iterdir()) == ["calib.npy", "image.jpg",
                                                      "totem_masks", "totems.json", "truth"]
    info = folder.read_jpeg_info(out / "image.jpg")
    assert info.quality == quality and info.exact
    assert np.array_equal(info.luma, ijg_luma(quality))
    assert folder.read_scene(out).jpeg == info


def test_chroma_subsampling_is_read_back(scene, tmp_path):
    for chroma, expected in (("420", "4:2:0"), ("444", "4:4:4")):
        recapture(scene, tmp_path / chroma, Channel(jpeg=(90,), chroma=chroma))
        assert folder.read_jpeg_info(tmp_path / chroma / "image.jpg").subsampling == expected


def test_the_jpeg_written_is_the_bytes_encoded(scene, tmp_path):
    """Not re-encoded on the way: the file is the channel's last JPEG, bit for bit."""
    recapture(scene, tmp_path / "r", Channel(jpeg=(80,)))
    photo = folder.read_image(scene / "image.png")
    assert (tmp_path / "r" / "image.jpg").read_bytes() == jpeg.encode(photo, quality=80)


def test_double_jpeg_ends_with_the_last_quality(scene, tmp_path):
    summary = recapture(scene, tmp_path / "r", Channel(jpeg=(90, 60)))
    assert [s for s in summary["steps"]] == [["jpeg", [90, "420"]], ["jpeg", [60, "420"]]]
    assert folder.read_jpeg_info(tmp_path / "r" / "image.jpg").quality == 60
    record = json.loads((tmp_path / "r" / "truth" / "recapture.json").read_text())
    assert record["steps"] == summary["steps"] and record["photo"] == "image.jpg"


def test_a_png_photo_has_no_jpeg_info_and_a_camera_jpeg_is_not_exact(scene, tmp_path):
    from PIL import Image

    assert folder.read_scene(scene).jpeg is None
    # a camera's own tables: libjpeg's at 85 with one entry changed
    L, C = jpeg.libjpeg_tables(85)
    L = L.copy()
    L[5] += 3
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(
        tmp_path / "cam.jpg", qtables=[L.tolist(), C.tolist()])
    info = folder.read_jpeg_info(tmp_path / "cam.jpg")
    assert info.quality == 85 and not info.exact


# --------------------------------------------------------------------------- the order

def test_the_plan_follows_a_camera_then_a_messenger():
    steps = channel.plan(Channel(jpeg=(95, 70), resize=0.5, noise=1.0, blur=0.7,
                                 sharpen=0.4, exposure=1.2, gamma=1.1), (640, 480))
    assert [s[0] for s in steps] == ["blur", "tone", "noise", "sharpen", "jpeg", "resize",
                                     "jpeg"]
    assert steps[4][1][0] == 95 and steps[6][1][0] == 70
    # one JPEG with a resize: the messenger's, after it
    assert [s[0] for s in channel.plan(Channel(jpeg=(75,), resize=0.5), (64, 48))] == \
        ["resize", "jpeg"]
    # a photo already within --long-side is not enlarged; a larger one is shrunk to it
    assert channel.plan(Channel(long_side=800), (640, 480)) == []
    assert channel.plan(Channel(long_side=320), (640, 480)) == [["resize", 0.5]]
    assert channel.plan(Channel(), (640, 480)) == []


def test_an_empty_channel_copies_the_photo_as_it_is(scene, tmp_path):
    recapture(scene, tmp_path / "r", Channel())
    assert (tmp_path / "r" / "image.png").read_bytes() == (scene / "image.png").read_bytes()


# --------------------------------------------------------------------------- resize

def test_resize_keeps_the_pixel_centre_convention():
    """Area-resizing a ramp I(u) = u: output pixel u' averages the source over its
    footprint, centred at (u' + 0.5) / s - 0.5, which scale_intrinsics inverts."""
    W, H = 640, 480
    ramp = np.broadcast_to(np.arange(W, dtype=np.float32)[None, :, None], (H, W, 3))
    K = camera.intrinsics(W, H, 60.0)
    for s in (0.5, 0.33, 0.7):
        small = channel.resize(ramp, s)
        assert small.shape[:2] == (round(H * s), round(W * s))
        u_src = small[0, :-1, 0].astype(np.float64)   # last column may be clipped
        u_new = np.arange(u_src.size)
        Ks = camera.scale_intrinsics(K, s)
        # the ray through source pixel u_src lands on new pixel u' through the scaled K
        mapped = Ks[0, 0] * (u_src - K[0, 2]) / K[0, 0] + Ks[0, 2]
        # unbiased (c' = c s would be off by 0.5 (1 - s)); within a tenth of a pixel
        # each, the source being piecewise constant
        assert abs((mapped - u_new).mean()) < 0.005
        assert np.abs(mapped - u_new).max() < 0.1
        assert np.isclose(Ks[0, 0], K[0, 0] * s) and Ks[0, 0] == Ks[1, 1]
        assert np.isclose(Ks[0, 2], (K[0, 2] + 0.5) * s - 0.5)


def test_resize_scales_k_and_keeps_the_masks_on_the_totems(scene, tmp_path):
    out = tmp_path / "half"
    summary = recapture(scene, out, Channel(resize=0.5, jpeg=(85,)))
    assert summary["size"] == [80, 60]
    small = folder.read_scene(out)
    big = folder.read_scene(scene)
    assert small.image.shape == (60, 80, 3) and small.masks.shape == (4, 60, 80)
    np.testing.assert_allclose(small.K, camera.scale_intrinsics(big.K, 0.5))
    np.testing.assert_allclose(small.K[:2, 2], (big.K[:2, 2] + 0.5) * 0.5 - 0.5)
    # the true centres project inside the resized masks, in the same order
    pose = folder.read_truth(out).totem_pose
    for j, (u, v) in enumerate(camera.project(small.K, pose)):
        assert small.masks[j, round(v), round(u)], j
    # and the masks agree with the totems rendered at the copy's size and K, which
    # truth/scene.json now holds
    desc = json.loads((out / "truth" / "scene.json").read_text())
    assert desc["size"] == [80, 60]
    ids = render.shape_ids(desc)
    for j, m in enumerate(small.masks):
        truth = ids == render.totem_id(j)
        iou = (m & truth).sum() / (m | truth).sum()
        assert iou > 0.85, (j, iou)
    assert folder.read_truth(out).clean.shape == (60, 80, 3)


def test_manip_mask_follows_a_resize(scene, tmp_path):
    tampered = tmp_path / "t"
    totems_ok = totems("tamper", scene, tampered, "--kind", "color", "--seed", "3",
                       "--quiet")
    assert totems_ok.returncode == 0, totems_ok.stderr
    recapture(tampered, tmp_path / "r", Channel(resize=0.5))
    big = folder.read_mask(tampered / "manip_mask.png")
    small = folder.read_mask(tmp_path / "r" / "manip_mask.png")
    assert small.shape == (60, 80)
    # any changed pixel under a resized pixel makes it changed
    assert small.sum() >= big.sum() / 4
    np.testing.assert_array_equal(small, channel.resize_mask(big, 0.5, threshold=0.0))


# --------------------------------------------------------------------------- files

def test_the_input_folder_is_left_as_it_was(scene, tmp_path):
    src = tmp_path / "src"
    shutil.copytree(scene, src)
    (src / "totems-out" / "fit").mkdir(parents=True)
    (src / "totems-out" / "fit" / "fit.json").write_text("{}")
    before = tree_hash(src)
    recapture(src, tmp_path / "r", Channel(jpeg=(90, 70), resize=0.5, noise=2, blur=0.8,
                                           sharpen=0.5, exposure=1.3, gamma=1.2))
    assert tree_hash(src) == before
    assert not (tmp_path / "r" / "totems-out").exists()      # a fit of another photo
    assert not list(tmp_path.glob(".*.part"))


def test_same_seed_same_bytes_another_seed_other_bytes(scene, tmp_path):
    c = {"jpeg": (90,), "noise": 2.0, "sharpen": 0.5}
    recapture(scene, tmp_path / "a", Channel(**c, seed=1))
    recapture(scene, tmp_path / "b", Channel(**c, seed=1))
    recapture(scene, tmp_path / "c", Channel(**c, seed=2))
    a, b, c_ = ((tmp_path / n / "image.jpg").read_bytes() for n in "abc")
    assert a == b and a != c_


def test_an_untouched_photo_and_its_edit_get_one_noise(scene, tmp_path):
    """Noise is seeded by the photo's set-up (size, K, masks), not its pixels: the two
    recaptured copies differ only where the edit did."""
    tampered = tmp_path / "t"
    assert totems("tamper", scene, tampered, "--kind", "color", "--quiet").returncode == 0
    recapture(scene, tmp_path / "a", Channel(noise=3.0))
    recapture(tampered, tmp_path / "b", Channel(noise=3.0))
    a = folder.read_image(tmp_path / "a" / "image.png")
    b = folder.read_image(tmp_path / "b" / "image.png")
    edited = folder.read_mask(tampered / "manip_mask.png")
    assert np.array_equal(a[~edited], b[~edited])
    assert not np.array_equal(a, folder.read_image(scene / "image.png"))


def test_bad_settings_are_refused(scene, tmp_path):
    for bad in (Channel(jpeg=(0,)), Channel(jpeg=(101,)), Channel(resize=0.0),
                Channel(resize=1.5), Channel(long_side=-4), Channel(noise=-1.0),
                Channel(exposure=0.0), Channel(gamma=float("nan")),
                Channel(resize=0.05)):
        with pytest.raises(BadInput):
            recapture(scene, tmp_path / "r", bad)
    with pytest.raises(BadInput, match="outside"):
        recapture(scene, scene / "inside", Channel(jpeg=(90,)))
    assert not (tmp_path / "r").exists()


def test_scene_make_camera_adds_noise_to_the_photo_only(scene, tmp_path):
    cam = make_scene(tmp_path / "cam", preset="box", seed=1, size=(160, 120), spp=4,
                     camera=True)
    plain = folder.read_image(scene / "image.png")
    noisy = folder.read_image(cam / "image.png")
    assert (cam / "truth" / "clean.png").read_bytes() == \
        (scene / "truth" / "clean.png").read_bytes()
    assert (cam / "totem_masks" / "totem_000.png").read_bytes() == \
        (scene / "totem_masks" / "totem_000.png").read_bytes()
    diff = noisy - plain
    assert 0.002 < diff.std() < 0.05 and abs(diff.mean()) < 0.005
    desc = json.loads((cam / "truth" / "scene.json").read_text())
    assert desc["camera"] == {"full_well_e": channel.FULL_WELL_E,
                              "read_noise_e": channel.READ_NOISE_E}
    assert "camera" not in json.loads((scene / "truth" / "scene.json").read_text())


def test_photon_noise_has_the_poisson_gaussian_variance():
    rng = np.random.default_rng(0)
    lin = np.full((200, 200, 3), 0.25, np.float32)
    noisy = channel.photon_noise(lin, rng, full_well=1000.0, read_noise=5.0)
    expected = 0.25 / 1000.0 + (5.0 / 1000.0) ** 2     # shot + read, in linear units^2
    assert abs(noisy.mean() - 0.25) < 1e-3
    assert abs(noisy.var() / expected - 1.0) < 0.03


# --------------------------------------------------------------------------- JPEG folders

def test_a_folder_with_image_jpg_is_read_tampered_and_benched(scene, tmp_path):
    from verify.batch.bench import find_scenes

    out = tmp_path / "jpg"
    recapture(scene, out, Channel(jpeg=(75,)))
    s = folder.read_scene(out)
    assert s.image.shape == (120, 160, 3) and s.jpeg.quality == 75
    assert find_scenes([tmp_path]) == [out.resolve()]
    proc = totems("tamper", out, tmp_path / "forged", "--kind", "color", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "forged" / "image.png").is_file()           # a forger re-saves
    assert not (tmp_path / "forged" / "image.jpg").exists()
    assert folder.read_scene(tmp_path / "forged").jpeg is None


def test_a_folder_with_two_photos_is_refused(scene, tmp_path):
    both = tmp_path / "both"
    shutil.copytree(scene, both)
    (both / "image.jpg").write_bytes(jpeg.encode(folder.read_image(both / "image.png"),
                                                 quality=90))
    with pytest.raises(BadInput, match="image.png and image.jpg"):
        folder.read_scene(both)


def test_cli_bad_arguments_exit_2_with_one_line(scene, tmp_path):
    assert "1-100" in assert_one_line_error(
        totems("recapture", scene, tmp_path / "a", "--jpeg", "0"))
    assert "(0, 1]" in assert_one_line_error(
        totems("recapture", scene, tmp_path / "a", "--resize", "2"))
    assert_one_line_error(totems("recapture", scene, tmp_path / "a", "--resize", "0.5",
                                 "--long-side", "100"))
    assert_one_line_error(totems("recapture", scene, tmp_path / "a", "--chroma", "411"))
    assert "not found" in assert_one_line_error(
        totems("recapture", tmp_path / "nope", tmp_path / "a"))
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    assert "exists" in assert_one_line_error(
        totems("recapture", scene, tmp_path / "full", "--jpeg", "80"))
    proc = totems("recapture", scene, tmp_path / "ok", "--jpeg", "80", "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["photo"] == "image.jpg"


@pytest.mark.slow
def test_check_runs_end_to_end_on_a_jpeg_75_copy(scene, tmp_path):
    recapture(scene, tmp_path / "jpg", Channel(jpeg=(75,)))
    proc = totems("check", tmp_path / "jpg", "--out", tmp_path / "out", "--json",
                  "--quiet")
    assert proc.returncode in (0, 1, 4), proc.stderr         # a verdict, not a failure
    report = json.loads((tmp_path / "out" / "verify" / "report.json").read_text())
    assert report["verdict"] == {0: "consistent", 1: "inconsistent",
                                 4: "unverifiable"}[proc.returncode]
    assert json.loads(proc.stdout)["verdict"] == report["verdict"]
