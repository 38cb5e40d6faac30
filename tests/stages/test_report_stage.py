"""The report stage: [report] section, figures, a hashed report.html, the batch index, Chromium.

One synthetic run (conftest's rig log and workflow, with ``[report]``) is shared by the CLI
tests; the pure parts (window choice, ``run_report``) run on the seeded bistable record.
"""

import base64
import io
import re
import shutil
from html import unescape
from html.parser import HTMLParser
from importlib.util import find_spec

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread
from typer.testing import CliRunner

from debist.cli import app
from debist.core import artifacts
from debist.core.errors import WorkflowError
from debist.engine import outdir
from debist.engine.runner import Runner
from debist.report.figures import dynamic_window
from debist.report.html import FIGURE_GROUPS, PNG_SIGNATURE, SECTIONS
from debist.stages.report import ReportInputs, run_report
from debist.workflow.loader import load_workflow
from debist.workflow.schema import check_workflow
from tests.conftest import SYNTHETIC_WORKFLOW

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
SHOWN = ["ingest", "differentiate", "identify", "validate", "compare"]


class Page(HTMLParser):
    """Collects table rows, image sources, headings and every URL-like attribute."""

    def __init__(self):
        super().__init__()
        self.rows, self.imgs, self.urls, self.cell = [], [], [], None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.imgs.append(attrs["src"])
        for key in ("src", "href"):
            if key in attrs:
                self.urls.append(attrs[key])
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self.cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self.rows[-1].append(self.cell.strip())
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def parse(html):
    page = Page()
    page.feed(html)
    page.close()
    return page


def decode(src):
    """The image of a data URI: PNG signature checked, decoded to an RGB(A) array."""
    prefix, data = src.split(",", 1)
    assert prefix == "data:image/png;base64"
    raw = base64.b64decode(data, validate=True)
    assert raw.startswith(PNG_SIGNATURE)
    return imread(io.BytesIO(raw), format="png")


def test_report_section_in_the_schema():
    assert check_workflow({"physics": {}}).report is None
    assert check_workflow({"physics": {}, "report": {}}).report.zoom_window == 2.0
    assert check_workflow({"physics": {}, "report": {"zoom_window": 0.5}}).report.zoom_window == 0.5
    with pytest.raises(WorkflowError) as err:
        check_workflow({"physics": {}, "report": {"zoom_window": -1.0}})
    assert err.value.key == "report.zoom_window"
    assert "> 0" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        check_workflow({"physics": {}, "report": {"zoom": 1.0}})
    assert err.value.key == "report.zoom"
    assert "unknown" in str(err.value)


def test_dynamic_window_is_the_burst():
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 10.0, 0.01)
    q_ddot = rng.normal(0.0, 1.0, t.size)
    burst = (t >= 6.0) & (t < 6.5)
    q_ddot[burst] += 40.0 * np.sin(2 * np.pi * 8 * t[burst])
    start, stop = dynamic_window(t, q_ddot, 1.0)
    assert stop - start == 100
    assert t[start] <= 6.0 and t[stop - 1] >= 6.49
    q_ddot[burst] = 0.0
    q_ddot[(t >= 2.0) & (t < 2.3)] = 50.0
    start, stop = dynamic_window(t, q_ddot, 1.0)
    assert t[start] <= 2.0 and t[stop - 1] >= 2.29
    assert dynamic_window(t, q_ddot, 100.0) == (0, t.size)


