"""The analyze stage: the design analysis of Section 3 for one prototype (``debist analyze``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from debist.core.artifacts import Figure, H5Tree
from debist.core.config import config_from_section
from debist.core.errors import WorkflowError
from debist.core.fileformats import REPORT_DPI
from debist.physics.analysis import AnalyzeConfig, analysis_tree, run_analysis
from debist.physics.params import PrototypeParams
from debist.report.physics_plots import analysis_figures
from debist.stages import StageInputs, StageOutput

__all__ = ["AnalyzeResult", "execute", "run_analyze"]


@dataclass(frozen=True)
class AnalyzeResult:
    """Result of the analyze stage.

    Attributes
    ----------
    tree : dict
        Contents of ``statics.h5`` (:func:`debist.physics.analysis.analysis_tree`).
    figures : dict of str to matplotlib.figure.Figure
        Fig. 3, 4, 5, 6a, 7 and the reduced model's curves.
    summary : dict
        Operating points, bifurcation points [m] and the full vs reduced NRMSE [-].
    """

    tree: dict[str, Any]
    figures: dict[str, Any]
    summary: dict[str, Any]


def run_analyze(
    params, section: Mapping[str, Any], report_unit: str | None = None
) -> AnalyzeResult:
    """Design analysis of Section 3 for one prototype (``debist analyze``).

    Parameters
    ----------
    params : debist.physics.params.PrototypeParams
        The prototype [SI].
    section : mapping
        The ``[analyze]`` section (:class:`debist.physics.analysis.AnalyzeConfig`).
    report_unit : str, optional
        ``[validate] report_unit``, the unit the figures draw q in (default mm,
        :func:`debist.report.tables.physics_factor`).

    Returns
    -------
    AnalyzeResult

    Raises
    ------
    WorkflowError
        For an invalid section, or a prototype without a stable well to start the switching
        simulation from (or whose simulation the analysis cannot compare).
    StaticsError
        If the static analysis fails for these parameters.

    References
    ----------
    Masoud & Maas 2025, Section 3, Fig. 3-7.
    """
    cfg = config_from_section(AnalyzeConfig, section, "[analyze]")
    try:
        res = run_analysis(params, cfg)
    except WorkflowError:
        raise
    except ValueError as exc:  # the settings give a prototype without a well or a usable run
        raise WorkflowError(
            f"[physics] the prototype cannot be analysed: {exc}; check its parameters"
        ) from None
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
    return AnalyzeResult(analysis_tree(res), analysis_figures(res, report_unit), summary)


def execute(ctx: StageInputs) -> StageOutput:
    """Run the analyze stage on the workflow's prototype.

    Parameters
    ----------
    ctx : StageInputs
        The ``[physics]`` prototype and the ``[analyze]`` section.

    Returns
    -------
    StageOutput
        ``statics.h5`` and one PNG per figure; summary: operating points, bifurcation
        points and the full vs reduced NRMSE.

    Raises
    ------
    WorkflowError, StaticsError
        As :func:`run_analyze`.
    """
    params = ctx.physics() or PrototypeParams.from_dict({})
    res = run_analyze(params, ctx.section("analyze"), ctx.section("validate").get("report_unit"))
    outputs: dict[str, Any] = {"statics.h5": H5Tree(res.tree)}
    outputs.update({f"{n}.png": Figure(f, REPORT_DPI) for n, f in res.figures.items()})
    return StageOutput(outputs, res.summary)
