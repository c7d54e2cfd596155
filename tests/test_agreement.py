"""verify/metrics/agreement.py, the totems checked against each other, on hand-made
values: a ray is put back on its pixel, a ray is in discord only where agreeing others
see another hue at every depth, a totem's region that disagrees stands out of its
surround while a totem that disagrees all over does not, and fewer than three totems
are not checked."""

import numpy as np
import pytest

from inverse.rays import TotemRays
from scenes import camera
from verify.metrics import agreement

import glass_cases


def test_a_ray_leaving_the_glass_is_put_back_on_its_pixel():
    K, centers, radius, ior = glass_cases.K, glass_cases.CENTERS, glass_cases.RADIUS, \
        glass_cases.IOR
    ex = glass_cases.two_spheres_exits(0.02)
    rays = TotemRays(ex.o.astype(np.float32), ex.d.astype(np.float32),      # as stored
                     np.zeros((len(ex.u), 3)), ex.totem, ex.cos_in)
    uv = agreement.ray_pixels(rays, centers, radius, ior, K)
    assert len(uv) > 1000 and set(np.unique(ex.totem)) == {0, 1}
    assert np.abs(uv - np.stack([ex.u, ex.v], 1)).max() < 1e-3      # rim rays too


def along(own, others, spread=None):
    """An :class:`agreement.Along` of one ray at len(others) depths, two others each."""
    k = len(others)
    own = np.asarray(own, np.float32).reshape(1, k, 3)
    mean = np.asarray(others, np.float32).reshape(1, k, 3)
    spread = np.full((1, k), 0.01 if spread is None else spread, np.float32)
    return agreement.Along(own, mean, spread, np.full((1, k), 2, np.int16))


def test_a_ray_is_in_discord_only_where_no_depth_explains_its_hue():
    grey, red, green = (0.5, 0.5, 0.5), (0.8, 0.2, 0.2), (0.2, 0.7, 0.2)
    # the others agree on red at the second depth: the ray that sees red there agrees
    explained = agreement.ray_discord(along([grey, red, grey], [green, red, grey]))
    # the ray's hue is red where the others see green, grey where they see grey: its
    # best depth (the third) explains it
    also = agreement.ray_discord(along([red, red, grey], [green, green, grey]))
    contradicted = agreement.ray_discord(along([red, red, red], [green, green, grey]))
    assert explained[0] < 0.01 and also[0] < 0.01
    assert contradicted[0] > 2.0
    # brightness alone is no discord: each totem's glass dims it differently
    darker = agreement.ray_discord(along([(0.4, 0.1, 0.1)], [(0.8, 0.5, 0.5)]))
    assert darker[0] < 0.01


def test_a_ray_the_others_do_not_agree_on_is_not_judged():
    red, green = (0.8, 0.2, 0.2), (0.2, 0.7, 0.2)
    disagree = agreement.ray_discord(along([red], [green], spread=0.2))
    a = along([red], [green])
    a.count[:] = 1                                  # one other totem is no prediction
    alone = agreement.ray_discord(a)
    assert np.isnan(disagree[0]) and np.isnan(alone[0])


def disc(size=120, centre=(60.0, 60.0), r=40.0):
    v, u = np.mgrid[0:size, 0:size]
    return np.hypot(u - centre[0], v - centre[1]) < r


def test_a_region_that_disagrees_stands_out_and_is_located():
    mask = disc()
    v, u = np.nonzero(mask)
    uv = np.stack([u, v], 1).astype(float)
    values = np.full(len(u), 0.3)
    patch = np.hypot(u - 75, v - 50) < 12
    values[patch] = 3.0
    contrast, sigma, judged = agreement.disc_contrast(values, uv, mask)
    assert judged == 1.0 and sigma == pytest.approx(0.15 * 40, rel=0.05)
    b, a = np.unravel_index(np.nanargmax(contrast), contrast.shape)
    assert np.hypot(a - 75, b - 50) < 5 and np.nanmax(contrast) > 1.0
    # a totem in discord all over has no region standing out of its surround
    flat, _, _ = agreement.disc_contrast(np.full(len(u), 3.0), uv, mask)
    assert np.nanmax(np.abs(flat)) < 0.3
    # nothing predicted: nothing judged
    none, _, j0 = agreement.disc_contrast(np.full(len(u), np.nan), uv, mask)
    assert j0 == 0.0 and np.isnan(none).all()


def test_fewer_than_three_totems_are_not_checked():
    K = camera.intrinsics(160, 120, 60.0)
    rays = TotemRays(np.zeros((4, 3)), np.tile([0, 0, 1.0], (4, 1)), np.zeros((4, 3)),
                     [0, 0, 1, 1], np.ones(4))
    masks = np.zeros((2, 120, 160), bool)
    out = agreement.totem_agreement(rays, np.array([[0, 0, 1.0], [0.2, 0, 1.0]]), 0.05,
                                    1.5, K, None, np.zeros((120, 160, 3)), masks)
    assert np.isnan(out.score).all() and np.isnan(out.lead).all()


def test_two_totems_retouched_alike_both_lead_and_totems_all_in_discord_none():
    lead = agreement.leads([0.2, 1.8, 1.7, 0.1])
    assert lead[1] > 1.0 and lead[2] > 1.0 and lead[0] < 0 and lead[3] < 0
    assert np.all(np.abs(agreement.leads([1.5, 1.6, 1.4])) < 0.2)
    assert np.isnan(agreement.leads([1.0, np.nan, np.nan])).all()
