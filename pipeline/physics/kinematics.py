"""Kinematics of the bistable DE actuator with the Ritz approximation (Eq. 1-6, 13, 16).

Generalised coordinates ``q_m = [q_2, q_3, q_4, u_0]`` [1/m, 1/m^2, 1/m^3, m]; the beam deflection
is ``w(x) = q_2 x^2 + q_3 x^3 + q_4 x^4`` (Eq. 13). Every function accepts a batch of coordinates,
``qm`` of shape ``(..., 4)``, and broadcasts the pre-strain ``b`` over the batch shape.

Geometry (docs/interpretation.md items 1 and 6): the beam is clamped at the origin, ``x``
points up along the undeformed beam, the horizontal coordinate points right. The upper frame is
a rigid inverted U
fixed to the beam tip ``(q, l + u_y)`` and rotated clockwise by the pitch angle ``phi``; the
upper end of DE ``i`` sits at the frame offset ``o_i = (-+a, -(b - a_0))`` from the tip (left DE
1 at ``-a``, right DE 2 at ``+a``), the fixed lower ends at ``p_i = (-+e_z + dz_i, e_x)``, where
``dz_1, dz_2`` are the (signed) anchor offsets of an asymmetric prototype, 0 in the paper. This is
the printed Eq. 5 with the signs of ``x_i, y_i`` and of ``a_0 cos(phi)`` reversed
(docs/interpretation.md item 1):

    l_DE1 = sqrt((-e_z - q - a_0 sin(phi) + x_1)^2 + (e_x - l - u_y - a_0 cos(phi) + y_1)^2)
    l_DE2 = sqrt(( e_z - q - a_0 sin(phi) - x_2)^2 + (e_x - l - u_y - a_0 cos(phi) + y_2)^2)

(``-e_z + dz_1`` and ``e_z + dz_2`` in place of ``-+e_z`` when asymmetric) with ``x_i, y_i`` of
Eq. 4. All derivatives are exact (closed form); integrals of polynomials are computed exactly
(closed form or Gauss-Legendre quadrature of sufficient order).

References
----------
Masoud & Maas 2025, Eq. 1-6, 13, 16; docs/interpretation.md items 1 and 6.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics.params import PrototypeParams

__all__ = [
    "RitzBasis",
    "de_lengths",
    "deflection",
    "pitch_angle",
    "ritz_basis",
    "stretches",
    "tip_displacement",
    "tip_slope",
    "vertical_displacement",
]

POWERS = np.array([2, 3, 4])
"""Exponents of the Ritz polynomials of Eq. 13."""


@dataclass(frozen=True, eq=False)
class RitzBasis:
    """Exact integrals of the Ritz polynomials ``B_k(x) = x^k``, k = 2, 3, 4, over ``[0, l]``.

    Attributes
    ----------
    l : float
        Beam length [m].
    L : ndarray, shape (4,)
        ``dq/dq_m = [l^2, l^3, l^4, 0]`` (Eq. 16, 22).
    S : ndarray, shape (4,)
        ``dw'(l)/dq_m = [2 l, 3 l^2, 4 l^3, 0]``.
    P0 : ndarray, shape (3, 3)
        ``int B_j B_k dx``.
    P1 : ndarray, shape (3, 3)
        ``int B_j' B_k' dx``.
    P2 : ndarray, shape (3, 3)
        ``int B_j'' B_k'' dx``.
    T4 : ndarray, shape (3, 3, 3, 3)
        ``int B_a'' B_b'' B_c' B_d' dx``, symmetrised over all index permutations, so that
        ``int w''^2 w'^2 dx = T4(q, q, q, q)``.
    scale : ndarray, shape (4,)
        ``[l^2, l^3, l^4, 1]``: multiplies ``q_m`` into metres (for tolerances and scaling).
    """

    l: float  # noqa: E741
    L: NDArray[np.float64]
    S: NDArray[np.float64]
    P0: NDArray[np.float64]
    P1: NDArray[np.float64]
    P2: NDArray[np.float64]
    T4: NDArray[np.float64]
    scale: NDArray[np.float64]


@functools.lru_cache(maxsize=32)
def ritz_basis(l: float) -> RitzBasis:  # noqa: E741
    """Return the exact integrals of the Ritz polynomials for a beam of length ``l``.

    Parameters
    ----------
    l : float
        Beam length [m].

    Returns
    -------
    RitzBasis
        Matrices of the quadratic and quartic forms of Eq. 2, 8, 9.

    References
    ----------
    Masoud & Maas 2025, Eq. 13.
    """
    j = POWERS[:, None].astype(float)
    k = POWERS[None, :].astype(float)
    P0 = l ** (j + k + 1) / (j + k + 1)
    P1 = j * k * l ** (j + k - 1) / (j + k - 1)
    P2 = j * (j - 1) * k * (k - 1) * l ** (j + k - 3) / (j + k - 3)
    # Gauss-Legendre with 8 nodes integrates polynomials up to degree 15 exactly (here 10).
    xg, wg = np.polynomial.legendre.leggauss(8)
    x = 0.5 * l * (xg + 1.0)
    w = 0.5 * l * wg
    B1 = POWERS * x[:, None] ** (POWERS - 1)
    B2 = POWERS * (POWERS - 1) * x[:, None] ** (POWERS - 2)
    T = np.einsum("g,ga,gb,gc,gd->abcd", w, B2, B2, B1, B1)
    T4 = sum(np.transpose(T, perm) for perm in itertools.permutations(range(4))) / 24.0
    L = np.array([l**2, l**3, l**4, 0.0])
    S = np.array([2 * l, 3 * l**2, 4 * l**3, 0.0])
    scale = np.array([l**2, l**3, l**4, 1.0])
    for arr in (L, S, P0, P1, P2, T4, scale):
        arr.setflags(write=False)
    return RitzBasis(l=l, L=L, S=S, P0=P0, P1=P1, P2=P2, T4=T4, scale=scale)


def tip_displacement(qm: ArrayLike, params: PrototypeParams) -> NDArray[np.float64]:
    """Horizontal tip displacement ``q = w(l) = q_2 l^2 + q_3 l^3 + q_4 l^4`` (Eq. 3, 16).

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates ``[q_2, q_3, q_4, u_0]`` [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters (uses ``l``).

    Returns
    -------
    ndarray, shape (...)
        ``q`` [m].

    References
    ----------
    Masoud & Maas 2025, Eq. 16.
    """
    return np.asarray(qm, dtype=float) @ ritz_basis(params.l).L


def tip_slope(qm: ArrayLike, params: PrototypeParams) -> NDArray[np.float64]:
    """Slope of the beam at the tip, ``w'(l)`` [-].

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters (uses ``l``).

    Returns
    -------
    ndarray, shape (...)
        ``w'(l)`` [-].

    References
    ----------
    Masoud & Maas 2025, Eq. 1, 13.
    """
    return np.asarray(qm, dtype=float) @ ritz_basis(params.l).S


def pitch_angle(qm: ArrayLike, params: PrototypeParams) -> NDArray[np.float64]:
    """Pitch angle of the upper frame ``phi = arctan(w'(l))`` (Eq. 1).

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters (uses ``l``).

    Returns
    -------
    ndarray, shape (...)
        ``phi`` [rad], positive (clockwise) when the tip leans right.

    References
    ----------
    Masoud & Maas 2025, Eq. 1; docs/interpretation.md item 6.
    """
    return np.arctan(tip_slope(qm, params))


def vertical_displacement(qm: ArrayLike, params: PrototypeParams) -> NDArray[np.float64]:
    """Vertical tip displacement ``u_y = u_0 - 1/2 int_0^l w'^2 dx`` (Eq. 2), integral exact.

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters (uses ``l``).

    Returns
    -------
    ndarray, shape (...)
        ``u_y`` [m], positive upward.

    References
    ----------
    Masoud & Maas 2025, Eq. 2; docs/interpretation.md item 6.
    """
    qm = np.asarray(qm, dtype=float)
    w3 = qm[..., :3]
    return qm[..., 3] - 0.5 * np.sum((w3 @ ritz_basis(params.l).P1) * w3, axis=-1)


def deflection(qm: ArrayLike, x: ArrayLike, params: PrototypeParams) -> NDArray[np.float64]:
    """Beam deflection ``w(x) = q_2 x^2 + q_3 x^3 + q_4 x^4`` (Eq. 13).

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    x : array_like, shape (n_x,)
        Positions along the beam [m].
    params : PrototypeParams
        Prototype parameters (unused except for consistency of the signature).

    Returns
    -------
    ndarray, shape (..., n_x)
        ``w`` [m].

    References
    ----------
    Masoud & Maas 2025, Eq. 13.
    """
    del params
    qm = np.asarray(qm, dtype=float)
    x = np.asarray(x, dtype=float)
    B = x[:, None] ** POWERS  # (n_x, 3)
    return qm[..., :3] @ B.T


def _frame_terms(
    qm: NDArray[np.float64], params: PrototypeParams, b: ArrayLike | None
) -> tuple[NDArray[np.float64], ...]:
    """Return the DE vectors and their derivatives w.r.t. z = (q, phi, u_y).

    Returns ``d (..., 2, 2)``, ``dd (..., 2, 2, 3)`` (d d_i / d z), ``d2 (..., 2, 2)``
    (d^2 d_i / d phi^2; all other second derivatives vanish), ``s`` (...) the tip slope.
    """
    p = params
    basis = ritz_basis(p.l)
    b = p.b if b is None else b
    b = np.asarray(b, dtype=float)
    q = qm @ basis.L
    s = qm @ basis.S
    uy = vertical_displacement(qm, p)
    c = 1.0 / np.sqrt(1.0 + s * s)
    sn = s * c
    h = np.broadcast_to(b - p.a_0, q.shape)
    ox = np.array([-p.a, p.a])  # (2,)
    oy = -h[..., None] * np.ones(2)  # (..., 2)
    c2, s2 = c[..., None], sn[..., None]
    Rx = ox * c2 + oy * s2
    Ry = -ox * s2 + oy * c2
    dRx = -ox * s2 + oy * c2
    dRy = -ox * c2 - oy * s2
    px = np.array([-p.e_z + p.dz_1, p.e_z + p.dz_2])  # signed anchor offsets (asymmetry)
    dx = px - q[..., None] - Rx
    dy = p.e_x - p.l - uy[..., None] - Ry
    d = np.stack([dx, dy], axis=-1)  # (..., 2 DE, 2 comp)
    zeros = np.zeros_like(dx)
    ones = np.ones_like(dx)
    ddx = np.stack([-ones, -dRx, zeros], axis=-1)
    ddy = np.stack([zeros, -dRy, -ones], axis=-1)
    dd = np.stack([ddx, ddy], axis=-2)  # (..., 2 DE, 2 comp, 3)
    d2 = np.stack([Rx, Ry], axis=-1)  # d^2 d / d phi^2 = +R o
    return d, dd, d2, s


def de_lengths(
    qm: ArrayLike, params: PrototypeParams, *, b: ArrayLike | None = None, order: int = 0
) -> tuple[NDArray[np.float64], ...]:
    """Deformed DE lengths ``l_DE,1``, ``l_DE,2`` (corrected Eq. 5) and their derivatives.

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b : array_like, shape broadcastable to (...), optional
        Pre-strain screw position [m]; ``params.b`` if omitted.
    order : {0, 1, 2}
        Highest derivative with respect to ``q_m`` to return.

    Returns
    -------
    length : ndarray, shape (..., 2)
        ``[l_DE,1, l_DE,2]`` [m] (left, right).
    grad : ndarray, shape (..., 2, 4)
        ``d l_DE,i / d q_m`` (only if ``order >= 1``).
    hess : ndarray, shape (..., 2, 4, 4)
        ``d^2 l_DE,i / d q_m^2`` (only if ``order == 2``).

    Raises
    ------
    ValueError
        If ``order`` is not 0, 1 or 2.

    References
    ----------
    Masoud & Maas 2025, Eq. 1, 2, 4, 5; docs/interpretation.md item 1 (sign corrections).
    """
    if order not in (0, 1, 2):
        raise ValueError(f"`order` must be 0, 1 or 2, got {order!r}")
    qm = np.asarray(qm, dtype=float)
    if b is not None:
        shape = np.broadcast_shapes(qm.shape[:-1], np.shape(b))
        qm = np.broadcast_to(qm, (*shape, 4))
    d, dd, d2, s = _frame_terms(qm, params, b)
    length = np.sqrt(np.sum(d * d, axis=-1))  # (..., 2)
    if order == 0:
        return (length,)
    basis = ritz_basis(params.l)
    # Jacobian of z = (q, phi, u_y) w.r.t. q_m: (..., 3, 4)
    dphi = 1.0 / (1.0 + s * s)
    g_uy = np.concatenate([-qm[..., :3] @ basis.P1, np.ones((*qm.shape[:-1], 1))], axis=-1)
    J = np.stack([np.broadcast_to(basis.L, g_uy.shape), dphi[..., None] * basis.S, g_uy], axis=-2)
    gz = (d[..., None, :] @ dd)[..., 0, :] / length[..., None]  # (..., 2, 3)
    grad = gz @ J
    if order == 1:
        return length, grad
    Hz = (np.swapaxes(dd, -1, -2) @ dd - gz[..., :, None] * gz[..., None, :]) / length[
        ..., None, None
    ]
    Hz[..., 1, 1] += np.sum(d * d2, axis=-1) / length
    Je = J[..., None, :, :]
    hess = np.swapaxes(Je, -1, -2) @ Hz @ Je
    d2phi = -2.0 * s * dphi * dphi
    hess += (gz[..., 1] * d2phi[..., None])[..., None, None] * np.multiply.outer(basis.S, basis.S)
    H_uy = np.zeros((4, 4))
    H_uy[:3, :3] = -basis.P1
    hess += gz[..., 2, None, None] * H_uy
    return length, grad, hess


def stretches(
    qm: ArrayLike, params: PrototypeParams, *, b: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Longitudinal stretches ``lambda_1,i = l_DE,i / l_0`` of both DEs (Eq. 6).

    Parameters
    ----------
    qm : array_like, shape (..., 4)
        Generalised coordinates [1/m, 1/m^2, 1/m^3, m].
    params : PrototypeParams
        Prototype parameters.
    b : array_like, optional
        Pre-strain screw position [m]; ``params.b`` if omitted.

    Returns
    -------
    ndarray, shape (..., 2)
        ``[lambda_1,1, lambda_1,2]`` [-]; ``lambda_2 = lambda_3 = lambda_1^(-1/2)`` (uniaxial).

    References
    ----------
    Masoud & Maas 2025, Eq. 6.
    """
    return de_lengths(qm, params, b=b)[0] / params.l_0
