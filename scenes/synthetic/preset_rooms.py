"""The ``window`` preset: a furnished room lit mainly through a window.

Differs from ``box`` in what the fit and the metrics meet: one-sided light from a
window (an area light filling an opening in a wall, its radiance a photograph: the view
out), dim corners and a lamp, walls mostly plain paint (little texture for stereo
to hold on to), furniture (tables with things on them, cabinets, shelves with books,
armchairs, plants, a rug, pictures on the walls) that occludes the floor, a room yawed
against the camera, a wider lens, and 3-6 totems of 6-12 cm radius and IoR 1.45-1.55
each. Room coordinates as in :mod:`scenes.synthetic.preset_kit`, aligned with the room's
walls.
"""

from __future__ import annotations

import numpy as np

from scenes.synthetic import preset_kit as kit
from scenes.synthetic.placement import support_json
from scenes.synthetic.preset_parts import PHOTO_TEXTURES, affine, panel, yaw_rotation

__all__ = ["FLOORS", "WALLPAPER", "VIEWS", "ALBEDO", "describe"]

FLOORS = ("wood", "checkerboard", "gravel", "marble", "noise")
WALLPAPER = ("brick", "blobs", "noise", "text", "wood")
VIEWS = ("astronaut", "coffee", "chelsea", "rocket", "immunohistochemistry")
THINGS = PHOTO_TEXTURES + ("wood", "marble", "blobs")
# Surfaces reflect this much of what the kit's materials do: a closed room lit by
# bounces is otherwise so noisy at 64 spp that two sampler seeds differ visibly over
# 40-60 % of the image (4-16 % so, as envmap and outdoor), and a re-rendering edit
# re-draws the noise of every path that meets the edited object.
ALBEDO = 0.6


# --------------------------------------------------------------------------- furniture

def _table(rng, xz, floor_y):
    """A table (top and four legs) with one to three things on it (removable)."""
    w, d, h = rng.uniform(0.9, 1.5), rng.uniform(0.6, 0.9), rng.uniform(0.7, 0.78)
    yaw = rng.uniform(-20, 20)
    x, z = xz
    wood = kit.material(rng, ("wood", "marble", "wood"))
    parts = [("table", "cube", kit.cube((x, floor_y - h + 0.02, z), (w, 0.04, d), yaw),
              wood, False)]
    Y = yaw_rotation(yaw)
    for sx in (-1, 1):
        for sz in (-1, 1):
            leg = Y @ [sx * (w / 2 - 0.05), 0, sz * (d / 2 - 0.05)]
            parts.append(("leg", "cylinder", kit.cylinder(
                (x + leg[0], floor_y, z + leg[2]), 0.025, h - 0.04), wood, False))
    top = floor_y - h
    for _ in range(int(rng.integers(1, 4))):
        p = Y @ [rng.uniform(-0.35, 0.35) * w, 0, rng.uniform(-0.3, 0.3) * d]
        parts.append(_small_thing(rng, (x + p[0], z + p[2]), top))
    return 0.5 * np.hypot(w, d), parts


def _small_thing(rng, xz, top_y):
    """A vase, ball or book standing at height ``top_y`` (room y): removable."""
    x, z = xz
    kind = int(rng.integers(3))
    if kind == 0:
        r, h = rng.uniform(0.04, 0.08), rng.uniform(0.12, 0.3)
        return ("vase", "cylinder", kit.cylinder((x, top_y, z), r, h),
                kit.paint(rng, (0.4, 0.9), (0.4, 0.9)), True)
    if kind == 1:
        r = rng.uniform(0.05, 0.1)
        return ("ball", "sphere", kit.ball((x, top_y - r, z), r),
                kit.paint(rng, (0.5, 0.9), (0.5, 0.9)), True)
    w, h, d = rng.uniform(0.15, 0.3), rng.uniform(0.03, 0.08), rng.uniform(0.2, 0.3)
    local = kit.cube((x, top_y - h / 2, z), (w, h, d), rng.uniform(0, 90))
    return ("book", "cube", local, kit.material(rng, THINGS), True)


def _cabinet(rng, xz, floor_y):
    w, h, d = rng.uniform(0.6, 1.4), rng.uniform(0.5, 0.95), rng.uniform(0.4, 0.55)
    yaw = float(rng.choice([0.0, 90.0])) + rng.uniform(-5, 5)
    body = kit.cube((xz[0], floor_y - h / 2, xz[1]), (w, h, d), yaw)
    mat = kit.paint(rng) if rng.uniform() < 0.5 else kit.material(rng, ("wood",))
    return 0.5 * np.hypot(w, d), [("cabinet", "cube", body, mat, False),
                                  _small_thing(rng, xz, floor_y - h)]


