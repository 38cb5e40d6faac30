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

    Parameters
    ----------
    prototype : PrototypeParams
        The physics of the prototype (Table 1 read as docs/interpretation.md items 1-6) with its
        asymmetry;
        default the paper's prototype at b = 23 mm with ``dz_1 = 0.15 mm``,
        ``dz_2 = 0.05 mm`` (assembly tolerance of a 3D-printed frame; wells at -9.50 and
        +10.99 mm, still switchable by 3 kV on either DE).
    model : {"full", "reduced"}
        The mechanics of the plant: ``"full"`` (default) the full model of Sec. 3
        (:class:`debist.rig.plant.RigPlant`, Eq. 19-23), whose DE force is not of the
        separable form ``g_i(q) v_i^2`` of Eq. 37; ``"reduced"`` the reduced one-coordinate
        model of Eq. 24-26 of the same prototype (:class:`debist.rig.reduced.ReducedPlant`),
        whose true curves ``f(q)``, ``d(q)``, ``g_i(q)`` are exactly those of Eq. 37. Both
        have the same friction, drivers and sensors.
    friction_k : tuple of float
        Stiffnesses ``k_i`` of the Maxwell-slip elements at the beam tip [N/m]; default
        (40, 12, 4) N/m: pre-sliding distances ``F_i / k_i`` of 10, 50 and 250 um, a tangent
        stiffness after a reversal of 56 N/m against the 13 N/m of the wells.
    friction_F : tuple of float
        Slip forces ``F_i`` of the elements [N]; default (0.4, 0.6, 1.0) mN, a breakaway
        force of 2 mN: 2 % of the +-80 mN force span over +-15 mm of Fig. 4 and 6 % of the
        36 mN barrier, so friction perturbs the model without changing its switching. The
        paper does not quantify friction; these are plausible values for a rubbing frame.
    friction_c : float
        Viscous part of the tip friction [N s/m]; 0 by default (the model's own damping,
        Eq. 12, is in the prototype).
    friction_exponent : float
        Sharpness ``p`` of the regularised stick-slip transition (>= 1; large = ideal
        elasto-plastic elements, see :class:`RigPlant`).
    driver_tau : float
        Time constant of the first-order lag of each HV driver [s]; default 5 ms.
    driver_slew : float
        Slew-rate limit of each HV driver [V/s]; default 100 kV/s (30 ms for 0 -> 3 kV).
    sensor_range : float
        Measuring range of the laser sensor, ``+-sensor_range`` about q = 0 [m]; default
        25 mm.
    sensor_resolution : float
        Quantisation step of the laser sensor [m]; default 0.3 um; 0 disables quantisation.
    sensor_noise : float
        RMS of the white noise of one internal laser sample [m]; default 1 um. The FIR of
        the decimation removes the part above the log's Nyquist frequency, so the logged
        noise is about ``sensor_noise / sqrt(oversample)``.
    monitor_noise : float
        RMS of the white noise of one internal sample of the voltage monitors [V]; default
        2 V (0.07 % of 3 kV).
    oversample : int
        Internal samples per log sample (sensors and plant output on the grid
        ``sample_time / oversample``); default 10.
    gain_1, gain_2 : float
        Electrostatic gain of DE 1 and DE 2 against the prototype's [-]: the DE force is
        ``gain_i`` times the prototype's at the same voltage (a membrane whose permittivity or
        electrode area differs by that factor); default 1.
    force_offset : float
        Constant horizontal force on the tip [N], positive towards +q (a tilted mount, a
        cable); default 0.
    sensor_offset : float
        Zero offset of the laser [m]: it reads ``q + sensor_offset`` (the range is about its
        own zero); default 0.
    sensor_average : int
        0 (default): the laser and the monitors are decimated by a zero-phase FIR (the rig's
        anti-aliasing). ``N >= 1``: the logger stores the trailing mean of the laser's last
        ``N`` internal samples (a moving-average FIR with a group delay of ``(N - 1) / 2``
        internal samples) and the monitors' values at the log instants (point samples).
    sensor_lag : float
        Time constant of a first-order lag of the laser's output [s], applied on the internal
        grid before the logger; default 0 (none).

    Raises
    ------
    pydantic.ValidationError
        If a value is of the wrong type, not finite or out of range, or the friction tuples
        differ in length (a ``ValueError``; :meth:`from_dict` and :meth:`replace` raise a
        ``WorkflowError`` naming the key).

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
    model: Literal["full", "reduced"] = "full"
    friction_k: Annotated[tuple[PositiveFloat, ...], AsTuple] = (40.0, 12.0, 4.0)
    friction_F: Annotated[tuple[PositiveFloat, ...], AsTuple] = (0.4e-3, 0.6e-3, 1.0e-3)
    friction_c: NonNegativeFloat = 0.0
    friction_exponent: Annotated[float, Field(ge=1)] = 4.0
    driver_tau: PositiveFloat = 5e-3
    driver_slew: PositiveFloat = 100e3
    sensor_range: PositiveFloat = 25e-3
    sensor_resolution: NonNegativeFloat = 0.3e-6
    sensor_noise: NonNegativeFloat = 1e-6
    monitor_noise: NonNegativeFloat = 2.0
    oversample: PositiveInt = 10
    gain_1: Annotated[float, Field(gt=0, le=10)] = 1.0
    gain_2: Annotated[float, Field(gt=0, le=10)] = 1.0
    force_offset: FiniteFloat = 0.0
    sensor_offset: FiniteFloat = 0.0
    sensor_average: Annotated[int, Field(ge=0, le=1000)] = 0
    sensor_lag: NonNegativeFloat = 0.0

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
