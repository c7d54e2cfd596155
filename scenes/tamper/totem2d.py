"""The totem views edited by hand: what a forger with an editor, and no key, does to the
totems (issue 61).

``totem-retouch`` (:func:`edit_totem_retouch`): one or more totems retouched, the camera
view untouched. In each, a round patch of the disc (a quarter to 0.45 of its radius,
lying within 0.9 of it) is cloned from elsewhere in the same totem, blurred, or
recoloured, through a soft-edged brush; nothing outside the totem's mask is read or
written.

``consistent-paste`` (:func:`paste_in_totems`, after ``splice`` in the camera view): the
pasted person also pasted into each totem where the naive model of the glass puts it
(:func:`scenes.tamper.forger.naive_image_point`: turned by half a turn and shrunk about
the disc's centre, as a ball lens of index 1.5 shows a far scene), clipped to the totem.

``erase-everywhere`` (:func:`erase_in_totems`, after ``inpaint`` in the camera view):
the removed object's refracted image in every totem, from the truth (its footprint
traced through the true spheres, :func:`object_footprints`, grown by a pixel), filled
from the totem's own neighbouring pixels (:func:`scenes.tamper.edits2d.clone_fill` with
everything outside the totem avoided).

Each returns an :class:`~scenes.tamper.edits.Edit` whose ``totem_mask`` is the totem
pixels it changed and whose record lists, per totem, what was done (``totem_edits``).
Images are 8-bit sRGB (H, W, 3) uint8; pixels (u, v) with centres at integers.
"""

from __future__ import annotations

import numpy as np

from scenes import masks
from scenes.errors import BadInput
from scenes.tamper import edits2d, forger
from scenes.tamper.edits import Edit, Source

__all__ = ["TOOLS", "PATCH_RADII", "INSIDE", "edit_totem_retouch", "erase_in_totems",
           "object_footprints", "paste_in_totems", "retouch"]

TOOLS = ("clone", "blur", "recolour")
PATCH_RADII = (0.25, 0.45)
"""The retouched patch's radius, drawn in this range, in units of the disc's radius."""
INSIDE = 0.9
"""The patch (and a clone's source) lies within this fraction of the disc's radius."""


# --------------------------------------------------------------------------- retouch

def retouch(image, mask, tool: str, rng) -> tuple[np.ndarray, np.ndarray, dict]:
    """One totem retouched by ``tool`` (one of :data:`TOOLS`) in a round patch drawn
    from ``rng``, its brush feathered over a sixth of its radius (at least a pixel).

    Parameters
    ----------
    image : (H, W, 3) uint8 sRGB.
    mask : (H, W) bool, the totem's pixels; nothing outside is read or written.
    tool : "clone" (the patch copied from another place of the disc, at least its own
        radius away), "blur" (Gaussian, sigma a third of the patch's radius, at least a
        pixel) or "recolour" (hue turned by 90-270 degrees, saturation at least 0.35).

    Returns
    -------
    out : (H, W, 3) uint8; footprint : (H, W) bool, the pixels the brush touched (all in
    ``mask``); record : dict.
    """
    cx, cy, r = forger.disc(mask)
    a = float(rng.uniform(*PATCH_RADII))
    room = INSIDE - a                               # where a patch's centre may lie
    src_off = np.zeros(2)
    if tool == "clone":                             # the source patch, then the target
        for _ in range(200):
            length = rng.uniform(a, 2 * room)
            ang = rng.uniform(0, 2 * np.pi)
            src_off = length * np.array([np.cos(ang), np.sin(ang)])
            s = _in_disc(rng, room)
            c = s - src_off
            if np.hypot(*c) <= room:
                break
        else:
            c = -src_off / 2
    else:
        c = _in_disc(rng, room)
    centre = np.array([cx, cy]) + r * c
    radius = a * r
    alpha = edits2d.disc_alpha(mask.shape, centre, radius, max(1.0, radius / 6)) * mask
    record = {"tool": tool, "centre_px": [round(float(v), 2) for v in centre],
              "radius_px": round(radius, 2)}
    if tool == "clone":
        dx, dy = (int(v) for v in np.rint(-src_off * r))
        if (dx, dy) == (0, 0):
            dx = 1
        layer = edits2d.shifted(image, dx, dy)
        alpha = alpha * masks.shift_mask(mask, dx, dy)   # copy only totem pixels
        record["offset_px"] = [dx, dy]
    elif tool == "blur":
        sigma = max(1.0, radius / 3)
        layer = edits2d.blur_within(image, mask, sigma)
        record["sigma_px"] = round(sigma, 2)
    elif tool == "recolour":
        hue = float(rng.uniform(90, 270))
        layer = edits2d.recolour(image, hue, 0.35)
        record["hue_deg"] = round(hue, 1)
    else:
        raise BadInput(f"unknown retouch tool {tool!r}; use one of {', '.join(TOOLS)}")
    out, footprint = edits2d.composite(image, layer, alpha)
    record["pixels"] = int(footprint.sum())
    return out, footprint, record