def _armchair(rng, xz, floor_y):
    w, yaw = rng.uniform(0.7, 0.95), rng.uniform(0, 360)
    Y = yaw_rotation(yaw)
    fabric = kit.material(rng, ("noise", "blobs", "checkerboard"))
    back = Y @ [0, 0, 0.35 * w]
    return 0.7 * w, [
        ("seat", "cube", kit.cube((xz[0], floor_y - 0.22, xz[1]), (w, 0.44, w), yaw),
         fabric, False),
        ("back", "cube", kit.cube((xz[0] + back[0], floor_y - 0.6, xz[1] + back[2]),
                                  (w, 0.5, 0.2 * w), yaw), fabric, False)]


def _plant(rng, xz, floor_y):
    r, h = rng.uniform(0.12, 0.2), rng.uniform(0.25, 0.45)
    leaves = rng.uniform(0.25, 0.45)
    return leaves, [
        ("pot", "cylinder", kit.cylinder((xz[0], floor_y, xz[1]), r, h),
         kit.paint(rng, (0.3, 0.7), (0.3, 0.7)), False),
        ("leaves", "sphere", kit.ball((xz[0], floor_y - h - 0.8 * leaves, xz[1]), leaves),
         kit.material(rng, ("grass", "noise", "blobs")), False)]


def _floor_thing(rng, xz, floor_y):
    """A box, ball or stool on the floor: removable."""
    x, z = xz
    kind = int(rng.integers(3))
    if kind == 0:
        return kit.resting_box(rng, "box", xz, floor_y, rng.uniform(0.2, 0.5, 3), 360,
                               THINGS)
    if kind == 1:
        r = rng.uniform(0.1, 0.25)
        return r, [("ball", "sphere", kit.ball((x, floor_y - r, z), r),
                    kit.paint(rng, (0.5, 0.9), (0.5, 0.9)), True)]
    r, h = rng.uniform(0.15, 0.22), rng.uniform(0.4, 0.5)
    return r, [("stool", "cylinder", kit.cylinder((x, floor_y, z), r, h),
                kit.material(rng, ("wood", "marble")), True)]


# --------------------------------------------------------------------------- room

def _walls(rng, room):
    """(name, centre, inward normal, texture-down, width, height) of the room's six
    surfaces, room coordinates; the window's wall is left out (:func:`_window`)."""
    a, b, back, front, floor, ceil = room
    cy, cz = 0.5 * (floor + ceil), 0.5 * (back + front)
    wh, depth = floor - ceil, back - front
    up, fwd = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    return {"floor": ([0.5 * (b - a), floor, cz], up, -fwd, a + b, depth),
            "ceiling": ([0.5 * (b - a), ceil, cz], -up, -fwd, a + b, depth),
            "back": ([0.5 * (b - a), cy, back], -fwd, -up, a + b, wh),
            "left": ([-a, cy, cz], [1, 0, 0], -up, depth, wh),
            "right": ([b, cy, cz], [-1, 0, 0], -up, depth, wh),
            "front": ([0.5 * (b - a), cy, front], fwd, -up, a + b, wh)}


def _window(rng, spec, floor):
    """The window's wall as four panels around an opening, and the opening, each as
    (centre, inward normal, down, width, height) in room coordinates."""
    c, n, down = (np.asarray(v, float) for v in spec[:3])
    W, H = spec[3], spec[4]
    right = np.cross(down, -n)
    ww, wh, sill = rng.uniform(1.2, 2.0), rng.uniform(1.2, 1.6), rng.uniform(0.7, 0.9)
    s = rng.uniform(-0.5, 0.5) * (W - ww - 0.4)         # opening centre along the wall
    x0, x1 = s - ww / 2, s + ww / 2
    top, bottom = floor - sill - wh, floor - sill     # room y of the opening's edges
    wall_top, wall_bottom = c[1] - H / 2, c[1] + H / 2
    pieces = [((x0 - W / 2) / 2, c[1], x0 + W / 2, H),               # left of it
              ((x1 + W / 2) / 2, c[1], W / 2 - x1, H),               # right of it
              (s, (wall_top + top) / 2, ww, top - wall_top),          # above it
              (s, (bottom + wall_bottom) / 2, ww, wall_bottom - bottom)]   # below it

    def at(along, y):
        return c + right * along + np.array([0.0, y - c[1], 0.0])

    panels = [(at(a, y), n, down, w, h) for a, y, w, h in pieces]
    return panels, (at(s, floor - sill - wh / 2), n, down, ww, wh)


