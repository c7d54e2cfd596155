"""inverse/sphere: ray/sphere intersection and refraction through a totem.

Checked against an independent float64 numpy implementation (textbook quadratic, the
paper's vector form of Snell's law, textbook Fresnel), against Snell's law and the
sphere's symmetries directly, and the Dr.Jit gradients against finite differences.
"""

import numpy as np
import pytest

from inverse import sphere
from scenes import backend

dr, mi = backend.modules()


# ----------------------------------------------------------------- numpy twin (f64)

def np_intersect(o, d, P, R):
    """Textbook roots of |o + t d - P|^2 = R^2 (float64); NaN where missing."""
    a = np.sum(d * d, -1)
    b = 2 * np.sum((o - P) * d, -1)
    c = np.sum((o - P) ** 2, -1) - R ** 2
    disc = b * b - 4 * a * c
    s = np.sqrt(np.where(disc > 0, disc, np.nan))
    return (-b - s) / (2 * a), (-b + s) / (2 * a)


def np_refract(n1, n2, N, d):
    """Paper supp. A.1: n1/n2 (N x (-N x d)) - N sqrt(1 - (n1/n2)^2 |N x d|^2).

    N is the unit normal on the incident side (facing against d)."""
    r = (n1 / n2)[..., None]
    cross = np.cross(N, d)
    k = 1 - (n1 / n2) ** 2 * np.sum(cross ** 2, -1)
    return r * np.cross(N, np.cross(-N, d)) - N * np.sqrt(k)[..., None]


def np_fresnel(n1, n2, cos_i):
    """Unpolarised Fresnel reflectance, textbook (Hecht) s and p amplitudes."""
    sin_t = n1 / n2 * np.sqrt(1 - cos_i ** 2)
    cos_t = np.sqrt(1 - sin_t ** 2)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return 0.5 * (rs ** 2 + rp ** 2)


def np_totem(o, d, P, R, n):
    """Entry, inside direction, exit, exit direction and T, all float64."""
    ones = np.ones(len(d))
    t0, _ = np_intersect(o, d, P, R)
    D = o + t0[:, None] * d
    N1 = (D - P) / R[:, None]
    d_mid = np_refract(ones, n, N1, d)
    _, t1 = np_intersect(D, d_mid, P, R)
    E = D + t1[:, None] * d_mid
    N2 = (E - P) / R[:, None]
    d_out = np_refract(n, ones, -N2, d_mid)
    cos1 = -np.sum(d * N1, -1)
    cos2 = np.sum(d_mid * N2, -1)
    T = (1 - np_fresnel(ones, n, cos1)) * (1 - np_fresnel(n, ones, cos2))
    return D, d_mid, E, d_out, T


# ----------------------------------------------------------------- helpers

def vec(a, cls=mi.Vector3f):
    a = np.asarray(a, dtype=np.float32)
    return cls(a[:, 0], a[:, 1], a[:, 2])


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle_to(v, N):
    """sin of the angle between unit vectors v and the line of N."""
    return np.linalg.norm(np.cross(v, N), axis=-1)


@pytest.fixture(scope="module")
def rays():
    """Camera rays hitting three totems (various P, R, eta), not grazing."""
    rng = np.random.default_rng(3)
    m = 300
    centers = np.array([[-0.3, 0.2, 1.2], [0.05, 0.15, 0.8], [0.4, 0.25, 2.0]])
    radii = np.array([0.1, 0.05, 0.15])
    iors = np.array([1.52, 1.33, 1.9])
    j = rng.integers(0, 3, m)
    P, R, n = centers[j], radii[j], iors[j]
    o = rng.normal(0, 0.02, (m, 3))                 # small camera-origin offsets
    # Aim at points of the sphere's silhouette disc, at most 0.9 of its radius.
    axis = unit(P - o)
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u = unit(np.cross(axis, helper))
    w = np.cross(axis, u)
    r = 0.9 * np.sqrt(rng.uniform(0, 1, m)) * R
    phi = rng.uniform(0, 2 * np.pi, m)
    target = P + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * w
    d = unit(target - o)
    return dict(o=o, d=d, P=P, R=R, n=n)


