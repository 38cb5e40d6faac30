"""Batch runs: many workflows (one per prototype) on Dask, locally or on a cluster.

Each workflow is one Dask task that loads the workflow file and runs its stages with
:class:`pipeline.runner.Runner` in a worker, with the runner's content-hash caching (a
rerun skips up-to-date stages). One failing workflow never stops the others: its error
comes back in its :class:`BatchResult`. Every workflow writes only to its own
``output_dir`` (checked before anything runs), so a parallel batch writes the same bytes
as a serial one.

The scheduling is Dask's: the local schedulers of ``dask.compute`` (``"synchronous"``,
``"threads"``, ``"processes"``) on one machine, and ``dask.distributed`` (optional extra
``debist[cluster]``) past one machine. Progress is shown by Dask's own diagnostics
(``dask.diagnostics.ProgressBar``, ``distributed.progress``), or by the caller from the
``on_done`` callbacks (e.g. a ``rich.progress`` bar).

Examples
--------
A script that runs every prototype of a folder on two local processes (the
``__main__`` guard is needed because worker processes are spawned)::

    from pipeline.batch import expand_workflows, run_batch, summary_table

    if __name__ == "__main__":
        results = run_batch(expand_workflows(["workflows/protos/"]), workers=2)
        summary_table(results).to_csv("batch-summary.csv", index=False)

References
----------
Dask documentation: "Scheduling" (https://docs.dask.org/en/stable/scheduling.html),
"Delayed" (https://docs.dask.org/en/stable/delayed.html), "Diagnostics (local)"
(https://docs.dask.org/en/stable/diagnostics-local.html), "Futures"
(https://docs.dask.org/en/stable/futures.html); dask.distributed "Quickstart" and
"Diagnosing Performance" (https://distributed.dask.org/en/stable/).
"""

from __future__ import annotations

import contextlib
import glob
import os
import socket
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.errors import DebistError, WorkflowError

#: Values of ``scheduler`` in :func:`run_batch`.
SCHEDULERS = ("synchronous", "threads", "processes", "distributed")
#: Characters that make an argument of :func:`expand_workflows` a glob pattern.
_GLOB_CHARS = frozenset("*?[")
_CLUSTER_HINT = 'pip install "debist[cluster]"'
#: One BLAS/OpenMP thread per worker process, as dask.distributed's nanny sets for its
#: workers (config ``distributed.nanny.pre-spawn-environ``): n processes x n BLAS threads
#: would oversubscribe the cores.
_WORKER_ENVIRON = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


@dataclass(frozen=True)
class StageEvent:
    """What one stage of a workflow did in a batch run.

    Parameters
    ----------
    stage : str
        Stage name.
    action : {"ran", "skipped", "failed"}
        The stage ran, was up to date (skipped), or raised.
    seconds : float
        Wall time [s]: of the stage's run, or of the up-to-date check for a skipped
        stage, or until the error for a failed one.
    """

    stage: str
    action: str
    seconds: float


