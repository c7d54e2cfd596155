"""Where the totems stand: floating, resting on a support plane, or on thin stands.

People rest totems on the floor, the ground or a table, or hold them up on a stand;
they do not float. Every preset can place its totems each way (``PLACEMENTS``):

``floating``
    in mid-air, as the presets first drew them (the default of every preset but
    ``tabletop``);
``resting``
    lying on the preset's support plane (the floor, the ground, the table top): each
    centre one radius above it;
``stand``
    floating where ``floating`` would put them, each on a thin upright post
    (``POST_RADIUS``) from the support plane to the sphere's lowest point.

Frames: the camera frame (OpenCV: +x right, +y down, +z forward; metres). A support
is ``(point, up)``: a point of the plane and its unit normal towards the camera side.
"""

from __future__ import annotations

import numpy as np

from scenes.errors import BadInput

__all__ = ["PLACEMENTS", "POST_RADIUS", "POST_COLOUR", "check_placement", "support_json",
           "post_height", "post_to_world", "posts_clear", "post_objects"]

PLACEMENTS = ("floating", "resting", "stand")

POST_RADIUS = 0.006
"""Radius of a stand's post in metres (a 12 mm rod)."""

POST_COLOUR = [0.05, 0.05, 0.055]
"""The posts' linear reflectance: a dark anodised rod."""


def check_placement(placement: str) -> str:
    """``placement`` if it is one of ``PLACEMENTS``, else BadInput."""
    if placement not in PLACEMENTS:
        raise BadInput(f"unknown placement {placement!r}; use one of "
                       f"{', '.join(PLACEMENTS)}")
    return placement


def support_json(support) -> dict:
    """The description's ``support``: ``{"point": [x, y, z], "normal": [x, y, z]}``
    (camera frame, m; the unit normal up), the plane the totems rest or stand on, or
    would (floating)."""
    p0, up = (np.asarray(a, float) for a in support)
    return {"point": [round(float(c), 9) for c in p0],
            "normal": [round(float(c), 9) for c in up / np.linalg.norm(up)]}


def post_height(center, radius: float, support) -> float:
    """Length (m) of the post from the support plane up to the sphere's lowest point."""
    p0, up = (np.asarray(a, float) for a in support)
    return float((np.asarray(center, float) - p0) @ up - radius)


def post_to_world(center, radius: float, support) -> np.ndarray:
    """4x4 camera-frame ``to_world`` of Mitsuba's cylinder (radius 1 about z, z in
    [0, 1]) as the post under a sphere: its foot on the support plane below the
    centre, its top touching the sphere's lowest point."""
    P = np.asarray(center, float)
    p0, up = (np.asarray(a, float) for a in support)
    foot = P - ((P - p0) @ up) * up
    a = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    M = np.eye(4)
    M[:3, :3] = np.stack([a * POST_RADIUS, b * POST_RADIUS,
                          up * post_height(P, radius, support)], axis=1)
    M[:3, 3] = foot
    return M


def _segment_distance(c, a, b) -> float:
    """Distance from point ``c`` to the segment from ``a`` to ``b``."""
    ab = b - a
    t = np.clip((c - a) @ ab / (ab @ ab), 0.0, 1.0)
    return float(np.linalg.norm(c - (a + t * ab)))


def posts_clear(P, radii, support, obstacles, *, gap: float = 0.02) -> bool:
    """Every sphere is above the support and its post keeps ``gap`` (m) from the
    ``obstacles`` (centre, radius) and from the other spheres."""
    p0, up = (np.asarray(a, float) for a in support)
    spheres = [(np.asarray(p, float), float(r)) for p, r in zip(P, radii)]
    for i, (p, r) in enumerate(spheres):
        h = (p - p0) @ up - r
        if h <= gap:
            return False
        top, foot = p - r * up, p - (h + r) * up
        others = list(obstacles) + [s for j, s in enumerate(spheres) if j != i]
        if any(_segment_distance(np.asarray(c, float), foot, top) < rc + POST_RADIUS + gap
               for c, rc in others):
            return False
    return True


def post_objects(totems: list, support, first_id: int) -> list:
    """The posts under ``totems`` (dicts with ``center``, ``radius``) as objects of
    the description (format of :mod:`scenes.synthetic.render`), numbered from ``first_id``;
    fixed parts of the scene (never removed by an edit)."""
    return [{"id": first_id + j, "name": f"stand_{first_id + j}", "kind": "cylinder",
             "to_world": post_to_world(t["center"], t["radius"], support).tolist(),
             "material": {"type": "diffuse", "rgb": list(POST_COLOUR)},
             "removable": False}
            for j, t in enumerate(totems)]
