"""Where given rays first meet a Cycles scene, as Blender builds it (with .venv-cycles'
python).

    .venv-cycles/bin/python benchmarks/cycles/blender_trace.py DESC.json RAYS.npz OUT.npz

The scene of ``DESC.json`` (a :mod:`design` description, as ``render.py`` takes it) is
built by :func:`blender_scene.build`; its meshes, evaluated and placed in the world, make
one BVH (``mathutils.bvhtree``), and its spheres (the totems and any markers, Cycles
points, no mesh) are met in closed form. ``RAYS.npz`` holds rays in the OpenCV camera
frame of the scene's camera (+x right, +y down, +z forward, metres): ``camera_o``,
``camera_d`` traced WITHOUT the totems (the surfaces the camera's pixels show behind them
too), ``totem_o``, ``totem_d`` traced WITH them (a totem ray that meets a totem is
blocked). Directions need not be unit.

Writes ``OUT.npz`` (atomically): for each group ``<g>_Y`` (m, 3) the first hit (camera
frame, metres; NaN where the ray leaves the scene), ``<g>_normal`` (m, 3) the surface's
unit geometric normal there (either side; NaN where none), ``<g>_index`` (m,) int32 the
object's ``pass_index`` (objects 1, 2, ...; floor, walls and table 0; totem j
``blender_scene.TOTEM_INDEX + j``, markers ``MARKER_INDEX + j``; -1 where the ray leaves
the scene); ``K`` (3x3) of the camera as Blender holds it, for the caller to check it
traced the scene it meant; ``totem_base``, ``marker_base`` the two indices.

Frames: Blender's world (+Z up, metres) is reached from the camera frame by the camera's
camera-to-world transform, ``X_world = R (FLIP X_cv) + t`` with ``matrix_world = [R t]``
and ``FLIP = diag(1, -1, -1)`` (``blender_camera.opencv_from_blender``); hits go back the
same way. Lights are no surface here: Cycles hides them from camera rays
(``visible_camera`` is False), and a totem ray that would meet the room's area light
leaves the scene (there is no ceiling behind it).
"""

from __future__ import annotations

import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402  (bpy's own numpy)

import blender_camera as bc  # noqa: E402
import blender_scene as bs  # noqa: E402

T_MIN = 1e-6
"""Hits nearer than this along a ray (metres) are not taken: a ray that leaves a sphere's
surface does not meet that sphere again."""


def scene_mesh(depsgraph):
    """Every mesh surface of the scene, evaluated, in world coordinates: (vertices (v, 3)
    float64 metres, triangles (t, 3) int, pass_index of each triangle's object (t,))."""
    import bpy

    verts, tris, owner, base = [], [], [], 0
    for obj in bpy.context.scene.objects:
        if obj.type != "MESH" or obj.hide_render:
            continue
        ev = obj.evaluated_get(depsgraph)
        me = ev.to_mesh()
        me.calc_loop_triangles()
        n, t = len(me.vertices), len(me.loop_triangles)
        if t:
            co = np.empty(3 * n, np.float32)
            me.vertices.foreach_get("co", co)
            M = np.array(ev.matrix_world, np.float64)
            idx = np.empty(3 * t, np.int32)
            me.loop_triangles.foreach_get("vertices", idx)
            verts.append(co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])
            tris.append(idx.reshape(-1, 3) + base)
            owner.append(np.full(t, obj.pass_index, np.int32))
            base += n
        ev.to_mesh_clear()
    if not tris:
        return np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros(0, np.int32)
    return np.concatenate(verts), np.concatenate(tris), np.concatenate(owner)