def run(r, **kw):
    path = sphere.totem_path(vec(r["o"], mi.Point3f), vec(r["d"]), vec(r["P"], mi.Point3f),
                             mi.Float(r["R"].astype(np.float32)),
                             mi.Float(r["n"].astype(np.float32)), **kw)
    out = {k: (np.array(getattr(path, k), dtype=np.float64).T
               if k in ("D", "d_mid", "E", "d_out") else np.array(getattr(path, k)))
           for k in path._fields}
    return out


# ----------------------------------------------------------------- tests

def test_agrees_with_independent_numpy(rays):
    got = run(rays)
    D, d_mid, E, d_out, T = np_totem(rays["o"], rays["d"], rays["P"], rays["R"], rays["n"])
    assert got["valid"].all()
    np.testing.assert_allclose(got["D"], D, atol=1e-5)
    np.testing.assert_allclose(got["d_mid"], d_mid, atol=1e-5)
    np.testing.assert_allclose(got["E"], E, atol=1e-5)
    np.testing.assert_allclose(got["d_out"], d_out, atol=1e-5)
    np.testing.assert_allclose(got["T"], T, atol=1e-5)


def test_snell_coplanarity_and_points_on_sphere(rays):
    got = run(rays)
    P, R, n, d_in = rays["P"], rays["R"], rays["n"], rays["d"]
    N1 = (got["D"] - P) / R[:, None]
    N2 = (got["E"] - P) / R[:, None]
    # Entry and exit points on the sphere.
    np.testing.assert_allclose(np.linalg.norm(got["D"] - P, axis=1), R, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(got["E"] - P, axis=1), R, atol=1e-6)
    # Snell at both surfaces: n1 sin(theta1) = n2 sin(theta2).
    np.testing.assert_allclose(angle_to(d_in, N1), n * angle_to(got["d_mid"], N1), atol=2e-6)
    np.testing.assert_allclose(n * angle_to(got["d_mid"], N2), angle_to(got["d_out"], N2),
                               atol=1e-5)
    # The refracted ray goes to the other side of the surface.
    assert (np.sum(got["d_mid"] * N1, 1) < 0).all() and (np.sum(got["d_out"] * N2, 1) > 0).all()
    # Incident direction, normal and refracted direction are coplanar.
    for a, N, b in ((d_in, N1, got["d_mid"]), (got["d_mid"], N2, got["d_out"])):
        np.testing.assert_allclose(np.linalg.det(np.stack([a, N, b], 1)), 0, atol=2e-6)
    # Unit directions.
    for k in ("d_mid", "d_out"):
        np.testing.assert_allclose(np.linalg.norm(got[k], axis=1), 1, atol=1e-6)
    # Sphere symmetry: the exit angle at E equals the entry angle at D.
    np.testing.assert_allclose(np.sum(got["d_out"] * N2, 1), -np.sum(d_in * N1, 1), atol=1e-5)
    np.testing.assert_allclose(got["cos_in"], -np.sum(d_in * N1, 1), atol=1e-6)


def test_numpy_inputs_accepted(rays):
    """numpy arrays (n, 3) and (n,) work in place of Dr.Jit arrays."""
    a = sphere.totem_rays(rays["o"], rays["d"], rays["P"], rays["R"], rays["n"])
    b = sphere.totem_rays(vec(rays["o"], mi.Point3f), vec(rays["d"]), vec(rays["P"], mi.Point3f),
                          mi.Float(rays["R"].astype(np.float32)),
                          mi.Float(rays["n"].astype(np.float32)))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(np.array(x), np.array(y))
    with pytest.raises(ValueError, match="3-vector"):
        sphere.totem_rays(rays["o"][:, :2], rays["d"], rays["P"], rays["R"], rays["n"])


def test_ray_through_centre_is_undeviated():
    P = np.array([[0.1, -0.2, 1.5], [0.0, 0.0, 0.7]])
    d = unit(P)
    R = np.array([0.1, 0.2])
    o_out, d_out, T, valid = sphere.totem_rays(mi.Point3f(0, 0, 0), vec(d), vec(P, mi.Point3f),
                                               mi.Float(R.astype(np.float32)), 1.5)
    assert np.array(valid).all()
    np.testing.assert_allclose(np.array(d_out).T, d, atol=1e-6)
    np.testing.assert_allclose(np.array(o_out).T, P + R[:, None] * d, atol=1e-6)
    # Normal incidence: F = ((n - 1) / (n + 1))^2 at each surface.
    np.testing.assert_allclose(np.array(T), (1 - (0.5 / 2.5) ** 2) ** 2, rtol=1e-6)


