"""Fit the frustum radiance grid and the totem centres to the photo's totem pixels.

Only the totem pixels are used (never the rest of the photo). The model (see
:mod:`inverse.integrator`): a totem pixel sees ``T_F C + R_F a`` in linear RGB, ``T_F``
the Fresnel transmittance of its sphere, ``C`` the grid's radiance along the refracted
ray, ``R_F = 1 - sqrt(T_F)`` the reflectance of the glass's front and ``a`` one ambient
linear colour it reflects (fitted; with ``mirror``, the grid's own radiance along the
mirrored ray where that runs forward through the grid). The loss compares in **sRGB**,
the space of the photo and of the recon L1 metric, so dark regions weigh as they will be
judged:

    loss = photometric MSE (sRGB)
         + TV of density and colour (Plenoxels; squared neighbour differences)
         + distortion (Mip-NeRF 360) on each ray's weights: the scene is opaque surfaces
         + pose term: ``inverse.fit.outline.outline_loss`` (tangent cone vs mask outline).

Schedule: coarse to fine (the grid is resampled between stages), Adam (``mi.ad.Adam``),
each step on a seeded batch of the totem rays (:mod:`inverse.fit.batches`), the coarse
stage with samples in proportion to its depth, the last stage's rates falling;
the centres are frozen for the first part of the steps, then fitted jointly (unless
``fixed_pose`` or ``true_pose``), and kept only if they render the totem pixels better
than the initial ones with the final grid.

The far plane is effectively at infinity (``far_factor`` times the farthest totem's
depth; the grid is uniform in inverse depth, so this costs little depth resolution).
Totem rays leaving the grid through its top face (what the camera does not see) are left
out of the loss, since their backdrop painted the view's top rows. The colour grid is
coarse in depth: a column of the camera view shows one surface. After the fit the camera
view is chosen between the grid and stereo (:mod:`inverse.view.view`). What each of these
choices was measured against is in docs/decisions.md.

Stages of :func:`fit_scene`: check the scene, the initial pose, the totem pixels, the
usable rays, the optimisation, the pose check, the outputs (view, totem predictions,
rays), the camera view. The files: :mod:`inverse.fit.files`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from inverse import exact_gather
from inverse.fit.batches import DeviceRays, photo_terms, ray_batches
from inverse.fit.files import FitResult, fit_timings, scene_fingerprint
from inverse.fit.losses import TotalVariation, outline_term
from inverse.grid import FrustumFrame, frame_for_scene, resample, stage_res, stage_samples
from inverse.rays import TotemPixels, TotemRays, exit_rays, refracted_rays, totem_pixels
from inverse.view import view
from inverse.view.support import plane_from_centres, plane_view
from scenes import backend, folder
from scenes.colour import linear_to_srgb, srgb_to_linear
from scenes.errors import BadInput

__all__ = ["FitSettings", "FitResult", "fit_scene"]


@dataclass
class FitSettings:
    """Everything that shapes a fit (stored in ``fit.json``).

    Grid resolutions are (depth slices, rows, columns). ``stages`` lists (fraction of
    the final image-plane and depth resolution, steps). The ``stereo_*`` settings were
    tuned on held-out scenes (docs/decisions.md, "Stereo settings").
    """

    density_res: tuple = (48, 60, 80)
    colour_res: tuple = (1, 120, 160)
    stages: tuple = ((0.5, 125), (1.0, 125))
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
    pose_from: str = "both"          # mask and photo weighed; "photo" / "mask": overrides
    margin: float = 0.15
    near_factor: float = 0.5
    far_factor: float = 1000.0       # far plane: effectively at infinity
    render_samples: int = 128
    seed: int = 0                    # the ray batches' order
    batch_rays: int = 4096           # totem rays per step (0: all of them)
    lr_decay: float = 0.1            # the last stage's rates fall to this fraction
    lr_ambient: float = 0.002
    mirror: bool = False             # the glass reflects the grid's own scene
    stereo: bool = True              # keep stereo's geometry where held-out totems say so
    stereo_res: tuple = (120, 160)   # (rows, columns) of the stereo depth maps
    stereo_slices: int = 128
    stereo_sigma: float = 0.7        # cells: each totem ray's splat in the sweep
    stereo_p1: float = 1.0           # semi-global matching penalties (median costs)
    stereo_p2: float = 8.0
    stereo_margin: float = 0.9       # stereo must beat the grid's hold-out by 10 %
    stereo_far_biases: tuple = (0.0, 1.0)
    resting: bool = False            # the totems rest on one plane: it caps the view

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


@dataclass
class _Model:
    """The grid, centres and ambient colour as the optimisation leaves them."""

    density: np.ndarray
    colour: np.ndarray
    centers: np.ndarray
    ambient: object                 # mi.Float (3,), linear RGB
    history: dict
    step_times: list
    pose_moved: bool


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
    t_start = time.perf_counter()
    settings = settings or FitSettings()
    _check_scene(scene)
    K = np.asarray(scene.K, dtype=np.float64)
    n_tot = scene.masks.shape[0]
    radius = np.broadcast_to(np.asarray(scene.radius, float), (n_tot,)).copy()
    ior = np.broadcast_to(np.asarray(scene.ior, float), (n_tot,)).copy()

    t0 = time.perf_counter()
    initial, fixed_pose, pose_sd = _initial_pose(scene, K, radius, true_pose, fixed_pose,
                                                 settings.pose_from)
    t_pose = time.perf_counter() - t0

    pixels = totem_pixels(scene, K, settings.erode_px)
    frame = frame_for_scene(K, scene.size, initial, radius, margin=settings.margin,
                            near_factor=settings.near_factor,
                            far_factor=settings.far_factor)
    itg = _integrator(settings)
    pixels, refl = _usable_pixels(itg, frame, pixels, initial, radius, ior, settings)
    refl_all = refl                      # the exit rays take the ambient's reflection off
    if settings.mirror:                  # the fit: there the grid's reflection instead
        itg.mirror = True
        refl = np.where(itg.mirrored_numpy(pixels.d_cam, pixels.totem)[1], 0.0, refl)

    learn_pose = not fixed_pose
    plane = plane_from_centres(initial, radius) if settings.resting else None
    model = _optimise(itg, frame, pixels, refl, initial, radius, ior, settings,
                      outline=(_outline(scene, K, radius, initial, settings)
                               if learn_pose and settings.outline > 0 else None),
                      learn_pose=learn_pose, progress=progress)
    centers, pose_accepted = _pose_check(itg, frame, model, pixels, refl, initial,
                                         radius, ior, learn_pose, model.history)

    t0 = time.perf_counter()
    ambient = np.maximum(np.asarray(model.ambient, np.float64), 0.0)
    itg.setup(frame, model.density, model.colour, centers, radius, ior)
    recon, depth = view.render_view(itg, frame, scene.size, n=settings.render_samples)
    totem_pred, totem_points = _totem_outputs(itg, frame, pixels, refl, model.ambient,
                                              scene.size)
    t_render = time.perf_counter() - t0
    rays = exit_rays(itg, centers, radius, pixels.d_cam, pixels.totem, pixels.observed,
                     refl_all, ambient)

    t0 = time.perf_counter()
    geometry = {"chosen": "grid", "holdout_L1": {}}
    if settings.stereo:
        chosen = _camera_view(rays, frame, model.density, recon, totem_points, scene.size,
                              settings)
        geometry = {"chosen": chosen.chosen, "stereo_share": round(chosen.stereo_share, 4),
                    "holdout_L1": {k: round(float(e), 5) for k, e in chosen.holdout.items()}}
        recon, depth, totem_points = chosen.recon, chosen.depth, chosen.points
    geometry["support"] = None if plane is None else plane.to_dict()
    if plane is not None:        # the view capped; the rays' end points (the region) kept
        recon, depth, _, geometry["support"]["share"] = plane_view(
            rays, frame, plane, recon, depth, totem_points, scene.size)
    t_stereo = time.perf_counter() - t0

    timings = fit_timings(model.step_times, settings, t_pose=t_pose, t_render=t_render,
                          t_stereo=t_stereo, t_total=time.perf_counter() - t_start,
                          n_rays=len(pixels.u), pose_accepted=pose_accepted)
    grid = {"density": model.density, "colour": model.colour, **frame.to_dict(),
            "n_samples": np.int64(settings.n_samples)}
    return FitResult(centers=centers, initial=initial, recon=recon, recon_depth=depth,
                     totem_points=totem_points, totem_pred=totem_pred, grid=grid,
                     history=model.history, timings=timings, settings=settings.to_dict(),
                     scene_fingerprint=scene_fingerprint(scene), geometry=geometry,
                     rays=rays, ambient=[float(x) for x in ambient],
                     pose_uncertainty=pose_sd)


# --------------------------------------------------------------------------- stages

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


def _initial_pose(scene, K, radius, true_pose, fixed_pose, pose_from: str = "both"):
    """The centres the fit starts from (n, 3) metres, whether they stay fixed, and their
    uncertainty (fit.json ``pose_uncertainty``, or None): the oracle's (fixed), the
    scene's own ``initial_totem_pose.npy``, or the masks' and photo's
    (:func:`inverse.pose.combined.initial_centres`)."""
    n_tot = scene.masks.shape[0]
    if true_pose is not None:
        return np.asarray(true_pose, dtype=np.float64).reshape(n_tot, 3), True, None
    if scene.initial_pose is not None:
        return np.asarray(scene.initial_pose, dtype=np.float64), fixed_pose, None
    from inverse.pose.combined import initial_centres
    centers, sd = initial_centres(scene.image, scene.masks, K, radius, pose_from)
    return centers, fixed_pose, sd


def _outline(scene, K, radius, initial, settings):
    """The joint fit's pose term: towards the masks' outlines (``pose_from`` mask or a
    given initial pose), else towards the initial centres' outlines."""
    if settings.pose_from != "mask" and scene.initial_pose is None:
        from inverse.pose.rim import outline

        uv = [outline(P, float(r), K)[0] for P, r in zip(initial, radius)]
        return outline_term(None, K, radius, outlines=uv)
    return outline_term(scene.masks, K, radius)


