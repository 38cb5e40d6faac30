"""The compare stage: SINDy on the same data and derivatives, free-run with the same simulator."""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from pipeline import progress
from pipeline.datasets import validation_datasets
from pipeline.physics_stages import analytical_for
from pipeline.records import estimation_records
from pipeline.stages import StageInputs, StageOutput
from pipeline.validate import ValidateConfig, default_q_limit, validate_model

__all__ = ["CompareResult", "execute", "run_compare"]


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
        The equations and the number of terms.
    timings : dict of str to float
        Wall times [s] of the fit and of the free runs (not reproducible, hence kept out
        of the hashed artifacts).
    """

    model: Any
    table: pd.DataFrame
    simulated: dict[str, pd.DataFrame]
    summary: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


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
    from pipeline.sindy import SindyConfig, fit_sindy

    cfg = SindyConfig.from_dict(dict(section["sindy"]))
    vcfg = ValidateConfig.from_dict(section["validate"])
    records = estimation_records(tables, derivs)
    progress.report("compare: SINDy fit", 0, 1)
    model = fit_sindy(
        [r.q for r in records],
        [r.q_dot for r in records],
        [r.q_ddot for r in records],
        [r.v for r in records],
        records[0].dt,
        cfg,
        input_units=_input_units(tables, records[0].v),
    )
    progress.report("compare: SINDy fit", 1, 1)
    q_limit = vcfg.q_limit if vcfg.q_limit is not None else default_q_limit(model.q_range)
    datasets = validation_datasets(tables, derivs)
    analytical = analytical_for(physics, datasets, replace(vcfg, analytical=False))
    t0 = time.perf_counter()
    table, simulated = validate_model(
        model, "sindy", datasets, vcfg, q_limit, analytical.phi if analytical else None
    )
    sim_time = time.perf_counter() - t0
    table["n_params"] = model.n_params
    combined = pd.concat([rbf_table, table], ignore_index=True)
    summary = {"equations": model.equations, "n_params": model.n_params}
    timings = {"fit": model.fit_time, "simulate": sim_time}
    return CompareResult(model, combined, simulated, summary, timings)


def _input_units(tables, v) -> list[str]:
    """Units of the inputs ``v1..vN`` from the ingested tables' attrs (V where not given)."""
    units = next(iter(tables.values())).attrs.get("units", {})
    n = 1 if np.ndim(v) == 1 else np.shape(v)[1]
    return [units.get(f"v{i + 1}", "V") for i in range(n)]


def execute(ctx: StageInputs) -> StageOutput:
    """Run the compare stage: SINDy beside the validated RBF model.

    Parameters
    ----------
    ctx : StageInputs
        The ``[compare]`` and ``[validate]`` sections, the data and the validation table.

    Returns
    -------
    StageOutput
        ``sindy.h5``, ``nrmse.parquet`` (RBF and SINDy rows) and
        ``simulated/<table>.parquet``; summary: the equations and the combined table.

    Raises
    ------
    WorkflowError, IdentificationError
        As :func:`run_compare`.
    """
    from pipeline.artifacts import H5Tree

    res = run_compare(
        ctx.tables("ingest"),
        ctx.tables("differentiate"),
        ctx.read_parquet("validate", "nrmse.parquet"),
        ctx.stage_config("compare"),
        ctx.physics(),
    )
    outputs: dict[str, Any] = {
        "sindy.h5": H5Tree(res.model.to_tree()),
        "nrmse.parquet": res.table,
    }
    outputs.update({f"simulated/{n}.parquet": s for n, s in res.simulated.items()})
    summary = {
        **res.summary,
        "table": res.table.to_dict(orient="records"),
        "published": list(ctx.section("validate").get("published", [])),
        "order": [d.name for d in ctx.wf.datasets],
    }
    return StageOutput(outputs, summary, res.timings)