def test_fresnel_transmittance_matches_textbook():
    eta = 1.52
    cos_i = np.linspace(0.05, 1.0, 40)
    N = np.tile([0.0, 0.0, 1.0], (40, 1))
    sin_i = np.sqrt(1 - cos_i ** 2)
    # Entering from outside (air -> glass), d travels against N.
    d_in = np.stack([sin_i, 0 * sin_i, -cos_i], 1)
    d_t, F, c, tir = sphere.refract(vec(d_in), vec(N), eta)
    np.testing.assert_allclose(np.array(F), np_fresnel(np.ones(40), eta * np.ones(40), cos_i),
                               atol=1e-6)
    np.testing.assert_allclose(np.array(c), cos_i, atol=1e-6)
    assert not np.array(tir).any()
    # Leaving (glass -> air), d travels along N; beyond the critical angle: TIR.
    d_out = np.stack([sin_i, 0 * sin_i, cos_i], 1)
    d_t, F, c, tir = sphere.refract(vec(d_out), vec(N), eta)
    with np.errstate(invalid="ignore"):
        d_t_np = np_refract(eta * np.ones(40), np.ones(40), -N, d_out)
    tir_np = sin_i * eta >= 1
    assert (np.array(tir) == tir_np).all() and tir_np.any() and (~tir_np).any()
    F_np = np_fresnel(eta * np.ones(40), np.ones(40), np.where(tir_np, 1.0, cos_i))
    np.testing.assert_allclose(np.array(F)[~tir_np], F_np[~tir_np], atol=1e-6)
    np.testing.assert_allclose(np.array(F)[tir_np], 1.0)
    # The transmitted direction in the air, from the paper's formula.
    np.testing.assert_allclose(np.array(d_t).T[~tir_np], d_t_np[~tir_np], atol=1e-5)


