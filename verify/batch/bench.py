"""``totems bench``: run check over many scene folders and write the paper's tables.

Each scene runs in its own process (``totems check ... --json``) on a worker of a Dask
cluster (:mod:`verify.batch.batch`), so a scene that fails, even by a crash of the backend,
is recorded as failed and the others go on; a bench run again into its folder reads back
the runs it finished (:mod:`verify.batch.runs`). Untouched
synthetic scenes are also fitted with the initial pose kept fixed and with the true pose
(oracle), which gives the three rows of the paper's Table 1.

A fit reads only the totem pixels, masks, camera and key
(``inverse.fit.files.scene_fingerprint``): scenes that share them (a photo and its copies
edited outside the totems) are fitted once, by the untouched one, and the others run
``totems verify --fit`` on that fit. The manipulations that leave the totems alone (colour,
splice, inpaint, remove, insert) then cost a verify each, not a fit; ``refit=True`` fits
every scene anyway.

Outputs (``OUT/``): ``bench.json`` (every run), ``bench.csv`` (one row a run),
``bench.md`` (the tables beside the paper's figures), ``plots/*.png``, ``bench.html``
(bench.md's tables and the plots in one self-contained page,
:mod:`verify.report.html_report`).
"""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput
from scenes.synthetic.presets import DEFAULT_PLACEMENT
from verify.batch.batch import Engine
from verify.batch.runs import Run, fingerprint, run_all
from verify.metrics.patches import METRICS
from verify.metrics.truth import TRUTH_METRICS
from verify.verdict.verdict import THRESHOLDS

__all__ = ["PAPER_TABLE1", "PAPER_TABLE2", "PAPER_TOTEMS", "MODES", "find_scenes",
           "describe_scene", "modes_for", "plan", "bench_runs",
           "run_bench", "summarise", "markdown", "CSV_FIELDS", "csv_text",
           "write_outputs", "write_plots"]

# The paper's figures (Tables 1 and 2 of the main text; supplementary for the totem study).
PAPER_TABLE1 = {  # preset -> mode -> (recon L1, pose L1 in metres)
    "box": {"initial": (0.057, 0.008), "joint": (0.054, 0.108), "oracle": (0.047, None)},
    "envmap": {"initial": (0.173, 0.060), "joint": (0.103, 0.027), "oracle": (0.040, None)},
}
PAPER_TABLE2 = {  # kind -> (AP with L1, AP with LPIPS), joint fit
    "color": (0.961, 0.946), "splice": (0.638, 0.739), "inpaint": (0.554, 0.666),
}
PAPER_TOTEMS = {2: 0.16, 4: 0.08, 6: 0.09}   # recon L1 against the number of totems
MODES = {"joint": [], "initial": ["--fixed-pose"], "oracle": ["--oracle-pose"]}


def find_scenes(roots) -> list[Path]:
    """Scene folders (with a photo, image.png or image.jpg, and totem_masks/) at or
    below ``roots``, sorted."""
    found = set()
    for root in map(Path, roots):
        if not root.exists():
            raise BadInput(f"no such folder: {root}")
        for name in folder.PHOTO_NAMES:
            for img in [root / name, *root.rglob(name)]:
                d = img.parent
                if img.is_file() and (d / "totem_masks").is_dir() \
                        and "totems-out" not in d.parts:
                    found.add(d.resolve())
    if not found:
        raise BadInput(f"no scene folders (image.png or image.jpg + totem_masks/) under "
                              f"{', '.join(map(str, roots))}")
    return sorted(found)


def describe_scene(scene: Path) -> dict:
    """Preset, placement of the totems, manipulation kind and number of totems of a
    scene folder, as recorded (placement "" when unknown: a real photo)."""
    info = {"scene": str(scene), "name": scene.name, "preset": "real", "kind": "none",
            "n_totems": len(list((scene / "totem_masks").glob("*.png"))), "placement": ""}
    sj = scene / "truth" / "scene.json"
    if sj.is_file():
        desc = json.loads(sj.read_text())
        info["preset"] = desc.get("preset", "synthetic")
        info["placement"] = desc.get("placement", DEFAULT_PLACEMENT.get(info["preset"],
                                                                        "floating"))
    tj = scene / "truth" / "tamper.json"
    if tj.is_file():
        info["kind"] = json.loads(tj.read_text()).get("kind", "unknown")
    elif (scene / "manip_mask.png").is_file():
        info["kind"] = "manipulated"
    return info


