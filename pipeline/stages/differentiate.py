"""The differentiate stage: q_dot and q_ddot of every table (TVRegDiff by default)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import pandas as pd

from debist import progress
from debist.errors import ConvergenceWarning
from debist.stages import StageInputs, StageOutput
from debist.stages.tables import sample_time

__all__ = ["execute", "run_differentiate"]


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
    from debist.differentiate import differentiate

    params = dict(section)
    method = params.pop("method", "tvregdiff")
    out = {}
    for i, name in enumerate(tables):
        progress.report("differentiate: data sets", i, len(tables))
        frame = tables[name]
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
        if "alpha_search" in res.info:  # alpha = "auto": what it chose, and from what
            deriv.attrs["alpha"] = res.info["alpha"]
            deriv.attrs["alpha_search"] = res.info["alpha_search"]
        out[name] = deriv
    progress.report("differentiate: data sets", len(tables), len(tables))
    return out


def execute(ctx: StageInputs) -> StageOutput:
    """Run the differentiate stage on the ingested tables.

    Parameters
    ----------
    ctx : StageInputs
        The workflow's ``[differentiate]`` section and the ingest artifacts.

    Returns
    -------
    StageOutput
        ``<table>.parquet`` per table; summary: whether each iterative solve converged and,
        with ``alpha = "auto"``, the alpha chosen per table and the residuals it was chosen
        from.

    Raises
    ------
    WorkflowError, RigLogError
        As :func:`run_differentiate`.
    """
    derivs = run_differentiate(ctx.tables("ingest"), ctx.section("differentiate"))
    summary: dict = {"converged": {n: d.attrs["converged"] for n, d in derivs.items()}}
    auto = {n: {"alpha": d.attrs["alpha"], "search": d.attrs["alpha_search"]}
            for n, d in derivs.items() if "alpha_search" in d.attrs}  # fmt: skip
    if auto:
        summary["auto_alpha"] = auto
    return StageOutput({f"{n}.parquet": d for n, d in derivs.items()}, summary)
