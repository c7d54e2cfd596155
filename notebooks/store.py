"""Run the notebooks top to bottom and store them with their outputs (``make notebooks``).

    python notebooks/store.py [NOTEBOOK.ipynb ...] [--small] [--out DIR]

Each notebook runs in a fresh kernel in this folder, at the real size (640x480) unless
``--small`` (``TOTEMS_NOTEBOOK_SIZE=small``, what the tests run). Its outputs are then
cleaned for a repository: stderr streams dropped (warnings, progress bars), widget
outputs dropped, pictures re-encoded as palette PNGs, execution counts 1..n, the run's
timestamps taken out of the cell metadata. A notebook is written only when every cell
ran without error and its outputs name no machine path; it replaces the stored file
atomically (``--out DIR`` writes there instead, for a look before storing).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SIZE_ENV = "TOTEMS_NOTEBOOK_SIZE"
"""The environment variable the notebooks read: ``small`` (240x180, the tests) or
``full`` (640x480, the default)."""

MAX_PICTURE_SIDE = 1400         # px: wider pictures are scaled down
PALETTE = 256                    # colours: pictures are stored as palette PNGs
TIMEOUT_S = 3600                 # per cell: a real-size cell may fit several photos
MACHINE_PATH = re.compile(r"(/work/|/root/|/tmp/|/home/)")
PROGRESS = re.compile(r"\d+%\|[^|]*\||\d+it/s|\ds/it")

__all__ = ["SIZE_ENV", "notebooks", "execute", "small_png", "clean", "problems", "store"]


def notebooks() -> list[Path]:
    """The notebooks of this folder, in order."""
    return sorted(HERE.glob("[0-9][0-9]_*.ipynb"))


def execute(nb, *, small: bool, timeout: float = TIMEOUT_S):
    """Run ``nb`` (an nbformat notebook, changed in place) top to bottom in a fresh
    kernel at the small or the real size, in this folder as Jupyter would (the notebooks
    read ``data/`` and write only to temporary folders of their own)."""
    from nbclient import NotebookClient

    saved = {k: os.environ.get(k) for k in (SIZE_ENV, "MPLBACKEND")}
    os.environ[SIZE_ENV] = "small" if small else "full"
    os.environ.pop("MPLBACKEND", None)        # Agg would keep the figures out of the outputs
    try:
        NotebookClient(nb, timeout=timeout, kernel_name="python3",
                       resources={"metadata": {"path": str(HERE)}}).execute()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def small_png(data: str) -> str:
    """A base64 PNG as a palette PNG of at most ``PALETTE`` colours and
    ``MAX_PICTURE_SIDE`` px (about a fifth of the bytes of a photo-filled figure)."""
    import base64
    import io

    from PIL import Image

    im = Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB")
    if max(im.size) > MAX_PICTURE_SIDE:
        f = MAX_PICTURE_SIDE / max(im.size)
        im = im.resize((round(im.size[0] * f), round(im.size[1] * f)), Image.LANCZOS)
    buf = io.BytesIO()
    im.quantize(PALETTE, method=Image.Quantize.FASTOCTREE).save(buf, "PNG", optimize=True)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def clean(nb):
    """Outputs fit for a repository (changed in place): no stderr streams or widgets,
    pictures as small palette PNGs, execution counts 1..n, no run timestamps in the
    metadata."""
    count = 0
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
        if cell.cell_type != "code":
            continue
        count += 1
        cell.execution_count = count
        kept = []
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream" and out.get("name") == "stderr":
                continue
            data = out.get("data", {})
            if "application/vnd.jupyter.widget-view+json" in data:
                continue
            if "image/png" in data:
                data["image/png"] = small_png(data["image/png"])
            if "execution_count" in out:
                out["execution_count"] = count
            kept.append(out)
        cell.outputs = kept
    nb.metadata.pop("widgets", None)
    return nb


def _text(out) -> str:
    if out.get("output_type") == "stream":
        return out.get("text", "")
    if out.get("output_type") == "error":
        return "\n".join(out.get("traceback", []))
    return "\n".join(v if isinstance(v, str) else "".join(v)
                     for k, v in out.get("data", {}).items() if k.startswith("text/"))


def problems(nb) -> list[str]:
    """What keeps a run notebook from being stored (empty: nothing): error outputs,
    code cells without output, machine paths or progress bars in the outputs, no
    picture."""
    found, pictures = [], 0
    for i, cell in enumerate(c for c in nb.cells if c.cell_type == "code"):
        outs = cell.get("outputs", [])
        if not outs:
            found.append(f"code cell {i + 1} has no output")
        for out in outs:
            if out.get("output_type") == "error":
                found.append(f"code cell {i + 1}: {out.get('ename')}: {out.get('evalue')}")
            pictures += "image/png" in out.get("data", {})
            text = _text(out)
            if MACHINE_PATH.search(text):
                found.append(f"code cell {i + 1} shows a machine path: "
                             f"{MACHINE_PATH.search(text).group(0)}...")
            if PROGRESS.search(text):
                found.append(f"code cell {i + 1} shows a progress bar")
    if not pictures:
        found.append("no picture (image/png) in the outputs")
    return found


def store(path: Path, *, small: bool = False, out_dir: Path | None = None) -> tuple[float, int]:
    """Run, clean and write one notebook; (seconds, bytes written). Raises RuntimeError
    (the stored file untouched) when a cell failed or an output would not be stored."""
    import nbformat
    from nbclient.exceptions import CellExecutionError

    nb = nbformat.read(path, as_version=4)
    t0 = time.perf_counter()
    try:
        execute(nb, small=small)
    except CellExecutionError as exc:
        raise RuntimeError(f"{path.name}: a cell failed:\n{exc}") from None
    seconds = time.perf_counter() - t0
    clean(nb)
    bad = problems(nb)
    if bad:
        raise RuntimeError(f"{path.name} not stored: " + "; ".join(bad))
    target = (out_dir or path.parent) / path.name
    target.parent.mkdir(parents=True, exist_ok=True)
    text = nbformat.writes(nb) + "\n"
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return seconds, len(text.encode())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("notebooks", nargs="*", type=Path,
                    help="notebooks to run (default: every NN_*.ipynb here)")
    ap.add_argument("--small", action="store_true",
                    help=f"{SIZE_ENV}=small: 240x180, quick (what the tests run)")
    ap.add_argument("--out", type=Path, help="write here instead of over the stored files")
    args = ap.parse_args(argv)
    failed = 0
    for path in args.notebooks or notebooks():
        try:
            seconds, size = store(Path(path), small=args.small, out_dir=args.out)
        except RuntimeError as exc:
            print(exc, file=sys.stderr)
            failed += 1
            continue
        print(f"{Path(path).name}: {seconds:.0f} s, {size / 1024:.0f} KiB", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
