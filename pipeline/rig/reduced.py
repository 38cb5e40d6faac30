"""The virtual rig's reduced plant: the one-coordinate model of Eq. 24-26 with the rig around it.

``[rig.plant] model = "reduced"`` replaces the full model of :class:`debist.rig.plant.RigPlant`
by the paper's reduced model of the same prototype (the ``[rig.prototype]`` with its anchor
offsets), built by :func:`debist.physics.reduced.fit_reduced` and tabulated as cubic splines
like :class:`debist.physics.freerun.AnalyticalModel`:

    m_q(q) q_ddot + 1/2 m_q'(q) q_dot^2 + d(q) q_dot + f(q) + sum_i k_bar k_i(q) q_eps,i
        = g_1(q) v_1^2 + g_2(q) v_2^2 + F_fr,
    q_eps,i_dot = k_i(q) q_dot - Y_MW / eta_MW q_eps,i,

with the same tip friction ``F_fr`` as the full plant (the Maxwell-slip elements act on the
tip displacement ``q``, which is the reduced coordinate), the same HV drivers and the same
sensors (:func:`debist.rig.run.simulate_rig` runs both plants). Its DE force is exactly
``g_i(q) v_i^2`` with ``g_i = 1/2 dC_i/dq``, so the curves an identification of Eq. 37 should
recover are known exactly (:func:`reduced_true_curves`). What Eq. 37 does not represent is the
position-dependent mass (``m_q`` varies by about 13 % over +-25 mm; the term
``1/2 m_q' q_dot^2``), the Maxwell creep of the DEs, the friction, the drivers and the sensors.

The state is ``x = [q, q_dot, q_eps,1, q_eps,2, z (n_friction)]`` [m, m/s, -, -, m].

References
----------
Masoud & Maas 2025, Eq. 18, 24-26, 33, 37, Sec. 5.1; Al-Bender, Lampaert & Swevers 2005 (GMS).
"""

from __future__ import annotations

import functools

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics.params import PrototypeParams
from debist.physics.reduced import fit_reduced
from debist.rig import gms
from debist.rig.params import RigParams

# the libraries below load on first use (lazy_loader): start-up of the CLI
interpolate = lazy.load("scipy.interpolate", suppress_warning=True)

__all__ = ["CURVES", "ReducedPlant", "reduced_tables", "reduced_true_curves", "truth_attrs"]

#: The tabulated curves, in the order of the spline's last axis.
CURVES = ("m_q", "dm_q", "d", "f", "g1", "g2", "k1", "k2", "phi")
#: Half width of the tabulated range of ``q`` [m] and its points (0.025 mm spacing), as the
#: analytical model of :func:`debist.physics.freerun.analytical_model`.
Q_MAX = 25e-3
N_GRID = 2001


@functools.lru_cache(maxsize=8)
def reduced_tables(
    prototype: PrototypeParams, q_max: float = Q_MAX, n_grid: int = N_GRID
) -> interpolate.CubicSpline:
    """Tabulate the reduced model's curves of a prototype as one cubic spline.

    Parameters
    ----------
    prototype : PrototypeParams
        The prototype (asymmetry included; ``prototype.b`` is the operating point).
    q_max : float
        Half width of the tabulated range [m]; outside, the end polynomials extrapolate.
    n_grid : int
        Points of the uniform grid.

    Returns
    -------
    scipy.interpolate.CubicSpline
        Values of shape ``(..., len(CURVES))``: ``m_q`` [kg], ``dm_q/dq`` [kg/m], ``d``
        [N s/m], ``f`` [N], ``g1``, ``g2`` [N/V^2], ``k1``, ``k2`` [1/m], ``phi`` [rad].
        Cached per argument set (the experiments of a rig and its truth share it).

    Raises
    ------
    StaticsError
        If the static path cannot be continued over the range.

    References
    ----------
    Masoud & Maas 2025, Eq. 18, 24-26, 33.
    """
    q = np.linspace(-q_max, q_max, n_grid)
    cur = fit_reduced(prototype, q_max=q_max).curves(q)
    return interpolate.CubicSpline(q, np.stack([getattr(cur, name) for name in CURVES], axis=1))


