"""The totem pixels, and the same pixels as rays into the scene: the one data type
from the fit to verify.

A totem pixel's camera ray, refracted into and out of its glass sphere at the fitted centre,
leaves the glass as a ray into the scene; the pixel's colour, with the glass's front
reflection taken off and divided by its Fresnel transmittance, is the radiance that ray
brought back. The view's stereo (:mod:`inverse.view.view`) and the verify metrics that read
the totems directly (:mod:`verify.metrics.corroborate`, :mod:`verify.metrics.absence`) all
take a :class:`TotemRays`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes import camera
from scenes.colour import srgb_to_linear
from scenes.refraction import MIN_TRANSMITTANCE

__all__ = ["TotemRays", "TotemPixels", "totem_pixels", "exit_rays", "refracted_rays",
           "MIN_TRANSMITTANCE"]

@dataclass
class TotemRays:
    """The totem pixels' rays leaving the glass, camera frame (OpenCV, metres).

    Attributes
    ----------
    o : (m, 3) float64, exit points on the spheres, metres.
    d : (m, 3) float64, unit directions into the scene.
    radiance : (m, 3) float64, linear RGB each ray brought back.
    totem : (m,) int64, the sphere each ray left.
    cos_in : (m,) float64, the incidence cosine where the camera ray entered (rim rays
        near 0).

    It holds no colour but the totem pixels'. With the camera's K the directions give
    away the IoR (and the exit points the radius), so it belongs to the defender:
    ``fit/`` is not for sharing, unlike ``verify/``.
    """

    o: np.ndarray
    d: np.ndarray
    radiance: np.ndarray
    totem: np.ndarray
    cos_in: np.ndarray

    def __post_init__(self):
        self.o, self.d, self.radiance, self.cos_in = (
            np.asarray(x, np.float64) for x in (self.o, self.d, self.radiance, self.cos_in))
        self.totem = np.asarray(self.totem, np.int64)
        m = len(self.totem)
        if self.o.shape != (m, 3) or self.d.shape != (m, 3) \
                or self.radiance.shape != (m, 3) or self.cos_in.shape != (m,):
            raise ValueError("TotemRays arrays disagree in shape")

    def __len__(self) -> int:
        return len(self.totem)

    def select(self, keep) -> "TotemRays":
        """The rays where ``keep`` (a bool mask or indices) holds."""
        return TotemRays(self.o[keep], self.d[keep], self.radiance[keep], self.totem[keep],
                         self.cos_in[keep])

    def entering_at_least(self, cos_min: float) -> "TotemRays":
        """The rays that entered their sphere at an incidence cosine ``>= cos_min``
        (the rim's rays are blurred and mixed with reflection)."""
        return self.select(self.cos_in >= cos_min)

    def n_totems(self) -> int:
        """How many distinct totems the rays leave."""
        return len(np.unique(self.totem))

    def to_dict(self) -> dict:
        """Arrays for ``totem_rays.npz`` (float32, totem int32)."""
        return {"o": self.o.astype(np.float32), "d": self.d.astype(np.float32),
                "radiance": self.radiance.astype(np.float32),
                "totem": self.totem.astype(np.int32), "cos_in": self.cos_in.astype(np.float32)}

    @classmethod
    def from_dict(cls, z) -> "TotemRays":
        """Inverse of :meth:`to_dict` (accepts an ``np.load`` result); ValueError if the
        arrays disagree in shape."""
        return cls(**{k: z[k] for k in ("o", "d", "radiance", "totem", "cos_in")})


@dataclass
class TotemPixels:
    """The totem pixels a fit reads: pixel ``(u, v)`` (m,), totem index (m,), unit
    camera-ray direction ``d_cam`` (m, 3) (camera frame, float32) and the observed
    sRGB colour (m, 3) float32."""

    u: np.ndarray
    v: np.ndarray
    totem: np.ndarray
    d_cam: np.ndarray
    observed: np.ndarray

    def select(self, keep) -> "TotemPixels":
        """The pixels where ``keep`` (a bool mask or indices) holds."""
        return TotemPixels(self.u[keep], self.v[keep], self.totem[keep], self.d_cam[keep],
                       self.observed[keep])


def totem_pixels(scene, K, erode_px: int) -> TotemPixels:
    """Every totem pixel of ``scene`` once (each mask eroded by ``erode_px`` to drop the
    blurred rim, unless that leaves under 20 pixels), with its camera ray through ``K``
    and its observed sRGB colour."""
    from scipy.ndimage import binary_erosion

    us, vs, js = [], [], []
    taken = np.zeros(scene.masks.shape[1:], dtype=bool)
    for j, m in enumerate(scene.masks):
        m = np.asarray(m, dtype=bool)
        if erode_px > 0:
            e = binary_erosion(m, iterations=erode_px)
            m = e if e.sum() >= 20 else m
        m = m & ~taken
        taken |= m
        v, u = np.nonzero(m)
        us.append(u)
        vs.append(v)
        js.append(np.full(u.size, j))
    u, v, jt = np.concatenate(us), np.concatenate(vs), np.concatenate(js)
    d_cam = camera.pixel_rays(K, u, v).astype(np.float32)
    observed = np.asarray(scene.image, np.float32)[v, u]          # sRGB
    return TotemPixels(u, v, jt, d_cam, observed)


def refracted_rays(itg, d_cam, totem):
    """Camera rays through totem pixels, refracted out of their sphere at the
    integrator's centres (:meth:`TotemGridIntegrator.refract`), as numpy.

    Returns exit points (m, 3) metres, unit directions (m, 3), Fresnel transmittance
    (m,) and validity (m,) bool.
    """
    o_out, d_out, T_F, ok = itg.refract(d_cam, totem)
    return (np.asarray(o_out, np.float64).T.reshape(-1, 3),
            np.asarray(d_out, np.float64).T.reshape(-1, 3),
            np.asarray(T_F, np.float64).reshape(-1), np.asarray(ok, bool).reshape(-1))


def exit_rays(itg, centers, radius, d_cam, totem, observed, refl, ambient) -> TotemRays:
    """The totem pixels' rays leaving the glass at the integrator's centres.

    ``observed`` (m, 3) sRGB of the pixels whose camera rays are ``d_cam`` (m, 3) into
    totems ``totem``; ``refl`` (m,) their front-surface Fresnel reflectance and
    ``ambient`` (3,) the fitted linear colour it reflects; ``centers`` (n, 3) and
    ``radius`` (n,) metres. Rays with transmittance below :data:`MIN_TRANSMITTANCE`
    are dropped.
    """
    o, d, T, ok = refracted_rays(itg, d_cam, totem)
    keep = ok & (T > MIN_TRANSMITTANCE)
    P = np.asarray(centers, np.float64)[totem]
    cos_in = np.abs(((o - P) * d).sum(1)) / np.asarray(radius, np.float64)[totem]
    lin = np.clip(srgb_to_linear(observed) - refl[:, None] * ambient[None], 0.0, None)
    lin = lin / np.maximum(T, MIN_TRANSMITTANCE)[:, None]
    return TotemRays(o[keep], d[keep], lin[keep], np.asarray(totem)[keep], cos_in[keep])
