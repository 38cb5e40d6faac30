"""The validate stage: free runs of the identified model on every data set, NRMSE (Eq. 41)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core.progress import Stopwatch
from debist.core.tables import input_columns
from debist.identify.bands import fitted_curves, simulation_only
from debist.identify.driven import beyond_driven, driven_ranges
from debist.identify.physics_prior import analytical_for
from debist.identify.spectrum import under_excitation
from debist.identify.stability import model_is_stable
from debist.model.rbf import RBFModel
from debist.report.tables import with_verdicts
from debist.stages import StageInputs, StageOutput
from debist.validate.datasets import validation_datasets
from debist.validate.freerun import (
    REPLICATE_BAND,
    ValidateConfig,
    default_q_limit,
    mark_unstable,
    replicate_spread,
    report_factor,
    validate_model,
)
from debist.validate.prediction import prediction_table

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

#: Free-run columns of ``simulated/<data set>.parquet``; those of the other models validated
#: beside the RBF model (``analytical``, ``rbf-ls``) carry the model name as a suffix.
SIM_COLUMNS = ("q_sim", "q_dot_sim", "q_ddot_sim")

__all__ = ["ValidateResult", "execute", "run_validate"]


@dataclass(frozen=True)
class ValidateResult:
    """Output of the validation stage.

    Attributes
    ----------
    table : pandas.DataFrame
        NRMSE and RMS per data set and model.
    simulated : dict of str to pandas.DataFrame
        Measured and simulated trajectories per data set.
    timings : dict of str to float
        Wall times of the parts [s], adding up to the call's: ``prepare``, ``simulate`` (the
        model's free runs), ``replicates`` (the bootstrap replicates' free runs), ``other
        models`` (``rbf-ls``, ``analytical``), ``k-step and residuals``, ``stability``.
    residuals : pandas.DataFrame or None
        The residual analysis's correlations (:func:`debist.validate.prediction.prediction_table`),
        None with ``predict_steps = 0``.
    """

    table: pd.DataFrame
    simulated: dict[str, pd.DataFrame]
    timings: dict[str, float] = field(default_factory=dict)
    residuals: pd.DataFrame | None = None

    @property
    def sim_time(self) -> float:
        """Wall time of the model's free runs [s] (``timings["simulate"]``)."""
        return self.timings.get("simulate", 0.0)


