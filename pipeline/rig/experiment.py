"""Experiments on the virtual rig: the ``[rig]`` workflow section, the recording and the truth.

A workflow's ``[rig]`` section describes the simulated prototype (the ``[physics]`` prototype
with the deviations of ``[rig.prototype]``, e.g. an assembly asymmetry), the rig around it
(``[rig.plant]``: friction, HV drivers, laser sensor) and its experiments
(``[rig.experiments.<name>]``: an excitation profile, seeds, the MAT version). Each experiment
becomes a dSPACE ControlDesk recording with the laser position in mm, the monitored voltages
and the references in kV, under full block paths, which the ingest stage reads like a lab's
file, and a truth record (noise-free states, the true characteristic curves) for tests.

Examples
--------
::

    [rig]
    sample_time = 0.01                    # log interval [s] (paper: 10 ms)

    [rig.prototype]                       # deviations of the built prototype from [physics]
    dz_1 = 0.15e-3                        # [m]

    [rig.plant]                           # debist.rig.params.RigParams keys
    sensor_noise = 1e-6                   # [m]

    [rig.experiments.identification]
    profile = "identification"            # debist.rig.profiles.PROFILES
    seed = 1                              # sensor noise
    format = "7.3"                        # MAT version: "5" or "7.3"

References
----------
Masoud & Maas 2025, Sec. 5.1 (rig), Fig. 11a (identification profile).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import as_completed
from typing import Any

import numpy as np

from debist.core import progress
from debist.core.errors import WorkflowError
from debist.core.forking import fork_workers, worker_pool
from debist.rig.config import ExperimentConfig, RigConfig
from debist.rig.dspace import Channel, recording
from debist.rig.profiles import make_profile
from debist.rig.run import RigRun, simulate_rig

__all__ = [
    "CHANNELS",
    "ExperimentConfig",
    "RigConfig",
    "rig_recording",
    "run_experiment",
    "run_experiments",
    "truth_tree",
]

#: Block paths and units of the recorded channels (what a lab's ControlDesk layout shows).
CHANNELS = {
    "q": ("Model Root/Sensors/Laser/q", "mm", 1e3),
    "v1": ("Model Root/HV Amplifier/DE1/v_mon", "kV", 1e-3),
    "v2": ("Model Root/HV Amplifier/DE2/v_mon", "kV", 1e-3),
    "r1": ("Model Root/Reference/DE1/v_ref", "kV", 1e-3),
    "r2": ("Model Root/Reference/DE2/v_ref", "kV", 1e-3),
}
RASTER = "Periodic Task 1"
#: Fixed "created" stamp of the recordings: a rig log is a function of its inputs only.
CREATED = "Sat Jan 01 00:00:00 2000"


def run_experiment(cfg: RigConfig, name: str) -> RigRun:
    """Simulate one experiment of the rig (profile -> drivers -> plant -> sensors -> log).

    Parameters
    ----------
    cfg : RigConfig
        The rig.
    name : str
        Key of ``cfg.experiments``.

    Returns
    -------
    RigRun
        Logged channels and truth.

    Raises
    ------
    WorkflowError
        For an unknown profile or invalid profile settings, or a prototype the plant cannot
        start (no stable well on the start side, :func:`debist.rig.run.simulate_rig`).
    """
    exp = cfg.experiments[name]
    prof = make_profile(exp.profile, **exp.profile_kwargs())
    try:
        return simulate_rig(
            cfg.rig, prof.t, prof.r1, prof.r2, sample_time=cfg.sample_time, seed=exp.seed,
            side=exp.side,
        )  # fmt: skip
    except ValueError as exc:  # the settings make a plant without a start (e.g. no well)
        raise WorkflowError(
            f"[rig.experiments.{name}] side = {exp.side}: {exc}; the prototype of [physics] "
            "and [rig.prototype] cannot start this experiment",
            key=f"rig.experiments.{name}.side",
            value=exp.side,
        ) from None


def _run_unobserved(cfg: RigConfig, name: str) -> RigRun:
    """:func:`run_experiment` in a child process, with the parent's progress listener muted.

    A forked child inherits the listener (a context variable) of the thread that forked; it
    must not draw on the parent's display, so the parent reports whole experiments instead.
    """
    with progress.listening(None):
        return run_experiment(cfg, name)


def run_experiments(
    cfg: RigConfig,
    meanwhile: Callable[[], Any] | None = None,
    idle: Callable[[], Any] | None = None,
) -> tuple[dict[str, RigRun], Any]:
    """Simulate every experiment of the rig, in parallel processes where that is safe.

    The experiments are independent (each starts at rest with its own seeds), so they run
    in forked worker processes (:class:`concurrent.futures.ProcessPoolExecutor`), one per
    core; each result is the same as a serial run's (the same deterministic computation in
    another process). Serially where :func:`debist.core.forking.fork_workers` says forking is
    unsafe (inside a daemonic worker: ``debist batch`` already runs one prototype per worker;
    outside the main thread; on platforms without ``fork``).

    Parameters
    ----------
    cfg : RigConfig
        The rig and its experiments.
    meanwhile : callable, optional
        Work of the calling process that does not depend on the runs (the true curves): run
        while the workers integrate, or after the runs when they are serial.
    idle : callable, optional
        Work worth doing only on a core the workers leave free (loading what later stages
        will need): called after ``meanwhile`` while the workers integrate, not at all when
        the runs are serial. What it returns is discarded.

    Returns
    -------
    runs : dict of str to RigRun
        Per experiment name, in the order of ``cfg.experiments``.
    other : object
        What ``meanwhile`` returned (None without it).

    Raises
    ------
    WorkflowError
        As :func:`run_experiment` (the first failing experiment's error).

    References
    ----------
    Python documentation, :mod:`concurrent.futures` (ProcessPoolExecutor) and
    :mod:`multiprocessing` (start methods).
    """
    names = list(cfg.experiments)
    task = "rig: experiments"
    workers = fork_workers(len(names))
    other = None
    if workers == 1:
        runs = {}
        for i, name in enumerate(names):
            progress.report(task, i, len(names))
            runs[name] = run_experiment(cfg, name)
        progress.report(task, len(names), len(names))
        return runs, (meanwhile() if meanwhile is not None else None)
    with worker_pool(workers) as pool:
        futures = {pool.submit(_run_unobserved, cfg, name): name for name in names}
        progress.report(task, 0, len(names))
        if meanwhile is not None:
            other = meanwhile()
        if idle is not None:
            idle()
        for i, _ in enumerate(as_completed(futures)):
            progress.report(task, i + 1, len(names))
        done = {futures[f]: f.result() for f in futures}
    return {name: done[name] for name in names}, other


def rig_recording(run: RigRun, name: str, cfg: RigConfig) -> dict[str, Any]:
    """Build the ControlDesk recording of a run: laser q [mm], monitors, references [kV].

    Parameters
    ----------
    run : RigRun
        From :func:`run_experiment`.
    name : str
        Experiment name (in the description).
    cfg : RigConfig
        The rig (its settings go into the description).

    Returns
    -------
    dict
        For :func:`debist.rig.dspace.write_recording`.
    """
    exp = cfg.experiments[name]
    channels = [
        Channel(path, getattr(run, key) * scale, unit, RASTER)
        for key, (path, unit, scale) in CHANNELS.items()
    ]
    description = {
        "General": {"DateTime": CREATED, "Device": "debist virtual rig"},
        "Experiment": {"Name": name, "Profile": exp.profile, "Seed": float(exp.seed)},
    }
    return recording(channels, {RASTER: run.t}, description)


def truth_tree(run: RigRun, cfg: RigConfig, curves: dict[str, np.ndarray]) -> dict[str, Any]:
    """Collect the truth behind a run, for ``<experiment>_truth.h5``.

    Parameters
    ----------
    run : RigRun
        From :func:`run_experiment`.
    cfg : RigConfig
        The rig.
    curves : dict of str to ndarray
        The prototype's true curves, :func:`debist.rig.run.true_curves` (the same for
        every experiment of the rig, so computed once by the caller).

    Returns
    -------
    dict
        ``prototype`` and ``plant`` parameters [SI] (the plant ``model`` in the attributes
        of ``plant``), ``states`` (noise-free ``q``,
        ``q_dot``, ``phi``, the friction force and the applied voltages at the log
        instants) and ``curves``.

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 33, 37.
    """
    plant = cfg.rig.to_dict()
    prototype = plant.pop("prototype")
    model = plant.pop("model")
    return {
        "attrs": {"units": "SI", "sample_time": run.sample_time, "seed": run.seed},
        "prototype": {"attrs": prototype},
        "plant": {"attrs": {"model": model}}
        | {k: np.asarray(v, dtype=float) for k, v in plant.items()},
        "states": {
            "t": run.t,
            "q": run.q_true,
            "q_dot": run.q_dot_true,
            "phi": run.phi_true,
            "F_friction": run.F_friction,
            "v1": run.v1_applied,
            "v2": run.v2_applied,
            "x": run.x_true,
            "saturated": run.saturated,
        },
        "curves": curves,
    }
