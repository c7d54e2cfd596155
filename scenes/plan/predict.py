"""The reach a placement of totems predicts, with the subject taken as a plane.

Before the shot there is nothing to trace: the subject is a plane (a person a few metres
away nearly is one, as the totems see it), the camera's ray through each pixel meets it
at ``X``, and each totem pixel's ray, refracted through the key's sphere
(:func:`scenes.refraction.refract_sphere`), leaves the glass and meets it at ``Y``, or
passes it by where the plane beyond the subject's region would be. The
rays kept are those the truth's reach keeps (:func:`scenes.synthetic.trace.truth_reach`):
transmitting more than :data:`~scenes.refraction.MIN_TRANSMITTANCE`, entered at an
incidence cosine of at least :data:`~scenes.reach.COS_EVIDENCE`, and not into another
totem. From ``X`` and ``Y``, :func:`scenes.reach.reach_map` gives the reach by the rule the
truth's reach and the evidence map share. What the plane leaves out: the subject's own
depth, and anything else (a chair, the floor under totems resting on it, a stand's post)
that hides part of the subject from a totem.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres; pixel
centres at integers (:mod:`scenes.camera`); angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.reach import COS_EVIDENCE, Reach, reach_map
from scenes.refraction import MIN_TRANSMITTANCE, entry_cosine, refract_sphere, transmittance

__all__ = ["MIN_GAP", "Plane", "subject_plane", "fronto_plane", "plane_hits", "subject_hits",
           "disc_box", "disc_pixels", "entry_distance", "totem_image", "check_placement",
           "TotemRays", "sent_on", "totem_rays", "grid_points", "Prediction", "plane_reach",
           "seen_by", "predict", "seen_shares"]

MIN_GAP = 0.01
"""A sphere's nearest point must be this far (metres) from the camera's centre."""


class Plane(NamedTuple):
    """The subject: a plane through ``point`` (3,) metres with unit ``normal`` (3,)
    turned towards the camera."""

    point: np.ndarray
    normal: np.ndarray


def subject_plane(point, normal) -> Plane:
    """The plane through ``point`` with normal ``normal`` (camera frame, metres; either
    sign: it is turned towards the camera). BadInput when it passes through the camera."""
    p, n = np.asarray(point, np.float64), np.asarray(normal, np.float64)
    if p.shape != (3,) or n.shape != (3,) or not np.isfinite([*p, *n]).all():
        raise BadInput("the subject plane needs a point x,y,z and a normal nx,ny,nz "
                       "(metres)")
    if np.linalg.norm(n) < 1e-9:
        raise BadInput("the subject plane's normal is zero")
    n = n / np.linalg.norm(n)
    side = float(-(n @ p))                 # the camera's signed distance from the plane
    if abs(side) < 1e-6:
        raise BadInput("the subject plane passes through the camera")
    return Plane(p, n if side > 0 else -n)


def fronto_plane(distance: float) -> Plane:
    """The plane ``z = distance`` (metres), facing the camera. BadInput unless it lies
    in front of the camera."""
    if not (np.isfinite(distance) and distance > 0):
        raise BadInput(f"the subject distance must be positive (in front of the camera), "
                       f"got {distance:g} m")
    return Plane(np.array([0.0, 0.0, float(distance)]), np.array([0.0, 0.0, -1.0]))


def plane_hits(o, d, plane: Plane) -> np.ndarray:
    """Where rays ``o + t d`` ((m, 3) each, metres; ``d`` unit) meet ``plane`` ahead
    (``t > 0``): (m, 3) metres, NaN for a ray parallel to it or leaving it behind."""
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    along = d @ plane.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((plane.point - o) @ plane.normal) / along
    ok = (np.abs(along) > 1e-9) & (t > 0)
    return np.where(ok[:, None], o + np.where(ok, t, 0.0)[:, None] * d, np.nan)


def subject_hits(o, d, plane: Plane, K=None, region=None) -> np.ndarray:
    """Where rays meet the subject: :func:`plane_hits`, and NaN too where the point lies
    outside ``region`` ((H, W) bool, the pixels the subject fills in a camera ``K``), as
    the ray passes the subject by. Without a region, the plane has no edge."""
    Y = plane_hits(o, d, plane)
    if region is None:
        return Y
    H, W = region.shape
    ok = np.isfinite(Y).all(1)
    uv = np.rint(camera.project(K, Y[ok])).astype(np.int64)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    on = np.zeros(len(Y), bool)
    on[np.flatnonzero(ok)[inside]] = region[uv[inside, 1], uv[inside, 0]]
    return np.where(on[:, None], Y, np.nan)


def disc_box(K, center, radius: float) -> tuple[float, float, float, float]:
    """(u0, v0, u1, v1) pixels: a box holding a sphere's image (the projection of its
    bounding cube; the sphere wholly in front of the camera)."""
    P = np.asarray(center, np.float64)
    corners = P + radius * np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1)
                                     for c in (-1, 1)], np.float64)
    uv = camera.project(K, corners)
    return uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()


def disc_pixels(K, size, center, radius: float):
    """The pixels whose centre's ray meets a sphere (``center`` (3,) m, ``radius`` m) in
    a frame of ``size`` (W, H): (u (k,) int, v (k,) int, t (k,) the distance in metres at
    which each ray enters it)."""
    W, H = size
    P = np.asarray(center, np.float64)
    u0, v0, u1, v1 = disc_box(K, P, radius)
    u0, v0 = max(int(np.floor(u0)), 0), max(int(np.floor(v0)), 0)
    u1, v1 = min(int(np.ceil(u1)), W - 1), min(int(np.ceil(v1)), H - 1)
    if u1 < u0 or v1 < v0:
        e = np.zeros(0, np.int64)
        return e, e, np.zeros(0)
    v, u = np.mgrid[v0:v1 + 1, u0:u1 + 1]
    d = camera.pixel_rays(K, u, v)
    b = d @ P
    l2 = P @ P - b * b
    t = b - np.sqrt(np.maximum(radius * radius - l2, 0.0))
    hit = (l2 < radius * radius) & (t > 0)
    return u[hit], v[hit], t[hit]


def entry_distance(K, u, v, center, radius: float) -> np.ndarray:
    """(k,) metres at which the rays through pixels (u, v) enter a sphere; inf where
    they miss it."""
    d = camera.pixel_rays(K, u, v)
    P = np.asarray(center, np.float64)
    b = d @ P
    l2 = P @ P - b * b
    t = b - np.sqrt(np.maximum(radius * radius - l2, 0.0))
    return np.where((l2 < radius * radius) & (t > 0), t, np.inf)


def totem_image(K, size, centers, radius) -> np.ndarray:
    """(H, W) int: the totem whose sphere each pixel centre's ray meets first (its index
    in ``centers``), -1 where it meets none. ``size`` (W, H); ``radius`` (n,) metres."""
    W, H = size
    labels = np.full((H, W), -1, np.int64)
    first = np.full((H, W), np.inf)
    for j, (P, R) in enumerate(zip(np.asarray(centers, np.float64), np.asarray(radius))):
        u, v, t = disc_pixels(K, size, P, R)
        near = t < first[v, u]
        first[v[near], u[near]] = t[near]
        labels[v[near], u[near]] = j
    return labels


def check_placement(K, size, centers, radius, plane: Plane) -> None:
    """BadInput, in one line, for a placement no photo can have: fewer than two totems,
    a totem behind or touching the camera, beyond or through the subject's plane, not
    wholly in the frame, or two totems overlapping."""
    W, H = size
    centers = np.asarray(centers, np.float64)
    radius = np.asarray(radius, np.float64)
    if centers.ndim != 2 or centers.shape[1] != 3 or len(centers) < 2:
        raise BadInput(f"a plan needs at least two totems (the reach is what two see), "
                       f"got {len(centers) if centers.ndim == 2 else 0}")
    for j, (P, R) in enumerate(zip(centers, radius)):
        if P[2] <= 0:
            raise BadInput(f"totem {j} is behind the camera (centre z = {P[2]:.2f} m)")
        if np.linalg.norm(P) - R < MIN_GAP or P[2] - R < MIN_GAP:
            raise BadInput(f"totem {j} of radius {R:g} m would touch the camera or stand "
                           f"beside it (centre {np.linalg.norm(P):.3f} m away, "
                           f"z = {P[2]:.3f} m)")
        side = float((P - plane.point) @ plane.normal)
        if side < -R:
            raise BadInput(f"totem {j} stands behind the subject ({-side:.2f} m beyond its "
                           "plane): put the totems between the camera and the subject")
        if side < R:
            raise BadInput(f"totem {j} intersects the subject's plane (its centre "
                           f"{side:.2f} m from it, radius {R:g} m)")
        u0, v0, u1, v1 = disc_box(K, P, R)
        if u0 < 0 or v0 < 0 or u1 > W - 1 or v1 > H - 1:
            uv = camera.project(K, P)
            raise BadInput(f"totem {j} (at pixel {uv[0]:.0f},{uv[1]:.0f}, radius {R:g} m) "
                           f"leaves the {W}x{H} frame: keep every totem wholly in view")
    for i in range(len(centers)):
        for j in range(i + 1, len(centers)):
            if np.linalg.norm(centers[i] - centers[j]) < radius[i] + radius[j]:
                raise BadInput(f"totems {i} and {j} overlap: their centres are "
                               f"{np.linalg.norm(centers[i] - centers[j]):.3f} m apart")


@dataclass
class TotemRays:
    """The totem pixels' rays the glass sends on into the scene.

    Attributes
    ----------
    o, d : (m, 3) exit points (metres) and unit directions.
    totem : (m,) int, the totem each left.
    """

    o: np.ndarray
    d: np.ndarray
    totem: np.ndarray

    def of(self, j: int) -> "TotemRays":
        """Totem ``j``'s rays alone, numbered 0."""
        k = self.totem == j
        return TotemRays(self.o[k], self.d[k], np.zeros(int(k.sum()), np.int64))


