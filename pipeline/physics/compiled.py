"""The full model's right-hand side and Jacobian compiled with numba (Eq. 19-23).

The same equations as :class:`debist.physics.dynamics.FullModel` (its NumPy methods are the
reference; the tests check that both agree to rounding), as nopython functions of plain
arrays: the generated potential-energy terms of :mod:`debist.physics._generated` compiled
as they are, the mass, damping and creep matrices, and a Cholesky factorisation for the
mass-matrix solves. A model reaches the kernels as one float array (:func:`pack_model`); the
squared voltages and the tip force are arguments.

The generated terms are equal bit for bit; the rest sums in another order than NumPy's BLAS,
so the accelerations, which come out of a solve with a mass matrix of condition number about
``2e6`` (coordinates scaled to metres), agree with the reference to about ``1e-8`` relative
and solve the reference's equations to rounding (backward error ``1e-14``).

Caching. The kernels are cached on disk (``cache=True``). numba invalidates a cached function
when its own file changes, not when a function it calls from another file does; the
Python-facing kernels therefore close over :data:`STAMP`, the sha256 of the source of
:mod:`debist.physics._generated`, which numba hashes into the cache's index key, and the
helpers they call are not cached on their own. Kernels of other modules that call the
helpers close over :func:`source_stamp` of this module and the generated one.

References
----------
Masoud & Maas 2025, Eq. 8, 12, 19-23; Lam, Pitrou & Seibert 2015, "Numba: a LLVM-based
Python JIT compiler" (numba documentation: ``njit``, ``cache=True``, notes on caching);
Golub & Van Loan, Matrix Computations, 4th ed., Sec. 4.2 (Cholesky factorisation); Higham,
Accuracy and Stability of Numerical Algorithms, 2nd ed., Sec. 7.3, 10.1 (scaling, Cholesky).
"""

from __future__ import annotations

import hashlib
import inspect
import math
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numba as nb
import numpy as np
from numpy.typing import NDArray

from debist.core.jitcache import prepare_cache
from debist.physics import _generated

prepare_cache(__file__)  # before the first cache=True: a folder numba can write

if TYPE_CHECKING:
    from debist.physics.dynamics import FullModel

__all__ = [
    "N_MODEL",
    "STAMP",
    "full_jac",
    "full_rhs",
    "grad_terms",
    "gradient_hessian",
    "hess_terms",
    "pack_model",
    "source_stamp",
]

# Layout of the model array (pack_model): the 12 constants of the generated code, then
_B, _M, _ETAV, _KBAR, _RELAX = 12, 13, 14, 15, 16
_M0, _D0, _P1, _L = 17, 33, 49, 58
#: Length of the model array of :func:`pack_model`.
N_MODEL = 62
_L0 = 9  # l_0 among the constants


def source_stamp(*modules: ModuleType) -> str:
    """Return the sha256 of the source files of ``modules`` (for numba's cache index key).

    Parameters
    ----------
    modules : module
        Modules whose compiled functions a cached kernel calls.

    Returns
    -------
    str
        Hex digest over the files' bytes, in the order given.

    References
    ----------
    numba documentation, "Notes on caching" (changes in other files are not detected).
    """
    h = hashlib.sha256()
    for mod in modules:
        h.update(Path(inspect.getfile(mod)).read_bytes())
    return h.hexdigest()


#: sha256 of :mod:`debist.physics._generated`; the cached kernels close over it.
STAMP = source_stamp(_generated)

#: The generated terms compiled as they are (see :mod:`debist.physics._generated`).
grad_terms = nb.njit(cache=True)(_generated.grad_terms)
hess_terms = nb.njit(cache=True)(_generated.hess_terms)


def pack_model(model: FullModel) -> NDArray[np.float64]:
    """Pack a full model's parameters into the float array the kernels take.

    Parameters
    ----------
    model : FullModel
        The model (its constants are the ones its NumPy methods use).

    Returns
    -------
    ndarray, shape (N_MODEL,)
        ``l, EI, EA, m g, a, a_0, e_x, -e_z + dz_1, e_z + dz_2, l_0, V_DE Y / 6, C_0 / 2``
        (the constants of :mod:`debist.physics._generated`), ``b`` [m], ``m`` [kg],
        ``V_DE eta_v``, ``K_bar / K = V_DE Y_MW``, ``Y_MW / eta_MW`` [1/s], the constant
        parts ``M_0`` (16) and ``D_0`` (16) of the mass and damping matrices (row-major),
        the slope matrix ``P_1`` (9) and the tip map ``L`` (4).

    References
    ----------
    Masoud & Maas 2025, Eq. 8, 12, 19-23.
    """
    p = model.params
    scalars = [model.b, p.m, p.V_DE * p.eta_v, model._kbar, model._relax]
    parts = [model._consts, scalars, model._M0.ravel(), model._D0.ravel(), model._P1.ravel()]
    out = np.concatenate([*parts, model._L]).astype(float)
    assert out.size == N_MODEL
    return out


