"""The study stage: sensitivity studies of Fig. 11b (M, sigma_n) and Fig. 11c (alpha)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from debist.core.artifacts import Figure
from debist.core.fileformats import REPORT_DPI
from debist.stages import StageInputs, StageOutput
from debist.stages.studies import StudyConfig, alpha_study, rbf_grid_study

__all__ = ["execute", "preload", "run_study"]


def preload(ctx: StageInputs) -> None:
    """Load what the study and the stages run while it runs beside them both load.

    The runner calls it just before it forks the study (the registry's ``beside``): the
    forked process inherits what it loads instead of loading it a second time, on the core
    the stages here need. scipy.signal (the band-limited inputs of every free run, the
    spectra of the excitation check) and matplotlib's ``Figure`` (the study draws its
    figures in its process; identify and the report draw theirs in processes forked from
    this one). Loads nothing else, decides nothing.

    Parameters
    ----------
    ctx : StageInputs
        Not read: what the study loads does not depend on the workflow.

    References
    ----------
    Python documentation, :mod:`multiprocessing` (the ``fork`` start method: the child
    starts as a copy of the parent's memory).
    """
    del ctx
    importlib.import_module("scipy.signal").resample_poly  # noqa: B018 (loads a lazy stub)
    importlib.import_module("matplotlib.figure")


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
    study = dict(section["study"])
    identify = {**section["identify"], **study.pop("identify", {})}
    diff = dict(study.pop("differentiate", section["differentiate"]))
    cfg = StudyConfig.from_dict(study)
    grid = rbf_grid_study(tables, derivs, identify, section["validate"], cfg)
    alpha = alpha_study(tables, identify, section["validate"], diff, cfg)
    return {"rbf_grid": grid, "alpha": alpha}


def execute(ctx: StageInputs) -> StageOutput:
    """Run the study stage on the ingested tables and their derivatives.

    Parameters
    ----------
    ctx : StageInputs
        The ``[study]`` section with the sections it overrides, and the data.

    Returns
    -------
    StageOutput
        ``rbf_grid`` and ``alpha``: a Parquet table and a PNG figure each; summary: the
        tables' rows.

    Raises
    ------
    WorkflowError
        As :func:`run_study`.
    """
    results = run_study(
        ctx.tables("ingest"), ctx.tables("differentiate"), ctx.stage_config("study")
    )
    outputs: dict[str, Any] = {}
    for name, (table, figure) in results.items():
        outputs[f"{name}.parquet"] = table
        outputs[f"{name}.png"] = Figure(figure, REPORT_DPI)  # shown in the report
    summary = {name: table.to_dict(orient="records") for name, (table, _) in results.items()}
    return StageOutput(outputs, summary)
