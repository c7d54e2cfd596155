"""verify.report.html_report: report.html and bench.html are whole, self-contained pages
that say the verdict first and give away neither a path nor the key."""

import base64
import dataclasses
import io
import json
import os
import re
import shutil
from html.parser import HTMLParser

import numpy as np
import pytest

from scenes import folder
from verify.batch import bench
from verify.report import html_report, report
from verify.verdict import calibration
from verify_cases import (CENTERS, SQUARE, H, K, W, box_mask, make_fit, make_scene, texture,
                          with_square)

RADIUS_KEY, IOR_KEY = 0.0937, 1.5173          # distinctive digits, looked for below
KEY_TEXTS = ("0.0937", "0.09370", "9.37e-02", "1.5173", "1.51730", "1.517")
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta",
        "source", "track", "wbr"}


class Page(HTMLParser):
    """The tags of a page, checked for balance, and every URL-carrying attribute."""

    def __init__(self, text: str):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.tags, self.urls = [], [], [], []
        self.text = []
        self.feed(text)
        self.close()
        if self.stack:
            self.errors.append(f"unclosed {self.stack}")

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        for name in ("src", "href", "srcset", "poster", "action", "data"):
            if name in attrs:
                self.urls.append((tag, name, attrs[name] or ""))
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        self.handle_starttag(tag, attrs)
        if tag not in VOID:
            self.stack.pop()

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)

    def find(self, tag):
        return [a for t, a in self.tags if t == tag]

    @property
    def words(self) -> str:
        return " ".join(" ".join(self.text).split())


def self_contained(text: str) -> Page:
    """Parse ``text`` and check that it loads nothing: every URL is a data: picture."""
    page = Page(text)
    assert not page.errors, page.errors
    assert page.find("img"), "no picture"
    for tag, name, url in page.urls:
        assert url.startswith("data:image/"), f"<{tag} {name}={url[:60]}> is not embedded"
    assert not page.find("link") and not page.find("iframe")
    assert all("src" not in a for a in page.find("script"))
    assert not re.search(r"https?:|url\(|@import", text), "a network reference"
    csp = [a for a in page.find("meta") if a.get("http-equiv") == "Content-Security-Policy"]
    assert csp and "default-src 'none'" in csp[0]["content"]
    return page


def no_path(text: str, *paths) -> None:
    for p in ("/tmp", "/work", "/home", "/root", os.getcwd(), *map(str, paths)):
        assert p not in text, f"path {p} in the page"


def key_scene(path, image) -> folder.Scene:
    """The test scene with the key RADIUS_KEY, IOR_KEY (masks are its silhouettes)."""
    masks = np.stack([report.sphere_silhouette(c, RADIUS_KEY, K, (H, W)) for c in CENTERS])
    return folder.Scene(path, image, K, masks, np.full(2, RADIUS_KEY),
                        np.full(2, IOR_KEY), None, box_mask(SQUARE))


@pytest.fixture(scope="module")
def tampered(tmp_path_factory):
    """(scene, fit) of a photo with a red square the totems never saw."""
    photo = texture()
    root = tmp_path_factory.mktemp("scenes")
    return key_scene(root / "box-7-color", with_square(photo)), make_fit(photo)


@pytest.fixture(scope="module")
def written(tampered, tmp_path_factory):
    """(report.html text, report.json dict, out folder, call order of the writes)."""
    out = tmp_path_factory.mktemp("out") / "verify"
    rep = report.verify_scene(*tampered, calibration=None)
    order = []
    with pytest.MonkeyPatch.context() as mp:
        for name in ("write_bytes", "write_json"):
            real = getattr(folder, name)
            mp.setattr(folder, name, lambda path, data, _real=real, **kw:
                       (order.append(path.name), _real(path, data, **kw))[1])
        report.write_verify(rep, out)
    return ((out / "report.html").read_text("utf-8"),
            json.loads((out / "report.json").read_text()), out, order)


