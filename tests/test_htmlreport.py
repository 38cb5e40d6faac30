"""The HTML run report: sections, Table 2 numbers, verdicts, embedded PNGs, self-containment."""

import base64
import io
import json
import math
import re
from html.parser import HTMLParser

import pytest
from conftest import SYNTHETIC_WORKFLOW, write_rig_csv
from matplotlib.figure import Figure

from pipeline.errors import ArtifactError
from pipeline.htmlreport import PNG_SIGNATURE, SECTIONS, render_report


def tiny_png(color: str) -> bytes:
    fig = Figure(figsize=(0.5, 0.5), dpi=20)
    fig.add_subplot().plot([0, 1], [0, 1], color=color)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def row(model, dataset, q, status="ok", reason="", diverged=False):
    return {
        "model": model,
        "dataset": dataset,
        "role": "validation",
        "nrmse_q": q,
        "nrmse_phi": q * 1.1,
        "nrmse_q_dot": q * 1.7,
        "nrmse_q_ddot": q * 2.3,
        "nrmse_q_baseline": 0.2246,
        "rms_q": 0.5,
        "rms_unit": "mm",
        "status": status,
        "reason": reason,
        "diverged": diverged,
    }


@pytest.fixture
def run():
    return {
        "workflow": "proto-7",
        "datasets": [
            {"name": "identification", "role": "estimation", "source": "ident.mat"},
            {"name": "unseen", "role": "validation", "source": "validation.mat"},
        ],
        "identify": {
            "T_z": 0.0625,
            "m_q": 0.0402,
            "backbone": {"k_1": 3.045, "k_3": 19849.18, "g_0": [0.0, 0.0]},
            "condition": 1906.07,
            "n_params": 44,
            "fit_r2": 0.99958,
            "identified": {"restoring": [[-0.016, -0.00384], [0.00096, 0.016]], "g1": []},
            "design": {
                "verdict": "stable",
                "reason": "2 visited wells",
                "equilibria": [
                    {
                        "model": "rbf",
                        "level": 0,
                        "q": -0.009516,
                        "v1": 0.0,
                        "v2": 0.0,
                        "stable": True,
                        "static_stable": True,
                        "f_n": 2.2116,
                        "zeta": 0.3832,
                        "barrier": 0.00017,
                    },
                    {
                        "model": "rbf",
                        "level": 0,
                        "q": -0.000775,
                        "v1": 0.0,
                        "v2": 0.0,
                        "stable": False,
                        "static_stable": False,
                        "f_n": None,
                        "zeta": None,
                        "barrier": None,
                    },
                ],
                "switching": [
                    {"model": "rbf", "input": 1, "v_switch": 1975.667, "reason": ""},
                    {
                        "model": "rbf",
                        "input": 2,
                        "v_switch": None,
                        "reason": "the well persists up to v_max = 3018.48 V",
                    },
                ],
            },
            "excitation": {"warnings": ["g1: input 1 is never active for q in [-17.8, -10.7] mm"]},
        },
        "nrmse": [
            row("rbf", "unseen", 0.011277),
            row("sindy", "unseen", 0.0731, status="unstable", reason="negative damping"),
            row("analytical", "unseen", math.nan, diverged=True),
        ],
        "equations": "q_ddot = 1.7e-01 + 1.4e+02 q & <h1>",
        "figures": {
            "identify": [("Fig. 14", tiny_png("k"))],
            "validate": [("Free run on unseen", tiny_png("r"))],
            "analyze": [("analyze: fig3.png", tiny_png("b"))],
        },
        "digest": "ab" * 32,
        "verify": "debist verify wf.toml --digest " + "ab" * 32,
        "stages": {"ingest": "1" * 64, "identify": "2" * 64},
        "versions": {"numpy": "2.4.6", "pysindy": "2.0.1"},
    }


