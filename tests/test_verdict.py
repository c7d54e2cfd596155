"""verify.verdict.verdict: untouched-looking recons pass, a coloured square does not."""

import numpy as np
import pytest

from scenes.errors import BadInput
from verify.metrics import patches
from verify.report.report import verify_scene
from verify.verdict import verdict
from verify_cases import (SQUARE, box_mask, make_fit, make_scene, points_in_box, texture,
                          with_square)


def test_score_is_the_mean_of_the_worst_patches():
    # 100 patches: 97 at 0.1, three at 0.5 -> top-3 mean 0.5 (median 0.1, reported)
    s = np.full((10, 10), 0.1)
    s[0, :3] = 0.5
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    d = verdict.decide({"L1": s}, np.ones_like(s), g, thresholds={"L1": 0.4}, calibration=None)
    assert d.medians["L1"] == pytest.approx(0.1) and d.scores["L1"] == pytest.approx(0.5)
    assert d.score == pytest.approx(0.5 / 0.4) and d.threshold == 1.0
    assert d.verdict == "inconsistent"
    assert d.drivers and all(x["row"] == 0 and x["col"] < 3 for x in d.drivers)
    assert all(x["excess"] == pytest.approx(0.5 / 0.4, abs=1e-5) and x["metric"] == "L1"
               for x in d.drivers)
    d = verdict.decide({"L1": s}, np.ones_like(s), g, thresholds={"L1": 0.6}, calibration=None)
    assert d.verdict == "consistent" and d.drivers[0]["excess"] == pytest.approx(0.5 / 0.6, abs=1e-5)
    # the verdict before the evidence map measured the excess over the median patch
    d = verdict.decide({"L1": s}, np.ones_like(s), g, thresholds={"L1": 0.3},
                       calibration=None, reference="median")
    assert d.scores["L1"] == pytest.approx(0.4)


def test_editing_more_patches_never_lowers_the_score():
    # one bad patch, then the same patch and more: the median reference let the second
    # photo score lower (its median rose); the score without it cannot
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    one = np.full((10, 10), 0.02)
    one[2, 2] = 0.3
    more = one.copy()
    more[4:9, :] = 0.12                          # half the photo edited a little
    for reference, lower in (("median", True), ("none", False)):
        a, b = (verdict.decide({"UNSEEN": x}, np.ones_like(x), g, calibration=None,
                               reference=reference).score for x in (one, more))
        assert (b < a) is lower


def test_either_metric_over_its_threshold_decides():
    # L1 flat under its threshold, CHROMA high in one corner: inconsistent, by CHROMA
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    l1 = np.full((10, 10), 0.1)
    chroma = np.full((10, 10), 0.01)
    chroma[9, 7:] = 0.2
    d = verdict.decide({"L1": l1, "CHROMA": chroma}, np.ones_like(l1), g,
                       thresholds={"L1": 0.18, "CHROMA": 0.1}, calibration=None)
    assert d.scores["L1"] == pytest.approx(0.1) and d.scores["CHROMA"] == pytest.approx(0.2)
    assert d.score == pytest.approx(2.0) and d.verdict == "inconsistent"
    assert {(x["row"], x["col"]) for x in d.drivers} <= {(9, 7), (9, 8), (9, 9)}
    assert all(x["metric"] == "CHROMA" and x["L1"] == pytest.approx(0.1) for x in d.drivers)
    # the same patches under a CHROMA threshold above their excess: consistent
    d = verdict.decide({"L1": l1, "CHROMA": chroma}, np.ones_like(l1), g,
                       thresholds={"L1": 0.18, "CHROMA": 0.25}, calibration=None)
    assert d.verdict == "consistent" and d.score == pytest.approx(0.2 / 0.25)


