"""Build a set of scene folders: a named set (``benchmarks/sets.py``) or the standard set.

    python benchmarks/make_set.py OUT --set development|calibration|benchmark
        [--jobs N] [--dry-run] [--small] [--presets P,..] [--kinds K,..] [--channels C,..]
        [--cycles]
    python benchmarks/make_set.py OUT [--small] [--seeds N] [--first-seed S]
        [--totems-study] [--presets box,envmap] [--kinds K,..] [--jobs N] [--dry-run]

Layout: OUT/<preset>-<seed>/ (untouched), OUT/<preset>-<seed>-<kind>/ (manipulated),
OUT/<name>+<channel>/ (recaptured through ``scenes.channel.recapture``),
OUT/<preset>-<seed>-<n>totems/ (the totems study). Without ``--set``, the standard set: box
and envmap seeds 1-5 (``--seeds``, ``--first-seed``), untouched and every manipulation
of ``sets.SCENE_KINDS`` (``--kinds`` for the others), pristine.
--small: 320x240 and the first 2 seeds of each preset, for a quick run.
--totems-study: also box scenes with 2 and 6 totems (the supplementary's study).
--presets, --kinds, --channels keep only those (``--kinds ""``: untouched photos only).
Existing folders are kept (each is written under a temporary name and renamed when
complete), so an interrupted build resumes. --jobs N: the scenes are made, then
tampered, then recaptured, N at a time in separate processes (renders are
deterministic per seed, so the order does not matter). --dry-run: what is left to
make and how long it would take here (``SECONDS``). --cycles: also the set's scenes
rendered by Blender's Cycles (``sets.CYCLES``; ``make cycles-env`` first), OUT/cycles-
<kind>-s<seed>[-<edit>|-remove]/, by ``benchmarks/cycles/make_cycles_set.py`` at 64
samples, and their copies in the set's ``sets.CYCLES_CHANNELS`` (OUT/<that>+jpeg75/).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import sets

from scenes.errors import BadInput
from scenes.synthetic.make import make_scene
from scenes.tamper.tamper import KINDS, tamper

# Seconds per task at 640x480, 64 spp, on this machine's 2 cores: seed 1 of each preset
# made and edited beside a benchmark run (make: box 51 s, envmap 19, outdoor 19,
# window 86, tabletop 33), divided by 1.83, the factor that brings the standard set's
# tasks so timed to the 13 min its build took alone (README, 2026-12). At 320x240 a
# make takes about a third. A re-rendering edit takes RENDER_FACTOR times its preset's
# make (measured on the same scenes: remove 0.85-1.0, insert 0.8-1.1, shift 1.2-2.0;
# rekey 2.6 times remove on box 1 with a key error, four renders; 1.1 without, two).
SECONDS = {"make": {"box": 28.0, "envmap": 10.2, "outdoor": 10.6, "window": 47.0,
                    "tabletop": 18.3},
           "tamper": {"color": 0.2, "splice": 0.5, "inpaint": 0.5, "totem-retouch": 0.2,
                      "consistent-paste": 0.5, "erase-everywhere": 1.0},
           "recapture": 0.2}
RENDER_FACTOR = {"remove": 0.93, "insert": 0.97, "shift": 1.5, "rekey": 2.4}
PARALLEL_GAIN = 1.2          # 2 jobs on 2 cores against 1: renders already use both


# --------------------------------------------------------------------------- what

def standard_photos(presets, seeds, kinds, totem_study: bool) -> list:
    """The standard set's photos (module docstring), as ``sets.Photo``."""
    out = [sets.Photo(p, s, k) for p in presets for s in seeds
           for k in (sets.UNTOUCHED,) + tuple(kinds)]
    if totem_study:
        out += [sets.Photo(p, s, n_totems=n) for p in presets for s in seeds
                for n in (2, 6)]
    return out


