"""Render a scene description (``presets.describe``) with Mitsuba 3: photo, ids, masks.

The description format (JSON-serialisable; all positions in the camera frame, which is
the world frame: OpenCV, +x right, +y down, +z forward, metres)::

    {
      "format": 1,
      "preset": str,                "seed": int,    # presets.PRESETS
      "size": [W, H],                               # pixels
      "K": 3x3 list,                                # intrinsics, pixel-centre convention
      "fov_x_deg": float,                           # informational; K rules
      "max_depth": int,                             # path length (optional, default 8)
      "objects": [ {
          "id": int,              # unique over objects and lights, >= 0
          "name": str,
          "kind": "rectangle" | "cube" | "sphere" | "cylinder" | "disk",
          "to_world": 4x4 list,   # maps the unit shape into the camera frame:
                                  #   rectangle [-1,1]^2 at z=0, front +z (one-sided)
                                  #   cube      [-1,1]^3
                                  #   sphere    centre 0, radius 1
                                  #   cylinder  radius 1 about z, z in [0,1], closed
                                  #             by two caps (drawn as disks, same id)
                                  #   disk      radius 1 at z=0, front +z
          "material": {"type": "diffuse",
                       "rgb": [r, g, b]                    # linear reflectance, or
                       "texture": "<skimage.data name>",   # sRGB photo, linearised,
                       "tint": [r, g, b],                  # ... times a linear tint,
                       "uv_scale": [su, sv]},              # ... repeated su x sv times
          "removable": bool       # true for objects standing on the floor
        }, ... ],
      "lights": [ {"id": int, "name": str, "kind": "rectangle", "to_world": 4x4,
                   "radiance": [r, g, b],           # linear, W/(m^2 sr), front side
                   "texture": "<name>"}             # optional: radiance x the texture
                | {"id": int, "name": str, "kind": "directional",   # the sun: no shape
                   "direction": [x, y, z],          # the way the light travels
                   "irradiance": [r, g, b]} ],      # linear, W/m^2
      "envmap": null | {"image": "<skimage.data name>", "scale": float,
                        "to_world": 4x4,            # Mitsuba envmap frame (+y up)
                        "layout": "tiled" | "horizon",   # optional, default tiled
                        "sky": [[zenith], [horizon]],    # horizon layout: sRGB 0-1
                        "ground": [r, g, b]},            # horizon layout: sRGB 0-1
      "object_scale": float,                        # optional (1): size of the objects
                                                    # a re-rendering edit adds
      "totems": [ {"center": [x, y, z], "radius": m, "ior": n} ], # left to right
      "placement": "floating" | "resting" | "stand",  # optional, informational
      "support": {"point": [x, y, z], "normal": [x, y, z]}  # optional: the plane
                                 # the totems rest or stand on (normal up), or would
    }

With ``stand`` the posts under the totems are objects (``stand_<id>``, cylinders,
not removable; :mod:`scenes.synthetic.placement`).

A texture ``"<name>"`` is a ``skimage.data`` image or a procedural ``"<kind>:<seed>"``
(:mod:`scenes.synthetic.textures`). The ``tiled`` envmap is :func:`envmap_image` of the
photo, the ``horizon`` one :func:`scenes.synthetic.textures.horizon_panorama`.

Adding an object = appending a dict of a supported kind (with a new id) to
``desc["objects"]``; removing one = ``exclude_ids=(id,)``. Materials are diffuse
(view-independent), totems are smooth ``dielectric`` spheres in vacuum.

Ids returned by :func:`shape_ids`: the object or light id that the ray through the
pixel centre hits first; ``NOTHING`` (-1) for the environment; totem ``j`` (index in
``desc["totems"]``) as ``totem_id(j) = -(1000 + j)``.
"""

from __future__ import annotations

import functools

import numpy as np

from scenes import backend, camera
from scenes.colour import linear_to_srgb, srgb_to_linear
from scenes.errors import BadInput

