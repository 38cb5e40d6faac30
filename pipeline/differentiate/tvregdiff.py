"""Total-variation regularised differentiation (TVRegDiff) with exact O(n) steps.

Chartrand's method finds the derivative ``u`` of data ``f`` as the minimiser of

    F(u) = alpha * TV_ep(u) + 1/2 * ||A u - (f - f_0)||^2,

with ``A`` an antiderivative operator and ``TV_ep`` a smoothed total variation, by
lagged diffusivity: each iteration minimises the quadratic model of ``F`` around the
current iterate. Chartrand's code solves that model inexactly with preconditioned
conjugate gradients; here it is solved exactly, in O(n), as a banded system
(see :mod:`debist.differentiate._tvr_solve`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import ConvergenceWarning
from debist.differentiate._tvr_solve import solve_large, solve_small
from debist.differentiate.result import check_int, check_positive

__all__ = ["TVRegDiffResult", "tv_functional", "tvregdiff"]

_SCALES = ("small", "large")


@dataclass(frozen=True)
class TVRegDiffResult:
    """Result of :func:`tvregdiff`.

    Attributes
    ----------
    u : ndarray, shape (n + 1,) for ``"small"``, (n,) for ``"large"`` [data unit / dx unit]
        The regularised derivative in Chartrand's raw convention: for ``"small"`` at the
        ``n + 1`` cell edges, for ``"large"`` at the ``n`` samples.
    derivative : ndarray, shape (n,) [data unit / dx unit]
        The derivative at the ``n`` sample instants: ``u[1:]`` for ``"small"``; for
        ``"large"`` the mean of neighbouring values, ``(u[k] + u[k + 1]) / 2``, with linear
        extrapolation at both ends (see Alignment in the Notes of :func:`tvregdiff`).
    converged : bool
        Whether the relative change of ``u`` in the last iteration fell below ``tol``.
    n_iter : int
        Number of iterations run (at most ``iterations``; fewer when converged).
    functional : ndarray, shape (n_iter,)
        ``F(u)`` after each iteration (non-increasing for lagged diffusivity).
    rel_change : ndarray, shape (n_iter,)
        ``||u_{k+1} - u_k|| / ||u_{k+1}||`` of each iteration.
    scale : str
        ``"small"`` or ``"large"``.
    alpha : float
        Regularisation weight used.
    ep : float
        Smoothing parameter of the total variation used.
    dx : float
        Grid spacing used.
    """

    u: NDArray[np.float64]
    derivative: NDArray[np.float64]
    converged: bool
    n_iter: int
    functional: NDArray[np.float64]
    rel_change: NDArray[np.float64]
    scale: str
    alpha: float
    ep: float
    dx: float


def tv_functional(
    u: ArrayLike,
    data: ArrayLike,
    alpha: float,
    *,
    scale: str = "small",
    ep: float = 1e-6,
    dx: float | None = None,
) -> float:
    """Chartrand's TV functional ``F(u)``, minimised by :func:`tvregdiff`.

    Parameters
    ----------
    u : array_like, shape (n + 1,) for ``"small"``, (n,) for ``"large"`` [data unit / dx unit]
        Derivative in the raw convention of :attr:`TVRegDiffResult.u`.
    data : array_like, shape (n,) [data unit]
        Samples ``f``.
    alpha : float
        Regularisation weight.
    scale : {"small", "large"}, optional
        Discretisation.
    ep : float, optional
        Smoothing parameter of the total variation.
    dx : float, optional
        Grid spacing; default ``1 / n``.

    Returns
    -------
    float
        For ``"small"``: ``alpha * dx * sum(sqrt((D u)^2 + ep)) + 0.5 * ||A u - (f - f_0)||^2``
        with ``D u = diff(u) / dx`` and ``A`` the cumulative trapezoid rule.
        For ``"large"``:
        ``alpha * sum(sqrt(diff(u)^2 + ep)) + 0.5 * ||dx cumsum(u) - (f - f_0)||^2``,
        which is Chartrand's large-scale functional written in the units of the returned
        ``u`` (his internal iterate is ``u * dx``).

    Raises
    ------
    ValueError
        If ``scale`` is not ``"small"`` or ``"large"`` or ``u`` has the wrong length.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.array([0.0, 1.0, 2.0, 3.0])
    >>> float(tv_functional([0.0, 1.0, 1.0, 1.0], f, 0.1, scale="large", ep=0.0, dx=1.0))
    0.1
    """
    u = np.asarray(u, dtype=float)
    f = np.asarray(data, dtype=float)
    scale = _check_scale(scale)
    n = f.size
    dx = 1.0 / n if dx is None else float(dx)
    b = f - f[0]
    expected = n + 1 if scale == "small" else n
    if u.shape != (expected,):
        raise ValueError(f"`u` must have shape ({expected},) for scale {scale!r}, got {u.shape}")
    if scale == "small":
        tv = dx * np.sum(np.sqrt((np.diff(u) / dx) ** 2 + ep))
        residual = dx * np.cumsum(0.5 * (u[:-1] + u[1:])) - b
    else:
        tv = np.sum(np.sqrt(np.diff(u) ** 2 + ep))
        residual = dx * np.cumsum(u) - b
    return float(alpha * tv + 0.5 * residual @ residual)


def tvregdiff(
    data: ArrayLike,
    iterations: int,
    alpha: float,
    *,
    u0: ArrayLike | None = None,
    scale: str = "small",
    ep: float = 1e-6,
    dx: float | None = None,
    tol: float = 1e-6,
) -> TVRegDiffResult:
    """Differentiate noisy data by total-variation regularisation (Chartrand 2011).

    Minimises ``alpha * TV_ep(u) + 1/2 ||A u - (f - f_0)||^2`` (:func:`tv_functional`) by
    lagged diffusivity; solver, units, alignment: docs/explanation/implementation.md.

    Parameters
    ----------
    data : array_like, shape (n,) [data unit]
        Samples to differentiate, ``n >= 3``, finite.
    iterations : int
        Maximum number of lagged-diffusivity iterations, ``>= 1``.
    alpha : float
        Regularisation weight, ``> 0`` [data unit * dx unit].
    u0 : array_like, shape (n + 1,) for ``"small"``, (n,) for ``"large"``, optional
        Initial iterate in the units of ``u``; default Chartrand's naive derivative.
    scale : {"small", "large"}, optional
        ``"small"``: ``u`` at the ``n + 1`` cell edges; ``"large"``: ``u`` at the samples.
    ep, dx, tol : float, optional
        TV smoothing (> 0); grid spacing [e.g. s] (default ``1 / n``); relative-change tolerance.

    Returns
    -------
    TVRegDiffResult
        ``u``, ``derivative`` (at the samples), ``converged``, ``n_iter`` and the histories.

    Raises
    ------
    ValueError
        If ``data`` is not 1-D, finite and >= 3 samples, or another argument is invalid.

    Warns
    -----
    ConvergenceWarning
        If the relative change is still ``>= tol`` after ``iterations`` (``converged=False``).

    References
    ----------
    Chartrand 2011, ISRN Appl. Math. 2011, 164564; Rudin, Osher & Fatemi 1992, Physica D 60,
    259-268; Vogel & Oman 1996, SIAM J. Sci. Comput. 17(1), 227-238.
    """
    f = _check_data(data)
    n = f.size
    scale = _check_scale(scale)
    iterations = check_int("iterations", iterations, 1)
    alpha = check_positive("alpha", alpha)
    ep = check_positive("ep", ep)
    dx = 1.0 / n if dx is None else check_positive("dx", dx)
    tol = check_positive("tol", tol)
    u = _initial(f, u0, scale, dx)
    b = f - f[0]

    functional = np.empty(iterations)
    rel_change = np.empty(iterations)
    converged = False
    k = 0
    for k in range(iterations):
        if scale == "small":
            q = 1.0 / np.sqrt((np.diff(u) / dx) ** 2 + ep)
            u_new = solve_small(q, b, alpha, dx)
        else:
            q = 1.0 / np.sqrt(np.diff(u) ** 2 + ep)
            u_new = solve_large(q, b, alpha, dx)
        step = np.linalg.norm(u_new - u)
        rel_change[k] = step / max(np.linalg.norm(u_new), np.finfo(float).tiny)
        u = u_new
        functional[k] = tv_functional(u, f, alpha, scale=scale, ep=ep, dx=dx)
        if rel_change[k] < tol:
            converged = True
            break
    n_iter = k + 1
    if not converged:
        warnings.warn(
            f"tvregdiff: relative change {rel_change[k]:.3e} >= tol={tol:g} after "
            f"{n_iter} iterations (scale={scale!r}, alpha={alpha:g})",
            ConvergenceWarning,
            stacklevel=2,
        )
    derivative = u[1:].copy() if scale == "small" else _large_at_samples(u)
    return TVRegDiffResult(
        u=u,
        derivative=derivative,
        converged=converged,
        n_iter=n_iter,
        functional=functional[:n_iter].copy(),
        rel_change=rel_change[:n_iter].copy(),
        scale=scale,
        alpha=alpha,
        ep=ep,
        dx=dx,
    )


def _large_at_samples(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Interpolate the half-sample-lagged ``"large"`` derivative to the sample instants."""
    d = np.empty_like(u)
    d[1:-1] = 0.5 * (u[1:-1] + u[2:])
    d[0] = 1.5 * u[1] - 0.5 * u[2]
    d[-1] = 1.5 * u[-1] - 0.5 * u[-2]
    return d