def select(photos, *, presets=None, kinds=None, channels=None, first=None) -> list:
    """The photos of the given presets, manipulations (the untouched ones always) and
    channels, and of each preset's ``first`` seeds only."""
    keep = []
    for p in photos:
        if presets is not None and p.preset not in presets:
            continue
        if kinds is not None and p.kind not in (sets.UNTOUCHED,) + tuple(kinds):
            continue
        if channels is not None and p.channel not in channels:
            continue
        keep.append(p)
    if first is not None:
        seeds = {pr: sorted({p.seed for p in keep if p.preset == pr})[:first]
                 for pr in {p.preset for p in keep}}
        keep = [p for p in keep if p.seed in seeds[p.preset]]
    return keep


def tasks(photos, out: Path) -> dict:
    """The three stages' tasks not done yet, ``{"make"|"tamper"|"recapture": [Photo]}``
    (one per folder to write; a photo whose folder exists is done)."""
    todo = {"make": {}, "tamper": {}, "recapture": {}}
    for p in photos:
        base = sets.Photo(p.preset, p.seed, n_totems=p.n_totems, placement=p.placement)
        if not (out / base.scene).exists():
            todo["make"][base.scene] = base
        src = sets.Photo(p.preset, p.seed, p.kind, n_totems=p.n_totems,
                         placement=p.placement)
        if p.kind != sets.UNTOUCHED and not (out / src.source).exists():
            todo["tamper"][src.source] = src
        if p.channel != "pristine" and not (out / p.name).exists():
            todo["recapture"][p.name] = p
    return {stage: list(v.values()) for stage, v in todo.items()}


def estimate_s(todo: dict, *, size, jobs: int) -> float:
    """Seconds the tasks would take here (``SECONDS``), with ``jobs`` processes."""
    scale = size[0] * size[1] / (640 * 480)
    scale = max(scale, 1 / 3)            # fixed costs (scene loading, masks) remain
    total = 0.0
    for p in todo["make"]:
        total += SECONDS["make"][p.preset] * scale
    for p in todo["tamper"]:
        if p.kind in RENDER_FACTOR:
            total += RENDER_FACTOR[p.kind] * SECONDS["make"][p.preset] * scale
        else:
            total += SECONDS["tamper"].get(p.kind, 1.0)
    total += SECONDS["recapture"] * len(todo["recapture"])
    return total / (PARALLEL_GAIN if jobs > 1 else 1.0)


# --------------------------------------------------------------------------- doing

def make_one(out: str, photo, size, spp) -> str:
    """Make the untouched scene of ``photo``; returns a line for the log (a seed whose
    scene cannot be made, e.g. a totem hidden behind an object, is skipped and says why)."""
    t0 = time.perf_counter()
    kw = {} if spp is None else {"spp": spp}
    try:
        make_scene(Path(out) / photo.scene, preset=photo.preset, seed=photo.seed, size=size,
                   n_totems=photo.n_totems, placement=photo.placement, **kw)
    except BadInput as e:
        return f"skipped {photo.scene}: {e}"
    return f"made {photo.scene} in {time.perf_counter() - t0:.0f} s"


def tamper_one(out: str, photo) -> str:
    """Write the manipulated copy ``photo.source`` of its scene (seed: the scene's)."""
    t0 = time.perf_counter()
    try:
        tamper(Path(out) / photo.scene, Path(out) / photo.source, kind=photo.kind,
               seed=photo.seed)
    except BadInput as e:               # e.g. no object fit to remove: skip it
        return f"skipped {photo.source}: {e}"
    return f"tampered {photo.source} in {time.perf_counter() - t0:.0f} s"


def recapture_one(out: str, photo) -> str:
    """Write ``photo.name``: its pristine source through the channel."""
    src = Path(out) / photo.source
    if not src.exists():
        return f"skipped {photo.name}: no {photo.source}"
    recapture(src, Path(out) / photo.name, photo.channel, seed=photo.seed)
    return f"recaptured {photo.name}"


