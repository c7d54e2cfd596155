"""``totems check DIR...``: many photos at once, on the batch engine, and an index.

Each folder is a scene folder checked as ``totems check`` checks one (its ``fit/`` and
``verify/`` in ``OUT/runs/<name>/``), on a Dask cluster (:mod:`verify.batch.batch`); photos
that share a fit fingerprint are fitted once (``verify.batch.bench.plan``), as in a bench. A
line per photo as each finishes, then ``OUT/index.html`` and ``OUT/index.json`` (last).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from scenes import folder
from scenes.errors import BadInput
from verify.batch.batch import Engine
from verify.batch.bench import describe_scene, plan
from verify.batch.runs import Run, run_all
from verify.verdict.verdict import totems_disagree

__all__ = ["EXIT_OK", "EXIT_INCONSISTENT", "EXIT_FAILED", "EXIT_UNVERIFIABLE",
           "scene_folders", "unique_names", "photo_line", "index_entry", "render_index", "check_many", "from_args"]

EXIT_OK, EXIT_INCONSISTENT, EXIT_FAILED, EXIT_UNVERIFIABLE = 0, 1, 2, 4


def scene_folders(dirs) -> list[Path]:
    """The folders given, resolved, each once, in the order given; a path that is not a
    folder is refused (``BadInput``)."""
    seen: dict[Path, None] = {}
    for d in map(Path, dirs):
        if not d.is_dir():
            raise BadInput(f"no such folder: {d}")
        seen.setdefault(d.resolve(), None)
    return list(seen)


def unique_names(paths: list[Path]) -> list[str]:
    """Each folder's name, with ``-2``, ``-3``... after a name already taken."""
    taken: set[str] = set()
    names = []
    for p in paths:
        name, k = p.name, 1
        while name in taken:
            k += 1
            name = f"{p.name}-{k}"
        taken.add(name)
        names.append(name)
    return names


def _describe(path: Path, name: str) -> dict:
    """``describe_scene``'s fields, or the bare scene when its truth/ cannot be read
    (its check then says why)."""
    try:
        info = describe_scene(path)
    except (OSError, ValueError):
        info = {"scene": str(path), "preset": "real", "kind": "none", "n_totems": 0}
    return {**info, "name": name}


def photo_line(record: dict) -> str:
    """One line on a finished photo: its verdict and score, or why it failed."""
    name = record["name"]
    if record["status"] != "ok":
        return f"{name}: could not be checked: {record.get('error')}"
    p = record.get("p_value")
    named = (record.get("totem_check") or {}).get("named") or []
    return (f"{name}: {record['verdict']}, score {record['score']:.2f} of "
            f"{record['threshold']:.2f}" + ("" if p is None else f", p = {p:.2g}")
            + ("" if not named else f"; {totems_disagree(named)}")
            + (f"; fit of {record['fit_from']}" if record.get("fit_from") else "")
            + (" (resumed)" if record.get("resumed") else ""))


def _relative(path: Path, out: Path) -> str | None:
    return os.path.relpath(path, out) if path.is_file() else None


def index_entry(record: dict, folder_: Path, out: Path) -> dict:
    """A photo's entry of index.json; paths relative to ``out``."""
    ok = record["status"] == "ok"
    return {"name": record["name"], "scene": record["scene"], "status": record["status"],
            "verdict": record.get("verdict"), "score": record.get("score"),
            "threshold": record.get("threshold"), "p_value": record.get("p_value"),
            "folder": os.path.relpath(folder_, out),
            "report": _relative(folder_ / "verify" / "report.json", out) if ok else None,
            "html": _relative(folder_ / "verify" / "report.html", out) if ok else None,
            "fit_from": record.get("fit_from"), "resumed": bool(record.get("resumed")),
            "error": record.get("error"), "exit_code": record.get("exit_code"),
            "wall_s": record.get("wall_s")}


def render_index(index: dict) -> str:
    """index.html: a table of the photos, each linked to its report.html; absolute paths
    in errors shortened to their last component, as in the other pages."""
    from verify.report.html_report import environment, unpath

    photos = [{**p, "error": p["error"] and unpath(p["error"])} for p in index["photos"]]
    return environment().get_template("index.html").render(
        index={**index, "photos": photos})