__all__ = ["NOTHING", "TOTEM_ID_BASE", "KINDS", "sampler_type", "totem_id",
           "texture_image", "envmap_image", "scene_dict", "load_scene", "render",
           "shape_ids", "hit_ids", "depth_map", "totem_masks"]

NOTHING = -1
TOTEM_ID_BASE = 1000
KINDS = ("rectangle", "cube", "sphere", "cylinder", "disk")


def sampler_type(spp: int) -> str:
    """Multi-jittered samples when ``spp`` is a square (at 64 spp about 1.6x less mean
    error than independent ones on the box preset, against a 2048-spp reference, for
    ~15% more time); independent samples otherwise (multijitter would round ``spp``)."""
    return "multijitter" if int(np.sqrt(spp)) ** 2 == int(spp) else "independent"


def totem_id(j: int) -> int:
    """The id :func:`shape_ids` gives totem ``j``."""
    return -(TOTEM_ID_BASE + j)


# --------------------------------------------------------------------------- textures

@functools.lru_cache(maxsize=None)
def texture_image(name: str) -> np.ndarray:
    """``skimage.data.<name>`` (or a procedural ``"<kind>:<seed>"``) as (h, w, 3)
    uint8 sRGB."""
    import skimage.data
    from skimage.color import gray2rgb

    from scenes.synthetic import textures

    if textures.is_procedural(name):
        return textures.procedural(name)
    fn = getattr(skimage.data, str(name), None)
    if fn is None or not callable(fn):
        raise BadInput(f"unknown texture {name!r}: use a skimage.data image name")
    img = np.asarray(fn())
    if img.dtype == bool:
        img = img.astype(np.uint8) * 255
    if img.ndim == 2:
        img = gray2rgb(img)
    return np.ascontiguousarray(img[..., :3].astype(np.uint8))


@functools.lru_cache(maxsize=None)
def _bitmap(name: str, kind: str = "texture", tint=(1.0, 1.0, 1.0), sky=None):
    """A linear float32 ``mi.Bitmap`` of a texture times a linear ``tint`` (or of a
    lat-long envmap: tiled, or with ``sky`` = (zenith, horizon, ground) the horizon
    panorama)."""
    mi = backend.modules()[1]

    img = texture_image(name)
    if kind == "envmap" and sky is not None:
        from scenes.synthetic.textures import horizon_panorama
        img = horizon_panorama(img, *sky)
    elif kind == "envmap":
        img = envmap_image(img)
    lin = srgb_to_linear(img / 255.0) * np.asarray(tint, np.float32)
    return mi.Bitmap(np.ascontiguousarray(lin, dtype=np.float32))


