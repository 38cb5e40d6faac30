"""HV drivers of the virtual rig: a first-order lag and a slew limit between the DAC and the DEs.

Each DE is fed by a high-voltage converter whose output follows the reference of the rig's DAC
(zero-order hold) with a first-order lag and a slew-rate limit, within ``[0, 3000]`` V. The
drivers do not depend on the mechanics, so :mod:`debist.rig.plant` computes their outputs
first (:class:`DriverOutput`) and feeds them to the plant as functions of time, or as arrays
(:attr:`DriverOutput.table`) to the compiled plant (:func:`debist.rig.compiled.driver_value`).

References
----------
Masoud & Maas 2025, Sec. 5.1 (3 kV high-voltage converters).
"""

from __future__ import annotations

import math

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.physics.params import V_MAX

# the libraries below load on first use (lazy_loader): start-up of the CLI
signal = lazy.load("scipy.signal", suppress_warning=True)

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

    The driver follows its reference with a first-order lag and a slew-rate limit,
    ``dv/dt = clip((r(t) - v) / tau, -slew, slew)``, ``r`` clipped to ``[0, v_max]``; the
    solution is piecewise analytic (exact ZOH lag, slew-limited ramps):
    docs/explanation/implementation.md.

    Parameters
    ----------
    t_ref : array_like, shape (n,)
        Uniform sample times of the reference [s]; sample ``k`` holds on
        ``[t_ref[k], t_ref[k] + hold)``.
    r : array_like, shape (n,)
        Reference voltage [V].
    tau, slew : float
        Lag time constant [s]; slew-rate limit [V/s].
    v0 : float
        Output at ``t_ref[0]`` [V] (also returned before it).
    v_max : float
        Largest output [V].

    Attributes
    ----------
    knots : ndarray, shape (n + 1,)
        Output at ``t_ref[0] + k hold``, ``k = 0..n`` [V].
    ramp : ndarray, shape (n,)
        Duration of the slew-limited ramp at the start of each hold interval [s].
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
        ramp = np.zeros(n)
        k = 0
        block = 4096
        while k < n:
            d = r[k] - v[k]
            if abs(d) > lim:
                sg = 1.0 if d > 0.0 else -1.0
                ramp[k] = (abs(d) - lim) / slew
                if ramp[k] >= hold:
                    v[k + 1] = v[k] + sg * slew * hold
                else:
                    v[k + 1] = r[k] - sg * lim * math.exp(-(hold - ramp[k]) / tau)
                k += 1
                continue
            m = min(n - k, block)
            y = signal.lfilter([1.0 - a], [1.0, -a], r[k : k + m], zi=[a * v[k]])[0]
            # interval k + j (j >= 1) starts at v_{k+j} = y[j - 1]
            bad = np.flatnonzero(np.abs(r[k + 1 : k + m] - y[: m - 1]) > lim)
            j = int(bad[0]) + 1 if bad.size else m
            v[k + 1 : k + j + 1] = y[:j]
            k += j
        self.knots = np.clip(v, 0.0, v_max)
        self.ramp = ramp
        self.n_slew = int(np.count_nonzero(ramp))
        self._knots_list = self.knots.tolist()
        self._r_list = r.tolist()
        self._ramp_list = ramp.tolist()

    @property
    def table(self) -> NDArray[np.float64]:
        """The driver as one float array (the compiled plant's form).

        Returns
        -------
        ndarray, shape (3 n + 6,)
            ``[t_0, hold, tau, slew, n, r (n), knots (n + 1), ramp (n)]`` ([s], [s], [s],
            [V/s], [-], [V], [V], [s]); :func:`debist.rig.compiled.driver_value` evaluates
            it as :meth:`__call__` does.
        """
        head = [self.t0, self.hold, self.tau, self.slew, float(self._r.size)]
        return np.concatenate([head, self._r, self.knots, self.ramp])

    def __call__(self, t: float) -> float:
        """Output voltage at one time ``t`` [s] (fast scalar path for the plant) [V].

        Parameters
        ----------
        t : float
            Time [s]; before ``t_ref[0]`` the initial value; after the end the output
            keeps following the last reference (ramp and lag as within a hold interval).

        Returns
        -------
        float
            ``v(t)`` [V].
        """
        s = (t - self.t0) / self.hold
        if s <= 0.0:
            return self._knots_list[0]
        k = min(int(s), len(self._r_list) - 1)
        rk, vk, tc = self._r_list[k], self._knots_list[k], self._ramp_list[k]
        e = (s - k) * self.hold
        if tc > 0.0:
            sg = 1.0 if rk > vk else -1.0
            if e < tc:
                return vk + sg * self.slew * e
            return rk - sg * self.slew * self.tau * math.exp(-(e - tc) / self.tau)
        return rk + (vk - rk) * math.exp(-e / self.tau)

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
        rk, vk, tc = self._r[k], self.knots[k], self.ramp[k]
        e = np.maximum(s - k, 0.0) * self.hold  # before t0 (s < 0) the first knot holds
        sg = np.where(rk > vk, 1.0, -1.0)
        lag = rk + (vk - rk) * np.exp(-e / self.tau)
        after = rk - sg * self.slew * self.tau * np.exp(-np.maximum(e - tc, 0.0) / self.tau)
        out = np.where(tc > 0.0, np.where(e < tc, vk + sg * self.slew * e, after), lag)
        return np.where(s <= 0.0, self.knots[0], out)
