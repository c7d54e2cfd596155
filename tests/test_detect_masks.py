"""scenes/detect_masks: glass-sphere silhouettes found to IoU >= 0.95; none in a wall."""

import json
import subprocess
import sys

import numpy as np
import pytest

from scenes import folder
from scenes.errors import BadInput
from scenes.photo.detect_masks import ellipse_masks, find_totems, propose_masks, write_masks
from verify.cli.commands import EXIT_INCOMPLETE


def _photo(seed, n=3, totems=True, W=320, H=240):
    """A smooth textured wall with n sphere images: inside each ellipse the wall seen
    minified and inverted (as through a glass sphere) with a darkening rim. The true
    mask is the set of pixel centres inside each ellipse (computed independently)."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H, 0:W].astype(float)

    def wall(x, y):
        return np.stack([0.5 + 0.25 * np.sin(x / 11 + 1) * np.cos(y / 17),
                         0.45 + 0.2 * np.cos((x - y) / 23),
                         0.4 + 0.2 * np.sin(y / 9 + x / 31)], -1)

    img, masks = wall(u, v), []
    if totems:
        for x in np.linspace(50, W - 50, n) + rng.uniform(-10, 10, n):
            y, r = rng.uniform(120, 190), rng.uniform(16, 26)
            rho = np.hypot((u - x) / (r * rng.uniform(1.0, 1.08)), (v - y) / r)
            m = rho < 1
            inside = wall(x - 3 * (u - x), y - 3 * (v - y)) * (0.85 - 0.4 * rho[..., None] ** 4)
            img[m] = inside[m]
            masks.append(m)
    img = np.clip(img + rng.normal(0, 0.01, img.shape), 0, 1).astype(np.float32)
    return img, np.array(masks)


@pytest.mark.slow
def test_masks_match_truth_and_go_left_to_right():
    img, truth = _photo(1, n=4)
    masks = propose_masks(img, n=4)
    assert masks.shape == truth.shape
    iou = (masks & truth).sum((1, 2)) / (masks | truth).sum((1, 2))
    assert np.all(iou >= 0.95), iou        # index by index: also checks the order


def test_wall_without_totem_is_bad_input():
    img, _ = _photo(2, totems=False)
    with pytest.raises(BadInput, match="no totem found"):
        propose_masks(img)


def test_write_masks_keeps_hand_drawn(tmp_path):
    img, truth = _photo(0, n=2)
    folder.write_image(tmp_path / "image.png", img)
    hand = np.zeros_like(truth[0])
    hand[100:130, 20:60] = True                          # a person's mask: used as given
    folder.write_image(tmp_path / "totem_masks" / "mine.png", hand)
    out = write_masks(tmp_path)
    assert out["proposed"] is False and out["n"] == 1
    assert sorted(p.name for p in (tmp_path / "totem_masks").iterdir()) == ["mine.png"]
    check = folder.read_image(tmp_path / "totem_masks_check.png")
    assert np.abs(check - folder.read_image(tmp_path / "image.png")).max() > 0.3  # outline

    other = tmp_path / "other"
    other.mkdir()
    folder.write_image(other / "image.png", img)
    out = write_masks(other, truth)                      # given masks, none on disk
    assert out["proposed"] is True
    back = np.stack([folder.read_mask(p) for p in out["masks"]])
    assert np.array_equal(back, truth)


def test_cone_points_are_tangent_to_the_sphere():
    # A sphere of radius R at P (camera frame, metres): every ray through the cone's
    # image points passes at distance R from P, and the normals point away from P's image.
    from scenes.silhouette import cone_points
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
    P, R = np.array([0.4, 0.3, 1.5]), 0.05
    p = K @ P
    q = (p[0] / p[2], p[1] / p[2], K[0, 0] * np.tan(np.arcsin(R / np.linalg.norm(P))))
    pts, nrm = cone_points(q, K, 64)
    rays = np.linalg.solve(K, np.c_[pts, np.ones(len(pts))].T).T
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    dist = np.linalg.norm(P - (rays @ P)[:, None] * rays, axis=1)
    assert np.allclose(dist, R, rtol=1e-6)
    assert np.all(((pts - q[:2]) * nrm).sum(1) > 0)
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0)


@pytest.fixture(scope="module")
def envmap_scene(tmp_path_factory):
    """A rendered envmap scene (320x240, 32 spp): photo, true masks, clean view, K."""
    from scenes.synthetic.make import make_scene
    out = make_scene(tmp_path_factory.mktemp("dm") / "s", preset="envmap", seed=3,
                     size=(320, 240), spp=32)
    scene = folder.read_scene(out)
    return (scene.image, scene.masks, folder.read_image(out / "truth" / "clean.png"),
            scene.K)


@pytest.mark.slow
def test_rendered_glass_spheres_found_left_to_right(envmap_scene):
    # With K each silhouette is fitted as a sphere's tangent cone: IoU >= 0.95, the
    # issue's target (free ellipses, without K, reached 0.91-0.97 here).
    img, truth, _, K = envmap_scene
    masks = propose_masks(img, n=len(truth), K=K)
    assert masks.shape == truth.shape
    iou = (masks & truth).sum((1, 2)) / (masks | truth).sum((1, 2))
    assert np.all(iou >= 0.95), iou        # index by index: also checks the order
    loose = propose_masks(img, n=len(truth))
    assert np.all((loose & truth).sum((1, 2)) / (loose | truth).sum((1, 2)) >= 0.85)


@pytest.mark.slow
def test_write_masks_uses_the_scenes_calibration(envmap_scene, tmp_path):
    img, truth, _, K = envmap_scene
    folder.write_image(tmp_path / "image.png", img)
    folder.write_calib(tmp_path / "calib.npy", K)
    out = write_masks(tmp_path, n=len(truth))
    masks = np.stack([folder.read_mask(p) for p in out["masks"]])
    assert np.all((masks & truth).sum((1, 2)) / (masks | truth).sum((1, 2)) >= 0.95)


@pytest.mark.slow
def test_rendered_view_without_totems_is_bad_input(envmap_scene):
    _, _, clean, _ = envmap_scene               # same scene and floor, no glass spheres
    with pytest.raises(BadInput, match="no totem found"):
        propose_masks(clean)


def _folder_with_key(tmp_path, img, n_key):
    folder.write_image(tmp_path / "image.png", img)
    (tmp_path / "totems.json").write_text(
        json.dumps([{"radius": 0.1, "ior": 1.5}] * n_key))
    return tmp_path


@pytest.mark.slow
def test_masks_says_so_when_the_key_lists_more_totems_than_it_finds(tmp_path):
    img, truth = _photo(1, n=4)
    scene = _folder_with_key(tmp_path / "s", img, 5)
    done = subprocess.run([sys.executable, "-m", "verify.cli", "masks", str(scene)],
                          capture_output=True, text=True)
    assert done.returncode == EXIT_INCOMPLETE, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "found 4 of the 5 totems" in lines[0]
    assert "radii" in lines[0] and "--hint" in lines[0]
    assert not (scene / "totem_masks").exists()          # never fewer masks silently
    assert (scene / "totem_masks_check.png").is_file()


@pytest.mark.slow
def test_hints_find_each_totem_and_the_key_sets_the_count(tmp_path):
    img, truth = _photo(1, n=4)
    scene = _folder_with_key(tmp_path / "s", img, 4)
    hints = [(np.nonzero(m)[1].mean(), np.nonzero(m)[0].mean()) for m in truth]
    out = write_masks(scene, hints=hints)
    assert out["complete"] and out["n"] == 4
    masks = np.stack([folder.read_mask(p) for p in out["masks"]])
    iou = (masks & truth).sum((1, 2)) / (masks | truth).sum((1, 2))
    assert np.all(iou >= 0.95), iou
    # the key alone sets how many are wanted: all four found, in order
    out2 = write_masks(_folder_with_key(tmp_path / "t", img, 4))
    assert out2["complete"] and out2["n"] == 4


def _totem_among_coins():
    """A 320x240 photo: a glass-like totem (r = 24 px, an inverted copy of the wall with
    a dark rim) amid a grid of black and white coins whose sharp rings outrank it; and
    the totem's true mask."""
    H, W = 240, 320
    v, u = np.mgrid[0:H, 0:W].astype(float)
    img = np.stack([0.5 + 0.1 * np.sin(u / 11) * np.cos(v / 17),
                    0.45 + 0.1 * np.cos((u - v) / 23),
                    0.4 + 0.1 * np.sin(v / 9 + u / 31)], -1)
    rho = np.hypot(u - 150, v - 118) / 24.0
    mask = rho < 1
    img[mask] = img[::-1, ::-1][mask] * (0.95 - 0.7 * rho[mask][:, None] ** 4)
    k = 0
    for y in np.arange(22, H - 10, 44):
        for x in np.arange(22, W - 10, 44):
            if np.hypot(x - 150, y - 118) >= 48:
                img[(u - x) ** 2 + (v - y) ** 2 < 17 ** 2] = 0.05 if k % 2 else 0.95
                k += 1
    noise = np.random.default_rng(0).normal(0, 0.01, img.shape)
    return np.clip(img + noise, 0, 1).astype(np.float32), mask


