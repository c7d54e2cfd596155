"""The support plane from resting totems (inverse/view/support.py), against planes and
spheres built by hand, and the camera view it caps."""

import numpy as np
import pytest

from inverse.view.support import plane_from_centres, ray_plane


def _resting(normal, offset, radius, spots):
    """Spheres of ``radius`` resting on ``N . X = h`` at in-plane points ``spots``."""
    N = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) - N[0] * N        # in-plane x: the camera's x
    a /= np.linalg.norm(a)
    b = np.cross(N, a)
    b *= np.sign(b[2])                              # in-plane y: away from the camera
    base = offset * N                               # the plane's point nearest the camera
    return np.array([base + x * a + y * b + r * N for (x, y), r in zip(spots, radius)])


# a table 0.45 m below the camera's centre, tilted towards it (as tabletop's)
N_TABLE = np.array([0.03, -0.82, -0.57])
N_TABLE /= np.linalg.norm(N_TABLE)


@pytest.mark.parametrize("radius", [(0.07, 0.07, 0.07), (0.06, 0.075, 0.08)])
def test_three_resting_totems_give_their_plane(radius):
    C = _resting(N_TABLE, -0.45, radius, [(-0.2, 0.5), (0.05, 0.7), (0.25, 0.6)])
    plane = plane_from_centres(C, radius)
    assert plane is not None
    np.testing.assert_allclose(plane.normal, N_TABLE, atol=1e-9)
    assert plane.offset == pytest.approx(-0.45, abs=1e-9)
    # each totem touches the plane one radius below its centre
    touch = plane.contact_points(C, radius)
    np.testing.assert_allclose(touch @ N_TABLE, -0.45, atol=1e-9)


def test_four_resting_totems_with_a_millimetre_of_pose_error():
    rng = np.random.default_rng(3)
    R = np.array([0.1, 0.1, 0.1, 0.1])
    C = _resting([0, -1, -0.25], -1.0, R, [(-0.4, 2), (0.1, 2.5), (0.5, 2.2), (0, 3)])
    C += rng.normal(0, 0.001, C.shape)
    plane = plane_from_centres(C, R)
    assert plane is not None and plane.residual < 0.002
    N = np.array([0, -1, -0.25]) / np.linalg.norm([0, -1, -0.25])
    assert np.degrees(np.arccos(plane.normal @ N)) < 2.0


def test_floating_totems_at_different_heights_have_no_plane():
    R = np.full(4, 0.1)
    C = _resting([0, -1, 0], -1.0, R, [(-0.4, 2), (0.1, 2.5), (0.5, 2.2), (0, 3)])
    C[1] += [0, -0.3, 0]                            # one totem 30 cm up in the air
    assert plane_from_centres(C, R) is None
    assert plane_from_centres(C[:2], R[:2]) is None  # two never fix a plane


def test_a_plane_above_the_camera_is_refused():
    # totems on a shelf above the camera: the camera sees the shelf from below
    R = np.full(3, 0.07)
    C = _resting([0, -1, 0], 0.3, R, [(-0.2, 1), (0, 1.3), (0.2, 1.1)])
    assert plane_from_centres(C, R) is None


def test_ray_plane_distance():
    d = np.array([[0, 0.6, 0.8], [0, -0.6, 0.8]])
    t = ray_plane(np.zeros(3), d, np.array([0, -1.0, 0]), -0.3)   # the plane y = 0.3
    assert t[0] == pytest.approx(0.5)
    assert np.isinf(t[1])                           # looks up, away from it