def _integrator(settings: FitSettings):
    """A fresh :class:`inverse.integrator.TotemGridIntegrator`."""
    from inverse.integrator import integrator_class

    mi = backend.modules()[1]
    itg = integrator_class()(mi.Properties())
    itg.n_samples = settings.n_samples
    return itg


def _initial_grids(settings: FitSettings):
    """Raw density and colour grids at full resolution before the fit."""
    d0 = np.full(tuple(settings.density_res) + (1,), settings.density_init, np.float32)
    c0 = np.full(tuple(settings.colour_res) + (3,), 0.2, np.float32)
    return d0, c0


def _usable_pixels(itg, frame, pixels: TotemPixels, initial, radius, ior, settings):
    """The pixels whose refracted ray is valid at the initial centres (BadInput when
    fewer than 20), and each one's front-surface Fresnel reflectance ``R_F`` (m,)."""
    d0, c0 = _initial_grids(settings)
    itg.setup(frame, d0[:2, :2, :2], c0[:2, :2, :2], initial, radius, ior)
    _, valid0, *_ = itg.render_totem_rays(pixels.d_cam, pixels.totem, n=2)
    valid0 = np.asarray(valid0, dtype=bool)
    if valid0.sum() < 20:
        raise BadInput("no usable refracted rays through the totems with this key: check "
                       "the radius and IoR in totems.json")
    pixels = pixels.select(valid0)
    # R_F = 1 - sqrt(T_F): the two interfaces are alike, T_F = (1 - R_F)^2.
    _, _, T, ok = refracted_rays(itg, pixels.d_cam, pixels.totem)
    return pixels, np.where(ok, 1.0 - np.sqrt(np.clip(T, 0.0, 1.0)), 0.0)


