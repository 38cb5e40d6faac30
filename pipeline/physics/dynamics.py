"""Full state-space model of the bistable DE actuator (Eq. 8, 12, 19-23) and its SVD mode analysis.

State ``x = [q_m, q_m_dot, q_eps]`` with ``q_m = [q_2, q_3, q_4, u_0]`` and the Maxwell strains
``q_eps = [eps_E,1, eps_E,2]`` of the left and right DE (Eq. 20):

    M(q_m) q_m_ddot + c(q_m, q_m_dot) + D(q_m) q_m_dot + dU/dq_m + K_bar(q_m) q_eps = F dq/dq_m
    q_eps_dot = K(q_m)^T q_m_dot - Y_MW / eta_MW q_eps

* ``M`` from the kinetic energy Eq. 8 with the Ritz shape: the tip mass ``m`` moving with
  ``q_dot`` and ``u_y_dot`` plus the beam's ``rho (I w_dot'^2 + A w_dot^2)``;
* ``c = m (q_m_dot^T d^2u_y/dq_m^2 q_m_dot) du_y/dq_m`` is the convective term of the
  Lagrange equations that ``M(q_m)`` implies (Eq. 19 omits it; it is exact and cheap);
* ``D = 2 eta I int B'' B''^T dx + V_DE eta_v K K^T`` from the beam term of Eq. 12 and the
  Kelvin-Voigt viscosity of the DEs;
* ``dU/dq_m`` includes the electrostatic term, i.e. ``f_F - 1/2 dC_i/dq_m v_i^2`` of Eq. 19, 23;
* ``K = [d lambda_3,1/dq_m, d lambda_3,2/dq_m]`` (4 x 2), ``K_bar = V_DE Y_MW K`` (Eq. 12, 19).

:class:`FullModel` evaluates the right-hand side and Jacobian with the compiled kernels of
:mod:`debist.physics.compiled` (numba, imported on first use); ``compiled=False`` selects
the NumPy implementation here, the reference the kernels are tested against.

References
----------
Masoud & Maas 2025, Eq. 8, 12, 19-23, Fig. 6a; docs/interpretation.md items 3, 6.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics import _generated
from debist.physics.energy import HESS_INDEX, generated_constants
from debist.physics.kinematics import de_lengths, deflection, pitch_angle, ritz_basis
from debist.physics.params import PrototypeParams
from debist.physics.segments import solve_segments
from debist.physics.statics import equilibria

__all__ = [
    "FullModel",
    "ModeAnalysis",
    "SimulationResult",
    "mode_analysis",
    "simulate",
    "well_state",
]

Signal = Callable[[float], float]


def _zero(t: float) -> float:
    return 0.0


def _kernels():
    """Return the compiled kernels (numba is imported on first use, not with this module)."""
    # here, not at the top: numba loads and compiles the kernel on first use only
    from debist.physics import compiled

    return compiled


class FullModel:
    """Right-hand side and Jacobian of the state-space model Eq. 21-22.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    v1, v2 : callable
        ``v_i(t)`` [V] of DE 1 (left) and DE 2 (right).
    F : callable, optional
        External horizontal tip force ``F(t)`` [N]; zero if omitted.
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    compiled : bool
        Evaluate :meth:`rhs` and :meth:`jac` with the compiled kernels of
        :mod:`debist.physics.compiled` (default; the same equations, equal to the NumPy
        implementation to rounding, see there) or with NumPy (``False``, the reference).

    References
    ----------
    Masoud & Maas 2025, Eq. 19-23.
    """

    n_states = 10

    def __init__(
        self,
        params: PrototypeParams,
        v1: Signal,
        v2: Signal,
        F: Signal | None = None,
        b: float | None = None,
        *,
        compiled: bool = True,
    ):
        p = params
        self.params = p
        self.compiled = bool(compiled)
        self._packed = None
        self.v1, self.v2 = v1, v2
        self.F = _zero if F is None else F
        self.b = p.b if b is None else float(b)
        basis = ritz_basis(p.l)
        self._L = basis.L
        self._P1 = basis.P1
        M0 = np.zeros((4, 4))
        M0[:3, :3] = p.rho * (p.I * basis.P1 + p.A * basis.P0)
        self._M0 = M0 + p.m * np.outer(basis.L, basis.L)
        D0 = np.zeros((4, 4))
        D0[:3, :3] = 2.0 * p.eta * p.I * basis.P2
        self._D0 = D0
        self._relax = p.Y_MW / p.eta_MW if p.eta_MW > 0 else 0.0
        self._kbar = p.V_DE * p.Y_MW
        self._consts = generated_constants(p)
        self._sym = HESS_INDEX

    def _fp(self) -> NDArray[np.float64]:
        """Return the model as the compiled kernels take it (packed on first use)."""
        if self._packed is None:
            self._packed = _kernels().pack_model(self)
        return self._packed

    def _terms(self, qm: NDArray[np.float64], t: float, hess: bool = False):
        """Evaluate the generated terms: grad U, DE lengths and gradients (and the Hessian)."""
        w1, w2 = float(self.v1(t)) ** 2, float(self.v2(t)) ** 2
        # Python floats: the generated scalar code runs twice as fast as on numpy scalars
        args = (*np.asarray(qm, dtype=float).tolist(), self.b, w1, w2, *self._consts)
        grad, length, dlen = _generated.grad_terms(*args)
        out = [np.array(grad), np.array(length), np.array(dlen).reshape(2, 4)]
        if hess:
            out.append(np.array(_generated.hess_terms(*args))[self._sym])
        return out

    def _g_uy_and_mass(self, qm):
        """``d u_y / d q_m`` (Eq. 8) and the mass matrix it implies (Eq. 19)."""
        g_uy = np.ones(4)
        g_uy[:3] = -self._P1 @ qm[:3]
        return g_uy, self._M0 + self.params.m * np.outer(g_uy, g_uy)

    def _mats(self, qm, length, dlen):
        p = self.params
        g_uy, M = self._g_uy_and_mass(qm)
        lam = length / p.l_0
        K = (-0.5 * lam**-1.5 / p.l_0)[:, None] * dlen  # (2, 4): d lambda_3,i / d q_m
        D = self._D0 + p.V_DE * p.eta_v * K.T @ K
        return M, D, K.T, g_uy

    def matrices(self, qm: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """Mass, damping and creep matrices at ``q_m`` (Eq. 19, 21).

        Parameters
        ----------
        qm : array_like, shape (4,)
            Ritz coordinates [1/m, 1/m^2, 1/m^3, m].

        Returns
        -------
        dict
            ``"M"`` (4, 4) mass matrix [kg m^2 / (unit of q_m)^2], ``"D"`` (4, 4) damping
            matrix, ``"K"`` (4, 2) ``d lambda_3,i / d q_m``, ``"K_bar"`` (4, 2)
            ``= V_DE Y_MW K`` and ``"g_uy"`` (4,) ``d u_y / d q_m``.

        References
        ----------
        Masoud & Maas 2025, Eq. 8, 12, 19.
        """
        qm = np.asarray(qm, dtype=float)
        length, dlen = de_lengths(qm, self.params, b=self.b, order=1)
        M, D, K, g_uy = self._mats(qm, length, dlen)
        return {"M": M, "D": D, "K": K, "K_bar": self._kbar * K, "g_uy": g_uy}

    def _force(self, t: float, x: NDArray[np.float64], hess: bool = False, F_extra: float = 0.0):
        qm, qd, qe = x[:4], x[4:8], x[8:]
        terms = self._terms(qm, t, hess)
        M, D, K, g_uy = self._mats(qm, terms[1], terms[2])
        wd = qd[:3]
        conv = -self.params.m * (wd @ self._P1 @ wd) * g_uy
        F_tip = self.F(t) + F_extra
        force = F_tip * self._L - conv - D @ qd - terms[0] - self._kbar * (K @ qe)
        return force, M, D, K, g_uy, terms

    def mass_matrix(self, qm: ArrayLike) -> NDArray[np.float64]:
        """Mass matrix ``M(q_m)`` of Eq. 19 (cheaper than :meth:`matrices`).

        Parameters
        ----------
        qm : array_like, shape (4,)
            Ritz coordinates [1/m, 1/m^2, 1/m^3, m].

        Returns
        -------
        ndarray, shape (4, 4)
            ``M`` [kg m^2 / (unit of q_m)^2].

        References
        ----------
        Masoud & Maas 2025, Eq. 8, 19.
        """
        return self._g_uy_and_mass(np.asarray(qm, dtype=float))[1]

    def rhs(self, t: float, x: NDArray[np.float64], F_extra: float = 0.0) -> NDArray[np.float64]:
        """State derivative ``x_dot = f(x, u)`` (Eq. 22).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (10,)
            State ``[q_m, q_m_dot, q_eps]``.
        F_extra : float
            Horizontal tip force [N] added to ``F(t)``; a hook for forces that depend on
            states outside the model (e.g. friction, :mod:`debist.rig.plant`).

        Returns
        -------
        ndarray, shape (10,)
            ``x_dot``.

        References
        ----------
        Masoud & Maas 2025, Eq. 21-23.
        """
        if self.compiled:
            w1, w2 = float(self.v1(t)) ** 2, float(self.v2(t)) ** 2
            F_tip = float(self.F(t)) + F_extra
            x = np.ascontiguousarray(x, dtype=float)
            return _kernels().full_rhs(x, w1, w2, F_tip, self._fp())
        force, M, _, K, _, _ = self._force(t, x, F_extra=F_extra)
        qd, qe = x[4:8], x[8:]
        return np.concatenate([qd, np.linalg.solve(M, force), K.T @ qd - self._relax * qe])

    def jac(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian of :meth:`rhs` without the derivatives of M, D and K along ``q_m``.

        The omitted terms are of the order of the velocities and creep strains; the matrix is
        used by the implicit integrator's Newton iterations only, not for the solution.

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (10,)
            State.

        Returns
        -------
        ndarray, shape (10, 10)
            Approximate ``d x_dot / d x`` (the same for any ``F_extra`` of :meth:`rhs`,
            which enters additively).
        """
        if self.compiled:
            w1, w2 = float(self.v1(t)) ** 2, float(self.v2(t)) ** 2
            x = np.ascontiguousarray(x, dtype=float)
            return _kernels().full_jac(x, w1, w2, self._fp())
        _, M, D, K, g_uy, terms = self._force(t, x, hess=True)
        Minv = np.linalg.inv(M)
        dconv = np.zeros((4, 4))
        dconv[:, :3] = -2.0 * self.params.m * np.outer(g_uy, self._P1 @ x[4:7])
        J = np.zeros((10, 10))
        J[:4, 4:8] = np.eye(4)
        J[4:8, :4] = -Minv @ terms[3]
        J[4:8, 4:8] = -Minv @ (D + dconv)
        J[4:8, 8:] = -Minv @ (self._kbar * K)
        J[8:, 4:8] = K.T
        J[8:, 8:] = -self._relax * np.eye(2)
        return J


