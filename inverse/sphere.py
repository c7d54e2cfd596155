"""Ray optics of a glass sphere (a totem), in Dr.Jit, differentiable in its centre.

A camera ray ``o + t d`` enters the totem (centre ``P``, radius ``R``, index of
refraction ``eta`` relative to the air around it) at ``D``, travels inside along
``d_mid`` to ``E`` and leaves along ``d_out``. The scene ray a totem pixel sees is
``o_out + t d_out`` with ``o_out = E`` (paper, Sec. 4.1 and supp. A.1, Eqs. 1-6).

Conventions (the same everywhere in this module):

- Frame: the OpenCV camera frame (+x right, +y down, +z forward), metres.
- Directions are *propagation* directions (from the camera towards the scene), unit.
- Normals ``N = (X - P) / R`` point *out of* the sphere and are recomputed from the hit
  point and the centre, so that gradients with respect to ``P`` flow through them.
- ``eta = n_glass / n_air`` (> 1 for glass): Mitsuba's ``mi.fresnel`` convention,
  interior over exterior IoR, with the normal pointing to the exterior.
- All arrays are Dr.Jit arrays of the active variant (call
  ``scenes.backend.use()`` first), one lane per ray: ``mi.Point3f`` / ``mi.Vector3f``
  for points / directions, ``mi.Float`` (or Python floats, broadcast) for ``R``, ``eta``.
  ``P`` is the centre of the totem each ray is tested against (gathered per ray).

Reflections inside the totem are ignored (the paper does the same); ``T`` is the
fraction of unpolarised light that crosses both surfaces.

Public functions: :func:`intersect`, :func:`refract` (one surface),
:func:`refract_in_out` (both), :func:`totem_rays` / :func:`totem_path` (camera rays
through one given totem per ray), :func:`nearest_totem` (the first of several totems
each ray meets, analytically), :func:`totem_scene` / :func:`totem_rays_scene` (Mitsuba's
``ray_intersect`` picks the totem, occluders included; the optics stay analytic).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from scenes import backend

if TYPE_CHECKING:                    # annotations only: Dr.Jit loads at the first use
    import mitsuba as mi

__all__ = ["COS_VALID", "intersect", "refract", "refract_in_out", "TotemPath",
           "totem_path", "totem_rays", "nearest_totem", "totem_scene",
           "totem_rays_scene"]

#: Rays meeting the surface more obliquely than this (cosine of the incidence
#: angle) are flagged invalid: their exit direction is too sensitive to the pose.
COS_VALID = 0.2


def _vec(x, cls=None):
    """A Dr.Jit 3-vector (``cls``, default ``mi.Vector3f``) from a Dr.Jit array, or a
    numpy array of shape (3,) or (n, 3)."""
    dr, mi = backend.modules()
    cls = cls or mi.Vector3f
    if isinstance(x, dr.ArrayBase):
        return cls(x)
    a = np.asarray(x, dtype=np.float32)
    if a.ndim == 2 and a.shape[1] == 3:
        return cls(a[:, 0], a[:, 1], a[:, 2])
    if a.shape == (3,):
        return cls(float(a[0]), float(a[1]), float(a[2]))
    raise ValueError(f"expected a 3-vector or an (n, 3) array, got shape {a.shape}")


def _float(x):
    """``mi.Float`` from a Dr.Jit array or a numpy array; Python floats stay floats."""
    dr, mi = backend.modules()
    if isinstance(x, (float, int)) or isinstance(x, dr.ArrayBase):
        return x
    a = np.asarray(x, dtype=np.float32)
    return float(a) if a.ndim == 0 else mi.Float(a.ravel())


def intersect(o, d, P, R):
    """Both intersections of the rays ``o + t d`` with the sphere ``|X - P| = R``.

    Solves ``a t^2 + 2 b t + c = 0`` with ``a = |d|^2``, ``b = <o - P, d>``,
    ``c = |o - P|^2 - R^2`` (supp. A.1, ``intersect``) in a form that keeps float32
    accuracy for far spheres and for origins on the sphere:
    the discriminant is ``a (R^2 - |l|^2)`` with ``l`` the part of ``o - P``
    orthogonal to ``d`` (no cancellation of two large terms), and the roots are
    ``q / a`` and ``c / q`` with ``q = -(b + sign(b) sqrt(disc))``.

    Parameters
    ----------
    o : mi.Point3f
        Ray origins, metres.
    d : mi.Vector3f
        Ray directions (need not be unit; ``t`` is in units of ``|d|``).
    P : mi.Point3f
        Sphere centres, metres, one per ray (or one for all).
    R : mi.Float or float
        Sphere radii, metres.

    Returns
    -------
    t_near, t_far : mi.Float
        Ray parameters of the two intersections, ``t_near <= t_far`` (garbage where
        ``hit`` is False).
    hit : mi.Bool
        The line meets the sphere (discriminant > 0) and ``t_far > 0``.
    """
    dr, mi = backend.modules()
    o, d, P, R = _vec(o, mi.Point3f), _vec(d), _vec(P, mi.Point3f), _float(R)
    f = mi.Vector3f(o - P)
    a = dr.squared_norm(d)
    b = dr.dot(f, d)
    c = dr.squared_norm(f) - dr.square(R)
    l = f - (b / a) * d                      # component of o - P orthogonal to d
    disc = a * (dr.square(R) - dr.squared_norm(l))
    hit = disc > 0
    # Keep the square root's derivative finite on lanes that miss.
    sqrt_disc = dr.sqrt(dr.select(hit, disc, a * dr.square(R)))
    q = -(b + dr.select(b >= 0, sqrt_disc, -sqrt_disc))
    q = dr.select(q == 0, 1e-30, q)         # b = 0 and tangent: both roots are 0
    t0, t1 = c / q, q / a
    t_near, t_far = dr.minimum(t0, t1), dr.maximum(t0, t1)
    return t_near, t_far, hit & (t_far > 0)


def refract(d, N, eta):
    """Refract propagation directions ``d`` at a surface with outward normal ``N``.

    Works from either side: when ``d`` travels against ``N`` the ray enters the
    denser medium (``n_out -> n_in``), when along ``N`` it leaves it. Uses Mitsuba's
    ``mi.fresnel`` (unpolarised Fresnel, ``eta = n_in / n_out``) and the vector form
    of ``mi.refract`` (Snell: ``n1 sin(theta1) = n2 sin(theta2)``, ``d``, ``N``,
    ``d_t`` coplanar).

    Parameters
    ----------
    d : mi.Vector3f
        Unit propagation directions.
    N : mi.Vector3f
        Unit outward normals.
    eta : mi.Float or float
        ``n_in / n_out`` (glass over air for a totem).

    Returns
    -------
    d_t : mi.Vector3f
        Unit refracted propagation directions (undefined where ``tir``).
    F : mi.Float
        Fresnel reflectance (unpolarised); ``1 - F`` is transmitted.
    cos_theta_i : mi.Float
        ``|cos|`` of the incidence angle (1 at normal incidence, 0 grazing).
    tir : mi.Bool
        Total internal reflection: no transmitted ray.
    """
    dr, mi = backend.modules()
    d, N, eta = _vec(d), _vec(N), _float(eta)
    wi = -d                                  # Mitsuba's wi points back to the source
    cos_i = dr.dot(wi, N)                    # > 0 from outside, < 0 from inside
    F, cos_t, _eta_it, eta_ti = mi.fresnel(cos_i, eta)
    d_t = mi.refract(wi, mi.Normal3f(N), cos_t, eta_ti)
    tir = F >= 1
    return d_t, F, dr.abs(cos_i), tir


def refract_in_out(d_in, D, P, R, eta):
    """The two refractions through the sphere, from the entry point ``D`` on.

    Eqs. 2-6 of the paper: ``N1 = (D - P) / R``, ``d_mid = refract(d_in, N1)``,
    ``E`` = far intersection of ``D + t d_mid``, ``N2 = (E - P) / R``,
    ``d_out = refract(d_mid, N2)``.

    Parameters
    ----------
    d_in : mi.Vector3f
        Unit propagation directions of the incoming rays.
    D : mi.Point3f
        Entry points on the sphere, metres.
    P : mi.Point3f
        Sphere centres, metres.
    R : mi.Float or float
        Radii, metres.
    eta : mi.Float or float
        ``n_glass / n_air``.

    Returns
    -------
    d_mid : mi.Vector3f
        Unit direction inside the sphere.
    E : mi.Point3f
        Exit point, metres.
    d_out : mi.Vector3f
        Unit exit direction.
    T : mi.Float
        Transmittance ``(1 - F1)(1 - F2)``, unpolarised.
    cos_in, cos_out : mi.Float
        Cosines of the incidence angles at ``D`` (outside) and at ``E`` (inside).
    tir : mi.Bool
        Total internal reflection at either surface.
    """
    dr, mi = backend.modules()
    d_in, D, P = _vec(d_in), _vec(D, mi.Point3f), _vec(P, mi.Point3f)
    R, eta = _float(R), _float(eta)
    N1 = mi.Vector3f(D - P) / R
    d_mid, F1, cos_in, tir1 = refract(d_in, N1, eta)
    d_mid = dr.normalize(d_mid)
    # D is on the sphere, so the exit is the far root (the near one is ~0).
    _, t_exit, _ = intersect(D, d_mid, P, R)
    E = D + t_exit * d_mid
    N2 = mi.Vector3f(E - P) / R
    d_out, F2, cos_out, tir2 = refract(d_mid, N2, eta)
    d_out = dr.normalize(d_out)
    T = (1 - F1) * (1 - F2)
    return d_mid, mi.Point3f(E), d_out, T, cos_in, cos_out, tir1 | tir2


class TotemPath(NamedTuple):
    """Everything along a camera ray's path through a totem (camera frame, metres)."""
    D: mi.Point3f        # entry point
    d_mid: mi.Vector3f   # direction inside
    E: mi.Point3f        # exit point = o_out
    d_out: mi.Vector3f   # exit direction
    T: mi.Float          # Fresnel transmittance (1 - F1)(1 - F2), unpolarised
    cos_in: mi.Float     # cosine of the incidence angle at D
    t_in: mi.Float       # camera-ray parameter of D
    valid: mi.Bool       # hit, no TIR, not grazing