def _optimise(itg, frame, pixels: TotemPixels, refl, initial, radius, ior, settings, *,
              outline, learn_pose: bool, progress: bool) -> _Model:
    """Adam over the stages: grids (and from ``pose_start`` on the centres) and the
    ambient colour, on photometric + TV + distortion (+ outline) losses, each step on a
    batch of ``settings.batch_rays`` totem rays (:func:`ray_batches`)."""
    mi = backend.modules()[1]
    rays = DeviceRays.upload(pixels, refl)
    batches = ray_batches(len(pixels.u), settings.batch_rays, settings.seed)
    stages = [(float(f), int(s)) for f, s in settings.stages]
    total_steps = sum(s for _, s in stages)
    pose_step = int(round(settings.pose_start * total_steps))
    history = {"loss": [], "photo": [], "tv": [], "distortion": [], "pose": [],
               "stage": []}
    if learn_pose:
        history["centers"] = []      # (n, 3) per step, metres: the pose's path
    step_times, step = [], 0
    density, _ = _initial_grids(settings)
    # The colour starts at the mean observed radiance, the Fresnel loss (~0.9) undone.
    mean_lin = srgb_to_linear(pixels.observed).mean(0)
    colour = np.broadcast_to((mean_lin / 0.9).astype(np.float32),
                             tuple(settings.colour_res) + (3,)).copy()
    ambient = backend.upload(mi.Float, mean_lin)
    centers, pose_on = initial.copy(), False
    bar = _progress_bar(total_steps) if progress else None
    for k, (frac, n_steps) in enumerate(stages):
        density = resample(density, stage_res(settings.density_res, frac))
        colour = resample(colour, (settings.colour_res[0],)
                          + stage_res(settings.colour_res[1:], frac))
        itg.setup(frame, density, colour, centers, radius, ior)
        itg.n_samples = stage_samples(settings.n_samples, frac)
        params = mi.traverse(itg)
        opt = mi.ad.Adam(lr=settings.lr_density)
        opt["density"] = params["density"]
        opt["colour"] = params["colour"]
        opt.set_learning_rate({"density": settings.lr_density, "colour": settings.lr_colour})
        opt["ambient"] = ambient
        opt.set_learning_rate({"ambient": settings.lr_ambient})
        params.update(opt)
        tv_d, tv_c = TotalVariation(density.shape), TotalVariation(colour.shape)
        pose_on = False
        last = k == len(stages) - 1
        for i in range(n_steps):
            ts = time.perf_counter()
            if last and settings.lr_decay != 1.0:
                _decay(opt, settings, settings.lr_decay ** (i / max(1, n_steps - 1)))
            if learn_pose and not pose_on and step >= pose_step:
                opt["centers"] = params["centers"]
                opt.set_learning_rate({"centers": settings.lr_pose})
                params.update(opt)
                pose_on = True
            batch = rays.batch(next(batches))
            photo, dist = photo_terms(itg, batch, opt["ambient"])
            tv = settings.tv_density * tv_d(params["density"]) + \
                settings.tv_colour * tv_c(params["colour"])
            loss = photo + tv + settings.distortion * dist
            pose_l = mi.Float(0.0)
            if pose_on and outline is not None:
                pose_l = outline(params["centers"])
                loss = loss + settings.outline * pose_l
            _backend_step(loss, opt, params)
            for k, x in (("loss", loss), ("photo", photo), ("tv", tv),
                         ("distortion", dist), ("pose", pose_l)):
                history[k].append(float(x[0]))
            history["stage"].append(frac)
            if learn_pose:
                history["centers"].append(np.round(itg.center_numpy(), 6).tolist())
            step_times.append(time.perf_counter() - ts)
            step += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{history['loss'][-1]:.4g}")
        density = np.array(params["density"].numpy())
        colour = np.array(params["colour"].numpy()).reshape(colour.shape)
        ambient = backend.upload(mi.Float, np.maximum(np.asarray(opt["ambient"]), 0.0))
        if pose_on:
            centers = itg.center_numpy()
    if bar is not None:
        bar.close()
    itg.n_samples = settings.n_samples
    return _Model(density, colour, centers, ambient, history, step_times, pose_on)


