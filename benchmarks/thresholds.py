"""Calibrate the verdict's thresholds on untouched photos kept apart from the benchmark.

    python benchmarks/make_set.py CAL --first-seed 11 --seeds 8 --kinds ""
    python benchmarks/thresholds.py CAL OUT [--jobs 2] [--factor 1.25] [--reverify]

Runs ``totems check`` on every scene folder of CAL (skipping those whose report is
already in OUT, so an interrupted run resumes; with ``--reverify``, ``totems verify``
on the fits already in OUT instead, which is what a change to ``verify/`` alone
needs: seconds a scene instead of a fit), then prints each judging metric's score
per scene (``report.json`` ``scores``) and the threshold the rule gives: ``factor`` times
the largest score, so that no untouched photo of the held-out set is called
inconsistent and a photo must look a quarter worse than the worst of them to be.
The values go into ``verify/verdict.py`` by hand with one line of provenance; the date
and the figures go into ``docs/decisions.md``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from scenes.folder import PHOTO_NAMES


def check(scene: Path, out: Path, reverify: bool = False) -> Path:
    """``totems check`` of one scene into ``out/<name>``, or with ``reverify``
    ``totems verify`` (which reuses ``out/<name>/fit`` and fits only where there is
    none); returns its report.json."""
    report = out / scene.name / "verify" / "report.json"
    if reverify or not report.is_file():
        command = "verify" if reverify else "check"
        proc = subprocess.run([sys.executable, "-m", "verify.cli", command, str(scene),
                               "--out", str(out / scene.name), "--quiet"],
                              capture_output=True, text=True)
        if proc.returncode == 2 or not report.is_file():
            raise RuntimeError(f"{scene.name}: {proc.stdout.strip()} {proc.stderr.strip()}")
    return report


def thresholds(scores: dict[str, dict[str, float]], factor: float) -> dict[str, tuple]:
    """{metric: (threshold, largest score, scene with it)} from {scene: {metric: score}}."""
    out = {}
    for m in sorted({m for s in scores.values() for m in s}):
        name, top = max(((n, s[m]) for n, s in scores.items() if m in s), key=lambda x: x[1])
        out[m] = (factor * top, top, name)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", type=Path, help="folder of untouched scene folders")
    p.add_argument("out", type=Path, help="where the checks are written")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--factor", type=float, default=1.25)
    p.add_argument("--reverify", action="store_true",
                   help="verify again with the fits in OUT (after a change to verify/)")
    args = p.parse_args(argv)
    scenes = sorted(d for d in args.scenes.iterdir()
                    if any((d / n).is_file() for n in PHOTO_NAMES))
    if not scenes:
        print(f"error: no scene folders in {args.scenes}", file=sys.stderr)
        return 2
    with ThreadPoolExecutor(args.jobs) as pool:
        reports = list(pool.map(lambda s: check(s, args.out, args.reverify), scenes))
    scores = {}
    for scene, rep in zip(scenes, reports):
        r = json.loads(rep.read_text())
        scores[scene.name] = {m: v["score"] for m, v in r["scores"].items()}
        print(scene.name, r["verdict"], " ".join(f"{m} {v:.4f}" for m, v in
                                                 sorted(scores[scene.name].items())))
    for m, (thr, top, name) in thresholds(scores, args.factor).items():
        print(f"{m}: largest {top:.4f} ({name}) -> threshold {thr:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
