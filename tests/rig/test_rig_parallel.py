"""The rig's experiments in parallel worker processes give the serial runs' numbers."""

from __future__ import annotations

import multiprocessing
import os
from types import SimpleNamespace

import numpy as np
import pytest

from debist.core import forking, progress
from debist.core.errors import WorkflowError
from debist.core.forking import fork_workers
from debist.rig import experiment
from debist.rig.experiment import RigConfig, run_experiment, run_experiments

SECTION = {
    "sample_time": 0.01,
    "prototype": {"dz_1": 0.15e-3},
    "experiments": {
        "a": {"profile": "identification", "duration": 6.3, "seed": 1},
        "b": {"profile": "identification", "duration": 6.3, "seed": 2, "side": 1},
    },
}


@pytest.fixture(scope="module")
def cfg() -> RigConfig:
    return RigConfig.from_dict(SECTION, {"b": 23e-3})


def test_parallel_runs_equal_serial_runs(cfg, monkeypatch):
    """Each worker's run is the serial run bit for bit; ``meanwhile`` runs in the parent."""
    if fork_workers(2) < 2:
        pytest.skip("one core or no fork here: run_experiments runs serially")
    seen = []
    with progress.listening(lambda task, done, total: seen.append((task, done, total))):
        runs, other = run_experiments(cfg, meanwhile=lambda: multiprocessing.current_process().pid)
    assert list(runs) == ["a", "b"]
    assert other == multiprocessing.current_process().pid
    assert seen[-1] == ("rig: experiments", 2, 2)  # the children report nothing here
    assert {task for task, _, _ in seen} == {"rig: experiments"}
    for name in ("a", "b"):
        serial = run_experiment(cfg, name)
        for key in ("q", "v1", "v2", "q_true", "x_true", "F_friction"):
            np.testing.assert_array_equal(getattr(runs[name], key), getattr(serial, key))
        assert runs[name].nfev == serial.nfev
    assert runs["b"].q_true[0] > 0 > runs["a"].q_true[0]  # the start wells as configured


def test_idle_runs_in_the_parent_only_while_workers_integrate(cfg, monkeypatch):
    """``idle`` runs once, after ``meanwhile``, in the parent while the workers run; never
    when the runs are serial (the work it does would then only add to the run's time)."""
    calls = []
    meanwhile = lambda: calls.append(("meanwhile", os.getpid()))  # noqa: E731
    idle = lambda: calls.append(("idle", os.getpid()))  # noqa: E731
    if fork_workers(2) >= 2:
        run_experiments(cfg, meanwhile=meanwhile, idle=idle)
        assert calls == [("meanwhile", os.getpid()), ("idle", os.getpid())]
    calls.clear()
    monkeypatch.setattr(experiment, "fork_workers", lambda n: 1)
    runs, _ = run_experiments(cfg, meanwhile=meanwhile, idle=idle)
    assert calls == [("meanwhile", os.getpid())]
    assert list(runs) == ["a", "b"]


def test_no_children_from_a_daemonic_worker(monkeypatch):
    """Inside a Dask or multiprocessing worker (daemonic) the experiments run serially."""
    monkeypatch.setattr(
        forking.multiprocessing, "current_process", lambda: SimpleNamespace(daemon=True)
    )
    assert fork_workers(4) == 1
    monkeypatch.undo()
    assert fork_workers(1) == 1


def test_a_failing_worker_raises_the_experiments_error():
    """A worker's error reaches the caller as raised (named profile and value)."""
    section = {**SECTION, "experiments": {n: {"profile": "staircase", "duration": 1.0}
                                          for n in ("a", "b")}}  # fmt: skip
    cfg = RigConfig.from_dict(section, {"b": 23e-3})
    with pytest.raises(WorkflowError) as err:
        run_experiments(cfg)
    assert "staircase" in str(err.value) and "shorter" in str(err.value)
