"""Two glass spheres of their own radii and indices before a 320 x 240 camera, and the rays
leaving them from every pixel whose camera ray enters one (shared by the tests that put
a ray back on its pixel)."""

import numpy as np

from scenes import camera, refraction

K = camera.intrinsics(320, 240, 60.0)
CENTERS = np.array([[-0.3, 0.2, 1.5], [0.3, 0.25, 1.2]])
RADIUS, IOR = np.array([0.1, 0.08]), np.array([1.52, 1.45])


def two_spheres_exits(min_cos: float):
    """:func:`scenes.refraction.exit_rays` of both spheres' pixels whose camera ray
    enters at an incidence cosine above ``min_cos``."""
    v, u = np.mgrid[0:240, 0:320]
    d = camera.pixel_rays(K, u, v).reshape(-1, 3)
    masks = np.stack([refraction.entry_cosine(d, c, r).reshape(240, 320) > min_cos
                      for c, r in zip(CENTERS, RADIUS)])
    return refraction.exit_rays(K, masks, CENTERS, RADIUS, IOR)
