"""Figures of the identify stage (matplotlib ``Figure`` objects: no backend, no pyplot state)."""

from __future__ import annotations

from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.report.tables import de_inputs, display_factors, display_summary, summary_units

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")


def curves_figure(
    curves: pd.DataFrame,
    analytical: pd.DataFrame | None = None,
    summary: dict[str, Any] | None = None,
    report_unit: str | None = None,
) -> Any:
    """Draw the identified curves with their bootstrap bands, as Fig. 14 of the paper.

    The bands are those of ``curves.parquet``: the block bootstrap of the estimation scatter
    with, by default, the model error calibrated on the virtual rig
    (:func:`debist.identify.bands.band_label` says what they hold).

    Where a curve is not identified (``<name>_identified`` false) it is drawn thin and grey
    over its band; identified parts are drawn in colour.

    Parameters
    ----------
    curves : pandas.DataFrame
        ``curves.parquet`` of the identify stage: ``q``, ``restoring``, ``d``, ``g1..gN``
        and per curve ``<name>_lo``, ``<name>_hi``, ``<name>_identified``.
    analytical : pandas.DataFrame, optional
        The analytical model's curves on a grid in the same units (``q``, ``restoring``,
        ``d``, ``g1..gN``), drawn dashed beside the identified ones.
    summary : dict, optional
        The identify stage's summary (its ``units``: q's SI unit, the inputs, whether the
        curves are per unit mass): the y labels are those of
        :func:`debist.report.tables.summary_units` in the report unit; None: q in m, forces
        in N, no y units.
    report_unit : str, optional
        ``[validate] report_unit``: q on the x axis and the curves (per unit mass: in
        q/s^2; damping per length of q) are drawn in it,
        :func:`debist.report.tables.display_factors`; None: mm for q in m, else q's unit.

    Returns
    -------
    matplotlib.figure.Figure
        Three axes over q [report unit]: restoring force ``c(q) q + F_0``, damping ``d(q)`` and
        ``dC_i/dq = 2 g_i(q)`` for DE voltage inputs with ``h = v^2``
        (:func:`debist.report.tables.de_inputs`), else ``g_i(q)`` in its own unit.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q.

    References
    ----------
    Masoud & Maas 2025, Fig. 14.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 8), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    units = summary_units(display_summary(summary, report_unit)) if summary else None
    given = (summary or {}).get("units") or {}
    per_mass = units is not None and units["mass"] == "1"
    by_dim, unit = display_factors(given.get("q", "m"), report_unit, per_mass)  # as the tables
    q_scale = by_dim["q"]
    q = q_scale * curves["q"].to_numpy()
    if analytical is not None:
        analytical = analytical.assign(q=q_scale * analytical["q"].to_numpy())
    inputs = sorted(c for c in curves.columns if c[:1] == "g" and c[1:].isdigit())
    # 2 g_i is a capacitance gradient only for DE voltages with h = v^2 (Eq. 33); any other
    # input (an acceleration, a force) shows its gain g_i in its own unit

    de = units is None or de_inputs(units)
    gain = 2.0 if de else 1.0
    force = by_dim["F"]
    panels = [
        (axes[0], [("restoring", force, "tab:blue")], "restoring force c(q) q + F_0"),
        (axes[1], [("d", by_dim["Fs/q"], "tab:green")], "damping d(q)"),
        (
            axes[2],
            [(g, gain * force, c) for g, c in zip(inputs, ("tab:red", "tab:purple"), strict=False)],
            "dC_i/dq = 2 g_i(q)" if de else "input gain g_i(q) of h(u_i)",
        ),
    ]
    labels = ["", "", ""]
    if units is not None:
        gains = sorted(set(units["g_0"])) or ["1"]
        labels = [units["force"], units["d_v"], ", ".join(gains)]
    for i, (ax, series, title) in enumerate(panels):
        # a power of ten in the label, not matplotlib's offset text over the title
        decade = _decade(curves, series, analytical)
        series = [(name, factor / 10.0**decade, color) for name, factor, color in series]
        label = labels[i] if not decade else f"10^{decade} {labels[i]}".strip()
        ax.set_ylabel(f"[{label}]" if label else "")
        ax.ticklabel_format(axis="y", useOffset=False, style="plain")
        for name, factor, color in series:
            y = factor * curves[name].to_numpy()
            ident = curves[f"{name}_identified"].to_numpy()
            lo = factor * curves[f"{name}_lo"].to_numpy()
            hi = factor * curves[f"{name}_hi"].to_numpy()
            ax.fill_between(q, lo, hi, color=color, alpha=0.2, lw=0, label=f"{name}: band")
            ax.plot(q, y, color="0.6", lw=0.8)
            ax.plot(q, np.where(ident, y, np.nan), color=color, lw=1.6, label=f"{name} identified")
            if analytical is not None and name in analytical:
                ax.plot(
                    analytical["q"],
                    factor * analytical[name],
                    color=color,
                    ls="--",
                    lw=1.0,
                    label=f"{name} analytical",
                )
        _limit_to_identified(ax, curves, series, analytical)
        ax.set_title(title + " (grey: not identified)", fontsize=9)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    axes[-1].set_xlabel(f"q [{unit}]")
    return fig


def _panel_values(curves, series, analytical) -> np.ndarray:
    """Return what a panel must show: every curve, bands where identified, the analytical."""
    values = []
    for name, factor, _ in series:
        ident = curves[f"{name}_identified"].to_numpy()
        values.append(factor * curves[name].to_numpy())
        for key in (f"{name}_lo", f"{name}_hi"):
            values.append(factor * curves[key].to_numpy()[ident])
        if analytical is not None and name in analytical:
            values.append(factor * analytical[name].to_numpy())
    values = np.concatenate(values) if values else np.empty(0)
    return values[np.isfinite(values)]


def _decade(curves, series, analytical) -> int:
    """Power of ten to show a panel's values in (0 between 1e-2 and 1e4)."""
    values = _panel_values(curves, series, analytical)
    top = float(np.max(np.abs(values))) if values.size else 0.0
    if top == 0 or 1e-2 <= top < 1e4:
        return 0
    return int(np.floor(np.log10(top)))


def _limit_to_identified(ax, curves, series, analytical) -> None:
    """Scale the y axis to the curves and the identified bands (unsupported bands can be huge)."""
    values = _panel_values(curves, series, analytical)
    values = values[np.isfinite(values)]
    if values.size:
        lo, hi = float(values.min()), float(values.max())
        pad = 0.1 * (hi - lo) if hi > lo else max(abs(hi), 1e-30)
        ax.set_ylim(lo - pad, hi + pad)