def modes_for(info: dict, table1: bool) -> list[str]:
    """Joint fit always; initial and oracle too for untouched synthetic scenes."""
    if table1 and info["kind"] == "none" and info["preset"] != "real":
        return ["joint", "initial", "oracle"]
    return ["joint"]


def plan(scenes: list[dict], refit: bool = False) -> list[tuple[dict, dict | None]]:
    """Each scene with the scene whose joint fit it reuses (None: it fits itself).

    The leader of a group of scenes with one fingerprint is its untouched scene, or else
    its first; a scene that cannot be read leads itself and fails in its own run.
    """
    if refit:
        return [(info, None) for info in scenes]
    groups: dict[str, list[dict]] = {}
    for info in scenes:
        fp = fingerprint(Path(info["scene"]))
        groups.setdefault(fp or info["scene"], []).append(info)
    leader_of = {}
    for group in groups.values():
        leader = next((i for i in group if i["kind"] == "none"), group[0])
        for info in group:
            leader_of[info["scene"]] = None if info is leader else leader
    return [(info, leader_of[info["scene"]]) for info in scenes]


def bench_runs(planned: list[tuple[dict, dict | None]], out: Path,
               table1: bool) -> list[Run]:
    """The runs of a bench: each mode of a scene that fits, then (``joint``) each scene
    that reuses its leader's joint fit, in ``OUT/runs/<name>-<mode>/``."""
    joint, runs = {}, []
    for info, leader in planned:
        if leader is None:
            for mode in modes_for(info, table1):
                run = Run(info, mode, out / "runs" / f"{info['name']}-{mode}",
                          check_flags=tuple(MODES[mode]))
                joint.setdefault(info["scene"], run)
                runs.append(run)
    for info, leader in planned:
        if leader is not None:
            runs.append(Run(info, "joint", out / "runs" / f"{info['name']}-joint",
                            leader=joint[leader["scene"]]))
    return runs


def run_bench(roots, out, *, jobs: int = 1, table1: bool = True, timeout: float = 3600,
              refit: bool = False, reverify: bool = False, progress: bool = False,
              scheduler: str | None = None, tls=None) -> dict:
    """Run every scene under ``roots``; write bench.json/csv/md and plots in ``out``.

    The runs go to a Dask cluster (:mod:`verify.batch.batch`: ``jobs`` local workers, or the
    one at ``scheduler``, with ``tls`` = (ca file, cert, key)); those that reuse a
    leader's joint fit (``plan``) follow it, and a scene whose leader failed fits itself
    (:func:`verify.batch.runs.run_all`). A run an earlier bench finished in ``out`` with the
    same code is read back (``resumed``). With ``reverify`` a run whose fit is already
    in ``out`` is verified again on it instead of fitted: what a change to ``verify/``
    alone needs. Its fit times are then the fit's own (``fit.json``) and ``fit`` (wall)
    is not measured.
    """
    out = Path(out)
    scenes = [describe_scene(s) for s in find_scenes(roots)]
    runs = bench_runs(plan(scenes, refit), out.resolve(), table1)   # workers' cwd differ
    t0 = time.perf_counter()
    with Engine(scheduler=scheduler, jobs=jobs, tls=tls, timeout=timeout) as engine:
        engine.preflight([s["scene"] for s in scenes], out)
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(runs), desc="bench", unit="run")
        records = run_all(engine, runs, reverify=reverify,
                          on_record=None if bar is None else (lambda r: bar.update()))
        if bar:
            bar.close()
    order = {s["scene"]: k for k, s in enumerate(scenes)}
    records.sort(key=lambda r: (order[r["scene"]], list(MODES).index(r["mode"])))
    bench = {"runs": records, "summary": summarise(records), "jobs": engine.slots,
             "scheduler": scheduler or "local", "refit": refit,
             "reverified": sum(1 for r in records if r.get("reverified")),
             "resumed": sum(1 for r in records if r.get("resumed")),
             "wall_s": round(time.perf_counter() - t0, 1), "scenes": len(scenes),
             "fits": sum(1 for r in records if "fit_from" not in r
                         and not r.get("reverified") and not r.get("resumed"))}
    write_outputs(bench, out)
    return bench