def envmap_image(img: np.ndarray) -> np.ndarray:
    """A seamless 2:1 lat-long panorama (sRGB uint8) from a photograph.

    The upper hemisphere holds the photo four times around the horizon, mirrored
    every other time so the ends meet (each copy spans 90 degrees by 90 degrees);
    the lower hemisphere is the upper one mirrored about the horizon at half
    brightness, like a dull ground.
    """
    from skimage.transform import resize

    h = 256
    tile = resize(img, (h, h), order=1, preserve_range=True, anti_aliasing=True)
    sky = np.concatenate([tile, tile[:, ::-1], tile, tile[:, ::-1]], axis=1)
    pano = np.concatenate([sky, 0.5 * sky[::-1]], axis=0)
    return np.clip(pano + 0.5, 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- description

def _check(desc: dict) -> tuple[int, int]:
    try:
        W, H = (int(s) for s in desc["size"])
        np.asarray(desc["K"], float).reshape(3, 3)
        objects, totems = desc["objects"], desc["totems"]
    except (KeyError, TypeError, ValueError):
        raise BadInput("scene description needs 'size' [W, H], 'K' 3x3, 'objects' and "
                       "'totems' (see scenes.synthetic.render)") from None
    ids = [o["id"] for o in objects] + [l["id"] for l in desc.get("lights", [])]
    if len(set(ids)) != len(ids) or any(int(i) < 0 for i in ids):
        raise BadInput("object and light ids must be unique and >= 0")
    for o in objects:
        if o.get("kind") not in KINDS:
            raise BadInput(f"object {o.get('name')!r} has unknown kind {o.get('kind')!r}; "
                           f"use one of {', '.join(KINDS)}")
    for t in totems:
        if not (float(t["radius"]) > 0 and float(t["ior"]) > 1):
            raise BadInput("each totem needs radius > 0 and ior > 1")
    return W, H


def _material(m: dict) -> dict:
    """Mitsuba BSDF dict of a material of the description (diffuse)."""
    if "texture" in m:
        tint = tuple(float(c) for c in m.get("tint", [1.0, 1.0, 1.0]))
        tex = {"type": "bitmap", "bitmap": _bitmap(m["texture"], "texture", tint),
               "raw": True, "filter_type": "bilinear", "wrap_mode": "repeat"}
        su, sv = (float(s) for s in m.get("uv_scale", [1.0, 1.0]))
        if (su, sv) != (1.0, 1.0):
            mi = backend.modules()[1]
            tex["to_uv"] = mi.ScalarTransform4f().scale([su, sv, 1.0])
        return {"type": "diffuse", "reflectance": tex}
    rgb = [float(c) for c in m.get("rgb", [0.5, 0.5, 0.5])]
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb}}


def _shapes(obj: dict) -> dict:
    """Mitsuba shape dicts (key suffix -> dict) for one object of the description."""
    mi = backend.modules()[1]

    T = mi.ScalarTransform4f(np.asarray(obj["to_world"], float).tolist())
    kind = obj["kind"]
    if kind == "cylinder":
        # Mitsuba's cylinder is open: close it with a disk at each end (normals out).
        flip = mi.ScalarTransform4f().scale([1.0, -1.0, -1.0])
        lift = mi.ScalarTransform4f().translate([0.0, 0.0, 1.0])
        return {"": {"type": "cylinder", "to_world": T},
                "_cap0": {"type": "disk", "to_world": T @ flip},
                "_cap1": {"type": "disk", "to_world": T @ lift}}
    return {"": {"type": kind, "to_world": T}}


def _radiance(light: dict) -> dict:
    """An area light's radiance: an RGB value, or a texture times it (linear)."""
    rgb = [float(c) for c in light["radiance"]]
    if "texture" not in light:
        return {"type": "rgb", "value": rgb}
    return {"type": "bitmap", "bitmap": _bitmap(light["texture"], "texture", tuple(rgb)),
            "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"}


def _directional(light: dict) -> dict:
    """Mitsuba's ``directional`` emitter (a sun: parallel light, no shape)."""
    return {"type": "directional",
            "direction": [float(c) for c in light["direction"]],
            "irradiance": {"type": "rgb",
                           "value": [float(c) for c in light["irradiance"]]}}


def _env_bitmap(env: dict):
    """The envmap's bitmap in its layout (module docstring)."""
    if env.get("layout", "tiled") == "tiled":
        return _bitmap(env["image"], "envmap")
    if env["layout"] != "horizon":
        raise BadInput(f"unknown envmap layout {env['layout']!r}; use tiled or horizon")
    zenith, horizon = (tuple(float(c) for c in rgb) for rgb in env["sky"])
    ground = tuple(float(c) for c in env["ground"])
    return _bitmap(env["image"], "envmap", sky=(zenith, horizon, ground))


