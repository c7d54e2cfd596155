"""Refraction through a glass sphere, in numpy: the twin of :mod:`inverse.sphere`, and the
way back (:func:`entry_points`: where a ray leaving the glass entered it).

``scenes`` imports nothing of ``inverse``, so what a glass sphere does to the camera's
rays is written here again without Dr.Jit, for the code that needs it before or beside a
fit: the glass test of mask detection, the truth's reach of a synthetic scene and the
placement plan. ``tests/test_detect_masks.py`` checks the two agree.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres; rays
from the camera's centre (the origin). ``eta = n_glass / n_air``. Reflections are
ignored.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from scenes.camera import pixel_rays

__all__ = ["MIN_TRANSMITTANCE", "ExitRays", "refract_sphere", "entry_cosine",
           "transmittance", "exit_rays", "entry_points"]

MIN_TRANSMITTANCE = 0.05
"""Rays whose Fresnel transmittance through both surfaces is below this are dropped: the
glass sends back almost nothing of the scene along them."""


def refract_sphere(d, P, R: float, eta: float):
    """Camera rays from the origin along unit ``d`` (m, 3) through a glass sphere:
    centre ``P`` (3,) or one per ray (m, 3), metres; radius ``R`` metres; index of
    refraction ``eta`` = n_glass / n_air.

    Snell's law in vector form at entry ``D`` and exit ``E`` (paper, Eqs. 1-6):
    ``t = r d + (r c - sqrt(1 - r^2 (1 - c^2))) N`` with ``N`` the normal facing the
    incoming ray, ``c = -d.N``, ``r = n_from / n_to``. Reflections are ignored.

    Returns
    -------
    E : (m, 3) exit points, metres.
    d_out : (m, 3) unit exit directions.
    valid : (m,) bool, the ray meets the sphere in front of the camera.
    """
    d = np.asarray(d, np.float64)
    P = np.asarray(P, np.float64)
    b = (d * P).sum(-1)                         # ray parameter of the closest approach
    l2 = np.maximum((P * P).sum(-1) - b * b, 0.0)  # squared distance of the line from P
    valid = (l2 < R * R) & (b > 0)
    h = np.sqrt(np.maximum(R * R - l2, 0.0))
    D = (b - h)[:, None] * d                    # entry point
    N1 = (D - P) / R                            # outward normal at D (faces the ray)
    cos_i = np.clip(-(d * N1).sum(1), 0.0, 1.0)
    d_mid, cos_t = _into_glass(d, N1, eta)
    E = D + (2.0 * R * cos_t)[:, None] * d_mid  # chord of length 2 R cos_t
    N2 = (E - P) / R                            # outward; -N2 faces the ray inside
    # inside to outside: r = eta, c = d_mid . N2 = cos_t, the exit angle equals cos_i
    d_out = eta * d_mid - (eta * cos_t - cos_i)[:, None] * N2
    d_out /= np.linalg.norm(d_out, axis=1, keepdims=True)
    return E, d_out, valid


def entry_points(E, d_out, P, R, eta) -> np.ndarray:
    """Where the camera rays that leave a glass sphere at ``E`` along ``d_out`` entered
    it: :func:`refract_sphere` run backwards (a ray's path through glass is the same
    either way), so a ray leaving the glass can be put back on its totem pixel.

    Parameters
    ----------
    E : (m, 3) exit points on the sphere, camera frame, metres.
    d_out : (m, 3) unit directions the rays leave along.
    P : (3,) or (m, 3) sphere centre(s), metres; ``R`` radius, ``eta`` = n_glass / n_air:
        scalars or (m,), one per ray.

    Returns
    -------
    (m, 3) entry points, metres: the camera ray through each is the pixel the ray left
    (:func:`scenes.camera.project`). The exit point is first put on the sphere (it is
    stored in float32).
    """
    E = np.asarray(E, np.float64)
    d = np.asarray(d_out, np.float64)
    P = np.asarray(P, np.float64)
    R = np.asarray(R, np.float64)
    eta = np.asarray(eta, np.float64)
    N = E - P
    N = N / np.linalg.norm(N, axis=-1, keepdims=True)      # outward normal at the exit
    E = P + R[..., None] * N if R.ndim else P + R * N
    # backwards, the ray arrives along -d_out and enters the glass at E (air to glass);
    # the outward normal faces it, its incidence cosine that of the forward exit
    back, cos_t = _into_glass(-d, N, eta)
    return E + (2.0 * R * cos_t)[..., None] * back      # the chord back to the entry


def _into_glass(d, N, eta):
    """Snell's law from air into glass: unit rays ``d`` (m, 3) meeting the surface whose
    outward normal ``N`` (m, 3) faces them; ``eta`` = n_glass / n_air, scalar or (m,).
    Returns the refracted unit directions (m, 3) and the cosines of refraction (m,)."""
    c = np.clip(-(d * N).sum(-1), 0.0, 1.0)
    r = 1.0 / np.asarray(eta, np.float64)
    cos_t = np.sqrt(np.maximum(1.0 - r * r * (1.0 - c * c), 0.0))
    rr = r[..., None] if r.ndim else r
    return rr * d + (r * c - cos_t)[..., None] * N, cos_t


def entry_cosine(d, P, R: float) -> np.ndarray:
    """Cosine of the incidence angle where camera rays along unit ``d`` (m, 3) enter the
    sphere of centre ``P`` ((3,) or (m, 3), metres) and radius ``R``: 1 at the centre
    of its image, 0 at the rim; 0 for rays that miss it."""
    d = np.asarray(d, np.float64)
    P = np.asarray(P, np.float64)
    b = (d * P).sum(-1)
    l2 = np.maximum((P * P).sum(-1) - b * b, 0.0)
    return np.sqrt(np.clip(1.0 - l2 / (R * R), 0.0, 1.0))


def transmittance(cos_i, eta: float) -> np.ndarray:
    """Fresnel transmittance (unpolarised) of a ray through the sphere: ``(1 - F)^2``,
    ``F`` the reflectance at the entry, whose angles the exit repeats (a sphere's chord
    meets both surfaces at the same angle).

    ``cos_i`` the incidence cosine at the entry (:func:`entry_cosine`)."""
    c = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    sin_t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / eta
    cos_t = np.sqrt(np.maximum(1.0 - sin_t * sin_t, 0.0))
    r_s = (c - eta * cos_t) / np.maximum(c + eta * cos_t, 1e-12)
    r_p = (eta * c - cos_t) / np.maximum(eta * c + cos_t, 1e-12)
    F = 0.5 * (r_s * r_s + r_p * r_p)
    return (1.0 - F) ** 2


class ExitRays(NamedTuple):
    """The totem pixels' camera rays leaving their spheres (:func:`exit_rays`): ``u``,
    ``v`` (m,) int the pixel (column, row); ``totem`` (m,) int the sphere; ``o`` (m, 3)
    the exit point, metres; ``d`` (m, 3) the unit direction into the scene; ``T`` (m,) the
    Fresnel transmittance through both surfaces; ``cos_in`` (m,) the incidence cosine
    where the camera ray entered."""

    u: np.ndarray
    v: np.ndarray
    totem: np.ndarray
    o: np.ndarray
    d: np.ndarray
    T: np.ndarray
    cos_in: np.ndarray


def exit_rays(K, masks, centers, radius, ior, *, supersample: int = 1) -> ExitRays:
    """Every pixel of each totem's image, its camera ray refracted through the sphere.

    Parameters
    ----------
    K : (3, 3) intrinsics, pixels.
    masks : (n, H, W) bool, each totem's pixels (the pixels whose ray meets it first).
    centers : (n, 3) sphere centres, camera frame, metres.
    radius, ior : scalars, or (n,) one per sphere: metres, ``n_glass / n_air``.
    supersample : ``s``: s x s rays a pixel, through the centres of its s x s sub-pixels
        (``u``, ``v`` the pixel each came from).

    Returns
    -------
    :class:`ExitRays`, totem by totem, each in row-major pixel order; a pixel whose ray
    misses its sphere (a mask wider than the sphere) is left out.
    """
    n = len(masks)
    centers = np.asarray(centers, np.float64).reshape(n, 3)
    radius = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    ior = np.broadcast_to(np.asarray(ior, np.float64), (n,))
    parts = [(np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)),
              np.zeros((0, 3)), np.zeros(0), np.zeros(0))]
    s = int(supersample)
    sub_px = (np.arange(s) + 0.5) / s - 0.5
    du, dv = (x.ravel() for x in np.meshgrid(sub_px, sub_px))
    for j in range(n):
        v, u = np.nonzero(masks[j])
        u, v = np.repeat(u, s * s), np.repeat(v, s * s)
        k = len(u) // (s * s)
        dc = pixel_rays(K, u + np.tile(du, k), v + np.tile(dv, k)).reshape(-1, 3)
        E, d_out, valid = refract_sphere(dc, centers[j], float(radius[j]), float(ior[j]))
        cos_in = entry_cosine(dc, centers[j], float(radius[j]))[valid]
        parts.append((u[valid], v[valid], np.full(int(valid.sum()), j), E[valid],
                      d_out[valid], transmittance(cos_in, float(ior[j])), cos_in))
    return ExitRays(*(np.concatenate(x) for x in zip(*parts)))
