"""What a Cycles totem scene holds, drawn from a seed: a plain dict (JSON), no Blender.

Pure numpy (runs in ``.venv-cycles`` beside bpy, and in the package's venv). World frame
Blender's: metres, +Z up, the ground (or the table top) at ``support_z``. The
description lists the camera (Blender's parameters), the totems (world centres, one key),
objects with procedural materials, lights, the world (a bundled HDRI or a colour) and the
camera's pipeline (view transform, denoiser, pixel filter, samples).
"""

from __future__ import annotations

import numpy as np

try:                                     # run as a script inside .venv-cycles
    import blender_camera as bc
except ImportError:                      # imported from the package's venv
    from benchmarks.cycles import blender_camera as bc

__all__ = ["KINDS", "HDRIS", "describe", "ablate", "metered_ev"]

KINDS = ("room", "yard", "table")
HDRIS = ("courtyard", "forest", "city", "sunset", "sunrise", "interior", "studio")
SHAPES = ("cube", "cylinder", "cone", "torus", "ico", "monkey")
TEXTURES = ("checker", "noise", "brick", "wave", "voronoi", "magic", "plain")
VIEWS = ("AgX", "Filmic", "Standard")
FILTERS = ("BLACKMAN_HARRIS", "GAUSSIAN", "BOX")
GLASSES = ("glass", "refraction", "coated")
VIEW_WHITE = {"Standard": 1.0, "AgX": 0.18 * 2**4.026, "Filmic": 0.18 * 2**6.5}
"""The scene-linear value each view transform shows as white (Blender's OCIO config:
Standard clips at 1, AgX's range ends 4.03 stops and Filmic's 6.5 stops above 0.18)."""
HIGHLIGHT_Q = 0.95
"""The metering keeps this share of the photo's pixels (their largest channel) at or
under the view's white."""


def metered_ev(lin, view: str) -> float:
    """A camera's metering of a scene-linear image (H, W, 3): the exposure (stops) that
    brings its log-average luminance to 0.18, lowered where needed so that no more than
    5 % of its pixels go past the view's white (a photo metered on the average alone
    clipped a bright floor white under Standard, room-s207)."""
    lin = np.asarray(lin, np.float64)
    Y = lin @ np.array([0.2126, 0.7152, 0.0722])
    key = float(np.exp(np.mean(np.log(np.maximum(Y, 1e-4)))))
    ev = np.log2(0.18 / key)
    high = float(np.quantile(lin.max(axis=-1), HIGHLIGHT_Q))
    if high > 0:
        ev = min(ev, np.log2(VIEW_WHITE[view] / high))
    return float(ev)


def scene_options(ap) -> None:
    """The options that choose and draw a scene, shared by ``render.py`` and
    ``make_cycles_set.py``."""
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--kind", choices=KINDS)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--small", action="store_true", help="160x120, 16 samples (tests)")
    ap.add_argument("--samples", type=int, default=96)
    ap.add_argument("--view", choices=VIEWS,
                    help="this view transform instead of each scene's own (ablations)")
    ap.add_argument("--denoise", choices=("on", "off"),
                    help="the denoiser on or off instead of each scene's own (ablations)")
    ap.add_argument("--filter", choices=FILTERS,
                    help="this pixel filter instead of each scene's own (ablations)")
    ap.add_argument("--filter-width", type=float,
                    help="the pixel filter's width in pixels (ablations)")
    ap.add_argument("--glass", choices=GLASSES,
                    help="the totems' BSDF: Cycles' Glass (reflects and refracts; the "
                         "default), Refraction alone (no reflection, no Fresnel "
                         "dimming) or coated (the Glass without its reflection; "
                         "ablations)")
    ap.add_argument("--totem-shadows", choices=("on", "off"),
                    help="off: the totems hidden from shadow and diffuse rays, so they "
                         "cast no shadow and no caustic (ablations; default on)")


def ablate(desc: dict, a) -> dict:
    """``desc`` with the ablation options of :func:`scene_options` that ``a`` sets
    (the others leave it as drawn): a new dict, ``desc`` untouched."""
    d = dict(desc, pipeline=dict(desc["pipeline"]))
    p = d["pipeline"]
    if getattr(a, "view", None):
        p["view_transform"] = a.view
    if getattr(a, "denoise", None):
        p["denoise"] = a.denoise == "on"
    if getattr(a, "filter", None):
        p["filter"] = a.filter
    if getattr(a, "filter_width", None) is not None:
        if not a.filter_width > 0:
            raise ValueError(f"--filter-width must be > 0 px, got {a.filter_width}")
        p["filter_width"] = float(a.filter_width)
    if getattr(a, "glass", None):
        d["glass"] = a.glass
    if getattr(a, "totem_shadows", None):
        d["totem_shadows"] = a.totem_shadows == "on"
    return d