@nb.njit
def _cho_solve(A, B):
    """Solve ``A X = B`` for a symmetric positive definite ``A`` (n, n); ``B`` (n, k) in place.

    Cholesky ``A = R^T R`` (``A`` is not changed), then two triangular solves. The mass
    matrix is positive definite (the kinetic energy Eq. 8); Cholesky is backward stable
    without pivoting, and its accuracy depends on the condition number of the symmetrically
    scaled matrix only (van der Sluis), not on the units of the Ritz coordinates.
    """
    n = A.shape[0]
    R = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for i in range(j):
            s -= R[i, j] * R[i, j]
        d = math.sqrt(s)
        R[j, j] = d
        for c in range(j + 1, n):
            s = A[j, c]
            for i in range(j):
                s -= R[i, j] * R[i, c]
            R[j, c] = s / d
    for c in range(B.shape[1]):
        for j in range(n):  # R^T y = b
            s = B[j, c]
            for i in range(j):
                s -= R[i, j] * B[i, c]
            B[j, c] = s / R[j, j]
        for j in range(n - 1, -1, -1):  # R x = y
            s = B[j, c]
            for i in range(j + 1, n):
                s -= R[j, i] * B[i, c]
            B[j, c] = s / R[j, j]


@nb.njit
def _gen_args(x, w1, w2, fp):
    return (x[0], x[1], x[2], x[3], fp[_B], w1, w2, fp[0], fp[1], fp[2], fp[3], fp[4], fp[5],
            fp[6], fp[7], fp[8], fp[9], fp[10], fp[11])  # fmt: skip


@nb.njit
def _matrices(x, length, dlen, fp, M, D, K, g_uy):
    """Fill ``M``, ``D`` (4, 4), ``K = d lambda_3,i / d q_m`` (2, 4) and ``g_uy`` (4,)."""
    m = fp[_M]
    for i in range(3):
        s = 0.0
        for j in range(3):
            s += fp[_P1 + 3 * i + j] * x[j]
        g_uy[i] = -s
    g_uy[3] = 1.0
    for i in range(4):
        for j in range(4):
            M[i, j] = fp[_M0 + 4 * i + j] + m * g_uy[i] * g_uy[j]
    l0 = fp[_L0]
    for i in range(2):
        f = -0.5 * (length[i] / l0) ** -1.5 / l0
        for j in range(4):
            K[i, j] = f * dlen[4 * i + j]
    ev = fp[_ETAV]
    for i in range(4):
        for j in range(4):
            D[i, j] = fp[_D0 + 4 * i + j] + ev * (K[0, i] * K[0, j] + K[1, i] * K[1, j])


@nb.njit
def _rhs_into(x, w1, w2, F_tip, fp, out):
    """Write ``x_dot`` of the full model at tip force ``F_tip`` into ``out[:10]``."""
    grad, length, dlen = grad_terms(*_gen_args(x, w1, w2, fp))
    M = np.empty((4, 4))
    D = np.empty((4, 4))
    K = np.empty((2, 4))
    g_uy = np.empty(4)
    _matrices(x, length, dlen, fp, M, D, K, g_uy)
    conv = 0.0
    for i in range(3):
        s = 0.0
        for j in range(3):
            s += fp[_P1 + 3 * i + j] * x[4 + j]
        conv += x[4 + i] * s
    conv *= fp[_M]
    kbar = fp[_KBAR]
    f = np.empty((4, 1))
    for i in range(4):
        s = 0.0
        for j in range(4):
            s += D[i, j] * x[4 + j]
        f[i, 0] = (
            F_tip * fp[_L + i]
            + conv * g_uy[i]
            - s
            - grad[i]
            - kbar * (K[0, i] * x[8] + K[1, i] * x[9])
        )
    _cho_solve(M, f)
    relax = fp[_RELAX]
    for i in range(4):
        out[i] = x[4 + i]
        out[4 + i] = f[i, 0]
    for i in range(2):
        s = 0.0
        for j in range(4):
            s += K[i, j] * x[4 + j]
        out[8 + i] = s - relax * x[8 + i]


