"""Forgeries that need the scene's 3D description (``truth/scene.json``).

``remove`` / ``insert``: the perfect forger. The camera view is rendered again by
Mitsuba with an object left out (or a new one standing on the floor), with the same
sampler seed and samples per pixel as the original, and composited into the source
where the change is visible; the totem pixels stay those of the original scene. No
blending trace is left: only the geometry seen through the totems disagrees. What is
changed is planned first (:func:`plan_remove`, :func:`plan_insert`: a :class:`Plan`),
then rendered (:func:`rerender`) and composited (:func:`composite_view`), so that the
forger who re-renders the totems too (:mod:`scenes.tamper.rekey`) makes the same edit.

``shift``: the paper's reference shift. An object (with its shadow) is moved in the
camera view and, by 2D edits, in every totem view, to where the same new position
appears there, as a careful forger would do with an editor's move tool. Each view is
edited by translation only, which is where the geometry gives it away.

Renders are sRGB quantised to 8 bits exactly as ``folder.write_image`` does, so a
render that matches the source reproduces its pixel values.

The editors are called by :func:`scenes.tamper.tamper.tamper`; this module imports only what
they share (:mod:`scenes.tamper.edits`) and the pixel tools (:mod:`scenes.tamper.edits2d`),
never :mod:`scenes.tamper.tamper`. Mitsuba (:mod:`scenes.synthetic.render`) is imported
inside the functions.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from scenes import masks
from scenes.errors import BadInput
from scenes.tamper import edits2d
from scenes.tamper.edits import Edit, Source, pick_object, target_zone

__all__ = ["STRONG_DIFF", "VISIBLE_DIFF", "Plan", "composite_view", "edit_insert",
           "edit_remove", "edit_shift", "floor_plane", "new_object", "plan_insert",
           "plan_remove", "render8", "render_settings", "rerender", "visible_change"]

VISIBLE_DIFF = 6.0      # 8-bit levels, after a 3x3 mean: a change one can see
STRONG_DIFF = 16.0      # 8-bit levels in one pixel: a change whatever its size


# --------------------------------------------------------------------------- rendering

def render_settings(desc: dict) -> dict:
    """Sampler settings of the source image: ``{"spp": int, "seed": int}``.

    ``make_scene`` records them in ``truth/scene.json`` (``spp``, ``sampler_seed``); a
    render with the same settings repeats the source's noise wherever the change does
    not reach.
    """
    return {"spp": int(desc.get("spp", 64)), "seed": int(desc.get("sampler_seed", 0))}


def render8(desc: dict, **kw) -> np.ndarray:
    """``render.render`` quantised to 8-bit sRGB as ``folder.write_image`` writes it."""
    from scenes.synthetic import render

    img = render.render(desc, **kw)
    return (np.clip(np.nan_to_num(img), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def visible_change(a: np.ndarray, b: np.ndarray, *, min_px: int = 4) -> np.ndarray:
    """Where two 8-bit renders of the same sampler differ visibly, (H, W) bool.

    A pixel changed when the 3x3 mean of the largest channel difference exceeds
    :data:`VISIBLE_DIFF` levels or its own exceeds :data:`STRONG_DIFF`; specks of
    fewer than ``min_px`` pixels (noise of light paths that touched the change) are
    dropped, holes filled, and the result grown by one pixel to take in the edges.
    """
    d = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1).astype(np.float32)
    m = (ndi.uniform_filter(d, 3) > VISIBLE_DIFF) | (d > STRONG_DIFF)
    lab, n = ndi.label(m, structure=np.ones((3, 3)))
    if n:
        sizes = np.bincount(lab.ravel())
        keep = sizes >= min_px
        keep[0] = False
        m = keep[lab]
    m = ndi.binary_closing(m, structure=np.ones((3, 3)))
    m = ndi.binary_fill_holes(m)
    return ndi.binary_dilation(m, structure=np.ones((3, 3)))


@dataclass
class Plan:
    """A re-rendering edit before it is rendered: the scene as the forger wants it."""

    new_desc: dict              # the edited description (an object added, or as it was)
    exclude_ids: tuple          # ids left out of ``new_desc`` when rendered (a removal)
    footprint: np.ndarray       # (H, W) bool, the object's directly seen pixels
    record: dict                # what tamper.json records of it (``object``)


def rerender(src: Source, plan: Plan, *, base_desc: dict | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    """The source scene (or ``base_desc``) and the planned one rendered with the
    source's sampler (8-bit sRGB, (H, W, 3) uint8 each, totems drawn): (base, new)."""
    desc = src.truth.scene
    rs = render_settings(desc)
    base = render8(desc if base_desc is None else base_desc, spp=rs["spp"], seed=rs["seed"])
    new = render8(plan.new_desc, spp=rs["spp"], seed=rs["seed"],
                  exclude_ids=plan.exclude_ids)
    return base, new


def composite_view(src: Source, plan: Plan, base: np.ndarray, new: np.ndarray) -> Edit:
    """The render of the plan (``new``) composited into the source where it visibly
    differs from the source scene's (``base``, the same sampler), or where the object
    is; totem pixels kept."""
    H, W = src.shape
    min_px = max(4, int(2e-4 * H * W))
    mask = (visible_change(new, base, min_px=min_px) | plan.footprint) & ~src.totems
    image = np.where(mask[..., None], new, src.image)
    record = dict(plan.record, render=render_settings(src.truth.scene),
                  base_equals_source=round(
                      float((base == src.image).all(axis=-1).mean()), 6))
    return Edit(image, mask, record)


# --------------------------------------------------------------------------- remove

def plan_remove(src: Source, rng) -> Plan:
    """A removable object in view (:func:`scenes.tamper.edits.pick_object`) left out."""
    obj, seen = pick_object(src, rng)
    return Plan(src.truth.scene, (obj["id"],), seen,
                {"object": {"id": obj["id"], "name": obj.get("name")}})


def edit_remove(src: Source, rng) -> Edit:
    """A removable object rendered away (the perfect content-aware fill)."""
    plan = plan_remove(src, rng)
    return composite_view(src, plan, *rerender(src, plan))


# --------------------------------------------------------------------------- insert

