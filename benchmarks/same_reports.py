"""Do two versions of the code give the same reports? For changes meant to change no behaviour.

    python benchmarks/same_reports.py --base REV [--work DIR] [--size WxH]

A small fixed set (three presets and placements, two edits) is made, tampered and checked
by the code at REV (unpacked with ``git archive``) and by the working tree, each in its own
process with only its own tree on ``PYTHONPATH``. Then every file of each scene folder is
compared byte for byte, and every field of each ``report.json`` value for value, timings
(seconds) and the versions' own names left out. Prints one line per photo; exit 0 when all
are the same, 1 when any differs (each difference printed), 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (name, command after `totems`): scenes first, then edits of them, then the checks.
SCENES = (("box-1", ["--preset", "box", "--seed", "1"]),
          ("tabletop-2", ["--preset", "tabletop", "--seed", "2"]),
          ("outdoor-3", ["--preset", "outdoor", "--seed", "3", "--placement", "stand"]))
EDITS = (("box-1-splice", "box-1", ["--kind", "splice", "--seed", "1"]),
         ("outdoor-3-color", "outdoor-3", ["--kind", "color", "--seed", "2"]))
CHECK_FLAGS = {"tabletop-2": ["--resting"]}

# report.json keys whose values are the run's own clock or the code's name, not its result.
IGNORED = ("timing", "version", "seconds", "wall_s")


def totems(tree: Path, *args: str) -> subprocess.CompletedProcess:
    """``totems ARGS`` run by the code of ``tree`` alone."""
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONDONTWRITEBYTECODE="1")
    code = "import sys; from verify.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *args], cwd=tree, env=env,
                          capture_output=True, text=True)


def run_set(tree: Path, out: Path, size: str) -> dict:
    """Make, tamper and check the fixed set with ``tree``'s code into ``out``; the exit
    code of each check, by photo."""
    codes = {}
    for name, args in SCENES:
        done = totems(tree, "scene", "make", str(out / name), *args, "--size", size, "--quiet")
        if done.returncode != 0:
            raise SystemExit(f"scene make {name} failed in {tree}: {done.stderr.strip()}")
    for name, source, args in EDITS:
        done = totems(tree, "tamper", str(out / source), str(out / name), *args)
        if done.returncode != 0:
            raise SystemExit(f"tamper {name} failed in {tree}: {done.stderr.strip()}")
    for name in [n for n, _ in SCENES] + [n for n, _, _ in EDITS]:
        done = totems(tree, "check", str(out / name), "--quiet",
                      *CHECK_FLAGS.get(name.split("-")[0] + "-" + name.split("-")[1], []))
        if done.returncode not in (0, 1, 4):
            raise SystemExit(f"check {name} failed in {tree}: {done.stderr.strip()}")
        codes[name] = done.returncode
    return codes


def flatten(value, prefix: str = "") -> dict:
    """A JSON value as {dotted path: leaf}, the ignored keys left out."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if any(word in k for word in IGNORED):
                continue
            out.update(flatten(v, f"{prefix}.{k}" if prefix else k))
        return out
    if isinstance(value, list):
        out = {}
        for i, v in enumerate(value):
            out.update(flatten(v, f"{prefix}[{i}]"))
        return out
    return {prefix: value}


def differences(a: Path, b: Path) -> list[str]:
    """What differs between two checked scene folders: inputs byte for byte, report.json
    field for field."""
    diff = []
    files_a = {p.relative_to(a) for p in a.rglob("*") if p.is_file()
               and "totems-out" not in p.parts}
    files_b = {p.relative_to(b) for p in b.rglob("*") if p.is_file()
               and "totems-out" not in p.parts}
    for rel in sorted(files_a ^ files_b):
        diff.append(f"file only in one: {rel}")
    for rel in sorted(files_a & files_b):
        if rel.suffix != ".json" and (a / rel).read_bytes() != (b / rel).read_bytes():
            diff.append(f"file differs: {rel}")
    ra = flatten(json.loads((a / "totems-out/verify/report.json").read_text()))
    rb = flatten(json.loads((b / "totems-out/verify/report.json").read_text()))
    for key in sorted(ra.keys() | rb.keys()):
        if ra.get(key, "<missing>") != rb.get(key, "<missing>"):
            diff.append(f"report.json {key}: {ra.get(key, '<missing>')!r} != "
                        f"{rb.get(key, '<missing>')!r}")
    return diff


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", required=True, help="the git revision to compare against")
    p.add_argument("--work", type=Path, default=None, help="where to keep both runs")
    p.add_argument("--size", default="320x240")
    args = p.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="same-reports-"))
    base_tree = work / "base-tree"
    if not base_tree.exists():
        base_tree.mkdir(parents=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.base],
                                 capture_output=True)
        if archive.returncode != 0:
            print(f"error: no revision {args.base!r}: {archive.stderr.decode().strip()}",
                  file=sys.stderr)
            return 2
        subprocess.run(["tar", "-x", "-C", str(base_tree)], input=archive.stdout, check=True)
    codes = {}
    for label, tree in (("base", base_tree), ("head", ROOT)):
        out = work / label
        if not (out / "done.json").exists():
            codes[label] = run_set(tree, out, args.size)
            (out / "done.json").write_text(json.dumps(codes[label]))
        codes[label] = json.loads((work / label / "done.json").read_text())
    same = True
    for name in codes["base"]:
        diff = differences(work / "base" / name, work / "head" / name)
        if codes["base"][name] != codes["head"][name]:
            diff.insert(0, f"exit code {codes['base'][name]} != {codes['head'][name]}")
        n = len(flatten(json.loads((work / "head" / name / "totems-out/verify/report.json")
                                   .read_text())))
        print(f"{name:18s} exit {codes['head'][name]}  {n} report fields  "
              + ("same" if not diff else f"{len(diff)} differences"))
        for line in diff:
            print("    " + line)
        same &= not diff
    print(f"{args.base} and the working tree: " + ("the same" if same else "DIFFERENT")
          + f" (runs in {work})")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
