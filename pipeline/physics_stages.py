"""Stages and stage parts that use the physics model of Section 3.

The design analysis, the virtual rig, and the analytical model's parts in identification
and validation (backbone curves, m_q, phi(q)).

Pure functions like :mod:`pipeline.stages`: parameters and sections in, results out; the
runner writes the artifacts.

References
----------
Masoud & Maas 2025, Section 3 (analytical model), Sec. 5.1 (rig), Eq. 24-26, Table 2.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.errors import WorkflowError
from pipeline.identify import Record
from pipeline.validate import DataSet, ValidateConfig

__all__ = [
    "AnalyzeResult",
    "RigResult",
    "analytical_for",
    "physics_mass",
    "physics_prior",
    "run_analyze",
    "run_rig",
]


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
    from pipeline.rig.plant import true_curves

    cfg = RigConfig.from_dict(section, physics)
    curves = true_curves(cfg.rig, np.linspace(-20e-3, 20e-3, 401))
    outputs: dict[str, Any] = {}
    summary: dict[str, Any] = {}
    for name, exp in cfg.experiments.items():
        run = run_experiment(cfg, name)
        if not run.success:
            raise DebistError(f"[rig.experiments.{name}]: the plant integration failed: "
                              f"{run.message}")  # fmt: skip
        outputs[f"{name}.mat"] = MatRecording(rig_recording(run, name, cfg), exp.format, CREATED)
        outputs[f"{name}_truth.h5"] = H5Tree(truth_tree(run, cfg, curves))
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