def synthetic_inputs(rec):
    """Two data sets of the bistable record, an RBF free run on each and SINDy's on one."""
    rng = np.random.default_rng(2)
    tables, derivs, runs, rows = {}, {}, {}, []
    parts = {"est": ("estimation", slice(0, 4000)), "check": ("validation", slice(4000, 6500))}
    for name, (role, part) in parts.items():
        t, q = rec["t"][part], rec["q"][part]
        table = pd.DataFrame({"t": t, "q": q, "v1": rec["v"][part, 0], "v2": rec["v"][part, 1]})
        table.attrs.update({"role": role, "units": {"q": "m"}})
        tables[name] = table
        derivs[name] = pd.DataFrame(
            {"t": t, "q_dot": rec["q_dot"][part], "q_ddot": rec["q_ddot"][part]}
        )
        sim = {"rbf": pd.DataFrame({"t": t, "q": q, "q_sim": q + rng.normal(0, 1e-4, t.size)})}
        if role == "validation":
            sim["sindy"] = sim["rbf"].assign(q_sim=0.9 * q)
        runs[name] = sim
        for model in sim:
            score = 0.01 if model == "rbf" else 0.1
            rows.append(
                {"model": model, "dataset": name, "nrmse_q": score, "nrmse_q_baseline": 0.3,
                 "status": "ok", "diverged": False}
            )  # fmt: skip
    return ReportInputs(
        workflow="synthetic",
        datasets=[
            {"name": "est", "role": "estimation", "source": "rig.csv"},
            {"name": "check", "role": "validation", "source": "rig.csv"},
        ],
        summaries={"validate": {"table": rows}},
        tables=tables,
        derivs=derivs,
        runs=runs,
        provenance={"digest": "cd" * 32, "verify": "debist verify wf.toml", "stages": {}},
    )


@pytest.mark.slow
def test_run_report_draws_the_papers_figures(bistable_record):
    inputs = synthetic_inputs(bistable_record)
    res = run_report(inputs, {})
    assert res.figures == {g: {"excitation": 1, "free_run": 2}.get(g, 0) for g in FIGURE_GROUPS}
    assert run_report(inputs, {}).html == res.html  # a pure function: the same bytes again
    page = parse(res.html)
    assert all(f">{h}</h2>" in res.html for h in SECTIONS)
    assert len(page.imgs) == 3
    for src in page.imgs:
        image = decode(src)
        assert image.shape[0] > 200 and image.shape[1] > 400
        assert np.std(image[..., :3]) > 0.05  # drawn, not blank
    text = unescape(res.html)
    assert "Fig. 11a: estimation record 'est'" in text
    assert "Fig. 12, estimation data 'est'" in text
    assert "Fig. 15, cross-validation on unseen data 'check'" in text
    assert "rbf, sindy" in text and "2 s" in text and "window" in text
    other = run_report(inputs, {"zoom_window": 0.5})
    assert "0.5 s" in other.html and other.html != res.html
    with pytest.raises(WorkflowError) as err:
        run_report(inputs, {"zoom_window": "wide"})
    assert err.value.key.endswith(".zoom_window")


# ------------------------------------------------------------------ one CLI run


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory, synthetic_run):
    """`debist run` of the synthetic workflow with [report]; the folder and the run digest.

    The session's run of the same workflow without [report] is copied: only the report runs.
    """
    folder = tmp_path_factory.mktemp("report-run") / "run"
    shutil.copytree(synthetic_run[0], folder)
    wf = folder / "wf.toml"
    wf.write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6) + "\n[report]\nzoom_window = 1.5\n")
    code, out = invoke("run", wf)
    assert code == 0, out
    assert out.count("up to date, skipping") == len(SHOWN) and "Stage 'report' done" in out
    digest = re.search(r"run digest: ([0-9a-f]{64})", out).group(1)
    return folder, wf, digest