@dataclass(frozen=True)
class SimulationResult:
    """Trajectory of the full model.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time [s].
    x : ndarray, shape (n, 10)
        States ``[q_m, q_m_dot, q_eps]``.
    q : ndarray, shape (n,)
        Tip displacement [m] (output Eq. 22).
    phi : ndarray, shape (n,)
        Pitch angle [rad] (Eq. 1).
    v1, v2 : ndarray, shape (n,)
        Voltages [V].
    success : bool
        Whether every integration segment succeeded.
    message : str
        Messages of the integrator.
    nfev : int
        Number of right-hand-side evaluations.
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    q: NDArray[np.float64]
    phi: NDArray[np.float64]
    v1: NDArray[np.float64]
    v2: NDArray[np.float64]
    success: bool
    message: str
    nfev: int

    @property
    def qm(self) -> NDArray[np.float64]:
        """Ritz coordinates, shape (n, 4)."""
        return self.x[:, :4]


def well_state(
    params: PrototypeParams, side: int = -1, *, b: float | None = None, F: float = 0.0
) -> NDArray[np.float64]:
    """State vector at rest in the left (``side=-1``) or right (``side=+1``) well, v = 0.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    side : {-1, +1}
        Which well.
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    F : float
        Constant horizontal tip force [N] (as :func:`~debist.physics.statics.equilibria`).

    Returns
    -------
    ndarray, shape (10,)
        ``[q_m, 0, 0]`` at the stable equilibrium with ``side * q > 1 um``.

    Raises
    ------
    ValueError
        If there is no stable equilibrium on that side.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, 20.
    """
    eqs = [e for e in equilibria(params, b=b, F=F) if e.stable and side * e.q > 1e-6]
    if not eqs:
        raise ValueError(f"no stable equilibrium with sign(q) = {side} (b = {b})")
    e = max(eqs, key=lambda e: abs(e.q))
    return np.concatenate([e.qm, np.zeros(6)])


def simulate(
    params: PrototypeParams,
    v1: Signal,
    v2: Signal,
    t_span: tuple[float, float],
    x0: ArrayLike,
    *,
    t_eval: ArrayLike | None = None,
    F: Signal | None = None,
    b: float | None = None,
    breakpoints: Sequence[float] = (),
    method: str = "BDF",
    rtol: float = 1e-6,
    atol: float = 1e-9,
) -> SimulationResult:
    """Simulate the full model Eq. 21 with :func:`scipy.integrate.solve_ivp`.

    The integration is split at ``breakpoints`` (discontinuities of the inputs) so that the
    step-size control never straddles a voltage step.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters.
    v1, v2 : callable
        ``v_i(t)`` [V].
    t_span : tuple of float
        Start and end time [s].
    x0 : array_like, shape (10,)
        Initial state (e.g. :func:`well_state`).
    t_eval : array_like, shape (n,), optional
        Output times [s]; default 1 ms spacing.
    F : callable, optional
        External tip force ``F(t)`` [N].
    b : float, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    breakpoints : sequence of float
        Times of input discontinuities [s].
    method : str
        A stiff :func:`solve_ivp` method: ``"BDF"`` (default) or ``"Radau"``, both with the
        approximate Jacobian of :meth:`FullModel.jac`, or ``"LSODA"``.
    rtol, atol : float
        Tolerances; ``atol`` applies to the states scaled to metres (``q_m`` times
        ``[l^2, l^3, l^4, 1]``, the same for the velocities [m/s]) and to ``q_eps`` [-].

    Returns
    -------
    SimulationResult
        The trajectory (``success`` is False if an integration segment failed).

    References
    ----------
    Masoud & Maas 2025, Eq. 19-23, Fig. 7.
    """
    model = FullModel(params, v1, v2, F=F, b=b)
    t0, t1 = map(float, t_span)
    t_eval = np.arange(t0, t1 + 5e-4, 1e-3) if t_eval is None else np.asarray(t_eval, float)
    s = ritz_basis(params.l).scale
    atol_v = np.concatenate([atol / s, atol / s, [atol, atol]])
    kw = {"jac": model.jac} if method in ("Radau", "BDF") else {}
    sol = solve_segments(
        model.rhs, (t0, t1), x0, t_eval, breakpoints, method=method, rtol=rtol, atol=atol_v, **kw
    )
    t, X = sol.t, sol.y
    return SimulationResult(
        t=t,
        x=X,
        q=X[:, :4] @ ritz_basis(params.l).L,
        phi=pitch_angle(X[:, :4], params),
        v1=np.array([v1(tt) for tt in t]),
        v2=np.array([v2(tt) for tt in t]),
        success=sol.success,
        message=sol.message,
        nfev=sol.nfev,
    )


@dataclass(frozen=True)
class ModeAnalysis:
    """SVD of a simulated deflection field (Fig. 6a).

    Attributes
    ----------
    x : ndarray, shape (n_x,)
        Positions along the beam [m].
    modes : ndarray, shape (n_x, r)
        Spatial modes (left singular vectors, unit 2-norm, sign chosen so that the tip value
        is positive).
    singular_values : ndarray, shape (r,)
        Singular values [m], descending.
    coefficients : ndarray, shape (n_t, r)
        Time coefficients ``sigma_k v_k(t)`` [m]: ``w(x, t) = sum_k modes[:, k] coef[t, k]``.
    energy_fraction : ndarray, shape (r,)
        ``sigma_k^2 / sum sigma^2``.
    """

    x: NDArray[np.float64]
    modes: NDArray[np.float64]
    singular_values: NDArray[np.float64]
    coefficients: NDArray[np.float64]
    energy_fraction: NDArray[np.float64]


def mode_analysis(
    qm: ArrayLike, params: PrototypeParams, *, n_x: int = 46, center: bool = False
) -> ModeAnalysis:
    """Mode shapes of a trajectory by SVD of its deflection matrix ``W[j, k] = w(x_j, t_k)``.

    The axial coordinate ``u_0`` has no shape and is not part of ``w``. The SVD of ``W``
    (rather than of the raw ``q_m`` rows, whose units differ) gives shapes along the beam as
    in Fig. 6a; with three Ritz functions there are at most three modes.

    Parameters
    ----------
    qm : array_like, shape (n_t, 4)
        Trajectory of the Ritz coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    n_x : int
        Points along the beam.
    center : bool
        Subtract the time mean of ``w`` before the SVD (fluctuation modes).

    Returns
    -------
    ModeAnalysis
        Modes, singular values and time coefficients.

    References
    ----------
    Masoud & Maas 2025, Section 3.4, Fig. 6a.
    """
    qm = np.asarray(qm, dtype=float)
    x = np.linspace(0.0, params.l, n_x)
    W = deflection(qm, x, params).T  # (n_x, n_t)
    if center:
        W = W - W.mean(axis=1, keepdims=True)
    U, sv, Vt = np.linalg.svd(W, full_matrices=False)
    r = min(3, sv.size)
    U, sv, Vt = U[:, :r], sv[:r], Vt[:r]
    sign = np.where(U[-1] < 0, -1.0, 1.0)
    U, Vt = U * sign, Vt * sign[:, None]
    total = float(np.sum(sv**2)) or 1.0
    return ModeAnalysis(
        x=x,
        modes=U,
        singular_values=sv,
        coefficients=(Vt.T * sv),
        energy_fraction=sv**2 / total,
    )
