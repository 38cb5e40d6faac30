"""The polynomial NARX model's free run, compiled: the same recursion as SysIdentPy's predict.

A term of a SysIdentPy polynomial model is a row of regressor codes: 0 for none, ``1000 + i``
for ``y(k - i)`` and ``1000 (j + 1) + i`` for the j-th input's ``x_j(k - i)``; the model is
``y(k) = sum_t theta_t prod_{codes of t} value(code, k)``. :func:`factor_tables` turns the codes
into variable and lag tables, :func:`narx_free_run` runs the recursion from the first
``max_lag`` measured outputs with the measured inputs (tested equal to SysIdentPy's
``predict(..., steps_ahead=None)``), stopping where the output leaves a bound.

References
----------
Billings 2013, Nonlinear System Identification, Ch. 3 (polynomial NARX, free-run simulation);
Lacerda et al. 2020, JOSS 5(54) 2384 (SysIdentPy's regressor codes); Lam, Pitrou & Seibert
2015 (numba).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

from debist.core.jitcache import prepare_cache

prepare_cache(__file__)  # before the first cache=True: a folder numba can write

__all__ = ["factor_tables", "narx_free_run"]


def factor_tables(codes: NDArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Variables and lags of each term's factors from SysIdentPy regressor codes.

    Parameters
    ----------
    codes : ndarray of int, shape (n_terms, degree)
        SysIdentPy's ``final_model``.

    Returns
    -------
    var : ndarray of int, shape (n_terms, degree)
        0 for the output ``y``, ``j`` for the j-th input, -1 for no factor.
    lag : ndarray of int, shape (n_terms, degree)
        The factor's lag [samples] (0 where there is no factor).

    Raises
    ------
    ValueError
        For a code that is neither 0 nor a variable with a lag >= 1.
    """
    codes = np.asarray(codes, dtype=np.int64).reshape(len(codes), -1)
    var = np.where(codes > 0, codes // 1000 - 1, -1)
    lag = np.where(codes > 0, codes % 1000, 0)
    if np.any((codes > 0) & ((lag < 1) | (var < 0))) or np.any(codes < 0):
        raise ValueError(f"not SysIdentPy regressor codes: {codes.tolist()!r}")
    return var, lag


@nb.njit(cache=True)
def narx_free_run(
    y0: NDArray[np.float64],
    x: NDArray[np.float64],
    var: NDArray[np.int64],
    lag: NDArray[np.int64],
    theta: NDArray[np.float64],
    limit: float,
) -> tuple[NDArray[np.float64], int]:
    """Run a polynomial NARX model free from measured initial outputs.

    Parameters
    ----------
    y0 : ndarray, shape (max_lag,)
        The first measured outputs.
    x : ndarray, shape (n, n_inputs)
        The inputs over the whole run (its length sets the run's).
    var, lag : ndarray of int, shape (n_terms, degree)
        :func:`factor_tables` of the model.
    theta : ndarray, shape (n_terms,)
        The parameters.
    limit : float
        Largest ``|y|`` the run may reach.

    Returns
    -------
    y : ndarray, shape (n,)
        ``y0`` then the free run; NaN from the first sample beyond ``limit`` or not finite.
    diverged_at : int
        That sample, -1 if none.

    References
    ----------
    Billings 2013, Ch. 3 (free-run simulation of a NARX model).
    """
    n = x.shape[0]
    m = y0.size
    y = np.full(n, np.nan)
    y[:m] = y0
    for k in range(m, n):
        s = 0.0
        for t in range(theta.size):
            p = theta[t]
            for f in range(var.shape[1]):
                v = var[t, f]
                if v == 0:
                    p *= y[k - lag[t, f]]
                elif v > 0:
                    p *= x[k - lag[t, f], v - 1]
            s += p
        if not (abs(s) <= limit):  # also NaN
            return y, k
        y[k] = s
    return y, -1
