"""Figures of the hyper-parameter studies and searches (Masoud & Maas 2025, Fig. 11b and 11c).

Pure plotting: each function takes a study table from :mod:`debist.stages.studies` and
returns a matplotlib figure; saving is the caller's (the artifacts module).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import lazy_loader as lazy
import numpy as np

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["WINDOW_SAMPLES", "alpha_figure", "autotune_figure", "grid_figure"]

#: Samples of the estimation record shown in the alpha-study figure (Fig. 11c).
WINDOW_SAMPLES = 400


def _status_label(status: str) -> str:
    s = status.lower()
    for key, label in (
        ("condition", "cond."),
        ("rank", "rank"),
        ("centre", "support"),
        ("constant", "input"),
    ):
        if key in s:
            return label
    return "failed"


# ---------------------------------------------------------------------------------------------
# Fig. 11b: M and sigma_n
# ---------------------------------------------------------------------------------------------


def grid_figure(table: pd.DataFrame, free_run: bool = True, unit: str = "m") -> Any:
    """Heat maps of the grid study: model error and log10 condition over (sigma_n, M).

    Parameters
    ----------
    table : pandas.DataFrame
        The table of :func:`rbf_grid_study`.
    free_run : bool, optional
        Whether ``nrmse_q_est`` was computed (else ``eq_mse`` is mapped).
    unit : str, optional
        Unit of q, for the labels.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels with their colour bars (four axes).
    """
    Ms = sorted(table["M"].unique())
    sigmas = sorted(table["sigma_n"].unique())
    shape = (len(Ms), len(sigmas))
    err = np.full(shape, np.nan)
    cond = np.full(shape, np.nan)
    status = np.full(shape, "ok", dtype=object)
    for _, r in table.iterrows():
        i, j = Ms.index(r["M"]), sigmas.index(r["sigma_n"])
        err[i, j] = 100.0 * r["nrmse_q_est"] if free_run else r["eq_mse"]
        cond[i, j] = r["condition"]
        status[i, j] = r["status"]
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(11, 0.55 * len(Ms) + 2.6), layout="constrained")
    axes = fig.subplots(1, 2)
    err_title = (
        "free-run NRMSE(q) on estimation data [%]"
        if free_run
        else f"equation-error MSE [({unit}/s^2)^2 per unit mass]"
    )
    panels = (
        (axes[0], err, err_title, "viridis", True),
        (axes[1], np.log10(cond), "log10 condition number of the regressor", "magma", False),
    )
    for ax, values, title, cmap, log in panels:
        finite = values[np.isfinite(values) & (values > 0 if log else True)]
        norm = None
        if log and finite.size and finite.max() > finite.min():
            norm = LogNorm(finite.min(), finite.max())
        masked = np.ma.masked_invalid(values)
        im = ax.imshow(masked, cmap=cmap, norm=norm, aspect="auto", origin="lower")
        fig.colorbar(im, ax=ax, shrink=0.9)
        ax.set_xticks(range(len(sigmas)), [f"{s:g}" for s in sigmas])
        ax.set_yticks(range(len(Ms)), [str(m) for m in Ms])
        ax.set_xlabel("normalised width sigma_n")
        ax.set_ylabel("number of centres M")
        ax.set_title(title, fontsize=10)
        lo, hi = (np.nanmin(finite), np.nanmax(finite)) if finite.size else (0.0, 1.0)
        for i in range(shape[0]):
            for j in range(shape[1]):
                failed = status[i, j] != "ok"
                if failed:
                    ax.add_patch(
                        Rectangle(
                            (j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///", ec="0.45", lw=0
                        )
                    )
                v = values[i, j]
                if np.isfinite(v):
                    text = f"{v:.3g}"
                    if log and norm is not None:
                        frac = (np.log(v) - np.log(lo)) / (np.log(hi) - np.log(lo))
                    else:
                        frac = (v - lo) / (hi - lo) if hi > lo else 0.5
                    color = "white" if frac < 0.5 else "black"
                else:
                    text, color = ("diverged" if not failed and free_run else ""), "black"
                if failed:
                    text = (text + "\n" if text else "") + _status_label(status[i, j])
                    color = "black" if not np.isfinite(v) else color
                box = {"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1} if failed else None
                ax.text(j, i, text, ha="center", va="center", fontsize=7, color=color, bbox=box)
        if np.isfinite(values).any():
            i, j = np.unravel_index(
                np.nanargmin(np.where(np.isfinite(values), values, np.nan)), shape
            )
            if ax is axes[0]:
                ax.add_patch(
                    Rectangle((j - 0.48, i - 0.48), 0.96, 0.96, fill=False, ec="red", lw=2)
                )
    fig.suptitle(
        "RBF hyper-parameters (cf. Fig. 11b); red box: lowest error; "
        "hatched: fit rejected by the identification",
        fontsize=10,
    )
    return fig


# ---------------------------------------------------------------------------------------------
# Fig. 11c: TVRegDiff alpha
# ---------------------------------------------------------------------------------------------


def alpha_figure(
    table: pd.DataFrame,
    curves: Sequence[tuple[float, pd.DataFrame]],
    name: str,
    free_run: bool = True,
    unit: str = "m",
) -> Any:
    """Plot the derivatives for several ``alpha`` overlaid and the scores versus ``alpha``.

    The layout follows Fig. 11c of Masoud & Maas 2025, with the scores beside it.

    Parameters
    ----------
    table : pandas.DataFrame
        The table of :func:`alpha_study`.
    curves : sequence of (float, pandas.DataFrame)
        Per ``alpha``, the derivatives table ``t [s], q, q_dot, q_ddot`` of one record.
    name : str
        That record's name (title).
    free_run : bool, optional
        Whether ``nrmse_q_est`` was computed.
    unit : str, optional
        Unit of q for the axis labels.

    Returns
    -------
    matplotlib.figure.Figure
        Six axes: q, q_dot, q_ddot over the window (left); NRMSE(q), equation-error
        MSE and roughness versus ``alpha`` (right).
    """
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 8), layout="constrained")
    axes = fig.subplots(3, 2, width_ratios=(2.2, 1))
    # window around the fastest motion of the most regularised derivative
    smooth = curves[int(np.argmax([a for a, _ in curves]))][1]
    n = min(len(smooth), int(table.attrs.get("max_samples", len(smooth))))
    half = min(WINDOW_SAMPLES, n) // 2
    centre = int(np.argmax(np.abs(smooth["q_dot"].to_numpy())))
    start = min(max(centre - half, 0), max(n - 2 * half, 0))
    w = slice(start, start + 2 * half)
    t = smooth["t"].to_numpy()[w]
    ax_q, ax_v, ax_a = axes[:, 0]
    ax_q.plot(t, smooth["q"].to_numpy()[w], color="0.2", lw=1.0, label="measured q")
    colors = colormaps["viridis"](np.linspace(0.0, 0.9, len(curves)))
    for (alpha, d), c in zip(curves, colors, strict=True):
        label = f"alpha = {alpha:.3g}"
        ax_v.plot(t, d["q_dot"].to_numpy()[w], color=c, lw=0.9, label=label)
        ax_a.plot(t, d["q_ddot"].to_numpy()[w], color=c, lw=0.9, label=label)
    ax_q.set_ylabel(f"q [{unit}]")
    ax_q.legend(loc="best", fontsize=8)
    ax_q.set_title(f"{name}: TVRegDiff derivatives for several alpha (cf. Fig. 11c)", fontsize=10)
    ax_v.set_ylabel(f"q_dot [{unit}/s]")
    ax_a.set_ylabel(f"q_ddot [{unit}/s^2]")
    ax_a.set_xlabel("t [s]")
    ax_v.legend(loc="best", fontsize=7, ncol=2)
    # q_ddot of a tiny alpha can be pure noise: scale the axis to the smoother curves
    ref = np.concatenate([d["q_ddot"].to_numpy()[w] for _, d in curves[len(curves) // 2 :]])
    if ref.size and np.all(np.isfinite(ref)) and np.ptp(ref) > 0:
        pad = 0.6 * np.ptp(ref)
        ax_a.set_ylim(ref.min() - pad, ref.max() + pad)
    alpha = table["alpha"].to_numpy()
    ax_n, ax_e, ax_r = axes[:, 1]
    if free_run:
        ax_n.plot(alpha, 100 * table["nrmse_q_est"], "o-", label="estimation")
        if table["nrmse_q_val"].notna().any():
            ax_n.plot(alpha, 100 * table["nrmse_q_val"], "s--", label="validation")
        ax_n.legend(fontsize=8)
    else:
        ax_n.text(0.5, 0.5, "free_run = false", ha="center", va="center", transform=ax_n.transAxes)
    ax_n.set_ylabel("free-run NRMSE(q) [%]")
    ax_e.plot(alpha, table["eq_mse"], "o-", color="tab:red")
    ax_e.set_ylabel(f"equation-error MSE [({unit}/s^2)^2]")
    ax_r.plot(alpha, table["roughness"], "o-", color="tab:green")
    ax_r.set_ylabel(f"roughness of q_dot [{unit}/s]")
    ax_r.set_xlabel("alpha")
    for ax in (ax_n, ax_e, ax_r):
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
    for ax, col in ((ax_e, "eq_mse"), (ax_r, "roughness")):
        values = table[col].dropna()
        if values.size and np.all(values > 0):  # an all-failed study has nothing to log-scale
            ax.set_yscale("log")
    ax_n.set_title("scores vs alpha (dashed: workflow's)", fontsize=10)
    if "workflow_alpha" in table.attrs:
        for ax in (ax_n, ax_e, ax_r):
            ax.axvline(table.attrs["workflow_alpha"], color="0.3", ls="--", lw=1)
    bad = table["status"] != "ok"
    for a in alpha[bad.to_numpy()]:
        for ax in (ax_n, ax_e, ax_r):
            ax.axvline(a, color="0.6", ls=":", lw=1)
    return fig


def autotune_figure(result) -> Any:
    """Draw the cross-validation score against the candidates (Fig. 11b, 11c generalised).

    The x axis is ``M`` when the grid varies it (else the first varied parameter); one line
    per setting of the other grid parameters, with one-standard-error bars. The dashed line
    is the one-standard-error bound, the ring the chosen candidate; failed or diverged
    candidates are crosses at the top edge.

    Parameters
    ----------
    result : debist.identify.autotune.AutoResult
        Output of :func:`debist.identify.autotune.select_hyperparameters`.

    Returns
    -------
    matplotlib.figure.Figure
        One axis: mean NRMSE(q) of the held-out blocks [%] against the x parameter.

    References
    ----------
    Masoud & Maas 2025, Fig. 11b, 11c (validation error against M and sigma_n).
    """
    from matplotlib.figure import Figure
    from matplotlib.transforms import blended_transform_factory

    table = result.table
    keys = list(result.settings[0]) if result.settings else ["M"]
    varied = [k for k in keys if len({repr(s[k]) for s in result.settings}) > 1] or keys
    x_key = "M" if "M" in varied else varied[0]
    others = [k for k in varied if k != x_key]
    xs = [s[x_key] for s in result.settings]
    numeric = all(isinstance(x, int | float) and not isinstance(x, bool) for x in xs)
    labels = sorted({repr(x) for x in xs}) if not numeric else []

    def pos(x: Any) -> float:
        return float(x) if numeric else float(labels.index(repr(x)))

    fig = Figure(figsize=(8, 5))
    ax = fig.subplots()
    groups: dict[str, list[int]] = {}
    for i, s in enumerate(result.settings):
        label = ", ".join(f"{k} = {s[k]!r}" for k in others) or "score"
        groups.setdefault(label, []).append(i)
    top = blended_transform_factory(ax.transData, ax.transAxes)
    failed = False
    for label, rows in groups.items():
        rows = sorted(rows, key=lambda i: pos(result.settings[i][x_key]))
        ok = [i for i in rows if np.isfinite(table.loc[i, "mean"])]
        if ok:
            ax.errorbar(
                [pos(result.settings[i][x_key]) for i in ok],
                [100 * table.loc[i, "mean"] for i in ok],
                yerr=[100 * table.loc[i, "se"] for i in ok],
                marker="o", ms=4, capsize=3, lw=1, label=label,
            )  # fmt: skip
        for i in rows:
            if not np.isfinite(table.loc[i, "mean"]):
                failed = True
                ax.plot(pos(result.settings[i][x_key]), 0.97, "x", color="tab:red",
                        transform=top, clip_on=False)  # fmt: skip
    c = int(table.index[table["chosen"]][0])
    ax.plot(pos(result.settings[c][x_key]), 100 * table.loc[c, "mean"], "o", ms=13, mfc="none",
            mec="k", mew=1.5, label="chosen (one-standard-error rule)")  # fmt: skip
    ax.axhline(100 * result.threshold, color="0.4", ls="--", lw=1, label="best + 1 SE")
    if failed:
        ax.plot([], [], "x", color="tab:red", label="fit failed / diverged")
    finite = table["mean"][np.isfinite(table["mean"])]
    if len(finite) and finite.max() > 10 * finite.min() > 0:
        ax.set_yscale("log")
    if not numeric:
        ax.set_xticks(range(len(labels)), labels)
    ax.set_xlabel(x_key)
    ax.set_ylabel("held-out free-run NRMSE(q) [%]")
    ax.set_title(
        f"blocked {result.folds}-fold cross-validation ({result.strategy}, "
        f"{len(result.settings)} candidates)\nchosen: "
        + ", ".join(f"{k} = {v!r}" for k, v in result.chosen.items()),
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig
