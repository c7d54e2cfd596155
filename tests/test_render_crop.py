"""Why ``rekey`` renders its guessed glass over the whole frame (issue 61, the key's
strength): a Mitsuba film cropped to the totems is not the full render's crop.

Mitsuba 3's JIT variants seed each sample by its lane in the render's wavefront, the
lanes numbered over the crop's own pixels; a crop anywhere but at the image's top-left
corner gives its pixels other samples than the full frame gives them (another noise
draw, not a reproduction). A crop of whole rows from the top keeps the lanes, and its
pixels match the full render's to float rounding, at most one 8-bit level here and
there. These tests hold the measurement: should Mitsuba ever seed by the pixel, the
first one fails and cropping becomes exact.
"""

import numpy as np
import pytest

from scenes import backend
from scenes.colour import linear_to_srgb

SIZE = (160, 120)
SPP = 16


@pytest.fixture(scope="module")
def desc(tmp_path_factory):
    from scenes import folder
    from scenes.synthetic.make import make_scene

    out = make_scene(tmp_path_factory.mktemp("crop") / "scene", preset="box", seed=1,
                     size=SIZE, spp=SPP)
    return folder.read_truth(out).scene


def render8(desc, crop=None):
    """The box scene rendered in 8-bit sRGB, over the frame or a film crop
    ``(x, y, w, h)``, with the sampler seed 3."""
    from scenes.synthetic import render

    mi = backend.modules()[1]
    d, _ = render.scene_dict(desc, spp=SPP)
    if crop is not None:
        x, y, w, h = crop
        d["sensor"]["film"].update(crop_offset_x=x, crop_offset_y=y, crop_width=w,
                                   crop_height=h)
    img = np.array(mi.render(render.load_scene(d), spp=SPP, seed=3))[..., :3]
    return (np.clip(np.nan_to_num(linear_to_srgb(img)), 0, 1) * 255 + 0.5).astype(np.uint8)


@pytest.mark.slow
def test_a_crop_inside_the_frame_draws_other_samples(desc):
    full = render8(desc)
    x, y, w, h = 40, 61, 64, 40
    crop = render8(desc, (x, y, w, h))
    d = np.abs(crop.astype(int) - full[y:y + h, x:x + w]).max(axis=-1)
    assert crop.shape == (h, w, 3)
    # another noise draw: most pixels off, some by much more than a level
    assert (d > 0).mean() > 0.3 and d.max() > 16


@pytest.mark.slow
def test_whole_rows_from_the_top_match_to_rounding(desc):
    full = render8(desc)
    h = 97
    crop = render8(desc, (0, 0, SIZE[0], h))
    d = np.abs(crop.astype(int) - full[:h]).max(axis=-1)
    assert d.max() <= 1 and (d > 0).mean() < 0.01