def _shelf(rng, objects, R, room) -> tuple:
    """A bookshelf against the back wall, books on its boards; its footprint
    (x, z, radius), room coordinates."""
    a, b, back, _, floor, _ = room
    w, h, d = rng.uniform(0.8, 1.2), rng.uniform(1.4, 2.0), 0.32
    x, z = rng.uniform(-a + w / 2 + 0.1, b - w / 2 - 0.1), back - d / 2 - 0.01
    body = kit.material(rng, ("wood",))
    kit.solid(objects, R, "shelf", "cube", kit.cube((x, floor - h / 2, z), (w, h, d)),
              body)
    boards = int(rng.integers(2, 4))
    for k in range(boards):
        top = floor - h * (k + 1) / (boards + 1)          # room y of a board's top
        at = x - w / 2 + 0.03
        while at < x + w / 2 - 0.06:
            bw, bh = rng.uniform(0.025, 0.06), rng.uniform(0.16, 0.26)
            kit.solid(objects, R, "book", "cube",
                      kit.cube((at + bw / 2, top - bh / 2, z - d / 2 - 0.09),
                               (bw, bh, 0.18)),
                      kit.paint(rng, (0.3, 0.9), (0.3, 0.9)))
            at += bw + 0.004
    return x, z - 0.1, 0.5 * w + 0.1


def _pictures(rng, objects, R, surfaces, window_side, floor):
    """One to three framed photos on the walls without the window, 1.3-1.9 m up."""
    walls = [w for w in ("back", "left", "right") if w != window_side]
    for _ in range(int(rng.integers(1, 4))):
        wall = surfaces[str(rng.choice(walls))]
        c, n, down, W, _ = (np.asarray(v, float) for v in wall)
        w, h = rng.uniform(0.4, 0.9), rng.uniform(0.3, 0.7)
        right = np.cross(down, -n)
        centre = c + right * rng.uniform(-0.35, 0.35) * (W - w) + 0.01 * n
        centre[1] = floor - rng.uniform(1.3, 1.9)
        kit.solid(objects, R, "picture", "rectangle", panel(centre, n, down, w, h),
                  kit.material(rng, PHOTO_TEXTURES))


def _rug(rng, objects, R, room):
    """A rug just above the floor, somewhere in its middle."""
    a, b, back, _, floor, _ = room
    w, d = rng.uniform(1.2, 2.2), rng.uniform(0.9, 1.6)
    centre = [rng.uniform(-0.3 * a, 0.3 * b), floor - 0.003, rng.uniform(2.2, back - 1.2)]
    kit.solid(objects, R, "rug", "rectangle",
              panel(centre, [0, -1, 0], [0, 0, -1], w, d),
              kit.material(rng, ("blobs", "noise", "checkerboard", "gravel")))


def _shell(rng, objects, R, room):
    """Floor, ceiling and walls (the window's wall with an opening), pictures, a rug;
    returns the opening (room coordinates) and the inward planes (camera frame)."""
    surfaces = _walls(rng, room)
    side = str(rng.choice(["left", "right", "back"]))
    floor_mat = kit.material(rng, FLOORS, (3.0, 3.0))
    accent = str(rng.choice(["left", "right", "back", "none"]))
    planes = []
    for name, spec in surfaces.items():
        c, n = np.asarray(spec[0], float), np.asarray(spec[1], float)
        planes.append((kit.to_camera(R, c), kit.to_camera(R, n)))
        mat = floor_mat if name == "floor" else kit.paint(rng, value=(0.75, 0.95)) \
            if name == "ceiling" else kit.material(rng, WALLPAPER, (2.0, 1.0)) \
            if name == accent else kit.paint(rng)
        panels, opening = ([spec], None) if name != side else _window(rng, spec, room[4])
        for p in panels:
            kit.solid(objects, R, name, "rectangle", panel(*p), mat)
            if name == "floor":
                objects[-1]["name"] = "floor"
        if name == side:
            window = opening
    _pictures(rng, objects, R, surfaces, side, room[4])
    if rng.uniform() < 0.6:
        _rug(rng, objects, R, room)
    return window, planes


