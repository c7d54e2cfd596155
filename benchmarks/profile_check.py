"""Where a check's time goes: `totems check` of each SCENE, stage by stage.

    python benchmarks/profile_check.py SCENE [SCENE ...] [--against REV] [--pairs N]
                                       [--no-kernels]

Each photo runs in a fresh process (so its peak memory is its own): the stages of the
fit and of verify are timed by wrapping the functions that do them (inclusive seconds,
nested stages indented), and Dr.Jit's kernel history says how much of each stage was
kernels running (the rest is Python, tracing and numpy). ``--against REV`` times the
plain `totems check` of the code at git revision REV and of this code on the same photo,
in the same run, one after the other, each in a process of its own (REV from a worktree
under a temporary folder); ``--pairs N`` runs that pair N times, the order alternating,
and takes the median ratio (on a machine shared with other work one pair's ratio wanders
by 10-20 %). Prints a table per photo and a summary: the profiled check's
seconds (the kernel history's reading left out) and peak memory (``--no-kernels`` for
a peak without the history's copies of every kernel), and with REV both plain checks'
seconds and their ratio.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: (module, function) pairs timed, in the order a check calls them.
STAGES = [
    ("scenes.folder", "read_scene"),
    ("inverse.fit.fit", "fit_scene"),
    ("inverse.fit.fit", "_initial_pose"),
    ("inverse.pose.pose", "initial_pose"),
    ("inverse.pose.combined", "combined_poses"),
    ("inverse.pose.rim", "refine_centres"),
    ("inverse.fit.fit", "totem_pixels"),
    ("inverse.fit.fit", "frame_for_scene"),
    ("inverse.fit.fit", "_integrator"),
    ("inverse.fit.fit", "_outline"),
    ("inverse.fit.fit", "_usable_pixels"),
    ("inverse.fit.fit", "_optimise"),
    ("inverse.fit.fit", "_pose_check"),
    ("inverse.view.view", "render_view"),
    ("inverse.fit.fit", "_totem_outputs"),
    ("inverse.fit.fit", "exit_rays"),
    ("inverse.fit.fit", "_camera_view"),
    ("inverse.fit.fit", "scene_fingerprint"),
    ("inverse.view.view", "slice_colours"),
    ("inverse.view.view", "plane_sweep"),
    ("inverse.view.view", "holdout_errors"),
    ("inverse.view.view", "stereo_weight"),
    ("inverse.fit.files", "write_fit"),
    ("verify.report.report", "verify_scene"),
    ("verify.metrics.region", "protected_region"),
    ("verify.metrics.patches", "pixel_errors"),
    ("verify.metrics.corroborate", "corroboration"),
    ("verify.metrics.absence", "absence"),
    ("verify.metrics.patches", "heatmaps"),
    ("verify.verdict.verdict", "decide"),
    ("verify.report.report", "write_verify"),
]


class _Timer:
    """Inclusive wall time and Dr.Jit kernel time of wrapped functions, nested."""

    def __init__(self):
        self.rows = []          # (depth, name, seconds, kernel seconds, calls)
        self.index = {}
        self.depth = 0

    def wrap(self, name, fn):
        def timed(*args, **kwargs):
            key = (self.depth, name)
            if key not in self.index:
                self.index[key] = len(self.rows)
                self.rows.append([self.depth, name, 0.0, 0.0, 0])
            row = self.rows[self.index[key]]
            k0 = _kernel_seconds()
            o0 = _DRAIN_S[0]
            t0 = time.perf_counter()
            self.depth += 1
            try:
                return fn(*args, **kwargs)
            finally:
                self.depth -= 1
                row[2] += time.perf_counter() - t0 - (_DRAIN_S[0] - o0)
                row[3] += _kernel_seconds() - k0
                row[4] += 1
        return timed


_KERNEL_S = [0.0]
_DRAIN_S = [0.0]      # seconds spent reading the kernel history, left out of the stages


def _kernel_seconds() -> float:
    """Seconds of Dr.Jit kernels run so far (the history is drained as it is read)."""
    import drjit as dr

    t0 = time.perf_counter()
    if dr.flag(dr.JitFlag.KernelHistory):
        _KERNEL_S[0] += sum(k.get("execution_time", 0.0)
                            for k in dr.kernel_history()) / 1e3
    _DRAIN_S[0] += time.perf_counter() - t0
    return _KERNEL_S[0]


def profile_one(scene_dir: str, out: str, kernels: bool = True) -> dict:
    """Check one photo in this process with every stage of :data:`STAGES` timed (and
    Dr.Jit's kernel time per stage when ``kernels``)."""
    from scenes import backend

    dr, _ = backend.modules()
    dr.set_flag(dr.JitFlag.KernelHistory, kernels)
    timer = _Timer()
    originals = []
    for mod_name, fn_name in STAGES:
        mod = importlib.import_module(mod_name)
        fn = getattr(mod, fn_name)
        originals.append((mod, fn_name, fn))
        setattr(mod, fn_name, timer.wrap(fn_name, fn))
    from verify.cli import commands as cli

    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stdout(sys.stderr):
            cli.main(["check", scene_dir, "--out", out, "--quiet"])
    finally:
        for mod, fn_name, fn in originals:
            setattr(mod, fn_name, fn)
    total = time.perf_counter() - t0 - _DRAIN_S[0]
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    fit = json.loads((Path(out) / "fit" / "fit.json").read_text())
    return {"scene": scene_dir, "check_s": total, "peak_mb": peak, "rows": timer.rows,
            "steps": len(fit["history"]["loss"]), "fit_timings": fit["timings"]}


def _child(args: list[str]) -> dict:
    """Run this script's ``--one`` in a fresh process and read its JSON line."""
    res = subprocess.run([sys.executable, __file__, "--one", *args], capture_output=True,
                         text=True, cwd=ROOT)
    if res.returncode != 0:
        raise SystemExit(f"profile of {args[0]} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


_PLAIN = ("import resource, sys\n"
          "from verify.cli.commands import main\n"
          "code = main(sys.argv[1:])\n"
          "kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
          "print(f'peak_kb {kb}', file=sys.stderr)\n"
          "sys.exit(code)\n")


def time_revision(worktree: Path, scene_dir: str, out: str) -> dict:
    """Wall seconds and peak memory (MB) of `totems check` with the code of
    ``worktree``, in a process of its own."""
    env = dict(os.environ, PYTHONPATH=str(worktree))
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", _PLAIN, "check", scene_dir, "--out", out,
                          "--quiet"], cwd=worktree, env=env, capture_output=True,
                         text=True)
    seconds = time.perf_counter() - t0
    if res.returncode not in (0, 1, 4):       # a verdict: consistent, not, unverifiable
        raise SystemExit(f"check at {worktree} failed:\n{res.stderr[-2000:]}")
    kb = [ln.split()[1] for ln in res.stderr.splitlines() if ln.startswith("peak_kb ")]
    return {"check_s": seconds, "peak_mb": int(kb[-1]) / 1024 if kb else float("nan")}


