"""The ``totems`` command: parse, call the library, map errors to exit codes.

Exit codes (as ``cmp``/``diff``): 0 ran (and for verify/check: consistent), 1 verify/check
found the photo inconsistent with its totems, 2 bad input or usage (one line on stderr),
3 masks found too few totems, 4 verify/check: unverifiable.
Everything else is a bug. Verbs and outputs: ``docs/contract.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from verify.cli import arguments, helptext

__all__ = ["main"]

EXIT_OK, EXIT_INCONSISTENT, EXIT_BAD_INPUT, EXIT_INCOMPLETE = 0, 1, 2, 3
EXIT_UNVERIFIABLE = 4
EXIT_BUG = 70                      # an unexpected error (sysexits' EX_SOFTWARE)


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in one line, exit 2."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


# --------------------------------------------------------------------------- verbs

def _progress(args) -> bool:
    return not args.quiet and sys.stderr.isatty()


def cmd_scene_reach(args) -> dict:
    from scenes.synthetic.trace import write_reach

    t0 = time.perf_counter()
    written = [str(write_reach(s)) for s in args.scenes]
    return {"written": written, "seconds": round(time.perf_counter() - t0, 2)}


def cmd_scene_make(args) -> dict:
    from scenes.synthetic.make import make_scene

    t0 = time.perf_counter()
    options = {"spp": args.spp} if args.spp else {}
    out = make_scene(args.out, preset=args.preset, seed=args.seed, size=args.size,
                     n_totems=args.totems, camera=args.camera, progress=_progress(args),
                     placement=args.placement, **options)
    return {"scene": str(out), "preset": args.preset, "seed": args.seed,
            "seconds": round(time.perf_counter() - t0, 2)}


def cmd_tamper(args) -> dict:
    from scenes.folder import read_mask
    from scenes.tamper.tamper import tamper

    region = args.region
    if args.region_mask:
        region = read_mask(args.region_mask, what="region mask")
    out = tamper(args.scene, args.out, kind=args.kind, seed=args.seed, region=region,
                 tool=args.tool, totems=args.totem, key_error=args.key_error, edit=args.edit)
    return {"scene": str(out), "kind": args.kind, "seed": args.seed}


def cmd_recapture(args) -> dict:
    from scenes.channel.channel import Channel
    from scenes.channel.recapture import recapture

    channel = Channel(jpeg=tuple(args.jpeg or ()), chroma=args.chroma, resize=args.resize,
                      long_side=args.long_side, noise=args.noise, blur=args.blur,
                      sharpen=args.sharpen, exposure=args.exposure, gamma=args.gamma,
                      seed=args.seed)
    return recapture(args.scene, args.out, channel)


def _out_dir(args) -> Path:
    return Path(args.out) if args.out else Path(args.scene) / "totems-out"


def _fit(args, scene):
    from inverse.fit.files import write_fit
    from inverse.fit.fit import fit_scene
    from scenes.errors import BadInput

    true_pose = None
    if getattr(args, "oracle_pose", False):
        from scenes.folder import read_truth

        truth = read_truth(args.scene)
        if truth is None:
            raise BadInput("--oracle-pose needs truth/totem_pose.npy (synthetic scenes)")
        true_pose = truth.totem_pose
    from inverse.fit.fit import FitSettings

    settings = FitSettings(pose_from=getattr(args, "pose_from", "both"),
                           resting=getattr(args, "resting", False))
    result = fit_scene(scene, fixed_pose=getattr(args, "fixed_pose", False),
                       true_pose=true_pose, progress=_progress(args), settings=settings)
    fit_dir = _out_dir(args) / "fit"
    write_fit(result, fit_dir, scene=scene)
    return result, fit_dir


def cmd_fit(args) -> dict:
    from scenes.working import read_working_scene

    scene = read_working_scene(args.scene)
    result, fit_dir = _fit(args, scene)
    return {"fit": str(fit_dir), "centers": result.centers.tolist(),
            "initial": result.initial.tolist(), "timing_s": result.timings}


def _verify(args, scene, fit, fit_seconds=None) -> dict:
    from scenes.folder import read_truth
    from scenes.working import working_truth
    from verify.report.report import verify_scene, write_verify

    report = verify_scene(scene, fit, truth=working_truth(read_truth(args.scene)),
                          region_shape=args.region)
    if fit_seconds is not None:
        report.timing_s["fit"] = round(fit_seconds, 2)
    out = _out_dir(args) / "verify"
    write_verify(report, out)
    summary = report.to_json()
    summary["verify"] = str(out)
    return summary


def cmd_verify(args) -> dict:
    from scenes.errors import BadInput
    from scenes.working import read_working_scene

    scene = read_working_scene(args.scene)
    from inverse.fit.files import load_fit, scene_fingerprint
    fit_dir = Path(args.fit) if args.fit else _out_dir(args) / "fit"
    if args.fit or (fit_dir / "fit.json").is_file():
        fit = load_fit(fit_dir)
        if fit.scene_fingerprint != scene_fingerprint(scene):
            raise BadInput(f"the fit in {fit_dir} was made from another scene, totem "
                           f"pixels or key; run `totems fit {args.scene}` or drop --fit")
        return _verify(args, scene, fit)
    t0 = time.perf_counter()
    fit, _ = _fit(args, scene)
    return _verify(args, scene, fit, time.perf_counter() - t0)


def cmd_check(args) -> dict:
    from scenes.working import read_working_scene

    if len(args.scene) > 1 or args.scheduler:      # many photos: verify/batch/checks.py
        from verify.batch.checks import from_args
        return from_args(args)
    args.scene = args.scene[0]
    scene = read_working_scene(args.scene)
    t0 = time.perf_counter()
    fit, _ = _fit(args, scene)
    return _verify(args, scene, fit, time.perf_counter() - t0)


def cmd_bench(args) -> dict:
    from verify.batch.bench import run_bench

    bench = run_bench(args.dirs, args.out, jobs=args.jobs, table1=not args.no_table1,
                      refit=args.refit, reverify=args.reverify, progress=_progress(args),
                      scheduler=args.scheduler, tls=arguments.tls(args))
    return {"bench": str(args.out), "scenes": bench["scenes"],
            "failed": len(bench["summary"]["failed"]), "wall_s": bench["wall_s"]}


def cmd_calib(args) -> dict:
    from scenes.photo.calibrate import calibrate, write_calib

    calib = calibrate(args.images, board=args.board, square=args.square, alpha=args.alpha)
    write_calib(calib, args.out)
    return {"calib": str(args.out), "rms_px": float(calib["rms"]),
            "used": len(calib["used"]), "images": len(args.images),
            "mtx": calib["mtx"].tolist()}


def cmd_ingest(args) -> dict:
    from scenes.photo.ingest import ingest

    out = ingest(args.photo, args.calib, args.key, args.out, masks_dir=args.masks)
    return {"scene": str(out)}


def cmd_masks(args) -> dict:
    from scenes.photo.detect_masks import write_masks

    return write_masks(args.scene, n=args.n, hints=args.hint or None, radii=args.radius)


def cmd_crosscheck(args) -> dict:
    import numpy as np

    from inverse.fit.files import load_fit
    from scenes.folder import read_mask
    from scenes.photo.nerf_layout import read_nerf_case
    from verify.report.crosscheck import crosscheck, read_nerf_log, write_crosscheck

    scene = read_nerf_case(args.scene)
    nerf = read_nerf_log(args.nerf)
    out = _out_dir(args)
    if (out / "fit" / "fit.json").is_file():
        fit = load_fit(out / "fit")
    else:
        fit, _ = _fit(args, scene)
        _verify(args, scene, fit)
    heat_file, protect_file = out / "verify/L1/heatmap.npy", out / "verify/protect_mask.png"
    heat = np.load(heat_file) if heat_file.is_file() else None
    protect = read_mask(protect_file) if protect_file.is_file() else None
    result = crosscheck(scene, fit, heat, protect, nerf)
    write_crosscheck(result, out / "crosscheck")
    summary = {k: v for k, v in result.items() if not k.startswith("_")}
    return {**summary, "crosscheck": str(out / "crosscheck")}


def _plan_camera_and_totems(args):
    """(K, size, centres (n, 3) m, radius (n,), ior (n,), the photo or None) from a
    test photo's folder, or from a camera, a key and totems' pixels and distances."""
    import numpy as np

    from scenes import camera, folder
    from scenes.errors import BadInput

    if args.photo:
        from inverse.pose.pose import initial_pose

        if args.totem or args.calib or args.fov or args.size:
            raise BadInput("--photo gives the camera and the totems: drop --totem, --calib, "
                           "--fov and --size")
        default = (args.radius, args.ior) if args.radius and args.ior else None
        scene = folder.read_scene(args.photo, default_key=default)
        radius, ior = scene.radius, scene.ior
        if args.key:
            radius, ior = folder.read_key(args.key, scene.n_totems)
        elif default:
            radius, ior = np.full(scene.n_totems, args.radius), np.full(scene.n_totems,
                                                                        args.ior)
        centers = initial_pose(scene.masks, scene.K, radius)
        return scene.K, scene.size, centers, radius, ior, scene.image
    if not args.totem:
        raise BadInput("say where the totems will stand: --totem U,V,DIST once per totem, "
                       "or --photo SCENE")
    if args.size is None or (args.calib is None) == (args.fov is None):
        raise BadInput("give the camera: --calib calib.npy or --fov DEG, with --size WxH")
    K = folder.read_calib(args.calib)["mtx"] if args.calib else \
        camera.intrinsics(*args.size, args.fov)
    n = len(args.totem)
    if args.key:
        radius, ior = folder.read_key(args.key, n, what="totems given (--totem)")
    elif args.radius and args.ior:
        radius, ior = np.full(n, args.radius), np.full(n, args.ior)
    else:
        raise BadInput("give the key: --key totems.json, or --radius M and --ior N")
    uvd = np.asarray(args.totem, np.float64)
    if np.any(uvd[:, 2] <= 0):
        raise BadInput("a totem's distance (the third number of --totem) must be positive: "
                       "it stands in front of the camera")
    centers = camera.pixel_rays(K, uvd[:, 0], uvd[:, 1]) * uvd[:, 2:3]
    return K, args.size, centers, radius, ior, None


def cmd_plan(args) -> dict:
    from scenes.folder import read_mask
    from scenes.plan.files import summary_line, write_plan
    from scenes.plan.plan import make_plan, region_box
    from scenes.plan.predict import fronto_plane, subject_plane
    from scenes.working import block_mean

    t0 = time.perf_counter()
    K, size, centers, radius, ior, photo = _plan_camera_and_totems(args)
    plane = fronto_plane(args.subject_distance) if args.subject_plane is None else \
        subject_plane(args.subject_plane[:3], args.subject_plane[3:])
    region, how = None, "above the totems"
    if args.subject_region:
        region, how = region_box(args.subject_region, size), "box"
    elif args.subject_mask:
        region, how = read_mask(args.subject_mask, what="subject mask"), "mask"
    plan = make_plan(K, size, centers, radius, ior, plane, region=region, region_from=how,
                     suggest=not args.no_move)
    background = None if photo is None else (
        photo if plan.scale == 1 else block_mean(photo, plan.scale))
    out = Path(args.out) if args.out else (
        Path(args.photo) / "totems-out" / "plan" if args.photo else Path("plan-out"))
    seconds = round(time.perf_counter() - t0, 2)
    write_plan(plan, out, background=background, extra={"seconds": seconds})
    return {"plan": str(out), **plan.to_json(), "summary": summary_line(plan),
            "seconds": seconds}


def _print_summary(verb: str, summary: dict) -> None:
    from verify.verdict.verdict import totems_disagree

    if "verdict" in summary:
        m = summary.get("metrics", {})
        extras = ", ".join(f"{k} {v:.3f}" for k, v in m.items() if v is not None)
        each = ", ".join(f"{k} {v['score']:.3f} of {v['threshold']:.3f}"
                         for k, v in summary.get("scores", {}).items())
        p = summary.get("p_value")
        odds = "" if p is None else (f"p = {p:.2g} (the chance an untouched photo "
                                     f"scores this high; {summary['line_p_value']:.2g} "
                                     f"at the threshold), ")
        why = "" if summary.get("unverifiable_reason") != "holdout" else (
            " (the totems do not predict each other: holdout {L1:.3f} > {max})"
            .format(**summary["holdout"]))
        named = (summary.get("totem_check") or {}).get("named") or []
        if named and summary["verdict"] == "inconsistent":
            why += f" ({totems_disagree(named)})"
        print(f"{summary['verdict']}{why}: {odds}score {summary['score']:.2f} of "
              f"{summary['threshold']:.2f} ({each}); "
              f"protected {100 * summary['protected_fraction']:.0f}% of the photo"
              + ("" if summary.get("judged_fraction") is None else
                 f", judged {100 * summary['judged_fraction']:.0f}%")
              + (f"; {extras}" if extras else "") + f"; wrote {summary['verify']}")
    elif verb == "plan":
        print(f"plan: {summary['summary']}; wrote {summary['plan']}")
    elif verb == "masks":
        how = "proposed" if summary["proposed"] else "as drawn"
        print(f"masks: {summary['n']} totems ({how}); check them in {summary['check']}")
    else:
        where = next((summary[k] for k in (verb, "scene", "fit", "bench", "calib",
                                           "crosscheck", "check", "written")
                      if k in summary), "")
        print(f"{verb}: wrote {', '.join(where) if isinstance(where, list) else where}")


# --------------------------------------------------------------------------- parser

def _region_argument(v) -> None:
    v.add_argument("--region", choices=("filled", "hull"), default="filled",
                   help="protected region: well-seen pixels, gaps closed and holes filled "
                        "(default), or their convex hull as the paper (to compare with "
                        "the NeRF path)")


def _fit_arguments(v, many: bool = False) -> None:
    """Arguments shared by the verbs that fit: fit and check (``many``: SCENE...)."""
    v.add_argument("scene", nargs="+" if many else None)
    v.add_argument("--out", default=None, help="output folder (default SCENE/totems-out"
                   + ("; with several SCENEs check-out)" if many else ")"))
    v.add_argument("--fixed-pose", action="store_true",
                   help="keep the totem centres at their initialisation")
    v.add_argument("--oracle-pose", action="store_true",
                   help="use truth/totem_pose.npy, fixed (synthetic scenes; benchmarks)")
    v.add_argument("--pose-from", choices=("both", "photo", "mask"), default="both",
                   help="the totems' initial pose from the mask and the photo's edges "
                        "weighed by what each is worth (default), or, as an override, "
                        "from the rims' strongest edges near each mask alone, or from the "
                        "masks' own outlines alone")
    v.add_argument("--resting", action="store_true",
                   help="the totems rest on one surface (a table, the floor): the plane "
                        "their centres and radii fix caps the rebuilt view")


def build_parser() -> argparse.ArgumentParser:
    p = helptext.add_version(_Parser(prog="totems", description=helptext.DESCRIPTION,
                                     **helptext.usage("totems")))
    sub = p.add_subparsers(dest="verb", required=True, parser_class=_Parser)

    def verb(name, func, help_, parent=sub):
        v = parent.add_parser(name, help=help_, description=help_, **helptext.usage(name))
        v.set_defaults(func=func)
        v.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
        v.add_argument("--quiet", action="store_true", help="no progress, no summary line")
        return v

    _scene_verbs(verb, sub)
    _check_verbs(verb)
    _photo_verbs(verb)
    v = verb("plan", cmd_plan, "before the shot: the reach a placement of totems predicts "
             "over the subject (a plane), its share, and the move that widens it most")
    arguments.plan(v)
    return p


def _scene_verbs(verb, sub) -> None:
    """scene make, tamper, recapture: the verbs that write scene folders."""
    scene = sub.add_parser("scene", help="synthetic totem-protected scenes",
                           **helptext.usage("scene"))
    scene_sub = scene.add_subparsers(dest="scene_verb", required=True, parser_class=_Parser)
    v = verb("make", cmd_scene_make, "render a synthetic totem-protected scene folder",
             scene_sub)
    arguments.scene_make(v)
    v = verb("reach", cmd_scene_reach, "trace what the totems of synthetic scene folders "
             "truly see into truth/reach.npz (scene make writes it; for folders made "
             "before)", scene_sub)
    v.add_argument("scenes", nargs="+", metavar="scene")

    v = verb("tamper", cmd_tamper, "write a manipulated copy of a scene folder")
    v.add_argument("scene")
    v.add_argument("out")
    v.add_argument("--kind", required=True,
                   choices=("color", "splice", "inpaint", "shift", "remove", "insert",
                            "totem-retouch", "consistent-paste", "erase-everywhere",
                            "rekey"))
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--region", type=arguments.region, default=None,
                   help="x,y,w,h region to edit (photos without truth/)")
    v.add_argument("--region-mask", default=None, help="PNG mask of the region to edit")
    v.add_argument("--tool", choices=("clone", "blur", "recolour"), default=None,
                   help="totem-retouch: the tool (default: drawn per totem)")
    v.add_argument("--totem", type=int, action="append", default=None, metavar="J",
                   help="totem-retouch: a totem to retouch, 0 the leftmost; repeat for "
                        "more (default: drawn)")
    v.add_argument("--key-error", default=None, metavar="SPEC",
                   help="rekey: the forger's key off by this much, "
                        "ior=D,radius=F[,pose=mask|exact] (radius relative; default: "
                        "no error, the pose from the masks)")
    v.add_argument("--edit", choices=("remove", "insert"), default=None,
                   help="rekey: the edit (default: drawn)")

    v = verb("recapture", cmd_recapture, "write a copy of a scene folder whose photo went "
             "through a camera and a messenger: blur, tone curve, noise, sharpening, "
             "JPEG, resize, JPEG again (in that order)")
    v.add_argument("scene")
    v.add_argument("out", help="new scene folder")
    v.add_argument("--jpeg", type=int, action="append", metavar="Q",
                   help="JPEG quality 1-100; repeat for a double JPEG (with a resize, "
                        "the last one comes after it)")
    v.add_argument("--chroma", choices=("420", "444"), default="420",
                   help="JPEG chroma subsampling (default 420)")
    size = v.add_mutually_exclusive_group()
    size.add_argument("--resize", type=float, default=None, metavar="F",
                      help="scale factor in (0, 1]; K and the masks follow the photo")
    size.add_argument("--long-side", type=int, default=None, metavar="N",
                      help="shrink so that the long side is N px (a smaller photo is "
                           "left as it is)")
    v.add_argument("--noise", type=float, default=0.0, metavar="SIGMA",
                   help="Gaussian noise, sigma in 8-bit levels")
    v.add_argument("--blur", type=float, default=0.0, metavar="SIGMA",
                   help="defocus: Gaussian sigma in pixels")
    v.add_argument("--sharpen", type=float, default=0.0, metavar="AMOUNT",
                   help="unsharp mask amount (radius 1 px)")
    v.add_argument("--exposure", type=float, default=1.0, metavar="GAIN",
                   help="gain on linear light (clipped at white)")
    v.add_argument("--gamma", type=float, default=1.0, metavar="G",
                   help="tone curve out = in ** (1/G) on sRGB values")
    v.add_argument("--seed", type=int, default=0, help="the noise's seed (default 0)")


def _check_verbs(verb) -> None:
    """fit, verify, check, bench: the verbs that judge photos."""
    v = verb("fit", cmd_fit, "pose initialisation + joint fit of the radiance grid and "
             "the totem centres")
    _fit_arguments(v)

    v = verb("verify", cmd_verify, "protected region, heatmaps, verdict, metrics")
    v.add_argument("scene")
    v.add_argument("--fit", default=None, help="fit folder (default: OUT/fit, else fit now)")
    v.add_argument("--out", default=None, help="output folder (default SCENE/totems-out)")
    _region_argument(v)

    v = verb("check", cmd_check, "fit, then verify: the one-shot fit-and-compare; with "
             "several SCENEs each on a Dask cluster, and an index (OUT default check-out)")
    _fit_arguments(v, many=True)
    _region_argument(v)
    arguments.engine(v)

    v = verb("bench", cmd_bench, "run check over many scene folders and write the tables")
    v.add_argument("dirs", nargs="+", help="folders holding scene folders")
    v.add_argument("--out", default="bench-out", help="output folder (default bench-out)")
    arguments.engine(v)
    v.add_argument("--no-table1", action="store_true",
                   help="skip the initial-pose and oracle-pose fits of untouched scenes")
    v.add_argument("--refit", action="store_true",
                   help="fit every scene, even one whose totem pixels another's fit serves")
    v.add_argument("--reverify", action="store_true",
                   help="verify again on the fits an earlier bench left in OUT (after a "
                        "change to verify/ alone) instead of fitting")


def _photo_verbs(verb) -> None:
    """calib, ingest, masks, crosscheck: the verbs for one's own photos."""
    v = verb("calib", cmd_calib, "camera calibration from checkerboard photos")
    v.add_argument("images", nargs="+", help="photos of a printed checkerboard")
    v.add_argument("--board", type=arguments.size_any, required=True,
                   help="inner corners as COLSxROWS, e.g. 9x6")
    v.add_argument("--square", type=arguments.positive(float), required=True,
                   help="side of one square, metres")
    v.add_argument("--alpha", type=float, default=0.0,
                   help="0 keeps only valid pixels after undistortion, 1 keeps all")
    v.add_argument("--out", default="calib.npy", help="output (default calib.npy)")

    v = verb("ingest", cmd_ingest, "a camera photo (undistorted) to a scene folder")
    v.add_argument("photo")
    v.add_argument("--calib", required=True, help="calib.npy from `totems calib`")
    v.add_argument("--key", required=True, help="totems.json: radius (m) and ior")
    v.add_argument("--masks", default=None, help="totem masks drawn on the raw photo")
    v.add_argument("out", help="new scene folder")

    v = verb("masks", cmd_masks, "propose totem_masks/ where the folder has none, and a "
             "picture to check them")
    v.add_argument("scene")
    v.add_argument("--n", type=arguments.positive(int), default=None,
                   help="number of totems (default: as many as the key lists)")
    v.add_argument("--hint", type=arguments.point, action="append", default=None,
                   metavar="X,Y",
                   help="a pixel inside a totem, once per totem: search around it")
    v.add_argument("--radius", type=arguments.point, default=None, metavar="MIN,MAX",
                   help="range of totem radii in the photo, pixels")

    v = verb("crosscheck", cmd_crosscheck, "our fit beside a NeRF-path run of the scene")
    v.add_argument("scene")
    v.add_argument("--nerf", required=True, help="NeRF-path experiment (log) folder")
    v.add_argument("--out", default=None, help="output folder (default SCENE/totems-out)")
    _region_argument(v)


