"""Building blocks of the presets beyond box and envmap (``scenes.synthetic.preset_*``).

Frames: a preset builds its world in *room coordinates* (metres; y down along gravity,
z forward horizontal, x right; the camera at the origin) and turns it into the camera
frame (OpenCV: +x right, +y down, +z forward) with the rig's rotation ``R`` (pitch down,
then roll about the optical axis). The camera itself never moves, as in
:mod:`scenes.synthetic.presets`.

Here: the rig (an off-centre ``K`` and ``R``), the key (radius and IoR per totem),
totem placement with obstacles, solids as description objects, materials drawn from a
bank of textures (``skimage.data`` images and :mod:`scenes.synthetic.textures`), and objects
scattered on a surface.
"""

from __future__ import annotations

from colorsys import hsv_to_rgb
from typing import NamedTuple

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.synthetic import textures
from scenes.synthetic.placement import check_placement, post_objects, posts_clear
from scenes.synthetic.preset_parts import (FORMAT, GREY_TEXTURES, MAX_DEPTH, affine,
                                           pitch_rotation, sphere_outline, yaw_rotation)

__all__ = ["Rig", "rig", "draw_key", "place_totems", "place_as", "to_camera", "cube", "ball",
           "cylinder", "solid", "bounds", "paint", "material", "scatter", "finish"]

RESTING_ROWS = (0.75, 0.95)
RESTING_DEPTH = (0.8, 4.5)
"""Image rows (fractions of the height) and camera depths (m) of totems resting on a
floor or the ground: wherever the support shows near the bottom of the frame."""

UP_CYL = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])   # cylinder axis z -> up (-y)


# --------------------------------------------------------------------------- camera

class Rig(NamedTuple):
    """A camera: intrinsics ``K`` (pixels), room-to-camera rotation ``R``, ``fov`` the
    horizontal field of view (degrees)."""
    K: np.ndarray
    R: np.ndarray
    fov: float


def rig(rng, size, *, fov=(55.0, 70.0), pitch=(8.0, 16.0), roll=3.0,
        offset=(0.01, 0.05)) -> Rig:
    """A camera of random field of view (degrees, horizontal), pitch (degrees down),
    roll (degrees, either way) and principal point off the image centre by a fraction
    ``offset`` of the width and of the height (either way, each axis): a calibrated
    camera's, not the ideal one. Drawn in fractions of the image, so the 3D scene is
    the same at every size."""
    W, H = size
    f = float(rng.uniform(*fov))
    K = camera.intrinsics(W, H, f)
    dx, dy = rng.uniform(*offset, 2) * rng.choice([-1.0, 1.0], 2)
    K[0, 2] += dx * W
    K[1, 2] += dy * H
    t = np.radians(rng.uniform(-roll, roll))
    c, s = np.cos(t), np.sin(t)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Rig(K, Rz @ pitch_rotation(rng.uniform(*pitch)), round(f, 4))


def to_camera(R, p) -> np.ndarray:
    """A room-coordinate point or direction in the camera frame."""
    return np.asarray(R) @ np.asarray(p, float)


# --------------------------------------------------------------------------- totems

def draw_key(rng, *, n=(3, 6), radius=(0.06, 0.12), ior=(1.45, 1.55),
             n_totems=None, fixed_radius=None, fixed_ior=None) -> list:
    """``[(radius m, ior), ...]``, one per totem: each drawn, unless fixed."""
    k = int(rng.integers(n[0], n[1] + 1)) if n_totems is None else int(n_totems)
    r = rng.uniform(*radius, k) if fixed_radius is None else np.full(k, fixed_radius)
    eta = rng.uniform(*ior, k) if fixed_ior is None else np.full(k, fixed_ior)
    return [(round(float(a), 4), round(float(b), 4)) for a, b in zip(r, eta)]


def _clear(P, radii, obstacles, planes, gap=0.03) -> bool:
    """Each sphere clear of the obstacle spheres and inside the half-spaces."""
    for p, r in zip(P, radii):
        if any(np.linalg.norm(p - c) < r + rc + gap for c, rc in obstacles):
            return False
        if any((p - p0) @ n < r + gap for p0, n in planes):
            return False
    return True


def _in_image(K, P, radii, size, margin_px) -> bool:
    """Each sphere's image inside the frame and the images pairwise disjoint."""
    W, H = size
    for p, r in zip(P, radii):
        uv = sphere_outline(K, p, r)
        if not (uv.min() > margin_px and uv[:, 0].max() < W - 1 - margin_px
                and uv[:, 1].max() < H - 1 - margin_px):
            return False
    d = P / np.linalg.norm(P, axis=1, keepdims=True)
    alpha = np.arcsin(radii / np.linalg.norm(P, axis=1))
    pad = margin_px / K[0, 0]
    for i in range(len(P)):
        for j in range(i + 1, len(P)):
            if np.arccos(np.clip(d[i] @ d[j], -1, 1)) <= alpha[i] + alpha[j] + pad:
                return False
    return True


def place_totems(rng, K, size, key, *, rows=(0.72, 0.86), depth=(1.1, 1.8),
                 rest_on=None, obstacles=(), planes=(), margin=0.01, tries=3000,
                 at_least=None, posts_on=None) -> list:
    """Totem centres (camera frame, m) in a row across the lower image, left to right.

    Each totem ``(radius, ior)`` of ``key`` sits at image row fraction ``rows`` and
    camera depth ``depth`` (m): floating there or, with ``rest_on`` = (point, unit
    normal) of a plane in the camera frame (the normal towards the camera), lying on
    it. Each stays ``margin * W`` pixels inside the frame, the images apart, clear of
    ``obstacles`` (centre, radius) spheres and inside ``planes`` (point, inward
    normal). With ``posts_on`` = a support (point, unit normal up) each totem also
    needs room for a post down to it (:func:`scenes.synthetic.placement.posts_clear`). When
    ``tries`` draws find no placement, the key's last totem is dropped while more than
    ``at_least`` remain (None: never); then BadInput.
    """
    kw = {"rows": rows, "depth": depth, "rest_on": rest_on, "obstacles": obstacles,
          "planes": planes, "margin": margin, "tries": tries, "posts_on": posts_on}
    while True:
        try:
            return _place(rng, K, size, key, **kw)
        except BadInput:
            if at_least is None or len(key) <= at_least:
                raise
            key = key[:-1]


def _place(rng, K, size, key, *, rows, depth, rest_on, obstacles, planes, margin,
           tries, posts_on) -> list:
    """One attempt of :func:`place_totems` with the whole key."""
    W, H = size
    n = len(key)
    radii = np.array([k[0] for k in key], float)
    for _ in range(tries):
        slots = (np.arange(n) + 0.5 + rng.uniform(-0.25, 0.25, n)) / n
        u = (0.06 + 0.88 * slots) * W - 0.5
        v = rng.uniform(*rows, n) * H - 0.5
        d = np.linalg.solve(K, np.stack([u, v, np.ones(n)])).T     # z = 1
        if rest_on is None:
            t = rng.uniform(*depth, n)
        else:
            p0, up = (np.asarray(a, float) for a in rest_on)
            with np.errstate(divide="ignore"):
                t = (radii + p0 @ up) / (d @ up)
        P = d * t[:, None]
        if not (np.all(t > 0) and np.all((P[:, 2] >= depth[0]) & (P[:, 2] <= depth[1]))):
            continue
        if _clear(P, radii, obstacles, planes) and \
                _in_image(K, P, radii, size, margin * W) and \
                (posts_on is None or posts_clear(P, radii, posts_on, obstacles)):
            order = np.argsort(P[:, 0] / P[:, 2])
            return [{"center": [round(float(c), 6) for c in P[i]],
                     "radius": float(key[i][0]), "ior": float(key[i][1])} for i in order]
    raise BadInput(f"cannot place {n} totems of radii {list(radii)} m side by side in a "
                   f"{W}x{H} image; use fewer totems or a smaller radius")


def place_as(placement, rng, K, size, key, *, support, rows, depth, obstacles=(),
             planes=(), at_least=None, resting_rows=RESTING_ROWS,
             resting_depth=RESTING_DEPTH, first_id=0) -> tuple[list, list]:
    """Totems placed ``placement``-wise (:mod:`scenes.synthetic.placement`) and the posts
    under them (objects numbered from ``first_id``; none unless ``stand``).

    ``rows``, ``depth``: the floating placement's (and the stands'); a resting totem
    lies on ``support`` (point, unit normal up; camera frame) at image rows
    ``resting_rows`` and camera depths ``resting_depth`` (m), clear of the ``planes``
    other than the support's own.
    """
    check_placement(placement)
    kw = {"obstacles": obstacles, "at_least": at_least}
    if placement == "resting":
        up = np.asarray(support[1], float)
        walls = [pl for pl in planes if np.asarray(pl[1], float) @ up < 0.99]
        return place_totems(rng, K, size, key, rows=resting_rows, depth=resting_depth,
                            rest_on=support, planes=walls, **kw), []
    stand = support if placement == "stand" else None
    totems = place_totems(rng, K, size, key, rows=rows, depth=depth, planes=planes,
                          posts_on=stand, **kw)
    return totems, post_objects(totems, support, first_id) if stand is not None else []


# --------------------------------------------------------------------------- solids

def cube(centre, size, yaw_deg=0.0) -> np.ndarray:
    """Room ``to_world`` of Mitsuba's cube [-1, 1]^3 as a w x h x d box (m) at centre."""
    return affine(yaw_rotation(yaw_deg) @ np.diag(np.asarray(size, float) / 2), centre)