@dataclass(frozen=True)
class BatchResult:
    """The outcome of one workflow of a batch.

    Parameters
    ----------
    path : pathlib.Path
        The workflow file (absolute).
    name : str
        ``[workflow] name`` (the file's stem when the file could not be loaded).
    status : {"done", "failed"}
        ``"failed"`` when loading or a stage raised.
    seconds : float
        Wall time of loading and running the workflow in its worker [s].
    events : tuple of StageEvent
        Per stage, in execution order.
    error : str
        ``"<ExceptionClass>: <message>"`` for a failed item (the last line of its
        traceback); empty when done.
    traceback : str
        The full traceback of an unexpected (non-:class:`~pipeline.errors.DebistError`)
        exception; empty otherwise.
    output_dir : pathlib.Path or None
        The workflow's artifact root (None when the file could not be loaded).
    outputs : dict of str to dict of str to str
        Per stage considered: output path (relative to the stage directory) to sha256,
        as in the stage's manifest. Empty for a failed item.
    summary : dict
        Small results: ``"nrmse"``, the rows of the NRMSE table (the compare stage's
        when it was considered, which includes the RBF rows, else the validate
        stage's), when one of those stages was considered.
    worker : str
        ``"<host>:<pid>"`` of the process that ran the workflow.
    """

    path: Path
    name: str
    status: str
    seconds: float
    events: tuple[StageEvent, ...] = ()
    error: str = ""
    traceback: str = ""
    output_dir: Path | None = None
    outputs: dict[str, dict[str, str]] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    worker: str = ""

    @property
    def ok(self) -> bool:
        """Whether the workflow ran to the end (``status == "done"``)."""
        return self.status == "done"

    @property
    def ran(self) -> tuple[str, ...]:
        """Stages that ran."""
        return tuple(e.stage for e in self.events if e.action == "ran")

    @property
    def skipped(self) -> tuple[str, ...]:
        """Stages that were up to date and skipped."""
        return tuple(e.stage for e in self.events if e.action == "skipped")

    @property
    def failed_stage(self) -> str:
        """The stage that raised; empty when none did (done, or failed while loading)."""
        return next((e.stage for e in self.events if e.action == "failed"), "")


# --------------------------------------------------------------------------- inputs


def expand_workflows(paths_or_globs: str | os.PathLike | Iterable[str | os.PathLike]) -> list[Path]:
    """Expand files, directories and glob patterns into a list of workflow files.

    Parameters
    ----------
    paths_or_globs : path-like or iterable of path-like
        Each entry is a workflow file (taken as is), a directory (every ``*.toml``
        directly inside it, sorted by name) or a glob pattern (``*``, ``?``, ``[...]``;
        ``**`` recurses; sorted; a matched directory contributes its ``*.toml`` files).

    Returns
    -------
    list of pathlib.Path
        Absolute paths, in argument order, without duplicates (first occurrence kept).

    Raises
    ------
    WorkflowError
        If there is no entry, or an entry matches nothing: a missing file, a
        directory without ``*.toml`` files, or a pattern that matches no workflow file.
    """
    if isinstance(paths_or_globs, str | os.PathLike):
        paths_or_globs = [paths_or_globs]
    entries = [os.fspath(p) for p in paths_or_globs]
    if not entries:
        raise WorkflowError("no workflow files given")
    found: dict[Path, None] = {}
    for entry in entries:
        path = Path(entry)
        if path.is_dir():
            matches = sorted(path.glob("*.toml"))
            if not matches:
                raise WorkflowError(f"directory '{entry}' holds no *.toml workflow file")
        elif path.is_file():
            matches = [path]
        elif _GLOB_CHARS & set(entry):
            matches = []
            for hit in sorted(glob.glob(entry, recursive=True)):
                hit_path = Path(hit)
                if hit_path.is_dir():
                    matches += sorted(hit_path.glob("*.toml"))
                elif hit_path.is_file():
                    matches.append(hit_path)
            if not matches:
                raise WorkflowError(f"pattern '{entry}' matches no workflow file")
        else:
            raise WorkflowError(f"workflow file '{entry}' does not exist")
        for match in matches:
            found.setdefault(match.resolve(), None)
    return list(found)


def _check_output_dirs(paths: Sequence[Path]) -> None:
    """Refuse a batch in which two workflows would write to the same (or a nested) directory.

    Workflows that cannot be loaded here are left to their worker, which reports the error.
    """
    from pipeline.workflow import load_workflow

    owners: list[tuple[Path, Path]] = []
    for path in paths:
        try:
            out = load_workflow(path).output_dir
        except Exception:  # reported by the workflow's own task, as its failure
            continue
        for other, other_out in owners:
            if out == other_out or out.is_relative_to(other_out) or other_out.is_relative_to(out):
                raise WorkflowError(
                    f"workflows '{other}' and '{path}' write to the same output directory "
                    f"('{other_out}' and '{out}'); give each its own [workflow] output_dir"
                )
        owners.append((path, out))


# --------------------------------------------------------------------------- one item