def test_run_writes_a_hashed_report(synthetic_run):
    folder, wf, digest = synthetic_run
    out = folder / "out"
    manifest = artifacts.read_manifest(out / "report")
    assert sorted(manifest.outputs) == ["report.html", "summary.json"]
    assert sorted(manifest.upstream) == sorted(SHOWN)
    assert manifest.config == {"zoom_window": 1.5}
    html = (out / "report" / "report.html").read_text(encoding="utf-8")
    assert artifacts.sha256_bytes(html.encode()) == manifest.outputs["report.html"]
    page = parse(html)
    assert all(f">{h}</h2>" in html for h in SECTIONS)
    # Fig. 11a (one estimation set), two free runs, Fig. 14, the held-out choice of `slip`
    assert len(page.imgs) == 1 + 2 + 1 + 1
    for src in page.imgs:
        assert np.std(decode(src)[..., :3]) > 0.05
    assert all(u.startswith(("data:image/png;base64,", "#")) for u in page.urls)
    assert not re.search(r"https?://|<script|<link|@import|url\(", html, flags=re.I)
    # Table 2: the validate stage's numbers, and the provenance of every stage shown
    summary = artifacts.read_summary(out / "validate", artifacts.read_manifest(out / "validate"))
    cells = {(r[0], r[1]): r for r in page.rows if len(r) == 7}  # no phi without [physics]
    for r in summary["table"]:
        assert cells[(r["model"], r["dataset"])][2] == f"{100 * r['nrmse_q']:.2f} %"
        assert cells[(r["model"], r["dataset"])][5] == f"{100 * r['nrmse_q_baseline']:.2f} %"
    for stage in SHOWN:
        key = artifacts.read_manifest(out / stage).key
        assert [stage, key, artifacts.manifest_digest(out / stage)] in page.rows
    assert outdir.run_digest(out, SHOWN) in html
    assert "verify" in html and "wf.toml" in html
    assert str(folder) not in html  # no absolute path: the same page in any clone
    code, text = invoke("verify", wf, "--digest", digest)
    assert code == 0, text


def test_report_reruns_only_when_its_inputs_change(synthetic_run):
    folder, wf, digest = synthetic_run
    page = folder / "out" / "report" / "report.html"
    before = page.read_bytes()
    code, out = invoke("run", wf)
    assert code == 0 and "Stage 'report'" in out and "date" in out and digest in out
    assert f"report: {page}" in out and "written" not in out
    code, out = invoke("report", wf)
    assert code == 0 and "Stage 'report'" in out and "date" in out and str(page) in out
    page.write_text("<html>edited</html>")
    code, out = invoke("verify", wf)
    assert code == 3 and "report.html (modified)" in out
    code, out = invoke("report", wf)
    assert code == 0 and "Running stage 'report'" in out
    assert page.read_bytes() == before  # rebuilt from the same artifacts: the same bytes
    code, out = invoke("verify", wf, "--digest", digest)
    assert code == 0, out
    # a changed [report] section makes only the report stale
    changed = folder / "wf-zoom.toml"
    changed.write_text(wf.read_text().replace("zoom_window = 1.5", "zoom_window = 3.0"))
    states = {s.stage: s for s in Runner(load_workflow(changed)).status()}
    assert states.pop("report").state == "stale"
    assert {s.state for s in states.values()} == {"up to date"}


def test_a_workflow_without_report_is_unaffected(synthetic_run):
    folder, _, _ = synthetic_run
    plain = folder / "wf-plain.toml"
    plain.write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    runner = Runner(load_workflow(plain))
    assert "report" not in runner.stages()
    assert {s.stage: s.state for s in runner.status()} == dict.fromkeys(SHOWN, "up to date")
    code, out = invoke("report", plain)
    assert code == 2 and "[report]" in out and "no [report] section" in out


def test_batch_writes_an_index_of_the_reports(synthetic_run):
    folder, wf, _ = synthetic_run
    broken = folder / "broken.toml"
    broken.write_text(
        SYNTHETIC_WORKFLOW.format(alpha=1e-6)
        .replace('name = "synthetic"', 'name = "broken"')
        .replace('output_dir = "out"', 'output_dir = "out-broken"')
        .replace('source = "rig.csv"', 'source = "missing.csv"')
    )
    code, out = invoke("batch", wf, broken, "--scheduler", "synchronous")
    assert code == 1, out  # the broken prototype fails, the index is written all the same
    index = folder / "index.html"
    assert f"reports: {index}" in out.replace("\n", "")
    html = index.read_text(encoding="utf-8")
    page = parse(html)
    assert page.urls == ["./out/report/report.html"]
    assert (folder / page.urls[0]).is_file()
    rows = {r[0]: r for r in page.rows[1:]}
    summary = artifacts.read_summary(
        folder / "out/validate", artifacts.read_manifest(folder / "out/validate")
    )
    for r in summary["table"]:
        column = page.rows[0].index(f"NRMSE(q) {r['dataset']}")
        cell = rows["synthetic"][column]  # the value, and its verdict when it is not "ok"
        assert cell.split(" (")[0] == f"{100 * r['nrmse_q']:.2f} %"
    assert rows["broken"][2].startswith("failed")
    assert "http:" not in html and "https:" not in html and "<script" not in html


