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


def physics_prior(physics, records: Sequence[Record], n_grid: int = 2001):
    """Tabulate the analytical model's curves as the backbone of the RBF model.

    Parameters
    ----------
    physics : PrototypeParams
        The workflow's ``[physics]`` prototype.
    records : sequence of Record
        Estimation data (``q`` [m]); the grid covers them and at least +-25 mm.
    n_grid : int
        Grid points.

    Returns
    -------
    pipeline.identify.terms.PhysicsPrior

    Raises
    ------
    WorkflowError
        If there is no ``[physics]`` section or the data have other than two inputs.

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26, 33.
    """
    from pipeline.identify.terms import PHYSICS_TERMS, PhysicsPrior
    from pipeline.physics.reduced import reduced_curves

    if physics is None:
        raise WorkflowError(
            f"[identify] backbone terms {PHYSICS_TERMS} need a [physics] section (the prototype)"
        )
    if any(r.v.shape[1] != 2 for r in records):
        raise WorkflowError("[identify] physics_* terms need the two DE voltages v1, v2")
    q_max = max(25e-3, 1.2 * max(float(np.max(np.abs(r.q))) for r in records))
    grid = np.linspace(-q_max, q_max, n_grid)
    cur = reduced_curves(physics, grid)
    return PhysicsPrior(q=grid, c=cur.c, d=cur.d, g=np.stack([cur.g1, cur.g2], axis=1))


def physics_mass(physics) -> float:
    """Generalised mass ``m_q`` of the analytical reduced model at ``q = 0`` [kg] (Eq. 26).

    Parameters
    ----------
    physics : PrototypeParams or None
        The workflow's ``[physics]`` prototype.

    Returns
    -------
    float
        ``Phi^T M Phi`` at ``q = 0`` [kg] (0.0402 kg for Table 1).

    Raises
    ------
    WorkflowError
        Without a ``[physics]`` section.

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (a constant m_q).
    """
    from pipeline.physics.reduced import reduced_curves

    if physics is None:
        raise WorkflowError("[identify] m_q = 'physics' needs a [physics] section")
    return float(reduced_curves(physics, np.array([0.0])).m_q[0])


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


def analytical_for(physics, datasets: Sequence[DataSet], cfg: ValidateConfig):
    """Build the prototype's analytical reduced model, for ``phi(q)`` and its own row.

    Parameters
    ----------
    physics : PrototypeParams or None
        The ``[physics]`` parameters; None when the workflow has none.
    datasets : sequence of DataSet
        The data to validate on (``q`` must be in metres, two DE voltages).
    cfg : ValidateConfig
        ``analytical`` asks for the model's own row.

    Returns
    -------
    pipeline.physics.freerun.AnalyticalModel or None
        None without ``[physics]``.

    Raises
    ------
    WorkflowError
        If ``analytical = true`` without ``[physics]``, or the data are not a DE rig's
        (``q`` not in metres or not two inputs).

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26, Table 2.
    """
    if physics is None:
        if cfg.analytical:
            raise WorkflowError("[validate] analytical = true needs a [physics] section")
        return None
    for ds in datasets:
        if ds.q_unit != "m" or ds.v.shape[1] != 2:
            raise WorkflowError(
                f"[physics] describes a DE prototype (q [m], inputs v1, v2 [V]); data set "
                f"'{ds.name}' has q in {ds.q_unit!r} and {ds.v.shape[1]} input(s)"
            )
    from pipeline.physics.freerun import analytical_model

    return analytical_model(physics)


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


@dataclass(frozen=True)
class AnalyzeResult:
    """Result of the analyze stage.

    Attributes
    ----------
    tree : dict
        Contents of ``statics.h5`` (:func:`pipeline.physics.analysis.analysis_tree`).
    figures : dict of str to matplotlib.figure.Figure
        Fig. 3, 4, 5, 6a, 7 and the reduced model's curves.
    summary : dict
        Operating points, bifurcation points [m] and the full vs reduced NRMSE [-].
    """

    tree: dict[str, Any]
    figures: dict[str, Any]
    summary: dict[str, Any]


