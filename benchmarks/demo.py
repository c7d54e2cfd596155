"""`make demo`: make a scene, tamper it, check both, show the verdicts and a picture.

    python benchmarks/demo.py [OUT] [--size WxH] [--kind KIND]

Runs the real `totems` commands (printed as they run), so the demo is also a tutorial.
The picture, OUT/demo.png: the untouched and the tampered photo, the camera view
re-rendered from the totems alone, what was changed, and the UNSEEN heatmap over each
photo with its verdict.
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path


def run(*args) -> int:
    cmd = [str(Path(sys.executable).with_name("totems")), *args]
    print("$ totems " + " ".join(shlex.quote(a) for a in args), flush=True)
    return subprocess.run(cmd).returncode


def _verdict(scene: Path) -> str:
    """'consistent (p = 0.79)\nRANGE 0.060/0.140  UNSEEN 0.003/0.062 ...' (the
    verdict, its p-value, each judging metric's score over its threshold) from the
    scene's report.json, or ''."""
    path = scene / "totems-out/verify/report.json"
    if not path.is_file():
        return ""
    r = json.loads(path.read_text())
    each = "  ".join(f"{k} {v['score']:.3f}/{v['threshold']:.3f}"
                     for k, v in r.get("scores", {}).items())
    p = r.get("p_value")
    odds = "" if p is None else f" (p = {p:.2g})"
    return f"{r['verdict']}{odds}\n{each}"


def picture(untouched: Path, tampered: Path, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scenes.folder import read_image

    panels = [(untouched / "image.png", "untouched photo"),
              (untouched / "totems-out/verify/recon.png", "re-rendered from the totems"),
              (untouched / "totems-out/verify/UNSEEN/heatmap_overlay.png",
               "untouched: " + _verdict(untouched)),
              (tampered / "image.png", "tampered photo"),
              (tampered / "manip_mask.png", "what was changed"),
              (tampered / "totems-out/verify/UNSEEN/heatmap_overlay.png",
               "tampered: " + _verdict(tampered))]
    fig, axes = plt.subplots(2, 3, figsize=(12, 7.4))
    for ax, (path, title) in zip(axes.ravel(), panels):
        if path.is_file():
            ax.imshow(read_image(path))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", nargs="?", default="demo-out", type=Path)
    p.add_argument("--size", default="640x480")
    p.add_argument("--kind", default="color")
    args = p.parse_args(argv)
    if args.out.exists():
        shutil.rmtree(args.out)
    scene, tampered = args.out / "scene", args.out / f"scene-{args.kind}"
    t0 = time.perf_counter()
    if run("scene", "make", str(scene), "--preset", "box", "--seed", "1",
           "--size", args.size) != 0:
        return 1
    if run("tamper", str(scene), str(tampered), "--kind", args.kind, "--seed", "1") != 0:
        return 1
    verdicts = {}
    for folder in (scene, tampered):
        code = run("check", str(folder))
        verdicts[folder.name] = {0: "consistent", 1: "INCONSISTENT",
                                 4: "unverifiable"}.get(code, "error")
        if code not in (0, 1, 4):
            return 1
    picture(scene, tampered, args.out / "demo.png")
    print()
    for name, v in verdicts.items():
        print(f"  {name:24s} {v}")
    print(f"\npicture: {args.out / 'demo.png'}   ({time.perf_counter() - t0:.0f} s in all)")
    ok = verdicts[scene.name] == "consistent" and verdicts[tampered.name] == "INCONSISTENT"
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
