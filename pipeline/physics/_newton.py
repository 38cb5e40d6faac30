"""A batched, damped Newton solver for the small nonlinear systems of the physics model."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Residual = Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]]


@dataclass(frozen=True)
class NewtonResult:
    """Result of :func:`newton` for a batch of problems.

    Attributes
    ----------
    x : ndarray, shape (..., n)
        Solutions.
    residual : ndarray, shape (...)
        Final scaled residual norm (2-norm) [N].
    converged : ndarray of bool, shape (...)
        Whether the tolerance was met.
    n_iter : int
        Number of iterations performed.
    """

    x: NDArray[np.float64]
    residual: NDArray[np.float64]
    converged: NDArray[np.bool_]
    n_iter: int


def newton(
    fun: Residual,
    x0: NDArray[np.float64],
    scale: NDArray[np.float64],
    *,
    ftol: float = 1e-9,
    xtol: float = 1e-13,
    max_step: float = 5e-3,
    maxiter: int = 60,
) -> NewtonResult:
    """Solve ``fun(x)[0] = 0`` for a batch of independent problems by damped Newton iterations.

    The unknowns are scaled to ``xi = x * scale`` (metres for the Ritz coordinates) and the
    residual to ``r / scale`` (newtons for gradients of an energy), in which the tolerances and
    the step limit are given. Each step is limited to ``max_step`` (max norm) and halved up to
    ten times while the residual 2-norm grows.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> (r, J)`` with ``x, r`` of shape ``(..., n)`` and ``J`` of shape
        ``(..., n, n)``, ``J = dr/dx``.
    x0 : ndarray, shape (..., n)
        Starting points.
    scale : ndarray, shape (n,)
        Scale of the unknowns.
    ftol : float
        Tolerance on the scaled residual (2-norm).
    xtol : float
        Tolerance on the scaled step (max norm).
    max_step : float
        Largest scaled step.
    maxiter : int
        Maximum number of iterations.

    Returns
    -------
    NewtonResult
        Solutions, residuals and convergence flags.
    """
    x = np.array(x0, dtype=float, copy=True)
    r, J = fun(x)
    rs = r / scale  # the scaled residual, kept with each accepted point
    res = _norm(rs)
    done = res < ftol
    scale2 = np.multiply.outer(scale, scale)
    it = 0
    for it in range(1, maxiter + 1):
        if np.all(done):
            it -= 1
            break
        Js = J / scale2
        try:
            dxi = -np.linalg.solve(Js, rs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            dxi = -(np.linalg.pinv(Js) @ rs[..., None])[..., 0]
        dxi = np.where(np.isfinite(dxi), dxi, 0.0)
        step = np.max(np.abs(dxi), axis=-1)
        dxi = dxi * np.minimum(1.0, max_step / np.maximum(step, 1e-300))[..., None]
        dxi = np.where(done[..., None], 0.0, dxi)
        alpha = np.ones(res.shape)
        for _ in range(10):
            x_new = x + alpha[..., None] * dxi / scale
            r_new, J_new = fun(x_new)
            rs_new = r_new / scale
            res_new = _norm(rs_new)
            bad = ~(res_new <= res * (1.0 + 1e-12) + ftol) & ~done
            if not np.any(bad):
                break
            alpha = np.where(bad, 0.5 * alpha, alpha)
        x, J, rs, res = x_new, J_new, rs_new, res_new
        small_step = alpha * np.max(np.abs(dxi), axis=-1) < xtol
        done = done | (res < ftol) | (small_step & (res < 1e3 * ftol))
    converged = (res < ftol) | done
    return NewtonResult(x=x, residual=res, converged=converged, n_iter=it)


def _norm(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """2-norm over the last axis: ``numpy.linalg.norm(a, axis=-1)``'s sum, without its checks."""
    return np.sqrt(np.add.reduce(a * a, axis=-1))
