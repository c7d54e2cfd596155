"""Build the standard benchmark set: both presets, several seeds, every manipulation.

    python benchmarks/make_set.py OUT [--small] [--seeds N] [--first-seed S] [--totems-study]

Layout: OUT/<preset>-<seed>/ (untouched) and OUT/<preset>-<seed>-<kind>/ (manipulated).
--small: 2 seeds at 320x240, for a quick run. --totems-study: also box scenes with 2 and
6 totems (the supplementary's study of the number of totems). Existing folders are kept,
so an interrupted build resumes. The held-out set the verdict's thresholds are calibrated
on (``benchmarks/thresholds.py``): ``--first-seed 11 --seeds 8 --kinds ""``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from scenes.errors import BadInput
from scenes.make import make_scene
from scenes.tamper import KINDS, tamper


def build(out: Path, *, presets, seeds, size, kinds, totem_counts, spp=None) -> list[Path]:
    made = []
    for preset in presets:
        for seed in seeds:
            for n in totem_counts:
                name = f"{preset}-{seed}" + ("" if n == 4 else f"-{n}totems")
                base = out / name
                if not base.exists():
                    t0 = time.perf_counter()
                    kw = {} if spp is None else {"spp": spp}
                    make_scene(base, preset=preset, seed=seed, size=size, n_totems=n, **kw)
                    print(f"made {name} in {time.perf_counter() - t0:.0f} s", flush=True)
                made.append(base)
                if n != 4:
                    continue
                for kind in kinds:
                    dst = out / f"{name}-{kind}"
                    if not dst.exists():
                        try:
                            tamper(base, dst, kind=kind, seed=seed)
                        except BadInput as e:   # e.g. no object fit to remove: skip it
                            print(f"skipped {dst.name}: {e}", flush=True)
                            continue
                        print(f"tampered {dst.name}", flush=True)
                    made.append(dst)
    return made


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--small", action="store_true", help="2 seeds at 320x240")
    p.add_argument("--seeds", type=int, default=None, help="seeds per preset (default 5)")
    p.add_argument("--first-seed", type=int, default=1,
                   help="first seed (default 1; the held-out calibration set uses 11)")
    p.add_argument("--totems-study", action="store_true")
    p.add_argument("--presets", default="box,envmap")
    p.add_argument("--kinds", default=",".join(KINDS))
    args = p.parse_args(argv)
    n_seeds = args.seeds or (2 if args.small else 5)
    seeds = range(args.first_seed, args.first_seed + n_seeds)
    size = (320, 240) if args.small else (640, 480)
    counts = (2, 4, 6) if args.totems_study else (4,)
    made = build(args.out, presets=args.presets.split(","), seeds=seeds, size=size,
                 kinds=[k for k in args.kinds.split(",") if k], totem_counts=counts)
    print(f"{len(made)} scene folders in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
