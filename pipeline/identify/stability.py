"""Stability and design numbers of an identified model: equilibria, wells, switching voltages.

The identified model of Masoud & Maas 2025 (Eq. 37),

    m_q q'' + d(q) z + F_c tanh(z / v_c) + f(q) = sum_i g_i(q) h(v_i),   T_z z' = q' - z,

with the restoring force ``f(q) = c(q) q + F_0``, is at rest where the static force
``F(q; v) = f(q) - sum_i g_i(q) h(v_i)`` vanishes. Per constant input level this module
finds those roots, their stiffness ``k = dF/dq`` [N/unit of q], the small-signal natural
frequency ``f_n`` [Hz] and damping ratio, and each well's energy barrier ``int F dq`` [J for
q in m; per unit mass when ``m_q = 1``]; per input the static switching voltage [V] (a
saddle-node); and a verdict on whether the model is stable where the data are. The
analytical model's numbers come from the same functions
(:func:`debist.identify.design.analytical_as_eq37`). A well is stable iff ``k > 0`` and
``d > 0`` (Routh-Hurwitz, whatever ``T_z``): docs/explanation/implementation.md.

References
----------
Masoud & Maas 2025, Eq. 15, 26, 33, 37, Section 3.3.3-3.3.4; Strogatz, Nonlinear Dynamics and
Chaos (2015), Sec. 3.1 (saddle-node bifurcation); Ogata, Modern Control Engineering (2010),
Sec. 5-6 (Routh's stability criterion).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import NamedTuple

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import DebistError
from debist.model.rbf import RBFModel

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")
integrate = lazy.load("scipy.integrate", suppress_warning=True)
optimize = lazy.load("scipy.optimize", suppress_warning=True)

__all__ = [
    "EquilibriumPoint",
    "StabilityError",
    "SwitchingVoltage",
    "Verdict",
    "equilibria",
    "model_is_stable",
    "small_signal",
    "stability_table",
    "switching_voltages",
    "verdict",
]


class StabilityError(DebistError, ValueError):
    """The stability analysis cannot be set up (empty range, level of the wrong length)."""


@dataclass(frozen=True)
class EquilibriumPoint:
    """One equilibrium ``F(q*; v) = 0`` of a model at a constant input level.

    Attributes
    ----------
    level : int
        Index of the input level (0 = all inputs at 0 V).
    v : tuple of float
        The input voltages of the level [V].
    q : float
        Position ``q*`` [unit of q].
    k : float
        Stiffness ``dF/dq`` at ``q*`` [N/unit of q].
    m_q : float
        Generalised mass at ``q*`` [kg].
    d : float
        Viscous damping ``d(q*)`` [N s/unit of q] (the Coulomb term is left out, see the
        module docstring).
    static_stable : bool
        ``k > 0`` (a well).
    damped : bool
        ``d > 0``.
    stable : bool
        ``static_stable and damped``: small-signal asymptotic stability.
    f_n : float
        Natural frequency ``sqrt(k / m_q) / (2 pi)`` [Hz]; NaN unless ``k > 0``.
    zeta : float
        Damping ratio ``d / (2 sqrt(k m_q))`` [-]; NaN unless ``k > 0``.
    barrier : float
        For a well: the smallest ``int_{q*}^{q_s} F dq`` over its neighbouring unstable
        equilibria ``q_s`` (the energy to leave it) [N * unit of q]; NaN for a saddle or a
        well without a neighbouring saddle.
    """

    level: int
    v: tuple[float, ...]
    q: float
    k: float
    m_q: float
    d: float
    static_stable: bool
    damped: bool
    stable: bool
    f_n: float
    zeta: float
    barrier: float


@dataclass(frozen=True)
class SwitchingVoltage:
    """Static switching voltage of one input (the others at 0 V).

    Attributes
    ----------
    input : int
        The input, 1-based (``v1`` is 1).
    v_switch : float
        Smallest voltage at which the well the input pushes out of disappears [V]; NaN when
        not reached (see ``reason``).
    q_well : float
        That well at ``v = 0`` [unit of q]; NaN when there is none.
    q_saddle : float
        The unstable equilibrium next to it on the push side at ``v = 0`` [unit of q].
    q_fold : float
        Where the well and the saddle merge at ``v_switch`` [unit of q]; NaN when not reached.
    reached : bool
        Whether the well disappears within ``[0, v_max]``.
    reason : str
        Why not reached (empty when reached).
    """

    input: int
    v_switch: float
    q_well: float
    q_saddle: float
    q_fold: float
    reached: bool
    reason: str


class Verdict(NamedTuple):
    """Result of :func:`verdict`: ``label`` is ``"stable"`` or ``"unstable"``, ``reason`` why."""

    label: str
    reason: str


_COLUMNS = ("q", "static_stable", "damped", "stable", "k", "m_q", "d", "f_n", "zeta", "barrier")
_SWITCH_COLUMNS = ("input", "v_switch", "q_well", "q_saddle", "q_fold", "reached", "reason")


def small_signal(k: float, m_q: float, d: float) -> tuple[float, float]:
    """Natural frequency and damping ratio of the linearisation ``m_q s^2 + d s + k`` at a well.

    Parameters
    ----------
    k : float
        Tangent stiffness ``dF/dq`` at the equilibrium [N/m, or per unit mass].
    m_q : float
        Mass at the equilibrium [kg, or 1 per unit mass].
    d : float
        Damping at the equilibrium [N s/m, or per unit mass].

    Returns
    -------
    f_n : float
        ``sqrt(k / m_q) / (2 pi)`` [Hz]; NaN unless ``k > 0`` (no well).
    zeta : float
        ``d / (2 sqrt(k m_q))`` [-]; NaN unless ``k > 0``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37 linearised at an equilibrium (a mass-spring-damper).
    """
    if not k > 0:
        return float("nan"), float("nan")
    return float(np.sqrt(k / m_q) / (2.0 * np.pi)), float(d / (2.0 * np.sqrt(k * m_q)))


def _mass_at(model: RBFModel, q: float) -> float:
    """Return the model's mass at ``q`` [kg]: m(q) with a position-dependent inertia, else m_q."""
    mass = getattr(model, "mass", None)
    return float(mass(np.array([q]))[0]) if callable(mass) else float(model.m_q)


