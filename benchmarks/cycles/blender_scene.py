"""Build a :mod:`design` description in Blender and render it with Cycles on the CPU.

Runs inside ``.venv-cycles`` only (imports ``bpy``). Totems are Cycles point-cloud
points, which Cycles intersects as exact spheres (made by a one-point Geometry Nodes
tree, so no mesh approximates them), with a sharp Glass BSDF of the key's IoR.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

__all__ = ["build", "render_png", "render_linear", "render_ids", "render_depth", "meter",
           "camera_params", "set_visible"]

TOTEM_INDEX = 100          # pass_index of totem j is TOTEM_INDEX + j; objects 1, 2, ...
MARKER_INDEX = 200


def _link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _mix(nodes, links, fac, c1, c2):
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    a = [s for s in mix.inputs if s.name == "A" and s.type == "RGBA"][0]
    b = [s for s in mix.inputs if s.name == "B" and s.type == "RGBA"][0]
    a.default_value, b.default_value = (*c1, 1.0), (*c2, 1.0)
    links.new(fac, mix.inputs["Factor"])
    return [s for s in mix.outputs if s.type == "RGBA"][0]


def material(name: str, spec: dict):
    """A Principled BSDF whose base colour is a procedural texture in object
    coordinates (metres): checker, noise, brick, wave, voronoi, magic or plain."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = spec["roughness"]
    kind, c1, c2 = spec["texture"], spec["c1"], spec["c2"]
    if kind == "plain":
        bsdf.inputs["Base Color"].default_value = (*c1, 1.0)
        return mat
    coord = nodes.new("ShaderNodeTexCoord").outputs["Object"]
    tex = nodes.new({"checker": "ShaderNodeTexChecker", "noise": "ShaderNodeTexNoise",
                     "brick": "ShaderNodeTexBrick", "wave": "ShaderNodeTexWave",
                     "voronoi": "ShaderNodeTexVoronoi",
                     "magic": "ShaderNodeTexMagic"}[kind])
    links.new(coord, tex.inputs["Vector"])
    tex.inputs["Scale"].default_value = spec["scale"]
    if kind in ("checker", "brick"):
        tex.inputs["Color1"].default_value = (*c1, 1.0)
        tex.inputs["Color2"].default_value = (*c2, 1.0)
        colour = tex.outputs["Color"]
    else:
        fac = tex.outputs["Distance" if kind == "voronoi" else "Fac"]
        colour = _mix(nodes, links, fac, c1, c2)
    links.new(colour, bsdf.inputs["Base Color"])
    return mat


def _one_shader(name: str, node: str, output: str, **inputs):
    """A material of one shader node (``node``, its ``inputs`` set) into the output."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    shader = nodes.new(node)
    for key, value in inputs.items():
        shader.inputs[key].default_value = value
    mat.node_tree.links.new(shader.outputs[output],
                            nodes["Material Output"].inputs["Surface"])
    return mat


def _glass(ior: float, kind: str = "glass"):
    """The totems' sharp dielectric: Cycles' Glass BSDF (Fresnel-weighted reflection and
    refraction); for ablations, ``kind`` "refraction", the Refraction BSDF alone (no
    reflection of the environment, the transmitted light not dimmed by Fresnel), or
    "coated", the Glass BSDF without its reflection (the refraction weighted by one
    minus the Fresnel reflectance, as the fit's key assumes; an ideal anti-reflective
    coating that absorbs what uncoated glass would reflect)."""
    if kind == "coated":
        return _coated(ior)
    node = {"glass": "ShaderNodeBsdfGlass", "refraction": "ShaderNodeBsdfRefraction"}[kind]
    return _one_shader("totem_glass", node, "BSDF", IOR=ior, Roughness=0.0)


def _coated(ior: float):
    """``mix(refraction, black, Fresnel(ior))``: Cycles' Fresnel node takes ``1 / ior``
    on the inside, so both surfaces dim the light as the Glass BSDF's do."""
    mat = _one_shader("totem_glass", "ShaderNodeBsdfRefraction", "BSDF", IOR=ior,
                      Roughness=0.0)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    refraction = nodes["Refraction BSDF"]
    fresnel = nodes.new("ShaderNodeFresnel")
    fresnel.inputs["IOR"].default_value = ior
    black = nodes.new("ShaderNodeEmission")
    black.inputs["Strength"].default_value = 0.0
    mix = nodes.new("ShaderNodeMixShader")
    links.new(fresnel.outputs["Fac"], mix.inputs["Fac"])
    links.new(refraction.outputs["BSDF"], mix.inputs[1])
    links.new(black.outputs["Emission"], mix.inputs[2])
    links.new(mix.outputs["Shader"], nodes["Material Output"].inputs["Surface"])
    return mat


