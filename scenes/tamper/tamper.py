"""Manipulated copies of a scene folder: the forgeries the verifier must catch.

``tamper(scene_dir, out, kind=...)`` writes a copy of ``scene_dir`` whose ``image.png``
is edited, with ``manip_mask.png`` (white = changed camera-view pixels) and a record of
the edit in ``truth/tamper.json``. The input folder is never modified; the copy is
built under a temporary name and renamed when complete.

Kinds (the totems paper, Sec. 5 "Image manipulations", and its supplementary):

``color``    randomly coloured rectangles of several sizes pasted above the totems.
``splice``   a person cut from another photograph (scikit-image's ``astronaut``) pasted
             with a soft edge.
``inpaint``  an object of the scene removed and its footprint filled by a clone of
             nearby texture blended into OpenCV inpainting (the stand-in for
             Photoshop's content-aware fill).
``shift``    the reference shift: an object moved in the camera view and, by 2D edits,
             in every totem view to where the same reference point appears there.
``remove``   the perfect forger: the camera view re-rendered without an object, the
             totem pixels kept as they were (no blending trace; only geometry tells).
``insert``   the same with a new object added on the floor.

The forgers who edit the totems too (issue 61, :data:`TOTEM_KINDS`):

``totem-retouch``     one or more totems retouched by hand (a patch cloned from elsewhere
                      in the same totem, blurred or recoloured), the camera view
                      untouched (:mod:`scenes.tamper.totem2d`).
``consistent-paste``  a ``splice``, also pasted shrunk and turned into every totem where
                      a naive model of the glass puts it (:mod:`scenes.tamper.forger`).
``erase-everywhere``  an ``inpaint`` of an object that a totem sees, and its refracted
                      image (from the truth) inpainted out of every totem from the
                      totem's own pixels.
``rekey``             the adaptive forger: ``remove`` or ``insert`` re-rendered in the
                      camera view and in the totems, the glass with a guessed key
                      (:mod:`scenes.tamper.rekey`).

``color``, ``splice``, ``inpaint``, ``totem-retouch`` and ``consistent-paste`` also work
on a real photo (no ``truth/``; ``inpaint`` in a ``region``); the others need
``truth/scene.json`` to render or trace the scene again. Totem pixels are changed only
by ``shift`` and the kinds of :data:`TOTEM_KINDS`, whose totem edits are listed in
``tamper.json`` and drawn in ``truth/tamper_totem_mask.png``.

Images are handled as the 8-bit sRGB values of the file, so pixels outside the mask
are the source's bit for bit. The copy's photo is always ``image.png``, also for a
source with ``image.jpg``: a forger re-saves the decoded pixels (losslessly here).

This module holds the verb (:func:`tamper`, :func:`parse_region`, the table of kinds,
the writing of the copy) and the 2D editors of the camera view (with, for
``consistent-paste`` and ``erase-everywhere``, their totem halves from
:mod:`scenes.tamper.totem2d`). The re-rendering editors are in
:mod:`scenes.tamper.tamper3d` and :mod:`scenes.tamper.rekey`, loaded (with Mitsuba) only
for those kinds; what all share
(:class:`~scenes.tamper.edits.Edit`, :class:`~scenes.tamper.edits.Source`, the target zone,
the choice of an object) is in :mod:`scenes.tamper.edits`, the pixel tools in
:mod:`scenes.tamper.edits2d`.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from scenes import folder, masks
from scenes.errors import BadInput
from scenes.tamper import edits2d
from scenes.tamper.edits import Edit, Source, pick_object, target_zone

__all__ = ["FORMAT", "KINDS", "TOTEM_KINDS", "NEEDS_TRUTH", "REGION_KINDS", "OPTIONS",
           "edit_color", "edit_consistent_paste", "edit_erase_everywhere", "edit_inpaint",
           "edit_splice", "parse_region", "tamper"]

TOTEM_KINDS = ("totem-retouch", "consistent-paste", "erase-everywhere", "rekey")
"""The forgers who edit the totems as well as (or instead of) the camera view."""
KINDS = ("color", "splice", "inpaint", "shift", "remove", "insert") + TOTEM_KINDS
NEEDS_TRUTH = ("shift", "remove", "insert", "erase-everywhere", "rekey")
REGION_KINDS = ("color", "splice", "inpaint", "remove", "consistent-paste",
                "erase-everywhere", "rekey")
"""The kinds a region applies to (where to paste or fill, or which object to take;
``rekey`` only with its edit ``remove``)."""
OPTIONS = {"tool": ("totem-retouch", "--tool"), "totems": ("totem-retouch", "--totem"),
           "key_error": ("rekey", "--key-error"), "edit": ("rekey", "--edit")}
"""The kinds' own options: argument of :func:`tamper` -> (its kind, its flag)."""
FORMAT = 1