def test_intersect_stable_and_against_numpy():
    # A far sphere seen at a small angle, and a ray starting on the sphere.
    o = np.array([[0.0, 0, 0], [0.0, 0, 0], [0.0, 0.0, 0.9]])
    d = np.array([[0.0, 0.0, 1.0], [0.0005, 0.0, 1.0], [0.0, 0.6, 0.8]])
    P = np.array([[0.0, 0.0, 50.0], [0.0, 0.0, 50.0], [0.0, 0.0, 1.0]])
    R = np.array([0.05, 0.05, 0.1])
    t0, t1, hit = sphere.intersect(vec(o, mi.Point3f), vec(d), vec(P, mi.Point3f),
                                   mi.Float(R.astype(np.float32)))
    r0, r1 = np_intersect(o, d, P, R)
    assert np.array(hit).all()
    np.testing.assert_allclose(np.array(t0), r0, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(np.array(t1), r1, rtol=1e-6, atol=1e-7)
    # The chord of the far sphere: its length is the quantity that cancels naively.
    np.testing.assert_allclose(np.array(t1) - np.array(t0), r1 - r0, rtol=1e-3)


def test_invalid_rays_flagged():
    P = mi.Point3f(0.0, 0.0, 1.0)
    R, eta = 0.1, 1.5
    # Incidence cosine of a ray at off-axis distance h (camera at 0, sphere at z=1).
    def ray_at(h):
        return unit(np.array([h, 0.0, 1.0]))
    dirs = np.array([
        ray_at(0.05),               # ordinary hit
        [0.0, 0.6, 0.8],            # misses
        [0.0, 0.0, -1.0],           # sphere behind the camera
        ray_at(0.0985),             # hits, grazing (cos_i ~ 0.1)
        ray_at(0.097),              # hits, cos_i ~ 0.25: valid
    ])
    o_out, d_out, T, valid = sphere.totem_rays(mi.Point3f(0, 0, 0), vec(dirs), P, R, eta)
    # Independent incidence cosines.
    t0, _ = np_intersect(np.zeros((5, 3)), dirs, np.array([[0, 0, 1.0]]), np.full(5, R))
    Dn = t0[:, None] * dirs
    cos_i = -np.sum(dirs * (Dn - [0, 0, 1.0]) / R, 1)
    assert cos_i[3] < sphere.COS_VALID < cos_i[4]
    assert np.array(valid).tolist() == [True, False, False, False, True]
    T = np.array(T)
    assert T[0] > 0.8 and (T[1:4] == 0).all()
    # Invalid rays pass through unchanged; nothing is NaN.
    np.testing.assert_allclose(np.array(d_out).T[1:4], dirs[1:4], atol=1e-7)
    assert np.isfinite(np.array(o_out)).all() and np.isfinite(np.array(d_out)).all()
    # The camera inside the totem is not a valid totem ray either.
    _, _, _, v_in = sphere.totem_rays(mi.Point3f(0, 0, 0.95), vec(dirs[:1]), P, R, eta)
    assert not np.array(v_in).any()
    # A stricter threshold drops the cos ~ 0.25 ray.
    _, _, _, v = sphere.totem_rays(mi.Point3f(0, 0, 0), vec(dirs), P, R, eta, cos_valid=0.3)
    assert not np.array(v)[4]


def _objective(path, w1, w2):
    """Per-ray scalar: <d_out, w1> + <E, w2> + 3 T (Dr.Jit)."""
    return dr.dot(path.d_out, vec(w1)) + dr.dot(path.E, vec(w2)) + 3 * path.T


def test_gradient_wrt_centre_matches_finite_differences(rays):
    rng = np.random.default_rng(5)
    m = 40
    r = {k: v[:m] for k, v in rays.items()}
    w1, w2 = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    eps = 1e-3

    def f32(Pn):
        path = sphere.totem_path(vec(r["o"], mi.Point3f), vec(r["d"]), vec(Pn, mi.Point3f),
                                 mi.Float(r["R"].astype(np.float32)),
                                 mi.Float(r["n"].astype(np.float32)))
        return np.array(_objective(path, w1, w2), dtype=np.float64)

    def f64(Pn):
        D, d_mid, E, d_out, T = np_totem(r["o"], r["d"], Pn, r["R"], r["n"])
        return np.sum(d_out * w1, 1) + np.sum(E * w2, 1) + 3 * T

    # Reverse mode: the gradient of the sum is the per-ray gradient (one P per ray).
    P = vec(r["P"], mi.Point3f)
    dr.enable_grad(P)
    path = sphere.totem_path(vec(r["o"], mi.Point3f), vec(r["d"]), P,
                             mi.Float(r["R"].astype(np.float32)),
                             mi.Float(r["n"].astype(np.float32)))
    dr.backward(dr.sum(_objective(path, w1, w2)))
    g_ad = np.array(dr.grad(P), dtype=np.float64).T

    def central(f, h):
        g = np.zeros((m, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            g[:, k] = (f(r["P"] + e) - f(r["P"] - e)) / (2 * h)
        return g

    # Float32 central differences at eps (metres), Richardson-extrapolated: the
    # O(eps^2) error alone is 5e-3 for a 5 cm totem at eps = 1 mm (T varies fast).
    g_fd32 = (4 * central(f32, eps / 2) - central(f32, eps)) / 3
    g_fd64 = central(f64, 1e-6)
    scale = np.linalg.norm(g_fd64, axis=1)
    assert (scale > 0.1).all()
    err32 = np.linalg.norm(g_ad - g_fd32, axis=1) / scale
    err64 = np.linalg.norm(g_ad - g_fd64, axis=1) / scale
    assert err32.max() < 1e-3, err32.max()
    assert err64.max() < 1e-4, err64.max()

    # Forward mode along one direction agrees with reverse mode.
    P = vec(r["P"], mi.Point3f)
    dr.enable_grad(P)
    v = np.array([0.3, -0.5, 0.8])
    dr.set_grad(P, mi.Vector3f(*map(float, v)))
    path = sphere.totem_path(vec(r["o"], mi.Point3f), vec(r["d"]), P,
                             mi.Float(r["R"].astype(np.float32)),
                             mi.Float(r["n"].astype(np.float32)))
    y = _objective(path, w1, w2)
    dr.forward_to(y)
    np.testing.assert_allclose(np.array(dr.grad(y)), g_ad @ v, rtol=1e-4,
                               atol=1e-4 * scale.max())


def test_gradient_wrt_direction_and_shared_centre(rays):
    """d_out depends on the camera-ray direction; one centre shared by many rays."""
    m = 20
    r = {k: v[:m] for k, v in rays.items() if k != "P"}
    Pc = np.array([0.05, 0.15, 0.8])
    r["R"], r["n"] = np.full(m, 0.05), np.full(m, 1.33)
    # Re-aim the rays at the shared totem.
    rng = np.random.default_rng(8)
    tgt = Pc + rng.uniform(-0.03, 0.03, (m, 3))
    r["d"] = unit(tgt - r["o"])
    w1 = rng.normal(size=(m, 3))

    def f(Pn, dn):
        _, _, _, d_out, _ = np_totem(r["o"], unit(dn), np.tile(Pn, (m, 1)), r["R"], r["n"])
        return np.sum(d_out * w1)

    P = mi.Point3f(*map(float, Pc))
    d = vec(r["d"])
    dr.enable_grad(P, d)
    o_out, d_out, T, valid = sphere.totem_rays(vec(r["o"], mi.Point3f), d, P, 0.05, 1.33)
    assert np.array(valid).all()
    dr.backward(dr.sum(dr.dot(d_out, vec(w1))))
    gP = np.array(dr.grad(P), dtype=np.float64).ravel()
    gd = np.array(dr.grad(d), dtype=np.float64).T
    h = 1e-6
    fdP = np.array([(f(Pc + e, r["d"]) - f(Pc - e, r["d"])) / (2 * h) for e in np.eye(3) * h])
    np.testing.assert_allclose(gP, fdP, rtol=1e-3, atol=1e-3 * np.abs(fdP).max())
    # Perturb one ray's direction (d is normalised inside: no radial component).
    fdd = np.zeros(3)
    for k in range(3):
        dp, dm = r["d"].copy(), r["d"].copy()
        dp[3, k] += h
        dm[3, k] -= h
        fdd[k] = (f(Pc, dp) - f(Pc, dm)) / (2 * h)
    np.testing.assert_allclose(gd[3], fdd, rtol=1e-3, atol=1e-3 * np.abs(fdd).max())


def test_no_nan_gradients_on_invalid_rays():
    """Misses and grazing rays must not poison the centre's gradient."""
    dirs = unit(np.array([[0.05, 0, 1.0], [0.0, 0.6, 0.8], [0.0985, 0, 1.0], [0.1, 0, 1.0]]))
    P = mi.Point3f(0.0, 0.0, 1.0)
    dr.enable_grad(P)
    o_out, d_out, T, valid = sphere.totem_rays(mi.Point3f(0, 0, 0), vec(dirs), P, 0.1, 1.5)
    loss = dr.sum(dr.dot(d_out, mi.Vector3f(1, 2, 3)) + dr.dot(o_out, mi.Vector3f(1, 1, 1)) + T)
    dr.backward(loss)
    assert np.isfinite(np.array(dr.grad(P))).all()
    # Invalid lanes carry no gradient at all.
    P2 = mi.Point3f(0.0, 0.0, 1.0)
    dr.enable_grad(P2)
    o_out, d_out, T, valid = sphere.totem_rays(mi.Point3f(0, 0, 0), vec(dirs[1:]), P2, 0.1, 1.5)
    assert not np.array(valid).any()
    dr.backward(dr.sum(dr.dot(d_out, mi.Vector3f(1, 2, 3)) + dr.dot(o_out, mi.Vector3f(1, 1, 1))
                       + T))
    assert (np.array(dr.grad(P2)) == 0).all()


@pytest.fixture(scope="module")
def two_totems():
    """Two totems, one partly in front of the other, and a wall in front of a third."""
    C = np.array([[0.0, 0.0, 1.0], [0.08, 0.0, 1.4], [-0.3, 0.0, 1.2]])
    R = np.array([0.1, 0.1, 0.08])
    eta = np.array([1.5, 1.52, 1.4])
    rng = np.random.default_rng(11)
    # Pixels over a patch covering totems 0 and 1 and the occluded totem 2.
    x = rng.uniform(-0.42, 0.25, 400)
    y = rng.uniform(-0.12, 0.12, 400)
    d = unit(np.stack([x, y, np.ones_like(x)], 1))
    return C, R, eta, d


def _expected_index(C, R, d, occluder_z=None):
    """First totem along each ray (float64), -1 for none or behind the occluder."""
    t = np.full(len(d), np.inf)
    idx = np.full(len(d), -1)
    for j in range(len(C)):
        t0, _ = np_intersect(np.zeros((len(d), 3)), d, C[j][None], np.full(len(d), R[j]))
        closer = np.nan_to_num(t0, nan=np.inf) < t
        idx[closer], t[closer] = j, t0[closer]
    if occluder_z is not None:
        # A wall z = occluder_z, x in [-0.25, -0.14]: hides part of totem 2.
        tw = occluder_z / d[:, 2]
        xw = tw * d[:, 0]
        blocked = (xw > -0.25) & (xw < -0.14) & (tw < t)
        idx[blocked] = -1
    return idx


def test_nearest_totem_and_scene_agree_with_analytic_choice(two_totems):
    C, R, eta, d = two_totems
    o = mi.Point3f(0, 0, 0)
    index, _ = sphere.nearest_totem(o, vec(d), C, R)
    expected = _expected_index(C, R, d)
    # Far from silhouette edges (float32 vs float64 ties aside), the choice agrees.
    assert (np.array(index) == expected).mean() > 0.99
    assert {0, 1, 2} <= set(expected.tolist())
    assert ((expected == 0) & (np.abs(d[:, 0] / d[:, 2] - 0.08 / 1.4) < 0.05)).any()  # overlap

    # The same through Mitsuba's own intersection, with a wall hiding totem 2.
    wall = {"type": "rectangle",
            "to_world": mi.ScalarTransform4f().translate([-0.195, 0.0, 0.6]).scale(
                [0.055, 0.5, 1.0])}
    scene = sphere.totem_scene(C, R, extra={"wall": wall})
    ray = mi.Ray3f(o, vec(d))
    o_out, d_out, T, valid, index_s = sphere.totem_rays_scene(scene, ray, C, R, eta)
    expected_s = _expected_index(C, R, d, occluder_z=0.6)
    assert ((expected == 2) & (expected_s == -1)).sum() > 10
    assert ((expected == 2) & (expected_s == 2)).sum() > 10
    assert (np.array(index_s) == expected_s).mean() > 0.99

    # The rays equal the single-totem trace through the chosen totem.
    sel = np.array(valid)
    j = np.array(index_s)[sel]
    _, _, E, d_o, T_np = np_totem(np.zeros((sel.sum(), 3)), d[sel], C[j], R[j], eta[j])
    np.testing.assert_allclose(np.array(o_out).T[sel], E, atol=2e-5)
    np.testing.assert_allclose(np.array(d_out).T[sel], d_o, atol=2e-5)
    np.testing.assert_allclose(np.array(T)[sel], T_np, atol=1e-5)
    # Rays that see no totem pass through with T = 0.
    none = np.array(index_s) < 0
    np.testing.assert_allclose(np.array(d_out).T[none], d[none], atol=1e-6)
    assert (np.array(T)[none] == 0).all()


def test_scene_path_gradients_reach_each_centre(two_totems):
    C, R, eta, d = two_totems
    scene = sphere.totem_scene(C, R)
    w = np.array([0.2, -0.7, 0.4])
    centers = vec(C, mi.Point3f)
    dr.enable_grad(centers)
    ray = mi.Ray3f(mi.Point3f(0, 0, 0), vec(d))
    o_out, d_out, T, valid, index = sphere.totem_rays_scene(scene, ray, centers, R, eta)
    dr.backward(dr.sum(dr.dot(d_out, mi.Vector3f(*map(float, w))) + dr.select(valid, o_out.z, 0.0)))
    g = np.array(dr.grad(centers), dtype=np.float64).T
    idx = np.array(index)

    def f(Cn):
        sel = (idx >= 0) & np.array(valid)
        j = idx[sel]
        _, _, E, d_o, _ = np_totem(np.zeros((sel.sum(), 3)), d[sel], Cn[j], R[j], eta[j])
        return np.sum(d_o @ w) + np.sum(E[:, 2])

    h = 1e-6
    for j in range(3):
        for k in range(3):
            e = np.zeros_like(C)
            e[j, k] = h
            fd = (f(C + e) - f(C - e)) / (2 * h)
            assert abs(g[j, k] - fd) <= 1e-3 * np.abs(g).max(), (j, k, g[j, k], fd)