def _describe(exc: BaseException) -> str:
    """``"<ExceptionClass>: <message>"``, the last line of the exception's traceback."""
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def run_workflow_item(
    path: str | os.PathLike, stages: Sequence[str] | None = None, force: bool = False
) -> BatchResult:
    """Load one workflow and run its stages, capturing any error (the task of a batch).

    Parameters
    ----------
    path : path-like
        The workflow file.
    stages : sequence of str, optional
        Stages to consider (default: all of the workflow's stages).
    force : bool, optional
        Rerun up-to-date stages too.

    Returns
    -------
    BatchResult
        Never raises for a failing workflow: a :class:`~pipeline.errors.DebistError`
        or any other ``Exception`` comes back as ``status="failed"`` with its class
        and message (and the traceback for an unexpected one).
    """
    from pipeline.runner import Runner
    from pipeline.workflow import load_workflow

    path = Path(path).resolve()
    t_start = time.perf_counter()
    events: list[StageEvent] = []
    clock = {"last": t_start, "stage": ""}

    def on_event(stage: str, what: str, _detail: str) -> None:
        now = time.perf_counter()
        if what == "start":
            clock["stage"] = stage
        else:
            action = "ran" if what == "done" else "skipped"
            events.append(StageEvent(stage, action, now - clock["last"]))
            clock["stage"] = ""
        clock["last"] = now

    name, output_dir = path.stem, None
    error = tb = ""
    manifests: dict[str, Any] = {}
    try:
        wf = load_workflow(path)
        name, output_dir = wf.name, wf.output_dir
        clock["last"] = time.perf_counter()
        manifests = Runner(wf).run(stages, force=force, on_event=on_event)
    except Exception as exc:
        error = _describe(exc)
        if not isinstance(exc, DebistError):
            tb = traceback.format_exc()
        if clock["stage"]:
            events.append(StageEvent(clock["stage"], "failed", time.perf_counter() - clock["last"]))
    summary: dict[str, Any] = {}
    for stage in ("compare", "validate"):
        rows = manifests[stage].summary.get("table") if stage in manifests else None
        if rows is not None:
            summary["nrmse"] = rows
            break
    return BatchResult(
        path=path,
        name=name,
        status="failed" if error else "done",
        seconds=time.perf_counter() - t_start,
        events=tuple(events),
        error=error,
        traceback=tb,
        output_dir=output_dir,
        outputs={stage: dict(m.outputs) for stage, m in manifests.items()},
        summary=summary,
        worker=_worker_id(),
    )


# --------------------------------------------------------------------------- the batch