def _in_disc(rng, radius: float) -> np.ndarray:
    """A point drawn uniformly in the disc of ``radius`` about 0, (2,)."""
    rho, ang = radius * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
    return rho * np.array([np.cos(ang), np.sin(ang)])


def edit_totem_retouch(src: Source, rng) -> Edit:
    """``totem-retouch``: the totems of ``src.options["totems"]`` (indices, left to
    right; drawn: one, or two of four or more, a third of the time, always leaving one
    untouched where there are two or more), each retouched by ``src.options["tool"]``
    (drawn per totem when absent). The camera view is untouched (an empty mask)."""
    n = len(src.scene.masks)
    chosen = src.options.get("totems")
    if chosen is None:
        k = 2 if n >= 4 and rng.uniform() < 1 / 3 else 1
        chosen = sorted(int(j) for j in rng.choice(n, size=k, replace=False))
    else:
        chosen = [int(j) for j in chosen]
        if not chosen or len(set(chosen)) != len(chosen) or \
                any(not 0 <= j < n for j in chosen):
            raise BadInput(f"--totem must name different totems 0-{n - 1} (left to "
                           f"right), got {chosen}")
    tool = src.options.get("tool")
    if tool is not None and tool not in TOOLS:
        raise BadInput(f"unknown retouch tool {tool!r}; use one of {', '.join(TOOLS)}")
    image = src.image
    totem_mask = np.zeros(src.shape, bool)
    edits = []
    for j in chosen:
        t = tool or TOOLS[int(rng.integers(len(TOOLS)))]
        image, touched, rec = retouch(image, src.scene.masks[j], t, rng)
        totem_mask |= touched
        edits.append({"totem": j, **rec})
    return Edit(image, np.zeros(src.shape, bool), {"totem_edits": edits},
                totem_mask=totem_mask)


# --------------------------------------------------------------------------- paste

