"""Figures rendered in forked processes: the same PNG bytes, in order, errors and warnings kept."""

import os
import threading
import warnings

import numpy as np
import pytest
from matplotlib.figure import Figure

from debist.core import forking
from debist.core.forking import fork_workers
from debist.report import render
from debist.report.render import FigureJob, render_pngs


def _draw(seed: int, warn: bool = False) -> Figure:
    """A line plot of a seeded random walk (a figure that differs per seed)."""
    rng = np.random.default_rng(seed)
    fig = Figure(figsize=(3, 2))
    ax = fig.subplots()
    ax.plot(np.cumsum(rng.standard_normal(500)), lw=0.8)
    ax.set_title(f"walk {seed}")
    if warn:
        warnings.warn(f"walk {seed} warns", UserWarning, stacklevel=1)
    return fig


def _fail(seed: int) -> Figure:
    raise ValueError(f"no figure for {seed}")


def _jobs(n: int, **kwargs) -> list[FigureJob]:
    return [FigureJob(_draw, (seed,), kwargs, dpi=60) for seed in range(n)]


@pytest.fixture
def parallel(monkeypatch):
    """Two processes even on a one-core machine, so that the forked path runs."""
    monkeypatch.setattr(render, "fork_workers", lambda n: 1 if n < 2 else 2)


def test_parallel_bytes_are_the_serial_bytes_in_order(parallel):
    jobs = _jobs(5)
    pngs = render_pngs(jobs)
    assert pngs == [job.png() for job in jobs]
    assert len(set(pngs)) == 5  # five different figures, not one repeated
    assert all(p.startswith(b"\x89PNG\r\n\x1a\n") for p in pngs)


#: Processes that drew a figure with _draw_counted (this process's list; a worker's own copy
#: of it is not seen here).
_drawn: list[int] = []


def _draw_counted(seed: int) -> Figure:
    _drawn.append(os.getpid())
    return _draw(seed)


def test_no_figure_is_drawn_here_where_forking_is_safe(parallel):
    """One figure and three: the bytes are those drawn here, yet this process drew none."""
    for n in (1, 3):
        jobs = [FigureJob(_draw_counted, (seed,), dpi=60) for seed in range(n)]
        _drawn.clear()
        pngs = render_pngs(jobs)
        assert _drawn == []
        assert pngs == [job.png() for job in jobs]
        assert _drawn == [os.getpid()] * n  # the reference bytes, drawn here by job.png()


def test_without_forking_the_figures_render_here(monkeypatch):
    monkeypatch.setattr(render, "fork_workers", lambda n: 1)
    assert render_pngs([]) == []
    jobs = [FigureJob(_draw_counted, (seed,), dpi=60) for seed in range(2)]
    _drawn.clear()
    assert render_pngs(jobs) == [job.png() for job in jobs]
    assert _drawn == [os.getpid()] * 4


def test_a_workers_warning_is_issued_here(parallel):
    jobs = _jobs(3, warn=True)  # two worker processes draw them
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_pngs(jobs)
    assert sorted(str(w.message) for w in caught) == [f"walk {s} warns" for s in range(3)]


def test_a_workers_error_is_raised_here(parallel):
    jobs = [*_jobs(2), FigureJob(_fail, (7,))]  # a worker's job fails
    with pytest.raises(ValueError) as err:
        render_pngs(jobs)
    assert "for 7" in str(err.value)


def test_a_daemonic_process_renders_serially(monkeypatch):
    class Daemon:
        daemon = True

    monkeypatch.setattr(forking.multiprocessing, "current_process", lambda: Daemon())
    assert fork_workers(4) == 1


def test_a_thread_other_than_the_main_one_renders_serially():
    found = []
    worker = threading.Thread(target=lambda: found.append(fork_workers(4)))
    worker.start()
    worker.join()
    assert found == [1]


def _png_size(data: bytes) -> tuple[int, int]:
    """Width and height of a PNG from its IHDR chunk [px]."""
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.mark.parametrize(
    ("size_in", "dpi", "expected"),
    [
        ((12.0, 8.0), 216, (1920, 1280)),  # 2592 px asked: capped at twice the report's column
        ((10.5, 7.5), 216, (1920, 1371)),  # 182.86 dpi: 7.5 in are 1371.4 px
        ((8.0, 7.5), 216, (1728, 1620)),  # narrower than the cap: as asked
        ((4.0, 3.0), 60, (240, 180)),
    ],
)
def test_a_png_is_never_wider_than_the_report_shows(size_in, dpi, expected):
    from debist.core.fileformats import MAX_PNG_WIDTH, png_bytes

    fig = Figure(figsize=size_in)
    fig.subplots().plot([0, 1], [1, 0])
    size = _png_size(png_bytes(fig, dpi))
    assert size == expected
    assert size[0] <= MAX_PNG_WIDTH == 1920
