"""The differentiate stage: q_dot and q_ddot of every table (TVRegDiff by default)."""

from __future__ import annotations

from debist.differentiate.tables import differentiate_tables
from debist.stages import StageInputs, StageOutput

__all__ = ["execute", "run_differentiate"]


#: The stage's pure function: :func:`debist.differentiate.tables.differentiate_tables`.
run_differentiate = differentiate_tables


def execute(ctx: StageInputs) -> StageOutput:
    """Run the differentiate stage on the ingested tables.

    Parameters
    ----------
    ctx : StageInputs
        The workflow's ``[differentiate]`` section and the ingest artifacts.

    Returns
    -------
    StageOutput
        ``<table>.parquet`` per table; summary: whether each iterative solve converged,
        with ``alpha = "auto"`` the alpha chosen per table and the residuals it was chosen
        from, and for each table where TVRegDiff stopped at its iteration limit how far a
        run with more iterations moved q_dot and q_ddot
        (:func:`debist.differentiate.tvregdiff_method.longer_run`).

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
    longer = {n: d.attrs["longer_run"] for n, d in derivs.items() if "longer_run" in d.attrs}
    if longer:  # per stopped table: how far a run with more iterations moved q_dot, q_ddot
        summary["longer_run"] = longer
    return StageOutput({f"{n}.parquet": d for n, d in derivs.items()}, summary)