def run_validate(
    model: RBFModel,
    tables,
    derivs,
    section: Mapping[str, Any],
    baseline: RBFModel | None = None,
    physics=None,
    replicates: tuple[list[str], np.ndarray] | None = None,
) -> ValidateResult:
    """Free-run the identified model on every data set and score it (Sec. 5, Eq. 41).

    Parameters
    ----------
    model : RBFModel
        The identified model.
    tables, derivs : mapping of str to pandas.DataFrame
        Measured data and derivatives of every data set.
    section : mapping
        The ``[validate]`` section (see :class:`ValidateConfig`).
    baseline : RBFModel, optional
        The equation-error (least-squares) model when ``model`` was refined by
        simulation error; scored too, as model ``"rbf-ls"``, so both fits stand
        side by side.
    physics : PrototypeParams, optional
        The prototype of the ``[physics]`` section: every row gets ``nrmse_phi`` through its
        ``phi(q)`` map, and with ``analytical = true`` the analytical model (nominal
        parameters, Eq. 26) is scored as model ``"analytical"``.
    replicates : tuple of (list of str, ndarray of shape (B, p)), optional
        The fit's regressor columns and its bootstrap replicates minus the estimate: up to
        ``[validate] replicates`` of them are simulated (:func:`debist.validate.freerun.
        replicate_spread`), and the rbf rows get ``replicates``, ``nrmse_q_lo``,
        ``nrmse_q_hi``, ``replicates_poor`` and ``replicates_hold_q``, the free runs ``q_sim_lo``
        and ``q_sim_hi``.

    Returns
    -------
    ValidateResult

    Raises
    ------
    WorkflowError
        For an invalid section, or physics that does not fit the data.
    """
    watch = Stopwatch()
    cfg = ValidateConfig.from_dict(section)
    q_limit = cfg.q_limit if cfg.q_limit is not None else default_q_limit(model.q_range)
    datasets = validation_datasets(tables, derivs)
    analytical = analytical_for(physics, datasets, cfg)
    phi = analytical.phi if analytical is not None else None
    watch.lap("prepare")
    table, simulated = validate_model(model, "rbf", datasets, cfg, q_limit, phi)
    table["n_params"] = model.n_params
    watch.lap("simulate")
    if replicates is not None and cfg.replicates > 0:
        columns, deviations = replicates
        spread, bands = replicate_spread(
            model, columns, deviations[: cfg.replicates], datasets, cfg, q_limit
        )
        table = table.merge(spread, on="dataset", how="left", validate="one_to_one")
        for ds, band in bands.items():
            simulated[ds] = simulated[ds].assign(**dict(zip(REPLICATE_BAND, band, strict=True)))
        watch.lap("replicates")
    others = [(baseline, "rbf-ls")] if baseline is not None else []
    if cfg.analytical:
        others.append((analytical, "analytical"))
    for other, name in others:
        extra, runs = validate_model(other, name, datasets, cfg, q_limit, phi)
        extra["n_params"] = getattr(other, "n_params", 0)
        table = pd.concat([table, extra], ignore_index=True)
        for ds, run in runs.items():  # the other models' free runs beside the rbf's
            simulated[ds] = simulated[ds].assign(
                **{f"{col}_{name}": run[col].to_numpy() for col in SIM_COLUMNS}
            )
    if others:
        watch.lap("other models")
    residuals = None
    if cfg.predict_steps:
        scored = [
            prediction_table(
                m, name, datasets, k=cfg.predict_steps, max_lag=cfg.resid_lags,
                substeps=cfg.substeps, interpolation=cfg.input_interpolation,
                q_limit=q_limit, engine=cfg.engine,
            )
            for m, name in [(model, "rbf"), *others]
        ]  # fmt: skip
        scores = pd.concat([s for s, _ in scored], ignore_index=True)
        table = table.merge(scores, on=["dataset", "model"], how="left", validate="one_to_one")
        residuals = pd.concat([c for _, c in scored], ignore_index=True)
        watch.lap("k-step and residuals")
    table["reason"] = ""
    q_est, qd_est = estimation_motion(tables, derivs)
    for other, name in [(model, "rbf"), *others]:
        if not isinstance(other, RBFModel) or not q_est.size:
            continue  # the analytical model is the designed one: its stability is physics
        stable, reason = model_is_stable(other, q_est, q_dot=qd_est)
        if not stable:
            table = mark_unstable(table, name, reason)
    watch.lap("stability")
    return ValidateResult(table, simulated, watch.times, residuals)