# --------------------------------------------------------------------------- public

def tamper(scene_dir, out, *, kind: str, seed: int = 0, region=None, tool=None,
           totems=None, key_error=None, edit=None) -> Path:
    """Write a manipulated copy of the scene folder ``scene_dir`` at ``out``.

    Parameters
    ----------
    scene_dir : a scene folder (``docs/contract.md``).
    out : the new folder; must not exist (or be empty).
    kind : one of :data:`KINDS`.
    seed : random seed; the same seed gives the same forgery, bit for bit.
    region : where to edit, for the kinds of :data:`REGION_KINDS`: ``(x, y, w, h)``
        in pixels or an (H, W) bool mask (``remove``, ``erase-everywhere`` and
        ``rekey``'s ``remove`` take the object seen most in it). Needed by ``inpaint``
        on a photo without ``truth/``; otherwise the edit goes above the totems, in the
        middle of the image.
    tool, totems : ``totem-retouch``'s tool (``clone``, ``blur`` or ``recolour``) and
        the totems it retouches (indices, left to right); drawn per seed when None.
    key_error : ``rekey``'s guessed key, as its error: ``"ior=0.02,radius=0.03"`` (and
        ``pose=mask|exact``), a dict, or a :class:`scenes.tamper.forger.KeyGuess`; None
        is no error with the pose from the masks.
    edit : ``rekey``'s edit, ``remove`` or ``insert``; drawn per seed when None.

    Returns
    -------
    Path of the written folder.

    Raises
    ------
    BadInput for an unknown kind, a bad region or option (or one the kind does not
    take), a scene that cannot be read, or a kind that needs ``truth/scene.json`` on a
    scene without it.
    """
    if kind not in KINDS:
        raise BadInput(f"unknown tamper kind {kind!r}; use one of {', '.join(KINDS)}")
    options = {k: v for k, v in dict(tool=tool, totems=totems, key_error=key_error,
                                     edit=edit).items() if v is not None}
    for name in options:
        owner, flag = OPTIONS[name]
        if owner != kind:
            raise BadInput(f"{flag} applies to --kind {owner}, not to {kind}")
    if kind == "rekey":
        from scenes.tamper.forger import parse_key_error
        options["key_error"] = parse_key_error(key_error)
    scene_dir = Path(scene_dir)
    out = Path(out)
    if out.resolve() == scene_dir.resolve():
        raise BadInput("the output folder must differ from the scene folder "
                       "(inputs are never modified)")
    scene = folder.read_scene(scene_dir)
    truth = folder.read_truth(scene_dir)
    if kind in NEEDS_TRUTH and (truth is None or not truth.scene.get("objects")):
        raise BadInput(f"--kind {kind} re-renders or traces the scene and needs "
                       f"truth/scene.json (a scene made by `totems scene make`); "
                       f"{scene_dir} has none: use color, splice, inpaint, "
                       f"totem-retouch or consistent-paste")
    if region is not None and kind not in REGION_KINDS:
        raise BadInput(f"a region applies to {', '.join(REGION_KINDS)}, not to {kind}")
    image = _read_uint8(folder.photo_path(scene_dir))
    totems = scene.masks.any(axis=0)
    src = Source(scene_dir, image, scene, truth, totems,
                 parse_region(region, image.shape[:2], totems), options)
    rng = np.random.default_rng([int(seed), KINDS.index(kind)])
    edit = _editor(kind)(src, rng)
    if not (edit.mask.any() or (edit.totem_mask is not None and edit.totem_mask.any())):
        raise BadInput(f"the {kind} edit changed no pixel of {scene_dir}; "
                       f"try another seed or region")
    edit.record.update(kind=kind, seed=int(seed))
    return _write_copy(src, out, edit)


