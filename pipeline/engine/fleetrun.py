"""A fleet whose every member's logs pass the template's own ingest.

:func:`debist.rig.fleet.make_fleet` keeps prototypes that are bistable and switchable by
their statics; whether a prototype's *recording* is usable is a property of the rig run: a
member that overshoots past the laser's range, for instance, logs samples at the range limit,
which the template's ingest refuses as sensor faults. :func:`viable_fleet` therefore runs the
rig and ingest stages of each candidate and keeps the first ``size`` draws that pass, in draw
order; the rejected draws and their reasons are returned to be reported. Member names keep
their draw index, so a member is the same prototype whatever the fleet size.

A candidate is checked in its own output folder, under its own workflow file's name (the
folder records that file as its owner): a kept member's rig logs and ingested tables stay
there, and the batch that runs the fleet finds those two stages up to date instead of
recording the same logs again. A rejected candidate's folder is removed, and so are the kept
ones' when the fleet cannot be completed. With two cores the next candidate is drawn and
checked in a forked process while the current one is (the results are taken in draw order,
so the fleet is the serial loop's); a candidate checked beyond the fleet's size is removed.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import signal
import sys
import tempfile
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from debist.core import progress
from debist.core.errors import DebistError
from debist.core.forking import call_recording_warnings, fork_context, fork_workers, replay_warnings
from debist.engine.fleetmark import note_candidate
from debist.engine.runner import Runner
from debist.rig.fleet import FleetError
from debist.rig.fleet_workflows import fleet_workflows
from debist.workflow.loader import load_workflow

__all__ = ["remove_runs", "viable_fleet"]

#: Extra draws allowed per requested member before giving up.
EXTRA_DRAWS = 2
#: ``prctl`` option: the signal a process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


def _ingest_problem(text: str, folder: Path, name: str) -> tuple[str | None, Path | None]:
    """Run a candidate's rig and ingest stages; the error (or None) and the run folder kept.

    The candidate's workflow is written as ``folder/name`` for the run and removed after it
    (the caller writes the kept ones, all or none). The run goes to the workflow's own output
    folder, kept when the logs pass; a folder that exists already is not touched (the check
    then runs in a scratch folder, as a failing one's is removed).
    """
    path = folder / name
    with tempfile.TemporaryDirectory(prefix="debist-fleet-") as tmp:
        run_dir = None
        try:
            path.write_text(text, encoding="utf-8")
            wf = load_workflow(path)
            if Path(wf.output_dir).exists():
                wf = load_workflow(path, Path(tmp) / "run")
            else:
                run_dir = Path(wf.output_dir)
            runner = Runner(wf)
            runner.run([s for s in ("rig", "ingest") if s in runner.stages()])
        except BaseException as exc:
            remove_runs([run_dir] if run_dir is not None else [])
            if isinstance(exc, DebistError):
                return str(exc), None
            raise
        finally:
            path.unlink(missing_ok=True)
    return None, run_dir


def _die_with(parent: int) -> None:
    """End a checking worker when the fleet's process dies, however it dies (Linux).

    A worker whose parent was killed (SIGKILL: nothing in it can stop its workers) would
    otherwise wait for work forever, or finish a check and write into the fleet folder while
    the next ``debist fleet`` replaces the stopped fleet there.

    References
    ----------
    Linux ``prctl(2)``: ``PR_SET_PDEATHSIG``.
    """
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # it died before the call above
        os._exit(1)


def _check_quietly(text: str, folder: Path, name: str):
    """:func:`_ingest_problem` in a worker process: no progress reports, warnings recorded."""
    with progress.listening(None):
        return call_recording_warnings(lambda: _ingest_problem(text, folder, name))


def _checks(
    draws: Iterable[tuple[str, str]], folder: Path
) -> Iterator[tuple[str, str, str | None, Path | None]]:
    """Check the draws in order: name, text, the problem (or None) and the run folder kept.

    With two cores the next draw is rendered and checked in a forked process while this one
    waits for the current check, so the results arrive in draw order as from a serial loop.
    A draw checked ahead of need is undone when the caller stops (the generator is closed):
    its kept run folder is removed. An error of the draws themselves (a member the scatter
    does not give) is raised only when the caller asks for that draw.
    """
    workers = fork_workers(2)
    if workers == 1:
        for name, text in draws:
            yield name, text, *_ingest_problem(text, folder, name)
        return
    draws = iter(draws)
    ahead: deque = deque()
    error: list[BaseException] = []
    with ProcessPoolExecutor(
        workers, mp_context=fork_context(), initializer=_die_with, initargs=(os.getpid(),)
    ) as pool:

        def draw_ahead() -> None:
            while not error and len(ahead) < workers:
                try:
                    name, text = next(draws)
                except StopIteration:
                    return
                except Exception as exc:  # raised when its turn comes
                    error.append(exc)
                    return
                ahead.append((name, text, pool.submit(_check_quietly, text, folder, name)))

        try:
            draw_ahead()
            while ahead:
                name, text, future = ahead[0]
                (problem, run_dir), caught = future.result()
                ahead.popleft()
                replay_warnings(caught)
                yield name, text, problem, run_dir
                draw_ahead()
            if error:
                raise error[0]
        finally:
            for _, _, future in ahead:  # checked ahead of need, or after a failure
                if future.cancel():
                    continue
                with contextlib.suppress(Exception):  # a failed check removed its own folder
                    (_, run_dir), _ = future.result()
                    remove_runs([run_dir] if run_dir is not None else [])


def viable_fleet(
    template: Mapping,
    template_dir: Path,
    folder: Path,
    size: int,
    seed: int,
    scatter: Mapping[str, float] | None = None,
) -> tuple[dict[str, str], dict[str, str], list[Path]]:
    """Render ``size`` member workflows whose rig logs pass the template's ingest.

    Parameters
    ----------
    template : mapping
        The parsed template workflow (it needs a ``[rig]`` section).
    template_dir : pathlib.Path
        Folder of the template.
    folder : pathlib.Path
        Folder the member workflows go to (created; each check writes its workflow there and
        removes it, and keeps a passing member's output folder).
    size : int
        Members wanted.
    seed : int
        Seed of the scatter.
    scatter : mapping, optional
        Spreads (:data:`debist.rig.fleet.DEFAULT_SCATTER`).

    Returns
    -------
    files : dict of str to str
        ``<name>-<draw>.toml`` -> TOML text of the kept members, in draw order.
    rejected : dict of str to str
        Member name -> why its log failed the template's ingest (one line).
    runs : list of pathlib.Path
        The output folders that hold the kept members' rig and ingest stages (for
        :func:`remove_runs` if their workflows cannot be written).

    Raises
    ------
    FleetError
        If fewer than ``size`` of ``size * (1 + EXTRA_DRAWS)`` draws pass.
    WorkflowError
        As :func:`debist.rig.fleet_workflows.fleet_workflows`.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (the experiment each member repeats).
    """
    folder.mkdir(parents=True, exist_ok=True)
    n_draws = size * (1 + EXTRA_DRAWS)
    draws = _noted(
        fleet_workflows(template, template_dir, folder, n_draws, seed=seed, scatter=scatter),
        folder,
    )
    kept: dict[str, str] = {}
    rejected: dict[str, str] = {}
    runs: list[Path] = []
    try:
        with contextlib.closing(_checks(draws if size > 0 else (), folder)) as checks:
            for name, text, problem, run_dir in checks:
                runs += [run_dir] if run_dir is not None else []
                if problem is None:
                    kept[name] = text
                else:
                    rejected[name.removesuffix(".toml")] = problem
                if len(kept) == size:
                    break
        if len(kept) < size:
            raise FleetError(
                f"only {len(kept)} of {n_draws} drawn prototypes give logs that the template's "
                f"ingest accepts (wanted {size}); first refusal: {next(iter(rejected.values()))}"
            )
    except BaseException:
        remove_runs(runs)
        raise
    return kept, rejected, runs


def _noted(draws: Iterable[tuple[str, str]], folder: Path) -> Iterator[tuple[str, str]]:
    """Yield the draws, each named in the fleet's record before its workflow file is written.

    Drawn in this process (also when checked in a forked one), so the record is written by
    one process: a fleet killed part way leaves files its rerun finds there
    (:func:`debist.engine.fleetmark.clear_unfinished`).
    """
    for name, text in draws:
        note_candidate(folder, name, text)
        yield name, text


def remove_runs(runs: Sequence[Path]) -> None:
    """Remove the output folders the candidates' checks kept (a fleet that is not written).

    Parameters
    ----------
    runs : sequence of pathlib.Path
        The folders :func:`viable_fleet` returned.
    """
    for run_dir in runs:
        shutil.rmtree(run_dir, ignore_errors=True)
