"""The command line: usage and bad input give exit 2 and one line, never a traceback."""

import argparse
import subprocess
import sys

import numpy as np

from scenes import folder


def totems(*args, cwd=None):
    """Run the installed CLI in a fresh process, as a user would."""
    return subprocess.run([sys.executable, "-m", "verify.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def assert_one_line_error(proc):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    return lines[0]


def tiny_scene(path, size=(64, 48)):
    """A minimal valid scene folder: a flat photo with one round totem mask."""
    W, H = size
    yy, xx = np.mgrid[:H, :W]
    mask = (xx - 32) ** 2 + (yy - 30) ** 2 < 8 ** 2
    K = np.array([[60.0, 0, (W - 1) / 2], [0, 60.0, (H - 1) / 2], [0, 0, 1]])
    image = np.full((H, W, 3), 0.5, np.float32)
    return folder.write_scene(path, image=image, K=K, masks=[mask], radius=0.1, ior=1.52)


def test_usage_error_is_exit_2():
    line = assert_one_line_error(totems("fit"))
    assert "scene" in line


def test_unknown_verb_is_exit_2():
    assert_one_line_error(totems("frobnicate"))


def test_missing_scene_folder(tmp_path):
    line = assert_one_line_error(totems("fit", tmp_path / "nope"))
    assert "not found" in line


def test_bad_size_argument(tmp_path):
    line = assert_one_line_error(totems("scene", "make", tmp_path / "s", "--size", "big"))
    assert "WxH" in line


def test_malicious_calib_is_refused_and_not_run(tmp_path):
    scene = tiny_scene(tmp_path / "s")
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    np.save(scene / "calib.npy", np.array({"mtx": Evil()}, dtype=object), allow_pickle=True)
    line = assert_one_line_error(totems("verify", scene))
    assert "calib.npy" in line
    assert not marker.exists()


def test_mask_of_another_size(tmp_path):
    scene = tiny_scene(tmp_path / "s")
    folder.write_image(scene / "totem_masks" / "totem_001.png", np.ones((10, 10), bool))
    line = assert_one_line_error(totems("check", scene))
    assert "totem_001" in line


def test_nan_key(tmp_path):
    scene = tiny_scene(tmp_path / "s")
    (scene / "totems.json").write_text('{"radius": NaN, "ior": 1.5}')
    line = assert_one_line_error(totems("fit", scene))
    assert "radius" in line


def test_inputs_untouched_on_error(tmp_path):
    scene = tiny_scene(tmp_path / "s")
    (scene / "totems.json").write_text('{"radius": -1, "ior": 1.5}')
    before = sorted(p.relative_to(scene) for p in scene.rglob("*"))
    assert_one_line_error(totems("check", scene))
    assert sorted(p.relative_to(scene) for p in scene.rglob("*")) == before


def test_the_summary_line_names_what_the_verb_wrote(capsys):
    """crosscheck once said 'wrote SCENE' where it wrote OUT/crosscheck."""
    from verify.cli.commands import _print_summary

    _print_summary("crosscheck", {"scene": "S", "crosscheck": "OUT/crosscheck"})
    _print_summary("fit", {"fit": "OUT/fit"})
    _print_summary("tamper", {"scene": "COPY", "kind": "color"})
    assert capsys.readouterr().out.splitlines() == [
        "crosscheck: wrote OUT/crosscheck", "fit: wrote OUT/fit", "tamper: wrote COPY"]


def test_a_crash_is_not_a_verdict(monkeypatch, capsys):
    """An unexpected error exits 70 (a bug), never 1 (inconsistent)."""
    from verify.cli import commands as cli

    def boom(args):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(cli, "cmd_fit", boom)
    assert cli.main(["fit", "nowhere"]) == cli.EXIT_BUG
    assert "internal error" in capsys.readouterr().err


def test_version_names_the_three_versions_and_the_backend():
    from importlib import metadata

    proc = totems("--version")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    for package in ("totems", "mitsuba", "drjit"):      # read from the installed wheels
        assert f"{package} {metadata.version(package)}" in lines, proc.stdout
    backend = [x for x in lines if x.startswith("backend ")]
    assert len(backend) == 1 and backend[0].split()[1] in ("llvm_ad_rgb", "cuda_ad_rgb")


def _parsers(parser, path=()):
    """(the words after `totems`, parser) of every parser of the command, nested ones
    included, found in the parser itself so that a new verb is covered."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, path + (name,))


def test_every_help_shows_an_example_and_the_exit_codes(capsys):
    from verify.cli.commands import build_parser

    seen = []
    for path, parser in _parsers(build_parser()):
        text = parser.format_help()
        lines = [x.strip() for x in text.splitlines()]
        command = " ".join(("totems",) + path)
        example = lines.index("example:")
        assert lines[example + 1].startswith(command + " "), (command, text)
        codes = lines[lines.index("exit codes:") + 1:]
        assert {"0", "2", "70"} <= {x.split()[0] for x in codes if x[:1].isdigit()}, text
        seen.append(command)
    assert {"totems check", "totems scene make", "totems masks",
            "totems bench"} <= set(seen)
    by_name = {" ".join(path): parser.format_help() for path, parser in
               _parsers(build_parser())}
    assert "1    inconsistent" in by_name["check"] and "3    fewer" in by_name["masks"]


def test_help_is_printed_and_exits_0():
    proc = totems("check", "--help")
    assert proc.returncode == 0 and "exit codes:" in proc.stdout, proc.stderr


def test_resting_reaches_the_fit_and_every_photo_of_a_check(monkeypatch, tmp_path):
    """``--resting`` sets ``FitSettings.resting`` for fit (and check, which fits alike),
    and a check of several photos passes it to each; without it the fit is not told."""
    import inverse.fit.fit
    from verify.batch import checks
    from verify.cli import commands as cli

    seen = []

    def fake_fit(scene, *, settings, **kwargs):
        seen.append(settings.resting)
        raise KeyboardInterrupt                      # stop before anything is written

    monkeypatch.setattr(inverse.fit.fit, "fit_scene", fake_fit)
    scene = tiny_scene(tmp_path / "s")
    assert cli.main(["fit", str(scene), "--resting", "--quiet"]) == 130
    assert cli.main(["fit", str(scene), "--quiet"]) == 130
    assert seen == [True, False]

    flags = {}
    monkeypatch.setattr(checks, "check_many",
                        lambda scenes, out, **kw: flags.update(kw) or {})
    args = cli.build_parser().parse_args(["check", "a", "b", "--resting", "--quiet"])
    checks.from_args(args)
    assert "--resting" in flags["check_flags"]
    args = cli.build_parser().parse_args(["check", "a", "b", "--quiet"])
    checks.from_args(args)
    assert "--resting" not in flags["check_flags"]


def test_the_summary_line_says_why_a_photo_is_unverifiable(capsys):
    from verify.cli import commands as cli

    base = {"score": 1.2, "threshold": 1.0, "scores": {}, "protected_fraction": 0.5,
            "judged_fraction": 0.4, "metrics": {}, "verify": "out", "p_value": None}
    cli._print_summary("check", {**base, "verdict": "unverifiable",
                                 "unverifiable_reason": "holdout",
                                 "holdout": {"L1": 0.3, "max": 0.16}})
    line = capsys.readouterr().out
    assert line.startswith("unverifiable (the totems do not predict each other")
    assert "0.300 > 0.16" in line
    cli._print_summary("check", {**base, "verdict": "unverifiable",
                                 "unverifiable_reason": "judged"})
    assert capsys.readouterr().out.startswith("unverifiable: score 1.20")