def _emitter(strength: float):
    return _one_shader("marker", "ShaderNodeEmission", "Emission", Strength=strength)


def sphere(name: str, centre, radius: float, mat, index: int):
    """An exact sphere: one point of a point cloud (Geometry Nodes ``Points``)."""
    obj = _link(bpy.data.objects.new(name, bpy.data.meshes.new(name)))
    obj.location = centre
    obj.pass_index = index
    tree = bpy.data.node_groups.new(name, "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT",
                              socket_type="NodeSocketGeometry")
    pts = tree.nodes.new("GeometryNodePoints")
    pts.inputs["Count"].default_value = 1
    pts.inputs["Radius"].default_value = radius
    setm = tree.nodes.new("GeometryNodeSetMaterial")
    setm.inputs["Material"].default_value = mat
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(pts.outputs["Points"], setm.inputs["Geometry"])
    tree.links.new(setm.outputs["Geometry"], out.inputs["Geometry"])
    obj.modifiers.new("sphere", "NODES").node_group = tree
    return obj


def _primitive(o: dict, index: int, z0: float):
    s, (x, y, z) = o["size"], o["location"]
    rot = (0.0, 0.0, np.radians(o["yaw"]))
    ops = bpy.ops.mesh
    if o["shape"] == "cube":
        ops.primitive_cube_add(size=s, location=(x, y, z), rotation=rot)
    elif o["shape"] == "cylinder":
        ops.primitive_cylinder_add(radius=s / 2, depth=s, location=(x, y, z),
                                   rotation=rot)
    elif o["shape"] == "cone":
        ops.primitive_cone_add(radius1=s / 2, depth=s, location=(x, y, z), rotation=rot)
    elif o["shape"] == "torus":
        ops.primitive_torus_add(major_radius=s / 2, minor_radius=s / 6,
                                location=(x, y, z0 + s / 6), rotation=rot)
    elif o["shape"] == "ico":
        ops.primitive_ico_sphere_add(radius=s / 2, subdivisions=4, location=(x, y, z))
        bpy.ops.object.shade_smooth()
    else:
        ops.primitive_monkey_add(size=s, location=(x, y, z), rotation=rot)
        bpy.ops.object.shade_smooth()
    obj = bpy.context.active_object
    obj.name = f"object_{index:02d}"
    obj.pass_index = index
    obj.data.materials.append(material(obj.name, o["material"]))
    return obj


def _box(name, location, scale, mat):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name, obj.scale = name, scale
    obj.data.materials.append(mat)
    return obj


