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
multithreaded process is problematic).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = [
    "Caught",
    "call_recording_warnings",
    "fork_context",
    "fork_workers",
    "one_core",
    "replay_warnings",
    "usable_cores",
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


def fork_context():
    """Return the ``fork`` multiprocessing context (check :func:`fork_workers` first).

    Returns
    -------
    multiprocessing.context.ForkContext
    """
    return multiprocessing.get_context("fork")


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
