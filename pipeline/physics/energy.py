"""Potential energy of the bistable DE actuator and its exact derivatives (Eq. 9-11, 14-15, 18).

``U = U_s + U_m + U_DE,1 + U_DE,2`` as a function of the Ritz coordinates
``q_m = [q_2, q_3, q_4, u_0]``, with gradient and Hessian in closed form (no finite differences):

* ``U_s = 1/2 int EI w''^2 (1 + w'^2) dx + 1/2 EA/l u_0^2`` (Eq. 9 with the textbook 1/2 on the
  bending term, docs/interpretation.md item 3), a quadratic plus a quartic form in ``q_2..q_4``;
* ``U_m = m g u_y`` (Eq. 10, docs/interpretation.md item 6);
* ``U_DE,i = V_DE Y/6 (lambda^2 + lambda^-2 - 2) - 1/2 C_0 lambda v_i^2`` (Eq. 11 with
  ``C_0 / lambda_3^2 = C_0 lambda_1``, docs/interpretation.md item 6). Eq. 11 is kept as
  printed (pure-shear form, resisting compression); equilibria with a slack DE
  (``lambda_1 < 1``) are filtered out by
  :mod:`debist.physics.statics` (docs/interpretation.md item 5).

References
----------
Masoud & Maas 2025, Eq. 9-11, 14, 15, 18; docs/interpretation.md items 3, 5, 6.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics import _generated, compiled
from debist.physics.kinematics import de_lengths, ritz_basis, vertical_displacement
from debist.physics.params import PrototypeParams

__all__ = [
    "HESS_INDEX",
    "PYTHON_STATES",
    "EnergyEval",
    "capacitances",
    "energy_parts",
    "generated_constants",
    "potential",
    "scalar_gradient_hessian",
]


def _hess_index() -> NDArray[np.int64]:
    iu = np.triu_indices(4)
    sym = np.zeros((4, 4), dtype=np.int64)
    sym[iu] = np.arange(10)
    sym.T[iu] = np.arange(10)
    return sym


#: Index (4, 4) of the generated upper-triangle Hessian (10,) in the full symmetric matrix.
HESS_INDEX = _hess_index()


def generated_constants(params: PrototypeParams) -> tuple[float, ...]:
    """Return the prototype constants the generated energy terms take after ``(q_m, b, w1, w2)``.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters [SI].

    Returns
    -------
    tuple of float
        ``l, EI, EA, mg, a, a_0, e_x, -e_z + dz_1, e_z + dz_2, l_0, V_DE Y / 6, C_0 / 2``
        (the order of :func:`debist.physics._generated.grad_terms`).

    References
    ----------
    Masoud & Maas 2025, Table 1, Eq. 1-6, 9-11.
    """
    p = params
    return (
        p.l, p.E * p.I, p.E * p.A, p.m * p.g, p.a, p.a_0, p.e_x, -p.e_z + p.dz_1,
        p.e_z + p.dz_2, p.l_0, p.V_DE * p.Y / 6.0, 0.5 * p.C_0,
    )  # fmt: skip


def scalar_gradient_hessian(
    qm: NDArray[np.float64],
    params: PrototypeParams,
    b: ArrayLike,
    v1: ArrayLike,
    v2: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gradient and Hessian of ``U`` (Eq. 14) from the generated scalar terms.

    The same equations as :func:`potential` (checked against it to 1e-10 in the tests), in
    the SymPy-generated scalar code of :mod:`debist.physics._generated`, state by state: run
    as Python (about 35 us a state) for the first :data:`PYTHON_STATES` states of a process,
    then compiled by numba (:func:`debist.physics.compiled.gradient_hessian`, about 3 us a
    state, equal bit for bit), whose load from numba's cache (about 0.5 s) a process with a
    few static solves never pays. Where the vectorised chain rule spends a third of a
    millisecond on the NumPy calls of any batch, the Newton solves of the statics use this
    for every batch size.

    Parameters
    ----------
    qm : ndarray, shape (..., 4)
        Ritz coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b, v1, v2 : array_like, broadcastable to (...)
        Screw position [m] and voltages [V] per state.

    Returns
    -------
    grad : ndarray, shape (..., 4)
        ``dU/dq_m``.
    hess : ndarray, shape (..., 4, 4)
        ``d^2U/dq_m^2``.

    References
    ----------
    Masoud & Maas 2025, Eq. 9-11, 14, 15.
    """
    qm = np.asarray(qm, dtype=float)
    shape = qm.shape[:-1]
    n = math.prod(shape)
    per_state = np.empty((3, *shape))  # b, v1^2, v2^2 broadcast to the states
    per_state[0], per_state[1], per_state[2] = b, np.square(v1), np.square(v2)
    per_state = per_state.reshape(3, n)
    grad, hess = _terms(np.ascontiguousarray(qm.reshape(n, 4)), *per_state, _constants(params))
    return grad.reshape((*shape, 4)), hess.reshape((*shape, 4, 4))