def totem_path(o, d, P, R, eta, *, cos_valid: float = COS_VALID) -> TotemPath:
    """Trace camera rays through totems; see :func:`totem_rays` (this returns more).

    Lanes that are not valid (miss, totem behind or around the camera, grazing) are
    traced along the ray through the centre instead, so no huge or NaN derivative is
    ever formed, and their outputs are the input ray: ``D = E = o``,
    ``d_mid = d_out = d``, ``T = 0``, with no gradient with respect to ``P``.
    """
    dr, mi = backend.modules()
    o, d, P = _vec(o, mi.Point3f), dr.normalize(_vec(d)), _vec(P, mi.Point3f)
    R, eta = _float(R), _float(eta)
    t_near, _, hit = intersect(o, d, P, R)
    hit &= t_near > 0                        # camera outside the totem, totem ahead
    # Incidence cosine at D from the chord: cos = sqrt(R^2 - l^2) / R, l the
    # distance from the centre to the ray's line.
    f = mi.Vector3f(o - P)
    l2 = dr.squared_norm(f - dr.dot(f, d) * d)
    cos_geom = dr.safe_sqrt(1 - l2 / dr.square(R))
    ok = hit & (cos_geom >= cos_valid)
    # Invalid lanes: trace the central ray instead (well conditioned everywhere).
    d_safe = dr.select(ok, d, dr.normalize(mi.Vector3f(P - o)))
    t_in, _, _ = intersect(o, d_safe, P, R)
    D = o + t_in * d_safe
    d_mid, E, d_out, T, cos_in, _, tir = refract_in_out(d_safe, D, P, R, eta)
    valid = ok & ~tir
    return TotemPath(
        D=mi.Point3f(dr.select(valid, D, o)),
        d_mid=mi.Vector3f(dr.select(valid, d_mid, d)),
        E=mi.Point3f(dr.select(valid, E, o)),
        d_out=mi.Vector3f(dr.select(valid, d_out, d)),
        T=dr.select(valid, T, 0.0),
        cos_in=dr.select(ok, cos_in, dr.detach(dr.select(hit, cos_geom, 0.0))),
        t_in=dr.select(valid, t_in, 0.0),
        valid=valid,
    )


