"""Batch runs: many workflows (one per prototype) on Dask, locally or on a cluster.

Each workflow is one Dask task running its stages with :class:`debist.engine.runner.Runner`
(with its caching). One failing workflow never stops the others: its error, or the death of
its worker process, comes back in its :class:`BatchResult`. Every workflow writes only to
its own ``output_dir``, so a parallel batch writes the same bytes as a serial one. The
schedulers, and a script that runs a folder of prototypes:
docs/explanation/implementation.md.

References
----------
Dask documentation: "Scheduling" (https://docs.dask.org/en/stable/scheduling.html),
"Delayed", "Diagnostics (local)", "Futures"; dask.distributed "LocalCluster", "Nanny",
"Why did my worker die?" (https://distributed.dask.org/en/stable/killed.html).
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import json
import logging
import os
import signal
import socket
import sys
import threading
import time
import traceback
import uuid
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from debist.core import allocator, preflight
from debist.core.errors import DebistError, DebistWarning, OutputDirError, WorkflowError
from debist.core.fileformats import atomic_write
from debist.core.forking import usable_cores
from debist.engine.fleetmark import unfinished_fleet, unfinished_message
from debist.engine.runner import STAGES, Runner
from debist.engine.zooindex import ZOO_FILE, zoo_workflows
from debist.report.html import INDEX_FILE, REPORT_FILE, index_row, render_index, write_page
from debist.workflow.loader import load_workflow

#: Values of ``scheduler`` in :func:`run_batch`.
SCHEDULERS = ("synchronous", "threads", "processes", "distributed")
#: Times a workflow is retried on a fresh worker process after its worker died, on the
#: local cluster (dask config ``distributed.scheduler.allowed-failures``). On a cluster at an
#: ``address`` that scheduler's own setting counts (distributed's default: 3).
ALLOWED_FAILURES = 1
#: Memory one local worker process is given at least [bytes]: a worker's peak over four of
#: the paper's workflows was 617-757 MiB (:func:`debist.core.allocator.collector_frozen`),
#: so the budget holds ``budget // WORKER_BYTES`` workers (at least one).
WORKER_BYTES = 10**9
#: Characters that make an argument of :func:`expand_workflows` a glob pattern.
_GLOB_CHARS = frozenset("*?[")
_INSTALL_HINT = "pip install distributed"
#: One BLAS/OpenMP thread per worker process (n processes x n BLAS threads would
#: oversubscribe the cores), set by the nanny before it spawns a worker (dask config
#: ``distributed.nanny.pre-spawn-environ``); a variable the user set keeps its value.
_WORKER_ENVIRON = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",  # the free-run kernel's threads: one per worker process too
    # freed arrays stay in the worker's heap (debist.core.allocator), instead of dask's default
    # MALLOC_TRIM_THRESHOLD_ of 64 KiB, which returns them to the kernel
    **allocator.ENVIRON,
    **allocator.ARROW_ENVIRON,  # pyarrow's allocator: the C library's, as in the command
}
#: How often a batch on a cluster looks for workers that joined since [s] (SLURM jobs that
#: started late), while no workflow finishes.
_REFILL_SECONDS = 2.0
#: The preload module of the local cluster's worker processes (they ignore Ctrl-C).
_WORKER_SETUP = "debist.engine.batchworker"
#: Type of the arguments of one batch item: (workflow file, stages, force).
_Args = tuple[str, tuple[str, ...] | None, bool]
#: Beside the batch index: the sha256 of the page debist wrote there (JSON), so that a later
#: batch replaces only its own page, never a user's ``index.html``.
INDEX_MARKER = ".debist-index.json"


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
        The full traceback of an unexpected (non-:class:`~debist.core.errors.DebistError`)
        exception; empty otherwise.
    output_dir : pathlib.Path or None
        The workflow's artifact root (None when the file could not be loaded).
    outputs : dict of str to dict of str to str
        Per stage considered: output path (relative to the stage directory) to sha256,
        as in the stage's manifest. Empty for a failed item.
    summary : dict
        Small results: ``"nrmse"``, the rows of the NRMSE table (the compare stage's
        when it was considered, which includes the RBF rows, else the validate
        stage's), when one of those stages was considered; ``"design"``, the identified
        model's equilibria and switching voltages (the identify summary's), and
        ``"q_unit"``, the SI unit of q, and ``"input_units"``, the SI unit of each input.
    worker : str
        ``"<host>:<pid>"`` of the process that ran the workflow; the address of the last
        Dask worker for a workflow whose worker processes died.
    worker_deaths : int
        Worker processes that died while running it (each followed by a retry on a fresh
        one while the scheduler allows; read from the scheduler's task story).
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
    worker_deaths: int = 0

    @property
    def note(self) -> str:
        """What else happened: worker processes that died under it and the retries."""
        if not self.worker_deaths:
            return ""
        times = "once" if self.worker_deaths == 1 else f"{self.worker_deaths} times"
        end = "retried on a fresh one" if self.ok else "retried, then given up"
        return f"its worker process died {times} (killed or out of memory); {end}"

    @property
    def file(self) -> str:
        """The workflow file relative to the current directory (absolute when outside it)."""
        return display_path(self.path)

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
        directly inside it, sorted by name; a zoo folder of ``debist zoo``: its members'
        ``workflow.toml``, in member order) or a glob pattern (``*``, ``?``, ``[...]``;
        ``**`` recurses; sorted; a matched directory contributes its ``*.toml`` files).

    Returns
    -------
    list of pathlib.Path
        Absolute paths, in argument order, without duplicates (first occurrence kept).

    Raises
    ------
    WorkflowError
        If there is no entry, or an entry matches nothing: a missing file, a
        directory without ``*.toml`` files, or a pattern that matches no workflow file;
        or a workflow file is in the folder of a fleet whose ``debist fleet`` was stopped
        part way (:func:`debist.engine.fleetmark.unfinished_fleet`).
    """
    if isinstance(paths_or_globs, str | os.PathLike):
        paths_or_globs = [paths_or_globs]
    entries = [os.fspath(p) for p in paths_or_globs]
    if not entries:
        raise WorkflowError("no workflow files given")
    found: dict[Path, None] = {}
    for entry in entries:
        path = Path(entry)
        if path.is_dir() and (path / ZOO_FILE).is_file():  # a zoo: its members' workflows
            matches = zoo_workflows(path)
        elif path.is_dir():
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
            unfinished = unfinished_fleet(match.parent)
            if unfinished is not None:
                raise WorkflowError(unfinished_message(match.parent, unfinished))
            found.setdefault(match.resolve(), None)
    return list(found)


