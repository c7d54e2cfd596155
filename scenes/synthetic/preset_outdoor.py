"""The ``outdoor`` preset: a sunlit place with natural ground and distant scenery.

Differs from ``envmap`` in what the fit and the metrics meet: a low sun casting hard shadows
beside a bright, smooth sky (the glass reflects mostly sky), distant scenery in a thin band
at the horizon (a photograph, :func:`scenes.synthetic.textures.horizon_panorama`), things
from 2.5 m to 16 m away (trees, boulders, posts, crates, balls) on a natural ground (grass,
gravel, regolith, procedural soil) that runs out to 100 m, a taller camera (1.3-1.7 m)
looking nearly level, and 3-6 totems of 6-12 cm radius and IoR 1.45-1.55 each. Room
coordinates as in :mod:`scenes.synthetic.preset_kit`.
"""

from __future__ import annotations

import numpy as np

from scenes.synthetic import preset_kit as kit
from scenes.synthetic.placement import support_json
from scenes.synthetic.preset_parts import PHOTO_TEXTURES, affine, panel, yaw_rotation

__all__ = ["GROUND", "SCENERY", "describe"]

GROUND = ("grass", "gravel", "moon", "noise")
SCENERY = ("astronaut", "coffee", "chelsea", "rocket", "immunohistochemistry")
STONE = ("gravel", "moon", "noise", "brick")
FOLIAGE = ("grass", "noise", "blobs")
THINGS = PHOTO_TEXTURES + ("wood", "marble", "checkerboard", "blobs")


# --------------------------------------------------------------------------- things

def _boulder(rng, xz, floor_y):
    w, h, d = rng.uniform(0.3, 1.0, 3) * [1.0, 0.7, 1.0]
    centre = (xz[0], floor_y - 0.35 * h, xz[1])          # a third sunk in the ground
    local = kit.cube(centre, (w, h, d), rng.uniform(0, 360))
    return 0.5 * np.hypot(w, d), [("boulder", "cube", local, kit.material(rng, STONE),
                                   True)]


def _tree(rng, xz, floor_y):
    r, h = rng.uniform(0.07, 0.18), rng.uniform(1.4, 2.8)
    crown = rng.uniform(0.6, 1.3)
    trunk = kit.cylinder((xz[0], floor_y, xz[1]), r, h + 0.3 * crown)
    top = kit.ball((xz[0], floor_y - h - 0.6 * crown, xz[1]), crown)
    bark = kit.paint(rng, (0.3, 0.6), (0.2, 0.45))
    return crown, [("trunk", "cylinder", trunk, bark, False),
                   ("crown", "sphere", top, kit.material(rng, FOLIAGE), False)]


def _post(rng, xz, floor_y):
    r, h = rng.uniform(0.04, 0.09), rng.uniform(0.9, 1.6)
    local = kit.cylinder((xz[0], floor_y, xz[1]), r, h)
    return r, [("post", "cylinder", local, kit.paint(rng, (0.3, 0.9), (0.3, 0.9)), True)]


def _crate(rng, xz, floor_y):
    return kit.resting_box(rng, "crate", xz, floor_y, rng.uniform(0.35, 0.8, 3), 360, THINGS)


def _ball(rng, xz, floor_y):
    r = rng.uniform(0.15, 0.4)
    local = kit.ball((xz[0], floor_y - r, xz[1]), r)
    mat = kit.paint(rng, (0.5, 0.9), (0.5, 0.95)) if rng.uniform() < 0.5 else \
        kit.material(rng, THINGS)
    return r, [("ball", "sphere", local, mat, True)]


# --------------------------------------------------------------------------- place

def _ground(rng, objects, R, height):
    """The ground (id 0): a 200 m square, one texture copy every 1.5-3 m."""
    size, tile = 200.0, rng.uniform(1.5, 3.0)
    local = panel([0, height, 0], [0, -1, 0], [0, 0, -1], size, size)
    mat = kit.material(rng, GROUND, (size / tile, size / tile))
    kit.solid(objects, R, "ground", "rectangle", local, mat)
    objects[-1]["name"] = "ground"


