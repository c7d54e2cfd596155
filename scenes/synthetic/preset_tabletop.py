"""The ``tabletop`` preset: a table close up, small things on it, totems lying on it.

Differs from ``box`` and ``envmap`` in what the fit and the metrics meet: everything
is near (the totems 0.5-1.0 m from the camera, things 0.85-1.6 m, a wall behind),
the camera looks steeply down (25-38 degrees) from 0.4-0.6 m above the table, the
totems (3-4, radius 6-8 cm, IoR 1.45-1.55 each; 3 where 4 do not fit) lie on the
table instead of floating, so the surface under them touches the glass (and the
light they focus shows there), and a softbox above lights the table with the room's
photograph around (a tiled envmap). Re-rendering edits add things
scaled to the table (``object_scale``). Room coordinates as in
:mod:`scenes.synthetic.preset_kit`.
"""

from __future__ import annotations

import numpy as np

from scenes.synthetic import preset_kit as kit
from scenes.synthetic.placement import support_json
from scenes.synthetic.preset_parts import (ENV_PHOTOS, PHOTO_TEXTURES, affine, panel,
                                           yaw_rotation)

__all__ = ["TOPS", "OBJECT_SCALE", "describe"]

TOPS = ("wood", "marble", "checkerboard", "page", "noise", "wood")
WALLS = ("brick", "blobs", "noise", "astronaut", "coffee", "chelsea", "wood")
THINGS = PHOTO_TEXTURES + ("wood", "marble", "blobs", "checkerboard")
OBJECT_SCALE = 0.3


# --------------------------------------------------------------------------- things

def _mug(rng, xz, top_y):
    r, h = rng.uniform(0.035, 0.05), rng.uniform(0.08, 0.12)
    return r, [("mug", "cylinder", kit.cylinder((xz[0], top_y, xz[1]), r, h),
                kit.paint(rng, (0.3, 0.9), (0.4, 0.95)), True)]


def _bottle(rng, xz, top_y):
    r, h = rng.uniform(0.025, 0.04), rng.uniform(0.18, 0.28)
    return r, [("bottle", "cylinder", kit.cylinder((xz[0], top_y, xz[1]), r, h),
                kit.material(rng, THINGS), True)]


def _book(rng, xz, top_y):
    size = rng.uniform(0.13, 0.22), rng.uniform(0.015, 0.05), rng.uniform(0.18, 0.28)
    return kit.resting_box(rng, "book", xz, top_y, size, 180, THINGS)


def _block(rng, xz, top_y):
    return kit.resting_box(rng, "block", xz, top_y, rng.uniform(0.04, 0.1, 3), 180, THINGS)


def _fruit(rng, xz, top_y):
    r = rng.uniform(0.03, 0.06)
    return r, [("fruit", "sphere", kit.ball((xz[0], top_y - r, xz[1]), r),
                kit.paint(rng, (0.5, 0.95), (0.5, 0.95)), True)]


# --------------------------------------------------------------------------- set

def _table(rng, objects, R, top_y, far):
    """The table top (a rectangle named "table", id 0, where edits stand new things)
    and its edge, the floor 0.75 m below and a wall behind."""
    width, near = rng.uniform(1.6, 2.4), -0.4
    depth = far - near
    cz = 0.5 * (far + near)
    up, fwd = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    top = kit.material(rng, TOPS, (width / 0.8, depth / 0.8))
    kit.solid(objects, R, "table", "rectangle", panel([0, top_y, cz], up, -fwd, width,
                                                      depth), top)
    objects[-1]["name"] = "table"
    kit.solid(objects, R, "table_edge", "cube",
              kit.cube((0, top_y + 0.0205, cz), (width, 0.04, depth)), top)
    floor_y, wall_z = top_y + 0.75, far + rng.uniform(0.4, 1.2)
    kit.solid(objects, R, "floor", "rectangle",
              panel([0, floor_y, wall_z / 2], up, -fwd, 8.0, wall_z + 4.0),
              kit.material(rng, ("wood", "gravel", "checkerboard"), (4.0, 4.0)))
    objects[-1]["name"] = "room_floor"
    kit.solid(objects, R, "wall", "rectangle",
              panel([0, floor_y - 1.5, wall_z], -fwd, -up, 8.0, 3.0),
              kit.material(rng, WALLS, (2.0, 1.0)))


def _light(rng, R, top_y) -> dict:
    """A softbox 0.9-1.3 m above the table, facing down."""
    s = rng.uniform(0.5, 0.9)
    L = rng.uniform(6.0, 10.0) / (s * s)
    warm = rng.uniform(0.85, 1.0)
    centre = [rng.uniform(-0.6, 0.6), top_y - rng.uniform(0.9, 1.3),
              rng.uniform(0.0, 1.0)]
    return {"name": "softbox", "kind": "rectangle",
            "to_world": (affine(R, [0, 0, 0])
                         @ panel(centre, [0, 1, 0], [0, 0, -1], s, s)).tolist(),
            "radiance": [round(L, 4), round(L * warm, 4), round(L * warm ** 2, 4)]}


def describe(seed: int, size, preset_index: int, *, n_totems=None, radius=None,
             ior=None, placement="resting") -> dict:
    """A random ``tabletop`` scene (format of :mod:`scenes.synthetic.render`); ``n_totems``,
    ``radius`` (m) and ``ior``, when given, replace the drawn key; ``placement``:
    :mod:`scenes.synthetic.placement` (resting on the table top by default)."""
    rng = np.random.default_rng([int(seed), preset_index])
    rig = kit.rig(rng, size, fov=(50.0, 65.0), pitch=(25.0, 38.0), roll=3.0)
    R = rig.R @ yaw_rotation(rng.uniform(-15.0, 15.0))
    top_y = rng.uniform(0.4, 0.6)
    objects: list = []
    _table(rng, objects, R, top_y, far=rng.uniform(1.6, 2.0))
    things = kit.scatter(rng, objects, R, [_mug, _bottle, _book, _block, _fruit],
                         floor_y=top_y, x_range=(-0.6, 0.6), z_range=(0.85, 1.6),
                         n=(4, 8), gap=0.02)
    env = {"image": str(rng.choice(ENV_PHOTOS)),
           "scale": round(float(rng.uniform(0.4, 0.8)), 3),
           "to_world": affine(R @ yaw_rotation(rng.uniform(0, 360)) @ np.diag([-1.0, -1.0, 1.0]),
                               [0, 0, 0]).tolist()}
    key = kit.draw_key(np.random.default_rng([int(seed), preset_index, 7]), n=(3, 4),
                       radius=(0.06, 0.08), n_totems=n_totems, fixed_radius=radius,
                       fixed_ior=ior)
    top = (kit.to_camera(R, [0, top_y, 0]), kit.to_camera(R, [0, -1, 0]))
    totems, posts = kit.place_as(
        placement, np.random.default_rng([int(seed), preset_index, 8]), rig.K, size, key,
        support=top, rows=(0.4, 0.75), depth=(0.5, 1.0), resting_rows=(0.45, 0.9),
        resting_depth=(0.5, 1.0), obstacles=[kit.bounds(o) for o in things],
        planes=[top], at_least=None if n_totems else 3, first_id=len(objects))
    objects += posts
    return kit.finish("tabletop", seed, size, rig, objects, [_light(rng, R, top_y)], env,
                      totems, object_scale=OBJECT_SCALE, support=support_json(top))
