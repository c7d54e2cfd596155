"""Totems floating, resting on the support plane, or on thin stands, on every preset."""

import numpy as np
import pytest

from scenes import camera
from scenes.errors import BadInput
from scenes.synthetic import placement, presets, render


def _support(desc):
    s = desc["support"]
    return np.asarray(s["point"]), np.asarray(s["normal"])


def _heights(desc) -> np.ndarray:
    """Each totem's lowest point above the support plane (m)."""
    p0, up = _support(desc)
    return np.array([(np.asarray(t["center"]) - p0) @ up - t["radius"]
                     for t in desc["totems"]])


@pytest.mark.parametrize("preset", presets.PRESETS)
def test_resting_totems_touch_the_support(preset):
    desc = presets.describe(preset, 4, size=(320, 240), placement="resting")
    assert desc["placement"] == "resting" and len(desc["totems"]) >= 3
    assert np.allclose(_heights(desc), 0.0, atol=1e-5)
    assert not any(o["name"].startswith("stand_") for o in desc["objects"])


@pytest.mark.parametrize("preset", presets.PRESETS)
def test_each_stand_holds_its_totem_from_the_floor(preset):
    """A post per totem: its foot on the support plane, right below the centre, its
    top at the sphere's lowest point; clear of the other objects' bounds."""
    desc = presets.describe(preset, 4, size=(320, 240), placement="stand")
    p0, up = _support(desc)
    posts = [o for o in desc["objects"] if o["name"].startswith("stand_")]
    assert len(posts) == len(desc["totems"])
    ids = [o["id"] for o in desc["objects"]] + [li["id"] for li in desc["lights"]]
    assert len(set(ids)) == len(ids)
    assert np.all(_heights(desc) > 0.02)
    for post, t in zip(posts, desc["totems"]):
        M = np.asarray(post["to_world"])
        foot, top = M[:3, 3], M[:3, 3] + M[:3, 2]
        c, r = np.asarray(t["center"]), t["radius"]
        assert abs((foot - p0) @ up) < 1e-9                    # on the plane
        assert np.allclose(top, c - r * up, atol=1e-9)         # touching the sphere
        assert np.isclose(np.linalg.norm(M[:3, 0]), placement.POST_RADIUS)
        assert not post["removable"]


def test_posts_clear_refuses_a_post_through_an_obstacle():
    support = (np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0]))   # floor y = 1
    P, radii = [np.array([0.0, 0.0, 2.0])], [0.1]
    assert placement.posts_clear(P, radii, support, [])
    assert not placement.posts_clear(P, radii, support, [(np.array([0.0, 0.5, 2.0]), 0.05)])
    assert placement.posts_clear(P, radii, support, [(np.array([0.3, 0.5, 2.0]), 0.05)])
    below = [np.array([0.0, 1.05, 2.0])]                        # lower than its radius
    assert not placement.posts_clear(below, radii, support, [])


@pytest.mark.parametrize("preset", presets.PRESETS)
def test_the_default_placement_is_the_presets_own(preset):
    default = presets.DEFAULT_PLACEMENT.get(preset, "floating")
    desc = presets.describe(preset, 2, size=(160, 120))
    assert desc["placement"] == default
    assert desc == presets.describe(preset, 2, size=(160, 120), placement=default)
    other = "stand" if default == "resting" else "resting"
    assert desc["objects"][:3] == presets.describe(preset, 2, size=(160, 120),
                                                   placement=other)["objects"][:3]
    if default == "floating":
        assert np.all(_heights(desc) > 0.02)


def test_an_unknown_placement_is_bad_input():
    with pytest.raises(BadInput, match="placement"):
        presets.describe("box", 1, placement="hanging")


@pytest.mark.slow
@pytest.mark.parametrize("preset,how", [("box", "stand"), ("outdoor", "resting")])
def test_placed_totems_render_where_the_truth_says(preset, how):
    """The masks of resting totems and of totems on posts are the spheres' own: each
    centre in its mask, each mask's area the silhouette's (the post is not the totem)."""
    desc = presets.describe(preset, 5, size=(320, 240), placement=how)
    K = np.asarray(desc["K"])
    masks = render.totem_masks(desc)
    for m, t in zip(masks, desc["totems"]):
        u, v = np.rint(camera.project(K, t["center"])).astype(int)
        assert m[v, u]
        uv = presets.sphere_outline(K, t["center"], t["radius"], n=256)
        x, y = uv[:, 0], uv[:, 1]
        area = 0.5 * abs(x @ np.roll(y, -1) - y @ np.roll(x, -1))
        assert abs(m.sum() - area) / area < 0.05, (m.sum(), area)


def test_scene_make_places_totems_on_stands(tmp_path, capsys):
    """``totems scene make --placement stand`` writes the posts and the support into
    truth/scene.json; an unknown placement is a one-line error, exit 2."""
    import json

    from verify.cli import commands as cli

    out = tmp_path / "s"
    assert cli.main(["scene", "make", str(out), "--placement", "stand", "--size", "96x72",
                     "--spp", "2", "--quiet"]) == 0
    desc = json.loads((out / "truth" / "scene.json").read_text())
    assert desc["placement"] == "stand"
    assert sum(o["name"].startswith("stand_") for o in desc["objects"]) == 4
    assert set(desc["support"]) == {"point", "normal"}
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        cli.main(["scene", "make", str(tmp_path / "t"), "--placement", "hanging"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "placement" in err[0]
