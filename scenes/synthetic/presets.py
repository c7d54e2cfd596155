"""Random synthetic scenes as plain descriptions (dicts), as in the paper's Sec. 5.1.

Five presets (``PRESETS``), all seen by an OpenCV camera at the origin whose frame is the
world frame (+x right, +y down, +z forward; metres). ``box`` and ``envmap``, the ones the
thresholds were first calibrated on, are drawn here; ``outdoor``
(:mod:`scenes.synthetic.preset_outdoor`), ``window`` (:mod:`scenes.synthetic.preset_rooms`)
and ``tabletop`` (:mod:`scenes.synthetic.preset_tabletop`) differ from them in lighting,
scale, camera (field of view, pitch, roll, an off-centre principal point) and key (radius
and IoR drawn per totem), and are built from :mod:`scenes.synthetic.preset_kit`; all share
:mod:`scenes.synthetic.preset_parts`.

``box``
    A closed room like a Cornell box: floor, ceiling and four walls papered with
    random textures (photographs and textures that scikit-image ships), random boxes,
    spheres and cylinders on the floor, one or two rectangular area lights under the
    ceiling.
``envmap``
    A textured ground plane with random objects on it, lit by and surrounded by an
    environment map made from a bundled photograph.
``outdoor``
    Natural ground, a sun and a sky with distant scenery, things 2.5-16 m away.
``window``
    A furnished room lit through a window (a textured area light in an opening).
``tabletop``
    A table close up (0.5-1.6 m), small things, totems of 6-8 cm lying on it.

Box and envmap carry ``n_totems`` glass spheres floating between the camera and the
scene, near the bottom of the frame, each wholly inside the image and apart from the
others in the image, about 1-2 m from the camera. The camera looks slightly down on the floor:
the room is pitched in the camera frame, the camera itself is never moved.

The description is JSON-serialisable and is the whole scene: ``render.render(desc)``
draws it again (the format is documented in :mod:`scenes.synthetic.render`). The 3D scene
does not depend on the image size: the same seed at 160x120 and 640x480 is the same room.
"""

from __future__ import annotations

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.synthetic import preset_kit, preset_outdoor, preset_rooms, preset_tabletop
from scenes.synthetic.placement import check_placement, support_json
from scenes.synthetic.preset_parts import (CAMERA_HEIGHT, ENV_PHOTOS, FLOOR_TEXTURES,
                                           FORMAT, FOV_X_DEG, GREY_TEXTURES, MAX_DEPTH,
                                           PHOTO_TEXTURES, PITCH_DEG, TOTEM_IOR,
                                           TOTEM_RADIUS, WALL_TEXTURES, affine, panel,
                                           pitch_rotation, sphere_outline, yaw_rotation)

__all__ = ["PRESETS", "FORMAT", "FOV_X_DEG", "PITCH_DEG", "CAMERA_HEIGHT", "MAX_DEPTH",
           "GREY_TEXTURES", "PHOTO_TEXTURES", "WALL_TEXTURES", "FLOOR_TEXTURES",
           "ENV_PHOTOS", "TOTEM_RADIUS", "TOTEM_IOR", "panel", "sphere_outline",
           "place_totems", "describe", "DEFAULT_PLACEMENT"]

PRESETS = ("box", "envmap", "outdoor", "window", "tabletop")   # the order seeds rngs
DEFAULT_PLACEMENT = {"tabletop": "resting"}
"""Each preset's placement of its totems when none is asked for; the rest float."""


# --------------------------------------------------------------------------- materials

def _random_rgb(rng, saturation=(0.4, 0.8), value=(0.35, 0.8)) -> list:
    """A random linear RGB reflectance from a random hue."""
    from colorsys import hsv_to_rgb
    rgb = hsv_to_rgb(rng.uniform(), rng.uniform(*saturation), rng.uniform(*value))
    return [round(float(c) ** 2.2, 4) for c in rgb]      # sRGB-ish -> linear


def _texture_material(rng, name: str, uv_scale=(1.0, 1.0)) -> dict:
    """A diffuse material textured by ``skimage.data.<name>``; grey ones are tinted."""
    tint = _random_rgb(rng, (0.25, 0.6), (0.85, 1.0)) if name in GREY_TEXTURES \
        else [1.0, 1.0, 1.0]
    return {"type": "diffuse", "texture": name, "tint": tint,
            "uv_scale": [float(uv_scale[0]), float(uv_scale[1])]}


