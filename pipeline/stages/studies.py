"""Hyper-parameter studies of Sec. 5.2: RBF grid (M, sigma_n) and TVRegDiff alpha (Fig. 11b/11c).

Both studies are pure functions over the stages' tables: canonical rig-log tables and
their derivatives in, a result table and a matplotlib figure out. They call the
pipeline's own differentiator, identification and free-run validation, so a study
scores exactly what a workflow run with those settings would produce, except that at
most ``max_samples`` samples of each record are fitted and simulated (for speed; the
table's ``attrs`` say so). The alpha study differentiates those samples only, as a workflow
on records of that length would.

References
----------
Masoud, A. & Maas, J. (2025). Front. Robot. AI 12, Sec. 5.1-5.2 and Fig. 11b
(M and sigma_n versus model error) and Fig. 11c (TVRegDiff alpha study).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core import preflight, progress
from debist.core.errors import IdentificationError, WorkflowError
from debist.core.metrics import rms
from debist.core.tables import input_columns
from debist.differentiate.tables import differentiate_tables
from debist.differentiate.tvregdiff_method import TVRegDiffConfig
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.identify.records import estimation_records
from debist.model.rbf import RBFModel
from debist.report.study_plots import alpha_figure, grid_figure
from debist.validate.config import ValidateConfig
from debist.validate.datasets import validation_datasets
from debist.validate.freerun import DataSet, validate_model
from debist.workflow.sections import StudyConfig

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "StudyConfig",
    "alpha_figure",
    "alpha_study",
    "derivative_roughness",
    "grid_figure",
    "rbf_grid_study",
]

#: Longest status message kept in the result tables [characters].
STATUS_CHARS = 90


def derivative_roughness(x_dot: np.ndarray) -> float:
    """Roughness of a derivative: RMS of its second difference.

    Parameters
    ----------
    x_dot : ndarray, shape (n,) [unit/s]
        A derivative signal, ``n >= 3``.

    Returns
    -------
    float
        ``sqrt(mean(diff(x_dot, 2)**2))`` [unit/s]; large for noisy (under-
        regularised) derivatives, small for over-smoothed ones.

    Examples
    --------
    >>> derivative_roughness(np.arange(10.0))
    0.0
    >>> derivative_roughness(np.array([0.0, 1.0, 0.0]))
    2.0
    """
    x_dot = np.asarray(x_dot, dtype=float)
    return rms(np.diff(x_dot, 2))


# ---------------------------------------------------------------------------------------------
# shared scoring of one fit
# ---------------------------------------------------------------------------------------------


def _short(message: str) -> str:
    message = " ".join(str(message).split())
    return message if len(message) <= STATUS_CHARS else message[: STATUS_CHARS - 3] + "..."


def _cut_record(r: Record, n: int) -> Record:
    return Record(r.name, r.q[:n], r.q_dot[:n], r.q_ddot[:n], r.v[:n], r.dt)


def _cut_dataset(ds: DataSet, n: int) -> DataSet:
    return dataclasses.replace(
        ds, t=ds.t[:n], q=ds.q[:n], q_dot=ds.q_dot[:n], q_ddot=ds.q_ddot[:n], v=ds.v[:n]
    )


def _study_data(tables, derivs, max_samples: int) -> tuple[list[Record], list[DataSet]]:
    records = [_cut_record(r, max_samples) for r in estimation_records(tables, derivs)]
    datasets = [_cut_dataset(ds, max_samples) for ds in validation_datasets(tables, derivs)]
    return records, datasets


def _fit_and_score(
    records: Sequence[Record],
    datasets: Sequence[DataSet],
    identify: IdentifyConfig,
    vcfg: ValidateConfig,
    free_run: bool,
) -> dict[str, Any]:
    """Fit one model and score it; an ill-posed fit is a row with its status, not an error."""
    row: dict[str, Any] = {
        "condition": math.nan,
        "rank": -1,
        "n_columns": 0,
        "eq_mse": math.nan,
        "nrmse_q_est": math.nan,
        "nrmse_q_val": math.nan,
        "status": "ok",
    }
    # The condition limit is applied here, after the fit, so that a rejected cell
    # still reports its condition number and equation error; a study reads no band, so
    # no bootstrap (the point estimate does not depend on it).
    unchecked = dataclasses.replace(identify, max_condition=math.inf, bootstrap=0)
    try:
        model, diag = fit_rbf_model(records, unchecked)
    except IdentificationError as exc:
        row["status"] = _short(str(exc))
        return row
    row.update(
        condition=float(diag.condition),
        rank=int(diag.rank),
        n_columns=len(diag.columns),
        eq_mse=float(diag.residual_rms**2),
    )
    if diag.condition > identify.max_condition:
        row["status"] = _short(
            f"regressor condition number {diag.condition:.3g} exceeds "
            f"max_condition = {identify.max_condition:.3g}"
        )
        return row
    if free_run:
        row.update(_free_run_scores(model, datasets, vcfg))
    return row


def _free_run_scores(
    model: RBFModel, datasets: Sequence[DataSet], vcfg: ValidateConfig
) -> dict[str, float]:
    span = max(abs(model.q_range[0]), abs(model.q_range[1]))
    q_limit = vcfg.q_limit if vcfg.q_limit is not None else 100.0 * span
    table, _ = validate_model(model, "rbf", datasets, vcfg, q_limit)
    score = table["nrmse_q"].where(~table["diverged"].astype(bool))
    est = score[table["role"] == "estimation"]
    val = score[table["role"] != "estimation"]
    return {
        "nrmse_q_est": float(est.mean(skipna=False)) if est.size else math.nan,
        "nrmse_q_val": float(val.mean(skipna=False)) if val.size else math.nan,
    }


def _attrs(cfg: StudyConfig, records: Sequence[Record]) -> dict[str, Any]:
    return {
        "max_samples": cfg.max_samples,
        "n_samples": {r.name: int(r.q.size) for r in records},
        "free_run": cfg.free_run,
        "note": (
            f"at most the first {cfg.max_samples} samples of each record are fitted and "
            "free-run; eq_mse is the mean squared equation error of the fit "
            "[(unit of q/s^2)^2 per unit mass]; nrmse_q_* is the free-run NRMSE(q) of Eq. 41 "
            "(NaN when diverged, not run, or the fit failed)"
        ),
    }


def rbf_grid_study(
    tables: Mapping[str, pd.DataFrame],
    derivs: Mapping[str, pd.DataFrame],
    identify_section: Mapping[str, Any],
    validate_section: Mapping[str, Any],
    cfg: StudyConfig,
) -> tuple[pd.DataFrame, Any]:
    """Identify the RBF model for every (M, sigma_n) of the grid and score it (Fig. 11b).

    Every cell is fitted with the ``[identify]`` section with ``M`` and ``sigma_n`` replaced;
    a fit the identification rejects is a row with that status, not an exception.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical tables ``t [s], q [m], v1..vN [V]`` with ``attrs['role']``.
    derivs : mapping of str to pandas.DataFrame
        Their derivatives ``t, q, q_hat, q_dot [m/s], q_ddot [m/s^2]`` with ``attrs['dt']`` [s].
    identify_section, validate_section : mapping
        The ``[identify]`` and ``[validate]`` sections.
    cfg : StudyConfig
        The grids, ``free_run`` and ``max_samples``.

    Returns
    -------
    table : pandas.DataFrame
        One row per cell, M-major: ``M, sigma_n, condition, rank, n_columns, eq_mse``
        [(m/s^2)^2 per unit mass], ``nrmse_q_est, nrmse_q_val`` [-], ``status``; ``attrs``
        hold ``max_samples``, the samples used per record and a note.
    figure : matplotlib.figure.Figure
        Heat maps over (sigma_n, M) of the model error (free-run NRMSE(q) [%], or the
        equation-error MSE) and log10 of the condition number. Four axes.

    Raises
    ------
    WorkflowError
        For an invalid section or no estimation data set.
    ResourceError
        If the largest ``M`` of the grid would exceed the memory budget (checked first).

    References
    ----------
    Masoud & Maas 2025, Sec. 5.2 and Fig. 11b (paper's choice M = 10, sigma_n = 0.5).
    """
    base = dict(identify_section)
    icfg = IdentifyConfig.from_dict(base)  # report an invalid section once, before the loop
    vcfg = ValidateConfig.from_dict(validate_section)
    records, datasets = _study_data(tables, derivs, cfg.max_samples)
    sizes = [max(r.q.size - 2 * icfg.trim, 0) for r in records]
    preflight.check_identify(
        dataclasses.replace(icfg, M=max(cfg.M)),
        records[0].v.shape[1],
        sum(sizes),
        max(sizes),
        f"[study] M = {max(cfg.M)}",
    )
    rows = []
    for M in cfg.M:
        for sigma_n in cfg.sigma_n:
            icfg = IdentifyConfig.from_dict({**base, "M": int(M), "sigma_n": float(sigma_n)})
            row = {"M": int(M), "sigma_n": float(sigma_n)}
            row.update(_fit_and_score(records, datasets, icfg, vcfg, cfg.free_run))
            rows.append(row)
            progress.report("study: RBF grid", len(rows), len(cfg.M) * len(cfg.sigma_n))
    table = pd.DataFrame(rows)
    table.attrs.update(_attrs(cfg, records))
    return table, grid_figure(table, cfg.free_run, datasets[0].q_unit)


def _scaled_section(section: Mapping[str, Any], alpha: float) -> dict[str, Any]:
    params = dict(section)
    method = params.pop("method", "tvregdiff")
    if method != "tvregdiff":
        raise WorkflowError(
            f"[differentiate] the alpha study needs method = 'tvregdiff', got {method!r}"
        )
    alpha0 = float(params.get("alpha", TVRegDiffConfig.alpha))
    params["alpha"] = float(alpha)
    if params.get("alpha2") is not None:
        params["alpha2"] = float(params["alpha2"]) * alpha / alpha0
    return params


def alpha_study(
    tables: Mapping[str, pd.DataFrame],
    identify_section: Mapping[str, Any],
    validate_section: Mapping[str, Any],
    diff_section: Mapping[str, Any],
    cfg: StudyConfig,
) -> tuple[pd.DataFrame, Any]:
    """Differentiate, identify and score for every TVRegDiff ``alpha`` (Fig. 11c).

    Per ``alpha`` (``alpha2`` scaled alike) the first ``max_samples`` samples of each table are
    differentiated, fitted and scored as in :func:`rbf_grid_study` (why both scores:
    docs/explanation/implementation.md).

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical tables ``t [s], q [m], v1..vN [V]`` with ``attrs['role']``.
    identify_section, validate_section : mapping
        The ``[identify]`` and ``[validate]`` sections.
    diff_section : mapping
        The ``[differentiate]`` section; its ``method`` must be "tvregdiff" (the default).
    cfg : StudyConfig
        ``alpha`` values [unit of q * s], ``free_run``, ``max_samples``.

    Returns
    -------
    table : pandas.DataFrame
        One row per ``alpha``: ``alpha, eq_mse, nrmse_q_est, nrmse_q_val, condition, status,
        roughness`` (RMS of the second difference of q_dot [m/s]) and ``converged``;
        ``attrs`` as in :func:`rbf_grid_study` plus ``workflow_alpha``.
    figure : matplotlib.figure.Figure
        Left: q, q_dot and q_ddot per ``alpha`` over :data:`WINDOW_SAMPLES` samples around
        the fastest motion; right: NRMSE(q), equation-error MSE and roughness against
        ``alpha``. Six axes.

    Raises
    ------
    WorkflowError
        For an invalid section, a method other than TVRegDiff or no estimation data.
    ResourceError
        If the least squares would exceed the memory budget.
    RigLogError
        For non-uniform sampling.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 and Fig. 11c (alpha = 0.01 for q in mm); Chartrand 2011.
    """
    icfg = IdentifyConfig.from_dict(dict(identify_section))
    vcfg = ValidateConfig.from_dict(validate_section)
    est = [f for f in tables.values() if f.attrs.get("role") == "estimation"]
    sizes = [max(min(len(f), cfg.max_samples) - 2 * icfg.trim, 0) for f in est]
    if est:  # without estimation data the first fit says so
        preflight.check_identify(icfg, len(input_columns(est[0])), sum(sizes), max(sizes))
    rows, curves = [], []
    heads = {name: frame.iloc[: cfg.max_samples] for name, frame in tables.items()}
    for alpha in cfg.alpha:
        params = _scaled_section(diff_section, float(alpha))
        derivs = differentiate_tables(heads, {"method": "tvregdiff", **params})
        converged = all(d.attrs["converged"] for d in derivs.values())
        records, datasets = _study_data(tables, derivs, cfg.max_samples)
        score = _fit_and_score(records, datasets, icfg, vcfg, cfg.free_run)
        rough = float(np.mean([derivative_roughness(r.q_dot) for r in records]))
        progress.report("study: TVRegDiff alpha", len(rows) + 1, len(cfg.alpha))
        rows.append(
            {
                "alpha": float(alpha),
                "eq_mse": score["eq_mse"],
                "nrmse_q_est": score["nrmse_q_est"],
                "nrmse_q_val": score["nrmse_q_val"],
                "condition": score["condition"],
                "status": score["status"],
                "roughness": rough,
                "converged": converged,
            }
        )
        first = derivs[records[0].name]
        curves.append((float(alpha), first))
    table = pd.DataFrame(rows)
    table.attrs.update(_attrs(cfg, records))
    table.attrs["workflow_alpha"] = float(diff_section.get("alpha", TVRegDiffConfig.alpha))
    unit = tables[records[0].name].attrs.get("units", {}).get("q", "m")
    return table, alpha_figure(table, curves, records[0].name, cfg.free_run, unit)