def floor_plane(desc: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor (object "floor", "ground" or "table"): a point on it, its upward unit
    normal and its ``to_world`` (camera frame, metres)."""
    for o in desc["objects"]:
        if o.get("name") in ("floor", "ground", "table") and o.get("kind") == "rectangle":
            M = np.asarray(o["to_world"], float)
            n = M[:3, 2] / np.linalg.norm(M[:3, 2])
            return M[:3, 3], n, M
    raise BadInput("truth/scene.json has no floor or ground to stand a new object on")


def _footprint_radius(obj: dict) -> tuple[np.ndarray, float]:
    """Centre of an object's base on the floor and the radius of its footprint (m)."""
    M = np.asarray(obj["to_world"], float)
    cols = np.linalg.norm(M[:3, :3], axis=0)
    if obj["kind"] == "cylinder":
        return M[:3, 3], float(cols[0])
    if obj["kind"] == "cube":
        return M[:3, 3], float(np.hypot(*np.sort(cols)[-2:]))
    return M[:3, 3], float(cols.max())


def new_object(desc: dict, rng, base: np.ndarray, up: np.ndarray, along: np.ndarray,
               new_id: int) -> dict:
    """A random box, sphere or cylinder standing on the floor at ``base``.

    ``up`` is the floor's unit normal, ``along`` a unit vector in the floor plane.
    The rotation is proper (det +1) so Mitsuba's shapes keep outward normals. Sizes
    are scaled by the description's ``object_scale`` (1 when absent).
    """
    s = float(desc.get("object_scale", 1.0))
    t = rng.uniform(0.0, 2 * np.pi)
    side = np.cross(up, along)
    e1 = np.cos(t) * along + np.sin(t) * side
    Q = np.stack([e1, np.cross(up, e1), up], axis=1)      # local z = up
    kind = str(rng.choice(["cube", "sphere", "cylinder"]))
    if kind == "cube":
        w, d, h = rng.uniform(0.25, 0.45), rng.uniform(0.25, 0.45), rng.uniform(0.3, 0.6)
        w, d, h = s * w, s * d, s * h
        L, t0 = Q @ np.diag([w / 2, d / 2, h / 2]), base + up * h / 2
    elif kind == "sphere":
        r = s * rng.uniform(0.15, 0.25)
        L, t0 = Q * r, base + up * r
    else:
        r, h = s * rng.uniform(0.1, 0.2), s * rng.uniform(0.35, 0.7)
        L, t0 = Q @ np.diag([r, r, h]), base
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = L, t0
    from colorsys import hsv_to_rgb
    rgb = hsv_to_rgb(rng.uniform(), rng.uniform(0.5, 0.9), rng.uniform(0.5, 0.9))
    return {"id": int(new_id), "name": f"inserted_{kind}", "kind": kind,
            "to_world": M.tolist(),
            "material": {"type": "diffuse",
                         "rgb": [round(float(c) ** 2.2, 4) for c in rgb]},
            "removable": True}


def _floor_point(K, u, v, p0, n):
    """Where the camera ray through pixel (u, v) meets the plane (p0, n), or None."""
    d = np.linalg.solve(K, [u, v, 1.0])
    denom = d @ n
    if abs(denom) < 1e-9:
        return None
    t = (p0 @ n) / denom
    return d * t if t > 0 else None


def plan_insert(src: Source, rng) -> Plan:
    """A new object standing on the floor, above the totems, in view (BadInput when no
    place is found)."""
    from scenes.synthetic import render

    desc = src.truth.scene
    K = np.asarray(desc["K"], float)
    H, W = src.shape
    p0, up, Mf = floor_plane(desc)
    # floor frame: half-extents along the rectangle's first two axes
    a1, a2 = Mf[:3, 0], Mf[:3, 1]
    along = a1 / np.linalg.norm(a1)
    others = [_footprint_radius(o) for o in desc["objects"] if o.get("removable")]
    zone = target_zone(src.totems)
    x0, y0, w0, h0 = masks.bbox(zone)
    new_id = 1 + max([int(o["id"]) for o in desc["objects"]]
                     + [int(li["id"]) for li in desc.get("lights", [])])
    for _ in range(60):
        u = rng.uniform(x0 + 0.15 * w0, x0 + 0.85 * w0)
        v = rng.uniform(y0 + 0.55 * h0, y0 + 0.95 * h0)      # the base low in the zone
        b = _floor_point(K, u, v, p0, up)
        if b is None:
            continue
        # inside the floor rectangle, away from its edges (local coords in [-1, 1])
        loc = np.linalg.lstsq(np.stack([a1, a2], 1), b - p0, rcond=None)[0]
        if np.abs(loc).max() > 0.85:
            continue
        obj = new_object(desc, rng, b, up, along, new_id)
        _, foot = _footprint_radius(obj)
        if any(np.linalg.norm((c - b) - up * ((c - b) @ up)) < foot + f + 0.08
               for c, f in others):
            continue
        new_desc = copy.deepcopy(desc)
        new_desc["objects"].append(obj)
        seen = render.shape_ids(new_desc, totems=True) == new_id
        if seen.sum() >= max(20, 2e-3 * H * W) and (seen & zone).sum() >= 0.7 * seen.sum():
            return Plan(new_desc, (), seen & ~src.totems, {"object": obj})
    raise BadInput("could not place a new object on the floor in view above the "
                   "totems; try another seed")


def edit_insert(src: Source, rng) -> Edit:
    """A new object rendered standing on the floor, above the totems, in view."""
    plan = plan_insert(src, rng)
    return composite_view(src, plan, *rerender(src, plan))


# --------------------------------------------------------------------------- shift

def _moved(desc: dict, obj_id: int, delta: np.ndarray) -> dict:
    out = copy.deepcopy(desc)
    for o in out["objects"]:
        if o["id"] == obj_id:
            M = np.asarray(o["to_world"], float)
            M[:3, 3] += delta
            o["to_world"] = M.tolist()
    return out


def _centroid(mask):
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()])