def _barriers(q: Sequence[float], wells: Sequence[bool], energy: Callable[[int, int], float]):
    """Barrier of each well: min over neighbouring unstable roots of ``energy(well, saddle)``."""
    out = []
    for j, is_well in enumerate(wells):
        sides = [n for n in (j - 1, j + 1) if 0 <= n < len(q) and not wells[n]]
        out.append(min((energy(j, n) for n in sides), default=np.nan) if is_well else np.nan)
    return out


def _table(points: Sequence[EquilibriumPoint], n_inputs: int) -> pd.DataFrame:
    """Rows of :class:`EquilibriumPoint` as the table of :func:`stability_table`."""
    rows = []
    for p in points:
        row = {"level": p.level}
        row.update({f"v{i + 1}": p.v[i] for i in range(n_inputs)})
        row.update({c: asdict(p)[c] for c in _COLUMNS})
        rows.append(row)
    cols = ["level", *(f"v{i + 1}" for i in range(n_inputs)), *_COLUMNS]
    return pd.DataFrame(rows, columns=cols)


def _levels(levels: Sequence[Sequence[float]], n_inputs: int) -> list[tuple[float, ...]]:
    """Rest level first, then the distinct given levels, each of length ``n_inputs``."""
    out = [(0.0,) * n_inputs]
    for lv in levels:
        t = tuple(float(x) for x in np.atleast_1d(np.asarray(lv, dtype=float)))
        if len(t) != n_inputs:
            raise StabilityError(
                f"input level {list(t)} has {len(t)} voltages, the model has {n_inputs} inputs"
            )
        if t not in out:
            out.append(t)
    return out


# --------------------------------------------------------------------------- identified model


def _force(model: RBFModel, v: Sequence[float]) -> Callable[[ArrayLike], NDArray[np.float64]]:
    """:meth:`RBFModel.static_force` at ``v`` [N] as a vectorised function of ``q``."""
    v = np.asarray(v, dtype=float)
    return lambda q: model.static_force(q, v)


def _search_range(model: RBFModel, q_range) -> tuple[float, float]:
    lo, hi = model.q_range if q_range is None else q_range
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise StabilityError(
            f"the range of q searched for equilibria [{lo!r}, {hi!r}] is empty: give `q_range` "
            "or a model with its estimation range"
        )
    return lo, hi