def paste_in_totems(src: Source, edit: Edit) -> Edit:
    """``consistent-paste``: the camera view's splice (``edit``, by ``splice``: its record
    holds the cutout's ``box`` and ``flip``) pasted into every totem too, where
    :func:`scenes.tamper.forger.naive_image_point` puts the cutout's centre, shrunk by
    :func:`scenes.tamper.forger.naive_scale` (resampled from the full cutout, at least 4
    px tall) and turned by half a turn, its edge feathered by half a pixel, clipped to
    the totem's mask. A totem where none of it lands is listed as not ``visible``."""
    x, y, w, h = edit.record["box"]
    flip = bool(edit.record["flip"])
    p = np.array([x + (w - 1) / 2.0, y + (h - 1) / 2.0])
    f = float(src.scene.K[0, 0])
    rgb, matte = edits2d.astronaut_cutout()
    image = edit.image
    totem_mask = np.zeros(src.shape, bool)
    totem_edits = []
    for j, m in enumerate(src.scene.masks):
        cx, cy, r = forger.disc(m)
        s = forger.naive_scale(r, f)
        q = forger.naive_image_point(p, (cx, cy), r, f)
        small, cover = edits2d.scaled_cutout(rgb, matte, round(h * s), flip=flip)
        small, cover = small[::-1, ::-1].copy(), cover[::-1, ::-1].copy()   # half a turn
        hs, ws = cover.shape
        x0, y0 = int(round(q[0] - (ws - 1) / 2.0)), int(round(q[1] - (hs - 1) / 2.0))
        image, fp = edits2d.splice(image, small, cover, x0, y0, feather_px=0.5, keep=~m)
        fp &= m
        totem_mask |= fp
        totem_edits.append({"totem": j, "visible": bool(fp.any()), "box": [x0, y0, ws, hs],
                            "scale": round(s, 5), "pixels": int(fp.sum())})
    record = dict(edit.record, totem_model={"model": "paraxial ball lens, far scene",
                                            "ior": forger.GUESSED_IOR},
                  totem_edits=totem_edits)
    return Edit(image, edit.mask, record, totem_mask=totem_mask)


# --------------------------------------------------------------------------- erase

def object_footprints(src: Source) -> dict[int, np.ndarray]:
    """Each removable object's refracted image in the totems, from the truth: object id
    -> (H, W) bool, the totem pixels (of the folder's masks) whose ray, traced through
    its true sphere (:func:`scenes.synthetic.trace.totem_hits`), lands on it first.
    Objects no totem pixel sees are left out. Needs ``src.truth``."""
    from scenes.synthetic import trace   # Mitsuba: loaded only when a scene is traced

    desc = src.truth.scene
    t = trace.tracer(desc)
    _, _, ids = trace.camera_points(desc, t)
    hits = trace.totem_hits(desc, ids, t)
    H, W = src.shape
    inside = src.totems[np.clip(hits.v, 0, H - 1), np.clip(hits.u, 0, W - 1)]
    out = {}
    for obj in desc["objects"]:
        sel = inside & (hits.hit_id == obj["id"])
        if obj.get("removable") and sel.any():
            fp = np.zeros((H, W), bool)
            fp[hits.v[sel], hits.u[sel]] = True
            out[int(obj["id"])] = fp
    return out


def erase_in_totems(src: Source, edit: Edit, footprint: np.ndarray, *,
                    grow_px: int = 1) -> Edit:
    """``erase-everywhere``: the camera view's removal (``edit``, by ``inpaint``) carried
    into every totem: the object's refracted ``footprint`` ((H, W) bool, from
    :func:`object_footprints`), grown by ``grow_px``, filled in each totem from that
    totem's own pixels (:func:`scenes.tamper.edits2d.clone_fill`, everything outside
    the totem avoided: a sideways clone of the totem's texture where one fits inside the
    disc, its seam blended into an inpainting of the totem's pixels)."""
    image = edit.image
    H, W = src.shape
    totem_mask = np.zeros((H, W), bool)
    totem_edits = []
    for j, m in enumerate(src.scene.masks):
        fill = masks.dilate(footprint & m, grow_px) & m
        if not fill.any():
            totem_edits.append({"totem": j, "visible": False})
            continue
        x, y, w, h = masks.bbox(m)
        ys = slice(max(y - 2, 0), min(y + h + 2, H))
        xs = slice(max(x - 2, 0), min(x + w + 2, W))
        out, _, offset = edits2d.clone_fill(image[ys, xs], fill[ys, xs],
                                            avoid=~m[ys, xs], feather_px=1.0)
        image = image.copy()
        image[ys, xs] = out
        totem_mask |= fill
        totem_edits.append({"totem": j, "visible": True, "pixels": int(fill.sum()),
                            "method": "clone+telea" if offset else "telea"})
    record = dict(edit.record, totem_edits=totem_edits, totem_grow_px=int(grow_px))
    return Edit(image, edit.mask, record, totem_mask=totem_mask)
