"""Figures of the HTML run report, drawn from stage artifacts (``Figure`` objects, no pyplot).

The excitation overview (Fig. 11a of the paper), the free runs of every model against the
measurement (Fig. 12 on estimation data, Fig. 15 on unseen data) with a zoom on the most
dynamic window (Fig. 13); :func:`debist.core.fileformats.png_bytes` turns each into the same
PNG bytes on every call (no time stamp, no software tag), so that the report is a pure
function of its inputs.

References
----------
Masoud & Maas 2025, Front. Robot. AI 12, Fig. 11a, 12, 13, 15; matplotlib documentation,
"Embedding in a web application server" (``matplotlib.figure.Figure`` without pyplot) and
``Figure.savefig`` (``metadata={"Software": None}``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.validate.freerun import REPLICATE_BAND, report_factor

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "MODEL_STYLES",
    "dynamic_window",
    "excitation_figure",
    "free_run_figure",
    "q_scale",
    "replicate_band",
]

#: Line colour and style per model name (others cycle through the last entry's colours).
MODEL_STYLES = {
    "rbf": ("tab:red", "--"),
    "sindy": ("tab:green", ":"),
    "rbf-ls": ("tab:orange", "-."),
    "analytical": ("tab:purple", "-."),
}


def q_scale(unit: str) -> tuple[float, str]:
    """Factor and unit in which positions are drawn: mm for q in m, else q's own unit.

    Parameters
    ----------
    unit : str
        SI unit of q (``"m"`` or ``"rad"``).

    Returns
    -------
    factor : float
        Multiply q [unit] by it.
    label : str
        The drawn unit.
    """
    return (1e3, "mm") if unit == "m" else (1.0, unit)


def dynamic_window(t: np.ndarray, q_ddot: np.ndarray, width: float) -> tuple[int, int]:
    """Find the window of a record whose acceleration has the largest RMS.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times [s], uniformly spaced.
    q_ddot : ndarray, shape (n,)
        Acceleration [unit of q / s^2] (NaN counts as zero).
    width : float
        Window length [s]; the whole record when it is shorter.

    Returns
    -------
    start, stop : int
        Sample slice ``[start, stop)`` of the window (the earliest one on ties).

    References
    ----------
    Masoud & Maas 2025, Fig. 13 (a zoom on the switching, where the dynamics are fastest).
    """
    n = t.size
    if n < 2:
        return 0, n
    dt = float(t[1] - t[0])
    m = int(min(max(round(width / dt), 2), n)) if dt > 0 else n
    power = np.nan_to_num(np.asarray(q_ddot, dtype=float)) ** 2
    csum = np.concatenate([[0.0], np.cumsum(power)])
    energy = csum[m:] - csum[:-m]
    start = int(np.argmax(energy))
    return start, start + m


def excitation_figure(
    table: pd.DataFrame,
    deriv: pd.DataFrame,
    name: str,
    unit: str,
    report_unit: str | None = None,
) -> Any:
    """Position, velocity, acceleration and inputs of one record, as Fig. 11a of the paper.

    Parameters
    ----------
    table : pandas.DataFrame
        The ingested record: ``t`` [s], ``q`` [unit], ``v1`` .. ``vN`` [V].
    deriv : pandas.DataFrame
        Its derivatives: ``q_dot`` [unit/s], ``q_ddot`` [unit/s^2].
    name : str
        Data set name (title).
    unit : str
        SI unit of q.
    report_unit : str, optional
        ``[validate] report_unit``: q and its derivatives are drawn in it (None: mm for q
        in m, :func:`debist.validate.freerun.report_factor`).

    Returns
    -------
    matplotlib.figure.Figure
        Four axes sharing t: q, q_dot, q_ddot (in the report unit) and the inputs in kV.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q.

    References
    ----------
    Masoud & Maas 2025, Fig. 11a.
    """
    from matplotlib.figure import Figure

    factor, label = report_factor(unit, report_unit)
    t = table["t"].to_numpy()
    inputs = sorted((c for c in table.columns if c[:1] == "v" and c[1:].isdigit()), key=_index)
    fig = Figure(figsize=(9, 7.5), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True)
    series = (
        (table["q"], f"q [{label}]"),
        (deriv["q_dot"], f"q_dot [{label}/s]"),
        (deriv["q_ddot"], f"q_ddot [{label}/s^2]"),
    )
    for ax, (values, ylabel) in zip(axes[:3], series, strict=True):
        ax.plot(*thin(t, factor * values.to_numpy()), color="0.15", lw=0.6)
        ax.set_ylabel(ylabel, fontsize=8)
    for col, color in zip(inputs, ("tab:red", "tab:blue", "tab:green", "tab:orange"), strict=False):
        axes[3].plot(*thin(t, 1e-3 * table[col].to_numpy()), color=color, lw=0.7, label=col)
    axes[3].set_ylabel("v_i [kV]", fontsize=8)
    if inputs:
        axes[3].legend(fontsize=7, loc="upper right")
    axes[3].set_xlabel("t [s]")
    axes[0].set_title(f"{name}: excitation and response", fontsize=10)
    return fig


#: Columns a full-record trace is thinned to (:func:`thin`): about twice the pixel width of
#: the widest axes at the report's resolution, so the thinned trace covers the same pixels.
DISPLAY_BINS = 2000


def thin(t: np.ndarray, y: np.ndarray, bins: int = DISPLAY_BINS) -> tuple[np.ndarray, np.ndarray]:
    """Thin a long trace to what a plot of ``bins`` columns shows: each column's min and max.

    A line of n >> pixels samples is drawn as one vertical stroke per pixel column from its
    lowest to its highest value; drawing only those two values per column gives the same
    picture at a fraction of the cost (the min-max decimation of oscilloscopes and plotting
    libraries for long time series).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time [s], increasing.
    y : ndarray, shape (n,)
        Values (NaN where missing: a column of NaN only stays NaN).
    bins : int
        Columns; a trace of at most ``4 bins`` samples comes back unchanged.

    Returns
    -------
    t, y : ndarray, shape (2 bins,) or (n,)
        Per column its mean time twice, with its min and its max.

    References
    ----------
    Steinarsson 2013, Downsampling Time Series for Visual Representation, MSc thesis,
    University of Iceland (min-max and related decimations).

    Examples
    --------
    >>> t = np.arange(16.0)
    >>> thin(t, np.sin(t), bins=2)[1].round(3).tolist()
    [-0.959, 0.909, -1.0, 0.991]
    """
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if t.size <= 4 * bins:
        return t, y
    edges = np.linspace(0, t.size, bins + 1).astype(np.intp)[:-1]
    counts = np.diff(np.append(edges, t.size))
    mid = np.add.reduceat(t, edges) / counts
    with np.errstate(invalid="ignore"):
        lo, hi = np.fmin.reduceat(y, edges), np.fmax.reduceat(y, edges)
    return np.repeat(mid, 2), np.column_stack([lo, hi]).ravel()


def thin_band(
    t: np.ndarray, lo: np.ndarray, hi: np.ndarray, bins: int = DISPLAY_BINS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin a band to ``bins`` columns: per column the lowest ``lo`` and the highest ``hi``.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time [s], increasing.
    lo, hi : ndarray, shape (n,)
        Lower and upper edge (NaN where missing).
    bins : int
        Columns; a band of at most ``4 bins`` samples comes back unchanged.

    Returns
    -------
    t, lo, hi : ndarray, shape (bins,) or (n,)
        The column's mean time and its envelope (the band drawn covers what the full one does).
    """
    t = np.asarray(t, dtype=float)
    if t.size <= 4 * bins:
        return t, np.asarray(lo), np.asarray(hi)
    edges = np.linspace(0, t.size, bins + 1).astype(np.intp)[:-1]
    counts = np.diff(np.append(edges, t.size))
    with np.errstate(invalid="ignore"):
        return (
            np.add.reduceat(t, edges) / counts,
            np.fmin.reduceat(np.asarray(lo, dtype=float), edges),
            np.fmax.reduceat(np.asarray(hi, dtype=float), edges),
        )


