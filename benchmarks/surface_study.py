"""The photo against what its totems see at each surface's depth, from several depth maps
(issue 60, items 2 and 3): what the geometry buys the verdict.

    python benchmarks/surface_study.py BENCH [--out CSV] [--slices N] [--far M]

For each photo of a bench (``totems bench``; its scene's ``truth/reach.npz``), the
fit's totem rays are swept (:func:`verify.metrics.corroborate.ray_slices`, ``N`` slices to
``M`` metres) and read at one depth per cell of the map: the truth's (the cell's median
true depth: the oracle), semi-global matching's on the totems' colour agreement, or the
fit's view depth. There each totem that lands gives a colour; the photo is compared
with their mean, ``e`` (sRGB, mean over channels), and with their spread, ``z = e / (s +
S0)``, on the cells where two totems land with a parallax of MIN_PARALLAX. The
statistic is the worst patch of the verdict's grid (patches at least half judged).
Prints one line a photo and, per depth source and residual, the AUC of each kind of edit
against the untouched photos.

    python benchmarks/surface_study.py BENCH --cache DIR [--seeds 31,32,33]
        [--variant KEY=VALUE,...]... [--source truth|sgm] [--ceiling] [--jpeg 75]

caches each photo's intermediate arrays in ``DIR/NAME.npz`` (:func:`cache_bench`, a few
seconds a photo, once) and scores each :class:`Variant` of the oracle on them (a second
a photo): the colour gains, what is left out (highlights, grazing rays, depth edges,
cells outside the truth's reach), the splat and photo blur, the residual (colours or
hues) and the patch statistic. Prints, per variant, the untouched and removed photos'
median worst patch, the AUC of each kind pooled and per preset against the same
preset's untouched photos; ``--ceiling`` each edit's own size at the prediction's
resolution (:func:`change`); ``--jpeg`` the photo saved as a JPEG first.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

S0 = 0.02
SOURCES = ("truth", "sgm", "fit")


def _load_fit(sd: Path, fit_dir: Path, far: float):
    """The scene's truth and folder, its fit, the fit's frame cut at ``far`` metres and
    the totem rays the evidence reads (entering at COS_EVIDENCE or more)."""
    from inverse.fit.files import load_fit
    from inverse.grid import FrustumFrame
    from scenes import folder
    from verify.metrics import corroborate

    truth, scene = folder.read_truth(sd), folder.read_scene(sd)
    fit = load_fit(fit_dir)
    frame = FrustumFrame.from_dict(fit.grid)
    frame = dataclasses.replace(frame, far=min(frame.far, far))
    return truth, scene, fit, frame, fit.rays.entering_at_least(corroborate.COS_EVIDENCE)


def cell_depth(depth_px, frame, res):
    """(nt, ns) the median of a (H, W) depth map over each map cell (NaN where none)."""
    from inverse.grid import FrustumFrame  # noqa: F401
    H, W = depth_px.shape
    nt, ns = res
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
    col = np.clip((np.asarray(s) * ns).astype(int), 0, ns - 1)
    row = np.clip((np.asarray(t) * nt).astype(int), 0, nt - 1)
    cell = row * ns + col
    z = depth_px.ravel()
    ok = np.isfinite(z)
    out = np.full(nt * ns, np.nan)
    order = np.argsort(cell[ok], kind="stable")
    cs, zs = cell[ok][order], z[ok][order]
    starts = np.r_[0, np.flatnonzero(np.diff(cs)) + 1]
    for a, b in zip(starts, np.r_[starts[1:], len(cs)]):
        out[cs[a]] = np.median(zs[a:b])
    return out.reshape(nt, ns)


def at_depth(sc, par, z_cells):
    """Each totem's colour at each cell's depth ``z_cells`` (nt, ns): the slice nearest in
    inverse depth. Returns colours (n, nt, ns, 3), landing (n, nt, ns) bool and the
    parallax there (nt, ns)."""
    inv = 1.0 / np.asarray(sc.z, np.float64)
    zc = np.where(np.isfinite(z_cells), z_cells, sc.z[-1])
    k = np.abs(inv[:, None, None] - 1.0 / zc[None]).argmin(axis=0)          # (nt, ns)
    col = np.take_along_axis(sc.colour, k[None, None, ..., None], 1)[:, 0]
    land = np.take_along_axis(sc.land, k[None, None], 1)[:, 0] & np.isfinite(z_cells)[None]
    p = np.take_along_axis(par, k[None], 0)[0]
    return col, land, p


def sgm_depth(sc, par, min_parallax):
    from inverse.view.sweep import semi_global
    n_land, _, var = sc.consistency
    ok = (n_land >= 2) & (par >= min_parallax)
    fill = float(np.median(var[ok])) if ok.any() else 1.0
    c = np.where(ok, var, fill) / max(fill, 1e-12)
    k = np.argmin(semi_global(c, 0.3, 3.0), axis=0)
    return np.where(ok.any(axis=0), np.asarray(sc.z)[k], np.nan)


def study(sd: Path, fit_dir: Path, n_slices: int, far: float) -> dict:
    from inverse.grid import cells_to_pixels
    from scenes.colour import linear_to_srgb, srgb_to_linear
    from scenes.reach import MIN_PARALLAX
    from verify.metrics import corroborate, evidence, patches, resolution
    from verify.verdict.verdict import judging_grid

    truth, scene, fit, frame, rays = _load_fit(sd, fit_dir, far)
    H, W = scene.image.shape[:2]
    sc = corroborate.ray_slices(fit.rays, frame, n_slices=n_slices)
    res = sc.land.shape[2:]
    spacing = evidence.angular_spacing(rays.d, rays.totem, len(fit.centers))
    par = evidence.slice_parallax(sc, frame, fit.centers, spacing)
    spx = resolution.ray_spacing(fit.totem_points, scene.K, (W, H))
    blurred = patches.blur_varying(np.asarray(scene.image, np.float64),
                                   resolution.photo_sigma(spx))
    uu, vv = corroborate.cell_centres(frame, res)
    photo = corroborate._sample(blurred.astype(np.float32), uu, vv).astype(np.float64)
    depths = {"truth": cell_depth(np.where(truth.reach.backdrop, np.nan,
                                           truth.reach.depth.astype(np.float64)), frame, res),
              "sgm": sgm_depth(sc, par, MIN_PARALLAX),
              "fit": cell_depth(np.asarray(fit.recon_depth, np.float64), frame, res)}
    grid = judging_grid((H, W))
    totem_px = scene.masks.any(axis=0)
    out = {}
    for name, zc in depths.items():
        col, land, p = at_depth(sc, par, zc)
        n = land.sum(0)
        judged = (n >= 2) & (p >= MIN_PARALLAX)
        mu = (col * land[..., None]).sum(0) / np.maximum(n, 1)[..., None]
        spread = np.sqrt(((col - mu[None]) ** 2 * land[..., None]).sum(0).mean(-1)
                         / np.maximum(n - 1, 1))
        # exposure: per channel median ratio in linear light over the judged cells
        if judged.sum() > 50:
            ratio = srgb_to_linear(np.clip(photo[judged], 1e-3, 1)) / \
                np.maximum(srgb_to_linear(np.clip(mu[judged], 1e-3, 1)), 1e-4)
            g = np.clip(np.exp(np.median(np.log(np.maximum(ratio, 1e-4)), axis=0)), 0.5, 2)
        else:
            g = np.ones(3)
        mu_g = linear_to_srgb(np.clip(srgb_to_linear(np.clip(mu, 0, 1)) * g, 0, 1))
        e = np.abs(photo - mu_g).mean(-1)
        z = e / (spread + S0)
        for kind, m in (("e", e), ("z", z)):
            cells = np.where(judged, m, np.nan)
            px = cells_to_pixels(cells, frame, (W, H), nearest=True)
            px = np.where(totem_px, np.nan, px)
            ok = np.isfinite(px)
            sc_p = patches.patch_means(np.nan_to_num(px), grid, ok)
            cov = patches.patch_fraction(ok, grid)
            vals = sc_p[cov >= 0.5]
            out[f"{name}_{kind}"] = float(np.nanmax(vals)) if np.isfinite(vals).any() \
                else np.nan
        zt = depths["truth"]
        both = np.isfinite(zt) & np.isfinite(zc)
        out[f"{name}_deperr"] = float(np.median(np.abs(zc[both] - zt[both]) / zt[both])) \
            if both.any() else np.nan
        out[f"{name}_judged"] = float(judged.mean())
    return out


def auc(neg, pos) -> float:
    neg, pos = np.asarray(neg, float), np.asarray(pos, float)
    neg, pos = neg[np.isfinite(neg)], pos[np.isfinite(pos)]
    if not len(neg) or not len(pos):
        return np.nan
    return float(((pos[:, None] > neg[None]) + 0.5 * (pos[:, None] == neg[None])).mean())



# --- The oracle's fidelity (issue 60): cached intermediates and variants --------------
#
# ``cache_photo`` writes, per photo, what every variant reads (cells of the evidence map,
# camera frame): each totem's colour at the cell's depth (truth's and SGM's, and at the
# truth's with the rays entering the glass at higher incidence cosines), the photo there,
# the true depth's range over each cell, and the pixel -> cell map. ``score`` then judges
# one variant in well under a second.

COS_HIGH = (0.6, 0.8)
"""Incidence cosines (at the sphere's entry) above COS_EVIDENCE cached for variant 2:
rays nearer the rim are blurred and mixed with reflection."""


SIGMAS = (1.0, 0.75)
"""Splat spreads (cells) below corroborate.SIGMA_CELLS cached for the sharper
prediction: each ray's colour spread over fewer cells (more cells where no totem lands)."""

BLURS = (0.5, 0.25)
"""Factors on the photo's blur (:func:`verify.metrics.resolution.photo_sigma`) cached
for a sharper comparison."""

CACHE_KEYS = ("reach", "truth_s75_col", "photo_b25")
"""Keys a cache file must hold to be current (older files are made again)."""


def _cell_index(frame, res, size):
    """(H, W) int32: the map cell (row * ns + col) each pixel centre falls in, as
    :func:`inverse.grid.cells_to_pixels` with ``nearest`` reads it."""
    W, H = size
    nt, ns = res
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
    col = np.clip((np.asarray(s) * ns).astype(int), 0, ns - 1)
    row = np.clip((np.asarray(t) * nt).astype(int), 0, nt - 1)
    return (row * ns + col).reshape(H, W).astype(np.int32)


def _cell_reduce(values, cell, n_cells, how):
    """Per cell ``how`` ('min' or 'max') of the (H, W) ``values`` whose pixels fall in it
    (``cell`` from :func:`_cell_index`); NaN for a cell with no pixel or no finite value
    (for 'min' and 'max' infinities count)."""
    v = np.asarray(values, np.float64).ravel()
    c = np.asarray(cell).ravel()
    ok = ~np.isnan(v)
    out = np.full(n_cells, np.inf if how == "min" else -np.inf)
    (np.minimum if how == "min" else np.maximum).at(out, c[ok], v[ok])
    out[~np.isfinite(out) & (out == (np.inf if how == "min" else -np.inf))] = np.nan
    return out


def _reach_cells(reach, cell, res):
    """(nt, ns) the fraction of each cell's pixels whose surface two totems truly see
    with its depth resolved (the truth's reach, :meth:`scenes.reach.Reach.in_reach`,
    backdrop left out): where the totems' colour at the true depth is of that surface
    and not of something in front of it."""
    from scenes.reach import MIN_PARALLAX, MIN_TOTEMS
    seen = ((reach.n_totems >= MIN_TOTEMS) & (reach.parallax >= MIN_PARALLAX)
            & ~reach.excluded & ~reach.backdrop)
    n = res[0] * res[1]
    tot = np.bincount(cell.ravel(), minlength=n)
    hit = np.bincount(cell.ravel(), seen.ravel().astype(float), minlength=n)
    return (hit / np.maximum(tot, 1)).reshape(res)


def _fit_arrays(sd: Path, fit_dir: Path, n_slices: int, far: float) -> dict:
    """What one fit gives every photo verified on it: per depth source (``truth``,
    ``sgm``, ``truth_c60`` ... for the rays entering at cosines COS_HIGH, ``truth_s100``
    ... for the splat spreads SIGMAS) each totem's
    sRGB colour at each cell's depth ``*_col`` (n, nt, ns, 3) float32, where it lands
    ``*_land`` (n, nt, ns) and the parallax there ``*_par`` (nt, ns) in rays' spacings;
    the cells' depths ``zt`` (truth: median over the cell, NaN for a backdrop), ``zsgm``;
    the true depth's range over each cell ``zmin``, ``zmax`` (metres, inf for a
    backdrop), the pixel -> cell map ``cell`` (H, W), the rays' spacing ``spx`` (H, W,
    pixels) for the photo's blur, the frame's dict."""
    from scenes.reach import MIN_PARALLAX
    from verify.metrics import corroborate, evidence, resolution

    truth, scene, fit, frame, rays = _load_fit(sd, fit_dir, far)
    H, W = scene.image.shape[:2]
    spacing = evidence.angular_spacing(rays.d, rays.totem, len(fit.centers))
    out = {}
    depth = np.where(truth.reach.backdrop, np.inf, truth.reach.depth.astype(np.float64))
    runs = ([("", corroborate.COS_EVIDENCE, corroborate.SIGMA_CELLS)]
            + [(f"_c{round(c * 100)}", c, corroborate.SIGMA_CELLS) for c in COS_HIGH]
            + [(f"_s{round(g * 100)}", corroborate.COS_EVIDENCE, g) for g in SIGMAS])
    for tag, cos, sigma in runs:
        sc = corroborate.ray_slices(fit.rays, frame, n_slices=n_slices, cos_evidence=cos,
                                    sigma=sigma)
        res = sc.land.shape[2:]
        par = evidence.slice_parallax(sc, frame, fit.centers, spacing)
        if not tag:
            zt = cell_depth(np.where(truth.reach.backdrop, np.nan,
                                     truth.reach.depth.astype(np.float64)), frame, res)
            zs = sgm_depth(sc, par, MIN_PARALLAX)
            srcs = {"truth": zt, "sgm": zs}
            out.update(zt=zt, zsgm=zs)
        else:
            srcs = {"truth" + tag: out["zt"]}
        for name, zc in srcs.items():
            col, land, p = at_depth(sc, par, zc)
            out.update({f"{name}_col": col.astype(np.float32), f"{name}_land": land,
                        f"{name}_par": p.astype(np.float32)})
    cell = _cell_index(frame, res, (W, H))
    n_cells = res[0] * res[1]
    out["zmin"] = _cell_reduce(depth, cell, n_cells, "min").reshape(res)
    out["zmax"] = _cell_reduce(depth, cell, n_cells, "max").reshape(res)
    out["cell"] = cell
    out["reach"] = _reach_cells(truth.reach, cell, res)
    out["spx"] = resolution.ray_spacing(fit.totem_points, scene.K, (W, H))
    out["frame"] = np.array(json.dumps({k: np.asarray(v).tolist()
                                        for k, v in frame.to_dict().items()}))
    return out


def _photo_arrays(sd: Path, fit: dict, jpeg: int | None = None) -> dict:
    """The photo at the map's cells: ``photo`` (nt, ns, 3) sRGB, blurred to the rays'
    spacing (:func:`verify.metrics.resolution.photo_sigma`) and sampled at the cell
    centres, as :func:`study` does (``photo_b50`` ... with that blur times BLURS); ``white`` (nt, ns) the largest over the cell's pixels
    of the pixel's least channel (unblurred: 1 where a pixel is white); ``totem_px``
    (H, W) the totems' pixels. ``jpeg``: the photo first saved as a JPEG of that quality
    (4:2:0) and read back (the camera view only; the totem rays stay the fit's)."""
    from inverse.grid import FrustumFrame
    from scenes import folder
    from verify.metrics import corroborate, patches, resolution

    scene = folder.read_scene(sd)
    frame = FrustumFrame.from_dict({k: np.asarray(v) for k, v in
                                    json.loads(str(fit["frame"])).items()})
    res = fit["zt"].shape
    img = np.asarray(scene.image, np.float64)
    if jpeg is not None:
        from scenes import jpeg as jpg
        img = jpg.decode(jpg.encode(img, quality=jpeg, chroma="420")).astype(np.float64)
    blurred = patches.blur_varying(img, resolution.photo_sigma(fit["spx"]))
    uu, vv = corroborate.cell_centres(frame, res)
    photo = corroborate._sample(blurred.astype(np.float32), uu, vv).astype(np.float32)
    white = _cell_reduce(img.min(-1), fit["cell"], res[0] * res[1], "max").reshape(res)
    sharper = {}
    for f in BLURS:
        b = patches.blur_varying(img, resolution.photo_sigma(fit["spx"], f))
        sharper[f"photo_b{round(f * 100)}"] = corroborate._sample(
            b.astype(np.float32), uu, vv).astype(np.float32)
    return {"photo": photo, **sharper, "white": white.astype(np.float32),
            "totem_px": scene.masks.any(axis=0)}


def cache_bench(bench: Path, cache: Path, names: set | None, n_slices: int,
                far: float) -> list[dict]:
    """Write ``cache/NAME.npz`` (:func:`_fit_arrays` and :func:`_photo_arrays`) for every
    joint photo of ``bench`` in ``names`` (None: all) not cached yet; returns each photo's
    row (name, kind, preset, placement, seed, path)."""
    cache.mkdir(parents=True, exist_ok=True)
    rows, memo = [], {}
    for run in json.loads((bench / "bench.json").read_text())["runs"]:
        if run.get("mode") != "joint" or run.get("status") != "ok":
            continue
        sd = Path(run["scene"])
        if names is not None and sd.name not in names:
            continue
        fit_dir = bench / "runs" / f"{run.get('fit_from') or run['name']}-joint" / "fit"
        if not fit_dir.is_dir() or not (sd / "truth" / "reach.npz").is_file():
            continue
        tj = sd / "truth" / "tamper.json"
        kind = json.loads(tj.read_text())["kind"] if tj.is_file() else "none"
        path = cache / f"{sd.name}.npz"
        if path.is_file() and not set(CACHE_KEYS) <= set(np.load(path).files):
            path.unlink()                                          # an older cache
        if not path.is_file():
            if fit_dir not in memo:
                memo = {fit_dir: _fit_arrays(sd, fit_dir, n_slices, far)}
            arrays = {**memo[fit_dir], **_photo_arrays(sd, memo[fit_dir])}
            np.savez_compressed(path, **arrays)
            print(f"cached {sd.name}", flush=True)
        rows.append({"name": sd.name, "kind": kind, "preset": run.get("preset"),
                     "placement": "resting" if "-resting" in sd.name else "floating",
                     "seed": int(sd.name.split("-")[1]), "path": path, "scene": sd})
    return rows


@dataclasses.dataclass(frozen=True)
class Variant:
    """How the oracle turns the cached colours into a photo's score (:func:`score`).

    Attributes
    ----------
    gain : how the totems' colours are brought to the photo's, in linear light per
        channel: ``global`` one gain for their mean (the median ratio, :func:`study`'s),
        ``totem`` one per totem (median ratio over the cells where that totem lands),
        ``totem_ls`` the same by least squares, ``totem_affine`` gain and offset per totem
        (least squares, sRGB).
    white : leave out cells where the photo (any pixel of the cell) or a landing totem has
        every channel at least this (sRGB): lights and highlights; None: none.
    bright : leave out cells whose photo or totems' mean luminance exceeds this
        percentile of the photo's over the judged cells; None: none.
    grow : cells the left-out highlights grow by (3 x 3 steps).
    cos : read the rays entering the glass at an incidence cosine of at least
        ``cos / 100`` (one of COS_HIGH); None: COS_EVIDENCE's.
    stat : a patch's score: ``mean`` of its judged pixels' residual, or ``q90`` their
        90th percentile.
    s0 : floor (sRGB) added to the totems' spread in ``z = e / (spread + s0)``.
    edge : leave out cells where the depth varies by more than this fraction over the
        cell and its eight neighbours (a backdrop counts as infinitely far); None: none.
    reach : judge only cells at least this fraction of whose pixels lie in the truth's
        reach (two totems truly see the surface, no occluder in front): visibility from
        the truth, an oracle as the depth is; None: every cell.
    sigma : each ray's splat spread, in hundredths of a cell (one of SIGMAS); None:
        corroborate.SIGMA_CELLS (1.5 cells, 7.8 px).
    blur : the photo's blur, in hundredths of the verify's (one of BLURS); None: the
        verify's (:func:`verify.metrics.resolution.photo_sigma`, median 14 px).
    resid : what ``e`` compares: ``rgb`` the sRGB colours, ``chroma`` each colour less
        its grey level (:func:`verify.metrics.patches.chroma`: brightness left out, as
        the verify's hue metrics do).
    """

    gain: str = "global"
    white: float | None = None
    bright: float | None = None
    grow: int = 1
    cos: int | None = None
    stat: str = "mean"
    s0: float = S0
    edge: float | None = None
    reach: float | None = None
    sigma: int | None = None
    blur: int | None = None
    resid: str = "rgb"

    def label(self) -> str:
        base = Variant()
        parts = [f"{f.name}={getattr(self, f.name)}" for f in dataclasses.fields(self)
                 if getattr(self, f.name) != getattr(base, f.name)]
        return ",".join(parts) or "baseline"

    @classmethod
    def parse(cls, text: str) -> "Variant":
        """``key=value,...`` (e.g. ``gain=totem,white=0.9``), or ``baseline``."""
        kw = {}
        for part in filter(None, text.split(",")):
            if part == "baseline":
                continue
            k, v = part.split("=")
            ftype = {f.name: f.type for f in dataclasses.fields(cls)}[k]
            kw[k] = v if "str" in str(ftype) else (int(v) if "int" in str(ftype)
                                                    else float(v))
        return cls(**kw)


def _to_lin(x):
    from scenes.colour import srgb_to_linear
    return srgb_to_linear(np.clip(x, 0.0, 1.0))


def _to_srgb(x):
    from scenes.colour import linear_to_srgb
    return linear_to_srgb(np.clip(x, 0.0, 1.0))


def _gains(col, land, photo, cells, how):
    """The totems' colours (n, nt, ns, 3) sRGB brought to the photo's (nt, ns, 3), fitted
    over ``cells`` (nt, ns) bool where each totem lands (see :class:`Variant`'s ``gain``);
    returns the corrected colours (sRGB)."""
    out = col.astype(np.float64).copy()
    P = photo[cells].astype(np.float64)
    for j in range(len(col)):
        m = land[j][cells]
        if m.sum() < 50:
            continue
        c, p = col[j][cells][m].astype(np.float64), P[m]
        if how == "totem_affine":
            for ch in range(3):
                A = np.stack([c[:, ch], np.ones(len(c))], 1)
                a, b = np.linalg.lstsq(A, p[:, ch], rcond=None)[0]
                out[j, ..., ch] = a * col[j, ..., ch] + b
            continue
        cl, pl = _to_lin(c), _to_lin(p)
        if how == "totem":
            g = np.exp(np.median(np.log(np.maximum(pl, 1e-4) / np.maximum(cl, 1e-4)), 0))
        else:                                                   # totem_ls
            g = (cl * pl).sum(0) / np.maximum((cl * cl).sum(0), 1e-12)
        out[j] = _to_srgb(_to_lin(col[j]) * np.clip(g, 0.25, 4.0))
    return np.clip(out, 0.0, 1.0)


def _patch_stat(px, grid, stat):
    """The worst patch of ``grid`` over the (H, W) residual ``px`` (NaN: not judged),
    among patches at least half judged: the largest of their means or 90th percentiles."""
    from verify.metrics import patches
    ok = np.isfinite(px)
    cov = patches.patch_fraction(ok, grid)
    if stat == "mean":
        vals = patches.patch_means(np.nan_to_num(px), grid, ok)
    else:
        r = np.arange(grid.size)
        rows = grid.rows[:, None, None, None] + r[None, None, :, None]
        cols = grid.cols[None, :, None, None] + r[None, None, None, :]
        use = cov >= 0.5
        blocks = px[rows, cols][use].reshape(int(use.sum()), -1)
        vals = np.full(cov.shape, np.nan)
        if use.any():
            vals[use] = np.nanpercentile(blocks, 90, axis=1)
    vals = vals[cov >= 0.5]
    return float(np.nanmax(vals)) if np.isfinite(vals).any() else np.nan


def score(arr, v: Variant, src: str = "truth", maps: bool = False) -> dict:
    """One photo's worst-patch residuals under variant ``v`` with depth source ``src``
    (``truth`` or ``sgm``) from its cached arrays (:func:`cache_bench`): ``e`` (sRGB, mean
    over channels), ``z`` (e over the totems' spread plus ``v.s0``), and ``judged`` the
    fraction of the map's cells judged; with ``maps`` also the cell maps ``e_cells``,
    ``z_cells`` (NaN where not judged) and the prediction ``mu`` (nt, ns, 3) sRGB."""
    from scipy import ndimage
    from scenes.reach import MIN_PARALLAX
    from verify.verdict.verdict import judging_grid

    key = src + (f"_c{v.cos}" if v.cos else "") + (f"_s{v.sigma}" if v.sigma else "")
    col, land, p = arr[f"{key}_col"], arr[f"{key}_land"], arr[f"{key}_par"]
    photo = arr[f"photo_b{v.blur}" if v.blur else "photo"].astype(np.float64)
    n = land.sum(0)
    judged = (n >= 2) & (p >= MIN_PARALLAX)
    drop = np.zeros_like(judged)
    if v.white is not None:
        drop |= arr["white"] >= v.white
        drop |= ((col.min(-1) >= v.white) & land).any(0)
    if v.bright is not None and judged.any():
        lum = photo @ np.array([0.2126, 0.7152, 0.0722])
        tl = np.where(land, col @ np.array([0.2126, 0.7152, 0.0722]), 0).max(0)
        line = np.percentile(lum[judged], v.bright)
        drop |= (lum > line) | (tl > line)
    if drop.any() and v.grow:
        drop = ndimage.binary_dilation(drop, np.ones((3, 3), bool), iterations=v.grow)
    if v.edge is not None:
        if src == "truth":
            lo, hi = arr["zmin"], arr["zmax"]
        else:
            lo = hi = np.where(np.isfinite(arr["zsgm"]), arr["zsgm"], np.inf)
        lo = ndimage.minimum_filter(np.where(np.isnan(lo), np.inf, lo), 3, mode="nearest")
        hi = ndimage.maximum_filter(np.where(np.isnan(hi), np.inf, hi), 3, mode="nearest")
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(np.isfinite(hi), hi / np.maximum(lo, 1e-6) - 1.0, np.inf)
        drop |= rel > v.edge
    if v.reach is not None:
        drop |= arr["reach"] < v.reach
    judged &= ~drop
    if v.gain == "global":
        mu = (col * land[..., None]).sum(0) / np.maximum(n, 1)[..., None]
        if judged.sum() > 50:
            ratio = _to_lin(np.maximum(photo[judged], 1e-3)) / \
                np.maximum(_to_lin(np.maximum(mu[judged], 1e-3)), 1e-4)
            g = np.clip(np.exp(np.median(np.log(np.maximum(ratio, 1e-4)), 0)), 0.5, 2)
        else:
            g = np.ones(3)
        mu = _to_srgb(_to_lin(mu) * g)                 # the mean's gain, as study()'s
    else:
        cg = _gains(col, land, photo, judged, v.gain)
        mu = (cg * land[..., None]).sum(0) / np.maximum(n, 1)[..., None]
    sp = col if v.gain == "global" else cg       # global: the spread as study()'s
    mu_s = (sp * land[..., None]).sum(0) / np.maximum(n, 1)[..., None]
    spread = np.sqrt(((sp - mu_s[None]) ** 2 * land[..., None]).sum(0).mean(-1)
                     / np.maximum(n - 1, 1))
    if v.resid == "chroma":
        e = np.abs((photo - photo.mean(-1, keepdims=True))
                   - (mu - mu.mean(-1, keepdims=True))).mean(-1)
    else:
        e = np.abs(photo - mu).mean(-1)
    z = e / (spread + v.s0)
    out = {"judged": float(judged.mean())}
    if maps:
        out.update(e_cells=np.where(judged, e, np.nan), z_cells=np.where(judged, z, np.nan),
                   mu=mu)
    grid = judging_grid(arr["cell"].shape)
    for name, m in (("e", e), ("z", z)):
        px = np.where(judged, m, np.nan).ravel()[arr["cell"]]
        px[arr["totem_px"]] = np.nan
        out[name] = _patch_stat(px, grid, v.stat)
    return out


def change(arr, src_arr, v: Variant) -> float:
    """The edit's own size at the prediction's resolution: the worst patch (as
    :func:`score`'s) of ``|photo - source photo|`` (sRGB, mean over channels, the photo
    blurred as ``v`` says) over the cells the untouched source's oracle judges. A
    prediction that reproduced the source photo exactly at this blur would score the
    edit this and the untouched photo 0: the most any prediction at it can separate."""
    from scenes.reach import MIN_PARALLAX
    from verify.verdict.verdict import judging_grid
    key = f"photo_b{v.blur}" if v.blur else "photo"
    d = arr[key].astype(np.float64) - src_arr[key]
    if v.resid == "chroma":
        d = d - d.mean(-1, keepdims=True)
    d = np.abs(d).mean(-1)
    judged = (src_arr["truth_land"].sum(0) >= 2) & (src_arr["truth_par"] >= MIN_PARALLAX)
    px = np.where(judged, d, np.nan).ravel()[arr["cell"]]
    px[arr["totem_px"]] = np.nan
    return _patch_stat(px, judging_grid(arr["cell"].shape), v.stat)


KINDS = ("color", "splice", "inpaint", "remove")
PRESETS = ("box", "envmap", "outdoor", "tabletop", "window")


def auc_table(rows, key) -> dict:
    """AUC of each kind against the untouched photos, pooled (``(kind, 'all')``) and per
    preset against the same preset's untouched photos (``(kind, preset)``)."""
    out = {}
    for kind in KINDS:
        for preset in ("all",) + PRESETS:
            sel = [r for r in rows if preset in ("all", r["preset"])]
            out[kind, preset] = auc([r[key] for r in sel if r["kind"] == "none"],
                                    [r[key] for r in sel if r["kind"] == kind])
    return out


def report(rows, variants, keys=("e", "z")) -> list[str]:
    """Lines of the variants' tables: the untouched and removed photos' median worst
    patch ``e``, the pooled AUC per kind, and per preset the removals' and inpaintings'."""
    head = (f"{'variant':44s} {'res':3s} {'e none':>6s} {'e rem':>6s} | "
            + " ".join(f"{k[:5]:>5s}" for k in KINDS) + " | remove "
            + " ".join(f"{p[:4]:>4s}" for p in PRESETS) + " | inpaint "
            + " ".join(f"{p[:4]:>4s}" for p in PRESETS))
    lines = [head]
    for v in variants:
        lab = v.label()
        for key in keys:
            col = f"{lab}|{key}"
            t = auc_table(rows, col)
            med = lambda kind: np.nanmedian([r[f"{lab}|e"] for r in rows
                                             if r["kind"] == kind])
            lines.append(
                f"{lab[:44]:44s} {key:3s} {med('none'):6.3f} {med('remove'):6.3f} | "
                + " ".join(f"{t[k, 'all']:5.2f}" for k in KINDS) + " |        "
                + " ".join(f"{t['remove', p]:4.2f}" for p in PRESETS) + " |         "
                + " ".join(f"{t['inpaint', p]:4.2f}" for p in PRESETS))
    return lines


def _source_name(row, by_name):
    """The untouched photo an edited one was made from (its name), or None."""
    if row["kind"] == "none":
        return None
    src = row["name"]
    for suffix in ("-" + row["kind"], "-color", "-splice", "-inpaint", "-remove"):
        src = src.removesuffix(suffix)
    return src if src in by_name else None


def ceiling_lines(rows, variants) -> list[str]:
    """Per variant, the median over each kind's edits of :func:`change` (the edit's
    size at the prediction's resolution), per preset, beside the untouched photos'
    median worst-patch ``e`` under that variant."""
    lines = ["\nmedian worst-patch change (edit - source photo), sRGB; 'none': the "
             "untouched photos' residual e"]
    for v in variants:
        lab = v.label()
        lines.append(f"{lab}:" + " ".join(f"{p:>9s}" for p in ("all",) + PRESETS))
        for kind in ("none",) + KINDS:
            key = f"{lab}|e" if kind == "none" else f"{lab}|change"
            vals = [np.nanmedian([r.get(key, np.nan) for r in rows if r["kind"] == kind
                                  and preset in ("all", r["preset"])] or [np.nan])
                    for preset in ("all",) + PRESETS]
            lines.append(f"  {kind:8s}" + " ".join(f"{x:9.3f}" for x in vals))
    return lines


def per_preset(rows, v: Variant, key: str) -> list[str]:
    """Every kind's AUC per preset (against that preset's untouched photos) for one
    variant and residual."""
    t = auc_table(rows, f"{v.label()}|{key}")
    lines = [f"{v.label()} {key}: " + " ".join(f"{p:>8s}" for p in ("all",) + PRESETS)]
    for kind in KINDS:
        lines.append(f"  {kind:8s} " + " ".join(f"{t[kind, p]:8.2f}"
                                                  for p in ("all",) + PRESETS))
    return lines


def _jpeg_cache(row, cache: Path, quality: int) -> Path:
    """``cache/jpegQ/NAME.npz``: :func:`_photo_arrays` of the photo saved as a JPEG of
    ``quality`` (made when missing)."""
    path = cache / f"jpeg{quality}" / f"{row['name']}.npz"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **_photo_arrays(row["scene"], dict(np.load(row["path"])),
                                                  jpeg=quality))
    return path