def resting_box(rng, name: str, xz, base_y: float, size, yaw_max: float, bank):
    """A removable box ``name`` of ``size`` (w, h, d) m standing on the surface at room
    height ``base_y`` (y down) at ``xz``, turned by up to ``yaw_max`` degrees, textured
    from ``bank``: (its footprint's radius in metres, [its part])."""
    w, h, d = size
    local = cube((xz[0], base_y - h / 2, xz[1]), (w, h, d), rng.uniform(0, yaw_max))
    return 0.5 * np.hypot(w, d), [(name, "cube", local, material(rng, bank), True)]


def ball(centre, radius) -> np.ndarray:
    """Room ``to_world`` of the unit sphere as a ball of ``radius`` (m) at centre."""
    return affine(np.eye(3) * radius, centre)


def cylinder(base, radius, height, yaw_deg=0.0) -> np.ndarray:
    """Room ``to_world`` of Mitsuba's cylinder standing upright on ``base``."""
    return affine(yaw_rotation(yaw_deg) @ UP_CYL @ np.diag([radius, radius, height]), base)


def solid(objects: list, R, name, kind, local, mat, removable=False) -> dict:
    """Append an object (room ``local`` to_world taken to the camera frame by ``R``)
    with the next id and its own copy of ``mat``, and return it."""
    obj = {"id": len(objects), "name": f"{name}_{len(objects)}", "kind": kind,
           "to_world": (affine(R, [0, 0, 0]) @ local).tolist(), "material": dict(mat),
           "removable": bool(removable)}
    objects.append(obj)
    return obj


def bounds(obj: dict) -> tuple[np.ndarray, float]:
    """A sphere (centre, radius; camera frame, m) holding a solid (not rectangles)."""
    M = np.asarray(obj["to_world"], float)
    if obj["kind"] == "cylinder":
        c = M[:3, 3] + 0.5 * M[:3, 2]
        r, h = np.linalg.norm(M[:3, 0]), np.linalg.norm(M[:3, 2])
        return c, float(np.hypot(r, 0.5 * h))
    if obj["kind"] == "sphere":
        return M[:3, 3], float(np.linalg.norm(M[:3, 0]))
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    return M[:3, 3], float(np.linalg.norm(corners @ M[:3, :3].T, axis=1).max())


# --------------------------------------------------------------------------- materials

def paint(rng, saturation=(0.05, 0.35), value=(0.55, 0.9)) -> dict:
    """A plain diffuse colour (linear reflectance), by default a muted paint."""
    rgb = hsv_to_rgb(rng.uniform(), rng.uniform(*saturation), rng.uniform(*value))
    return {"type": "diffuse", "rgb": [round(float(c) ** 2.2, 4) for c in rgb]}


def material(rng, bank, uv=(1.0, 1.0)) -> dict:
    """A diffuse material textured by a name drawn from ``bank``: a ``skimage.data``
    name, or a procedural kind (``"wood"``, ...) given its own seed here. Grey
    textures are tinted with a random colour."""
    name = str(rng.choice(list(bank)))
    if name in textures.KINDS:
        name = f"{name}:{int(rng.integers(1000))}"
    grey = name in GREY_TEXTURES or name.split(":")[0] in textures.GREY_KINDS
    tint = paint(rng, (0.2, 0.6), (0.8, 1.0))["rgb"] if grey else [1.0, 1.0, 1.0]
    return {"type": "diffuse", "texture": name, "tint": tint,
            "uv_scale": [float(uv[0]), float(uv[1])]}


# --------------------------------------------------------------------------- scatter

def scatter(rng, objects: list, R, makers, *, floor_y, x_range, z_range, n,
            avoid=(), gap=0.05) -> list:
    """Objects from ``makers`` standing on the floor at height ``floor_y`` (room y).

    A maker ``f(rng, (x, z), floor_y) -> (footprint radius, [(name, kind, local,
    material, removable), ...])`` builds one object (perhaps several parts) around
    the floor point (x, z). Footprints stay apart from each other and from ``avoid``
    ((x, z, radius) circles). Returns the added objects.
    """
    placed, added = list(avoid), []
    count = int(rng.integers(n[0], n[1] + 1))
    for _ in range(40 * count):
        if count == 0:
            break
        maker = makers[int(rng.integers(len(makers)))]
        x, z = rng.uniform(*x_range), rng.uniform(*z_range)
        foot, parts = maker(rng, (x, z), floor_y)
        if any(np.hypot(x - px, z - pz) < foot + pf + gap for px, pz, pf in placed):
            continue
        placed.append((x, z, foot))
        added += [solid(objects, R, *p) for p in parts]
        count -= 1
    return added


def finish(preset, seed, size, rig_: Rig, objects, lights, envmap, totems,
           **extra) -> dict:
    """The description dict (format of :mod:`scenes.synthetic.render`); lights numbered
    after the objects."""
    for j, light in enumerate(lights):
        light["id"] = len(objects) + j
    W, H = size
    return {"format": FORMAT, "preset": preset, "seed": int(seed), "size": [W, H],
            "K": np.asarray(rig_.K).tolist(), "fov_x_deg": rig_.fov,
            "max_depth": MAX_DEPTH, "objects": objects, "lights": lights,
            "envmap": envmap, "totems": totems, **extra}