def _roots(F: Callable, grid: NDArray[np.float64]) -> list[float]:
    """Roots of ``F`` on ``grid``: exact zeros and sign changes refined by Brent's method."""
    Fg = F(grid)
    s = np.sign(Fg)
    roots = [float(q) for q in grid[s == 0]]
    for k in np.flatnonzero(s[:-1] * s[1:] < 0):
        roots.append(
            optimize.brentq(lambda x: float(F(x)[0]), grid[k], grid[k + 1], xtol=1e-14, rtol=1e-13)
        )
    return sorted(roots)


def equilibria(
    model: RBFModel,
    levels: Sequence[Sequence[float]] = (),
    q_range: tuple[float, float] | None = None,
    *,
    n_grid: int = 4001,
) -> tuple[EquilibriumPoint, ...]:
    """Equilibria of the identified model at rest and at constant input levels.

    The roots of ``F(q; v) = c(q) q + F_0 - sum_i g_i(q) h(v_i)`` are bracketed by the sign
    changes of ``F`` on a uniform grid and refined by Brent's method (a double root that does
    not change sign, i.e. a level exactly at a fold, is not reported). The stiffness is the
    central difference ``dF/dq`` with step ``1e-5`` of the range.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    levels : sequence of sequence of float
        Constant input levels, each ``(v_1, ..., v_N)`` [V]; the rest level (all 0 V) is always
        first (level 0), repeated levels are dropped.
    q_range : tuple of float, optional
        Range searched [unit of q]; default ``model.q_range`` (the estimation range).
    n_grid : int
        Points of the bracketing grid.

    Returns
    -------
    tuple of EquilibriumPoint
        By level, then ascending ``q``.

    Raises
    ------
    StabilityError
        If the range is empty or a level does not have ``model.n_inputs`` voltages.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Brent, Algorithms for Minimization without Derivatives
    (1973), ch. 4 (``scipy.optimize.brentq``).
    """
    lo, hi = _search_range(model, q_range)
    grid = np.linspace(lo, hi, int(n_grid))
    step = 1e-5 * (hi - lo)
    out: list[EquilibriumPoint] = []
    for index, v in enumerate(_levels(levels, model.n_inputs)):
        F = _force(model, v)
        q = _roots(F, grid)
        if not q:
            continue
        qa = np.asarray(q)
        k = (F(qa + step) - F(qa - step)) / (2.0 * step)
        d = model.curves(qa)["d"]
        wells = [bool(x > 0) for x in k]

        def scalar(x: float, F=F) -> float:
            return float(F(x)[0])

        def energy(j: int, n: int, scalar=scalar, qa=qa) -> float:
            return float(integrate.quad(scalar, qa[j], qa[n], limit=200)[0])

        barrier = _barriers(q, wells, energy)
        for j in range(len(q)):
            m_j = _mass_at(model, float(q[j]))
            f_n, zeta = small_signal(float(k[j]), m_j, float(d[j]))
            out.append(
                EquilibriumPoint(
                    level=index, v=v, q=float(q[j]), k=float(k[j]), m_q=m_j,
                    d=float(d[j]), static_stable=wells[j], damped=bool(d[j] > 0),
                    stable=wells[j] and bool(d[j] > 0), f_n=f_n, zeta=zeta,
                    barrier=float(barrier[j]),
                )
            )  # fmt: skip
    return tuple(out)


def stability_table(
    model: RBFModel,
    levels: Sequence[Sequence[float]] = (),
    *,
    visited: Sequence[tuple[float, float]] | None = None,
    q_range: tuple[float, float] | None = None,
    n_grid: int = 4001,
) -> pd.DataFrame:
    """Equilibria of the identified model as a table, with the verdict when ``visited`` is given.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    levels : sequence of sequence of float
        Constant input levels [V] (:func:`equilibria`).
    visited : sequence of (float, float), optional
        Intervals of ``q`` the data visit [unit of q]: adds the column ``visited`` and
        ``attrs["verdict"]``, ``attrs["reason"]`` (:func:`verdict`).
    q_range : tuple of float, optional
        Range searched [unit of q]; default ``model.q_range``.
    n_grid : int
        Points of the bracketing grid.

    Returns
    -------
    pandas.DataFrame
        One row per equilibrium: ``level`` (0 = rest), ``v1..vN`` [V], ``q`` [unit of q],
        ``static_stable``, ``damped``, ``stable`` (bool), ``k`` [N/unit of q], ``m_q`` [kg],
        ``d`` [N s/unit of q], ``f_n`` [Hz], ``zeta`` [-], ``barrier`` [N * unit of q]
        (see :class:`EquilibriumPoint`), and ``visited`` (bool) when ``visited`` is given.

    Raises
    ------
    StabilityError
        As :func:`equilibria`.

    References
    ----------
    Masoud & Maas 2025, Eq. 37.
    """
    table = _table(equilibria(model, levels, q_range, n_grid=n_grid), model.n_inputs)
    if visited is not None:
        table["visited"] = _inside(table["q"].to_numpy(), visited)
        table.attrs["verdict"], table.attrs["reason"] = verdict(table, visited)
    return table


