"""Fleets of virtual prototypes: seeded manufacturing scatter around the paper's prototype.

A lab builds several copies of the actuator; they differ in pre-strain, assembly and friction.
:func:`make_fleet` draws such copies around a nominal rig, keeping only those that still work
as the paper's actuator (bistable at 0 V, switched by one DE at 3 kV), checked directly on the
equilibria of each draw (:func:`is_bistable_and_switchable`). The bifurcation searches of
:mod:`debist.physics.prestrain` (``pitchfork_zb``, ``switching_limit_zb``) assume the mirror
symmetry of the paper's prototype, which the anchor offsets break, so they are not used here.

References
----------
Masoud & Maas 2025, Eq. 15, 17, Section 3.3.3, Fig. 3 (bistability and switching versus the
pre-strain).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping

import numpy as np

from debist.core.errors import DebistError, WorkflowError
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.statics import equilibria, switches
from debist.rig.params import RigParams

__all__ = [
    "DEFAULT_SCATTER",
    "FleetError",
    "fleet_members",
    "is_bistable_and_switchable",
    "make_fleet",
]

DEFAULT_SCATTER: Mapping[str, float] = {
    "b": 0.5e-3,
    "dz_1": 0.3e-3,
    "dz_2": 0.3e-3,
    "friction_F": 0.3,
    "friction_k": 0.0,
}
"""Default spreads of :func:`make_fleet`: standard deviations of the normal scatter of the
pre-strain screw position ``b`` and the anchor offsets ``dz_1``, ``dz_2`` [m] (assembly
tolerances of a 3D-printed frame), and the log-standard deviations [-] of the lognormal
scatter of the friction elements' slip forces and stiffnesses (each element independently,
median = nominal; 0.3 is about +-30 %)."""


class FleetError(DebistError, RuntimeError):
    """No acceptable prototype was found within the allowed number of draws."""


def is_bistable_and_switchable(
    rig: RigParams,
    *,
    v_switch: float = 0.95 * V_MAX,
    force_margin: float | None = None,
) -> bool:
    """Whether a rig's prototype works as the paper's actuator, with margins.

    Four equilibrium problems (Eq. 15, :func:`debist.physics.statics.equilibria`):

    1. at v = 0 with a tip force ``+force_margin`` pushing right, a stable equilibrium with
       ``q < 0`` exists (the left well holds against friction), and
    2. with ``-force_margin`` a stable one with ``q > 0`` (the right well holds): bistable;
    3. with ``v_switch`` on DE 1 every stable equilibrium has ``q > 0`` (the left well is
       gone: a pulse switches to the right), and
    4. with ``v_switch`` on DE 2 every stable equilibrium has ``q < 0``.

    Parameters
    ----------
    rig : RigParams
        The rig (uses ``prototype`` and, for the default margin, the friction).
    v_switch : float
        Voltage that must switch the prototype [V]; default 95 % of 3 kV, so that 3 kV
        switches with a force margin of about 10 % of the electrostatic force (well above
        the friction) and the driver lag does not matter.
    force_margin : float, optional
        Tip force the wells must withstand [N]; default twice the breakaway force of the
        rig's friction, so friction cannot hold the beam on the barrier.

    Returns
    -------
    bool
        True if all four conditions hold.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.3-3.3.4.
    """
    p = rig.prototype
    F = 2.0 * rig.breakaway_force if force_margin is None else float(force_margin)
    left = [e for e in equilibria(p, F=F) if e.stable and e.q < 0]
    if not left:
        return False
    right = [e for e in equilibria(p, F=-F) if e.stable and e.q > 0]
    if not right:
        return False
    return switches(p, 1, v_switch) and switches(p, 2, v_switch)


def _draw(rng: np.random.Generator, nominal: RigParams, spread: Mapping[str, float]) -> RigParams:
    """One candidate: normal b, dz_1, dz_2; lognormal friction (fixed order of draws)."""
    p0 = nominal.prototype
    b = p0.b + spread["b"] * rng.standard_normal()
    dz_1 = p0.dz_1 + spread["dz_1"] * rng.standard_normal()
    dz_2 = p0.dz_2 + spread["dz_2"] * rng.standard_normal()
    n = nominal.n_friction
    F = np.array(nominal.friction_F) * np.exp(spread["friction_F"] * rng.standard_normal(n))
    k = np.array(nominal.friction_k) * np.exp(spread["friction_k"] * rng.standard_normal(n))
    proto = p0.replace(b=b, dz_1=dz_1, dz_2=dz_2)
    return nominal.replace(
        prototype=proto, friction_F=tuple(F.tolist()), friction_k=tuple(k.tolist())
    )


def make_fleet(
    n: int,
    *,
    seed: int,
    nominal: RigParams | None = None,
    scatter: Mapping[str, float] | None = None,
    max_draws: int = 200,
) -> list[RigParams]:
    """Draw ``n`` prototypes scattered around a nominal rig, all bistable and switchable.

    Each member draws from ``numpy.random.default_rng(seed)``: the pre-strain ``b`` and the
    anchor offsets ``dz_1``, ``dz_2`` (normal), then the friction elements' slip forces and
    stiffnesses (lognormal, median = nominal). A draw that fails
    :func:`is_bistable_and_switchable` is redrawn. The first ``m`` members do not depend on ``n``.

    Parameters
    ----------
    n : int
        Number of prototypes (>= 0).
    seed : int
        Seed of the scatter.
    nominal : RigParams, optional
        Centre of the scatter; default the paper's symmetric prototype (b = 23 mm) on the
        default rig.
    scatter : Mapping[str, float], optional
        Spreads overriding :data:`DEFAULT_SCATTER`: ``"b"``, ``"dz_1"``, ``"dz_2"`` [m],
        ``"friction_F"``, ``"friction_k"`` (log-standard deviations [-]); 0 disables one.
    max_draws : int
        Draws per member before giving up.

    Returns
    -------
    list of RigParams
        The fleet, ``n`` members.

    Raises
    ------
    WorkflowError
        If ``n`` is negative or not an integer, a scatter name is unknown or a spread invalid.
    FleetError
        If a member is not found within ``max_draws`` draws.

    References
    ----------
    Masoud & Maas 2025, Table 1, Eq. 15, 17, Fig. 3.
    """
    return list(fleet_members(n, seed=seed, nominal=nominal, scatter=scatter, max_draws=max_draws))


def fleet_members(
    n: int | None = None,
    *,
    seed: int,
    nominal: RigParams | None = None,
    scatter: Mapping[str, float] | None = None,
    max_draws: int = 200,
) -> Iterator[RigParams]:
    """Draw the prototypes of :func:`make_fleet` one at a time, each when it is asked for.

    The scatter is checked at the call; each member is drawn (and redrawn until it passes
    :func:`is_bistable_and_switchable`) only when the iterator reaches it, so a caller that
    needs fewer members than it might pays only for those. Member ``i`` is
    ``make_fleet(n, ...)[i]`` for every ``n > i``.

    Parameters
    ----------
    n : int, optional
        Number of members (>= 0); without it the iterator has no end.
    seed, nominal, scatter, max_draws
        As :func:`make_fleet`.

    Returns
    -------
    iterator of RigParams
        The fleet's members in order.

    Raises
    ------
    WorkflowError
        At the call, if ``n`` is negative or not an integer, for an unknown scatter name or
        an invalid spread.
    FleetError
        When the iterator reaches a member not found within ``max_draws`` draws.

    References
    ----------
    Masoud & Maas 2025, Table 1, Eq. 15, 17, Fig. 3.
    """
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 0):
        raise WorkflowError(f"`n` must be a non-negative integer, got {n!r}")
    spread = dict(DEFAULT_SCATTER)
    for key, value in (scatter or {}).items():
        if key not in DEFAULT_SCATTER:
            raise WorkflowError(f"unknown scatter '{key}'; known: {', '.join(DEFAULT_SCATTER)}")
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not (math.isfinite(value) and value >= 0)
        ):
            raise WorkflowError(f"scatter '{key}' must be a finite number >= 0, got {value!r}")
        spread[key] = float(value)
    if nominal is None:
        nominal = RigParams(prototype=PrototypeParams.paper())
    members = _members(np.random.default_rng(seed), nominal, spread, seed, max_draws)
    return members if n is None else itertools.islice(members, n)


def _members(rng, nominal, spread, seed, max_draws) -> Iterator[RigParams]:
    """Yield the screened draws of :func:`fleet_members`."""
    for i in itertools.count():
        for _ in range(max_draws):
            candidate = _draw(rng, nominal, spread)
            if is_bistable_and_switchable(candidate):
                yield candidate
                break
        else:
            raise FleetError(
                f"make_fleet: no bistable, switchable prototype in {max_draws} draws for "
                f"member {i} (seed {seed}, scatter {spread})"
            )
