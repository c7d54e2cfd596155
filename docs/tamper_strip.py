"""Draw docs/tamper_strip.png: one forgery of each kind that edits the camera view (the
six before issue 61's forgers of the totems, ``TOTEM_KINDS``) on a 640x480 box scene.

    python docs/tamper_strip.py WORKDIR [--seed 1] [--spp 64]

Top row: the original and each forged image; bottom row: manip_mask.png in red over the
darkened image. Outputs already in WORKDIR are reused.
"""
import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from scenes import folder
from scenes.synthetic.make import make_scene
from scenes.tamper.tamper import KINDS, TOTEM_KINDS, tamper

TILE = (200, 150)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("work")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--out", default=str(Path(__file__).with_name("tamper_strip.png")))
    a = ap.parse_args()
    work = Path(a.work)
    scene = work / "scene"
    if not scene.exists():
        make_scene(scene, preset="box", seed=a.seed, size=(640, 480), spp=a.spp)
    tiles = [("original", scene, None)]
    for k in (k for k in KINDS if k not in TOTEM_KINDS):
        if not (work / k).exists():
            tamper(scene, work / k, kind=k, seed=0)
        tiles.append((k, work / k, folder.read_mask(work / k / "manip_mask.png")))
    w, h = TILE
    top, bottom = [], []
    for name, path, mask in tiles:
        img = np.rint(folder.read_image(path / "image.png") * 255).astype(np.uint8)
        im = Image.fromarray(img).resize(TILE, Image.LANCZOS)
        ImageDraw.Draw(im).text((4, 2), name, fill=(255, 255, 255))
        top.append(np.asarray(im))
        ov = (0.35 * img).astype(np.uint8)
        if mask is not None:
            ov[mask] = (255, 60, 60)
        bottom.append(np.asarray(Image.fromarray(ov).resize(TILE, Image.NEAREST)))
    gap = np.full((h, 2, 3), 255, np.uint8)

    def row(ts):
        return np.concatenate([x for t in ts for x in (t, gap)][:-1], axis=1)

    r1, r2 = row(top), row(bottom)
    Image.fromarray(np.concatenate([r1, np.full((2, r1.shape[1], 3), 255, np.uint8), r2])
                    ).save(a.out)


if __name__ == "__main__":
    main()
