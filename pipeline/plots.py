"""Figures of the validation stage (matplotlib, non-interactive Agg backend)."""

from __future__ import annotations

from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pandas as pd


def free_run_figure(sim: pd.DataFrame, name: str, row: Any, init_samples: int = 0) -> Any:
    """Measured vs simulated position and the error, as in Fig. 12 and 15 of the paper.

    Parameters
    ----------
    sim : pandas.DataFrame
        Columns ``t [s], q, q_sim``.
    name : str
        Data set name (title).
    row : pandas.Series
        Its NRMSE table row (``nrmse_q``, ``rms_q``, ``rms_unit``, ``model``).
    init_samples : int, optional
        Samples used for initialisation (shaded).

    Returns
    -------
    matplotlib.figure.Figure
        Two axes: q measured and simulated; the error.
    """
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True, height_ratios=(2, 1))
    t = sim["t"].to_numpy()
    ax1.plot(t, sim["q"], color="0.2", lw=0.8, label="measured")
    ax1.plot(t, sim["q_sim"], color="tab:red", lw=0.8, ls="--", label=f"{row['model']} free run")
    ax1.set_ylabel("q")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(
        f"{name}: NRMSE(q) = {100 * row['nrmse_q']:.2f} %, "
        f"RMS = {row['rms_q']:.4g} {row['rms_unit']}" + ("  (diverged)" if row["diverged"] else ""),
        fontsize=10,
    )
    ax2.plot(t, sim["q"] - sim["q_sim"], color="tab:blue", lw=0.6)
    ax2.set_ylabel("error")
    ax2.set_xlabel("t [s]")
    if init_samples:
        for ax in (ax1, ax2):
            ax.axvspan(t[0], t[min(init_samples, t.size - 1)], color="0.9", zorder=0)
    fig.tight_layout()
    return fig