def test_a_photo_edited_more_never_scores_lower(monkeypatch):
    # the same square, then the same square and three more squares of a paler colour
    # over much of the view (39 % of the judged pixels): the more edited photo scores
    # at least as high at the same tone gains, and within 2 % when the edits move them
    from verify.metrics import tone

    photo = texture()
    one = with_square(photo)
    more = one
    for box in ((20, 20, 84, 84), (230, 30, 300, 100), (40, 120, 120, 170)):
        more = with_square(more, colour=(0.6, 0.5, 0.9), box=box)
    a, b = (verify_scene(make_scene(x), make_fit(photo), calibration=None)
            for x in (one, more))
    assert a.verdict == "inconsistent" and b.score >= 0.98 * a.score
    assert np.abs(np.subtract(b.tone["gain"], a.tone["gain"])).max() < 0.05
    monkeypatch.setattr(tone, "match_gain", lambda image, recon, pixels: (
        np.asarray(recon, np.float32), {"gain": [1.0] * 3, "pixels": 0}))
    a, b = (verify_scene(make_scene(x), make_fit(photo), calibration=None)
            for x in (one, more))
    assert b.score >= a.score - 1e-6               # float32 patch sums
    for m in a.decision.scores:
        assert b.decision.scores[m] >= a.decision.scores[m] - 1e-6


def test_noisy_recon_is_consistent():
    photo = texture()
    rng = np.random.default_rng(1)
    recon = np.clip(photo + rng.normal(0, 0.01, photo.shape), 0, 1)
    rep = verify_scene(make_scene(photo), make_fit(recon))
    assert rep.verdict == "consistent"
    assert rep.score < 0.25                    # a quarter of the way to the threshold


def test_global_colour_offset_is_consistent():
    # a recon a little brighter everywhere (exposure) is not a local edit
    photo = texture()
    rep = verify_scene(make_scene(photo), make_fit(np.clip(photo + 0.05, 0, 1)))
    assert rep.verdict == "consistent"


def test_coloured_square_is_inconsistent_and_named():
    photo = texture()
    tampered = with_square(photo)
    rep = verify_scene(make_scene(tampered, box_mask(SQUARE)), make_fit(photo))
    assert rep.verdict == "inconsistent" and rep.score > 1.0
    assert rep.drivers
    x0, y0, x1, y1 = SQUARE
    for d in rep.drivers:
        bx0, by0, bx1, by1 = d["box"]
        assert bx0 < x1 and bx1 > x0 and by0 < y1 and by1 > y0     # overlaps the square
        assert d["excess"] > 1.0
        assert rep.judging.box(d["row"], d["col"]) == d["box"]
    assert all(rep.metrics[f"patch_ap_{m}"] > 0.9 for m in ("L1", "SSIM", "CHROMA"))
    assert rep.metrics["patch_ap_CORROB"] is None        # a fit without totem rays


def test_totems_that_do_not_predict_each_other_leave_the_photo_unverifiable():
    # one bad patch over the line: inconsistent while the fit predicts each totem from
    # the others; past MAX_HOLDOUT the view vouches for nothing, whatever the score
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    s = np.full((10, 10), 0.01)
    s[3, 3:6] = 0.5
    over = verdict.MAX_HOLDOUT + 0.01
    for holdout in (None, verdict.MAX_HOLDOUT - 0.01):
        d = verdict.decide({"UNSEEN": s}, np.ones_like(s), g, calibration=None,
                           holdout=holdout)
        assert d.verdict == "inconsistent" and d.reason is None
    d = verdict.decide({"UNSEEN": s}, np.ones_like(s), g, calibration=None, holdout=over)
    assert d.verdict == "unverifiable" and d.reason == "holdout" and d.score > 1.0
    assert d.drivers and all(x["row"] == 3 for x in d.drivers)   # still shown where
    calm = np.full((10, 10), 0.01)
    d = verdict.decide({"UNSEEN": calm}, np.ones_like(calm), g, calibration=None,
                       holdout=over, judged_fraction=0.5)
    assert d.verdict == "unverifiable" and d.reason == "holdout"
    d = verdict.decide({"UNSEEN": calm}, np.ones_like(calm), g, calibration=None,
                       judged_fraction=0.01)
    assert d.verdict == "unverifiable" and d.reason == "judged"


