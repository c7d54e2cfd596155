"""benchmarks/cycles/make_cycles_set.py without Blender: which kept renders serve."""

import json
from types import SimpleNamespace

from benchmarks.cycles import make_cycles_set as mcs


def _record(path, **fields):
    path.mkdir(parents=True)
    (path / "render.json").write_text(json.dumps({"format": 1, **fields}))
    return path


def test_a_render_made_without_the_removal_is_made_again_when_one_is_asked(tmp_path):
    """A kept render serves a set without removals; one asked for a removal serves both,
    whether or not it found an object to remove; one made without does not."""
    without = _record(tmp_path / "a", remove_asked=False, removed_index=None)
    asked_none = _record(tmp_path / "b", remove_asked=True, removed_index=None)
    older = _record(tmp_path / "c", removed_index=None)        # before remove_asked
    older_removed = _record(tmp_path / "d", removed_index=5)
    assert [mcs.finished(d, False) for d in (without, asked_none, older, older_removed)] \
        == [True] * 4
    assert [mcs.finished(d, True) for d in (without, asked_none, older, older_removed)] \
        == [False, True, False, True]
    assert not mcs.finished(tmp_path / "none", False)
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "render.json").write_text("{half")      # an interrupted write
    assert not mcs.finished(tmp_path / "e", False)


def test_render_runs_blender_only_when_the_kept_render_does_not_serve(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(mcs.subprocess, "run",
                        lambda cmd, **kw: calls.append(cmd) or SimpleNamespace(returncode=0))
    rdir = _record(tmp_path / "s301", remove_asked=False, removed_index=None)
    args = SimpleNamespace(samples=64, small=False, size="640x480", kind=None,
                           no_remove=True, view=None, denoise=None, filter=None,
                           filter_width=None, glass=None, totem_shadows=None)
    assert mcs.render(rdir, 301, args) == 0.0 and calls == []
    args.no_remove = False
    mcs.render(rdir, 301, args)
    assert len(calls) == 1 and "--remove" in calls[0] and calls[0][-1] != "--no-remove"


def _removal_case(tmp_path, object_box):
    """A scene folder (one totem) and a render folder whose removed.png differs from the
    photo by the renders' noise everywhere and by the object within ``object_box``."""
    import numpy as np

    from benchmarks.cycles import convert
    from scenes import folder
    from scenes.files import write_image

    H, W = 96, 128
    rng = np.random.default_rng(0)
    photo = rng.integers(40, 200, (H, W, 3)).astype(np.uint8)
    yy, xx = np.mgrid[:H, :W]
    mask = (xx - 40) ** 2 + (yy - 48) ** 2 <= 12 ** 2
    K = np.array([[100.0, 0, W / 2], [0, 100.0, H / 2], [0, 0, 1]])
    scene = folder.write_scene(tmp_path / "scene", image=photo / 255.0, K=K, masks=[mask],
                               radius=0.05, ior=1.5)
    removed = np.clip(photo.astype(int) + rng.choice([-6, 6], photo.shape), 0, 255)
    ids = np.zeros((H, W), np.int32)
    x0, y0, x1, y1 = object_box
    ids[y0:y1, x0:x1] = 3
    removed[y0:y1, x0:x1] = (250, 10, 10)
    rdir = tmp_path / "render"
    rdir.mkdir()
    (rdir / "render.json").write_text(json.dumps({"removed_index": 3,
                                                  "description": {"seed": 1}}))
    np.save(rdir / "ids.npy", ids)
    write_image(rdir / "removed.png", removed.astype(np.uint8))
    return convert.write_removed(rdir, scene, tmp_path / "removed"), scene


def test_a_removal_away_from_the_totems_shares_its_photos_fit(tmp_path):
    """The renders' noise is not taken into the band a fit reads, so the copy keeps the
    photo's fingerprint (one fit serves both, as for a forger's copy); the object's own
    pixels and the noise elsewhere are taken."""
    import numpy as np

    from inverse.fit.files import pixels_read, scene_fingerprint
    from scenes import folder

    out, scene = _removal_case(tmp_path, (100, 10, 120, 40))
    copy, orig = folder.read_scene(out), folder.read_scene(scene)
    assert scene_fingerprint(copy) == scene_fingerprint(orig)
    manip = np.asarray(copy.manip_mask, bool)
    read = pixels_read(orig.masks)
    assert manip[10:40, 100:120].all() and not (manip & read).any()
    assert manip[~read].mean() > 0.9              # elsewhere the noise is the other render's


def test_a_removal_inside_the_band_gets_its_own_fit(tmp_path):
    from inverse.fit.files import scene_fingerprint
    from scenes import folder

    out, scene = _removal_case(tmp_path, (54, 40, 62, 56))     # 2-10 px right of the rim
    assert scene_fingerprint(folder.read_scene(out)) \
        != scene_fingerprint(folder.read_scene(scene))
