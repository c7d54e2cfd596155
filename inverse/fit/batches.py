"""The totem rays a fit's step reads: on the device once, in seeded batches, and their
photometric terms.

Each step of :func:`inverse.fit.fit.fit_scene` fits a batch of the totem pixels' rays (every
ray once an epoch, in an order drawn from the fit's seed), so a step costs the same
whatever the photo's size; the loss compares the rays rendered through their totems with
the observed pixels in sRGB (see :mod:`inverse.fit.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inverse.rays import TotemPixels
from scenes import backend
from scenes.colour import linear_to_srgb_dr

__all__ = ["DeviceRays", "ray_batches", "photo_terms"]


@dataclass
class DeviceRays:
    """The totem pixels on the device: directions, totems, observed sRGB, ``R_F``."""

    d: object
    totem: object
    observed: object
    refl: object

    @classmethod
    def upload(cls, pixels: TotemPixels, refl) -> "DeviceRays":
        from inverse.integrator import device_rays

        mi = backend.modules()[1]
        d, totem = device_rays(pixels.d_cam, pixels.totem)
        return cls(d, totem, backend.upload(mi.Color3f, pixels.observed),
                   backend.upload(mi.Float, refl))

    def batch(self, index) -> "DeviceRays":
        """The rays at ``index`` (numpy ints), or all of them when None."""
        if index is None:
            return self
        dr, mi = backend.modules()
        i = backend.upload(mi.UInt32, index, np.uint32)
        return DeviceRays(*[dr.gather(type(x), x, i) for x in
                             (self.d, self.totem, self.observed, self.refl)])


def ray_batches(n: int, size: int, seed: int):
    """Endless batches of ``size`` indices into ``n`` rays (numpy int64), every ray
    once per epoch in an order drawn from ``seed``; None each step when ``size`` is 0
    or covers all rays (full batch)."""
    if size <= 0 or size >= n:
        while True:
            yield None
    rng = np.random.default_rng(seed)
    queue = np.empty(0, np.int64)
    while True:
        if len(queue) < size:
            queue = np.concatenate([queue, rng.permutation(n)])
        yield queue[:size]
        queue = queue[size:]


def photo_terms(itg, rays: DeviceRays, ambient):
    """The photometric term (mean squared sRGB error per channel) and the mean
    distortion of ``rays`` rendered through their totems, with the glass's front
    reflection ``R_F a`` added (``ambient`` a linear RGB ``mi.Float`` (3,))."""
    dr, mi = backend.modules()
    from inverse.integrator import distortion

    n_rays = dr.width(rays.refl)
    L, valid, w, m, *_ = itg.render_totem_rays(rays.d, rays.totem)
    L = L + rays.refl * mi.Color3f(*[
        dr.gather(mi.Float, ambient, i, mode=dr.ReduceMode.Direct) for i in range(3)])
    pred = mi.Color3f(*[linear_to_srgb_dr(L[i]) for i in range(3)])
    vmask = dr.select(valid, 1.0, 0.0)
    diff = pred - rays.observed
    photo = dr.sum(vmask * (dr.square(diff.x) + dr.square(diff.y)
                            + dr.square(diff.z))) / (3.0 * n_rays)
    dist = dr.sum(vmask * distortion(w, m, itg.n_samples)) / n_rays
    return photo, dist
