"""One self-contained HTML report of a workflow run: tables, figures and provenance.

:func:`load_run` gathers what the stages wrote (summaries checked against their manifests,
PNG figures checked against their hashes), :func:`render_report` turns that into one HTML
page without any external URL or script (figures as base64 data URIs, readable on a phone,
printable), and :func:`write_report` replaces ``<output_dir>/report/report.html`` atomically.
The report is not a hashed stage: no manifest covers it, and ``debist verify`` ignores it.

References
----------
Masoud & Maas 2025, Front. Robot. AI 12 (Table 2, Fig. 12-15, Eq. 41); Jinja2 documentation,
"API" (``Environment(autoescape=True)``); RFC 2397 (the "data" URL scheme).
"""

from __future__ import annotations

import base64
import math
import os
import shlex
import shutil
import tempfile
from pathlib import Path
from typing import Any

import jinja2

from pipeline import artifacts
from pipeline.errors import ArtifactError

#: The first eight bytes of every PNG file (PNG specification, Sec. 5.2).
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
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
    "Free-run validation (NRMSE, Table 2)",
    "Identified model",
    "Equilibria and switching",
    "Excitation warnings",
    "Free-run figures",
    "SINDy equations",
    "Provenance",
)
#: Which PNG outputs of which stage are shown, and in which figure group.
FIGURE_STAGES = ("identify", "validate", "study", "analyze")

_TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>debist report: {{ workflow }}</title>
<style>
body { font-family: system-ui, sans-serif; max-width: 60rem; margin: 0 auto; padding: 0.8rem;
       line-height: 1.4; color: #111; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; border-bottom: 1px solid #ccc; }
.scroll { overflow-x: auto; }
table { border-collapse: collapse; margin: 0.5rem 0; font-size: 0.9rem; }
th, td { border: 1px solid #ccc; padding: 0.2rem 0.4rem; text-align: right; }
th:first-child, td.text { text-align: left; }
td.bad { color: #a00; font-weight: bold; }
img { width: 100%; height: auto; }
figure { margin: 0.5rem 0; }
pre, code { white-space: pre-wrap; word-break: break-all; font-size: 0.85rem; }
@media print { body { max-width: none; } figure, table { page-break-inside: avoid; } }
</style>
</head>
<body>
<h1>debist report: {{ workflow }}</h1>

<h2>{{ sections[0] }}</h2>
<p>Workflow <strong>{{ workflow }}</strong></p>
{% if datasets %}
<div class="scroll"><table>
<tr><th>data set</th><th>role</th><th>source</th></tr>
{% for d in datasets %}
<tr><td class="text">{{ d.name }}</td><td class="text">{{ d.role }}</td>
<td class="text">{{ d.source }}</td></tr>
{% endfor %}
</table></div>
{% else %}<p>No data sets.</p>{% endif %}

<h2>{{ sections[1] }}</h2>
{% if nrmse %}
<div class="scroll"><table>
<tr><th>model</th><th>data set</th>{% for h in nrmse_heads %}<th>NRMSE {{ h }}</th>{% endfor %}
<th>NRMSE q, mean baseline</th><th>status / note</th></tr>
{% for r in nrmse %}
<tr><td class="text">{{ r.model }}</td><td class="text">{{ r.dataset }}</td>
{% for c in r.cells %}<td{% if c.bad %} class="bad"{% endif %}>{{ c.text }}</td>{% endfor %}
<td>{{ r.baseline }}</td><td class="text">{{ r.note }}</td></tr>
{% endfor %}
</table></div>
{% else %}<p>Not run.</p>{% endif %}

<h2>{{ sections[2] }}</h2>
{% if model %}
<div class="scroll"><table>
<tr><th>quantity</th><th>value</th></tr>
{% for label, value in model %}
<tr><td class="text">{{ label }}</td><td>{{ value }}</td></tr>
{% endfor %}
</table></div>
{% else %}<p>Not run.</p>{% endif %}
{% for f in figures.identify %}
<figure><img src="{{ f.uri }}" alt="{{ f.caption }}"><figcaption>{{ f.caption }}</figcaption>
</figure>
{% endfor %}

<h2>{{ sections[3] }}</h2>
{% if design %}
<p>Identified model: {{ design.verdict }}{% if design.reason %} ({{ design.reason }}){% endif %}</p>
<div class="scroll"><table>
<tr><th>model</th><th>inputs [V]</th><th>q* [m]</th><th>kind</th><th>f_n [Hz]</th><th>zeta</th>
<th>barrier</th></tr>
{% for r in design.rows %}
<tr>{% for c in r %}<td{% if loop.index in (1, 4) %} class="text"{% endif %}>{{ c }}</td>
{% endfor %}</tr>
{% endfor %}
</table></div>
{% else %}<p>No design numbers.</p>{% endif %}

<h2>{{ sections[4] }}</h2>
{% if warnings %}
<ul>{% for w in warnings %}<li>{{ w }}</li>{% endfor %}</ul>
{% else %}<p>None.</p>{% endif %}

<h2>{{ sections[5] }}</h2>
{% for group in ("validate", "study", "analyze") %}{% for f in figures[group] %}
<figure><img src="{{ f.uri }}" alt="{{ f.caption }}"><figcaption>{{ f.caption }}</figcaption>
</figure>
{% endfor %}{% endfor %}
{% if not (figures.validate or figures.study or figures.analyze) %}<p>No figures.</p>{% endif %}

<h2>{{ sections[6] }}</h2>
{% if equations %}<pre>{{ equations }}</pre>{% else %}<p>Not run.</p>{% endif %}

<h2>{{ sections[7] }}</h2>
{% if digest %}
<p>Run digest: <code>{{ digest }}</code></p>
<p>Verify these artifacts with: <code>{{ verify }}</code></p>
{% else %}<p>No run digest: not every stage of the workflow has run.</p>{% endif %}
{% if stages %}
<div class="scroll"><table>
<tr><th>stage</th><th>stage key</th></tr>
{% for s, k in stages %}<tr><td class="text">{{ s }}</td><td class="text"><code>{{ k }}</code>
</td></tr>{% endfor %}
</table></div>
{% endif %}
{% if versions %}
<div class="scroll"><table>
<tr><th>library</th><th>version</th></tr>
{% for lib, v in versions %}<tr><td class="text">{{ lib }}</td><td class="text">{{ v }}</td></tr>
{% endfor %}
</table></div>
{% endif %}
<p>This page is not covered by a manifest: it is rebuilt from the hashed artifacts.</p>
</body>
</html>
"""

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
        verdict = status if status != "ok" else "diverged"
        failed = status != "ok" or bool(r.get("diverged"))
        cells = []
        for key, _ in keys:
            value = r.get(key)
            if failed or _missing(value):
                text = verdict if failed or value is not None else "-"
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
        elif not _missing(base) and not _missing(r.get("nrmse_q")) and r["nrmse_q"] >= base:
            note = "not better than the mean: q is not predicted"
        else:
            note = ""
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


def _model_rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """Quantity/value rows of the identified model (Eq. 37-40)."""
    rows = [("T_z [s]", _num(summary.get("T_z"))), ("m_q", _num(summary.get("m_q")))]
    rows += [(f"backbone {k}", _num(v)) for k, v in (summary.get("backbone") or {}).items()]
    for label, key in (
        ("condition number", "condition"),
        ("nonzero parameters", "n_params"),
        ("R^2 of Eq. 40", "fit_r2"),
    ):
        if key in summary:
            rows.append((label, _num(summary[key])))
    for name, spans in (summary.get("identified") or {}).items():
        text = ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in spans) or "nowhere"
        rows.append((f"{name} identified on q in [m]", text))
    return rows


def _design(summary: dict[str, Any]) -> dict[str, Any] | None:
    """Equilibria (wells and saddles at rest, wells at held levels) and switching rows."""
    design = summary.get("design")
    if not design:
        return None
    rows = []
    for r in design.get("equilibria", []):
        if r.get("level", 0) != 0 and not r.get("static_stable"):
            continue
        volts = ", ".join(_num(r[k]) for k in sorted(r) if k[:1] == "v" and k[1:].isdigit())
        well = bool(r.get("static_stable"))
        kind = ("well" if r.get("stable") else "well, negative damping") if well else "saddle"
        small = [_num(r.get(k)) if well else "" for k in ("f_n", "zeta", "barrier")]
        rows.append([r.get("model", ""), volts, _num(r.get("q")), kind, *small])
    for r in design.get("switching", []):
        text = f"{_num(r['v_switch'])} V" if r.get("v_switch") is not None else r.get("reason")
        label = f"switching, input {r.get('input')}"
        rows.append([r.get("model", ""), label, "", text, "", "", ""])
    return {"verdict": design.get("verdict", ""), "reason": design.get("reason", ""), "rows": rows}


def _data_uri(name: str, data: bytes) -> str:
    if not data.startswith(PNG_SIGNATURE):
        raise ArtifactError(f"figure '{name}' is not a PNG file (starts with {data[:8]!r})")
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def render_report(run: dict[str, Any]) -> str:
    """Render one self-contained HTML page of a run.

    Parameters
    ----------
    run : dict
        As :func:`load_run` returns it: ``workflow`` (name), ``datasets`` (list of dicts with
        ``name``, ``role``, ``source``), ``identify`` (the identify summary, or None),
        ``nrmse`` (rows of the validate/compare summary's ``table``; NRMSE dimensionless,
        Eq. 41), ``equations`` (the compare summary's SINDy equations, or None),
        ``figures`` (stage -> list of ``(caption, PNG bytes)``; stages ``identify``,
        ``validate``, ``study``, ``analyze``), ``digest`` (run digest or None), ``verify``
        (the command that checks it), ``stages`` (stage -> stage key) and ``versions``
        (library -> version). Missing keys are shown as not run.

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
    Masoud & Maas 2025, Table 2 (NRMSE layout), Fig. 12-15; RFC 2397 (data URLs).
    """
    identify = run.get("identify") or {}
    heads, nrmse = _nrmse_rows(run.get("nrmse") or [])
    figures = {
        stage: [
            {"caption": caption, "uri": _data_uri(caption, data)}
            for caption, data in (run.get("figures") or {}).get(stage, [])
        ]
        for stage in FIGURE_STAGES
    }
    return _ENV.from_string(_TEMPLATE).render(
        sections=SECTIONS,
        workflow=run.get("workflow", ""),
        datasets=run.get("datasets") or [],
        nrmse_heads=heads,
        nrmse=nrmse,
        model=_model_rows(identify) if identify else [],
        design=_design(identify),
        warnings=(identify.get("excitation") or {}).get("warnings", []),
        figures=figures,
        equations=run.get("equations"),
        digest=run.get("digest"),
        verify=run.get("verify", ""),
        stages=list((run.get("stages") or {}).items()),
        versions=sorted((run.get("versions") or {}).items()),
    )


def _caption(stage: str, rel: str) -> str:
    name = Path(rel).stem
    if stage == "identify":
        return f"Identified curves (Fig. 14): {rel}"
    if stage == "validate":
        return f"Free run on '{name}', measured and simulated (Fig. 12, 13, 15)"
    return f"{stage}: {rel}"


def load_run(runner, workflow_arg: str | os.PathLike | None = None) -> dict[str, Any]:
    """Read what a workflow's stages wrote into the ``run`` dict of :func:`render_report`.

    Only stages with a manifest are read; the others are left out of the report.

    Parameters
    ----------
    runner : pipeline.runner.Runner
        The workflow's runner.
    workflow_arg : path-like, optional
        The workflow file as the user names it in the verify command (default: its path).

    Returns
    -------
    dict
        The ``run`` dict (see :func:`render_report`).

    Raises
    ------
    ArtifactError
        If no stage has run, or a summary or figure does not match its manifest's sha256.
    """
    wf = runner.wf
    manifests = {}
    for stage in runner.stages():
        manifest = artifacts.read_manifest(wf.stage_dir(stage))
        if manifest is not None:
            manifests[stage] = manifest
    if not manifests:
        raise ArtifactError(
            f"workflow '{wf.name}': no stage has run in '{wf.output_dir}' (run `debist run` first)"
        )
    summaries = {s: artifacts.read_summary(wf.stage_dir(s), m) for s, m in manifests.items()}
    figures: dict[str, list[tuple[str, bytes]]] = {}
    for stage in FIGURE_STAGES:
        if stage not in manifests:
            continue
        rels = sorted(r for r in manifests[stage].outputs if r.endswith(".png"))
        if stage == "identify":
            rels = [r for r in rels if r == "plots/curves.png"]
        elif stage == "validate":
            rels = [r for r in rels if r.startswith("plots/")]
        for rel in rels:
            path = wf.stage_dir(stage) / rel
            data = path.read_bytes() if path.is_file() else b""
            if artifacts.sha256_bytes(data) != manifests[stage].outputs[rel]:
                raise ArtifactError(
                    f"'{path}' is missing or changed since the stage wrote it (run `debist verify`)"
                )
            figures.setdefault(stage, []).append((_caption(stage, rel), data))
    versions: dict[str, set[str]] = {}
    for manifest in manifests.values():
        for lib, version in manifest.versions.items():
            versions.setdefault(lib, set()).add(str(version))
    last = next((s for s in ("compare", "validate") if s in summaries), None)
    digest = runner.digest()
    arg = str(workflow_arg if workflow_arg is not None else wf.path)
    datasets = []
    for d in wf.datasets:
        source = d.rig or os.path.relpath(d.source, wf.path.parent)
        datasets.append({"name": d.name, "role": d.role, "source": str(source)})
    return {
        "workflow": wf.name,
        "datasets": datasets,
        "identify": summaries.get("identify"),
        "nrmse": summaries[last].get("table", []) if last else [],
        "equations": summaries.get("compare", {}).get("equations"),
        "figures": figures,
        "digest": digest,
        "verify": f"debist verify {shlex.quote(arg)} --digest {digest}" if digest else "",
        "stages": {s: m.key for s, m in manifests.items()},
        "versions": {lib: " / ".join(sorted(v)) for lib, v in versions.items()},
    }


def write_report(folder: str | os.PathLike, html: str) -> Path:
    """Write ``report.html`` into a folder, replacing an older one atomically.

    Parameters
    ----------
    folder : path-like
        Target folder (created if missing), normally ``<output_dir>/report``.
    html : str
        The page (:func:`render_report`).

    Returns
    -------
    pathlib.Path
        The file written.

    References
    ----------
    POSIX ``rename(2)``: the new file replaces the old one in one step, so a reader never
    sees half a page.
    """
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".report.tmp-", dir=target))
    try:
        (written,) = artifacts.write_text_files(tmp, {"report.html": html})
        os.replace(written, target / "report.html")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target / "report.html"
