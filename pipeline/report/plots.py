"""Figures of the validation stage (matplotlib ``Figure`` objects: no backend, no pyplot state)."""

from __future__ import annotations

from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.report.figures import dynamic_window, replicate_band, thin, thin_band
from debist.report.tables import de_inputs
from debist.validate.freerun import REPLICATE_BAND, report_factor

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")


def free_run_figure(
    sim: pd.DataFrame,
    name: str,
    row: Any,
    init_samples: int = 0,
    unit: str = "m",
    report_unit: str | None = None,
    q_ddot: np.ndarray | None = None,
) -> Any:
    """Measured vs simulated position, a zoom and the error, as in Fig. 12, 13 and 15 of the paper.

    Parameters
    ----------
    sim : pandas.DataFrame
        Columns ``t [s], q, q_sim`` (q in ``unit``), optionally ``q_sim_lo, q_sim_hi``: the
        2.5 and 97.5 percentiles of the bootstrap replicates' free runs (shaded, labelled
        as what they are: :func:`debist.validate.freerun.replicate_spread`).
    name : str
        Data set name (title).
    row : pandas.Series
        Its NRMSE table row (``nrmse_q``, ``rms_q``, ``rms_unit``, ``model``, ``diverged``).
    init_samples : int, optional
        Samples used for initialisation (shaded).
    unit : str, optional
        SI unit of q, the unit of ``sim``.
    report_unit : str, optional
        Unit the axes show q in (``[validate] report_unit``, e.g. ``"mm"``); the data are
        converted for display only. None: ``unit``.
    q_ddot : ndarray, shape (n,), optional
        The measured acceleration [unit/s^2]: the zoom is the 200-sample window where its
        RMS is largest (:func:`debist.report.figures.dynamic_window`, as in the report);
        default the second difference of the measured q.

    Returns
    -------
    matplotlib.figure.Figure
        Three axes: the whole record, a zoom of 200 samples on its most dynamic part, the
        error; q and the error in ``report_unit``.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q (:func:`debist.validate.freerun.report_factor`).
    """
    from matplotlib.figure import Figure

    factor, unit = report_factor(unit, report_unit)
    q, q_sim = factor * sim["q"].to_numpy(), factor * sim["q_sim"].to_numpy()
    fig = Figure(figsize=(10.5, 7), layout="constrained")
    ax1, ax_zoom, ax2 = fig.subplots(3, 1, height_ratios=(2, 2, 1))
    t = sim["t"].to_numpy()
    accel = np.gradient(np.gradient(q)) if q_ddot is None else np.asarray(q_ddot, float)
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    mid = slice(*dynamic_window(t, accel, 200 * dt))
    for ax, s in ((ax1, slice(None)), (ax_zoom, mid)):
        ax.plot(*thin(t[s], q[s]), color="0.2", lw=0.8, label="measured")
        ax.plot(
            *thin(t[s], q_sim[s]), color="tab:red", lw=0.8, ls="--",
            label=f"{row['model']} free run",
        )  # fmt: skip
        if set(REPLICATE_BAND) <= set(sim):
            lo, hi = (factor * sim[c].to_numpy() for c in REPLICATE_BAND)
            replicate_band(ax, *thin_band(t[s], lo[s], hi[s]), row, "tab:red")
        ax.set_ylabel(f"q [{unit}]")
    handles, labels = ax1.get_legend_handles_labels()  # under the axes: full width for them
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    ax1.axvspan(t[mid][0], t[mid][-1], color="0.9", zorder=0)
    ax_zoom.set_title(f"zoom: t = {t[mid][0]:.3g} ... {t[mid][-1]:.3g} s", fontsize=9)
    ax1.set_title(
        f"{name}: NRMSE(q) = {100 * row['nrmse_q']:.2f} %, "
        f"RMS = {row['rms_q']:.4g} {row['rms_unit']}" + ("  (diverged)" if row["diverged"] else ""),
        fontsize=10,
    )
    ax2.plot(*thin(t, q - q_sim), color="tab:blue", lw=0.6)
    ax2.set_ylabel(f"error [{unit}]")
    ax2.set_xlabel("t [s]")
    if init_samples:
        for ax in (ax1, ax2):
            ax.axvspan(t[0], t[min(init_samples, t.size - 1)], color="0.85", zorder=0)
    return fig


def curves_figure(
    curves: pd.DataFrame,
    analytical: pd.DataFrame | None = None,
    unit: str = "m",
    units: dict[str, Any] | None = None,
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
    unit : str, optional
        Unit of q for the axis labels.
    units : dict, optional
        Units of the identified quantities (:func:`debist.report.tables.summary_units`:
        ``force``, ``d_v``, ``g_0``) for the y labels; None: no y units.

    Returns
    -------
    matplotlib.figure.Figure
        Three axes: restoring force ``c(q) q + F_0``, damping ``d(q)`` and
        ``dC_i/dq = 2 g_i(q)`` for DE voltage inputs with ``h = v^2``
        (:func:`debist.report.tables.de_inputs`), else ``g_i(q)`` in its own unit.

    References
    ----------
    Masoud & Maas 2025, Fig. 14.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 8), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    q_scale, unit = (1e3, "mm") if unit == "m" else (1.0, unit)  # q in mm, as the report
    q = q_scale * curves["q"].to_numpy()
    if analytical is not None:
        analytical = analytical.assign(q=q_scale * analytical["q"].to_numpy())
    inputs = sorted(c for c in curves.columns if c[:1] == "g" and c[1:].isdigit())
    # 2 g_i is a capacitance gradient only for DE voltages with h = v^2 (Eq. 33); any other
    # input (an acceleration, a force) shows its gain g_i in its own unit

    de = units is None or de_inputs(units)
    gain = 2.0 if de else 1.0
    panels = [
        (axes[0], [("restoring", 1.0, "tab:blue")], "restoring force c(q) q + F_0"),
        (axes[1], [("d", 1.0, "tab:green")], "damping d(q)"),
        (
            axes[2],
            [(g, gain, c) for g, c in zip(inputs, ("tab:red", "tab:purple"), strict=False)],
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
