"""Static analysis: equilibria (Eq. 15), F(q) (Fig. 4) and C(q) (Fig. 5).

Equilibria solve ``dU/dq_m = F dq/dq_m`` (Eq. 15) by Newton's method with the exact Hessian.
Force-displacement curves are computed by continuation in the tip displacement ``q``: since
``q = L . q_m`` is linear (Eq. 16), ``q_2 = (q - l^3 q_3 - l^4 q_4) / l^2`` is eliminated, the
remaining three coordinates solve ``T^T dU/dq_m = 0`` and the reaction is ``F = dU/dq_2 / l^2``.
All equilibria at a given load are found as the roots of ``F_v(q) - F`` along that path, each
refined by a Newton solve of the full Eq. 15 (other starting points may be added); equilibria
with a slack DE (``lambda_1 < 1``) are discarded (docs/interpretation.md item 5). The
pre-strain analysis of Fig. 3 is in :mod:`debist.physics.prestrain`.

References
----------
Masoud & Maas 2025, Eq. 14-18, Fig. 3-5; docs/interpretation.md items 1-6.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import ConvergenceWarning, DebistError
from debist.physics._newton import newton
from debist.physics.energy import capacitances, potential, scalar_gradient_hessian
from debist.physics.kinematics import ritz_basis
from debist.physics.params import V_MAX, PrototypeParams

__all__ = [
    "Equilibrium",
    "ForceCurve",
    "StaticsError",
    "equilibria",
    "force_displacement",
    "force_displacements",
    "solve_equilibrium",
    "switches",
    "switching_voltage",
]

FORCE_STATES = ((0.0, 0.0), (V_MAX, 0.0), (0.0, V_MAX), (V_MAX, V_MAX))
"""Voltage states ``(v1, v2)`` [V] of the force-displacement curves of Fig. 4."""


class StaticsError(DebistError, RuntimeError):
    """A static problem has no solution in the searched range (e.g. no bracket for a root)."""


def _elimination(params: PrototypeParams) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return ``T (4, 3)`` and ``t (4,)`` with ``q_m = T y + t q``, ``y = [q_3, q_4, u_0]``."""
    l = params.l  # noqa: E741
    T = np.array([[-l, -(l**2), 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([1.0 / l**2, 0.0, 0.0, 0.0])
    return T, t


def _solve_at_q(
    params: PrototypeParams,
    q: NDArray[np.float64],
    y0: NDArray[np.float64],
    b: NDArray[np.float64],
    v1: NDArray[np.float64],
    v2: NDArray[np.float64],
    max_step: float = 5e-3,
):
    """Solve ``T^T dU/dq_m = 0`` for ``y = [q_3, q_4, u_0]`` at prescribed ``q`` (batched)."""
    T, t = _elimination(params)
    sy = np.array([params.l**3, params.l**4, 1.0])
    tq = t * np.asarray(q, dtype=float)[..., None]

    def fun(y):
        grad, hess = scalar_gradient_hessian(y @ T.T + tq, params, b, v1, v2)
        return grad @ T, T.T @ hess @ T

    res = newton(fun, y0, sy, max_step=max_step)
    return res.x @ T.T + tq, res.x, res.converged


def _path(
    params: PrototypeParams,
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    v1: NDArray[np.float64],
    v2: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Continuation in ``q`` (ascending grid, shape (n_q,)) for a batch of (b, v1, v2), (n_b,).

    Starts at the grid point nearest to ``q = 0`` (straight beam as first guess) and marches
    outwards with a secant predictor. Returns ``q_m`` of shape (n_b, n_q, 4) and the
    convergence flags (n_b, n_q).
    """
    n_q = q.size
    qm = np.zeros((b.size, n_q, 4))
    ys = np.zeros((b.size, n_q, 3))
    ok = np.zeros((b.size, n_q), dtype=bool)
    i0 = int(np.argmin(np.abs(q)))
    qm[:, i0], ys[:, i0], ok[:, i0] = _solve_at_q(params, q[i0], ys[:, i0], b, v1, v2)
    for direction in (1, -1):
        k = i0 + direction
        while 0 <= k < n_q:
            guess = ys[:, k - direction]
            k2 = k - 2 * direction
            if 0 <= k2 < n_q and (k2 - i0) * direction >= 0:  # secant predictor
                dq = (q[k] - q[k - direction]) / (q[k - direction] - q[k2])
                guess = guess + (guess - ys[:, k2]) * dq
            qm[:, k], ys[:, k], ok[:, k] = _solve_at_q(params, q[k], guess, b, v1, v2, 1e-3)
            k += direction
    return qm, ok


def _path_grid(
    params: PrototypeParams,
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    v1: NDArray[np.float64],
    v2: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Paths ``q_m(q)`` on a (b, q) grid for voltage states (v1, v2) of shape (n_s,).

    The largest ``b`` (least pre-stretch, the straight beam is stable and the path unique) is
    solved by continuation in ``q``; smaller ``b`` follow by natural continuation in ``b``,
    all ``q`` of a row in one batched Newton solve. Returns ``q_m`` (n_s, n_b, n_q, 4) in the
    order of ``b`` and the convergence flags (n_s, n_b, n_q).
    """
    order = np.argsort(b)[::-1]
    n_s, n_b, n_q = v1.size, b.size, q.size
    qm = np.zeros((n_s, n_b, n_q, 4))
    ys = np.zeros((n_s, n_b, n_q, 3))
    ok = np.zeros((n_s, n_b, n_q), dtype=bool)
    first = order[0]
    qm[:, first], ok[:, first] = _path(params, q, np.full(n_s, b[first]), v1, v2)
    ys[:, first] = qm[:, first, :, 1:]
    prev = first
    for k in order[1:]:
        qm[:, k], ys[:, k], ok[:, k] = _solve_at_q(
            params, q, ys[:, prev], b[k], v1[:, None], v2[:, None], 1e-3
        )
        prev = k
    return qm, ok


def _as_batch(*values: ArrayLike) -> list[NDArray[np.float64]]:
    return [np.atleast_1d(np.asarray(v, dtype=float)) for v in np.broadcast_arrays(*values)]


def _path_derived(
    params: PrototypeParams,
    qm: NDArray[np.float64],
    b: NDArray[np.float64],
    v1: NDArray[np.float64],
    v2: NDArray[np.float64],
) -> dict[str, NDArray[np.float64]]:
    """Reaction force, tangent and stability along continuation solutions ``qm (..., n_q, 4)``."""
    T, t = _elimination(params)
    scale = ritz_basis(params.l).scale
    ev = potential(qm, params, b=b, v1=v1, v2=v2)
    H = ev.hess
    F = ev.grad[..., 0] / params.l**2
    A = T.T @ H @ T
    dy = -np.linalg.solve(A, (T.T @ H @ t)[..., None])[..., 0]
    dqm_dq = dy @ T.T + t
    dF_dq = np.einsum("...i,...ij,...j->...", dqm_dq, H, dqm_dq)
    eig = np.linalg.eigvalsh(H / np.multiply.outer(scale, scale))
    C, dC = capacitances(qm, params, b=b, order=1)
    dC_dq = np.einsum("...ik,...k->...i", dC, dqm_dq)
    return {
        "F": F,
        "dF_dq": dF_dq,
        "dqm_dq": dqm_dq,
        "stable": eig[..., 0] > 0,
        "lambda_1": ev.lambda_1,
        "C": C,
        "dC_dq": dC_dq,
    }


@dataclass(frozen=True)
class ForceCurve:
    """Static force-displacement path ``F(q)`` for one voltage state (Fig. 4, Fig. 5).

    Attributes
    ----------
    q : ndarray, shape (n,)
        Prescribed tip displacement [m], ascending.
    F : ndarray, shape (n,)
        External force holding the tip at ``q`` [N] (Eq. 15).
    dF_dq : ndarray, shape (n,)
        Tangent stiffness along the path [N/m].
    qm : ndarray, shape (n, 4)
        Ritz coordinates along the path [1/m, 1/m^2, 1/m^3, m].
    dqm_dq : ndarray, shape (n, 4)
        Tangent ``dq_m/dq`` along the path [1/m^3, 1/m^4, 1/m^5, -].
    stable : ndarray of bool, shape (n,)
        Hessian of ``U - F q`` positive definite (stable under the dead load ``F``).
    lambda_1 : ndarray, shape (n, 2)
        Stretches of DE 1 (left) and DE 2 (right) [-].
    C : ndarray, shape (n, 2)
        Capacitances ``C_1, C_2`` [F].
    dC_dq : ndarray, shape (n, 2)
        ``dC_i/dq`` along the path [F/m] (``g_i = 1/2 dC_i/dq``, Eq. 18, 33).
    converged : ndarray of bool, shape (n,)
        Convergence of the Newton solves.
    b, v1, v2 : float
        Pre-strain screw position [m] and voltages [V] of the curve.
    """

    q: NDArray[np.float64]
    F: NDArray[np.float64]
    dF_dq: NDArray[np.float64]
    qm: NDArray[np.float64]
    dqm_dq: NDArray[np.float64]
    stable: NDArray[np.bool_]
    lambda_1: NDArray[np.float64]
    C: NDArray[np.float64]
    dC_dq: NDArray[np.float64]
    converged: NDArray[np.bool_]
    b: float
    v1: float
    v2: float


def force_displacement(
    params: PrototypeParams,
    q: ArrayLike,
    *,
    v1: float = 0.0,
    v2: float = 0.0,
    b: float | None = None,
    guess: ArrayLike | None = None,
) -> ForceCurve:
    """Force-displacement curve ``F(q)`` by continuation in ``q`` (Fig. 4) with ``C_i(q)`` (Fig. 5).

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    q : array_like, shape (n,)
        Tip displacements [m], strictly increasing; the continuation starts at the value
        nearest to 0 (steps of at most ~0.5 mm are advisable).
    v1, v2 : float
        Voltages of DE 1 (left) and DE 2 (right) [V].
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    guess : array_like, shape (n, 4), optional
        The path ``q_m(q)`` on the same ``q`` at nearby settings (voltages, ``b``) [1/m,
        1/m^2, 1/m^3, m]: every point is solved from it in one batched Newton solve (natural
        continuation in the settings), and the continuation in ``q`` runs only if one of
        them does not converge.

    Returns
    -------
    ForceCurve
        The path, its stability and the capacitances.

    Raises
    ------
    ValueError
        If ``q`` is not one-dimensional and strictly increasing.

    Warns
    -----
    ConvergenceWarning
        If a Newton solve along the path did not converge (flagged in ``converged``).

    References
    ----------
    Masoud & Maas 2025, Eq. 15, 16, 18, Fig. 4, 5.
    """
    q = _tip_grid(q)
    b = params.b if b is None else float(b)
    bb, vv1, vv2 = _as_batch(b, v1, v2)
    ok = np.zeros((1, q.size), dtype=bool)
    if guess is not None:
        y0 = np.asarray(guess, dtype=float).reshape(q.size, 4)[:, 1:]
        path, _, ok = _solve_at_q(params, q, y0, bb[0], vv1[0], vv2[0], 1e-3)
        qm, ok = path[None], ok[None]
    if not np.all(ok):
        qm, ok = _path(params, q, bb, vv1, vv2)
    return _curve(params, q, qm[0], ok[0], bb, vv1, vv2)


def force_displacements(
    params: PrototypeParams,
    q: ArrayLike,
    states: Sequence[tuple[float, float]],
    *,
    b: float | None = None,
) -> tuple[ForceCurve, ...]:
    """Force-displacement curves of several voltage states, continued in ``q`` together.

    The paths of all states march along ``q`` in one batched Newton solve per point, each
    state by the equations and steps of :func:`force_displacement` (its own predictor,
    damping and convergence test): one pass over the grid instead of one per state.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    q : array_like, shape (n,)
        Tip displacements [m], strictly increasing (see :func:`force_displacement`).
    states : sequence of (float, float)
        Voltages ``(v1, v2)`` of DE 1 and DE 2 [V], one pair per curve.
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.

    Returns
    -------
    tuple of ForceCurve
        One per state, in the order of ``states``.

    Raises
    ------
    ValueError
        If ``q`` is not one-dimensional and strictly increasing, or ``states`` is empty.

    Warns
    -----
    ConvergenceWarning
        Per state whose path has a Newton solve that did not converge.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, 16, 18, Fig. 4, 5.
    """
    q = _tip_grid(q)
    if len(states) == 0:
        raise ValueError("`states` must hold at least one (v1, v2) pair [V]")
    b = params.b if b is None else float(b)
    v1, v2 = (np.array([float(s[i]) for s in states]) for i in (0, 1))
    bb = np.full(v1.size, b)
    qm, ok = _path(params, q, bb, v1, v2)
    return tuple(
        _curve(params, q, qm[k], ok[k], bb[k : k + 1], v1[k : k + 1], v2[k : k + 1])
        for k in range(v1.size)
    )


def _tip_grid(q: ArrayLike) -> NDArray[np.float64]:
    """``q`` as a float array, checked to be one-dimensional and strictly increasing."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 1 or q.size < 2 or np.any(np.diff(q) <= 0):
        raise ValueError("`q` must be a strictly increasing 1-D array of at least 2 values [m]")
    return q


def _curve(params, q, qm, ok, b, v1, v2) -> ForceCurve:
    """Build the :class:`ForceCurve` of one state's path ``qm`` (n, 4); b, v1, v2 (1,)."""
    if not np.all(ok):
        warnings.warn(
            f"force_displacement: {np.count_nonzero(~ok)} of {ok.size} path points did not "
            f"converge (b={b[0]}, v1={v1[0]}, v2={v2[0]})",
            ConvergenceWarning,
            stacklevel=3,
        )
    d = _path_derived(params, qm, b, v1, v2)
    return ForceCurve(q=q, qm=qm, converged=ok, b=float(b[0]), v1=float(v1[0]), v2=float(v2[0]),
                      **d)  # fmt: skip


@dataclass(frozen=True)
class Equilibrium:
    """One solution of Eq. 15.

    Attributes
    ----------
    qm : ndarray, shape (4,)
        Ritz coordinates [1/m, 1/m^2, 1/m^3, m].
    q : float
        Tip displacement [m].
    stable : bool
        All eigenvalues of the Hessian positive.
    eigenvalues : ndarray, shape (4,)
        Eigenvalues of the Hessian in the scaled coordinates ``q_m * [l^2, l^3, l^4, 1]``
        [N/m], ascending.
    lambda_1 : ndarray, shape (2,)
        DE stretches [-].
    residual : float
        Final residual of Eq. 15 in the scaled coordinates [N].
    converged : bool
        Whether Newton's method met its tolerance.
    """

    qm: NDArray[np.float64]
    q: float
    stable: bool
    eigenvalues: NDArray[np.float64]
    lambda_1: NDArray[np.float64]
    residual: float
    converged: bool


def _solve_batch(params, qm0, b, v1, v2, F):
    """Newton on Eq. 15 for a batch; returns NewtonResult plus derived arrays."""
    basis = ritz_basis(params.l)
    scale = basis.scale
    F = np.asarray(F, dtype=float)

    def fun(x):  # the generated terms: a fraction of potential()'s cost per call
        grad, hess = scalar_gradient_hessian(x, params, b, v1, v2)
        return grad - F[..., None] * basis.L, hess

    res = newton(fun, qm0, scale)
    ev = potential(res.x, params, b=b, v1=v1, v2=v2)
    eig = np.linalg.eigvalsh(ev.hess / np.multiply.outer(scale, scale))
    return res, eig, ev.lambda_1


def solve_equilibrium(
    params: PrototypeParams,
    qm0: ArrayLike,
    *,
    b: float | None = None,
    v1: float = 0.0,
    v2: float = 0.0,
    F: float = 0.0,
) -> Equilibrium:
    """Solve Eq. 15 by Newton's method (exact Hessian, line search) from one starting point.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    qm0 : array_like, shape (4,)
        Starting point [1/m, 1/m^2, 1/m^3, m].
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    v1, v2 : float
        Voltages of DE 1 (left) and DE 2 (right) [V].
    F : float
        External horizontal force at the tip [N].

    Returns
    -------
    Equilibrium
        The solution reached (check ``converged``); it may be stable or unstable.

    References
    ----------
    Masoud & Maas 2025, Eq. 15.
    """
    b = params.b if b is None else float(b)
    qm0 = np.asarray(qm0, dtype=float).reshape(4)
    res, eig, lam = _solve_batch(params, qm0, b, v1, v2, F)
    return Equilibrium(
        qm=res.x,
        q=float(res.x @ ritz_basis(params.l).L),
        stable=bool(eig[0] > 0),
        eigenvalues=eig,
        lambda_1=lam,
        residual=float(res.residual),
        converged=bool(res.converged),
    )


def _bracket_starts(q, qm, F, F_ext):
    """Interpolate starting points at the sign changes of ``F(q) - F_ext`` along a path."""
    r = F - F_ext
    idx = np.flatnonzero(np.sign(r[:-1]) != np.sign(r[1:]))
    starts = []
    for k in idx:
        denom = r[k] - r[k + 1]
        w = 0.5 if denom == 0 else r[k] / denom
        starts.append(qm[k] + w * (qm[k + 1] - qm[k]))
    return starts


def _dedup(eqs: Sequence[Equilibrium], scale, tol: float = 1e-7) -> tuple[Equilibrium, ...]:
    out: list[Equilibrium] = []
    for e in sorted(eqs, key=lambda e: e.q):
        if not any(np.max(np.abs((e.qm - o.qm) * scale)) < tol for o in out):
            out.append(e)
    return tuple(out)


def equilibria(
    params: PrototypeParams,
    *,
    b: float | None = None,
    v1: float = 0.0,
    v2: float = 0.0,
    F: float = 0.0,
    q_max: float = 25e-3,
    n_grid: int = 201,
    starts: Sequence[ArrayLike] = (),
) -> tuple[Equilibrium, ...]:
    """All physical equilibria of Eq. 15 for given pre-strain, voltages and load, sorted by ``q``.

    Newton's method on Eq. 15 from the sign changes along the continuation path, the
    straight beam, cantilever-like shapes and ``starts``; equilibria with a slack DE
    (``lambda_1 < 1``, docs/interpretation.md item 5) are dropped.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    v1, v2 : float
        Voltages of DE 1 (left) and DE 2 (right) [V].
    F : float
        External horizontal force at the tip [N].
    q_max : float
        Half width of the searched range of ``q`` [m].
    n_grid : int
        Number of continuation points on ``[-q_max, q_max]``.
    starts : sequence of array_like, shape (4,)
        Additional starting points [1/m, 1/m^2, 1/m^3, m].

    Returns
    -------
    tuple of Equilibrium
        Converged, physical, distinct equilibria in ascending ``q``.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.3-3.3.4; docs/interpretation.md item 5.

    Examples
    --------
    >>> from debist.physics.params import PrototypeParams
    >>> eqs = equilibria(PrototypeParams.paper())
    >>> [(round(e.q * 1e3, 1) + 0.0, e.stable) for e in eqs]
    [(-10.2, True), (0.0, False), (10.2, True)]
    """
    return _equilibria(params, b=b, v1=v1, v2=v2, F=F, q_max=q_max, n_grid=n_grid, starts=starts)[0]


def _equilibria(
    params, *, b=None, v1=0.0, v2=0.0, F=0.0, q_max=25e-3, n_grid=201, starts=(), guess=None
):
    """:func:`equilibria`, and the continuation path ``q_m(q)`` (n_grid, 4) it started from.

    ``guess``: such a path at nearby voltages, from which the new one is solved at once
    (:func:`force_displacement`).
    """
    b = params.b if b is None else float(b)
    q = np.linspace(-q_max, q_max, n_grid)
    if guess is None:
        qm, F_q = _path_from_rest(params, b, v1, v2, q_max, n_grid)
    else:
        curve = force_displacement(params, q, v1=v1, v2=v2, b=b, guess=guess)
        qm, F_q = curve.qm, curve.F
    L = ritz_basis(params.l).L
    x0 = list(_bracket_starts(q, qm, F_q, F))
    x0.append(np.zeros(4))
    for qq in (-20e-3, -15e-3, -10e-3, -5e-3, 5e-3, 10e-3, 15e-3, 20e-3):
        x0.append(np.array([qq / L[0], 0.0, 0.0, 0.0]))
    x0.extend(np.asarray(s, dtype=float).reshape(4) for s in starts)
    X0 = np.array(x0)
    res, eig, lam = _solve_batch(params, X0, b, v1, v2, np.full(len(X0), F))
    eqs = [
        Equilibrium(
            qm=res.x[k],
            q=float(res.x[k] @ L),
            stable=bool(eig[k, 0] > 0),
            eigenvalues=eig[k],
            lambda_1=lam[k],
            residual=float(res.residual[k]),
            converged=True,
        )
        for k in range(len(X0))
        if res.converged[k] and np.all(lam[k] >= 1.0)
    ]
    return _dedup(eqs, ritz_basis(params.l).scale), qm


@functools.lru_cache(maxsize=32)
def _path_from_rest(params, b, v1, v2, q_max, n_grid):
    """``q_m`` and ``F`` of :func:`force_displacement` on the grid of :func:`_equilibria`.

    Continued from the straight beam (no guess): a pure function of its hashable arguments,
    cached (read-only arrays), since the equilibria at several tip loads share the path (the
    load enters only their starting points): screening a fleet member at +F and -F and its
    switching thresholds' brackets at 0 V march one path instead of four.
    """
    curve = force_displacement(params, np.linspace(-q_max, q_max, n_grid), v1=v1, v2=v2, b=b)
    for a in (curve.qm, curve.F):
        a.setflags(write=False)
    return curve.qm, curve.F


def switches(params: PrototypeParams, de: int, v: float, *, F: float = 0.0) -> bool:
    """Whether ``v`` on one DE alone switches the beam: its well is gone (static, Eq. 15).

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    de : {1, 2}
        The DE at ``v``, the other at 0 V.
    v : float
        Voltage [V].
    F : float
        Constant horizontal tip force [N] (as :func:`equilibria`); default no load.

    Returns
    -------
    bool
        True if stable equilibria exist and all lie on the far side from that DE's well
        (``q > 0`` for DE 1, ``q < 0`` for DE 2).

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.4.
    """
    return _switches(params, de, v, F)[0]


def _switches(params, de, v, F, guess=None):
    """:func:`switches`, and the path of its equilibria (:func:`_equilibria`)."""
    eqs, path = _equilibria(params, F=F, guess=guess, **{f"v{de}": v})
    stable = [e for e in eqs if e.stable]
    return bool(stable) and all((e.q > 0) if de == 1 else (e.q < 0) for e in stable), path


@functools.lru_cache(maxsize=64)
def switching_voltage(
    params: PrototypeParams, de: int, *, v_max: float = V_MAX, tol: float = 1.0, F: float = 0.0
) -> float:
    """Return the static switching threshold of one DE: the lowest voltage removing its well.

    DE 1 (left) pushes the beam towards ``+q``: its threshold is the lowest ``v1`` (with
    ``v2 = 0``, no load) at which every stable equilibrium of Eq. 15 has ``q > 0``, so the
    left well is gone and the beam must snap to the right; DE 2 the same towards ``-q``.
    Found by bisection on ``[0, v_max]``; static and without friction (creep or a resonance
    switch lower). Cached per argument set: the threshold is a pure function of its
    (hashable) arguments, and each costs 10-14 static solves.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters (its anchor offsets ``dz_1``, ``dz_2`` included).
    de : {1, 2}
        The DE whose voltage rises.
    v_max, tol : float
        Upper end of the search [V] (default 3 kV); width of the final bracket [V].
    F : float
        Constant horizontal tip force [N] (as :func:`equilibria`); default no load.

    Returns
    -------
    float
        The threshold [V], to within ``tol`` above; ``0.0`` if the well on that DE's side
        does not exist at 0 V, ``math.inf`` if ``v_max`` does not remove it.

    Raises
    ------
    ValueError
        If ``de`` is not 1 or 2, or ``v_max`` or ``tol`` is not positive.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.4 and Fig. 3 (the switching limit).

    Examples
    --------
    >>> from debist.physics.params import PrototypeParams
    >>> round(switching_voltage(PrototypeParams.paper(), 1, tol=10.0), -1)
    1430.0
    """
    if de not in (1, 2):
        raise ValueError(f"`de` must be 1 or 2, got {de!r}")
    if not (v_max > 0 and tol > 0):
        raise ValueError(f"`v_max` and `tol` must be positive, got {v_max!r} and {tol!r}")
    at_lo, path_lo = _switches(params, de, 0.0, F)
    if at_lo:
        return 0.0
    at_hi, path_hi = _switches(params, de, float(v_max), F)
    if not at_hi:
        return float("inf")
    lo, hi = 0.0, float(v_max)
    while hi - lo > tol:  # each path solved at once from the last one's (natural continuation)
        mid = 0.5 * (lo + hi)
        at_mid, path = _switches(params, de, mid, F, path_hi if hi - mid < mid - lo else path_lo)
        if at_mid:
            hi, path_hi = mid, path
        else:
            lo, path_lo = mid, path
    return hi