def display_path(path: str | os.PathLike) -> str:
    """Show a workflow file as a person refers to it: relative to the current directory.

    Parameters
    ----------
    path : path-like
        A file path.

    Returns
    -------
    str
        The path relative to the current working directory when the file is inside it,
        else the absolute path.

    Examples
    --------
    >>> display_path(Path.cwd() / "workflows" / "a.toml") == os.path.join("workflows", "a.toml")
    True
    """
    absolute = Path(path).resolve()
    try:
        return str(absolute.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(absolute)


def _load_headers(paths: Sequence[Path]) -> dict[Path, tuple[str, Path]]:
    """Load every workflow's ``[workflow] name`` and ``output_dir``, refusing shared outputs.

    Workflows that cannot be loaded here are left out: their worker reports the error.

    Raises
    ------
    WorkflowError
        If two workflows write to the same (or a nested) output directory.
    """
    headers: dict[Path, tuple[str, Path]] = {}
    for path in paths:
        try:
            wf = load_workflow(path)
        except Exception:  # reported by the workflow's own task, as its failure
            continue
        out = wf.output_dir
        for other, (_name, other_out) in headers.items():
            if out == other_out or out.is_relative_to(other_out) or other_out.is_relative_to(out):
                raise WorkflowError(
                    f"workflows '{other}' and '{path}' write to the same output directory "
                    f"('{other_out}' and '{out}'); give each its own [workflow] output_dir"
                )
        headers[path] = (wf.name, out)
    return headers


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
        Never raises for a failing workflow: a :class:`~debist.core.errors.DebistError`
        or any other ``Exception`` comes back as ``status="failed"`` with its class
        and message (and the traceback for an unexpected one).
    """
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
    if "identify" in manifests and manifests["identify"].summary.get("design"):
        summary["design"] = manifests["identify"].summary["design"]
        units = manifests["identify"].summary.get("units", {})
        summary["q_unit"] = units.get("q", "m")
        summary["input_units"] = [
            units[k] for k in sorted(units) if k[:1] == "v" and k[1:].isdigit()
        ]
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
    stages, force : sequence of str, bool, optional
        Stages to consider in every workflow (default its own); rerun up-to-date stages too.
    scheduler : {"processes", "threads", "synchronous", "distributed"}, optional
        A local cluster of worker processes (default; a workflow whose worker dies is retried
        once), the cluster at ``address`` (retried as often as its scheduler's
        ``distributed.scheduler.allowed-failures`` allows), threads, or the calling thread
        (docs/explanation/implementation.md, docs/how-to/cluster.md).
        Spawned workers re-import the calling script: call under ``if __name__ == "__main__":``.
    workers : int, optional
        Worker processes or threads; default ``min(number of workflows, cores)``. On this
        machine at most as many as there are workflows, cores and workers of
        :data:`WORKER_BYTES` in the memory budget (a ``DebistWarning`` says so).
    address : str, optional
        A running ``dask.distributed`` scheduler, e.g. ``"tcp://host:8786"``. Its workers must
        import this debist and see the workflow files, their data and output folders at the
        same paths; their environment (one BLAS thread each) is theirs to set. Each worker
        thread gets one workflow at a time, and workers that join while the batch runs get
        theirs within seconds.
    on_done : callable, optional
        Called as ``on_done(result)`` in the calling thread as each workflow finishes.
    progress : bool, optional
        Show a console progress bar.

    Returns
    -------
    list of BatchResult
        One per workflow, in input order, failed ones included (one whose worker processes died
        more often than the scheduler allows with ``error`` ``"KilledWorker: ..."``).

    Raises
    ------
    WorkflowError
        Before anything runs: an unknown scheduler or stage, ``workers < 1``, ``address`` with
        a local scheduler, two workflows with one output directory, ``distributed`` missing,
        or a cluster that cannot be reached.

    References
    ----------
    Dask "Scheduling" (https://docs.dask.org/en/stable/scheduling.html); dask.distributed
    ``LocalCluster``, ``KilledWorker``, ``allowed-failures`` (https://distributed.dask.org).
    """
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
    headers = _load_headers(paths)
    n_workers = workers or min(len(paths), usable_cores())
    if not address:
        n_workers = _capped_workers(n_workers, len(paths))
    args = [(str(p), stages, force) for p in paths]
    with interrupt_kept():
        if scheduler in ("synchronous", "threads"):
            return _run_local(args, scheduler, n_workers, on_done, progress)
        return _run_on_cluster(args, headers, address, n_workers, on_done, progress)


@contextlib.contextmanager
def interrupt_kept() -> Iterator[None]:
    """Let no Ctrl-C during the block be lost: raise ``KeyboardInterrupt`` at its end.

    A Ctrl-C reaches the batch's worker processes too (the terminal signals the whole
    process group), and the cluster's event loop may catch the ``KeyboardInterrupt`` raised
    in this process, so that the batch went on and ended with exit code 0. While the block
    runs, ``SIGINT`` is recorded before it raises as usual; if the block then ends normally
    or with another exception, ``KeyboardInterrupt`` is raised (the command line's exit
    code 130). Outside the main thread, or when ``SIGINT`` does not have Python's default
    handler, the block runs as it is.

    Yields
    ------
    None

    Raises
    ------
    KeyboardInterrupt
        If ``SIGINT`` arrived while the block ran.

    References
    ----------
    Python documentation, :mod:`signal` (``default_int_handler``; handlers run in the main
    thread only); POSIX, "General Terminal Interface" (the foreground process group gets
    the terminal's INTR signal).
    """
    main = threading.current_thread() is threading.main_thread()
    if not main or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    seen: list[int] = []

    def record(signum: int, frame: Any) -> None:
        seen.append(signum)
        signal.default_int_handler(signum, frame)

    signal.signal(signal.SIGINT, record)
    try:
        yield
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        if seen:
            raise KeyboardInterrupt from exc
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if seen:
        raise KeyboardInterrupt


def _capped_workers(asked: int, n_items: int) -> int:
    """Cap local workers at the workflows, this process's cores and the memory budget."""
    budget = preflight.memory_budget()
    limits = {
        f"{n_items} workflow(s)": n_items,
        f"{usable_cores()} core(s)": usable_cores(),
        f"a memory budget of {preflight.format_bytes(budget)} for workers of "
        f"{preflight.format_bytes(WORKER_BYTES)}": max(1, budget // WORKER_BYTES),
    }
    why, most = min(limits.items(), key=lambda item: item[1])
    if asked <= most:
        return asked
    warnings.warn(
        f"batch: {most} worker(s) instead of {asked}: as many as {why} allow",
        DebistWarning,
        stacklevel=3,
    )
    return most


def _run_local(
    args: list[_Args],
    scheduler: str,
    n_workers: int,
    on_done: Callable[[BatchResult], None] | None,
    progress: bool,
) -> list[BatchResult]:
    """Run the items with a local scheduler of ``dask.compute`` (threads or synchronous)."""
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

    options: dict[str, Any] = {} if scheduler == "synchronous" else {"num_workers": n_workers}
    with contextlib.ExitStack() as stack:
        stack.enter_context(Callback(posttask=posttask))
        if progress:
            stack.enter_context(ProgressBar())
        results = dask.compute(*tasks, scheduler=scheduler, optimize_graph=False, **options)
    return list(results)


@contextlib.contextmanager
def _environ_restored(names: Iterable[str]) -> Iterator[None]:
    """Put the listed environment variables of this process back as they were on exit."""
    saved = {name: os.environ.get(name) for name in names}
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextlib.contextmanager
def local_cluster(n_workers: int) -> Iterator[Any]:
    """Start the local Dask cluster of a batch and yield a client of it.

    Parameters
    ----------
    n_workers : int
        Worker processes, one thread each.

    Yields
    ------
    distributed.Client
        A client of a ``distributed.LocalCluster`` on this machine's loopback interface
        (no dashboard): each worker process runs under a nanny, which restarts it when it
        dies; the scheduler retries a task whose worker died :data:`ALLOWED_FAILURES`
        time(s) and then fails it with ``KilledWorker``. The worker processes start with
        one BLAS/OpenMP thread (``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` and
        ``OPENBLAS_NUM_THREADS`` = 1, unless this process's environment sets them), each
        with an equal share of the memory budget (``DEBIST_MEMORY_BUDGET_GB``, unless set
        here: :func:`debist.core.preflight.memory_budget`), and inherit the rest of this
        process's environment. The cluster's logs are silenced
        (its failures come back as task errors), and the environment variables that the
        nannies set in this process are restored on exit. The worker processes ignore SIGINT
        (:mod:`debist.engine.batchworker`): a terminal's Ctrl-C, which reaches them too, is
        this process's to handle.

    References
    ----------
    dask.distributed: ``LocalCluster``, ``Nanny`` ("env" and the configuration
    ``distributed.nanny.pre-spawn-environ``), ``distributed.scheduler.allowed-failures``
    (https://distributed.dask.org/en/stable/killed.html).
    """
    import dask
    from distributed import Client, LocalCluster

    pre_spawn = {**dask.config.get("distributed.nanny.pre-spawn-environ"), **_WORKER_ENVIRON}
    if preflight.BUDGET_ENV not in os.environ:  # the workers share this machine's budget
        share = preflight.memory_budget() / n_workers / 1e9  # the variable is in 10^9 bytes
        pre_spawn[preflight.BUDGET_ENV] = f"{share:.3f}"
    config = {
        "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
        "distributed.nanny.pre-spawn-environ": pre_spawn,
    }
    with contextlib.ExitStack() as stack:
        # The nannies live in this process and set their pre-spawn variables here too
        # (and PYTHONHASHSEED; distributed's proctitle sets __DASK_PARENT_PID): undo that
        # when the cluster is gone.
        restored = [*pre_spawn, "PYTHONHASHSEED", "__DASK_PARENT_PID"]
        stack.enter_context(_environ_restored(restored))
        with dask.config.set(config):  # read when the scheduler and nannies are created
            cluster = LocalCluster(
                host="127.0.0.1",
                n_workers=n_workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
                preload=[_WORKER_SETUP],  # Ctrl-C is the command's, not its workers'
            )
        stack.enter_context(cluster)
        yield stack.enter_context(Client(cluster, set_as_default=False))


def _deaths(client: Any, key: str) -> int:
    """Worker deaths under a task: its scheduler transitions from processing to released.

    A batch gives each worker one workflow at a time, so a task released while processing
    lost its worker (``distributed``'s ``handle-worker-cleanup``); 0 if the story is lost.
    """
    try:
        story = client.story(key)
    except Exception:  # an older scheduler or a forgotten key: nothing to report
        return 0
    return sum(
        1 for entry in story if entry[0] == "scheduler" and entry[2:4] == ("processing", "released")
    )


def _died(allowed_failures: int) -> str:
    """Describe the error of a workflow whose worker processes died (``KilledWorker``)."""
    times = allowed_failures + 1
    count = {1: "once", 2: "twice"}.get(times, f"{times} times")
    return (
        f"KilledWorker: worker process died {count} while running it "
        "(killed by a signal or out of memory)"
    )


def _console_bar(total: int, enabled: bool) -> Any:
    """Build a ``rich.progress`` bar on stdout in the format of ``dask.diagnostics.ProgressBar``."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (BarColumn(), TextColumn("| {task.percentage:>3.0f}% Completed |"),
               TimeElapsedColumn())  # fmt: skip
    bar = Progress(*columns, console=Console(file=sys.stdout), disable=not enabled)
    bar.add_task("batch", total=total)
    return bar


def _worker_threads() -> int:
    """Threads the free runs of this process may use (``NUMBA_NUM_THREADS``), run on a worker."""
    from debist.simulate.kernel import kernel_threads

    return kernel_threads()


def check_cluster_workers(client: Any) -> list[str]:
    """Warn about workers of a cluster at an address that would run workflows unsafely or slowly.

    A worker with several threads runs as many workflows at once in one process, whose
    stages draw with matplotlib's pyplot (not thread-safe); a worker whose free runs may use
    several threads (``NUMBA_NUM_THREADS`` unset on a machine of several cores)
    oversubscribes the cores its job was given. The local cluster of a batch is set up right;
    a cluster the user started is the user's to set up (docs/how-to/cluster.md).

    Parameters
    ----------
    client : distributed.Client
        A client of the cluster.

    Returns
    -------
    list of str
        The warnings given (each also issued as a :class:`~debist.core.errors.DebistWarning`);
        empty when every worker has one thread and one free-run thread, or when the workers
        cannot be asked (this check then raises nothing: the batch reports what fails).

    Warns
    -----
    DebistWarning
        One per kind of worker found: several threads, several free-run threads.

    References
    ----------
    dask.distributed: ``Client.nthreads``, ``Client.run``; matplotlib, "Thread safety" of
    pyplot; numba, ``NUMBA_NUM_THREADS``.
    """
    said: list[str] = []
    try:
        nthreads = client.nthreads()
        free_run = client.run(_worker_threads) if nthreads else {}
    except Exception:  # an older worker or a lost connection: the batch reports what fails
        return said
    many = sorted(w for w, n in nthreads.items() if n > 1)
    if many:
        said.append(
            f"batch: {len(many)} of the cluster's {len(nthreads)} workers have more than one "
            f"thread (e.g. {many[0]}, {nthreads[many[0]]}): their workflows share a process and "
            "its plotting; start the workers with --nthreads 1"
        )
    wide = sorted(w for w, n in free_run.items() if isinstance(n, int) and n > 1)
    if wide:
        said.append(
            f"batch: {len(wide)} of the cluster's workers integrate free runs on several "
            f"threads (e.g. {wide[0]}, {free_run[wide[0]]}): set NUMBA_NUM_THREADS=1 (and "
            "OMP_NUM_THREADS=1) in the workers' environment"
        )
    for text in said:
        warnings.warn(text, DebistWarning, stacklevel=2)
    return said


def _as_they_finish(running: Any, refill: Callable[[], object], every: float) -> Iterator[Any]:
    """Yield the futures of an ``as_completed`` as they finish, calling ``refill()`` meanwhile.

    ``refill()`` runs every ``every`` seconds while none finishes: workers that joined the
    cluster since then get workflows without waiting for one to finish.
    """
    checked = time.monotonic()
    while not running.is_empty():
        finished = running.next_batch(block=False)
        if finished:
            yield from finished
            checked = time.monotonic()
            continue
        if time.monotonic() - checked >= every:
            refill()
            checked = time.monotonic()
        time.sleep(0.1)  # as ``as_completed`` itself polls


def _run_on_cluster(
    args: list[_Args],
    headers: dict[Path, tuple[str, Path]],
    address: str | None,
    n_workers: int,
    on_done: Callable[[BatchResult], None] | None,
    progress: bool,
) -> list[BatchResult]:
    """Run the items on a Dask cluster: the one at ``address``, else a local one."""
    try:
        from distributed import Client, KilledWorker, as_completed
    except ImportError:
        raise WorkflowError(
            "a batch on worker processes needs the dask.distributed package, a dependency "
            f"of debist that is missing here: {_INSTALL_HINT}"
        ) from None
    with contextlib.ExitStack() as stack:
        bar = stack.enter_context(_console_bar(len(args), progress))
        if address:
            try:
                client = stack.enter_context(Client(address, set_as_default=False))
            except OSError as exc:
                raise WorkflowError(
                    f"cannot reach the Dask scheduler at {address!r}: {exc}"
                ) from None
            check_cluster_workers(client)
        else:
            client = stack.enter_context(local_cluster(n_workers))
        batch_id = uuid.uuid4().hex[:8]
        waiting = list(reversed(range(len(args))))  # popped from the end: input order
        submitted: dict[str, tuple[int, float]] = {}
        running = as_completed(loop=client.loop)
        results: dict[int, BatchResult] = {}

        def submit_to_idle_workers() -> None:
            # At most one workflow per worker thread at a time: when a worker dies, the
            # scheduler counts the death against every task assigned to it, queued ones
            # too, so a queued workflow could fail for another one's crash.
            slots = max(1, sum(client.nthreads().values()))
            while waiting and running.count() < slots:
                i = waiting.pop()
                key = f"debist-{Path(args[i][0]).stem}-{batch_id}-{i}"
                future = client.submit(run_workflow_item, *args[i], key=key, pure=False)
                submitted[future.key] = (i, time.perf_counter())
                running.add(future)

        submit_to_idle_workers()
        refill = lambda: waiting and submit_to_idle_workers()  # noqa: E731
        for future in _as_they_finish(running, refill, _REFILL_SECONDS):
            i, t_submit = submitted.pop(future.key)
            try:
                results[i] = replace(future.result(), worker_deaths=_deaths(client, future.key))
            except Exception as exc:  # the task never returned: its workers died, ...
                path = Path(args[i][0])
                name, output_dir = headers.get(path, (path.stem, None))
                killed = isinstance(exc, KilledWorker)
                results[i] = BatchResult(
                    path=path,
                    name=name,
                    status="failed",
                    seconds=time.perf_counter() - t_submit,
                    error=_died(exc.allowed_failures) if killed else _describe(exc),
                    output_dir=output_dir,
                    worker=exc.last_worker.address if killed else "",
                    worker_deaths=_deaths(client, future.key),
                )
            future.release()
            bar.advance(bar.task_ids[0])
            if on_done is not None:
                on_done(results[i])
            submit_to_idle_workers()
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
        Columns ``file`` (the workflow file relative to the current directory, see
        :func:`display_path`), ``name`` (``[workflow] name``, which workflows may share),
        ``status``, ``seconds`` [s], ``ran`` and ``skipped`` (numbers of stages),
        ``failed_stage``, ``error``, ``note`` (:attr:`BatchResult.note`: worker deaths
        and retries), ``path`` (absolute) and ``rbf_nrmse_q``: the free-run
        NRMSE(q) of the identified model per data set (``"name: value"``, empty without a
        validation table), in the order of ``results``.
    """
    import pandas as pd

    columns = ["file", "name", "status", "seconds", "ran", "skipped", "failed_stage", "error"]
    columns += ["note", "path", "rbf_nrmse_q"]
    rows = [
        {
            "file": r.file,
            "name": r.name,
            "status": r.status,
            "seconds": round(r.seconds, 3),
            "ran": len(r.ran),
            "skipped": len(r.skipped),
            "failed_stage": r.failed_stage,
            "error": r.error,
            "note": r.note,
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


def write_index(
    results: Sequence[BatchResult],
    folder: str | os.PathLike | None = None,
    pages: Sequence[tuple[str, str | os.PathLike]] = (),
) -> Path | None:
    """Write the batch's index page: one row per prototype, linking each one's report.

    Parameters
    ----------
    results : sequence of BatchResult
        The batch's results (:func:`run_batch`), in the order of the rows.
    folder : path-like, optional
        Where ``index.html`` goes; default the folder that holds every workflow's output
        folder (``runs/`` of a fleet from ``debist fleet``).
    pages : sequence of (str, path-like), optional
        Other pages of the batch report (label, file), linked from the index by their path
        relative to it (e.g. a zoo's ``zoo.html``).

    Returns
    -------
    pathlib.Path or None
        The page written (replaced atomically); None when no workflow could be loaded or
        the common folder is the file system root or the home folder.

    Raises
    ------
    OutputDirError
        If ``index.html`` exists in the folder and is not debist's (:func:`index_is_ours`):
        nothing is written, the user's file stays as it is.

    References
    ----------
    :func:`debist.report.html.render_index` (the page).
    """
    dirs = [Path(r.output_dir).resolve() for r in results if r.output_dir is not None]
    if folder is None:
        if not dirs:
            return None
        folder = Path(os.path.commonpath([d.parent for d in dirs]))
        if folder in (Path(folder.anchor), Path.home().resolve()):
            return None
    folder = Path(folder).resolve()
    rows = []
    for r in results:
        page = Path(r.output_dir) / "report" / REPORT_FILE if r.output_dir else None
        link = None
        if page is not None and REPORT_FILE in r.outputs.get("report", {}) and page.is_file():
            link = Path(os.path.relpath(page.resolve(), folder)).as_posix()
        rows.append(
            index_row(
                r.name,
                r.file,
                r.status,
                error=r.error,
                nrmse=r.summary.get("nrmse", []),
                design=r.summary.get("design"),
                q_unit=r.summary.get("q_unit", "m"),
                input_units=r.summary.get("input_units", ()),
                link=link,
                note=r.note,
            )
        )
    links = [(label, Path(os.path.relpath(Path(page).resolve(), folder)).as_posix())
             for label, page in pages]  # fmt: skip
    page = folder / INDEX_FILE
    if not index_is_ours(folder):
        raise OutputDirError(
            f"'{page}' is not a batch index debist wrote (a page of yours, or one changed "
            "since): kept as it is; remove or rename it for the batch to write its index there"
        )
    text = render_index(rows, links)
    written = write_page(page, text)
    record = {"debist": "batch index", "file": INDEX_FILE, "sha256": _sha256_text(text)}
    atomic_write(folder / INDEX_MARKER, json.dumps(record, indent=2) + "\n")
    return written


def _sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def index_is_ours(folder: str | os.PathLike) -> bool:
    """Tell whether debist may write the batch index into a folder without losing a user's file.

    Parameters
    ----------
    folder : path-like
        The folder of the index.

    Returns
    -------
    bool
        True when the folder holds no ``index.html``, or one that debist wrote and nobody
        changed since: its sha256 is the one recorded in :data:`INDEX_MARKER` beside it (or,
        without that record, as written by an older debist, its title is the batch index's).
        False for any other ``index.html`` (a user's page, or debist's edited by hand).

    References
    ----------
    FIPS 180-4 (SHA-256).
    """
    page = Path(folder) / INDEX_FILE
    if not page.exists() and not page.is_symlink():
        return True
    if page.is_symlink() or not page.is_file():
        return False
    try:
        data = page.read_bytes()
    except OSError:
        return False
    try:
        record = json.loads((Path(folder) / INDEX_MARKER).read_text(encoding="utf-8"))
    except FileNotFoundError:  # an index of a debist that kept no record: its title
        return b"<title>debist batch: " in data[:2048]
    except (OSError, ValueError):
        return False
    return isinstance(record, dict) and record.get("sha256") == hashlib.sha256(data).hexdigest()