def _object_material(rng, textured: bool) -> dict:
    if textured:
        name = str(rng.choice(PHOTO_TEXTURES + ("brick", "checkerboard", "coins")))
        return _texture_material(rng, name)
    return {"type": "diffuse", "rgb": _random_rgb(rng)}


# --------------------------------------------------------------------------- objects

def _floor_objects(rng, R: np.ndarray, floor_y: float, *, x_range, z_range, n_range,
                   first_id: int) -> list:
    """Random boxes, spheres and cylinders standing on the floor, footprints apart."""
    n = int(rng.integers(n_range[0], n_range[1] + 1))
    textured = rng.permutation(np.arange(n) < int(np.ceil(0.6 * n)))
    placed, objects = [], []
    for _ in range(200):
        if len(objects) == n:
            break
        kind = str(rng.choice(["cube", "sphere", "cylinder"]))
        if kind == "cube":
            w, h, d = rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.7), rng.uniform(0.2, 0.5)
            foot = 0.5 * np.hypot(w, d)
        elif kind == "sphere":
            rad = rng.uniform(0.12, 0.3)
            foot = rad
        else:
            rad, h = rng.uniform(0.08, 0.22), rng.uniform(0.25, 0.8)
            foot = rad
        x, z = rng.uniform(*x_range), rng.uniform(*z_range)
        if any(np.hypot(x - px, z - pz) < foot + pf + 0.05 for px, pz, pf in placed):
            continue
        placed.append((x, z, foot))
        yaw = yaw_rotation(rng.uniform(0.0, 360.0))
        if kind == "cube":          # Mitsuba cube: [-1, 1]^3
            local = affine(yaw @ np.diag([w / 2, h / 2, d / 2]), [x, floor_y - h / 2, z])
        elif kind == "sphere":      # unit sphere at the origin
            local = affine(yaw * rad, [x, floor_y - rad, z])
        else:                       # Mitsuba cylinder: radius 1 about z, z in [0, 1]
            up = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])   # z -> -y (up)
            local = affine(yaw @ up @ np.diag([rad, rad, h]), [x, floor_y, z])
        objects.append({
            "id": first_id + len(objects), "name": f"{kind}_{len(objects)}", "kind": kind,
            "to_world": (affine(R, [0, 0, 0]) @ local).tolist(),
            "material": _object_material(rng, bool(textured[len(objects)])),
            "removable": True})
    return objects


def _room(rng, R: np.ndarray) -> tuple[list, list]:
    """Walls, floor and ceiling (ids 0-5) and one or two ceiling lights."""
    half_w, ceil, front, back = 1.6, -1.5, -1.5, 5.0
    floor = CAMERA_HEIGHT
    depth, cz = back - front, 0.5 * (back + front)
    height, cy = floor - ceil, 0.5 * (floor + ceil)
    floor_tex = str(rng.choice(FLOOR_TEXTURES))
    walls = [t for t in WALL_TEXTURES if t != floor_tex]
    wall_tex = [str(t) for t in rng.choice(walls, size=5, replace=False)]
    up, fwd = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    # (name, centre, inward normal, texture-down direction, width, height)
    specs = [
        ("floor", [0, floor, cz], up, -fwd, 2 * half_w, depth),
        ("ceiling", [0, ceil, cz], -up, -fwd, 2 * half_w, depth),
        ("back_wall", [0, cy, back], -fwd, -up, 2 * half_w, height),
        ("left_wall", [-half_w, cy, cz], [1, 0, 0], -up, depth, height),
        ("right_wall", [half_w, cy, cz], [-1, 0, 0], -up, depth, height),
        ("front_wall", [0, cy, front], fwd, -up, 2 * half_w, height),
    ]
    textures = [floor_tex, wall_tex[0], wall_tex[1], wall_tex[2], wall_tex[3], wall_tex[4]]
    objects = []
    for i, ((name, c, n, d, w, h), tex) in enumerate(zip(specs, textures)):
        tile = 1.6                  # metres covered by one copy of a grey texture
        uv = (max(1, round(w / tile)), max(1, round(h / tile))) if tex in GREY_TEXTURES \
            else (1.0, 1.0)
        to_world = affine(R, [0, 0, 0]) @ panel(c, n, d, w, h)
        objects.append({"id": i, "name": name, "kind": "rectangle",
                        "to_world": to_world.tolist(),
                        "material": _texture_material(rng, tex, uv), "removable": False})
    n_lights = int(rng.integers(1, 3))
    lights = []
    for j in range(n_lights):
        x = 0.0 if n_lights == 1 else (-0.75 if j == 0 else 0.75)
        z = rng.uniform(1.8, 3.0)
        w, d = rng.uniform(0.9, 1.3), rng.uniform(0.8, 1.1)
        power = 20.0 / n_lights / (w * d)
        warm = rng.uniform(0.85, 1.0)
        to_world = affine(R, [0, 0, 0]) @ panel([x, ceil + 0.01, z], -up, -fwd, w, d)
        lights.append({"name": f"light_{j}", "kind": "rectangle",
                       "to_world": to_world.tolist(),
                       "radiance": [round(power, 4), round(power * warm, 4),
                                    round(power * warm ** 2, 4)]})
    return objects, lights