def test_a_click_finds_its_totem_among_stronger_rings():
    # The window around a click holds dozens of coins whose rings outrank the totem's:
    # only the candidates that hold the click are fitted, so the totem is found.
    img, truth = _totem_among_coins()
    found = find_totems(img, hints=[(156.0, 113.0)])
    assert len(found) == 1
    mask = ellipse_masks(found, img.shape)[0]
    assert (mask & truth).sum() / (mask | truth).sum() >= 0.95


def test_a_hint_outside_the_photo_is_bad_input(tmp_path):
    img, _ = _photo(0, n=2)
    with pytest.raises(BadInput, match="outside"):
        write_masks(_folder_with_key(tmp_path, img, 2), hints=[(-5.0, 10.0)])


def test_masks_benchmark_tells_an_imprecise_outline_from_a_missed_totem():
    # benchmarks/masks_iou.py: a mask on the totem with its outline a few pixels off is
    # "found, imprecise", a mask on something else leaves the totem "not found".
    from benchmarks.masks_iou import classify, matched_iou
    v, u = np.mgrid[0:120, 0:160]
    disc = lambda x, y, r: np.hypot(u - x, v - y) < r
    true = np.stack([disc(40, 60, 20), disc(110, 60, 20), disc(140, 20, 10)])
    found = np.stack([disc(40.3, 60, 20), disc(113, 60, 20), disc(40, 100, 12)])
    iou = matched_iou(found, true)
    assert iou[0] >= 0.95 and 0.5 <= iou[1] < 0.95 and iou[2] < 0.5, iou
    assert classify(iou) == {"good": 1, "imprecise": 1, "missed": 1, "n": 3}