def replicate_band(
    ax: Any, t: np.ndarray, lo: np.ndarray, hi: np.ndarray, row: Mapping[str, Any], color: str
) -> None:
    """Shade the bootstrap replicates' free-run band, labelled with what it held.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw in.
    t : ndarray, shape (n,)
        Time [s].
    lo, hi : ndarray, shape (n,)
        The replicates' pointwise 2.5 and 97.5 percentiles of q [display unit]
        (:func:`debist.validate.freerun.replicate_spread`).
    row : mapping
        The model's NRMSE row on the data set: ``replicates`` (count) and
        ``replicates_hold_q`` (share of the samples whose measured q the band holds; absent
        or NaN: not stated).
    color : str
        The model's colour.

    Notes
    -----
    The band is the scatter of the estimate alone (no model error), so it is never
    labelled a prediction interval: the label gives the share of this record's measured q it
    holds.

    References
    ----------
    MathWorks, System Identification Toolbox, ``simsd``; Efron & Tibshirani 1993, Ch. 13.
    """
    held = row.get("replicates_hold_q")
    held = "" if held is None or not np.isfinite(held) else f"; holds {100 * held:.0f} % of q here"
    label = f"{int(row['replicates'])} bootstrap replicates, middle 95 % (estimation only{held})"
    ax.fill_between(t, lo, hi, color=color, alpha=0.15, lw=0, label=label)


