"""The pipeline's stages as pure functions: arrays and configuration in, results out.

No stage writes files or prints: :mod:`pipeline.runner` loads their inputs and
hands their results to :mod:`pipeline.artifacts`. Only ingest reads, because
reading rig logs is what it is for.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from pipeline.errors import ConvergenceWarning, RigLogError, WorkflowError
from pipeline.identify import FitDiagnostics, IdentifyConfig, RBFModel, Record, fit_rbf_model
from pipeline.physics_stages import analytical_for, physics_mass, physics_prior
from pipeline.validate import DataSet, ValidateConfig, validate_model
from pipeline.workflow import DatasetSpec

#: Largest relative deviation of a time step from the median accepted as uniform sampling.
UNIFORM_TOL = 0.05


def input_columns(frame: pd.DataFrame) -> list[str]:
    """Input channel names v1..vN of a canonical rig-log table, in order."""
    names, k = [], 1
    while f"v{k}" in frame.columns:
        names.append(f"v{k}")
        k += 1
    return names


def run_ingest(datasets: Sequence[DatasetSpec]) -> dict[str, pd.DataFrame]:
    """Read every data set into a canonical rig-log table.

    Parameters
    ----------
    datasets : sequence of DatasetSpec
        Data sets with their merged ingest sections.

    Returns
    -------
    dict of str to pandas.DataFrame
        Table name to table (``t [s], q, v1..vN [V], ...``). A data set split at
        logging gaps gives ``<name>.seg<k>`` tables, each with the same role.

    Raises
    ------
    RigLogError
        For a file or channel that cannot be used (names file and channel).
    WorkflowError
        For an invalid ingest section.
    """
    from pipeline.ingest import IngestSpec, load_rig_log

    tables: dict[str, pd.DataFrame] = {}
    for ds in datasets:
        spec = IngestSpec.from_dict(ds.ingest)
        segments = load_rig_log(ds.source, spec)
        for k, frame in enumerate(segments):
            name = ds.name if len(segments) == 1 else f"{ds.name}.seg{k}"
            frame.attrs["role"] = ds.role
            frame.attrs["dataset"] = ds.name
            tables[name] = frame
    return tables


def sample_time(frame: pd.DataFrame, name: str) -> float:
    """Uniform sample time of a table [s].

    Parameters
    ----------
    frame : pandas.DataFrame
        Table with a ``t`` column [s].
    name : str
        Table name for messages.

    Returns
    -------
    float
        Median time step [s].

    Raises
    ------
    RigLogError
        If a step deviates from the median by more than :data:`UNIFORM_TOL`.
    """
    steps = np.diff(frame["t"].to_numpy())
    dt = float(np.median(steps))
    worst = int(np.argmax(np.abs(steps - dt)))
    if abs(steps[worst] - dt) > UNIFORM_TOL * dt:
        raise RigLogError(
            f"non-uniform sampling in data set '{name}': step {steps[worst]:.6g} s at "
            f"t = {frame['t'].iloc[worst]:.6g} s against the median {dt:.6g} s; "
            "set [ingest] resample = {{ sample_time = ... }}",
            path=frame.attrs.get("source"),
            channel="t",
        )
    return dt


def run_differentiate(
    tables: Mapping[str, pd.DataFrame], section: Mapping[str, Any]
) -> dict[str, pd.DataFrame]:
    """Differentiate q of every table twice (TVRegDiff by default).

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical rig-log tables.
    section : mapping
        The ``[differentiate]`` section: ``method`` plus that method's parameters.

    Returns
    -------
    dict of str to pandas.DataFrame
        Per table: ``t [s], q, q_hat, q_dot [unit/s], q_ddot [unit/s^2]``.

    Raises
    ------
    WorkflowError
        For an unknown method or parameter.
    RigLogError
        For non-uniform sampling.
    """
    from pipeline.differentiate import differentiate

    params = dict(section)
    method = params.pop("method", "tvregdiff")
    out = {}
    for name, frame in tables.items():
        dt = sample_time(frame, name)
        q = frame["q"].to_numpy()
        with warnings.catch_warnings():
            # Stopping at the configured iteration count is recorded as data (attrs).
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = differentiate(q, dt, method=method, params=params)
        deriv = pd.DataFrame(
            {
                "t": frame["t"].to_numpy(),
                "q": q,
                "q_hat": res.x_hat,
                "q_dot": res.x_dot,
                "q_ddot": res.x_ddot,
            }
        )
        deriv.attrs.update({"method": method, "converged": bool(res.converged), "dt": dt})
        out[name] = deriv
    return out


@dataclass(frozen=True)
class IdentifyResult:
    """Output of the identification stage.

    Attributes
    ----------
    model : RBFModel
        The identified model.
    diagnostics : FitDiagnostics
        Rank, condition number, residuals, T_z trace.
    curves : pandas.DataFrame
        Characteristic curves on a grid: ``q, c, d, cq, g1..gN, dC1_dq..dCN_dq``.
    summary : dict
        Scalars for reports.
    equation_error_model : RBFModel or None
        The least-squares model before simulation-error refinement.
    """

    model: RBFModel
    diagnostics: FitDiagnostics
    curves: pd.DataFrame
    summary: dict[str, Any] = field(default_factory=dict)
    equation_error_model: RBFModel | None = None


def estimation_records(tables, derivs) -> list[Record]:
    """Build identification records from the estimation tables and their derivatives."""
    records = []
    for name, frame in tables.items():
        if frame.attrs.get("role") != "estimation":
            continue
        d = derivs[name]
        v = frame[input_columns(frame)].to_numpy()
        records.append(
            Record(
                name,
                frame["q"].to_numpy(),
                d["q_dot"].to_numpy(),
                d["q_ddot"].to_numpy(),
                v,
                float(d.attrs["dt"]),
            )
        )
    if not records:
        raise WorkflowError("no estimation data set: mark one with role = 'estimation'")
    return records


def run_identify(tables, derivs, section: Mapping[str, Any], physics=None) -> IdentifyResult:
    """Identify the RBF model (Eq. 37-40) on the estimation data sets.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical tables (``attrs['role']`` tells estimation data).
    derivs : mapping of str to pandas.DataFrame
        Their derivatives.
    section : mapping
        The ``[identify]`` section (see :class:`IdentifyConfig`).
    physics : PrototypeParams, optional
        The ``[physics]`` prototype, whose curves the ``physics_*`` backbone terms use and
        whose ``m_q`` at ``q = 0`` ``m_q = "physics"`` takes (:func:`physics_mass`).

    Returns
    -------
    IdentifyResult

    Raises
    ------
    IdentificationError
        If the problem is under-excited, rank deficient or badly conditioned.
    WorkflowError
        For an invalid section.
    """
    import time

    from pipeline.identify.refine import refine_config, refine_model
    from pipeline.identify.terms import PHYSICS_TERMS

    section = dict(section)
    if section.get("m_q") == "physics":
        section["m_q"] = physics_mass(physics)
    cfg = IdentifyConfig.from_dict(section)
    t0 = time.perf_counter()
    records = estimation_records(tables, derivs)
    if set(PHYSICS_TERMS) & set(cfg.backbone):
        cfg = replace(cfg, prior=physics_prior(physics, records))
    model, diag = fit_rbf_model(records, cfg)
    fit_time = time.perf_counter() - t0
    ls_model, refine = model, None
    rcfg = refine_config(cfg.refine)
    if rcfg is not None:
        res = refine_model(model, diag, records, cfg, rcfg)
        model = res.model
        refine = {
            "accepted": res.accepted,
            "window_rms_equation_error": res.window_rms_ls,
            "window_rms_simulation_error": res.window_rms_refined,
            "full_rms_equation_error": res.full_rms_ls,
            "full_rms_simulation_error": res.full_rms_refined,
            "nfev": res.nfev,
            "message": res.message,
            "seconds": res.seconds,
        }
    grid = np.linspace(model.q_range[0], model.q_range[1], 201)
    cur = model.curves(grid)
    curves = {"q": grid, "c": cur["c"], "d": cur["d"], "cq": cur["cq"]}
    for j in range(model.n_inputs):
        curves[f"g{j + 1}"] = cur["g"][:, j]
        curves[f"dC{j + 1}_dq"] = cur["dC_dq"][:, j]
    summary = {
        "T_z": model.T_z,
        "m_q": model.m_q,
        "condition": diag.condition,
        "rank": diag.rank,
        "n_columns": len(diag.columns),
        "n_params": model.n_params,
        "n_samples": diag.n_samples,
        "fit_r2": diag.fit_r2,
        "residual_rms": diag.residual_rms,
        "backbone": {k: (np.asarray(v).tolist()) for k, v in model.backbone.items()},
        "published": dict(cfg.published or {}),
        "fit_time": fit_time,
        "refine": refine,
    }
    return IdentifyResult(model, diag, pd.DataFrame(curves), summary, ls_model)


def diagnostics_tree(diag: FitDiagnostics) -> dict[str, Any]:
    """HDF5 layout of the fit diagnostics."""
    return {
        "attrs": {
            "rank": diag.rank,
            "condition": diag.condition,
            "n_samples": diag.n_samples,
            "residual_rms": diag.residual_rms,
            "fit_r2": diag.fit_r2,
        },
        "columns": np.array(diag.columns),
        "singular_values": diag.singular_values,
        "support": diag.support,
        "T_z_trace": diag.T_z_trace,
    }


@dataclass(frozen=True)
class ValidateResult:
    """Output of the validation stage.

    Attributes
    ----------
    table : pandas.DataFrame
        NRMSE and RMS per data set and model.
    simulated : dict of str to pandas.DataFrame
        Measured and simulated trajectories per data set.
    figures : dict of str to matplotlib.figure.Figure
        Measured vs simulated q per data set.
    sim_time : float
        Wall time of the free runs [s].
    """

    table: pd.DataFrame
    simulated: dict[str, pd.DataFrame]
    figures: dict[str, Any]
    sim_time: float = 0.0


def validation_datasets(tables, derivs) -> list[DataSet]:
    """Assemble the measured data of every table for validation."""
    out = []
    for name, frame in tables.items():
        d = derivs[name]
        out.append(
            DataSet(
                name=name,
                role=frame.attrs.get("role", "validation"),
                t=frame["t"].to_numpy(),
                q=frame["q"].to_numpy(),
                q_dot=d["q_dot"].to_numpy(),
                q_ddot=d["q_ddot"].to_numpy(),
                v=frame[input_columns(frame)].to_numpy(),
                q_unit=frame.attrs.get("units", {}).get("q", "m"),
            )
        )
    return out


def run_validate(
    model: RBFModel,
    tables,
    derivs,
    section: Mapping[str, Any],
    baseline: RBFModel | None = None,
    physics=None,
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

    Returns
    -------
    ValidateResult

    Raises
    ------
    WorkflowError
        For an invalid section, or physics that does not fit the data.
    """
    import time

    from pipeline.plots import free_run_figure

    cfg = ValidateConfig.from_dict(section)
    span = max(abs(model.q_range[0]), abs(model.q_range[1]))
    q_limit = cfg.q_limit if cfg.q_limit is not None else 100.0 * span
    datasets = validation_datasets(tables, derivs)
    analytical = analytical_for(physics, datasets, cfg)
    phi = analytical.phi if analytical is not None else None
    t0 = time.perf_counter()
    table, simulated = validate_model(model, "rbf", datasets, cfg, q_limit, phi)
    sim_time = time.perf_counter() - t0
    table["n_params"] = model.n_params
    others = [(baseline, "rbf-ls")] if baseline is not None else []
    if cfg.analytical:
        others.append((analytical, "analytical"))
    for other, name in others:
        extra, _ = validate_model(other, name, datasets, cfg, q_limit, phi)
        extra["n_params"] = getattr(other, "n_params", 0)
        table = pd.concat([table, extra], ignore_index=True)
    units = {ds.name: ds.q_unit for ds in datasets}
    figures = {
        name: free_run_figure(
            sim,
            name,
            table[(table.dataset == name) & (table.model == "rbf")].iloc[0],
            cfg.init_samples,
            units[name],
        )
        for name, sim in simulated.items()
    }
    return ValidateResult(table, simulated, figures, sim_time)


