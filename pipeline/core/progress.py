"""Progress of long computations, reported to whoever listens; the wall times of parts.

Library code calls :func:`report` (or passes :func:`reporter` down to a loop) with a task
label and the work done so far; nothing happens unless a caller installed a listener with
:func:`listening`. The listener lives in a context variable, so concurrent runs in one
process (threads, asyncio tasks) each see their own, and a library user who installs none
pays one lookup per report. A stage times its parts with a :class:`Stopwatch` (its
``timings``, which ``-v`` shows).

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

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import partial
from typing import Any

__all__ = ["Listener", "Stopwatch", "listening", "report", "reporter", "tracking_time"]

#: A listener: called as ``listener(task, done, total)``; ``total`` 0 when unknown.
Listener = Callable[[str, int, int], None]
_LISTENER: ContextVar[Listener | None] = ContextVar("debist_progress", default=None)


@contextmanager
def listening(listener: Listener | None) -> Iterator[None]:
    """Send every progress report made inside the block to ``listener``.

    Parameters
    ----------
    listener : callable or None
        Called as ``listener(task, done, total)``; None mutes the reports inside the block
        (e.g. in a forked child, which must not draw on its parent's display).

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


def tracking_time(
    fun: Callable[..., Any],
    t_span: tuple[float, float],
    task: str = "simulated time [ms]",
    steps: int = 200,
) -> Callable[..., Any]:
    """Wrap an ODE right-hand side ``fun(t, x, *args)`` to report the simulated time reached.

    An integrator evaluates the right-hand side at ever later times; the wrapper reports
    the latest time as milliseconds done of the span, at most ``steps`` times. With no
    listener the function is returned unwrapped (no cost).

    Parameters
    ----------
    fun : callable
        Right-hand side, as for :func:`scipy.integrate.solve_ivp`.
    t_span : tuple of float
        Start and end time of the whole integration [s].
    task : str, optional
        The task label.
    steps : int, optional
        Reports at most this many times.

    Returns
    -------
    callable
        ``fun`` itself, or a wrapper with the same signature and results.

    Examples
    --------
    >>> seen = []
    >>> with listening(lambda task, done, total: seen.append((done, total))):
    ...     f = tracking_time(lambda t, x: -x, (0.0, 2.0), steps=2)
    ...     _ = [f(t, 1.0) for t in (0.0, 0.5, 1.0, 1.5, 2.0)]
    >>> seen
    [(0, 2000), (1000, 2000), (2000, 2000)]
    """
    rep = reporter(task)
    if rep is None:
        return fun
    t0, t1 = float(t_span[0]), float(t_span[1])
    total = max(1, round((t1 - t0) * 1e3))
    stride = (t1 - t0) / max(1, steps)
    state = {"next": t0}

    def wrapped(t: float, *args: Any) -> Any:
        if t >= state["next"]:
            state["next"] = t + stride
            rep(min(total, round((t - t0) * 1e3)), total)
        return fun(t, *args)

    return wrapped


class Stopwatch:
    """Wall times of the consecutive parts of a computation [s], for a stage's ``timings``.

    Each :meth:`lap` gives the time since the previous lap (or the start) to a part, so the
    parts add up to the time the computation took, and nothing is counted twice. A part
    named twice gets the sum of its laps.

    Attributes
    ----------
    times : dict of str to float
        Part name to its wall time [s], in the order the parts first ended.

    References
    ----------
    Python documentation, :func:`time.perf_counter`.

    Examples
    --------
    >>> watch = Stopwatch()
    >>> watch.lap("read inputs")
    >>> watch.lap("simulate")
    >>> list(watch.times), all(t >= 0 for t in watch.times.values())
    (['read inputs', 'simulate'], True)
    """

    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, part: str) -> None:
        """Give the time since the previous lap (or the start or :meth:`restart`) to ``part``.

        Parameters
        ----------
        part : str
            The part's name, e.g. ``"plots"``.
        """
        now = time.perf_counter()
        self.times[part] = self.times.get(part, 0.0) + (now - self._last)
        self._last = now

    def restart(self) -> None:
        """Start the next part now: the time since the previous lap goes to no part."""
        self._last = time.perf_counter()
