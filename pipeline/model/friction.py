"""The friction state z, the creep states and the slip elements of the identified model.

The state equations are written here once: the NumPy engine, the model's own right-hand side
and (compiled by numba) the free-run kernel call :func:`friction_state_rate`,
:func:`creep_state_rate`, :func:`slip_state_rate` and :func:`slip_clip`.

The *slip elements* are the generalised Maxwell-slip friction of Al-Bender, Lampaert & Swevers
(2005) in its stop-operator form: element e is a spring in series with an ideal block that
slips when the spring's deflection delta_e reaches its break-away deflection Delta_e. With
Delta_e fixed on a grid, the friction force ``sum_e k_e delta_e`` is linear in the element
stiffnesses k_e, which the least squares of Eq. 40 identifies beside the friction state z.
(Masoud & Maas 2025, Sec. 4, name this model; the paper's Eq. 37 keeps the first-order z.)
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


def slip_state_rate(q_dot, delta, width):
    """Return delta_e' of an ideal Maxwell-slip element: q_dot while it sticks, 0 while it slips.

    The element slips (its deflection stays put) when the deflection is at its break-away value
    and the motion loads it further: ``|delta| >= width`` and ``q_dot delta > 0``.

    Parameters
    ----------
    q_dot : float or ndarray
        Velocity [unit of q / s].
    delta : float or ndarray
        The element's deflection [unit of q].
    width : float or ndarray
        Break-away deflection Delta_e > 0 [unit of q].

    Returns
    -------
    float or ndarray
        [unit of q / s].

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005, Eq. 3-4 (the elementary Maxwell-slip element);
    Krasnosel'skii & Pokrovskii 1989 (the stop operator).

    Examples
    --------
    >>> [slip_state_rate(qd, delta, 1.0) for qd, delta in ((2.0, 0.5), (2.0, 1.0), (-2.0, 1.0))]
    [2.0, 0.0, -2.0]
    """
    return q_dot * slip_sticks(q_dot, delta, width)


def slip_sticks(q_dot, delta, width):
    """Return 1 while a Maxwell-slip element sticks, 0 while it slips: d delta_e' / d q_dot.

    The element slips when its deflection is at the break-away value and the motion loads it
    further, ``|delta| >= width`` and ``q_dot delta > 0`` (:func:`slip_state_rate`); away from
    that switching surface the rate ``q_dot * slip_sticks(...)`` is linear in q_dot with this
    slope, which the forward sensitivities of the free run use.

    Parameters
    ----------
    q_dot : float or ndarray
        Velocity [unit of q / s].
    delta : float or ndarray
        The element's deflection [unit of q].
    width : float or ndarray
        Break-away deflection Delta_e > 0 [unit of q].

    Returns
    -------
    int or ndarray of int
        1 (sticks) or 0 (slips).

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005, Eq. 3-4.

    Examples
    --------
    >>> [int(slip_sticks(qd, 1.0, 1.0)) for qd in (2.0, -2.0)]
    [0, 1]
    """
    return 1 - (abs(delta) >= width) * (q_dot * delta > 0.0)


def slip_clip(delta, width):
    """Return the deflection held to the break-away range ``[-width, width]`` (after a step).

    The fixed-step free run moves an element's deflection with :func:`slip_state_rate` inside
    a step and then projects it back onto ``|delta| <= width`` (Moreau's catch-up step of the
    stop operator), so that a step that crosses the break-away point cannot overshoot it.

    Parameters
    ----------
    delta : float or ndarray
        Deflection [unit of q].
    width : float or ndarray
        Break-away deflection Delta_e > 0 [unit of q].

    Returns
    -------
    float or ndarray
        ``min(max(delta, -width), width)``.

    References
    ----------
    Moreau 1977, "Evolution problem associated with a moving convex set in a Hilbert space"
    (the catch-up algorithm); Al-Bender, Lampaert & Swevers 2005.

    Examples
    --------
    >>> float(slip_clip(1.5, 1.0)), float(slip_clip(-0.25, 1.0))
    (1.0, -0.25)
    """
    return np.minimum(np.maximum(delta, -width), width)


def slip_states(q_dot: np.ndarray, dt: float, widths: np.ndarray) -> np.ndarray:
    """Deflections of the Maxwell-slip elements along a record (the stop operators of q).

    The position increments are the trapezoidal integral of the velocity, and each element
    follows them until it reaches its break-away deflection:
    ``delta[k+1] = clip(delta[k] + (q_dot[k] + q_dot[k+1]) dt / 2, -Delta, Delta)``, from
    ``delta[0] = 0`` (the elements unloaded at the record's start, as the free run starts).

    Parameters
    ----------
    q_dot : ndarray, shape (n,)
        Velocity [unit of q / s].
    dt : float
        Sample time [s].
    widths : ndarray, shape (E,)
        Break-away deflections Delta_e > 0 [unit of q].

    Returns
    -------
    ndarray, shape (n, E)
        The deflections delta_e [unit of q].

    Raises
    ------
    ValueError
        If ``dt <= 0`` or a width is not positive.

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005; Moreau 1977 (catch-up algorithm).

    Examples
    --------
    >>> slip_states(np.array([1.0, 1.0, 1.0, -1.0]), 1.0, np.array([1.5])).ravel().tolist()
    [0.0, 1.0, 1.5, 1.5]
    """
    if not dt > 0:
        raise ValueError(f"`dt` must be positive, got {dt!r}")
    widths = np.asarray(widths, dtype=float)
    if not np.all(widths > 0):
        raise ValueError(f"slip widths must be positive, got {widths.tolist()}")
    q_dot = np.asarray(q_dot, dtype=float)
    from debist.model.slip_kernel import stop_operator  # numba: loaded when slip is used

    return stop_operator(0.5 * dt * (q_dot[1:] + q_dot[:-1]), widths)


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

    The creep of the DEs (Eq. 26) with k(q) in the RBF basis: ``w_j = z_j / lambda`` with z_j
    the friction filter of :func:`friction_state` (``T_z = 1 / lambda``) of ``phi_j q_dot``.

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
