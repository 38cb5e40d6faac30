"""One self-contained HTML report of a workflow run: tables, figures and provenance.

:func:`render_report` turns the results of a run (the stages' summaries, figures and
provenance, gathered by the report stage :mod:`debist.stages.report` from hashed
artifacts only) into one HTML page without any external URL or script: figures as base64
data URIs, readable on a phone, printable. The page is the report stage's artifact
(``<output_dir>/report/report.html``), covered by its manifest and checked by ``debist
verify``. :func:`render_index` is the index page of a batch: one row per prototype, linking
each prototype's report.

References
----------
Masoud & Maas 2025, Front. Robot. AI 12 (Table 2, Fig. 11-15, Eq. 41); Jinja2 documentation,
"API" (``Environment(autoescape=True)``); RFC 2397 (the "data" URL scheme).
"""

from __future__ import annotations

import base64
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jinja2

from debist.core.errors import ArtifactError
from debist.core.fileformats import atomic_write
from debist.report.tables import (
    auto_line,
    display_summary,
    equilibrium_kind,
    identified_text,
    mass_rows,
    not_modelled,
    sindy_units,
    small_signal_cells,
    stiffness_caption,
    summary_units,
    switching_note,
    switching_word,
    term_rows,
    verdict,
)
from debist.workflow.sections import ReportConfig

__all__ = [
    "FIGURE_GROUPS",
    "INDEX_FILE",
    "NRMSE_COLUMNS",
    "PNG_SIGNATURE",
    "REPORT_FILE",
    "SECTIONS",
    "ReportConfig",
    "index_row",
    "render_index",
    "render_report",
    "write_page",
]

#: The first eight bytes of every PNG file (PNG specification, Sec. 5.2).
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The report stage's page (relative to its stage folder).
REPORT_FILE = "report.html"
#: The batch index page's file name.
INDEX_FILE = "index.html"
#: NRMSE columns of Table 2, in the paper's order (summary key, heading).
NRMSE_COLUMNS = (
    ("nrmse_q", "q"),
    ("nrmse_phi", "phi"),
    ("nrmse_q_dot", "q_dot"),
    ("nrmse_q_ddot", "q_ddot"),
)
#: Section headings, in page order (the tests check each of them).
SECTIONS = (
    "Workflow and data sets",
    "Excitation (Fig. 11a)",
    "Free-run validation (NRMSE, Table 2)",
    "Free runs (Fig. 12, 13, 15)",
    "Identified model (Fig. 14)",
    "Equilibria and switching",
    "Excitation warnings",
    "Hyper-parameter search (Fig. 11b, 11c)",
    "Design analysis (Fig. 3-7)",
    "SINDy equations",
    "Provenance",
)
#: Figure groups of :func:`render_report`, each shown in its section.
FIGURE_GROUPS = ("excitation", "free_run", "identify", "study", "analyze")


#: The tables' style of the report and the batch index: one place (wide tables scroll with an
#: edge shadow, and a note says so on a phone-sized screen; numbers never wrap: a wrapped
#: "-1.351e-13" reads as two numbers; the verdict after a number, in a ``note`` span, does).
_TABLE_CSS = """\
.scroll { overflow-x: auto; background:
  linear-gradient(to right, #fff 30%, rgba(255,255,255,0)) left / 2rem 100% no-repeat local,
  linear-gradient(to left, #fff 30%, rgba(255,255,255,0)) right / 2rem 100% no-repeat local,
  radial-gradient(farthest-side at 0 50%, rgba(0,0,0,.3), rgba(0,0,0,0)) left / .8rem 100%
    no-repeat scroll,
  radial-gradient(farthest-side at 100% 50%, rgba(0,0,0,.3), rgba(0,0,0,0)) right / .8rem 100%
    no-repeat scroll; }
.scrollnote { display: none; font-size: 0.8rem; color: #555; }
@media (max-width: 40rem) { .scrollnote { display: block; } td.text { min-width: 6rem; } }
table { border-collapse: collapse; margin: 0.5rem 0; font-size: 0.9rem; }
th, td { border: 1px solid #ccc; padding: 0.2rem 0.4rem; text-align: right; vertical-align: top; }
td:not(.text) { white-space: nowrap; }
td .note { white-space: normal; }
th:first-child, td.text { text-align: left; }
td.bad { color: #a00; font-weight: bold; }
"""


_TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>debist report: {{ workflow }}</title>
<style>
body { font-family: system-ui, sans-serif; max-width: 60rem; margin: 0 auto; padding: 0.8rem;
       line-height: 1.4; color: #111; background: #fff; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; border-bottom: 1px solid #ccc; }
/*TABLE_CSS*/
img { max-width: 100%; height: auto; }
figure { margin: 0.5rem 0; }
nav a { margin-right: 0.6rem; white-space: nowrap; }
pre, code { white-space: pre-wrap; overflow-wrap: anywhere; font-size: 0.85rem; }
@media print { body { max-width: none; } nav { display: none; }
               figure, table { page-break-inside: avoid; } }
</style>
</head>
<body>
<h1>debist report: {{ workflow }}</h1>
<nav>{% for h in sections %}<a href="#s{{ loop.index }}">{{ h }}</a> {% endfor %}</nav>

<h2 id="s1">{{ sections[0] }}</h2>
<p>Workflow <strong>{{ workflow }}</strong></p>
{% if simulation_only %}<p><strong>simulation only: {{ simulation_only }}</strong>: the identified
model's free run may be scored, but these curves are not the beam's physics.</p>{% endif %}
{% if datasets %}
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>data set</th><th>role</th><th>source</th><th>samples</th><th>duration [s]</th></tr>
{% for d in datasets %}
<tr><td class="text">{{ d.name }}</td><td class="text">{{ d.role }}</td>
<td class="text">{{ d.source }}</td><td>{{ d.samples }}</td><td>{{ d.duration }}</td></tr>
{% endfor %}
</table></div>
{% else %}<p>No data sets.</p>{% endif %}

<h2 id="s2">{{ sections[1] }}</h2>
{{ show(figures.excitation, "Not run.") }}

<h2 id="s3">{{ sections[2] }}</h2>
{% if nrmse %}
<p>NRMSE of the free run (Eq. 41); the last number is that of the trivial model that predicts
the mean of q (a model is only useful below it).</p>
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>model</th><th>data set</th>{% for h in nrmse_heads %}<th>NRMSE {{ h }}</th>{% endfor %}
<th>NRMSE q, mean baseline</th><th>verdict</th></tr>
{% for r in nrmse %}
<tr><td class="text">{{ r.model }}</td><td class="text">{{ r.dataset }}</td>
{% for c in r.cells %}<td{% if c.bad %} class="bad"{% endif %}>{{ c.text }}</td>{% endfor %}
<td>{{ r.baseline }}</td><td class="text">{{ r.note }}</td></tr>
{% endfor %}
</table></div>
{% if checks %}
<p>The checks of MATLAB's <code>predict</code> and <code>resid</code>: NRMSE of the prediction
k samples ahead from the measured state (the friction state filtered from q_dot), and the
one-step prediction errors tested for whiteness (Ljung-Box at 99 %) and for correlation with
each input (share of lags 0-25 outside the 99 % limits; a model that misses an input's effect
leaves its errors correlated with it).</p>
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>model</th><th>data set</th><th>k [samples]</th><th>NRMSE q, k-step</th>
<th>one-step errors white (Ljung-Box p)</th>
<th>lags outside the input cross-correlation limits</th></tr>
{% for r in checks %}
<tr><td class="text">{{ r.model }}</td><td class="text">{{ r.dataset }}</td><td>{{ r.k }}</td>
<td>{{ r.nrmse_k }}</td><td class="text">{{ r.white }}</td><td>{{ r.cross }}</td></tr>
{% endfor %}
</table></div>
{% endif %}
{% else %}<p>Not run.</p>{% endif %}

<h2 id="s4">{{ sections[3] }}</h2>
{{ show(figures.free_run, "Not run.") }}

<h2 id="s5">{{ sections[4] }}</h2>
{% if model %}
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>quantity</th><th>value</th></tr>
{% for label, value in model %}
<tr><td class="text">{{ label }}</td><td>{{ value }}</td></tr>
{% endfor %}
</table></div>
{% else %}<p>Not run.</p>{% endif %}
{{ show(figures.identify, "") }}

<h2 id="s6">{{ sections[5] }}</h2>
{% if design %}
<p>Identified model: {{ design.verdict }}{% if design.reason %} ({{ design.reason }}){% endif %}</p>
<p>Equilibria and switching levels ({{ design.title }}); at each well the total damping d(q*),
the tangent stiffness k* = dF/dq and the small-signal natural frequency
f_n = sqrt(k*/m_q)/(2 pi); {{ design.k_band }}.</p>
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>model</th><th>inputs [{{ design.inputs }}]</th><th>q* [{{ design.q_unit }}]</th>
<th>kind</th><th>d(q*) [{{ design.damping }}]</th><th>k* [{{ design.stiffness }}]</th>
<th>f_n [Hz]</th><th>zeta</th><th>barrier [{{ design.barrier }}]</th></tr>
{% for r in design.rows %}
<tr>{% for c in r %}<td{% if loop.index in (1, 4) %} class="text"{% endif %}>{{ c }}</td>
{% endfor %}</tr>
{% endfor %}
</table></div>
{% else %}<p>No design numbers.</p>{% endif %}

<h2 id="s7">{{ sections[6] }}</h2>
{% if warnings %}
<ul>{% for w in warnings %}<li>{{ w }}</li>{% endfor %}</ul>
{% else %}<p>None.</p>{% endif %}

<h2 id="s8">{{ sections[7] }}</h2>
{% if auto %}<p>{{ auto }}</p>{% endif %}
{{ show(figures.study, "Not run (add a [study] section).") }}

<h2 id="s9">{{ sections[8] }}</h2>
{{ show(figures.analyze, "Not run (add an [analyze] section).") }}

<h2 id="s10">{{ sections[9] }}</h2>
{% if equations %}<pre>{{ equations }}</pre>
<p>Coefficients as fitted, in SI: {{ sindy_units }}.</p>{% else %}<p>Not run.</p>{% endif %}

<h2 id="s11">{{ sections[10] }}</h2>
{% if digest %}
<p>Digest of the stages shown: <code>{{ digest }}</code>. It differs from the run digest
that <code>debist run</code> printed, and must: the run digest also covers this page's own
manifest, which a page cannot contain.</p>
{% else %}<p>No digest: not every stage shown has run.</p>{% endif %}
{% if verify %}<p>Verify this page and the artifacts it shows with: <code>{{ verify }}</code>
(in the workflow's folder; add <code>--digest</code> with the run digest that
<code>debist run</code> printed, which covers this page's manifest too).</p>{% endif %}
{% if stages %}
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>stage</th><th>stage key</th><th>manifest sha256</th></tr>
{% for s in stages %}<tr><td class="text">{{ s.name }}</td><td class="text"><code>{{ s.key }}</code>
</td><td class="text"><code>{{ s.manifest }}</code></td></tr>{% endfor %}
</table></div>
{% endif %}
{% if versions %}
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>library</th><th>version</th></tr>
{% for lib, v in versions %}<tr><td class="text">{{ lib }}</td><td class="text">{{ v }}</td></tr>
{% endfor %}
</table></div>
{% endif %}
<p>This page is the report stage's artifact: built from the hashed artifacts above only, and
covered by <code>report/manifest.json</code>.</p>
</body>
</html>
"""

_MACROS = """{% macro show(items, empty) %}
{% for f in items %}
<figure><img src="{{ f.uri }}" width="{{ f.width }}" alt="{{ f.caption }}">
<figcaption>{{ f.caption }}</figcaption>
</figure>
{% endfor %}
{% if not items and empty %}<p>{{ empty }}</p>{% endif %}
{% endmacro %}
"""

_INDEX = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'">
<title>debist batch: {{ rows|length }} prototypes</title>
<style>
body { font-family: system-ui, sans-serif; max-width: 72rem; margin: 0 auto; padding: 0.8rem;
       line-height: 1.4; color: #111; background: #fff; }
h1 { font-size: 1.5rem; }
/*TABLE_CSS*/
</style>
</head>
<body>
<h1>debist batch: {{ rows|length }} prototypes, {{ failed }} failed</h1>
<p>One row per prototype: the free-run NRMSE(q) of the identified model on each data set
(Eq. 41), its wells at rest and its switching levels (in each input's unit). Each name links
to the prototype's report.</p>
{% if pages %}<p>Also in this batch report: {% for label, href in pages %}<a href="{{ href }}">\
{{ label }}</a>{% if not loop.last %}, {% endif %}{% endfor %}.</p>{% endif %}
{% macro cell(text) %}{% set head, sep, tail = text.partition(" (") %}{{ head }}\
{% if sep %}<span class="note"> ({{ tail }}</span>{% endif %}{% endmacro %}
<p class="scrollnote">wide table: scroll sideways &rarr;</p><div class="scroll"><table>
<tr><th>prototype</th><th>workflow file</th><th>status</th>
{% for d in datasets %}<th>NRMSE(q) {{ d }}</th>{% endfor %}
{% for d in narx_datasets %}<th>NARX NRMSE(q) {{ d }}</th>{% endfor %}
<th>wells q* at rest</th><th>switching levels</th></tr>
{% for r in rows %}
<tr><td class="text">{% if r.link %}<a href="{{ r.link }}">{{ r.name }}</a>{% else %}{{ r.name }}\
{% endif %}</td><td class="text">{{ r.file }}</td>
<td class="text{% if r.status != 'done' %} bad{% endif %}">{{ r.status }}{% if r.error %}: \
{{ r.error }}{% endif %}{% if r.note %} ({{ r.note }}){% endif %}</td>
{% for d in datasets %}<td>{{ cell(r.nrmse.get(d, "-")) }}</td>{% endfor %}
{% for d in narx_datasets %}<td>{{ cell(r.narx.get(d, "-")) }}</td>{% endfor %}
<td>{{ cell(r.wells) }}</td><td class="text">{{ r.switching }}</td></tr>
{% endfor %}
</table></div>
</body>
</html>
"""

_TEMPLATE = _TEMPLATE.replace("/*TABLE_CSS*/\n", _TABLE_CSS)
_INDEX = _INDEX.replace("/*TABLE_CSS*/\n", _TABLE_CSS)
_ENV = jinja2.Environment(autoescape=True, trim_blocks=True, lstrip_blocks=True)


def _num(value: Any, digits: int = 4) -> str:
    """Format a number with ``digits`` significant digits ("-" for None, "diverged" for NaN)."""
    if value is None:
        return "-"
    if isinstance(value, float) and math.isnan(value):
        return "diverged"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    if isinstance(value, list):
        return ", ".join(_num(v, digits) for v in value)
    return str(value)


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def _nrmse_rows(rows: list[dict[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    """Rows of the NRMSE table: percentages, or the row's verdict instead of numbers."""
    keys = [(k, h) for k, h in NRMSE_COLUMNS if any(k in r for r in rows)]
    out = []
    for r in rows:
        status = r.get("status") or "ok"
        failure = status if status != "ok" else "diverged"
        failed = status != "ok" or bool(r.get("diverged"))
        cells = []
        for key, _ in keys:
            value = r.get(key)
            if not_modelled(r, key):
                cells.append({"text": "n/a", "bad": False})
            elif failed or _missing(value):
                text = failure if failed or value is not None else "-"
                cells.append({"text": text, "bad": text != "-"})
            else:
                cells.append({"text": f"{100 * value:.2f} %", "bad": False})
        base = r.get("nrmse_q_baseline")
        reason = r.get("reason")
        reason = "" if _missing(reason) else str(reason)
        if status != "ok":
            note = f"{status}: {reason}" if reason else status
        elif failed:
            note = "diverged: left twice the estimation range"
        else:
            note = verdict(r, rows)
        out.append(
            {
                "model": r.get("model", ""),
                "dataset": r.get("dataset", ""),
                "cells": cells,
                "baseline": "-" if _missing(base) else f"{100 * base:.2f} %",
                "note": note,
            }
        )
    return [h for _, h in keys], out


def _check_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, str]]:
    """Rows of the prediction and residual checks (validate's ``nrmse_q_k``, ``resid_*``)."""
    out = []
    for r in rows:
        if r.get("k_steps") is None or _missing(r.get("k_steps")):
            continue
        white, p = r.get("resid_white"), r.get("resid_ljung_box_p")
        cross = r.get("resid_cross_outside")
        out.append(
            {
                "model": str(r.get("model", "")),
                "dataset": str(r.get("dataset", "")),
                "k": str(int(r["k_steps"])),
                "nrmse_k": "-" if _missing(r.get("nrmse_q_k")) else f"{100 * r['nrmse_q_k']:.2f} %",
                "white": "not tested"
                if white is None or _missing(p)
                else f"{'yes' if white else 'no'} (p = {p:.2g})",
                "cross": "-" if _missing(cross) else f"{100 * cross:.0f} %",
            }
        )
    return out


def _model_rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """Quantity/value rows of the identified model (Eq. 37-40), every one with its unit.

    The backbone's coefficients are basis coefficients of the fit (the RBF sums add to
    them), not the physics of the beam: they are labelled so, with their units.
    """
    units = summary_units(summary)
    rows = [
        ("T_z [s]", _num(summary.get("T_z"))),
        *(
            (f"{label} [{unit}]", _num(value))
            for label, unit, value, _ in mass_rows(summary, units["mass"])
        ),
    ]
    for key, value in (summary.get("backbone") or {}).items():
        unit = units.get(key)
        if isinstance(unit, list):
            unit = ", ".join(dict.fromkeys(unit))
        label = f"backbone coefficient {key} (a basis term, not a physical constant)"
        rows.append((f"{label} [{unit or '?'}]", _num(value)))
    rows += [(f"{label} [{unit}]", _num(value)) for label, unit, value in term_rows(summary)]
    for label, key in (
        ("condition number", "condition"),
        ("nonzero parameters", "n_params"),
        ("R^2 of Eq. 40", "fit_r2"),
    ):
        if key in summary:
            rows.append((label, _num(summary[key])))
    for name, spans in (summary.get("identified") or {}).items():
        rows.append(
            (f"{name} identified on q in [{units['q']}]", identified_text(name, spans, summary))
        )
    return rows


def _design(summary: dict[str, Any]) -> dict[str, Any] | None:
    """Equilibria (wells and saddles at rest, wells at held levels) and switching rows."""
    design = summary.get("design")
    if not design:
        return None

    units = summary_units(summary)  # q in the report unit (display_summary)
    rows = []
    for r in design.get("equilibria", []):
        if r.get("level", 0) != 0 and not r.get("static_stable"):
            continue
        volts = ", ".join(_num(r[k]) for k in sorted(r) if k[:1] == "v" and k[1:].isdigit())
        small = small_signal_cells(r, _num)
        rows.append([r.get("model", ""), volts, _num(r.get("q")), equilibrium_kind(r), *small])
    for r in design.get("switching", []):
        unit = dict(enumerate(units["inputs"], 1)).get(r.get("input"), "V")
        value = r.get("v_switch")
        text = f"{_num(value)} {unit}" if value is not None else r.get("reason")
        text += switching_note(r)
        label = f"{switching_word(units, r.get('input', 0))}, input {r.get('input')}"
        rows.append([r.get("model", ""), label, "", text, *[""] * 5])
    analytical = any(r.get("model") == "analytical" for r in design.get("equilibria", []))
    return {
        "title": "identified beside analytical" if analytical else "identified",
        "damping": units["damping"],
        "stiffness": units["stiffness"],
        "verdict": design.get("verdict", ""),
        "reason": design.get("reason", ""),
        "rows": rows,
        "q_unit": units["q"],
        "inputs": ", ".join(dict.fromkeys(units["inputs"])) or "V",
        "barrier": units["barrier"],
        "k_band": stiffness_caption(summary),
    }


def _simulation_only(rows: Sequence[Mapping[str, Any]]) -> str:
    """Return the identified model's ``simulation_only`` words from its NRMSE rows, or ``""``."""
    said = [r.get("simulation_only") for r in rows if r.get("model") == "rbf"]
    return next((w for w in said if isinstance(w, str) and w), "")


def _data_uri(name: str, data: bytes) -> str:
    if not data.startswith(PNG_SIGNATURE):
        raise ArtifactError(f"figure '{name}' is not a PNG file (starts with {data[:8]!r})")
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _shown_width(data: bytes) -> int:
    """Half a PNG's pixel width (its IHDR chunk): the CSS width that shows it at 2x."""
    return max(1, int.from_bytes(data[16:20], "big") // 2)


def render_report(run: dict[str, Any]) -> str:
    """Render one self-contained HTML page of a run.

    Parameters
    ----------
    run : dict
        As :func:`debist.stages.report.run_report` builds it: ``workflow`` (name),
        ``datasets`` (list of dicts with ``name``, ``role``, ``source``,
        ``samples``, ``duration`` [s]), ``identify`` (the identify summary, or None),
        ``nrmse`` (rows of the validate/compare summary's ``table``; NRMSE dimensionless,
        Eq. 41), ``equations`` (the compare summary's SINDy equations, or None),
        ``figures`` (group of :data:`FIGURE_GROUPS` -> list of ``(caption, PNG bytes)``),
        ``digest`` (digest of the stages shown, or None), ``report_unit`` (``[validate]
        report_unit``: q, its ranges and what is per length of q are shown in it,
        :func:`debist.report.tables.display_summary`), ``verify`` (the command that
        checks them), ``stages`` (stage -> ``(stage key, manifest sha256)``) and
        ``versions`` (library -> version). Missing keys are shown as not run.

    Returns
    -------
    str
        The HTML document: no external URL, no script; figures as base64 data URIs.

    Raises
    ------
    ArtifactError
        If a figure is not a PNG file.

    References
    ----------
    Masoud & Maas 2025, Table 2 (NRMSE layout), Fig. 11-15; RFC 2397 (data URLs).
    """
    identify = display_summary(run.get("identify") or {}, run.get("report_unit"))
    heads, nrmse = _nrmse_rows(run.get("nrmse") or [])
    figures = {
        group: [
            {"caption": caption, "uri": _data_uri(caption, data), "width": _shown_width(data)}
            for caption, data in (run.get("figures") or {}).get(group, [])
        ]
        for group in FIGURE_GROUPS
    }
    stages = [
        {"name": name, "key": key, "manifest": manifest}
        for name, (key, manifest) in (run.get("stages") or {}).items()
    ]
    return _ENV.from_string(_MACROS + _TEMPLATE).render(
        sections=SECTIONS,
        workflow=run.get("workflow", ""),
        datasets=run.get("datasets") or [],
        nrmse_heads=heads,
        nrmse=nrmse,
        checks=_check_rows(run.get("nrmse") or []),
        model=_model_rows(identify) if identify else [],
        design=_design(identify),
        simulation_only=_simulation_only(run.get("nrmse") or []),
        warnings=(identify.get("excitation") or {}).get("warnings", []),
        auto=auto_line(identify) if identify else "",
        figures=figures,
        equations=run.get("equations"),
        sindy_units=sindy_units(identify),
        digest=run.get("digest"),
        verify=run.get("verify", ""),
        stages=stages,
        versions=sorted((run.get("versions") or {}).items()),
    )


def _wells(design: Mapping[str, Any] | None, unit: str = "m") -> str:
    """Return the identified model's wells at rest, ascending (in mm for q in m).

    Wells where the restoring force is not identified are counted, not listed.
    """
    rows = (design or {}).get("equilibria", [])
    at_rest = [
        r
        for r in rows
        if r.get("model") == "rbf" and r.get("level", 0) == 0 and r.get("static_stable")
    ]
    wells = sorted(r["q"] for r in at_rest if r.get("identified", True))
    spurious = len(at_rest) - len(wells)
    note = f" (+{spurious} not identified)" if spurious else ""
    if not wells:
        return "-" + note
    factor, label = (1e3, "mm") if unit == "m" else (1.0, unit)
    return ", ".join(f"{factor * q:.4g}" for q in wells) + f" {label}" + note


def _switching(design: Mapping[str, Any] | None, units: Sequence[str] = ()) -> str:
    """Return the identified model's switching level per input with its unit (or "none")."""
    parts = []
    for r in (design or {}).get("switching", []):
        if r.get("model") != "rbf":
            continue
        value, i = r.get("v_switch"), int(r.get("input", 0))
        unit = units[i - 1] if 0 < i <= len(units) else "V"
        text = f"{value:.4g} {unit}" if not _missing(value) else "none"
        text += " (not identified)" if not _missing(value) and r.get("identified") is False else ""
        parts.append(f"v{i}: {text}")
    return ", ".join(parts) or "-"


def _index_scores(nrmse: Sequence[Mapping[str, Any]], model: str) -> dict[str, str]:
    """One model's NRMSE(q) per data set as index cells: a percentage with its verdict."""
    scores = {}
    for r in nrmse:
        if r.get("model") != model:
            continue
        status_r = r.get("status") or "ok"
        value = r.get("nrmse_q")
        if status_r != "ok":
            scores[r["dataset"]] = status_r
        elif r.get("diverged") or _missing(value):
            scores[r["dataset"]] = "diverged"
        else:
            word = verdict(r, list(nrmse))
            scores[r["dataset"]] = f"{100 * value:.2f} %" + ("" if word == "ok" else f" ({word})")
    return scores


def index_row(
    name: str,
    file: str,
    status: str,
    *,
    error: str = "",
    nrmse: Sequence[Mapping[str, Any]] = (),
    design: Mapping[str, Any] | None = None,
    q_unit: str = "m",
    input_units: Sequence[str] = (),
    link: str | None = None,
    note: str = "",
) -> dict[str, Any]:
    """One prototype's row of the batch index page.

    Parameters
    ----------
    name : str
        ``[workflow] name``.
    file : str
        The workflow file as shown.
    status : {"done", "failed"}
        How its run ended.
    error : str, optional
        The error of a failed run.
    nrmse : sequence of dict, optional
        Rows of its NRMSE table (the validate or compare summary's ``table``); the
        ``rbf`` rows are shown, and the ``narx`` rows (the black-box peer) beside them
        (NRMSE dimensionless, Eq. 41).
    design : dict, optional
        The identify summary's ``design`` (equilibria and switching levels [SI]).
    q_unit : str, optional
        SI unit of q (wells in m are shown in mm).
    input_units : sequence of str, optional
        SI unit of each input (the switching levels are shown in it; V where not given).
    link : str, optional
        Relative URL of its report page (None: no report).
    note : str, optional
        What else happened to the run (a worker process that died and a retry).

    Returns
    -------
    dict
        The row for :func:`render_index`: ``nrmse`` maps data set to a percentage text
        (``"unstable"``, ``"diverged"`` instead where that is the verdict; ``narx`` the
        same for the NARX peer), ``wells`` the
        wells at rest with their unit, ``switching`` the switching level per input with its
        unit.
    """
    scores = _index_scores(nrmse, "rbf")
    narx = _index_scores(nrmse, "narx")
    return {
        "name": name,
        "file": file,
        "status": status,
        "error": error,
        "note": note,
        "nrmse": scores,
        "narx": narx,
        "wells": _wells(design, q_unit),
        "switching": _switching(design, input_units),
        "link": link,
    }


def render_index(rows: Sequence[Mapping[str, Any]], pages: Sequence[tuple[str, str]] = ()) -> str:
    """Render the batch index page: one row per prototype, linking each report.

    Parameters
    ----------
    rows : sequence of dict
        :func:`index_row` per prototype, in the batch's order.
    pages : sequence of (str, str), optional
        Other pages of the batch report: label and relative URL (e.g. the zoo table).

    Returns
    -------
    str
        A self-contained HTML document (no script, no external URL; the links are relative,
        :func:`relative_href`, and a Content-Security-Policy forbids script).

    References
    ----------
    Jinja2 documentation, "API" (autoescaping).
    """
    datasets: list[str] = []
    narx: list[str] = []
    for r in rows:
        datasets += [d for d in r["nrmse"] if d not in datasets]
        narx += [d for d in r.get("narx", {}) if d not in narx]
    failed = sum(r["status"] != "done" for r in rows)
    rows = [{**r, "link": relative_href(r["link"]) if r.get("link") else None} for r in rows]
    pages = [(label, relative_href(href)) for label, href in pages]
    return _ENV.from_string(_INDEX).render(
        rows=rows, datasets=datasets, narx_datasets=narx, failed=failed, pages=pages
    )


def relative_href(path: str) -> str:
    """Turn a relative file path into a link that can only name a file below the page.

    Each segment is percent-encoded (a ``:``, ``?`` or ``#`` in a folder name is a
    character of the name, not a scheme, query or fragment) and the result starts with
    ``./``, so that no first segment can be read as a scheme (``javascript:...``).

    Parameters
    ----------
    path : str
        A POSIX path relative to the page's folder.

    Returns
    -------
    str
        The URL reference.

    Raises
    ------
    ValueError
        For an absolute path.

    References
    ----------
    RFC 3986, Sec. 2.1 (percent-encoding) and Sec. 4.2 (a relative-path reference whose
    first segment contains a colon is preceded by "./").

    Examples
    --------
    >>> relative_href("javascript:alert(1)/report/report.html")
    './javascript%3Aalert%281%29/report/report.html'
    """
    from urllib.parse import quote

    if path.startswith("/"):
        raise ValueError(f"not a relative path: {path!r}")
    return "./" + "/".join(quote(part, safe="") for part in path.split("/"))


def write_page(path: str | os.PathLike, html: str) -> Path:
    """Write an HTML page that is not a stage artifact (the batch index), atomically.

    Parameters
    ----------
    path : path-like
        The file; its folder is created, an older page of that name is replaced.
    html : str
        The page.

    Returns
    -------
    pathlib.Path
        The file written.

    References
    ----------
    POSIX ``rename(2)``: the new file replaces the old one in one step, so a reader never
    sees half a page.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(target, html)
