"""verify.metrics.patches: the NeRF path's patch grid, heatmaps and patch AP."""

import numpy as np
import pytest

from scenes.errors import BadInput
from verify.metrics import patches
from verify_cases import H, W, box_mask, make_scene, texture, with_square

NOTHING = 1e-6   # no distance: the photo is blurred in float32 (resolution.gaussian)


def _grid():
    return patches.patch_grid(make_scene().masks.any(axis=0))


def test_grid_lies_above_the_totems_and_spans_the_crop():
    totems = make_scene().masks.any(axis=0)
    g = patches.patch_grid(totems)
    top = np.nonzero(totems.any(axis=1))[0].min()
    assert g.y_valid == top and g.size == 64 and g.n == 30
    assert g.rows[0] == 0 and g.rows[-1] + g.size == top
    assert g.cols[0] == 0 and g.cols[-1] + g.size == W
    assert np.all(np.diff(g.rows) >= 0) and np.all(np.diff(g.cols) > 0)
    assert g.box(2, 3) == [g.cols[3], g.rows[2], g.cols[3] + 64, g.rows[2] + 64]


def test_grid_without_room_is_bad_input():
    m = np.zeros((H, W), bool)
    m[5:40, 100:140] = True
    with pytest.raises(BadInput, match="above the totems"):
        patches.patch_grid(m)


def test_patch_means_agree_with_a_loop():
    g = _grid()
    rng = np.random.default_rng(0)
    vals = rng.random((H, W))
    wts = rng.random((H, W)) > 0.3
    got = patches.patch_means(vals, g, wts)
    for a in (0, 7, 29):
        for b in (0, 13, 29):
            y0, x0 = g.rows[a], g.cols[b]
            v = vals[y0:y0 + 64, x0:x0 + 64]
            w = wts[y0:y0 + 64, x0:x0 + 64]
            assert got[a, b] == pytest.approx(v[w].mean(), rel=1e-9)


def test_patch_top_means_agree_with_a_loop():
    g = _grid()
    rng = np.random.default_rng(1)
    vals = rng.random((H, W))
    vals[rng.random((H, W)) < 0.05] = np.nan            # not known there
    wts = rng.random((H, W)) > 0.3
    got = patches.patch_top_means(vals, g, wts, fraction=0.1)
    for a in (0, 11, 29):
        for b in (0, 17, 29):
            y0, x0 = g.rows[a], g.cols[b]
            v = vals[y0:y0 + 64, x0:x0 + 64][wts[y0:y0 + 64, x0:x0 + 64]]
            v = np.sort(v[np.isfinite(v)])[::-1]
            assert got[a, b] == pytest.approx(v[:int(np.ceil(0.1 * len(v)))].mean(),
                                              rel=1e-6)
    none = np.zeros((H, W), bool)
    assert np.isnan(patches.patch_top_means(vals, g, none)).all()


def test_an_edit_a_tenth_of_a_patch_scores_in_full_for_the_hue_metrics():
    g = _grid()
    d = np.zeros((H, W))
    a, b = 10, 10
    y0, x0 = g.rows[a], g.cols[b]
    d[y0 + 20:y0 + 40, x0 + 20:x0 + 40] = 0.3           # 400 px: a tenth of 64 x 64
    scores = patches.patch_scores({"UNSEEN": d, "RANGE": d}, g)
    assert scores["UNSEEN"][a, b] == pytest.approx(0.3 * 400 / 410, rel=1e-6)
    assert scores["RANGE"][a, b] == pytest.approx(0.3 * 400 / 64 ** 2, rel=1e-6)
    assert scores["UNSEEN"][0, 0] == 0.0


def test_heatmap_peaks_at_the_square():
    photo = texture()
    small = (150, 60, 190, 100)             # inside one patch, with room around it
    recon = with_square(photo, colour=(0.2, 0.9, 0.2), box=small)
    g = _grid()
    heat = patches.heatmaps(patches.pixel_errors(photo, recon), g)
    diff = np.abs(photo - recon).mean(axis=2)
    x0, y0, x1, y1 = small
    inside = np.array([[g.rows[a] <= y0 and g.rows[a] + 64 >= y1 and g.cols[b] <= x0
                        and g.cols[b] + 64 >= x1 for b in range(30)] for a in range(30)])
    apart = np.array([[g.rows[a] >= y1 or g.rows[a] + 64 <= y0 or g.cols[b] >= x1
                       or g.cols[b] + 64 <= x0 for b in range(30)] for a in range(30)])
    assert inside.any() and apart.any()
    # a patch holding the whole square: NeRF units = 2 * (sum of |diff| in square) / 64^2
    expected = 2.0 * diff[y0:y1, x0:x1].sum() / 64 ** 2
    np.testing.assert_allclose(heat["L1"][inside], expected, rtol=1e-6)
    assert heat["L1"][apart].max() < 1e-9
    assert heat["L1"].max() == pytest.approx(expected)
    # SSIM: zero where photo and recon agree beyond the 11-px Gaussian window
    far = np.array([[g.rows[a] >= y1 + 6 or g.rows[a] + 64 <= y0 - 6
                     or g.cols[b] >= x1 + 6 or g.cols[b] + 64 <= x0 - 6
                     for b in range(30)] for a in range(30)])
    assert far.any() and heat["SSIM"][far].max() < 1e-6
    assert heat["SSIM"][inside].min() > 0.05


