"""The analytical model's parts in identification and validation: backbone curves, m_q, phi(q).

Pure functions: parameters and data in, results out. The stages that use the physics model
as a whole (the design analysis, the virtual rig) are :mod:`debist.stages.analyze` and
:mod:`debist.stages.rig`.

References
----------
Masoud & Maas 2025, Section 3 (analytical model), Eq. 24-26, Table 2.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

from debist.core.errors import WorkflowError
from debist.model.terms import PHYSICS_TERMS, PhysicsPrior
from debist.physics.freerun import analytical_model
from debist.physics.reduced import reduced_curves
from debist.physics.statics import force_displacement

if TYPE_CHECKING:  # types only: the identify stage must not depend on the validation code
    from debist.identify.fit import Record
    from debist.validate.config import ValidateConfig
    from debist.validate.freerun import DataSet

__all__ = ["analytical_for", "physics_mass", "physics_prior", "quadratic_force"]

#: Voltage levels of the second-order fit, as fractions of the largest recorded voltage.
_QUADRATIC_LEVELS = np.linspace(0.0, 1.0, 7)[1:]
#: Spacing of the continuation grid of the held-voltage force-displacement curves [m].
_QUADRATIC_STEP = 0.5e-3


def quadratic_force(physics, grid: np.ndarray, v_top: float) -> np.ndarray:
    """Second order ``g_h,i(q)`` of the full model's static DE force in ``h = v_i^2``.

    The force that holds the beam at ``q`` changes with DE i's voltage by ``Delta F_i(q; v) =
    F(q; 0) - F(q; v_i = v)`` (the force-displacement curves of Fig. 4). It is not the
    separable ``g_i(q) v^2`` of Eq. 26 and 37 with the small-signal gain ``g_i = 1/2 dC_i/dq``
    (the first order of ``Delta F_i`` in h, to 0.1 %): the DE's pull bends the beam off the v
    = 0 path. What the separable force lacks, ``Delta F_i - g_i h``, is fitted per ``q`` by
    least squares as ``g_h,i(q) h^2`` over six levels up to ``v_top``. On the paper's
    prototype (b = 23 mm, 0.5-3 kV) the two orders hold ``Delta F_i`` to 1.1 % of its largest
    value; ``g_i h`` alone is off by 17 %.

    Parameters
    ----------
    physics : PrototypeParams
        The prototype.
    grid : ndarray, shape (n,)
        Ascending positions [m] to tabulate at (computed on a 0.5 mm grid over their span,
        then interpolated by a cubic spline).
    v_top : float
        Largest voltage of the fit [V] (the estimation data's largest |v_i|).

    Returns
    -------
    ndarray, shape (n, 2)
        ``g_h,1(q), g_h,2(q)`` [N/V^4].

    Raises
    ------
    WorkflowError
        If ``v_top`` is not positive or a held-voltage path does not converge.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, 18, 26 and Fig. 4 (force-displacement at held voltages).
    """
    if not v_top > 0:
        raise WorkflowError(f"physics_quadratic needs a positive recorded voltage, got {v_top!r} V")
    n = int(np.ceil((grid[-1] - grid[0]) / _QUADRATIC_STEP)) + 1
    q = np.linspace(grid[0], grid[-1], max(n, 4))
    base = force_displacement(physics, q)
    cur = reduced_curves(physics, q)
    h = (v_top * _QUADRATIC_LEVELS) ** 2
    out = []
    for i, g in ((1, cur.g1), (2, cur.g2)):
        paths = [force_displacement(physics, q, **{f"v{i}": float(np.sqrt(x))}) for x in h]
        if not all(p.converged.all() for p in (base, *paths)):
            raise WorkflowError(
                f"physics_quadratic: the held-voltage force-displacement path of DE {i} did "
                f"not converge between {q[0]:.4g} and {q[-1]:.4g} m (up to {v_top:.4g} V)"
            )
        rest = np.stack([base.F - p.F - g * x for p, x in zip(paths, h, strict=True)])
        out.append(CubicSpline(q, (h**2 @ rest) / np.sum(h**4))(grid))
    return np.stack(out, axis=1)


def physics_prior(physics, records: Sequence[Record], n_grid: int = 2001, quadratic: bool = False):
    """Tabulate the analytical model's curves as the backbone of the RBF model.

    Parameters
    ----------
    physics : PrototypeParams
        The workflow's ``[physics]`` prototype.
    records : sequence of Record
        Estimation data (``q`` [m], ``v`` [V]); the grid covers them and at least +-25 mm.
    n_grid : int
        Grid points.
    quadratic : bool
        Also tabulate the large-signal DE force's second order (:func:`quadratic_force`,
        the backbone term ``physics_quadratic``) up to the records' largest |v_i|.

    Returns
    -------
    debist.model.terms.PhysicsPrior

    Raises
    ------
    WorkflowError
        If there is no ``[physics]`` section or the data have other than two inputs.

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26, 33.
    """
    if physics is None:
        raise WorkflowError(
            f"[identify] backbone terms {PHYSICS_TERMS} need a [physics] section (the prototype)"
        )
    if any(r.v.shape[1] != 2 for r in records):
        raise WorkflowError("[identify] physics_* terms need the two DE voltages v1, v2")
    q_max = max(25e-3, 1.2 * max(float(np.max(np.abs(r.q))) for r in records))
    grid = np.linspace(-q_max, q_max, n_grid)
    cur = reduced_curves(physics, grid)
    # the creep of Eq. 26: force k_bar k_i(q) q_eps,i, q_eps,i' = k_i q_dot - Y_MW/eta_MW q_eps,i
    k_bar = physics.V_DE * physics.Y_MW
    rate = physics.Y_MW / physics.eta_MW if physics.eta_MW > 0 else 0.0
    v_top = max(float(np.max(np.abs(r.v))) for r in records)
    return PhysicsPrior(
        q=grid, c=cur.c, d=cur.d, g=np.stack([cur.g1, cur.g2], axis=1),
        k=np.stack([cur.k1, cur.k2], axis=1), k_bar=float(k_bar), creep_rate=float(rate),
        gh=quadratic_force(physics, grid, v_top) if quadratic else None,
    )  # fmt: skip


def physics_mass(physics) -> float:
    """Generalised mass ``m_q`` of the analytical reduced model at ``q = 0`` [kg] (Eq. 26).

    Parameters
    ----------
    physics : PrototypeParams or None
        The workflow's ``[physics]`` prototype.

    Returns
    -------
    float
        ``Phi^T M Phi`` at ``q = 0`` [kg] (0.0402 kg for Table 1).

    Raises
    ------
    WorkflowError
        Without a ``[physics]`` section.

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (a constant m_q).
    """
    if physics is None:
        raise WorkflowError("[identify] m_q = 'physics' needs a [physics] section")
    return float(reduced_curves(physics, np.array([0.0])).m_q[0])


def analytical_for(physics, datasets: Sequence[DataSet], cfg: ValidateConfig):
    """Build the prototype's analytical reduced model, for ``phi(q)`` and its own row.

    Parameters
    ----------
    physics : PrototypeParams or None
        The ``[physics]`` parameters; None when the workflow has none.
    datasets : sequence of DataSet
        The data to validate on (``q`` must be in metres, two DE voltages).
    cfg : ValidateConfig
        ``analytical`` asks for the model's own row.

    Returns
    -------
    debist.physics.freerun.AnalyticalModel or None
        None without ``[physics]``.

    Raises
    ------
    WorkflowError
        If ``analytical = true`` without ``[physics]``, or the data are not a DE rig's
        (``q`` not in metres or not two inputs).

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26, Table 2.
    """
    if physics is None:
        if cfg.analytical:
            raise WorkflowError("[validate] analytical = true needs a [physics] section")
        return None
    for ds in datasets:
        if ds.q_unit != "m" or ds.v.shape[1] != 2:
            raise WorkflowError(
                f"[physics] describes a DE prototype (q [m], inputs v1, v2 [V]); data set "
                f"'{ds.name}' has q in {ds.q_unit!r} and {ds.v.shape[1]} input(s)"
            )

    return analytical_model(physics)
