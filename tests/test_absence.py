"""Tests of verify/absence: a hue on a ray's image line is found, one that is not is
missed; an object the totems saw and the photo lacks is found where it stood, not
where the photo still shows it, and not behind the surface the fit put in front."""

from __future__ import annotations

import numpy as np
import pytest

from inverse.grid import frame_for_scene
from inverse.rays import TotemRays
from scenes.camera import pixel_rays
from plane_cases import CENTERS, RADIUS, H, K, W, rays_onto_plane, texture
from scenes.colour import srgb_to_linear
from verify.metrics.absence import absence, in_view, line_absence

Z_PLANE = 3.0
CELL = 6.9                      # px, as test_corroborate's
SQUARE = (-0.25, 0.25, 0.05, 0.45)    # x0, x1, y0, y1 (metres) of a red card on the plane
RED = np.array([0.85, 0.12, 0.1])


def on_card(x, y):
    x0, x1, y0, y1 = SQUARE
    return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def camera_view(with_card: bool):
    """The camera's photo of the plane, with or without the card, (H, W, 3) sRGB."""
    vv, uu = np.mgrid[0:H, 0:W]
    X = pixel_rays(K, uu.ravel(), vv.ravel())
    X = X / X[:, 2:3] * Z_PLANE
    img = texture(X[:, 0], X[:, 1])
    if with_card:
        img[on_card(X[:, 0], X[:, 1])] = RED
    return img.reshape(H, W, 3)


@pytest.fixture(scope="module")
def rays():
    """The totems' rays onto the plane with the card on it (what they saw)."""
    o, d, js, col = rays_onto_plane(Z_PLANE)
    t = (Z_PLANE - o[:, 2]) / d[:, 2]
    X = o + t[:, None] * d
    col = col.copy()
    col[on_card(X[:, 0], X[:, 1])] = RED
    frame = frame_for_scene(K, (W, H), CENTERS, np.full(4, RADIUS))
    return TotemRays(o, d, srgb_to_linear(col), js, np.ones(len(js))), frame


def card_pixels():
    """(H, W) bool, where the camera sees the card."""
    return np.all(camera_view(True) == RED, axis=-1)


def test_line_absence_finds_a_hue_on_the_line_and_misses_one_that_is_not():
    image = np.full((H, W, 3), 0.5)
    image[:, 150:160] = (0.2, 0.3, 0.8)                 # a blue band, columns 150-159
    valid = np.ones((H, W), bool)
    o = np.array([[0.0, 0.0, 1.0]] * 3)                 # pixel (120, 90)
    d = np.array([[0.3, 0.0, 1.0], [0.3, 0.0, 1.0], [-0.3, 0.0, 1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    colour = np.array([(0.2, 0.3, 0.8), (0.9, 0.1, 0.1), (0.2, 0.3, 0.8)])
    a = line_absence(o, d, colour, image, valid, K)
    assert a[0] == pytest.approx(0.0, abs=1e-9)         # its line crosses the band
    # red's chroma (0.533, -0.267, -0.267): nearest is the grey's 0, at 1.067 / 3
    assert a[1] == pytest.approx((0.9 - 1.1 / 3 + 2 * (1.1 / 3 - 0.1)) / 3, rel=1e-6)
    # leftwards the band is not there: blue's chroma (-0.233, -0.133, 0.367) to grey
    assert a[2] == pytest.approx((0.7 / 3 + 0.4 / 3 + 1.1 / 3) / 3, rel=1e-6)
    # a line over pixels that may not be read has no value
    assert np.isnan(line_absence(o[:1], d[:1], colour[:1], image,
                                 np.zeros((H, W), bool), K))[0]


def test_in_view_keeps_directions_whose_vanishing_point_is_in_the_image():
    d = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    assert in_view(d, K, (W, H)).tolist() == [True, False, False]


def test_a_removed_card_is_missed_where_it_stood(rays):
    depth = np.full((H, W), Z_PLANE)
    card = card_pixels()
    assert card.sum() > 300
    kept = absence(*rays, camera_view(True), np.zeros((H, W), bool), K, depth,
                   cell_px=CELL, n_slices=48)
    removed = absence(*rays, camera_view(False), np.zeros((H, W), bool), K, depth,
                      cell_px=CELL, n_slices=48)
    inner = np.zeros((H, W), bool)                      # the card, 4 px in from its edge
    ys, xs = np.nonzero(card)
    inner[ys.min() + 4:ys.max() - 3, xs.min() + 4:xs.max() - 3] = True
    assert np.nanmedian(kept[inner]) < 0.02
    # red (chroma 0.49, -0.24, -0.25) found nowhere on the plane's lines of sight
    assert np.nanmedian(removed[inner]) > 5 * max(np.nanmedian(kept[inner]), 0.01)
    far = np.ones((H, W), bool)
    far[max(0, ys.min() - 40):ys.max() + 40, max(0, xs.min() - 40):xs.max() + 40] = False
    assert np.nanmedian(removed[far & np.isfinite(removed)]) < 0.02


def test_what_lies_behind_the_fitted_surface_is_not_judged(rays):
    # The fit claims a surface at 1.5 m everywhere: the card, at 3 m, is behind it, where
    # the camera could not have seen it. What is left is the smear of the two rays
    # meeting at a shallow angle (they share cells in front of the card too).
    card = card_pixels()
    photo = camera_view(False)
    none = np.zeros((H, W), bool)
    at = absence(*rays, photo, none, K, np.full((H, W), Z_PLANE), cell_px=CELL,
                 n_slices=48)
    near = absence(*rays, photo, none, K, np.full((H, W), 1.5), cell_px=CELL,
                   n_slices=48)
    assert np.nanmedian(near[card]) < 0.25 * np.nanmedian(at[card])
    # and with no depth at all every slice is judged, as at the card's own depth
    free = absence(*rays, photo, none, K, None, cell_px=CELL, n_slices=48)
    assert np.nanmedian(free[card]) >= np.nanmedian(at[card]) - 1e-9


def test_two_totems_cannot_tell(rays):
    totem_rays, frame = rays
    A = absence(totem_rays.select(totem_rays.totem < 2), frame, camera_view(False),
                np.zeros((H, W), bool), K, None, cell_px=CELL)
    assert np.isnan(A).all()


def test_only_the_points_inside_the_established_interval_are_judged(rays):
    # The totems establish the card's plane at 2.9-3.1 m: the removed card is found
    # there. An interval at 1.4-1.6 m (the totems agree on a surface in front) leaves
    # the card's depth unjudged, and where no interval is given nothing is judged.
    card = card_pixels()
    photo = camera_view(False)
    none = np.zeros((H, W), bool)
    full = np.ones((H, W))
    at = absence(*rays, photo, none, K, None, cell_px=CELL, n_slices=48,
                 interval=(2.9 * full, 3.1 * full))
    free = absence(*rays, photo, none, K, None, cell_px=CELL, n_slices=48)
    assert np.nanmedian(at[card]) == pytest.approx(np.nanmedian(free[card]), rel=0.2)
    near = absence(*rays, photo, none, K, None, cell_px=CELL, n_slices=48,
                   interval=(1.4 * full, 1.6 * full))
    judged = near[card][np.isfinite(near[card])]       # few points there, if any
    assert judged.size < 0.1 * card.sum() or np.median(judged) < 0.25 * np.nanmedian(at[card])
    unknown = absence(*rays, photo, none, K, None, cell_px=CELL, n_slices=48,
                      interval=(np.full((H, W), np.nan), np.full((H, W), np.nan)))
    assert np.isnan(unknown).all()
