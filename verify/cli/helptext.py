"""The ``totems`` command's help texts: one example per verb, the exit codes each verb
can return (``docs/contract.md``, "Exit codes"), and ``--version``.

Kept apart from ``verify/cli/commands.py`` so that the parser there stays a list of options.
"""

from __future__ import annotations

import argparse

__all__ = ["DESCRIPTION", "EXAMPLES", "EXIT_CODES", "usage", "add_version",
           "version_text"]

DESCRIPTION = ("Physics-based verifier for totem-protected photographs: fit the scene "
               "seen through glass totems, re-render the camera view, find where the "
               "photo disagrees.")

EXAMPLES = {
    "totems": "totems check scenes/IMG_0001        # fit, re-render, judge one photo",
    "scene": "totems scene make box1 --preset box --seed 1",
    "make": "totems scene make box1 --preset box --seed 1 --size 640x480",
    "reach": "totems scene reach set/*           # truth/reach.npz of each",
    "tamper": "totems tamper box1 box1-color --kind color --seed 0",
    "recapture": "totems recapture box1 box1-jpeg75 --jpeg 75 --long-side 480",
    "fit": "totems fit box1 --out box1-out",
    "verify": "totems verify box1-color --fit box1-out/fit --out box1-color-out",
    "check": "totems check scenes/IMG_0001     # or: totems check set/* --jobs 2",
    "bench": "totems bench standard-set --out bench-out --jobs 2",
    "calib": "totems calib calib/*.JPG --board 9x6 --square 0.025 --out calib.npy",
    "ingest": "totems ingest IMG_0001.JPG --calib calib.npy --key totems.json "
              "scenes/IMG_0001",
    "masks": "totems masks scenes/IMG_0001 --hint 212,388 --hint 401,379",
    "crosscheck": "totems crosscheck scenes/IMG_0001 --nerf logs/IMG_0001",
    "plan": "totems plan --fov 60 --size 640x480 --radius 0.05 --ior 1.5 "
            "--totem 120,400,2 --totem 520,400,2 --subject-distance 4",
}
"""One command line per parser, keyed by its name (``make`` is ``scene make``)."""

_FAILED = ("  2    bad input or usage (one line on stderr saying what is wrong)\n"
           "  70   a bug (the traceback, and a line saying so)\n"
           "  130  interrupted")
_JUDGED = ("  0    consistent: the photo agrees with its totems\n"
           "  1    inconsistent: it does not\n"
           "  4    unverifiable: the totems establish too little of it, or do not\n"
           "       predict each other, to tell\n")
EXIT_CODES = {
    "totems": "  0    ran; for verify and check: consistent\n"
              "  1    verify, check: inconsistent\n"
              "  2    bad input or usage (one line on stderr saying what is wrong)\n"
              "  3    masks: fewer totems found than wanted\n"
              "  4    verify, check: unverifiable\n"
              "  70   a bug\n"
              "  130  interrupted",
    "verify": _JUDGED + _FAILED,
    "check": _JUDGED + _FAILED + "\n  with several SCENEs: 2 if any photo could not be "
             "checked, else 1 if any\n  was inconsistent, else 4 if any was unverifiable, "
             "else 0",
    "bench": "  0    ran, whatever its scenes gave (failed runs are counted in its "
             "summary)\n" + _FAILED,
    "masks": "  0    masks written, or the folder's own kept\n"
             "  3    fewer totems found than wanted: no mask written, see "
             "totem_masks_check.png\n" + _FAILED,
}
"""Each parser's exit codes (``verify/cli/commands.py`` ``main`` maps them); the rest: 0 or
a failure."""


def usage(name: str) -> dict:
    """``ArgumentParser`` keywords for parser ``name``: its example and exit codes as
    the epilog, laid out as written here."""
    lines = EXIT_CODES.get(name, "  0    ran\n" + _FAILED).split("\n")
    coded = sorted((x for x in lines if x[2:3].isdigit()),
                   key=lambda x: int(x.split()[0]))
    codes = "\n".join(coded + [x for x in lines if not x[2:3].isdigit()])
    return {"epilog": f"example:\n  {EXAMPLES[name]}\n\nexit codes:\n{codes}",
            "formatter_class": argparse.RawDescriptionHelpFormatter}


def version_text() -> str:
    """The package's version, Mitsuba's and Dr.Jit's, and the Dr.Jit variant this
    process uses (chosen in one place, ``scenes.backend.use``)."""
    from importlib import metadata

    from scenes import backend

    info = backend.describe()
    llvm = f" (libLLVM {info['llvm']})" if "llvm" in info else ""
    return (f"totems {metadata.version('totems')}\nmitsuba {info['mitsuba']}\n"
            f"drjit {info['drjit']}\nbackend {info['variant']}{llvm}")


class _Version(argparse.Action):
    """``--version``: computed only when asked (it loads Dr.Jit), then exit 0; without
    a working backend, one line and exit 2."""

    def __call__(self, parser, namespace, values, option_string=None):
        from scenes.backend import BackendError

        try:
            text = version_text()
        except BackendError as exc:
            parser.exit(2, f"totems: error: {exc}\n")
        print(text)
        parser.exit(0)


def add_version(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``parser`` with the ``--version`` option."""
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="print the versions of totems, Mitsuba and Dr.Jit and the "
                             "Dr.Jit backend in use, then exit")
    return parser
