"""Fit the frustum radiance grid and the totem centres to the photo's totem pixels.

Only the totem pixels are used (never the rest of the photo). The model (see
:mod:`inverse.integrator`): a totem pixel sees ``T_F * C`` in linear RGB, ``T_F`` the
Fresnel transmittance of its sphere and ``C`` the grid's radiance along the refracted
ray. The loss compares in **sRGB** (``srgb(T_F C)`` against the 8-bit pixel), the space
of the photo and of the recon L1 metric, so dark regions weigh as they will be judged.

Loss = photometric MSE (sRGB)
     + TV of density and colour (Plenoxels; squared neighbour differences)
     + distortion (Mip-NeRF 360) on each ray's weights: the scene is opaque surfaces
     + pose term: ``inverse.outline.outline_loss`` (tangent cone vs mask outline).

The glass also reflects: a totem pixel is modelled as ``T_F C + R_F a``, ``R_F = 1 -
sqrt(T_F)`` the Fresnel reflectance of its front surface and ``a`` one ambient linear
colour (fitted; starts at the mean observed radiance). Without it, dark regions seen
through the totems take the tint of the reflected room (measured: box seed 1 at
320x240, recon L1 0.078 -> 0.068; envmap seed 1, 0.104 -> 0.090). Two things that did
not help (640x480): a lat-long map of the reflected environment (16 x 32, fitted in log
radiance) in place of the one colour took light from the scene (5x the true reflection,
rendered by Mitsuba with the glass's transmission off; recon L1 box 0.10 -> 0.16,
envmap 0.08 -> 0.16); and subtracting that true reflection from the totem pixels
before the fit left the view no better (envmap seeds 1, 2: 0.065 -> 0.071, 0.067 -> 0.074).
The rays still carry light the model does not take off: where they meet the surface
the camera sees, they are 1.35x as bright as the truth on envmap scenes and 1.09x on
box scenes (``benchmarks/geometry_bound.py``, seeds 1-5; the environment behind the
camera is bright, and the glass reflects it at its front and again inside). Three
models of it were fitted on envmap seeds 1, 3 and 5 and box seed 1 (2026-12-01,
640x480; recon L1 against 0.065 / 0.123 / 0.094 and 0.059) and dropped: the reflected
weight ``R (1 + T_F)`` (the path reflected once inside the sphere too), 0.063 / 0.172
/ 0.095 and 0.059 (seed 3 then took the stereo view, which suits it worse); that
weight with one ambient colour per totem, 0.063 (envmap seed 1) and 0.060 (box seed
1); an ambient linear in the reflected direction (first-order spherical harmonics),
0.074 / 0.126 on envmap seeds 1 and 3, although the held-out totems' error fell (0.067
-> 0.060 on seed 1). The one colour learnt ten times faster comes to the same (linear
0.54, 0.12, 0.05 on seed 1) and so does the view. The brightness is not what keeps
envmap above 0.08: the view scaled by the oracle gain (the truth's mean over the
view's) averages 0.082.

What the rays carry beyond the scene is mostly that reflected environment, and it is not
separable by the models here (measured 2026-12-02, envmap seeds 1-5, 640x480). Against
the truth where the rays land (true centres and depth), a lat-long map of the
environment (16 x 32) seen along the two reflected paths, the front surface's (Fresnel
``F``) and the one reflected once inside (``(1 - F)^2 F``), fitted by least squares to
what the truth leaves unexplained, each totem's map from the other three, takes the
rays' sRGB error from 0.074-0.098 to 0.052-0.078 and the view splatted at the true depth
from 0.100 to 0.076 on average (0.079 -> 0.059, 0.092 -> 0.075, 0.119 -> 0.088, 0.102 ->
0.060, 0.107 -> 0.099); the front path alone does less (seed 3: 0.097). Without the
truth the map takes scene light: fitted to what the grid leaves unexplained, the view
stayed as it was (seeds 1, 2, 3, 5: 0.065, 0.068, 0.122, 0.094) and the stereo's
hold-out did not improve (seed 3: 0.099 -> 0.117); fitted to what the other totems' rays
predict at the grid's depth, the view splatted there went 0.073 -> 0.068 and 0.124 ->
0.113 on seeds 1 and 3, but the grid's own view, which the hold-out still prefers, stays
0.065 and 0.120. (The same map in the loss, in log radiance, took scene light too: see
above.)

The camera view (``FitSettings.stereo``, on by default): the grid's geometry is
weakly determined (a far backdrop explains each totem ray on its own), so after the
fit it is compared with plane-sweep stereo between the totems, and the one that
predicts held-out totems better gives the view, pixel by pixel (:mod:`inverse.view`):
where stereo wins, the view is splatted from the totem rays at its depth rather than
rendered from the grid; ``fit.json``'s ``geometry`` says how much. (Starting the grid
from the stereo depth instead was measured and dropped: the fit drifted from it, box
seed 2 recon L1 0.098 splatted -> 0.109-0.135 fitted.) The sweep's settings
(``stereo_*``: 128 slices, 0.7-cell splats, SGM penalties 1 and 8) were tuned on
held-out scenes (box seeds 11-18, 640x480, the fits' totem rays): the view splatted at
the stereo depth, recon L1 0.098 -> 0.089 against 64 slices, 1.5 cells, penalties 0.3
and 3; on the benchmark's box seeds 1-5, 0.106 -> 0.095 (at the true depth: 0.071).

Schedule: coarse to fine (the grid is resampled between stages), Adam
(``mi.ad.Adam``); the totem centres are frozen for the first part of the steps, then
fitted jointly (unless ``fixed_pose`` or ``true_pose``); the fitted centres are kept
only if they render the totem pixels better than the initial ones with the final grid.

The far plane is effectively at infinity (``far_factor`` 1000 times the farthest totem
depth; the grid is uniform in inverse depth, so this costs little depth resolution):
what lies beyond the far plane is drawn as a backdrop at the far plane, and a backdrop
only 6 totem depths away put a distant environment ~7 degrees off for a totem 1.3 m from
the camera. Measured at 640x480 (fixed pose), recon L1 over the image above the totems,
far 6x -> 1000x: envmap seeds 1, 2: 0.107 -> 0.076, 0.115 -> 0.076; box seeds 2, 3:
0.140 -> 0.127, 0.121 -> 0.110; box seed 1 alone got worse, 0.054 -> 0.068 (its back
wall sat near the old far plane, which acted as a wall prior).

Totem rays that leave the frustum through its top face (ceiling, lights, sky: what
the camera does not see) are left out of the loss: their opaque backdrop on that face
painted the top rows of the view (a box scene's back wall came back white, an untouched
photo scored 0.33 and was called inconsistent). Measured at 640x480, fixed pose, on
box seeds 1-3 and envmap seeds 2-3: verdict score of the untouched photos 0.114, 0.103,
0.330, 0.105, 0.145 -> 0.090, 0.096, 0.129, 0.095, 0.156; recon L1 0.072, 0.128, 0.123,
0.068, 0.131 -> 0.070, 0.145, 0.125, 0.068, 0.128 (box seed 2 worse: its protected region
shrinks from 76 % to 58 % of the photo). Rays leaving through the other sides are kept:
dropping all of them lost the floor below the view.

Rays that, leaving their sphere, run into another totem are kept, though they bring
back that sphere's glass, not the scene: few (0.3-1.4 %: 153 of 20429 on box seed 4),
but wrong by far (sRGB error against the truth where they land, true centres and depth,
0.21-0.23 against 0.06-0.09 for the others; box seed 4, envmap seeds 1 and 5). Leaving
them out (2026-12-02, the whole standard set refitted at 640x480) moved box recon L1
0.094 -> 0.093 (seed 4 0.137 -> 0.135), but on envmap seed 3 the grid's hold-out rose
0.108 -> 0.114, stereo won it (ratio 0.85) and the view went 0.123 -> 0.190: envmap
0.084 -> 0.098, and its untouched photo was called inconsistent. That choice is
fragile there (see ``inverse.view.choose_view``'s margin): box seed 2 needs stereo at
a ratio of 0.81, so no margin takes both.

The colour grid is coarse in depth (``colour_depth`` slices): a column of the camera
view shows one surface, and a colour that may vary freely along the depth would let
each totem see its own colour along the same column (the streaks along the viewing
direction an unregularised grid shows).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from scenes import backend, camera
from inverse.grid import FrustumFrame, frame_for_scene, resample
from scenes import folder
from scenes.colour import linear_to_srgb, srgb_to_linear
from scenes.errors import BadInput

FIT_FILES = ("totem_pose.npy", "initial_totem_pose.npy", "grid.npz", "recon.png",
             "totem_views.png", "fit.json", "totem_points.npy", "totem_rays.npz")


@dataclass
class FitSettings:
    """Everything that shapes a fit (stored in ``fit.json``).

    Grid resolutions are (depth slices, rows, columns). ``stages`` lists (fraction of
    the final image-plane and depth resolution, steps).
    """

    density_res: tuple = (48, 60, 80)
    colour_res: tuple = (1, 120, 160)
    stages: tuple = ((0.5, 200), (1.0, 200))
    n_samples: int = 64
    lr_density: float = 0.3
    lr_colour: float = 0.02
    lr_pose: float = 5e-5            # metres per step (Adam)
    tv_density: float = 0.01
    tv_colour: float = 1.0
    distortion: float = 1e-2
    outline: float = 1e-2            # per squared pixel of outline residual
    pose_start: float = 0.5          # fraction of all steps before centres move
    density_init: float = -4.0       # raw density (softplus -> 0.018 per 1/100)
    erode_px: int = 1                # mask erosion: drop the blurred rim
    margin: float = 0.15
    near_factor: float = 0.5
    far_factor: float = 1000.0       # far plane: effectively at infinity (see notes)
    render_samples: int = 128
    seed: int = 0
    reflection: bool = True          # model the glass's front reflection (an ambient colour)
    drop_top_exits: bool = True      # ignore totem rays leaving through the top (see notes)
    lr_ambient: float = 0.002
    stereo: bool = True              # keep stereo's geometry where held-out totems say so
    stereo_res: tuple = (120, 160)   # (rows, columns) of the stereo depth maps
    stereo_slices: int = 128
    stereo_sigma: float = 0.7        # cells: each totem ray's splat in the sweep
    stereo_p1: float = 1.0           # semi-global matching penalties (median costs)
    stereo_p2: float = 8.0
    stereo_margin: float = 0.9       # stereo must beat the grid's hold-out by 10 %
    stereo_far_biases: tuple = (0.0, 1.0)

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


@dataclass
class FitResult:
    """The outcome of a fit (see ``notes/interfaces.md``)."""

    centers: np.ndarray            # (n, 3) fitted centres, camera frame, metres
    initial: np.ndarray            # (n, 3) initial centres
    recon: np.ndarray              # (H, W, 3) sRGB [0, 1] float32, the re-rendered camera view
    recon_depth: np.ndarray | None  # (H, W) metres, depth along camera rays
    totem_points: np.ndarray       # (m, 3) camera-frame points where totem rays end
    totem_pred: np.ndarray         # (H, W, 3) sRGB fitted colour at totem pixels, 0 elsewhere
    grid: dict                     # density, colour, frame (np arrays)
    history: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    scene_fingerprint: str = ""
    geometry: dict = field(default_factory=dict)  # chosen geometry, hold-out errors
    ambient: list = field(default_factory=list)   # fitted linear RGB the glass reflects
                                                  # ([] without FitSettings.reflection)
    rays: "TotemRays | None" = None  # the totem pixels' rays leaving the glass


@dataclass
class TotemRays:
    """The totem pixels as rays into the scene, at the fitted centres (camera frame).

    What each totem pixel saw, with the glass undone: the ray leaves its sphere at
    ``o`` (m, 3) metres in direction ``d`` (m, 3, unit) and brought back the linear RGB
    ``radiance`` (m, 3), the pixel's colour with the front reflection taken off and
    divided by the Fresnel transmittance. ``totem`` (m,) is the sphere each left,
    ``cos_in`` (m,) the incidence cosine at its surface (rim rays near 0). Only rays
    that pass through the glass with transmittance above 5 % are kept. It holds no
    colour but the totem pixels'. With the camera's K the directions give away the
    IoR (and the exit points the radius), so it belongs to the defender: ``fit/`` is
    not for sharing, unlike ``verify/`` (which holds no ray).
    """

    o: np.ndarray
    d: np.ndarray
    radiance: np.ndarray
    totem: np.ndarray
    cos_in: np.ndarray

    def to_dict(self) -> dict:
        return {"o": self.o.astype(np.float32), "d": self.d.astype(np.float32),
                "radiance": self.radiance.astype(np.float32),
                "totem": self.totem.astype(np.int32), "cos_in": self.cos_in.astype(np.float32)}

    @classmethod
    def from_dict(cls, z) -> "TotemRays":
        m = len(z["totem"])
        arrays = {k: np.asarray(z[k], np.float64) for k in ("o", "d", "radiance", "cos_in")}
        if any(a.shape[0] != m for a in arrays.values()) or arrays["o"].shape != (m, 3) \
                or arrays["d"].shape != (m, 3) or arrays["radiance"].shape != (m, 3):
            raise ValueError("totem_rays arrays disagree in shape")
        return cls(totem=np.asarray(z["totem"], np.int64), **arrays)


# --------------------------------------------------------------------------- helpers

def scene_fingerprint(scene: folder.Scene) -> str:
    """Hash of what a fit depends on: totem pixels, masks, K, key and any initial pose.

    The fit reads the photo only inside the totem masks, so a photo edited elsewhere (the
    forger's case) shares the fit of the original, while a fit of another scene, of a
    photo whose totem pixels changed, or made with another key, differs. The key enters
    only through a hash, so the fingerprint can be shared.
    """
    masks = np.asarray(scene.masks, bool)
    totem_px = np.asarray(scene.image)[masks.any(0)]
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.round(totem_px * 255).astype(np.uint8)).tobytes())
    h.update(np.packbits(masks).tobytes())
    h.update(repr(masks.shape).encode())
    h.update(np.round(np.asarray(scene.K, np.float64), 6).tobytes())
    h.update(folder.key_fingerprint(scene.radius, scene.ior).encode())
    if scene.initial_pose is not None:      # a given initial pose replaces the masks' one
        h.update(np.round(np.asarray(scene.initial_pose, np.float64), 6).tobytes())
    return h.hexdigest()[:16]


def _dr_linear_to_srgb(x):
    """Differentiable linear -> sRGB on a Dr.Jit array (clamped to [1e-6, 1])."""
    import drjit as dr
    x = dr.clip(x, 1e-6, 1.0)
    return dr.select(x <= 0.0031308, 12.92 * x, 1.055 * dr.power(x, 1 / 2.4) - 0.055)


def _check_scene(scene: folder.Scene):
    img = np.asarray(scene.image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise BadInput(f"photo must be (H, W, 3), got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise BadInput("photo has NaN or infinite values: re-export it as an 8-bit PNG")
    masks = np.asarray(scene.masks, dtype=bool)
    if masks.ndim != 3 or masks.shape[1:] != img.shape[:2]:
        raise BadInput("totem masks must be (n, H, W) and the size of the photo")
    if masks.shape[0] == 0 or not masks.any():
        raise BadInput("no totem pixels: the totem masks are empty (white = totem)")
    if len(np.ravel(scene.radius)) != masks.shape[0] or \
            len(np.ravel(scene.ior)) != masks.shape[0]:
        raise BadInput("the key must give one radius and IoR per totem mask")


def _totem_pixels(masks: np.ndarray, erode_px: int):
    """Pixels (u, v) and totem index of every (eroded) totem pixel, each pixel once."""
    from scipy.ndimage import binary_erosion

    us, vs, js = [], [], []
    taken = np.zeros(masks.shape[1:], dtype=bool)
    for j, m in enumerate(masks):
        m = np.asarray(m, dtype=bool)
        if erode_px > 0:
            e = binary_erosion(m, iterations=erode_px)
            m = e if e.sum() >= 20 else m
        m = m & ~taken
        taken |= m
        v, u = np.nonzero(m)
        us.append(u)
        vs.append(v)
        js.append(np.full(u.size, j))
    return np.concatenate(us), np.concatenate(vs), np.concatenate(js)


class _TV:
    """Squared-difference total variation of a grid tensor (mean over neighbour pairs)."""

    def __init__(self, shape):
        import drjit as dr
        import mitsuba as mi

        D, Hh, Ww, C = shape
        idx = np.arange(D * Hh * Ww * C).reshape(D, Hh, Ww, C)
        a = [idx[1:].ravel(), idx[:, 1:].ravel(), idx[:, :, 1:].ravel()]
        b = [idx[:-1].ravel(), idx[:, :-1].ravel(), idx[:, :, :-1].ravel()]
        self.a = [mi.UInt32(x.astype(np.uint32)) for x in a if x.size]
        self.b = [mi.UInt32(x.astype(np.uint32)) for x in b if x.size]
        self.count = float(max(1, sum(x.size for x in a)))
        self._dr = dr

    def __call__(self, tensor):
        import mitsuba as mi

        dr = self._dr
        x = tensor.array
        total = mi.Float(0.0)
        for a, b in zip(self.a, self.b):
            total += dr.sum(dr.square(dr.gather(mi.Float, x, a) - dr.gather(mi.Float, x, b)))
        return total / self.count


# --------------------------------------------------------------------------- the fit

def fit_scene(scene: folder.Scene, *, fixed_pose: bool = False,
              settings: FitSettings | None = None, progress: bool = False,
              true_pose=None) -> FitResult:
    """Fit the radiance grid (and the totem centres) to the totem pixels of ``scene``.

    Parameters
    ----------
    scene : the scene folder in memory (photo, K, masks, key, optional initial pose).
    fixed_pose : keep the centres at their initialisation.
    settings : :class:`FitSettings` (defaults if None).
    progress : show a tqdm bar with the loss.
    true_pose : (n, 3) oracle centres (benchmarks): used as given, fixed.

    Returns
    -------
    :class:`FitResult`; recon in sRGB [0, 1].

    Raises
    ------
    BadInput
        No totem pixels, a photo with NaN, or a key for which no refracted ray is
        usable (impossible pose).
    """
    backend.use()
    import drjit as dr
    import mitsuba as mi

    from inverse import integrator as itg_mod

    t_start = time.perf_counter()
    settings = settings or FitSettings()
    _check_scene(scene)
    W, H = scene.size
    K = np.asarray(scene.K, dtype=np.float64)
    n_tot = scene.masks.shape[0]
    radius = np.broadcast_to(np.asarray(scene.radius, float), (n_tot,)).copy()
    ior = np.broadcast_to(np.asarray(scene.ior, float), (n_tot,)).copy()

    # ---- initial pose
    t0 = time.perf_counter()
    if true_pose is not None:
        initial = np.asarray(true_pose, dtype=np.float64).reshape(n_tot, 3)
        fixed_pose = True
    elif scene.initial_pose is not None:
        initial = np.asarray(scene.initial_pose, dtype=np.float64)
    else:
        from inverse.pose import initial_pose
        initial = initial_pose(scene.masks, K, radius)
    t_pose = time.perf_counter() - t0

    # ---- totem pixels and observed colours
    u, v, jt = _totem_pixels(scene.masks, settings.erode_px)
    d_cam = camera.pixel_rays(K, u, v).astype(np.float32)
    observed = np.asarray(scene.image, np.float32)[v, u]          # sRGB

    frame = frame_for_scene(K, (W, H), initial, radius, margin=settings.margin,
                            near_factor=settings.near_factor, far_factor=settings.far_factor)

    # ---- which rays are usable at the initial pose
    itg = itg_mod.TotemGridIntegrator(mi.Properties())
    itg.drop_top_exits = bool(settings.drop_top_exits)
    itg.n_samples = settings.n_samples
    d0 = np.full(tuple(settings.density_res) + (1,), settings.density_init, np.float32)
    c0 = np.full(tuple(settings.colour_res) + (3,), 0.2, np.float32)
    itg.setup(frame, d0[:2, :2, :2], c0[:2, :2, :2], initial, radius, ior)
    _, valid0, *_ = itg.render_totem_rays(d_cam, jt, n=2)
    valid0 = np.asarray(valid0, dtype=bool)
    if valid0.sum() < 20:
        raise BadInput("no usable refracted rays through the totems with this key: check "
                       "the radius and IoR in totems.json")
    u, v, jt, d_cam, observed = u[valid0], v[valid0], jt[valid0], d_cam[valid0], \
        observed[valid0]
    n_rays = u.size

    # Initial colour: the mean observed radiance, undoing the Fresnel loss (~0.9).
    mean_lin = srgb_to_linear(observed).mean(0) / 0.9
    # The glass also reflects (Fresnel R = 1 - sqrt(T_F) at each of the two equal
    # interfaces): modelled as R times one ambient linear colour, first the mean.
    _, _, T_np, ok_np = _totem_rays_np(itg, d_cam, jt)
    refl_np = np.where(ok_np, 1.0 - np.sqrt(np.clip(T_np, 0.0, 1.0)), 0.0) \
        if settings.reflection else np.zeros(n_rays)
    ambient0 = srgb_to_linear(observed).mean(0)
    obs_dr = mi.Color3f(observed[:, 0], observed[:, 1], observed[:, 2])
    refl_dr = mi.Float(refl_np.astype(np.float32))
    ambient = mi.Float(ambient0.astype(np.float32))

    # ---- schedule
    stages = [(float(f), int(s)) for f, s in settings.stages]
    total_steps = sum(s for _, s in stages)
    pose_step = int(round(settings.pose_start * total_steps))
    learn_pose = not fixed_pose
    outline_term = None
    if learn_pose and settings.outline > 0:
        outline_term = _outline_term(scene.masks, K, radius)

    history = {"loss": [], "photo": [], "tv": [], "distortion": [], "pose": [],
               "stage": []}
    step_times = []
    step = 0
    density = d0
    colour = np.broadcast_to(mean_lin.astype(np.float32),
                             tuple(settings.colour_res) + (3,)).copy()
    centers = initial.copy()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=total_steps, desc="fit", unit="step", leave=False)

    for frac, n_steps in stages:
        dres = tuple(max(2, int(round(r * frac))) for r in settings.density_res)
        cres = (settings.colour_res[0],) + tuple(max(2, int(round(r * frac)))
                                                for r in settings.colour_res[1:])
        density = resample(density, dres)
        colour = resample(colour, cres)
        itg.setup(frame, density, colour, centers, radius, ior)
        params = mi.traverse(itg)
        opt = mi.ad.Adam(lr=settings.lr_density)
        opt["density"] = params["density"]
        opt["colour"] = params["colour"]
        opt.set_learning_rate({"density": settings.lr_density, "colour": settings.lr_colour})
        if settings.reflection:
            opt["ambient"] = ambient
            opt.set_learning_rate({"ambient": settings.lr_ambient})
        params.update(opt)
        tv_d, tv_c = _TV(density.shape), _TV(colour.shape)
        pose_on = False
        for _ in range(n_steps):
            ts = time.perf_counter()
            if learn_pose and not pose_on and step >= pose_step:
                opt["centers"] = params["centers"]
                opt.set_learning_rate({"centers": settings.lr_pose})
                params.update(opt)
                pose_on = True
            L, valid, w, m, *_ = itg.render_totem_rays(d_cam, jt)
            if settings.reflection:
                amb = opt["ambient"]
                L = L + refl_dr * mi.Color3f(*[
                    dr.gather(mi.Float, amb, i, mode=dr.ReduceMode.Direct) for i in range(3)])
            pred = mi.Color3f(*[_dr_linear_to_srgb(L[i]) for i in range(3)])
            vmask = dr.select(valid, 1.0, 0.0)
            diff = pred - obs_dr
            photo = dr.sum(vmask * (dr.square(diff.x) + dr.square(diff.y)
                                    + dr.square(diff.z))) / (3.0 * n_rays)
            tv = settings.tv_density * tv_d(params["density"]) + \
                settings.tv_colour * tv_c(params["colour"])
            dist = dr.sum(vmask * itg_mod.distortion(w, m, itg.n_samples)) / n_rays
            loss = photo + tv + settings.distortion * dist
            pose_l = mi.Float(0.0)
            if pose_on and outline_term is not None:
                pose_l = outline_term(params["centers"])
                loss = loss + settings.outline * pose_l
            dr.backward(loss)
            opt.step()
            params.update(opt)
            history["loss"].append(float(loss[0]))
            history["photo"].append(float(photo[0]))
            history["tv"].append(float(tv[0]))
            history["distortion"].append(float(dist[0]))
            history["pose"].append(float(pose_l[0]))
            history["stage"].append(frac)
            step_times.append(time.perf_counter() - ts)
            step += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{history['loss'][-1]:.4g}")
        density = np.array(params["density"].numpy())
        colour = np.array(params["colour"].numpy())
        if settings.reflection:
            ambient = mi.Float(np.maximum(np.asarray(opt["ambient"]), 0.0))
        if pose_on:
            centers = itg.center_numpy()
    if bar is not None:
        bar.close()
    centers = itg.center_numpy() if learn_pose else initial.copy()
    pose_accepted = None
    if learn_pose:
        # Keep the fitted centres only if they explain the totem pixels better than
        # the initial ones with the same grid (the photometric term is biased by what
        # the model leaves out: highlights, inter-reflections).
        amb_np = np.maximum(np.asarray(ambient, np.float64), 0.0)
        e_fit = _photo_error(itg, frame, density, colour, centers, radius, ior, d_cam,
                             jt, observed, refl_np, amb_np)
        e_init = _photo_error(itg, frame, density, colour, initial, radius, ior, d_cam,
                              jt, observed, refl_np, amb_np)
        pose_accepted = bool(e_fit < e_init)
        history["pose_check"] = [e_init, e_fit]
        if not pose_accepted:
            centers = initial.copy()

    # ---- outputs
    t0 = time.perf_counter()
    itg.setup(frame, density, colour, centers, radius, ior)
    recon, depth = render_view(itg, frame, (W, H), n=settings.render_samples)
    L, valid, w, m, g0, g1 = itg.render_totem_rays(d_cam, jt)
    pred = linear_to_srgb(np.asarray(L).T + refl_np[:, None] * np.asarray(ambient)[None])
    totem_pred = np.zeros((H, W, 3), np.float32)
    totem_pred[v, u] = pred
    totem_points = _peak_points(frame, np.asarray(w), np.asarray(m), np.asarray(g0),
                                np.asarray(g1), itg.n_samples, np.asarray(valid, bool))
    t_render = time.perf_counter() - t0

    rays = exit_rays(itg, centers, radius, d_cam, jt, observed, refl_np,
                     np.maximum(np.asarray(ambient, np.float64), 0.0))

    # ---- the grid's geometry against plane-sweep stereo, judged on held-out totems
    t0 = time.perf_counter()
    geometry = {"chosen": "grid", "holdout_L1": {}}
    if settings.stereo:
        view = _stereo_view(rays, frame, density, recon, totem_points, (W, H), settings)
        geometry = {"chosen": view.chosen, "stereo_share": round(view.stereo_share, 4),
                    "holdout_L1": {k: round(float(e), 5) for k, e in view.holdout.items()}}
        recon, depth, totem_points = view.recon, view.depth, view.points
    t_stereo = time.perf_counter() - t0

    steady = float(np.median(step_times[1:])) if len(step_times) > 1 else None
    timings = {
        "pose_init_s": t_pose,
        "first_step_s": step_times[0] if step_times else None,
        "steady_step_s": steady,
        "optimise_s": float(np.sum(step_times)),
        "render_s": t_render,
        "stereo_s": t_stereo,
        "total_s": time.perf_counter() - t_start,
        "n_rays": int(n_rays),
        "pose_accepted": pose_accepted,
        "n_samples": int(settings.n_samples),
    }
    # Compile time: the first step of each stage compiles new kernels.
    firsts, i = [], 0
    for _, s in stages:
        if s:
            firsts.append(step_times[i])
        i += s
    if steady is not None:
        timings["compile_s_estimate"] = float(sum(max(0.0, f - steady) for f in firsts))
    amb_fit = [float(x) for x in np.maximum(np.asarray(ambient, np.float64), 0.0)] \
        if settings.reflection else []
    grid = {"density": density, "colour": colour, **frame.to_dict(),
            "n_samples": np.int64(settings.n_samples)}
    return FitResult(centers=centers, initial=initial, recon=recon, recon_depth=depth,
                     totem_points=totem_points, totem_pred=totem_pred, grid=grid,
                     history=history, timings=timings, settings=settings.to_dict(),
                     scene_fingerprint=scene_fingerprint(scene), geometry=geometry,
                     rays=rays, ambient=amb_fit)


def _photo_error(itg, frame, density, colour, centers, radius, ior, d_cam, jt, observed,
                 refl, ambient) -> float:
    """Mean squared sRGB error of the totem pixels rendered with ``centers``."""
    import drjit as dr

    itg.setup(frame, density, colour, centers, radius, ior)
    with dr.suspend_grad():
        L, valid, *_ = itg.render_totem_rays(d_cam, jt)
    pred = linear_to_srgb(np.asarray(L).T + refl[:, None] * ambient[None])
    ok = np.asarray(valid, bool)
    err = np.square(pred - observed).sum(1)
    return float(np.where(ok, err, 3.0).mean())


def _totem_rays_np(itg, d_cam, jt):
    """Refracted rays at the integrator's centres, numpy: exit points (m, 3) metres,
    unit directions (m, 3), Fresnel transmittance (m,), valid (m,)."""
    o_out, d_out, T_F, ok = itg.refract(d_cam, jt)
    return (np.asarray(o_out, np.float64).T.reshape(-1, 3),
            np.asarray(d_out, np.float64).T.reshape(-1, 3),
            np.asarray(T_F, np.float64).reshape(-1), np.asarray(ok, bool).reshape(-1))


def column_depth(density, frame: FrustumFrame) -> np.ndarray:
    """Depth (metres) where each camera column of a raw density grid (nr, nt, ns, 1)
    reaches transmittance 1/2 (the far plane if it never does), (nt, ns)."""
    from inverse.integrator import DELTA_SCALE

    dens = np.asarray(density, np.float64)[..., 0]
    nr = dens.shape[0]
    tau = np.cumsum(np.logaddexp(0.0, dens) * DELTA_SCALE / nr, axis=0)
    k = np.where(tau[-1] > np.log(2.0), np.argmax(tau > np.log(2.0), axis=0), nr - 1)
    r = (k + 0.5) / nr
    return 1.0 / (1.0 / frame.near - r * (1.0 / frame.near - 1.0 / frame.far))


def exit_rays(itg, centers, radius, d_cam, jt, observed, refl, ambient) -> TotemRays:
    """The totem pixels' rays leaving the glass at the integrator's centres.

    ``observed`` (m, 3) sRGB of the pixels whose camera rays are ``d_cam`` (m, 3) into
    totems ``jt``; ``refl`` (m,) their front-surface Fresnel reflectance and ``ambient``
    (3,) the fitted linear colour it reflects. See :class:`TotemRays`.
    """
    o, d, T, ok = _totem_rays_np(itg, d_cam, jt)
    keep = ok & (T > 0.05)
    P = np.asarray(centers, np.float64)[jt]
    cos_in = np.abs(((o - P) * d).sum(1)) / np.asarray(radius, np.float64)[jt]
    lin = np.clip(srgb_to_linear(observed) - refl[:, None] * ambient[None], 0.0, None)
    lin = lin / np.maximum(T, 0.05)[:, None]
    return TotemRays(o[keep], d[keep], lin[keep], np.asarray(jt)[keep], cos_in[keep])


def _stereo_view(rays: TotemRays, frame, density, grid_view, grid_points, size, settings):
    """:func:`inverse.view.choose_view` on the totem rays at the final centres."""
    from inverse.view import choose_view

    return choose_view(rays.o, rays.d, rays.radiance, rays.totem, rays.cos_in, frame,
                       column_depth(density, frame), grid_view, grid_points, size,
                       res=settings.stereo_res, n_slices=settings.stereo_slices,
                       far_biases=settings.stereo_far_biases,
                       sweep={"sigma": settings.stereo_sigma, "p1": settings.stereo_p1,
                              "p2": settings.stereo_p2}, margin=settings.stereo_margin)


def _outline_term(masks, K, radius):
    """The differentiable pose term: engineer P's ``outline_loss`` over mask outlines."""
    import drjit as dr
    import mitsuba as mi
    try:
        from inverse.outline import outline_loss
        from inverse.pose import mask_outline_rays
    except ImportError:
        return None
    rays, idx = [], []
    for j, mk in enumerate(masks):
        r = mask_outline_rays(mk, K)
        rays.append(r)
        idx.append(np.full(len(r), j))
    rays = np.concatenate(rays).astype(np.float32)
    idx = np.concatenate(idx)
    rays_dr = mi.Vector3f(rays[:, 0], rays[:, 1], rays[:, 2])
    idx_dr = mi.UInt32(idx.astype(np.uint32))
    R = mi.Float(np.asarray(radius, np.float32))
    n = len(masks)
    fx = float(K[0, 0])

    def term(centers_flat):
        i = dr.arange(mi.UInt32, n)
        P = mi.Point3f(*[dr.gather(mi.Float, centers_flat, i + a * n,
                                     mode=dr.ReduceMode.Direct) for a in range(3)])
        return outline_loss(P, R, rays_dr, idx_dr, scale=fx)

    return term


def render_view(itg, frame: FrustumFrame, size, *, n: int = 128, rows_per_chunk=None):
    """The camera view re-rendered from the grid (no totems).

    Returns
    -------
    recon : (H, W, 3) float32 sRGB [0, 1].
    depth : (H, W) float32 metres, the weight-averaged depth along each column.
    """
    import drjit as dr

    W, H = size
    rows_per_chunk = rows_per_chunk or max(1, 2_000_000 // (W * n))
    recon = np.zeros((H, W, 3), np.float32)
    depth = np.zeros((H, W), np.float32)
    inv_near, inv_far = 1.0 / frame.near, 1.0 / frame.far
    for r0 in range(0, H, rows_per_chunk):
        r1 = min(H, r0 + rows_per_chunk)
        vv, uu = np.mgrid[r0:r1, 0:W]
        s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
        with dr.suspend_grad():
            C, w, m = itg.render_columns(s, t, n=n)
        C = np.asarray(C).T
        w = np.asarray(w).reshape(-1, n)
        m = np.asarray(m).reshape(-1, n)
        z = 1.0 / (inv_near - m * (inv_near - inv_far))
        recon[r0:r1] = linear_to_srgb(C).reshape(r1 - r0, W, 3)
        depth[r0:r1] = ((w * z).sum(1) / np.maximum(w.sum(1), 1e-8)).reshape(r1 - r0, W)
    return recon, depth


def _peak_points(frame, w, m, g0, g1, n, valid):
    """Camera-frame point of highest weight along each valid totem ray, (m, 3) metres."""
    w = w.reshape(-1, n)
    k = np.argmax(w, axis=1)
    rows = np.arange(w.shape[0])
    mm = m.reshape(-1, n)[rows, k]
    a = g0.T.reshape(-1, n, 3)[rows, k]
    b = g1.T.reshape(-1, n, 3)[rows, k]
    g = a + mm[:, None] * (b - a)
    pts = frame.from_unit(g)
    return pts[valid & np.all(np.isfinite(pts), axis=1)]


# --------------------------------------------------------------------------- files

def _totem_views(scene_image, totem_pred, masks) -> np.ndarray:
    """Observed (top) and fitted (bottom) totem pixels, cropped to the masks' box."""
    any_m = np.asarray(masks, bool).any(0)
    v, u = np.nonzero(any_m)
    pad = 4
    v0, v1 = max(0, v.min() - pad), min(any_m.shape[0], v.max() + pad + 1)
    u0, u1 = max(0, u.min() - pad), min(any_m.shape[1], u.max() + pad + 1)
    obs = np.where(any_m[..., None], scene_image, 0.0)[v0:v1, u0:u1]
    fit = totem_pred[v0:v1, u0:u1]
    return np.concatenate([obs, np.ones((2, u1 - u0, 3)), fit], 0)


def write_fit(result: FitResult, out_dir, *, scene: folder.Scene | None = None) -> None:
    """Write the fit/ files of the contract (plus ``totem_points.npy`` and
    ``totem_rays.npz``), each atomically.

    ``totem_views.png`` shows observed over fitted totem pixels when ``scene`` is given,
    else the fitted totem pixels alone.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folder.write_npy(out / "totem_pose.npy", np.asarray(result.centers, np.float64))
    folder.write_npy(out / "initial_totem_pose.npy", np.asarray(result.initial, np.float64))
    folder.write_npy(out / "totem_points.npy", np.asarray(result.totem_points, np.float64))
    grid = {k: np.asarray(v) for k, v in result.grid.items()}
    if result.recon_depth is not None:
        grid["recon_depth"] = np.asarray(result.recon_depth, np.float32)
    grid["totem_pred"] = np.asarray(result.totem_pred, np.float32)
    folder.write_npz(out / "grid.npz", **grid)
    if result.rays is not None:
        folder.write_npz(out / "totem_rays.npz", **result.rays.to_dict())
    folder.write_image(out / "recon.png", result.recon)
    if scene is not None:
        views = _totem_views(scene.image, result.totem_pred, scene.masks)
    else:
        mask = np.any(result.totem_pred > 0, axis=2)
        views = _totem_views(result.totem_pred, result.totem_pred, mask[None])
    folder.write_image(out / "totem_views.png", views)
    folder.write_json(out / "fit.json", {
        "scene_fingerprint": result.scene_fingerprint,
        "centers": np.asarray(result.centers).tolist(),
        "initial": np.asarray(result.initial).tolist(),
        "history": result.history, "timings": result.timings,
        "geometry": result.geometry, "ambient": list(result.ambient),
        "settings": result.settings, "versions": backend.describe()})


def load_fit(fit_dir) -> FitResult:
    """Read a fit/ folder written by :func:`write_fit`. BadInput if missing or corrupt."""
    d = Path(fit_dir)
    if not d.is_dir():
        raise BadInput(f"fit folder not found: {d} (run `totems fit` first)")
    for name in ("totem_pose.npy", "initial_totem_pose.npy", "grid.npz", "recon.png",
                 "fit.json", "totem_points.npy"):
        if not (d / name).is_file():
            raise BadInput(f"fit folder {d} lacks {name}: run `totems fit` again")
    try:
        meta = json.loads((d / "fit.json").read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f"{d / 'fit.json'} is not valid JSON ({exc})") from None
    centers = np.asarray(folder.safe_load_npy(d / "totem_pose.npy"), dtype=np.float64)
    initial = np.asarray(folder.safe_load_npy(d / "initial_totem_pose.npy"), np.float64)
    points = np.asarray(folder.safe_load_npy(d / "totem_points.npy"), dtype=np.float64)
    if centers.ndim != 2 or centers.shape[1] != 3 or centers.shape != initial.shape \
            or not np.all(np.isfinite(centers)):
        raise BadInput(f"{d}: totem_pose.npy / initial_totem_pose.npy must be (n, 3) finite")
    if points.ndim != 2 or points.shape[1] != 3:
        raise BadInput(f"{d}: totem_points.npy must be (m, 3)")
    try:
        with np.load(d / "grid.npz", allow_pickle=False) as z:
            grid = {k: z[k] for k in z.files}
    except Exception as exc:
        raise BadInput(f"{d / 'grid.npz'} is unreadable ({exc.__class__.__name__})") from None
    for k in ("density", "colour"):
        if k not in grid or grid[k].ndim != 4:
            raise BadInput(f"{d / 'grid.npz'} lacks a 4-D '{k}' grid")
    FrustumFrame.from_dict(grid)               # validates the frame
    recon = folder.read_image(d / "recon.png", what="fit recon.png")
    depth = grid.pop("recon_depth", None)
    totem_pred = grid.pop("totem_pred", None)
    if totem_pred is None:
        totem_pred = np.zeros_like(recon)
    rays = None
    if (d / "totem_rays.npz").is_file():       # fits written before it have none
        try:
            with np.load(d / "totem_rays.npz", allow_pickle=False) as z:
                rays = TotemRays.from_dict(z)
        except Exception as exc:
            raise BadInput(f"{d / 'totem_rays.npz'} is unreadable "
                           f"({exc.__class__.__name__}): run `totems fit` again") from None
    return FitResult(centers=centers, initial=initial, recon=recon, recon_depth=depth,
                     totem_points=points, totem_pred=totem_pred, grid=grid,
                     history=meta.get("history", {}), timings=meta.get("timings", {}),
                     settings=meta.get("settings", {}),
                     scene_fingerprint=str(meta.get("scene_fingerprint", "")),
                     geometry=meta.get("geometry", {}), rays=rays,
                     ambient=list(meta.get("ambient", [])))


def render_grid(grid: dict, size, *, n: int = 128):
    """Re-render the camera view from a saved grid (``load_fit(...).grid``).

    Returns (recon sRGB (H, W, 3) float32, depth (H, W) metres).
    """
    backend.use()
    import mitsuba as mi

    from inverse.integrator import TotemGridIntegrator

    frame = FrustumFrame.from_dict(grid)
    itg = TotemGridIntegrator(mi.Properties()).setup(frame, grid["density"], grid["colour"])
    return render_view(itg, frame, size, n=n)
