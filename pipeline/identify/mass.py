"""The apparent mass of Eq. 37's lagged damping, and the scale that makes the mass physical.

The friction state of Eq. 37 lags the velocity, ``z' = (q_dot - z) / T_z``. At an angular
frequency omega the damping term is then

    d z = d / (1 + (omega T_z)^2) q_dot  -  d T_z / (1 + (omega T_z)^2) q_ddot,

damping *and* an apparent mass ``-d T_z / (1 + (omega T_z)^2)``. With m_q fixed at the physical
mass, a fit whose data ask for the lag identifies a model whose effective mass near the wells,
``lambda m_q`` with

    lambda = 1 - d(q*) T_z / ((1 + (omega_n T_z)^2) m_q),    omega_n = sqrt(k* / m_q),

is below m_q, and since only the ratios of mass, forces and gains shape the motion, every force
curve comes out scaled by about the same lambda. Multiplying the mass and every weight by
1 / lambda (:meth:`debist.model.rbf.RBFModel.scaled`) leaves every free run unchanged (lambda is
invariant under it) and puts the curves back on the physical scale: the effective mass at the
wells' natural frequency is then m_q. What it does on the virtual rig: docs/explanation/trust.md.

References
----------
Masoud & Maas 2025, Eq. 37 (the friction state z and the fixed m_q); the first-order lag's
frequency response: Ljung, *System Identification*, 2nd ed. (1999), Sec. 2.1.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from debist.identify.stability import equilibria

__all__ = ["EffectiveMass", "effective_mass", "effective_mass_ratio"]


@dataclass(frozen=True)
class EffectiveMass:
    """The effective-mass ratio of an identified model and whether it was applied.

    Attributes
    ----------
    ratio : float
        lambda, the mean over the wells at rest [-] (1 without a lag or without a well).
    wells : tuple of float
        Each well's q* [unit of q].
    ratios : tuple of float
        Each well's lambda [-].
    applied : bool
        Whether the model was rescaled by 1 / lambda.
    reason : str
        Why not, when it was not ("" when applied).
    """

    ratio: float
    wells: tuple[float, ...]
    ratios: tuple[float, ...]
    applied: bool
    reason: str

    def to_summary(self) -> dict:
        """Return the fields as a JSON-able dict."""
        return {
            "ratio": self.ratio,
            "wells": list(self.wells),
            "ratios": list(self.ratios),
            "applied": self.applied,
            "reason": self.reason,
        }


def effective_mass_ratio(model) -> tuple[float, tuple[float, ...], tuple[float, ...]]:
    """Return the effective-mass ratio lambda of each well at rest, and their mean.

    Parameters
    ----------
    model : RBFModel
        An identified model; ``T_z`` [s], the damping curve ``d`` [N s/unit of q] and the
        wells' k* [N/unit of q] and m_q [kg] (:func:`~debist.identify.stability.equilibria`).

    Returns
    -------
    ratio : float
        The mean lambda over the wells [-]; 1.0 when ``T_z = 0`` or the model has no well at
        rest.
    wells : tuple of float
        q* of each well at rest [unit of q].
    ratios : tuple of float
        lambda of each well [-].

    References
    ----------
    Masoud & Maas 2025, Eq. 37.
    """
    if not model.T_z > 0:
        return 1.0, (), ()
    wells = [p for p in equilibria(model) if p.level == 0 and p.static_stable]
    ratios = tuple(
        1.0 - p.d * model.T_z / ((1.0 + (2.0 * np.pi * p.f_n * model.T_z) ** 2) * p.m_q)
        for p in wells
    )
    if not ratios:
        return 1.0, (), ()
    return float(np.mean(ratios)), tuple(p.q for p in wells), ratios


def effective_mass(model, diagnostics):
    """Rescale an identified model so that its effective mass at the wells is m_q.

    Parameters
    ----------
    model : RBFModel
        The least-squares model (``m_q`` a mass, not identified).
    diagnostics : FitDiagnostics
        Its diagnostics; ``theta``, ``theta_boot``, ``residual_rms`` and ``y_norm`` are scaled
        with it (the least squares with ``m_q / lambda`` on the output has exactly these).

    Returns
    -------
    model : RBFModel
        ``model.scaled(1 / lambda)``, or ``model`` where not applied.
    diagnostics : FitDiagnostics
        Scaled the same way.
    info : EffectiveMass
        lambda per well and whether it was applied: not without a lag (``T_z = 0``), without a
        well at rest, or when lambda is not in (0, 1] (a lag whose apparent mass exceeds m_q,
        or a negative damping at a well: then the model is reported as it was fitted).

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40.
    """
    ratio, wells, ratios = effective_mass_ratio(model)
    if not wells:
        reason = "T_z = 0: no lag" if not model.T_z > 0 else "no well at rest"
        return model, diagnostics, EffectiveMass(1.0, (), (), False, reason)
    if not 0.0 < ratio <= 1.0:
        reason = f"lambda = {ratio:.3g} is not in (0, 1]"
        return model, diagnostics, EffectiveMass(ratio, wells, ratios, False, reason)
    s = 1.0 / ratio
    boot = diagnostics.theta_boot
    diagnostics = replace(
        diagnostics,
        theta=diagnostics.theta * s,
        theta_boot=None if boot is None else boot * s,
        residual_rms=diagnostics.residual_rms * s,
        y_norm=diagnostics.y_norm * s,
    )
    return model.scaled(s), diagnostics, EffectiveMass(ratio, wells, ratios, True, "")