#: States a process evaluates as Python before :func:`scalar_gradient_hessian` loads the
#: compiled kernel: the break-even count, about 0.47 s of Python (36 us a state) against
#: 0.47 s to load the kernel, so a process pays at most twice what knowing its count in
#: advance would cost (the numbers are the same either way).
PYTHON_STATES = 13_000
_evaluated = 0  # states this process evaluated as Python


def _terms(qm, b, w1, w2, consts):
    """Return the generated gradient and Hessian of the states ``qm`` (n, 4), Python or compiled."""
    global _evaluated
    n = qm.shape[0]
    if _evaluated >= PYTHON_STATES:
        return compiled.gradient_hessian(qm, b, w1, w2, consts)
    _evaluated += n
    grad = np.empty((n, 4))
    hess = np.empty((n, 4, 4))
    c = consts.tolist()
    for i in range(n):
        args = (*qm[i].tolist(), float(b[i]), float(w1[i]), float(w2[i]), *c)
        grad[i] = _generated.grad_terms(*args)[0]
        hess[i] = np.array(_generated.hess_terms(*args))[HESS_INDEX]
    return grad, hess


@functools.lru_cache(maxsize=64)
def _constants(params: PrototypeParams) -> NDArray[np.float64]:
    """:func:`generated_constants` as the float array the compiled kernel takes (read only)."""
    out = np.array(generated_constants(params), dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class EnergyEval:
    """Potential energy and its derivatives at a batch of coordinates.

    Attributes
    ----------
    U : ndarray, shape (...)
        ``U = U_s + U_m + U_DE,1 + U_DE,2`` [J].
    grad : ndarray, shape (..., 4) or None
        ``dU/dq_m`` [J/(unit of q_m)].
    hess : ndarray, shape (..., 4, 4) or None
        ``d^2U/dq_m^2``.
    lambda_1 : ndarray, shape (..., 2)
        Longitudinal stretches of DE 1 (left) and DE 2 (right) [-].
    """

    U: NDArray[np.float64]
    grad: NDArray[np.float64] | None
    hess: NDArray[np.float64] | None
    lambda_1: NDArray[np.float64]


def _beam(qm: NDArray[np.float64], p: PrototypeParams, order: int):
    """Beam strain energy (Eq. 9, with 1/2) and mass potential (Eq. 10) with derivatives."""
    basis = ritz_basis(p.l)
    w = qm[..., :3]
    u0 = qm[..., 3]
    EI = p.E * p.I
    k_ax = p.E * p.A / p.l
    P2w = w @ basis.P2
    ww = (w[..., :, None] * w[..., None, :]).reshape((*w.shape[:-1], 9))
    T2 = (ww @ basis.T4.reshape(9, 9)).reshape((*w.shape[:-1], 3, 3))
    T3 = (T2 @ w[..., None])[..., 0]
    uy = vertical_displacement(qm, p)
    U = 0.5 * EI * (np.sum(P2w * w, -1) + np.sum(T3 * w, -1)) + 0.5 * k_ax * u0**2
    U = U + p.m * p.g * uy
    if order == 0:
        return U, None, None
    grad = np.empty(qm.shape)
    grad[..., :3] = EI * (P2w + 2.0 * T3) - p.m * p.g * (w @ basis.P1)
    grad[..., 3] = k_ax * u0 + p.m * p.g
    if order == 1:
        return U, grad, None
    hess = np.zeros((*qm.shape, 4))
    hess[..., :3, :3] = EI * (basis.P2 + 6.0 * T2) - p.m * p.g * basis.P1
    hess[..., 3, 3] = k_ax
    return U, grad, hess


def potential(
    qm: ArrayLike,
    params: PrototypeParams,
    *,
    b: ArrayLike | None = None,
    v1: ArrayLike = 0.0,
    v2: ArrayLike = 0.0,
    order: int = 2,
) -> EnergyEval:
    """Total potential energy ``U`` of Eq. 14 with exact gradient and Hessian w.r.t. ``q_m``.

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates ``[q_2, q_3, q_4, u_0]`` [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b : array_like, broadcastable to (...), optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    v1, v2 : array_like, broadcastable to (...)
        Voltages of the left (DE 1) and right (DE 2) actuator [V].
    order : {0, 1, 2}
        Highest derivative to compute.

    Returns
    -------
    EnergyEval
        ``U`` [J], ``grad`` (``order >= 1``), ``hess`` (``order == 2``) and the stretches.

    Raises
    ------
    ValueError
        If ``order`` is not 0, 1 or 2.

    References
    ----------
    Masoud & Maas 2025, Eq. 9-11, 14, 15; docs/interpretation.md items 3, 5, 6.

    Examples
    --------
    >>> from debist.physics.params import PrototypeParams
    >>> p = PrototypeParams.paper()
    >>> ev = potential([0.0, 0.0, 0.0, 0.0], p, order=0)
    >>> ev.lambda_1.round(3).tolist()
    [1.427, 1.427]
    """
    if order not in (0, 1, 2):
        raise ValueError(f"`order` must be 0, 1 or 2, got {order!r}")
    p = params
    qm = np.asarray(qm, dtype=float)
    shape = np.broadcast_shapes(qm.shape[:-1], np.shape(b), np.shape(v1), np.shape(v2))
    qm = np.broadcast_to(qm, (*shape, 4))
    U, grad, hess = _beam(qm, p, order)
    out = de_lengths(qm, p, b=b, order=order)
    lam = out[0] / p.l_0
    vsq = np.stack(np.broadcast_arrays(np.asarray(v1, float) ** 2, np.asarray(v2, float) ** 2), -1)
    k = p.V_DE * p.Y / 6.0
    elec = 0.5 * p.C_0 * vsq  # (..., 2)
    U = U + np.sum(k * (lam**2 + lam**-2 - 2.0) - elec * lam, axis=-1)
    if order >= 1:
        dW = (k * (2.0 * lam - 2.0 * lam**-3) - elec) / p.l_0  # dU_DE / d l_DE
        grad = grad + (dW[..., None, :] @ out[1])[..., 0, :]
    if order == 2:
        d2W = k * (2.0 + 6.0 * lam**-4) / p.l_0**2
        g = out[1]
        hess = (
            hess
            + np.swapaxes(g * d2W[..., None], -1, -2) @ g
            + np.sum(dW[..., None, None] * out[2], axis=-3)
        )
    return EnergyEval(U=U, grad=grad, hess=hess, lambda_1=lam)


def energy_parts(
    qm: ArrayLike,
    params: PrototypeParams,
    *,
    b: ArrayLike | None = None,
    v1: ArrayLike = 0.0,
    v2: ArrayLike = 0.0,
) -> dict[str, NDArray[np.float64]]:
    """Return the terms of the potential energy separately (Eq. 9, 10, 11).

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b : array_like, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    v1, v2 : array_like
        Voltages of DE 1 (left) and DE 2 (right) [V].

    Returns
    -------
    dict[str, ndarray]
        ``"U_s"``, ``"U_m"``, ``"U_DE1"``, ``"U_DE2"`` (each shape (...)) [J].

    References
    ----------
    Masoud & Maas 2025, Eq. 9-11.
    """
    p = params
    qm = np.asarray(qm, dtype=float)
    uy = vertical_displacement(qm, p)
    U_beam = _beam(qm, p, 0)[0]
    lam = de_lengths(qm, p, b=b)[0] / p.l_0
    k = p.V_DE * p.Y / 6.0
    vs = (np.asarray(v1, float), np.asarray(v2, float))
    parts = {"U_s": U_beam - p.m * p.g * uy, "U_m": p.m * p.g * uy}
    for i, name in enumerate(("U_DE1", "U_DE2")):
        li = lam[..., i]
        parts[name] = k * (li**2 + li**-2 - 2.0) - 0.5 * p.C_0 * li * vs[i] ** 2
    return parts


def capacitances(
    qm: ArrayLike, params: PrototypeParams, *, b: ArrayLike | None = None, order: int = 1
) -> tuple[NDArray[np.float64], ...]:
    """Capacitances ``C_i = C_0 / lambda_3,i^2 = C_0 lambda_1,i`` and ``dC_i/dq_m``.

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b : array_like, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    order : {0, 1, 2}
        Highest derivative with respect to ``q_m`` to return.

    Returns
    -------
    C : ndarray, shape (..., 2)
        ``[C_1, C_2]`` [F].
    dC_dqm : ndarray, shape (..., 2, 4)
        ``dC_i/dq_m`` (only if ``order >= 1``); ``1/2 dC_i/dq_m v_i^2`` is the electrostatic
        generalised force of Eq. 19, 23.
    d2C_dqm2 : ndarray, shape (..., 2, 4, 4)
        Second derivatives (only if ``order == 2``).

    References
    ----------
    Masoud & Maas 2025, Eq. 11, 18, 23; docs/interpretation.md item 6.
    """
    c = params.C_0 / params.l_0
    return tuple(c * x for x in de_lengths(qm, params, b=b, order=order))