def _backend_step(loss, opt, params) -> None:
    """Back-propagate ``loss`` (the grids' gradients summed in fixed point, the same
    on any number of threads: :func:`inverse.exact_gather.backward`), take one Adam
    step and push it into the scene, on every thread the backend has."""
    exact_gather.backward(loss)
    opt.step()
    params.update(opt)


def _decay(opt, settings: FitSettings, factor: float) -> None:
    """Set every learning rate to ``factor`` times its setting."""
    rates = {"density": settings.lr_density, "colour": settings.lr_colour,
             "ambient": settings.lr_ambient, "centers": settings.lr_pose}
    opt.set_learning_rate({k: r * factor for k, r in rates.items() if k in opt.keys()})


def _progress_bar(total: int):
    from tqdm import tqdm

    return tqdm(total=total, desc="fit", unit="step", leave=False)


def _pose_check(itg, frame, model: _Model, pixels, refl, initial, radius, ior,
                learn_pose: bool, history: dict):
    """The fitted centres if they explain the totem pixels better than the initial
    ones with the final grid (the photometric term is biased by what the model leaves
    out: highlights, inter-reflections), else the initial ones; and whether they were
    accepted (None when the pose was not fitted). Records both errors in ``history``."""
    if not learn_pose:
        return initial.copy(), None
    centers = itg.center_numpy()
    amb = np.maximum(np.asarray(model.ambient, np.float64), 0.0)
    e_fit = _photo_error(itg, frame, model, centers, radius, ior, pixels, refl, amb)
    e_init = _photo_error(itg, frame, model, initial, radius, ior, pixels, refl, amb)
    history["pose_check"] = [e_init, e_fit]
    accepted = bool(e_fit < e_init)
    return (centers if accepted else initial.copy()), accepted