def run_analyze(params, section: Mapping[str, Any]) -> AnalyzeResult:
    """Design analysis of Section 3 for one prototype (``debist analyze``).

    Parameters
    ----------
    params : pipeline.physics.params.PrototypeParams
        The prototype [SI].
    section : mapping
        The ``[analyze]`` section (:class:`pipeline.physics.analysis.AnalyzeConfig`).

    Returns
    -------
    AnalyzeResult

    Raises
    ------
    WorkflowError
        For an invalid section.
    StaticsError
        If the static analysis fails for these parameters.

    References
    ----------
    Masoud & Maas 2025, Section 3, Fig. 3-7.
    """
    from pipeline.config import config_from_section
    from pipeline.physics.analysis import (
        AnalyzeConfig,
        analysis_figures,
        analysis_tree,
        run_analysis,
    )

    cfg = config_from_section(AnalyzeConfig, section, "[analyze]")
    res = run_analysis(params, cfg)
    cmp = res.comparison
    summary = {
        "b": params.b,
        "z_b_min": res.sweep.z_b_min,
        "z_b_max": res.sweep.z_b_max,
        "operating_points": {
            name: [
                {"q": float(q), "stable": bool(s)}
                for q, s in zip(point["q"], point["stable"], strict=True)
            ]
            for name, point in res.operating_points.items()
        },
        "nrmse_q": cmp.nrmse_q,
        "nrmse_phi": cmp.nrmse_phi,
        "switches": {
            "full": [float(cmp.full.q.min()), float(cmp.full.q.max())],
            "reduced": [float(cmp.reduced.q.min()), float(cmp.reduced.q.max())],
        },
    }
    return AnalyzeResult(analysis_tree(res), analysis_figures(res), summary)


@dataclass(frozen=True)
class RigResult:
    """Result of the rig stage (the virtual rig's experiments).

    Attributes
    ----------
    outputs : dict
        ``<experiment>.mat`` (:class:`pipeline.artifacts.MatRecording`) and
        ``<experiment>_truth.h5`` (:class:`pipeline.artifacts.H5Tree`) per experiment.
    summary : dict
        Per experiment: samples, q range [m], 3 kV switchings, saturated samples,
        integration statistics and wall time [s].
    """

    outputs: dict[str, Any]
    summary: dict[str, Any]


def run_rig(physics: Mapping[str, Any], section: Mapping[str, Any]) -> RigResult:
    """Simulate the virtual rig's experiments (``debist simulate-rig``).

    Parameters
    ----------
    physics : mapping
        The ``[physics]`` section (nominal prototype).
    section : mapping
        The ``[rig]`` section (:class:`pipeline.rig.experiment.RigConfig`).

    Returns
    -------
    RigResult

    Raises
    ------
    WorkflowError
        For an invalid section.
    DebistError
        If an integration fails (named by experiment).

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1, Fig. 11a.
    """
    from pipeline.artifacts import H5Tree, MatRecording
    from pipeline.errors import DebistError
    from pipeline.rig.experiment import (
        CREATED,
        RigConfig,
        rig_recording,
        run_experiment,
        truth_tree,
    )

    cfg = RigConfig.from_dict(section, physics)
    grid = np.linspace(-20e-3, 20e-3, 401)
    outputs: dict[str, Any] = {}
    summary: dict[str, Any] = {}
    for name, exp in cfg.experiments.items():
        run = run_experiment(cfg, name)
        if not run.success:
            raise DebistError(f"[rig.experiments.{name}]: the plant integration failed: "
                              f"{run.message}")  # fmt: skip
        outputs[f"{name}.mat"] = MatRecording(rig_recording(run, name, cfg), exp.format, CREATED)
        outputs[f"{name}_truth.h5"] = H5Tree(truth_tree(run, cfg, grid))
        sign = np.sign(run.q_true)
        summary[name] = {
            "samples": int(run.t.size),
            "q_min": float(run.q_true.min()),
            "q_max": float(run.q_true.max()),
            "well_changes": int(np.count_nonzero(np.diff(sign[np.abs(run.q_true) > 5e-3]))),
            "saturated": int(np.count_nonzero(run.saturated)),
            "nfev": run.nfev,
            "seconds": run.wall_time,
        }
    return RigResult(outputs, summary)
