"""The Mitsuba integrator that renders a frustum radiance grid, through totems or not.

``TotemGridIntegrator`` (registered as ``"totem_grid"``) is an emissive-absorptive volume
renderer (NeRF's quadrature) over the grid of :mod:`inverse.grid`:

    tau_k = sigma(g_k) * delta,        sigma = softplus(density grid)
    T_k   = exp(-sum_{i<k} tau_i)      (transmittance before sample k)
    w_k   = T_k * (1 - exp(-tau_k)),   the last sample opaque (the far/near boundary
                                       is a backdrop with the grid's colour there)
    C     = sum_k w_k c(g_k)           linear RGB radiance

A camera ray through a totem pixel is first refracted into and out of its glass
sphere (:func:`inverse.sphere.totem_rays`: Snell at both surfaces, weighted by the
Fresnel transmittance ``T_F``; reflections ignored), so the pixel's linear radiance
is ``T_F * C``. Rays that graze the sphere are dropped (``valid`` False); a ray is
followed until it leaves the grid's frustum (far or near plane, or a side), where the
grid's colour is an opaque backdrop.

All samples of all rays are one flat Dr.Jit array (ray ``i`` owns lanes
``i*n .. i*n + n-1``): the transmittance is an exclusive ``dr.block_prefix_sum`` and the
compositing a ``dr.block_sum`` over blocks of ``n``, so one kernel does a whole batch
and reverse-mode AD stays a handful of vector operations. Refraction runs once per
ray and its segment is spread to the ray's lanes by ``dr.repeat`` (whose adjoint is a
block sum: no scatter-add contention in the backward pass); totem centres enter by a
``dr.select`` chain over the few totems, whose adjoint is a horizontal sum.

Samples are evenly spaced in the grid's unit coordinates (inverse depth in ``r``),
so along the ray (the map is projective); ``delta`` is the segment's length in 1/100
of the grid's depth extent, so densities keep their meaning when the grid is refined.

With ``mirror`` set, a totem pixel also sees the glass's front reflection of the scene
itself, ``R_F C_r`` (:meth:`TotemGrid.mirrored`): ``C_r`` the grid's radiance along the
camera ray mirrored at its entry point, where that ray runs forward through the grid;
other reflections are left to the fit's one ambient colour.

Parameters (``mi.traverse``): ``density`` (nr, nt, ns, 1) raw density before the
softplus; ``colour`` (nr', nt', ns', 3) linear RGB; ``centers`` (3 n floats, metres,
camera frame; every x, then y, then z). Option: ``n_samples`` (default 64) per ray.
Totem rays that leave through the grid's top face are invalid (:func:`leaves_through_top`).
The class is made at the first use (:func:`integrator_class`): its base needs the variant.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from inverse.exact_gather import grid_at
from inverse.grid import FrustumFrame
from inverse.sphere import intersect, totem_rays
from scenes import backend

if TYPE_CHECKING:                    # annotations only: Dr.Jit loads at the first use
    import mitsuba as mi

__all__ = ["DELTA_SCALE", "softplus", "FrameConstants", "ray_segment", "device_rays",
           "leaves_through_top", "density_at", "march", "distortion", "select_center",
           "TotemGrid",
           "integrator_class"]

#: Length, in unit grid coordinates, of one unit of ``delta`` (density is per 1/100).
DELTA_SCALE = 100.0


def softplus(x):
    """``log(1 + exp(x))``, overflow-safe; its gradient never vanishes (unlike ReLU)."""
    dr = backend.modules()[0]
    return dr.select(x > 20.0, x, dr.log(1.0 + dr.exp(dr.minimum(x, 20.0))))


def _opaque(x) -> mi.Float:
    """A scalar as an opaque Dr.Jit value: changing it does not recompile kernels."""
    dr, mi = backend.modules()
    v = mi.Float(float(x))
    dr.make_opaque(v)
    return v


class FrameConstants:
    """A :class:`FrustumFrame` as opaque Dr.Jit scalars (one kernel for every scene)."""

    def __init__(self, frame: FrustumFrame):
        K = frame.K
        self.frame = frame
        self.fx, self.fy = _opaque(K[0, 0]), _opaque(K[1, 1])
        self.cx, self.cy = _opaque(K[0, 2]), _opaque(K[1, 2])
        self.u0, self.v0 = _opaque(frame.u_range[0]), _opaque(frame.v_range[0])
        self.du = _opaque(frame.u_range[1] - frame.u_range[0])
        self.dv = _opaque(frame.v_range[1] - frame.v_range[0])
        self.near, self.far = _opaque(frame.near), _opaque(frame.far)
        self.inv_near = _opaque(1.0 / frame.near)
        self.dinv = _opaque(1.0 / frame.near - 1.0 / frame.far)

    def unit(self, p):
        """Camera-frame points (mi.Point3f, metres) -> unit grid coordinates."""
        mi = backend.modules()[1]
        s = (self.fx * p.x / p.z + self.cx - self.u0) / self.du
        t = (self.fy * p.y / p.z + self.cy - self.v0) / self.dv
        r = (self.inv_near - 1.0 / p.z) / self.dinv
        return mi.Point3f(s, t, r)


def ray_segment(fc: FrameConstants, o, d):
    """The part of the rays ``o + t d`` (t >= 0) inside the grid, in unit coordinates.

    A ray moving away from the camera (``d_z > 0``) is followed to the far plane, one
    moving towards it to the near plane; the segment is then clipped to the unit cube
    (the frustum: the map to grid coordinates is projective, so the clipped segment is
    exactly the part of the ray inside the frustum). Where it ends (far plane, near
    plane or a side) the last sample is an opaque backdrop with the grid's colour there.

    Returns
    -------
    g0, g1 : mi.Point3f
        Unit coordinates of the start and end.
    valid : mi.Bool
        The ray starts in front of the camera and crosses the grid.
    """
    dr, mi = backend.modules()
    eps = 1e-4
    dz = dr.select(dr.abs(d.z) > eps, d.z, eps)
    t_end = dr.select(d.z > eps, (fc.far - o.z) / dz,
                      dr.select(d.z < -eps, (fc.near - o.z) / dz, 1e3))
    t_end = dr.maximum(t_end, 0.0)
    t_start = dr.select((o.z < fc.near) & (d.z > eps), (fc.near - o.z) / dz, 0.0)
    p0 = o + t_start * d
    p1 = o + t_end * d
    p0 = mi.Point3f(p0.x, p0.y, dr.maximum(p0.z, fc.near))
    p1 = mi.Point3f(p1.x, p1.y, dr.clip(p1.z, fc.near, fc.far))
    a, b = fc.unit(p0), fc.unit(p1)
    # Slab clipping of a -> b against [0, 1]^3.
    lo, hi = mi.Float(0.0), mi.Float(1.0)
    for ai, bi in ((a.x, b.x), (a.y, b.y), (a.z, b.z)):
        di = bi - ai
        di_s = dr.select(dr.abs(di) > 1e-9, di, 1e-9)
        l0, l1 = (0.0 - ai) / di_s, (1.0 - ai) / di_s
        flat = dr.abs(di) <= 1e-9
        lo = dr.select(flat, lo, dr.maximum(lo, dr.minimum(l0, l1)))
        hi = dr.select(flat, hi, dr.minimum(hi, dr.maximum(l0, l1)))
        inside_flat = (ai >= 0.0) & (ai <= 1.0)
        hi = dr.select(flat & ~inside_flat, -1.0, hi)
    valid = (o.z > 0) & (hi > lo + 1e-4)
    g0 = a + lo * (b - a)
    g1 = a + hi * (b - a)
    return mi.Point3f(g0), mi.Point3f(g1), valid


def leaves_through_top(g1) -> mi.Bool:
    """Segments that end on the grid's top face (``t = 0``, above the camera view)
    before its far plane: totem rays going to what the camera cannot see (ceiling,
    lights, sky), whose backdrop would paint the top rows of the view."""
    return (g1.y <= 1e-4) & (g1.z < 1.0 - 1e-4)


def density_at(density: mi.Texture3f, p) -> mi.Float:
    """The raw density at unit grid points ``p`` (mi.Point3f): trilinear between cell
    centres, clamped at the edges, as ``mi.Texture3f.eval`` (equal to float rounding).

    Eight gathers whose adjoint adds in fixed point (:func:`inverse.exact_gather.grid_at`),
    so a fit's gradient is the same on two threads as on one (docs/decisions.md, "fit:
    the backward pass on two threads, in fixed point").
    """
    return grid_at(density, p)[0]


def march(density: mi.Texture3f, colour: mi.Texture3f, g0, g1, n: int, *,
          jitter=None, delta_scale=(DELTA_SCALE, DELTA_SCALE, DELTA_SCALE)):
    """Volume rendering of segments ``g0 -> g1`` given per lane (blocks of ``n``).

    Parameters
    ----------
    density, colour : mi.Texture3f
        Raw density (1 channel) and linear RGB colour (3 channels; a ``mi.Texture2f``
        over ``(s, t)`` when the colour grid is one slice deep).
    g0, g1 : mi.Point3f
        Segment ends in unit grid coordinates, one value per *lane* (constant within
        each block of ``n`` lanes).
    n : int
        Samples per ray (block size).
    jitter : mi.Float or None
        Per-lane offset in [0, 1) within each sample's interval (stratified
        sampling); None = interval midpoints.

    Returns
    -------
    C : mi.Color3f, one per ray: linear radiance.
    w : mi.Float, per lane: the compositing weights (sum to 1 per ray).
    m : mi.Float, per lane: the sample's position along the segment in [0, 1].
    """
    dr, mi = backend.modules()
    lanes = dr.width(g0)
    k = dr.arange(mi.UInt32, lanes) % n
    m = (mi.Float(k) + (0.5 if jitter is None else jitter)) / n
    p = g0 + m * (g1 - g0)
    seg = mi.Vector3f(g1 - g0) * mi.Vector3f(*delta_scale)
    delta = dr.norm(seg) / n
    sigma = softplus(density_at(density, p))
    tau = sigma * delta
    c = mi.Color3f(*grid_at(colour, p))
    dr.eval(tau, c, m)        # one kernel for the lookups, reused by every reduction
    T = dr.exp(-dr.block_prefix_sum(tau, n, exclusive=True))
    alpha = dr.select(k == n - 1, 1.0, 1.0 - dr.exp(-tau))   # opaque backdrop
    w = T * alpha
    dr.eval(w)
    C = mi.Color3f(dr.block_sum(w * c.x, n), dr.block_sum(w * c.y, n),
                   dr.block_sum(w * c.z, n))
    return C, w, m


def distortion(w, m, n: int):
    """Mip-NeRF 360's distortion loss per ray, on the segment coordinate ``m``.

    ``sum_ij w_i w_j |m_i - m_j| + 1/3 sum_i w_i^2 / n``, the pairwise term in O(n)
    by exclusive prefix sums: ``2 sum_i w_i (m_i W_<i - (wm)_<i)``. Small when each
    ray's weight sits in one short interval (an opaque surface).
    """
    dr = backend.modules()[0]
    W_ex = dr.block_prefix_sum(w, n, exclusive=True)
    WM_ex = dr.block_prefix_sum(w * m, n, exclusive=True)
    per_lane = 2.0 * w * (m * W_ex - WM_ex) + dr.square(w) / (3.0 * n)
    return dr.block_sum(per_lane, n)


def device_rays(d_cam, totem_index):
    """Pixel directions (m, 3) and totem indices (m,) as ``mi.Vector3f`` and
    ``mi.UInt32`` (uploaded once: a fit's steps reuse them); Dr.Jit inputs pass."""
    mi = backend.modules()[1]
    if isinstance(d_cam, mi.Vector3f):
        return d_cam, totem_index
    return (backend.upload(mi.Vector3f, d_cam),
            backend.upload(mi.UInt32, totem_index, np.uint32))


def select_center(centers, index):
    """Per-lane totem centre: ``centers`` (x, y, z mi.Float of width n_totems),
    ``index`` (mi.UInt32 per lane). A select chain, whose adjoint is a plain sum."""
    dr, mi = backend.modules()
    n_tot = dr.width(centers[0])
    P = [mi.Float(0.0)] * 3
    for j in range(n_tot):
        is_j = index == j
        P = [dr.select(is_j, dr.gather(mi.Float, centers[a], j, mode=dr.ReduceMode.Direct),
                       P[a]) for a in range(3)]
    return mi.Point3f(*P)


class TotemGrid:
    """Emission-absorption rendering of the frustum grid: camera columns, or totem
    pixels' rays refracted through their sphere (:meth:`render_totem_rays`). Only the
    methods: :func:`integrator_class` puts them on a Mitsuba integrator.

    Set the scene-specific parts with :meth:`setup` (frame, grids, totems); the grids
    and centres are then Mitsuba parameters (``mi.traverse``), differentiable.
    """

    def __init__(self, props=None):
        mi = backend.modules()[1]
        props = props if props is not None else mi.Properties()
        mi.SamplingIntegrator.__init__(self, props)
        self.n_samples = int(props.get("n_samples", 64))
        self.fc = None
        self.density = None
        self.colour = None
        self.centers = None
        self.radius = None
        self.ior = None
        self.mirror = False          # add the front reflection of the grid itself

    # ------------------------------------------------------------------ parameters

    def setup(self, frame: FrustumFrame, density: np.ndarray, colour: np.ndarray,
              centers=None, radius=None, ior=None):
        """Scene parts: the frame, raw density (nr, nt, ns, 1), linear colour
        (nr', nt', ns', 3), totem centres (n, 3) m, radii (n,) m, IoR (n,)."""
        mi = backend.modules()[1]
        self.fc = FrameConstants(frame)
        self.density = mi.Texture3f(backend.upload(mi.TensorXf, density))
        colour = np.asarray(colour, np.float32)
        # One slice deep: a 2-D texture, half the lookups of a 3-D one.
        self.colour = (mi.Texture2f(backend.upload(mi.TensorXf, colour[0]))
                       if colour.shape[0] == 1 else
                       mi.Texture3f(backend.upload(mi.TensorXf, colour)))
        if centers is not None:
            c = np.asarray(centers, dtype=np.float32).reshape(-1, 3)
            self.centers = backend.upload(mi.Float, c.T.ravel())
            self.radius = backend.upload(mi.Float, np.reshape(radius, -1))
            self.ior = backend.upload(mi.Float, np.reshape(ior, -1))
        return self

    def traverse(self, callback):
        mi = backend.modules()[1]
        callback.put("density", self.density.tensor(), mi.ParamFlags.Differentiable)
        callback.put("colour", self.colour.tensor(), mi.ParamFlags.Differentiable)
        if self.centers is not None:
            callback.put("centers", self.centers, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        self.density.update_inplace()
        self.colour.update_inplace()

    def center_array(self):
        """The centres as three mi.Float of width n_totems (x, y, z)."""
        dr, mi = backend.modules()
        n = dr.width(self.centers) // 3
        idx = dr.arange(mi.UInt32, n)
        return [dr.gather(mi.Float, self.centers, idx + a * n, mode=dr.ReduceMode.Direct)
                for a in range(3)]

    def center_numpy(self) -> np.ndarray:
        """(n, 3) centres, metres."""
        c = np.asarray(self.centers, dtype=np.float64)
        return c.reshape(3, -1).T.copy()

    # ------------------------------------------------------------------ rendering

    def render_columns(self, s, t, *, n=None, jitter=None):
        """Camera rays as grid columns at unit coordinates ``(s, t)`` (numpy, per ray).

        Returns per-ray linear colour, and per-lane weights and positions (see
        :func:`march`).
        """
        mi = backend.modules()[1]
        n = n or self.n_samples
        s = backend.upload(mi.Float, np.repeat(np.asarray(s, np.float32), n))
        t = backend.upload(mi.Float, np.repeat(np.asarray(t, np.float32), n))
        g0 = mi.Point3f(s, t, 0.0)
        g1 = mi.Point3f(s, t, 1.0)
        return march(self.density, self.colour, g0, g1, n, jitter=jitter)

    def refract(self, d_cam, totem_index):
        """Camera rays through totem pixels, refracted out of their sphere.

        ``d_cam`` (m, 3) numpy unit camera-frame directions, ``totem_index`` (m,) ints
        (or both already on the device, :func:`device_rays`). Returns the exit points
        (mi.Point3f, metres), exit directions, Fresnel transmittance ``T_F`` and
        validity per ray (:func:`inverse.sphere.totem_rays`), differentiable in the
        centres.
        """
        dr, mi = backend.modules()
        d, idx = device_rays(d_cam, totem_index)
        P = select_center(self.center_array(), idx)
        R = dr.gather(mi.Float, self.radius, idx)
        eta = dr.gather(mi.Float, self.ior, idx)
        return totem_rays(mi.Point3f(0.0), d, P, R, eta)

    def render_totem_rays(self, d_cam, totem_index, *, n=None, jitter=None):
        """Totem pixels: camera rays refracted through their totem, then marched.

        Parameters
        ----------
        d_cam : (m, 3) numpy, unit camera-frame directions of the pixels.
        totem_index : (m,) int, which totem each pixel belongs to.

        Returns
        -------
        L : mi.Color3f per ray, linear radiance the pixel sees (``T_F * C``).
        valid : mi.Bool per ray (refraction valid and segment inside the grid).
        w, m : per-lane weights and positions (see :func:`march`).
        g0, g1 : per-lane segment ends (unit coordinates).
        """
        dr, mi = backend.modules()
        n = n or self.n_samples
        o_out, d_out, T_F, ok = self.refract(d_cam, totem_index)
        g0, g1, inside = ray_segment(self.fc, o_out, d_out)
        valid = ok & inside & ~leaves_through_top(g1)
        dr.eval(g0, g1, T_F, valid)
        # Per ray -> per lane: dr.repeat's adjoint is a block sum (no atomics).
        g0_l = mi.Point3f(*[dr.repeat(g0[a], n) for a in range(3)])
        g1_l = mi.Point3f(*[dr.repeat(g1[a], n) for a in range(3)])
        C, w, m = march(self.density, self.colour, g0_l, g1_l, n, jitter=jitter)
        L = C * T_F
        if self.mirror:
            L = L + self.mirrored(d_cam, totem_index, T_F)[0]
        return L, valid, w, m, g0_l, g1_l

    def mirrored(self, d_cam, totem_index, T_F):
        """The front reflection of the scene the grid holds, per ray: ``R_F C_r``
        (mi.Color3f, linear RGB), ``R_F = 1 - sqrt(T_F)`` (the two surfaces alike) and
        ``C_r`` the grid marched along the camera ray mirrored where it enters its
        sphere, where that ray goes away from the camera and not out through the top
        face (behind, the near plane's colour is not the scene's); and that mask
        (mi.Bool). The sphere's geometry is detached: the reflection fits the scene,
        not the pose."""
        dr, mi = backend.modules()
        d, idx = device_rays(d_cam, totem_index)
        P = dr.detach(select_center(self.center_array(), idx))
        R = dr.gather(mi.Float, self.radius, idx)
        t_near, _, _ = intersect(mi.Point3f(0.0), d, P, R)
        X = dr.detach(t_near) * d
        N = dr.normalize(mi.Vector3f(X - P))
        r = d - 2.0 * dr.dot(d, N) * N
        g0, g1, inside = ray_segment(self.fc, mi.Point3f(X + 1e-4 * N), r)
        ok = inside & ~leaves_through_top(g1) & (r.z > 0.0)
        n = max(16, self.n_samples // 2)
        g0_l = mi.Point3f(*[dr.repeat(g0[a], n) for a in range(3)])
        g1_l = mi.Point3f(*[dr.repeat(g1[a], n) for a in range(3)])
        C, _, _ = march(self.density, self.colour, g0_l, g1_l, n)
        R_F = 1.0 - dr.sqrt(dr.clip(dr.detach(T_F), 0.0, 1.0))
        return dr.select(ok, R_F * C, 0.0), ok

    def mirrored_numpy(self, d_cam, totem_index):
        """:meth:`mirrored` at the current centres without gradients: (m, 3) linear RGB
        and (m,) bool."""
        dr = backend.modules()[0]
        with dr.suspend_grad():
            _, _, T_F, _ = self.refract(d_cam, totem_index)
            L, ok = self.mirrored(d_cam, totem_index, T_F)
            return np.asarray(L).T.copy(), np.asarray(ok, bool)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """One camera ray per lane (camera frame = world frame), marched through the
        grid: the camera view, as :meth:`render_columns` gives it."""
        dr, mi = backend.modules()
        n = self.n_samples
        m_rays = dr.width(ray.o)
        idx = dr.arange(mi.UInt32, m_rays * n) // n
        o = dr.gather(mi.Point3f, mi.Point3f(ray.o), idx)
        d = dr.gather(mi.Vector3f, mi.Vector3f(ray.d), idx)
        g0, g1, inside = ray_segment(self.fc, o, d)
        C, _, _ = march(self.density, self.colour, g0, g1, n)
        keep = dr.block_sum(dr.select(inside, 1.0, 0.0), n) / n
        return mi.Spectrum(C * keep), mi.Bool(active), []

    def aov_names(self):
        return []

    def to_string(self):
        return f"TotemGridIntegrator[n_samples={self.n_samples}]"


@functools.cache
def integrator_class():
    """``TotemGridIntegrator``: the methods of :class:`TotemGrid` on a
    ``mi.SamplingIntegrator`` (registered as ``"totem_grid"``), made at the first use
    since its Mitsuba base needs the variant chosen (and nanobind allows one base)."""
    mi = backend.modules()[1]
    methods = {k: v for k, v in vars(TotemGrid).items()
               if k not in ("__dict__", "__weakref__")}
    TotemGridIntegrator = type("TotemGridIntegrator", (mi.SamplingIntegrator,), methods)
    mi.register_integrator("totem_grid", lambda props: TotemGridIntegrator(props))
    return TotemGridIntegrator


def __getattr__(name):
    """``TotemGridIntegrator``: the class of :func:`integrator_class` (PEP 562)."""
    if name == "TotemGridIntegrator":
        return integrator_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