def _outdoor(rng, R: np.ndarray) -> tuple[list, dict]:
    """A large textured ground plane (id 0) and an environment map."""
    tex = str(rng.choice(FLOOR_TEXTURES))
    size = 16.0
    to_world = affine(R, [0, 0, 0]) @ panel([0, CAMERA_HEIGHT, 4.0], [0, -1, 0],
                                              [0, 0, -1], size, size)
    ground = {"id": 0, "name": "ground", "kind": "rectangle", "to_world": to_world.tolist(),
              "material": _texture_material(rng, tex, (8.0, 8.0)), "removable": False}
    # Mitsuba's envmap has +y up; the room's up is -y, pitched into the camera frame.
    flip = np.diag([-1.0, -1.0, 1.0])
    turn = yaw_rotation(rng.uniform(0.0, 360.0))
    env = {"image": str(rng.choice(ENV_PHOTOS)),
           "scale": round(float(rng.uniform(2.0, 3.0)), 3),
           "to_world": affine(R @ turn @ flip, [0, 0, 0]).tolist()}
    return [ground], env


# --------------------------------------------------------------------------- totems

def place_totems(rng, K: np.ndarray, size, n: int, radius: float, ior: float,
                 *, margin: float = 0.01) -> list:
    """``n`` sphere centres near the bottom of the frame, left to right.

    Each sphere's image lies inside the frame with ``margin * W`` pixels to spare and
    the images are disjoint (the angle between two centres exceeds the sum of the
    spheres' angular radii). Depths are 1.1-1.7 m. Positions are drawn in fractions
    of the image, so the 3D centres depend on the aspect ratio but not on the size.
    """
    W, H = size
    margin_px = margin * W
    if n < 1:
        return []
    for _ in range(2000):
        slots = (np.arange(n) + 0.5 + rng.uniform(-0.25, 0.25, n)) / n
        u = K[0, 2] + (0.06 + 0.88 * slots - 0.5) * W
        v = K[1, 2] + (rng.uniform(0.72, 0.84, n) - 0.5) * H
        z = rng.uniform(1.1, 1.7, n)
        P = np.linalg.solve(K, np.stack([u, v, np.ones(n)])).T * z[:, None]
        ok = True
        for p in P:
            uv = sphere_outline(K, p, radius)
            ok &= bool(uv.min() > margin_px and uv[:, 0].max() < W - 1 - margin_px
                       and uv[:, 1].max() < H - 1 - margin_px)
        d = P / np.linalg.norm(P, axis=1, keepdims=True)
        alpha = np.arcsin(radius / np.linalg.norm(P, axis=1))
        pad = margin_px / K[0, 0]
        for i in range(n):
            for j in range(i + 1, n):
                angle = np.arccos(np.clip(d[i] @ d[j], -1.0, 1.0))
                ok &= bool(angle > alpha[i] + alpha[j] + pad)
        if ok:
            P = P[np.argsort(P[:, 0] / P[:, 2])]
            return [{"center": [round(float(c), 6) for c in p], "radius": float(radius),
                     "ior": float(ior)} for p in P]
    raise BadInput(f"cannot fit {n} totems of radius {radius} m side by side in a "
                   f"{W}x{H} image; use fewer totems or a smaller radius")


# --------------------------------------------------------------------------- public

def _check_args(preset, size, n_totems, radius, ior) -> tuple[int, int]:
    """(W, H) of ``size``, after checking every argument of :func:`describe`."""
    if preset not in PRESETS:
        raise BadInput(f"unknown preset {preset!r}; use one of {', '.join(PRESETS)}")
    try:
        W, H = int(size[0]), int(size[1])
    except (TypeError, ValueError, IndexError):
        raise BadInput(f"size must be (width, height) in pixels, got {size!r}") from None
    if not (16 <= W <= 8192 and 16 <= H <= 8192):
        raise BadInput(f"size must be between 16 and 8192 pixels a side, got {W}x{H}")
    if n_totems is not None and not (0 <= int(n_totems) <= 8):
        raise BadInput(f"number of totems must be 0..8, got {n_totems}")
    if radius is not None and not (np.isfinite(radius) and 0.01 <= radius <= 0.3):
        raise BadInput(f"totem radius must be 0.01..0.3 m, got {radius}")
    if ior is not None and not (np.isfinite(ior) and 1.0 < ior < 4.0):
        raise BadInput(f"totem ior must lie in (1, 4), got {ior}")
    return W, H