def _initial(
    f: NDArray[np.float64], u0: ArrayLike | None, scale: str, dx: float
) -> NDArray[np.float64]:
    """Chartrand's default initial iterate, or the checked ``u0``."""
    n = f.size
    if u0 is None:
        if scale == "small":
            return np.concatenate(([0.0], np.diff(f), [0.0]))
        return np.concatenate(([0.0], np.diff(f))) / dx
    u0 = np.asarray(u0, dtype=float)
    expected = n + 1 if scale == "small" else n
    if u0.shape != (expected,):
        raise ValueError(
            f"`u0` must have shape ({expected},) for scale {scale!r} and n={n}, got {u0.shape}"
        )
    if not np.all(np.isfinite(u0)):
        raise ValueError("`u0` must be finite, got non-finite values")
    return u0.copy()


def _check_data(data: ArrayLike) -> NDArray[np.float64]:
    f = np.asarray(data, dtype=float)
    if f.ndim != 1:
        raise ValueError(f"`data` must be 1-D, got shape {f.shape}")
    if f.size < 3:
        raise ValueError(f"`data` must have at least 3 samples, got {f.size}")
    bad = np.flatnonzero(~np.isfinite(f))
    if bad.size:
        raise ValueError(
            f"`data` must be finite, got {f[bad[0]]} at index {bad[0]} ({bad.size} non-finite)"
        )
    return f


def _check_scale(scale: str) -> str:
    if not isinstance(scale, str) or scale.lower() not in _SCALES:
        raise ValueError(f"`scale` must be 'small' or 'large', got {scale!r}")
    return scale.lower()