def recapture(src: Path, dst: Path, channel: str, *, seed: int) -> None:
    """The hook to ``scenes.channel.recapture``: ``src`` through the channel named
    ``channel`` (``sets.CHANNELS``), its noise seeded by ``seed``, written at ``dst``."""
    from scenes.channel.channel import Channel
    from scenes.channel.recapture import recapture as run

    run(src, dst, Channel(**sets.CHANNELS[channel], seed=int(seed)))


def _init_worker(threads: int) -> None:
    os.environ.setdefault("TOTEMS_THREADS", str(threads))


def run_stage(calls, jobs: int) -> None:
    """Run ``calls`` ([(function, args)]), ``jobs`` at a time, printing their lines."""
    if jobs <= 1 or len(calls) <= 1:
        for fn, args in calls:
            print(fn(*args), flush=True)
        return
    threads = max(1, (os.cpu_count() or 1) // jobs)
    with ProcessPoolExecutor(jobs, mp_context=get_context("spawn"),
                             initializer=_init_worker, initargs=(threads,)) as pool:
        for fut in as_completed([pool.submit(fn, *args) for fn, args in calls]):
            print(fut.result(), flush=True)


def build(out: Path, photos, *, size, jobs: int = 1, spp=None) -> list[Path]:
    """Make, tamper and recapture what ``photos`` needs under ``out``; returns the
    photos' folders that exist afterwards."""
    out.mkdir(parents=True, exist_ok=True)
    todo = tasks(photos, out)
    run_stage([(make_one, (str(out), p, size, spp)) for p in todo["make"]], jobs)
    run_stage([(tamper_one, (str(out), p)) for p in todo["tamper"]], jobs)
    run_stage([(recapture_one, (str(out), p)) for p in todo["recapture"]], jobs)
    return [out / p.name for p in photos if (out / p.name).exists()]


CYCLES_SECONDS = 240.0     # a Cycles scene with its removal at 640x480 here (150-363 s)
CYCLES_SAMPLES = 64        # the samples the sets' Cycles scenes are rendered at (about 100 s here)
CYCLES_NAME = re.compile(r"cycles-[a-z]+-s(\d+)(-[a-z]+)?")


def cycles_command(out: Path, set_name: str, *, small: bool = False) -> list[str]:
    """The arguments of ``benchmarks/cycles/make_cycles_set.py`` that build the Cycles
    scenes of ``set_name`` in ``out`` (with --small its first 2 seeds, 160x120)."""
    seeds, edits, remove = sets.CYCLES[set_name]
    count = min(2, len(seeds)) if small else len(seeds)
    return [str(out), "--seed", str(seeds.start), "--count", str(count),
            "--edits", ",".join(edits) or "none", *([] if remove else ["--no-remove"]),
            *(["--small"] if small else ["--samples", str(CYCLES_SAMPLES)])]


def recapture_cycles(out: Path, set_name: str) -> list[str]:
    """Recapture every Cycles photo of the set's seeds found in ``out`` (untouched and
    edited, ``cycles-<kind>-s<seed>[-<edit>]``) in the set's ``sets.CYCLES_CHANNELS``, as
    ``<name>+<channel>`` (its noise seeded by the seed; one found is kept); log lines."""
    seeds = sets.CYCLES[set_name][0]
    lines = []
    for src in sorted(out.glob("cycles-*")):
        m = CYCLES_NAME.fullmatch(src.name)
        if not (m and src.is_dir() and int(m.group(1)) in seeds):
            continue
        for channel in sets.CYCLES_CHANNELS.get(set_name, ()):
            dst = out / f"{src.name}+{channel}"
            if not dst.exists():
                recapture(src, dst, channel, seed=int(m.group(1)))
                lines.append(f"recaptured {dst.name}")
    return lines


def build_cycles(out: Path, set_name: str, *, small: bool) -> int:
    """Run make_cycles_set.py for the set's Cycles scenes, then recapture them
    (``recapture_cycles``); the exit code."""
    import subprocess

    script = Path(__file__).with_name("cycles") / "make_cycles_set.py"
    code = subprocess.run([sys.executable, str(script),
                           *cycles_command(out, set_name, small=small)]).returncode
    if code == 0:
        for line in recapture_cycles(out, set_name):
            print(line, flush=True)
    return code


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--set", choices=sets.SETS, default=None,
                   help="a named set of benchmarks/sets.py (default: the standard set)")
    p.add_argument("--small", action="store_true", help="2 seeds at 320x240")
    p.add_argument("--seeds", type=int, default=None, help="seeds per preset (default 5)")
    p.add_argument("--first-seed", type=int, default=None,
                   help="first seed (default 1; the held-out calibration set uses 11)")
    p.add_argument("--totems-study", action="store_true")
    p.add_argument("--presets", default=None, help="default: box,envmap; a set's: all")
    p.add_argument("--kinds", default=None, help="manipulations (default: all)")
    p.add_argument("--channels", default=None, help="channels (default: the set's)")
    p.add_argument("--jobs", type=int, default=1, help="processes at a time (default 1)")
    p.add_argument("--dry-run", action="store_true",
                   help="print what is left to make and how long it would take here")
    p.add_argument("--cycles", action="store_true",
                   help="also the set's Cycles-rendered scenes (needs make cycles-env)")
    args = p.parse_args(argv)
    if args.cycles and args.set is None:
        p.error("--cycles needs --set")
    size = (320, 240) if args.small else (640, 480)
    photos = _photos(p, args)
    todo = tasks(photos, args.out)
    counts = ", ".join(f"{len(v)} to {k}" for k, v in todo.items())
    est = estimate_s(todo, size=size, jobs=args.jobs)
    print(f"{len(photos)} photos ({args.set or 'standard set'}, {size[0]}x{size[1]}): "
          f"{counts}; about {est / 60:.0f} min here with --jobs {args.jobs}", flush=True)
    if args.cycles:
        n = int(cycles_command(args.out, args.set, small=args.small)[4])
        print(f"and {n} Cycles scenes: at most {n * CYCLES_SECONDS / 60:.0f} min here "
              f"(a scene found rendered is not made again)", flush=True)
    if args.dry_run:
        return 0
    made = build(args.out, photos, size=size, jobs=args.jobs)
    print(f"{len(made)} scene folders in {args.out}")
    return build_cycles(args.out, args.set, small=args.small) if args.cycles else 0


