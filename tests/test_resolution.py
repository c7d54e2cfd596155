"""The photo blurred to the evidence's resolution (verify/metrics/resolution.py)."""

import io

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from scenes import jpeg
from verify.metrics import patches, resolution

K = np.array([[100.0, 0.0, 80.0], [0.0, 100.0, 60.0], [0.0, 0.0, 1.0]])
SIZE = (160, 120)


def grid_points(step_px: float, z: float = 2.0) -> np.ndarray:
    """Camera-frame points (metres) that project onto a square grid ``step_px`` apart."""
    u, v = np.meshgrid(np.arange(0.0, SIZE[0], step_px), np.arange(0.0, SIZE[1], step_px))
    x = (u.ravel() - K[0, 2]) / K[0, 0] * z
    y = (v.ravel() - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, np.full_like(x, z)], axis=1)


@pytest.mark.parametrize("step", [2.0, 4.0, 6.0])
def test_spacing_of_points_on_a_grid(step):
    s = resolution.ray_spacing(grid_points(step), K, SIZE)
    inner = s[30:90, 40:120]
    assert np.median(inner) == pytest.approx(step, rel=0.1)


def test_no_point_no_spacing_and_the_largest_blur():
    pts = grid_points(3.0)
    pts = pts[pts[:, 0] < 0]                                   # left half only
    s = resolution.ray_spacing(pts, K, SIZE)
    assert np.isinf(s[:, -1]).all()
    sigma = resolution.photo_sigma(s)
    assert sigma[:, -1] == pytest.approx(resolution.MAX_SIGMA_PX)
    assert sigma[60, 20] == pytest.approx(max(resolution.MIN_SIGMA_PX,
                                              resolution.SPACING_GAIN * 3.0), rel=0.1)


def test_subsampled_jpeg_halves_the_hue_resolution():
    rng = np.random.default_rng(0)
    img = rng.random((32, 32, 3))
    assert resolution.chroma_factor(None) == 1.0
    for chroma, factor in (("420", 2.0), ("444", 1.0)):
        with Image.open(io.BytesIO(jpeg.encode(img, quality=80, chroma=chroma))) as im:
            assert resolution.chroma_factor(jpeg.info(im)) == factor
    spacing = np.full((4, 4), 4.0)
    assert np.allclose(resolution.photo_sigma(spacing, 2.0),
                       2.0 * resolution.photo_sigma(spacing))


def test_a_blur_map_is_the_gaussian_of_each_pixel():
    rng = np.random.default_rng(1)
    img = rng.random((60, 80, 2))
    assert np.allclose(resolution.blur_varying(img, 4.5),
                       ndimage.gaussian_filter(img, (4.5, 4.5, 0)))
    level = resolution.LEVELS[2]
    assert np.allclose(resolution.blur_varying(img, np.full((60, 80), level)),
                       ndimage.gaussian_filter(img, (level, level, 0)))
    # two impulses, one where the map is sharp, one where it is wide
    spikes = np.zeros((60, 80, 1))
    spikes[30, 20] = spikes[30, 60] = 1.0
    sigma = np.where(np.arange(80)[None, :] < 40, 3.0, 12.0) * np.ones((60, 1))
    out = resolution.blur_varying(spikes, sigma)[..., 0]
    assert out[30, 20] == pytest.approx(1 / (2 * np.pi * 9.0), rel=0.02)
    assert out[30, 60] == pytest.approx(1 / (2 * np.pi * 144.0), rel=0.1)


def test_texture_finer_than_the_rays_is_forgiven_a_patch_is_not():
    # red-green stripes 16 px apart, which rays 8 px apart cannot resolve: the view
    # rebuilt from them holds the stripes' mean
    H, W = 120, 160
    stripes = (np.arange(W) // 8) % 2
    photo = np.zeros((H, W, 3))
    photo[..., 0] = 0.3 + 0.4 * stripes
    photo[..., 1] = 0.7 - 0.4 * stripes
    photo[..., 2] = 0.4
    recon = np.broadcast_to(photo.mean(axis=(0, 1)), photo.shape).copy()
    sigma = resolution.photo_sigma(np.full((H, W), 8.0))
    fixed = patches.chroma_distance(photo, recon)
    adapted = patches.chroma_distance(photo, recon, sigma=sigma)
    assert fixed[40:80, 40:120].mean() > 0.05
    assert adapted[40:80, 40:120].max() < 0.01
    pasted = photo.copy()
    pasted[40:100, 50:110] = (0.2, 0.3, 0.9)                    # 60 px of blue
    d = patches.chroma_distance(pasted, recon, sigma=sigma)
    assert d[60:80, 70:90].min() > 0.2