def _blocks():
    """A photo of flat coloured 20-px blocks, sRGB [0, 1]."""
    rng = np.random.default_rng(3)
    cells = rng.random((H // 20 + 1, W // 20 + 1, 3))
    return np.kron(cells, np.ones((20, 20, 1)))[:H, :W]


def test_chroma_distance_forgives_brightness_and_small_shifts():
    photo = 0.8 * _blocks()
    brighter = photo + 0.1                       # grey added: the chroma is unchanged
    assert patches.chroma_distance(photo, brighter).max() < NOTHING
    assert np.abs(photo - brighter).min() > 0.09                           # L1 is not
    # the recon 3 px off: every blurred photo value lies in the recon's 16-px range
    shifted = np.roll(photo, (3, -3), axis=(0, 1))
    d = patches.chroma_distance(photo, shifted)
    assert d[20:-20, 20:-20].max() < NOTHING
    assert np.abs(photo - shifted).mean(axis=2)[20:-20, 20:-20].max() > 0.1


def test_chroma_distance_finds_a_colour_that_is_not_there():
    photo = np.full((H, W, 3), (0.5, 0.4, 0.3))
    recon = photo.copy()
    photo[60:100, 150:190] = (0.2, 0.5, 0.8)        # a blue square only the photo has
    d = patches.chroma_distance(photo, recon)
    # its chroma (-0.3, 0, 0.3) against the recon's (0.1, 0, -0.1): 0.8 / 3 at the centre
    assert d[80, 170] == pytest.approx(0.8 / 3, rel=1e-6)
    assert d[:40].max() < NOTHING and d[:, :120].max() < NOTHING       # away from the square
    # and the patch map peaks over the square: the patches that hold it all score the
    # most (their worst tenth is all square), those clear of it (and of the photo's
    # 3-px blur) nothing
    g = _grid()
    heat = patches.heatmaps({"CHROMA": d}, g)["CHROMA"]
    boxes = np.array([[g.box(a, b) for b in range(g.n)] for a in range(g.n)])
    x0, y0, x1, y1 = np.moveaxis(boxes, -1, 0)
    holds = (x0 <= 150) & (x1 >= 190) & (y0 <= 60) & (y1 >= 100)
    apart = (x0 >= 202) | (x1 <= 138) | (y0 >= 112) | (y1 <= 48)
    assert holds.any() and heat[holds].min() == pytest.approx(heat.max())
    assert heat[apart].max() < NOTHING


def test_range_distance_sees_brightness_but_forgives_small_shifts():
    photo = 0.8 * _blocks()
    # the recon 3 px off: every blurred photo value lies in the recon's 16-px range
    shifted = np.roll(photo, (3, -3), axis=(0, 1))
    assert patches.range_distance(photo, shifted)[20:-20, 20:-20].max() < NOTHING
    # a grey square (no hue, so CHROMA cannot see it) darker than anything nearby
    flat = np.full((H, W, 3), 0.6)
    dark = flat.copy()
    dark[60:100, 150:190] = 0.1
    assert patches.chroma_distance(dark, flat).max() < NOTHING
    d = patches.range_distance(dark, flat)
    assert d[80, 170] == pytest.approx(0.5, rel=1e-6)          # 0.6 - 0.1 in each channel
    assert d[:40].max() < NOTHING and d[:, :120].max() < NOTHING     # away from the square


def test_patch_labels_use_more_than_ten_percent():
    g = _grid()
    a, b = 10, 10
    y0, x0 = g.rows[a], g.cols[b]
    m = np.zeros((H, W), bool)
    m[y0:y0 + 64, x0:x0 + 64].flat[:410] = True      # 410 / 4096 = 10.01 %
    assert patches.patch_labels(m, g)[a, b]
    m[y0:y0 + 64, x0:x0 + 64].flat[409:] = False      # 409 / 4096 = 9.99 %
    assert not patches.patch_labels(m, g)[a, b]


def test_patch_ap_by_hand():
    # five kept patches, ranked 0.9 (+) 0.8 (-) 0.7 (+) 0.6 (-) 0.5 (-):
    # precision at the positives 1/1 and 2/3 -> AP = (1 + 2/3) / 2
    scores = np.zeros((3, 3))
    labels = np.zeros((3, 3), bool)
    keep = np.zeros((3, 3), bool)
    for (i, j), s, y in zip([(0, 0), (0, 1), (1, 0), (1, 1), (2, 2)],
                            [0.9, 0.8, 0.7, 0.6, 0.5], [1, 0, 1, 0, 0]):
        scores[i, j], labels[i, j], keep[i, j] = s, y, True
    scores[2, 0] = 5.0                 # not kept (outside the protected region): ignored
    assert patches.patch_ap(scores, labels, keep) == pytest.approx((1 + 2 / 3) / 2)
    keep[2, 0] = True                  # if kept, this high-scoring negative ranks first
    assert patches.patch_ap(scores, labels, keep) == pytest.approx((1 / 2 + 2 / 4) / 2)
    assert patches.patch_ap(scores, np.zeros_like(labels), keep) is None


def test_pictures():
    g = _grid()
    heat = np.full((30, 30), 0.3)
    px = patches.to_pixels(heat, g)
    assert px.shape == (g.y_valid, W) and np.allclose(px, 0.3)
    ramp = np.tile(np.arange(30.0), (30, 1))          # grows left to right
    px = patches.to_pixels(ramp, g)
    assert np.all(np.diff(px[0]) >= 0) and px[0, 0] == 0 and px[0, -1] == 29
    photo = texture()
    protected = box_mask((0, 0, W // 2, H))
    totems = make_scene().masks.any(axis=0)
    over = patches.heatmap_overlay(photo, ramp, g, protected, totems, vmax=29.0)
    assert over.shape == photo.shape
    grey = np.ptp(over, axis=2) < 1e-6
    assert grey[:, W // 2:].all() and grey[g.y_valid:].all()       # outside: grey
    assert not grey[:g.y_valid, :W // 2].all()                     # inside: coloured
