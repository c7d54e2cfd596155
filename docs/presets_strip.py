"""Draw docs/presets.png: one untouched photo of each preset, side by side.

    python docs/presets_strip.py WORKDIR [--seed 1] [--spp 64] [--size 320x240]

Each tile is the photo of ``totems scene make --preset P --seed N``, labelled with the
preset and its key (totems, radii, IoRs). Scenes already in WORKDIR are reused.
"""
import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from scenes import folder
from scenes.synthetic.make import make_scene
from scenes.synthetic.presets import PRESETS


def _label(scene: Path, preset: str) -> str:
    key = json.loads((scene / "totems.json").read_text())
    key = key if isinstance(key, list) else [key] * len(list((scene / "totem_masks")
                                                              .glob("*.png")))
    r = [100 * k["radius"] for k in key]
    n = [k["ior"] for k in key]
    return (f"{preset}: {len(key)} totems, r {_span(r, '.1f')} cm, "
            f"IoR {_span(n, '.2f')}")


def _span(values, fmt: str) -> str:
    lo, hi = format(min(values), fmt), format(max(values), fmt)
    return lo if lo == hi else f"{lo}-{hi}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("work")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--out", default=str(Path(__file__).with_name("presets.png")))
    a = ap.parse_args()
    size = tuple(int(s) for s in a.size.split("x"))
    tiles = []
    for preset in PRESETS:
        scene = Path(a.work) / f"{preset}-{a.seed}"
        if not scene.exists():
            make_scene(scene, preset=preset, seed=a.seed, size=size, spp=a.spp)
        img = np.rint(folder.read_image(scene / "image.png") * 255).astype(np.uint8)
        im = Image.fromarray(img)
        draw = ImageDraw.Draw(im)
        text = _label(scene, preset)
        draw.rectangle((0, 0, 6 * len(text) + 6, 13), fill=(0, 0, 0))
        draw.text((3, 1), text, fill=(255, 255, 255))
        tiles.append(np.asarray(im))
    gap = np.full((size[1], 2, 3), 255, np.uint8)
    row = np.concatenate([x for t in tiles for x in (t, gap)][:-1], axis=1)
    Image.fromarray(row).save(a.out)


if __name__ == "__main__":
    main()