class Strict(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self.imgs, self.cell, self.open = [], [], None, []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.imgs.append(dict(attrs)["src"])
        elif tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self.cell = ""
        if tag not in ("meta", "img", "br"):
            self.open.append(tag)

    def handle_endtag(self, tag):
        assert self.open and self.open[-1] == tag, (tag, self.open[-3:])
        self.open.pop()
        if tag in ("td", "th"):
            self.rows[-1].append(self.cell.strip())
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data

    def error(self, message):  # pragma: no cover - older Python only
        raise AssertionError(message)


def parse(html):
    parser = Strict()
    parser.feed(html)
    parser.close()
    assert parser.open == [], parser.open
    return parser


def test_sections_numbers_and_verdicts(run):
    html = render_report(run)
    parser = parse(html)
    for heading in SECTIONS:
        assert f"<h2>{heading}</h2>" in html
    assert '<meta name="viewport"' in html and "max-width" in html
    table = {(r[0], r[1]): r for r in parser.rows if len(r) == 8}
    rbf = table[("rbf", "unseen")]
    assert rbf[2:7] == ["1.13 %", "1.24 %", "1.92 %", "2.59 %", "22.46 %"]
    sindy = table[("sindy", "unseen")]
    assert sindy[2:6] == ["unstable"] * 4
    assert sindy[7] == "unstable: negative damping"
    assert not any(re.search(r"\d", cell) for cell in sindy[2:6])
    for value in (0.0731, 0.0731 * 1.1, 0.0731 * 1.7, 0.0731 * 2.3):
        assert f"{100 * value:.2f} %" not in html
    analytical = table[("analytical", "unseen")]
    assert analytical[2:6] == ["diverged"] * 4
    # identified model, design and warnings
    model = {r[0]: r[1] for r in parser.rows if len(r) == 2}
    assert model["T_z [s]"] == "0.0625" and model["backbone k_3"] == "1.985e+04"
    assert model["restoring identified on q in [m]"] == "[-0.016, -0.00384], [0.00096, 0.016]"
    assert model["g1 identified on q in [m]"] == "nowhere"
    assert any(r[:4] == ["rbf", "0, 0", "-0.009516", "well"] for r in parser.rows)
    assert any(r[3] == "1976 V" for r in parser.rows if len(r) == 7)
    assert "the well persists up to v_max = 3018.48 V" in html
    assert "g1: input 1 is never active" in html
    # provenance
    assert "debist verify wf.toml --digest " + "ab" * 32 in html
    assert ["identify", "2" * 64] in parser.rows and ["pysindy", "2.0.1"] in parser.rows
    # content is escaped, not markup
    assert "&amp; &lt;h1&gt;" in html


def test_images_are_embedded_pngs_and_nothing_is_external(run):
    html = render_report(run)
    parser = parse(html)
    assert len(parser.imgs) == 3
    for src in parser.imgs:
        prefix, data = src.split(",", 1)
        assert prefix == "data:image/png;base64"
        assert base64.b64decode(data, validate=True).startswith(PNG_SIGNATURE)
    assert "http://" not in html and "https://" not in html
    assert "<script" not in html.lower() and "<link" not in html.lower()


def test_missing_stages_are_left_out(run):
    html = render_report({"workflow": "only-ingest", "stages": {"ingest": "1" * 64}})
    parse(html)
    assert all(f"<h2>{h}</h2>" in html for h in SECTIONS)
    assert "<img" not in html and "No run digest" in html
    assert run["identify"]["design"]["reason"] not in html


def test_a_figure_that_is_not_a_png_is_refused(run):
    run["figures"]["validate"] = [("broken", b"GIF89a....")]
    with pytest.raises(ArtifactError, match="broken"):
        render_report(run)


def test_cli_report_of_a_synthetic_run(tmp_path, bistable_record):
    from typer.testing import CliRunner

    from cli import app

    write_rig_csv(tmp_path, bistable_record)
    wf = tmp_path / "wf.toml"
    wf.write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    cli = CliRunner()
    missing = cli.invoke(app, ["report", str(wf)])
    assert missing.exit_code == 1 and "no stage has run" in missing.output
    ran = cli.invoke(app, ["run", str(wf)])
    assert ran.exit_code == 0, ran.output
    digest = re.search(r"run digest: ([0-9a-f]{64})", ran.output).group(1)
    for _ in range(2):  # a second report replaces the first
        done = cli.invoke(app, ["report", str(wf)])
        assert done.exit_code == 0, done.output
    page = tmp_path / "out" / "report" / "report.html"
    assert sorted(p.name for p in page.parent.iterdir()) == ["report.html"]
    html = page.read_text(encoding="utf-8")
    parser = parse(html)
    assert f"debist verify {wf} --digest {digest}" in html
    assert len(parser.imgs) == 1 + 2  # Fig. 14 and one free run per data set
    summary = json.loads((tmp_path / "out" / "validate" / "summary.json").read_text())
    rows = {(r[0], r[1]): r for r in parser.rows if len(r) == 7}  # no phi without [physics]
    for r in summary["table"]:
        cells = rows[(r["model"], r["dataset"])]
        assert cells[2] == f"{100 * r['nrmse_q']:.2f} %"
        assert cells[5] == f"{100 * r['nrmse_q_baseline']:.2f} %"
    assert "http://" not in html and "https://" not in html
    verified = cli.invoke(app, ["verify", str(wf), "--digest", digest])
    assert verified.exit_code == 0, verified.output