def _index(column: str) -> int:
    return int(column[1:])


def free_run_figure(
    measured: pd.DataFrame,
    runs: Mapping[str, pd.DataFrame],
    window: tuple[int, int],
    name: str,
    unit: str,
    nrmse: Mapping[str, float] | None = None,
    rows: Mapping[str, Mapping[str, Any]] | None = None,
    report_unit: str | None = None,
    init_samples: int = 0,
) -> Any:
    """Measured position against the free run of every model, a zoom and the errors.

    Parameters
    ----------
    measured : pandas.DataFrame
        ``t`` [s] and the measured ``q`` [unit] of one data set.
    runs : mapping of str to pandas.DataFrame
        Model name to its free run on that data set (``q_sim`` [unit], same samples; with
        ``q_sim_lo`` and ``q_sim_hi``, the band of its bootstrap replicates, shaded by
        :func:`replicate_band`).
    window : tuple of int
        Sample slice of the zoom (:func:`dynamic_window`).
    name : str
        Data set name (title).
    unit : str
        SI unit of q.
    nrmse : mapping of str to float, optional
        NRMSE(q) per model, shown in the legend (dimensionless; NaN: diverged).
    rows : mapping of str to mapping, optional
        NRMSE row per model (``replicates``, ``replicates_hold_q``): the label of a run's
        replicate band, which is drawn only for a model that has a row.
    report_unit : str, optional
        Unit the axes show q in (``[validate] report_unit``, e.g. ``"mV"``); the data are
        converted for display only. None: as :func:`debist.validate.freerun.report_factor`.
    init_samples : int, optional
        Samples used for the initial state, not scored (``[validate] init_samples``; shaded).

    Returns
    -------
    matplotlib.figure.Figure
        Three axes: the whole record (Fig. 12 / 15), the zoom (Fig. 13, shaded in the
        first axes) and the error ``q - q_sim`` of each model.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q (:func:`debist.validate.freerun.report_factor`).

    References
    ----------
    Masoud & Maas 2025, Fig. 12, 13, 15.
    """
    from matplotlib.figure import Figure

    factor, label = report_factor(unit, report_unit)
    nrmse = nrmse or {}
    t = measured["t"].to_numpy()
    q = factor * measured["q"].to_numpy()
    a, b = window
    fig = Figure(figsize=(10.5, 7.5), layout="constrained")
    full, zoom, err = fig.subplots(3, 1, height_ratios=(2, 2, 1.2))
    for ax, part in ((full, slice(None)), (zoom, slice(a, b))):
        ax.plot(*thin(t[part], q[part]), color="0.15", lw=0.9, label="measured")
    for model, run in runs.items():
        color, style = MODEL_STYLES.get(model, ("tab:brown", "--"))
        sim = factor * run["q_sim"].to_numpy()
        score = nrmse.get(model)
        text = "" if score is None else f" (NRMSE(q) {_percent(score)})"
        band = set(REPLICATE_BAND) <= set(run) and model in (rows or {})
        for ax, part in ((full, slice(None)), (zoom, slice(a, b))):
            ax.plot(
                *thin(t[part], sim[part]), color=color, ls=style, lw=0.9, label=f"{model}{text}"
            )
            if band:
                lo, hi = (factor * run[c].to_numpy()[part] for c in REPLICATE_BAND)
                replicate_band(ax, *thin_band(t[part], lo, hi), rows[model], color)
        err.plot(*thin(t, q - sim), color=color, lw=0.6, label=model)
    if b > a:
        full.axvspan(t[a], t[b - 1], color="0.88", zorder=0)
        zoom.set_title(
            f"zoom on the most dynamic window (largest q_ddot RMS): "
            f"t = {t[a]:.3g} ... {t[b - 1]:.3g} s",
            fontsize=9,
        )
    if init_samples:
        for ax in (full, err):
            ax.axvspan(t[0], t[min(init_samples, t.size - 1)], color="0.8", zorder=0)
    full.set_title(f"{name}: measured and free-run q", fontsize=10)
    # under the axes, across the figure: beside them a long label took 40 % of their width
    handles, labels = full.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncols=3, frameon=False)
    for ax in (full, zoom):
        ax.set_ylabel(f"q [{label}]", fontsize=8)
    err.set_ylabel(f"error [{label}]", fontsize=8)
    err.set_xlabel("t [s]")
    return fig


def _percent(value: float) -> str:
    return "diverged" if value is None or not np.isfinite(value) else f"{100 * value:.2f} %"
