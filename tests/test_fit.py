"""Tests of inverse/grid, inverse/integrator and inverse/fit: the frustum frame, the
gradients of the rendered totem colour (finite differences), the fit on a small
rendered scene, the fit/ files round trip and bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from inverse.grid import FrustumFrame, frame_for_scene, resample
from scenes import backend, camera
from scenes import colour
from scenes.errors import BadInput
from scenes.synthetic import render

dr, mi = backend.modules()

W, H = 80, 60
K = camera.intrinsics(W, H, 60.0)
CENTERS = np.array([[-0.25, 0.1, 1.4], [0.25, 0.12, 1.5]])
RADIUS = np.array([0.1, 0.1])
IOR = np.array([1.52, 1.52])


def _sphere_pixels(j=0, step=1):
    """Pixels whose rays hit totem j (analytic), and their unit directions."""
    vv, uu = np.mgrid[0:H:step, 0:W:step]
    d = camera.pixel_rays(K, uu.ravel(), vv.ravel())
    P = CENTERS[j]
    b = d @ P
    disc = b ** 2 - (P @ P - RADIUS[j] ** 2)
    hit = disc > (0.3 * RADIUS[j]) ** 2          # away from the grazing rim
    return d[hit], np.full(hit.sum(), j)


def _integrator(seed=0, centers=CENTERS):
    from inverse.integrator import TotemGridIntegrator

    rng = np.random.default_rng(seed)
    frame = frame_for_scene(K, (W, H), CENTERS, RADIUS)
    density = rng.normal(-2.0, 1.0, (6, 8, 10, 1)).astype(np.float32)
    colour = rng.random((3, 8, 10, 3)).astype(np.float32)
    itg = TotemGridIntegrator(mi.Properties()).setup(frame, density, colour, centers,
                                                     RADIUS, IOR)
    itg.n_samples = 32
    return itg, frame, density, colour


# --------------------------------------------------------------------------- the frame

def test_frame_round_trip_and_camera_columns():
    frame = frame_for_scene(K, (W, H), CENTERS, RADIUS)
    rng = np.random.default_rng(1)
    g = rng.random((50, 3))
    X = frame.from_unit(g)
    assert np.allclose(frame.to_unit(X), g, atol=1e-9)
    # Points along one camera ray share (s, t): the view is straight columns.
    d = camera.pixel_rays(K, np.array([13.0]), np.array([41.0]))[0]
    gs = frame.to_unit(np.outer(np.linspace(1.0, 5.0, 7), d))
    assert np.ptp(gs[:, 0]) < 1e-9 and np.ptp(gs[:, 1]) < 1e-9
    s, t = frame.pixel_to_st(13.0, 41.0)
    assert np.allclose([s, t], gs[0, :2])
    # r is inverse depth: even in 1/z.
    z = frame.from_unit(np.array([[0.5, 0.5, 0.0], [0.5, 0.5, 0.5], [0.5, 0.5, 1.0]]))[:, 2]
    assert np.isclose(z[0], frame.near) and np.isclose(z[2], frame.far)
    assert np.isclose(1 / z[1], 0.5 * (1 / z[0] + 1 / z[2]))
    back = FrustumFrame.from_dict(frame.to_dict())
    assert np.allclose(back.K, frame.K) and back.u_range == frame.u_range
    assert (back.near, back.far, back.v_range) == (frame.near, frame.far, frame.v_range)


def test_resample_keeps_a_linear_field():
    D, Hh, Ww = 4, 5, 6
    z, y, x = np.meshgrid((np.arange(D) + 0.5) / D, (np.arange(Hh) + 0.5) / Hh,
                          (np.arange(Ww) + 0.5) / Ww, indexing="ij")
    f = (2 * x + 3 * y - z)[..., None]
    g = resample(f, (8, 10, 12))
    z2, y2, x2 = np.meshgrid((np.arange(8) + 0.5) / 8, (np.arange(10) + 0.5) / 10,
                             (np.arange(12) + 0.5) / 12, indexing="ij")
    inner = (slice(1, -1),) * 3
    assert np.allclose(g[..., 0][inner], (2 * x2 + 3 * y2 - z2)[inner], atol=1e-5)


# --------------------------------------------------------------------------- gradients

def _totem_colour_sum(itg, d, j, weights):
    L, valid, *_ = itg.render_totem_rays(d, j)
    return dr.sum(dr.select(valid, weights[0] * L.x + weights[1] * L.y + weights[2] * L.z,
                            0.0)), valid


def test_grid_value_gradient_matches_finite_differences():
    itg, frame, density, colour = _integrator()
    d, j = _sphere_pixels(0, step=2)
    wts = (0.3, 0.5, 0.2)
    params = mi.traverse(itg)
    dr.enable_grad(params["density"])
    dr.enable_grad(params["colour"])
    params.update()
    f, valid = _totem_colour_sum(itg, d, j, wts)
    assert np.asarray(valid).mean() > 0.8
    dr.backward(f)
    g_d = np.asarray(dr.grad(params["density"])).reshape(density.shape)
    g_c = np.asarray(dr.grad(params["colour"])).reshape(colour.shape)

    def value(den, col):
        itg2 = _integrator()[0]
        itg2.setup(frame, den, col, CENTERS, RADIUS, IOR)
        return float(_totem_colour_sum(itg2, d, j, wts)[0][0])

    for grid, g, which in ((density, g_d, "d"), (colour, g_c, "c")):
        for idx in np.argsort(np.abs(g).ravel())[-3:]:
            e = 1e-2
            plus, minus = grid.copy(), grid.copy()
            plus.ravel()[idx] += e
            minus.ravel()[idx] -= e
            if which == "d":
                fd = (value(plus, colour) - value(minus, colour)) / (2 * e)
            else:
                fd = (value(density, plus) - value(density, minus)) / (2 * e)
            assert abs(g.ravel()[idx]) > 1e-3
            assert fd == pytest.approx(g.ravel()[idx], rel=0.05, abs=1e-3), (which, idx)


def test_totem_centre_gradient_matches_finite_differences():
    itg, frame, density, colour = _integrator(seed=3)
    d, j = _sphere_pixels(0, step=2)
    wts = (0.3, 0.5, 0.2)
    params = mi.traverse(itg)
    dr.enable_grad(params["centers"])
    params.update()
    f, valid = _totem_colour_sum(itg, d, j, wts)
    base_valid = np.asarray(valid, bool)
    dr.backward(f)
    g = np.asarray(dr.grad(params["centers"])).reshape(3, -1).T   # (n, 3)
    assert np.all(g[1] == 0)                  # totem 1 is not in these pixels
    for a in range(3):
        e = 5e-4
        vals, oks = [], []
        for sgn in (1, -1):
            c = CENTERS.copy()
            c[0, a] += sgn * e
            itg2 = _integrator(seed=3, centers=c)[0]
            itg2.setup(frame, density, colour, c, RADIUS, IOR)
            L, ok = itg2.render_totem_rays(d, j)[:2]
            vals.append(wts[0] * np.asarray(L.x) + wts[1] * np.asarray(L.y)
                        + wts[2] * np.asarray(L.z))
            oks.append(np.asarray(ok, bool))
        # A ray whose validity flips within +-e is a jump, not a derivative: skip it
        # (it must be rare).
        same = base_valid & oks[0] & oks[1]
        assert same.sum() >= base_valid.sum() - 3
        vals = [float(x[same].sum()) for x in vals]
        fd = (vals[0] - vals[1]) / (2 * e)
        assert fd == pytest.approx(float(g[0, a]), rel=0.1, abs=0.02 * float(np.abs(g[0]).max()))


def test_camera_columns_through_mitsuba_render():
    """The registered integrator renders the grid like render_view does (no totems)."""
    from inverse.integrator import TotemGridIntegrator
    from inverse.view import view

    loaded = mi.load_dict({"type": "totem_grid", "n_samples": 8})
    assert isinstance(loaded, TotemGridIntegrator) and loaded.n_samples == 8
    itg, frame, *_ = _integrator(seed=5)
    scene = mi.load_dict({"type": "scene",
                          "sensor": camera.mitsuba_sensor(K, W, H, spp=4)})
    img = np.asarray(mi.render(scene, integrator=itg, spp=4))
    recon, depth = view.render_view(itg, frame, (W, H), n=32)
    lin = colour.srgb_to_linear(recon)
    # Pixel footprints differ (random sub-pixel positions), so compare means/edges.
    assert np.abs(img - lin).mean() < 0.02
    assert np.all((depth >= frame.near - 1e-4) & (depth <= frame.far + 1e-3))


# --------------------------------------------------------------------------- the fit

@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    from scenes import folder
    from scenes.synthetic import presets

    desc = presets.describe("box", 3, size=(160, 120), n_totems=4)
    image = render.render(desc, spp=16)
    masks = render.totem_masks(desc)
    truth = np.array([t["center"] for t in desc["totems"]])
    scene = folder.Scene(path=tmp_path_factory.mktemp("s"), image=image,
                         K=np.asarray(desc["K"]), masks=masks,
                         radius=np.array([t["radius"] for t in desc["totems"]]),
                         ior=np.array([t["ior"] for t in desc["totems"]]))
    return scene, truth


def _perturbed(small_scene, steps=(20, 30)):
    """The small scene starting from its true centres but totem 1's moved 12 mm and 8 mm
    sideways, the true centres, that start, and small fit settings for it."""
    from inverse.fit import fit

    scene, truth = small_scene
    init = truth.copy()
    init[1] += np.array([0.012, -0.008, 0.0])
    st = fit.FitSettings(density_res=(16, 24, 32), colour_res=(1, 30, 40),
                         stages=((0.5, steps[0]), (1.0, steps[1])), n_samples=32,
                         lr_pose=1e-3, pose_start=0.3, render_samples=32)
    return dataclasses.replace(scene, initial_pose=init), truth, init, st


@pytest.mark.slow
def test_fit_lowers_loss_and_pulls_a_perturbed_centre_back(small_scene, tmp_path):
    from inverse.fit import fit, files
    from inverse.view import view

    scene, truth, init, st = _perturbed(small_scene)
    r = fit.fit_scene(scene, settings=st)
    photo = np.asarray(r.history["photo"])
    assert photo[-5:].mean() < 0.8 * photo[:3].mean()
    err0 = np.abs(init[1] - truth[1]).sum()
    err1 = np.abs(r.centers[1] - truth[1]).sum()
    assert err1 < 0.8 * err0
    assert np.allclose(r.initial, init)
    # The pose's path: one (n, 3) per step, still until the centres are freed, then
    # leaving the initial centres for where the fit put them.
    path = np.asarray(r.history["centers"])
    assert path.shape == (len(photo), 4, 3)
    freed = int(round(st.pose_start * len(photo)))
    assert np.allclose(path[:freed], init, atol=1e-6)
    assert np.abs(path[-1] - truth).sum(1)[1] < err0
    if r.timings["pose_accepted"]:
        assert np.allclose(path[-1], r.centers, atol=1e-6)
    assert r.recon.shape == (120, 160, 3) and r.recon.dtype == np.float32
    assert np.all((r.recon >= 0) & (r.recon <= 1))
    assert r.totem_points.shape[1] == 3 and len(r.totem_points) > 100
    # The fitted totem pixels resemble the observed ones more than a flat colour does.
    m = scene.masks.any(0) & (r.totem_pred.sum(2) > 0)
    obs = scene.image[m]
    assert np.abs(r.totem_pred[m] - obs).mean() < np.abs(obs.mean(0) - obs).mean()

    # write_fit / load_fit round trip, and re-rendering from the saved grid.
    files.write_fit(r, tmp_path / "fit", scene=scene)
    back = files.load_fit(tmp_path / "fit")
    assert np.allclose(back.centers, r.centers) and np.allclose(back.initial, r.initial)
    assert np.allclose(back.totem_points, r.totem_points)
    assert np.abs(back.recon - r.recon).max() <= 1 / 255 + 1e-6
    assert back.scene_fingerprint == files.scene_fingerprint(scene)
    assert back.pose_uncertainty is None                 # a given initial pose
    # The fitted colour the glass reflects is kept: linear RGB, non-negative.
    assert back.ambient == r.ambient and len(r.ambient) == 3
    assert min(r.ambient) >= 0.0 and max(r.ambient) > 0.0
    # The totem rays verify reads leave the fitted spheres outwards, unit, and come back.
    rays = back.rays
    P = r.centers[rays.totem]
    assert np.allclose(np.linalg.norm(rays.o - P, axis=1), scene.radius[rays.totem],
                       atol=1e-5)
    assert np.allclose(np.linalg.norm(rays.d, axis=1), 1.0, atol=1e-5)
    assert np.all(((rays.o - P) * rays.d).sum(1) > 0)
    assert np.allclose(rays.radiance, r.rays.radiance, atol=1e-6)
    assert set(np.unique(rays.totem)) == set(range(len(r.centers)))      # every totem
    # The view comes from the geometry the held-out totems preferred, ...
    assert back.geometry == r.geometry
    held = r.geometry["holdout_L1"]
    assert set(held) == {"grid", "stereo", "stereo_far1"}
    # Stereo must beat the grid by the margin (its hold-out divided by it).
    margin = r.settings["stereo_margin"]
    scaled = {k: e / (1.0 if k == "grid" else margin) for k, e in held.items()}
    assert scaled[r.geometry["chosen"]] == min(scaled.values())
    # Without stereo the view is the grid's, and a saved grid re-renders it.
    grid_only = fit.fit_scene(scene, settings=dataclasses.replace(st, stereo=False),
                              fixed_pose=True)
    assert grid_only.geometry["chosen"] == "grid"
    recon2, _ = view.render_grid(grid_only.grid, scene.size, n=32)
    assert np.abs(recon2 - grid_only.recon).max() < 1e-3
    # The fingerprint follows what the fit reads: the totem pixels and the key.
    outside = scene.image.copy()
    outside[~scene.masks.any(0)] = 0.5
    assert files.scene_fingerprint(dataclasses.replace(scene, image=outside)) \
        == back.scene_fingerprint
    assert files.scene_fingerprint(dataclasses.replace(scene, image=scene.image[::-1])) \
        != back.scene_fingerprint
    assert files.scene_fingerprint(dataclasses.replace(scene, ior=scene.ior + 0.01)) \
        != back.scene_fingerprint


def test_the_fingerprint_covers_the_band_the_rim_search_reads(small_scene):
    # With no given initial pose the pose comes from the rims, read within rim.READ_PX of
    # each mask: a pixel there changes the fit, one farther away does not.
    from scipy.ndimage import binary_dilation

    from inverse.fit import files
    from inverse.pose import rim

    scene, _ = small_scene
    scene = dataclasses.replace(scene, initial_pose=None)
    masks = scene.masks.any(0)
    band = binary_dilation(masks, iterations=rim.READ_PX) & ~masks
    far = ~binary_dilation(masks, iterations=rim.READ_PX + 1)
    base = files.scene_fingerprint(scene)
    for where, same in ((band, False), (far, True)):
        v, u = np.argwhere(where)[len(np.argwhere(where)) // 2]
        image = scene.image.copy()
        image[v, u] = 1.0 - image[v, u]
        got = files.scene_fingerprint(dataclasses.replace(scene, image=image))
        assert (got == base) == same


def test_the_default_pose_weighs_mask_and_photo_and_says_how_sure(small_scene):
    # No given pose: the masks' and the photo's weighed (fit.json pose_uncertainty);
    # the --pose-from overrides give none.
    from inverse.fit import fit

    scene, truth = small_scene
    scene = dataclasses.replace(scene, initial_pose=None)
    K, R = np.asarray(scene.K), np.asarray(scene.radius, float)
    centers, fixed, sd = fit._initial_pose(scene, K, R, None, False)
    assert not fixed and len(sd) == len(truth)
    assert all(s["along_mm"] > s["across_mm"] > 0 and 0 <= s["mask_share"] <= 1
               for s in sd)
    err = np.linalg.norm(centers - truth, axis=1) / np.linalg.norm(truth, axis=1)
    assert err.max() < 0.02, err                     # exact masks, 160 x 120
    for how in ("photo", "mask"):
        assert fit._initial_pose(scene, K, R, None, False, how)[2] is None


def test_load_fit_refuses_missing_or_corrupt(tmp_path):
    from inverse.fit import files

    with pytest.raises(BadInput):
        files.load_fit(tmp_path / "nothing")
    d = tmp_path / "fit"
    d.mkdir()
    for name in files.FIT_FILES:
        (d / name).write_bytes(b"garbage")
    with pytest.raises(BadInput):
        files.load_fit(d)


def test_bad_input(small_scene):
    from inverse.fit import fit

    scene, truth = small_scene
    nan = scene.image.copy()
    nan[3, 4, 1] = np.nan
    with pytest.raises(BadInput, match="NaN"):
        fit.fit_scene(dataclasses.replace(scene, image=nan))
    with pytest.raises(BadInput, match="no totem pixels"):
        fit.fit_scene(dataclasses.replace(scene, masks=np.zeros_like(scene.masks)))
    # A key whose radius puts the totems behind the camera: no usable ray.
    with pytest.raises(BadInput):
        fit.fit_scene(dataclasses.replace(scene, radius=np.full(4, 5.0)),
                      true_pose=truth)


def test_rays_leaving_through_the_top_face_are_told_apart():
    from inverse.integrator import FrameConstants, leaves_through_top, ray_segment

    frame = frame_for_scene(K, (W, H), CENTERS, RADIUS)
    fc = FrameConstants(frame)
    o = mi.Point3f(0.0, 0.0, 2.0)                       # inside the frustum, metres
    up, ahead, down = [0.0, -1.0, 0.2], [0.0, 0.0, 1.0], [0.0, 1.0, 0.2]   # +y is down
    d = mi.Vector3f(*[np.array(v, np.float32) for v in zip(up, ahead, down)])
    d = dr.normalize(d)
    g0, g1, valid = ray_segment(fc, o, d)
    assert np.all(np.asarray(valid))
    g1y, g1r = np.asarray(g1.y), np.asarray(g1.z)
    assert g1y[0] == pytest.approx(0.0, abs=1e-4) and g1r[0] < 1.0     # top face
    assert g1r[1] == pytest.approx(1.0, abs=1e-4)                       # far plane
    assert g1y[2] == pytest.approx(1.0, abs=1e-4)                       # bottom face
    assert np.asarray(leaves_through_top(g1)).tolist() == [True, False, False]


def test_ray_batches_cover_every_ray_once_an_epoch_in_a_seeded_order():
    from inverse.fit.batches import ray_batches

    n, size = 1000, 300
    gen = ray_batches(n, size, seed=3)
    drawn = np.concatenate([next(gen) for _ in range(10)])         # 3000 = 3 epochs
    assert all(len(b) == size for b in np.split(drawn, 10))
    for epoch in np.split(drawn, 3):
        assert np.array_equal(np.sort(epoch), np.arange(n))
    again = ray_batches(n, size, seed=3)
    assert np.array_equal(np.concatenate([next(again) for _ in range(10)]), drawn)
    other = ray_batches(n, size, seed=4)
    assert not np.array_equal(next(other), drawn[:size])
    assert next(ray_batches(n, 0, seed=3)) is None               # full batch
    assert next(ray_batches(n, n + 5, seed=3)) is None


def test_a_batch_holding_every_ray_gives_the_full_photometric_term():
    from inverse.fit.batches import DeviceRays, photo_terms
    from inverse.rays import TotemPixels

    itg, frame, _, _ = _integrator()
    d0, j0 = _sphere_pixels(0, 2)
    d1, j1 = _sphere_pixels(1, 2)
    d, j = np.concatenate([d0, d1]), np.concatenate([j0, j1])
    rng = np.random.default_rng(1)
    observed = rng.random((len(j), 3)).astype(np.float32)
    pixels = TotemPixels(u=np.zeros(len(j), int), v=np.zeros(len(j), int), d_cam=d,
                         totem=j, observed=observed)
    rays = DeviceRays.upload(pixels, np.full(len(j), 0.04))
    ambient = mi.Float([0.1, 0.2, 0.3])
    photo, dist = photo_terms(itg, rays, ambient)
    shuffled = rays.batch(rng.permutation(len(j)))
    photo_b, dist_b = photo_terms(itg, shuffled, ambient)
    assert float(photo[0]) > 0
    assert abs(float(photo_b[0]) - float(photo[0])) <= 1e-5 * float(photo[0])
    assert abs(float(dist_b[0]) - float(dist[0])) <= 1e-5 * abs(float(dist[0])) + 1e-9
    half = rays.batch(np.arange(len(j) // 2))
    assert dr.width(half.refl) == len(j) // 2


@pytest.mark.slow
def test_a_batched_fit_recovers_the_pose_and_the_view_as_the_full_batch_one(small_scene):
    from inverse.fit import fit

    scene, truth, init, st = _perturbed(small_scene, steps=(40, 60))
    st = dataclasses.replace(st, stereo=False)
    full = fit.fit_scene(scene, settings=dataclasses.replace(st, batch_rays=0))
    n_rays = full.timings["n_rays"]
    batched = fit.fit_scene(scene, settings=dataclasses.replace(st, batch_rays=n_rays // 4))
    err0 = np.abs(init[1] - truth[1]).sum()
    for r in (full, batched):
        path = np.asarray(r.history["centers"])
        assert np.abs(path[-1] - truth).sum(1)[1] < 0.8 * err0
    # The view and the totem pixels come out as well as with every ray at each step.
    m = scene.masks.any(0) & (batched.totem_pred.sum(2) > 0)
    e_full = np.abs(full.totem_pred[m] - scene.image[m]).mean()
    e_batch = np.abs(batched.totem_pred[m] - scene.image[m]).mean()
    assert e_batch < 1.2 * e_full
    assert np.abs(batched.recon - full.recon).mean() < 0.03


@pytest.mark.slow
def test_two_fits_of_one_photo_agree_to_the_last_bit(small_scene):
    """Same photo, same answer: the batches are seeded and the grids' gradients summed in
    fixed point, so the grid, the centres, the losses and the view of two fits whose
    backward pass runs on two threads, and of a third on one, are equal, not merely
    close."""
    from inverse.fit import fit
    from scenes import backend

    scene, _, _, st = _perturbed(small_scene, steps=(10, 20))
    st = dataclasses.replace(st, batch_rays=512)
    with backend.one_thread():                             # every kernel on one thread
        c = fit.fit_scene(scene, settings=st)
    assert backend.modules()[0].thread_count() >= 2
    a, b = (fit.fit_scene(scene, settings=st) for _ in range(2))
    for r in (b, c):
        assert a.history["loss"] == r.history["loss"]
        assert np.array_equal(a.centers, r.centers)
        for k in ("density", "colour"):
            assert np.array_equal(a.grid[k], r.grid[k])
        assert np.array_equal(a.recon, r.recon) and np.array_equal(a.recon_depth, r.recon_depth)
        assert a.geometry == r.geometry


def test_mirror_adds_the_fresnel_weighted_grid_along_the_forward_mirrored_ray():
    """With ``mirror`` set, a totem pixel gains R_F times the grid's colour along the
    camera ray mirrored at its entry point (computed here by hand), where that ray goes
    forward; a grid of one colour, opaque everywhere, makes that colour what it sees."""
    from inverse.integrator import TotemGridIntegrator

    frame = frame_for_scene(K, (W, H), CENTERS, RADIUS)
    grey = np.array([0.2, 0.5, 0.8], np.float32)
    itg = TotemGridIntegrator(mi.Properties()).setup(
        frame, np.full((6, 8, 10, 1), 30.0, np.float32),
        np.broadcast_to(grey, (1, 8, 10, 3)).copy(), CENTERS, RADIUS, IOR)
    itg.n_samples = 32
    d, j = _sphere_pixels(0, step=1)
    base = np.asarray(itg.render_totem_rays(d, j)[0]).T
    itg.mirror = True
    gain = np.asarray(itg.render_totem_rays(d, j)[0]).T - base
    added, ok = itg.mirrored_numpy(d, j)
    np.testing.assert_allclose(gain, added, atol=1e-6)
    P, R = CENTERS[0], RADIUS[0]
    b = d @ P
    t = b - np.sqrt(b ** 2 - (P @ P - R ** 2))
    N = (d * t[:, None] - P) / R
    r = d - 2.0 * (d * N).sum(1)[:, None] * N
    T = np.asarray(itg.refract(d, j)[2])
    forward = r[:, 2] > 0.02
    assert forward.sum() > 10 and (~forward).sum() > 10
    assert not ok[r[:, 2] < -0.02].any()            # towards the camera: the ambient's
    sure = forward & ok
    assert sure.sum() > 0.5 * forward.sum()
    np.testing.assert_allclose(added[sure], (1.0 - np.sqrt(T))[sure, None] * grey,
                               rtol=1e-3, atol=1e-6)
