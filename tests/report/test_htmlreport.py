"""The HTML run report and the batch index: sections, Table 2 numbers, verdicts, embedded PNGs,
self-containment."""

import base64
import io
import math
import re
from html.parser import HTMLParser

import pytest
from matplotlib.figure import Figure

from debist.core.errors import ArtifactError
from debist.report.html import (
    FIGURE_GROUPS,
    PNG_SIGNATURE,
    SECTIONS,
    index_row,
    render_index,
    render_report,
)


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
            "excitation": [("Fig. 11a", tiny_png("g"))],
            "free_run": [("Free run on unseen", tiny_png("r"))],
            "identify": [("Fig. 14", tiny_png("k"))],
            "study": [("Fig. 11b", tiny_png("c")), ("Fig. 11c", tiny_png("m"))],
            "analyze": [("analyze: fig3.png", tiny_png("b"))],
        },
        "digest": "ab" * 32,
        "verify": "debist verify wf.toml",
        "stages": {"ingest": ("1" * 64, "3" * 64), "identify": ("2" * 64, "4" * 64)},
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
        assert f">{heading}</h2>" in html
    assert '<meta name="viewport"' in html and "max-width" in html
    table = {(r[0], r[1]): r for r in parser.rows if len(r) == 8}
    rbf = table[("rbf", "unseen")]
    assert rbf[2:7] == ["1.13 %", "1.24 %", "1.92 %", "2.59 %", "22.46 %"]
    sindy = table[("sindy", "unseen")]
    assert sindy[2:6] == ["unstable"] * 4
    assert sindy[7].startswith("unstable:") and sindy[7].endswith("damping")
    assert not any(re.search(r"\d", cell) for cell in sindy[2:6])
    for value in (0.0731, 0.0731 * 1.1, 0.0731 * 1.7, 0.0731 * 2.3):
        assert f"{100 * value:.2f} %" not in html
    analytical = table[("analytical", "unseen")]
    assert analytical[2:6] == ["diverged"] * 4
    # identified model, design and warnings
    model = {r[0]: r[1] for r in parser.rows if len(r) == 2}
    assert model["T_z [s]"] == "0.0625"
    # q and what is per length of q in the report unit, mm by default: 19849.18 N/m^3 is
    # 1.985e-05 N/mm^3, the span -0.016 m is -16 mm
    k_3 = "backbone coefficient k_3 (a basis term, not a physical constant) [N/mm^3]"
    assert model[k_3] == "1.985e-05" and model["mass m_q [kg]"]
    assert model["restoring identified on q in [mm]"] == "[-16, -3.84], [0.96, 16]"
    assert model["g1 identified on q in [mm]"] == "nowhere"
    assert any(r[:4] == ["rbf", "0, 0", "-9.516", "well"] for r in parser.rows)  # q* [mm]
    assert "<th>q* [mm]</th>" in html
    assert any(r[3] == "1976 V" for r in parser.rows if len(r) == 9)  # d(q*), k* added
    assert any(r[1] == "switching voltage, input 1" for r in parser.rows if len(r) == 9)
    assert "persists" in html and "v_max = 3018.48 V" in html
    assert "g1: input 1" in html and "never" in html
    # provenance
    assert "verify" in html and "wf.toml" in html and "ab" * 32 in html
    assert ["identify", "2" * 64, "4" * 64] in parser.rows and ["pysindy", "2.0.1"] in parser.rows
    # content is escaped, not markup
    assert "&amp; &lt;h1&gt;" in html
    assert "Coefficients as fitted, in SI: q [m], q_dot [m/s], q_ddot [m/s^2]." in html


def test_a_model_whose_physical_curves_hold_nowhere_says_simulation_only_first(run):
    """d and g2 nowhere, g1 on part of q: the page's first lines and the verdict say so."""
    from debist.identify.bands import simulation_only

    run["identify"]["identified"] = {"restoring": [[-0.016, 0.016]], "d": [],
                                     "g1": [[0.001, 0.01]], "g2": []}  # fmt: skip
    said = simulation_only(run["identify"]["identified"])
    assert said == "d, g2 identified nowhere (restoring, g1 hold on part of q)"
    run["nrmse"][0]["simulation_only"] = said  # as the validate stage writes it
    html = render_report(run)
    top = html.split('<h2 id="s2">')[0]
    assert f"simulation only: {said}" in top
    rows = {(r[0], r[1]): r for r in parse(html).rows if len(r) == 8}
    assert rows[("rbf", "unseen")][7] == f"simulation only: {said}"
    run["nrmse"][0]["simulation_only"] = ""  # every fitted curve holds somewhere
    assert "simulation only" not in render_report(run).split('<h2 id="s2">')[0]


def test_images_are_embedded_pngs_and_nothing_is_external(run):
    html = render_report(run)
    parser = parse(html)
    assert len(parser.imgs) == sum(len(v) for v in run["figures"].values()) == 6
    for src in parser.imgs:
        prefix, data = src.split(",", 1)
        assert prefix == "data:image/png;base64"
        assert base64.b64decode(data, validate=True).startswith(PNG_SIGNATURE)
    assert "http://" not in html and "https://" not in html
    assert "<script" not in html.lower() and "<link" not in html.lower()


