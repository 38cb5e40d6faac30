"""The friction state z of the identified model (Masoud & Maas 2025, Eq. 37)."""

from __future__ import annotations

import numpy as np


def friction_state(q_dot: np.ndarray, dt: float, T_z: float) -> np.ndarray:
    """Filter the velocity through z' = (q_dot - z) / T_z, discretised exactly.

    The velocity is taken as piecewise linear between samples (first-order
    hold); for that input the recursion
    ``z[k+1] = a z[k] + b1 q_dot[k+1] + b0 q_dot[k]`` with ``a = exp(-dt/T_z)``,
    ``b1 = 1 - (T_z/dt)(1 - a)`` and ``b0 = (T_z/dt)(1 - a) - a`` is exact.
    The filter starts at rest relative to the velocity, ``z[0] = q_dot[0]``.

    Parameters
    ----------
    q_dot : ndarray, shape (n,)
        Velocity [unit of q / s].
    dt : float
        Sample time [s].
    T_z : float
        Friction time constant [s]; 0 gives ``z = q_dot``.

    Returns
    -------
    ndarray, shape (n,)
        The friction state z [unit of q / s].

    Raises
    ------
    ValueError
        If ``dt <= 0`` or ``T_z < 0``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Franklin, Powell & Workman, Digital Control of
    Dynamic Systems (triangle-hold equivalent).

    Examples
    --------
    A constant velocity passes unchanged:

    >>> friction_state(np.full(4, 2.0), dt=0.01, T_z=0.05).tolist()
    [2.0, 2.0, 2.0, 2.0]
    """
    if not dt > 0:
        raise ValueError(f"`dt` must be positive, got {dt!r}")
    if not T_z >= 0:
        raise ValueError(f"`T_z` must be >= 0, got {T_z!r}")
    q_dot = np.asarray(q_dot, dtype=float)
    if T_z == 0:
        return q_dot.copy()
    a = np.exp(-dt / T_z)
    r = (T_z / dt) * (-np.expm1(-dt / T_z))
    b = [1.0 - r, r - a]
    den = [1.0, -a]
    from scipy.signal import lfilter, lfiltic

    zi = lfiltic(b, den, y=[q_dot[0]], x=[q_dot[0]])
    z, _ = lfilter(b, den, q_dot, zi=zi)
    return z
