"""Tests of verify/corroborate: a photo of what the totems saw is corroborated at the
surface's depth without being told it; a hue they did not see, or the right palette in
the wrong place, is not."""

from __future__ import annotations

import numpy as np
import pytest

from inverse.grid import frame_for_scene
from inverse.rays import TotemRays
from scenes.camera import pixel_rays
from plane_cases import CENTERS, RADIUS, H, K, W, rays_onto_plane, texture
from scenes.colour import srgb_to_linear
from verify.metrics.corroborate import cell_errors, corroboration, unseen
from verify.metrics.patches import chroma_distance

Z_PLANE = 3.0
CELL = 6.9          # px: 34 x 45 cells over this 240 x 180 view and its 15 % margins


def camera_view(z_plane):
    """The camera's photo of the textured plane at depth ``z_plane``, (H, W, 3) sRGB."""
    vv, uu = np.mgrid[0:H, 0:W]
    X = pixel_rays(K, uu.ravel(), vv.ravel())
    X = X / X[:, 2:3] * z_plane
    return texture(X[:, 0], X[:, 1]).reshape(H, W, 3)


@pytest.fixture(scope="module")
def plane():
    o, d, js, col = rays_onto_plane(Z_PLANE)
    frame = frame_for_scene(K, (W, H), CENTERS, np.full(4, RADIUS))
    return TotemRays(o, d, srgb_to_linear(col), js, np.ones(len(js))), frame


def centre(E):
    """The middle of the view, where several totems see the plane."""
    return E[int(0.3 * H):int(0.6 * H), int(0.3 * W):int(0.7 * W)]


def test_the_plane_is_corroborated_and_a_pasted_hue_is_not(plane):
    photo = camera_view(Z_PLANE)
    E = corroboration(*plane, photo, cell_px=CELL, n_slices=48)
    inner = centre(E)
    assert np.isfinite(inner).mean() > 0.9
    assert np.nanmedian(inner) < 0.02
    tampered = photo.copy()
    y0, x0 = int(0.4 * H), int(0.45 * W)
    tampered[y0:y0 + 20, x0:x0 + 20] = [0.1, 0.9, 0.1]      # a green the plane lacks
    E2 = corroboration(*plane, tampered, cell_px=CELL, n_slices=48)
    square = E2[y0 + 5:y0 + 15, x0 + 5:x0 + 15]
    # chroma of (0.1, 0.9, 0.1) is (-0.27, 0.53, -0.27): far from the plane's hues
    assert np.nanmin(square) > 5 * np.nanpercentile(inner, 95)
    away = np.ones((H, W), bool)
    away[y0 - 15:y0 + 35, x0 - 15:x0 + 35] = False
    assert np.nanmedian(E2[away]) == pytest.approx(np.nanmedian(E[away]), abs=1e-3)


def test_the_right_palette_at_the_wrong_depth_is_not_corroborated(plane):
    # The same texture photographed as if the plane stood at 1.5 m: every hue of it is
    # somewhere in the totems' view, but not along the pixels' rays.
    E_true = corroboration(*plane, camera_view(Z_PLANE), cell_px=CELL, n_slices=48)
    E_wrong = corroboration(*plane, camera_view(1.5), cell_px=CELL, n_slices=48)
    assert np.nanmedian(centre(E_wrong)) > 2 * np.nanmedian(centre(E_true))


