"""The virtual rig's plant compiled with numba: HV drivers, tip friction and the full model.

The same equations as :class:`debist.rig.plant.RigPlant` and
:class:`debist.rig.drivers.DriverOutput` (their Python/NumPy methods are the reference; the
tests check that both agree) as nopython functions of plain arrays: the full model of
:mod:`debist.physics.compiled` (packed by :func:`~debist.physics.compiled.pack_model`),
the Maxwell-slip elements (:func:`pack_friction`) and the drivers' piecewise analytic output
(:attr:`DriverOutput.table <debist.rig.drivers.DriverOutput.table>`). One call evaluates
the whole right-hand side or Jacobian, drivers included, for :func:`scipy.integrate.odeint`
(or ``solve_ivp``).

The Python-facing kernels are cached on disk and close over :data:`STAMP`, the sha256 of
the physics modules they call (numba's cache does not see changes in other files; see
:mod:`debist.physics.compiled`).

References
----------
Masoud & Maas 2025, Eq. 19-23, Sec. 5.1; Al-Bender, Lampaert & Swevers 2005 (GMS model);
Lam, Pitrou & Seibert 2015, "Numba: a LLVM-based Python JIT compiler" (numba documentation:
``njit``, ``cache=True``, notes on caching).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba as nb
import numpy as np
from numpy.typing import NDArray

from debist.core.jitcache import prepare_cache
from debist.physics import _generated
from debist.physics import compiled as physics_compiled
from debist.physics.compiled import _L, _cho_solve, _jac_into, _rhs_into, source_stamp
from debist.rig import gms

prepare_cache(__file__)  # before the first cache=True: a folder numba can write

if TYPE_CHECKING:
    from debist.rig.plant import RigPlant

__all__ = [
    "NO_DRIVER",
    "STAMP",
    "driver_value",
    "pack_friction",
    "plant_jac",
    "plant_rhs",
]

#: sha256 of the physics modules the plant kernels call; they close over it.
STAMP = source_stamp(physics_compiled, _generated, gms)
#: The empty driver table: the kernels then take the squared voltages from ``w``.
NO_DRIVER = np.empty(0)


def pack_friction(plant: RigPlant) -> NDArray[np.float64]:
    """Pack the tip friction of a plant into the float array the plant kernels take.

    Parameters
    ----------
    plant : RigPlant
        The plant (its constants are the ones its NumPy methods use).

    Returns
    -------
    ndarray, shape (5 + 2 n_friction,)
        ``[c, p, F_0, gain_1, gain_2, k_1..k_n, k_1/F_1..k_n/F_n]``: viscous coefficient
        [N s/m], the exponent of the regularised elements, the constant tip force [N], the
        DEs' electrostatic gains [-], the element stiffnesses [N/m] and ``k_i / F_i`` [1/m].

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005 (GMS model).
    """
    head = [plant._c, plant._p, plant._F0, plant._gain[0], plant._gain[1]]
    return np.concatenate([head, plant._k, plant._kF]).astype(float).reshape(-1)


@nb.njit(cache=True)
def driver_value(t: float, d: NDArray[np.float64]) -> float:
    """Output of one HV driver at time ``t`` from its table (compiled ``DriverOutput(t)``).

    Parameters
    ----------
    t : float
        Time [s].
    d : ndarray, shape (3 n + 6,)
        :attr:`debist.rig.drivers.DriverOutput.table`.

    Returns
    -------
    float
        ``v(t)`` [V].

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (3 kV high-voltage converters).
    """
    t0, hold, tau, slew = d[0], d[1], d[2], d[3]
    n = int(d[4])
    s = (t - t0) / hold
    if s <= 0.0:
        return d[5 + n]
    k = min(int(s), n - 1)
    rk, vk, tc = d[5 + k], d[5 + n + k], d[6 + 2 * n + k]
    e = (s - k) * hold
    if tc > 0.0:
        sg = 1.0 if rk > vk else -1.0
        if e < tc:
            return vk + sg * slew * e
        return rk - sg * slew * tau * math.exp(-(e - tc) / tau)
    return rk + (vk - rk) * math.exp(-e / tau)


#: One GMS element (:mod:`debist.rig.gms`), compiled into the kernels (its source is in
#: :data:`STAMP`, so numba's cache follows it).
_element_rate = nb.njit(inline="always")(gms.element_rate)
_element_partials = nb.njit(inline="always")(gms.element_partials)


def _stamped(stamp: str):
    """Build the Python-facing kernels as closures over ``stamp`` (see the module docstring).

    The friction code sits in the kernels themselves: every level of compiled calls between
    a kernel and the generated terms makes numba optimise and emit their code once more.
    """

    @nb.njit(cache=True)
    def plant_rhs(t, x, fp, fr, d1, d2, w):
        """State derivative of the plant, compiled (:meth:`RigPlant.rhs`).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray of float64, shape (10 + n_friction,), contiguous
            State ``[q_m, q_m_dot, q_eps, z]``.
        fp : ndarray, shape (N_MODEL,)
            The full model (:func:`debist.physics.compiled.pack_model`).
        fr : ndarray, shape (5 + 2 n_friction,)
            The friction, tip force and DE gains (:func:`pack_friction`).
        d1, d2 : ndarray
            Tables of the HV drivers of DE 1 and DE 2 (:attr:`DriverOutput.table
            <debist.rig.drivers.DriverOutput.table>`), or empty: then ``w`` holds the
            squared voltages.
        w : ndarray, shape (2,)
            ``v_1^2``, ``v_2^2`` [V^2] where ``d1``, ``d2`` are empty.

        Returns
        -------
        ndarray, shape (10 + n_friction,)
            ``x_dot``.

        References
        ----------
        Masoud & Maas 2025, Eq. 19-23, Sec. 5.1; Al-Bender, Lampaert & Swevers 2005.
        """
        stamp  # noqa: B018
        w1 = fr[3] * (driver_value(t, d1) ** 2 if d1.size else w[0])
        w2 = fr[4] * (driver_value(t, d2) ** 2 if d2.size else w[1])
        nf = x.size - 10
        c, p = fr[0], fr[1]
        qd = 0.0
        for i in range(4):
            qd += fp[_L + i] * x[4 + i]
        F = fr[2]
        for i in range(nf):
            F -= fr[5 + i] * x[10 + i]
        F -= c * qd
        out = np.empty(x.size)
        _rhs_into(x[:10], w1, w2, F, fp, out)
        for i in range(nf):
            out[10 + i] = _element_rate(qd, x[10 + i], fr[5 + nf + i], p)
        return out

    @nb.njit(cache=True)
    def plant_jac(t, x, fp, fr, d1, d2, w):
        """Approximate Jacobian of the plant, compiled (:meth:`RigPlant.jac`).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray of float64, shape (10 + n_friction,), contiguous
            State.
        fp, fr, d1, d2, w : ndarray
            The full model, the friction and the inputs (see :func:`plant_rhs`).

        Returns
        -------
        ndarray, shape (10 + n_friction, 10 + n_friction)
            ``d x_dot / d x`` without the derivatives of M, D and K along ``q_m``.

        References
        ----------
        Masoud & Maas 2025, Eq. 19-23, Sec. 5.1; Al-Bender, Lampaert & Swevers 2005.
        """
        stamp  # noqa: B018
        w1 = fr[3] * (driver_value(t, d1) ** 2 if d1.size else w[0])
        w2 = fr[4] * (driver_value(t, d2) ** 2 if d2.size else w[1])
        n = x.size
        nf = n - 10
        c, p = fr[0], fr[1]
        J = np.zeros((n, n))
        M = _jac_into(x[:10], w1, w2, fp, J)
        MinvL = np.empty((4, 1))
        for i in range(4):
            MinvL[i, 0] = fp[_L + i]
        _cho_solve(M, MinvL)
        for i in range(4):
            for j in range(nf):
                J[4 + i, 10 + j] = -MinvL[i, 0] * fr[5 + j]
            for j in range(4):
                J[4 + i, 4 + j] -= c * MinvL[i, 0] * fp[_L + j]
        qd = 0.0
        for i in range(4):
            qd += fp[_L + i] * x[4 + i]
        for i in range(nf):
            g, dz = _element_partials(qd, x[10 + i], fr[5 + nf + i], p)
            for j in range(4):
                J[10 + i, 4 + j] = g * fp[_L + j]
            J[10 + i, 10 + i] = dz
        return J

    return plant_rhs, plant_jac


plant_rhs, plant_jac = _stamped(STAMP)
