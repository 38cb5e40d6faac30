"""How many forked worker processes a stage may start for independent pieces of work.

The rig's experiments and the stages' figures are independent pieces of CPU-bound work that
a stage can hand to worker processes (:class:`concurrent.futures.ProcessPoolExecutor` with
the POSIX ``fork`` start method, so a child starts without importing the library again).
:func:`fork_workers` is the one policy for both: one process per core, and none where
forking is unsafe or pointless.

References
----------
Python documentation, :mod:`concurrent.futures` (ProcessPoolExecutor) and
:mod:`multiprocessing` (start methods; "Contexts and start methods": forking a
multithreaded process is problematic); :mod:`signal` (``pthread_sigmask``); POSIX
``fork(2)`` (the child inherits the signal mask).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.context as mp_context
import os
import signal
import threading
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

__all__ = [
    "STOP_SIGNALS",
    "Caught",
    "call_recording_warnings",
    "fork_context",
    "fork_workers",
    "one_core",
    "replay_warnings",
    "usable_cores",
    "worker_pool",
]

#: Warnings recorded in a worker process: (message, category, filename, lineno) each.
Caught = list[tuple[str, type[Warning], str, int]]


def usable_cores() -> int:
    """Count the cores this process may run on (its CPU affinity where the OS has one).

    Returns
    -------
    int
        At least 1.
    """
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, cores or 1)


#: Depth of :func:`one_core` blocks in this process (a forked child starts with its parent's).
_ONE_CORE = 0


@contextmanager
def one_core() -> Iterator[None]:
    """Run the block on this process's core alone: :func:`fork_workers` returns 1 inside.

    For work that already runs in a process beside others (a stage's first part started
    ahead): a child it forked could outlive it when it is stopped, and would only compete
    for the cores the others use.

    Yields
    ------
    None
    """
    global _ONE_CORE
    _ONE_CORE += 1
    try:
        yield
    finally:
        _ONE_CORE -= 1


def fork_workers(n: int) -> int:
    """Count the processes for ``n`` independent jobs: one per core, 1 where forking is unsafe.

    A daemonic process (a Dask or multiprocessing worker, which already runs in parallel
    with its peers) may not start children, nor may a :func:`one_core` block; only POSIX
    ``fork`` starts a child without importing the library again (``spawn`` costs more than a
    short job saves); outside the main thread (``debist batch`` with threads) another thread
    may hold a lock that a forked child could never take.

    Parameters
    ----------
    n : int
        Number of jobs.

    Returns
    -------
    int
        Processes to use, the calling one included: ``min(n, cores)``, or 1.
    """
    if n < 2 or _ONE_CORE or multiprocessing.current_process().daemon:
        return 1
    if threading.current_thread() is not threading.main_thread():
        return 1
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    return min(n, usable_cores())


#: The signals that stop a run (Ctrl-C, ``kill``); a terminal sends SIGINT to every process
#: of its foreground group, forked children included.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


if hasattr(mp_context, "ForkContext"):  # POSIX

    class _QuietProcess(mp_context.ForkProcess):
        """A forked process that ignores SIGINT and SIGTERM: its parent stops it.

        The parent's handlers (Python's ``KeyboardInterrupt``, the command line's SIGTERM
        handler) would raise in the child wherever it is, print its traceback, and could
        cut a result off halfway through the pipe (its reader then waits forever). The stop
        signals are blocked across the fork (the child inherits the mask), the child
        ignores them, then unblocks them: there is no moment in which a child could raise.
        A Ctrl-C reaches the parent too, which stops its children: a pool by its shutdown
        (:func:`worker_pool`), a :class:`~debist.core.beside.BesideRun` by its ``stop``
        (that child handles the signals itself).
        """

        def start(self) -> None:
            """Fork with the stop signals blocked (delivered here once the child exists)."""
            held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
            try:
                super().start()
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, held)

        def run(self) -> None:
            """Ignore the stop signals, unblock them, then run."""
            for signum in STOP_SIGNALS:
                signal.signal(signum, signal.SIG_IGN)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
            super().run()

    class _QuietForkContext(mp_context.ForkContext):
        """The ``fork`` context whose processes are :class:`_QuietProcess`."""

        Process = _QuietProcess


def fork_context(*, quiet: bool = False):
    """Return the ``fork`` multiprocessing context (check :func:`fork_workers` first).

    Parameters
    ----------
    quiet : bool, optional
        Children that ignore SIGINT and SIGTERM and are stopped by this process instead
        (see :class:`_QuietProcess`): no child traceback after a Ctrl-C.

    Returns
    -------
    multiprocessing.context.ForkContext

    Raises
    ------
    ValueError
        Where there is no ``fork`` (Windows).
    """
    if not quiet or not hasattr(mp_context, "ForkContext"):
        return multiprocessing.get_context("fork")
    return _QuietForkContext()


@contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """Open a pool of forked processes that a Ctrl-C or SIGTERM stops quietly.

    The workers ignore the stop signals (:func:`fork_context` with ``quiet``); when the
    block ends with an exception (the ``KeyboardInterrupt`` of a Ctrl-C included), the jobs
    not yet started are cancelled and the running ones finish before it propagates.

    Parameters
    ----------
    workers : int
        Number of processes (:func:`fork_workers`).

    Yields
    ------
    concurrent.futures.ProcessPoolExecutor

    References
    ----------
    Python documentation, :meth:`concurrent.futures.Executor.shutdown` (``cancel_futures``).
    """
    pool = ProcessPoolExecutor(workers, mp_context=fork_context(quiet=True))
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def call_recording_warnings(fn: Callable[[], Any]) -> tuple[Any, Caught]:
    """Call ``fn()`` in a worker process and record the warnings it issues.

    A worker's warnings would reach the terminal from another process, past the parent's
    progress display and its warning format; they travel back with the result instead and
    :func:`replay_warnings` issues them in the parent, as a serial call would have.

    Parameters
    ----------
    fn : callable
        Called without arguments.

    Returns
    -------
    result : object
        What ``fn`` returned.
    caught : list of tuple
        The warnings, in order (every one, not filtered by the "once" rules).
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = fn()
    return result, [(str(w.message), w.category, w.filename, w.lineno) for w in caught]


def replay_warnings(caught: Caught) -> None:
    """Issue warnings recorded by :func:`call_recording_warnings` in this process.

    Parameters
    ----------
    caught : list of tuple
        (message, category, filename, lineno) of each warning.
    """
    for message, category, filename, lineno in caught:
        warnings.warn_explicit(message, category, filename, lineno)