CHROMEDRIVER = shutil.which("chromedriver")

#: Measured in the page: page-level overflow, tables wider than their container and whether
#: they sit in a scrolling box, the scroll cue, images (loaded, natural and shown width),
#: number cells broken over lines and headings or captions whose text is cut off.
LAYOUT_PROBE = """
const page = document.documentElement;
const scrolls = (el) => { for (let e = el.parentElement; e; e = e.parentElement) {
    const o = getComputedStyle(e).overflowX;
    if (o === "auto" || o === "scroll") return true; }
  return false; };
const shown = (el) => getComputedStyle(el).display !== "none" && el.getClientRects().length > 0;
return {
  inner: window.innerWidth, scrollWidth: page.scrollWidth,
  tables: [...document.querySelectorAll("table")].map((t) => ({
    width: t.scrollWidth, room: t.parentElement.clientWidth, scrolls: scrolls(t),
    cue: t.parentElement.previousElementSibling !== null
      && t.parentElement.previousElementSibling.classList.contains("scrollnote")
      && shown(t.parentElement.previousElementSibling)})),
  imgs: [...document.images].map((i) => ({complete: i.complete, natural: i.naturalWidth,
    css: i.getBoundingClientRect().width, right: i.getBoundingClientRect().right})),
  wrapped: [...document.querySelectorAll("td:not(.text)")].filter((td) => {
    const r = document.createRange(); if (!td.firstChild) return false;
    r.selectNodeContents(td.firstChild);  // the number; a verdict after it may wrap
    return new Set([...r.getClientRects()].map((x) => Math.round(x.top))).size > 1; })
    .map((td) => td.textContent),
  cut: [...document.querySelectorAll("h1, h2, p, figcaption, nav, li")]
    .filter((e) => e.scrollWidth > e.clientWidth + 1)
    .map((e) => e.tagName + ": " + e.textContent.slice(0, 60)),
};
"""


def chrome(tmp_path, width):
    """A headless Chromium under Selenium, from Debian's chromium and chromium-driver only."""
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("Chromium or its driver is absent (apt-get install chromium chromium-driver)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (
        "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}",
    ):  # fmt: skip
        options.add_argument(flag)
    # an explicit driver path: Selenium Manager downloads nothing
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.set_window_size(width, 900)
    # the viewport, not the window, is `width` wide (the window has no frame when headless)
    inner = driver.execute_script("return window.innerWidth")
    if inner != width:
        driver.set_window_size(2 * width - inner, 900)
    return driver


@pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="Chromium or its driver is absent (apt-get install chromium chromium-driver)",
)
@pytest.mark.skipif(find_spec("selenium") is None, reason="selenium is not installed")
@pytest.mark.parametrize("width", [1366, 400])
@pytest.mark.slow
def test_chromium_lays_the_report_out_at_desktop_and_phone_width(synthetic_run, tmp_path, width):
    """Headless Chromium at 1366 and 400 px: nothing overflows the page, wide tables scroll in
    their own box with the cue shown on a phone, figures are loaded at twice their shown width
    and no heading or caption is cut off; a full-page screenshot is kept for a look."""
    folder, _, _ = synthetic_run
    driver = chrome(tmp_path, width)
    try:
        driver.get((folder / "out/report/report.html").as_uri())
        driver.execute_script("return document.fonts.ready")
        m = driver.execute_script(LAYOUT_PROBE)
        height = driver.execute_script("return document.documentElement.scrollHeight")
        driver.set_window_size(driver.get_window_size()["width"], height + 100)
        shot = tmp_path / f"report-{width}.png"
        assert driver.save_screenshot(str(shot))
    finally:
        driver.quit()
    assert m["inner"] == width
    assert m["scrollWidth"] <= m["inner"] + 1, m  # no page-level sideways scrolling
    assert len(m["tables"]) >= 5
    wide = [t for t in m["tables"] if t["width"] > t["room"] + 1]
    assert all(t["scrolls"] for t in wide), wide
    if width == 400:
        assert wide  # the digests' table cannot fit a phone
        assert all(t["cue"] for t in m["tables"]), m["tables"]
    else:
        assert not any(t["cue"] for t in m["tables"])
    assert len(m["imgs"]) == 5  # four figures and the held-out choice of slip
    for img in m["imgs"]:
        assert img["complete"] and img["natural"] > 0, img
        assert img["natural"] >= 1.95 * img["css"], img  # drawn for a 2x (HiDPI) screen
        assert img["right"] <= width, img
    assert m["wrapped"] == []  # a number on two lines ("-1.351e-" / "13") reads as two
    assert m["cut"] == []
    image = imread(shot)[..., :3]
    assert image.shape[1] == width and image.shape[0] > 2000
    gray = image.mean(axis=2)
    assert gray.std() > 0.1 and (gray < 0.5).mean() > 0.01  # text and figures, not blank


def test_the_validate_stages_other_models_become_runs_of_their_own():
    """q_sim_<model> columns of validate's free runs are drawn as that model's run."""
    from debist.stages.report import _split_runs

    t = np.arange(5) * 0.01
    frame = pd.DataFrame({"t": t, "q": t, "q_sim": 2 * t, "q_dot_sim": t,
                          "q_sim_analytical": 3 * t, "q_dot_sim_analytical": t})  # fmt: skip
    runs = _split_runs(frame, "rbf")
    assert sorted(runs) == ["analytical", "rbf"]
    np.testing.assert_array_equal(runs["analytical"]["q_sim"], 3 * t)
    np.testing.assert_array_equal(runs["analytical"]["q"], t)
    np.testing.assert_array_equal(runs["rbf"]["q_sim"], 2 * t)


def test_the_replicate_band_stays_with_its_model_and_says_what_it_held():
    """q_sim_lo / q_sim_hi are the rbf run's own band (not models "lo" and "hi"); the report's
    free-run figure shades it with the share of the measured q it holds."""
    from debist.report.figures import free_run_figure
    from debist.stages.report import _split_runs

    t = np.arange(50) * 0.01
    frame = pd.DataFrame({"t": t, "q": t, "q_sim": t, "q_sim_lo": t - 1e-3, "q_sim_hi": t + 1e-3,
                          "q_sim_analytical": 2 * t})  # fmt: skip
    runs = _split_runs(frame, "rbf")
    assert sorted(runs) == ["analytical", "rbf"]
    np.testing.assert_array_equal(runs["rbf"]["q_sim_hi"], t + 1e-3)
    rows = {"rbf": {"replicates": 40, "replicates_hold_q": 0.625}}
    fig = free_run_figure(frame[["t", "q"]], runs, (10, 30), "val", "m", {"rbf": 0.01}, rows)
    labels = [text.get_text() for text in fig.legends[0].get_texts()]
    band = "40 bootstrap replicates, middle 95 % (estimation only; holds 62 % of q here)"
    assert band in labels and not any(lab.startswith(("lo", "hi")) for lab in labels)
    shaded = [c for c in fig.axes[0].collections if c.get_label() == band]
    lo, hi = (
        shaded[0].get_paths()[0].vertices[:, 1].min(),
        shaded[0].get_paths()[0].vertices[:, 1].max(),
    )
    assert lo == pytest.approx(1e3 * (t[0] - 1e-3)) and hi == pytest.approx(1e3 * (t[-1] + 1e-3))
