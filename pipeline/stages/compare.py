"""The compare stage: SINDy and a polynomial NARX model beside the identified model.

SINDy is fitted on the same data and derivatives and run free with the same simulator; the
NARX model (:mod:`debist.model.narx`), a discrete-time black box, is chosen and fitted on the
estimation records and run free on every data set from its first measured samples. Both
join the NRMSE table of Eq. 41, so every row's verdict says whether the physics-informed
model beats them.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core import progress
from debist.core.artifacts import H5Tree
from debist.core.beside import BesideRun
from debist.core.errors import DebistError, DebistWarning, IdentificationError
from debist.core.forking import fork_workers
from debist.identify.physics_prior import analytical_for
from debist.identify.records import estimation_records
from debist.model.narx import NARX_MISSING, NarxConfig, fit_narx, narx_available
from debist.model.sindy import SindyConfig, fit_sindy
from debist.physics.freerun import analytical_model
from debist.report.tables import with_verdicts
from debist.simulate.freerun import SimulationResult
from debist.stages import StageInputs, StageOutput
from debist.stages.sindy_choice import choose_sindy
from debist.validate.config import ValidateConfig
from debist.validate.datasets import validation_datasets
from debist.validate.freerun import default_q_limit, score_free_runs, validate_model

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

#: Columns of validate's NRMSE table that the compare stage carries over per data set.
CAVEATS = ("under_excited", "extrapolated")

__all__ = ["CompareResult", "execute", "preload", "prepare", "run_peers", "with_rbf_rows"]


@dataclass(frozen=True)
class CompareResult:
    """Output of the comparison stage: the SINDy model beside the RBF model.

    Attributes
    ----------
    model : SindyModel
        The identified SINDy model.
    table : pandas.DataFrame
        The SINDy and NARX rows (:func:`run_peers`), with the RBF rows of the validation
        stage before them (:func:`with_rbf_rows`), per data set: NRMSE of q, q_dot, q_ddot,
        RMS, divergence and ``n_params``.
    simulated : dict of str to pandas.DataFrame
        SINDy free runs per data set.
    summary : dict
        The equations and the number of terms.
    timings : dict of str to float
        Wall times [s] of the SINDy fit and free runs and (``narx``) the time spent on the
        NARX peer or waiting for it (not reproducible, hence kept out of the hashed
        artifacts).
    narx : NarxModel or None
        The NARX peer (None when disabled or not installed).
    """

    model: Any
    table: pd.DataFrame
    simulated: dict[str, pd.DataFrame]
    summary: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    narx: Any = None


def with_rbf_rows(peers: CompareResult, rbf_table: pd.DataFrame) -> CompareResult:
    """Return the peers' result with the RBF model's rows before theirs.

    Parameters
    ----------
    peers : CompareResult
        :func:`run_peers`'s result.
    rbf_table : pandas.DataFrame
        The validation stage's NRMSE table of the RBF model.

    Returns
    -------
    CompareResult
        The same, its table ``rbf_table``'s rows followed by the peers' (a new index).
    """
    return replace(peers, table=pd.concat([rbf_table, peers.table], ignore_index=True))


def run_peers(tables, derivs, section: Mapping[str, Any], physics=None) -> CompareResult:
    """Fit SINDy and the NARX peer on the estimation data; free-run them as the RBF model.

    SINDy is fitted on the same data and derivatives and run free with the same simulator.
    Nothing here reads the identified model: the peers can be fitted while it is identified
    and validated (the stage's first part, :func:`prepare`).

    Parameters
    ----------
    tables, derivs : mapping of str to pandas.DataFrame
        Measured data and derivatives of every data set (the stages' outputs).
    section : mapping
        ``{"sindy": [compare] section, "validate": [validate] section}``.
    physics : PrototypeParams, optional
        The ``[physics]`` prototype; its ``phi(q)`` map gives the SINDy rows ``nrmse_phi``.

    Returns
    -------
    CompareResult
        Its table the SINDy rows, then the NARX peer's.

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
    sindy_section = dict(section["sindy"])
    ncfg = NarxConfig.from_dict(sindy_section.pop("narx", None))
    cfg = SindyConfig.from_dict(sindy_section)
    vcfg = ValidateConfig.from_dict(section["validate"])
    records = estimation_records(tables, derivs)
    datasets = validation_datasets(tables, derivs)
    analytical = analytical_for(physics, datasets, replace(vcfg, analytical=False))
    phi = analytical.phi if analytical else None
    # one divergence bound for both peers: from the estimation records' q, as fit_sindy's
    # q_range (SindyModel.q_range) and default_q_limit define it
    q_est = np.concatenate([r.q for r in records])
    q_range = (float(q_est.min()), float(q_est.max()))
    q_limit = vcfg.q_limit if vcfg.q_limit is not None else default_q_limit(q_range)
    narx_job = _start_narx(records, datasets, cfg.input_map, ncfg, vcfg, q_limit, phi)
    progress.report("compare: SINDy fit", 0, 1)
    q_unit = next(iter(tables.values())).attrs.get("units", {}).get("q", "m")
    cfg, search = choose_sindy(records, cfg, sindy_section, vcfg, q_unit,
                               _input_units(tables, records[0].v))  # fmt: skip
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
    t0 = time.perf_counter()
    table, simulated = validate_model(model, "sindy", datasets, vcfg, q_limit, phi)
    sim_time = time.perf_counter() - t0
    table["n_params"] = model.n_params
    summary = {"equations": model.equations, "n_params": model.n_params,
               "degree": cfg.degree, "threshold": cfg.threshold,
               "search": [{k: (None if v == np.inf else v) for k, v in r.items()}
                          for r in search]}  # fmt: skip
    timings = {"fit": model.fit_time, "simulate": sim_time}
    narx, parts = None, [table]
    if narx_job is not None:
        t0 = time.perf_counter()
        narx, narx_table, runs = narx_job()
        for name, q_sim in runs.items():
            simulated[name] = simulated[name].assign(q_sim_narx=q_sim)
        parts.append(narx_table)
        timings["narx"] = time.perf_counter() - t0
        summary["narx"] = _narx_summary(narx)
    combined = pd.concat(parts, ignore_index=True)
    return CompareResult(model, combined, simulated, summary, timings, narx)


def _start_narx(records, datasets, input_map, ncfg, vcfg, q_limit, phi):
    """Start the NARX peer (:func:`_narx_rows`); return a call that gives its result, or None.

    It does not depend on the SINDy search, so with a second core it runs in a forked process
    beside it (:class:`debist.core.beside.BesideRun`: the same code on the same inputs, so the
    same numbers); otherwise the call runs it here. None when the peer is off.
    """
    if not ncfg.enabled:
        return None
    job = partial(_narx_rows, records, datasets, input_map, ncfg, vcfg, q_limit, phi)
    if fork_workers(2) < 2:
        return job
    return BesideRun(job, "the NARX peer").result


def _narx_rows(records, datasets, input_map, ncfg, vcfg, q_limit, phi):
    """Fit the NARX peer and score its free runs.

    Returns the model (None without one), its rows of the NRMSE table and its free runs' q
    per data set (the simulated tables' ``q_sim_narx``). Without SysIdentPy, or when no
    candidate structure survives, the rows say so (status) with NaN numbers: the peer is
    never silently missing.
    """
    status, narx = None, None
    if not narx_available():
        status = NARX_MISSING
    else:
        progress.report("compare: NARX", 0, 1)
        try:
            narx = fit_narx([r.q for r in records], [r.v for r in records], input_map, ncfg,
                            q_limit)  # fmt: skip
        except IdentificationError as exc:
            status = f"not identified: {exc}"
        progress.report("compare: NARX", 1, 1)
    if narx is None:
        warnings.warn(f"compare: the NARX peer is {status}", DebistWarning, stacklevel=2)
        nan = float("nan")
        rows = [{"dataset": ds.name, "role": ds.role, "model": "narx", "n_samples": ds.q.size,
                 "nrmse_q": nan, "nrmse_q_dot": nan, "nrmse_q_ddot": nan, "rms_q": nan,
                 "diverged": False, "status": status} for ds in datasets]  # fmt: skip
        return None, pd.DataFrame(rows).assign(n_params=0), {}
    results = {}
    for ds in datasets:
        q_sim, at = narx.simulate(ds.q, ds.v)
        nan = np.full(ds.q.size, np.nan)  # a NARX model predicts q only
        results[ds.name] = SimulationResult(q_sim, nan, nan, q_sim[:, None], at >= 0, at, 0)
    table, runs = score_free_runs("narx", datasets, results, vcfg, phi)
    q_sims = {name: run["q_sim"].to_numpy() for name, run in runs.items()}
    return narx, table.assign(n_params=narx.n_params), q_sims


def _narx_summary(narx) -> dict[str, Any]:
    """Summarise the NARX peer's structure and search for the stage summary (NaN as None)."""
    if narx is None:
        return {}
    search = narx.candidates.replace([np.inf], np.nan)
    return {
        "degree": narx.degree,
        "lag": narx.lag,
        "input_map": narx.input_map,
        "n_params": narx.n_params,
        "candidates": search.astype(object).where(search.notna(), None).to_dict(orient="records"),
    }


def _input_units(tables, v) -> list[str]:
    """Units of the inputs ``v1..vN`` from the ingested tables' attrs (V where not given)."""
    units = next(iter(tables.values())).attrs.get("units", {})
    n = 1 if np.ndim(v) == 1 else np.shape(v)[1]
    return [units.get(f"v{i + 1}", "V") for i in range(n)]


def preload(ctx: StageInputs) -> None:
    """Load what :func:`prepare` and the stages run while it runs beside them both load.

    The runner calls it here just before it forks :func:`prepare` (the registry's
    ``early``): the forked process inherits what it loads instead of loading it a second
    time, on the core the stages here need. With ``[physics]``, the prototype's analytical
    model (cached per prototype: the forked SINDy rows' ``phi(q)``, identify's curves and
    ``m_q``, validate's analytical row); with the NARX peer on, SysIdentPy and matplotlib
    (SysIdentPy imports pyplot; the NARX model comes back pickled, so this process imports
    SysIdentPy anyway, and matplotlib before it forks the workers that draw the figures of
    identify and report). Loads nothing else, decides nothing: a prototype whose model
    cannot be built is left to the stage that needs it to report.

    Parameters
    ----------
    ctx : StageInputs
        The ``[physics]`` section and the ``[compare.narx]`` table.

    References
    ----------
    Python documentation, :mod:`multiprocessing` (the ``fork`` start method: the child
    starts as a copy of the parent's memory).
    """
    # an error here (a prototype without a static path, an invalid [compare.narx]) is left
    # to the stage that meets it to raise, in its own context
    with contextlib.suppress(DebistError):
        physics = ctx.physics()
        if physics is not None:
            analytical_model(physics)
        if NarxConfig.from_dict(dict(ctx.stage_config("compare")["sindy"]).get("narx")).enabled:
            narx_available()


def prepare(ctx: StageInputs) -> CompareResult:
    """Run the stage's first part: the peers (:func:`run_peers`), from ingest and differentiate.

    The runner may call it in a forked process while identify and validate run (the
    registry's ``early``) and hand its result to :func:`execute`.

    Parameters
    ----------
    ctx : StageInputs
        The ``[compare]`` and ``[validate]`` sections and the data.

    Returns
    -------
    CompareResult
        The SINDy and NARX rows, models and free runs.

    Raises
    ------
    WorkflowError, IdentificationError
        As :func:`run_peers`.
    """
    return run_peers(
        ctx.tables("ingest"), ctx.tables("differentiate"), ctx.stage_config("compare"),
        ctx.physics(),
    )  # fmt: skip


def execute(ctx: StageInputs, prepared: CompareResult | None = None) -> StageOutput:
    """Run the compare stage: SINDy and the NARX peer beside the validated RBF model.

    Parameters
    ----------
    ctx : StageInputs
        The ``[compare]`` and ``[validate]`` sections, the data and the validation table.
    prepared : CompareResult, optional
        :func:`prepare`'s result for this ``ctx``, if it ran already; else it runs here.

    Returns
    -------
    StageOutput
        ``sindy.h5``, ``narx.h5`` (with the NARX peer), ``nrmse.parquet`` (RBF, SINDy and
        NARX rows) and ``simulated/<table>.parquet`` (SINDy's free run, NARX's as
        ``q_sim_narx``); summary: the equations, the NARX structure and the combined table.

    Raises
    ------
    WorkflowError, IdentificationError
        As :func:`run_peers`.
    """
    validated = ctx.read_parquet("validate", "nrmse.parquet")
    res = with_rbf_rows(prepare(ctx) if prepared is None else prepared, validated)
    # every model is fitted on the same estimation data and run on the same records: what
    # the data lack (under-excited) and ask for (extrapolated), each row says as validate's
    per_dataset = validated.drop_duplicates("dataset").set_index("dataset")
    table = res.table.assign(**{
        c: res.table.dataset.map(per_dataset[c]).fillna("") if c in per_dataset else ""
        for c in CAVEATS
    })  # fmt: skip
    table = with_verdicts(table)
    outputs: dict[str, Any] = {
        "sindy.h5": H5Tree(res.model.to_tree()),
        "nrmse.parquet": table,
    }
    if res.narx is not None:
        outputs["narx.h5"] = H5Tree(res.narx.to_tree())
    outputs.update({f"simulated/{n}.parquet": s for n, s in res.simulated.items()})
    summary = {
        **res.summary,
        "table": table.to_dict(orient="records"),
        "published": list(ctx.section("validate").get("published", [])),
        "order": [d.name for d in ctx.wf.datasets],
    }
    return StageOutput(outputs, summary, res.timings)