def main(argv=None) -> int:
    """Entry point of the ``totems`` console script; returns the exit code."""
    from scenes.backend import BackendError
    from scenes.errors import BadInput

    args = build_parser().parse_args(argv)
    try:
        summary = args.func(args)
    except (BadInput, BackendError) as exc:
        print(f"totems: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        print(f"totems: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "),
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("totems: interrupted", file=sys.stderr)
        return 130
    except Exception:                  # a bug: say so, never as a verdict's exit code
        import traceback

        traceback.print_exc()
        print("totems: internal error (a bug): please report it with the lines above",
              file=sys.stderr)
        return EXIT_BUG
    if summary.get("complete") is False:
        print(f"totems: {args.verb}: found {summary['found']} of the "
              f"{summary['expected'] or 'wanted'} totems, searching {summary['searched']}; "
              f"see {summary['check']}; draw the missing masks by hand (totem_masks/, "
              "white = totem) or give --hint X,Y for each totem", file=sys.stderr)
        if args.json:
            print(json.dumps(summary, default=str))
        return EXIT_INCOMPLETE
    if args.json:
        print(json.dumps(summary, default=str))
    elif not args.quiet:
        _print_summary(args.verb, summary)
    if summary.get("verdict") == "inconsistent":
        return EXIT_INCONSISTENT
    if summary.get("verdict") == "unverifiable":
        return EXIT_UNVERIFIABLE
    return summary.get("exit_code", EXIT_OK)      # check SCENE...: its photos' worst


if __name__ == "__main__":
    sys.exit(main())
