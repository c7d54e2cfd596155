"""The benchmark: build the standard set (if missing), run `totems bench` on it, print
the tables (bench.md) with the paper's figures beside ours.

    python benchmarks/run.py [--small] [--set DIR] [--out DIR] [--jobs N]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import make_set  # noqa: E402
from verify.batch.bench import run_bench  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="2 seeds at 320x240")
    p.add_argument("--set", type=Path, default=None, help="scene set folder")
    p.add_argument("--out", type=Path, default=None, help="bench output folder")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--totems-study", action="store_true")
    args = p.parse_args(argv)
    tag = "small" if args.small else "full"
    set_dir = args.set or Path(f"bench-out/set-{tag}")
    out = args.out or Path(f"bench-out/results-{tag}")
    t0 = time.perf_counter()
    make_set.main([str(set_dir)] + (["--small"] if args.small else [])
                  + (["--totems-study"] if args.totems_study else []))
    t_set = time.perf_counter() - t0
    bench = run_bench([set_dir], out, jobs=args.jobs, progress=sys.stderr.isatty())
    print((out / "bench.md").read_text())
    print(f"set built in {t_set:.0f} s; bench {bench['wall_s']:.0f} s; results in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
