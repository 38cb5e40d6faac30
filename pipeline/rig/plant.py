"""The virtual rig's plant: the full model of Section 3 plus what the analytical model misses.

The "real" prototype that the virtual rig measures is the full dynamic model of
:mod:`debist.physics.dynamics` (Eq. 19-23) with

* **geometric asymmetry**: the anchor offsets ``dz_1``, ``dz_2`` of
  :class:`~debist.physics.params.PrototypeParams` (a bearing offset, an anchor off its
  nominal position); the default rig has ``dz_1 = 0.15 mm``, ``dz_2 = 0.05 mm``, wells at
  -9.50 and +10.99 mm instead of +-10.21 mm;
* **friction at the beam tip**: a generalised Maxwell-slip (GMS) model with a few elements
  (Al-Bender, Lampaert & Swevers 2005), hysteretic pre-sliding and a breakaway force;
* **high-voltage drivers**: the voltage applied to a DE follows the DAC reference with a
  first-order lag and a slew-rate limit (:class:`debist.rig.drivers.DriverOutput`);
* **sensors**: a laser triangulation sensor with white noise, quantisation and a finite
  range, sampled ``oversample`` times faster than the log and decimated by a zero-phase FIR
  (the rig's anti-aliasing); noisy voltage monitors.

The plant state is ``x = [q_m (4), q_m_dot (4), q_eps (2), z (n_friction)]``: the state of
:class:`~debist.physics.dynamics.FullModel` and the deflections ``z_i`` [m] of the friction
elements. :func:`debist.rig.run.simulate_rig` integrates it with
:func:`scipy.integrate.odeint` (ODEPACK's LSODA with the analytic Jacobian; or
:func:`scipy.integrate.solve_ivp`'s Radau) behind the drivers and sensors;
:func:`debist.rig.run.true_curves` gives the characteristic curves an identification should
recover. The right-hand side and Jacobian run compiled
(:mod:`debist.rig.compiled`, numba, drivers included); the NumPy implementation of
:class:`RigPlant` is the reference they are tested against (``compiled=False``).

``[rig.plant] model = "reduced"`` swaps the full model for the reduced one-coordinate model of
Eq. 24-26 of the same prototype (:class:`debist.rig.reduced.ReducedPlant`, state ``[q,
q_dot, q_eps (2), z]``), whose DE force is exactly ``g_i(q) v_i^2`` (Eq. 37): the same
friction, drivers, sensors and recorder, so an identification can be checked against exact
curves. :func:`debist.rig.run.make_plant` selects the plant.

References
----------
Masoud & Maas 2025, Eq. 19-23, 33, 37, Sec. 5.1 (3 kV converters, laser sensor, 10 ms log).
Al-Bender, F., Lampaert, V. & Swevers, J. (2005). The generalized Maxwell-slip model: a novel
model for friction simulation and compensation. IEEE Trans. Autom. Control 50(11), 1883-1887.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics.dynamics import FullModel, well_state
from debist.physics.kinematics import pitch_angle, ritz_basis
from debist.rig import gms
from debist.rig.drivers import DriverOutput
from debist.rig.params import RigParams

__all__ = ["RigPlant"]


def _scaled(v, gain: float):
    """``v`` itself for a unit gain, else ``t -> sqrt(gain) v(t)`` (the force goes with v^2)."""
    if gain == 1.0:
        return v
    root = float(np.sqrt(gain))
    return lambda t: root * v(t)


class RigPlant:
    """Right-hand side and Jacobian of the plant: full model plus tip friction.

    State ``x = [x_full (10), z (n_friction)]``. The friction force on the tip,

        F_fr = -sum_i k_i z_i - c q_dot,

    enters :class:`~debist.physics.dynamics.FullModel` as the external horizontal tip force
    (mapped onto the Ritz coordinates by ``dq/dq_m = L``, Eq. 15, 22). Each Maxwell-slip
    element (a spring ``k_i`` in series with a block of slip force ``F_i``) evolves as the
    regularised elasto-plastic element

        dz_i/dt = q_dot (1 - s_i |k_i z_i / F_i|^p),  s_i = 1 if q_dot z_i > 0 else 0,

    i.e. it sticks (``dz_i/dt = q_dot``) while unloading or lightly loaded and approaches
    slipping at ``|k_i z_i| = F_i`` smoothly (a Bouc-Wen-type smoothing of the GMS element;
    ``p -> infinity`` is the ideal Maxwell-slip element). The right-hand side is continuous
    (where ``s_i`` switches either ``z_i = 0`` or ``q_dot = 0``), which a stiff solver needs.

    Parameters
    ----------
    rig : RigParams
        Rig parameters.
    v1, v2 : callable
        Applied voltages ``v_i(t)`` [V] (e.g. :class:`~debist.rig.drivers.DriverOutput`).
    compiled : bool
        Evaluate :meth:`rhs` and :meth:`jac` with the compiled kernels of
        :mod:`debist.rig.compiled` (default; two :class:`~debist.rig.drivers.DriverOutput`
        are then evaluated inside the kernel, other callables in Python) or with NumPy
        (``False``, the reference).

    References
    ----------
    Masoud & Maas 2025, Eq. 19-23; Al-Bender, Lampaert & Swevers 2005 (GMS model).
    """

    def __init__(self, rig: RigParams, v1, v2, *, compiled: bool = True):
        self.rig = rig
        self.compiled = bool(compiled)
        self._drivers = (v1, v2)
        self._gain = (rig.gain_1, rig.gain_2)
        self._F0 = rig.force_offset
        # the NumPy reference sees the voltages scaled so that v^2 carries the DE gain
        scaled = [_scaled(v, g) for v, g in zip(self._drivers, self._gain, strict=True)]
        self.model = FullModel(rig.prototype, *scaled, compiled=False)
        self.n_friction = rig.n_friction
        self.n_states = 10 + self.n_friction
        self._L = ritz_basis(rig.prototype.l).L
        self._k = np.array(rig.friction_k)
        self._kF = self._k / np.array(rig.friction_F)
        self._p = rig.friction_exponent
        self._c = rig.friction_c
        self._kernels = None

    def _compiled(self):
        """``(rhs, jac)`` of the compiled path, built on first use (numba imported then)."""
        if self._kernels is None:
            # here, not at the top: numba compiles these kernels on first use only
            from debist.physics.compiled import pack_model
            from debist.rig import compiled as kern

            fp, fr = pack_model(self.model), kern.pack_friction(self)
            v1, v2 = self._drivers
            krhs, kjac = kern.plant_rhs, kern.plant_jac
            as_x = np.ascontiguousarray
            if isinstance(v1, DriverOutput) and isinstance(v2, DriverOutput):
                d1, d2, w = v1.table, v2.table, np.zeros(2)

                def rhs(t, x):
                    return krhs(float(t), as_x(x, dtype=float), fp, fr, d1, d2, w)

                def jac(t, x):
                    return kjac(float(t), as_x(x, dtype=float), fp, fr, d1, d2, w)

            else:
                none = kern.NO_DRIVER

                def rhs(t, x):
                    w = np.array([float(v1(t)) ** 2, float(v2(t)) ** 2])
                    return krhs(float(t), as_x(x, dtype=float), fp, fr, none, none, w)

                def jac(t, x):
                    w = np.array([float(v1(t)) ** 2, float(v2(t)) ** 2])
                    return kjac(float(t), as_x(x, dtype=float), fp, fr, none, none, w)

            self._kernels = (rhs, jac)
        return self._kernels

    def functions(self) -> tuple:
        """Return ``(rhs, jac)`` for :func:`scipy.integrate.odeint` or ``solve_ivp``.

        Returns
        -------
        tuple of callable
            The compiled kernels or :meth:`rhs`, :meth:`jac` (``compiled=False``).
        """
        return self._compiled() if self.compiled else (self.rhs, self.jac)

    def rest_state(self, side: int) -> NDArray[np.float64]:
        """Rest state in a well at ``v = 0`` under the tip force: relaxed creep, no friction load.

        Parameters
        ----------
        side : {-1, +1}
            Which well (:func:`~debist.physics.dynamics.well_state` with ``force_offset``).

        Returns
        -------
        ndarray, shape (n_states,)
            ``[q_m, 0, 0, 0...]``.

        Raises
        ------
        ValueError
            If there is no stable equilibrium on that side.
        """
        x_well = well_state(self.rig.prototype, side, F=self._F0)
        return np.concatenate([x_well, np.zeros(self.n_friction)])

    def atol_vector(self, atol: float, positions: float | None = None) -> NDArray[np.float64]:
        """Absolute tolerances of the states for the integrator (see :mod:`debist.rig.run`).

        Parameters
        ----------
        atol : float
            Base tolerance [m]: of the bending coordinates scaled to metres and of ``z``
            unless ``positions`` is given.
        positions : float, optional
            Tolerance of the bending coordinates scaled to metres and of ``z`` [m]; default
            ``atol``.

        Returns
        -------
        ndarray, shape (n_states,)
            ``positions`` for the bending coordinates and ``z``, ``100 atol`` for ``u_0``
            and the creep strains, ``1e4 atol`` per second for the velocities.
        """
        pos = atol if positions is None else positions
        scale = ritz_basis(self.rig.prototype.l).scale
        tol_x = np.array([pos, pos, pos, 100.0 * atol])
        return np.concatenate(
            [tol_x / scale, 1e4 * atol / scale, np.full(2, 100.0 * atol),
             np.full(self.n_friction, pos)]
        )  # fmt: skip

    def tip(self, x: ArrayLike) -> NDArray[np.float64]:
        """Tip displacement ``q = L . q_m`` of states [m] (Eq. 16).

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``q`` [m].
        """
        return np.asarray(x, dtype=float)[..., :4] @ self._L

    def tip_velocity(self, x: ArrayLike) -> NDArray[np.float64]:
        """Tip velocity ``L . q_m_dot`` of states [m/s].

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``q_dot`` [m/s].
        """
        return np.asarray(x, dtype=float)[..., 4:8] @ self._L

    def pitch(self, x: ArrayLike) -> NDArray[np.float64]:
        """Pitch angle of the upper frame of states [rad] (Eq. 1).

        Parameters
        ----------
        x : array_like, shape (..., n_states)
            States.

        Returns
        -------
        ndarray, shape (...)
            ``phi`` [rad].
        """
        return pitch_angle(np.asarray(x, dtype=float)[..., :4], self.rig.prototype)

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
        return -(x[..., 10:] @ self._k) - self._c * (x[..., 4:8] @ self._L)

    def rhs(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """State derivative of the plant.

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (n_states,)
            State ``[q_m, q_m_dot, q_eps, z]``.

        Returns
        -------
        ndarray, shape (n_states,)
            ``x_dot``.
        """
        if self.compiled:
            return self._compiled()[0](t, x)
        z = x[10:]
        qd = float(self._L @ x[4:8])
        out = np.empty(self.n_states)
        F_tip = float(self.friction_force(x)) + self._F0
        out[:10] = self.model.rhs(t, x[:10], F_extra=F_tip)
        pairs = zip(z, self._kF, strict=True)
        out[10:] = [gms.element_rate(qd, zi, kFi, self._p) for zi, kFi in pairs]
        return out

    def jac(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Approximate Jacobian of :meth:`rhs` (that of :meth:`FullModel.jac` plus friction).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (n_states,)
            State.

        Returns
        -------
        ndarray, shape (n_states, n_states)
            ``d x_dot / d x`` without the derivatives of M, D and K along ``q_m``.
        """
        if self.compiled:
            return self._compiled()[1](t, x)
        n = self.n_states
        J = np.zeros((n, n))
        J[:10, :10] = self.model.jac(t, x[:10])
        MinvL = np.linalg.solve(self.model.mass_matrix(x[:4]), self._L)
        J[4:8, 10:] = -np.outer(MinvL, self._k)
        J[4:8, 4:8] -= self._c * np.outer(MinvL, self._L)
        z = x[10:]
        qd = float(self._L @ x[4:8])
        parts = np.array(
            [
                gms.element_partials(qd, zi, kFi, self._p)
                for zi, kFi in zip(z, self._kF, strict=True)
            ]
        )
        J[10:, 4:8] = np.outer(parts[:, 0], self._L)
        J[10:, 10:] = np.diag(parts[:, 1])
        return J
