"""verify.verdict: untouched-looking recons pass, a coloured square does not."""

import numpy as np
import pytest

from scenes.errors import BadInput
from verify import patches, verdict
from verify.report import verify_scene
from verify_cases import SQUARE, box_mask, make_fit, make_scene, texture, with_square


def test_score_is_the_excess_of_the_worst_patches_over_the_median():
    # 100 patches: 97 at 0.1, three at 0.5 -> top-3 mean 0.5, median 0.1
    s = np.full((10, 10), 0.1)
    s[0, :3] = 0.5
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    d = verdict.decide(s, np.ones_like(s), g, threshold=0.3)
    assert d.median == pytest.approx(0.1) and d.score == pytest.approx(0.4)
    assert d.verdict == "inconsistent"
    assert d.drivers and all(x["row"] == 0 and x["col"] < 3 for x in d.drivers)
    assert all(x["excess"] == pytest.approx(0.4) for x in d.drivers)
    d = verdict.decide(s, np.ones_like(s), g, threshold=0.45)
    assert d.verdict == "consistent" and d.drivers[0]["excess"] == pytest.approx(0.4)


def test_noisy_recon_is_consistent():
    photo = texture()
    rng = np.random.default_rng(1)
    recon = np.clip(photo + rng.normal(0, 0.01, photo.shape), 0, 1)
    rep = verify_scene(make_scene(photo), make_fit(recon))
    assert rep.verdict == "consistent"
    assert rep.score < verdict.VERDICT_THRESHOLD / 4


def test_global_colour_offset_is_consistent():
    # a recon a little brighter everywhere (exposure) is not a local edit
    photo = texture()
    rep = verify_scene(make_scene(photo), make_fit(np.clip(photo + 0.05, 0, 1)))
    assert rep.verdict == "consistent"


def test_coloured_square_is_inconsistent_and_named():
    photo = texture()
    tampered = with_square(photo)
    rep = verify_scene(make_scene(tampered, box_mask(SQUARE)), make_fit(photo))
    assert rep.verdict == "inconsistent" and rep.score > verdict.VERDICT_THRESHOLD
    assert rep.drivers
    x0, y0, x1, y1 = SQUARE
    for d in rep.drivers:
        bx0, by0, bx1, by1 = d["box"]
        assert bx0 < x1 and bx1 > x0 and by0 < y1 and by1 > y0     # overlaps the square
        assert d["excess"] > verdict.VERDICT_THRESHOLD
        assert rep.grid.box(d["row"], d["col"]) == d["box"]
    assert rep.metrics["patch_ap_L1"] > 0.9 and rep.metrics["patch_ap_SSIM"] > 0.9


def test_threshold_override_and_no_patches():
    photo = texture()
    rep = verify_scene(make_scene(with_square(photo)), make_fit(photo), threshold=1e6)
    assert rep.verdict == "consistent" and rep.threshold == 1e6
    g = patches.patch_grid(make_scene().masks.any(axis=0))
    with pytest.raises(BadInput, match="cannot be verified"):
        verdict.decide(np.ones((30, 30)), np.zeros((30, 30)), g)
