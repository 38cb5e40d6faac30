"""Design numbers of an identified model beside the analytical model's (the identify stage's).

The equilibria of the identified model at rest and at the constant input levels the data
hold, their stability, small-signal frequency and damping, the barriers and the static
switching voltages (:mod:`debist.identify.stability`), and, with a ``[physics]``
prototype, the same numbers of the analytical model, which is what a designer compares.

References
----------
Masoud & Maas 2025, Eq. 26, 37, Sec. 3.3 (equilibria and switching), Fig. 4.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.identify.physics_prior import physics_mass, physics_prior
from debist.identify.stability import stability_table, switching_voltages
from debist.model.rbf import RBFModel
from debist.model.terms import PhysicsPrior
from debist.physics.params import V_MAX

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")


def _level_step(records: Sequence[Any], resolution: float) -> float:
    """Input resolution of a level [V]: ``resolution`` times the largest input in the data."""
    return resolution * (max(float(np.max(np.abs(r.v))) for r in records) or 1.0)


def _level_keys(v: np.ndarray, step: float) -> np.ndarray:
    """Integer level of every sample's input vector (n, n_inputs) at resolution ``step``."""
    return np.round(np.asarray(v, dtype=float) / step).astype(np.int64)


def at_level(
    records: Sequence[Any], level: Sequence[float], *, resolution: float = 0.02
) -> np.ndarray:
    """Mark the samples whose inputs are at a level, as :func:`held_levels` groups them.

    Parameters
    ----------
    records : sequence of Record
        Estimation records (``v`` (n, n_inputs) [V]).
    level : sequence of float, shape (n_inputs,)
        Input vector [V] (one of :func:`held_levels`).
    resolution : float
        Inputs within this fraction of their largest value count as one level.

    Returns
    -------
    ndarray of bool, shape (sum of n,)
        Per sample of the concatenated records.
    """
    step = _level_step(records, resolution)
    key = _level_keys(np.asarray(level, dtype=float)[None, :], step)[0]
    return np.concatenate([np.all(_level_keys(r.v, step) == key, axis=1) for r in records])


def held_levels(
    records: Sequence[Any],
    *,
    hold: float = 0.25,
    resolution: float = 0.02,
    max_levels: int = 4,
) -> list[tuple[float, ...]]:
    """Constant input levels the data hold long enough for the beam to settle.

    Parameters
    ----------
    records : sequence of Record
        Estimation records (``v`` (n, n_inputs) [V], ``dt`` [s]).
    hold : float
        Shortest hold [s].
    resolution : float
        Inputs within this fraction of their largest value count as one level.
    max_levels : int
        Most levels returned (those held longest first).

    Returns
    -------
    list of tuple of float
        Input vectors [V] other than all-zero (the rest level is always analysed), rounded
        to the resolution.
    """
    step = _level_step(records, resolution)
    held: dict[tuple[float, ...], float] = {}
    for r in records:
        key = _level_keys(r.v, step)
        change = np.flatnonzero(np.any(np.diff(key, axis=0) != 0, axis=1)) + 1
        starts = np.concatenate([[0], change])
        ends = np.concatenate([change, [key.shape[0]]])
        # only the runs long enough enter the loop (a noise input changes level every sample)
        long = ((ends - starts) * r.dt >= hold) & np.any(key[starts] != 0, axis=1)
        for s, e in zip(starts[long], ends[long], strict=True):
            level = tuple(float(x) for x in key[s] * step)
            held[level] = held.get(level, 0.0) + (e - s) * r.dt
    ordered = sorted(held, key=lambda k: -held[k])
    return ordered[:max_levels]