def parse_region(region, shape, totems=None) -> np.ndarray | None:
    """A region given as ``(x, y, w, h)`` (pixels) or an (H, W) bool mask, as a mask.

    Totem pixels are taken out of it (totems are left as they are). Raises BadInput
    for anything else, for a rectangle that is not inside the image, or for a region
    with no pixel outside the totems.
    """
    if region is None:
        return None
    H, W = shape
    if isinstance(region, (str, Path)):
        region = folder.read_mask(region, what="region mask")
    arr = np.asarray(region)
    if arr.ndim == 2:
        if arr.shape != (H, W):
            raise BadInput(f"region mask is {arr.shape[1]}x{arr.shape[0]} but the photo "
                           f"is {W}x{H}")
        mask = arr.astype(bool)
    else:
        try:
            x, y, w, h = (float(v) for v in np.ravel(arr))
        except (TypeError, ValueError):
            raise BadInput(f"region must be x,y,w,h in pixels or a mask, got {region!r}") \
                from None
        if not all(np.isfinite([x, y, w, h])) or any(v != int(v) for v in (x, y, w, h)):
            raise BadInput(f"region x,y,w,h must be whole pixels, got {region!r}")
        x, y, w, h = int(x), int(y), int(w), int(h)
        if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > W or y + h > H:
            raise BadInput(f"region {x},{y},{w},{h} is not inside the {W}x{H} photo "
                           f"(x,y = top-left corner, w,h > 0)")
        mask = np.zeros((H, W), bool)
        mask[y:y + h, x:x + w] = True
    if totems is not None:
        mask &= ~totems
    if mask.sum() < 4:
        raise BadInput("the region has no pixels outside the totems; give a region "
                       "of the photo to edit")
    return mask


# --------------------------------------------------------------------------- 2D kinds

def edit_color(src: Source, rng) -> Edit:
    """Randomly coloured rectangles, two to four, of several sizes (paper Sec. 5)."""
    H, W = src.shape
    area = src.region if src.region is not None else target_zone(src.totems)
    x0, y0, w0, h0 = masks.bbox(area)
    n = int(rng.integers(2, 5))
    # Sides of 5-14% of the image's scale (each patch 0.25-2% of it), or 20-50% of
    # a region's.
    lo, hi, scale = (0.2, 0.5, np.sqrt(float(area.sum()))) if src.region is not None \
        else (0.05, 0.14, np.sqrt(float(H * W)))
    sizes = np.sort(rng.uniform(lo, hi, n))[::-1] * scale
    boxes, colors = [], []
    for s in sizes:
        aspect = rng.uniform(0.6, 1.6)
        w = int(np.clip(round(s * aspect), 2, w0))
        h = int(np.clip(round(s / aspect), 2, h0))
        x = int(x0 + rng.integers(0, w0 - w + 1))
        y = int(y0 + rng.integers(0, h0 - h + 1))
        boxes.append((x, y, w, h))
        colors.append([int(c) for c in rng.integers(0, 256, 3)])
    image, mask = edits2d.paste_patches(src.image, boxes, colors, keep=~area)
    return Edit(image, mask, {"patches": [{"box": b, "rgb": c}
                                          for b, c in zip(boxes, colors)]})


