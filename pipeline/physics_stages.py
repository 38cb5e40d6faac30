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

from debist.errors import WorkflowError
from debist.model.terms import PHYSICS_TERMS, PhysicsPrior
from debist.physics.freerun import analytical_model
from debist.physics.reduced import reduced_curves

if TYPE_CHECKING:  # types only: the identify stage must not depend on the validation code
    from debist.identify.fit import Record
    from debist.validate import DataSet, ValidateConfig

__all__ = ["analytical_for", "physics_mass", "physics_prior"]


def physics_prior(physics, records: Sequence[Record], n_grid: int = 2001):
    """Tabulate the analytical model's curves as the backbone of the RBF model.

    Parameters
    ----------
    physics : PrototypeParams
        The workflow's ``[physics]`` prototype.
    records : sequence of Record
        Estimation data (``q`` [m]); the grid covers them and at least +-25 mm.
    n_grid : int
        Grid points.

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
    return PhysicsPrior(
        q=grid, c=cur.c, d=cur.d, g=np.stack([cur.g1, cur.g2], axis=1),
        k=np.stack([cur.k1, cur.k2], axis=1), k_bar=float(k_bar), creep_rate=float(rate),
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