def describe(preset: str, seed: int, size=(640, 480), n_totems: int | None = None,
             radius: float | None = None, ior: float | None = None,
             placement: str | None = None) -> dict:
    """A random scene of ``preset`` drawn from ``seed``, as a JSON-ready dict.

    Parameters
    ----------
    preset : one of ``PRESETS`` (module docstring).
    seed : the random seed; the same seed gives the same description.
    size : (W, H) in pixels; the 3D scene does not depend on it.
    n_totems : number of glass spheres (0 allowed: a scene without totems); None:
        the preset's (box, envmap: 4; the others 3-6 drawn per seed, tabletop 3-4).
    radius : totem radius in metres, all totems; None: the preset's (box, envmap:
        ``TOTEM_RADIUS``; the others 0.06-0.12 drawn per totem, tabletop 0.06-0.08).
    ior : totems' index of refraction; None: the preset's (box, envmap:
        ``TOTEM_IOR``; the others 1.45-1.55 drawn per totem).
    placement : how the totems stand, one of :data:`scenes.synthetic.placement.PLACEMENTS`;
        None: the preset's (``DEFAULT_PLACEMENT``: tabletop's rest on the table, the
        others' float). The description records it as ``placement``.

    Returns
    -------
    dict in the format documented in :mod:`scenes.synthetic.render`.
    """
    W, H = _check_args(preset, size, n_totems, radius, ior)
    placement = check_placement(DEFAULT_PLACEMENT.get(preset, "floating")
                                if placement is None else placement)
    if preset not in ("box", "envmap"):
        module = {"outdoor": preset_outdoor, "window": preset_rooms,
                  "tabletop": preset_tabletop}[preset]
        desc = module.describe(seed, (W, H), PRESETS.index(preset), n_totems=n_totems,
                               radius=radius, ior=ior, placement=placement)
        return {**desc, "placement": placement}
    n_totems = 4 if n_totems is None else n_totems
    radius = TOTEM_RADIUS if radius is None else radius
    ior = TOTEM_IOR if ior is None else ior
    rng = np.random.default_rng([int(seed), PRESETS.index(preset)])
    K = camera.intrinsics(W, H, FOV_X_DEG)
    R = pitch_rotation(PITCH_DEG)
    if preset == "box":
        objects, lights = _room(rng, R)
        env = None
        x_range, z_range = (-1.2, 1.2), (2.4, 4.4)
    else:
        objects, env = _outdoor(rng, R)
        lights = []
        x_range, z_range = (-1.5, 1.5), (2.4, 5.0)
    objects += _floor_objects(rng, R, CAMERA_HEIGHT, x_range=x_range, z_range=z_range,
                              n_range=(3, 6), first_id=len(objects))
    # The totems are drawn from their own stream so that their placement does not
    # change the room and vice versa.
    trng = np.random.default_rng([int(seed), PRESETS.index(preset), 7])
    floor = (R @ [0.0, CAMERA_HEIGHT, 0.0], R @ [0.0, -1.0, 0.0])
    if placement == "floating":
        totems = place_totems(trng, K, (W, H), int(n_totems), float(radius), float(ior))
    else:
        solids = [o for o in objects if o["kind"] != "rectangle"]
        totems, posts = preset_kit.place_as(
            placement, trng, K, (W, H), [(float(radius), float(ior))] * int(n_totems),
            support=floor, rows=(0.72, 0.84), depth=(1.1, 1.7), first_id=len(objects),
            obstacles=[preset_kit.bounds(o) for o in solids])
        objects += posts
    for j, light in enumerate(lights):
        light["id"] = len(objects) + j
    return {"format": FORMAT, "preset": preset, "seed": int(seed), "size": [W, H],
            "K": K.tolist(), "fov_x_deg": FOV_X_DEG, "max_depth": MAX_DEPTH,
            "objects": objects, "lights": lights, "envmap": env, "totems": totems,
            "placement": placement, "support": support_json(floor)}