@dataclass(frozen=True)
class CompareResult:
    """Output of the comparison stage: the SINDy model beside the RBF model.

    Attributes
    ----------
    model : SindyModel
        The identified SINDy model.
    table : pandas.DataFrame
        The RBF rows of the validation stage and the SINDy rows, per data set:
        NRMSE of q, q_dot, q_ddot, RMS, divergence and ``n_params``.
    simulated : dict of str to pandas.DataFrame
        SINDy free runs per data set.
    summary : dict
        Equations, fit and simulation times [s] (not reproducible, hence not in
        the Parquet/HDF5 artifacts).
    """

    model: Any
    table: pd.DataFrame
    simulated: dict[str, pd.DataFrame]
    summary: dict[str, Any] = field(default_factory=dict)


def run_compare(
    tables, derivs, rbf_table: pd.DataFrame, section: Mapping[str, Any], physics=None
) -> CompareResult:
    """Fit SINDy on the RBF model's data and derivatives; free-run it with the same simulator.

    Parameters
    ----------
    tables, derivs : mapping of str to pandas.DataFrame
        Measured data and derivatives of every data set (the stages' outputs).
    rbf_table : pandas.DataFrame
        The validation stage's NRMSE table of the RBF model (with ``n_params``).
    section : mapping
        ``{"sindy": [compare] section, "validate": [validate] section}``.
    physics : PrototypeParams, optional
        The ``[physics]`` prototype; its ``phi(q)`` map gives the SINDy rows ``nrmse_phi``.

    Returns
    -------
    CompareResult

    Raises
    ------
    WorkflowError
        For an invalid section.
    IdentificationError
        If the SINDy regression cannot be formed.

    References
    ----------
    Brunton, Proctor & Kutz 2016 (SINDy); Masoud & Maas 2025, Eq. 41.
    """
    import time

    from pipeline.sindy import SindyConfig, fit_sindy

    cfg = SindyConfig.from_dict(dict(section["sindy"]))
    vcfg = ValidateConfig.from_dict(section["validate"])
    records = estimation_records(tables, derivs)
    model = fit_sindy(
        [r.q for r in records],
        [r.q_dot for r in records],
        [r.q_ddot for r in records],
        [r.v for r in records],
        records[0].dt,
        cfg,
    )
    span = max(abs(model.q_range[0]), abs(model.q_range[1]))
    q_limit = vcfg.q_limit if vcfg.q_limit is not None else 100.0 * span
    datasets = validation_datasets(tables, derivs)
    analytical = analytical_for(physics, datasets, replace(vcfg, analytical=False))
    t0 = time.perf_counter()
    table, simulated = validate_model(
        model, "sindy", datasets, vcfg, q_limit, analytical.phi if analytical else None
    )
    sim_time = time.perf_counter() - t0
    table["n_params"] = model.n_params
    combined = pd.concat([rbf_table, table], ignore_index=True)
    summary = {
        "equations": model.equations,
        "fit_time": model.fit_time,
        "sim_time": sim_time,
        "n_params": model.n_params,
    }
    return CompareResult(model, combined, simulated, summary)