def test_refraction_through_the_sphere_matches_inverse_sphere():
    # scenes/refraction.py's numpy optics against inverse.sphere (Dr.Jit, Mitsuba's Snell
    # and Fresnel code): the same exit points and directions for rays across the sphere.
    from inverse import sphere
    from scenes import backend, camera, silhouette
    from scenes.refraction import entry_cosine, refract_sphere, transmittance
    backend.use()
    mi = backend.modules()[1]
    K = camera.intrinsics(640, 480, 60)
    P, R, eta = np.array([0.3, -0.1, 1.5]), 0.1, 1.52
    uv = camera.project(K, P[None])[0]
    s = K[0, 0] * np.tan(np.arcsin(R / np.linalg.norm(P)))
    rng = np.random.default_rng(0)
    a, rho = rng.uniform(0, 2 * np.pi, 300), 0.9 * s * np.sqrt(rng.uniform(0, 1, 300))
    d = camera.pixel_rays(K, uv[0] + rho * np.cos(a), uv[1] + rho * np.sin(a))
    E, d_out, valid = refract_sphere(d, P, R, eta)
    E2, d2, T2, valid2 = sphere.totem_rays(mi.Point3f(0, 0, 0),
                                          mi.Vector3f(*d.T.astype(np.float32)), P, R, eta)
    ok = np.asarray(valid2, bool)
    assert valid.all() and ok.sum() > 250
    assert np.allclose(E[ok], np.array(E2).reshape(3, -1).T[ok], atol=1e-6)
    assert np.allclose(d_out[ok], np.array(d2).reshape(3, -1).T[ok], atol=1e-5)
    T = transmittance(entry_cosine(d, P, R), eta)        # Fresnel, against mi.fresnel's
    assert np.allclose(T[ok], np.array(T2)[ok], atol=1e-5) and T.min() < 0.9 < T.max()
    # and the sphere the circle implies is the one it was drawn from
    assert np.allclose(silhouette.sphere_from_circle(uv[0], uv[1], s, K, R), P, atol=1e-9)