def test_figures_go_to_their_sections(run):
    html = render_report(run)
    heads = [html.index(f">{h}</h2>") for h in SECTIONS]
    where = {
        "excitation": SECTIONS.index("Excitation (Fig. 11a)"),
        "free_run": SECTIONS.index("Free runs (Fig. 12, 13, 15)"),
        "identify": SECTIONS.index("Identified model (Fig. 14)"),
        "study": SECTIONS.index("Hyper-parameter search (Fig. 11b, 11c)"),
        "analyze": SECTIONS.index("Design analysis (Fig. 3-7)"),
    }
    assert set(where) == set(FIGURE_GROUPS)
    for group, k in where.items():
        for caption, _ in run["figures"][group]:
            at = html.index(f"<figcaption>{caption}</figcaption>")
            assert heads[k] < at < (heads[k + 1] if k + 1 < len(heads) else len(html)), caption


def test_figures_are_shown_at_most_at_half_their_pixel_width_and_numbers_do_not_wrap(run):
    """A figure of N px is given width N/2 (CSS px, shrunk further by max-width: 100%): 2x
    sharp on a HiDPI screen; the verdict after an index number may wrap, the number not."""
    html = render_report(run)
    widths = re.findall(r'<img src="data:image/png;base64,([^"]+)" width="(\d+)"', html)
    assert len(widths) == 6
    for data, width in widths:
        png = base64.b64decode(data)
        assert int(width) == int.from_bytes(png[16:20], "big") // 2 > 0
    assert "img { max-width: 100%; height: auto; }" in html
    assert "td:not(.text) { white-space: nowrap; }" in html
    row = index_row("p", "p.toml", "done", design={"equilibria": [
        {"model": "rbf", "level": 0, "static_stable": True, "q": -0.01},
        {"model": "rbf", "level": 0, "static_stable": True, "q": 0.01, "identified": False},
    ]})  # fmt: skip
    row["nrmse"] = {"unseen": "16.72 % (poor: 69 % of the mean error)"}
    page = render_index([row])
    assert '<td>16.72 %<span class="note"> (poor: 69 % of the mean error)</span></td>' in page
    assert '<td>-10 mm<span class="note"> (+1 not identified)</span></td>' in page
    assert "td .note { white-space: normal; }" in page


def test_missing_stages_are_left_out(run):
    html = render_report({"workflow": "only-ingest", "stages": {"ingest": ("1" * 64, "2" * 64)}})
    parse(html)
    assert all(f">{h}</h2>" in html for h in SECTIONS)
    assert "<img" not in html and "No" in html and "digest" in html
    assert "Not run (add a [study] section)." in html
    assert run["identify"]["design"]["reason"] not in html


def test_a_figure_that_is_not_a_png_is_refused(run):
    run["figures"]["free_run"] = [("broken", b"GIF89a....")]
    with pytest.raises(ArtifactError) as err:
        render_report(run)
    assert "broken" in str(err.value)


def test_index_rows_and_page(run):
    design = run["identify"]["design"]
    rows = [
        index_row("proto-0", "fleet/proto-0.toml", "done", nrmse=run["nrmse"], design=design,
                  link="proto-0/report/report.html"),
        index_row("proto-1", "fleet/proto-1.toml", "failed", error="IdentificationError: x < y"),
    ]  # fmt: skip
    assert rows[0]["nrmse"] == {"unseen": "1.13 %"}  # the identified model's rows only
    assert rows[0]["wells"] == "-9.516 mm" and rows[0]["switching"] == "v1: 1976 V, v2: none"
    # the switching level in its input's own unit (an acceleration input)
    accel = index_row("a", "a.toml", "done", design=design, input_units=["m/s**2", "V"])
    assert accel["switching"] == "v1: 1976 m/s**2, v2: none"
    assert index_row("x", "x.toml", "done", design=design, q_unit="V")["wells"] == "-0.009516 V"
    assert rows[1]["wells"] == "-" and rows[1]["link"] is None
    html = render_index(rows)
    parser = parse(html)
    assert "1 failed" in html and "IdentificationError: x &lt; y" in html
    assert 'href="./proto-0/report/report.html"' in html and html.count("<a ") == 1
    table = [r for r in parser.rows if len(r) == 6]
    assert table[0][0] == "prototype" and table[0][3] == "NRMSE(q) unseen"
    assert table[1] == ["proto-0", "fleet/proto-0.toml", "done", "1.13 %", "-9.516 mm",
                        "v1: 1976 V, v2: none"]  # fmt: skip
    assert table[2][3] == "-"
    assert "http:" not in html and "https:" not in html and "<script" not in html
    # the NARX peer's column beside the identified model's, with the verdict it earns
    peer = [*run["nrmse"], {**run["nrmse"][0], "model": "narx", "nrmse_q": 0.005}]
    row = index_row("p", "p.toml", "done", nrmse=peer, design=design)
    assert row["narx"] == {"unseen": "0.50 %"} and "worse" in row["nrmse"]["unseen"]
    html = render_index([row])
    assert "<th>NARX NRMSE(q) unseen</th>" in html and "0.50 %" in html


