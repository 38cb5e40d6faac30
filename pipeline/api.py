"""debist's Python API: run workflows, read their results, simulate identified models.

The command line (:mod:`debist.cli`) is a display adapter over these functions; a lab's
script uses them directly::

    import debist

    result = debist.run("workflows/silverbox.toml", overrides={"identify.M": 8})
    digest = result.digest                   # what `debist verify --digest` checks
    table = result.nrmse                     # the table `debist run` prints, in percent
    model = result.model                     # or debist.load_model("runs/silverbox")
    sim = model.simulate(t, v, q0=0.0, q_dot0=0.0)

Nothing here prints: progress goes to an optional callback. Every artifact a
:class:`Result` reads is checked against its stage's manifest first (sha256), so a
number read here is one the run vouches for.

References
----------
Masoud & Maas 2025, Sec. 4-5 (the stages); the shape follows pysindy's model objects
(``simulate``) and DVC's ``dvc.api`` (a library over the pipeline's artifacts).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lazy_loader as lazy
import numpy as np

from debist.core import artifacts, progress

# The stages' machinery (runner, batch, the model and its simulator) is imported inside the
# functions that use it: `import debist` loads this module lazily and must stay light.
from debist.core.arguments import (
    check_callable,
    check_flag,
    check_int,
    check_names,
    check_path,
    check_str,
)
from debist.core.errors import ArgumentError, ArtifactError, WorkflowError
from debist.workflow.loader import Workflow
from debist.workflow.loader import load_workflow as _load_workflow

if TYPE_CHECKING:
    from debist.report.frames import NrmseTable

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "Export",
    "FleetResult",
    "Model",
    "ProgressEvent",
    "Result",
    "Verification",
    "batch_index",
    "batch_table",
    "diff",
    "example_workflow",
    "export_model",
    "find_workflows",
    "find_zoos",
    "fleet",
    "init_workflow",
    "list_channels",
    "load_model",
    "load_workflow",
    "missing_output",
    "open_run",
    "run",
    "run_batch",
    "run_blocker",
    "status",
    "verify",
    "workflow_schema",
    "workflow_stages",
    "zoo",
    "zoo_report",
]

PathLike = str | os.PathLike


@dataclass(frozen=True)
class ProgressEvent:
    """One progress report of :func:`run`.

    Attributes
    ----------
    stage : str
        The stage (empty for a recovery of an interrupted run's leftovers).
    what : {"recovered", "skip", "start", "done", "step"}
        A stage skipped as up to date, started, finished; ``"step"`` for the progress of a
        long computation inside the running stage.
    detail : str
        Why a stage runs (``"start"``), its wall time (``"done"``), or the task of a step.
    done, total : int
        Work done and in all for a ``"step"`` (``total`` 0 when unknown); 0 otherwise.
    """

    stage: str
    what: str
    detail: str = ""
    done: int = 0
    total: int = 0


def load_workflow(
    path: PathLike,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    *,
    output_dir: PathLike | None = None,
) -> Workflow:
    """Read and check a workflow file, with settings overridden for this call.

    Parameters
    ----------
    path : path-like
        The TOML workflow file.
    overrides : mapping or sequence of str, optional
        Any key of the workflow, dotted (``{"identify.M": 8, "validate.substeps": 4}``) or
        as ``"identify.M=8"`` strings; checked by the same schema as the file, and recorded
        in the stages' manifests.
    output_dir : path-like, optional
        Replaces ``[workflow] output_dir``.

    Returns
    -------
    Workflow
        The checked workflow (:class:`debist.workflow.loader.Workflow`).

    Raises
    ------
    WorkflowError
        One line naming the file, the section and the key: a missing or invalid file, an
        unknown key, a value of the wrong type or range, a missing data file; overrides
        given as one string instead of a mapping or a list of strings.
    """
    if isinstance(overrides, (str, bytes)):
        raise ArgumentError(
            f"overrides: expected a mapping {{'identify.M': 8}} or a list of 'KEY=VALUE' "
            f"strings, got the string {overrides!r}; pass [{overrides!r}]"
        )
    return _load_workflow(path, output_dir, overrides)


def _workflow(
    workflow: PathLike | Workflow,
    overrides: Mapping[str, Any] | Sequence[str] | None,
    output_dir: PathLike | None,
) -> Workflow:
    if isinstance(workflow, Workflow):
        if overrides or output_dir is not None:
            raise WorkflowError(
                "overrides and output_dir go to load_workflow, not with a loaded Workflow"
            )
        return workflow
    return load_workflow(workflow, overrides, output_dir=output_dir)


def run(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
    stages: Sequence[str] | None = None,
    start: str | None = None,
    until: str | None = None,
    force: bool = False,
    wait: bool = False,
    on_progress: Callable[[ProgressEvent], None] | None = None,
) -> Result:
    """Run a workflow's stages, skipping those that are up to date (as ``debist run``).

    Parameters
    ----------
    workflow : path-like or Workflow
        A workflow file, or one loaded by :func:`load_workflow`.
    overrides : mapping or sequence of str, optional
        Settings that replace the file's (see :func:`load_workflow`).
    output_dir : path-like, optional
        Replaces ``[workflow] output_dir``.
    stages : sequence of str, optional
        Run only these stages (their upstream stages must be up to date); default all, and
        only then does the result carry the run digest.
    start, until : str, optional
        Run the range of the workflow's stages from ``start`` to ``until`` (inclusive).
    force : bool, optional
        Rerun up-to-date stages too.
    wait : bool, optional
        Wait for another process writing to the same output folder instead of refusing.
    on_progress : callable, optional
        Called with a :class:`ProgressEvent` per stage event and per step of a long
        computation. Nothing is printed either way.

    Returns
    -------
    Result
        The run's results, read from its artifacts.

    Raises
    ------
    WorkflowError
        A bad workflow, override or stage name, or a refused output folder.
    RunLockedError
        Another process writes to the output folder (unless ``wait``).
    DebistError
        What a stage raised (bad data: the message names the file, channel and value);
        that stage's previous artifacts stay as they were.
    """
    from debist.engine.runner import Runner

    stages = check_names(stages, "stages", what="stage names")
    check_str(start, "start", optional=True, example="'identify'")
    check_str(until, "until", optional=True, example="'validate'")
    force, wait = check_flag(force, "force"), check_flag(wait, "wait")
    check_callable(on_progress, "on_progress")
    wf = _workflow(workflow, overrides, output_dir)
    runner = Runner(wf, wait=wait)
    stages = runner.select(stages, start=start, until=until)  # names checked, in order
    state = {"stage": ""}

    def on_event(stage: str, what: str, detail: str) -> None:
        state["stage"] = stage
        if on_progress is not None:
            on_progress(ProgressEvent(stage, what, detail))

    def on_step(task: str, done: int, total: int) -> None:
        if on_progress is not None:
            on_progress(ProgressEvent(state["stage"], "step", task, done, total))

    with progress.listening(on_step if on_progress is not None else None):
        manifests = runner.run(stages, force=force, on_event=on_event)
    digest = runner.digest() if stages is None else None
    return Result(wf, manifests, digest)


def status(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> list[Any]:
    """Say per stage whether it is up to date, stale (and why) or missing; reads only.

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    list of debist.engine.runner.StageStatus
        In execution order: ``stage``, ``state`` (``"up to date"``, ``"stale"``,
        ``"missing"``) and the ``reasons``.

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    """
    from debist.engine.runner import Runner

    return Runner(_workflow(workflow, overrides, output_dir)).status()


def workflow_stages(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> tuple[str, ...]:
    """Name the stages a workflow has, in execution order (its sections decide).

    (Not ``stages``, ``debist.stages`` is the package of the stage adapters.)

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    tuple of str
        E.g. ``("ingest", "differentiate", "identify", "validate", "compare", "report")``.

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    """
    from debist.engine.runner import Runner

    return tuple(Runner(_workflow(workflow, overrides, output_dir)).stages())


def missing_output(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> str | None:
    """Say that a workflow's output folder does not exist, naming the run it may mean.

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    str or None
        One line naming the folder and, if there is one, the ``--set`` run beside it
        (:func:`debist.engine.verification.missing_output`); None when the folder exists.

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    """
    from debist.engine.runner import Runner

    return Runner(_workflow(workflow, overrides, output_dir)).missing()


def run_blocker(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> str | None:
    """Say why a run of the workflow would stop at its output folder, without running it.

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    str or None
        The refusal a run would raise (the folder belongs to another workflow, is not a
        debist folder, ...), or None when a run may write there.

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    """
    from debist.engine.runner import Runner

    return Runner(_workflow(workflow, overrides, output_dir)).blocker()


def diff(
    run_a: PathLike,
    run_b: PathLike | None = None,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> dict[str, list[Any]]:
    """Compare two runs: the settings and the NRMSE that differ (reads only).

    Either two output folders, or a workflow file and ``overrides``: the run with those
    overrides (in ``output_dir``, or without it in its folder beside the output folder, see
    :func:`debist.workflow.overrides.override_folder`) against the workflow's own run.

    Parameters
    ----------
    run_a : path-like
        The output folder of a run, or (with ``run_b`` None) a workflow file.
    run_b : path-like, optional
        The output folder of another run.
    overrides : mapping or sequence of str, optional
        With a workflow file: the settings of the run compared with the workflow's own.
    output_dir : path-like, optional
        With a workflow file: the folder of the run with ``overrides`` (as for :func:`run`);
        the workflow's own run stays in ``[workflow] output_dir``.

    Returns
    -------
    dict
        ``"runs"``: the two folders compared, as strings; ``"config"``: rows ``{stage, key,
        a, b}`` of the settings that differ once each side's defaults are filled in;
        ``"nrmse"``: rows ``{dataset, model, metric, a, b, change}`` in percent [%] (see
        :func:`debist.engine.rundiff.diff_runs`).

    Raises
    ------
    WorkflowError
        A folder holds no stage manifest; a workflow file without overrides, overrides
        with two folders, or a bad workflow or override.
    """
    from debist.engine.rundiff import diff_runs

    run_a = check_path(run_a, "run_a")
    if run_b is None:
        if not overrides:
            raise WorkflowError(
                f"diff '{run_a}': give a second output folder, or a workflow file with the "
                "overrides (--set KEY=VALUE) whose run to compare with the workflow's own"
            )
        if not Path(run_a).is_file():
            raise WorkflowError(f"diff '{run_a}': with overrides, expected a workflow file")
        run_a, run_b = (
            load_workflow(run_a).output_dir,
            load_workflow(run_a, overrides, output_dir=output_dir).output_dir,
        )
    elif overrides or output_dir is not None:
        raise WorkflowError(
            "diff: overrides and output_dir go with a workflow file, not with two output folders"
        )
    run_b = check_path(run_b, "run_b")
    return {"runs": [str(run_a), str(run_b)], **diff_runs(run_a, run_b)}


def workflow_schema() -> dict[str, Any]:
    """Return the JSON Schema of a workflow file, as ``debist schema`` prints it.

    Returns
    -------
    dict
        A JSON Schema (draft 2020-12): every section, sub-table and key a workflow may
        have, with its type, range, default and description (see
        :func:`debist.workflow.jsonschema.workflow_schema`).

    References
    ----------
    JSON Schema 2020-12 (https://json-schema.org/draft/2020-12/json-schema-core).

    Examples
    --------
    >>> workflow_schema()["properties"]["identify"]
    {'$ref': '#/$defs/IdentifyConfig'}
    """
    from debist.workflow.jsonschema import workflow_schema as schema

    return schema()


@dataclass(frozen=True)
class Export:
    """What :func:`export_model` wrote.

    Attributes
    ----------
    files : tuple of pathlib.Path
        The files written, in the order of the format's file list.
    run_digest : str or None
        The digest of the run the model comes from (None when not every stage has run).
    """

    files: tuple[Path, ...]
    run_digest: str | None


def export_model(
    workflow: PathLike | Workflow,
    fmt: str = "c",
    *,
    dest: PathLike | None = None,
    force: bool = False,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
    wait: bool = False,
) -> Export:
    """Write the identified model as self-contained C99, MATLAB or NumPy code (``debist export``).

    (Not ``export``, ``debist.export`` is the package of the code generators.)

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`; its identify stage must be up to date.
    fmt : {"c", "matlab", "python"}, optional
        ``debist_model.h`` and ``.c``; ``debist_model.m`` and ``debist_free_run.m``;
        ``debist_model.py``. Each carries validate's scheme and, in its header, the NRMSE(q)
        of its free run and its per-sample step on the run's records, simulated at export.
    dest : path-like, optional
        Folder of the files (default ``<output_dir>/export``).
    force : bool, optional
        Replace files of the same names (each atomically); without it an existing file is
        an error and nothing is written.
    overrides, output_dir : optional
        As for :func:`run`.
    wait : bool, optional
        When another process writes to the output folder, wait for it to end instead of
        refusing (as for :func:`run`).

    Returns
    -------
    Export

    Raises
    ------
    WorkflowError
        A bad workflow (a bad ``[validate]`` table too: the export carries its scheme), or
        an identify stage that is missing or stale.
    ResourceError
        If the free runs that score the export on the run's records would exceed the memory
        budget (as validate's would).
    OutputDirError
        A file exists (without ``force``, also one that appears while the files are
        written), or a name resolves outside ``dest``; the default folder ``export/`` or a
        file to be replaced is a symbolic link (:func:`debist.export.files.export_folder`);
        ``dest`` is a folder no run writes into either: the file system root, the home
        folder, the workflow file's folder or one that holds a data source
        (:func:`debist.engine.outdir.check_place`).
    RunLockedError
        Another process writes to the output folder (unless ``wait``).
    ArtifactError
        ``identify/model.h5`` holds arrays of the wrong shapes, naming the dataset.

    References
    ----------
    See :mod:`debist.export` (the model of Masoud & Maas 2025, Eq. 37, in validate's scheme).
    """
    from contextlib import nullcontext

    from debist.core.fileformats import atomic_write
    from debist.engine import outdir
    from debist.engine.runner import Runner
    from debist.export.files import export_files, export_folder, load_identified, load_scheme

    check_str(fmt, "fmt", example="'c', 'matlab' or 'python'")
    dest = check_path(dest, "dest", optional=True)
    force, wait = check_flag(force, "force"), check_flag(wait, "wait")
    runner = Runner(_workflow(workflow, overrides, output_dir))
    folder = runner.wf.output_dir
    if dest is not None:
        outdir.check_place(
            dest.resolve(),
            workflow_dir=runner.wf.path.parent,
            sources=[d.source for d in runner.wf.datasets if not d.rig],
            what="export folder (dest)",
            advice="the model's files go into a folder of their own; choose one for dest",
        )
    with outdir.output_lock(folder, wait=wait) if folder.is_dir() else nullcontext():
        model, info = load_identified(runner)
        files = export_files(model, fmt, info, load_scheme(runner, model))
        target = export_folder(folder, dest, files)
        if force:
            target.mkdir(parents=True, exist_ok=True)
            for name, text in files.items():
                atomic_write(artifacts.inside(target, name), text)
        else:
            artifacts.write_text_files(target, files)
    return Export(tuple(target / name for name in files), info.run_digest)


@dataclass(frozen=True)
class Verification:
    """What :func:`verify` found.

    Attributes
    ----------
    problems : tuple of str
        Each naming a file: modified, missing or unlisted artifacts, a broken chain of
        manifests, a digest that differs. Empty when the run is intact.
    notes : tuple of str
        Libraries installed now in other versions than those that made the run (not a
        failure: a rerun may give other bytes).
    """

    problems: tuple[str, ...]
    notes: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Whether every artifact matches its manifest and the chain holds."""
        return not self.problems


def verify(
    workflow: PathLike | Workflow,
    digest: str | None = None,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> Verification:
    """Re-hash every artifact of a run and check the chain of manifests (``debist verify``).

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`: the run is checked against the workflow as it is now.
    digest : str, optional
        A run digest (:attr:`Result.digest`) the manifests must be exactly those of.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    Verification

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    RunLockedError
        While another process writes to the output folder.
    """
    from debist.engine.runner import Runner

    check_str(digest, "digest", optional=True, example="result.digest")
    runner = Runner(_workflow(workflow, overrides, output_dir))
    return Verification(tuple(runner.verify(digest)), tuple(runner.version_notes()))


def run_batch(
    workflows: PathLike | Iterable[PathLike],
    *,
    stages: Sequence[str] | None = None,
    force: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    address: str | None = None,
    on_done: Callable[[Any], None] | None = None,
) -> list[Any]:
    """Run many workflows as Dask tasks; one result or failure per workflow (``debist batch``).

    Parameters
    ----------
    workflows : path-like or iterable of path-like
        Workflow files, folders (their ``*.toml``) or glob patterns.
    stages, force : optional
        As for :func:`run`, for every workflow.
    scheduler : {"processes", "threads", "synchronous", "distributed"}, optional
        Default: a local Dask cluster of ``workers`` processes (see
        :func:`debist.engine.batch.run_batch`); ``"distributed"`` with ``address``.
    workers : int, optional
        Worker processes (default: one per workflow, at most one per CPU); on this machine
        at most one per workflow, per core and per :data:`debist.engine.batch.WORKER_BYTES`
        of the memory budget (a warning says when fewer run).
    address : str, optional
        A running Dask scheduler, e.g. ``"tcp://host:8786"``.
    on_done : callable, optional
        Called with each :class:`debist.engine.batch.BatchResult` as its workflow finishes.

    Returns
    -------
    list of debist.engine.batch.BatchResult
        In input order: ``ok``, ``error`` (the failure, naming the stage), ``output_dir``
        (open it with :func:`open_run`), ``summary["nrmse"]`` (rows as fractions).

    Raises
    ------
    WorkflowError
        Before anything runs: no workflow found, an unknown stage or scheduler, two
        workflows writing to one folder, a cluster that cannot be reached.

    Notes
    -----
    Worker processes re-import the calling script: call from under
    ``if __name__ == "__main__":``.
    """
    from debist.engine.batch import expand_workflows
    from debist.engine.batch import run_batch as _run_batch

    stages = check_names(stages, "stages", what="stage names")
    force = check_flag(force, "force")
    check_str(scheduler, "scheduler", optional=True, example="'processes'")
    if workers is not None:
        workers = check_int(workers, "workers", minimum=1)
    check_str(address, "address", optional=True, example="'tcp://host:8786'")
    check_callable(on_done, "on_done")
    files = expand_workflows(workflows)
    if not files:
        raise WorkflowError(f"no workflow file found in {workflows!r}")
    return _run_batch(
        files,
        stages=stages,
        force=force,
        scheduler=scheduler,
        workers=workers,
        address=address,
        on_done=on_done,
    )


def find_workflows(paths: PathLike | Iterable[PathLike]) -> list[Path]:
    """Expand workflow files, folders (their ``*.toml``) and glob patterns, as ``debist batch``.

    Parameters
    ----------
    paths : path-like or iterable of path-like
        Files (taken as they are), folders, patterns (``**`` recurses).

    Returns
    -------
    list of pathlib.Path
        Sorted within each entry, in the order of the entries.

    Raises
    ------
    WorkflowError
        No entry, or an entry that matches nothing.
    """
    from debist.engine.batch import expand_workflows

    return expand_workflows(paths)


def find_zoos(paths: PathLike | Iterable[PathLike]) -> list[Path]:
    """Return the zoo folders (``debist zoo``) among the entries of a batch.

    Parameters
    ----------
    paths : path-like or iterable of path-like
        The entries given to :func:`find_workflows`.

    Returns
    -------
    list of pathlib.Path
        The entries that are folders holding a ``zoo.json``, in order.
    """
    from debist.engine.zooindex import ZOO_FILE

    entries = [paths] if isinstance(paths, str | os.PathLike) else list(paths)
    return [Path(p) for p in entries if (Path(p) / ZOO_FILE).is_file()]


def batch_table(results: Iterable[Any]) -> pd.DataFrame:
    """Tabulate a batch's results, one row per workflow, failures included.

    Parameters
    ----------
    results : iterable of debist.engine.batch.BatchResult
        From :func:`run_batch`.

    Returns
    -------
    pandas.DataFrame
        ``file``, ``name``, ``status`` ("ok" or "failed"), ``seconds``, ``ran``,
        ``skipped``, ``failed_stage``, ``error``, ``note``, ``rbf_nrmse_q`` (see
        :func:`debist.engine.batch.summary_table`).
    """
    from debist.engine.batch import summary_table

    return summary_table(results)


def batch_index(
    results: Sequence[Any],
    folder: PathLike | None = None,
    pages: Sequence[tuple[str, PathLike]] = (),
) -> Path | None:
    """Write a batch's index page: one row per prototype, linking each one's report.

    Parameters
    ----------
    results : sequence of debist.engine.batch.BatchResult
        From :func:`run_batch`.
    folder : path-like, optional
        Where ``index.html`` goes (default: the folder that holds every output folder).
    pages : sequence of (str, path-like), optional
        Other pages of the batch report to link (label, file), e.g. :func:`zoo_report`'s.

    Returns
    -------
    pathlib.Path or None
        The page (replaced atomically); None when no workflow could be loaded or the
        common folder is the file system root or the home folder.

    Raises
    ------
    OutputDirError
        If the folder holds an ``index.html`` that debist did not write (or that was changed
        since): it is left as it is and nothing is written.
    """
    from debist.engine.batch import write_index

    return write_index(results, folder, pages)


@dataclass(frozen=True)
class FleetResult:
    """The workflows :func:`fleet` wrote.

    Attributes
    ----------
    paths : tuple of pathlib.Path
        One workflow file per kept prototype, in draw order.
    rejected : dict of str to str
        Draws skipped because their logs fail the template's ingest, with the reason.
    replaced : tuple of pathlib.Path
        What a fleet stopped part way had left in the folder and this call removed first
        (unscreened workflows, their output folders).
    """

    paths: tuple[Path, ...]
    rejected: dict[str, str]
    replaced: tuple[Path, ...] = ()


def fleet(template: PathLike, size: int, *, seed: int = 0, folder: PathLike) -> FleetResult:
    """Write one workflow per prototype of a seeded fleet around a template's rig.

    Each prototype's rig experiments are run once and its logs checked by the template's
    own ingest; a draw whose logs fail is skipped (and named), the next draw taken. A kept
    member's rig and ingest stages stay in its output folder (up to date for the batch).
    The folder records the fleet as unfinished until its workflows are all written
    (:mod:`debist.engine.fleetmark`): a fleet stopped part way is refused by
    :func:`run_batch` and replaced by the next call.

    Parameters
    ----------
    template : path-like
        A workflow with a ``[rig]`` section.
    size : int
        Prototypes wanted, ``>= 1``.
    seed : int, optional
        Seed of the scatter, ``>= 0`` (numpy's ``SeedSequence`` entropy).
    folder : path-like
        Where the workflows go; it must not hold workflows already (but those of a fleet
        stopped part way, which are removed first).

    Returns
    -------
    FleetResult

    Raises
    ------
    WorkflowError
        An unreadable template, one without ``[rig]``, a folder that holds workflows
        already (nothing is overwritten), or too few viable draws.
    """
    import tomllib

    from debist.engine.fleetmark import clear_unfinished, finish_fleet, start_fleet
    from debist.engine.fleetrun import remove_runs, viable_fleet
    from debist.workflow import tomltext

    template, folder = check_path(template, "template"), check_path(folder, "folder")
    size, seed = check_int(size, "size", minimum=1), check_int(seed, "seed", minimum=0)
    try:
        raw = tomltext.loads(template.read_text(encoding="utf-8"), f"template '{template}'")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise WorkflowError(f"cannot read the template '{template}': {exc}") from None
    replaced = clear_unfinished(folder)  # what a fleet stopped part way left there
    existing = sorted(folder.glob("*.toml")) if folder.is_dir() else []
    if existing:
        raise WorkflowError(
            f"'{folder}' holds workflows already ({existing[0].name}, ...): choose another "
            "folder (debist never overwrites them)"
        )
    start_fleet(folder, template, size, seed)  # unfinished until the workflows are written
    try:
        files, rejected, runs = viable_fleet(raw, template.resolve().parent, folder, size, seed)
        try:
            paths = artifacts.write_text_files(folder, files)
        except BaseException:
            remove_runs(runs)  # the checks' output folders without their workflows
            raise
    except BaseException:
        clear_unfinished(folder)  # what the checks left, if anything, and the record
        raise
    finish_fleet(folder, [p.name for p in paths])
    return FleetResult(tuple(paths), dict(rejected), tuple(replaced))


def zoo(size: int, *, seed: int, folder: PathLike) -> Any:
    """Write a plant zoo: ``size`` virtual DE rigs drawn from ``seed``, each with its truth.

    Each member gets its rig logs (MAT), a minimal workflow and its truth (``truth.json``,
    ``truth.parquet``); run them with :func:`run_batch` on the folder, then
    :func:`zoo_report`.

    Parameters
    ----------
    size : int
        Members, ``>= 1``.
    seed : int
        The zoo's seed, ``>= 0``; member ``i`` is the same whatever ``size``.
    folder : path-like
        New or empty folder, or a zoo of the same seed (kept, extended).

    Returns
    -------
    debist.engine.zoo.ZooResult

    Raises
    ------
    WorkflowError
        A negative seed, ``size < 1``, or a folder that holds other files or another zoo.
    debist.engine.zooindex.ZooError
        A member without a viable draw.
    """
    from debist.engine.zoo import write_zoo

    size, seed = check_int(size, "size", minimum=1), check_int(seed, "seed", minimum=0)
    folder = check_path(folder, "folder")
    return write_zoo(folder, size, seed)


def zoo_report(folder: PathLike) -> tuple[Path, Path, pd.DataFrame, pd.DataFrame]:
    """Write a zoo's table (``zoo.parquet``) and page (``zoo.html``) after its batch.

    Parameters
    ----------
    folder : path-like
        The zoo folder; members whose runs are missing or incomplete get a row that says so.

    Returns
    -------
    table_path, page_path : pathlib.Path
        The files written.
    table : pandas.DataFrame
        One row per member (:func:`debist.engine.zootable.zoo_table`).
    summary : pandas.DataFrame
        Medians and worst cases (:func:`debist.engine.zootable.zoo_summary`).

    Raises
    ------
    debist.engine.zooindex.ZooError
        If the folder is not a zoo.
    """
    from debist.engine.zootable import PAGE_FILE, write_zoo_table, zoo_summary
    from debist.report.html import write_page
    from debist.report.zoo import render_zoo

    folder = Path(folder)
    table_path, table = write_zoo_table(folder)
    summary = zoo_summary(table)
    page = write_page(folder / PAGE_FILE, render_zoo(table, summary, table.attrs))
    return table_path, page, table, summary


# --------------------------------------------------------- first steps


def list_channels(data: PathLike | Iterable[PathLike]) -> tuple[Any, ...]:
    """List the channels of rig logs, with their units and value ranges (reads only).

    Parameters
    ----------
    data : path-like or iterable of path-like
        Rig logs in any format the ingest reads (MAT v5/v7.3, text, Parquet, MF4).

    Returns
    -------
    tuple of debist.ingest.survey.FileSurvey
        One per file, in the order given: its format, its channels (name, unit, samples,
        smallest and largest value) and a recording's time bases.

    Raises
    ------
    RigLogError
        A file that cannot be read, naming it.
    WorkflowError
        A FIFO, socket or device, refused before it is opened.
    """
    from debist.core.arguments import check_regular_file
    from debist.ingest.survey import survey_file

    paths = [data] if isinstance(data, (str, os.PathLike)) else list(data)
    for path in paths:
        check_regular_file(path, "rig log")
    return tuple(survey_file(Path(p)) for p in paths)


def _unit_options(units: Mapping[str, str] | Sequence[str] | None) -> dict[str, str]:
    """Return ``{"q": "mm"}`` from a mapping or from ``"ROLE=UNIT"`` strings."""
    if units is None:
        return {}
    if isinstance(units, (str, bytes)):
        raise WorkflowError(f"units: expected a mapping or a list of 'ROLE=UNIT', got {units!r}")
    if isinstance(units, Mapping):
        return {str(k): str(v) for k, v in units.items()}
    out = {}
    for item in units:
        role, sep, unit = str(item).partition("=")
        if not sep or not role.strip() or not unit.strip():
            raise WorkflowError(f"--unit {item!r}: expected ROLE=UNIT, e.g. q=mm or v=kV")
        out[role.strip()] = unit.strip()
    return out


def init_workflow(
    data: Sequence[PathLike],
    out: PathLike | None = None,
    *,
    force: bool = False,
    time: str | None = None,
    q: str | None = None,
    v: Sequence[str] = (),
    units: Mapping[str, str] | Sequence[str] | None = None,
    sample_time: float | None = None,
) -> Any:
    """Write a first workflow for one's own rig logs (as ``debist init``).

    The channels are mapped to ``time``, ``q``, ``v1``, ``v2`` by their names and units
    (:func:`debist.ingest.survey.guess_mapping`) unless given; the first file becomes the
    estimation data set, the others validation data sets; ``[report]`` is on. The workflow
    is checked and every file ingested with it before it is written.

    Parameters
    ----------
    data : sequence of path-like
        Rig logs, the estimation file first.
    out : path-like, optional
        The workflow file; default ``debist.toml`` in the working folder. Never
        overwritten without ``force``.
    force : bool, optional
        Replace an existing ``out``.
    time, q : str, optional
        Channel names that replace the guess (every file).
    v : sequence of str, optional
        The inputs' channel names, ``v1`` first.
    units : mapping or sequence of str, optional
        Units per role, ``{"q": "mm", "v": "kV"}`` or ``["q=mm", "v=kV"]`` (``v`` for
        every input, or ``v1``, ``v2``, ...).
    sample_time : float, optional
        [s] for files without a time channel.

    Returns
    -------
    debist.workflow.init.InitResult
        The file written, its text and each data set's mapping with the reasons.

    Raises
    ------
    WorkflowError
        ``out`` exists (without ``force``); a channel that cannot be guessed or is
        ambiguous (one line naming the file, its channels and the option to pass); a bad
        unit.
    RigLogError
        A file that cannot be read or does not ingest with the mapping.
    """
    from debist.ingest.survey import MappingRequest
    from debist.workflow.init import init_workflow as write

    if isinstance(data, (str, os.PathLike)):
        data = [data]
    if isinstance(v, str):
        v = [v]
    request = MappingRequest(time, q, tuple(v), _unit_options(units), sample_time)
    return write(list(data), out, force=force, request=request)


def example_workflow(name: str, folder: PathLike) -> Path:
    """Copy a shipped example workflow (and the data it reads) into a folder; its path.

    Parameters
    ----------
    name : str
        ``"paper-experiment"`` (the paper's experiment on the virtual rig, no data),
        ``"silverbox"``, ``"emps"``, ... (:func:`debist.workflow.examples.example_names`).
    folder : path-like
        Gets ``workflows/<name>.toml`` and ``data/...``; the runs go to
        ``<folder>/runs/<name>``.

    Returns
    -------
    pathlib.Path
        The workflow file, ready for :func:`run`.

    Raises
    ------
    WorkflowError
        An unknown name.
    OutputDirError
        A file of the same name with other content is in the folder (never overwritten;
        an identical one is kept).
    """
    from debist.workflow.examples import copy_example

    return copy_example(name, folder)


# ------------------------------------------------------------------- results


class Result:
    """The results of a workflow's run, read from its checked artifacts.

    Made by :func:`run` or :func:`open_run`; every table is read on first access, after its
    sha256 was checked against the stage's manifest.

    Parameters
    ----------
    workflow : Workflow
        The workflow that ran.
    manifests : dict of str to Manifest
        The manifest of every stage considered.
    digest : str or None
        The run digest (None for a partial run).
    """

    def __init__(
        self,
        workflow: Workflow,
        manifests: Mapping[str, artifacts.Manifest],
        digest: str | None,
    ):
        self.workflow = workflow
        self.manifests = dict(manifests)
        self.digest = digest

    def __repr__(self) -> str:
        stages = ", ".join(self.manifests)
        return f"<debist.Result {self.workflow.name!r}: {stages}; digest {self.digest}>"

    @property
    def output_dir(self) -> Path:
        """The run's artifact folder."""
        return self.workflow.output_dir

    def _manifest(self, stage: str) -> artifacts.Manifest:
        manifest = self.manifests.get(stage)
        if manifest is None:
            raise ArtifactError(
                f"the run of '{self.workflow.name}' has no '{stage}' stage "
                f"(it has: {', '.join(self.manifests) or 'none'})"
            )
        return manifest

    def path(self, stage: str, rel: str) -> Path:
        """Return an artifact's path after checking its bytes against the stage's manifest.

        Parameters
        ----------
        stage : str
            Stage name.
        rel : str
            Path inside the stage folder (``"nrmse.parquet"``, ``"model.h5"``).

        Returns
        -------
        pathlib.Path

        Raises
        ------
        ArtifactError
            The stage did not run, does not list the file, or the file changed.
        """
        return artifacts.checked_output(self.workflow.stage_dir(stage), self._manifest(stage), rel)

    def summary(self, stage: str) -> dict[str, Any]:
        """Return a stage's checked ``summary.json`` (small results, as the CLI prints them).

        Raises
        ------
        ArtifactError
            The stage did not run or its summary changed.
        """
        return artifacts.read_summary(self.workflow.stage_dir(stage), self._manifest(stage))

    def table(self, stage: str, rel: str) -> pd.DataFrame:
        """Read a Parquet artifact after checking it (see :meth:`path`)."""
        return artifacts.read_parquet(self.path(stage, rel))

    @property
    def _scored(self) -> str:
        return "compare" if "compare" in self.manifests else "validate"

    @cached_property
    def nrmse(self) -> NrmseTable:
        """The free-run NRMSE table (Eq. 41) that ``debist run`` prints, in percent.

        The compare stage's when it ran (RBF, SINDy and NARX rows), else the validate
        stage's; columns as :func:`debist.report.tables.nrmse_frame` (units in the names).

        Raises
        ------
        ArtifactError
            Neither stage ran.
        """
        from debist.report.frames import (  # here, not at the top: pandas loads in 0.3 s
            NrmseTable,
        )
        from debist.report.tables import nrmse_frame

        return NrmseTable(nrmse_frame(self.summary(self._scored)["table"]))

    @cached_property
    def nrmse_raw(self) -> pd.DataFrame:
        """Every column of the stage's ``nrmse.parquet``, one row per data set and model.

        NRMSE as fractions, the k-step-ahead scores and the residual whiteness beside them.
        """
        return self.table(self._scored, "nrmse.parquet")

    @cached_property
    def curves(self) -> pd.DataFrame:
        """The identified characteristic curves on a grid of q, with their bands and masks.

        Columns ``q`` [unit of q], ``restoring``, ``d``, ``g1``... and per curve ``_lo``,
        ``_hi`` (the band of ``attrs["band"]``) and ``_identified`` (where the data
        inform it); ``attrs["band"]`` says what the band holds.
        """
        frame = self.table("identify", "curves.parquet")
        frame.attrs["band"] = self.summary("identify").get("bands", {}).get("label", "")
        return frame

    @cached_property
    def equilibria(self) -> pd.DataFrame:
        """Equilibria of the identified (and analytical) model with their stability.

        At the identified model's wells ``k`` [N/m] and ``f_n`` [Hz] carry their 95 % band
        (``k_lo``, ``k_hi``, ``f_n_lo``, ``f_n_hi``; :func:`debist.identify.bands.stiffness_bands`).
        """
        return self.table("identify", "equilibria.parquet")

    @cached_property
    def switching(self) -> pd.DataFrame:
        """Switching levels of each input, in the input's own unit."""
        return self.table("identify", "switching.parquet")

    @cached_property
    def model(self) -> Model:
        """The identified model (``identify/model.h5``), ready to simulate."""
        return Model.from_h5(self.path("identify", "model.h5"), self.summary("identify"))

    def free_run(self, dataset: str) -> pd.DataFrame:
        """Measured and simulated trajectories of one data set.

        Parameters
        ----------
        dataset : str
            Data set name (a row of :attr:`nrmse`).

        Returns
        -------
        pandas.DataFrame
            The validate stage's ``t, q`` and the identified model's ``q_sim, q_dot_sim,
            q_ddot_sim``, the other models validated beside it with their name as suffix
            (``q_sim_analytical``, ``q_sim_rbf-ls``), and when the compare stage ran SINDy's
            (``q_sim_sindy``...) and the NARX peer's (``q_sim_narx``).

        Raises
        ------
        ArtifactError
            No such data set, or a file changed.
        """
        rel = f"simulated/{dataset}.parquet"
        frame = self.table("validate", rel)
        if "compare" in self.manifests:
            other = self.table("compare", rel).drop(columns=["t", "q"])
            other = other.rename(columns=lambda c: c if c.endswith("_narx") else f"{c}_sindy")
            frame = pd.concat([frame, other], axis=1)
        return frame


def open_run(
    workflow: PathLike | Workflow,
    *,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    output_dir: PathLike | None = None,
) -> Result:
    """Open the results of a workflow that ran before, without running anything.

    Parameters
    ----------
    workflow : path-like or Workflow
        As for :func:`run`.
    overrides, output_dir : optional
        As for :func:`run`.

    Returns
    -------
    Result
        With the manifests of the stages that have artifacts; ``digest`` when all do.

    Raises
    ------
    WorkflowError
        A bad workflow or override.
    """
    from debist.engine.runner import Runner

    wf = _workflow(workflow, overrides, output_dir)
    runner = Runner(wf)
    manifests = {}
    for stage in runner.stages():
        manifest = artifacts.read_manifest(wf.stage_dir(stage))
        if manifest is not None:
            summary = artifacts.read_summary(wf.stage_dir(stage), manifest)
            manifests[stage] = replace(manifest, summary=summary)
    return Result(wf, manifests, runner.digest())


# --------------------------------------------------------------------- model


class Model:
    """An identified model (Eq. 37-40): simulate it, evaluate its curves and equilibria.

    Parameters
    ----------
    rbf : debist.model.rbf.RBFModel
        The identified model.
    units : dict, optional
        The identify stage's units (``q``, ``v1``...); for labels only.

    See Also
    --------
    load_model : from a run folder or a ``model.h5``.
    """

    def __init__(self, rbf: Any, units: Mapping[str, Any] | None = None):
        self.rbf = rbf
        self.units = dict(units or {})

    @classmethod
    def from_h5(cls, path: PathLike, summary: Mapping[str, Any] | None = None) -> Model:
        """Load from an identify stage's ``model.h5`` (:meth:`RBFModel.from_tree`)."""
        from debist.model.rbf import RBFModel

        tree = artifacts.read_h5(path)
        return cls(RBFModel.from_tree(tree, str(path)), (summary or {}).get("units"))

    def __repr__(self) -> str:
        m = self.rbf
        return (
            f"<debist.Model: {m.basis.xi.size} RBF centres, {m.n_inputs} input(s), "
            f"{m.n_params} parameters, T_z = {m.T_z:.4g} s>"
        )

    @property
    def n_inputs(self) -> int:
        """Number of inputs v_i."""
        return int(self.rbf.n_inputs)

    @property
    def q_range(self) -> tuple[float, float]:
        """The estimation range of q [unit of q]: where the model was fitted."""
        lo, hi = self.rbf.q_range
        return float(lo), float(hi)

    def simulate(
        self,
        t: np.ndarray,
        v: np.ndarray,
        q0: float,
        q_dot0: float,
        *,
        substeps: int = 2,
        interpolation: str = "bandlimited",
        engine: str = "compiled",
        q_limit: float | None = None,
    ) -> pd.DataFrame:
        """Free-run the model on new inputs (the validate stage's simulator and settings).

        Parameters
        ----------
        t : ndarray, shape (n,)
            Uniformly sampled time [s].
        v : ndarray, shape (n,) or (n, n_inputs)
            Inputs [V] (the unit the model was identified in).
        q0, q_dot0 : float
            Initial position [unit of q] and velocity [unit of q / s].
        substeps : int, optional
            RK4 steps per sample interval (``[validate] substeps``, default 2).
        interpolation : {"bandlimited", "linear"}, optional
            Input interpolation between samples.
        engine : {"compiled", "numpy"}, optional
            The compiled kernel or the NumPy reference (same numbers to rounding).
        q_limit : float, optional
            ``|q|`` beyond which the run counts as diverged; default twice the largest
            ``|q|`` of the estimation range, as validate.

        Returns
        -------
        pandas.DataFrame
            ``t, q, q_dot, q_ddot`` (NaN after a divergence; ``attrs["diverged_at"]`` is
            its sample index, -1 if none).

        Raises
        ------
        ValueError
            Time not uniform and increasing, inputs of the wrong shape or not finite.
        ResourceError
            The run would exceed the memory budget.

        References
        ----------
        Masoud & Maas 2025, Sec. 5.2 (free-run simulation).
        """
        from debist.simulate.freerun import simulate
        from debist.validate.freerun import default_q_limit

        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"t must be 1-D with at least 2 samples, got shape {t.shape}")
        if v.shape != (t.size, self.n_inputs):
            raise ValueError(
                f"v must have shape ({t.size}, {self.n_inputs}) for this model, got {v.shape}"
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("t and v must be finite")
        steps = np.diff(t)
        dt = float(np.median(steps))
        if dt <= 0 or np.max(np.abs(steps - dt)) > 1e-6 * dt:
            raise ValueError("t must increase in uniform steps (resample the inputs first)")
        limit = default_q_limit(self.rbf.q_range) if q_limit is None else float(q_limit)
        (res,) = simulate(
            self.rbf,
            [v],
            dt,
            np.array([float(q0)]),
            np.array([float(q_dot0)]),
            substeps=substeps,
            interpolation=interpolation,
            q_limit=limit,
            engine=engine,
        )
        frame = pd.DataFrame({"t": t, "q": res.q, "q_dot": res.q_dot, "q_ddot": res.q_ddot})
        frame.attrs["diverged_at"] = res.diverged_at
        return frame

    def curves(self, q: np.ndarray) -> pd.DataFrame:
        """Evaluate the identified curves of Eq. 37 at positions ``q``.

        Parameters
        ----------
        q : ndarray, shape (n,)
            Positions [unit of q].

        Returns
        -------
        pandas.DataFrame
            The columns of the identify stage's curve table without its bands (those are in
            :attr:`Result.curves`): ``q, c, d, cq, restoring`` (``c(q) q + F_0``), ``g1,
            dC1_dq``, ... (:func:`debist.identify.bands.point_curves`).
        """
        from debist.identify.bands import point_curves

        return pd.DataFrame(point_curves(self.rbf, np.atleast_1d(np.asarray(q, dtype=float))))

    def equilibria(self, v: Sequence[float] | Sequence[Sequence[float]] = ()) -> pd.DataFrame:
        """Equilibria at rest and at constant inputs, with their stability.

        Parameters
        ----------
        v : sequence of float, or sequence of sequences
            One input level ``(v_1, ..., v_N)`` [V] or several; the rest level (all 0) is
            always level 0.

        Returns
        -------
        pandas.DataFrame
            One row per equilibrium: level, inputs, ``q``, stiffness ``k``, damping ``d``,
            natural frequency ``f_n``, stability
            (:func:`debist.identify.stability.stability_table`), without bands: the bands of
            ``k`` and ``f_n`` at the wells the data hold (``k_lo``, ``k_hi``, ``f_n_lo``,
            ``f_n_hi``) are in :attr:`Result.equilibria`.

        Raises
        ------
        StabilityError
            A level without ``n_inputs`` values.
        """
        from debist.identify.stability import stability_table

        levels = np.atleast_2d(np.asarray(v, dtype=float)) if len(v) else np.empty((0, 0))
        return stability_table(self.rbf, [tuple(map(float, row)) for row in levels])


def load_model(path: PathLike) -> Model:
    """Load an identified model: a run's output folder, its ``identify`` folder or a ``model.h5``.

    From a run folder the file is checked against the identify stage's manifest first.

    Parameters
    ----------
    path : path-like
        The output folder of a run, its ``identify`` folder, or a ``model.h5`` file.

    Returns
    -------
    Model

    Raises
    ------
    ArtifactError
        No model there, or a ``model.h5`` that does not hash to its manifest.
    """
    path = check_path(path, "path")
    folder = path if path.is_dir() else None
    if folder is not None and (folder / "identify").is_dir():
        folder = folder / "identify"
    if folder is None:
        return Model.from_h5(path) if path.is_file() else _no_model(path)
    manifest = artifacts.read_manifest(folder)
    if manifest is None:
        return _no_model(path)
    return Model.from_h5(
        artifacts.checked_output(folder, manifest, "model.h5"),
        artifacts.read_summary(folder, manifest),
    )


def _no_model(path: Path) -> Model:
    raise ArtifactError(
        f"'{path}' is not a run folder, an identify folder or a model.h5 file "
        "(run the workflow first: debist.run(...))"
    )