def scene_dict(desc: dict, *, spp: int = 64, totems: bool = True, exclude_ids=(),
               integrator: dict | None = None) -> tuple[dict, dict]:
    """The Mitsuba scene dict of a description, and its shape key -> our id map."""
    mi = backend.modules()[1]
    W, H = _check(desc)
    exclude = {int(i) for i in exclude_ids}
    K = np.asarray(desc["K"], float)
    d: dict = {"type": "scene",
               "integrator": integrator or {"type": "path",
                                            "max_depth": int(desc.get("max_depth", 8))},
               "sensor": camera.mitsuba_sensor(K, W, H, spp)}
    d["sensor"]["sampler"] = {"type": sampler_type(spp), "sample_count": int(spp)}
    ids: dict = {}
    for o in desc["objects"]:
        if int(o["id"]) in exclude:
            continue
        bsdf = _material(o.get("material", {}))
        for suffix, shape in _shapes(o).items():
            key = f"obj{int(o['id'])}{suffix}"
            shape["bsdf"] = bsdf
            d[key] = shape
            ids[key] = int(o["id"])
    for light in desc.get("lights", []):
        if int(light["id"]) in exclude:
            continue
        key = f"light{int(light['id'])}"
        if light.get("kind") == "directional":
            d[key] = _directional(light)
            continue
        shape = _shapes(light)[""]
        shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}
        shape["emitter"] = {"type": "area", "radiance": _radiance(light)}
        d[key] = shape
        ids[key] = int(light["id"])
    env = desc.get("envmap")
    if env:
        d["envmap"] = {"type": "envmap", "bitmap": _env_bitmap(env),
                       "scale": float(env.get("scale", 1.0)),
                       "to_world": mi.ScalarTransform4f(
                           np.asarray(env["to_world"], float).tolist())}
    if totems:
        for j, t in enumerate(desc["totems"]):
            key = f"totem{j}"
            d[key] = {"type": "sphere", "center": [float(c) for c in t["center"]],
                      "radius": float(t["radius"]),
                      "bsdf": {"type": "dielectric", "int_ior": float(t["ior"]),
                               "ext_ior": 1.0}}
            ids[key] = totem_id(j)
    return d, ids


# --------------------------------------------------------------------------- public

def _light_order(scene) -> list:
    """Keys of the scene's emitters that are shapes (``light<id>``), in its order."""
    return [str(e.get_shape().id()) for e in scene.emitters() if e.get_shape()]


def load_scene(d: dict, tries: int = 64):
    """``mi.load_dict(d)`` with its area lights in a fixed order (descending id).

    Mitsuba (3.9) lists a scene's area lights in an order that changes from load to
    load, and its path tracer picks the light to sample by that index: with two lights
    or more the same sampler seed gave different noise (box seeds 4 and 5, whose
    re-rendering edits then composited another noise). Loads again until the order
    is descending by id (each load is a fresh shuffle; two lights: 1/2 each time), the
    order the standard set's box seeds 4 and 5 were rendered in (their image.png again).
    """
    mi = backend.modules()[1]
    want = sorted((k for k in d if k.startswith("light") and "emitter" in d[k]),
                  key=lambda k: -int(k[5:]))
    for _ in range(tries):
        scene = mi.load_dict(d)
        if _light_order(scene) == want:
            return scene
    raise RuntimeError(f"Mitsuba kept the lights {want} out of order in {tries} loads")


def render(desc: dict, *, spp: int = 64, totems: bool = True, exclude_ids=(),
           seed: int = 0, linear: bool = False) -> np.ndarray:
    """Path-trace the camera view of ``desc``.

    Parameters
    ----------
    desc : scene description (module docstring).
    spp : samples per pixel.
    totems : draw the totems (False gives the clean view).
    exclude_ids : object or light ids left out (e.g. a removed object).
    seed : the sampler's seed (the same seed gives the same noise).
    linear : return the linear radiance as rendered (not clipped), for a camera model
        to act on before the tone curve.

    Returns
    -------
    (H, W, 3) float32 sRGB in [0, 1] (clipped, no tone mapping); linear with ``linear``.
    """
    mi = backend.modules()[1]
    if int(spp) < 1:
        raise BadInput(f"samples per pixel must be >= 1, got {spp}")
    d, _ = scene_dict(desc, spp=spp, totems=totems, exclude_ids=exclude_ids)
    scene = load_scene(d)
    img = mi.render(scene, spp=int(spp), seed=int(seed))
    if linear:
        return np.array(img, dtype=np.float32)[..., :3]
    return linear_to_srgb(np.array(img)[..., :3])