def _colour(rng, lo=0.05, hi=0.85) -> list:
    return [float(c) for c in rng.uniform(lo, hi, 3)]


def _material(rng, kind=None) -> dict:
    return {"texture": kind or str(rng.choice(TEXTURES)), "c1": _colour(rng),
            "c2": _colour(rng), "scale": float(rng.uniform(2.0, 12.0)),
            "roughness": float(rng.uniform(0.25, 0.9))}


def _camera(rng, kind: str, width: int, height: int) -> dict:
    height_m = {"room": (0.7, 1.0), "yard": (0.75, 1.05), "table": (1.05, 1.2)}[kind]
    pitch = {"room": (10, 18), "yard": (8, 16), "table": (6, 12)}[kind]
    fov_x = float(rng.uniform(55.0, 70.0))
    lens = 36.0 / 2.0 / np.tan(np.radians(fov_x) / 2.0) * width / max(width, height)
    M = bc.look_matrix([0.0, 0.0, float(rng.uniform(*height_m))],
                       float(rng.uniform(-10, 10)), float(rng.uniform(*pitch)))
    return {"lens": float(lens), "sensor_width": 36.0, "sensor_fit": "AUTO",
            "shift_x": float(rng.uniform(-0.03, 0.03)),
            "shift_y": float(rng.uniform(-0.03, 0.03)), "matrix_world": M.tolist(),
            "width": int(width), "height": int(height)}


BANDS = ((0.55, 0.08), (0.35, 0.05), (0.15, 0.03))
"""The totems' band of image rows (its top, a share of the height) and the floating
totems' clearance above the support (m), tried in turn until the totems fit: a camera
low over a table sees little of it below the first band's top."""


def _totems(rng, cam: dict, support_z: float, radius: float, n: int) -> list:
    """``n`` totem centres (world), the first resting on the support, the others
    floating; each silhouette whole in the lower part of the image, apart. The first of
    ``BANDS`` that places them all (a seed placed in the first band draws as before)."""
    for top, clear in BANDS:
        placed = _place(rng, cam, support_z, radius, n, top, clear)
        if placed:
            return placed
    raise RuntimeError("could not place the totems; try another seed")


def _place(rng, cam, support_z, radius, n, top, clear) -> list | None:
    """Totems in image rows from ``top`` of the height down, floating ones at least
    ``clear`` above the support; None when 20000 draws do not place all ``n``."""
    W, H = cam["width"], cam["height"]
    K, w2c = bc.opencv_from_blender(**{k: v for k, v in cam.items() if k not in
                                       ("width", "height")}, width=W, height=H)
    c2w = np.linalg.inv(w2c)
    placed, discs = [], []
    gap = 8.0 * W / 640.0
    for attempt in range(20000):
        if len(placed) == n:
            break
        if attempt % 2000 == 1999:                  # stuck: start again
            placed, discs = [], []
        resting = not placed
        u = rng.uniform(0.1 * W, 0.9 * W)
        v = rng.uniform(top * H, (0.97 if resting else 0.9) * H)
        ray = np.linalg.solve(K, [u, v, 1.0])
        d_w = c2w[:3, :3] @ ray
        o_w = c2w[:3, 3]
        if resting:                       # slide along the pixel's ray to the support
            if d_w[2] >= -1e-3:
                continue
            t = (support_z + radius - o_w[2]) / d_w[2]
        else:
            t = rng.uniform(1.0, 2.2) / np.linalg.norm(ray)
        P_w = o_w + t * d_w
        P_c = w2c[:3, :3] @ P_w + w2c[:3, 3]
        depth = np.linalg.norm(P_c)
        low = P_w[2] < support_z + radius + clear
        if not 1.0 <= depth <= 2.2 or (not resting and low):
            continue
        r_px = K[0, 0] * radius / np.sqrt(max(depth**2 - radius**2, 1e-9)) * 1.15
        uc, vc = K[:2, :2] @ (P_c[:2] / P_c[2]) + K[:2, 2]
        if min(uc - r_px, vc - r_px, W - 1 - uc - r_px, H - 1 - vc - r_px) < gap:
            continue
        if any(np.hypot(uc - a, vc - b) < r_px + s + gap for a, b, s in discs):
            continue
        placed.append({"centre": P_w.tolist(), "resting": resting})
        discs.append((uc, vc, r_px))
    return placed if len(placed) == n else None


