"""Parameters of the virtual rig: the simulated prototype, its friction, drivers and sensors.

References
----------
Masoud & Maas 2025, Table 1, Sec. 5.1; Al-Bender, Lampaert & Swevers 2005 (GMS friction).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import field
from typing import Annotated, ClassVar, Literal

import pydantic
from pydantic import Field, FiniteFloat, NonNegativeFloat, PositiveFloat, PositiveInt

from debist.core.config import (
    CONFIG,
    AsTuple,
    ConfigValueError,
    SectionConfig,
)
from debist.physics.params import PrototypeParams

__all__ = ["RigParams"]


def _default_prototype() -> PrototypeParams:
    return PrototypeParams.paper().replace(dz_1=0.15e-3, dz_2=0.05e-3)


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class RigParams(SectionConfig):
    """The simulated prototype and the rig around it, SI units.

    Raises
    ------
    pydantic.ValidationError
        If a value is of the wrong type, not finite or out of range, or the friction tuples
        differ in length (a ``ValueError``; :meth:`from_dict` and :meth:`replace` raise a
        ``WorkflowError`` naming the key).

    Notes
    -----
    Each field is one key of the ``[rig]`` workflow section, documented under its declaration.
    Where the defaults come from: docs/explanation/calibration.md.

    References
    ----------
    Masoud & Maas 2025, Table 1, Sec. 5.1, Eq. 19-26, 37; Al-Bender, Lampaert & Swevers
    2005 (GMS).

    Examples
    --------
    >>> rig = RigParams()
    >>> round(rig.breakaway_force * 1e3, 3)  # [mN]
    2.0
    >>> RigParams.from_dict(rig.to_dict()) == rig
    True
    """

    SECTION: ClassVar[str] = "[rig.plant]"

    prototype: PrototypeParams = field(default_factory=_default_prototype)
    """The physics of the prototype (Table 1, docs/interpretation.md items 1-6) with its asymmetry;
    default the paper's prototype with dz_1 = 0.15 mm, dz_2 = 0.05 mm.
    """
    model: Literal["full", "reduced"] = "full"
    """The plant's mechanics: "full", the model of Sec. 3 (Eq. 19-23), or "reduced", the
    one-coordinate model of Eq. 24-26, exact in the form of Eq. 37.
    """
    friction_k: Annotated[tuple[PositiveFloat, ...], AsTuple] = (40.0, 12.0, 4.0)
    """Stiffnesses k_i of the Maxwell-slip elements at the beam tip [N/m]."""
    friction_F: Annotated[tuple[PositiveFloat, ...], AsTuple] = (0.4e-3, 0.6e-3, 1.0e-3)
    """Slip forces F_i of the elements [N]."""
    friction_c: NonNegativeFloat = 0.0
    """Viscous part of the tip friction [N s/m] (the model's own damping, Eq. 12, is in the
    prototype).
    """
    friction_exponent: Annotated[float, Field(ge=1)] = 4.0
    """Sharpness p of the regularised stick-slip transition (>= 1; large: ideal elasto-plastic
    elements).
    """
    driver_tau: PositiveFloat = 5e-3
    """Time constant of the first-order lag of each HV driver [s]."""
    driver_slew: PositiveFloat = 100e3
    """Slew-rate limit of each HV driver [V/s]."""
    sensor_range: PositiveFloat = 25e-3
    """Measuring range of the laser sensor, +-sensor_range about q = 0 [m]."""
    sensor_resolution: NonNegativeFloat = 0.3e-6
    """Quantisation step of the laser sensor [m]; 0: none."""
    sensor_noise: NonNegativeFloat = 1e-6
    """RMS of the white noise of one internal laser sample [m]."""
    monitor_noise: NonNegativeFloat = 2.0
    """RMS of the white noise of one internal sample of the voltage monitors [V]."""
    oversample: PositiveInt = 10
    """Internal samples per log sample (sensors and plant output)."""
    gain_1: Annotated[float, Field(gt=0, le=10)] = 1.0
    """Electrostatic gain of DE 1 against the prototype's [-] (its force at the same voltage).
    """
    gain_2: Annotated[float, Field(gt=0, le=10)] = 1.0
    """Electrostatic gain of DE 2 against the prototype's [-]."""
    force_offset: FiniteFloat = 0.0
    """Constant horizontal force on the tip [N], positive towards +q."""
    sensor_offset: FiniteFloat = 0.0
    """Zero offset of the laser [m]: it reads q + sensor_offset."""
    sensor_average: Annotated[int, Field(ge=0, le=1000)] = 0
    """0: anti-aliasing FIR and decimation; N >= 1: the trailing mean of the laser's last N
    internal samples, the monitors point-sampled.
    """
    sensor_lag: NonNegativeFloat = 0.0
    """Time constant of a first-order lag of the laser's output [s]; 0: none."""

    def __post_init__(self) -> None:
        if self.sensor_average > 10 * self.oversample:
            raise ConfigValueError(
                "sensor_average", f"at most 10 oversample ({10 * self.oversample})",
                self.sensor_average,
            )  # fmt: skip
        if len(self.friction_k) != len(self.friction_F):
            raise ConfigValueError(
                "friction_F",
                f"as many values as friction_k ({len(self.friction_k)})",
                list(self.friction_F),
            )

    @property
    def n_friction(self) -> int:
        """Number of Maxwell-slip elements."""
        return len(self.friction_k)

    @property
    def breakaway_force(self) -> float:
        """Total slip force ``sum F_i`` [N] (the Coulomb level of gross sliding)."""
        return float(sum(self.friction_F))

    @classmethod
    def from_dict(cls, section: Mapping[str, object], where: str | None = None) -> RigParams:
        """Build rig parameters from a workflow section (e.g. the ``[rig.plant]`` table).

        Parameters
        ----------
        section : Mapping[str, object]
            Field name -> value [SI]; ``prototype`` is a nested table of
            :class:`PrototypeParams` keys (missing keys keep the paper's values, a missing
            table the default asymmetric prototype) or a :class:`PrototypeParams`;
            friction tuples may be lists.
        where : str, optional
            The workflow table, for the messages (default ``[rig.plant]``).

        Returns
        -------
        RigParams
            The parameters; keys not given keep their defaults.

        Raises
        ------
        WorkflowError
            If a key is unknown (with a suggestion) or a value invalid:
            ``[rig.plant] key: expected ..., got ...``.

        Examples
        --------
        >>> RigParams.from_dict({"oversample": 2.5})
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [rig.plant] oversample: expected an integer, got 2.5
        """
        where = cls.SECTION if where is None else where
        if isinstance(section, Mapping) and isinstance(section.get("prototype"), Mapping):
            proto = PrototypeParams.from_dict(section["prototype"], f"{where[:-1]}.prototype]")
            section = {**section, "prototype": proto}
        return super().from_dict(section, where)

    def to_dict(self) -> dict[str, object]:
        """Return the parameters as nested plain data [SI], the inverse of :meth:`from_dict`.

        Returns
        -------
        dict[str, object]
            Field name -> value; ``prototype`` as a dict, the friction tuples as lists,
            ``model`` as a string.
        """
        out: dict[str, object] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "prototype":
                value = value.to_dict()
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        return out

    def replace(self, **changes: object) -> RigParams:
        """Return a copy with some fields changed (validated like the constructor).

        Parameters
        ----------
        **changes : object
            Field name -> new value.

        Returns
        -------
        RigParams
            The modified copy.

        Raises
        ------
        WorkflowError
            If a name is unknown or a value invalid.
        """
        current = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return RigParams.from_dict({**current, **changes})
