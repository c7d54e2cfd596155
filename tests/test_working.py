"""scenes/working: a photo over the working size is fitted and judged at an integer
fraction of it, with K, masks and truth that agree with the coarser pixels."""

from __future__ import annotations

import dataclasses

import numpy as np

import verify_cases as vc
from scenes import folder
from scenes.camera import project
from scenes.working import (WORKING_PIXELS, block_mean, scale_intrinsics, working_factor,
                            working_scene, working_truth)


def test_the_factor_brings_the_photo_nearest_the_calibrated_size():
    assert WORKING_PIXELS == 640 * 480
    assert working_factor((640, 480)) == 1
    assert working_factor((320, 240)) == 1                 # never enlarged
    assert working_factor((800, 600)) == 1                 # 1.56x nearer than 0.39x
    assert working_factor((1280, 960)) == 2
    assert working_factor((1024, 768)) == 2                # 0.64x nearer than 2.56x
    assert working_factor((4000, 3000)) == 6               # 666 x 500; 7 leaves 571 x 428
    for W, H in [(4000, 3000), (4032, 3024), (6000, 4000), (1921, 1081), (1000, 700)]:
        f = working_factor((W, H))
        ratio = lambda g: abs(np.log((W // g) * (H // g) / WORKING_PIXELS))  # noqa: E731
        assert all(ratio(f) <= ratio(g) for g in range(1, 12) if (W // g) * (H // g) > 0)


def test_a_known_point_lands_on_its_coarse_pixel():
    X = np.array([[0.3, -0.2, 2.5], [-1.0, 0.4, 4.0]])
    for f in (2, 3, 5):
        u, v = project(vc.K, X).T
        uc, vc_ = project(scale_intrinsics(vc.K, f), X).T
        assert np.allclose(uc, (u + 0.5) / f - 0.5) and np.allclose(vc_, (v + 0.5) / f - 0.5)
    # The block mean's pixel (i, j) is the mean of the fine pixels whose centres average
    # to (f i + (f - 1) / 2, ...): the same map.
    a = np.arange(36.0).reshape(6, 6)
    assert block_mean(a, 3)[1, 0] == a[3:6, 0:3].mean()


def _upsampled(f: int):
    """The hand-made scene with every pixel repeated f x f, and K for those pixels."""
    image = vc.texture()
    masks = vc.sphere_masks()
    up = np.ones((f, f))
    big_K = np.linalg.inv(scale_intrinsics(np.eye(3), f)) @ vc.K
    scene = folder.Scene(path=".", image=np.kron(image, up[..., None]).astype(np.float32),
                         K=big_K, masks=np.stack([np.kron(m, up) > 0 for m in masks]),
                         radius=np.full(2, vc.RADIUS), ior=np.full(2, vc.IOR),
                         manip_mask=np.kron(masks[0], up) > 0)
    return scene, image, masks


def test_an_upsampled_photo_comes_back_to_its_own_pixels():
    scene, image, masks = _upsampled(3)
    work = working_scene(scene, pixels=vc.W * vc.H)
    assert work.scale == 3 and work.size == (vc.W, vc.H)
    assert np.allclose(work.image, image, atol=1e-6)
    assert np.array_equal(work.masks, masks)
    assert np.array_equal(work.manip_mask, masks[0])
    assert np.allclose(work.K, vc.K)
    assert work.jpeg is None
    assert working_scene(work, pixels=vc.W * vc.H) is work        # already there
    small = dataclasses.replace(scene, image=image, K=vc.K, masks=masks, manip_mask=None)
    assert working_scene(small, pixels=vc.W * vc.H) is small


def test_the_truth_follows_the_photo():
    clean = np.kron(vc.texture(1), np.ones((2, 2, 1))).astype(np.float32)
    truth = folder.Truth(clean=clean, totem_pose=vc.CENTERS, scene={})
    work = working_truth(truth, pixels=vc.W * vc.H)
    assert work.clean.shape == (vc.H, vc.W, 3)
    assert np.allclose(work.clean, vc.texture(1), atol=1e-6)
    assert np.array_equal(work.totem_pose, vc.CENTERS)
    assert working_truth(None) is None
