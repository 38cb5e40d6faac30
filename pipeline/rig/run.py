"""One experiment on the virtual rig: drivers, plant, sensors and recorder, and its truth.

:func:`simulate_rig` drives the plant :func:`make_plant` selects (the full model of
:class:`debist.rig.plant.RigPlant` or the reduced one of
:class:`debist.rig.reduced.ReducedPlant`) through the HV drivers
(:class:`debist.rig.drivers.DriverOutput`), integrates it with
:func:`scipy.integrate.odeint` (ODEPACK's LSODA; or :func:`scipy.integrate.solve_ivp`'s
Radau or BDF) and records what the rig's sensors see: the laser with
white noise, quantisation and a finite range, sampled ``oversample`` times faster than the log
and decimated by a zero-phase FIR (the rig's anti-aliasing), and noisy voltage monitors
(:class:`RigRun`, with the noise-free truth). :func:`true_curves` gives the characteristic
curves an identification should recover.

References
----------
Masoud & Maas 2025, Eq. 19-26, 33, 37, Sec. 5.1 (3 kV converters, laser sensor, 10 ms log).
Hindmarsh 1983 (ODEPACK); Petzold 1983 (LSODA); see :mod:`debist.physics.segments`.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import DebistWarning
from debist.physics.params import V_MAX
from debist.physics.reduced import reduced_curves
from debist.physics.segments import ODEINT, solve_segments
from debist.physics.statics import force_displacements
from debist.rig.drivers import DriverOutput, uniform_grid
from debist.rig.params import RigParams
from debist.rig.plant import RigPlant
from debist.rig.reduced import ReducedPlant, reduced_true_curves

# the libraries below load on first use (lazy_loader): start-up of the CLI
signal = lazy.load("scipy.signal", suppress_warning=True)

__all__ = ["METHODS", "TOLERANCES", "RigRun", "make_plant", "simulate_rig", "true_curves"]

#: Log samples simulated beyond each end of the record so that the zero-phase FIR of the
#: decimation (half length 10 log samples, :func:`scipy.signal.decimate`) has no edge effect.
_PAD_LOG = 11
#: Integrators of :func:`simulate_rig`: ODEPACK's LSODA (:func:`scipy.integrate.odeint`,
#: compiled step loop) and the implicit :func:`scipy.integrate.solve_ivp` methods.
METHODS = (ODEINT, "Radau", "BDF")
#: Per method: the default ``rtol`` and the factor on ``atol`` for the positions (bending
#: coordinates, friction deflections), chosen for the same accuracy of ``q`` (see
#: :func:`simulate_rig`).
TOLERANCES = {ODEINT: (1e-8, 0.3), "Radau": (1e-4, 1.0), "BDF": (1e-4, 1.0)}


def make_plant(rig: RigParams, v1, v2, *, compiled: bool = True):
    """Build the plant ``[rig.plant] model`` selects, with the rig's friction.

    Parameters
    ----------
    rig : RigParams
        Rig parameters; ``rig.model`` selects the mechanics.
    v1, v2 : callable
        Applied voltages ``v_i(t)`` [V].
    compiled : bool
        Compiled kernels for the full plant (:class:`RigPlant`); the reduced plant runs in
        NumPy.

    Returns
    -------
    RigPlant or debist.rig.reduced.ReducedPlant
        ``"full"``: the full model of Sec. 3 (Eq. 19-23); ``"reduced"``: the reduced model
        of Eq. 24-26. Both offer ``functions``, ``rest_state``, ``atol_vector``, ``tip``,
        ``tip_velocity``, ``pitch`` and ``friction_force``.

    References
    ----------
    Masoud & Maas 2025, Eq. 19-26.
    """
    if rig.model == "reduced":
        return ReducedPlant(rig, v1, v2)
    return RigPlant(rig, v1, v2, compiled=compiled)


@dataclass(frozen=True)
class RigRun:
    """One rig experiment: the logged channels and the truth behind them.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Log instants ``t_ref[0] + k sample_time`` [s].
    q : ndarray, shape (n,)
        Laser reading of the tip displacement [m]; saturates at ``+-sensor_range``.
    v1, v2 : ndarray, shape (n,)
        Voltage monitors of DE 1 and DE 2 [V].
    r1, r2 : ndarray, shape (n,)
        Reference voltages at the log instants [V].
    q_true, q_dot_true, phi_true : ndarray, shape (n,)
        Noise-free tip displacement [m] (Eq. 16), velocity [m/s], frame pitch [rad] (Eq. 1).
    x_true : ndarray, shape (n, n_states)
        Plant states: ``[q_m, q_m_dot, q_eps, z]`` (full), ``[q, q_dot, q_eps, z]`` (reduced).
    F_friction : ndarray, shape (n,)
        Friction force on the tip [N].
    v1_applied, v2_applied : ndarray, shape (n,)
        Voltages at the DEs, the drivers' outputs [V].
    saturated : ndarray of bool, shape (n,)
        ``|q_true|`` beyond the sensor range.
    sample_time : float
        Log interval [s].
    seed : int
        Seed of the sensor noise.
    nfev, njev : int
        Right-hand-side and Jacobian evaluations of the plant integration.
    success : bool
        Whether every integration segment succeeded.
    message : str
        Messages of the integrator.
    wall_time : float
        Wall-clock time of :func:`simulate_rig` [s].
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    v1: NDArray[np.float64]
    v2: NDArray[np.float64]
    r1: NDArray[np.float64]
    r2: NDArray[np.float64]
    q_true: NDArray[np.float64]
    q_dot_true: NDArray[np.float64]
    phi_true: NDArray[np.float64]
    x_true: NDArray[np.float64]
    F_friction: NDArray[np.float64]
    v1_applied: NDArray[np.float64]
    v2_applied: NDArray[np.float64]
    saturated: NDArray[np.bool_]
    sample_time: float
    seed: int
    nfev: int
    njev: int
    success: bool
    message: str
    wall_time: float


