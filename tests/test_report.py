"""verify.report.report: report.json fields, metrics against hand values, no key in
outputs."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from scenes import folder
from scenes.errors import BadInput
from verify.report import report
from verify_cases import (CENTERS, IOR, K, RADIUS, SQUARE, H, W, box_mask, make_fit,
                          make_scene, texture, with_square)

FIELDS = {"verdict", "score", "threshold", "protected_fraction", "totems", "metrics",
          "timing_s", "versions", "scores", "drivers", "key_fingerprint", "region",
          "statistic", "p_value", "line_p_value", "skipped", "working_scale",
          "judged_fraction", "evidence", "tone", "holdout", "unverifiable_reason",
          "inconsistent_reasons", "totem_check"}


def test_silhouette_of_a_sphere_on_the_axis_is_a_disc():
    # on the optical axis the image of a sphere is a disc of radius f tan(asin(R/Z))
    Z, R = 2.0, 0.3
    sil = report.sphere_silhouette([0, 0, Z], R, K, (H, W))
    v, u = np.mgrid[0:H, 0:W]
    r = K[0, 0] * np.tan(np.arcsin(R / Z))
    disc = np.hypot(u - K[0, 2], v - K[1, 2]) < r
    assert report.mask_iou(sil, disc) > 0.99
    assert abs(int(sil.sum()) - np.pi * r * r) < 2 * np.pi * r


def test_the_papers_hull_region_on_request(tmp_path):
    # totem points in two clusters: the default region keeps them apart, the paper's
    # convex hull also takes in the gap, and report.json says which one was used
    from verify_cases import points_in_box
    photo = texture()
    scene = make_scene(photo)
    fit = make_fit(photo)
    fit.totem_points = np.concatenate([points_in_box((20, 20, 100, 100), 3000),
                                       points_in_box((220, 20, 300, 100), 3000, seed=1)])
    filled = report.verify_scene(scene, fit)
    hull = report.verify_scene(scene, fit, region_shape="hull")
    assert filled.region == "filled" and hull.region == "hull"
    assert not filled.protected[60, 160] and hull.protected[60, 160]
    assert hull.protected_fraction > filled.protected_fraction
    assert json.loads(report.write_verify(hull, tmp_path / "v").read_text())["region"] == "hull"


def test_report_json_has_the_contract_fields_and_no_key(tmp_path):
    photo = texture()
    scene = make_scene(with_square(photo), box_mask(SQUARE))
    fit = make_fit(photo, centers=CENTERS + [[0.01, 0, 0], [0, 0.02, -0.01]])
    truth = folder.Truth(clean=np.clip(photo + 0.02, 0, 1), totem_pose=CENTERS, scene={})
    rep = report.verify_scene(scene, fit, truth=truth)
    path = report.write_verify(rep, tmp_path / "verify")
    data = json.loads(path.read_text())
    assert set(data) == FIELDS
    assert data["working_scale"] == 1                  # a 320 x 240 photo, as it is
    assert data["verdict"] == "inconsistent" and data["inconsistent_reasons"] == ["photo"]
    assert data["totem_check"] is None                 # a fit without its totem rays
    assert set(data["metrics"]) == {"patch_ap_L1", "patch_ap_SSIM", "patch_ap_CHROMA",
                                    "patch_ap_RANGE", "patch_ap_CORROB",
                                    "patch_ap_UNSEEN", "patch_ap_ABSENT", "recon_L1",
                                    "pose_L1", "manip_judged", "reach_fraction",
                                    "reach_judged", "judged_seen", "manip_in_reach",
                                    "depth_error", "totem_depth_error",
                                    "totem_depth_given", "totem_depth_within",
                                    "totem_depth_bound"}
    assert data["metrics"]["reach_judged"] is None          # no truth/reach.npz
    # pose_L1 = mean over totems of sum |dP|: (0.01 + 0.03) / 2
    assert data["metrics"]["pose_L1"] == pytest.approx(0.02, abs=1e-6)
    # recon_L1 over protected non-totem pixels, computed here by hand
    seen = rep.protected & ~scene.masks.any(axis=0)
    want = np.abs(photo.astype(float) - truth.clean).mean(axis=2)[seen].mean()
    assert data["metrics"]["recon_L1"] == pytest.approx(want, abs=1e-6)
    assert len(data["totems"]) == 2
    # totem 1 moved farther (0.03 m) than totem 0 (0.01 m): its silhouette overlaps less
    assert data["totems"][1]["mask_iou"] < data["totems"][0]["mask_iou"] < 1
    assert data["key_fingerprint"] == folder.key_fingerprint(scene.radius, scene.ior)
    for name in ("L1", "SSIM", "CHROMA", "RANGE", "UNSEEN"):
        h = np.load(tmp_path / "verify" / name / "heatmap.npy")
        assert h.shape == (30, 30) and np.isfinite(h).all()
        for pic in ("heatmap_vis.png", "heatmap_overlay.png"):
            assert (tmp_path / "verify" / name / pic).is_file()
    assert folder.read_mask(tmp_path / "verify" / "protect_mask.png").mean() == \
        pytest.approx(data["protected_fraction"], abs=1e-6)
    # the key appears nowhere: not as text, not as a number in report.json
    def numbers(o):
        if isinstance(o, dict):
            for v in o.values():
                yield from numbers(v)
        elif isinstance(o, list):
            for v in o:
                yield from numbers(v)
        elif isinstance(o, (int, float)) and not isinstance(o, bool):
            yield float(o)
    assert all(abs(x - k) > 1e-5 for x in numbers(data) for k in (RADIUS, IOR))
    for f in (tmp_path / "verify").rglob("*"):
        if f.is_file():
            blob = f.read_bytes()
            for k in (RADIUS, IOR):
                for text in (repr(k), f"{k:.6f}", f"{k:.4f}"):
                    assert text.encode() not in blob, f"key {text} in {f.name}"


def test_metrics_are_null_without_ground_truth():
    photo = texture()
    rep = report.verify_scene(make_scene(photo), make_fit(photo))
    assert rep.to_json()["metrics"] == {"patch_ap_L1": None, "patch_ap_SSIM": None,
                                       "patch_ap_CHROMA": None, "patch_ap_RANGE": None,
                                       "patch_ap_CORROB": None,
                                       "patch_ap_UNSEEN": None, "patch_ap_ABSENT": None,
                                       "recon_L1": None, "pose_L1": None,
                                       "manip_judged": None, "reach_fraction": None,
                                       "reach_judged": None, "judged_seen": None,
                                       "manip_in_reach": None, "depth_error": None,
                                       "totem_depth_error": None, "totem_depth_given": None,
                                       "totem_depth_within": None,
                                       "totem_depth_bound": None}
    assert rep.to_json()["totems"][0]["mask_iou"] > 0.98     # true centres, true masks


def test_fit_from_another_scene_is_bad_input():
    photo = texture()
    small = SimpleNamespace(**{**vars(make_fit(photo)), "recon": photo[:100]})
    with pytest.raises(BadInput, match="refit"):
        report.verify_scene(make_scene(photo), small)
    three = SimpleNamespace(**{**vars(make_fit(photo)), "centers": np.zeros((3, 3))})
    with pytest.raises(BadInput, match="refit"):
        report.verify_scene(make_scene(photo), three)


def test_a_view_off_by_an_exposure_is_judged_as_the_photos_own():
    """A view whose linear light is 0.6-0.8 of the photo's (a camera's other exposure
    and white balance) is brought back by its gains and judged as the exact view is."""
    from scenes.colour import linear_to_srgb, srgb_to_linear

    photo = texture()
    dark = linear_to_srgb(srgb_to_linear(photo) * np.array([0.6, 0.7, 0.8]))
    scene = make_scene(with_square(photo), box_mask(SQUARE))
    exact = report.verify_scene(scene, make_fit(photo))
    off = report.verify_scene(scene, make_fit(dark))
    assert off.tone["gain"] == pytest.approx([1 / 0.6, 1 / 0.7, 1 / 0.8], rel=0.02)
    assert exact.tone["gain"] == pytest.approx([1, 1, 1], abs=0.03)    # the blur only
    assert off.verdict == exact.verdict == "inconsistent"
    assert off.score == pytest.approx(exact.score, rel=0.05)