def test_report_html_is_whole_self_contained_and_written_before_report_json(written):
    text, data, out, order = written
    page = self_contained(text)
    assert order[-2:] == ["report.html", "report.json"]
    # photo, recon, one overlay per heatmap, the region, one close-up per totem
    n_img = 2 + len(list(out.glob("*/heatmap.npy"))) + 1 + len(data["totems"])
    assert len(page.find("img")) == n_img
    fade = [a for a in page.find("input") if a.get("type") == "range"]
    assert len(fade) == 1 and "fade" in fade[0]["aria-label"]
    assert len(text.encode()) < 1_000_000


def test_the_verdict_comes_first_in_words(written):
    text, data, _, _ = written
    assert data["verdict"] == "inconsistent" and data["p_value"] is None
    words = Page(text).words
    n = len(data["drivers"])               # patches over the one square, not overlapping
    assert n >= 1
    first = words.index(f"Verdict Inconsistent: {n} places in the protected region")
    for later in ("The photo, its re-rendered view", "drove the verdict",
                  "The protected region", "The totems", "What was checked"):
        assert words.index(later) > first
    assert "No p-value" in words
    assert data["key_fingerprint"] in words and "filled" in words
    for dist, version in data["versions"].items():
        assert dist in words and version in words
    assert "ABSENT: needs 3 totems" in words          # skipped, with its reason


def test_drivers_are_outlined_on_the_photo_and_listed(written):
    text, data, _, _ = written
    page = Page(text)
    rects = [[int(r[k]) for k in ("x", "y", "width", "height")] for r in page.find("rect")]
    boxes = [d["box"] for d in data["drivers"]]
    assert data["drivers"] and rects == [[x0, y0, x1 - x0, y1 - y0]
                                         for x0, y0, x1, y1 in boxes]
    words = page.words
    for d in data["drivers"]:
        assert ", ".join(map(str, d["box"])) in words
        assert f"{d['excess']:.2f}" in words


def test_no_absolute_path_and_no_key(written, tampered):
    text, _, out, _ = written
    no_path(text, out, tampered[0].path)
    for key in KEY_TEXTS + (repr(RADIUS_KEY), repr(IOR_KEY)):
        assert key not in text, f"the key's {key} is in report.html"
    # the key as totems.json would hold it: its values' text is absent too
    for value in json.loads(json.dumps({"radius": RADIUS_KEY, "ior": IOR_KEY})).values():
        assert str(value) not in text


def test_a_hostile_scene_name_is_escaped(tampered, tmp_path):
    scene, fit = tampered
    hostile = dataclasses.replace(scene, path=tmp_path / "<img src=x onerror=alert(1)>")
    rep = report.verify_scene(hostile, fit, calibration=None)
    assert rep.scene_name == "<img src=x onerror=alert(1)>"
    for name in (rep.scene_name, "<script>alert(1)</script>"):
        text = html_report.render_report(dataclasses.replace(rep, scene_name=name), {})
        assert name not in text and "alert(1)" in text       # shown, escaped
        page = self_contained(text)
        assert len(page.find("script")) == 1                  # only the fader's
        no_path(text, tmp_path)


def test_the_p_value_in_a_sentence(tampered):
    scene, fit = tampered
    cal = calibration.fit_tail(np.linspace(0.3, 1.2, 40))
    rep = report.verify_scene(scene, fit, calibration=cal)
    data = rep.to_json()
    assert data["p_value"] is not None and data["p_value"] < data["line_p_value"]
    assert data["line_p_value"] == pytest.approx(cal.p_value(1.0), rel=1e-3)
    words = Page(html_report.render_report(rep, {})).words
    assert f"p = {data['p_value']:.2g}" in words
    assert "the chance that an untouched photo scores this high is" in words
    assert "at the threshold it is" in words


def test_a_consistent_photo_says_so():
    photo = texture()
    rep = report.verify_scene(make_scene(photo), make_fit(photo), calibration=None)
    assert rep.verdict == "consistent"
    words = Page(html_report.render_report(rep, {})).words
    assert ("Consistent: nothing in the protected region disagrees with what the totems "
            "saw") in words
    assert "came closest" in words


