"""``rekey``: the adaptive forger, who re-renders the totems too, with a key guessed.

The forger makes the perfect forger's edit (:mod:`scenes.tamper.tamper3d`: an object
removed, or a new one inserted, the scene rendered again by Mitsuba with the source's
sampler) and carries it into every totem by rendering the glass as well, but with the
key it guessed (:class:`scenes.tamper.forger.KeyGuess`: each totem's index of refraction
and radius off by the chosen amounts, its centre posed from its mask's outline and the
guessed radius, or on the true outline's cone):

- the camera view outside the totems: the perfect forger's, from the true scene
  (:func:`scenes.tamper.tamper3d.composite_view`);
- the totem pixels (the true masks): the source's plus what the edit changes in the
  forger's own renders, ``source + render(edited, guessed spheres) - render(scene,
  guessed spheres)`` in 8-bit levels, clipped, wherever the two renders differ (a
  difference layer: outside the change the totems keep the source's pixels, so only
  the change is drawn through the wrong glass).

With no error at all (``ior=0,radius=0,pose=exact``) the guessed spheres are the true
ones and the totem pixels are the render of the edited scene, bit for bit where the
source is its own render: the perfect forger who holds the key, whom no method can
catch. Four renders (two where the spheres are the true ones).
"""

from __future__ import annotations

import copy

import numpy as np

from scenes import camera
from scenes.errors import BadInput
from scenes.tamper import forger, tamper3d
from scenes.tamper.edits import Edit, Source

__all__ = ["EDITS", "edit_rekey", "mask_order", "with_totems"]

EDITS = ("remove", "insert")


def mask_order(masks, K, centres) -> list[int]:
    """For each sphere centre (m, 3) (camera frame, metres), the index of the mask (n,
    H, W) holding its projection (else the mask whose centroid is nearest it), pixels
    by ``K``. Raises BadInput when two spheres fall to one mask."""
    uv = camera.project(np.asarray(K, np.float64), np.asarray(centres, np.float64))
    H, W = masks.shape[1:]
    cents = np.array([np.argwhere(m)[:, ::-1].mean(0) for m in masks])
    order = []
    for u, v in uv:
        iu, iv = int(round(u)), int(round(v))
        inside = [j for j, m in enumerate(masks) if 0 <= iu < W and 0 <= iv < H and m[iv, iu]]
        order.append(inside[0] if inside else
                     int(np.argmin(np.linalg.norm(cents - [u, v], axis=1))))
    if len(set(order)) != len(order):
        raise BadInput("truth/scene.json's totems do not match the folder's totem masks "
                       "one to one")
    return order


def with_totems(desc: dict, spheres) -> dict:
    """A copy of the description ``desc`` with its totems replaced by ``spheres`` (dicts
    ``{"center", "radius", "ior"}``, in ``desc["totems"]``'s order)."""
    out = copy.deepcopy(desc)
    out["totems"] = [{**t, **{k: s[k] for k in ("center", "radius", "ior")}}
                     for t, s in zip(desc["totems"], spheres)]
    return out


def edit_rekey(src: Source, rng) -> Edit:
    """``rekey``: ``src.options["edit"]`` (``remove``, of the object seen most in the
    region if one is given, or ``insert``; drawn when absent, ``remove`` with a region)
    made in the camera view and in the totems, the totems through the spheres of
    ``src.options["key_error"]`` (a :class:`~scenes.tamper.forger.KeyGuess`; no error
    and the pose from the masks when absent). Needs ``src.truth`` with objects."""
    guess = forger.parse_key_error(src.options.get("key_error"))
    kind = src.options.get("edit") or ("remove" if src.region is not None
                                       else EDITS[int(rng.integers(len(EDITS)))])
    if kind not in EDITS:
        raise BadInput(f"rekey's --edit must be one of {', '.join(EDITS)}, got {kind!r}")
    if kind == "insert" and src.region is not None:
        raise BadInput("a region applies to rekey's remove (the object to take), not to "
                       "its insert")
    plan = (tamper3d.plan_remove if kind == "remove" else tamper3d.plan_insert)(src, rng)
    base, new = tamper3d.rerender(src, plan)
    view = tamper3d.composite_view(src, plan, base, new)

    desc = src.truth.scene
    true = desc["totems"]
    masks = src.scene.masks
    if len(true) != len(masks):
        raise BadInput(f"truth/scene.json has {len(true)} totems but the folder "
                       f"{len(masks)} totem masks")
    order = mask_order(masks, src.scene.K, [t["center"] for t in true])
    spheres = forger.guessed_spheres(masks[order], src.scene.K, true, guess)
    if guess.exact:                        # the true spheres: the renders are made
        g_base, g_new = base, new
    else:
        g_base, g_new = tamper3d.rerender(
            src, tamper3d.Plan(with_totems(plan.new_desc, spheres), plan.exclude_ids,
                               plan.footprint, plan.record),
            base_desc=with_totems(desc, spheres))

    delta = g_new.astype(np.int16) - g_base.astype(np.int16)
    drawn = src.totems & (delta != 0).any(axis=-1)
    totem_px = np.clip(view.image.astype(np.int16) + delta, 0, 255).astype(np.uint8)
    image = np.where(drawn[..., None], totem_px, view.image)
    totem_mask = src.totems & (image != src.image).any(axis=-1)

    per_totem = []
    for k, (t, s) in enumerate(zip(true, spheres)):
        j = order[k]
        per_totem.append({
            "totem": j, "guessed": {"center": [round(c, 6) for c in s["center"]],
                                    "radius": round(s["radius"], 6),
                                    "ior": round(s["ior"], 6)},
            "center_error_m": round(float(np.linalg.norm(
                np.subtract(s["center"], t["center"]))), 6),
            "pixels": int((totem_mask & masks[j]).sum())})
    per_totem.sort(key=lambda e: e["totem"])
    record = dict(view.record, edit=kind, key_error=guess.to_dict(), totems=per_totem)
    return Edit(image, view.mask, record, totem_mask=totem_mask)
