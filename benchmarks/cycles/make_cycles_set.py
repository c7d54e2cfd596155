"""Build a small set of Cycles-rendered totem scenes (issue 38), in the package's venv.

    .venv/bin/python benchmarks/cycles/make_cycles_set.py DIR [--seed N] [--count K]
        [--kind room|yard|table] [--small | --size WxH] [--samples S]
        [--edits color,splice] [--no-remove] [--view AgX|Filmic|Standard]
        [--denoise on|off] [--filter BOX|GAUSSIAN|BLACKMAN_HARRIS] [--filter-width PX]
        [--glass glass|refraction|coated] [--totem-shadows on|off]

For K seeds from N (a seed whose totems cannot be placed is skipped, and said so), it
renders each scene with Blender Cycles in ``.venv-cycles`` (``make cycles-env``;
``render.py``), then writes under DIR:

  cycles-<kind>-s<seed>/          the untouched scene folder (``convert.write_untouched``)
  cycles-<kind>-s<seed>-<edit>/   2D edits of it by ``totems tamper`` (scenes.tamper.tamper)
  cycles-<kind>-s<seed>-remove/   an object removed from the camera's view only: the
                                  photo outside the totems re-rendered by Cycles without
                                  it (``convert.write_removed``)
  _renders/s<seed>/               Cycles' own output (render.json, photo, ids...), kept;
                                  a render found there finished is not made again
                                  (unless the removal is asked and it was made without).

and each scene folder's truth/reach.npz, the truth's reach (``truth_reach.py``: the
camera's and the totems' rays traced by Blender in the scene; the edited copies get their
source's), where a folder has none.

Exit 2 with one line for bad arguments or a missing .venv-cycles; 1 when a render fails
(its log is in ``_renders/s<seed>/render.log``) or the reach's trace fails.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.cycles import convert, design, truth_reach  # noqa: E402
from scenes.errors import BadInput  # noqa: E402
from scenes.tamper import tamper  # noqa: E402

PY = ROOT / ".venv-cycles" / "bin" / "python"


def finished(rdir: Path, remove: bool) -> bool:
    """Whether the render in ``rdir`` serves: it finished and, when a removal is asked,
    it was asked for one too (one made without is made again: Cycles renders a seed to
    the same pixels, so the scene already written from it still holds)."""
    try:
        rec = json.loads((rdir / "render.json").read_text())
    except (OSError, ValueError):
        return False
    return not remove or bool(rec.get("remove_asked", rec.get("removed_index") is not None))


def render(rdir: Path, seed: int, args) -> float:
    """Cycles' render of one seed into ``rdir`` (skipped when ``finished``); its seconds."""
    if finished(rdir, not args.no_remove):
        return 0.0
    cmd = [str(PY), str(Path(__file__).with_name("render.py")), str(rdir), "--seed",
           str(seed), "--samples", str(args.samples)]
    cmd += ["--small"] if args.small else ["--size", args.size]
    cmd += ["--kind", args.kind] if args.kind else []
    cmd += [] if args.no_remove else ["--remove"]
    cmd += ["--view", args.view] if args.view else []
    cmd += ["--denoise", args.denoise] if args.denoise else []
    cmd += ["--filter", args.filter] if args.filter else []
    cmd += ["--filter-width", str(args.filter_width)] if args.filter_width else []
    cmd += ["--glass", args.glass] if args.glass else []
    cmd += ["--totem-shadows", args.totem_shadows] if args.totem_shadows else []
    rdir.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    with open(rdir / "render.log", "w") as log:
        r = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT)
    if r.returncode != 0:
        raise RuntimeError(f"Cycles render of seed {seed} failed (see {rdir}/render.log)")
    return time.perf_counter() - t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dir")
    design.scene_options(ap)
    ap.add_argument("--count", type=int, default=1)
    ap.add_argument("--edits", default="color,splice",
                    help="comma-separated totems tamper kinds (2D ones), or none")
    ap.add_argument("--no-remove", action="store_true")
    a = ap.parse_args(argv)
    try:
        W, H = (160, 120) if a.small else (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        print(f"error: --size must be WxH, got {a.size!r}", file=sys.stderr)
        return 2
    edits = [] if a.edits in ("", "none") else a.edits.split(",")
    bad = [e for e in edits if e not in ("color", "splice", "inpaint")]
    if a.filter_width is not None and not a.filter_width > 0:
        print(f"error: --filter-width must be > 0 px, got {a.filter_width}",
              file=sys.stderr)
        return 2
    if bad or a.count < 1:
        print(f"error: edits must be color, splice or inpaint (got {bad}); count >= 1",
              file=sys.stderr)
        return 2
    if not PY.is_file():
        print(f"error: no {PY}: run `make cycles-env` first", file=sys.stderr)
        return 2
    out = Path(a.dir)
    if out.exists() and not out.is_dir():
        print(f"error: {out} is not a folder", file=sys.stderr)
        return 2
    for seed in range(a.seed, a.seed + a.count):
        try:
            desc = design.describe(seed, kind=a.kind, size=(W, H))
        except RuntimeError as exc:
            print(f"seed {seed}: skipped ({exc})")
            continue
        name = f"cycles-{desc['kind']}-s{seed}"
        rdir = out / "_renders" / f"s{seed}"
        try:
            secs = render(rdir, seed, a)
        except RuntimeError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        scene = out / name
        if not scene.exists():
            convert.write_untouched(rdir, scene)
        made = [name]
        for kind in edits:
            if not (out / f"{name}-{kind}").exists():
                try:
                    tamper.tamper(scene, out / f"{name}-{kind}", kind=kind, seed=seed)
                except BadInput as exc:
                    print(f"{name}: no {kind} edit ({exc})")
                    continue
            made.append(f"{name}-{kind}")
        if not a.no_remove and not (out / f"{name}-remove").exists():
            if convert.write_removed(rdir, scene, out / f"{name}-remove") is None:
                print(f"{name}: no removable object in view")
        if (out / f"{name}-remove").exists():
            made.append(f"{name}-remove")
        t = time.perf_counter()
        try:
            truth_reach.write_reaches([out / m for m in made], missing=True, python=PY)
        except RuntimeError as exc:
            print(f"error: {name}: {exc}", file=sys.stderr)
            return 1
        print(f"seed {seed}: {', '.join(made)} (render {secs:.0f} s, reach "
              f"{time.perf_counter() - t:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