def test_each_totems_pose_uncertainty_is_shown_beside_it():
    photo = texture()
    fit = make_fit(photo)
    fit.pose_uncertainty = [{"along_mm": 12.34 + j, "across_mm": 0.56, "mask_share": 1.0}
                            for j in range(len(fit.centers))]
    rep = report.verify_scene(make_scene(photo), fit, calibration=None)
    assert rep.to_json()["totems"][1]["pose_sd_mm"] == [13.34, 0.56]
    words = Page(html_report.render_report(rep, {})).words
    assert "13.3 / 0.6" in words and "along / across the line of sight" in words
    bare = report.verify_scene(make_scene(photo), make_fit(photo), calibration=None)
    assert bare.to_json()["totems"][0]["pose_sd_mm"] is None


def test_an_unverifiable_photo_says_why():
    base = {"drivers": [], "p_value": None, "line_p_value": None, "score": 1.4,
            "threshold": 1.0, "judged_fraction": 0.4, "evidence": {"min_judged": 0.05}}
    held = html_report.verdict_words({**base, "verdict": "unverifiable",
                                      "unverifiable_reason": "holdout",
                                      "holdout": {"L1": 0.23, "max": 0.16}})["headline"]
    assert "do not agree" in held and "0.23" in held and "0.16" in held
    thin = html_report.verdict_words({**base, "verdict": "unverifiable", "judged_fraction": 0.02,
                                      "unverifiable_reason": "judged"})["headline"]
    assert "too little" in thin and "2 % judged" in thin


def test_chances_in_words():
    assert html_report._chance(0.25) == "25 %"
    assert html_report._chance(0.01) == "1 %"
    assert html_report._chance(3.2e-5) == "about 1 in 31,000"


def test_pictures_are_capped_and_embedded():
    big = np.random.default_rng(0).uniform(size=(1000, 2400, 3))
    from PIL import Image
    for fmt in ("JPEG", "PNG"):
        uri = html_report.data_uri(big, fmt=fmt)
        assert uri.startswith(f"data:image/{fmt.lower()};base64,")
        with Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))) as im:
            assert im.size == (800, 333)
    mask = np.zeros((900, 100), bool)
    assert html_report.data_uri(mask).startswith("data:image/png;base64,")


def test_a_totem_close_up_draws_the_fitted_outline():
    sil = report.sphere_silhouette(CENTERS[0], RADIUS_KEY, K, (H, W))
    moved = np.roll(sil, 3, axis=1)                     # the mask, 3 px to the right
    pic = html_report.totem_picture(texture(), moved, sil)
    assert max(pic.shape[:2]) <= html_report.TOTEM_SIDE
    fit_px = np.all(np.isclose(pic, html_report.FIT_RGB, atol=1e-6), axis=2)
    mask_px = np.all(np.isclose(pic, html_report.MASK_RGB, atol=1e-6), axis=2)
    assert fit_px.sum() > 50 and mask_px.sum() > 50
    assert html_report.totem_picture(texture(), moved, np.zeros_like(sil)) is None