def _photo_error(itg, frame, model: _Model, centers, radius, ior, pixels: TotemPixels, refl,
                 ambient) -> float:
    """Mean squared sRGB error of the totem pixels rendered with ``centers``."""
    dr = backend.modules()[0]
    itg.setup(frame, model.density, model.colour, centers, radius, ior)
    with dr.suspend_grad():
        L, valid, *_ = itg.render_totem_rays(pixels.d_cam, pixels.totem)
    pred = linear_to_srgb(np.asarray(L).T + refl[:, None] * ambient[None])
    ok = np.asarray(valid, bool)
    err = np.square(pred - pixels.observed).sum(1)
    return float(np.where(ok, err, 3.0).mean())


def _totem_outputs(itg, frame: FrustumFrame, pixels: TotemPixels, refl, ambient, size):
    """The fitted colour at the totem pixels (H, W, 3) sRGB, 0 elsewhere, and where
    their rays end in the grid (m, 3) camera frame, metres."""
    W, H = size
    L, valid, w, m, g0, g1 = itg.render_totem_rays(pixels.d_cam, pixels.totem)
    pred = linear_to_srgb(np.asarray(L).T + refl[:, None] * np.asarray(ambient)[None])
    totem_pred = np.zeros((H, W, 3), np.float32)
    totem_pred[pixels.v, pixels.u] = pred
    points = view.peak_points(frame, np.asarray(w), np.asarray(m), np.asarray(g0),
                              np.asarray(g1), itg.n_samples, np.asarray(valid, bool))
    return totem_pred, points


def _camera_view(rays: TotemRays, frame, density, grid_view, grid_points, size,
                 settings: FitSettings) -> view.StereoView:
    """:func:`inverse.view.view.choose_view` with the fit's stereo settings."""
    return view.choose_view(rays, frame, view.column_depth(density, frame), grid_view,
                            grid_points, size, res=settings.stereo_res,
                            n_slices=settings.stereo_slices,
                            far_biases=settings.stereo_far_biases,
                            sweep={"sigma": settings.stereo_sigma, "p1": settings.stereo_p1,
                                   "p2": settings.stereo_p2},
                            margin=settings.stereo_margin)