class ReducedPlant:
    """Right-hand side and Jacobian of the reduced plant: Eq. 26 plus tip friction.

    The friction is that of :class:`debist.rig.plant.RigPlant`: ``F_fr = -sum_i k_i z_i -
    c q_dot`` acts on the tip, i.e. directly on ``q``, and each element evolves as
    ``dz_i/dt = q_dot (1 - s_i |k_i z_i / F_i|^p)``, ``s_i = 1`` if ``q_dot z_i > 0``.
    The curves are evaluated from the piecewise cubics of :func:`reduced_tables` (the
    Jacobian uses their exact derivatives; ``m_q'`` in the Jacobian is the spline's
    derivative of ``m_q``, in the right-hand side the tabulated ``dm_q``).

    Parameters
    ----------
    rig : RigParams
        Rig parameters (``prototype`` and the friction).
    v1, v2 : callable
        Applied voltages ``v_i(t)`` [V] (e.g. :class:`~debist.rig.drivers.DriverOutput`).

    Attributes
    ----------
    n_states : int
        ``4 + n_friction``.
    spline : scipy.interpolate.CubicSpline
        The tabulated curves (:func:`reduced_tables`).

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26; Al-Bender, Lampaert & Swevers 2005 (GMS model).
    """

    def __init__(self, rig: RigParams, v1, v2):
        self.rig = rig
        self.v1, self.v2 = v1, v2
        self.n_friction = rig.n_friction
        self.n_states = 4 + self.n_friction
        self.spline = reduced_tables(rig.prototype)
        x = self.spline.x
        self._q0, self._h, self._n = float(x[0]), float(x[1] - x[0]), x.size - 1
        self._x, self._xl = x, x.tolist()
        self._c = np.ascontiguousarray(np.moveaxis(self.spline.c[:, :, :8], 1, 0))  # (n, 4, 8)
        p = rig.prototype
        self._relax = p.Y_MW / p.eta_MW if p.eta_MW > 0 else 0.0
        self._kbar = p.V_DE * p.Y_MW
        self._k = np.array(rig.friction_k, dtype=float)
        self._kF = self._k / np.array(rig.friction_F, dtype=float)
        self._p = rig.friction_exponent
        self._cv = rig.friction_c
        self._gain1, self._gain2 = rig.gain_1, rig.gain_2
        self._F0 = rig.force_offset
        self._kl, self._kFl = self._k.tolist(), self._kF.tolist()

    def _local(self, q: float) -> tuple[NDArray[np.float64], float]:
        """Coefficients (4, 8) of the piece holding ``q`` and the local abscissa [m]."""
        k = min(max(int((q - self._q0) / self._h), 0), self._n - 1)
        return self._c[k], q - self._xl[k]

    def curves(self, q: float, der: bool = False):
        """Curves at one ``q``: ``m_q, dm_q, d, f, g1, g2, k1, k2`` (and their q-derivatives).

        Parameters
        ----------
        q : float
            Tip displacement [m].
        der : bool
            Also return the derivatives in ``q``.

        Returns
        -------
        values : ndarray, shape (8,)
            The curves at ``q`` (units of :func:`reduced_tables`).
        slopes : ndarray, shape (8,)
            Their derivatives [unit/m]; only with ``der=True``.
        """
        c, s = self._local(q)
        val = np.array([s * s * s, s * s, s, 1.0]) @ c
        if not der:
            return val
        return val, np.array([3.0 * s * s, 2.0 * s, 1.0, 0.0]) @ c

    def friction_force(self, x: ArrayLike) -> NDArray[np.float64]:
        """Friction force on the tip, ``-sum k_i z_i - c q_dot`` [N].

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            Plant states.

        Returns
        -------
        ndarray, shape (...)
            ``F_fr`` [N].
        """
        x = np.asarray(x, dtype=float)
        return -(x[..., 4:] @ self._k) - self._cv * x[..., 1]

    def rhs(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """State derivative of the plant (Eq. 26 with friction and creep).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (n_states,)
            State ``[q, q_dot, q_eps,1, q_eps,2, z]``.

        Returns
        -------
        ndarray, shape (n_states,)
            ``x_dot``.

        References
        ----------
        Masoud & Maas 2025, Eq. 26; Al-Bender, Lampaert & Swevers 2005.
        """
        q, qd, e1, e2, *z = x.tolist()  # scalar arithmetic: a few states, many calls
        m, dm, d, f, g1, g2, k1, k2 = self.curves(q).tolist()
        w1, w2 = self._gain1 * float(self.v1(t)) ** 2, self._gain2 * float(self.v2(t)) ** 2
        force = g1 * w1 + g2 * w2 - self._cv * qd + self._F0
        force -= 0.5 * dm * qd * qd + d * qd + f + self._kbar * (k1 * e1 + k2 * e2)
        out = [qd, 0.0, k1 * qd - self._relax * e1, k2 * qd - self._relax * e2]
        p = self._p
        for zi, ki, kFi in zip(z, self._kl, self._kFl, strict=True):
            force -= ki * zi
            out.append(gms.element_rate(qd, zi, kFi, p))
        out[1] = force / m
        return np.array(out)

    def jac(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian ``d x_dot / d x`` of :meth:`rhs`.

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (n_states,)
            State.

        Returns
        -------
        ndarray, shape (n_states, n_states)
            The Jacobian (``m_q'`` from the spline's derivative, see the class).
        """
        q, qd, e1, e2, *z = x.tolist()
        val, der = self.curves(q, der=True)
        m, dm, d, f, g1, g2, k1, k2 = val.tolist()
        dm_, ddm, dd, df, dg1, dg2, dk1, dk2 = der.tolist()
        w1, w2 = self._gain1 * float(self.v1(t)) ** 2, self._gain2 * float(self.v2(t)) ** 2
        kb, p = self._kbar, self._p
        force = g1 * w1 + g2 * w2 - self._cv * qd + self._F0
        force -= sum(a * b for a, b in zip(self._kl, z, strict=True))
        force -= 0.5 * dm * qd * qd + d * qd + f + kb * (k1 * e1 + k2 * e2)
        dforce = dg1 * w1 + dg2 * w2 - 0.5 * ddm * qd * qd - dd * qd - df
        dforce -= kb * (dk1 * e1 + dk2 * e2)
        n = self.n_states
        J = np.zeros((n, n))
        J[0, 1] = 1.0
        J[1, 0] = (dforce - force / m * dm_) / m
        J[1, 1] = -(dm * qd + d + self._cv) / m
        J[1, 2] = -kb * k1 / m
        J[1, 3] = -kb * k2 / m
        J[1, 4:] = -self._k / m
        J[2, 0], J[2, 1], J[2, 2] = dk1 * qd, k1, -self._relax
        J[3, 0], J[3, 1], J[3, 3] = dk2 * qd, k2, -self._relax
        for i, (zi, kFi) in enumerate(zip(z, self._kFl, strict=True), start=4):
            J[i, 1], J[i, i] = gms.element_partials(qd, zi, kFi, p)
        return J

    def functions(self, compiled: bool = True):
        """Return ``(rhs, jac)`` for :func:`scipy.integrate.odeint` or ``solve_ivp``.

        Parameters
        ----------
        compiled : bool
            Ignored: the reduced plant runs in NumPy (a few seconds for a 37.5 s
            experiment).

        Returns
        -------
        tuple of callable
            :meth:`rhs` and :meth:`jac`.
        """
        return self.rhs, self.jac

    def rest_state(self, side: int) -> NDArray[np.float64]:
        """State at rest in a well at ``v = 0``: relaxed creep, unloaded friction.

        Parameters
        ----------
        side : {-1, +1}
            Which well; the stable solution of ``f(q) = force_offset`` (``df/dq > 0``) with
            ``side * q > 1 um`` farthest from ``q = 0``.

        Returns
        -------
        ndarray, shape (n_states,)
            ``[q_well, 0, 0, 0, 0...]``.

        Raises
        ------
        ValueError
            If the tabulated ``f`` has no stable zero on that side.

        References
        ----------
        Masoud & Maas 2025, Eq. 26 (static equilibria).
        """
        f = interpolate.PPoly(self.spline.c[:, :, CURVES.index("f")], self._x, extrapolate=False)
        slope = f.derivative()
        roots = [r for r in f.solve(self._F0) if side * r > 1e-6 and slope(r) > 0.0]
        if not roots:
            raise ValueError(f"no stable equilibrium of the reduced model with sign(q) = {side}")
        x0 = np.zeros(self.n_states)
        x0[0] = max(roots, key=abs)
        return x0

    def atol_vector(self, atol: float, positions: float | None = None) -> NDArray[np.float64]:
        """Absolute tolerances of the states for the integrator (see :mod:`debist.rig.run`).

        Parameters
        ----------
        atol : float
            Base tolerance [m]: of ``q`` and ``z`` unless ``positions`` is given.
        positions : float, optional
            Tolerance of the positions ``q`` and ``z`` [m]; default ``atol``.

        Returns
        -------
        ndarray, shape (n_states,)
            ``positions`` for ``q`` and ``z``, ``100 atol`` per second for ``q_dot`` and
            ``100 atol`` [-] for the creep strains.
        """
        out = np.full(self.n_states, float(atol if positions is None else positions))
        out[1:4] = 100.0 * atol
        return out

    def tip(self, x: ArrayLike) -> NDArray[np.float64]:
        """Tip displacement ``q`` of states [m].

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``q`` [m].
        """
        return np.asarray(x, dtype=float)[..., 0]

    def tip_velocity(self, x: ArrayLike) -> NDArray[np.float64]:
        """Tip velocity of states [m/s].

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``q_dot`` [m/s].
        """
        return np.asarray(x, dtype=float)[..., 1]

    def pitch(self, x: ArrayLike) -> NDArray[np.float64]:
        """Pitch angle of the upper frame along the reduced model's ``q_m(q)`` [rad].

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``phi`` [rad] (Eq. 1, 24).

        References
        ----------
        Masoud & Maas 2025, Eq. 1, 24.
        """
        return self.spline(self.tip(x))[..., CURVES.index("phi")]


def reduced_true_curves(rig: RigParams, q_grid: ArrayLike) -> dict[str, NDArray[np.float64]]:
    """Return the reduced plant's exact curves in the convention of Eq. 37.

    The same tabulation the plant integrates (:func:`reduced_tables`), so at rest with
    relaxed creep and unloaded friction the plant's acceleration is exactly
    ``(g1 v_1^2 + g2 v_2^2 - f(q)) / m_q(q)``.

    Parameters
    ----------
    rig : RigParams
        Rig parameters (uses ``prototype``).
    q_grid : array_like, shape (n,)
        Tip displacements [m].

    Returns
    -------
    dict[str, ndarray]
        Each of shape (n,): ``"q"`` [m]; ``"f"`` restoring force at ``v = 0`` [N];
        ``"c"`` ``= f / q`` [N/m] (``df/dq`` at q = 0; a pole there when ``f(0) != 0``);
        ``"k"`` ``= df/dq`` [N/m]; ``"d"`` damping [N s/m]; ``"g1"``, ``"g2"`` ``= 1/2
        dC_i/dq`` [N/V^2]; ``"g1_vmax"``, ``"g2_vmax"`` the 3 kV secants, equal to ``g1``,
        ``g2`` (the force is exactly ``g_i v_i^2``); ``"m_q"`` [kg] and ``"dm_q"`` [kg/m]
        (the mass varies with ``q``; see :func:`truth_attrs`); ``"k1"``, ``"k2"`` creep
        couplings [1/m]; ``"phi"`` [rad]. All are per the plant's own ``m_q(q)``:
        ``m_q(q) q_ddot + d q_dot + f = g_1 v_1^2 + g_2 v_2^2`` (plus the terms Eq. 37 lacks).

    References
    ----------
    Masoud & Maas 2025, Eq. 18, 26, 33, 37.
    """
    q = np.asarray(q_grid, dtype=float)
    spl = reduced_tables(rig.prototype)
    val = {name: spl(q)[..., i] for i, name in enumerate(CURVES)}
    f = val["f"]
    k = spl(q, 1)[..., CURVES.index("f")]
    small = np.abs(q) < 1e-12
    c = np.where(small, k, f / np.where(small, 1.0, q))
    return {
        "q": q,
        "f": f,
        "c": c,
        "k": k,
        "g1": val["g1"],
        "g2": val["g2"],
        "g1_vmax": val["g1"].copy(),
        "g2_vmax": val["g2"].copy(),
        "m_q": val["m_q"],
        "dm_q": val["dm_q"],
        "d": val["d"],
        "k1": val["k1"],
        "k2": val["k2"],
        "phi": val["phi"],
    }


def truth_attrs(rig: RigParams, curves: dict[str, NDArray[np.float64]]) -> dict[str, object]:
    """Attributes of the truth file's ``curves`` group: which plant, and per which mass.

    Parameters
    ----------
    rig : RigParams
        Rig parameters.
    curves : dict of str to ndarray
        The true curves (:func:`debist.rig.run.true_curves`), with ``"q"`` and ``"m_q"``.

    Returns
    -------
    dict
        ``model`` (``"full"`` or ``"reduced"``); ``separable`` (whether the DE force is
        exactly ``g_i(q) v_i^2``, so ``g1``, ``g2`` are exact); ``mass`` (what the forces
        are per); ``m_q0`` the mass at ``q = 0`` [kg] and ``m_q_min``, ``m_q_max`` its range
        on the grid [kg]. The identified model of Eq. 37 has a constant ``m_q``; its
        forces compare with these at rest when scaled by ``m_q(q) / m_q0``, or directly
        where ``m_q(q)`` is near ``m_q0`` (the wells and the barrier).

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 37.
    """
    q, m = np.asarray(curves["q"], dtype=float), np.asarray(curves["m_q"], dtype=float)
    reduced = rig.model == "reduced"
    mass = (
        "the plant's position-dependent m_q(q) (curve 'm_q'): m_q(q) q_ddot + 1/2 m_q'(q) "
        "q_dot^2 + d(q) q_dot + f(q) + creep = g1(q) v1^2 + g2(q) v2^2 + friction; Eq. 37 "
        "with a constant m_q = m_q0 sees m_q0 / m_q(q) times these curves"
        if reduced
        else "the reduced model's m_q(q) (curve 'm_q'); the full plant's DE force is not "
        "g_i(q) v_i^2 (g1, g2: small-signal gains, g1_vmax, g2_vmax: 3 kV secants)"
    )
    return {
        "model": rig.model,
        "separable": reduced,
        "mass": mass,
        "m_q0": float(np.interp(0.0, q, m)),
        "m_q_min": float(m.min()),
        "m_q_max": float(m.max()),
    }
