"""Where the camera's and the totems' rays truly land in a synthetic scene, and its reach.

A described scene (:mod:`scenes.synthetic.render`) is ray traced by Mitsuba itself, so
occlusion is the renderer's: each camera pixel's ray to its first surface, and each totem
pixel's ray refracted through its true sphere (:mod:`scenes.refraction`) and sent on from
the glass. A totem ray that meets another totem first is blocked (what lies behind a
sphere reaches the glass bent). From both, :func:`scenes.reach.reach_map` gives the
truth's reach: what physics lets the totems establish, which no fit can widen.

Frames and units: the camera frame (OpenCV, metres), pixel centres as
:func:`scenes.camera.pixel_rays` (the sensor of :func:`scenes.camera.mitsuba_sensor` shoots
the same rays).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes import backend, camera, folder
from scenes.errors import BadInput
from scenes.reach import COS_EVIDENCE, SUPERSAMPLE, Reach, reach_map
from scenes.refraction import MIN_TRANSMITTANCE, exit_rays
from scenes.synthetic.render import (NOTHING, TOTEM_ID_BASE, hit_ids, load_scene, scene_dict,
                                     totem_id)

__all__ = ["TotemHits", "tracer", "camera_points", "totem_hits", "truth_reach", "write_reach"]


@dataclass
class TotemHits:
    """Every totem pixel's ray through its true sphere and where it lands.

    Attributes
    ----------
    u, v, totem, o, d, T, cos_in : as :class:`scenes.refraction.ExitRays` (the sphere
        ``totem`` as ``desc["totems"]`` orders them).
    Y : (m, 3) where the ray lands, metres; NaN where it leaves the scene.
    normal : (m, 3) the surface's unit normal there; NaN where it left.
    hit_id : (m,) int, the object or light it lands on (:data:`NOTHING` for the
        environment, :func:`totem_id` for another totem).
    """

    u: np.ndarray
    v: np.ndarray
    totem: np.ndarray
    o: np.ndarray
    d: np.ndarray
    T: np.ndarray
    cos_in: np.ndarray
    Y: np.ndarray
    normal: np.ndarray
    hit_id: np.ndarray

    def sent_on(self) -> np.ndarray:
        """(m,) bool: rays the glass sends on into the scene (transmitting more than
        :data:`MIN_TRANSMITTANCE`, not into another totem)."""
        return (self.T > MIN_TRANSMITTANCE) & (self.hit_id > -TOTEM_ID_BASE)


def tracer(desc: dict, *, totems: bool = True):
    """A function ``trace(o, d)`` giving the first surfaces along rays ``o + t d`` ((m, 3)
    each, camera frame, metres) in the described scene (loaded once, with its totems
    unless ``totems`` is False).

    ``trace`` returns (Y (m, 3) metres, NaN where the ray leaves the scene; normal (m, 3)
    unit, NaN there; ids (m,) int as :func:`scenes.synthetic.render.shape_ids` gives them).
    """
    mi = backend.modules()[1]
    sd, ids = scene_dict(desc, spp=1, totems=totems)
    scene = load_scene(sd)

    def trace(o, d):
        o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
        ray = mi.Ray3f(mi.Point3f(*o.T.astype(np.float32)),
                       mi.Vector3f(*d.T.astype(np.float32)))
        si = scene.ray_intersect(ray)
        valid = np.asarray(si.is_valid(), bool)
        t = np.asarray(si.t, np.float64)
        Y = np.where(valid[:, None], o + t[:, None] * d, np.nan)
        N = np.where(valid[:, None], np.asarray(si.n, np.float64).T.reshape(-1, 3), np.nan)
        return Y, N, hit_ids(scene, ids, si)

    return trace


def camera_points(desc: dict, trace):
    """Each camera pixel's ray and first surface, by ``trace`` (:func:`tracer`): (view
    (H, W, 3) unit directions, X (H, W, 3) metres, NaN where the ray leaves the scene,
    ids (H, W) int)."""
    W, H = (int(s) for s in desc["size"])
    v, u = np.mgrid[0:H, 0:W]
    view = camera.pixel_rays(np.asarray(desc["K"], np.float64), u, v).reshape(-1, 3)
    X, _, ids = trace(np.zeros_like(view), view)
    return view.reshape(H, W, 3), X.reshape(H, W, 3), ids.reshape(H, W)


def totem_hits(desc: dict, ids: np.ndarray, trace, *, supersample: int = 1) -> TotemHits:
    """Every pixel of each totem's true image (``ids``, from :func:`camera_points`),
    refracted through its sphere (:func:`scenes.refraction.exit_rays`, ``supersample``
    x itself rays a pixel) and traced on into the scene by ``trace``."""
    t = desc["totems"]
    r = exit_rays(np.asarray(desc["K"], np.float64),
                  [ids == totem_id(j) for j in range(len(t))],
                  [x["center"] for x in t], [x["radius"] for x in t], [x["ior"] for x in t],
                  supersample=supersample)
    if len(r.u) == 0:
        return TotemHits(*r, Y=r.o.copy(), normal=r.o.copy(), hit_id=r.u.copy())
    Y, N, hit_id = trace(r.o + 1e-5 * r.d, r.d)
    return TotemHits(*r, Y=Y, normal=N, hit_id=hit_id)


def truth_reach(desc: dict, *, cos_min: float = COS_EVIDENCE,
                supersample: int = SUPERSAMPLE) -> tuple[Reach, TotemHits]:
    """The truth's reach of a described scene (:class:`scenes.reach.Reach`) from the totem
    rays that entered their sphere at an incidence cosine of at least ``cos_min`` (by
    default the rays the evidence map reads), ``supersample`` x itself a totem pixel,
    and every totem ray traced."""
    trace = tracer(desc)
    view, X, ids = camera_points(desc, trace)
    hits = totem_hits(desc, ids, trace, supersample=supersample)
    go = hits.sent_on() & (hits.cos_in >= cos_min)
    centers = np.array([t["center"] for t in desc["totems"]], np.float64)
    reach = reach_map(view, X, ids <= -TOTEM_ID_BASE, centers, o=hits.o[go], d=hits.d[go],
                      Y=hits.Y[go], normal=hits.normal[go], totem=hits.totem[go],
                      supersample=supersample)
    return reach, hits


def write_reach(scene_dir) -> Path:
    """Trace the truth's reach of a synthetic scene folder (its ``truth/scene.json``) into
    ``truth/reach.npz``, written atomically; nothing else of the folder is touched. For
    folders made before ``scene make`` wrote it. A tampered copy holds its source's
    description, so it gets the source's reach: what its totems show."""
    scene_dir = Path(scene_dir)
    desc = folder.read_scene_json(scene_dir, missing="the truth's reach is traced in a "
                                  "synthetic scene made by `totems scene make`")
    if "objects" not in desc or "totems" not in desc:
        raise BadInput(f"{scene_dir / 'truth' / 'scene.json'} is not a Mitsuba scene "
                       "description (a Cycles scene's "
                       "reach is traced by Blender: benchmarks/cycles/truth_reach.py)")
    reach, _ = truth_reach(desc)
    pose = folder.safe_load_npy(scene_dir / "truth" / "totem_pose.npy")
    centers = np.array([t["center"] for t in desc["totems"]], np.float64)
    order = [int(np.argmin(np.linalg.norm(centers - p, axis=1))) for p in np.atleast_2d(pose)]
    reach.spacing = reach.spacing[order]
    folder.write_npz(scene_dir / "truth" / "reach.npz", **reach.to_dict())
    return scene_dir / "truth" / "reach.npz"