def totem_rays(o, d, P, R, eta, *, cos_valid: float = COS_VALID):
    """Scene rays seen through totems by camera rays (paper Sec. 4.1, Eqs. 1-6).

    Parameters
    ----------
    o : mi.Point3f
        Camera-ray origins, metres, camera frame (usually 0).
    d : mi.Vector3f
        Camera-ray directions, camera frame (e.g. ``camera.pixel_rays``); normalised
        here, so derivatives along ``d`` itself are 0.
    P : mi.Point3f
        Centre of the totem each ray is traced through, metres, camera frame
        (gather it per ray, e.g. ``dr.gather(mi.Point3f, centers, totem_index)``).
    R : mi.Float or float
        Totem radius, metres.
    eta : mi.Float or float
        Totem IoR relative to air, ``n_glass / n_air`` (e.g. 1.52).
    cos_valid : float
        Rays whose incidence cosine at entry is below this are flagged invalid
        (grazing). For a sphere the exit angle equals the entry angle, so this
        bounds both surfaces; TIR cannot occur for ``eta > 1`` but is flagged anyway.

    Returns
    -------
    o_out : mi.Point3f
        Exit point ``E`` on the sphere, metres (``o`` where not valid).
    d_out : mi.Vector3f
        Unit exit direction (``d`` where not valid).
    T : mi.Float
        Fresnel transmittance ``(1 - F1)(1 - F2)`` of unpolarised light; 0 where
        invalid.
    valid : mi.Bool
        The ray hits the sphere in front of the camera, no TIR, not grazing.

    All outputs are differentiable with respect to ``P`` (and ``o``, ``d``): the
    normals are recomputed from the hit points and the centre.
    """
    path = totem_path(o, d, P, R, eta, cos_valid=cos_valid)
    return path.E, path.d_out, path.T, path.valid