def edit_shift(src: Source, rng) -> Edit:
    """The reference shift: an object (and its shadow) moved along the floor in the
    camera view and, by 2D translations, in each totem view that sees it."""
    from scenes import camera

    desc = src.truth.scene
    rs = render_settings(desc)
    K = np.asarray(desc["K"], float)
    H, W = src.shape
    p0, up, Mf = floor_plane(desc)
    along = Mf[:3, 0] / np.linalg.norm(Mf[:3, 0])
    obj, seen = pick_object(src, rng)
    centre, foot = _footprint_radius(obj)
    others = [_footprint_radius(o) for o in desc["objects"]
              if o.get("removable") and o["id"] != obj["id"]]
    zone = target_zone(src.totems)
    # The reference point: a new place on the floor, sideways, free, still in view.
    delta = None
    for _ in range(40):
        step = rng.uniform(2.2, 4.0) * foot * rng.choice([-1.0, 1.0])
        d3 = along * step
        c2 = centre + d3
        if any(np.linalg.norm((c - c2) - up * ((c - c2) @ up)) < foot + f + 0.05
               for c, f in others):
            continue
        uv0, uv1 = camera.project(K, np.stack([centre, c2]))
        if zone[int(np.clip(uv1[1], 0, H - 1)), int(np.clip(uv1[0], 0, W - 1))]:
            delta = d3
            break
    if delta is None:
        raise BadInput("could not find a free place in view to shift an object to; "
                       "try another seed")
    dx, dy = (int(v) for v in np.rint(uv1 - uv0))
    base = render8(desc, spp=rs["spp"], seed=rs["seed"])
    without = render8(desc, spp=rs["spp"], seed=rs["seed"], exclude_ids=[obj["id"]])
    moved = render8(_moved(desc, obj["id"], delta), spp=rs["spp"], seed=rs["seed"])
    min_px = max(4, int(2e-4 * H * W))
    # The object is a few dozen pixels in a totem view: keep small changes there.
    tot = src.totems
    old_all = np.where(tot, visible_change(base, without, min_px=2),
                       visible_change(base, without, min_px=min_px))
    new_all = visible_change(moved, without, min_px=2)
    # Camera view: object and shadow moved by the projected shift, hole inpainted.
    cam_old = (old_all | seen) & ~src.totems
    image, cam_mask = edits2d.move_pixels(src.image, cam_old, dx, dy, within=~src.totems)
    # Totem views: each edited by the translation that takes the object's image there
    # to the image of the new place there.
    totem_mask = np.zeros((H, W), bool)
    edits = []
    for j, tm in enumerate(src.scene.masks):
        old_j, new_j = old_all & tm, new_all & tm
        if old_j.sum() < 2 or new_j.sum() < 2:
            edits.append({"totem": j, "visible": False})
            continue
        tdx, tdy = (int(v) for v in np.rint(_centroid(new_j) - _centroid(old_j)))
        image, fp = edits2d.move_pixels(image, old_j, tdx, tdy, within=tm)
        totem_mask |= fp
        edits.append({"totem": j, "visible": True, "shift_px": [tdx, tdy],
                      "pixels": int(fp.sum())})
    record = {"object": {"id": obj["id"], "name": obj.get("name")},
              "shift_m": [round(float(v), 6) for v in delta], "shift_px": [dx, dy],
              "totem_edits": edits, "render": rs}
    return Edit(image, cam_mask & ~src.totems, record, totem_mask=totem_mask)