def _world(w: dict):
    world = bpy.data.worlds.new("world")
    bpy.context.scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = nodes["Background"]
    bg.inputs["Strength"].default_value = w["strength"]
    if "hdri" in w:
        path = os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights",
                            "world", w["hdri"] + ".exr")
        env = nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(path)
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0,
                                                    np.radians(w["rotation_deg"]))
        links.new(nodes.new("ShaderNodeTexCoord").outputs["Generated"],
                  mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
        links.new(env.outputs["Color"], bg.inputs["Color"])
    else:
        bg.inputs["Color"].default_value = (*w["colour"], 1.0)


def _lights(lights: list):
    for i, li in enumerate(lights):
        data = bpy.data.lights.new(f"light_{i}", li["type"])
        data.energy = li["energy"]
        obj = _link(bpy.data.objects.new(f"light_{i}", data))
        if li["type"] == "SUN":
            data.angle = np.radians(1.0)
            obj.rotation_euler = [np.radians(a) for a in li["rotation_deg"]]
        else:
            data.size = li["size"]
            obj.location = li["location"]


def _camera(c: dict):
    from mathutils import Matrix

    data = bpy.data.cameras.new("camera")
    data.lens, data.sensor_width, data.sensor_fit = c["lens"], c["sensor_width"], "AUTO"
    data.shift_x, data.shift_y = c["shift_x"], c["shift_y"]
    data.clip_start, data.clip_end = 0.01, 1000.0
    obj = _link(bpy.data.objects.new("camera", data))
    obj.matrix_world = Matrix(c["matrix_world"])
    bpy.context.scene.camera = obj


def build(desc: dict, threads: int = 2) -> dict:
    """An empty Blender scene filled with ``desc``. Returns the objects by role."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.render.threads_mode, sc.render.threads = "FIXED", int(threads)
    c = desc["camera"]
    sc.render.resolution_x, sc.render.resolution_y = c["width"], c["height"]
    sc.render.resolution_percentage = 100
    sc.render.pixel_aspect_x = sc.render.pixel_aspect_y = 1.0
    cy = sc.cycles
    cy.max_bounces, cy.transmission_bounces, cy.glossy_bounces = 12, 12, 4
    cy.diffuse_bounces, cy.transparent_max_bounces = 2, 8
    _camera(c)
    _world(desc["world"])
    _lights(desc.get("lights", []))
    z0 = desc.get("support_z", 0.0)
    if desc.get("floor"):
        bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0.0, 0.0, 0.0))
        bpy.context.active_object.data.materials.append(material("floor", desc["floor"]))
    if desc.get("walls"):
        wall = material("walls", desc["walls"])
        for loc, sc_ in (((0, 6.5, 1.5), (8, 0.1, 3)), ((0, -3.5, 1.5), (8, 0.1, 3)),
                         ((-4, 1.5, 1.5), (0.1, 10, 3)), ((4, 1.5, 1.5), (0.1, 10, 3))):
            _box("wall", loc, sc_, wall)
    if desc.get("table"):
        top = material("table", desc["table"])
        _box("table_top", (0, 1.7, z0 - 0.02), (2.8, 2.6, 0.04), top)
        for x in (-1.3, 1.3):
            for y in (0.5, 2.9):
                _box("table_leg", (x, y, (z0 - 0.04) / 2), (0.06, 0.06, z0 - 0.04), top)
    objects = [_primitive(o, i + 1, z0) for i, o in enumerate(desc.get("objects", []))]
    glass = _glass(desc["key"]["ior"], desc.get("glass", "glass"))
    totems = [sphere(f"totem_{j}", t["centre"], desc["key"]["radius"], glass,
                     TOTEM_INDEX + j) for j, t in enumerate(desc["totems"])]
    if not desc.get("totem_shadows", True):       # no shadow, no caustic (ablations)
        for t in totems:
            t.visible_shadow = t.visible_diffuse = False
    markers = [sphere(f"marker_{j}", m["centre"], m["radius"], _emitter(m["strength"]),
                      MARKER_INDEX + j) for j, m in enumerate(desc.get("markers", []))]
    return {"objects": objects, "totems": totems, "markers": markers}


def _pipeline(p: dict, *, view=None):
    sc = bpy.context.scene
    cy = sc.cycles
    cy.samples = int(p["samples"])
    cy.use_adaptive_sampling = cy.samples >= 16
    cy.adaptive_threshold = 0.02
    cy.seed = int(p.get("sampling_seed", 0))
    cy.use_denoising = bool(p["denoise"])
    cy.denoiser = "OPENIMAGEDENOISE"
    cy.pixel_filter_type = p["filter"]
    cy.filter_width = float(p["filter_width"])
    sc.display_settings.display_device = "sRGB"
    sc.view_settings.view_transform = view or p["view_transform"]
    sc.view_settings.look = "None"
    sc.view_settings.exposure = p.get("exposure", 0.0) if view is None else 0.0
    sc.view_settings.gamma = 1.0


def render_png(path: str, pipeline: dict, border=None) -> None:
    """The camera's photo as its pipeline makes it: 8-bit sRGB PNG, view transform.
    ``border`` (x0, y0, x1, y1) in pixels from the top left: render only there (the
    rest of the image black)."""
    _pipeline(pipeline)
    sc = bpy.context.scene
    sc.render.use_border, sc.render.use_crop_to_border = border is not None, False
    if border is not None:
        W, H = sc.render.resolution_x, sc.render.resolution_y
        x0, y0, x1, y1 = border
        sc.render.border_min_x, sc.render.border_max_x = x0 / W, x1 / W
        sc.render.border_min_y, sc.render.border_max_y = 1 - y1 / H, 1 - y0 / H
    sc.render.image_settings.file_format = "PNG"
    sc.render.image_settings.color_mode = "RGB"
    sc.render.image_settings.color_depth = "8"
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    sc.render.use_border = False


def _read_exr(path: str) -> np.ndarray:
    img = bpy.data.images.load(path)
    W, H = img.size
    px = np.empty(W * H * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(H, W, 4)[::-1, :, :3].copy()       # top row first


def render_linear(path: str, pipeline: dict) -> np.ndarray:
    """Scene-linear radiance (H, W, 3) float32, top row first, through the pipeline's
    samples and pixel filter, no view transform (an OpenEXR written then read)."""
    _pipeline(pipeline, view="Standard")
    sc = bpy.context.scene
    s = sc.render.image_settings
    s.file_format, s.color_mode, s.color_depth = "OPEN_EXR", "RGB", "32"
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return _read_exr(path)


def meter(path: str, pipeline: dict) -> float:
    """A camera's metering (``design.metered_ev``: log-average luminance to 0.18, the
    highlights kept under the view's white) of a quick, coarse linear render (an eighth
    of the size, 4 samples)."""
    import design

    sc = bpy.context.scene
    sc.render.resolution_percentage = 12
    try:
        lin = render_linear(path, dict(pipeline, samples=4, denoise=False))
    finally:
        sc.render.resolution_percentage = 100
    return design.metered_ev(lin, pipeline["view_transform"])


def _probe(path: str, wire) -> np.ndarray:
    """What each pixel centre's camera ray meets first, as every surface's emission
    ``wire(nodes, links, combine)`` links into a Combine Color: (H, W, 3) float32, top
    row first, 0 where the ray leaves the scene. One sample a pixel, a 0.01 px filter,
    the world dark."""
    sc = bpy.context.scene
    mat = bpy.data.materials.new("probe")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    em = nodes.new("ShaderNodeEmission")
    comb = nodes.new("ShaderNodeCombineColor")
    wire(nodes, links, comb)
    links.new(comb.outputs["Color"], em.inputs["Color"])
    links.new(em.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    layer = sc.view_layers[0]
    bg = sc.world.node_tree.nodes["Background"].inputs["Strength"]
    strength, bg.default_value = bg.default_value, 0.0
    layer.material_override = mat
    try:
        return render_linear(path, {"samples": 1, "denoise": False, "filter": "BOX",
                                    "filter_width": 0.01, "sampling_seed": 0})
    finally:
        layer.material_override = None
        bg.default_value = strength


def render_ids(path: str) -> np.ndarray:
    """Which object each pixel centre's camera ray meets first: (H, W) int16 of
    ``pass_index`` (0 for none), :func:`_probe` of the Object Index."""
    def wire(nodes, links, comb):
        links.new(nodes.new("ShaderNodeObjectInfo").outputs["Object Index"],
                  comb.inputs["Red"])

    return np.rint(_probe(path, wire)[..., 0]).astype(np.int16)


def render_depth(path: str) -> np.ndarray:
    """Cycles' own depth of the first surface each pixel centre's camera ray meets, among
    the objects rendered: (H, W) float32, metres along the camera's view axis (the
    OpenCV camera frame's z), inf where the ray leaves the scene; :func:`_probe` of the
    Camera Data node's View Z Depth (a check of ``blender_trace.py``)."""
    def wire(nodes, links, comb):
        links.new(nodes.new("ShaderNodeCameraData").outputs["View Z Depth"],
                  comb.inputs["Red"])
        comb.inputs["Green"].default_value = 1.0             # a surface was met

    lin = _probe(path, wire)
    return np.where(lin[..., 1] > 0.5, lin[..., 0], np.inf).astype(np.float32)


def set_visible(obj, *, render=None, camera=None) -> None:
    """Hide an object from the render altogether, or from camera rays only (it still
    casts shadows and shows in reflections and refractions)."""
    if render is not None:
        obj.hide_render = not render
    if camera is not None:
        obj.visible_camera = camera


def camera_params() -> dict:
    """The scene camera as Blender holds it (after Blender's own float32 rounding)."""
    sc = bpy.context.scene
    cam = sc.camera
    d = cam.data
    return {"width": sc.render.resolution_x, "height": sc.render.resolution_y,
            "lens": d.lens, "sensor_width": d.sensor_width,
            "sensor_height": d.sensor_height,
            "sensor_fit": d.sensor_fit, "shift_x": d.shift_x, "shift_y": d.shift_y,
            "matrix_world": [list(r) for r in cam.matrix_world]}
