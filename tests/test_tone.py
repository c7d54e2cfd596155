"""verify/tone: the view brought to the photo's exposure and white balance by one gain
per channel, which a local edit and the view's blur do not move."""

import numpy as np
import pytest

from scenes.colour import linear_to_srgb, srgb_to_linear
from verify import tone


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


def _block_score(photo):
    """A toy verdict: the largest mean |photo - view| over 10 px blocks (sRGB)."""
    def score_at(view):
        err = np.abs(photo - view).mean(axis=2)
        blocks = err.reshape(err.shape[0] // 10, 10, err.shape[1] // 10, 10).mean((1, 3))
        return float(blocks.max()), blocks
    return score_at


def test_least_score_finds_a_known_exposure_of_the_set_and_holds_to_its_ends():
    recon = _view(3)
    for g in (tone.EXPOSURES[0], tone.EXPOSURES[-2]):
        photo = tone.at_gain(recon, g)
        _, _, found = tone.least_score(recon, _block_score(photo))
        assert found["gain"] == [g] * 3 and found["scores"][round(g, 4)] < 1e-6
    photo = tone.at_gain(recon, 0.1)                 # beyond the set: its darkest end
    view, blocks, found = tone.least_score(recon, _block_score(photo))
    assert found["gain"] == [min(tone.EXPOSURES)] * 3 and blocks.max() > 0.05
    assert np.allclose(view, tone.at_gain(recon, min(tone.EXPOSURES)))
    with pytest.raises(ValueError):
        tone.least_score(recon, _block_score(photo), gains=[1.0, -0.5])


def test_editing_more_never_lowers_the_least_score_where_the_median_gain_can():
    # the photo a third of a stop dark, then a bright patch, then that patch and more:
    # the median ratio follows edits over half the pixels, the least score cannot fall
    recon = _view(4)
    photo = tone.at_gain(recon, 2 ** (-1 / 3))
    one = photo.copy()
    one[10:30, 10:40] = 0.95
    more = one.copy()
    more[40:80, :] = np.clip(tone.at_gain(more[40:80, :], 1.6), 0, 1)   # half of it
    least = [tone.least_score(recon, _block_score(x))[2] for x in (one, more)]
    s_one, s_more = (min(f["scores"].values()) for f in least)
    assert s_more >= s_one - 1e-9
    every = np.ones(recon.shape[:2], bool)
    med = [_block_score(x)(tone.match_gain(x, recon, every)[0])[0] for x in (one, more)]
    assert med[1] < med[0]                       # what the median gain allowed
