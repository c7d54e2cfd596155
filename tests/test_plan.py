"""scenes.plan and `totems plan`: the reach a placement predicts on a plane, against hand
computations (a ball lens's paraxial optics, the edge of a totem's view by Snell's law in
the plane of the totems, the subject distance at which two totems' parallax falls to the
rule's); the move that widens it, scored as the plan scores; a plan from a test photo's
masks and key; bad input as one line and exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage

from scenes import camera, folder
from scenes.errors import BadInput
from scenes.plan.predict import (check_placement, fronto_plane, predict, sent_on,
                                 subject_hits, subject_plane, totem_image)
from scenes.reach import COS_EVIDENCE, MIN_PARALLAX, Reach

W, H = 400, 300
K = camera.intrinsics(W, H, 60)
R, ETA = 0.1, 1.5


def _angle(a, b, X) -> float:
    """The angle at X between points a and b."""
    p, q = a - X, b - X
    return float(np.arccos(p @ q / np.linalg.norm(p) / np.linalg.norm(q)))


def _pixel(X):
    return tuple(np.rint(camera.project(K, np.asarray(X, float)[None])[0]).astype(int))


def test_rays_near_a_totems_centre_spread_as_a_ball_lens_does():
    """Paraxially a ball lens is a thin lens at its centre of focal length n R / 2(n-1):
    camera rays at angle a to the line through the centre, L away, leave at
    a (1 - L / f_ball), so neighbouring pixels' rays part by (L / f_ball - 1) / fx."""
    P = np.array([0.0, 0.0, 1.5])
    u0, v0 = _pixel(P)
    E, d = sent_on(K, np.array([u0, u0 + 1]), np.array([v0, v0]), P, R, ETA)
    f_ball = ETA * R / (2 * (ETA - 1))
    expected = (1.5 / f_ball - 1) / K[0, 0]
    assert np.arccos(d[0] @ d[1]) == pytest.approx(expected, rel=0.02)
    assert d[1][0] < d[0][0]                    # inverted: the ray to the right turns left


def _landing(P, u: int, plane_z: float) -> tuple[float, float]:
    """Where the ray of pixel (u, the totems' row) through a totem at ``P`` (y = 0)
    lands on the plane z = ``plane_z``, and the cosine at which it entered the sphere:
    Snell's law at both surfaces in the xz plane, in scalar trigonometry (angles from
    +z, positive towards +x)."""
    L, phi = np.hypot(P[0], P[2]), np.arctan2(P[0], P[2])
    a = np.arctan((u - K[0, 2]) / K[0, 0])            # the camera ray's angle
    b = L * np.sin(a - phi)                           # its impact parameter
    i = np.arcsin(abs(b) / R)                         # incidence angle
    r = np.arcsin(np.sin(i) / ETA)                    # refraction angle
    side = np.sign(b)
    D = (L * np.cos(a - phi) - R * np.cos(i)) * np.array([np.sin(a), np.cos(a)])
    inside = a - side * (i - r)                       # bent towards the centre
    E = D + 2 * R * np.cos(r) * np.array([np.sin(inside), np.cos(inside)])
    out = a - side * 2 * (i - r)                      # a ray through a ball turns 2 (i - r)
    return float(E[0] + (plane_z - E[1]) * np.tan(out)), float(np.cos(i))


