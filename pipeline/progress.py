"""Progress of long computations, reported to whoever listens (the CLI draws it).

Library code calls :func:`report` (or passes :func:`reporter` down to a loop) with a task
label and the work done so far; nothing happens unless a caller installed a listener with
:func:`listening`. The listener lives in a context variable, so concurrent runs in one
process (threads, asyncio tasks) each see their own, and a library user who installs none
pays one lookup per report.

Examples
--------
>>> seen = []
>>> with listening(lambda task, done, total: seen.append((task, done, total))):
...     report("free run", 1, 4)
>>> seen
[('free run', 1, 4)]
>>> report("free run", 2, 4)  # nobody listens: nothing happens

References
----------
Python documentation, :mod:`contextvars`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import partial

__all__ = ["Listener", "listening", "report", "reporter"]

#: A listener: called as ``listener(task, done, total)``; ``total`` 0 when unknown.
Listener = Callable[[str, int, int], None]
_LISTENER: ContextVar[Listener | None] = ContextVar("debist_progress", default=None)


@contextmanager
def listening(listener: Listener) -> Iterator[None]:
    """Send every progress report made inside the block to ``listener``.

    Parameters
    ----------
    listener : callable
        Called as ``listener(task, done, total)``.

    Yields
    ------
    None
    """
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)


def report(task: str, done: int, total: int = 0) -> None:
    """Report progress of a task to the listener, if there is one.

    Parameters
    ----------
    task : str
        What is being done (e.g. ``"validate: free runs of rbf"``).
    done : int
        Work done so far (samples, evaluations, grid points).
    total : int, optional
        Work in all; 0 when unknown.
    """
    listener = _LISTENER.get()
    if listener is not None:
        listener(task, int(done), int(total))


def reporter(task: str) -> Callable[[int, int], None] | None:
    """Return ``report`` bound to a task, or None when nobody listens (skip the bookkeeping).

    Parameters
    ----------
    task : str
        The task label.

    Returns
    -------
    callable or None
        Called as ``f(done, total)``.
    """
    return partial(report, task) if _LISTENER.get() is not None else None
