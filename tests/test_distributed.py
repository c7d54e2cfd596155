"""Batches on Dask (``verify/batch/batch.py``, ``verify/batch/runs.py``,
``verify/batch/checks.py``): ``totems check SCENE...`` gives each photo the verdict ``totems
check SCENE`` gives it, records a photo that fails and finishes the others (exit 2), resumes
without running a finished photo again, and refuses workers that run other code, in one
line."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from scenes.errors import BadInput
from scenes.synthetic.make import make_scene
from scenes.tamper.tamper import tamper
from test_cli import tiny_scene, totems
from verify.batch import batch
from verify.batch.checks import photo_line, unique_names


# --------------------------------------------------------------------------- no cluster

def _answer(version="0.1.0", source="abc", host="h", cpus=2, missing=0):
    return {"version": version, "source": source, "host": host, "cpus": cpus,
            "missing": missing, "first_missing": ["/x/y"] if missing else []}


def test_a_worker_with_other_code_or_paths_is_refused_in_one_line():
    same = {"tcp://a:1": _answer(), "tcp://b:1": _answer()}
    batch.compare_workers(same, mine=("0.1.0", "abc"), n_paths=3)
    for other, words in ((_answer(source="def"), "source def"),
                         (_answer(version="0.2.0"), "totems 0.2.0"),
                         (_answer(missing=2), "does not see 2 of the 3 paths")):
        with pytest.raises(BadInput) as exc:
            batch.compare_workers({**same, "tcp://b:1": other}, mine=("0.1.0", "abc"),
                                  n_paths=3)
        assert words in str(exc.value) and "tcp://b:1" in str(exc.value)
        assert "\n" not in str(exc.value)


def test_runs_share_their_host_cores():
    two = {"tcp://a:1": _answer(cpus=8), "tcp://a:2": _answer(cpus=8),
           "tcp://b:1": _answer(host="b", cpus=8)}
    shares = batch.thread_shares(two, {"tcp://a:1": 1, "tcp://a:2": 1, "tcp://b:1": 2})
    assert shares == {"tcp://a:1": 4, "tcp://a:2": 4, "tcp://b:1": 4}
    assert batch.thread_shares({"tcp://a:1": _answer(cpus=2)}, {"tcp://a:1": 4}) == {
        "tcp://a:1": 1}                       # never 0


def test_tls_files_need_a_tls_scheduler(tmp_path):
    assert batch.tls_security(None, (None, None, None)) is None
    with pytest.raises(BadInput, match="tls://"):
        batch.tls_security("tcp://h:8786", (None, "c.pem", "k.pem"))
    with pytest.raises(BadInput, match="no such TLS file"):
        batch.tls_security("tls://h:8786", (str(tmp_path / "ca.pem"), None, None))


def test_names_stay_unique_and_lines_say_what_happened(tmp_path):
    paths = [tmp_path / "a" / "box-1", tmp_path / "b" / "box-1", tmp_path / "box-2"]
    assert unique_names(paths) == ["box-1", "box-1-2", "box-2"]
    ok = {"name": "p", "status": "ok", "verdict": "inconsistent", "score": 2.5,
          "threshold": 1.0, "p_value": 0.001, "fit_from": "q", "resumed": True}
    assert photo_line(ok) == "p: inconsistent, score 2.50 of 1.00, p = 0.001; fit of q " \
                             "(resumed)"
    assert photo_line({"name": "p", "status": "failed", "error": "bad key"}) == \
        "p: could not be checked: bad key"
    named = dict(ok, fit_from=None, resumed=False,
                 totem_check={"named": [2], "totems": []})
    assert photo_line(named) == ("p: inconsistent, score 2.50 of 1.00, p = 0.001; totem 3 "
                                 "from the left disagrees with the other totems")


def test_a_missing_folder_is_refused_before_anything_runs(tmp_path):
    tiny_scene(tmp_path / "a")
    proc = totems("check", tmp_path / "a", tmp_path / "nope", "--out", tmp_path / "out")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "no such folder" in proc.stderr and not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- a cluster

def test_a_worker_running_another_version_is_refused(tmp_path, monkeypatch, capsys):
    from verify.cli.commands import main

    scenes = [tiny_scene(tmp_path / "a"), tiny_scene(tmp_path / "b")]
    monkeypatch.setattr(batch, "package_version", lambda: "9.9.9")   # this client only
    code = main(["check", *map(str, scenes), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "this client totems 9.9.9" in err and "Traceback" not in err
    assert not list((tmp_path / "out").glob("runs/*"))        # nothing ran


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    """Three folders: a photo, its colour edit (which reuses the photo's fit) and a
    copy with a broken key; checked as a batch on a two-worker LocalCluster."""
    root = tmp_path_factory.mktemp("batch")
    photo = make_scene(root / "env-1", preset="envmap", seed=1, size=(64, 48), spp=4)
    edit = tamper(photo, root / "env-1-color", kind="color", seed=1,
                  region=_away_from_the_totems(photo))
    broken = root / "env-1-broken"
    shutil.copytree(photo, broken)
    (broken / "totems.json").write_text(json.dumps({"radius": -0.1, "ior": 1.52}))
    out = root / "out"
    args = ("check", photo, edit, broken, "--out", out, "--jobs", "2")
    return {"root": root, "scenes": (photo, edit, broken), "out": out, "args": args,
            "proc": totems(*args)}


def _away_from_the_totems(scene_dir, side=8):
    """(x, y, w, h) of a square outside the band the fit reads around the totem masks
    (so the edit shares the photo's fit)."""
    from scipy.ndimage import binary_dilation

    from inverse.pose.rim import READ_PX
    from scenes import folder

    masks = folder.read_scene(scene_dir).masks.any(0)
    read = binary_dilation(masks, iterations=READ_PX)
    H, W = read.shape
    for y in range(0, H - side + 1):
        for x in range(0, W - side + 1):
            if not read[y:y + side, x:x + side].any():
                return (x, y, side, side)
    raise AssertionError("no room for an edit away from the totems")


@pytest.mark.slow
def test_a_failing_photo_is_recorded_and_the_others_finish(batch_run):
    proc, out = batch_run["proc"], batch_run["out"]
    assert proc.returncode == 2, proc.stderr
    lines = proc.stdout.splitlines()
    assert sorted(line.split(":")[0] for line in lines[:3]) == [
        "env-1", "env-1-broken", "env-1-color"]           # one line a photo, as it ends
    assert "env-1-broken: could not be checked:" in proc.stdout and "radius" in proc.stdout
    assert lines[-2].startswith("3 photos:") and "1 could not be checked" in lines[-2]
    index = json.loads((out / "index.json").read_text())
    photos = {p["name"]: p for p in index["photos"]}
    assert [p["name"] for p in index["photos"]] == ["env-1", "env-1-color", "env-1-broken"]
    assert photos["env-1-broken"]["status"] == "failed" and index["exit_code"] == 2
    assert photos["env-1-color"]["fit_from"] == "env-1"
    assert not (out / "runs" / "env-1-color" / "fit").exists()     # it fitted nothing
    for name in ("env-1", "env-1-color"):
        p = photos[name]
        assert p["status"] == "ok" and p["verdict"] in ("consistent", "inconsistent",
                                                        "unverifiable")
        assert (out / p["report"]).is_file()
        if p["html"]:
            assert f'href="{p["html"]}"' in (out / "index.html").read_text()
    html = (out / "index.html").read_text()
    assert "env-1-broken" in html and str(batch_run["root"]) not in html  # no abs. path


@pytest.mark.slow
def test_the_batch_gives_each_photo_the_verdict_of_the_old_path(batch_run, tmp_path):
    """The old path, one process a photo as bench ran them: check the photo, then
    verify its edit on that fit. Each run of the batch had its share of the cores; with
    the same threads it is the same computation (exactly so single-threaded, as on two
    cores)."""
    share = max(1, len(os.sched_getaffinity(0)) // 2)
    env = {**os.environ, "TOTEMS_THREADS": str(share), "OMP_NUM_THREADS": str(share)}
    tol = 1e-6 if share == 1 else 0.02
    photo, edit = batch_run["scenes"][:2]
    old = {}
    for scene, verb in ((photo, ["check"]), (edit, ["verify", "--fit", tmp_path / "fit"])):
        proc = subprocess.run([sys.executable, "-m", "verify.cli", *map(str, verb),
                               str(scene), "--out", str(tmp_path), "--json", "--quiet"],
                              capture_output=True, text=True, env=env, timeout=300)
        assert proc.returncode in (0, 1, 4), proc.stderr    # 64x48: maybe unverifiable
        old[scene.name] = json.loads(proc.stdout)
    index = json.loads((batch_run["out"] / "index.json").read_text())
    for batched in index["photos"][:2]:
        alone = old[batched["name"]]
        assert batched["verdict"] == alone["verdict"]
        for key in ("score", "p_value"):
            assert batched[key] == pytest.approx(alone[key], rel=tol, abs=tol)


@pytest.mark.slow
def test_a_batch_run_again_reads_back_what_it_finished(batch_run):
    out = batch_run["out"]
    fit_json = out / "runs" / "env-1" / "fit" / "fit.json"
    report = out / "runs" / "env-1-color" / "verify" / "report.json"
    before = {f: f.stat().st_mtime_ns for f in (fit_json, report)}
    first = json.loads((out / "index.json").read_text())
    proc = totems(*batch_run["args"])
    assert proc.returncode == 2, proc.stderr
    again = json.loads((out / "index.json").read_text())
    assert again["resumed"] == 2 and "(resumed)" in proc.stdout
    assert {f: f.stat().st_mtime_ns for f in (fit_json, report)} == before   # not rerun
    strip = ("resumed", "wall_s")
    assert [{k: v for k, v in p.items() if k not in strip} for p in again["photos"]] == \
        [{k: v for k, v in p.items() if k not in strip} for p in first["photos"]]
    assert again["photos"][2]["status"] == "failed"            # a failure runs again
