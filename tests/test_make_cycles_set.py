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