def _sky(rng, R) -> tuple[dict, dict]:
    """The horizon envmap and the sun (a directional light), in the camera frame."""
    from colorsys import hsv_to_rgb

    hue = rng.uniform(0.55, 0.63)
    zenith = hsv_to_rgb(hue, rng.uniform(0.4, 0.7), rng.uniform(0.6, 0.9))
    horizon = hsv_to_rgb(hue, rng.uniform(0.05, 0.2), rng.uniform(0.85, 1.0))
    ground = hsv_to_rgb(rng.uniform(0.05, 0.15), rng.uniform(0.1, 0.4),
                        rng.uniform(0.2, 0.4))
    flip = np.diag([-1.0, -1.0, 1.0])          # Mitsuba's envmap: +y up; the room: -y
    env = {"image": str(rng.choice(SCENERY)), "layout": "horizon",
           "sky": [[round(float(c), 4) for c in zenith],
                   [round(float(c), 4) for c in horizon]],
           "ground": [round(float(c), 4) for c in ground],
           "scale": round(float(rng.uniform(0.8, 1.5)), 3),
           "to_world": affine(R @ yaw_rotation(rng.uniform(0, 360)) @ flip, [0, 0, 0]).tolist()}
    el, az = np.radians(rng.uniform(20, 60)), np.radians(rng.uniform(0, 360))
    to_sun = np.array([np.cos(el) * np.sin(az), -np.sin(el), np.cos(el) * np.cos(az)])
    E, warm = rng.uniform(3.0, 6.0), rng.uniform(0.85, 0.97)
    sun = {"name": "sun", "kind": "directional",
           "direction": [round(float(c), 6) for c in kit.to_camera(R, -to_sun)],
           "irradiance": [round(E, 4), round(E * warm, 4), round(E * warm ** 2, 4)]}
    return env, sun


def describe(seed: int, size, preset_index: int, *, n_totems=None, radius=None,
             ior=None, placement="floating") -> dict:
    """A random ``outdoor`` scene (format of :mod:`scenes.synthetic.render`); ``n_totems``,
    ``radius`` (m) and ``ior``, when given, replace the drawn key; ``placement``:
    :mod:`scenes.synthetic.placement` (resting and stands on the ground)."""
    rng = np.random.default_rng([int(seed), preset_index])
    rig = kit.rig(rng, size, fov=(50.0, 70.0), pitch=(6.0, 12.0), roll=3.0)
    height = rng.uniform(1.3, 1.7)
    objects: list = []
    _ground(rng, objects, rig.R, height)
    near = kit.scatter(rng, objects, rig.R, [_boulder, _post, _crate, _ball],
                       floor_y=height, x_range=(-2.5, 2.5), z_range=(2.5, 7.0), n=(3, 6))
    kit.scatter(rng, objects, rig.R, [_tree, _tree, _boulder], floor_y=height,
                x_range=(-9.0, 9.0), z_range=(8.0, 16.0), n=(2, 5))
    env, sun = _sky(rng, rig.R)
    key = kit.draw_key(np.random.default_rng([int(seed), preset_index, 7]),
                       n_totems=n_totems, fixed_radius=radius, fixed_ior=ior)
    ground = (kit.to_camera(rig.R, [0, height, 0]), kit.to_camera(rig.R, [0, -1, 0]))
    totems, posts = kit.place_as(
        placement, np.random.default_rng([int(seed), preset_index, 8]), rig.K, size, key,
        support=ground, rows=(0.7, 0.86), depth=(1.2, 2.2),
        obstacles=[kit.bounds(o) for o in near], planes=[ground], first_id=len(objects),
        at_least=None if n_totems else 3)
    objects += posts
    return kit.finish("outdoor", seed, size, rig, objects, [sun], env, totems,
                      support=support_json(ground))