def _inside(q: NDArray[np.float64], intervals: Sequence[tuple[float, float]]) -> NDArray:
    """Whether each ``q`` lies in one of the closed ``intervals``."""
    q = np.asarray(q, dtype=float)
    hit = np.zeros(q.shape, dtype=bool)
    for lo, hi in intervals:
        hit |= (q >= lo) & (q <= hi)
    return hit


def verdict(table: pd.DataFrame, visited_intervals: Sequence[tuple[float, float]]) -> Verdict:
    """Stable or unstable where the data are, from the equilibrium table.

    Two rules, checked in this order:

    1. **Negative damping in a visited well**: a well (``static_stable``) of any level inside a
       visited interval with ``d < 0``. The model's free run resting there oscillates with a
       growing amplitude.
    2. **Nowhere to rest**: no well of the rest level (all inputs 0 V) inside the visited
       intervals, i.e. only unstable equilibria (negative stiffness) or none where the data
       rest; the model's free run at 0 V drifts out of the visited range.

    ``d = 0`` is not flagged (undamped, e.g. a model with Coulomb friction only).

    Parameters
    ----------
    table : pandas.DataFrame
        From :func:`stability_table` (columns ``level``, ``q``,
        ``static_stable``, ``d``).
    visited_intervals : sequence of (float, float)
        Intervals of ``q`` the data visit [unit of q], e.g. ``[(q.min(), q.max())]``.

    Returns
    -------
    Verdict
        ``("unstable", reason)`` naming the first offending well or level, else
        ``("stable", summary)``.

    References
    ----------
    Ogata, Modern Control Engineering (2010), Sec. 5-6 (Routh's stability criterion).
    """
    inside = _inside(table["q"].to_numpy(), visited_intervals)
    wells = table["static_stable"].to_numpy(dtype=bool)
    span = ", ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in visited_intervals)
    bad = table[inside & wells & (table["d"].to_numpy() < 0)]
    if len(bad):
        row = bad.iloc[0]
        return Verdict(
            "unstable",
            f"negative damping d = {row['d']:.4g} in the visited well at q = {row['q']:.6g} "
            f"(level {row['level']})",
        )
    rest = table["level"].to_numpy() == 0
    if not np.any(rest & inside & wells):
        return Verdict("unstable", f"no stable equilibrium at 0 V inside the visited {span}")
    n = int(np.count_nonzero(inside & wells))
    return Verdict("stable", f"{n} visited well(s), all with d >= 0, in {span}")