def run_batch(
    workflow_paths: Iterable[str | os.PathLike],
    *,
    stages: Sequence[str] | None = None,
    force: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    address: str | None = None,
    on_done: Callable[[BatchResult], None] | None = None,
    progress: bool = False,
) -> list[BatchResult]:
    """Run many workflows as independent Dask tasks and collect one result per workflow.

    Parameters
    ----------
    workflow_paths : iterable of path-like
        Workflow files (see :func:`expand_workflows` for directories and patterns).
    stages : sequence of str, optional
        Stages to consider in every workflow (default: each workflow's own stages).
    force : bool, optional
        Rerun up-to-date stages too.
    scheduler : {"synchronous", "threads", "processes", "distributed"}, optional
        Default ``"processes"``, or ``"distributed"`` when ``address`` is given.
        ``"synchronous"`` runs in the calling thread (debugging); ``"threads"`` shares
        one process (the validate and study stages draw with matplotlib's pyplot, which
        is not thread-safe: prefer processes for those); ``"processes"`` spawns
        ``workers`` processes; ``"distributed"`` connects to ``address``, or starts a
        ``LocalCluster`` of ``workers`` single-threaded worker processes when there is
        none. Spawned workers re-import the calling script: call from under
        ``if __name__ == "__main__":``.
    workers : int, optional
        Worker processes or threads of a local scheduler or local cluster (default:
        ``min(number of workflows, CPU count)``). Ignored by ``"synchronous"`` and
        with ``address`` (the cluster has its workers).
    address : str, optional
        A running ``dask.distributed`` scheduler, e.g. ``"tcp://host:8786"``. Its
        workers must import this version of debist and see the workflow files and their
        data at the same absolute paths; start them with ``--nthreads 1`` (pyplot).
    on_done : callable, optional
        Called as ``on_done(result)`` in the calling thread each time a workflow
        finishes, in completion order (e.g. to advance a ``rich.progress`` bar). With
        ``progress=True`` on a cluster, the calls follow the end of the bar.
    progress : bool, optional
        Show Dask's own console progress bar: ``dask.diagnostics.ProgressBar`` for
        local schedulers, ``distributed.progress`` on a cluster.

    Returns
    -------
    list of BatchResult
        One per workflow, in input order; failed workflows included.

    Raises
    ------
    WorkflowError
        Before anything runs: an unknown scheduler or stage, ``workers < 1``,
        ``address`` with a local scheduler, two workflows writing to the same output
        directory, or ``"distributed"`` without the ``distributed`` package (the message
        says ``pip install "debist[cluster]"``), or a cluster that cannot be reached.
    concurrent.futures.process.BrokenProcessPool
        When a worker process of the ``"processes"`` scheduler dies (a crash in native
        code, the out-of-memory killer): Dask's local process pool cannot recover, so the
        batch stops. Workflows that finished keep their artifacts and a rerun skips
        them. ``"distributed"`` isolates such crashes: its nanny restarts the worker and
        only that workflow fails (``KilledWorker``).

    References
    ----------
    ``dask.delayed`` and ``dask.compute(..., scheduler=, num_workers=, chunksize=)``:
    https://docs.dask.org/en/stable/scheduling.html; ``dask.diagnostics.Callback`` and
    ``ProgressBar``: https://docs.dask.org/en/stable/diagnostics-local.html;
    ``distributed.Client.submit``, ``as_completed``, ``progress``:
    https://docs.dask.org/en/stable/futures.html.
    """
    from pipeline.runner import STAGES

    paths = [Path(p).resolve() for p in workflow_paths]
    if scheduler is None:
        scheduler = "distributed" if address else "processes"
    if scheduler not in SCHEDULERS:
        raise WorkflowError(f"unknown scheduler {scheduler!r}; schedulers: {SCHEDULERS}")
    if address and scheduler != "distributed":
        raise WorkflowError(f"address {address!r} needs scheduler 'distributed', not {scheduler!r}")
    if workers is not None and workers < 1:
        raise WorkflowError(f"workers must be at least 1, got {workers}")
    stages = None if stages is None else tuple(stages)
    for stage in stages or ():
        if stage not in STAGES:
            raise WorkflowError(f"unknown stage {stage!r}; stages: {STAGES}")
    if not paths:
        return []
    _check_output_dirs(paths)
    n_workers = workers or min(len(paths), os.cpu_count() or 1)
    args = [(str(p), stages, force) for p in paths]
    if scheduler == "distributed":
        return _run_distributed(args, address, n_workers, on_done, progress)
    return _run_local(args, scheduler, n_workers, on_done, progress)


def _init_worker_process() -> None:
    """Make BLAS single-threaded in a local worker process, unless the user set it.

    It runs before the first task, so before the worker imports NumPy (unless the main
    module of the calling program imports it at the top: then the setting comes too late).
    """
    for name, value in _WORKER_ENVIRON.items():
        os.environ.setdefault(name, value)