def _split(text) -> list | None:
    return None if text is None else [k for k in text.split(",") if k]


def _photos(parser, args) -> list:
    """The photos the arguments ask for (module docstring)."""
    presets, kinds, channels = _split(args.presets), _split(args.kinds), \
        _split(args.channels)
    for given, known, what in ((presets, sets.PRESETS, "preset"), (kinds, KINDS, "kind"),
                               (channels, tuple(sets.CHANNELS), "channel")):
        unknown = sorted(set(given or ()) - set(known))
        if unknown:
            parser.error(f"unknown {what} {', '.join(unknown)}; use {', '.join(known)}")
    if args.set is not None:
        if args.seeds is not None or args.first_seed is not None or args.totems_study:
            parser.error("--set fixes the seeds and the totems study: drop --seeds, "
                         "--first-seed and --totems-study")
        return select(sets.photos(args.set), presets=presets, kinds=kinds,
                      channels=channels, first=2 if args.small else None)
    if channels not in (None, ["pristine"]):
        parser.error("--channels needs --set")
    first = 1 if args.first_seed is None else args.first_seed
    n_seeds = args.seeds or (2 if args.small else 5)
    return standard_photos(presets or ["box", "envmap"],
                           range(first, first + n_seeds),
                           sets.SCENE_KINDS if kinds is None else kinds, args.totems_study)


if __name__ == "__main__":
    sys.exit(main())
