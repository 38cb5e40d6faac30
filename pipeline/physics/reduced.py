"""Reduced one-coordinate model of Eq. 24-26 and its comparison with the full model (Fig. 6b, 7).

The Ritz coordinates are written as functions of the tip displacement, ``q_m(q)`` (Eq. 24),
by fitting polynomials to the static solutions along the force-displacement continuation at
``v = 0`` (Fig. 6b): ``q_3(q), q_4(q), u_0(q)`` are fitted and ``q_2`` follows from
``q = L . q_m`` exactly. Substituting into Eq. 8-12 (Hamilton's principle on ``q``) gives

    m_q(q) q_ddot + 1/2 m_q'(q) q_dot^2 + d(q) q_dot + f(q) + sum_i k_bar_i(q) q_eps,i
        = g_1(q) v_1^2 + g_2(q) v_2^2 + F,
    q_eps,i_dot = k_i(q) q_dot - Y_MW / eta_MW q_eps,i,

with ``Phi = dq_m/dq``, ``m_q = Phi^T M Phi``, ``d = Phi^T D Phi``, ``f = dU_mech/dq``,
``g_i = 1/2 dC_i/dq`` (Eq. 18, 33), ``k_i = d lambda_3,i/dq``, ``k_bar_i = V_DE Y_MW k_i``. The
term ``1/2 m_q' q_dot^2`` follows from ``m_q(q)`` (Eq. 26 writes a constant ``m_q``; here it is
kept, it is exact and small). In the convention of the identified model (Eq. 33, 37)
``f(q) = c(q) q``.

References
----------
Masoud & Maas 2025, Eq. 18, 24-26, 33, 37, 41, Fig. 6b, 7.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Chebyshev
from numpy.typing import ArrayLike, NDArray

from debist.core.metrics import nrmse
from debist.physics.dynamics import FullModel, SimulationResult, simulate, well_state
from debist.physics.energy import potential
from debist.physics.kinematics import ritz_basis
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.segments import solve_segments
from debist.physics.statics import force_displacement

__all__ = [
    "Comparison",
    "ReducedCurves",
    "ReducedModel",
    "ReducedResult",
    "compare_full_reduced",
    "fit_reduced",
    "reduced_curves",
    "simulate_reduced",
    "switching_profile",
]

Signal = Callable[[float], float]


@dataclass(frozen=True)
class ReducedCurves:
    """Characteristic curves of the reduced model on a grid of ``q`` (Eq. 26, 33).

    Attributes
    ----------
    q : ndarray, shape (n,)
        Tip displacement [m].
    m_q : ndarray, shape (n,)
        Generalised mass ``Phi^T M Phi`` [kg].
    dm_q : ndarray, shape (n,)
        ``dm_q/dq`` [kg/m].
    d : ndarray, shape (n,)
        Damping ``Phi^T D Phi`` [N s/m].
    f : ndarray, shape (n,)
        Restoring force ``dU_mech/dq`` at ``v = 0`` [N].
    c : ndarray, shape (n,)
        Stiffness ``f(q) / q`` of the convention ``f = c(q) q`` (Eq. 29, 33) [N/m]; at
        ``q = 0`` the limit ``df/dq``.
    k : ndarray, shape (n,)
        Tangent stiffness ``df/dq`` [N/m].
    g1, g2 : ndarray, shape (n,)
        ``g_i = 1/2 dC_i/dq`` (Eq. 18, 33) [F/m]; the electrostatic force is ``g_i v_i^2``
        and ``dC_i/dq = 2 g_i`` (docs/interpretation.md item 8).
    C1, C2 : ndarray, shape (n,)
        Capacitances [F].
    k1, k2 : ndarray, shape (n,)
        Creep coupling ``d lambda_3,i / dq`` [1/m] (Eq. 26).
    k_bar1, k_bar2 : ndarray, shape (n,)
        ``V_DE Y_MW k_i`` [N].
    phi : ndarray, shape (n,)
        Pitch angle ``arctan(w'(l))`` along ``q_m(q)`` (Eq. 1) [rad].
    """

    q: NDArray[np.float64]
    m_q: NDArray[np.float64]
    dm_q: NDArray[np.float64]
    d: NDArray[np.float64]
    f: NDArray[np.float64]
    c: NDArray[np.float64]
    k: NDArray[np.float64]
    g1: NDArray[np.float64]
    g2: NDArray[np.float64]
    C1: NDArray[np.float64]
    C2: NDArray[np.float64]
    k1: NDArray[np.float64]
    k2: NDArray[np.float64]
    k_bar1: NDArray[np.float64]
    k_bar2: NDArray[np.float64]
    phi: NDArray[np.float64]


class ReducedModel:
    """The reduced model of Eq. 24-26: polynomial ``q_m(q)`` and the curves it implies.

    Use :func:`fit_reduced` to build one.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    b : float
        Pre-strain screw position [m].
    polys : tuple of numpy.polynomial.Chebyshev
        Fitted polynomials ``q_3(q), q_4(q), u_0(q)`` [1/m^2, 1/m^3, m], ``q`` in metres.
    q_range : tuple of float
        Range of the fit [m]; the curves are extrapolated outside.
    fit_residual : float
        Largest fit error in the scaled coordinates ``q_m * [l^2, l^3, l^4, 1]`` [m].

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26.
    """

    def __init__(
        self,
        params: PrototypeParams,
        b: float,
        polys: tuple[Chebyshev, Chebyshev, Chebyshev],
        q_range: tuple[float, float],
        fit_residual: float,
    ):
        self.params = params
        self.b = float(b)
        self.polys = polys
        # q_m and its first two derivatives, differentiated once here, not at every call
        self._derivs = tuple(tuple(P.deriv(der) if der else P for P in polys) for der in (0, 1, 2))
        self.q_range = q_range
        self.fit_residual = float(fit_residual)
        self._full = FullModel(params, lambda t: 0.0, lambda t: 0.0, b=b)
        p = params
        self._relax = p.Y_MW / p.eta_MW if p.eta_MW > 0 else 0.0
        self._kbar = p.V_DE * p.Y_MW

    def _y(self, q: NDArray[np.float64], der: int) -> NDArray[np.float64]:
        return np.stack([P(q) for P in self._derivs[der]], axis=-1)

    def qm(self, q: ArrayLike, der: int = 0) -> NDArray[np.float64]:
        """Ritz coordinates ``q_m(q)`` (Eq. 24) or their ``der``-th derivative in ``q``.

        Parameters
        ----------
        q : array_like, shape (...)
            Tip displacement [m].
        der : {0, 1, 2}
            Order of the derivative with respect to ``q``.

        Returns
        -------
        ndarray, shape (..., 4)
            ``d^der q_m / dq^der``.
        """
        q = np.asarray(q, dtype=float)
        l = self.params.l  # noqa: E741
        y = self._y(q, der)
        lin = {0: q, 1: np.ones_like(q), 2: np.zeros_like(q)}[der]
        q2 = (lin - l**3 * y[..., 0] - l**4 * y[..., 1]) / l**2
        return np.concatenate([q2[..., None], y], axis=-1)

    def phi(self, q: ArrayLike) -> NDArray[np.float64]:
        """Pitch angle ``phi(q) = arctan(w'(l))`` along ``q_m(q)`` (Eq. 1, 24).

        Parameters
        ----------
        q : array_like, shape (...)
            Tip displacement [m].

        Returns
        -------
        ndarray, shape (...)
            ``phi`` [rad].

        References
        ----------
        Masoud & Maas 2025, Eq. 1, 24.
        """
        return np.arctan(self.qm(q) @ ritz_basis(self.params.l).S)

    def _point(self, q: float):
        """Scalar terms at one ``q``: m_q, dm_q, d, f (v=0), g (2,), k (2,)."""
        return self._point_at(self.qm(q), self.qm(q, 1), self.qm(q, 2))

    def _point_at(self, qm, Phi, dPhi):
        """:meth:`_point` from ``q_m``, ``Phi`` and ``dPhi`` at the point (4,) each."""
        grad, length, dlen = self._full._terms(qm, 0.0)
        M, D, K, g_uy = self._full._mats(qm, length, dlen)
        p = self.params
        MPhi = M @ Phi
        g_dot = np.append(-self._full._P1 @ Phi[:3], 0.0)
        m_q = Phi @ MPhi
        dm_q = 2.0 * dPhi @ MPhi + 2.0 * p.m * (g_dot @ Phi) * (g_uy @ Phi)
        g = 0.5 * p.C_0 / p.l_0 * (dlen @ Phi)
        return m_q, dm_q, Phi @ D @ Phi, grad @ Phi, g, K.T @ Phi

    def curves(self, q: ArrayLike) -> ReducedCurves:
        """Characteristic curves on a grid (Eq. 26 in the convention of Eq. 33).

        Parameters
        ----------
        q : array_like, shape (n,)
            Tip displacements [m].

        Returns
        -------
        ReducedCurves
            ``m_q, d, f, c, g1, g2, k1, k2, ...`` on ``q``.

        References
        ----------
        Masoud & Maas 2025, Eq. 18, 26, 29, 33.
        """
        p = self.params
        q = np.atleast_1d(np.asarray(q, dtype=float))
        qm, Phi, dPhi = self.qm(q), self.qm(q, 1), self.qm(q, 2)
        ev = potential(qm, p, b=self.b, order=2)
        f = np.sum(ev.grad * Phi, axis=-1)
        k = np.einsum("ni,nij,nj->n", Phi, ev.hess, Phi) + np.sum(ev.grad * dPhi, axis=-1)
        rows = [self._point_at(*point) for point in zip(qm, Phi, dPhi, strict=True)]
        m_q, dm_q, d = (np.array([r[i] for r in rows]) for i in range(3))
        g = np.array([r[4] for r in rows])
        kk = np.array([r[5] for r in rows])
        small = np.abs(q) < 1e-12
        c = np.where(small, k, f / np.where(small, 1.0, q))
        C = p.C_0 / p.l_0 * np.array([self._full._terms(x, 0.0)[1] for x in qm])
        return ReducedCurves(
            q=q, m_q=m_q, dm_q=dm_q, d=d, f=f, c=c, k=k, g1=g[:, 0], g2=g[:, 1],
            C1=C[:, 0], C2=C[:, 1], k1=kk[:, 0], k2=kk[:, 1],
            k_bar1=self._kbar * kk[:, 0], k_bar2=self._kbar * kk[:, 1], phi=self.phi(q),
        )  # fmt: skip

    def rhs(self, t: float, x: NDArray[np.float64], v1: Signal, v2: Signal, F: Signal | None):
        """State derivative of Eq. 26, ``x = [q, q_dot, q_eps,1, q_eps,2]``.

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (4,)
            State [m, m/s, -, -].
        v1, v2 : callable
            ``v_i(t)`` [V].
        F : callable or None
            External tip force ``F(t)`` [N].

        Returns
        -------
        ndarray, shape (4,)
            ``x_dot``.

        References
        ----------
        Masoud & Maas 2025, Eq. 26.
        """
        q, qd, qe = x[0], x[1], x[2:]
        m_q, dm_q, d, f, g, k = self._point(q)
        force = g[0] * v1(t) ** 2 + g[1] * v2(t) ** 2 + (0.0 if F is None else F(t))
        force -= 0.5 * dm_q * qd * qd + d * qd + f + self._kbar * (k @ qe)
        return np.array([qd, force / m_q, k[0] * qd - self._relax * qe[0],
                         k[1] * qd - self._relax * qe[1]])  # fmt: skip


@functools.lru_cache(maxsize=16)
def fit_reduced(
    params: PrototypeParams,
    *,
    q_max: float = 25e-3,
    n_points: int = 401,
    degree: int = 30,
    b: float | None = None,
) -> ReducedModel:
    """Fit ``q_m(q)`` (Eq. 24) to the static path at ``v = 0`` and build the reduced model.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    q_max : float
        The path is computed on ``[-q_max, q_max]`` [m]; it should cover the simulated motion
        (overshoot included).
    n_points : int
        Points of the static path.
    degree : int
        Degree of the least-squares polynomials (Chebyshev basis). The path has a narrow
        feature around ``q = 0`` (the S-shaped Ritz mode is soft there), so the fit converges
        slowly: degree 12 leaves errors of ~1 mm in ``q_m * [l^2, l^3, l^4, 1]``, degree 30
        about 10 um.
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.

    Returns
    -------
    ReducedModel
        The fitted model (``fit_residual`` reports the fit quality). Results are cached per
        argument set (the parameters are immutable), so the stages of one run that need the
        same prototype's model fit it once.

    References
    ----------
    Masoud & Maas 2025, Eq. 24, 25, Fig. 6b.
    """
    b = params.b if b is None else float(b)
    q = np.linspace(-q_max, q_max, n_points)
    curve = force_displacement(params, q, b=b)
    polys = tuple(
        Chebyshev.fit(q, curve.qm[:, k], degree, domain=[-q_max, q_max]) for k in (1, 2, 3)
    )
    model = ReducedModel(params, b, polys, (-q_max, q_max), 0.0)
    err = (model.qm(q) - curve.qm) * ritz_basis(params.l).scale
    return ReducedModel(params, b, polys, (-q_max, q_max), float(np.max(np.abs(err))))


def reduced_curves(
    params: PrototypeParams, q_grid: ArrayLike, *, b: float | None = None
) -> ReducedCurves:
    """Physical backbone curves ``m_q, c, d, g1, g2`` of the reduced model on ``q_grid``.

    Fits the reduced model with :func:`fit_reduced` (covering ``q_grid``) and evaluates
    :meth:`ReducedModel.curves`. Conventions as the identified model (Eq. 33, 37):
    ``f(q) = c(q) q``, ``g_i = 1/2 dC_i/dq``.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    q_grid : array_like, shape (n,)
        Tip displacements [m].
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.

    Returns
    -------
    ReducedCurves
        The curves on ``q_grid``.

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 29, 33; docs/interpretation.md item 8.
    """
    q_grid = np.asarray(q_grid, dtype=float)
    q_max = max(25e-3, float(np.max(np.abs(q_grid))) if q_grid.size else 0.0)
    # b only when given: lru_cache keys on the keywords as passed, so that this call and
    # fit_reduced(params, q_max=...) elsewhere (the analytical model) share one fit
    model = fit_reduced(params, q_max=q_max) if b is None else fit_reduced(params, q_max=q_max, b=b)
    return model.curves(q_grid)


@dataclass(frozen=True)
class ReducedResult:
    """Trajectory of the reduced model.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time [s].
    x : ndarray, shape (n, 4)
        States ``[q, q_dot, q_eps,1, q_eps,2]``.
    q : ndarray, shape (n,)
        Tip displacement [m].
    phi : ndarray, shape (n,)
        Pitch angle along ``q_m(q)`` [rad].
    success : bool
        Whether every integration segment succeeded.
    nfev : int
        Number of right-hand-side evaluations.
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    q: NDArray[np.float64]
    phi: NDArray[np.float64]
    success: bool
    nfev: int


def simulate_reduced(
    model: ReducedModel,
    v1: Signal,
    v2: Signal,
    t_span: tuple[float, float],
    x0: ArrayLike,
    *,
    t_eval: ArrayLike | None = None,
    F: Signal | None = None,
    breakpoints: Sequence[float] = (),
    method: str = "DOP853",
    rtol: float = 1e-8,
    atol: float = 1e-11,
) -> ReducedResult:
    """Simulate the reduced model Eq. 26 with :func:`scipy.integrate.solve_ivp`.

    Parameters
    ----------
    model : ReducedModel
        From :func:`fit_reduced`.
    v1, v2 : callable
        ``v_i(t)`` [V].
    t_span : tuple of float
        Start and end time [s].
    x0 : array_like, shape (4,)
        Initial state ``[q, q_dot, q_eps,1, q_eps,2]``.
    t_eval : array_like, optional
        Output times [s]; default 1 ms spacing.
    F : callable, optional
        External tip force ``F(t)`` [N].
    breakpoints : sequence of float
        Times of input discontinuities [s]; the integration is split there.
    method : str
        :func:`solve_ivp` method (the reduced model is not stiff).
    rtol, atol : float
        Tolerances (``atol`` in metres and m/s).

    Returns
    -------
    ReducedResult
        The trajectory.

    References
    ----------
    Masoud & Maas 2025, Eq. 26, Fig. 7.
    """
    t0, t1 = map(float, t_span)
    t_eval = np.arange(t0, t1 + 5e-4, 1e-3) if t_eval is None else np.asarray(t_eval, float)
    sol = solve_segments(
        model.rhs, (t0, t1), x0, t_eval, breakpoints, method=method, rtol=rtol, atol=atol,
        args=(v1, v2, F),
    )  # fmt: skip
    t, X, ok, nfev = sol.t, sol.y, sol.success, sol.nfev
    return ReducedResult(t=t, x=X, q=X[:, 0], phi=model.phi(X[:, 0]), success=ok, nfev=nfev)


def switching_profile(
    *,
    v: float = V_MAX,
    left: tuple[float, float] = (0.5, 1.5),
    right: tuple[float, float] = (2.5, 3.5),
) -> tuple[Signal, Signal, tuple[float, ...]]:
    """Voltage steps of Fig. 7: DE 1 (left) at ``v`` during ``left``, then DE 2 during ``right``.

    Parameters
    ----------
    v : float
        Step height [V].
    left, right : tuple of float
        On and off times of DE 1 and DE 2 [s].

    Returns
    -------
    v1, v2 : callable
        ``v_i(t)`` [V].
    breakpoints : tuple of float
        The switching times [s].

    References
    ----------
    Masoud & Maas 2025, Fig. 7.
    """

    def v1(t: float) -> float:
        return v if left[0] <= t < left[1] else 0.0

    def v2(t: float) -> float:
        return v if right[0] <= t < right[1] else 0.0

    return v1, v2, (*left, *right)


@dataclass(frozen=True)
class Comparison:
    """Full versus reduced model under the same input (Fig. 7).

    Attributes
    ----------
    full : SimulationResult
        Full model trajectory.
    reduced : ReducedResult
        Reduced model trajectory on the same time grid.
    model : ReducedModel
        The reduced model used.
    v1, v2 : ndarray, shape (n,)
        Voltages [V].
    nrmse_q : float
        NRMSE of ``q`` (Eq. 41) with the full model as reference [-].
    nrmse_phi : float
        NRMSE of ``phi`` (Eq. 41) with the full model as reference [-].
    """

    full: SimulationResult
    reduced: ReducedResult
    model: ReducedModel
    v1: NDArray[np.float64]
    v2: NDArray[np.float64]
    nrmse_q: float
    nrmse_phi: float


def compare_full_reduced(
    params: PrototypeParams,
    *,
    t_end: float = 5.0,
    side: int = -1,
    profile: tuple[Signal, Signal, Sequence[float]] | None = None,
    dt: float = 1e-3,
    model: ReducedModel | None = None,
) -> Comparison:
    """Simulate the full and the reduced model with the same voltages (Fig. 7).

    Both start at rest in the well ``side`` (-1 left, +1 right) with relaxed Maxwell strains.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    t_end : float
        Duration [s].
    side : {-1, +1}
        Initial well.
    profile : (v1, v2, breakpoints), optional
        Input; default :func:`switching_profile` (left DE 3 kV on [0.5, 1.5) s, right DE
        3 kV on [2.5, 3.5) s).
    dt : float
        Output sampling interval [s].
    model : ReducedModel, optional
        Reduced model; :func:`fit_reduced` if omitted.

    Returns
    -------
    Comparison
        Both trajectories and the NRMSE of ``q`` and ``phi``.

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 41, Fig. 7.
    """
    v1, v2, bp = switching_profile() if profile is None else profile
    model = fit_reduced(params) if model is None else model
    t_eval = np.arange(0.0, t_end + 0.5 * dt, dt)
    x0 = well_state(params, side, b=model.b)
    full = simulate(params, v1, v2, (0.0, t_end), x0, t_eval=t_eval, b=model.b, breakpoints=bp)
    q0 = float(x0[:4] @ ritz_basis(params.l).L)
    red = simulate_reduced(model, v1, v2, (0.0, t_end), [q0, 0.0, 0.0, 0.0], t_eval=t_eval,
                           breakpoints=bp)  # fmt: skip
    return Comparison(
        full=full,
        reduced=red,
        model=model,
        v1=full.v1,
        v2=full.v2,
        nrmse_q=nrmse(full.q, red.q, on_constant="nan"),
        nrmse_phi=nrmse(full.phi, red.phi, on_constant="nan"),
    )