def _run_local(
    args: list[tuple[str, tuple[str, ...] | None, bool]],
    scheduler: str,
    n_workers: int,
    on_done: Callable[[BatchResult], None] | None,
    progress: bool,
) -> list[BatchResult]:
    import dask
    from dask.diagnostics import Callback, ProgressBar

    keys = {f"debist-batch-{i}": i for i in range(len(args))}
    tasks = [
        dask.delayed(run_workflow_item, pure=False)(*a, dask_key_name=k)
        for k, a in zip(keys, args, strict=True)
    ]

    def posttask(key: Any, result: Any, _dsk: Any, _state: Any, _worker: Any) -> None:
        if on_done is not None and key in keys:
            on_done(result)

    options: dict[str, Any] = {}
    if scheduler != "synchronous":
        options["num_workers"] = n_workers
    if scheduler == "processes":
        # The default chunksize (6) would send several workflows to one worker process
        # together; each workflow is a long task, so hand them out one at a time.
        options["chunksize"] = 1
        options["initializer"] = _init_worker_process
    with contextlib.ExitStack() as stack:
        stack.enter_context(Callback(posttask=posttask))
        if progress:
            stack.enter_context(ProgressBar())
        results = dask.compute(*tasks, scheduler=scheduler, optimize_graph=False, **options)
    return list(results)


def _run_distributed(
    args: list[tuple[str, tuple[str, ...] | None, bool]],
    address: str | None,
    n_workers: int,
    on_done: Callable[[BatchResult], None] | None,
    progress: bool,
) -> list[BatchResult]:
    try:
        from distributed import Client, LocalCluster, as_completed
        from distributed import progress as show_progress
    except ImportError:
        raise WorkflowError(
            f"the 'distributed' scheduler needs the dask.distributed package: {_CLUSTER_HINT}"
        ) from None
    with contextlib.ExitStack() as stack:
        if address:
            try:
                client = stack.enter_context(Client(address, set_as_default=False))
            except OSError as exc:
                raise WorkflowError(
                    f"cannot reach the Dask scheduler at {address!r}: {exc}"
                ) from None
        else:
            cluster = stack.enter_context(
                LocalCluster(
                    n_workers=n_workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                )
            )
            client = stack.enter_context(Client(cluster, set_as_default=False))
        futures = [client.submit(run_workflow_item, *a, pure=False) for a in args]
        index = {f.key: i for i, f in enumerate(futures)}
        if progress:  # blocks until done in a console (a widget in a notebook)
            show_progress(futures, scheduler=client.scheduler.address)
        results: dict[int, BatchResult] = {}
        for future in as_completed(futures, loop=client.loop):
            i = index[future.key]
            try:
                results[i] = future.result()
            except Exception as exc:  # the task never returned: its worker died, ...
                path = Path(args[i][0])
                results[i] = BatchResult(
                    path=path,
                    name=path.stem,
                    status="failed",
                    seconds=0.0,
                    error=_describe(exc),
                )
            future.release()
            if on_done is not None:
                on_done(results[i])
    return [results[i] for i in range(len(args))]


# --------------------------------------------------------------------------- reporting


def summary_table(results: Iterable[BatchResult]) -> Any:
    """Tabulate a batch: one row per workflow.

    Parameters
    ----------
    results : iterable of BatchResult
        The batch's results (e.g. from :func:`run_batch`).

    Returns
    -------
    pandas.DataFrame
        Columns ``name``, ``status``, ``seconds`` [s], ``ran`` and ``skipped`` (numbers
        of stages), ``failed_stage``, ``error``, ``path`` and ``rbf_nrmse_q``: the free-run
        NRMSE(q) of the identified model per data set (``"name: value"``, empty without a
        validation table), in the order of ``results``.
    """
    import pandas as pd

    columns = ["name", "status", "seconds", "ran", "skipped", "failed_stage", "error", "path"]
    columns.append("rbf_nrmse_q")
    rows = [
        {
            "name": r.name,
            "status": r.status,
            "seconds": round(r.seconds, 3),
            "ran": len(r.ran),
            "skipped": len(r.skipped),
            "failed_stage": r.failed_stage,
            "error": r.error,
            "path": str(r.path),
            "rbf_nrmse_q": ", ".join(
                f"{row['dataset']}: {100 * row['nrmse_q']:.2f} %"
                for row in (r.summary or {}).get("nrmse", [])
                if row.get("model") == "rbf"
            ),
        }
        for r in results
    ]
    return pd.DataFrame(rows, columns=columns)
