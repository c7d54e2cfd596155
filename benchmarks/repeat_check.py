"""Same photo, same answer? `totems check` each SCENE twice and compare the outputs.

    python benchmarks/repeat_check.py SCENE [SCENE ...] [--times 2]

Each check runs in a process of its own (as a user runs it). Prints, per photo, the
report.json fields that differ between the runs (timings aside) with the largest
difference of each number, whether the verdicts agree, and how many pixels of the
re-rendered view (fit/recon.png) differ and by how many levels at most; then one line
for all, and exit 0 when every check of every photo wrote the same, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image


def _leaves(x, path=""):
    """(path, value) of every leaf of a JSON value, timings left out."""
    if isinstance(x, dict):
        for k, v in x.items():
            if "timing" not in k:
                yield from _leaves(v, f"{path}/{k}")
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, x


def compare(a: Path, b: Path) -> dict:
    """The differences between two check outputs ``a`` and ``b`` (their OUT folders)."""
    ra = dict(_leaves(json.loads((a / "verify" / "report.json").read_text())))
    rb = dict(_leaves(json.loads((b / "verify" / "report.json").read_text())))
    fields = {}
    for k in sorted(set(ra) | set(rb)):
        x, y = ra.get(k), rb.get(k)
        if x != y:
            num = isinstance(x, (int, float)) and isinstance(y, (int, float))
            fields[k] = abs(x - y) if num else f"{x!r} / {y!r}"
    pa = np.asarray(Image.open(a / "fit" / "recon.png"), np.int16)
    pb = np.asarray(Image.open(b / "fit" / "recon.png"), np.int16)
    d = np.abs(pa - pb).max(axis=2)
    return {"fields": fields, "verdicts_agree": ra.get("/verdict") == rb.get("/verdict"),
            "pixels_differ": float((d > 0).mean()), "max_levels": int(d.max())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--times", type=int, default=2, help="checks of each photo")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="repeat-check-"))
    worst = {"fields": 0, "pixels": 0.0, "levels": 0}
    for scene in args.scenes:
        outs = []
        for i in range(args.times):
            out = tmp / f"{Path(scene).name}-{i}"
            subprocess.run([sys.executable, "-m", "verify.cli", "check", scene, "--out",
                            str(out), "--quiet"], check=False, capture_output=True)
            outs.append(out)
        for other in outs[1:]:
            c = compare(outs[0], other)
            print(f"{Path(scene).name}: verdicts agree {c['verdicts_agree']}, view "
                  f"pixels differing {100 * c['pixels_differ']:.3f} % (at most "
                  f"{c['max_levels']} levels), report fields differing "
                  f"{len(c['fields'])}")
            for k, v in c["fields"].items():
                print(f"    {k}: {v if isinstance(v, str) else f'{v:.3g}'}")
            worst = {"fields": max(worst["fields"], len(c["fields"])),
                     "pixels": max(worst["pixels"], c["pixels_differ"]),
                     "levels": max(worst["levels"], c["max_levels"])}
    same = worst["fields"] == 0 and worst["levels"] == 0
    print(f"{len(args.scenes)} photos, {args.times} checks each: "
          + ("identical" if same else
             f"at most {worst['fields']} report fields, {100 * worst['pixels']:.3f} % of "
             f"the view's pixels by up to {worst['levels']} levels differ"))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