def _meets_sphere(o, d, P, R) -> np.ndarray:
    """(m,) bool: rays ``o + t d`` (starting outside the sphere) enter it ahead."""
    b = ((P - o) * d).sum(1)
    l2 = ((P - o) ** 2).sum(1) - b * b
    return (l2 < R * R) & (b - np.sqrt(np.maximum(R * R - l2, 0.0)) > 0)


def sent_on(K, u, v, center, radius: float, ior: float, others=(), *,
            cos_min: float = COS_EVIDENCE):
    """The rays of one totem's pixels (u, v) refracted through its sphere (``center``
    (3,) m, ``radius`` m, ``ior``), kept as the truth's reach keeps them: transmitting
    more than ``MIN_TRANSMITTANCE``, entered at an incidence cosine of at least
    ``cos_min``, not into another totem (``others``: (centre, radius) pairs). Returns
    (exit points (m, 3) metres, unit directions (m, 3))."""
    dc = camera.pixel_rays(K, u, v).reshape(-1, 3)
    P, R, eta = np.asarray(center, np.float64), float(radius), float(ior)
    E, d, valid = refract_sphere(dc, P, R, eta)
    cos_in = entry_cosine(dc, P, R)
    keep = valid & (transmittance(cos_in, eta) > MIN_TRANSMITTANCE) & (cos_in >= cos_min)
    E, d = E[keep], d[keep]
    for Pi, Ri in others:
        if len(E):
            free = ~_meets_sphere(E, d, np.asarray(Pi, np.float64), float(Ri))
            E, d = E[free], d[free]
    return E, d


