"""Draw the pictures of docs/your-own-photo.md from notebook 05.

    python docs/own_photo_pictures.py [--report]

The notebook's stored outputs hold its figures as PNGs; each is written to
``docs/own_photo_<name>.png`` as it is (no run needed). ``--report`` also runs the
notebook's code once (about a minute at 640x480) and screenshots the case's
``report.html`` with a headless Chromium into ``docs/own_photo_report.png``.
"""
import argparse
import base64
import io
import json
import subprocess
import tempfile
from pathlib import Path

from PIL import Image

DOCS = Path(__file__).resolve().parent
NOTEBOOK = DOCS.parent / "notebooks" / "05_your_own_photos.ipynb"
NAMES = {"find_corners": "checkerboard", "ingest(": "ingest", "write_masks": "masks",
         "verify_scene": "check"}
"""Each code cell's picture is named by the call it shows."""
MAX_BYTES = 200_000
MAX_WIDTH = 800


def _save(png: bytes, out: Path) -> None:
    """Write ``png``; a picture over MAX_BYTES is stored at most MAX_WIDTH wide as a
    palette PNG."""
    img = Image.open(io.BytesIO(png))
    if len(png) > MAX_BYTES:
        img = img.convert("RGB")
        if img.width > MAX_WIDTH:
            img = img.resize((MAX_WIDTH, round(img.height * MAX_WIDTH / img.width)),
                             Image.LANCZOS)
        buf = io.BytesIO()
        img.quantize(128).save(buf, "PNG", optimize=True)
        png = buf.getvalue()
    out.write_bytes(png)
    print(f"{out.name}: {img.size[0]}x{img.size[1]}, {len(png) // 1000} kB")


def stored_pictures(nb: dict) -> None:
    for cell in nb["cells"]:
        source = "".join(cell["source"])
        name = next((n for call, n in NAMES.items() if call in source), None)
        pngs = [o["data"]["image/png"] for o in cell.get("outputs", [])
                if "image/png" in o.get("data", {})]
        if cell["cell_type"] == "code" and name and pngs:
            _save(base64.b64decode(pngs[0]), DOCS / f"own_photo_{name}.png")


def report_picture(nb: dict) -> None:
    """Run the notebook's code (its scratch folder lives as long as ``env``), then
    screenshot the ``report.html`` it wrote."""
    import matplotlib
    matplotlib.use("Agg")
    env: dict = {}
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), "notebook 05", "exec"), env)
    verify = env["work"] / "IMG_0001-out" / "verify"
    with tempfile.TemporaryDirectory() as tmp:
        shot = Path(tmp) / "shot.png"
        subprocess.run(["chromium", "--headless", "--no-sandbox", "--hide-scrollbars",
                        "--window-size=1000,1400", f"--screenshot={shot}",
                        (verify / "report.html").as_uri()],
                       check=True, capture_output=True, timeout=120)
        _save(shot.read_bytes(), DOCS / "own_photo_report.png")
    r = json.loads((verify / "report.json").read_text())
    print(f"report: {r['verdict']}, score {r['score']:.2f}, p = {r['p_value']}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--report", action="store_true",
                    help="also run the notebook's case and screenshot its report.html")
    args = ap.parse_args()
    nb = json.loads(NOTEBOOK.read_text())
    stored_pictures(nb)
    if args.report:
        report_picture(nb)


if __name__ == "__main__":
    main()
