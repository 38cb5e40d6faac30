"""Simulation-error refinement of the identified model (beyond the paper).

The least squares of Eq. 40 minimise the *equation* error, which is biased when
the derivatives are noisy and is not what the model is used for. This module
refines the same parameters (RBF weights, backbone, optionally T_z) by
minimising the *free-run simulation* error over windows of the estimation data,
each started from the measured state (windowed free runs, a simple form of
multiple shooting). Test data are never used. Every few blocks of each estimation
record are held out of the fit (blocked cross-validation); the refined model is
accepted only if its windowed free-run error on those blocks falls and its free run
over the whole estimation records is not worse than the least-squares model's, so
refinement never increases that error and is not kept for fitting what it was fitted on.
An optional ridge prior (``[identify.refine] prior``) pulls the parameters towards the
least-squares estimate (Tikhonov regularisation of the simulation-error fit): where the model
class lacks part of the plant, the unpenalised fit trades that bias for windows it fits
better and a free run that gets worse; the prior keeps the finish close to the start. Given
several weights, each is refined and judged, and the accepted refinement with the lowest
free-run error over the whole estimation records is kept.

References
----------
Ljung, System Identification (1999), Sec. 7.3 (output-error methods); Bock &
Plitt (1984) and Ribeiro et al. (2020) on multiple shooting for simulation-error
fitting; Bergmeir & Benitez, Inf. Sci. 191 (2012), on blocked cross-validation of
time-series models; T. A. Johansen, Automatica 33(3), 441-446 (1997), on Tikhonov
regularisation towards prior parameters in nonlinear system identification.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import lazy_loader as lazy
import numpy as np

from debist.core import preflight, progress
from debist.core.metrics import rms
from debist.identify.config import IdentifyConfig, RefineConfig, refine_config
from debist.identify.fit import FitDiagnostics, Record, assemble_model
from debist.identify.signs import lost_dissipation
from debist.identify.stability import model_is_stable
from debist.model.rbf import RBFModel
from debist.model.terms import term_sign, term_table
from debist.model.termtable import TableModel
from debist.simulate.freerun import check_free_run, prepare_inputs, simulate
from debist.simulate.kernel import free_run_sensitivity, kernel_arrays
from debist.validate.prediction import restarted_runs

# the libraries below load on first use (lazy_loader): start-up of the CLI
optimize = lazy.load("scipy.optimize", suppress_warning=True)


@dataclass(frozen=True)
class RefineResult:
    """Outcome of the refinement, with the equation-error and simulation-error fits side by side.

    Attributes
    ----------
    model : RBFModel
        The accepted model (refined, or the least-squares model if refinement did not help).
    accepted : bool
        Whether the refined parameters were kept.
    window_rms_ls, window_rms_refined : float
        RMS free-run error over the windows before and after [unit of q].
    full_rms_ls, full_rms_refined : float
        RMS free-run error over the whole estimation records [unit of q].
    holdout_rms_ls, holdout_rms_refined : float
        RMS free-run error over the windows of the held-out blocks [unit of q] (NaN
        without held-out blocks).
    holdout_windows : int
        Windows in the held-out blocks.
    nfev : int
        Cost evaluations used.
    message : str
        The optimiser's message.
    seconds : float
        Wall time [s] (of every candidate prior's refinement together).
    prior : float
        The ridge weight of this refinement (with several, the one chosen).
    candidates : tuple of dict
        With several ridge weights, per weight ``prior``, ``accepted``,
        ``full_rms_simulation_error`` and ``holdout_rms_simulation_error`` [unit of q],
        ``nfev`` (0: not run) and ``message``; else empty.
    """

    model: RBFModel
    accepted: bool
    window_rms_ls: float
    window_rms_refined: float
    full_rms_ls: float
    full_rms_refined: float
    nfev: int
    message: str
    seconds: float
    holdout_rms_ls: float = float("nan")
    holdout_rms_refined: float = float("nan")
    holdout_windows: int = 0
    prior: float = 0.0
    candidates: tuple[dict, ...] = ()


def _theta_model(
    thetas: np.ndarray,
    names: Sequence[str],
    basis,
    cfg: IdentifyConfig,
    n_inputs: int,
    n_windows: int,
    T_z: float,
    log_tz: bool,
    creep_rate: float = 0.0,
    slip_width: Sequence[float] = (),
) -> TableModel:
    """Eq. 37 with one parameter vector per trajectory (rows repeated for every window).

    Parameters
    ----------
    thetas : ndarray, shape (R, P)
        Parameter vectors in the order of the regressor columns ``names`` (and log T_z last
        with ``log_tz``).
    names : sequence of str
        Regressor column names (``"m_q"`` first when the mass is identified).
    basis : RBFBasis
        The model's basis.
    cfg : IdentifyConfig
        Terms, input map, fixed input gains.
    n_inputs : int
        Number of inputs.
    n_windows : int
        Trajectories per parameter vector.
    T_z : float
        The model's T_z [s] when it is not refined.
    log_tz : bool
        Whether the last parameter is log T_z.
    creep_rate : float, optional
        The creep states' relaxation rate lambda [1/s] (``creep[i]`` columns, Eq. 26).
    slip_width : sequence of float, optional
        Break-away deflections of the Maxwell-slip elements (``slip[e]`` columns) [unit of q].

    Returns
    -------
    TableModel
        ``R * n_windows`` trajectories, parameter vector by parameter vector.
    """
    rows = np.repeat(thetas, n_windows, axis=0)
    tz = np.exp(rows[:, -1]) if log_tz else np.full(rows.shape[0], T_z)
    theta = rows[:, :-1] if log_tz else rows
    terms = [n for n in names if n != "m_q"]
    extra = {"creep_rate": creep_rate, "slip_width": tuple(slip_width) or None}
    if cfg.m_q == "identify":
        gains = [f"input_gain{j + 1}" for j in range(n_inputs)]
        table = term_table([*terms, *gains], basis, n_inputs, cfg.input_map,
                           cfg.coulomb_velocity, cfg.prior, **extra)  # fmt: skip
        fixed = np.broadcast_to(np.asarray(cfg.input_gain, float), (theta.shape[0], n_inputs))
        weights = np.hstack([-theta[:, 1:], fixed])
        mass = theta[:, 0]
    else:
        table = term_table(terms, basis, n_inputs, cfg.input_map, cfg.coulomb_velocity, cfg.prior,
                           **extra)  # fmt: skip
        weights = theta * np.array([term_sign(n) for n in terms])
        mass = np.full(theta.shape[0], float(cfg.m_q))
    return TableModel(table, weights, mass, tz)


def _held_out(n: int, rcfg: RefineConfig) -> np.ndarray:
    """Mask of the samples of a record of ``n`` samples that lie in held-out blocks."""
    held = np.zeros(n, dtype=bool)
    if rcfg.holdout:
        block = 2 * rcfg.length
        held = (np.arange(n) // block) % rcfg.holdout == rcfg.holdout - 1
    return held


def _windows(records: Sequence[Record], rcfg: RefineConfig):
    """Fitted and held-out windows, each a list of (record index, start).

    ``windows`` starts are spread evenly over the records; those whose window touches a
    held-out block are dropped from the fit. The held-out windows tile each held-out block
    at half-window steps.
    """
    L = rcfg.length
    spans = [(i, r.q.size - L) for i, r in enumerate(records) if r.q.size > L]
    total = sum(s for _, s in spans)
    if total <= 0:
        return [], []
    picks = np.linspace(0, total - 1, rcfg.windows).astype(int)
    fit, test, offset = [], [], 0
    for i, span in spans:
        held = _held_out(records[i].q.size, rcfg)
        covered = np.convolve(held, np.ones(L, dtype=int), mode="valid")[:span]  # per start
        fit += [
            (i, int(p - offset))
            for p in picks[(picks >= offset) & (picks < offset + span)]
            if not covered[p - offset]
        ]
        inside = np.flatnonzero(covered == L)
        test += [(i, int(s)) for s in inside if (s - inside[0]) % max(L // 2, 1) == 0]
        offset += span
    return fit, test


def _window_rms(model: RBFModel, records, picks, rcfg: RefineConfig, q_limit: float) -> float:
    """RMS free-run error over windows restarted from the model's states along the records."""
    if not picks:
        return float("nan")
    L = rcfg.length
    runs = restarted_runs(
        model,
        records,
        [(i, s, s + L) for i, s in picks],
        records[0].dt,
        substeps=rcfg.substeps,
        interpolation=rcfg.interpolation,
        q_limit=q_limit,
    )
    err = np.concatenate(
        [run - records[i].q[s : s + L] for run, (i, s) in zip(runs, picks, strict=True)]
    )
    return rms(err)


def refine_model(
    model: RBFModel,
    diag: FitDiagnostics,
    records: Sequence[Record],
    cfg: IdentifyConfig,
    rcfg: RefineConfig,
) -> RefineResult:
    """Refine an identified model by minimising its windowed free-run error.

    With several ridge weights (``rcfg.prior`` a tuple) it runs once per weight, and of the runs
    that pass the guards the one with the lowest free-run error over the whole estimation
    records is kept; with none accepted, the least-squares model is kept.

    Parameters
    ----------
    model : RBFModel
        The least-squares model of :func:`debist.identify.fit.fit_rbf_model`.
    diag : FitDiagnostics
        Its diagnostics (parameter vector, column names and norms).
    records : sequence of Record
        The estimation records (never test data).
    cfg : IdentifyConfig
        The identification settings the model was fitted with.
    rcfg : RefineConfig
        Window and optimiser settings; ``prior`` one weight or several.

    Returns
    -------
    RefineResult
        The kept refinement (``candidates`` every weight's outcome when there were several).

    Raises
    ------
    ResourceError
        If the batched window runs exceed the memory budget (:func:`_check_memory`).

    References
    ----------
    Ljung, System Identification (1999), Sec. 7.3 (output-error methods); Johansen,
    Automatica 33(3), 441-446 (1997) (the ridge prior); Bergmeir & Benitez, Inf. Sci. 191
    (2012) (held-out blocks of the estimation records).
    """
    priors = rcfg.priors
    runs = [_refine_once(model, diag, records, cfg, replace(rcfg, prior=p)) for p in priors]
    if len(runs) == 1:
        return runs[0]

    kept = [r for r in runs if r.accepted] or runs
    # NaN (diverged, or not run) last; min keeps the first of equal scores: the order given
    best = min(kept, key=lambda r: np.nan_to_num(r.full_rms_refined, nan=np.inf))
    candidates = tuple(
        {"prior": r.prior, "accepted": r.accepted, "full_rms_simulation_error": r.full_rms_refined,
         "holdout_rms_simulation_error": r.holdout_rms_refined, "nfev": r.nfev,
         "message": r.message}
        for r in runs
    )  # fmt: skip
    return replace(best, candidates=candidates, seconds=sum(r.seconds for r in runs))


def _refine_once(model: RBFModel, diag: FitDiagnostics, records: Sequence[Record],
                 cfg: IdentifyConfig, rcfg: RefineConfig) -> RefineResult:  # fmt: skip
    """Refine an identified model by minimising its windowed free-run error (one ridge weight).

    Parameters and result as :func:`refine_model`, with ``rcfg.prior`` a single weight.

    Notes
    -----
    Parameters are scaled by ``||y|| / ||psi_j||`` (the size of a parameter whose
    term would be as large as the regression output), so that the optimiser sees
    comparable variables. The Jacobian comes from the forward sensitivities of the
    windows' free runs, integrated with them by the compiled kernel
    (:func:`debist.simulate.kernel.free_run_sensitivity`): the exact derivative of the discrete
    free run, at the cost of about one run per window.
    Residuals are q_sim - q over each window, with diverged windows penalised, and with
    ``rcfg.prior > 0`` the ridge rows ``prior * r_0 * sqrt(N) * (x - x_LS)`` in the scaled
    variables (``r_0`` the windows' RMS error at the start, ``N`` their sample count), so
    ``|x - x_LS| <= 1 / prior`` at the optimum; the reported window error excludes them. The
    creep states (Eq. 26) and the Maxwell-slip elements are refined with the rest (their relaxation
    rate and break-away deflections stay fixed; the element stiffnesses stay >= 0), each
    window starting from their states along the record (``RBFModel.measured_states``).
    Before anything is allocated, settings whose batched simulations exceed the memory
    budget are refused (``ResourceError``, :mod:`debist.core.preflight`).
    """
    # the fit's settings with the slip elements resolved to the model's break-away deflections
    cfg = replace(cfg, slip=tuple(model.slip_width) if model.has_slip else False)
    _check_memory(model, diag, records, rcfg)
    t_start = time.perf_counter()
    dt = records[0].dt
    picks, held = _windows(records, rcfg)
    if not picks:
        return _rejected(model, records, rcfg, "records shorter than one window", t_start)
    L = rcfg.length
    inputs = [records[i].v[s : s + L] for i, s in picks]
    q_meas = np.stack([records[i].q[s : s + L] for i, s in picks])
    q0 = np.array([records[i].q[s] for i, s in picks])
    qd0 = np.array([records[i].q_dot[s] for i, s in picks])
    q_all = np.concatenate([r.q for r in records])
    penalty = 10.0 * float(np.ptp(q_all))
    q_limit = 2.0 * float(np.max(np.abs(q_all)))  # as validation's divergence bound
    log_tz = rcfg.refine_T_z and model.T_z > 0
    scale = diag.y_norm / np.where(diag.column_norms > 0, diag.column_norms, 1.0)
    x0 = diag.theta / scale
    if log_tz:
        x0 = np.append(x0, np.log(model.T_z))
        scale = np.append(scale, 1.0)
    ns = (
        max(rcfg.substeps, int(np.ceil(dt / (1.5 * model.T_z)))) if model.T_z > 0 else rcfg.substeps
    )
    if log_tz:
        ns *= 2  # room for T_z to shrink during the search
    fine = prepare_inputs(inputs, ns, rcfg.interpolation)
    W = len(picks)

    names = list(diag.columns)
    identify_mass = cfg.m_q == "identify"
    terms = [n for n in names if n != "m_q"]
    n_fixed = model.n_inputs if identify_mass else 0  # the known input gains
    term_param = [names.index(n) for n in terms] + [-1] * n_fixed
    signs = [-1.0 if identify_mass else term_sign(n) for n in terms] + [1.0] * n_fixed
    # each window starts from the model's states along its record: the friction state is the
    # measured velocity filtered by z' = (q_dot - z) / T_z, not q_dot (true only at rest)
    # (and the creep and slip states likewise, from the measured velocity)
    x_rec = [model.measured_states(r.q, r.q_dot, dt) for r in records]
    x_start = np.stack([x_rec[i][s] for i, s in picks])
    x_start[:, 0], x_start[:, 1] = q0, qd0
    lengths = np.full(W, L)
    last: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Window residuals and their Jacobian (forward sensitivities) at scaled xs."""
        key = xs.tobytes()
        if key not in last:
            theta = xs * scale
            batch = _theta_model(
                theta[None, :], names, model.basis, cfg, model.n_inputs, 1, model.T_z, log_tz,
                model.creep_rate, model.slip_width,
            )  # fmt: skip
            q_sim, dq = free_run_sensitivity(
                kernel_arrays(batch), fine.values, lengths, dt, fine.substeps, x_start,
                q_limit, np.array(term_param), np.array(signs),
                names.index("m_q") if identify_mass else -1,
                len(names) if log_tz else -1, xs.size,
            )  # fmt: skip
            err = np.where(np.isfinite(q_sim), q_sim - q_meas, penalty)
            jac = np.where(np.isfinite(dq), dq, 0.0) * scale  # d/d(xs) = d/d(theta) * scale
            last.clear()
            last[key] = (err.reshape(-1), jac.reshape(-1, xs.size))
        return last[key]

    calls = [0]

    r0 = evaluate(x0)[0]
    # ridge towards the least-squares estimate (Tikhonov), in the scaled variables
    ridge = rcfg.priors[0] * rms(r0) * math.sqrt(r0.size)
    ridge_jac = ridge * np.eye(x0.size)  # constant: built once, not per Jacobian

    def fun(x):
        calls[0] += 1
        progress.report("refine: optimiser evaluations", calls[0], rcfg.max_nfev)
        err = evaluate(x)[0]
        return np.concatenate([err, ridge * (x - x0)]) if ridge > 0 else err

    def jac(x):
        J = evaluate(x)[1]
        return np.vstack([J, ridge_jac]) if ridge > 0 else J

    lower = np.full(x0.size, -np.inf)  # the slip elements' stiffnesses stay >= 0, as in the fit
    lower[[j for j, n in enumerate(names) if n.startswith("slip[")]] = 0.0
    sol = optimize.least_squares(
        fun,
        np.maximum(x0, lower),
        jac=jac,
        bounds=(lower, np.inf),
        method="trf",
        max_nfev=rcfg.max_nfev,
        ftol=rcfg.ftol,
        xtol=1e-10,
        gtol=1e-10,
    )
    theta = sol.x * scale
    T_z = float(np.exp(theta[-1])) if log_tz else model.T_z
    if log_tz:
        theta = theta[:-1]
    refined = assemble_model(
        theta, diag.columns, model.basis, cfg, model.n_inputs, T_z, model.q_range, model.creep_rate
    )
    full_ls, full_ref = (_full_rms(m, records, rcfg, q_limit) for m in (model, refined))
    held_ls, held_ref = (_window_rms(m, records, held, rcfg, q_limit) for m in (model, refined))
    accepted = bool(np.isfinite(full_ref) and full_ref <= full_ls)
    message = str(sol.message)
    if not accepted:
        message = "rejected: the free run over the estimation records got worse"
    elif held and not (np.isfinite(held_ref) and held_ref < held_ls):
        accepted = False
        message = (
            f"rejected: the windows of the held-out estimation blocks got worse "
            f"({held_ls:.4g} -> {held_ref:.4g} RMS)"
        )
    if accepted:
        qd_all = np.concatenate([r.q_dot for r in records])
        stable, reason = model_is_stable(refined, q_all, q_dot=qd_all)
        if not stable:
            accepted, message = False, f"rejected: the refined model is unstable ({reason})"
        elif negative := lost_dissipation(model, refined, q_all):
            accepted = False
            message = f"rejected: the refined model has negative damping ({negative}), the fit none"
    return RefineResult(
        model=refined if accepted else model,
        accepted=accepted,
        window_rms_ls=rms(r0),
        window_rms_refined=rms(sol.fun[: r0.size]),
        full_rms_ls=full_ls,
        full_rms_refined=full_ref,
        nfev=int(sol.nfev),
        message=message,
        seconds=time.perf_counter() - t_start,
        holdout_rms_ls=held_ls,
        holdout_rms_refined=held_ref,
        holdout_windows=len(held),
        prior=rcfg.priors[0],
    )


def _full_rms(
    model: RBFModel, records: Sequence[Record], rcfg: RefineConfig, q_limit: float
) -> float:
    """RMS free-run error of a model over the whole estimation records (NaN if it diverges)."""
    sims = simulate(
        model,
        [r.v for r in records],
        records[0].dt,
        np.array([r.q[0] for r in records]),
        np.array([r.q_dot[0] for r in records]),
        substeps=rcfg.substeps,
        interpolation=rcfg.interpolation,
        q_limit=q_limit,
    )
    err = np.concatenate([s.q - r.q for s, r in zip(sims, records, strict=True)])
    return rms(err)


def _rejected(model, records, rcfg, message, t_start) -> RefineResult:
    nan = float("nan")
    return RefineResult(
        model, False, nan, nan, nan, nan, 0, message, time.perf_counter() - t_start,
        prior=rcfg.priors[0],
    )  # fmt: skip


def _check_memory(model: RBFModel, diag: FitDiagnostics, records: Sequence[Record], rcfg) -> None:
    """Refuse a simulation-error refinement whose batched free runs exceed the budget.

    Parameters
    ----------
    model : RBFModel
        The least-squares model (``T_z``, ``n_inputs``, ``basis``).
    diag : FitDiagnostics
        Its diagnostics (``theta``, ``columns``).
    records : sequence of Record
        The estimation records (their lengths and sample time).
    rcfg : RefineConfig
        ``windows``, ``length``, ``substeps``, ``refine_T_z``.

    Raises
    ------
    ResourceError
        If :func:`debist.core.preflight.refine_bytes` for the window runs, or
        :func:`debist.core.preflight.free_run_bytes` for the free runs over the whole records,
        exceeds the budget, naming the ``[identify.refine]`` keys.

    Notes
    -----
    The sub-steps follow :func:`refine_model`: at least
    ``substeps`` and ``dt / (1.5 T_z)``, doubled when T_z is refined.

    References
    ----------
    Ljung, System Identification (1999), Sec. 7.3 (output-error methods).
    """
    dt = records[0].dt
    lengths = [r.q.size for r in records]
    check_free_run(
        model,
        lengths,
        model.n_inputs,
        dt,
        rcfg.substeps,
        f"[identify.refine] substeps = {rcfg.substeps}",
    )
    log_tz = bool(rcfg.refine_T_z and model.T_z > 0)
    ns = int(rcfg.substeps)
    if model.T_z > 0:
        ns = max(ns, math.ceil(dt / (1.5 * model.T_z)))
    ns *= 2 if log_tz else 1
    P = len(diag.theta) + log_tz
    W, L = int(rcfg.windows), int(rcfg.length)
    preflight.check_memory(
        preflight.refine_bytes(
            W, L, P, model.n_inputs, ns, len(diag.columns), model.basis.M, model.n_states
        ),
        f"[identify.refine] windows = {W}, length = {L}",
        f"the Jacobian's batched free run of {(P + 1) * W} window trajectories "
        f"({W} windows x {P + 1} parameter vectors) of {L} samples x {ns} sub-steps",
    )


__all__ = ["RefineConfig", "RefineResult", "refine_config", "refine_model"]
