"""k-step-ahead prediction and residual analysis: the checks of MATLAB's ``predict`` and ``resid``.

A free run (Eq. 41's simulation) shows what a model does on its own; a control engineer also
asks how well it predicts a short horizon from a known state, and whether what it leaves
unexplained is noise. Both are computed here for any model the free-run simulator takes:

- :func:`k_step_prediction` restarts the model from the measured state (q and the
  differentiate stage's q_dot) at every sample and integrates ``k`` samples ahead with the
  same RK4 scheme and input interpolation as the free run (:func:`debist.simulate.freerun.simulate`,
  the windows batched); ``k = 1`` gives the one-step prediction errors.
- :func:`residual_analysis` tests those errors: their autocorrelation (whiteness, with the
  Ljung-Box portmanteau statistic) and their cross-correlation with each input, each with
  99 % confidence limits.

The identified models have no noise model, so the predictor's state is the measured one: the
one-step errors hold the sensor noise and the derivative estimate's error as well as the
model's. The cross-correlation with the inputs is then the test of the dynamics (a model
that misses an input's effect leaves errors correlated with that input); the autocorrelation
says whether the errors are noise or structure (Ljung 1999, Sec. 16.6).

References
----------
Ljung, L., System Identification: Theory for the User, 2nd ed., Prentice Hall 1999,
Sec. 16.6 (residual analysis) and Sec. 7.3 (k-step-ahead predictors).
Ljung, G. M. & Box, G. E. P., On a measure of lack of fit in time series models,
Biometrika 65(2), 1978, 297-303.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import lazy_loader as lazy
import numpy as np

from debist.core.errors import WorkflowError
from debist.core.metrics import nrmse
from debist.simulate.freerun import (
    FineInputs,
    FreeRunModel,
    prepare_inputs,
    simulate_batch,
    substeps_needed,
)
from debist.validate.freerun import DataSet

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")
stats = lazy.load("scipy.stats", suppress_warning=True)

__all__ = [
    "RESIDUAL_CONFIDENCE",
    "ResidualAnalysis",
    "k_step_prediction",
    "prediction_table",
    "residual_analysis",
    "restarted_runs",
]

#: Confidence level of the residual tests' limits and of the Ljung-Box test (as ``resid``).
RESIDUAL_CONFIDENCE = 0.99
#: At most this many restarted windows per record; longer records are sampled evenly.
MAX_WINDOWS = 20000


def k_step_prediction(
    model: FreeRunModel,
    q: np.ndarray,
    q_dot: np.ndarray,
    v: np.ndarray,
    dt: float,
    k: int,
    *,
    substeps: int = 2,
    interpolation: str = "bandlimited",
    q_limit: float = np.inf,
    engine: str = "compiled",
    max_windows: int = MAX_WINDOWS,
) -> np.ndarray:
    """Predict q ``k`` samples ahead from the measured state at every sample.

    Parameters
    ----------
    model : FreeRunModel
        The model; each window starts from its ``measured_states`` (or ``initial_state``).
    q, q_dot, v : ndarray, shapes (n,), (n,), (n, n_inputs)
        Measured position [unit of q], velocity [unit of q / s] and inputs [V].
    dt, k : float, int
        Sample time [s]; prediction horizon [samples], ``>= 1``.
    substeps, interpolation, q_limit, engine
        As :func:`debist.simulate.freerun.simulate`.
    max_windows : int, optional
        Most restarts per record, evenly spaced (``k >= 2``; ``k = 1`` keeps every sample).

    Returns
    -------
    ndarray, shape (n,)
        ``q_hat(j | j - k)`` [unit of q]; NaN for ``j < k``, unstarted or diverged windows.

    Raises
    ------
    WorkflowError
        If ``k < 1``, the record is not longer than ``k`` samples or the shapes differ.

    References
    ----------
    Ljung 1999, Sec. 7.3 (k-step-ahead prediction).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> ramp = SimpleNamespace(n_states=2, max_step=lambda: np.inf,  # holds its velocity
    ...     initial_state=lambda q0, q_dot0: np.stack([q0, q_dot0], axis=-1),
    ...     rhs=lambda x, v: (np.stack([x[:, 1], 0 * x[:, 1]], axis=1), 0 * x[:, 1]))
    >>> q_hat = k_step_prediction(
    ...     ramp, 0.2 * np.arange(6), np.full(6, 2.0), np.zeros((6, 1)), 0.1, 2)
    >>> np.round(q_hat, 12).tolist()[2:]
    [0.4, 0.6, 0.8, 1.0]
    """
    q = np.asarray(q, dtype=float)
    q_dot = np.asarray(q_dot, dtype=float)
    v = np.asarray(v, dtype=float)
    k = int(k)
    n = q.size
    if k < 1:
        raise WorkflowError(f"the prediction horizon k must be >= 1 sample, got {k}")
    if q_dot.shape != q.shape or v.shape[0] != n:
        raise WorkflowError(f"shapes differ: q {q.shape}, q_dot {q_dot.shape}, v {v.shape}")
    if n <= k:
        raise WorkflowError(f"a record of {n} samples is too short for {k}-step prediction")
    starts = np.arange(n - k)
    if k > 1 and starts.size > max_windows:
        starts = np.unique(np.linspace(0, n - k - 1, max_windows).astype(np.int64))
    windows = np.column_stack([np.zeros_like(starts), starts, starts + k + 1])
    run = _restarted_batch(
        model, [_Record(q, q_dot, v)], windows, dt, substeps, interpolation, q_limit, engine
    )  # fmt: skip
    out = np.full(n, np.nan)
    out[starts + k] = run.last_q()
    return out


@dataclass(frozen=True)
class _Record:
    """A measured record as :func:`restarted_runs` reads it."""

    q: np.ndarray
    q_dot: np.ndarray
    v: np.ndarray


def restarted_runs(
    model: FreeRunModel,
    records: Sequence,
    windows: Sequence[tuple[int, int, int]],
    dt: float,
    *,
    substeps: int = 2,
    interpolation: str = "bandlimited",
    q_limit: float = np.inf,
    engine: str = "compiled",
) -> list[np.ndarray]:
    """Free runs over windows of measured records, each restarted from the measured state.

    Multiple shooting, in one batch: each window starts from the model's ``measured_states``
    (else ``initial_state``); a lost switch costs one window, not the rest of the record.

    Parameters
    ----------
    model : FreeRunModel
        The model (identified, SINDy, analytical).
    records : sequence
        Records with ``q`` (n,) [unit of q], ``q_dot`` (n,) [unit/s], ``v`` (n, n_inputs) [V].
    windows, dt : sequence of (int, int, int), float
        ``(record, first sample, sample after the last)``, >= 2 samples each; sample time [s].
    substeps, interpolation, q_limit, engine
        As :func:`debist.simulate.freerun.simulate`.

    Returns
    -------
    list of ndarray, shape (stop - start,)
        Simulated q of each window [unit of q], NaN after a divergence.

    Raises
    ------
    WorkflowError
        If there is no window, or one is shorter than 2 samples or outside its record.

    References
    ----------
    Bock & Plitt 1984, IFAC 9th World Congress; Ribeiro et al. 2020, Automatica 121.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> ramp = SimpleNamespace(n_states=2, max_step=lambda: np.inf,  # holds its velocity
    ...     initial_state=lambda q0, q_dot0: np.stack([q0, q_dot0], axis=-1),
    ...     rhs=lambda x, v: (np.stack([x[:, 1], 0 * x[:, 1]], axis=1), 0 * x[:, 1]))
    >>> rec = _Record(np.arange(8.0), np.ones(8), np.zeros((8, 1)))
    >>> [r.tolist() for r in restarted_runs(ramp, [rec], [(0, 1, 4), (0, 5, 8)], 1.0)]
    [[1.0, 2.0, 3.0], [5.0, 6.0, 7.0]]
    """
    run = _restarted_batch(
        model, records, windows, dt, substeps, interpolation, q_limit, engine
    )  # fmt: skip
    return [run.q[b, :length] for b, length in enumerate(run.lengths.tolist())]


def _restarted_batch(model, records, windows, dt, substeps, interpolation, q_limit, engine):
    """Run :func:`restarted_runs`; return the batch as arrays (a ``BatchRun``)."""
    idx = np.asarray(windows, dtype=np.int64).reshape(-1, 3)
    if not idx.size:
        raise WorkflowError("no window to simulate")
    sizes = np.array([np.size(r.q) for r in records], dtype=np.int64)[idx[:, 0]]
    bad = ~((idx[:, 1] >= 0) & (idx[:, 1] < idx[:, 2] - 1) & (idx[:, 2] <= sizes))
    if bad.any():
        i, a, b = idx[np.argmax(bad)].tolist()
        raise WorkflowError(f"window {(i, a, b)} is not inside record {i} with 2+ samples")
    ns = substeps_needed(model, dt, substeps)
    step = 2 * ns  # fine-grid points per sample interval
    span = (int((idx[:, 2] - idx[:, 1]).max()) - 1) * step + 1
    values = np.empty((len(idx), span, np.shape(records[idx[0, 0]].v)[1]))
    x0 = np.empty((len(idx), model.n_states))
    for i in np.unique(idx[:, 0]):
        r, rows = records[i], np.flatnonzero(idx[:, 0] == i)
        fine = prepare_inputs([np.asarray(r.v, dtype=float)], ns, interpolation).values[0]
        # each window's stretch of the fine grid, padded with its last value
        at = np.minimum(
            idx[rows, 1, None] * step + np.arange(span)[None, :], (idx[rows, 2, None] - 1) * step
        )
        values[rows] = fine[at]
        if hasattr(model, "measured_states"):  # e.g. z filtered from q_dot
            x0[rows] = model.measured_states(r.q, r.q_dot, dt)[idx[rows, 1]]
        else:
            x0[rows] = model.initial_state(np.asarray(r.q), np.asarray(r.q_dot))[idx[rows, 1]]
    batch = FineInputs(values, (idx[:, 2] - idx[:, 1]).tolist(), ns)
    return simulate_batch(
        model,
        batch,
        dt,
        x0[:, 0],
        x0[:, 1],
        substeps=ns,
        q_limit=q_limit,
        engine=engine,
        progress=lambda done, total: None,
        x0=x0,
    )


@dataclass(frozen=True)
class ResidualAnalysis:
    """Autocorrelation and input cross-correlation of prediction errors, with their limits.

    Attributes
    ----------
    n : int
        Residual samples used (finite ones).
    lags : ndarray, shape (L + 1,)
        Lags 0..L of the autocorrelation [samples].
    autocorr : ndarray, shape (L + 1,)
        Normalised autocorrelation ``r_ee(tau) / r_ee(0)``; 1 at lag 0.
    auto_limit : float
        Its 99 % limit ``z / sqrt(n)`` for white errors (``z = 2.58``).
    ljung_box_p : float
        p-value of the Ljung-Box statistic over lags 1..L (white errors: large; below
        0.01 the errors are not white at the 99 % level).
    cross_lags : ndarray, shape (2 L + 1,)
        Lags -L..L of the cross-correlation [samples]; positive: the input leads.
    crosscorr : ndarray, shape (n_inputs, 2 L + 1)
        Normalised cross-correlation of the errors with each input (its mean removed).
    cross_limit : ndarray, shape (n_inputs,)
        Each input's 99 % limit under independence, ``z sqrt(sum_k rho_e(k) rho_u(k) / n)``
        (Bartlett's variance; ``z / sqrt(n)`` for white errors or a white input); NaN for
        a constant input.
    """

    n: int
    lags: np.ndarray
    autocorr: np.ndarray
    auto_limit: float
    ljung_box_p: float
    cross_lags: np.ndarray
    crosscorr: np.ndarray
    cross_limit: np.ndarray

    @property
    def white(self) -> bool:
        """Whether the errors pass the Ljung-Box test at the 99 % level."""
        return bool(self.ljung_box_p >= 1.0 - RESIDUAL_CONFIDENCE)

    @property
    def cross_outside(self) -> np.ndarray:
        """Share of lags, per input, whose cross-correlation lies outside its limit.

        Returns
        -------
        ndarray, shape (n_inputs,)
            Between 0 and 1; NaN for a constant input.
        """
        with np.errstate(invalid="ignore"):
            out = np.mean(np.abs(self.crosscorr) > self.cross_limit[:, None], axis=1)
        return np.where(np.isfinite(self.cross_limit), out, np.nan)


def _correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased normalised cross-correlation ``r_ab(tau)``, tau = -max_lag..max_lag.

    ``r_ab(tau) = sum_t a(t) b(t - tau) / (n s_a s_b)`` (Ljung 1999, Eq. 16.61), both
    means removed; ``a(t)`` against ``b`` ``tau`` samples earlier.
    """
    n = a.size
    a = a - a.mean()
    b = b - b.mean()
    scale = n * np.sqrt(np.mean(a * a) * np.mean(b * b))
    # only the 2 max_lag + 1 lags asked for, O(n max_lag) (the full correlation is O(n^2)):
    # padded[k : k + n] is b shifted by tau = max_lag - k, zeros beyond its ends
    padded = np.concatenate([np.zeros(max_lag), b, np.zeros(max_lag)])
    shifted = np.lib.stride_tricks.sliding_window_view(padded, n)
    return (shifted @ a)[::-1] / scale


def residual_analysis(errors: np.ndarray, v: np.ndarray, max_lag: int = 25) -> ResidualAnalysis:
    """Test prediction errors for whiteness and for correlation with the inputs.

    Parameters
    ----------
    errors : ndarray, shape (n,)
        One-step prediction errors ``q - q_hat(. | . - 1)`` [unit of q]; NaN samples (no
        prediction) are dropped with the inputs at the same samples.
    v : ndarray, shape (n, n_inputs)
        Inputs at the same samples.
    max_lag : int, optional
        Largest lag L [samples] (MATLAB's ``resid`` uses 25).

    Returns
    -------
    ResidualAnalysis

    Raises
    ------
    WorkflowError
        If fewer than ``4 max_lag`` finite errors remain, or the errors are constant.

    References
    ----------
    Ljung 1999, Sec. 16.6, Eq. 16.61-16.63 (correlations and their limits); Ljung & Box 1978
    (portmanteau statistic); Box, Jenkins & Reinsel 2008, Sec. 11.1.3 (Bartlett's formula).

    Examples
    --------
    White noise passes; its own input is far outside the limits:

    >>> rng = np.random.default_rng(0)
    >>> e = rng.standard_normal(2000)
    >>> res = residual_analysis(e, rng.standard_normal((2000, 1)))
    >>> res.white, bool(res.cross_outside[0] < 0.05)
    (True, True)
    >>> bool(residual_analysis(e[1:], e[:-1, None]).cross_outside[0] > 0)
    True
    """
    errors = np.asarray(errors, dtype=float)
    v = np.asarray(v, dtype=float).reshape(errors.size, -1)
    keep = np.isfinite(errors) & np.all(np.isfinite(v), axis=1)
    e, u = errors[keep], v[keep]
    n = e.size
    max_lag = int(max_lag)
    if n < 4 * max_lag:
        raise WorkflowError(
            f"residual analysis needs at least {4 * max_lag} finite prediction errors "
            f"for {max_lag} lags, got {n}"
        )
    if np.ptp(e) == 0:
        raise WorkflowError("the prediction errors are constant: no residual analysis")
    z = float(stats.norm.ppf(0.5 + RESIDUAL_CONFIDENCE / 2))
    r_ee = _correlation(e, e, max_lag)[max_lag:]
    tau = np.arange(1, max_lag + 1)
    q_stat = n * (n + 2) * np.sum(r_ee[1:] ** 2 / (n - tau))
    p = float(stats.chi2.sf(q_stat, df=max_lag))
    cross = np.full((u.shape[1], 2 * max_lag + 1), np.nan)
    limit = np.full(u.shape[1], np.nan)
    rho_e = _correlation(e, e, max_lag)
    for i in range(u.shape[1]):
        if np.ptp(u[:, i]) == 0:
            continue
        cross[i] = _correlation(e, u[:, i], max_lag)
        rho_u = _correlation(u[:, i], u[:, i], max_lag)
        limit[i] = z * np.sqrt(max(float(np.sum(rho_e * rho_u)), 1.0) / n)
    return ResidualAnalysis(
        n=n,
        lags=np.arange(max_lag + 1),
        autocorr=r_ee,
        auto_limit=z / np.sqrt(n),
        ljung_box_p=p,
        cross_lags=np.arange(-max_lag, max_lag + 1),
        crosscorr=cross,
        cross_limit=limit,
    )


def prediction_table(
    model: FreeRunModel,
    model_name: str,
    datasets: Sequence[DataSet],
    *,
    k: int,
    max_lag: int,
    substeps: int,
    interpolation: str,
    q_limit: float,
    engine: str,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Score a model's k-step predictions and test its one-step errors on every data set.

    Parameters
    ----------
    model : FreeRunModel
        The model.
    model_name : str
        Its row label ("rbf", "sindy", ...).
    datasets : sequence of debist.validate.freerun.DataSet
        Measured data with the differentiate stage's ``q_dot``.
    k : int
        Horizon of the k-step NRMSE [samples], ``>= 1``.
    max_lag : int
        Largest lag of the residual correlations [samples].
    substeps, interpolation, q_limit, engine
        The free run's settings (``[validate]``), so that prediction and free run use one
        scheme.

    Returns
    -------
    scores : pandas.DataFrame
        One row per data set: ``dataset, model, k_steps, nrmse_q_k`` (Eq. 41 over the
        predicted samples), ``resid_white`` (Ljung-Box at 99 %), ``resid_ljung_box_p``,
        ``resid_cross_outside`` (the largest share, over the inputs, of lags outside the
        99 % limits); NaN / None where a data set is too short to test.
    correlations : pandas.DataFrame
        Long table ``dataset, model, series ("autocorr" or "cross_v<i>"), lag [samples],
        r, limit`` for the figures of the residual check.

    References
    ----------
    Ljung 1999, Sec. 7.3 and 16.6; Masoud & Maas 2025, Eq. 41.
    """
    rows, curves = [], []
    for ds in datasets:
        row = {"dataset": ds.name, "model": model_name, "k_steps": int(k)}
        settings = dict(
            substeps=substeps, interpolation=interpolation, q_limit=q_limit, engine=engine
        )
        q_k = k_step_prediction(model, ds.q, ds.q_dot, ds.v, ds.dt, k, **settings)
        m = np.isfinite(q_k)
        row["nrmse_q_k"] = nrmse(ds.q[m], q_k[m]) if m.sum() > 1 and np.ptp(ds.q[m]) else np.nan
        q_1 = (
            q_k if k == 1 else k_step_prediction(model, ds.q, ds.q_dot, ds.v, ds.dt, 1, **settings)
        )
        try:
            res = residual_analysis(ds.q - q_1, ds.v, max_lag)
        except WorkflowError:  # too short or constant: no test, said by the NaN
            row.update(resid_white=None, resid_ljung_box_p=np.nan, resid_cross_outside=np.nan)
        else:
            outside = res.cross_outside
            row.update(
                resid_white=res.white,
                resid_ljung_box_p=res.ljung_box_p,
                resid_cross_outside=float(np.nanmax(outside))
                if np.isfinite(outside).any()
                else np.nan,
            )
            series = [("autocorr", res.lags, res.autocorr, res.auto_limit)]
            series += [
                (f"cross_v{i + 1}", res.cross_lags, r, lim)
                for i, (r, lim) in enumerate(zip(res.crosscorr, res.cross_limit, strict=True))
            ]
            curves += [
                pd.DataFrame(
                    {
                        "dataset": ds.name,
                        "model": model_name,
                        "series": name,
                        "lag": lags,
                        "r": r,
                        "limit": lim,
                    }
                )
                for name, lags, r, lim in series
            ]
        rows.append(row)
    columns = ["dataset", "model", "series", "lag", "r", "limit"]
    corr = pd.concat(curves, ignore_index=True) if curves else pd.DataFrame(columns=columns)
    return pd.DataFrame(rows), corr