def run_study(tables, derivs, section: Mapping[str, Any]) -> dict[str, Any]:
    """Sensitivity studies of Fig. 11b (M, sigma_n) and Fig. 11c (TVRegDiff alpha).

    Parameters
    ----------
    tables, derivs : mapping of str to pandas.DataFrame
        Measured data and derivatives of every data set.
    section : mapping
        ``{"study": [study] section, "identify": ..., "validate": ...,
        "differentiate": ...}``; the study section may hold ``identify`` (keys
        overriding the identification settings for the studies) and
        ``differentiate`` (the TVRegDiff settings the alpha study varies, default
        the workflow's own).

    Returns
    -------
    dict
        ``rbf_grid`` and ``alpha``: (table, figure) pairs.

    Raises
    ------
    WorkflowError
        For an invalid section, or an alpha study without a TVRegDiff section.

    References
    ----------
    Masoud & Maas 2025, Fig. 11b and 11c, Sec. 5.2.
    """
    from pipeline.studies import StudyConfig, alpha_study, rbf_grid_study

    study = dict(section["study"])
    identify = {**section["identify"], **study.pop("identify", {})}
    diff = dict(study.pop("differentiate", section["differentiate"]))
    cfg = StudyConfig.from_dict(study)
    grid = rbf_grid_study(tables, derivs, identify, section["validate"], cfg)
    alpha = alpha_study(tables, identify, section["validate"], diff, cfg)
    return {"rbf_grid": grid, "alpha": alpha}