# --------------------------------------------------------------------------- tables

def _mean(values):
    v = [x for x in values if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if v else None


def _metric(run, name):
    return (run.get("metrics") or {}).get(name)


def summarise(runs: list[dict]) -> dict:
    """Table 1 (recon/pose per preset and mode), Table 2 (AP per kind), accuracy."""
    ok = [r for r in runs if r["status"] == "ok"]
    table1 = {}
    for r in ok:
        if r["kind"] != "none":
            continue
        table1.setdefault(r["preset"], {}).setdefault(r["mode"], []).append(r)
    table1 = {p: {m: {"recon_L1": _mean(_metric(r, "recon_L1") for r in rs),
                      "pose_L1": _mean(_metric(r, "pose_L1") for r in rs), "n": len(rs)}
                  for m, rs in modes.items()} for p, modes in table1.items()}
    table2 = {}
    for r in ok:
        if r["mode"] == "joint" and r["kind"] != "none":
            table2.setdefault(r["kind"], []).append(r)
    table2 = {k: {**{f"ap_{name}": _mean(_metric(r, f"patch_ap_{name}") for r in rs)
                     for name in METRICS},
                  "flagged": sum(r["verdict"] == "inconsistent" for r in rs), "n": len(rs)}
              for k, rs in table2.items()}
    joint = [r for r in ok if r["mode"] == "joint"]
    untouched = [r for r in joint if r["kind"] == "none"]
    manipulated = [r for r in joint if r["kind"] != "none"]
    totems = {}
    for r in joint:
        if r["kind"] == "none":
            totems.setdefault(r["n_totems"], []).append(_metric(r, "recon_L1"))
    stages = {}
    for r in joint:
        for k, v in (r.get("timing_s") or {}).items():
            if isinstance(v, (int, float)) and (k in ("fit", "verify") or k.endswith("_s")
                                                  or "_s_" in k):   # times, not counts
                stages.setdefault(k, []).append(v)
    return {
        "table1": table1, "table2": table2,
        "accuracy": {
            "untouched_consistent": _frac(r["verdict"] == "consistent" for r in untouched),
            "manipulated_inconsistent": _frac(r["verdict"] == "inconsistent"
                                              for r in manipulated),
            "unverifiable": _frac(r["verdict"] == "unverifiable" for r in joint),
            "n_untouched": len(untouched), "n_manipulated": len(manipulated)},
        "totems_study": {int(n): _mean(v) for n, v in sorted(totems.items())},
        "time_per_stage_s": {k: _mean(v) for k, v in stages.items()},
        "failed": [{"scene": r["name"], "mode": r["mode"], "error": r.get("error")}
                   for r in runs if r["status"] != "ok"],
    }


def _frac(flags):
    flags = list(flags)
    return float(np.mean(flags)) if flags else None


def _fmt(x, digits=3):
    return "–" if x is None else f"{x:.{digits}f}"


def markdown(bench: dict) -> str:
    """The tables of ``bench.md``: ours beside the paper's."""
    s = bench["summary"]
    lines = ["# totems bench\n",
             f"{bench['scenes']} scenes, {len(bench['runs'])} runs "
             f"({bench.get('fits', len(bench['runs']))} fits; a copy edited outside the "
             f"totems reuses its original's fit), {bench['jobs']} jobs, "
             f"{bench['wall_s']:.0f} s wall.\n",
             *([f"{bench['reverified']} fits were an earlier bench's, verified again "
                f"(`--reverify`): their times are those of that bench.\n"]
               if bench.get("reverified") else []),
             *([f"{bench['resumed']} runs were an earlier bench's in this folder, read "
                f"back: their times are that bench's.\n"] if bench.get("resumed") else []),
             "## Table 1: camera-view reconstruction and pose (untouched scenes)\n",
             "| preset | totem pose | recon L1 | paper | pose L1 (m) | paper | n |",
             "|---|---|---|---|---|---|---|"]
    for preset, modes in sorted(s["table1"].items()):
        for mode in ("initial", "joint", "oracle"):
            if mode not in modes:
                continue
            m = modes[mode]
            paper = PAPER_TABLE1.get(preset, {}).get(mode, (None, None))
            lines.append(f"| {preset} | {mode} | {_fmt(m['recon_L1'])} | {_fmt(paper[0])} "
                         f"| {_fmt(m['pose_L1'])} | {_fmt(paper[1])} | {m['n']} |")
    ours = [name for name in METRICS if name not in ("L1", "SSIM")]   # no paper figure
    lines += ["", "## Table 2: patch AP per manipulation (joint fit)\n",
              "| kind | AP (L1) | paper L1 | AP (SSIM) | paper LPIPS | "
              + "".join(f"AP ({name}) | " for name in ours) + "flagged | n |",
              "|" + "---|" * (7 + len(ours))]
    for kind, m in sorted(s["table2"].items()):
        paper = PAPER_TABLE2.get(kind, (None, None))
        lines.append(f"| {kind} | {_fmt(m['ap_L1'])} | {_fmt(paper[0])} | "
                     f"{_fmt(m['ap_SSIM'])} | {_fmt(paper[1])} | "
                     + "".join(f"{_fmt(m.get(f'ap_{name}'))} | " for name in ours)
                     + f"{m.get('flagged', '–')} | {m['n']} |")
    a = s["accuracy"]
    lines += ["", "## Image level\n",
              f"- untouched judged consistent: {_fmt(a['untouched_consistent'], 2)} "
              f"(n = {a['n_untouched']})",
              f"- manipulated judged inconsistent: {_fmt(a['manipulated_inconsistent'], 2)} "
              f"(n = {a['n_manipulated']})",
              f"- unverifiable (untouched and manipulated): "
              f"{_fmt(a.get('unverifiable'), 2)}"]
    if len(s["totems_study"]) > 1:
        lines += ["", "## Number of totems (recon L1)\n", "| totems | ours | paper |",
                  "|---|---|---|"]
        lines += [f"| {n} | {_fmt(v)} | {_fmt(PAPER_TOTEMS.get(n))} |"
                  for n, v in s["totems_study"].items()]
    if s["time_per_stage_s"]:
        lines += ["", "## Time per stage (s, mean over joint runs)\n"]
        lines += [f"- {k}: {_fmt(v, 1)}" for k, v in sorted(s["time_per_stage_s"].items())]
    if s["failed"]:
        lines += ["", "## Failed runs\n"]
        lines += [f"- {f['scene']} ({f['mode']}): {f['error']}" for f in s["failed"]]
    return "\n".join(lines) + "\n"


CSV_FIELDS = ["name", "preset", "placement", "kind", "n_totems", "mode", "status", "verdict",
              "score", "threshold", *(f"score_{m}" for m in THRESHOLDS), "recon_L1", "pose_L1",
              "judged_fraction", "manip_judged", "holdout_L1", "unverifiable_reason",
              "inconsistent_reasons", "totems_named", "totem_lead",
              *(f"patch_ap_{m}" for m in METRICS), "wall_s", "fit_from", "error",
              *(m for m in TRUTH_METRICS if m not in ("recon_L1", "pose_L1"))]


def csv_text(runs: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for r in runs:
        scores = {f"score_{m}": v.get("score") for m, v in (r.get("scores") or {}).items()}
        held = {"holdout_L1": (r.get("holdout") or {}).get("L1")}
        w.writerow({**r, **(r.get("metrics") or {}), **scores, **held, **_totem_columns(r)})
    return buf.getvalue()


def _totem_columns(run: dict) -> dict:
    """bench.csv's columns of the totem check: ``inconsistent_reasons`` and
    ``totems_named`` joined by ";" (totem indices, 0 the leftmost), ``totem_lead`` the
    largest lead (empty when the check did not run)."""
    check = run.get("totem_check") or {}
    leads = [t["lead"] for t in check.get("totems") or [] if t.get("lead") is not None]
    return {"inconsistent_reasons": ";".join(run.get("inconsistent_reasons") or []),
            "totems_named": ";".join(str(j) for j in check.get("named") or []),
            "totem_lead": max(leads) if leads else None}


def write_outputs(bench: dict, out: Path) -> None:
    """bench.json, bench.csv, bench.md, plots/ and bench.html (last) in ``out``."""
    from verify.report import html_report

    md = markdown(bench)
    folder.write_json(out / "bench.json", bench)
    folder.write_bytes(out / "bench.csv", csv_text(bench["runs"]).encode())
    folder.write_bytes(out / "bench.md", md.encode())
    plots = write_plots(bench["summary"], out / "plots")
    folder.write_bytes(out / "bench.html", html_report.render_bench(md, plots).encode())


def write_plots(summary: dict, out: Path) -> dict:
    """AP per kind, recon L1 per preset and mode, time per stage, the totem study.

    Returns {file name: PNG bytes} of the plots written (those with data)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = {}

    def save(fig, name):
        buf = io.BytesIO()
        fig.tight_layout()
        fig.savefig(buf, format="png", dpi=100)
        plt.close(fig)
        written[name] = buf.getvalue()
        folder.write_bytes(out / name, written[name])

    t2 = summary["table2"]
    if t2:
        kinds = sorted(t2)
        x = np.arange(len(kinds))
        fig, ax = plt.subplots(figsize=(8, 3))
        bar = 0.8 / len(METRICS)
        offset = [bar * (i - (len(METRICS) - 1) / 2) for i in range(len(METRICS))]
        for i, name in enumerate(METRICS):
            ax.bar(x + offset[i], [t2[k].get(f"ap_{name}") or 0 for k in kinds], bar,
                   label=name)
        paper = [(i, PAPER_TABLE2[k][0]) for i, k in enumerate(kinds) if k in PAPER_TABLE2]
        if paper:
            ax.plot([i + offset[0] for i, _ in paper], [v for _, v in paper], "k_", ms=14,
                    mew=2, label="paper (L1)")
        ax.set_xticks(x, kinds)
        ax.set_ylim(0, 1)
        ax.set_ylabel("patch AP")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
        save(fig, "ap_per_kind.png")
    t1 = summary["table1"]
    if t1:
        fig, ax = plt.subplots(figsize=(6, 3))
        labels, values = [], []
        for p, modes in sorted(t1.items()):
            for m, v in modes.items():
                labels.append(f"{p}\n{m}")
                values.append(v["recon_L1"] or 0)
        ax.bar(range(len(values)), values)
        ax.set_xticks(range(len(values)), labels, fontsize=8)
        ax.set_ylabel("recon L1")
        save(fig, "recon_per_preset.png")
    stages = summary["time_per_stage_s"]
    if stages:
        fig, ax = plt.subplots(figsize=(6, 3))
        ax.barh(list(stages), [v or 0 for v in stages.values()])
        ax.set_xlabel("seconds")
        save(fig, "time_per_stage.png")
    study = summary["totems_study"]
    if len(study) > 1:
        fig, ax = plt.subplots(figsize=(4, 3))
        ax.plot(list(study), list(study.values()), "o-", label="ours")
        paper = [n for n in study if n in PAPER_TOTEMS]
        ax.plot(paper, [PAPER_TOTEMS[n] for n in paper], "s--", label="paper")
        ax.set_xlabel("number of totems")
        ax.set_ylabel("recon L1")
        ax.legend()
        save(fig, "totems_study.png")
    return written
