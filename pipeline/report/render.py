"""Figures drawn and rendered to PNG bytes, several at a time in forked processes.

A stage that writes figures (identify's curves and search, the report's
Fig. 11a, 12, 13 and 15) spends most of its time in matplotlib's layout and Agg rendering, on
one core. :func:`render_pngs` draws the figures of a list in worker processes, one per core:
each figure is drawn and rendered by the same code in a copy of the same process (POSIX
``fork``), so its bytes are those of a serial rendering (:func:`debist.core.fileformats.
png_bytes`). No figure is drawn in the calling process, a single one neither: matplotlib's
caches and drawing buffers then never stay in the stage's process, whose resident memory is
inherited by every later stage and every process forked after it. Where forking is unsafe
(:func:`debist.core.forking.fork_workers`) the figures are rendered here, one after the other.

References
----------
Python documentation, :mod:`concurrent.futures` (ProcessPoolExecutor) and
:mod:`multiprocessing` (start methods); matplotlib documentation, "Embedding in a web
application server" (``matplotlib.figure.Figure`` without pyplot).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from debist.core.fileformats import png_bytes
from debist.core.forking import (
    Caught,
    call_recording_warnings,
    fork_workers,
    replay_warnings,
    worker_pool,
)

__all__ = ["FigureJob", "render_pngs"]


@dataclass(frozen=True)
class FigureJob:
    """A figure to draw and render: ``draw(*args, **kwargs)`` at ``dpi``.

    Parameters
    ----------
    draw : callable
        A module-level function that returns a ``matplotlib.figure.Figure`` (it is sent
        to a worker process by reference).
    args : tuple, optional
        Its positional arguments (picklable).
    kwargs : mapping, optional
        Its keyword arguments (picklable).
    dpi : int, optional
        Resolution of the PNG [dots per inch].
    """

    draw: Callable[..., Any]
    args: tuple = ()
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    dpi: int = 160

    def figure(self) -> Any:
        """Draw the figure.

        Returns
        -------
        matplotlib.figure.Figure
        """
        return self.draw(*self.args, **dict(self.kwargs))

    def png(self) -> bytes:
        """Draw the figure and render it to PNG bytes (:func:`debist.core.fileformats.png_bytes`).

        Returns
        -------
        bytes
            The PNG file.
        """
        return png_bytes(self.figure(), self.dpi)


def _render(job: FigureJob) -> tuple[bytes, Caught]:
    """Render a job in a worker; its warnings travel back with the bytes (see _replay)."""
    return call_recording_warnings(job.png)


def _replay(result: tuple[bytes, Caught]) -> bytes:
    """Issue a worker's warnings here, as a serial rendering would have, and return its bytes."""
    png, caught = result
    replay_warnings(caught)
    return png


def render_pngs(jobs: Sequence[FigureJob]) -> list[bytes]:
    """Draw and render figures to PNG bytes, in forked worker processes where that is safe.

    ``min(n, cores)`` forked processes render the figures; this process only waits (one core
    or where forking is unsafe: it renders them itself, one after the other).

    Parameters
    ----------
    jobs : sequence of FigureJob
        The figures.

    Returns
    -------
    list of bytes
        The PNG files, in the order of ``jobs``; the same bytes as ``job.png()`` here.

    Raises
    ------
    Exception
        What drawing a figure raised (re-raised from the worker; a worker's warnings are
        issued here).

    References
    ----------
    Python documentation, :class:`concurrent.futures.ProcessPoolExecutor`.
    """
    jobs = list(jobs)
    if not jobs:
        return []
    workers = fork_workers(max(len(jobs), 2))  # two for one figure: one to draw it, this one
    if workers == 1:
        return [job.png() for job in jobs]
    import matplotlib.figure  # noqa: F401  (imported once here, inherited by the workers)

    with worker_pool(min(workers, len(jobs))) as pool:
        return [_replay(result) for result in pool.map(_render, jobs)]