def edit_splice(src: Source, rng) -> Edit:
    """A person from another photograph pasted with a feathered edge.

    Without a region the person stands just above the totems, about a third of the
    image tall (a few per cent of the pixels); with one, they fill the region's box.
    """
    H, W = src.shape
    rgb, matte = edits2d.astronaut_cutout()
    flip = bool(rng.integers(0, 2))
    aspect = matte.shape[1] / matte.shape[0]
    if src.region is not None:
        x0, y0, w0, h0 = masks.bbox(src.region)
        h = int(min(h0, w0 / aspect))
        small, cover = edits2d.scaled_cutout(rgb, matte, h, flip=flip)
        x = x0 + int(rng.integers(0, max(w0 - small.shape[1], 0) + 1))
        y = y0 + int(rng.integers(0, max(h0 - small.shape[0], 0) + 1))
        area = src.region
    else:
        zone = target_zone(src.totems)
        x0, y0, w0, h0 = masks.bbox(zone)
        h = int(min(rng.uniform(0.28, 0.38) * H, h0, w0 / aspect))
        small, cover = edits2d.scaled_cutout(rgb, matte, h, flip=flip)
        x = x0 + int(rng.integers(0, max(w0 - small.shape[1], 0) + 1))
        y = y0 + h0 - small.shape[0]                # feet (cut) just above the totems
        area = ~src.totems
    feather = max(1.0, 0.002 * W)
    image, mask = edits2d.splice(src.image, small, cover, x, y, feather_px=feather,
                                 keep=~area)
    return Edit(image, mask, {"source": "skimage.data.astronaut", "box":
                              [x, y, small.shape[1], small.shape[0]], "flip": flip,
                              "feather_px": feather})


def edit_inpaint(src: Source, rng, *, only=None) -> Edit:
    """An object removed and its place filled from nearby texture (content-aware
    fill's stand-in: :func:`edits2d.clone_fill`).

    With ``truth/scene.json`` and no region, the object is a removable one of the
    scene (of the ids ``only``, if given; the region then only chooses it) and the fill
    covers its footprint in the camera view; otherwise the region.
    """
    H, W = src.shape
    record = {}
    avoid = src.totems
    if src.region is not None and only is None:
        fill = src.region
    elif src.truth is not None and src.truth.scene.get("objects"):
        from scenes.synthetic import render
        ids = render.shape_ids(src.truth.scene, totems=True)
        obj, footprint = pick_object(src, rng, ids=ids, only=only)
        grow = max(1, round(0.004 * W))
        fill = masks.dilate(footprint, grow) & ~src.totems
        # texture is copied from the room, not from the other objects
        movable = [o["id"] for o in src.truth.scene["objects"] if o.get("removable")]
        avoid = avoid | masks.dilate(np.isin(ids, movable), grow)
        record["object"] = {"id": obj["id"], "name": obj.get("name")}
    else:
        raise BadInput("inpaint on a photo without truth/scene.json needs --region "
                       "x,y,w,h or --region-mask FILE (the thing to remove)")
    image, mask, offset = edits2d.clone_fill(src.image, fill, avoid=avoid & ~fill,
                                             feather_px=max(2.0, 0.005 * W))
    record["method"] = "clone+telea" if offset else "telea"
    record["clone_offset_px"] = offset
    return Edit(image, mask, record)


# --------------------------------------------------------------------------- totems too

def edit_consistent_paste(src: Source, rng) -> Edit:
    """``consistent-paste``: :func:`edit_splice`, and the person pasted into every totem
    too where the naive model of the glass puts it
    (:func:`scenes.tamper.totem2d.paste_in_totems`)."""
    from scenes.tamper import totem2d

    return totem2d.paste_in_totems(src, edit_splice(src, rng))


def edit_erase_everywhere(src: Source, rng) -> Edit:
    """``erase-everywhere``: :func:`edit_inpaint` of a removable object that a totem
    sees (in the region, if given), and its refracted image, traced from the truth,
    filled out of every totem from the totem's own pixels
    (:func:`scenes.tamper.totem2d.erase_in_totems`)."""
    from scenes.tamper import totem2d

    footprints = totem2d.object_footprints(src)
    edit = edit_inpaint(src, rng, only=set(footprints))
    return totem2d.erase_in_totems(src, edit, footprints[edit.record["object"]["id"]])


# --------------------------------------------------------------------------- helpers

def _read_uint8(path: Path) -> np.ndarray:
    """The 8-bit sRGB values of ``path`` exactly (read_image gives k / 255)."""
    return np.rint(folder.read_image(path, what="photo") * 255.0).astype(np.uint8)


# --------------------------------------------------------------------------- writing

def _copy_files(src_dir: Path) -> dict[str, bytes]:
    """The scene folder's files of the contract, by relative path, as bytes."""
    files = {"calib.npy": folder.find_calib(src_dir).read_bytes(),
             "totems.json": (src_dir / "totems.json").read_bytes()}
    if (src_dir / "initial_totem_pose.npy").is_file():
        files["initial_totem_pose.npy"] = (src_dir / "initial_totem_pose.npy").read_bytes()
    return {**files, **folder.read_parts(src_dir)}


def _write_copy(src: Source, out: Path, edit: Edit) -> Path:
    """The copy of the folder with the edited image, staged and renamed when done."""
    files = _copy_files(src.path)
    mask = edit.mask & ~src.totems
    manip = mask
    totem_mask = None if edit.totem_mask is None else edit.totem_mask & src.totems
    all_totem = totem_mask
    history = []
    if src.scene.manip_mask is not None:           # forging a forgery: masks add up
        manip = manip | src.scene.manip_mask
        old = files.get("truth/tamper.json")
        if old:
            prev = json.loads(old)
            history = prev.get("history", []) + [{k: v for k, v in prev.items()
                                                  if k != "history"}]
    old_totem = src.path / "truth" / "tamper_totem_mask.png"
    if old_totem.is_file():
        prev_mask = folder.read_mask(old_totem, what="truth/tamper_totem_mask.png")
        all_totem = prev_mask if all_totem is None else all_totem | prev_mask
    H, W = src.shape
    record = {"format": FORMAT, **edit.record,
              "source": {"folder": src.path.name,
                         "image_sha256": hashlib.sha256(
                             folder.photo_path(src.path).read_bytes()).hexdigest()},
              "changed_pixels": int(mask.sum()),
              "changed_fraction": round(float(mask.sum()) / (H * W), 6),
              "bbox": list(masks.bbox(mask)) if mask.any() else None,
              "totems_edited": totem_mask is not None}
    if totem_mask is not None:
        record["totem_mask"] = "truth/tamper_totem_mask.png"
        record["totem_changed_pixels"] = int(totem_mask.sum())
    if history:
        record["history"] = history
    with folder.staged_folder(out) as tmp:
        for rel, data in files.items():
            folder.write_bytes(tmp / rel, data)
        folder.write_image(tmp / "image.png", edit.image)
        folder.write_image(tmp / "manip_mask.png", manip)
        if all_totem is not None:
            folder.write_image(tmp / "truth" / "tamper_totem_mask.png", all_totem)
        folder.write_json(tmp / "truth" / "tamper.json", record)
    return out


def _editor(kind: str):
    """The function making a ``kind`` of edit: ``(Source, rng) -> Edit``."""
    if kind in ("shift", "remove", "insert"):
        from scenes.tamper import tamper3d  # imports render (Mitsuba) only when needed
        return {"shift": tamper3d.edit_shift, "remove": tamper3d.edit_remove,
                "insert": tamper3d.edit_insert}[kind]
    if kind == "totem-retouch":
        from scenes.tamper import totem2d
        return totem2d.edit_totem_retouch
    if kind == "rekey":
        from scenes.tamper import rekey
        return rekey.edit_rekey
    return {"color": edit_color, "splice": edit_splice, "inpaint": edit_inpaint,
            "consistent-paste": edit_consistent_paste,
            "erase-everywhere": edit_erase_everywhere}[kind]