@nb.njit
def _jac_into(x, w1, w2, fp, J):
    """Write the full model's approximate Jacobian into ``J[:10, :10]``; return ``M`` (4, 4).

    ``J`` must be zero where the model has no entries.
    """
    args = _gen_args(x, w1, w2, fp)
    _, length, dlen = grad_terms(*args)
    hu = hess_terms(*args)
    M = np.empty((4, 4))
    D = np.empty((4, 4))
    K = np.empty((2, 4))
    g_uy = np.empty(4)
    _matrices(x, length, dlen, fp, M, D, K, g_uy)
    B = np.empty((4, 10))
    pos = 0
    for i in range(4):
        for j in range(i, 4):
            B[i, j] = hu[pos]
            B[j, i] = hu[pos]
            pos += 1
    m2 = 2.0 * fp[_M]
    kbar = fp[_KBAR]
    for j in range(3):
        s = 0.0
        for i in range(3):
            s += fp[_P1 + 3 * j + i] * x[4 + i]
        for i in range(4):
            B[i, 4 + j] = D[i, j] + -m2 * g_uy[i] * s
    for i in range(4):
        B[i, 7] = D[i, 3]
        B[i, 8] = kbar * K[0, i]
        B[i, 9] = kbar * K[1, i]
    _cho_solve(M, B)
    for i in range(4):
        J[i, 4 + i] = 1.0
        for j in range(10):
            J[4 + i, j] = -B[i, j]
    relax = fp[_RELAX]
    for i in range(2):
        for j in range(4):
            J[8 + i, 4 + j] = K[i, j]
        J[8 + i, 8 + i] = -relax
    return M


def _stamped(stamp: str):
    """Build the Python-facing kernels as closures over ``stamp`` (see the module docstring)."""

    @nb.njit(cache=True)
    def full_rhs(x, w1, w2, F_tip, fp):
        """State derivative of the full model, compiled (:meth:`FullModel.rhs`).

        Parameters
        ----------
        x : ndarray of float64, shape (10,), contiguous
            State ``[q_m, q_m_dot, q_eps]``.
        w1, w2 : float
            Squared voltages ``v_1^2``, ``v_2^2`` [V^2].
        F_tip : float
            Horizontal tip force [N].
        fp : ndarray, shape (N_MODEL,)
            The model (:func:`pack_model`).

        Returns
        -------
        ndarray, shape (10,)
            ``x_dot``.

        References
        ----------
        Masoud & Maas 2025, Eq. 21-23.
        """
        stamp  # noqa: B018
        out = np.empty(10)
        _rhs_into(x, w1, w2, F_tip, fp, out)
        return out

    @nb.njit(cache=True)
    def full_jac(x, w1, w2, fp):
        """Approximate Jacobian of the full model, compiled (:meth:`FullModel.jac`).

        Parameters
        ----------
        x : ndarray of float64, shape (10,), contiguous
            State ``[q_m, q_m_dot, q_eps]``.
        w1, w2 : float
            Squared voltages ``v_1^2``, ``v_2^2`` [V^2].
        fp : ndarray, shape (N_MODEL,)
            The model (:func:`pack_model`).

        Returns
        -------
        ndarray, shape (10, 10)
            ``d x_dot / d x`` without the derivatives of M, D and K along ``q_m``.

        References
        ----------
        Masoud & Maas 2025, Eq. 21-23.
        """
        stamp  # noqa: B018
        J = np.zeros((10, 10))
        _jac_into(x, w1, w2, fp, J)
        return J

    @nb.njit(cache=True)
    def gradient_hessian(qm, b, w1, w2, consts):
        """Gradient and Hessian of the potential energy at a batch of states, compiled.

        The generated terms as they are, state by state: equal bit for bit to
        :func:`debist.physics._generated.grad_terms` and ``hess_terms`` run as Python.

        Parameters
        ----------
        qm : ndarray of float64, shape (n, 4)
            Ritz coordinates [1/m, 1/m^2, 1/m^3, m].
        b, w1, w2 : ndarray of float64, shape (n,)
            Screw position [m] and squared voltages ``v_1^2``, ``v_2^2`` [V^2] per state.
        consts : ndarray of float64, shape (12,)
            :func:`debist.physics.energy.generated_constants`.

        Returns
        -------
        grad : ndarray, shape (n, 4)
            ``dU/dq_m``.
        hess : ndarray, shape (n, 4, 4)
            ``d^2U/dq_m^2``.

        References
        ----------
        Masoud & Maas 2025, Eq. 9-11, 14, 15.
        """
        stamp  # noqa: B018
        n = qm.shape[0]
        grad = np.empty((n, 4))
        hess = np.empty((n, 4, 4))
        c = consts
        for i in range(n):
            args = (qm[i, 0], qm[i, 1], qm[i, 2], qm[i, 3], b[i], w1[i], w2[i], c[0], c[1],
                    c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11])  # fmt: skip
            g = grad_terms(*args)[0]
            h = hess_terms(*args)
            pos = 0
            for j in range(4):
                grad[i, j] = g[j]
                for k in range(j, 4):  # the upper triangle row by row, as HESS_INDEX
                    hess[i, j, k] = h[pos]
                    hess[i, k, j] = h[pos]
                    pos += 1
        return grad, hess

    return full_rhs, full_jac, gradient_hessian


full_rhs, full_jac, gradient_hessian = _stamped(STAMP)