def design_numbers(
    model, records: Sequence[Any], physics=None, mass: float | None = None
) -> dict[str, pd.DataFrame]:
    """Equilibria, verdict and switching voltages of the identified (and analytical) model.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    records : sequence of Record
        The estimation records (visited range, held levels, largest voltage).
    physics : PrototypeParams, optional
        The ``[physics]`` prototype: adds the analytical model's rows, from its reduced
        model in the form of Eq. 37 (:func:`analytical_as_eq37`; the full model's numbers
        are ``debist analyze``'s).
    mass : float, optional
        The mass the identified forces refer to [kg] (default ``model.m_q``; with the
        effective-mass scale of :mod:`debist.identify.mass` the effective mass at the wells),
        to which the analytical rows are scaled.

    Returns
    -------
    dict of str to pandas.DataFrame
        ``equilibria``: :func:`~debist.identify.stability.stability_table` rows with a
        ``model`` column (``"rbf"``, and ``"analytical"`` with ``physics``), the verdict in
        ``attrs``; ``switching``: the switching voltages, same ``model`` column (the
        identified model's up to the largest voltage in the data, the analytical model's up
        to the drivers' ``V_MAX``).

    References
    ----------
    Masoud & Maas 2025, Sec. 3.3, Eq. 37.
    """
    q = np.concatenate([r.q for r in records])
    levels = held_levels(records)
    eq = stability_table(model, levels, visited=[(float(q.min()), float(q.max()))])
    verdict = (eq.attrs["verdict"], eq.attrs["reason"])
    v_max = max(float(np.max(np.abs(r.v))) for r in records)
    sw = switching_voltages(model, v_max=v_max)
    eq.insert(0, "model", "rbf")
    sw.insert(0, "model", "rbf")
    if physics is not None and model.n_inputs == 2 and model.input_map == "v2":
        reduced = analytical_as_eq37(physics, records, model, mass)
        ana = stability_table(reduced, levels)
        ana.insert(0, "model", "analytical")
        ana_sw = switching_voltages(reduced, v_max=max(v_max, V_MAX))
        ana_sw.insert(0, "model", "analytical")
        eq = pd.concat([eq, ana], ignore_index=True)
        sw = pd.concat([sw, ana_sw], ignore_index=True)
    eq.attrs["verdict"], eq.attrs["reason"] = verdict
    return {"equilibria": eq, "switching": sw}


def analytical_as_eq37(physics, records: Sequence[Any], model, mass: float | None = None):
    """Write the analytical reduced model as an identified model (Eq. 37 form, Eq. 26 curves).

    Zero RBF weights and the physics backbone at scale one: ``f = c_phys(q) q``,
    ``d = d_phys(q)``, ``g_i = g_phys,i(q)``, all times ``m_q / m_q,phys(0)`` so that the
    numbers are in the identified model's units (``m_q = 1`` identifies per unit mass).
    The stability functions then apply to both models alike.

    Parameters
    ----------
    physics : PrototypeParams
        The prototype.
    records : sequence of Record
        The estimation records (range of the tabulation).
    model : RBFModel
        The identified model (basis, range, ``m_q``).
    mass : float, optional
        The mass the identified forces refer to [kg]; default ``model.m_q`` (see
        :func:`design_numbers`).

    Returns
    -------
    RBFModel

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26, 33, 37.
    """
    prior = physics_prior(physics, records, n_grid=801)
    m_q = model.m_q if mass is None else float(mass)
    scale = m_q / physics_mass(physics)
    prior = PhysicsPrior(q=prior.q, c=scale * prior.c, d=scale * prior.d, g=scale * prior.g)
    zeros = np.zeros(model.basis.M)
    backbone = {"s_c": 1.0, "s_d": 1.0, "s_g": np.ones(2), "g_0": np.zeros(2)}
    return RBFModel(
        model.basis, "v2", 2, m_q, 0.0, model.coulomb_velocity, zeros, zeros,
        np.zeros((2, model.basis.M)), backbone, model.q_range, prior,
    )  # fmt: skip


