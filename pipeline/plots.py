"""Figures of the validation stage (matplotlib ``Figure`` objects: no backend, no pyplot state)."""

from __future__ import annotations

from typing import Any

import pandas as pd


def free_run_figure(
    sim: pd.DataFrame, name: str, row: Any, init_samples: int = 0, unit: str = "m"
) -> Any:
    """Measured vs simulated position, a zoom and the error, as in Fig. 12, 13 and 15 of the paper.

    Parameters
    ----------
    sim : pandas.DataFrame
        Columns ``t [s], q, q_sim`` (q in ``unit``).
    name : str
        Data set name (title).
    row : pandas.Series
        Its NRMSE table row (``nrmse_q``, ``rms_q``, ``rms_unit``, ``model``, ``diverged``).
    init_samples : int, optional
        Samples used for initialisation (shaded).
    unit : str, optional
        SI unit of q, for the axis labels.

    Returns
    -------
    matplotlib.figure.Figure
        Three axes: the whole record, a zoom of 200 samples in its middle, the error.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 7))
    ax1, ax_zoom, ax2 = fig.subplots(3, 1, height_ratios=(2, 2, 1))
    t = sim["t"].to_numpy()
    mid = slice(max(t.size // 2 - 100, 0), min(t.size // 2 + 100, t.size))
    for ax, s in ((ax1, slice(None)), (ax_zoom, mid)):
        ax.plot(t[s], sim["q"].to_numpy()[s], color="0.2", lw=0.8, label="measured")
        ax.plot(
            t[s],
            sim["q_sim"].to_numpy()[s],
            color="tab:red",
            lw=0.8,
            ls="--",
            label=f"{row['model']} free run",
        )
        ax.set_ylabel(f"q [{unit}]")
    ax1.legend(loc="upper right", fontsize=8)
    ax_zoom.set_title(f"zoom: t = {t[mid][0]:.3g} ... {t[mid][-1]:.3g} s", fontsize=9)
    ax1.set_title(
        f"{name}: NRMSE(q) = {100 * row['nrmse_q']:.2f} %, "
        f"RMS = {row['rms_q']:.4g} {row['rms_unit']}" + ("  (diverged)" if row["diverged"] else ""),
        fontsize=10,
    )
    ax2.plot(t, sim["q"] - sim["q_sim"], color="tab:blue", lw=0.6)
    ax2.set_ylabel(f"error [{unit}]")
    ax2.set_xlabel("t [s]")
    if init_samples:
        for ax in (ax1, ax2):
            ax.axvspan(t[0], t[min(init_samples, t.size - 1)], color="0.85", zorder=0)
    fig.tight_layout()
    return fig
