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

from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import field
from typing import Annotated, Any, Literal

import numpy as np
import pydantic
from pydantic import (
    AfterValidator,
    BeforeValidator,
    NonNegativeFloat,
    NonNegativeInt,
    PositiveFloat,
)

from debist.engine import progress
from debist.engine.forking import fork_context, fork_workers
from debist.errors import WorkflowError
from debist.physics.params import PrototypeParams
from debist.rig.dspace import Channel, recording
from debist.rig.params import RigParams
from debist.rig.profiles import PROFILES, make_profile
from debist.rig.run import RigRun, simulate_rig
from debist.workflow.config import CONFIG, ConfigValueError, config_from_section

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


def _format_str(value: object) -> object:
    """Let ``format = 5`` or ``7.3`` (TOML numbers) mean the MAT versions "5" and "7.3"."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return str(value)
    return value


def _side(value: int) -> int:
    if value not in (-1, 1):
        raise ConfigValueError(None, "-1 (left well) or 1 (right well)")
    return value


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class ExperimentConfig:
    """One experiment of the virtual rig (a ``[rig.experiments.<name>]`` table).

    Parameters
    ----------
    profile : str
        Excitation profile, a key of :data:`debist.rig.profiles.PROFILES`.
    seed : int
        Seed of the sensor and monitor noise, ``>= 0``.
    profile_seed : int or None
        Seed of the profile's random parts, ``>= 0``; default the profile's own.
    duration : float
        Length [s] (paper: 37.5 s).
    hold : float
        DAC interval of the references [s].
    v_sub : float or None
        Peak of the sub-threshold excitation [V]; default the profile's.
    format : {"5", "7.3"}
        MAT file version of the recording.
    side : {-1, 1}
        Initial well (-1: left, as the paper's experiments).

    Raises
    ------
    pydantic.ValidationError
        On an unknown profile, an invalid format or side, or a value of the wrong type
        (a ``ValueError``; :meth:`RigConfig.from_dict` raises a ``WorkflowError``).
    """

    profile: str = "identification"
    seed: NonNegativeInt = 0
    profile_seed: NonNegativeInt | None = None
    duration: PositiveFloat = 37.5
    hold: PositiveFloat = 1e-3
    v_sub: NonNegativeFloat | None = None
    format: Annotated[Literal["5", "7.3"], BeforeValidator(_format_str)] = "7.3"
    side: Annotated[int, AfterValidator(_side)] = -1

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ConfigValueError("profile", "one of " + ", ".join(PROFILES), self.profile)

    def profile_kwargs(self) -> dict[str, Any]:
        """Return the keyword arguments of :func:`debist.rig.profiles.make_profile`.

        Returns
        -------
        dict
            ``duration`` and ``hold`` [s], and ``seed`` and ``v_sub`` [V] when given.
        """
        kwargs: dict[str, Any] = {"duration": self.duration, "hold": self.hold}
        if self.profile_seed is not None:
            kwargs["seed"] = self.profile_seed
        if self.v_sub is not None:
            kwargs["v_sub"] = self.v_sub
        return kwargs


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class _RigSection:
    """The keys of the ``[rig]`` table (its sub-tables are checked by their own classes)."""

    sample_time: PositiveFloat = 0.01
    prototype: dict[str, Any] = field(default_factory=dict)
    plant: dict[str, Any] = field(default_factory=dict)
    experiments: dict[str, dict[str, Any]] = field(default_factory=dict)


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class RigConfig:
    """The ``[rig]`` section: the simulated prototype, the rig and its experiments.

    Parameters
    ----------
    rig : RigParams
        Prototype (``[physics]`` updated by ``[rig.prototype]``) and plant (``[rig.plant]``).
    sample_time : float
        Log interval [s].
    experiments : dict of str to ExperimentConfig
        The experiments by name, in file order.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1.
    """

    rig: RigParams
    sample_time: PositiveFloat = 0.01
    experiments: dict[str, ExperimentConfig] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, section: Mapping[str, Any], physics: Mapping[str, Any]) -> RigConfig:
        """Build from the ``[rig]`` and ``[physics]`` sections.

        Parameters
        ----------
        section : mapping
            The ``[rig]`` table.
        physics : mapping
            The ``[physics]`` table (the nominal prototype; empty: Table 1).

        Returns
        -------
        RigConfig

        Raises
        ------
        WorkflowError
            On an unknown key (with a suggestion) or an invalid value, naming its table
            (``[rig]``, ``[rig.prototype]``, ``[rig.plant]``, ``[rig.experiments.<name>]``),
            or no experiments.

        Examples
        --------
        >>> RigConfig.from_dict({"experiments": {"a": {"seed": "1"}}}, {})
        Traceback (most recent call last):
        ...
        debist.errors.WorkflowError: [rig.experiments.a] seed: expected an integer, got '1'
        """
        head = config_from_section(_RigSection, section, "[rig]")
        PrototypeParams.from_dict(physics)
        prototype = PrototypeParams.from_dict({**physics, **head.prototype}, "[rig.prototype]")
        if "prototype" in head.plant:
            raise WorkflowError(
                "[rig.plant] prototype: the prototype goes in [rig.prototype], not [rig.plant]"
            )
        rig = RigParams.from_dict({**head.plant, "prototype": prototype}, "[rig.plant]")
        experiments = {
            name: config_from_section(ExperimentConfig, table, f"[rig.experiments.{name}]")
            for name, table in head.experiments.items()
        }
        if not experiments:
            raise WorkflowError(
                "[rig] experiments: expected at least one [rig.experiments.<name>] table"
            )
        return cls(rig, head.sample_time, experiments)


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
        For an unknown profile or invalid profile settings.
    ValueError
        From :func:`debist.rig.run.simulate_rig` (e.g. no well on the start side).
    """
    exp = cfg.experiments[name]
    kwargs: dict[str, Any] = {"duration": exp.duration, "hold": exp.hold}
    if exp.profile_seed is not None:
        kwargs["seed"] = exp.profile_seed
    if exp.v_sub is not None:
        kwargs["v_sub"] = exp.v_sub
    prof = make_profile(exp.profile, **kwargs)
    return simulate_rig(
        cfg.rig, prof.t, prof.r1, prof.r2, sample_time=cfg.sample_time, seed=exp.seed,
        side=exp.side,
    )  # fmt: skip


def _run_unobserved(cfg: RigConfig, name: str) -> RigRun:
    """:func:`run_experiment` in a child process, with the parent's progress listener muted.

    A forked child inherits the listener (a context variable) of the thread that forked; it
    must not draw on the parent's display, so the parent reports whole experiments instead.
    """
    with progress.listening(None):
        return run_experiment(cfg, name)


def run_experiments(
    cfg: RigConfig, meanwhile: Callable[[], Any] | None = None
) -> tuple[dict[str, RigRun], Any]:
    """Simulate every experiment of the rig, in parallel processes where that is safe.

    The experiments are independent (each starts at rest with its own seeds), so they run
    in forked worker processes (:class:`concurrent.futures.ProcessPoolExecutor`), one per
    core; each result is the same as a serial run's (the same deterministic computation in
    another process). Serially where :func:`debist.engine.forking.fork_workers` says forking is
    unsafe (inside a daemonic worker: ``debist batch`` already runs one prototype per worker;
    outside the main thread; on platforms without ``fork``).

    Parameters
    ----------
    cfg : RigConfig
        The rig and its experiments.
    meanwhile : callable, optional
        Work of the calling process that does not depend on the runs (the true curves): run
        while the workers integrate, or after the runs when they are serial.

    Returns
    -------
    runs : dict of str to RigRun
        Per experiment name, in the order of ``cfg.experiments``.
    other : object
        What ``meanwhile`` returned (None without it).

    Raises
    ------
    WorkflowError, ValueError
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
    with ProcessPoolExecutor(workers, mp_context=fork_context()) as pool:
        futures = {pool.submit(_run_unobserved, cfg, name): name for name in names}
        progress.report(task, 0, len(names))
        if meanwhile is not None:
            other = meanwhile()
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