def shape_ids(desc: dict, *, totems: bool = True, exclude_ids=()) -> np.ndarray:
    """Id of the first surface hit by the ray through each pixel centre, (H, W) int32.

    The rays are the Mitsuba sensor's own (``sample_ray`` at the film position of
    pixel centre (u, v) of ``K``). Ids as in the module docstring.
    """
    dr, mi = backend.modules()
    W, H = _check(desc)
    d, ids = scene_dict(desc, spp=1, totems=totems, exclude_ids=exclude_ids)
    scene = mi.load_dict(d)
    _, si = _centre_hits(scene, W, H)
    return hit_ids(scene, ids, si).astype(np.int32).reshape(H, W)


def hit_ids(scene, ids: dict, si) -> np.ndarray:
    """Our id (module docstring) of the shape each intersection ``si`` of ``scene`` met,
    :data:`NOTHING` where it met none, (m,) int64; ``ids`` the map of
    :func:`scene_dict`."""
    dr, mi = backend.modules()
    hit = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape)).astype(np.int64)
    lookup = {}
    for shape in scene.shapes():
        reg = int(np.asarray(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape)))[0])
        lookup[reg] = ids.get(shape.id(), NOTHING)
    table = np.full(max(lookup, default=0) + 2, NOTHING, np.int64)
    for reg, i in lookup.items():
        table[reg] = i
    return np.where(np.asarray(si.is_valid(), bool),
                    table[np.clip(hit, 0, len(table) - 1)], NOTHING)


def depth_map(desc: dict, *, totems: bool = False) -> np.ndarray:
    """Camera-frame z (metres) of the first surface along the ray through each pixel
    centre, (H, W) float64; inf where the ray meets nothing (the environment).

    The rays are :func:`shape_ids`'; without ``totems`` (the default) the depth of the
    scene behind them, as ``truth/clean.png`` shows it.
    """
    mi = backend.modules()[1]
    W, H = _check(desc)
    scene = mi.load_dict(scene_dict(desc, spp=1, totems=totems)[0])  # alive while si is read
    ray, si = _centre_hits(scene, W, H)
    z = np.array(ray.o.z + si.t * ray.d.z, np.float64)     # rays start on the near plane
    z[~np.array(si.is_valid())] = np.inf
    return z.reshape(H, W)


def _centre_hits(scene, W: int, H: int):
    """The sensor's rays through the W x H pixel centres (film positions (u + 0.5) / W,
    (v + 0.5) / H) and their first intersections: (ray, si), Dr.Jit arrays, to be
    read while ``scene`` is alive (they point into it)."""
    dr, mi = backend.modules()
    idx = dr.arange(mi.UInt32, W * H)
    pos = mi.Point2f((mi.Float(idx % W) + 0.5) / W, (mi.Float(idx // W) + 0.5) / H)
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    return ray, scene.ray_intersect(ray)


def totem_masks(desc: dict) -> np.ndarray:
    """(n, H, W) bool: pixels whose centre ray hits totem j first, left to right."""
    W, H = _check(desc)
    n = len(desc["totems"])
    if n == 0:
        return np.zeros((0, H, W), bool)
    sid = shape_ids(desc)
    masks = np.stack([sid == totem_id(j) for j in range(n)])
    cx = [np.nonzero(m)[1].mean() if m.any() else np.inf for m in masks]
    return masks[np.argsort(cx, kind="stable")]