def test_two_totems_side_by_side_both_see_between_the_edges_of_their_views():
    """Two totems at x = +-0.5 m, 1.5 m away, a wall 2.5 m away: the right totem's
    leftmost ray is its image's rightmost pixel that enters at an incidence cosine of at
    least COS_EVIDENCE (bent the most), and it lands where Snell's law puts it; the
    wall is seen by both totems from there to the mirror point, and by one beyond it
    once past that ray's footprint."""
    P1, P2 = np.array([-0.5, 0.0, 1.5]), np.array([0.5, 0.0, 1.5])
    check_placement(K, (W, H), np.stack([P1, P2]), np.full(2, R), fronto_plane(2.5))
    pred = predict(K, (W, H), np.stack([P1, P2]), R, ETA, fronto_plane(2.5))
    u, v = _pixel(P2)
    while _landing(P2, u + 1, 2.5)[1] >= COS_EVIDENCE:
        u += 1
    edge = _landing(P2, u, 2.5)[0]
    assert edge < 0                                   # past the middle, to the left
    u_edge = _pixel([edge, 0.0, 2.5])[0]
    u_left = np.flatnonzero(pred.labels[v] == 0).max()   # the left totem's image ends
    assert u_left + 30 < u_edge < W // 2
    n = pred.reach.n_totems[v]
    assert (n[u_edge + 2: W - 1 - u_edge - 2] == 2).all()
    # beyond the edge by more than the last ray's footprint (its path, about 1.2 m,
    # times its spacing, under 0.25 rad, is under 0.3 m, 40 px), one totem
    assert (n[u_left + 1: u_edge - 40] == 1).all()


def test_the_reach_ends_where_the_parallax_falls_to_the_rules():
    """Two totems 0.3 m apart see a wall at its image centre from an angle that shrinks
    with its distance; the wall is in the reach nearer than the distance at which that
    angle is MIN_PARALLAX of their rays' spacing (solved by hand), and out beyond it."""
    P1, P2 = np.array([-0.15, 0.1, 1.5]), np.array([0.15, 0.1, 1.5])
    centers = np.stack([P1, P2])
    spacing = predict(K, (W, H), centers, R, ETA, fronto_plane(4.0)).reach.spacing
    need = MIN_PARALLAX * spacing.mean()              # the spacing is the plane's own
    u, v = _pixel([0.0, -0.3, 4.0])
    ray = camera.pixel_rays(K, np.float64(u), np.float64(v))
    lo, hi = 1.7, 50.0                                # bisect the wall's distance
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _angle(P1, P2, ray * mid / ray[2]) > need else (lo, mid)
    far = lo
    assert 2.0 < far < 10.0
    for z, inside in ((0.9 * far, True), (1.1 * far, False)):
        r = predict(K, (W, H), centers, R, ETA, fronto_plane(z)).reach
        assert r.n_totems[v, u] == 2
        X = ray * z / ray[2]
        assert r.parallax[v, u] == pytest.approx(_angle(P1, P2, X) / spacing.mean(),
                                                 rel=1e-4)
        assert r.in_reach()[v, u] == inside


def test_a_totem_hides_what_lies_behind_it_and_its_own_pixels_are_excluded():
    P = np.array([[-0.3, 0.2, 1.5], [0.3, 0.2, 1.5]])
    labels = totem_image(K, (W, H), P, np.full(2, R))
    for j in range(2):
        assert labels[_pixel(P[j])[::-1]] == j
    expected = camera.sphere_silhouette(P[0], R, K, (H, W)) | \
        camera.sphere_silhouette(P[1], R, K, (H, W))
    np.testing.assert_array_equal(labels >= 0, expected)
    pred = predict(K, (W, H), P, R, ETA, fronto_plane(4.0))
    assert not pred.reach.in_reach()[labels >= 0].any()


def test_a_ray_that_would_land_beside_the_subject_passes_it_by():
    """The subject is the plane within its region: a ray meeting the plane where the
    camera sees the region lands there; one meeting it beside the region, or behind the
    ray's start, lands nowhere."""
    plane = fronto_plane(4.0)
    region = np.zeros((H, W), bool)
    region[100:200, 150:250] = True                       # the subject's box
    o = np.array([[0.3, 0.2, 1.5]] * 3)
    inside = np.array([0.0, 0.0, 4.0])                    # the image centre: in the box
    beside = np.array([1.5, 0.0, 4.0])                    # right of the box
    d = np.stack([inside - o[0], beside - o[1], o[2] - inside])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    Y = subject_hits(o, d, plane, K, region)
    np.testing.assert_allclose(Y[0], inside, atol=1e-12)
    assert np.isnan(Y[1]).all() and np.isnan(Y[2]).all()
    np.testing.assert_allclose(subject_hits(o[:2], d[:2], plane)[1], beside, atol=1e-12)