def _lights(rng, R, window, room) -> list:
    """The window (an area light its size, just outside, facing in, showing a photo)
    and a lamp under the ceiling (a fifth to a third of the window's power)."""
    oc, n, down, ww, wh = window
    L = rng.uniform(25.0, 45.0)
    sky = kit.paint(rng, (0.0, 0.2), (0.9, 1.0))["rgb"]
    win = {"name": "window", "kind": "rectangle",
           "to_world": (affine(R, [0, 0, 0]) @ panel(oc - 0.02 * n, n, down, ww, wh)
                        ).tolist(),
           "radiance": [round(L * c, 4) for c in sky], "texture": str(rng.choice(VIEWS))}
    a, b, back, ceil = room[0], room[1], room[2], room[5]
    x, z, s = rng.uniform(-0.5 * a, 0.5 * b), rng.uniform(1.5, back - 1.0), 0.5
    lamp = {"name": "lamp", "kind": "rectangle",
            "to_world": (affine(R, [0, 0, 0]) @ panel(
                [x, ceil + 0.01, z], [0, 1, 0], [0, 0, -1], s, s)).tolist(),
            "radiance": [round(rng.uniform(16.0, 32.0), 4)] * 3}
    return [win, lamp]


def describe(seed: int, size, preset_index: int, *, n_totems=None, radius=None,
             ior=None, placement="floating") -> dict:
    """A random ``window`` scene (format of :mod:`scenes.synthetic.render`); ``n_totems``,
    ``radius`` (m) and ``ior``, when given, replace the drawn key; ``placement``:
    :mod:`scenes.synthetic.placement` (resting and stands on the floor)."""
    rng = np.random.default_rng([int(seed), preset_index])
    rig = kit.rig(rng, size, fov=(62.0, 75.0), pitch=(15.0, 24.0), roll=2.0)
    R = rig.R @ yaw_rotation(rng.uniform(-20.0, 20.0))      # the room yawed against the camera
    height = rng.uniform(1.2, 1.6)
    room = (rng.uniform(1.5, 2.3), rng.uniform(1.5, 2.3), rng.uniform(4.0, 5.5),
            -rng.uniform(0.8, 1.5), height, height - rng.uniform(2.4, 2.8))
    a, b, back = room[:3]
    objects: list = []
    window, planes = _shell(rng, objects, R, room)
    shelf = [_shelf(rng, objects, R, room)] if rng.uniform() < 0.5 else []
    furniture = kit.scatter(rng, objects, R, [_table, _cabinet, _armchair, _plant],
                            floor_y=height, x_range=(-a + 0.6, b - 0.6),
                            z_range=(2.4, back - 0.5), n=(2, 4), avoid=shelf)
    kit.scatter(rng, objects, R, [_floor_thing], floor_y=height,
                x_range=(-a + 0.3, b - 0.3), z_range=(2.2, back - 0.3), n=(2, 4),
                avoid=shelf + [(*_xz(R, o), kit.bounds(o)[1]) for o in furniture])
    for o in objects:
        _dim(o["material"])
    lights = _lights(rng, R, window, room)
    key = kit.draw_key(np.random.default_rng([int(seed), preset_index, 7]),
                       n_totems=n_totems, fixed_radius=radius, fixed_ior=ior)
    floor = (kit.to_camera(R, [0, height, 0]), kit.to_camera(R, [0, -1, 0]))
    totems, posts = kit.place_as(
        placement, np.random.default_rng([int(seed), preset_index, 8]), rig.K, size, key,
        support=floor, rows=(0.7, 0.86), depth=(1.1, 1.9), planes=planes,
        obstacles=[kit.bounds(o) for o in objects if o["kind"] != "rectangle"],
        first_id=len(objects), at_least=None if n_totems else 3)
    objects += posts
    return kit.finish("window", seed, size, rig, objects, lights, None, totems,
                      support=support_json(floor))


def _dim(mat: dict) -> None:
    """Scale a material's reflectance (its colour, or its texture's tint) by ALBEDO."""
    key = "rgb" if "rgb" in mat else "tint"
    mat[key] = [round(c * ALBEDO, 4) for c in mat[key]]


def _xz(R, obj) -> tuple[float, float]:
    """Room (x, z) of a solid's bounding centre."""
    c = np.asarray(R).T @ kit.bounds(obj)[0]
    return float(c[0]), float(c[2])