def totem_rays(K, labels, centers, radius, ior, *,
               cos_min: float = COS_EVIDENCE) -> TotemRays:
    """Each totem's pixels (``labels``, :func:`totem_image`) refracted through its
    sphere (``centers`` (n, 3) m, ``radius`` (n,) m, ``ior`` (n,)) and kept as
    :func:`sent_on` keeps them."""
    centers = np.asarray(centers, np.float64)
    parts = []
    for j in range(len(centers)):
        v, u = np.nonzero(labels == j)
        others = [(centers[i], radius[i]) for i in range(len(centers)) if i != j]
        E, d = sent_on(K, u, v, centers[j], radius[j], ior[j], others, cos_min=cos_min)
        parts.append((E, d, np.full(len(E), j, np.int64)))
    if not parts:
        return TotemRays(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
    return TotemRays(*(np.concatenate(x) for x in zip(*parts)))


def grid_points(K, size, plane: Plane):
    """The camera's rays through every pixel of a frame of ``size`` (W, H) and where
    they meet the plane: (view (H, W, 3) unit, X (H, W, 3) metres, NaN where a ray
    misses it)."""
    W, H = size
    v, u = np.mgrid[0:H, 0:W]
    view = camera.pixel_rays(K, u, v)
    X = plane_hits(np.zeros((view.size // 3, 3)), view.reshape(-1, 3), plane)
    return view, X.reshape(view.shape)


@dataclass
class Prediction:
    """The reach a placement predicts.

    Attributes
    ----------
    reach : :class:`scenes.reach.Reach` over the frame (H, W).
    labels : (H, W) int, the totem each pixel images (-1 none).
    """

    reach: Reach
    labels: np.ndarray


def plane_reach(view, X, excluded, centers, rays: TotemRays, plane: Plane, *, K=None,
                region=None) -> Reach:
    """:func:`scenes.reach.reach_map` of camera points ``X`` ((h, w, 3) m, along unit
    ``view``; ``excluded`` (h, w)) and totem ``rays`` meeting the subject
    (:func:`subject_hits`: ``plane``, within ``region`` as camera ``K`` sees it)."""
    Y = subject_hits(rays.o, rays.d, plane, K, region)
    normal = np.broadcast_to(plane.normal, Y.shape)
    return reach_map(view, X, excluded, centers, o=rays.o, d=rays.d, Y=Y, normal=normal,
                     totem=rays.totem)


def seen_by(view, X, excluded, center, rays: TotemRays, plane: Plane, *, K=None,
            region=None):
    """Which points one totem (centre (3,) m, its ``rays`` numbered 0) sees, by the
    reach's rule (the subject as :func:`plane_reach` takes it): ((h, w) bool, its rays'
    angular spacing in radians)."""
    r = plane_reach(view, X, excluded, np.asarray(center, np.float64)[None], rays, plane,
                    K=K, region=region)
    return r.n_totems > 0, float(r.spacing[0])


def _key(centers, radius, ior):
    centers = np.asarray(centers, np.float64)
    n = len(centers)
    return (centers, np.broadcast_to(np.asarray(radius, np.float64), (n,)),
            np.broadcast_to(np.asarray(ior, np.float64), (n,)))


def predict(K, size, centers, radius, ior, plane: Plane, *, region=None,
            cos_min: float = COS_EVIDENCE) -> Prediction:
    """The reach of totems (``centers`` (n, 3) m, ``radius`` (n,) m, ``ior`` (n,)) seen
    by a camera ``K`` of ``size`` (W, H) px, on the subject's ``plane``: over the whole
    frame, or, given ``region`` ((H, W) bool, the pixels the subject fills), over the
    subject alone (a ray landing on the plane beyond the region passes it by, and no
    pixel outside it is counted as seen)."""
    W, H = size
    centers, radius, ior = _key(centers, radius, ior)
    labels = totem_image(K, size, centers, radius)
    rays = totem_rays(K, labels, centers, radius, ior, cos_min=cos_min)
    view, X = grid_points(K, size, plane)
    where = np.ones((H, W), bool) if region is None else np.asarray(region, bool)
    r = plane_reach(view[where][None], X[where][None], (labels >= 0)[where][None], centers,
                    rays, plane, K=K, region=region)
    n_totems, parallax, backdrop = (np.zeros((H, W), a.dtype) for a in
                                    (r.n_totems, r.parallax, r.backdrop))
    n_totems[where], parallax[where], backdrop[where] = r.n_totems[0], r.parallax[0], \
        r.backdrop[0]
    depth = np.where(np.isfinite(X[..., 2]), X[..., 2], np.inf).astype(np.float32)
    reach = Reach(depth=depth, n_totems=n_totems, parallax=parallax, backdrop=backdrop,
                  excluded=labels >= 0, spacing=r.spacing)
    return Prediction(reach, labels)


def seen_shares(K, size, centers, radius, ior, plane: Plane, u, v, *, region=None,
                cos_min: float = COS_EVIDENCE) -> np.ndarray:
    """(n,) the share of pixels (u, v) whose point of the subject (``plane`` within
    ``region``, as :func:`predict` takes it) each totem sees (pixels a totem hides count
    as unseen)."""
    centers, radius, ior = _key(centers, radius, ior)
    labels = totem_image(K, size, centers, radius)
    rays = totem_rays(K, labels, centers, radius, ior, cos_min=cos_min)
    view = camera.pixel_rays(K, u, v)
    X = plane_hits(np.zeros_like(view), view, plane)
    hidden = (labels[v, u] >= 0)[None]
    return np.array([seen_by(view[None], X[None], hidden, centers[j], rays.of(j), plane,
                             K=K, region=region)[0].mean() for j in range(len(centers))])