def cast_mesh(verts, tris, owner, o, d):
    """First hits of world rays ``o + t d`` (d unit) on the triangles: (t (m,) metres,
    inf where none; unit normals (m, 3); index (m,) of the triangle's object)."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    m = len(o)
    t = np.full(m, np.inf)
    normal = np.full((m, 3), np.nan)
    index = np.full(m, -1, np.int32)
    if not len(tris) or not m:
        return t, normal, index
    bvh = BVHTree.FromPolygons(verts.tolist(), tris.tolist(), all_triangles=True)
    cast = bvh.ray_cast
    for i, (oi, di) in enumerate(zip(o.tolist(), d.tolist())):
        hit, nrm, face, dist = cast(Vector(oi), Vector(di))
        if hit is not None and dist > T_MIN:
            t[i], normal[i], index[i] = dist, nrm, owner[face]
    return t, normal, index


def cast_spheres(centres, radii, indices, o, d):
    """First hits of world rays ``o + t d`` (d unit) on spheres ``centres`` (k, 3),
    ``radii`` (k,), metres: (t (m,), inf where none; unit outward normals (m, 3);
    index (m,) from ``indices``)."""
    m = len(o)
    best = np.full(m, np.inf)
    normal = np.full((m, 3), np.nan)
    index = np.full(m, -1, np.int32)
    for C, r, k in zip(centres, radii, indices):
        oc = o - C
        b = (oc * d).sum(1)
        disc = b * b - ((oc * oc).sum(1) - r * r)
        root = np.sqrt(np.maximum(disc, 0.0))
        t = np.where(-b - root > T_MIN, -b - root, -b + root)
        t = np.where((disc >= 0) & (t > T_MIN), t, np.inf)
        near = t < best
        best[near] = t[near]
        normal[near] = (o[near] + t[near, None] * d[near] - C) / r
        index[near] = k
    return best, normal, index


def trace(mesh, spheres, o, d):
    """First hits of world rays on ``mesh`` (:func:`scene_mesh`) and ``spheres``
    ((centres, radii, indices)): (Y (m, 3), NaN where none; normal (m, 3); index (m,))."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    t, normal, index = cast_mesh(*mesh, o, d)
    ts, ns, ks = cast_spheres(*spheres, o, d)
    take = ts < t
    t[take], normal[take], index[take] = ts[take], ns[take], ks[take]
    Y = np.where(np.isfinite(t)[:, None], o + np.where(np.isfinite(t), t, 0.0)[:, None] * d,
                 np.nan)
    return Y, normal, index


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3:
        print("usage: blender_trace.py DESC.json RAYS.npz OUT.npz", file=sys.stderr)
        return 2
    desc_path, rays_path, out_path = argv
    with open(desc_path) as f:
        desc = json.load(f)
    rays = dict(np.load(rays_path))
    t0 = time.perf_counter()
    parts = bs.build(desc, threads=1)
    import bpy

    K, w2c = bc.opencv_from_blender(**bs.camera_params())
    c2w = np.linalg.inv(w2c)                    # OpenCV camera frame -> Blender's world
    mesh = scene_mesh(bpy.context.evaluated_depsgraph_get())
    radius = desc["key"]["radius"]
    totems = ([np.array(t.matrix_world.translation) for t in parts["totems"]],
              [radius] * len(parts["totems"]),
              [bs.TOTEM_INDEX + j for j in range(len(parts["totems"]))])
    markers = ([np.array(m.matrix_world.translation) for m in parts["markers"]],
               [m["radius"] for m in desc.get("markers", [])],
               [bs.MARKER_INDEX + j for j in range(len(parts["markers"]))])
    both = tuple(a + b for a, b in zip(totems, markers))
    out = {"K": K, "totem_base": bs.TOTEM_INDEX, "marker_base": bs.MARKER_INDEX}
    for group, spheres in (("camera", markers), ("totem", both)):
        o = np.asarray(rays[f"{group}_o"], np.float64).reshape(-1, 3)
        d = np.asarray(rays[f"{group}_d"], np.float64).reshape(-1, 3)
        R, t = c2w[:3, :3], c2w[:3, 3]
        Y, N, index = trace(mesh, spheres, o @ R.T + t, d @ R.T)
        out[f"{group}_Y"] = (Y - t) @ R              # back to the camera frame
        out[f"{group}_normal"] = N @ R
        out[f"{group}_index"] = index
    tmp = out_path + ".part.npz"
    np.savez(tmp, **out)
    os.replace(tmp, out_path)
    n = sum(len(out[f"{g}_index"]) for g in ("camera", "totem"))
    print(f"traced {n} rays against {len(mesh[1])} triangles in "
          f"{time.perf_counter() - t0:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