def test_the_report_reads_the_fits_holdout_and_says_why():
    photo = texture()
    tampered = with_square(photo)
    fit = make_fit(photo)
    fit.geometry = {"chosen": "stereo", "holdout_L1": {"grid": 0.31, "stereo": 0.05}}
    rep = verify_scene(make_scene(tampered, box_mask(SQUARE)), fit)
    data = rep.to_json()
    assert rep.verdict == "inconsistent" and data["holdout"]["L1"] == pytest.approx(0.05)
    assert data["unverifiable_reason"] is None
    fit.geometry = {"chosen": "grid", "holdout_L1": {"grid": 0.31, "stereo": 0.29}}
    data = verify_scene(make_scene(tampered, box_mask(SQUARE)), fit).to_json()
    assert data["verdict"] == "unverifiable" and data["unverifiable_reason"] == "holdout"
    assert data["holdout"] == {"L1": pytest.approx(0.29), "max": verdict.MAX_HOLDOUT}
    assert data["score"] > 1.0                     # the score is still reported


def test_range_judges_only_where_the_totems_resolve_the_depth_well():
    # the left half's surface is established at a parallax of 5 (depth to a fifth), the
    # right half's at 20: UNSEEN judges both, RANGE (the view's colour at the pixel) the
    # right half only; ABSENT the protected pixels, whatever the map says
    from verify.metrics.evidence import MIN_PARALLAX, Evidence
    from verify.report.report import metric_pixels

    H, W = 240, 320
    par = np.full((H, W), 5.0)
    par[:, W // 2:] = 20.0
    assert MIN_PARALLAX <= 5.0 < verdict.RANGE_MIN_PARALLAX <= 20.0
    ev = Evidence(n_totems=np.full((H, W), 2), parallax=par, resolved=np.ones((H, W), bool),
                  spacing=np.array([0.01, 0.01]))
    grid = verdict.judging_grid((H, W))
    seen = np.ones((H, W), bool)
    judged = verdict.judgeable(seen & ev.resolved, grid)
    where = metric_pixels(judged, seen, ev, grid)
    assert "UNSEEN" not in where and where["ABSENT"] is seen
    rng = where["RANGE"]
    assert not rng[:, : W // 2 - 32].any() and rng[:, W // 2 + 32:].all()
    assert metric_pixels(judged, seen, None, grid) == {"ABSENT": seen}


def test_threshold_override_and_no_patches():
    photo = texture()
    rep = verify_scene(make_scene(with_square(photo)), make_fit(photo),
                       thresholds={"RANGE": 1e6, "UNSEEN": 1e6}, calibration=None)
    assert rep.verdict == "consistent" and rep.decision.thresholds["RANGE"] == 1e6
    g = patches.patch_grid(make_scene().masks.any(axis=0))
    with pytest.raises(BadInput, match="too little of it to verify"):
        verdict.decide({"RANGE": np.ones((30, 30))}, np.zeros((30, 30)), g)


def test_the_verdict_judges_below_the_highest_totem():
    # a protected region mostly below the highest totem's row, where heatmap.npy's grid
    # (the NeRF path's) stops: it was unverifiable (nothing judged); the verdict's grid
    # covers the whole photo, so it is judged, and a square pasted there, between the
    # totems, is found
    photo = texture()
    fit = make_fit(photo)
    fit.totem_points = points_in_box((40, 140, 280, 240), 8000)
    rep = verify_scene(make_scene(photo), fit, calibration=None)
    seen = rep.protected & ~rep.totem_mask
    assert seen[rep.grid.y_valid:].sum() > 0.6 * seen.sum()     # mostly below that grid
    assert rep.judged[rep.grid.y_valid:].sum() > 0.5 * seen[rep.grid.y_valid:].sum()
    assert rep.judged_fraction == pytest.approx(rep.judged.sum() / (~rep.totem_mask).sum())
    assert rep.judged_fraction > verdict.MIN_JUDGED and rep.verdict == "consistent"
    assert (rep.judged == (seen & verdict.judgeable(seen, rep.judging))).all()
    low = (128, 172, 192, 236)                      # x0, y0, x1, y1: below the totems' top
    bad = verify_scene(make_scene(with_square(photo, box=low)), fit, calibration=None)
    assert bad.verdict == "inconsistent"
    x0, y0, x1, y1 = bad.drivers[0]["box"]
    assert x0 < low[2] and x1 > low[0] and y0 < low[3] and y1 > low[1]
    assert y1 > rep.grid.y_valid                    # a patch the NeRF grid does not have


def test_judging_grid_covers_the_whole_photo():
    g = verdict.judging_grid((240, 320))
    assert g.size == 64 and g.n == 30 and g.y_valid == 240
    assert g.rows[0] == 0 and g.rows[-1] + g.size == 240
    assert g.cols[0] == 0 and g.cols[-1] + g.size == 320
    assert np.all(np.diff(g.rows) >= 0) and patches.patch_fraction(
        np.ones((240, 320), bool), g).min() == 1.0
    small = verdict.judging_grid((48, 64))          # patches shrink to the short side
    assert small.size == 48 and small.rows.max() == 0
    with pytest.raises(BadInput, match="patches need"):
        verdict.judging_grid((6, 64))


def test_a_patch_judged_too_thinly_judges_nothing():
    # a 10 x 10 grid of 8 px patches tiling 80 x 80: a sliver of 3 rows fills 37 % of
    # its patches (not counted), a block of 5 rows 62 % (counted, but not below the grid)
    totems = np.zeros((100, 80), bool)
    totems[80:, :] = True
    g = patches.patch_grid(totems, grid=10, patch=8)
    assert g.y_valid == 80 and g.size == 8 and list(g.rows) == list(range(0, 80, 8))
    judged = np.zeros((100, 80), bool)
    judged[0:3, 8:16] = True                          # sliver: 24 of 64 pixels
    judged[40:45, 16:24] = True                       # block: 40 of 64
    judged[82:, :] = True                             # below the grid
    out = verdict.judgeable(judged, g)
    assert not out[0:3].any() and not out[80:].any()
    assert out[40:45, 16:24].all() and out.sum() == 40


def test_a_totem_over_the_line_is_named_and_the_photo_inconsistent_with_its_reason():
    # the totems checked against each other (verify.metrics.agreement): a test of its
    # own, outside the statistic; unverifiable still wins when the totems do not
    # predict each other
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    calm, cover = np.full((10, 10), 0.01), np.ones((10, 10))
    lead = np.array([-1.2, verdict.TOTEM_LEAD + 0.2, np.nan])
    d = verdict.decide({"UNSEEN": calm}, cover, g, calibration=None, totem_lead=lead)
    assert d.verdict == "inconsistent" and d.inconsistent_reasons == ["totem"]
    assert d.totems_named == [1] and d.reason is None
    plain = verdict.decide({"UNSEEN": calm}, cover, g, calibration=None)
    assert plain.verdict == "consistent" and plain.inconsistent_reasons == []
    assert d.score == plain.score and d.statistic == plain.statistic
    below = verdict.decide({"UNSEEN": calm}, cover, g, calibration=None,
                           totem_lead=lead - 0.4)
    assert below.verdict == "consistent" and below.totems_named == []
    loud = np.full((10, 10), 1.0)
    both = verdict.decide({"UNSEEN": loud}, cover, g, calibration=None, totem_lead=lead)
    assert both.inconsistent_reasons == ["photo", "totem"]
    held = verdict.decide({"UNSEEN": calm}, cover, g, calibration=None, totem_lead=lead,
                          holdout=verdict.MAX_HOLDOUT + 0.1)
    assert held.verdict == "unverifiable" and held.reason == "holdout"
    assert held.inconsistent_reasons == [] and held.totems_named == [1]
    assert verdict.name_totems(None) == [] and verdict.name_totems([np.nan]) == []


def test_a_photo_no_patch_judges_is_inconsistent_when_a_totem_is_named():
    g = patches.patch_grid(make_scene().masks.any(axis=0), grid=10)
    none, cover = np.full((10, 10), np.nan), np.zeros((10, 10))
    lead = np.array([2.0 * verdict.TOTEM_LEAD, -1.0, -1.0])
    d = verdict.decide({"UNSEEN": none}, cover, g, calibration=None, judged_fraction=0.0,
                       totem_lead=lead)
    assert d.verdict == "inconsistent" and d.inconsistent_reasons == ["totem"]
    quiet = verdict.decide({"UNSEEN": none}, cover, g, calibration=None,
                           judged_fraction=0.0, totem_lead=-lead)
    assert quiet.verdict == "unverifiable" and quiet.reason == "judged"
