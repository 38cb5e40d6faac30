"""The stage registry: every stage of debist, its module, upstream stages and libraries.

The runner, the CLI and batch read the stage graph from here. A stage's module holds its
pure ``run_<stage>`` function and the ``execute(ctx)`` adapter the runner calls; the stage's
key hashes that module's import closure (:func:`debist.engine.fingerprint.code_fingerprint`) and
the versions of the libraries listed here, so a change elsewhere leaves it up to date.

References
----------
The stage entries of dvc's ``dvc.yaml`` (deps, outs, cmd) are the model: one entry per stage
from which the graph is read.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["OPTIONAL", "STAGES", "StageDef", "names", "stage"]

_BASE = ("numpy", "scipy", "pandas", "pyarrow")


@dataclass(frozen=True)
class StageDef:
    """One stage of the pipeline.

    Parameters
    ----------
    name : str
        Stage name (also the name of its folder in the output folder).
    module : str
        Module with the stage's ``execute(ctx)``; its import closure is the stage's code.
    upstream : tuple of str
        Stages whose artifacts it reads, those of them that the workflow has (``ingest``
        also reads ``rig`` when a data set is a virtual-rig log; the runner adds that).
    libraries : tuple of str
        Distributions whose versions enter the stage key.
    help : str
        One line for the CLI.
    optional : bool
        The stage runs only when the workflow has a section of its name.
    beside : bool
        The stage may run in a forked process beside the stages after it that do not read
        it (:class:`debist.core.beside.BesideRun`): it reads little and much follows it. An
        optional ``preload(ctx)`` of its module runs in the runner's process just before the
        fork, as for ``early``.
    early : tuple of str
        Upstream stages that the first part of the stage reads, its module's
        ``prepare(ctx)``: once they are done, the runner may call it in a forked process
        beside the stages between and hands its result to ``execute(ctx, prepared)`` (the
        same result as ``prepare`` called there; empty: no first part). An optional
        ``preload(ctx)`` of the module runs in the runner's process just before the fork and
        loads what both processes would load (the child inherits it).
    """

    name: str
    module: str
    upstream: tuple[str, ...]
    libraries: tuple[str, ...]
    help: str
    optional: bool = False
    beside: bool = False
    early: tuple[str, ...] = ()


#: The stages in execution order.
STAGES: tuple[StageDef, ...] = (
    StageDef(
        "rig",
        "debist.stages.rig",
        (),
        ("numpy", "scipy", "h5py"),
        "Virtual rig: dSPACE MAT logs and truth files per experiment.",
        optional=True,
    ),
    StageDef(
        "ingest",
        "debist.stages.ingest",
        (),
        (*_BASE, "h5py"),
        "Rig logs to canonical tables.",
    ),
    StageDef(
        "differentiate",
        "debist.stages.differentiate",
        ("ingest",),
        _BASE,
        "q_dot and q_ddot (TVRegDiff or the configured differentiator).",
    ),
    StageDef(
        "identify",
        "debist.stages.identify",
        ("ingest", "differentiate"),
        (*_BASE, "h5py"),
        "The RBF model of Eq. 37-40 by least squares with the T_z search.",
    ),
    StageDef(
        "validate",
        "debist.stages.validate",
        ("ingest", "differentiate", "identify"),
        (*_BASE, "h5py"),
        "Free runs on every data set: NRMSE table and the simulated runs.",
    ),
    StageDef(
        "compare",
        "debist.stages.compare",
        ("ingest", "differentiate", "validate"),
        (*_BASE, "h5py", "pysindy", "scikit-learn"),
        "SINDy on the same data, derivatives and simulator.",
        early=("ingest", "differentiate"),  # the peers' fits and free runs
    ),
    StageDef(
        "study",
        "debist.stages.study",
        ("ingest", "differentiate"),
        (*_BASE, "matplotlib"),
        "Sensitivity studies: RBF grid (Fig. 11b) and TVRegDiff alpha (Fig. 11c).",
        optional=True,
        beside=True,
    ),
    StageDef(
        "analyze",
        "debist.stages.analyze",
        (),
        ("numpy", "scipy", "h5py", "matplotlib"),
        "Design analysis of Section 3: statics.h5 and Fig. 3-7.",
        optional=True,
        beside=True,
    ),
    StageDef(
        "report",
        "debist.stages.report",
        ("ingest", "differentiate", "identify", "validate", "compare", "study", "analyze"),
        (*_BASE, "jinja2", "matplotlib"),
        "One self-contained HTML page of the run (Table 2, Fig. 11-15, provenance).",
        optional=True,
    ),
)
#: Names of the stages that run only with their section (``analyze`` also without data).
OPTIONAL = tuple(s.name for s in STAGES if s.optional)


def names() -> tuple[str, ...]:
    """Return the stage names in execution order."""
    return tuple(s.name for s in STAGES)


def stage(name: str) -> StageDef:
    """Return the registry entry of a stage.

    Parameters
    ----------
    name : str
        Stage name.

    Returns
    -------
    StageDef

    Raises
    ------
    KeyError
        If there is no such stage.
    """
    for entry in STAGES:
        if entry.name == name:
            return entry
    raise KeyError(name)
