"""verify/tone: the view brought to the photo's exposure and white balance by one gain
per channel, which a local edit and the view's blur do not move."""

import numpy as np
import pytest

from scenes.colour import linear_to_srgb, srgb_to_linear
from verify.metrics import tone


def _view(seed=0, shape=(80, 100)):
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.1, 0.9, (shape[0] // 10, shape[1] // 10, 3))
    return np.kron(base, np.ones((10, 10, 1)))


def test_a_known_gain_is_recovered_past_a_local_edit_and_misplaced_edges():
    recon = _view()
    gain = np.array([0.7, 1.2, 0.9])
    image = linear_to_srgb(np.clip(srgb_to_linear(recon) * gain, 0, 1))
    image = np.roll(image, 2, axis=1)                # the view's edges 2 px off
    image[10:30, 20:50] = [0.9, 0.1, 0.1]           # a colour patch on 7.5 % of it
    every = np.ones(recon.shape[:2], bool)
    out, info = tone.match_gain(image, recon, every)
    assert np.allclose(info["gain"], gain, rtol=0.01) and info["pixels"] == every.sum()
    rest = every.copy()
    rest[10:30, 20:50] = False
    rest[:, ::10] = rest[:, 1::10] = False           # the shifted edges
    assert np.abs(out - image)[rest].max() < 0.01    # the exposure taken away
    assert np.abs(out - image)[10:30, 20:50].mean() > 0.2      # the edit stays


def test_the_photo_itself_is_left_alone_and_few_pixels_change_nothing():
    recon = _view(1)
    out, info = tone.match_gain(recon, recon, np.ones(recon.shape[:2], bool))
    assert np.allclose(info["gain"], 1.0) and np.allclose(out, recon, atol=1e-5)
    few = np.zeros(recon.shape[:2], bool)
    few[:10, :10] = True                             # 100 pixels < MIN_PIXELS
    out, info = tone.match_gain(0.5 * recon, recon, few)
    assert info["gain"] == [1.0] * 3 and np.allclose(out, recon, atol=1e-5)


def test_the_gain_is_held_to_an_exposure():
    recon = _view(2)
    dark = linear_to_srgb(srgb_to_linear(recon) * 0.1)
    out, info = tone.match_gain(dark, recon, np.ones(recon.shape[:2], bool))
    assert info["gain"] == [tone.GAIN_RANGE[0]] * 3
    with pytest.raises(ValueError):
        tone.match_gain(recon[..., :2], recon, np.ones(recon.shape[:2], bool))
