"""Parameters of the bistable DE prototype (Table 1 and the geometry of Fig. 1) in SI units.

Interpretation of the printed values (see ``docs/interpretation.md``):

* **E** is in GPa, not MPa (docs/interpretation.md item 2). The bending energy carries the
  textbook factor 1/2 (item 3) and E = 2.1 GPa, the top of the PETG range quoted in the text;
  this is equivalent to the printed Eq. 9 without the 1/2 and E = 1.05 GPa. With Table 1's 1.62 GPa
  (and the 1/2) b = 23 mm is not switchable: E is the calibration knob together with b.
* **beta** = 1 and **V_DE** = n d_0 A_0 = 530.4 mm^3; neither is listed in Table 1 (item 4).
* **Damping**: Table 1 values Y_MW = 0.31 MPa, eta_MW = 83.5 kPa s, eta_v = 0.3 kPa s and
  eta = 3.64 MPa s (the text of Section 3.3 quotes eta_MW = 0.19 kPa s and Y_MW = 0.11 MPa
  as the initial values of the optimisation; Table 1 holds the optimised ones).
* **rho** = 1.2 g/cm^3 from Table 1 (the text quotes 1.27 g/cm^3 for raw PETG).
* The geometry follows item 1 (corrected Eq. 5); see :mod:`debist.physics.kinematics`.

References
----------
Masoud, A. & Maas, J. (2025). Data-driven modeling and identification of a bistable soft-robot
element based on dielectric elastomer. Front. Robot. AI 12. Table 1, Eq. 9, Eq. 11.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import pydantic
from pydantic import FiniteFloat, NonNegativeFloat, PositiveFloat

from debist.core.config import CONFIG, SectionConfig

__all__ = ["V_MAX", "PrototypeParams"]

V_MAX = 3.0e3
"""Maximum DE voltage of the prototype [V] (60 V/um on 50 um films, Section 2)."""


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class PrototypeParams(SectionConfig):
    """Geometry and material parameters of the bistable DE actuator, SI units.

    Each field is one key of the ``[physics]`` workflow section, documented under its
    declaration; what an asymmetry ``dz_1``, ``dz_2`` does: docs/explanation/implementation.md.

    Attributes
    ----------
    C_0 : float
        Capacitance of an undeformed DE [F] (Eq. 11).
    z_b : float
        Displacement parameter ``b_max - b`` [m] (Eq. 17).

    Raises
    ------
    pydantic.ValidationError
        If a value is not a finite number or is negative (zero where it must be positive;
        ``eta``, ``eta_v``, ``eta_MW``, ``Y_MW``, ``g``, ``e_x``, ``e_z``, ``a_0`` and
        ``m`` may be zero); ``dz_1`` and ``dz_2`` may have either sign. A ``ValueError``;
        :meth:`from_dict` and :meth:`replace` raise a ``WorkflowError`` naming the key.

    References
    ----------
    Masoud & Maas 2025, Table 1, Eq. 4, 5, 9, 11, 12; docs/interpretation.md items 1-4.

    Examples
    --------
    >>> p = PrototypeParams.paper()
    >>> round(p.V_DE * 1e9, 1)  # [mm^3]
    530.4
    >>> round(p.C_0 * 1e9, 2)  # [nF]
    5.26
    """

    SECTION: ClassVar[str] = "[physics]"

    epsilon_0: PositiveFloat = 8.854e-12
    """Vacuum permittivity [F/m]."""
    epsilon_r: PositiveFloat = 2.8
    """Relative permittivity of the elastomer [-]."""
    n: PositiveFloat = 8.0
    """Number of DE layers per actuator [-]."""
    d_0: PositiveFloat = 50e-6
    """Thickness of one layer, undeformed [m]."""
    l_0: PositiveFloat = 51e-3
    """Length of a DE strip, undeformed [m]."""
    A_0: PositiveFloat = 1326e-6
    """Area of one layer, undeformed [m^2]."""
    Y: PositiveFloat = 1.2e6
    """Neo-Hookean modulus of the DE (Eq. 11) [Pa]."""
    Y_MW: NonNegativeFloat = 0.31e6
    """Modulus of the Maxwell element (Eq. 12) [Pa]."""
    eta_MW: NonNegativeFloat = 83.5e3
    """Viscosity of the Maxwell element (Eq. 12) [Pa s]."""
    eta_v: NonNegativeFloat = 0.3e3
    """Kelvin-Voigt viscosity of the DE (Eq. 12) [Pa s]."""
    beta: PositiveFloat = 1.0
    """Electrode area / DE area (Eq. 11) [-] (docs/interpretation.md item 4)."""
    V_DE: PositiveFloat | None = None
    """Volume of one DE actuator [m^3]; None means n * d_0 * A_0 (docs/interpretation.md item 4).
    """
    l: PositiveFloat = 90e-3  # noqa: E741
    """Beam length [m]."""
    A: PositiveFloat = 11e-6
    """Beam cross-section [m^2]."""
    I: PositiveFloat = 1.1e-12  # noqa: E741
    """Second moment of area of the beam cross-section [m^4]."""
    E: PositiveFloat = 2.1e9
    """Young's modulus of the beam [Pa], with the 1/2 on the bending term (docs/interpretation.md
    items 2 and 3).
    """
    rho: PositiveFloat = 1.2e3
    """Density of the beam [kg/m^3]."""
    eta: NonNegativeFloat = 3.64e6
    """Viscosity of the beam (Eq. 12) [Pa s]."""
    a: PositiveFloat = 32e-3
    """Half width of the upper frame: horizontal offset of the DE upper ends from the beam tip [m].
    """
    b: PositiveFloat = 23e-3
    """Pre-strain screw position (Eq. 4); the DE upper ends sit b - a_0 below the tip [m]."""
    b_max: PositiveFloat = 30e-3
    """Reference screw position of Eq. 17, z_b = b_max - b [m]."""
    e_x: NonNegativeFloat = 7e-3
    """Height of the fixed DE ends above the beam clamp [m]."""
    e_z: NonNegativeFloat = 16e-3
    """Horizontal offset of the fixed DE ends from the beam axis [m]."""
    a_0: NonNegativeFloat = 11e-3
    """Vertical offset of the frame joint in Eq. 5 [m]."""
    m: NonNegativeFloat = 40e-3
    """Moving mass of the upper frame, lumped at the beam tip [kg]."""
    g: NonNegativeFloat = 9.81
    """Gravitational acceleration [m/s^2]."""
    dz_1: FiniteFloat = 0.0
    """Horizontal offset of DE 1's fixed end from -e_z, positive to the right [m]; 0: the symmetric
    prototype.
    """
    dz_2: FiniteFloat = 0.0
    """Horizontal offset of DE 2's fixed end from +e_z, positive to the right [m]."""

    def __post_init__(self) -> None:
        if self.V_DE is None:
            object.__setattr__(self, "V_DE", self.n * self.d_0 * self.A_0)

    @classmethod
    def paper(cls) -> PrototypeParams:
        """Return the prototype of the paper, read as docs/interpretation.md items 1-4.

        Returns
        -------
        PrototypeParams
            Table 1 in SI units with E = 2.1 GPa (1/2 on the bending term), beta = 1,
            V_DE = n d_0 A_0 and b = 23 mm.

        References
        ----------
        Masoud & Maas 2025, Table 1; docs/interpretation.md items 2-4.
        """
        return cls()

    def to_dict(self) -> dict[str, float]:
        """Return the parameters as a flat dict [SI], the inverse of :meth:`from_dict`.

        Returns
        -------
        dict[str, float]
            Field name -> value [SI].
        """
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def replace(self, **changes: float) -> PrototypeParams:
        """Return a copy with some parameters changed.

        Parameters
        ----------
        **changes : float
            Field name -> new value [SI].

        Returns
        -------
        PrototypeParams
            The modified copy. A ``V_DE`` derived as ``n d_0 A_0`` is derived again from the
            new values; an explicit ``V_DE`` is kept unless changed.

        Raises
        ------
        WorkflowError
            If a name is unknown or a value invalid.
        """
        base = self.to_dict()
        if "V_DE" not in changes and self.n * self.d_0 * self.A_0 == self.V_DE:
            base["V_DE"] = None  # type: ignore[assignment]
        return PrototypeParams.from_dict({**base, **changes})

    @property
    def C_0(self) -> float:
        """Capacitance of an undeformed DE, ``n eps_0 eps_r beta A_0 / d_0`` [F] (Eq. 11)."""
        return self.n * self.epsilon_0 * self.epsilon_r * self.beta * self.A_0 / self.d_0

    @property
    def z_b(self) -> float:
        """Displacement parameter ``z_b = b_max - b`` [m] (Eq. 17)."""
        return self.b_max - self.b