def test_the_plane_caps_a_view_that_put_the_table_at_infinity():
    """Rays from three totems' positions land on a striped table (y = 0.3 m below the
    camera); a fit that put everything at the far plane is mended where the camera sees
    the table, the rows above the horizon keep the fit's view, and the new points lie on
    the table."""
    from inverse.grid import frame_for_scene
    from inverse.rays import TotemRays
    from inverse.view.support import plane_view
    from scenes.camera import pixel_rays
    from scenes.colour import srgb_to_linear

    W, H = 160, 120
    K = np.array([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]])
    R = np.full(3, 0.07)
    C = np.array([[-0.2, 0.23, 1.0], [0.0, 0.23, 1.2], [0.2, 0.23, 1.1]])
    plane = plane_from_centres(C, R)
    assert plane is not None and plane.offset == pytest.approx(-0.3)

    def stripes(X):                                 # sRGB on the table, 10 cm stripes
        g = 0.2 + 0.6 * (np.floor(X[:, 2] / 0.1) % 2)
        return np.stack([g, 0.5 * g, 0.3 + 0 * g], 1)

    rng = np.random.default_rng(0)
    o, d, rad, tot = [], [], [], []
    for j, P in enumerate(C):                       # each totem's rays fan out over the table
        target = np.stack([rng.uniform(-0.8, 0.8, 4000), np.full(4000, 0.3),
                           rng.uniform(0.6, 3.0, 4000)], 1)
        dj = target - P
        dj /= np.linalg.norm(dj, axis=1, keepdims=True)
        o.append(np.repeat(P[None], 4000, 0))
        d.append(dj)
        rad.append(srgb_to_linear(stripes(target)))
        tot.append(np.full(4000, j))
    rays = TotemRays(np.concatenate(o), np.concatenate(d), np.concatenate(rad),
                     np.concatenate(tot), np.ones(12000))
    frame = frame_for_scene(K, (W, H), C, R)
    grey = np.full((H, W, 3), 0.5, np.float32)
    far = np.full((H, W), frame.far, np.float32)
    recon, depth, points, share = plane_view(rays, frame, plane, grey, far,
                                             np.zeros((0, 3)), (W, H))
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    dc = pixel_rays(K, uu.ravel().astype(float), vv.ravel().astype(float))
    t = ray_plane(np.zeros(3), dc, plane.normal, plane.offset)
    X = t[:, None] * dc
    on_table = (np.isfinite(t) & (X[:, 2] > 0.8) & (X[:, 2] < 2.5)
                & (np.abs(X[:, 0]) < 0.6)).reshape(H, W)
    truth = stripes(np.where(np.isfinite(X), X, 0)).reshape(H, W, 3)
    err_new = np.abs(recon - truth).mean(2)[on_table].mean()
    err_old = np.abs(grey - truth).mean(2)[on_table].mean()
    assert on_table.sum() > 1000
    assert err_new < 0.5 * err_old
    assert np.all(recon[0] == grey[0])              # above the horizon: the fit's view
    np.testing.assert_allclose(depth[on_table], X[on_table.ravel(), 2], rtol=0.05)
    assert len(points) > 1000
    off = np.abs(points @ plane.normal - plane.offset)  # metres off the table
    assert np.percentile(off, 95) < 0.01
    assert 0.2 < share < 0.9


@pytest.mark.slow
def test_a_small_tabletop_is_rebuilt_better_with_its_resting_plane(tmp_path):
    """Tabletop seed 31 (a development seed) at 160 x 120: the fit told the totems rest
    rebuilds the camera view better, on the region today's fit protects, than the fit
    that is not (0.337 against 0.394 when written), and protects about as much (the
    plane caps the view, not the region: with the plane's end points it fell to a
    fifth)."""
    from inverse.fit.fit import FitSettings, fit_scene
    from scenes import folder
    from scenes.synthetic.make import make_scene
    from verify.metrics.region import protected_region

    make_scene(tmp_path / "s", preset="tabletop", seed=31, size=(160, 120), spp=16)
    scene, truth = folder.read_scene(tmp_path / "s"), folder.read_truth(tmp_path / "s")
    totem = scene.masks.any(0)
    stages = ((0.5, 100), (1.0, 100))
    plain = fit_scene(scene, settings=FitSettings(stages=stages))
    rest = fit_scene(scene, settings=FitSettings(stages=stages, resting=True))
    assert plain.geometry["support"] is None and rest.geometry["support"]["share"] > 0.3
    seen = protected_region(plain.totem_points, scene.K, scene.size,
                            n_totem_pixels=int(totem.sum())) & ~totem
    err = [np.abs(f.recon - truth.clean).mean(2)[seen].mean() for f in (plain, rest)]
    assert err[1] < err[0] - 0.02
    share = [protected_region(f.totem_points, scene.K, scene.size,
                              n_totem_pixels=int(totem.sum())).mean() for f in (plain, rest)]
    assert abs(share[1] - share[0]) < 0.25 * share[0]