def mark_identified(
    equilibria: pd.DataFrame, curves: pd.DataFrame, static: pd.DataFrame
) -> pd.DataFrame:
    """Say of each equilibrium of the identified model whether the data support it.

    An equilibrium ``q*`` at rest lies where the restoring force ``c(q) q + F_0`` crosses
    zero; it is a result of the data only where that curve is identified (its
    ``restoring_identified`` mask of :func:`debist.identify.bands.curves_frame`). At a
    held input level the static force of that level (:func:`debist.identify.bands.
    static_frame`) must be identified at ``q*``. Elsewhere, e.g. a third "well" between the
    two where the data only pass in switching transits, the equilibrium is an artefact of
    the curve's unidentified part. The analytical model's rows are the designed model's
    and count as identified.

    Parameters
    ----------
    equilibria : pandas.DataFrame
        :func:`debist.identify.stability.stability_table` rows with a ``model`` column,
        ``level``, ``v1..vN`` [V] and ``q`` [unit of q].
    curves : pandas.DataFrame
        ``q`` and ``restoring_identified`` on the model's grid.
    static : pandas.DataFrame
        :func:`debist.identify.bands.static_frame` rows (``v1..vN``, ``q``,
        ``F_identified``).

    Returns
    -------
    pandas.DataFrame
        ``equilibria`` with boolean columns ``identified`` and ``d_identified`` (the damping
        curve d's mask at ``q*``, which d(q*) and zeta rest on; False where ``curves`` has
        no ``d_identified`` column), its ``attrs`` kept.

    References
    ----------
    Masoud & Maas 2025, Eq. 37, Sec. 3.3.
    """
    grid = curves["q"].to_numpy()
    d_mask = (
        curves["d_identified"].to_numpy()
        if "d_identified" in curves
        else np.zeros(grid.size, dtype=bool)
    )
    inputs = [c for c in equilibria.columns if c[:1] == "v" and c[1:].isdigit()]

    def at(q_grid: np.ndarray, mask: np.ndarray, q: float) -> bool:
        if not q_grid.size or not q_grid[0] <= q <= q_grid[-1]:
            return False
        return bool(mask[int(np.argmin(np.abs(q_grid - q)))])

    flags, d_flags = [], []
    for _, row in equilibria.iterrows():
        ours = row.get("model", "rbf") == "rbf"
        d_flags.append(at(grid, d_mask, float(row["q"])) if ours else True)
        if not ours:
            flags.append(True)
        elif int(row["level"]) == 0:
            flags.append(at(grid, curves["restoring_identified"].to_numpy(), float(row["q"])))
        else:
            same = np.ones(len(static), dtype=bool)
            for c in inputs:
                same &= np.isclose(static[c].to_numpy(), float(row[c]), rtol=1e-9, atol=1e-6)
            rows = static[same]
            flags.append(at(rows["q"].to_numpy(), rows["F_identified"].to_numpy(), float(row["q"])))
    out = equilibria.assign(
        identified=np.array(flags, dtype=bool), d_identified=np.array(d_flags, dtype=bool)
    )
    out.attrs = dict(equilibria.attrs)
    return out


def mark_switching(switching: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    """Say of each switching voltage of the identified model whether the data support it.

    Input i switches the beam out of the well it pushes against at the voltage where that
    well meets the saddle (:func:`debist.identify.stability.switching_voltages`): the
    number rests on the restoring force ``c(q) q + F_0`` and on ``g_i`` over the q interval
    the well travels as v_i rises, from ``q_well`` (at rest) to ``q_fold`` (where it
    vanishes). It is a result of the data only where both curves are identified over that
    whole interval (their masks of :func:`debist.identify.bands.curves_frame`); a
    profile that applies v_i only at full voltage (whose transits do not separate ``g_i``
    from ``c(q) q``) leaves it unidentified. The analytical model's rows count as
    identified; a row without a switching voltage is not.

    Parameters
    ----------
    switching : pandas.DataFrame
        :func:`~debist.identify.stability.switching_voltages` rows with a ``model``
        column: ``input``, ``v_switch`` [V], ``q_well``, ``q_fold`` [unit of q].
    curves : pandas.DataFrame
        ``q``, ``restoring_identified`` and ``g<i>_identified`` on the model's grid.

    Returns
    -------
    pandas.DataFrame
        ``switching`` with a boolean ``identified`` column (its ``attrs`` kept).

    References
    ----------
    Masoud & Maas 2025, Sec. 3.3 (switching condition), Eq. 37.
    """
    grid = curves["q"].to_numpy()
    restoring = curves["restoring_identified"].to_numpy(dtype=bool)
    flags = []
    for _, row in switching.iterrows():
        if row.get("model", "rbf") != "rbf":
            flags.append(True)
            continue
        ends = (row.get("q_well"), row.get("q_fold"))
        column = f"g{int(row['input'])}_identified"
        if pd.isna(row.get("v_switch")) or any(pd.isna(e) for e in ends) or column not in curves:
            flags.append(False)
            continue
        lo, hi = min(ends), max(ends)
        span = slice(int(np.argmin(np.abs(grid - lo))), int(np.argmin(np.abs(grid - hi))) + 1)
        ok = restoring & curves[column].to_numpy(dtype=bool)
        flags.append(bool(lo >= grid[0] and hi <= grid[-1] and ok[span].all()))
    out = switching.assign(identified=np.array(flags, dtype=bool))
    out.attrs = dict(switching.attrs)
    return out