@pytest.fixture(scope="module")
def glass_and_ball():
    """A rendered envmap scene (320x240, 16 spp) whose fourth sphere is an opaque
    textured ball: photo, K, the three glass spheres' and the ball's circles (the image
    of each tangent cone, (u0, v0, s) pixels)."""
    from scenes import camera
    from scenes.synthetic import presets, render
    desc = presets.describe("envmap", seed=4, size=(320, 240))
    ball = desc["totems"].pop()
    T = np.eye(4)
    T[:3, :3] *= ball["radius"]
    T[:3, 3] = ball["center"]
    desc["objects"].append({"id": 999, "name": "ball", "kind": "sphere",
                            "to_world": T.tolist(), "removable": False,
                            "material": {"type": "diffuse", "texture": "brick",
                                         "tint": [0.8, 0.5, 0.4], "uv_scale": [2.0, 2.0]}})
    img = np.asarray(render.render(desc, spp=16), np.float32)
    K = np.asarray(desc["K"], float)

    def circle(P, R):
        uv = camera.project(K, np.asarray(P, float)[None])[0]
        return uv[0], uv[1], K[0, 0] * np.tan(np.arcsin(R / np.linalg.norm(P)))

    circles = np.array([circle(t["center"], t["radius"]) for t in desc["totems"] + [ball]])
    return img, K, circles


@pytest.mark.slow
def test_the_key_tells_glass_from_an_opaque_ball(glass_and_ball):
    # What the key predicts through the glass is found inside the three glass spheres,
    # not inside the ball, and the detector given the key's IoR takes the glass ones.
    import cv2
    from scenes.photo import glass
    from scenes.photo.detect_masks import find_totems
    img, K, circles = glass_and_ball
    g = glass.glass_scores(cv2.GaussianBlur(img, (0, 0), glass.SIGMA_INSIDE_PX),
                           cv2.GaussianBlur(img, (0, 0), glass.SIGMA_PX), circles, K, [1.52])
    assert np.all(g[:3] > g[3] + 0.2), g
    found = find_totems(img, n=3, K=K, ior=[1.52])
    centres = np.array([e[0] for e, _ in found])
    assert len(found) == 3
    assert np.all(np.hypot(*(centres - circles[:3, :2]).T) < 2.0), (centres, circles)


@pytest.mark.slow
def test_a_key_listing_the_ball_too_is_told_fewer_were_found(glass_and_ball, tmp_path):
    # With calib.npy and a key that lists its totems, the three glass spheres pass the
    # final score and are written; a key listing four gets exit 3's "found 3 of 4": the
    # ball does not pass for the fourth.
    img, K, circles = glass_and_ball
    scenes = {}
    for n_key in (3, 4):
        scenes[n_key] = _folder_with_key(tmp_path / f"k{n_key}", img, n_key)
        folder.write_calib(scenes[n_key] / "calib.npy", K)
    four = write_masks(scenes[4])
    assert not four["complete"] and four["found"] == 3, four
    three = write_masks(scenes[3])
    assert three["complete"] and three["n"] == 3, three
    masks = np.stack([folder.read_mask(p) for p in three["masks"]])
    for m, (x, y, s) in zip(masks, circles[:3]):      # left to right, each on its sphere
        assert m[int(round(y)), int(round(x))] and m.sum() > 0.8 * np.pi * s * s


