"""The runs of a batch, on an :class:`verify.batch.batch.Engine`: each photo's command, the
order (a run that reuses another's fit waits for it), and resuming.

A run's folder holds ``fit/`` and ``verify/`` as ``totems check --out`` writes them and,
once it finished, ``run.json`` (the command, the source hash of the code that ran it,
the wall time; written by the worker, :func:`verify.batch.batch.run_job`). A later batch
reads such a run back instead of running it again when its command and code are the same,
``verify/report.json`` is there, and the fit it was verified on still matches: that fit's
``scene_fingerprint`` is the scene's and its centres are the report's.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Run", "command", "fingerprint", "resumed", "run_all"]


@dataclass(frozen=True)
class Run:
    """One command of a batch.

    ``info``: the scene's description (``scene``, ``name``, ...: ``verify.batch.bench.
    describe_scene``), copied into the record; ``folder``: the run's ``--out``;
    ``check_flags``: options of ``totems check`` (the pose mode, the region);
    ``verify_flags``: those of ``totems verify`` when it reuses ``leader``'s fit.
    """

    info: dict = field(hash=False, compare=False)
    mode: str
    folder: Path
    check_flags: tuple[str, ...] = ()
    verify_flags: tuple[str, ...] = ()
    leader: Run | None = None


def command(run: Run, fit_dir: Path | None) -> list[str]:
    """``totems`` arguments of ``run``: check, or verify on ``fit_dir`` when given."""
    if fit_dir is None:
        return ["check", run.info["scene"], "--out", str(run.folder), "--json", "--quiet",
                *run.check_flags]
    return ["verify", run.info["scene"], "--fit", str(fit_dir), "--out", str(run.folder),
            "--json", "--quiet", *run.verify_flags]


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def fingerprint(scene: Path) -> str | None:
    """The scene's fit fingerprint at its working resolution, or None when it cannot be
    read (its own check will say why)."""
    from inverse.fit.files import scene_fingerprint
    from scenes.errors import BadInput
    from scenes.working import read_working_scene

    try:
        return scene_fingerprint(read_working_scene(scene))
    except BadInput:
        return None


def resumed(run: Run, argv: list[str], fit_dir: Path, source: str) -> dict | None:
    """The record of ``run`` as an earlier batch finished it, or None to run it."""
    meta = _read_json(run.folder / "run.json")
    if not isinstance(meta, dict) or meta.get("argv") != argv \
            or meta.get("source") != source:
        return None
    report = _read_json(run.folder / "verify" / "report.json")
    fit = _read_json(fit_dir / "fit.json")
    if not isinstance(report, dict) or not isinstance(fit, dict):
        return None
    if fit.get("scene_fingerprint") != fingerprint(Path(run.info["scene"])):
        return None
    try:
        same = np.allclose([t["center"] for t in report["totems"]], fit["centers"],
                           atol=1e-5)
    except (KeyError, TypeError, ValueError):
        return None
    if not same:
        return None
    return {"status": "ok", "wall_s": meta.get("wall_s"), **report,
            "verify": str(run.folder / "verify"), "resumed": True}


def _record(run: Run, result: dict, fit_from: Run | None, reverified: bool) -> dict:
    record = {**run.info, "mode": run.mode, **result}
    if fit_from is not None:
        record["fit_from"] = fit_from.info["name"]
    if reverified:
        record["reverified"] = True
    return record


def run_all(engine, runs: list[Run], *, reverify: bool = False, resume: bool = True,
            on_record=None) -> list[dict]:
    """Every run of ``runs`` on ``engine``; returns their records, in the order they
    finished, each also given to ``on_record`` as it comes.

    A run with a leader is sent once its leader is done: on the leader's ``fit/`` when
    the leader succeeded, else fitting itself. With ``reverify`` a run without a leader
    whose ``fit/`` is already there is verified again on it (and nothing is resumed).
    """
    from distributed import as_completed

    followers: dict[Path, list[Run]] = {}
    for run in runs:
        if run.leader is not None:
            followers.setdefault(run.leader.folder, []).append(run)
    pending, sent, records = as_completed(), {}, []

    def finish(run, result, fit_from, reverified):
        record = _record(run, result, fit_from, reverified)
        records.append(record)
        if on_record:
            on_record(record)
        for f in followers.pop(run.folder, []):
            start(f, run if result["status"] == "ok" else None)

    def start(run, fit_from):
        own = run.folder / "fit"
        again = reverify and run.leader is None and (own / "fit.json").is_file()
        fit_dir = own if again else (fit_from.folder / "fit" if fit_from else None)
        argv = command(run, fit_dir)
        old = None if reverify else resumed(run, argv, fit_dir or own, engine.source)
        if old is not None:
            return finish(run, old, fit_from, False)
        (run.folder / "run.json").unlink(missing_ok=True)
        future = engine.submit(argv, run.folder)
        sent[future.key] = (run, fit_from, again)
        pending.add(future)

    for run in runs:
        if run.leader is None:
            start(run, None)
    for future in pending:
        run, fit_from, again = sent.pop(future.key)
        try:
            result = future.result()
        except Exception as exc:        # the worker died, or the task was cancelled
            result = {"status": "failed",
                      "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
        finish(run, result, fit_from, again)
    return records