def model_is_stable(
    model: RBFModel,
    q_visited: ArrayLike,
    *,
    q_dot: ArrayLike | None = None,
    n_grid: int = 4001,
) -> tuple[bool, str]:
    """Whether the identified model is stable where the data are (for refinement, validation).

    Unstable if :func:`verdict` says so at the rest level (over the visited interval joined
    with ``q_range``), if the damping feeds energy into a visited well's basin, or if m(q) is
    not positive; a model without an equilibrium at 0 V there is not judged. The rules:
    docs/explanation/implementation.md.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    q_visited : array_like
        Positions the data visit [unit of q] (e.g. the measured ``q``); NaN ignored.
    q_dot : array_like, optional
        The measured velocities at ``q_visited`` [unit of q / s]; given, the basin rule asks
        ``sum d(q_s) q_dot_s^2 >= 0``, without, any ``d(q) < 0`` in the visited basin fails.
    n_grid : int
        Points of the bracketing grid (also where ``d(q)`` is checked).

    Returns
    -------
    stable : bool
    reason : str
        The rule that failed, with the offending value, or a summary.

    Raises
    ------
    StabilityError
        If ``q_visited`` has no finite value.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Ogata, Modern Control Engineering (2010), Sec. 5-6.
    """
    qv = np.asarray(q_visited, dtype=float).ravel()
    qv = qv[np.isfinite(qv)]
    if qv.size == 0:
        raise StabilityError("`q_visited` has no finite position")
    v_lo, v_hi = float(qv.min()), float(qv.max())
    lo, hi = model.q_range
    lo, hi = (v_lo, v_hi) if not hi > lo else (min(lo, v_lo), max(hi, v_hi))
    if not hi > lo:
        hi = lo + max(1.0, abs(lo)) * 1e-9
    if getattr(model, "has_inertia", False):
        grid = np.linspace(lo, hi, int(n_grid))
        m = model.mass(grid)
        if np.min(m) <= 0:
            at = float(grid[np.argmin(m)])
            return False, (
                f"the identified mass m(q) = {np.min(m):.4g} is not positive at q = {at:.6g}"
            )
    table = stability_table(model, (), q_range=(lo, hi), n_grid=n_grid)
    q = table["q"].to_numpy()
    wells = table["static_stable"].to_numpy(dtype=bool)
    inside = (q >= v_lo) & (q <= v_hi)
    if not np.any(inside):  # no equilibrium at rest where the data are (a free mass, a
        return True, "no equilibrium at 0 V in the visited range"  # driven stage): no rule
    label, reason = verdict(table, [(v_lo, v_hi)])
    if label == "unstable":
        return False, reason
    grid = np.linspace(lo, hi, int(n_grid))
    d = model.curves(grid)["d"]
    for j in np.flatnonzero(wells & (q >= v_lo) & (q <= v_hi)):
        left = max([v_lo, *q[:j][~wells[:j]][-1:]])
        right = min([v_hi, *q[j + 1 :][~wells[j + 1 :]][:1]])
        sel = (grid >= left) & (grid <= right)
        if q_dot is not None:
            qd = np.asarray(q_dot, dtype=float).ravel()
            qs = np.asarray(q_visited, dtype=float).ravel()
            ok = np.isfinite(qs) & np.isfinite(qd) & (qs >= left) & (qs <= right)
            power = float(np.sum(model.curves(qs[ok])["d"] * qd[ok] ** 2)) if ok.any() else 0.0
            if power < 0:
                return False, (
                    f"the identified damping feeds energy into the measured motion in the "
                    f"basin [{left:.6g}, {right:.6g}] of the well at q = {q[j]:.6g} "
                    f"(sum d q_dot^2 = {power:.4g})"
                )
            continue
        if np.any(sel) and np.min(d[sel]) < 0:
            at = grid[sel][np.argmin(d[sel])]
            return False, (
                f"negative damping d = {np.min(d[sel]):.4g} at q = {at:.6g} in the visited "
                f"basin [{left:.6g}, {right:.6g}] of the well at q = {q[j]:.6g}"
            )
    return True, reason


# --------------------------------------------------------------------------- switching voltages


def _push_target(
    q: Sequence[float], wells: Sequence[bool], push: float
) -> tuple[float, float] | None:
    """Return the well an input pushing in direction ``push`` leaves, and its saddle there.

    Pushing to +q: the leftmost well with an unstable equilibrium right next to it on the
    right; pushing to -q: the rightmost well with one on its left.
    """
    order = range(len(q)) if push > 0 else range(len(q) - 1, -1, -1)
    step = 1 if push > 0 else -1
    for j in order:
        n = j + step
        if wells[j] and 0 <= n < len(q) and not wells[n]:
            return float(q[j]), float(q[n])
    return None