def test_cell_errors_take_the_second_best_totem_where_two_land_the_one_where_it_is_alone():
    # 3 totems, 2 slices, one cell; the photo's chroma is 0 (grey).
    mu = np.zeros((3, 2, 1, 1, 3))
    mu[0, 0, 0, 0] = [0.5, 0.5, 0.5]        # grey: error 0
    mu[1, 0, 0, 0] = [0.6, 0.3, 0.3]        # chroma (0.2, -0.1, -0.1): error 0.1333
    mu[2, 0, 0, 0] = [0.9, 0.0, 0.0]        # chroma (0.6, -0.3, -0.3): error 0.4
    mu[:, 1, 0, 0] = [[0.4, 0.5, 0.6], [0.0, 0.0, 0.9], [0.3, 0.3, 0.3]]
    land = np.ones((3, 2, 1, 1), bool)
    grey = np.zeros((1, 1, 3))
    # slice 1: errors 0.0667, 0.4, 0 -> second 0.0667; slice 0 -> second 0.1333
    assert cell_errors(mu, land, grey)[0, 0] == pytest.approx(0.2 / 3)
    land[2, 1] = False                      # slice 1: only errors 0.0667 and 0.4 remain
    assert cell_errors(mu, land, grey)[0, 0] == pytest.approx(0.4 / 3)
    assert cell_errors(mu, land, grey, min_totems=1)[0, 0] == pytest.approx(0.0)
    land[1:, 0] = False                     # slice 0: totem 0 alone, its grey explains
    assert cell_errors(mu, land, grey)[0, 0] == pytest.approx(0.0)
    assert cell_errors(mu, land, grey, alone=False)[0, 0] == pytest.approx(0.4)  # slice 1
    land[:] = False                         # no totem lands: nothing can be told
    assert np.isnan(cell_errors(mu, land, grey)[0, 0])


def test_on_the_values_a_brightened_square_is_seen_that_the_hue_forgives(plane):
    photo = camera_view(Z_PLANE)
    y0, x0 = int(0.4 * H), int(0.45 * W)
    brighter = photo.copy()
    brighter[y0:y0 + 30, x0:x0 + 30] = np.clip(0.25 + 1.5 * photo[y0:y0 + 30, x0:x0 + 30],
                                               0.0, 1.0)
    square = (slice(y0 + 10, y0 + 20), slice(x0 + 10, x0 + 20))
    values = corroboration(*plane, photo, cell_px=CELL, n_slices=48, hue=False)
    assert np.nanmedian(centre(values)) < 0.03          # the plane, brightness and all
    seen = corroboration(*plane, brighter, cell_px=CELL, n_slices=48, hue=False)
    assert np.nanmin(seen[square]) > 5 * np.nanpercentile(centre(values), 95)
    hue = corroboration(*plane, brighter, cell_px=CELL, n_slices=48)
    assert np.nanmax(hue[square]) < np.nanmin(seen[square]) / 3
    # the rays brought to another exposure: the same photo at half the light
    half = corroboration(*plane, photo, cell_px=CELL, n_slices=48, hue=False,
                         gain=[0.5, 0.5, 0.5])
    assert np.nanmedian(centre(half)) > 3 * np.nanmedian(centre(values))


def test_unseen_forgives_a_misplaced_rebuilt_view_but_not_a_pasted_hue(plane):
    photo = camera_view(Z_PLANE)
    misplaced = photo[:, ::-1]          # a rebuilt view with everything in the wrong place
    co = corroboration(*plane, photo, cell_px=CELL, n_slices=48)
    ch = chroma_distance(photo, misplaced)
    u = unseen(ch, co)
    assert np.all(u[np.isfinite(co)] <= co[np.isfinite(co)])
    assert np.nanmedian(centre(ch)) > 0.03                       # CHROMA alone: off
    assert np.nanmedian(centre(u)) < 0.1 * np.nanmedian(centre(ch))
    tampered = photo.copy()
    y0, x0 = int(0.4 * H), int(0.45 * W)
    tampered[y0:y0 + 20, x0:x0 + 20] = [0.1, 0.9, 0.1]
    u2 = unseen(chroma_distance(tampered, misplaced),
                corroboration(*plane, tampered, cell_px=CELL, n_slices=48))
    assert np.nanmin(u2[y0 + 5:y0 + 15, x0 + 5:x0 + 15]) > 5 * np.nanpercentile(centre(u), 95)
    # Without totem rays (NaN), UNSEEN is the rebuilt view's CHROMA alone.
    assert np.array_equal(unseen(ch, np.full_like(ch, np.nan)), ch)