def test_a_tilted_plane_is_turned_to_face_the_camera():
    p = subject_plane([0, 0, 4.0], [0, 0.3, 1.0])
    assert p.normal @ (np.zeros(3) - p.point) > 0
    with pytest.raises(BadInput, match="through the camera"):
        subject_plane([0, 0, 0.0], [0, 0, 1.0])
    with pytest.raises(BadInput, match="in front of the camera"):
        fronto_plane(-2.0)


@pytest.mark.parametrize("centers, words", [
    ([[0.0, 0.0, 1.5]], "at least two"),
    ([[-0.3, 0.2, 1.5], [0.3, 0.2, 5.0]], "behind the subject"),
    ([[-0.3, 0.2, 1.5], [0.3, 0.2, 3.95]], "intersects the subject"),
    ([[-0.3, 0.2, 1.5], [-0.25, 0.2, 1.5]], "overlap"),
    ([[-0.3, 0.2, 1.5], [2.0, 0.2, 1.5]], "leaves the"),
    ([[-0.3, 0.2, 1.5], [0.0, 0.0, -1.0]], "behind the camera"),
])
def test_placements_no_photo_can_have_are_refused_in_one_line(centers, words):
    with pytest.raises(BadInput, match=words) as err:
        check_placement(K, (W, H), np.array(centers), np.full(len(centers), R),
                        fronto_plane(4.0))
    assert "\n" not in str(err.value)


def test_the_move_screen_scores_as_the_plan_does_and_its_move_widens_the_reach():
    """Two totems too close together to establish anything: the screen's share of the
    placement as it stands (pairs composed) is the plan's own (reach_map over all), and
    the move it suggests widens the reach by what the plan predicts after it."""
    from scenes.plan.plan import make_plan
    from scenes.plan.suggest import _Screen, region_share, sample_pixels

    P = np.array([[-0.12, 0.35, 2.0], [0.12, 0.35, 2.0], [0.5, 0.3, 1.6]])
    plane = fronto_plane(5.0)
    plan = make_plan(K, (W, H), P, 0.05, ETA, plane)
    u, v, _ = sample_pixels(plan.region)
    screen = _Screen(plan.K, plan.size, P, plan.radius, plan.ior, plane, u, v, plan.region)
    exact = region_share(plan.K, plan.size, P, plan.radius, plan.ior, plane, u, v)
    assert screen.share(0, P[0]) == pytest.approx(exact, abs=0.02)
    assert plan.share == pytest.approx(exact, abs=0.02)
    m = plan.move
    assert m is not None and m.gain > 0.1
    moved = P.copy()
    moved[m.totem] = m.center
    after = make_plan(K, (W, H), moved, 0.05, ETA, plane, region=plan.region,
                      suggest=False)
    assert after.share == pytest.approx(m.share, abs=0.02)
    assert not plan.region[totem_image(K, (W, H), moved, np.full(3, 0.05)) >= 0].any()


# --------------------------------------------------------------------------- the verb