def _per_totem(x, n: int) -> mi.Float:
    """Radius or IoR given once or once per totem, as an ``n``-lane ``mi.Float``."""
    dr, mi = backend.modules()
    if isinstance(x, dr.ArrayBase):
        x = mi.Float(x)
        if dr.width(x) == 1 and n > 1:
            x = dr.zeros(mi.Float, n) + x    # broadcast, keeps any gradient
    else:
        x = np.asarray(x, dtype=np.float32)
        if x.size not in (1, n):
            raise ValueError(f"expected 1 or {n} values (one per totem), got {x.size}")
        x = backend.upload(mi.Float, np.broadcast_to(x.ravel(), (n,)))
    if dr.width(x) != n:
        raise ValueError(f"expected 1 or {n} values (one per totem), got {dr.width(x)}")
    return x


def _centers(centers) -> mi.Point3f:
    """Totem centres as an n-lane ``mi.Point3f`` (numpy (n, 3) accepted)."""
    mi = backend.modules()[1]
    return _vec(centers, mi.Point3f)


def nearest_totem(o, d, centers, radius):
    """Index of the first totem each ray meets, analytically (a loop over totems only).

    Parameters
    ----------
    o, d : mi.Point3f, mi.Vector3f
        Camera rays, camera frame, metres.
    centers : mi.Point3f (n lanes) or numpy (n, 3)
        Totem centres, metres. Only their values are used (the choice is discrete).
    radius : float or sequence of n floats
        Totem radii, metres.

    Returns
    -------
    index : mi.Int32
        Totem index (0..n-1, the order of ``centers``), -1 where no totem is hit.
    t : mi.Float
        Ray parameter of the entry point (inf where none).
    """
    dr, mi = backend.modules()
    C = np.array(dr.detach(_centers(centers)), dtype=np.float32).reshape(3, -1).T
    n = len(C)
    Rn = np.array(_per_totem(radius, n))
    o, d = _vec(o, mi.Point3f), dr.normalize(_vec(d))
    index = dr.full(mi.Int32, -1, dr.width(d))
    t_best = dr.full(mi.Float, dr.inf, dr.width(d))
    for j in range(n):                       # totems, not rays
        t_near, _, hit = intersect(o, d, mi.Point3f(*map(float, C[j])), float(Rn[j]))
        closer = hit & (t_near > 0) & (t_near < t_best)
        index = dr.select(closer, j, index)
        t_best = dr.select(closer, t_near, t_best)
    return index, dr.detach(t_best)


