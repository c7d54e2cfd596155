"""report.html and bench.html: one self-contained page each, for people to read.

Both are rendered by Jinja2 with autoescape on from ``verify/report/templates/``; every
picture is embedded as a data: URI (downscaled so its long side is at most ``MAX_SIDE`` px),
and a Content-Security-Policy in the page forbids loading anything, so a page opened from a
mail or a share makes no request. The pages hold no absolute path (``unpath``) and no value
of the key: the fitted totems are drawn as outlines in a picture, the radius never written
as a number, and the IoR is not known here.
"""

from __future__ import annotations

import base64
import functools
import io
import re

import numpy as np

from verify.metrics.patches import METRICS
from verify.report.findings import Report

__all__ = ["MAX_SIDE", "METRIC_WORDS", "environment", "data_uri", "png_uri", "unpath",
           "render_report", "render_bench", "markdown_blocks", "agreement_picture"]

MAX_SIDE = 800
"""Longest side (px) of an embedded picture; larger ones are downscaled."""

TOTEM_SIDE = 240
"""Longest side (px) of a totem's close-up; MAX_ZOOM caps its enlargement."""
MAX_ZOOM = 6.0
JPEG_QUALITY = 85
MASK_RGB = (1.0, 0.15, 0.85)        # the totem mask's outline (sRGB)
FIT_RGB = (0.1, 1.0, 1.0)           # the fitted sphere's outline (sRGB)
REGION_RGB = (1.0, 0.85, 0.1)       # the protected region's edge (sRGB)
NAMED_RGB = (1.0, 0.1, 0.1)         # the circle round a named totem's region (sRGB)
WORST_RGB = (1.0, 1.0, 1.0)         # the circle round another totem's worst region

METRIC_WORDS = {
    "L1": "colour difference from the re-rendered view (NeRF units: 2x sRGB)",
    "SSIM": "structural difference from the re-rendered view (1 - SSIM)",
    "CHROMA": "hues the re-rendered view shows nowhere nearby",
    "RANGE": "colours, brightness included, outside the re-rendered view's range nearby and unseen by the totems along the ray",
    "CORROB": "hues the totems' rays do not see along the pixel's ray (two where two reach)",
    "UNSEEN": "hues neither the re-rendered view nor the totems' rays show",
    "ABSENT": "hues three totems saw in front of the surface that the photo lacks",
}
"""One line per heatmap (:data:`verify.metrics.patches.METRICS`) for the page's legends."""

REGION_WORDS = {"filled": "the well-seen pixels, gaps closed and holes filled",
                "hull": "the convex hull of the well-seen pixels (as the paper)"}

PLOT_WORDS = {"ap_per_kind.png": "Patch AP per manipulation, every heatmap",
              "recon_per_preset.png": "Reconstruction L1 per preset and pose mode",
              "time_per_stage.png": "Time per stage (s, mean over joint runs)",
              "totems_study.png": "Reconstruction L1 against the number of totems"}

_PATH = re.compile(r"(?<![^\s'\"(\[=:])(?:/[^\s/:'\"<>|,;()]+)+/?")
"""An absolute path: "/" after a start, space, quote, bracket, "=" or ":", up to a space."""


@functools.lru_cache(maxsize=1)
def environment():
    """The Jinja2 environment of the package's templates; autoescape always on."""
    import jinja2

    return jinja2.Environment(loader=jinja2.PackageLoader("verify.report", "templates"),
                              autoescape=True, undefined=jinja2.StrictUndefined,
                              trim_blocks=True, lstrip_blocks=True)


def unpath(text) -> str:
    """``text`` with every absolute path shortened to its last component."""
    return _PATH.sub(lambda m: m.group(0).rstrip("/").rsplit("/", 1)[-1], str(text))


# --------------------------------------------------------------------------- pictures

