"""Build the photos of the key-strength curve (issue 61): each scene's removal made by
the forger without a key (``remove``: the totems untouched) and by the adaptive forger
(``rekey --edit remove``) at each key error of :data:`LEVELS`, the same object removed.

    python benchmarks/make_rekey.py OUT SCENE_DIR... [--levels exact,k5,...]

Writes ``OUT/<scene>-remove/`` (``totems tamper SCENE OUT --kind remove --seed S``, S the
scene's seed) and ``OUT/<scene>-rekey-<level>/`` (``totems tamper SCENE OUT --kind rekey
--edit remove --key-error ... --seed S --region-mask M``, M the removed object's directly
seen pixels, so that every level takes the object the plain removal took and the camera
view is the plain removal's). A folder that exists is kept (an interrupted build
resumes); a scene with no object to remove is skipped and says why. The levels are
made in the order given, each over every scene before the next, so that a build cut
short leaves whole levels.

The camera view is the same at every level: it is the perfect forger's render of the
scene and of the scene without the object, with the true totems. Within this process
those two renders (``scenes.tamper.tamper3d.rerender`` without ``base_desc``) are made
once per scene and reused (:func:`cached_rerender`; a render of a description is
deterministic, so the reuse is exact); the guessed-glass renders are made at each
level. The CLI renders them every time: one process a scene, so nothing is shared.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

LEVELS = {
    "exact": "ior=0,radius=0,pose=exact",   # the perfect forger: holds the key
    "mask": "ior=0,radius=0",               # the key, the centres from the masks
    "k1": "ior=0.01,radius=0.01",
    "k2": "ior=0.02,radius=0.02",
    "k3": "ior=0.03,radius=0.03",
    "k5": "ior=0.05,radius=0.05",
    "k10": "ior=0.1,radius=0.1",            # past issue 61's range: where does it rise?
}
"""Level name -> ``--key-error``: one combined axis (index off by D, radius by D x 100 %,
centres from the masks but at ``exact``)."""


def cached_rerender(tamper3d):
    """Replace ``tamper3d.rerender`` by one that remembers its true-scene renders (no
    ``base_desc``), keyed by the scene folder, the excluded ids and the planned
    description; the guessed-glass renders (with ``base_desc``) are made each time."""
    plain = tamper3d.rerender
    memo: dict = {}

    def rerender(src, plan, *, base_desc=None):
        if base_desc is not None:
            return plain(src, plan, base_desc=base_desc)
        key = (str(Path(src.path).resolve()), tuple(plan.exclude_ids),
               json.dumps(plan.new_desc, sort_keys=True))
        if key not in memo:                # two 8-bit frames a scene: a few MB
            memo[key] = plain(src, plan)
        return memo[key]

    tamper3d.rerender = rerender
    return memo


def make_scene_levels(scene: Path, out: Path, levels: dict) -> list[str]:
    """The plain removal and the rekey levels of one scene folder; log lines."""
    from scenes import folder
    from scenes.errors import BadInput
    from scenes.synthetic import render
    from scenes.tamper.tamper import tamper

    seed = int(folder.read_truth(scene).scene["seed"])
    lines = []
    t0 = time.perf_counter()
    plain = out / f"{scene.name}-remove"
    if not plain.exists():
        try:
            tamper(scene, plain, kind="remove", seed=seed)
        except BadInput as e:
            return [f"skipped {scene.name}: {e}"]
        lines.append(f"{plain.name} in {time.perf_counter() - t0:.0f} s")
    oid = json.loads((plain / "truth" / "tamper.json").read_text())["object"]["id"]
    seen = render.shape_ids(folder.read_truth(scene).scene, totems=True) == oid
    for name, spec in levels.items():
        dst = out / f"{scene.name}-rekey-{name}"
        if dst.exists():
            continue
        t0 = time.perf_counter()
        tamper(scene, dst, kind="rekey", seed=seed, region=seen, edit="remove",
               key_error=spec)
        rec = json.loads((dst / "truth" / "tamper.json").read_text())
        if rec["object"]["id"] != oid:
            raise RuntimeError(f"{dst.name} removed object {rec['object']['id']}, "
                               f"not the plain removal's {oid}")
        lines.append(f"{dst.name} in {time.perf_counter() - t0:.0f} s")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("scenes", type=Path, nargs="+", help="untouched scene folders with truth/")
    p.add_argument("--levels", default=",".join(LEVELS),
                   help=f"levels to make (default all: {','.join(LEVELS)})")
    args = p.parse_args(argv)
    unknown = [x for x in args.levels.split(",") if x not in LEVELS]
    if unknown:
        p.error(f"unknown level {unknown[0]}; use {', '.join(LEVELS)}")
    levels = {k: LEVELS[k] for k in args.levels.split(",")}
    from scenes.tamper import tamper3d
    cached_rerender(tamper3d)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, spec in levels.items():     # a level over every scene, then the next
        for scene in args.scenes:
            for line in make_scene_levels(scene, args.out, {name: spec}):
                print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
