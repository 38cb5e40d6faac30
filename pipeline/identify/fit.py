"""Least-squares RBF identification with the T_z outer search (Masoud & Maas 2025, Sec. 4.2)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from debist.core import preflight
from debist.core.errors import IdentificationError
from debist.core.metrics import rms
from debist.identify.bootstrap import block_bootstrap
from debist.identify.config import SLIP_GRID, IdentifyConfig
from debist.identify.driven import undriven_weights
from debist.identify.regularise import (
    Estimator,
    constraint_bounds,
    gcv_lambda,
    smoothness_operator,
    tie_rows,
    weight_penalty,
)
from debist.identify.signs import physical_signs
from debist.model.basis import RBFBasis
from debist.model.friction import creep_states, friction_state, slip_states
from debist.model.rbf import RBFModel
from debist.model.terms import PHYSICS_TERMS, force_columns, force_table, input_columns
from debist.model.termtable import input_map


@dataclass(frozen=True)
class Record:
    """One estimation record: measured position, its derivatives and the inputs.

    Parameters
    ----------
    name : str
        Data set name (for messages).
    q : ndarray, shape (n,)
        Position [unit of q].
    q_dot, q_ddot : ndarray, shape (n,)
        Velocity [unit/s] and acceleration [unit/s^2] from the differentiation stage.
    v : ndarray, shape (n, n_inputs)
        Inputs [V].
    dt : float
        Sample time [s].
    weight : ndarray, shape (n,), optional
        Weight of each sample's equation error (weighted least squares; the rows of Eq. 40
        are multiplied by it after the low-pass); None: 1 (:func:`variance_weights`).
    """

    name: str
    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray
    v: np.ndarray
    dt: float
    weight: np.ndarray | None = None


@dataclass(frozen=True)
class FitDiagnostics:
    """Diagnostics of the least-squares problem (Masoud & Maas 2025, Sec. 5.2: rank, condition).

    Attributes
    ----------
    n_samples : int
        Regressor rows.
    columns : list of str
        Regressor column names.
    rank, condition : int, float
        Numerical rank and 2-norm condition number of the column-scaled regressor.
    singular_values : ndarray, shape (p,)
        Its singular values.
    residual_rms : float
        RMS of the equation error [N, or unit/s^2 per unit mass] (weighted with ``weights_window``).
    fit_r2 : float
        Coefficient of determination of the regression output.
    support : ndarray of int, shape (M,)
        Samples within one width of each centre.
    T_z_trace, creep_trace : ndarray, shape (k, 2)
        (T_z [s] or lambda [1/s], relative residual) of every evaluation of the outer searches.
    theta : ndarray, shape (p,)
        The least-squares parameters, in the order of ``columns``.
    column_norms : ndarray, shape (p,)
        2-norms of the regressor columns.
    y_norm : float
        2-norm of the regression output.
    smoothing : float
        The smoothness penalty's lambda used (0: none; :mod:`debist.identify.regularise`).
    gcv_trace : ndarray, shape (k, 3)
        ``(lambda, GCV, tr H)`` of the GCV search (empty without it).
    theta_boot : ndarray, shape (B, p) or None
        Block-bootstrap replicates of ``theta``; None with ``bootstrap = 0``.
    block : int
        The bootstrap's block length [samples] (0 without bootstrap).
    dissipation : str
        Empty, or which signs were imposed and why (:func:`physical_signs`).
    undriven : str
        Empty, or the gains' weights tied to their driven neighbours and why
        (:func:`debist.identify.driven.undriven_weights`).
    """

    n_samples: int
    columns: list[str]
    rank: int
    condition: float
    singular_values: np.ndarray
    residual_rms: float
    fit_r2: float
    support: np.ndarray
    T_z_trace: np.ndarray
    theta: np.ndarray
    column_norms: np.ndarray
    y_norm: float
    theta_boot: np.ndarray | None = None
    block: int = 0
    smoothing: float = 0.0
    gcv_trace: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    creep_trace: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    dissipation: str = ""
    undriven: str = ""


def _trimmed(records: Sequence[Record], trim: int) -> list[Record]:
    out = []
    for r in records:
        if r.q.size <= 2 * trim + 10:
            raise IdentificationError(
                f"data set '{r.name}': {r.q.size} samples are too few for trim = {trim}",
                reason="samples",
            )
        s = slice(trim, r.q.size - trim)
        weight = None if r.weight is None else r.weight[s]
        cut = {"q": r.q[s], "q_dot": r.q_dot[s], "q_ddot": r.q_ddot[s], "v": r.v[s]}
        out.append(replace(r, **cut, weight=weight))
    return out


def _prefilter(a: np.ndarray, r: Record, cfg: IdentifyConfig) -> np.ndarray:
    """Zero-phase low-pass of regressor columns or output along time (filtered equation error).

    Raises
    ------
    IdentificationError
        If the corner frequency is not below the record's Nyquist frequency.
    """
    if cfg.lowpass is None:
        return a
    nyquist = 0.5 / r.dt
    if not cfg.lowpass < nyquist:
        raise IdentificationError(
            f"data set '{r.name}': [identify] lowpass = {cfg.lowpass:g} Hz is not below the "
            f"Nyquist frequency {nyquist:g} Hz of its sample time {r.dt:g} s",
            reason="nyquist",
        )
    from scipy import signal

    return signal.sosfiltfilt(_lowpass_sos(cfg.lowpass, 1.0 / r.dt).copy(), a, axis=0)


@functools.lru_cache(maxsize=8)
def _lowpass_sos(corner: float, fs: float) -> np.ndarray:
    """4th-order Butterworth low-pass sections for a corner and sampling rate [Hz], cached.

    Every fit of the T_z search and of the held-out folds filters its columns with the same
    filter. The array is shared: callers pass scipy a copy.
    """
    from scipy import signal

    return signal.butter(4, corner, fs=fs, output="sos")


def _rows(a: np.ndarray, r: Record, cfg: IdentifyConfig) -> np.ndarray:
    """Rows of Eq. 40 as the least squares sees them: low-passed, then weighted."""
    a = _prefilter(a, r, cfg)
    if r.weight is None:
        return a
    return a * (r.weight[:, None] if a.ndim == 2 else r.weight)


def variance_weights(
    records: Sequence[Record], residual: np.ndarray, window: float
) -> list[Record]:
    """Weight each sample's equation error by the inverse of its local RMS (two-stage FGLS).

    The equation error of Eq. 40 is far from homoscedastic: in the switching transients it
    is several times its typical size (derivative error of fast motion, and on the full
    model the one-coordinate reduction failing while the beam switches), and ordinary least
    squares lets those few seconds set the curves everywhere. The local RMS ``s(t)`` of a
    first, ordinary fit's residual over ``window`` (a moving average of its square, per
    record) gives the weight ``w = s_med / max(s, s_med)``, ``s_med`` its median over all
    samples: samples noisier than typical count less, none counts more.

    Parameters
    ----------
    records : sequence of Record
        The estimation records, as fitted (after ``trim``).
    residual : ndarray, shape (sum of the records' samples,)
        The first fit's equation error, stacked in record order.
    window : float
        Width of the moving RMS [s].

    Returns
    -------
    list of Record
        The records with ``weight`` set, shape (n,) each, in ``(0, 1]``.

    Raises
    ------
    ValueError
        If ``residual`` does not have one value per sample.

    References
    ----------
    Carroll & Ruppert 1988, Transformation and Weighting in Regression, Chapman & Hall,
    Ch. 3 (variance function estimation, generalised least squares); Ljung, System
    Identification, 2nd ed., Sec. 7.3 (weighted prediction-error criteria).
    """
    from scipy.ndimage import uniform_filter1d

    sizes = [r.q.size for r in records]
    residual = np.asarray(residual, dtype=float)
    if residual.shape != (sum(sizes),):
        raise ValueError(f"residual has shape {residual.shape}, the records {sum(sizes)} samples")
    parts = np.split(residual, np.cumsum(sizes)[:-1])
    local = [
        np.sqrt(uniform_filter1d(e**2, max(1, round(window / r.dt)), mode="nearest"))
        for r, e in zip(records, parts, strict=True)
    ]
    typical = float(np.median(np.concatenate(local)))
    if not typical > 0:
        return list(records)
    return [
        replace(r, weight=typical / np.maximum(s, typical))
        for r, s in zip(records, local, strict=True)
    ]


def _system(
    records: Sequence[Record],
    z_all: Sequence[np.ndarray],
    basis: RBFBasis,
    cfg: IdentifyConfig,
    w_all: Sequence[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Stack regressor rows Psi and outputs y of all records (Eq. 40; creep columns w_all).

    With ``cfg.slip`` (resolved to break-away deflections, :func:`slip_widths`) the force
    side has the Maxwell-slip elements' deflections along each record too; with
    ``cfg.inertia`` the inertia columns ``q^a q_ddot + 1/2 a q^(a-1) q_dot^2``.
    """
    rows, ys = [], []
    names: list[str] = []
    for i, (r, z) in enumerate(zip(records, z_all, strict=True)):
        w = None if w_all is None else w_all[i]
        slip = slip_states(r.q_dot, r.dt, np.asarray(cfg.slip)) if cfg.slip else None
        F, f_names = force_columns(
            r.q, z, basis, cfg.rbf, cfg.backbone, cfg.coulomb_velocity, cfg.prior, w, slip,
            cfg.inertia_powers, r.q_dot, r.q_ddot, _strain(r, cfg),
        )  # fmt: skip
        hv = input_map(r.v, cfg.input_map)
        if cfg.m_q == "identify":
            rows.append(_rows(np.hstack([r.q_ddot[:, None], F]), r, cfg))
            ys.append(_rows(hv @ np.asarray(cfg.input_gain, dtype=float), r, cfg))
            names = ["m_q", *f_names]
        else:
            G, g_names = input_columns(r.q, hv, basis, cfg.rbf, cfg.backbone, cfg.prior)
            rows.append(_rows(np.hstack([-F, G]), r, cfg))
            ys.append(_rows(float(cfg.m_q) * r.q_ddot, r, cfg))
            names = [*f_names, *g_names]
    return np.vstack(rows), np.concatenate(ys), names


def _model_prior(cfg: IdentifyConfig):
    """Return the prior the model keeps: its creep curves only with ``physics_creep``.

    A model with other ``physics_*`` terms keeps the bytes it had before the creep term.
    """
    if "physics_creep" in cfg.backbone:
        return cfg.prior
    return replace(cfg.prior, k=None, k_bar=0.0, creep_rate=0.0)


def _strain(r: Record, cfg: IdentifyConfig) -> np.ndarray | None:
    """Return the creep strains of ``physics_creep`` along a record (none without the term)."""
    return cfg.prior.strain(r.q, r.q_dot, r.dt) if "physics_creep" in cfg.backbone else None


def _solve(psi: np.ndarray, y: np.ndarray, names: list[str], cfg: IdentifyConfig, check: bool):
    """Least squares on the column-scaled regressor via SVD, with rank and condition checks."""
    scale = np.linalg.norm(psi, axis=0)
    if check:
        dead = [names[j] for j in np.flatnonzero(scale == 0)]
        if dead:
            raise IdentificationError(
                f"regressor columns {dead[:6]} are identically zero: the experiment does not "
                "excite them (an input never applied, or no motion)",
                reason="excitation",
            )
    scale = np.where(scale == 0, 1.0, scale)
    U, S, Vt = np.linalg.svd(psi / scale, full_matrices=False)
    tol = S[0] * max(psi.shape) * np.finfo(float).eps
    rank = int(np.sum(tol < S))
    cond = float(S[0] / S[-1]) if S[-1] > 0 else np.inf
    if check and rank < psi.shape[1]:
        null = np.abs(Vt[-1])
        culprits = [names[j] for j in np.argsort(null)[::-1][:4]]
        raise IdentificationError(
            f"regressor is rank deficient (rank {rank} of {psi.shape[1]} columns); the null "
            f"direction involves {culprits}: remove a redundant term or excite the system more",
            reason="rank",
        )
    if check and cond > cfg.max_condition:
        raise IdentificationError(
            f"regressor condition number {cond:.3g} exceeds "
            f"max_condition = {cfg.max_condition:.3g}: "
            f"reduce M (= {cfg.M}) or sigma_n (= {cfg.sigma_n}), or excite the range better",
            reason="condition",
        )
    keep = tol < S
    uty = U[:, keep].T @ y
    theta = (Vt[keep].T @ (uty / S[keep])) / scale
    resid = y - psi @ theta
    # ||psi/scale x - y|| = ||S V^T x - U^T y|| up to a constant: the compressed problem
    return theta, resid, rank, cond, S, (S[keep, None] * Vt[keep], uty)


def supported_range(q: np.ndarray, cfg: IdentifyConfig, step: float = 0.01) -> tuple[float, float]:
    """Return the operating range of Eq. 39 whose end centres the data support.

    The range of ``q``, with each end moved inwards in steps of ``step`` times the range
    until the end centre of the equidistant basis (Eq. 38-39 with ``cfg.M``,
    ``cfg.sigma_n``) has at least ``cfg.min_support`` samples within one width: the few
    samples of an overshoot peak then lie beyond the range, where the curves are held at
    their edge values (``outside = "clip"``) or the RBF part vanishes (``"zero"``), instead
    of failing the fit. A range the data support as it is comes back unchanged.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Positions of the estimation data [unit of q].
    cfg : IdentifyConfig
        ``M``, ``sigma_n``, ``outside`` and ``min_support``.
    step : float
        Fraction of the data range an end moves per iteration.

    Returns
    -------
    tuple of float
        ``(q_min, q_max)`` [unit of q].

    References
    ----------
    Masoud & Maas 2025, Eq. 38-39 and Sec. 5.2 (excite every centre's part of the range).
    """
    lo, hi = float(q.min()), float(q.max())
    span = hi - lo
    if span <= 0 or cfg.min_support == 0:
        return lo, hi
    for _ in range(int(0.5 / step)):  # at most half the range from each end
        support = RBFBasis.equidistant(lo, hi, cfg.M, cfg.sigma_n, cfg.outside).support(q)
        if support[0] >= cfg.min_support and support[-1] >= cfg.min_support:
            break
        lo += step * span if support[0] < cfg.min_support else 0.0
        hi -= step * span if support[-1] < cfg.min_support else 0.0
    return lo, hi


def supported_size(q: np.ndarray, cfg: IdentifyConfig) -> int:
    """Return the most centres, at most ``cfg.M``, whose every centre the data support.

    For ``M = cfg.M, cfg.M - 1, .., 2`` the equidistant basis over the supported range
    (:func:`supported_range`, or ``cfg.q_range``) is built; the first whose every centre has
    at least ``cfg.min_support`` samples within one width is taken. Fewer centres are wider
    (``sigma = sigma_n`` times the spacing), so thin data (one tone inside a well, a short
    record) get a coarser curve instead of a failed fit. Where not even two centres are
    supported, ``cfg.M`` comes back and the fit names the thin centre.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Positions of the estimation data [unit of q].
    cfg : IdentifyConfig
        ``M``, ``sigma_n``, ``outside``, ``q_range``, ``min_support`` and ``rbf``.

    Returns
    -------
    int
        The number of centres, ``2 <= M <= cfg.M`` (``cfg.M`` without RBF curves or with
        ``min_support = 0``).

    References
    ----------
    Masoud & Maas 2025, Eq. 38-39 and Sec. 5.2 (excite every centre's part of the range).
    """
    if cfg.min_support == 0 or not set(cfg.rbf) & {"c", "d", "g"}:
        return cfg.M
    for m in range(cfg.M, 1, -1):
        trial = replace(cfg, M=m)
        lo, hi = cfg.q_range or supported_range(q, trial)
        support = RBFBasis.equidistant(lo, hi, m, cfg.sigma_n, cfg.outside).support(q)
        if support.min() >= cfg.min_support:
            return m
    return cfg.M


def _check_support(records: Sequence[Record], basis: RBFBasis, cfg: IdentifyConfig) -> np.ndarray:
    support = basis.support(np.concatenate([r.q for r in records]))
    thin = np.flatnonzero(support < cfg.min_support)
    if thin.size and ("c" in cfg.rbf or "d" in cfg.rbf or "g" in cfg.rbf):
        i = int(thin[0])
        raise IdentificationError(
            f"centre xi_{i + 1} = {basis.xi[i]:.6g} has only {int(support[i])} samples within "
            f"sigma = {basis.sigma:.3g} (min_support = {cfg.min_support}): the experiment does not "
            "excite that part of the range; reduce M, set q_range, or excite it",
            reason="support",
        )
    return support


def _check_inputs(records: Sequence[Record], cfg: IdentifyConfig) -> None:
    v = np.vstack([r.v for r in records])
    for j in range(v.shape[1]):
        if np.ptp(v[:, j]) == 0:
            raise IdentificationError(
                f"input v{j + 1} is constant ({v[0, j]:.6g} V) over all estimation data: "
                "the experiment is under-excited and g(q) of that input cannot be identified",
                reason="excitation",
            )


def fit_rbf_model(
    records: Sequence[Record], cfg: IdentifyConfig
) -> tuple[RBFModel, FitDiagnostics]:
    """Identify the RBF model of Eq. 37 by least squares, T_z by a bounded outer search.

    The weights solve the linear regression of Eq. 40 (with the backbone terms) on the
    column-scaled regressor by SVD, for the friction state z of each T_z tried by a bounded
    Brent search over log T_z (and T_z = 0). ``lowpass``, ``weights_window`` and ``creep``
    extend it: docs/explanation/implementation.md.

    Parameters
    ----------
    records : sequence of Record
        Estimation data (one or several experiments; rows are stacked).
    cfg : IdentifyConfig
        Hyper-parameters.

    Returns
    -------
    model : RBFModel
        The identified model.
    diagnostics : FitDiagnostics
        Rank, condition number, residuals and the T_z search trace.

    Raises
    ------
    IdentificationError
        If a centre has no data near it, an input is never excited, the regressor is rank
        deficient or worse conditioned than ``max_condition``, or ``lowpass`` is not below a
        record's Nyquist frequency.
    ResourceError
        If the least squares would need more memory than the budget
        (:func:`debist.core.preflight.check_identify`), before anything is allocated.

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (creep), 37-40 and Sec. 4.2 (LS with T_z outer loop); Ljung 1999,
    System Identification, 2nd ed., Sec. 7.3 and 14.4 (filtered equation error).
    """
    records = _trimmed(records, cfg.trim)
    cfg = replace(cfg, trim=0)
    if cfg.weights_window is not None:
        first = replace(cfg, weights_window=None, bootstrap=0)
        records = variance_weights(records, _fit(records, first)[2], cfg.weights_window)
    model, diag, _ = _fit(records, cfg)
    return model, diag


def _fit(records: Sequence[Record], cfg: IdentifyConfig):
    """:func:`fit_rbf_model` on trimmed records with their weights; also the residual."""
    n_in = records[0].v.shape[1]
    sizes = [r.q.size for r in records]
    preflight.check_identify(cfg, n_in, sum(sizes), max(sizes))
    q_all = np.concatenate([r.q for r in records])
    q_range = cfg.q_range or supported_range(q_all, cfg)
    basis = RBFBasis.equidistant(q_range[0], q_range[1], cfg.M, cfg.sigma_n, cfg.outside)
    if cfg.slip is not False:
        cfg = replace(cfg, slip=slip_widths(cfg.slip, q_range))
    support = _check_support(records, basis, cfg)
    undriven, undriven_text = undriven_weights(records, basis, cfg)
    if cfg.m_q != "identify":
        _check_inputs(records, cfg)

    uses_z = "d" in cfg.rbf or bool(set(_Z_TERMS) & set(cfg.backbone))
    dt = min(r.dt for r in records)
    T_z_bounds = cfg.T_z_bounds or (dt, 100.0 * dt)
    if cfg.T_z != "search" or not uses_z:
        T_z = float(cfg.T_z) if cfg.T_z != "search" else 0.0
        trace = np.empty((0, 2))
    else:
        T_z, trace = _search_T_z(records, basis, cfg, T_z_bounds)
    rate, creep_trace = 0.0, np.empty((0, 2))
    if cfg.creep == "search":
        duration = max((r.q.size - 1) * r.dt for r in records)
        bounds = cfg.creep_bounds or (1.0 / duration, 0.1 / dt)
        rate, creep_trace = _search_creep(records, basis, cfg, bounds, T_z)
        if cfg.T_z == "search" and uses_z:  # once more, each with the other's estimate
            w_all = _creep_columns(records, basis, rate)
            T_z, trace_2 = _search_T_z(records, basis, cfg, T_z_bounds, w_all)
            rate, creep_2 = _search_creep(records, basis, cfg, bounds, T_z)
            trace, creep_trace = np.vstack([trace, trace_2]), np.vstack([creep_trace, creep_2])
    elif cfg.creep:
        rate = float(cfg.creep)

    z_all = [friction_state(r.q_dot, r.dt, T_z) for r in records]
    w_all = _creep_columns(records, basis, rate) if rate > 0 else None
    psi, y, names = _system(records, z_all, basis, cfg, w_all)
    theta, resid, rank, cond, S, compressed = _solve(psi, y, names, cfg, check=True)
    estimator, gcv_trace = _estimator(psi, y, names, cfg, undriven)
    if not estimator.plain:
        scale = np.linalg.norm(psi, axis=0)
        Q, R = np.linalg.qr(psi / scale)
        theta = estimator.solve(R, Q.T @ y) / scale
        resid = y - psi @ theta
    model = assemble_model(theta, names, basis, cfg, n_in, T_z, q_range, rate)
    h_all = np.vstack([input_map(r.v, cfg.input_map) for r in records])
    # A refit under some signs can break another (a gain held to its sign moves d below zero):
    # check again until the fit keeps every sign; each round adds a curve, so it ends.
    signed, reasons = cfg, []
    signs, reason = physical_signs(model, q_all, h_all, signed)
    scale = np.linalg.norm(psi, axis=0)
    while signs:
        reasons.append(reason)
        signed = replace(signed, constraints=(*signed.constraints, *signs))
        estimator, gcv_trace = _estimator(psi, y, names, signed, undriven)
        theta = estimator.solve(*compressed) / np.where(scale == 0, 1.0, scale)
        resid = y - psi @ theta
        model = assemble_model(theta, names, basis, cfg, n_in, T_z, q_range, rate)
        imposed = signed.constraints[len(cfg.constraints) :]
        signs, reason = physical_signs(model, q_all, h_all, signed, after=imposed)
    dissipation = "; then ".join(reasons)
    theta_boot, block = None, 0
    if cfg.bootstrap > 0:
        theta_boot, block = block_bootstrap(
            psi, y, [r.q.size for r in records], cfg.bootstrap, cfg.bootstrap_seed,
            estimator=estimator,
        )  # fmt: skip
    diag = FitDiagnostics(
        n_samples=int(y.size),
        columns=names,
        rank=rank,
        condition=cond,
        singular_values=S,
        residual_rms=rms(resid),
        fit_r2=float(1.0 - np.sum(resid**2) / np.sum((y - y.mean()) ** 2)),
        support=support,
        T_z_trace=trace,
        theta=theta,
        column_norms=np.linalg.norm(psi, axis=0),
        y_norm=float(np.linalg.norm(y)),
        theta_boot=theta_boot,
        block=block,
        smoothing=estimator.lam,
        gcv_trace=gcv_trace,
        creep_trace=creep_trace,
        dissipation=dissipation,
        undriven=undriven_text,
    )
    return model, diag, resid


def slip_widths(slip: int | Sequence[float], q_range: Sequence[float]) -> tuple[float, ...]:
    """Resolve ``[identify] slip`` to the break-away deflections of the Maxwell-slip elements.

    Parameters
    ----------
    slip : int or sequence of float
        A number N of elements, or their deflections [unit of q] (returned as they are).
    q_range : sequence of float
        ``(q_min, q_max)`` of the estimation range [unit of q].

    Returns
    -------
    tuple of float, length N
        N deflections spaced geometrically over :data:`~debist.identify.config.SLIP_GRID`
        times ``q_max - q_min`` [unit of q].

    Raises
    ------
    IdentificationError
        If the range is empty.

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005 (elements of distributed break-away deflections).

    Examples
    --------
    >>> [round(w * 1e6, 2) for w in slip_widths(4, (-16e-3, 16e-3))]
    [4.8, 19.46, 78.92, 320.0]
    """
    if not isinstance(slip, int):
        return tuple(float(w) for w in slip)
    span = float(q_range[1]) - float(q_range[0])
    if not span > 0:
        raise IdentificationError(f"slip elements need a q range, got {tuple(q_range)}")
    lo, hi = SLIP_GRID
    return tuple((span * np.geomspace(lo, hi, slip) if slip > 1 else [span * lo]).tolist())


def _creep_columns(records: Sequence[Record], basis: RBFBasis, rate: float) -> list[np.ndarray]:
    """Return the creep states w_j (n, M) of every record at the relaxation rate [1/s]."""
    return [creep_states(basis(r.q), r.q_dot, r.dt, rate) for r in records]


def _projected_search(a_fixed, y, columns, bounds, xatol):
    """Minimise the equation error over one time constant by variable projection.

    Only the columns ``columns(p)`` depend on the scalar ``p``; the fixed columns
    ``a_fixed`` are factorised once (QR) and projected out, so each evaluation solves the
    small least squares of the projected varying columns for the relative residual
    ``|y_perp - B_perp c| / |y|``, minimised over ``log p`` in ``bounds`` (Golub & Pereyra
    1973, separable least squares; Masoud & Maas 2025, Sec. 4.2 for T_z).

    Returns
    -------
    p : float
        The minimiser.
    value : float
        The relative residual there.
    cost : callable
        The relative residual of any ``p`` (appends to the trace).
    trace : list of (float, float)
        Every evaluation ``(p, relative residual)``.
    """
    from scipy.optimize import minimize_scalar

    Q, _ = np.linalg.qr(a_fixed)
    y_perp = y - Q @ (Q.T @ y)
    trace: list[tuple[float, float]] = []

    def cost(p: float) -> float:
        B = columns(p)
        B_perp = B - Q @ (Q.T @ B)
        coef, *_ = np.linalg.lstsq(B_perp, y_perp, rcond=None)
        value = float(np.linalg.norm(y_perp - B_perp @ coef) / np.linalg.norm(y))
        trace.append((p, value))
        return value

    lo, hi = bounds
    res = minimize_scalar(
        lambda s: cost(float(np.exp(s))),
        bounds=(np.log(lo), np.log(hi)),
        method="bounded",
        options={"xatol": xatol},
    )
    return float(np.exp(res.x)), float(res.fun), cost, trace


def _search_creep(records, basis, cfg, bounds, T_z):
    """Bounded search of the creep rate lambda by variable projection (as :func:`_search_T_z`).

    Only the creep columns depend on lambda: every other column (with z at ``T_z``) is
    projected out (:func:`_projected_search`).

    Returns lambda [1/s] and the trace (lambda, relative residual), shape (k, 2).
    """
    z_all = [friction_state(r.q_dot, r.dt, T_z) for r in records]
    a_fixed, y, _ = _system(records, z_all, basis, cfg)

    def columns(rate: float) -> np.ndarray:
        w_all = _creep_columns(records, basis, rate)
        return np.vstack([_rows(w, r, cfg) for r, w in zip(records, w_all, strict=True)])

    rate, _, _, trace = _projected_search(a_fixed, y, columns, bounds, 1e-3)
    return rate, np.array(trace, dtype=float)


def _estimator(psi, y, names, cfg: IdentifyConfig, undriven: Sequence[str] = ()):
    """Build the fit's estimator: plain, smoothed (fixed or GCV lambda), constrained, tied."""
    lower, upper = constraint_bounds(names, cfg.constraints)
    # an element stiffness is a spring's (Al-Bender, Lampaert & Swevers 2005): k_e >= 0
    lower[[j for j, n in enumerate(names) if n.startswith("slip[")]] = 0.0
    scale = np.linalg.norm(psi, axis=0)
    penalty = weight_penalty(
        smoothness_operator(names, cfg.M), np.where(scale == 0, 1.0, scale), names
    )
    trace = np.empty((0, 3))
    if cfg.smoothing == "gcv" and penalty.shape[0]:
        Q, R = np.linalg.qr(psi / scale)
        qty = Q.T @ y
        lam, trace = gcv_lambda(R, qty, float(y @ y - qty @ qty), y.size, penalty)
    else:
        lam = 0.0 if cfg.smoothing == "gcv" else float(cfg.smoothing)
    tie = tie_rows(names, cfg.M, np.where(scale == 0, 1.0, scale), undriven)
    return Estimator(penalty, lam, lower, upper, tie), trace


def _search_T_z(records, basis, cfg, bounds, w_all=None):
    """Bounded search of T_z by variable projection (Masoud & Maas 2025, Sec. 4.2).

    Only the friction columns (those multiplied by z) depend on T_z: the other
    columns (with the creep columns ``w_all`` when given) are factorised once (QR) and
    projected out, so each evaluation of the relative equation error solves a small
    least-squares problem.
    """
    zero = [np.zeros_like(r.q) for r in records]
    fixed_cfg = replace(cfg, rbf=tuple(t for t in cfg.rbf if t != "d"))
    fixed_cfg = replace(fixed_cfg, backbone=tuple(b for b in cfg.backbone if b not in _Z_TERMS))
    a_fixed, y, _ = _system(records, zero, basis, fixed_cfg, w_all)
    z_rbf = ("d",) if "d" in cfg.rbf else ()
    z_backbone = tuple(b for b in cfg.backbone if b in _Z_TERMS)
    # force_columns of the z terms, their factors of q computed once: only z moves with T_z
    table, _ = force_table(basis, z_rbf, z_backbone, cfg.coulomb_velocity, cfg.prior)
    fixed = [(table.position_part(r.q), np.zeros((r.q.size, 1))) for r in records]

    def columns(T_z: float) -> np.ndarray:
        cols = []
        for r, (position, idle) in zip(records, fixed, strict=True):
            z = friction_state(r.q_dot, r.dt, T_z)
            cols.append(_rows(table.columns(r.q, z, idle, position=position), r, cfg))
        return np.vstack(cols)

    T_z, value, cost, trace = _projected_search(a_fixed, y, columns, bounds, 1e-2)
    if cost(0.0) <= value:
        T_z = 0.0
    return T_z, np.array(trace, dtype=float)


_Z_TERMS = ("viscous", "coulomb", "physics_damping")


def assemble_model(theta, names, basis, cfg, n_in, T_z, q_range, creep_rate=0.0) -> RBFModel:
    """Map the parameter vector back onto the model's curves, backbone and creep weights."""
    value = dict(zip(names, theta, strict=True))
    M = basis.M
    vec = lambda prefix: np.array([value.get(f"{prefix}[{i}]", 0.0) for i in range(M)])  # noqa: E731
    backbone_map = {
        "linear_spring": "k_1",
        "cubic_spring": "k_3",
        "viscous": "d_v",
        "coulomb": "F_c",
        "offset": "F_0",
        "physics_spring": "s_c",
        "physics_damping": "s_d",
    }
    backbone = {sym: float(value[name]) for name, sym in backbone_map.items() if name in value}
    if cfg.m_q == "identify":
        m_q = float(value["m_q"])
        if not m_q > 0:
            raise IdentificationError(
                f"identified mass m_q = {m_q:.6g} is not positive: the acceleration is not "
                "excited or the input gain is wrong",
                reason="mass",
            )
        g_0 = np.asarray(cfg.input_gain, dtype=float)
    else:
        m_q = float(cfg.m_q)
        g_0 = np.array([value.get(f"input_gain{j + 1}", 0.0) for j in range(n_in)])
    backbone["g_0"] = g_0
    if "input_quadratic" in cfg.backbone:
        backbone["g_h"] = np.array([value[f"input_quadratic{j + 1}"] for j in range(n_in)])
    uses_prior = bool(set(PHYSICS_TERMS) & set(cfg.backbone))
    if uses_prior:
        backbone["s_g"] = np.array([value.get(f"physics_gain{j + 1}", 0.0) for j in range(n_in)])
    if "physics_quadratic" in cfg.backbone:
        backbone["s_gh"] = np.array([value[f"physics_quadratic{j + 1}"] for j in range(n_in)])
    if "physics_creep" in cfg.backbone:  # one rate per model: the prior's (config refuses both)
        backbone["s_k"] = np.array([value[f"physics_creep{j + 1}"] for j in range(n_in)])
        creep_rate = cfg.prior.creep()[1]
    return RBFModel(
        basis=basis,
        input_map=cfg.input_map,
        n_inputs=n_in,
        m_q=m_q,
        T_z=T_z,
        coulomb_velocity=cfg.coulomb_velocity,
        theta_c=vec("c"),
        theta_d=vec("d"),
        theta_g=np.stack([vec(f"g{j + 1}") for j in range(n_in)]),
        theta_gh=(np.stack([vec(f"gh{j + 1}") for j in range(n_in)]) if "gh" in cfg.rbf else None),
        backbone=backbone,
        q_range=(float(q_range[0]), float(q_range[1])),
        prior=_model_prior(cfg) if uses_prior else None,
        creep_rate=float(creep_rate),
        theta_creep=vec("creep") if any(n.startswith("creep[") for n in names) else None,
        slip_width=tuple(cfg.slip) if cfg.slip else (),
        theta_slip=(
            np.array([value[f"slip[{e}]"] for e in range(len(cfg.slip))]) if cfg.slip else None
        ),
        theta_inertia=(
            np.array(
                [value.get(f"inertia[{a}]", 0.0) for a in range(1, max(cfg.inertia_powers) + 1)]
            )
            if cfg.inertia_powers
            else None
        ),
    )
