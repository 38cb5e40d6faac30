"""The zoo page of a batch report: the zoo table with its medians and worst cases.

A self-contained HTML page (no script, no external URL; a Content-Security-Policy that
forbids scripts) written beside the batch index of a zoo (:mod:`debist.engine.zootable`).
Every number says what it is: NRMSE(q) and errors in percent, ``no free run`` where a free
run diverged or the model is unstable, ``not marked`` where a curve is marked identified
nowhere.

References
----------
Masoud & Maas 2025, Eq. 41; Jinja2 documentation, "API" (``Environment(autoescape=True)``);
W3C Content Security Policy Level 3 (the ``meta`` element).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import jinja2

__all__ = ["COLUMNS", "render_zoo"]

#: Endings of the zoo table's yes/no columns (counted, not averaged, in the summary).
FLAGS = ("_lost_switch", "_near_wells", "_extrapolated")
#: Columns shown on the page: (column, heading); the table holds more.
COLUMNS = (
    ("member", "member"),
    ("plant", "plant"),
    ("friction", "friction"),
    ("sensor_average", "avg N"),
    ("estimation_profile", "estimation"),
    ("floor_unseen", "floor %"),
    ("rbf_unseen", "RBF %"),
    ("rbf_unseen_max", "RBF worst %"),
    ("rbf_lost_switch", "RBF lost switch"),
    ("unseen_extrapolated", "unseen input beyond estimation's"),
    ("narx_unseen", "NARX %"),
    ("narx_terms", "NARX terms"),
    ("narx_lag", "NARX lags"),
    ("sindy_unseen", "SINDy %"),
    ("restoring_max_error", "restoring err %"),
    ("restoring_coverage", "restoring cov %"),
    ("g1_max_error", "g1 err %"),
    ("g1_coverage", "g1 cov %"),
    ("g1_near_wells", "g1 at wells"),
    ("g2_max_error", "g2 err %"),
    ("g2_coverage", "g2 cov %"),
    ("g2_near_wells", "g2 at wells"),
    ("status", "status"),
)

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>debist zoo, seed {{ seed }}</title>
<style>
body { font-family: system-ui, sans-serif; margin: 0 auto; padding: 0.8rem; color: #111; }
table { border-collapse: collapse; font-size: 0.85rem; }
th, td { border: 1px solid #ccc; padding: 0.2rem 0.4rem; text-align: right; white-space: nowrap; }
td.text, th.text { text-align: left; }
.scroll { overflow-x: auto; }
</style>
</head>
<body>
<h1>Plant zoo, seed {{ seed }}: {{ n }} members</h1>
<p>Unseen free-run NRMSE(q) (Eq. 41, mean over each member's unseen records) of the identified
model (RBF), the NARX peer and SINDy, beside the measurement floor (logged against true q).
Curve errors are the largest |identified &minus; true| where debist marks the curve identified,
in percent of the true curve's range; coverage is the share of those points whose band holds
the truth. "not marked": marked identified nowhere. "at wells": marked within 2 mm of each
well. In the worst row a yes/no column counts the members with yes.</p>
<h2>Medians and worst cases</h2>
<div class="scroll"><table>
<tr><th class="text"></th>{% for c, h in summary_cols %}<th>{{ h }}</th>{% endfor %}</tr>
{% for label, cells in summary_rows %}<tr><th class="text">{{ label }}</th>
{% for cell in cells %}<td>{{ cell }}</td>{% endfor %}</tr>
{% endfor %}</table></div>
<h2>Members</h2>
<div class="scroll"><table>
<tr>{% for c, h in columns %}
<th class="{{ 'text' if c in text_cols else '' }}">{{ h }}</th>{% endfor %}</tr>
{% for row in rows %}<tr>{% for c, h in columns %}
<td class="{{ 'text' if c in text_cols else '' }}">{{ row[c] }}</td>{% endfor %}</tr>
{% endfor %}</table></div>
</body>
</html>
"""
_ENV = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined)
_TEXT = {"member", "plant", "friction", "estimation_profile", "status"}


def _cell(column: str, value: Any) -> str:
    """Format one cell: percent numbers to two decimals, inf as diverged, NaN as not marked."""
    if isinstance(value, bool) or column.endswith(FLAGS):
        return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) \
            else ("yes" if value else "no")  # fmt: skip
    if isinstance(value, float):
        if math.isinf(value):
            return "no free run"  # diverged or unstable: the status column says which
        if math.isnan(value):
            return "not marked" if column.endswith(("_max_error", "_coverage")) else "n/a"
        if column in ("narx_terms", "narx_lag", "sensor_average"):
            return f"{value:.0f}"
        return f"{value:.2f}"
    return str(value)


def render_zoo(table: Any, summary: Any, attrs: Mapping[str, Any]) -> str:
    """Render the zoo page.

    Parameters
    ----------
    table : pandas.DataFrame
        The zoo table (:func:`debist.engine.zootable.zoo_table`).
    summary : pandas.DataFrame
        Its medians and worst cases (:func:`debist.engine.zootable.zoo_summary`).
    attrs : mapping
        The table's attributes (``zoo``: ``seed``).

    Returns
    -------
    str
        A self-contained HTML document.
    """
    columns = [(c, h) for c, h in COLUMNS if c in table.columns]
    rows = [{c: _cell(c, r[c]) for c, _ in columns} for r in table.to_dict(orient="records")]
    summary_cols = [(c, h) for c, h in columns if c in summary.columns]
    summary_rows = []
    for label in ("median", "worst"):
        cells = []
        for c, _ in summary_cols:
            value = summary.loc[label, c]
            if c.endswith(FLAGS):
                count = int(summary.loc["count", c])
                cells.append(f"{int(value)} of {count}" if label == "worst" else "")
            else:
                cells.append(_cell(c, float(value)))
        summary_rows.append((label, cells))
    summary_rows.append(("no free run", [
        "" if c.endswith(FLAGS)
        else f"{int(summary.loc['no_free_run', c])} of {int(summary.loc['count', c])}"
        for c, _ in summary_cols]))  # fmt: skip
    seed = attrs.get("zoo", {}).get("seed", "?")
    return _ENV.from_string(_PAGE).render(
        seed=seed, n=len(table), columns=columns, rows=rows, text_cols=_TEXT,
        summary_cols=summary_cols, summary_rows=summary_rows,
    )  # fmt: skip
