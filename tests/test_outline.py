"""Outline loss: value against the numpy twin, gradient against finite differences,
and descent from a perturbed centre."""

import numpy as np

from inverse.fit import outline
from inverse.pose import pose
from scenes import backend, camera

dr, mi = backend.modules()

W, H = 320, 240
K = camera.intrinsics(W, H, 60.0)
fx = K[0, 0]
P_TRUE = np.array([[-0.5, 0.15, 1.4], [0.45, -0.2, 1.7]])
R = np.array([0.1, 0.08])


def sphere_mask(P, r):
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    d = np.stack([(u - K[0, 2]) / fx, (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], -1)
    b = d @ P
    return b * b - (d * d).sum(-1) * (P @ P - r * r) > 0


RAYS, TID = outline.outline_targets(np.stack([sphere_mask(p, r) for p, r in zip(P_TRUE, R)]), K)


def loss_np(P):
    """float64 twin: mean over totems of the mean squared residual, pixels^2."""
    P = np.asarray(P, float).reshape(-1, 3)
    return np.mean([np.mean((fx * pose.tangent_residuals(P[j], R[j], RAYS[TID == j])) ** 2)
                    for j in range(len(P))])


def loss_dr(P):
    c = mi.Point3f(np.asarray(P, np.float32).reshape(-1, 3).T)
    dr.enable_grad(c)
    L = outline.outline_loss(c, R, RAYS, TID, scale=fx)
    dr.backward(L)
    return L[0], np.array(dr.grad(c)).T


def test_value_matches_numpy_twin_and_inputs_agree():
    P = P_TRUE + [[0.01, -0.02, 0.05], [0.0, 0.01, -0.04]]
    L, _ = loss_dr(P)
    assert abs(L - loss_np(P)) < 1e-4 * loss_np(P)
    flat = mi.Float(P.astype(np.float32).ravel())         # the other accepted forms
    assert abs(outline.outline_loss(flat, R, RAYS, TID, scale=fx)[0] - L) < 1e-4 * L
    assert abs(outline.outline_loss(P, R, mi.Vector3f(RAYS.T.astype(np.float32)),
                                    mi.UInt32(TID.astype(np.uint32)), scale=fx)[0] - L) < 1e-4 * L
    # at the true centres only pixel quantisation is left (< 0.3 px rms)
    assert loss_dr(P_TRUE)[0] < 0.3 ** 2


def test_gradient_matches_central_differences():
    P = P_TRUE + [[0.02, 0.01, -0.05], [-0.01, 0.02, 0.08]]
    _, g = loss_dr(P)
    h = 1e-6
    g_fd = np.zeros(P.size)
    for i in range(P.size):                       # 6 parameters
        e = np.zeros(P.size)
        e[i] = h
        g_fd[i] = (loss_np(P.ravel() + e) - loss_np(P.ravel() - e)) / (2 * h)
    np.testing.assert_allclose(g.ravel(), g_fd, rtol=2e-3, atol=1e-3 * np.abs(g_fd).max())


def _split(E):
    """Error (n, 3) -> |along the line of sight|, |across it| (m)."""
    dirs = P_TRUE / np.linalg.norm(P_TRUE, axis=1, keepdims=True)
    depth = (E * dirs).sum(1)
    return np.abs(depth), np.linalg.norm(E - depth[:, None] * dirs, axis=1)


def test_depth_is_weakly_constrained():
    """1 cm along the line of sight costs far less than 1 cm across it (tan(alpha)^2)."""
    dirs = P_TRUE / np.linalg.norm(P_TRUE, axis=1, keepdims=True)
    across = np.cross(dirs, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    base = loss_np(P_TRUE)
    d_lat = loss_np(P_TRUE + 0.01 * across) - base
    d_depth = loss_np(P_TRUE + 0.01 * dirs) - base
    print(f"\n+1 cm across: +{d_lat:.2f} px^2, +1 cm along: +{d_depth:.3f} px^2")
    assert d_lat > 20 * d_depth > 0


def test_descent_recovers_lateral_position_fast_and_depth_slowly():
    """Plain gradient steps from a perturbed centre (3 cm sideways, 10 cm in depth)."""
    P0 = P_TRUE + [[0.03, -0.02, 0.10], [-0.03, 0.02, -0.10]]
    c = mi.Point3f(P0.astype(np.float32).T)
    lr = 4e-5                  # m^2/px^2: stable below 2 |P|^2 / fx^2 (lateral curvature)
    for _ in range(300):
        dr.enable_grad(c)
        L = outline.outline_loss(c, R, RAYS, TID, scale=fx)
        dr.backward(L)
        c = mi.Point3f(dr.detach(c) - lr * dr.grad(c))
    P = np.array(c).T
    depth0, lat0 = _split(P0 - P_TRUE)
    depth, lat = _split(P - P_TRUE)
    print(f"\n300 steps: lateral {np.round(lat0 * 1e3, 1)} -> {np.round(lat * 1e3, 1)} mm, "
          f"depth {np.round(depth0 * 1e3, 1)} -> {np.round(depth * 1e3, 1)} mm")
    assert loss_np(P) < 0.01 * loss_np(P0)
    assert np.all(lat < 0.002)                    # up to 7 cm -> under 2 mm
    assert np.all(depth < 0.7 * depth0)           # depth moves back, slowly