def _load(row) -> dict:
    """A photo's cached arrays, its photo's from ``path_photo`` when given (JPEG)."""
    arr = dict(np.load(row["path"]))
    if row.get("path_photo"):
        arr.update(np.load(row["path_photo"]))
    return arr


def run_variants(args) -> int:
    """``--cache``: cache the chosen photos, score every ``--variant`` on them, print the
    tables (and write one row a photo to ``--out``)."""
    seeds = {int(x) for x in args.seeds.split(",")} if args.seeds else None
    runs = json.loads((args.bench / "bench.json").read_text())["runs"]
    names = {Path(r["scene"]).name for r in runs
             if (seeds is None or int(Path(r["scene"]).name.split("-")[1]) in seeds)
             and ("+" not in Path(r["scene"]).name or args.channels)}
    rows = [r for r in cache_bench(args.bench, args.cache, names, args.slices, args.far)
            if r["kind"] in ("none",) + KINDS]
    variants = [Variant.parse(t) for t in (args.variant or ["baseline"])]
    if args.jpeg:
        for r in rows:
            r["path_photo"] = _jpeg_cache(r, args.cache, args.jpeg)
    for r in rows:
        arr = _load(r)
        for v in variants:
            for k, x in score(arr, v, args.source).items():
                r[f"{v.label()}|{k}"] = x
    if args.ceiling:
        by_name = {r["name"]: r for r in rows}
        for r in rows:
            src = _source_name(r, by_name)
            if src is None:
                continue
            arr, sarr = _load(r), _load(by_name[src])
            for v in variants:
                r[f"{v.label()}|change"] = change(arr, sarr, v)
    n_none = sum(r["kind"] == "none" for r in rows)
    print(f"{len(rows)} photos ({n_none} untouched), seeds {args.seeds or 'all'}, "
          f"depth {args.source}")
    print("\n".join(report(rows, variants)))
    if args.ceiling:
        print("\n".join(ceiling_lines(rows, variants)))
    for v in variants[:args.detail]:
        for key in ("e", "z"):
            print("\n".join(per_preset(rows, v, key)))
    if args.out:
        with open(args.out, "w", newline="") as f:
            keys = list(dict.fromkeys(k for r in rows for k in r
                                      if k not in ("path", "path_photo", "scene")))
            w = csv.DictWriter(f, keys, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bench", type=Path)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--slices", type=int, default=128)
    p.add_argument("--far", type=float, default=100.0)
    p.add_argument("--cache", type=Path, default=None,
                   help="cache per-photo arrays here and score --variant on them")
    p.add_argument("--variant", action="append",
                   help="Variant fields, key=value,... (e.g. gain=totem,white=0.9); "
                        "repeat for several; default baseline")
    p.add_argument("--seeds", default=None, help="comma-separated scene seeds")
    p.add_argument("--source", default="truth", choices=("truth", "sgm"))
    p.add_argument("--channels", action="store_true",
                   help="include channel copies (names with '+', e.g. +jpeg75)")
    p.add_argument("--jpeg", type=int, default=None,
                   help="compare the photo saved as a JPEG of this quality (the fit's "
                        "totem rays unchanged)")
    p.add_argument("--ceiling", action="store_true",
                   help="also each edit's own size at the prediction's resolution")
    p.add_argument("--detail", type=int, default=1,
                   help="print the per-preset table of the first N variants")
    args = p.parse_args(argv)
    if args.cache is not None:
        return run_variants(args)
    rows = []
    runs = json.loads((args.bench / "bench.json").read_text())["runs"]
    for run in runs:
        if run.get("mode") != "joint" or run.get("status") != "ok":
            continue
        sd = Path(run["scene"])
        fit_dir = args.bench / "runs" / f"{run.get('fit_from') or run['name']}-joint" / "fit"
        if not fit_dir.is_dir() or not (sd / "truth" / "reach.npz").is_file():
            continue
        tj = sd / "truth" / "tamper.json"
        kind = json.loads(tj.read_text())["kind"] if tj.is_file() else "none"
        row = {"name": sd.name, "kind": kind, "preset": run.get("preset"),
               **study(sd, fit_dir, args.slices, args.far)}
        rows.append(row)
        print(" ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in row.items()), flush=True)
    keys = [k for k in rows[0] if k.endswith(("_e", "_z"))]
    neg = defaultdict(list)
    for r in rows:
        if r["kind"] == "none":
            for k in keys:
                neg[k].append(r[k])
    print("\nAUC against the untouched photos")
    for kind in sorted({r["kind"] for r in rows} - {"none"}):
        pos = [r for r in rows if r["kind"] == kind]
        print(f"{kind:10s} ({len(pos)}) " + "  ".join(
            f"{k} {auc(neg[k], [r[k] for r in pos]):.2f}" for k in keys))
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
