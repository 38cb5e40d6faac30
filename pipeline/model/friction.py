"""The friction state z and the creep states of the identified model (Masoud & Maas 2025).

The state equations are written here once: the NumPy engine, the model's own right-hand side
and (compiled by numba) the free-run kernel call :func:`friction_state_rate` and
:func:`creep_state_rate`.
"""

from __future__ import annotations

import numpy as np


def friction_state_rate(q_dot, z, T_z):
    """Return z' = (q_dot - z) / T_z, the friction state's rate of Eq. 37.

    Parameters
    ----------
    q_dot, z : float or ndarray
        Velocity and friction state [unit of q / s].
    T_z : float or ndarray
        Friction time constant [s], > 0 (with T_z = 0 the state is q_dot itself).

    Returns
    -------
    float or ndarray
        [unit of q / s^2].

    References
    ----------
    Masoud & Maas 2025, Eq. 37.

    Examples
    --------
    >>> friction_state_rate(1.0, 0.25, 0.5)
    1.5
    """
    return (q_dot - z) / T_z


def creep_state_rate(phi, q_dot, rate, w):
    """Return w' = phi(q) q_dot - lambda w, a creep state's rate (Eq. 26, Maxwell element).

    Parameters
    ----------
    phi : float or ndarray
        The state's basis value at q.
    q_dot : float or ndarray
        Velocity [unit of q / s].
    rate : float
        The relaxation rate lambda = Y_MW / eta_MW [1/s].
    w : float or ndarray
        The creep state.

    Returns
    -------
    float or ndarray
        The state's rate.

    References
    ----------
    Masoud & Maas 2025, Eq. 26.

    Examples
    --------
    >>> creep_state_rate(0.5, 2.0, 4.0, 0.25)
    0.0
    """
    return phi * q_dot - rate * w


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


def creep_states(phi: np.ndarray, q_dot: np.ndarray, dt: float, rate: float) -> np.ndarray:
    """Filter ``phi_j(q) q_dot`` through w_j' = phi_j(q) q_dot - lambda w_j: the creep states.

    The creep of the DEs (Masoud & Maas 2025, Eq. 26, q_eps' = k(q) q' - (Y_MW/eta_MW) q_eps)
    with k(q) written in the RBF basis: ``w_j = z_j / lambda`` where z_j is ``phi_j q_dot``
    through the friction filter of :func:`friction_state` with ``T_z = 1 / lambda`` (the same
    exact first-order-hold discretisation, started at rest relative to its input, which is
    w = 0 for a record that starts at rest).

    Parameters
    ----------
    phi : ndarray, shape (n, M)
        The basis along the record, phi_j(q) (:class:`debist.model.basis.RBFBasis`).
    q_dot : ndarray, shape (n,)
        Velocity [unit of q / s].
    dt : float
        Sample time [s].
    rate : float
        Relaxation rate lambda = Y_MW / eta_MW [1/s], > 0.

    Returns
    -------
    ndarray, shape (n, M)
        The creep states w_j [unit of q].

    Raises
    ------
    ValueError
        If ``dt <= 0`` or ``rate <= 0``.

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (Maxwell creep), Eq. 37 (the friction filter).

    Examples
    --------
    A constant input settles at phi q_dot / lambda:

    >>> w = creep_states(np.ones((4, 1)), np.full(4, 2.0), dt=0.01, rate=4.0)
    >>> w[:, 0].tolist()
    [0.5, 0.5, 0.5, 0.5]
    """
    if not rate > 0:
        raise ValueError(f"`rate` must be positive, got {rate!r}")
    u = np.asarray(phi, dtype=float) * np.asarray(q_dot, dtype=float)[:, None]
    cols = [friction_state(col, dt, 1.0 / rate) for col in u.T]
    return np.stack(cols, axis=1) / rate if cols else u.copy()