def _decimate(y: NDArray[np.float64], factor: int) -> NDArray[np.float64]:
    """Zero-phase FIR decimation (Hamming-window sinc, 20 factor + 1 taps)."""
    return y if factor == 1 else signal.decimate(y, factor, ftype="fir", zero_phase=True)


def _laser_lag(y: NDArray[np.float64], tau: float, dt: float) -> NDArray[np.float64]:
    """First-order lag ``tau y_s' = y - y_s`` on the grid ``dt``, started at rest (ZOH form)."""
    if tau <= 0.0:
        return y
    a = math.exp(-dt / tau)
    out, _ = signal.lfilter([1.0 - a], [1.0, -a], y, zi=[a * y[0]])
    return out


def _trailing_mean(y: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Mean of ``y[k - n + 1 .. k]`` at every ``k >= n - 1`` (NaN before)."""
    c = np.concatenate([[0.0], np.cumsum(y)])
    out = np.full(y.size, np.nan)
    out[n - 1 :] = (c[n:] - c[:-n]) / n
    return out


def simulate_rig(
    rig: RigParams,
    t_ref: ArrayLike,
    r1: ArrayLike,
    r2: ArrayLike,
    *,
    sample_time: float,
    seed: int,
    side: int = -1,
    method: str = "odeint",
    rtol: float | None = None,
    atol: float = 1e-8,
    step_threshold: float = 0.1 * V_MAX,
    compiled: bool = True,
) -> RigRun:
    """Run one experiment on the virtual rig: drivers, plant, sensors and recorder.

    Parameters
    ----------
    rig : RigParams
        Prototype and rig.
    t_ref, r1, r2 : array_like, shape (n_ref,)
        Uniform DAC times [s] (each held for ``hold``); references of DE 1 and DE 2 [V].
    sample_time, seed : float, int
        Log interval [s] (the log covers ``n_ref hold``); seed of the sensor and monitor noise.
    side : {-1, +1}
        Initial well: -1 left (the paper's start, q = -10 mm), +1 right.
    method : {"odeint", "Radau", "BDF"}
        LSODA by :func:`scipy.integrate.odeint` (default), or :func:`scipy.integrate.solve_ivp`.
    rtol, atol : float, optional
        Relative tolerance (default per method, :data:`TOLERANCES`); absolute one [m].
    step_threshold : float
        Reference jumps larger than this [V] become integration breakpoints.
    compiled : bool
        Integrate the compiled plant (default) or the NumPy reference.

    Returns
    -------
    RigRun

    Raises
    ------
    ValueError
        If an argument is out of its domain or the well ``side`` does not exist.

    Warns
    -----
    DebistWarning
        If a reference leaves ``[0, 3000]`` V and is clipped.

    References
    ----------
    Masoud & Maas 2025, Eq. 1, 16, 19-26, Sec. 5.1; Hindmarsh 1983 (ODEPACK); Petzold 1983
    (LSODA). Stages and accuracy of the integrators: docs/explanation/implementation.md.
    """
    start = time.perf_counter()
    t_ref, hold = uniform_grid(t_ref)
    r = np.stack([np.asarray(r1, dtype=float), np.asarray(r2, dtype=float)])
    if r.shape != (2, t_ref.size):
        raise ValueError(f"`r1`, `r2` must have the shape of `t_ref` {t_ref.shape}")
    if not np.all(np.isfinite(r)):
        raise ValueError("`r1`, `r2` must be finite")
    if np.any(r < 0.0) or np.any(r > V_MAX):
        warnings.warn(
            f"simulate_rig: references within [{r.min():.6g}, {r.max():.6g}] V are clipped to "
            f"[0, {V_MAX:g}] V",
            DebistWarning,
            stacklevel=2,
        )
        r = np.clip(r, 0.0, V_MAX)
    if side not in (-1, 1):
        raise ValueError(f"`side` must be -1 or +1, got {side!r}")
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {', '.join(METHODS)}, got {method!r}")
    rtol_default, pos_factor = TOLERANCES[method]
    rtol = rtol_default if rtol is None else rtol
    duration = t_ref.size * hold
    if not (sample_time > 0 and sample_time <= duration):
        raise ValueError(f"`sample_time` must be in (0, {duration}] s, got {sample_time!r}")
    n_log = math.floor(duration / sample_time + 1e-9)
    os_ = rig.oversample
    dt = sample_time / os_
    pad = _PAD_LOG * os_
    t0 = float(t_ref[0])
    j = np.arange(-pad, n_log * os_ + pad)
    t_fine = t0 + j * dt
    # reference held beyond its end for the padding
    t_end = float(t_fine[-1])
    n_ext = max(t_ref.size, math.ceil((t_end - t0) / hold) + 1)
    t_ext = t0 + hold * np.arange(n_ext)
    r_ext = np.concatenate([r, np.repeat(r[:, -1:], n_ext - t_ref.size, axis=1)], axis=1)
    drivers = [
        DriverOutput(t_ext, r_ext[i], tau=rig.driver_tau, slew=rig.driver_slew) for i in range(2)
    ]
    plant = make_plant(rig, drivers[0], drivers[1], compiled=compiled)
    x_rest = plant.rest_state(side)
    atol_v = plant.atol_vector(atol, pos_factor * atol)
    jumps = np.flatnonzero(np.any(np.abs(np.diff(r_ext, axis=1)) > step_threshold, axis=0))
    breaks = [t0 + (k + 1) * hold for k in jumps]
    t_run = t_fine[t_fine >= t0]
    fun, jac = plant.functions()
    sol = solve_segments(
        fun, (t0, t_end), x_rest, t_run, breaks, method=method, jac=jac, rtol=rtol, atol=atol_v
    )
    X = np.full((t_run.size, plant.n_states), np.nan)  # NaN beyond a failure
    X[: sol.t.size] = sol.y
    X_all = np.concatenate([np.repeat(x_rest[None, :], pad, axis=0), X])  # at rest before
    q_fine = plant.tip(X_all)
    v_fine = np.stack([d.values(t_fine) for d in drivers])
    rng = np.random.default_rng(seed)
    y = _laser_lag(q_fine + rig.sensor_offset, rig.sensor_lag, dt)
    y = y + rng.normal(0.0, rig.sensor_noise, q_fine.size)
    if rig.sensor_resolution > 0:
        y = np.round(y / rig.sensor_resolution) * rig.sensor_resolution
    y = np.clip(y, -rig.sensor_range, rig.sensor_range)
    mon = v_fine + rng.normal(0.0, rig.monitor_noise, v_fine.shape)
    idx = pad + os_ * np.arange(n_log)  # log instants on the internal grid
    if rig.sensor_average == 0:  # zero-phase FIR decimation of every channel
        log = slice(_PAD_LOG, _PAD_LOG + n_log)
        q_log = np.clip(_decimate(y, os_)[log], -rig.sensor_range, rig.sensor_range)
        mon_log = np.stack([_decimate(m, os_)[log] for m in mon])
    else:  # trailing block mean of the laser, point-sampled monitors
        q_log = _trailing_mean(y, rig.sensor_average)[idx]
        mon_log = mon[:, idx]
    t_log = t_fine[idx]
    X_log = X_all[idx]
    k_ref = np.clip(np.floor((t_log - t0) / hold + 1e-9).astype(int), 0, t_ref.size - 1)
    q_true = q_fine[idx]
    return RigRun(
        t=t_log,
        q=q_log,
        v1=mon_log[0],
        v2=mon_log[1],
        r1=r[0, k_ref],
        r2=r[1, k_ref],
        q_true=q_true,
        q_dot_true=plant.tip_velocity(X_log),
        phi_true=plant.pitch(X_log),
        x_true=X_log,
        F_friction=plant.friction_force(X_log),
        v1_applied=v_fine[0, idx],
        v2_applied=v_fine[1, idx],
        saturated=np.abs(q_true) > rig.sensor_range,
        sample_time=float(sample_time),
        seed=int(seed),
        nfev=sol.nfev,
        njev=sol.njev,
        success=sol.success,
        message=sol.message,
        wall_time=time.perf_counter() - start,
    )


def true_curves(rig: RigParams, q_grid: ArrayLike) -> dict[str, NDArray[np.float64]]:
    """Return the prototype's true characteristic curves in the identified model's convention.

    From the reduced model of the prototype (:func:`debist.physics.reduced.reduced_curves`,
    static path at v = 0, asymmetry included) and the full model's static force-displacement
    curves (Fig. 4). The rig's ``gain_i`` scale ``g_i`` and its ``force_offset`` moves ``f``;
    friction, drivers and sensors are not part of these curves. Why two gains:
    docs/explanation/implementation.md.

    Parameters
    ----------
    rig : RigParams
        Rig parameters (uses ``prototype``).
    q_grid : array_like, shape (n,)
        Tip displacements [m], increasing, spacing at most ~0.5 mm (continuation).

    Returns
    -------
    dict[str, ndarray]
        Each of shape (n,): ``"q"`` [m]; ``"f"`` restoring force at v = 0 [N]; ``"c" = f / q``
        [N/m] (Eq. 33); ``"k" = df/dq`` [N/m]; ``"g1"``, ``"g2" = 1/2 dC_i/dq`` [N/V^2]
        (small-signal); ``"g1_vmax"``, ``"g2_vmax"`` the secants at ``V_MAX`` [N/V^2];
        ``"m_q"`` [kg]; ``"d"`` [N s/m]; ``"phi"`` pitch along the static path [rad].

    Notes
    -----
    For ``rig.model = "reduced"`` the curves are the reduced plant's own, exact in the form of
    Eq. 37 (:func:`debist.rig.reduced.reduced_true_curves`; plus ``dm_q``, ``k1``, ``k2``).

    References
    ----------
    Masoud & Maas 2025, Eq. 18, 24-26, 33, 37, Fig. 4; docs/interpretation.md item 8.
    """
    if rig.model == "reduced":
        return _with_rig_forces(reduced_true_curves(rig, q_grid), rig)
    c = reduced_curves(rig.prototype, q_grid)
    rest, on_1, on_2 = force_displacements(rig.prototype, c.q, [(0.0, 0.0), (V_MAX, 0.0),
                                                                (0.0, V_MAX)])  # fmt: skip
    secant = [(rest.F - on.F) / V_MAX**2 for on in (on_1, on_2)]
    curves = {
        "q": c.q,
        "f": c.f,
        "c": c.c,
        "k": c.k,
        "g1": c.g1,
        "g2": c.g2,
        "g1_vmax": secant[0],
        "g2_vmax": secant[1],
        "m_q": c.m_q,
        "d": c.d,
        "phi": c.phi,
    }
    return _with_rig_forces(curves, rig)


def _with_rig_forces(
    curves: dict[str, NDArray[np.float64]], rig: RigParams
) -> dict[str, NDArray[np.float64]]:
    """Apply the rig's DE gains and constant tip force to the prototype's curves.

    ``g_i`` (and the secants) scale by ``gain_i``; the force offset ``F_0`` moves the
    restoring force to ``f - F_0`` (``m_q q_ddot + ... + f = g_1 v_1^2 + g_2 v_2^2 + F_0``),
    ``c = f / q`` with it; ``k = df/dq`` is unchanged.
    """
    if rig.gain_1 == 1.0 and rig.gain_2 == 1.0 and rig.force_offset == 0.0:
        return curves
    out = dict(curves)
    for i, gain in ((1, rig.gain_1), (2, rig.gain_2)):
        out[f"g{i}"] = gain * curves[f"g{i}"]
        out[f"g{i}_vmax"] = gain * curves[f"g{i}_vmax"]
    q = np.asarray(curves["q"], dtype=float)
    f = curves["f"] - rig.force_offset
    small = np.abs(q) < 1e-12
    out["f"] = f
    out["c"] = np.where(small, curves["k"], f / np.where(small, 1.0, q))
    return out