def _trace_indexed(o, d, index, centers, radius, eta, cos_valid):
    """totem_rays for rays already assigned to a totem (index -1: none)."""
    dr, mi = backend.modules()
    centers = _centers(centers)
    n = dr.width(centers)
    R_n, eta_n = _per_totem(radius, n), _per_totem(eta, n)
    has = index >= 0
    idx = mi.UInt32(dr.select(has, index, 0))
    # Gathers from attached centres: gradients scatter back to each totem.
    P = dr.gather(mi.Point3f, centers, idx)
    R = dr.gather(mi.Float, R_n, idx)
    eta_j = dr.gather(mi.Float, eta_n, idx)
    o, d = _vec(o, mi.Point3f), _vec(d)
    path = totem_path(o, d, P, R, eta_j, cos_valid=cos_valid)
    valid = path.valid & has
    return (mi.Point3f(dr.select(valid, path.E, o)),
            mi.Vector3f(dr.select(valid, path.d_out, dr.normalize(d))),
            dr.select(valid, path.T, 0.0), valid)


def totem_scene(centers, radius, *, extra: dict | None = None) -> mi.Scene:
    """A Mitsuba scene of the totem spheres (ids ``totem_000``...), plus ``extra`` shapes.

    ``centers`` numpy (n, 3) or ``mi.Point3f``, metres, camera frame; ``radius`` one
    value or one per totem. For :func:`totem_rays_scene`.
    """
    dr, mi = backend.modules()
    C = np.array(dr.detach(_centers(centers)), dtype=np.float64).reshape(3, -1).T
    Rn = np.array(_per_totem(radius, len(C)), dtype=np.float64)
    desc = {"type": "scene"}
    for j, (c, r) in enumerate(zip(C, Rn)):
        desc[f"totem_{j:03d}"] = {"type": "sphere", "center": c.tolist(), "radius": float(r)}
    desc.update(extra or {})
    return mi.load_dict(desc)


def totem_rays_scene(scene, ray, centers, radius, eta, *, shapes=None,
                     cos_valid: float = COS_VALID):
    """:func:`totem_rays` with Mitsuba choosing which totem (if any) each ray sees.

    ``scene.ray_intersect`` finds the first surface along each camera ray; rays whose
    first surface is a totem sphere are then traced analytically through the
    *attached* ``centers`` (Mitsuba's sphere normals and BSDF directions are detached
    from the centre, so only its choice of shape is used). Occluders in the scene
    make the ray invalid.

    Parameters
    ----------
    scene : mi.Scene
        Holds the totem spheres (e.g. :func:`totem_scene`), maybe other shapes. Its
        spheres should sit at (or near) ``centers``: a ray Mitsuba sends into a totem
        that misses the analytic sphere at ``centers`` is flagged invalid.
    ray : mi.Ray3f
        Camera rays (``o``, unit ``d``), camera frame, metres.
    centers : mi.Point3f (n lanes) or numpy (n, 3)
        Totem centres, metres, in the order of ``shapes``.
    radius, eta : float or n floats
        Radii (metres) and IoR ``n_glass / n_air``.
    shapes : sequence of mi.Shape, optional
        The totem shapes, in the order of ``centers``; default the scene's shapes
        whose id starts with ``totem``, sorted by id.

    Returns
    -------
    (o_out, d_out, T, valid, index) : as :func:`totem_rays`, and the totem each ray
    went through (as :func:`nearest_totem`: -1 for none).
    """
    dr, mi = backend.modules()
    if shapes is None:
        shapes = sorted((s for s in scene.shapes() if s.id().startswith("totem")),
                        key=lambda s: s.id())
    si = scene.ray_intersect(ray)
    index = dr.full(mi.Int32, -1, dr.width(ray.d))
    for j, shape in enumerate(shapes):       # totems, not rays
        index = dr.select(si.is_valid() & (si.shape == mi.ShapePtr(shape)), j, index)
    o_out, d_out, T, valid = _trace_indexed(ray.o, ray.d, index, centers, radius, eta,
                                            cos_valid)
    return o_out, d_out, T, valid, index