def _switching(
    input_: int,
    q: Sequence[float],
    wells: Sequence[bool],
    push: float,
    indicator: Callable[[float, float, float, float], tuple[float, float]],
    v_max: float,
    n_scan: int,
    xtol: float,
) -> SwitchingVoltage:
    """Smallest ``v`` in ``[0, v_max]`` with ``indicator(v) < 0`` (scan, then Brent's method).

    ``indicator(v, push, q_well, q_saddle)`` is the largest push-opposing force between the
    v = 0 well and saddle, ``max push * F(q; v)`` over that interval, and where it is: positive
    while the well exists, zero at the fold. The root is refined in ``v^2``, where the
    indicator is close to linear.
    """
    nan = float("nan")
    if push == 0:
        return SwitchingVoltage(input_, nan, nan, nan, nan, False, "the input exerts no force")
    target = _push_target(q, wells, push)
    if target is None:
        why = "no well at 0 V with an unstable equilibrium next to it on the side it pushes to"
        return SwitchingVoltage(input_, nan, nan, nan, nan, False, why)
    q_w, q_s = target

    def ind(v: float) -> float:
        return indicator(v, push, q_w, q_s)[0]

    vs = np.linspace(0.0, v_max, int(n_scan) + 1)
    prev = 0.0
    for v in vs[1:]:
        if ind(float(v)) < 0:
            # in v^2 the indicator is near linear (exactly for h = v^2 and constant g)
            w = optimize.brentq(
                lambda w: ind(np.sqrt(w)), prev**2, float(v) ** 2, xtol=2 * xtol * v
            )
            v_sw = float(np.sqrt(w))
            q_fold = indicator(v_sw, push, q_w, q_s)[1]
            return SwitchingVoltage(input_, float(v_sw), q_w, q_s, float(q_fold), True, "")
        prev = float(v)
    why = (
        f"the well at q = {q_w:.6g} persists up to v_max = {v_max:g} V (largest opposing "
        f"force {ind(v_max):.4g} at v_max)"
    )
    return SwitchingVoltage(input_, nan, q_w, q_s, nan, False, why)


def _switch_table(rows: Sequence[SwitchingVoltage]) -> pd.DataFrame:
    return pd.DataFrame([asdict(r) for r in rows], columns=list(_SWITCH_COLUMNS))


def switching_voltages(
    model: RBFModel,
    *,
    v_max: float,
    q_range: tuple[float, float] | None = None,
    n_grid: int = 4001,
    n_scan: int = 32,
    xtol: float = 1e-6,
) -> pd.DataFrame:
    """Find the static switching voltage of each input of the identified model (others at 0 V).

    The voltage at which the well input ``i`` pushes out of merges with its saddle
    (saddle-node), by a scan of ``[0, v_max]`` refined by Brent's method; assumes ``g_i`` of
    one sign between the well and the saddle. Details: docs/explanation/implementation.md.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    v_max : float
        Largest voltage searched [V] (beyond the data the model extrapolates).
    q_range : tuple of float, optional
        Range searched [unit of q]; default ``model.q_range``.
    n_grid, n_scan : int
        Points of the grid of ``q``; steps of the voltage scan.
    xtol : float
        Tolerance of the voltage [V].

    Returns
    -------
    pandas.DataFrame
        One row per input: ``input`` (1-based), ``v_switch`` [V] (NaN when not reached),
        ``q_well``, ``q_saddle``, ``q_fold`` [unit of q], ``reached`` and ``reason``.

    Raises
    ------
    StabilityError
        If the range is empty.

    References
    ----------
    Masoud & Maas 2025, Section 3.3.3 (switching by one DE); Strogatz, Nonlinear Dynamics and
    Chaos (2015), Sec. 3.1.
    """
    lo, hi = _search_range(model, q_range)
    grid = np.linspace(lo, hi, int(n_grid))
    rest = [p for p in equilibria(model, (), (lo, hi), n_grid=n_grid) if p.level == 0]
    q = [p.q for p in rest]
    wells = [p.static_stable for p in rest]
    rows = []
    for i in range(model.n_inputs):
        e_i = np.zeros(model.n_inputs)
        e_i[i] = 1.0
        span = (grid >= min(q)) & (grid <= max(q)) if len(q) > 1 else np.ones(grid.size, bool)
        on = grid[span]  # the way the input force at v_max pushes: the static force drops
        drop = model.static_force(on, 0.0 * e_i) - model.static_force(on, v_max * e_i)
        push = float(np.sign(np.mean(drop)))

        def indicator(v, push, q_w, q_s, e_i=e_i):
            F = _force(model, v * e_i)
            a, b = min(q_w, q_s), max(q_w, q_s)
            sub = np.linspace(a, b, max(3, int(n_grid * (b - a) / (hi - lo))))
            Fs = push * F(sub)
            k = int(np.argmax(Fs))
            r = optimize.minimize_scalar(
                lambda x: -push * float(F(x)[0]),
                bounds=(sub[max(k - 1, 0)], sub[min(k + 1, sub.size - 1)]),
                method="bounded",
                options={"xatol": 1e-12 * (hi - lo)},
            )
            return (-float(r.fun), float(r.x)) if -r.fun > Fs[k] else (float(Fs[k]), sub[k])

        rows.append(_switching(i + 1, q, wells, push, indicator, v_max, n_scan, xtol))
    return _switch_table(rows)
