"""The ``[rig]`` table: the experiments, the prototype and the plant of the virtual rig.

The configuration classes only (pydantic, see :class:`debist.core.config.SectionConfig`),
apart from :mod:`debist.rig.experiment` that runs them, so that checking a workflow does not
load the plant, the drivers and the recorder.

References
----------
Masoud & Maas 2025, Sec. 5.1 (the experiments and their profiles).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import field
from typing import Annotated, Any, Literal

import pydantic
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    NonNegativeFloat,
    NonNegativeInt,
    PositiveFloat,
)

from debist.core.config import CONFIG, AsTuple, ConfigValueError, config_from_section
from debist.core.errors import WorkflowError
from debist.physics.params import PrototypeParams
from debist.rig.params import RigParams
from debist.rig.profiles import PROFILES

__all__ = ["ExperimentConfig", "RigConfig"]


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
    ramps : tuple of float or None
        Ramp times of the identification profile's switching pulses [s], cycled
        (:func:`debist.rig.profiles.identification_profile`); default the profile's
        rectangular pulses. Other profiles reject it.
    frequency : float or None
        Tone frequency of the ``sine`` profile [Hz] (:func:`debist.rig.profiles.sine_profile`);
        default the profile's. Other profiles reject it.
    switching : bool or None
        The ``sine`` profile's antiphase tones on both DEs that switch the beam (true) or one
        tone inside the well (false, its default). Other profiles reject it.
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
    ramps: Annotated[tuple[NonNegativeFloat, ...] | None, AsTuple, Field(min_length=1)] = None
    frequency: PositiveFloat | None = None
    switching: bool | None = None
    format: Annotated[Literal["5", "7.3"], BeforeValidator(_format_str)] = "7.3"
    side: Annotated[int, AfterValidator(_side)] = -1

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ConfigValueError("profile", "one of " + ", ".join(PROFILES), self.profile)
        if self.ramps is not None and self.profile != "identification":
            raise ConfigValueError(
                "ramps", message=f"only the identification profile has ramps, not {self.profile!r}"
            )
        for key in ("frequency", "switching"):
            if getattr(self, key) is not None and self.profile != "sine":
                raise ConfigValueError(
                    key, message=f"only the sine profile has {key}, not {self.profile!r}"
                )

    def profile_kwargs(self) -> dict[str, Any]:
        """Return the keyword arguments of :func:`debist.rig.profiles.make_profile`.

        Returns
        -------
        dict
            ``duration`` and ``hold`` [s], and ``seed``, ``v_sub`` [V], ``ramps`` [s],
            ``frequency`` [Hz] and ``switching`` when given.
        """
        kwargs: dict[str, Any] = {"duration": self.duration, "hold": self.hold}
        if self.profile_seed is not None:
            kwargs["seed"] = self.profile_seed
        if self.v_sub is not None:
            kwargs["v_sub"] = self.v_sub
        if self.ramps is not None:
            kwargs["ramps"] = self.ramps
        for key in ("frequency", "switching"):
            if getattr(self, key) is not None:
                kwargs[key] = getattr(self, key)
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
            no experiments, or a ``sample_time`` longer than an experiment.

        Examples
        --------
        >>> RigConfig.from_dict({"experiments": {"a": {"seed": "1"}}}, {})
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [rig.experiments.a] seed: expected an integer, got '1'
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
        for name, exp in experiments.items():
            if head.sample_time > exp.duration:  # the log would hold no sample
                raise WorkflowError(
                    f"[rig] sample_time: expected at most the duration of [rig.experiments."
                    f"{name}] ({exp.duration:g} s), got {head.sample_time:g}",
                    key="rig.sample_time",
                    value=head.sample_time,
                )
        return cls(rig, head.sample_time, experiments)
