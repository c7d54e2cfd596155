"""Batches of photos on Dask's distributed scheduler: the engine of ``bench`` and of
``check DIR...``.

The client sends each photo's command (``totems check ... --json --quiet``, or
``totems verify --fit`` on another photo's fit) to a worker, which runs it in a
subprocess of its own (:func:`run_job`): a native crash of the backend fails that photo,
never the worker. Without a scheduler address the cluster is a ``LocalCluster`` here,
one single-threaded worker process per job; with one, an existing cluster whose workers
must see the scene folders and the output folder at the same paths as the client and
run the same totems (checked at start, :meth:`Engine.preflight`).

Each run's Dr.Jit and OpenMP thread counts are the worker host's cores shared among the
worker threads on that host (``TOTEMS_THREADS`` in a worker's environment wins), so two
runs do not fight over the cores.

The order of the runs and resuming are :mod:`verify.batch.runs`'s.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import socket
import subprocess
import sys
import time
import uuid
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from scenes.errors import BadInput

__all__ = ["PACKAGES", "package_version", "source_hash", "probe", "compare_workers",
           "thread_shares", "VERDICT_CODES", "run_job", "tls_security", "Engine"]

PACKAGES = ("inverse", "scenes", "verify")
"""The project's packages, whose files :func:`source_hash` covers."""

SOURCE_SUFFIXES = {".py", ".json", ".html"}

CONNECT_TIMEOUT_S = 20
"""How long to wait for a scheduler, and for its first worker."""


# --------------------------------------------------------------------------- both sides

def package_version() -> str:
    """The installed totems version ("unknown" when it is not installed)."""
    try:
        return version("totems")
    except PackageNotFoundError:
        return "unknown"