def _objects(rng, kind: str, support_z: float) -> list:
    """Primitives standing on the support ahead of the camera (and a few to the sides
    and behind it, which only the totems see)."""
    objs = []
    n = int(rng.integers(5, 9))
    for i in range(n):
        behind = i >= n - 2
        dist = rng.uniform(1.5, 3.0) if behind else rng.uniform(2.6, 5.5)
        spread = 28 if kind == "table" and not behind else 40
        ang = rng.uniform(-spread, spread) + (180 if behind else 0)
        size = rng.uniform(0.12, 0.25) if kind == "table" else rng.uniform(0.25, 0.7)
        if kind == "table" and not behind:
            dist = rng.uniform(1.9, 2.8)
        x, y = dist * np.sin(np.radians(ang)), dist * np.cos(np.radians(ang))
        z = (0.0 if behind else support_z)
        objs.append({"shape": str(rng.choice(SHAPES)), "location": [x, y, z + size / 2],
                     "size": float(size), "yaw": float(rng.uniform(0, 360)),
                     "material": _material(rng), "removable": not behind})
    return objs


def describe(seed: int, *, kind: str | None = None, size=(640, 480),
             samples: int = 96) -> dict:
    """The scene of ``seed`` (``kind`` drawn from it unless given) at ``size`` (W, H)."""
    rng = np.random.default_rng([38, int(seed)])
    kind = kind or KINDS[int(rng.integers(len(KINDS)))]
    W, H = int(size[0]), int(size[1])
    cam = _camera(rng, kind, W, H)
    support_z = 0.75 if kind == "table" else 0.0
    radius = float(rng.uniform(0.05, 0.08) if kind == "table" else rng.uniform(0.06, 0.1))
    ior = float(rng.uniform(1.45, 1.55))
    totems = _totems(rng, cam, support_z, radius, int(rng.integers(4, 6)))
    world = ({"hdri": str(rng.choice(HDRIS[:5])),
              "strength": float(rng.uniform(0.8, 1.4)),
              "rotation_deg": float(rng.uniform(0, 360))} if kind == "yard" else
             {"hdri": str(rng.choice(HDRIS[5:])),
              "strength": float(rng.uniform(0.3, 0.7)),
              "rotation_deg": float(rng.uniform(0, 360))} if kind == "table" else
             {"colour": _colour(rng, 0.02, 0.1), "strength": 1.0})
    sun = {"type": "SUN", "energy": float(rng.uniform(1.5, 3.0)),
           "rotation_deg": [float(rng.uniform(20, 50)), 0.0, float(rng.uniform(0, 360))]}
    area = {"type": "AREA", "energy": float(rng.uniform(250, 500)), "size": 2.0,
            "location": [float(rng.uniform(-1, 1)), float(rng.uniform(1.5, 3.5)), 2.8]}
    lights = {"yard": [sun], "table": [sun, area], "room": [area]}[kind]
    view = str(rng.choice(VIEWS))
    return {
        "format": 1, "renderer": "cycles", "kind": kind, "seed": int(seed),
        "camera": cam, "support_z": support_z,
        "key": {"radius": radius, "ior": ior}, "totems": totems,
        "objects": _objects(rng, kind, support_z),
        "floor": _material(rng, str(rng.choice(["checker", "brick", "noise",
                                                 "voronoi"]))),
        "walls": _material(rng) if kind == "room" else None,
        "table": _material(rng, "wave") if kind == "table" else None,
        "world": world, "lights": lights,
        "pipeline": {"view_transform": view, "look": "None",
                     "exposure": float(rng.uniform(-0.3, 0.3)),
                     "denoise": bool(rng.random() < 0.6),
                     "filter": str(rng.choice(["BLACKMAN_HARRIS", "GAUSSIAN"])),
                     "filter_width": float(rng.uniform(1.2, 1.8)),
                     "samples": int(samples), "sampling_seed": int(seed)},
    }
