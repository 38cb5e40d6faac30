"""HV drivers of the virtual rig: a first-order lag and a slew limit between the DAC and the DEs.

Each DE is fed by a high-voltage converter whose output follows the reference of the rig's DAC
(zero-order hold) with a first-order lag and a slew-rate limit, within ``[0, 3000]`` V. The
drivers do not depend on the mechanics, so :mod:`pipeline.rig.plant` computes their outputs
first (:class:`DriverOutput`) and feeds them to the plant as functions of time.

References
----------
Masoud & Maas 2025, Sec. 5.1 (3 kV high-voltage converters).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp
from scipy.signal import lfilter

from pipeline.physics.params import V_MAX

__all__ = ["DriverOutput", "uniform_grid"]


def uniform_grid(t_ref: ArrayLike, name: str = "t_ref") -> tuple[NDArray[np.float64], float]:
    """Check that sample times are uniform and return them with their interval.

    Parameters
    ----------
    t_ref : array_like, shape (n,)
        Sample times [s], at least two.
    name : str
        Argument name for the messages.

    Returns
    -------
    t_ref : ndarray, shape (n,)
        The times [s].
    hold : float
        The interval [s].

    Raises
    ------
    ValueError
        If the times are not finite, fewer than two, or not uniform and increasing (to
        1e-6 of the interval).
    """
    t_ref = np.asarray(t_ref, dtype=float)
    if t_ref.ndim != 1 or t_ref.size < 2 or not np.all(np.isfinite(t_ref)):
        raise ValueError(f"`{name}` must be a finite 1-D array of at least 2 times [s]")
    hold = (t_ref[-1] - t_ref[0]) / (t_ref.size - 1)
    if hold <= 0 or np.max(np.abs(np.diff(t_ref) - hold)) > 1e-6 * hold:
        raise ValueError(f"`{name}` must be uniform and increasing (hold interval {hold!r} s)")
    return t_ref, float(hold)


class DriverOutput:
    """Output voltage of one HV driver for a zero-order-hold reference.

    The driver follows its reference ``r`` with a first-order lag and a slew-rate limit,

        dv/dt = clip((r(t) - v) / tau, -slew, slew),

    ``r`` clipped to ``[0, v_max]``, so ``v`` stays in ``[0, v_max]``. Within a hold
    interval that starts with ``|r - v| <= slew tau`` the limit is never reached and the
    solution is the exact ZOH discretisation of the lag, ``v_{k+1} = a v_k + (1 - a) r_k``
    with ``a = exp(-hold / tau)`` (run as a recursive filter, :func:`scipy.signal.lfilter`);
    every interval that starts slew-limited is integrated by :func:`scipy.integrate.solve_ivp`
    (RK45, ``max_step`` = the hold interval, dense output). Splitting at the hold intervals
    keeps the discontinuities of ``r`` out of the integrator's steps: one ``solve_ivp`` over
    a 1 ms staircase costs minutes of rejected steps.

    Parameters
    ----------
    t_ref : array_like, shape (n,)
        Uniform sample times of the reference [s]; sample ``k`` holds on
        ``[t_ref[k], t_ref[k] + hold)``, the last one until ``t_ref[-1] + hold``.
    r : array_like, shape (n,)
        Reference voltage [V].
    tau : float
        Lag time constant [s].
    slew : float
        Slew-rate limit [V/s].
    v0 : float
        Output at ``t_ref[0]`` [V] (also returned before it).
    v_max : float
        Largest output [V]; the reference is clipped to ``[0, v_max]``.

    Attributes
    ----------
    knots : ndarray, shape (n + 1,)
        Output at ``t_ref[0] + k hold``, ``k = 0..n`` [V].
    n_slew : int
        Number of slew-limited hold intervals.

    Raises
    ------
    ValueError
        If ``t_ref`` is not uniform, the shapes differ or ``tau``, ``slew`` are not positive.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (3 kV high-voltage converters).
    """

    def __init__(
        self,
        t_ref: ArrayLike,
        r: ArrayLike,
        *,
        tau: float,
        slew: float,
        v0: float = 0.0,
        v_max: float = V_MAX,
    ):
        t_ref, hold = uniform_grid(t_ref)
        r = np.clip(np.asarray(r, dtype=float), 0.0, v_max)
        if r.shape != t_ref.shape:
            raise ValueError(f"`r` must have the shape of `t_ref`, got {r.shape}")
        if not (tau > 0 and slew > 0):
            raise ValueError(f"`tau` and `slew` must be positive, got {tau!r}, {slew!r}")
        self.t0, self.hold, self.tau, self.slew = float(t_ref[0]), hold, float(tau), float(slew)
        self._r = r
        n = r.size
        a = math.exp(-hold / tau)
        lim = slew * tau
        v = np.empty(n + 1)
        v[0] = min(max(float(v0), 0.0), v_max)
        pieces: dict[int, object] = {}
        k = 0
        block = 4096
        while k < n:
            if abs(r[k] - v[k]) > lim:
                sol = solve_ivp(
                    self._slew_rhs,
                    (self.t0 + k * hold, self.t0 + (k + 1) * hold),
                    [v[k]],
                    method="RK45",
                    max_step=hold,
                    rtol=1e-9,
                    atol=1e-6,
                    dense_output=True,
                    args=(r[k],),
                )
                v[k + 1] = sol.y[0, -1]
                pieces[k] = sol.sol
                k += 1
                continue
            m = min(n - k, block)
            y = lfilter([1.0 - a], [1.0, -a], r[k : k + m], zi=[a * v[k]])[0]
            # interval k + j (j >= 1) starts at v_{k+j} = y[j - 1]
            bad = np.flatnonzero(np.abs(r[k + 1 : k + m] - y[: m - 1]) > lim)
            j = int(bad[0]) + 1 if bad.size else m
            v[k + 1 : k + j + 1] = y[:j]
            k += j
        self.knots = np.clip(v, 0.0, v_max)
        self._pieces = pieces
        self._knots_list = self.knots.tolist()
        self._r_list = r.tolist()
        self.n_slew = len(pieces)

    def _slew_rhs(self, t: float, v: NDArray[np.float64], rk: float) -> NDArray[np.float64]:
        return np.clip((rk - v) / self.tau, -self.slew, self.slew)

    def __call__(self, t: float) -> float:
        """Output voltage at one time ``t`` [s] (fast scalar path for the plant) [V].

        Parameters
        ----------
        t : float
            Time [s]; before ``t_ref[0]`` the initial value; after the end the lag towards
            the last reference continues (without the slew limit: extend the reference to
            cover the times needed).

        Returns
        -------
        float
            ``v(t)`` [V].
        """
        s = (t - self.t0) / self.hold
        if s <= 0.0:
            return self._knots_list[0]
        k = min(int(s), len(self._r_list) - 1)
        piece = self._pieces.get(k)
        if piece is not None and s < k + 1:
            return float(piece(t)[0])
        rk = self._r_list[k]
        return rk + (self._knots_list[k] - rk) * math.exp(-(s - k) * self.hold / self.tau)

    def values(self, t: ArrayLike) -> NDArray[np.float64]:
        """Output voltage at many times (vectorised :meth:`__call__`).

        Parameters
        ----------
        t : array_like, shape (m,)
            Times [s].

        Returns
        -------
        ndarray, shape (m,)
            ``v(t)`` [V].
        """
        t = np.asarray(t, dtype=float)
        s = (t - self.t0) / self.hold
        k = np.clip(np.floor(s).astype(int), 0, self._r.size - 1)
        rk = self._r[k]
        out = rk + (self.knots[k] - rk) * np.exp(-(s - k) * self.hold / self.tau)
        out = np.where(s <= 0.0, self.knots[0], out)
        for i, piece in self._pieces.items():
            sel = (s >= i) & (s < i + 1)
            if np.any(sel):
                out[sel] = piece(t[sel])[0]
        return out