def estimation_motion(tables, derivs) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of the estimation data sets (where the model was fitted).

    Parameters
    ----------
    tables, derivs : mapping of str to pandas.DataFrame
        Canonical tables (``attrs['role']``) and their derivatives (``q_dot``).

    Returns
    -------
    q : ndarray, shape (n,)
        Their ``q`` concatenated [unit of q] (empty without estimation data).
    q_dot : ndarray, shape (n,)
        Their ``q_dot`` [unit of q / s].
    """
    names = [n for n, t in tables.items() if t.attrs.get("role") == "estimation"]
    if not names:
        return np.empty(0), np.empty(0)
    q = np.concatenate([tables[n]["q"].to_numpy() for n in names])
    q_dot = np.concatenate([derivs[n]["q_dot"].to_numpy() for n in names])
    return q, q_dot


def extrapolation(tables, margin: float, report_unit: str | None = None) -> dict[str, str]:
    """Per data set, where it applies an input beyond the estimation's driven range, or ``""``.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical tables (``q``, ``v1..vN``; ``attrs['role']``, ``attrs['units']``).
    margin : float
        One RBF width: positions this close to the driven range count as informed [unit of q].
    report_unit : str, optional
        ``[validate] report_unit``, the unit the positions are worded in (default mm for q
        in m, :func:`debist.validate.freerun.report_factor`).

    Returns
    -------
    dict of str to str
        :func:`debist.identify.driven.beyond_driven` of every data set (q in the report
        unit); ``""`` for the estimation data sets and when there are none.
    """
    est = [t for t in tables.values() if t.attrs.get("role") == "estimation"]
    if not est:
        return {name: "" for name in tables}
    ranges = driven_ranges(
        np.concatenate([t["q"].to_numpy() for t in est]),
        np.vstack([t[input_columns(t)].to_numpy() for t in est]),
    )
    out = {}
    for name, t in tables.items():
        unit = t.attrs.get("units", {}).get("q", "m")
        factor, shown = report_factor(unit, report_unit)
        out[name] = (
            ""
            if t.attrs.get("role") == "estimation"
            else beyond_driven(
                ranges, t["q"].to_numpy(), t[input_columns(t)].to_numpy(), margin, factor, shown
            )
        )
    return out


def execute(ctx: StageInputs) -> StageOutput:
    """Run the validate stage: the identified model (and its equation-error fit) in free run.

    Parameters
    ----------
    ctx : StageInputs
        The workflow's ``[validate]`` section, the identified model and the data.

    Returns
    -------
    StageOutput
        ``nrmse.parquet``, ``residuals.parquet`` and ``simulated/<table>.parquet`` (the
        report draws them); summary: the NRMSE rows, the published results to print beside
        them, the data-set order and what the report's figures need (``init_samples``, the
        ``report_unit`` or None).

    Raises
    ------
    WorkflowError
        As :func:`run_validate`.
    """
    watch = Stopwatch()
    tree = ctx.read_h5("identify", "model.h5")
    model = RBFModel.from_tree(tree)
    ls = tree.get("equation_error")
    baseline = RBFModel.from_tree({"model": ls}) if ls is not None else None
    section = ctx.section("validate")
    cfg = ValidateConfig.from_dict(section)
    diag = tree.get("diagnostics", {})
    replicates = None
    if "theta_boot" in diag and "theta" in diag:
        columns = np.asarray(diag["columns"]).astype(str).tolist()
        replicates = (columns, np.asarray(diag["theta_boot"]) - np.asarray(diag["theta"]))
    tables, derivs = ctx.tables("ingest"), ctx.tables("differentiate")
    thin = under_excitation(ctx.summary("identify").get("excitation", {}))
    watch.lap("read inputs")
    res = run_validate(model, tables, derivs, section, baseline, ctx.physics(), replicates)
    watch.restart()  # its own parts are in res.timings
    beyond = extrapolation(tables, model.basis.sigma, cfg.report_unit)
    # a model whose physical curves hold nowhere is a simulator only: its rows say so
    identified = ctx.summary("identify").get("identified") or {}
    unsure = simulation_only(identified, fitted_curves(model))
    table = res.table.assign(
        under_excited=thin,
        extrapolated=res.table.dataset.map(beyond),
        simulation_only=np.where(res.table.model.str.startswith("rbf"), unsure, ""),
    )
    table = with_verdicts(table)
    outputs: dict[str, Any] = {"nrmse.parquet": table}
    if res.residuals is not None:
        outputs["residuals.parquet"] = res.residuals
    outputs.update({f"simulated/{n}.parquet": s for n, s in res.simulated.items()})
    summary = {
        "table": table.to_dict(orient="records"),
        "published": list(section.get("published", [])),
        "order": [d.name for d in ctx.wf.datasets],
        "init_samples": cfg.init_samples,
        "report_unit": cfg.report_unit,
    }
    timings = {"read inputs": watch.times["read inputs"], **res.timings}
    return StageOutput(outputs, summary, timings)