def _u8(image: np.ndarray) -> np.ndarray:
    """sRGB [0, 1] float, bool or uint8 as uint8."""
    a = np.asarray(image)
    if a.dtype == bool:
        return a.astype(np.uint8) * 255
    if a.dtype == np.uint8:
        return a
    return (np.clip(np.nan_to_num(a), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def data_uri(image: np.ndarray, *, fmt: str = "JPEG", max_side: int = MAX_SIDE) -> str:
    """A picture as a ``data:`` URI, downscaled so its long side is <= ``max_side`` px.

    ``image``: (H, W, 3) sRGB [0, 1] (or uint8), or (H, W) bool (a mask, sent as a 1-bit
    PNG). ``fmt``: "JPEG" or "PNG" for colour pictures.
    """
    from PIL import Image

    a = np.asarray(image)
    im = Image.fromarray(_u8(a))
    scale = max_side / max(im.size)
    if scale < 1.0:
        size = (max(1, round(im.width * scale)), max(1, round(im.height * scale)))
        im = im.resize(size, Image.NEAREST if a.dtype == bool else Image.LANCZOS)
    buf = io.BytesIO()
    if a.dtype == bool:
        im.convert("1").save(buf, format="PNG", optimize=True)
        fmt = "PNG"
    elif fmt == "JPEG":
        im.save(buf, format="JPEG", quality=JPEG_QUALITY, optimize=True)
    else:
        im.save(buf, format="PNG", optimize=True)
    return f"data:image/{fmt.lower()};base64,{base64.b64encode(buf.getvalue()).decode()}"


def png_uri(data: bytes, *, max_side: int = MAX_SIDE) -> str:
    """A PNG file's bytes as a ``data:`` URI, re-encoded smaller if a side > max_side."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        if max(im.size) > max_side:
            return data_uri(np.asarray(im.convert("RGB")), fmt="PNG", max_side=max_side)
    return f"data:image/png;base64,{base64.b64encode(data).decode()}"


def _edge(mask: np.ndarray, width: int) -> np.ndarray:
    """The inner band of ``width`` px along a (H, W) bool mask's boundary."""
    from scipy import ndimage

    if not mask.any():
        return mask
    return mask & ~ndimage.binary_erosion(mask, iterations=width, border_value=1)


def _resize_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A (H, W) bool mask resampled to ``size`` (W, H) px: bilinear, cut at one half."""
    from PIL import Image

    return np.asarray(Image.fromarray(_u8(mask)).resize(size, Image.BILINEAR)) > 127


def region_picture(image: np.ndarray, protected: np.ndarray) -> np.ndarray:
    """The photo dimmed outside the protected region, its edge drawn: (H, W, 3) sRGB."""
    out = np.asarray(image, np.float32).copy()
    out[~protected] *= 0.3
    width = max(2, round(2 * max(protected.shape) / MAX_SIDE))
    out[_edge(protected, width)] = REGION_RGB
    return out


def depth_picture(image: np.ndarray, depth: np.ndarray):
    """The depth the totems establish over the photo in grey: ``depth`` (H, W) metres,
    NaN where none, coloured by inverse depth (turbo, red near, blue far, between its 2nd
    and 98th percentiles). Returns the (H, W, 3) sRGB picture and (near, far) in metres,
    or (None, None) where no pixel has a depth."""
    from verify.metrics.patches import colorize, luma

    z = np.asarray(depth, np.float64)
    has = np.isfinite(z) & (z > 0)
    if not has.any():
        return None, None
    near, far = np.percentile(z[has], [2, 98])
    inv = np.where(has, 1.0 / np.where(has, z, 1.0), 0.0)
    t = (inv - 1.0 / far) / max(1.0 / near - 1.0 / far, 1e-12)
    grey = np.repeat(luma(image)[..., None], 3, 2)
    out = 0.5 * grey
    turbo = 0.12 + 0.83 * np.clip(t[has], 0.0, 1.0)      # its blue to its red, no ends
    out[has] = 0.25 * grey[has] + 0.75 * colorize(turbo, 1.0)
    return out, (float(near), float(far))


def _close_up_box(mask: np.ndarray):
    """(y0, y1, x0, x1): the bounding box of ``mask`` (H, W) with a margin of 30 % of its
    larger side (at least 4 px), inside the image; None for an empty mask."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return None
    H, W = mask.shape
    m = max(4, int(0.3 * max(np.ptp(rows), np.ptp(cols))))
    return (max(0, rows.min() - m), min(H, rows.max() + m + 1),
            max(0, cols.min() - m), min(W, cols.max() + m + 1))


def totem_picture(image: np.ndarray, totem_mask: np.ndarray, silhouette: np.ndarray):
    """A close-up of one totem: the photo with the masks' outline and the fitted sphere's
    outline, (h, w, 3) sRGB, at most ``TOTEM_SIDE`` px; None when the sphere's image
    misses the photo. ``silhouette`` (H, W) bool, the fitted sphere's image."""
    from PIL import Image

    box = _close_up_box(silhouette)
    if box is None:
        return None
    y0, y1, x0, x1 = box
    crop = _u8(np.asarray(image)[y0:y1, x0:x1])
    zoom = min(MAX_ZOOM, TOTEM_SIDE / max(crop.shape[:2]))
    size = (max(1, round(crop.shape[1] * zoom)), max(1, round(crop.shape[0] * zoom)))
    out = np.asarray(Image.fromarray(crop).resize(size, Image.LANCZOS)) / 255.0
    for mask, rgb, width in ((totem_mask, MASK_RGB, 4), (silhouette, FIT_RGB, 2)):
        out[_edge(_resize_mask(mask[y0:y1, x0:x1], size), width)] = rgb
    return out


def agreement_picture(image: np.ndarray, contrast: np.ndarray, mask: np.ndarray,
                      centre, radius: float, named: bool, vmax: float):
    """A close-up of one totem checked against the others: the photo in grey with its
    regions' discord contrast (:func:`verify.metrics.agreement.disc_contrast`, 0 to
    ``vmax`` in turbo colours, where it was judged) and a circle round its worst region
    (``centre`` (u, v) and ``radius`` in pixels; red when the totem is ``named``), (h, w,
    3) sRGB at most ``TOTEM_SIDE`` px; None for an empty mask."""
    from PIL import Image

    from verify.metrics.patches import colorize, luma

    box = _close_up_box(mask)
    if box is None:
        return None
    y0, y1, x0, x1 = box
    grey = np.repeat(luma(np.asarray(image)[y0:y1, x0:x1])[..., None], 3, 2)
    c = np.asarray(contrast, np.float64)[y0:y1, x0:x1]
    seen = np.isfinite(c)
    crop = 0.6 * grey
    w = 0.7 * np.clip(c[seen] / vmax, 0.2, 1.0)[:, None]        # low contrast: mostly grey
    crop[seen] = (1.0 - w) * grey[seen] + w * colorize(np.clip(c[seen], 0.0, None), vmax)
    zoom = min(MAX_ZOOM, TOTEM_SIDE / max(crop.shape[:2]))
    size = (max(1, round(crop.shape[1] * zoom)), max(1, round(crop.shape[0] * zoom)))
    out = np.asarray(Image.fromarray(_u8(crop)).resize(size, Image.NEAREST)) / 255.0
    if centre is not None and np.all(np.isfinite(centre)):
        yy, xx = np.mgrid[0:size[1], 0:size[0]]
        u = (xx + 0.5) / zoom - 0.5 + x0
        v = (yy + 0.5) / zoom - 0.5 + y0
        d = np.hypot(u - centre[0], v - centre[1])
        out[np.abs(d - radius) <= 1.0 / zoom + 0.5] = NAMED_RGB if named else WORST_RGB
    return out


# --------------------------------------------------------------------------- words

def _fmt(x, spec: str = ".3g") -> str:
    return "–" if x is None else format(x, spec)


def _chance(p: float) -> str:
    """A probability in words: a percentage, or 'about 1 in N' below 0.1 %."""
    if p >= 1e-3:
        return f"{100 * p:.2g} %"
    n = float(f"{1.0 / p:.2g}")
    return f"about 1 in {n:,.0f}"


def verdict_words(data: dict) -> dict:
    """The verdict in sentences from report.json's fields: headline, odds, score."""
    n = len(data["drivers"])
    if data["verdict"] == "consistent":
        headline = ("Consistent: nothing in the protected region disagrees with what the "
                    "totems saw.")
    elif data["verdict"] == "unverifiable" and data.get("unverifiable_reason") == "holdout":
        held = data.get("holdout") or {}
        headline = (f"Unverifiable: the totems do not agree on one scene (each is predicted "
                    f"from the others with an error of {held.get('L1') or 0.0:.2f}, at most "
                    f"{held.get('max') or 0.0:.2f} allowed), so the view rebuilt from them "
                    f"can vouch neither for this photo nor against it.")
    elif data["verdict"] == "unverifiable":
        judged = data.get("judged_fraction") or 0.0
        least = (data.get("evidence") or {}).get("min_judged", 0.0)
        headline = (f"Unverifiable: the totems establish too little of this photo to "
                    f"vouch for it ({100 * judged:.0f} % judged, at least "
                    f"{100 * least:.0f} % needed); nothing in that part disagrees with "
                    f"what they saw.")
    else:
        reasons = data.get("inconsistent_reasons") or ["photo"]
        parts = []
        if "photo" in reasons:
            where = f"{n} place{'s' if n != 1 else ''}" if n else "part"
            parts.append(f"{where} in the protected region disagree"
                         f"{'s' if n <= 1 else ''} with what the totems saw (outlined "
                         f"below)")
        if "totem" in reasons:
            named = (data.get("totem_check") or {}).get("named") or []
            which = " and ".join(f"totem {j + 1}" for j in named) or "a totem"
            parts.append(f"{which} (counted from the left) "
                         f"{'sees' if len(named) <= 1 else 'see'} what the other totems "
                         f"contradict (circled under 'The totems checked against each "
                         f"other'): a totem's view disagrees with the others")
        headline = "Inconsistent: " + "; and ".join(parts) + "."
    p, at_line = data.get("p_value"), data.get("line_p_value")
    if p is None:
        odds = ("No p-value: this report was made without a calibration on untouched "
                "photos, so the score is only compared with its threshold.")
    else:
        odds = (f"p = {p:.2g}: the chance that an untouched photo scores this high is "
                f"{_chance(p)}; at the threshold it is {_chance(at_line)} (measured on "
                f"the calibration set's untouched photos).")
    score = (f"Score {_fmt(data['score'], '.2f')} against the threshold "
             f"{_fmt(data['threshold'], '.2f')}.")
    return {"headline": headline, "odds": odds, "score": score}


def _scores(data: dict) -> list[dict]:
    """One row per judging metric: its score, threshold, median patch (its units)."""
    return [{"metric": m, "words": METRIC_WORDS.get(m, ""), "score": _fmt(v["score"]),
             "threshold": _fmt(v["threshold"]), "median": _fmt(v["median"]),
             "ratio": "–" if not v["threshold"] or v["score"] is None
             else f"{v['score'] / v['threshold']:.2f}"}
            for m, v in data["scores"].items()]


def _drivers(data: dict) -> dict:
    """The drivers' boxes (pixels) and table rows, and the value columns present."""
    drivers = data["drivers"]
    columns = [m for m in METRICS if any(m in d for d in drivers)]
    rows = [{"n": k + 1, "metric": d["metric"], "excess": _fmt(d["excess"], ".2f"),
             "box": [int(v) for v in d["box"]],
             "cells": [_fmt(d.get(m), ".3f") for m in columns]}
            for k, d in enumerate(drivers)]
    return {"rows": rows, "columns": columns}


# --------------------------------------------------------------------------- report.html

def _layers(report: Report, overlays: dict, data: dict) -> dict:
    """The stacked pictures of the fader: photo, recon, one heatmap overlay per metric
    (judging metrics first, the first driver's metric shown first)."""
    names = [m for m in data["scores"] if m in overlays]
    names += [m for m in overlays if m not in names]
    first = data["drivers"][0]["metric"] if data["drivers"] else None
    first = first if first in overlays else next(iter(names), None)
    heats = [{"metric": m, "uri": data_uri(overlays[m][1]), "vmax": _fmt(overlays[m][0]),
              "words": METRIC_WORDS.get(m, ""), "shown": m == first} for m in names]
    return {"photo": data_uri(report.image), "recon": data_uri(report.recon),
            "heats": heats}


def _totems(report: Report, data: dict) -> list[dict]:
    """Each totem's close-up (a data: URI or None) and its fitted pose in words: centre
    (camera frame) and distance from the camera in metres, shift from the initial pose
    in millimetres, the initial pose's 1 sd along and across the line of sight in
    millimetres, mask IoU."""
    out = []
    sil = report.silhouettes
    for j, t in enumerate(data["totems"]):
        pic = None if sil is None or j >= len(sil) else \
            totem_picture(report.image, report.totem_mask, sil[j])
        c = np.asarray(t["center"], float)
        moved = None if t["initial"] is None else \
            1000.0 * float(np.linalg.norm(c - np.asarray(t["initial"], float)))
        out.append({"n": j + 1, "uri": None if pic is None else data_uri(pic),
                    "center": ", ".join(f"{x:.3f}" for x in c),
                    "distance": f"{np.linalg.norm(c):.2f}", "moved": _fmt(moved, ".1f"),
                    "iou": _fmt(t["mask_iou"], ".3f"),
                    "sd": "" if not t.get("pose_sd_mm") else
                    "{:.1f} / {:.1f}".format(*t["pose_sd_mm"])})
    return out


def _agreement(report: Report, data: dict) -> dict | None:
    """The totems checked against each other: the line, and per totem a close-up of its
    discord contrast with its worst region circled, its score and lead, and whether it
    is named; None when the check did not run."""
    check, a = data.get("totem_check"), report.agreement
    if check is None or a is None:
        return None
    masks = report.silhouettes
    vmax = 1.5 * check["line"]
    rows = []
    for t in check["totems"]:
        j = t["totem"]
        mask = _totem_mask(report, j) if masks is None else masks[j] & report.totem_mask
        where = t["where"]
        pic = agreement_picture(report.image, a.contrast, mask,
                                None if where is None else where["centre_px"],
                                0.0 if where is None else where["radius_px"], t["named"],
                                vmax)
        rows.append({"n": j + 1, "uri": None if pic is None else data_uri(pic),
                     "named": t["named"], "score": _fmt(t["score"], ".2f"),
                     "lead": _fmt(t["lead"], "+.2f"),
                     "judged": _fmt(None if t["judged"] is None else 100 * t["judged"],
                                    ".0f"),
                     "where": "–" if where is None else
                     "{:.0f}, {:.0f} (radius {:.0f})".format(*where["centre_px"],
                                                             where["radius_px"])})
    named = [j + 1 for j in check["named"]]
    words = " and ".join(f"Totem {n}" for n in named) + \
        (" disagrees" if len(named) == 1 else " disagree") + " with the other totems"
    return {"line": _fmt(check["line"], ".2f"), "vmax": _fmt(vmax, ".2f"),
            "min_others": check["min_others"], "totems": rows, "named": named,
            "named_words": words}


def _totem_mask(report: Report, j: int) -> np.ndarray:
    """Totem ``j``'s pixels when the fitted outlines are unknown: the connected part of
    the totem mask that holds its worst region (or none)."""
    from scipy import ndimage

    labels, _ = ndimage.label(report.totem_mask)
    c = report.agreement.centre[j]
    if not np.all(np.isfinite(c)):
        return np.zeros_like(report.totem_mask)
    k = labels[int(round(c[1])), int(round(c[0]))]
    return labels == k if k else np.zeros_like(report.totem_mask)


def render_report(report: Report, overlays: dict) -> str:
    """report.html of a :class:`verify.report.findings.Report`, as text.

    ``overlays``: {metric: (vmax, (H, W, 3) sRGB heatmap overlay)} as written to
    ``M/heatmap_overlay.png`` (vmax in heatmap.npy units, the colour scale's top).
    """
    data = report.to_json()
    H, W = np.asarray(report.image).shape[:2]
    context = {
        "name": unpath(report.scene_name), "verdict": data["verdict"],
        "words": verdict_words(data), "scores": _scores(data), "drivers": _drivers(data),
        "width": W, "height": H, "label_px": max(10, round(W / 50)),
        "layers": _layers(report, overlays, data),
        "region_uri": data_uri(region_picture(report.image, report.protected)),
        "protected": f"{100 * data['protected_fraction']:.0f}",
        "judged_uri": None if report.evidence is None else
        data_uri(region_picture(report.image, report.judged)),
        **_depth_context(report),
        "judged": _fmt(None if data["judged_fraction"] is None
                       else 100 * data["judged_fraction"], ".0f"),
        "evidence": data["evidence"],
        "region": data["region"], "region_words": REGION_WORDS.get(data["region"], ""),
        "totems": _totems(report, data),
        "agreement": _agreement(report, data),
        "named_rgb": _css(NAMED_RGB),
        "fit_rgb": _css(FIT_RGB), "mask_rgb": _css(MASK_RGB),
        "fingerprint": data["key_fingerprint"],
        "versions": [(unpath(k), unpath(v)) for k, v in data["versions"].items()],
        "skipped": [(m, unpath(why)) for m, why in data["skipped"].items()],
    }
    return environment().get_template("report.html").render(**context)


def _depth_context(report: Report) -> dict:
    """The depth picture's data: URI and its range in words, or None."""
    ev = report.evidence
    pic, rng = (None, None) if ev is None or ev.depth is None else \
        depth_picture(report.image, ev.depth)
    return {"depth_uri": None if pic is None else data_uri(pic),
            "depth_near": None if rng is None else _fmt(rng[0], ".2g"),
            "depth_far": None if rng is None else _fmt(rng[1], ".2g")}


def _css(rgb) -> str:
    return "rgb({}, {}, {})".format(*(round(255 * c) for c in rgb))


# --------------------------------------------------------------------------- bench.html

def _spans(text: str) -> list[tuple[str, bool]]:
    """Markdown text as (text, is_code) spans: `code` between backticks."""
    return [(part, k % 2 == 1) for k, part in enumerate(unpath(text).split("`")) if part]


def markdown_blocks(text: str) -> list[dict]:
    """bench.md (headings, pipe tables, "- " lists, paragraphs) as blocks to render:
    {"kind": "heading", "level", "spans"}, {"kind": "table", "head", "rows"} (cells as
    spans), {"kind": "list", "entries"}, {"kind": "paragraph", "spans"}. A blank line or a
    heading ends a table or list."""
    blocks, open_ = [], None
    for line in (raw.rstrip() for raw in text.splitlines()):
        if not line:
            open_ = None
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            blocks.append({"kind": "heading", "level": min(level, 4),
                           "spans": _spans(line.lstrip("#").strip())})
            open_ = None
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if all(c and set(c) <= set("-: ") for c in cells):
                continue                              # the header's rule
            cells = [_spans(c) for c in cells]
            if open_ is not None and open_["kind"] == "table":
                open_["rows"].append(cells)
            else:
                open_ = {"kind": "table", "head": cells, "rows": []}
                blocks.append(open_)
        elif line.startswith("- "):
            if open_ is None or open_["kind"] != "list":
                open_ = {"kind": "list", "entries": []}
                blocks.append(open_)
            open_["entries"].append(_spans(line[2:]))
        else:
            blocks.append({"kind": "paragraph", "spans": _spans(line)})
            open_ = None
    return blocks


def render_bench(markdown_text: str, plots: dict) -> str:
    """bench.html: bench.md's headings, tables and lists as HTML, then the plots.

    ``plots``: {file name: PNG bytes} as written to ``OUT/plots/``.
    """
    blocks = markdown_blocks(markdown_text)
    title = "totems bench"
    if blocks and blocks[0]["kind"] == "heading" and blocks[0]["level"] == 1:
        title = "".join(t for t, _ in blocks.pop(0)["spans"])
    pictures = [{"name": name, "words": PLOT_WORDS.get(name, name), "uri": png_uri(data)}
                for name, data in plots.items()]
    return environment().get_template("bench.html").render(
        blocks=blocks, pictures=pictures, title=title)
