"""The notebooks: each runs top to bottom at the small size (into a copy, never over the
stored file), and each stored copy carries its outputs as `make notebooks` leaves them."""

import hashlib
import importlib.util
import json
import re
from pathlib import Path

import nbformat
import pytest

HERE = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(HERE.glob("[0-9][0-9]_*.ipynb"))
MAX_BYTES = 1_000_000
MACHINE_PATH = re.compile(r"/work/|/root/|/tmp/|/home/")
PROGRESS = re.compile(r"\d+%\|[^|]*\||\d+it/s|\ds/it|\r")


def _store():
    """notebooks/store.py, what `make notebooks` runs."""
    spec = importlib.util.spec_from_file_location("store", HERE / "store.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _code(nb):
    return [c for c in nb.cells if c.cell_type == "code"]


def _texts(cell):
    for out in cell.get("outputs", []):
        if out.get("output_type") == "stream":
            yield out.get("text", "")
        elif out.get("output_type") == "error":
            yield "\n".join(out.get("traceback", []))
        else:
            yield from (v if isinstance(v, str) else "".join(v)
                        for k, v in out.get("data", {}).items() if k.startswith("text/"))


def _pictures(nb) -> int:
    return sum("image/png" in out.get("data", {}) for c in _code(nb) for out in c.outputs)


def test_six_notebooks_each_opening_with_what_it_shows_and_its_time():
    assert [p.name[:3] for p in NOTEBOOKS] == ["01_", "02_", "03_", "04_", "05_", "06_"]
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        first, setup = nb.cells[0], _code(nb)[0]
        assert first.cell_type == "markdown" and first.source.startswith("# ")
        assert re.search(r"\*\*Time:\*\* about \d+(\.\d+)? (s|min) at 640x480", first.source), \
            f"{path.name}: the first cell says how long it takes at the real size"
        assert "TOTEMS_NOTEBOOK_SIZE" in first.source and "TOTEMS_NOTEBOOK_SIZE" in setup.source


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_stored_notebook_has_its_outputs(path):
    """As `make notebooks` stores them: every code cell with output, none an error,
    counts 1..n, a picture, no machine path or progress bar, under 1 MB."""
    assert path.stat().st_size < MAX_BYTES, f"{path.name} is {path.stat().st_size} bytes"
    nb = nbformat.read(path, as_version=4)
    code = _code(nb)
    assert [c.execution_count for c in code] == list(range(1, len(code) + 1))
    for i, cell in enumerate(code, 1):
        assert cell.outputs, f"{path.name}: code cell {i} has no output"
        for out in cell.outputs:
            assert out.get("output_type") != "error", f"{path.name}: cell {i} failed"
            assert not (out.get("output_type") == "stream" and out.get("name") == "stderr")
            if "execution_count" in out:
                assert out["execution_count"] == i
        for text in _texts(cell):
            assert not MACHINE_PATH.search(text), f"{path.name}: cell {i} shows a machine path"
            assert not PROGRESS.search(text), f"{path.name}: cell {i} shows a progress bar"
        assert "execution" not in cell.metadata          # no run timestamps
    assert _pictures(nb) >= 1


def test_clean_gives_what_is_stored():
    """store.clean on a notebook as nbclient leaves it: stderr and widgets dropped,
    counts renumbered, pictures as palette PNGs, timestamps gone."""
    import base64
    import io

    import numpy as np
    from PIL import Image

    store = _store()
    buf = io.BytesIO()
    rgb = np.random.default_rng(0).integers(0, 255, (60, 2000, 3), dtype=np.uint8)
    Image.fromarray(rgb).save(buf, "PNG")
    png = base64.b64encode(buf.getvalue()).decode()
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# t"),
                                         nbformat.v4.new_code_cell("a"),
                                         nbformat.v4.new_code_cell("b")])
    nb.cells[1].execution_count = 7
    nb.cells[1].metadata["execution"] = {"iopub.execute_input": "2026-12-02T12:00:00Z"}
    nb.cells[1].outputs = [
        nbformat.v4.new_output("stream", name="stderr", text="fit: 50%|#####| 1/2 [00:01]\r"),
        nbformat.v4.new_output("stream", name="stdout", text="ok\n"),
        nbformat.v4.new_output("display_data", data={
            "application/vnd.jupyter.widget-view+json": {"model_id": "x"}}),
        nbformat.v4.new_output("display_data", data={"image/png": png, "text/plain": "<F>"})]
    nb.cells[2].execution_count = 9
    nb.cells[2].outputs = [nbformat.v4.new_output("execute_result", data={"text/plain": "1"},
                                                  execution_count=9)]
    store.clean(nb)
    one, two = _code(nb)
    assert (one.execution_count, two.execution_count) == (1, 2)
    assert two.outputs[0]["execution_count"] == 2
    assert [o.output_type for o in one.outputs] == ["stream", "display_data"]
    assert "execution" not in one.metadata
    im = Image.open(io.BytesIO(base64.b64decode(one.outputs[1].data["image/png"])))
    assert im.mode == "P" and max(im.size) == store.MAX_PICTURE_SIDE
    assert store.problems(nb) == []
    nb.cells[2].outputs = []
    assert store.problems(nb) == ["code cell 2 has no output"]


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_at_the_small_size(path, tmp_path):
    """Top to bottom with TOTEMS_NOTEBOOK_SIZE=small into a copy; the stored file is
    never rewritten."""
    store = _store()
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    nb = nbformat.read(path, as_version=4)
    store.execute(nb, small=True)
    store.clean(nb)
    nbformat.write(nb, tmp_path / path.name)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
    assert store.problems(nb) == []                # no error, every cell shows, a picture
    assert json.loads((tmp_path / path.name).read_text())["cells"]