def test_the_depth_picture_tells_near_from_far_and_greys_the_unknown():
    depth = np.full((H, W), 8.0)
    depth[: H // 3] = np.nan                            # the totems establish no depth
    depth[H // 2:, : W // 2] = 1.5                      # a near surface
    pic, (near, far) = html_report.depth_picture(np.full((H, W, 3), 0.6), depth)
    assert near == pytest.approx(1.5) and far == pytest.approx(8.0)
    unknown, close, away = pic[H // 6, W // 2], pic[-2, 2], pic[-2, -2]
    assert np.ptp(unknown) < 1e-6                       # grey
    assert close[0] > close[2] + 0.3 and away[2] > away[0] + 0.3   # red near, blue far
    assert html_report.depth_picture(np.zeros((H, W, 3)), np.full((H, W), np.nan)) == \
        (None, None)


def test_unpath_shortens_absolute_paths_only():
    assert html_report.unpath("bad key: /tmp/a/b/totems.json: radius") == \
        "bad key: totems.json: radius"
    # a space ends the match: what is left is no longer absolute
    assert "/tmp" not in html_report.unpath("in /tmp/my photos/x.png")
    assert html_report.unpath("/work/set/box-1/") == "box-1"
    for same in ("4:2:0", "and/or", "p (n + 1) / (n + 1)", "sRGB [0, 1]", "0.1.0",
                 "<b>bold</b>"):
        assert html_report.unpath(same) == same


def _bench(tmp_path) -> dict:
    def run(name, kind, verdict, **metrics):
        return {"scene": str(tmp_path / "set" / name), "name": name, "preset": "box",
                "kind": kind, "n_totems": 4, "mode": "joint", "status": "ok",
                "verdict": verdict, "metrics": metrics,
                "timing_s": {"fit": 200.0, "verify": 5.0}}
    runs = [run("box-1", "none", "consistent", recon_L1=0.09, pose_L1=0.001),
            run("box-1-color", "color", "inconsistent", patch_ap_L1=0.7,
                patch_ap_RANGE=0.8),
            {"scene": str(tmp_path / "set" / "<b>bad</b>"), "name": "<b>bad</b>",
             "preset": "box", "kind": "none", "n_totems": 4, "mode": "joint",
             "status": "failed", "error": f"{tmp_path}/set/bad/totems.json: radius must "
                                          f"be a positive length in metres, got -0.1"}]
    return {"runs": runs, "summary": bench.summarise(runs), "jobs": 1, "refit": False,
            "reverified": 0, "wall_s": 12.0, "scenes": 3, "fits": 2}


def test_bench_html_has_the_tables_and_the_plots(tmp_path):
    out = tmp_path / "bench-out"
    bench.write_outputs(_bench(tmp_path), out)
    text = (out / "bench.html").read_text("utf-8")
    page = self_contained(text)
    md = (out / "bench.md").read_text()
    # every table row of bench.md is a row of bench.html, cell for cell
    md_rows = [[c.strip() for c in line.strip("|").split("|")] for line in md.splitlines()
               if line.startswith("|") and not line.startswith("|---")]
    n_tables = sum(1 for k, line in enumerate(md.splitlines())
                   if line.startswith("|") and not md.splitlines()[k - 1].startswith("|"))
    assert len(page.find("table")) == n_tables == 2
    flat = page.words
    for row in md_rows:
        assert " ".join(" ".join(row).split()) in flat
    plots = sorted(p.name for p in (out / "plots").glob("*.png"))
    assert plots and len(page.find("img")) == len(plots)
    assert "untouched judged consistent" in flat and "Failed runs" in flat
    assert "totems.json: radius must be" in flat
    no_path(text, tmp_path)
    assert "<b>bad</b>" not in text and "&lt;b&gt;bad&lt;/b&gt;" in text


# --------------------------------------------------------------------------- a browser

def _chrome():
    """A headless Chromium driven by selenium, or a skip (a failure under CI=true)."""
    missing = None
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing = "selenium is not installed (pip install -e '.[test]')"
    if missing is None and not (chromium and driver):
        missing = ("no chromium and chromedriver on PATH (Debian: apt-get install "
                   "chromium chromium-driver)")
    if missing:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the browser test: {missing}")
        pytest.skip(missing)
    opts = Options()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu",
                "--disable-dev-shm-usage", "--window-size=1000,1400"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(executable_path=driver), options=opts)


@pytest.mark.slow
def test_report_html_in_a_browser(written):
    from PIL import Image

    _, data, out, _ = written
    browser = _chrome()
    try:
        browser.get((out / "report.html").as_uri())
        verdict = browser.find_element("id", "verdict")
        assert verdict.is_displayed() and verdict.text.startswith("Inconsistent:")
        png = browser.get_screenshot_as_png()
        shot = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
        assert shot.reshape(-1, 3).std(axis=0).max() > 10, "the page is blank"
        assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 100
        # the fader: the photo alone at 0, the heatmap over it at the far end
        opacity = """var f = document.getElementById('fade'); f.value = arguments[0];
            f.dispatchEvent(new Event('input'));
            var m = document.getElementById('heat-metric').value;
            return [document.getElementById('layer-recon').style.opacity,
                    document.querySelector('img.heat[data-metric="' + m + '"]')
                        .style.opacity];"""
        assert browser.execute_script(opacity, 0) == ["0", "0"]
        assert browser.execute_script(opacity, 200) == ["1", "1"]
        images = browser.execute_script(
            "return Array.from(document.images).map(i => i.complete && i.naturalWidth > 0)")
        assert images and all(images), "a picture did not load"
        errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        browser.quit()
