"""Exact O(n) linear solves of one lagged-diffusivity step of TVRegDiff.

Each step of Chartrand's iteration minimises the quadratic model of the TV functional,
i.e. solves ``(alpha L_k + A^T A) u = A^T b`` with ``L_k = dx D^T Q_k D``. ``A`` is a dense
cumulative-integration matrix, but its inverse relation is sparse, which gives banded
systems of bandwidth 2 for both of Chartrand's discretisations:

* ``"large"``: with ``y = A u`` (``u`` in Chartrand's internal units, ``u = diff(y)``
  with ``u_0 = y_0``) the step is ``(alpha M^T Q M + I) y = b`` with ``M = D A^{-1}`` a
  second difference; symmetric positive definite, pentadiagonal.
* ``"small"``: ``y = A u`` holds iff ``E y = dx S u`` (``E`` the first difference with
  ``y_{-1} = 0``, ``S`` the two-point average). With ``w = E^{-T}(A u - b)`` the step is
  the symmetric indefinite saddle-point system
  ``[[alpha L, dx S^T], [dx S, -E E^T]] [u; w] = [0; E b]``, pentadiagonal once the
  unknowns are interleaved ``(u_0, w_0, u_1, w_1, ..., u_n)``.

No dense ``n x n`` matrix is formed; storage and work are O(n) per step.

References
----------
Chartrand, R. (2011). Numerical differentiation of noisy, nonsmooth data.
ISRN Applied Mathematics 2011, 164564, Section 2.
Vogel, C. R. & Oman, M. E. (1996). Iterative methods for total variation denoising.
SIAM J. Sci. Comput. 17(1), 227-238.
"""

from __future__ import annotations

import lazy_loader as lazy
import numpy as np
from numpy.typing import NDArray

# the libraries below load on first use (lazy_loader): start-up of the CLI
sparse = lazy.load("scipy.sparse", suppress_warning=True)
linalg = lazy.load("scipy.linalg", suppress_warning=True)

__all__ = [
    "large_bands",
    "small_bands",
    "small_kkt",
    "solve_large",
    "solve_small",
]


def large_bands(q: NDArray[np.float64], alpha: float, dx: float) -> NDArray[np.float64]:
    """Upper banded storage of ``alpha M^T Q M + I`` (the ``"large"`` step matrix).

    Parameters
    ----------
    q : ndarray, shape (n - 1,)
        Lagged-diffusivity weights ``1 / sqrt((D u)_i^2 + ep)`` of the ``n - 1``
        differences of ``u``.
    alpha : float
        Regularisation weight.
    dx : float
        Grid spacing.

    Returns
    -------
    ndarray, shape (3, n)
        ``ab`` in the upper form of :func:`scipy.linalg.solveh_banded`
        (``ab[2 + i - j, j] = H[i, j]``): the matrix has bandwidth 2.
    """
    n = q.size + 1
    # qp[i + 1] is the weight of row i of M, i = 0 .. n - 2; rows -1, n - 1, n are empty.
    qp = np.zeros(n + 2)
    qp[1:n] = alpha * q / dx**2
    ab = np.empty((3, n))
    ab[2] = 1.0 + qp[:n] + 4.0 * qp[1 : n + 1] + qp[2 : n + 2]
    ab[1, 0] = 0.0
    ab[1, 1:] = -2.0 * (qp[1:n] + qp[2 : n + 1])
    ab[0, :2] = 0.0
    ab[0, 2:] = qp[2:n]
    return ab


def solve_large(
    q: NDArray[np.float64], b: NDArray[np.float64], alpha: float, dx: float
) -> NDArray[np.float64]:
    """Solve one ``"large"`` step exactly; return ``u`` in derivative units.

    Parameters
    ----------
    q : ndarray, shape (n - 1,)
        Lagged-diffusivity weights of the differences of ``u``.
    b : ndarray, shape (n,)
        Data minus its first value.
    alpha : float
        Regularisation weight.
    dx : float
        Grid spacing.

    Returns
    -------
    ndarray, shape (n,)
        ``u = diff(y) / dx`` with ``u_0 = y_0 / dx``, where ``y`` solves the
        pentadiagonal system.
    """
    y = linalg.solveh_banded(large_bands(q, alpha, dx), b, lower=False, check_finite=False)
    return np.diff(y, prepend=0.0) / dx


def small_bands(q: NDArray[np.float64], alpha: float, dx: float) -> NDArray[np.float64]:
    """Banded storage of the interleaved ``"small"`` saddle-point matrix.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Lagged-diffusivity weights of the ``n`` differences of ``u`` (``n + 1`` values).
    alpha : float
        Regularisation weight.
    dx : float
        Grid spacing.

    Returns
    -------
    ndarray, shape (5, 2 n + 1)
        ``ab`` in the form of :func:`scipy.linalg.solve_banded` with ``(l, u) = (2, 2)``
        (``ab[2 + i - j, j] = K[i, j]``), unknowns ordered ``(u_0, w_0, u_1, ..., u_n)``.
    """
    n = q.size
    size = 2 * n + 1
    aq = (alpha / dx) * q
    main = np.empty(size)
    main[0::2] = np.concatenate(([aq[0]], aq[:-1] + aq[1:], [aq[-1]]))
    main[1::2] = -2.0
    main[1] = -1.0
    second = np.empty(size - 2)  # K[i, i + 2] for i = 0 .. size - 3
    second[0::2] = -aq
    second[1::2] = 1.0
    ab = np.zeros((5, size))
    ab[0, 2:] = second
    ab[1, 1:] = 0.5 * dx
    ab[2] = main
    ab[3, :-1] = 0.5 * dx
    ab[4, :-2] = second
    return ab


def small_kkt(q: NDArray[np.float64], alpha: float, dx: float) -> sparse.csc_array:
    """Build the interleaved ``"small"`` saddle-point matrix as a sparse matrix.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Lagged-diffusivity weights of the ``n`` differences of ``u``.
    alpha : float
        Regularisation weight.
    dx : float
        Grid spacing.

    Returns
    -------
    scipy.sparse.csc_array, shape (2 n + 1, 2 n + 1)
        Symmetric, bandwidth 2 (the same matrix as :func:`small_bands`).
    """
    ab = small_bands(q, alpha, dx)
    size = ab.shape[1]
    diagonals = [ab[2 + k, : size - k] if k > 0 else ab[2] for k in range(3)]
    data = [diagonals[2], diagonals[1], diagonals[0], diagonals[1], diagonals[2]]
    return sparse.diags_array(data, offsets=[-2, -1, 0, 1, 2], format="csc")


def solve_small(
    q: NDArray[np.float64], b: NDArray[np.float64], alpha: float, dx: float
) -> NDArray[np.float64]:
    """Solve one ``"small"`` step exactly; return ``u`` at the ``n + 1`` cell edges.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Lagged-diffusivity weights of the differences of ``u``.
    b : ndarray, shape (n,)
        Data minus its first value.
    alpha : float
        Regularisation weight.
    dx : float
        Grid spacing.

    Returns
    -------
    ndarray, shape (n + 1,)
        The minimiser of the quadratic model.
    """
    rhs = np.zeros(2 * b.size + 1)
    rhs[1::2] = np.diff(b, prepend=0.0)
    z = linalg.solve_banded((2, 2), small_bands(q, alpha, dx), rhs, check_finite=False)
    return z[0::2]
