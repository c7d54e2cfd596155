"""scenes/refraction.py run backwards: a ray leaving a glass sphere is traced back to
where its camera ray entered, so it lands on the pixel it came from (stored in float32,
at the rim too)."""

import numpy as np

from scenes import camera, refraction

import glass_cases


def test_the_exit_traced_back_lands_on_the_pixel_it_left():
    K, centers, radius, ior = glass_cases.K, glass_cases.CENTERS, glass_cases.RADIUS, \
        glass_cases.IOR
    ex = glass_cases.two_spheres_exits(0.01)
    D = refraction.entry_points(ex.o.astype(np.float32), ex.d.astype(np.float32),
                                centers[ex.totem], radius[ex.totem], ior[ex.totem])
    assert len(D) > 1000 and ex.cos_in.min() < 0.05          # rim rays are there
    # the entry point lies on the sphere, in front of its centre, on the pixel's ray
    P, R = centers[ex.totem], radius[ex.totem]
    assert np.abs(np.linalg.norm(D - P, axis=1) - R).max() < 1e-6
    assert np.abs(camera.project(K, D) - np.stack([ex.u, ex.v], 1)).max() < 1e-3
