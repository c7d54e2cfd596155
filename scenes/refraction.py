"""Refraction through a glass sphere, in numpy: the twin of :mod:`inverse.sphere`.

``scenes`` imports nothing of ``inverse``, so what a glass sphere does to the camera's
rays is written here again without Dr.Jit, for the code that needs it before or beside a
fit: the glass test of mask detection, the truth's reach of a synthetic scene and the
placement plan. ``tests/test_detect_masks.py`` checks the two agree.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres; rays
from the camera's centre (the origin). ``eta = n_glass / n_air``. Reflections are
ignored.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_TRANSMITTANCE", "refract_sphere", "entry_cosine", "transmittance"]

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
    r = 1.0 / eta
    cos_t = np.sqrt(np.maximum(1.0 - r * r * (1.0 - cos_i ** 2), 0.0))
    d_mid = r * d + (r * cos_i - cos_t)[:, None] * N1
    E = D + (2.0 * R * cos_t)[:, None] * d_mid  # chord of length 2 R cos_t
    N2 = (E - P) / R                            # outward; -N2 faces the ray inside
    # inside to outside: r = eta, c = d_mid . N2 = cos_t, the exit angle equals cos_i
    d_out = eta * d_mid - (eta * cos_t - cos_i)[:, None] * N2
    d_out /= np.linalg.norm(d_out, axis=1, keepdims=True)
    return E, d_out, valid


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