def totems(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "verify.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def one_line_exit_2(proc) -> str:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


FRAME = ["--fov", "60", "--size", "400x300", "--radius", "0.05", "--ior", "1.5"]


def test_plan_writes_its_folder_and_says_its_share(tmp_path):
    out = tmp_path / "plan"
    proc = totems("plan", *FRAME, "--totem", "80,250,2", "--totem", "320,250,2",
                  "--subject-distance", "4", "--subject-region", "100,20,200,150",
                  "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    saved = json.loads((out / "plan.json").read_text())
    assert saved["share"] == summary["share"] and 0.0 <= saved["share"] <= 1.0
    assert saved["region"]["from"] == "box" and saved["region"]["box"] == [100, 20, 200, 150]
    assert [t["uv"] for t in saved["totems"]] == [[80.0, 250.0], [320.0, 250.0]]
    assert saved["totems"][0]["distance"] == pytest.approx(2.0)
    assert folder.read_image(out / "plan.png").shape == (300, 400, 3)
    assert summary["seconds"] < 5.0


def test_plan_help_shows_an_example():
    proc = totems("plan", "--help")
    assert proc.returncode == 0
    assert "example:\n  totems plan --fov" in proc.stdout and "--subject-distance" in \
        proc.stdout


@pytest.mark.parametrize("extra, words", [
    (["--subject-distance", "-3"], "in front of the camera"),
    (["--subject-plane", "0,0,-3,0,0,1"], "behind the camera"),
    (["--subject-distance", "1.5"], "behind the subject"),
    (["--subject-distance", "4", "--radius", "0"], "must be positive"),
])
def test_bad_subjects_and_keys_are_one_line_and_exit_2(extra, words):
    frame = FRAME if "--radius" not in extra else FRAME[:4] + ["--ior", "1.5"]
    proc = totems("plan", *frame, "--totem", "80,250,2", "--totem", "320,250,2", *extra)
    assert words in one_line_exit_2(proc)


def test_a_key_for_other_totems_is_one_line_and_exit_2(tmp_path):
    key = tmp_path / "totems.json"
    key.write_text(json.dumps([{"radius": 0.05, "ior": 1.5}] * 3))
    proc = totems("plan", "--fov", "60", "--size", "400x300", "--key", key, "--totem",
                  "80,250,2", "--totem", "320,250,2", "--subject-distance", "4")
    assert "lists 3 totems but there are 2 totems given" in one_line_exit_2(proc)


def test_a_photo_without_masks_is_one_line_and_exit_2(tmp_path):
    image = np.full((60, 80, 3), 0.5, np.float32)
    scene = folder.write_scene(tmp_path / "s", image=image, K=camera.intrinsics(80, 60, 60),
                               masks=np.zeros((0, 60, 80), bool), radius=0.05, ior=1.5)
    proc = totems("plan", "--photo", scene, "--subject-distance", "4")
    assert "no totem masks" in one_line_exit_2(proc)


@pytest.mark.slow
def test_a_plan_from_a_test_photo_reads_its_masks_and_key(tmp_path):
    """A rendered scene's masks and key give its totems' poses (close to the truth's),
    and the plan of that photo is drawn over it, in its folder by default."""
    from scenes.synthetic.make import make_scene

    scene = make_scene(tmp_path / "box", preset="box", seed=2, size=(160, 120), spp=4)
    truth = folder.read_truth(scene)
    key = json.loads((scene / "totems.json").read_text())
    proc = totems("plan", "--photo", scene, "--subject-distance", "5", "--json")
    assert proc.returncode == 0, proc.stderr
    saved = json.loads((scene / "totems-out" / "plan" / "plan.json").read_text())
    centers = np.array([t["center"] for t in saved["totems"]])
    assert len(centers) == len(truth.totem_pose)
    for P in truth.totem_pose:        # the masks are left to right, the truth need not be
        near = np.linalg.norm(centers - P, axis=1).min()
        assert near < 0.03 * np.linalg.norm(P)
    radius = key["radius"] if isinstance(key, dict) else key[0]["radius"]
    assert saved["totems"][0]["radius"] == pytest.approx(radius)
    png = folder.read_image(scene / "totems-out" / "plan" / "plan.png")
    photo = folder.read_image(scene / "image.png")
    assert png.shape == photo.shape
    with np.load(scene / "totems-out" / "plan" / "reach.npz") as z:
        reach, region = Reach.from_dict(z), z["region"]
    inside = reach.in_reach()
    short = (reach.n_totems >= 2) & ~inside & ~reach.excluded
    tints = [ndimage.binary_erosion(m & r, iterations=2)      # away from the outlines
             for m in (inside, short) for r in (region, ~region)]
    most = max(tints, key=np.sum)                    # pixels tinted alike show the photo
    assert most.mean() > 0.2
    for c in range(3):
        assert np.corrcoef(png[most][:, c], photo[most][:, c])[0, 1] > 0.8
