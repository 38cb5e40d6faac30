"""The rig stage: the virtual rig's experiments (``debist simulate-rig``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from debist.core.artifacts import FileWriter, H5Tree
from debist.core.errors import DebistError
from debist.rig.dspace import write_recording
from debist.rig.experiment import (
    CREATED,
    RigConfig,
    rig_recording,
    run_experiments,
    truth_tree,
)
from debist.rig.reduced import truth_attrs
from debist.rig.run import true_curves
from debist.stages import StageInputs, StageOutput

__all__ = ["RigResult", "execute", "run_rig"]


@dataclass(frozen=True)
class RigResult:
    """Result of the rig stage (the virtual rig's experiments).

    Attributes
    ----------
    outputs : dict
        ``<experiment>.mat`` (:class:`debist.core.artifacts.FileWriter` of the MAT writer) and
        ``<experiment>_truth.h5`` (:class:`debist.core.artifacts.H5Tree`) per experiment; its
        ``curves`` group holds the true curves (:func:`debist.rig.run.true_curves`) with
        the plant ``model`` and the mass they are per in its attributes
        (:func:`debist.rig.reduced.truth_attrs`).
    summary : dict
        Per experiment: samples, q range [m], 3 kV switchings, saturated samples and
        integration statistics.
    timings : dict of str to float
        Wall time of each experiment's integration [s].
    """

    outputs: dict[str, Any]
    summary: dict[str, Any]
    timings: dict[str, float]


def run_rig(
    physics: Mapping[str, Any],
    section: Mapping[str, Any],
    idle: Callable[[], Any] | None = None,
) -> RigResult:
    """Simulate the virtual rig's experiments (``debist simulate-rig``).

    Parameters
    ----------
    physics : mapping
        The ``[physics]`` section (nominal prototype).
    section : mapping
        The ``[rig]`` section (:class:`debist.rig.experiment.RigConfig`).
    idle : callable, optional
        Called while the experiments integrate in worker processes
        (:func:`debist.rig.experiment.run_experiments`).

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
    cfg = RigConfig.from_dict(section, physics)
    runs, curves = run_experiments(
        cfg,
        meanwhile=partial(true_curves, cfg.rig, np.linspace(-20e-3, 20e-3, 401)),
        idle=idle,
    )
    curves = {**curves, "attrs": truth_attrs(cfg.rig, curves)}
    outputs: dict[str, Any] = {}
    summary: dict[str, Any] = {}
    timings: dict[str, float] = {}
    for name, exp in cfg.experiments.items():
        run = runs[name]
        if not run.success:
            raise DebistError(f"[rig.experiments.{name}]: the plant integration failed: "
                              f"{run.message}")  # fmt: skip
        mat = partial(
            write_recording,
            recording=rig_recording(run, name, cfg),
            version=exp.format,
            created=CREATED,
        )
        outputs[f"{name}.mat"] = FileWriter(mat)
        outputs[f"{name}_truth.h5"] = H5Tree(truth_tree(run, cfg, curves))
        sign = np.sign(run.q_true)
        summary[name] = {
            "samples": int(run.t.size),
            "q_min": float(run.q_true.min()),
            "q_max": float(run.q_true.max()),
            "well_changes": int(np.count_nonzero(np.diff(sign[np.abs(run.q_true) > 5e-3]))),
            "saturated": int(np.count_nonzero(run.saturated)),
            "nfev": run.nfev,
        }
        timings[name] = run.wall_time
    return RigResult(outputs, summary, timings)


def execute(ctx: StageInputs) -> StageOutput:
    """Run the rig stage: every ``[rig.experiments.<name>]`` of the workflow.

    Parameters
    ----------
    ctx : StageInputs
        The ``[physics]`` and ``[rig]`` sections; while the experiments integrate in worker
        processes, this process loads what the stages after the rig will need
        (``ctx.load_ahead``).

    Returns
    -------
    StageOutput
        ``<experiment>.mat`` and ``<experiment>_truth.h5`` per experiment.

    Raises
    ------
    WorkflowError, DebistError
        As :func:`run_rig`.
    """
    res = run_rig(ctx.section("physics"), ctx.section("rig"), idle=ctx.load_ahead)
    return StageOutput(res.outputs, res.summary, res.timings)