def source_hash() -> str:
    """16 hex of sha256 over the packages' source files (path and bytes, sorted): two
    installs with one hash run the same code, whatever their version says."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for f in sorted((root / pkg).rglob("*")):
            if f.suffix in SOURCE_SUFFIXES and "__pycache__" not in f.parts and f.is_file():
                h.update(f.relative_to(root).as_posix().encode() + b"\0")
                h.update(f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                      # not Linux
        return os.cpu_count() or 1


def probe(paths: list[str]) -> dict:
    """What a worker runs at the start of a batch (``client.run``): its totems, its
    host and cores, and which of ``paths`` it cannot see."""
    missing = [p for p in paths if not os.path.exists(p)]
    return {"version": package_version(), "source": source_hash(),
            "host": socket.gethostname(), "cpus": _cpus(),
            "missing": len(missing), "first_missing": missing[:1]}


def compare_workers(answers: dict, *, mine: tuple[str, str], n_paths: int) -> None:
    """Refuse (``BadInput``, one line) a worker that runs other code than ``mine``
    (version, source hash) or misses any of the paths it was asked about."""
    for addr, a in sorted(answers.items()):
        theirs = (a["version"], a["source"])
        if theirs != mine:
            raise BadInput(f"the Dask worker {addr} runs totems {theirs[0]} (source "
                           f"{theirs[1]}), this client totems {mine[0]} (source {mine[1]}): "
                           f"install the same totems on every worker")
        if a["missing"]:
            raise BadInput(f"the Dask worker {addr} does not see {a['missing']} of the "
                           f"{n_paths} paths of this batch (e.g. {a['first_missing'][0]}): "
                           f"the scene folders and --out must be on a filesystem every "
                           f"worker mounts at the same paths")


def thread_shares(answers: dict, nthreads: dict) -> dict[str, int]:
    """Threads each run may use, per worker address: its host's cores over the worker
    threads (runs at once) on that host."""
    per_host: dict[str, int] = {}
    for addr, a in answers.items():
        per_host[a["host"]] = per_host.get(a["host"], 0) + nthreads.get(addr, 1)
    return {addr: max(1, a["cpus"] // max(1, per_host[a["host"]]))
            for addr, a in answers.items()}


# --------------------------------------------------------------------------- worker side

def _worker_address() -> str | None:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return None


def _death_signal():
    """A function for the child, before exec, that ends it when the worker that started
    it dies (Linux ``PR_SET_PDEATHSIG``), so that a stopped batch leaves no photo
    running; None elsewhere. Looked up here, in the parent: the child only calls it."""
    if sys.platform != "linux":
        return None
    try:
        import ctypes
        import signal

        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    return lambda: prctl(1, signal.SIGTERM)              # 1: PR_SET_PDEATHSIG


def _env(threads: dict[str, int]) -> dict:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    share = os.environ.get("TOTEMS_THREADS") or threads.get(_worker_address() or "")
    if share:
        env["TOTEMS_THREADS"] = env["OMP_NUM_THREADS"] = str(share)
    return env


VERDICT_CODES = (0, 1, 4)
"""Exit codes of a check that gave a verdict (consistent, inconsistent, unverifiable)."""


def run_job(argv: list[str], timeout: float, threads: dict[str, int],
            folder: str | None = None, source: str = "") -> dict:
    """Run ``totems ARGV`` (with ``--json``) in a fresh process; never raises.

    Returns {"status": "ok", "wall_s", the command's JSON summary...} when it exits 0,
    1 or 4 (a verdict), and then writes ``folder``/run.json (the command, ``source``, the wall time:
    what resuming reads, :mod:`verify.batch.runs`), here, so that a run whose client has
    gone still counts; else {"status": "failed", "error" (its last stderr line),
    "exit_code", "wall_s"}.
    """
    cmd = [sys.executable, "-m", "verify.cli", *argv]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              env=_env(threads), preexec_fn=_death_signal())
    except subprocess.TimeoutExpired:
        return {"status": "failed", "error": f"timed out after {timeout:.0f} s"}
    wall = time.perf_counter() - t0
    if proc.returncode in VERDICT_CODES:
        try:
            summary = json.loads(proc.stdout.strip().splitlines()[-1])
        except (ValueError, IndexError):
            return {"status": "failed", "error": "check printed no JSON summary",
                    "wall_s": wall}
        if folder:
            _write_run_json(Path(folder), argv, source, wall)
        return {"status": "ok", "wall_s": wall, **summary}
    err = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
    return {"status": "failed", "error": err, "exit_code": proc.returncode, "wall_s": wall}


def _write_run_json(folder: Path, argv: list[str], source: str, wall: float) -> None:
    from scenes.folder import write_json

    try:
        write_json(folder / "run.json", {"format": 1, "argv": argv, "source": source,
                                         "wall_s": wall})
    except OSError:              # no run.json: the run is simply not resumed
        pass


# --------------------------------------------------------------------------- client side

def tls_security(address: str | None, tls: tuple | None):
    """``distributed.Security`` from ``(ca_file, cert, key)``, or None: Dask's own
    configuration (``distributed.comm.tls.*``) then applies to a ``tls://`` address."""
    if not tls or not any(tls):
        return None
    if not (address or "").startswith("tls://"):
        raise BadInput("--tls-ca-file, --tls-cert and --tls-key need a tls:// --scheduler")
    for path in tls:
        if path and not Path(path).is_file():
            raise BadInput(f"no such TLS file: {path}")
    from distributed import Security

    ca, cert, key = tls
    return Security(tls_ca_file=ca, tls_client_cert=cert, tls_client_key=key,
                    require_encryption=True)


class Engine:
    """A Dask client for one batch: a ``LocalCluster`` of ``jobs`` single-threaded
    worker processes (its HTTP server on a free port: 8787 may be another cluster's), or
    the cluster at ``scheduler``. Use as a context manager, then
    :meth:`preflight` before :meth:`submit`."""

    def __init__(self, *, scheduler: str | None = None, jobs: int = 1, tls=None,
                 timeout: float = 3600):
        self.scheduler, self.jobs, self.timeout = scheduler, max(1, jobs), timeout
        self.security = tls_security(scheduler, tls)
        self.client = self.cluster = None
        self.threads: dict[str, int] = {}
        self.slots = self.jobs
        self.source = source_hash()

    def __enter__(self) -> Engine:
        import dask
        from distributed import Client, LocalCluster

        logging.getLogger("distributed").setLevel(logging.ERROR)
        if self.scheduler is None:
            with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
                self.cluster = LocalCluster(n_workers=self.jobs, threads_per_worker=1,
                                            processes=True, dashboard_address=":0",
                                            silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
            return self
        try:
            self.client = Client(self.scheduler, security=self.security,
                                 timeout=f"{CONNECT_TIMEOUT_S}s")
            self.client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            self.__exit__(None, None, None)
            raise BadInput(f"cannot use the Dask scheduler at {self.scheduler}: "
                           f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
        return self

    def __exit__(self, *exc) -> None:
        for part in (self.client, self.cluster):
            if part is not None:
                part.close()
        self.client = self.cluster = None

    def preflight(self, paths: list[str], out: Path) -> None:
        """Refuse, in one line, a worker that runs other code than this client or that
        does not see ``paths`` and ``out`` (by a marker file written there) at the same
        paths; then set each worker's thread share."""
        out.mkdir(parents=True, exist_ok=True)
        marker = out / f".totems-batch-{uuid.uuid4().hex[:12]}"
        marker.write_text("a batch checks that every worker sees this folder\n")
        try:
            answers = self.client.run(probe, [*paths, str(marker.resolve())])
        except Exception as exc:        # a worker without totems cannot unpickle probe
            raise BadInput(f"a Dask worker cannot run totems' probe: "
                           f"{type(exc).__name__}: {' '.join(str(exc).split())}") from None
        finally:
            marker.unlink(missing_ok=True)
        compare_workers(answers, mine=(package_version(), self.source),
                        n_paths=len(paths) + 1)
        nthreads = self.client.nthreads()
        self.threads = thread_shares(answers, nthreads)
        self.slots = sum(nthreads.get(a, 1) for a in answers)

    def submit(self, argv: list[str], folder: Path):
        """A future of :func:`run_job` on ``argv``, recording to ``folder``; not
        retried."""
        return self.client.submit(run_job, argv, self.timeout, self.threads, str(folder),
                                  self.source, pure=False, retries=0,
                                  key=f"totems-{folder.name}-{uuid.uuid4().hex[:8]}")
