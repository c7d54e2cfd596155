"""Hand-made scenes and fits for the verify tests (no rendering, no Mitsuba).

A 320 x 240 photo of smooth texture, two totems near the bottom whose masks are the
exact silhouettes of spheres, totem points back-projected from a known rectangle of the
image, and a FitResult-like namespace.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from scenes.camera import intrinsics, pixel_rays
from scenes import folder

W, H = 320, 240
K = intrinsics(W, H, 60.0)
RADIUS = 0.0987654          # distinctive digits: the tests look for them in the outputs
IOR = 1.5432109
CENTERS = np.array([[-0.40, 0.35, 1.5], [0.40, 0.35, 1.5]])
PROTECT_BOX = (40, 20, 280, 160)      # x0, y0, x1, y1 (end exclusive) of the seen area
SQUARE = (136, 56, 200, 120)         # x0, y0, x1, y1 of the coloured square (one patch)


def texture(seed: int = 0) -> np.ndarray:
    """Smooth sRGB texture in [0.1, 0.9], (H, W, 3) float32."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H, 0:W].astype(float)
    img = np.zeros((H, W, 3))
    for c in range(3):
        for _ in range(4):
            fx, fy = rng.uniform(0.01, 0.08, 2)
            ph = rng.uniform(0, 2 * np.pi)
            img[..., c] += np.sin(fx * u + fy * v + ph)
    img = 0.5 + 0.4 * img / np.abs(img).max()
    return img.astype(np.float32)


def sphere_masks() -> np.ndarray:
    """(2, H, W) silhouettes of the two spheres, computed from the rays' angles."""
    v, u = np.mgrid[0:H, 0:W]
    d = pixel_rays(K, u, v)
    out = []
    for P in CENTERS:
        cos_angle = d @ (P / np.linalg.norm(P))
        out.append(cos_angle > np.cos(np.arcsin(RADIUS / np.linalg.norm(P))))
    return np.stack(out)


def points_in_box(box, n: int, seed: int = 0, depth=(2.0, 4.0)) -> np.ndarray:
    """n camera-frame points (metres) that project uniformly into pixel box (x0,y0,x1,y1)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(box[0] - 0.5, box[2] - 0.5, n)
    v = rng.uniform(box[1] - 0.5, box[3] - 0.5, n)
    z = rng.uniform(*depth, n)
    d = pixel_rays(K, u, v)
    return d * (z / d[:, 2])[:, None]


def make_scene(image=None, manip_mask=None) -> folder.Scene:
    image = texture() if image is None else image
    masks = sphere_masks()
    return folder.Scene(Path("."), image, K, masks, np.full(2, RADIUS), np.full(2, IOR),
                        None, manip_mask)


def make_fit(recon, *, n_points: int = 6000, centers=None) -> SimpleNamespace:
    centers = CENTERS if centers is None else centers
    return SimpleNamespace(recon=np.asarray(recon, np.float32),
                           totem_points=points_in_box(PROTECT_BOX, n_points),
                           centers=np.asarray(centers, float), initial=CENTERS + 0.01,
                           timings={"total": 1.0})


def with_square(image, colour=(1.0, 0.1, 0.1), box=SQUARE) -> np.ndarray:
    out = image.copy()
    out[box[1]:box[3], box[0]:box[2]] = colour
    return out


def box_mask(box) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[box[1]:box[3], box[0]:box[2]] = True
    return m
