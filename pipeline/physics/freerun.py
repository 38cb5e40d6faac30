"""The analytical reduced model (Eq. 26) as a free-run model for validation (Table 2).

:class:`AnalyticalModel` tabulates the reduced model's curves once (``m_q, dm_q/dq, d, f, g_i,
k_i`` of :class:`debist.physics.reduced.ReducedModel`) and interpolates them with cubic
splines, so that the shared batched RK4 simulator (:mod:`debist.simulate.freerun`) runs it
beside the identified and SINDy models, driven by the measured voltages, with the same initial
states and the same scoring. The tabulation grid is fine (default 0.025 mm); the interpolation
error is far below the model's own error.

References
----------
Masoud & Maas 2025, Eq. 26, Table 2 ("analytical" row).
"""

from __future__ import annotations

import functools

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics.params import PrototypeParams
from debist.physics.reduced import ReducedModel, fit_reduced

# the libraries below load on first use (lazy_loader): start-up of the CLI
interpolate = lazy.load("scipy.interpolate", suppress_warning=True)

__all__ = ["AnalyticalModel", "analytical_model"]

_CURVES = ("m_q", "dm_q", "d", "f", "g1", "g2", "k1", "k2", "phi")


class AnalyticalModel:
    """Reduced model of Eq. 26 with tabulated curves, for :func:`debist.simulate.freerun.simulate`.

    States ``x = [q, q_dot, q_eps,1, q_eps,2]`` [m, m/s, -, -]; inputs ``v = [v1, v2]`` [V].

    Parameters
    ----------
    model : ReducedModel
        The fitted reduced model (:func:`debist.physics.reduced.fit_reduced`).
    n_grid : int, optional
        Points of the tabulation over the model's fit range.

    Attributes
    ----------
    n_states : int
        4.
    q_range : tuple of float
        Tabulated range [m]; outside it the splines extrapolate.

    References
    ----------
    Masoud & Maas 2025, Eq. 26.
    """

    n_states = 4

    def __init__(self, model: ReducedModel, n_grid: int = 2001):
        self.model = model
        self.q_range = model.q_range
        q = np.linspace(*model.q_range, n_grid)
        cur = model.curves(q)
        self._spl = interpolate.CubicSpline(
            q, np.stack([getattr(cur, name) for name in _CURVES], axis=1)
        )
        p = model.params
        self._relax = p.Y_MW / p.eta_MW if p.eta_MW > 0 else 0.0
        self._kbar = p.V_DE * p.Y_MW
        stiff = np.abs(cur.k) + self._kbar * (np.abs(cur.k1) + np.abs(cur.k2)) * 50.0
        self._omega = float(np.sqrt(np.max(stiff / cur.m_q)))
        self._rate = float(np.max(cur.d / cur.m_q)) + self._relax

    def phi(self, q: ArrayLike) -> NDArray[np.float64]:
        """Pitch angle along the reduced model's ``q_m(q)`` (Eq. 1, 24).

        Parameters
        ----------
        q : array_like
            Tip displacement [m].

        Returns
        -------
        ndarray
            ``phi`` [rad], same shape as ``q``.
        """
        return self._spl(np.asarray(q, dtype=float))[..., _CURVES.index("phi")]

    def initial_state(self, q0: np.ndarray, q_dot0: np.ndarray) -> np.ndarray:
        """States (B, 4) at ``q0`` [m], ``q_dot0`` [m/s] with relaxed Maxwell strains (0)."""
        q0 = np.asarray(q0, dtype=float)
        return np.stack([q0, np.asarray(q_dot0, float), np.zeros_like(q0), np.zeros_like(q0)], 1)

    def rhs(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """State derivative of Eq. 26 for a batch.

        Parameters
        ----------
        x : ndarray, shape (B, 4)
            States [m, m/s, -, -].
        v : ndarray, shape (B, 2)
            Voltages ``v1, v2`` [V].

        Returns
        -------
        x_dot : ndarray, shape (B, 4)
            Derivatives.
        q_ddot : ndarray, shape (B,)
            Acceleration [m/s^2].
        """
        q, qd = x[:, 0], x[:, 1]
        m_q, dm_q, d, f, g1, g2, k1, k2, _ = self._spl(q).T
        force = g1 * v[:, 0] ** 2 + g2 * v[:, 1] ** 2
        force -= 0.5 * dm_q * qd * qd + d * qd + f + self._kbar * (k1 * x[:, 2] + k2 * x[:, 3])
        qdd = force / m_q
        e1 = k1 * qd - self._relax * x[:, 2]
        e2 = k2 * qd - self._relax * x[:, 3]
        return np.stack([qd, qdd, e1, e2], axis=1), qdd

    def kernel_splines(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Return the model as the compiled free-run kernel takes it (its ``spline_arrays``).

        Returns
        -------
        x : ndarray, shape (n,)
            Breakpoints [m].
        c : ndarray, shape (4, n - 1, 8)
            Cubic coefficients of ``m_q, dm_q/dq, d, f, g1, g2, k1, k2``.
        relax : float
            ``Y_MW / eta_MW`` [1/s].
        kbar : float
            ``V_DE Y_MW`` [J].
        """
        return self._spl.x, self._spl.c[:, :, :8], self._relax, self._kbar

    def max_step(self) -> float:
        """Largest stable RK4 step [s] (2.5 / fastest linearised rate of the curves)."""
        return 2.5 / max(self._omega, self._rate)


@functools.lru_cache(maxsize=8)
def analytical_model(params: PrototypeParams, *, q_max: float = 25e-3) -> AnalyticalModel:
    """Build the analytical model of a prototype with nominal parameters.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters [SI] (``params.b`` is the operating point).
    q_max : float
        Half width of the range of ``q`` covered [m].

    Returns
    -------
    AnalyticalModel
        Cached per prototype: the validate and compare stages of one run share it.

    Raises
    ------
    StaticsError
        If the static path cannot be continued over the range.

    References
    ----------
    Masoud & Maas 2025, Eq. 24-26.
    """
    return AnalyticalModel(fit_reduced(params, q_max=q_max))
