"""scenes/refraction.py run backwards: a ray leaving a glass sphere is traced back to
where its camera ray entered, so it lands on the pixel it came from (stored in float32,
at the rim too)."""

import numpy as np

from scenes import camera, refraction


def test_the_exit_traced_back_lands_on_the_pixel_it_left():
    K = camera.intrinsics(320, 240, 60.0)
    centers = np.array([[-0.3, 0.2, 1.5], [0.3, 0.25, 1.2]])
    radius, ior = np.array([0.1, 0.08]), np.array([1.52, 1.45])
    v, u = np.mgrid[0:240, 0:320]
    d = camera.pixel_rays(K, u, v).reshape(-1, 3)
    masks = np.stack([refraction.entry_cosine(d, c, r).reshape(240, 320) > 0.01
                      for c, r in zip(centers, radius)])
    ex = refraction.exit_rays(K, masks, centers, radius, ior)
    D = refraction.entry_points(ex.o.astype(np.float32), ex.d.astype(np.float32),
                                centers[ex.totem], radius[ex.totem], ior[ex.totem])
    assert len(D) > 1000 and ex.cos_in.min() < 0.05          # rim rays are there
    # the entry point lies on the sphere, in front of its centre, on the pixel's ray
    P, R = centers[ex.totem], radius[ex.totem]
    assert np.abs(np.linalg.norm(D - P, axis=1) - R).max() < 1e-6
    assert np.abs(camera.project(K, D) - np.stack([ex.u, ex.v], 1)).max() < 1e-3
