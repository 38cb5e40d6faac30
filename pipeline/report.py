"""Terminal reports of a workflow's results: rich tables built from the stages' summaries.

Every number printed comes from a stage's ``summary.json``, read only after its sha256 was
checked against the stage's manifest (:func:`pipeline.artifacts.read_summary`); wall times,
which no hash covers, are not printed here.
"""

from __future__ import annotations

import math
from typing import Any

from rich.markup import escape
from rich.table import Table

#: How identified quantities are labelled in reports (summary key -> label, unit note).
PARAMETER_LABELS = {
    "m_q": "mass m_q",
    "d_v": "viscous friction d_v",
    "F_c": "Coulomb friction F_c",
    "F_0": "offset force F_0",
    "k_1": "linear spring k_1",
    "k_3": "cubic spring k_3",
    "s_c": "scale of the analytical c(q) q, s_c",
    "s_d": "scale of the analytical d(q), s_d",
}


def _fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and math.isnan(value):
        return "diverged"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def identify_table(summary: dict[str, Any]) -> Table:
    """Tabulate the identified model, with published values where the workflow gives them.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title="Identified model (Eq. 37-40)")
    published = summary.get("published") or {}
    table.add_column("quantity")
    table.add_column("identified", justify="right")
    if published:
        table.add_column("published", justify="right")
    scalars = {"T_z [s]": summary["T_z"], "m_q": summary["m_q"]}
    scalars.update({k: v for k, v in summary["backbone"].items() if not isinstance(v, list)})
    rows = [(escape("T_z [s]"), summary["T_z"])]
    rows += [(PARAMETER_LABELS.get(k, k), v, k) for k, v in scalars.items() if k != "T_z [s]"]
    for row in rows:
        label, value = row[0], row[1]
        key = row[2] if len(row) > 2 else None
        cells = [label, _fmt(value)]
        if published:
            cells.append(_fmt(published.get(key)) if key else "")
        table.add_row(*cells)
    for label, key in [
        ("condition number", "condition"),
        ("rank / columns", None),
        ("nonzero parameters", "n_params"),
        ("R^2 of Eq. 40", "fit_r2"),
    ]:
        value = f"{summary['rank']} / {summary['n_columns']}" if key is None else _fmt(summary[key])
        table.add_row(label, value, *([""] if published else []))
    for name, spans in (summary.get("identified") or {}).items():
        text = ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in spans) or "nowhere"
        table.add_row(f"{name} identified on q in", text, *([""] if published else []))
    refine = summary.get("refine")
    if refine:
        pad = [""] if published else []
        verdict = "accepted" if refine["accepted"] else "rejected (not better on the full records)"
        table.add_row(
            "free-run RMS, windows: equation error", _fmt(refine["window_rms_equation_error"]), *pad
        )
        table.add_row(
            "free-run RMS, windows: simulation error",
            _fmt(refine["window_rms_simulation_error"]),
            *pad,
        )
        table.add_row(
            "free-run RMS, estimation: equation error",
            _fmt(refine["full_rms_equation_error"]),
            *pad,
        )
        table.add_row(
            "free-run RMS, estimation: simulation error",
            _fmt(refine["full_rms_simulation_error"]),
            *pad,
        )
        table.add_row(
            "refinement",
            f"{verdict}, {refine['nfev']} evaluations",
            *pad,
        )
    return table


def nrmse_table(rows: list[dict[str, Any]]) -> Table:
    """Tabulate NRMSE (Eq. 41, Table 2 of the paper) per data set and model.

    Parameters
    ----------
    rows : list of dict
        Rows of ``nrmse.parquet``.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title="Free-run validation (NRMSE, Eq. 41)")
    params = bool(rows) and "n_params" in rows[0]
    keys = ["nrmse_q", "nrmse_phi", "nrmse_q_dot", "nrmse_q_ddot"]
    keys = [k for k in keys if rows and k in rows[0]]
    cols = ["data set", "role", "model"]
    cols += [f"NRMSE({k.removeprefix('nrmse_')})" for k in keys] + ["RMS(q)"]
    for col in cols + (["params"] if params else []):
        table.add_column(col, justify="left" if col in ("data set", "role", "model") else "right")
    table.add_column("note")
    for r in rows:
        status = r.get("status") or "diverged"
        failed = status if status != "ok" else "diverged"
        pct = [(failed if math.isnan(r[k]) else f"{100 * r[k]:.2f} %") for k in keys]
        extra = [str(r["n_params"])] if params else []
        rms_cell = failed if math.isnan(r["rms_q"]) else f"{_fmt(r['rms_q'])} {r['rms_unit']}"
        table.add_row(r["dataset"], r["role"], r["model"], *pct, rms_cell, *extra, _note(r))
    return table


def _note(row: dict[str, Any]) -> str:
    """Word the warning of an NRMSE row: unstable, diverged, or not better than the mean."""
    if row.get("status") == "unstable":
        return f"unstable: {row.get('reason', '')}"
    base = row.get("nrmse_q_baseline")
    value = row.get("nrmse_q")
    if base is None or value is None or math.isnan(value):
        return "diverged: left twice the estimation range" if row.get("diverged") else ""
    if value >= base:
        return f"not better than the mean (NRMSE {100 * base:.1f} %): q is not predicted"
    return ""