def _banded_totem(W=200, H=150, q=(122.0, 84.0, 21.0), seed=0):
    """A small glass-like totem on a textured floor: inside its tangent cone's outline
    (K of 60 degrees) the floor minified and inverted, and over its lower half a dark
    band from 0.75 of its size to the rim (the table reflected), whose inner edge is an
    arc as strong as the rim. Photo, K, true mask."""
    import cv2
    from scenes import camera, silhouette
    rng = np.random.default_rng(seed)
    K = camera.intrinsics(W, H, 60)
    noise = cv2.GaussianBlur(rng.uniform(0, 1, (H, W, 3)).astype(np.float32), (0, 0), 2.0)
    floor = 0.35 + 0.5 * (noise - noise.min()) / (noise.max() - noise.min())
    (cx, cy), (A, B), ang = cv2.fitEllipse(silhouette.cone_points(q, K, 90)[0].astype(np.float32))
    truth = silhouette.ellipse_mask(((cx, cy), (A, B), ang), (H, W))
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    rho = np.hypot(u - cx, v - cy) / (0.25 * (A + B))
    mx = np.clip(cx - 3 * (u - cx), 0, W - 1)
    my = np.clip(cy - 3 * (v - cy), 0, H - 1)
    seen = cv2.remap(floor, mx, my, cv2.INTER_LINEAR)
    dark = ((rho > 0.75) & (v > cy))[..., None]
    img = np.where(truth[..., None], (1 - dark) * seen + dark * 0.06, floor)
    img = np.clip(img + rng.normal(0, 0.01, img.shape), 0, 1).astype(np.float32)
    return img, K, truth


def test_the_wide_fit_finds_the_rim_outside_the_dark_band():
    # Started from a coarse circle on the dark band (0.78 of the size, 0.3 radii off),
    # the wide fit (scenes/photo/cone_fit.py) finds the rim of a 21 px totem on a textured
    # floor at IoU >= 0.95, within a pixel.
    from scenes import silhouette
    from scenes.photo import cone_fit
    img, K, truth = _banded_totem()
    field = silhouette.orientation_field(img, 1.0)
    polish = silhouette.gradients(img, 0.7)
    q0 = (122.0 + 0.25 * 21, 84.0 - 0.15 * 21, 0.78 * 21)
    ell, q, _ = cone_fit.refit_cone(field, q0, K, img.shape[:2], polish)
    m = silhouette.ellipse_mask(ell, img.shape[:2])
    assert (m & truth).sum() / (m | truth).sum() >= 0.95
    assert abs(q[2] - 21) < 1.0 and np.hypot(q[0] - 122, q[1] - 84) < 1.0, q


def test_arc_support_lets_one_arc_go():
    # A rim crossed over an eighth and a bit by radial stripes (texture across the outline) fails
    # the worst-quarter support but passes the arc support; a plain floor passes neither.
    import cv2
    from scenes import silhouette
    H, W = 120, 160
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    ang = np.arctan2(v - 60, u - 80)
    wedge = (ang > 0) & (ang < 1.0) & (np.hypot(u - 80, v - 60) > 15)
    grey = np.where(np.hypot(u - 80, v - 60) < 25, 0.8, 0.3)
    grey = np.where(wedge, 0.3 + 0.5 * (np.sin(ang * 20) > 0), grey)
    img = cv2.GaussianBlur(np.repeat(grey[..., None], 3, -1).astype(np.float32), (0, 0), 0.8)
    img = img + np.random.default_rng(0).normal(0, 0.01, img.shape).astype(np.float32)
    field = silhouette.orientation_field(img, 1.0)
    ell = ((80.0, 60.0), (50.0, 50.0), 0.0)
    assert silhouette.support(ell, field) < 0.05 < silhouette.arc_support(ell, field)
    flat = np.random.default_rng(1).normal(0.5, 0.05, img.shape).astype(np.float32)
    assert silhouette.arc_support(ell, silhouette.orientation_field(flat, 1.0)) < 0.05


def test_a_mask_outline_gives_the_sphere_for_a_radius():
    # scenes.silhouette.cone_from_outline on a sphere's exact silhouette (pixel centres
    # inside its image), then sphere_from_circle with its radius: the sphere's centre,
    # and twice the radius twice as far along the same line.
    from scenes import camera, masks, silhouette
    K = camera.intrinsics(160, 120, 60)
    for P, R in ((np.array([0.3, 0.2, 1.5]), 0.1), (np.array([-0.5, -0.1, 2.2]), 0.12)):
        m = camera.sphere_silhouette(P, R, K, (120, 160))
        uv = masks.outline(m)
        assert len(uv) > 30 and not np.allclose(uv[0], uv[-1])
        q = silhouette.cone_from_outline(uv, K)
        got = silhouette.sphere_from_circle(*q, K, R)
        assert np.linalg.norm(got - P) < 0.01 * np.linalg.norm(P), (got, P)   # 7-11 px discs
        twice = silhouette.sphere_from_circle(*q, K, 2 * R)
        assert np.allclose(twice, 2 * got)
