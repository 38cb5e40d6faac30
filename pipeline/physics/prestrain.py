"""Pre-strain analysis (Fig. 3): equilibria versus ``z_b = b_max - b`` and the bifurcations.

``z_b,min`` is the pitchfork where the straight beam loses stability; ``z_b,max`` the switching
limit beyond which 3 kV on one DE no longer removes the opposite well. Both are found by
root-finding on well-defined indicators (smallest Hessian eigenvalue; height of the local
maximum of the actuated force curve), not read off a grid.

References
----------
Masoud & Maas 2025, Eq. 15-17, Section 3.3.3, Fig. 3; docs/interpretation.md items 3, 5.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import ConvergenceWarning
from debist.physics.energy import potential
from debist.physics.kinematics import ritz_basis
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.statics import (
    Equilibrium,
    StaticsError,
    _bracket_starts,
    _dedup,
    _path,
    _path_derived,
    _path_grid,
    _solve_at_q,
    _solve_batch,
    solve_equilibrium,
)

# the libraries below load on first use (lazy_loader): start-up of the CLI
optimize = lazy.load("scipy.optimize", suppress_warning=True)

__all__ = [
    "PrestrainSweep",
    "equilibrium_branches",
    "pitchfork_zb",
    "prestrain_sweep",
    "switching_limit_zb",
]

SWEEP_STATES = ((0.0, 0.0), (V_MAX, 0.0), (0.0, V_MAX))
"""Voltage states ``(v1, v2)`` [V] of the pre-strain sweep of Fig. 3."""


def _jumps(q, F, dF_dq, tol: float = 1e-4):
    """Flag path points next to a jump of ``F`` (the path switched branch of the sub-problem).

    A smooth path satisfies ``F[k+1] - F[k] = (dF_dq[k] + dF_dq[k+1]) dq / 2`` up to
    ``O(dq^3)``; both ends of an interval that violates it by more than ``tol`` [N] plus 10 %
    are flagged.
    """
    dF = np.diff(F, axis=-1)
    pred = 0.5 * (dF_dq[..., 1:] + dF_dq[..., :-1]) * np.diff(q)
    bad = ~(np.abs(dF - pred) <= tol + 0.1 * np.abs(dF))
    out = np.zeros(F.shape, dtype=bool)
    out[..., 1:] |= bad
    out[..., :-1] |= bad
    return out


def _straight_state(params: PrototypeParams, b: float, v: float = 0.0) -> Equilibrium:
    """Solve for the straight-beam equilibrium ``q_2 = q_3 = q_4 = 0`` for symmetric voltages."""
    return solve_equilibrium(params, np.zeros(4), b=b, v1=v, v2=v)


def pitchfork_zb(
    params: PrototypeParams,
    *,
    b_bracket: tuple[float, float] = (20e-3, 30e-3),
    v: float = 0.0,
) -> float:
    """Pitchfork point ``z_b,min``: where the straight beam (q = 0) loses stability (Fig. 3, A).

    Solves ``lambda_min(H(b)) = 0`` by Brent's method, ``H`` the Hessian of ``U`` at the
    straight-beam equilibrium with both DEs at voltage ``v`` (scaled coordinates).

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters (``b`` is ignored).
    b_bracket : tuple of float
        Range of ``b`` searched [m]; the straight beam must be unstable at the lower end and
        stable at the upper end.
    v : float
        Voltage on both DEs [V].

    Returns
    -------
    float
        ``z_b,min = b_max - b_crit`` [m].

    Raises
    ------
    StaticsError
        If the smallest eigenvalue does not change sign over ``b_bracket``.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, 17, Fig. 3 (point A).
    """

    def lam_min(b: float) -> float:
        return float(_straight_state(params, b, v).eigenvalues[0])

    lo, hi = b_bracket
    f_lo, f_hi = lam_min(lo), lam_min(hi)
    if not (f_lo < 0 < f_hi):
        raise StaticsError(
            f"pitchfork_zb: the smallest Hessian eigenvalue of the straight beam does not change "
            f"sign over `b_bracket`={b_bracket} m (values {f_lo:.3g}, {f_hi:.3g} N/m)"
        )
    b_crit = optimize.brentq(lam_min, lo, hi, xtol=1e-10)
    return params.b_max - b_crit


def _left_max(params, q, y_row, b, v):
    """``max F_{v,0}(q)`` over the grid ``q`` (<= 0) refined by a bounded scalar search."""
    qm, ys, ok = _solve_at_q(params, q, y_row, b, v, 0.0, 1e-3)
    F = potential(qm, params, b=b, v1=v).grad[..., 0] / params.l**2
    F = np.where(ok, F, -np.inf)
    k = int(np.argmax(F))
    if k in (0, q.size - 1):
        return float(F[k]), ys
    cache = {"y": ys[k]}

    def neg_F(qq: float) -> float:
        qmq, yq, _ = _solve_at_q(params, np.array(qq), cache["y"], b, v, 0.0, 1e-3)
        cache["y"] = yq
        return -float(potential(qmq, params, b=b, v1=v).grad[0] / params.l**2)

    r = optimize.minimize_scalar(
        neg_F, bounds=(q[k - 1], q[k + 1]), method="bounded", options={"xatol": 1e-9}
    )
    return max(-float(r.fun), float(F[k])), ys


def switching_limit_zb(
    params: PrototypeParams,
    *,
    v: float = V_MAX,
    b_range: tuple[float, float] = (10e-3, 30e-3),
    q_max: float = 25e-3,
    n_q: int = 101,
    db: float = 0.25e-3,
) -> float:
    """Switching limit ``z_b,max``: where ``v`` on DE 1 no longer removes the left well (Fig. 3).

    With DE 1 (left) at ``v`` the indicator ``I(b) = max_{q <= 0} F_{v,0}(q; b)`` is the
    height of the local maximum of the actuated force curve on the left: ``I < 0`` means no
    equilibrium with ``q < 0`` (the DE switches the beam to the right), ``I > 0`` a left well
    (a fold pair of equilibria) that survives actuation. ``z_b,max`` is the root of ``I``,
    bracketed on a grid of ``b`` (continuation in ``b`` from ``b_range[1]`` downwards) and
    refined by Brent's method. By symmetry the same value holds for DE 2 and the right well.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters (``b`` is ignored).
    v : float
        Actuation voltage of DE 1 [V].
    b_range : tuple of float
        Range of ``b`` searched [m].
    q_max : float
        The left half ``[-q_max, 0]`` of the stroke is searched [m].
    n_q : int
        Grid points on ``[-q_max, 0]``.
    db : float
        Step of the ``b`` grid used for bracketing [m].

    Returns
    -------
    float
        ``z_b,max = b_max - b_switch`` [m].

    Raises
    ------
    StaticsError
        If ``I`` does not change sign over ``b_range``.

    References
    ----------
    Masoud & Maas 2025, Section 3.3.3, Fig. 3.
    """
    lo, hi = b_range
    b_grid = np.linspace(hi, lo, max(2, round((hi - lo) / db) + 1))
    q = np.linspace(-q_max, 0.0, n_q)
    qm0, _ = _path(params, q, np.array([hi]), np.array([v]), np.array([0.0]))
    y = qm0[0, :, 1:]
    prev = None
    for b in b_grid:
        ind, y_new = _left_max(params, q, y, b, v)
        if ind > 0:
            if prev is None:
                raise StaticsError(
                    f"switching_limit_zb: the left well survives v1={v} V already at "
                    f"b={hi} m (upper end of `b_range`)"
                )
            y_prev = prev[1]
            b_sw = optimize.brentq(
                lambda bb, y_prev=y_prev: _left_max(params, q, y_prev, bb, v)[0],
                b,
                prev[0],
                xtol=1e-10,
            )
            return params.b_max - b_sw
        prev = (b, y_new)
        y = y_new
    raise StaticsError(
        f"switching_limit_zb: v1={v} V removes the left well over the whole `b_range`="
        f"{b_range} m; extend the range downwards"
    )


@dataclass(frozen=True)
class PrestrainSweep:
    """Equilibria versus the pre-strain parameter (Fig. 3).

    Attributes
    ----------
    b : ndarray, shape (n_b,)
        Screw positions [m].
    z_b : ndarray, shape (n_b,)
        ``b_max - b`` [m] (Eq. 17).
    voltages : ndarray, shape (n_s, 2)
        Voltage states ``(v1, v2)`` [V].
    q : ndarray, shape (n_q,)
        Grid of the continuation paths [m].
    F : ndarray, shape (n_s, n_b, n_q)
        Force along the paths [N]; NaN where not converged or next to a jump of the path
        (for ``z_b`` beyond ~12 mm the prescribed-``q`` sub-problem has several branches).
    dF_dq : ndarray, shape (n_s, n_b, n_q)
        Tangent stiffness along the paths [N/m].
    eq_state, eq_b_index : ndarray of int, shape (n_eq,)
        Voltage state and ``b`` index of each equilibrium.
    eq_q : ndarray, shape (n_eq,)
        Tip displacement of each equilibrium [m].
    eq_qm : ndarray, shape (n_eq, 4)
        Ritz coordinates of each equilibrium.
    eq_stable : ndarray of bool, shape (n_eq,)
        Stability of each equilibrium.
    z_b_min : float
        Pitchfork point [m] (:func:`pitchfork_zb`), NaN if outside the searched range.
    z_b_max : float
        Switching limit [m] (:func:`switching_limit_zb`), NaN if outside the searched range.
    """

    b: NDArray[np.float64]
    z_b: NDArray[np.float64]
    voltages: NDArray[np.float64]
    q: NDArray[np.float64]
    F: NDArray[np.float64]
    dF_dq: NDArray[np.float64]
    eq_state: NDArray[np.int_]
    eq_b_index: NDArray[np.int_]
    eq_q: NDArray[np.float64]
    eq_qm: NDArray[np.float64]
    eq_stable: NDArray[np.bool_]
    z_b_min: float
    z_b_max: float

    def equilibria_of(self, state: int, b_index: int) -> tuple[NDArray, NDArray]:
        """Return ``(q, stable)`` of the equilibria of one voltage state at one ``b``.

        Parameters
        ----------
        state : int
            Index into ``voltages``.
        b_index : int
            Index into ``b``.

        Returns
        -------
        q : ndarray, shape (k,)
            Tip displacements [m], ascending.
        stable : ndarray of bool, shape (k,)
            Stability flags.
        """
        sel = (self.eq_state == state) & (self.eq_b_index == b_index)
        return self.eq_q[sel], self.eq_stable[sel]


def prestrain_sweep(
    params: PrototypeParams,
    *,
    b: ArrayLike | None = None,
    voltages: Sequence[tuple[float, float]] = SWEEP_STATES,
    q_max: float = 25e-3,
    n_q: int = 200,
    bifurcations: bool = True,
) -> PrestrainSweep:
    """Equilibria for a range of pre-strain ``b`` and voltage states (Fig. 3).

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters (``b`` is ignored).
    b : array_like, shape (n_b,), optional
        Screw positions [m]; default 101 values on ``[b_max - 12.5 mm, b_max]`` (17.5-30 mm).
        The paper sweeps [20, 30] mm; with E = 2.1 GPa the switching limit ``z_b,max`` =
        11.65 mm lies beyond that range, so the default extends it to show both bifurcations.
    voltages : sequence of (float, float)
        Voltage states ``(v1, v2)`` [V]; default (0, 0), (3 kV, 0), (0, 3 kV).
    q_max : float
        Half width of the searched range of ``q`` [m].
    n_q : int
        Continuation grid points on ``[-q_max, q_max]`` (an even number keeps ``q = 0`` off
        the grid, so that the straight-beam branch shows up as a sign change).
    bifurcations : bool
        Also compute ``z_b_min`` (:func:`pitchfork_zb`) and ``z_b_max``
        (:func:`switching_limit_zb`); they are searched on ``[b_max - 20 mm, b_max]``, which
        may extend beyond ``b``.

    Returns
    -------
    PrestrainSweep
        The paths, the equilibria and the bifurcation points.

    References
    ----------
    Masoud & Maas 2025, Eq. 15-17, Section 3.3.3, Fig. 3; docs/interpretation.md item 5.
    """
    if b is None:
        b = np.linspace(params.b_max - 12.5e-3, params.b_max, 101)
    b = np.asarray(b, dtype=float)
    V = np.asarray(voltages, dtype=float).reshape(-1, 2)
    q = np.linspace(-q_max, q_max, n_q)
    qm, ok = _path_grid(params, q, b, V[:, 0], V[:, 1])
    d = _path_derived(params, qm, b[None, :, None], V[:, 0, None, None], V[:, 1, None, None])
    ok = ok & ~_jumps(q, d["F"], d["dF_dq"])
    F = np.where(ok, d["F"], np.nan)
    # starting points: sign changes along each path, plus the straight beam
    starts, meta = [], []
    for s in range(V.shape[0]):
        for i in range(b.size):
            for x0 in _bracket_starts(q, qm[s, i], np.nan_to_num(F[s, i], nan=0.0), 0.0):
                starts.append(x0)
                meta.append((s, i))
            starts.append(np.zeros(4))
            meta.append((s, i))
    X0 = np.array(starts)
    mi = np.array(meta)
    res, eig, lam = _solve_batch(
        params, X0, b[mi[:, 1]], V[mi[:, 0], 0], V[mi[:, 0], 1], np.zeros(len(X0))
    )
    L = ritz_basis(params.l).L
    scale = ritz_basis(params.l).scale
    keep = res.converged & np.all(lam >= 1.0, axis=-1)
    rows = []
    for s in range(V.shape[0]):
        for i in range(b.size):
            sel = np.flatnonzero(keep & (mi[:, 0] == s) & (mi[:, 1] == i))
            eqs = [
                Equilibrium(
                    res.x[k],
                    float(res.x[k] @ L),
                    bool(eig[k, 0] > 0),
                    eig[k],
                    lam[k],
                    float(res.residual[k]),
                    True,
                )
                for k in sel
            ]
            rows.extend((s, i, e) for e in _dedup(eqs, scale))
    z_min = z_max = float("nan")
    if bifurcations:
        lo = params.b_max - 20e-3
        try:
            z_min = pitchfork_zb(params, b_bracket=(lo, params.b_max))
        except StaticsError as err:
            warnings.warn(str(err), ConvergenceWarning, stacklevel=2)
        try:
            z_max = switching_limit_zb(params, v=float(np.max(V)), b_range=(lo, params.b_max))
        except StaticsError as err:
            warnings.warn(str(err), ConvergenceWarning, stacklevel=2)
    return PrestrainSweep(
        b=b,
        z_b=params.b_max - b,
        voltages=V,
        q=q,
        F=F,
        dF_dq=np.where(ok, d["dF_dq"], np.nan),
        eq_state=np.array([r[0] for r in rows], dtype=int),
        eq_b_index=np.array([r[1] for r in rows], dtype=int),
        eq_q=np.array([r[2].q for r in rows]),
        eq_qm=np.array([r[2].qm for r in rows]).reshape(-1, 4),
        eq_stable=np.array([r[2].stable for r in rows], dtype=bool),
        z_b_min=z_min,
        z_b_max=z_max,
    )


def equilibrium_branches(
    sweep: PrestrainSweep, state: int
) -> list[tuple[NDArray[np.float64], NDArray[np.float64], bool]]:
    """Equilibrium branches of one voltage state as polylines in the (q, z_b) plane (Fig. 3).

    The zero level of ``F(q, z_b)`` on the sweep grid is traced (marching squares) and split
    into stable (``dF/dq > 0``) and unstable pieces; folds are where the two meet. For
    symmetric voltages the straight-beam branch ``q = 0`` is added from the equilibria.

    Parameters
    ----------
    sweep : PrestrainSweep
        Result of :func:`prestrain_sweep`.
    state : int
        Index into ``sweep.voltages``.

    Returns
    -------
    list of (q, z_b, stable)
        Polylines: ``q`` [m] and ``z_b`` [m] of shape (k,), and the stability of the piece.

    References
    ----------
    Masoud & Maas 2025, Fig. 3.
    """
    import contourpy

    order = np.argsort(sweep.z_b)
    z = sweep.z_b[order]
    F = sweep.F[state][order]
    K = sweep.dF_dq[state][order]
    gen = contourpy.contour_generator(sweep.q, z, np.ma.masked_invalid(F), name="serial")
    out = []
    for line in gen.lines(0.0):
        if len(line) < 2:
            continue
        qv, zv = line[:, 0], line[:, 1]
        iq = np.clip(np.searchsorted(sweep.q, qv) - 1, 0, sweep.q.size - 2)
        iz = np.clip(np.searchsorted(z, zv) - 1, 0, z.size - 2)
        wq = (qv - sweep.q[iq]) / (sweep.q[iq + 1] - sweep.q[iq])
        wz = (zv - z[iz]) / (z[iz + 1] - z[iz])
        k = (
            (1 - wq) * (1 - wz) * K[iz, iq]
            + wq * (1 - wz) * K[iz, iq + 1]
            + (1 - wq) * wz * K[iz + 1, iq]
            + wq * wz * K[iz + 1, iq + 1]
        )
        st = k > 0
        cuts = np.flatnonzero(st[1:] != st[:-1]) + 1
        start = 0
        for c in [*cuts, len(st)]:
            seg = slice(max(start - 1, 0), c)  # overlap one vertex to keep the line closed
            out.append((qv[seg], zv[seg], bool(st[start])))
            start = c
    v1, v2 = sweep.voltages[state]
    if v1 == v2:  # the straight beam, an exact equilibrium (the grid may miss it, see F)
        sel = (sweep.eq_state == state) & (np.abs(sweep.eq_q) < 1e-9)
        z = sweep.z_b[sweep.eq_b_index[sel]]
        k = np.argsort(z)
        z, st = z[k], sweep.eq_stable[sel][k]
        edges = [0, *(np.flatnonzero(st[1:] != st[:-1]) + 1), z.size]
        for i0, i1 in itertools.pairwise(edges):
            lo = z[i0] if i0 == 0 else 0.5 * (z[i0 - 1] + z[i0])
            hi = z[i1 - 1] if i1 == z.size else 0.5 * (z[i1 - 1] + z[i1])
            zs = np.unique(np.clip([lo, *z[i0:i1], hi], lo, hi))
            out.append((np.zeros(zs.size), zs, bool(st[i0])))
    return out