def _runs(infos: list[dict], out: Path, check_flags, verify_flags) -> list[Run]:
    """Each photo's run: those that fit first, then those that reuse a leader's fit."""
    planned = plan(infos)
    leaders, runs = {}, []
    for info, leader in planned:
        if leader is None:
            leaders[info["scene"]] = Run(info, "joint", out / "runs" / info["name"],
                                         tuple(check_flags), tuple(verify_flags))
            runs.append(leaders[info["scene"]])
    for info, leader in planned:
        if leader is not None:
            runs.append(Run(info, "joint", out / "runs" / info["name"], tuple(check_flags),
                            tuple(verify_flags), leader=leaders[leader["scene"]]))
    return runs


def check_many(dirs, out, *, check_flags=(), verify_flags=(), jobs: int = 1,
               scheduler: str | None = None, tls=None, timeout: float = 3600,
               say=None) -> dict:
    """Check every scene folder of ``dirs``; write ``out``/index.html and index.json.

    ``check_flags``: options of ``totems check`` for every photo (pose, region);
    ``verify_flags``: those that apply when a photo reuses another's fit (region);
    ``say``: called with :func:`photo_line` as each photo finishes. Returns the
    summary, with ``exit_code``: 2 if any photo could not be checked, else 1 if any was
    inconsistent, else 4 if any was unverifiable, else 0.
    """
    out = Path(out).resolve()                 # the workers' working folders differ
    paths = scene_folders(dirs)
    infos = [_describe(p, n) for p, n in zip(paths, unique_names(paths))]
    runs = _runs(infos, out, check_flags, verify_flags)
    t0 = time.perf_counter()
    with Engine(scheduler=scheduler, jobs=jobs, tls=tls, timeout=timeout) as engine:
        engine.preflight([i["scene"] for i in infos], out)
        records = run_all(engine, runs, on_record=say and (lambda r: say(photo_line(r))))
    order = {i["scene"]: k for k, i in enumerate(infos)}
    records.sort(key=lambda r: order[r["scene"]])
    by_scene = {r.info["scene"]: r.folder for r in runs}
    photos = [index_entry(r, by_scene[r["scene"]], out) for r in records]
    counts = {v: sum(p["verdict"] == v for p in photos if p["status"] == "ok")
              for v in ("consistent", "inconsistent", "unverifiable")}
    counts["failed"] = sum(p["status"] != "ok" for p in photos)
    code = EXIT_FAILED if counts["failed"] else (
        EXIT_INCONSISTENT if counts["inconsistent"] else
        EXIT_UNVERIFIABLE if counts["unverifiable"] else EXIT_OK)
    index = {"format": 1, "photos": photos, "counts": counts, "exit_code": code,
             "resumed": sum(p["resumed"] for p in photos), "workers": engine.slots,
             "scheduler": scheduler or "local",
             "wall_s": round(time.perf_counter() - t0, 1)}
    folder.write_bytes(out / "index.html", render_index(index).encode("utf-8"))
    folder.write_json(out / "index.json", index)
    return {"check": str(out / "index.html"), "index": str(out / "index.json"),
            "photos": len(photos), **counts, "resumed": index["resumed"],
            "exit_code": code, "wall_s": index["wall_s"]}


def _say(line: str) -> None:
    print(line, flush=True)


def from_args(args) -> dict:
    """``check_many`` with the options of ``totems check`` (``verify.cli``): the pose
    and region options go to every photo, a line per photo unless --quiet or --json,
    ``--out`` default ``check-out``."""
    region = ["--region", args.region]
    check_flags = [*(["--fixed-pose"] if args.fixed_pose else []),
                   *(["--oracle-pose"] if args.oracle_pose else []),
                   *(["--resting"] if args.resting else []),
                   "--pose-from", args.pose_from, *region]
    say = None if args.quiet or args.json else _say
    summary = check_many(args.scene, args.out or "check-out", check_flags=check_flags,
                         verify_flags=region, jobs=args.jobs, scheduler=args.scheduler,
                         tls=(args.tls_ca_file, args.tls_cert, args.tls_key), say=say)
    if say:
        say(f"{summary['photos']} photos: {summary['consistent']} consistent, "
            f"{summary['inconsistent']} inconsistent, {summary['unverifiable']} "
            f"unverifiable, {summary['failed']} could not be checked")
    return summary