def published_table(
    rows: list[dict[str, Any]], published: list[dict[str, Any]], order: list[str] | None = None
) -> Table | None:
    """Our free-run RMS beside the published results on the same data sets.

    Parameters
    ----------
    rows : list of dict
        Rows of ``nrmse.parquet``.
    published : list of dict
        ``{model = "...", rms = {dataset = value}}`` entries of ``[validate]``.
    order : list of str, optional
        Data set order of the workflow (default: as in the first entry).

    Returns
    -------
    rich.table.Table or None
        None when nothing is published.
    """
    if not published:
        return None
    sets = list(published[0]["rms"])
    if order:
        sets = sorted(sets, key=lambda s: order.index(s) if s in order else len(order))
    unit = rows[0]["rms_unit"] if rows else ""
    table = Table(title=escape(f"Free-run RMS error [{unit}] against published results"))
    table.add_column("model")
    for s in sets:
        table.add_column(s, justify="right")
    by_model: dict[str, dict[str, float]] = {}
    for r in rows:
        by_model.setdefault(r["model"], {})[r["dataset"]] = r["rms_q"]
    for model, values in by_model.items():
        table.add_row(f"debist {model} (this run)", *[_fmt(values.get(s), 3) for s in sets])
    for entry in published:
        table.add_row(entry["model"], *[_fmt(entry["rms"].get(s), 3) for s in sets])
    return table


def analyze_table(summary: dict[str, Any]) -> Table:
    """Tabulate the design analysis: equilibria, bifurcation points, full vs reduced model.

    Parameters
    ----------
    summary : dict
        Summary of the analyze stage's manifest (lengths in [m], reported in [mm]).

    Returns
    -------
    rich.table.Table

    References
    ----------
    Masoud & Maas 2025, Section 3.3, Fig. 3, 4, 7.
    """
    table = Table(title=f"Design analysis at b = {1e3 * summary['b']:.2f} mm (Section 3)")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for state, points in summary["operating_points"].items():
        cells = [
            f"{round(1e3 * p['q'], 3) + 0.0:+.3f}" + ("" if p["stable"] else " (unstable)")
            for p in points
        ]
        v1, v2 = state.removeprefix("v1_").removesuffix("kV").split("kV_v2_")
        label = escape(f"equilibria q [mm], (v1, v2) ({v1}, {v2}) kV")
        table.add_row(label, ", ".join(cells) or "none")
    table.add_row(escape("pitchfork z_b,min [mm]"), _fmt(1e3 * summary["z_b_min"]))
    table.add_row(escape("switching limit z_b,max [mm]"), _fmt(1e3 * summary["z_b_max"]))
    table.add_row("full vs reduced NRMSE(q), Fig. 7", f"{100 * summary['nrmse_q']:.2f} %")
    table.add_row("full vs reduced NRMSE(phi), Fig. 7", f"{100 * summary['nrmse_phi']:.2f} %")
    return table


def rig_table(summary: dict[str, Any]) -> Table:
    """Tabulate the virtual rig's experiments.

    Parameters
    ----------
    summary : dict
        Summary of the rig stage's manifest (per experiment; lengths in [m]).

    Returns
    -------
    rich.table.Table
    """
    table = Table(title="Virtual rig")
    for col in ("experiment", "samples", "q range [mm]", "well changes", "saturated", "nfev"):
        table.add_column(escape(col), justify="left" if col == "experiment" else "right")
    for name, s in summary.items():
        table.add_row(
            name,
            str(s["samples"]),
            f"{1e3 * s['q_min']:+.2f} ... {1e3 * s['q_max']:+.2f}",
            str(s["well_changes"]),
            str(s["saturated"]),
            str(s["nfev"]),
        )
    return table


def design_table(summary: dict[str, Any]) -> Table | None:
    """Tabulate the identified model's equilibria and switching voltages (and the analytical).

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``design`` entry).

    Returns
    -------
    rich.table.Table or None
        None when the summary has no design numbers.

    References
    ----------
    Masoud & Maas 2025, Sec. 3.3, Eq. 37.
    """
    design = summary.get("design")
    if not design:
        return None
    table = Table(
        title="Equilibria and switching (identified beside analytical)",
        caption=escape(f"identified model: {design['verdict']} ({design['reason']})"),
    )
    for col in ("model", "inputs [V]", "q*", "kind", "f_n [Hz]", "zeta", "barrier"):
        table.add_column(col, justify="left" if col in ("model", "kind") else "right")
    for r in design["equilibria"]:
        if r["level"] != 0 and not r["static_stable"]:
            continue  # at held levels only the wells
        volts = ", ".join(_fmt(r[k], 4) for k in sorted(r) if k[:1] == "v" and k[1:].isdigit())
        well = bool(r["static_stable"])
        kind = ("well" if r["stable"] else "well, negative damping") if well else "saddle"
        small = [_fmt(r[k]) if well else "" for k in ("f_n", "zeta", "barrier")]
        table.add_row(r["model"], volts, _fmt(r["q"]), kind, *small)
    for r in design["switching"]:
        text = f"{_fmt(r['v_switch'], 4)} V" if r["v_switch"] is not None else escape(r["reason"])
        table.add_row(r["model"], f"switching, input {r['input']}", "", text, "", "", "")
    return table