def _pairs(worktree: Path, scene: str, tmp: Path, n: int) -> dict:
    """``n`` plain checks of this code and of ``worktree``'s, the order alternating:
    the median of each one's seconds and of the pairs' ratios, and the peak memory."""
    import statistics

    runs = {"run": [], "old": []}
    for k in range(max(1, n)):
        order = (("run", ROOT), ("old", worktree))
        for name, code in (order if k % 2 == 0 else order[::-1]):
            runs[name].append(time_revision(code, scene, str(tmp / f"{name}{k}")))
    ratios = [a["check_s"] / b["check_s"] for a, b in zip(runs["run"], runs["old"])]
    med = {k: statistics.median(r["check_s"] for r in v) for k, v in runs.items()}
    return {"run_s": med["run"], "run_mb": max(r["peak_mb"] for r in runs["run"]),
            "old_s": med["old"], "old_mb": max(r["peak_mb"] for r in runs["old"]),
            "ratio": statistics.median(ratios), "ratios": ratios}


def _print_profile(p: dict) -> None:
    print(f"\n{p['scene']}: check {p['check_s']:.1f} s, peak {p['peak_mb']:.0f} MB, "
          f"{p['steps']} steps, {p['fit_timings'].get('n_rays')} rays")
    print(f"  {'stage':<34}{'s':>8}{'kernels s':>11}{'calls':>7}")
    for depth, name, sec, ker, calls in p["rows"]:
        print(f"  {'  ' * depth + name:<34}{sec:8.2f}{ker:11.2f}{calls:7d}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--against", metavar="REV", help="also time `totems check` at REV")
    ap.add_argument("--pairs", type=int, default=1,
                    help="with --against: time both checks N times, alternating")
    ap.add_argument("--no-kernels", action="store_true",
                    help="no Dr.Jit kernel history: its IR copies raise the peak memory")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(profile_one(args.scenes[0], args.out, not args.no_kernels)))
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="profile-check-"))
    worktree = None
    if args.against:
        worktree = tmp / "rev"
        subprocess.run(["git", "worktree", "add", "--detach", str(worktree),
                        args.against], cwd=ROOT, check=True, capture_output=True)
    summary = []
    try:
        for i, scene in enumerate(args.scenes):
            p = _child([str(Path(scene).resolve()), "--out", str(tmp / f"new{i}")]
                       + (["--no-kernels"] if args.no_kernels else []))
            _print_profile(p)
            row = {"scene": Path(scene).name, "check_s": p["check_s"],
                   "peak_mb": p["peak_mb"]}
            if worktree is not None:      # both as a user runs them: a process each
                row.update(_pairs(worktree, str(Path(scene).resolve()), tmp / str(i),
                                  args.pairs))
            summary.append(row)
    finally:
        if worktree is not None:
            subprocess.run(["git", "worktree", "remove", "--force", str(worktree)],
                           cwd=ROOT, capture_output=True)
    print("\nscene                 check s   peak MB"
          + ("   run s  run MB   old s  old MB  ratio" if worktree else ""))
    for r in summary:
        line = f"{r['scene']:<20}{r['check_s']:9.1f}{r['peak_mb']:10.0f}"
        if "old_s" in r:
            line += (f"{r['run_s']:8.1f}{r['run_mb']:8.0f}{r['old_s']:8.1f}"
                     f"{r['old_mb']:8.0f}{r['ratio']:7.2f}")
            if len(r["ratios"]) > 1:
                line += "  (" + ", ".join(f"{x:.2f}" for x in r["ratios"]) + ")"
        print(line)
    import statistics
    print(f"median check {statistics.median(r['check_s'] for r in summary):.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