def test_batch_index_links_cannot_form_a_scheme_and_forbid_script():
    """An output folder named like a URL scheme stays a folder name in the index's links,
    and the page's Content-Security-Policy forbids script."""
    import re

    rows = [index_row("x", "x.toml", "done", link="javascript:alert(document.domain)/r.html"),
            index_row("y", "y.toml", "done", link="a b/#?/r.html")]  # fmt: skip
    html = render_index(rows, pages=[("zoo table", "data:text/html,x")])
    hrefs = re.findall(r'href="([^"]*)"', html)
    assert hrefs == ["./data%3Atext/html%2Cx", "./javascript%3Aalert%28document.domain%29/r.html",
                     "./a%20b/%23%3F/r.html"]  # fmt: skip
    assert "Content-Security-Policy" in html and "default-src 'none'" in html


def test_batch_index_lists_only_identified_wells():
    """The fleet index counts a well on an unidentified part of the curve, it does not list it."""
    from debist.report.html import _wells

    rows = [
        {"model": "rbf", "level": 0, "q": -0.0105, "static_stable": True, "identified": True},
        {"model": "rbf", "level": 0, "q": -0.0014, "static_stable": True, "identified": False},
        {"model": "rbf", "level": 0, "q": 0.0113, "static_stable": True, "identified": True},
        {"model": "rbf", "level": 0, "q": 0.0008, "static_stable": False, "identified": False},
        {"model": "analytical", "level": 0, "q": 0.0102, "static_stable": True},
    ]
    assert _wells({"equilibria": rows}) == "-10.5, 11.3 mm (+1 not identified)"
    assert _wells({"equilibria": rows[:1]}) == "-10.5 mm"


def test_an_undecided_hyper_parameter_search_says_so(run):
    """The [identify.auto] line is on the page, with 'undecided' when the folds disagree."""
    import copy

    from debist.report.tables import auto_line

    assert "hyper-parameters:" not in render_report(run)
    run = copy.deepcopy(run)
    candidates = [
        {"settings": {"M": m}, "mean": mean, "se": se}
        for m, mean, se in ((6, 0.107, 0.098), (8, 0.11, 0.09))
    ]
    auto = {"chosen": {"M": 6}, "best": 0, "folds": 4, "n_candidates": 2,
            "candidates": candidates, "undecided": True}  # fmt: skip
    run["identify"]["auto"] = auto
    html = render_report(run)
    line = auto_line(run["identify"])
    assert line.startswith("hyper-parameters: M = 6, chosen among 2 candidates by blocked 4-fold")
    assert "10.7 % +- 9.8 %" in line and "undecided" in line
    assert f"<p>{line}</p>" in html
    study = html.index(SECTIONS[7])
    assert html.index("hyper-parameters:") > study  # in the hyper-parameter search section
    auto["undecided"] = False
    assert "undecided" not in auto_line(run["identify"])


def test_prediction_and_residual_checks_are_tabulated_with_their_verdicts():
    from debist.report.html import _check_rows

    rows = [
        {"model": "rbf", "dataset": "a", "k_steps": 10, "nrmse_q_k": 0.0031,
         "resid_white": False, "resid_ljung_box_p": 1e-12, "resid_cross_outside": 0.157},
        {"model": "rbf", "dataset": "b", "k_steps": 10, "nrmse_q_k": float("nan"),
         "resid_white": None, "resid_ljung_box_p": float("nan"), "resid_cross_outside": None},
        {"model": "sindy", "dataset": "a", "nrmse_q": 0.1},  # no prediction scores: no row
    ]  # fmt: skip
    assert _check_rows(rows) == [
        {"model": "rbf", "dataset": "a", "k": "10", "nrmse_k": "0.31 %",
         "white": "no (p = 1e-12)", "cross": "16 %"},
        {"model": "rbf", "dataset": "b", "k": "10", "nrmse_k": "-", "white": "not tested",
         "cross": "-"},
    ]  # fmt: skip


def test_the_data_caveats_come_before_simulation_only_in_a_verdict():
    from debist.report.tables import verdict

    row = {"nrmse_q": 0.004, "nrmse_q_baseline": 0.2, "extrapolated": "v1 applied at q = 4 mm",
           "simulation_only": "d identified nowhere"}  # fmt: skip
    assert (
        verdict(row)
        == "extrapolated: v1 applied at q = 4 mm; simulation only: d identified nowhere"
    )
    assert verdict({**row, "nrmse_q": 0.19}).endswith(
        "; poor: 95 % of the mean baseline error (a lost switch?)"
    )
