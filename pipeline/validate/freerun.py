"""Validation of identified models by free-run simulation (Masoud & Maas 2025, Sec. 5, Eq. 41)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import lazy_loader as lazy
import numpy as np

from debist.core import progress
from debist.core.errors import WorkflowError
from debist.core.metrics import (
    POOR_SHARE,
    TailPercentiles,
    mean_baseline_nrmse,
    nrmse,
    rms,
)
from debist.core.units import lookup_unit, pretty_unit
from debist.simulate.freerun import (
    FineInputs,
    FreeRunModel,
    SimulationResult,
    check_free_run,
    prepare_inputs,
    simulate,
    simulate_batch,
    substeps_needed,
)
from debist.validate.config import ValidateConfig

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

#: Columns of a free run (``simulated/<data set>.parquet``) holding the pointwise 2.5 and 97.5
#: percentiles of the bootstrap replicates' q (:func:`replicate_spread`): the model's own band,
#: not the free runs of other models.
REPLICATE_BAND = ("q_sim_lo", "q_sim_hi")


def initial_state(q: np.ndarray, dt: float, window: int) -> tuple[float, float]:
    """Estimate position and velocity at the first sample from the first samples only.

    A cubic is fitted by least squares to ``q[:window]``; its value and slope at
    the first instant are returned. Used where a benchmark protocol allows only
    the first samples of the output to initialise a free-run simulation.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Measured position [unit of q].
    dt : float
        Sample time [s].
    window : int
        Samples used, at least 4.

    Returns
    -------
    q0 : float
        Position [unit of q].
    q_dot0 : float
        Velocity [unit/s].

    Raises
    ------
    ValueError
        If fewer than 4 samples are available.
    """
    window = min(int(window), q.size)
    if window < 4:
        raise ValueError(f"need at least 4 samples to estimate the initial state, got {window}")
    t = np.arange(window) * dt
    coef = np.polynomial.polynomial.polyfit(t, q[:window], 3)
    return float(coef[0]), float(coef[1])


@dataclass(frozen=True)
class DataSet:
    """Measured data of one record for validation.

    Parameters
    ----------
    name : str
        Data set name.
    role : {"estimation", "validation"}
        Whether it was used for identification.
    t : ndarray, shape (n,)
        Time [s].
    q, q_dot, q_ddot : ndarray, shape (n,)
        Measured position and its derivatives (differentiation stage).
    v : ndarray, shape (n, n_inputs)
        Inputs [V].
    q_unit : str
        SI unit of q (e.g. "m", or "V" for the Silverbox circuit).
    """

    name: str
    role: str
    t: np.ndarray
    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray
    v: np.ndarray
    q_unit: str

    @property
    def dt(self) -> float:
        """Sample time [s] (median step)."""
        return float(np.median(np.diff(self.t)))


def report_factor(q_unit: str, report_unit: str | None) -> tuple[float, str]:
    """Factor converting q from its SI unit to the unit q is reported in.

    One unit per workflow for q and what is made of it (ranges, q*, RMS errors, stiffness
    per length): ``[validate] report_unit``, else mm for q in m (a DE's stroke is a few mm),
    else q's own unit.

    Parameters
    ----------
    q_unit : str
        SI unit of q.
    report_unit : str or None
        Wanted unit; None: ``"mm"`` for q in ``"m"``, else ``q_unit``.

    Returns
    -------
    factor : float
        Multiply a value in ``q_unit`` by it.
    unit : str
        The report unit, as :func:`debist.core.units.pretty_unit` writes it (``"µm"`` for
        ``"um"``), so that every table spells it alike.

    Raises
    ------
    WorkflowError
        If the report unit is unknown or of another quantity.

    Examples
    --------
    >>> report_factor("m", None), report_factor("V", None), report_factor("V", "mV")
    ((1000.0, 'mm'), (1.0, 'V'), (1000.0, 'mV'))
    """
    if report_unit is None:
        if q_unit != "m":
            return 1.0, q_unit
        report_unit = "mm"
    unit = lookup_unit(report_unit)
    if unit is None or unit.si != q_unit:
        raise WorkflowError(
            f"[validate] report_unit {report_unit!r} cannot express q in {q_unit!r}"
        )
    return 1.0 / unit.factor, pretty_unit(report_unit)


def words_factor(q_unit: str) -> tuple[float, str]:
    """Factor and unit for positions in warnings and verdicts: mm when q is in m.

    Parameters
    ----------
    q_unit : str
        SI unit of q.

    Returns
    -------
    factor, unit : float, str
        :func:`report_factor` without a report unit.

    Examples
    --------
    >>> words_factor("m")
    (1000.0, 'mm')
    >>> words_factor("V")
    (1.0, 'V')
    """
    return report_factor(q_unit, None)


def default_q_limit(q_range: tuple[float, float]) -> float:
    """Divergence bound of a free run: twice the largest ``|q|`` of the estimation range.

    A run that leaves it is reported as diverged, never scored: the model is extrapolating
    far outside anything it was fitted on.

    Parameters
    ----------
    q_range : (float, float)
        The model's estimation range [unit of q].

    Returns
    -------
    float
        ``2 max(|q_lo|, |q_hi|)`` [unit of q].

    Examples
    --------
    >>> default_q_limit((-1.5, 4.0))
    8.0
    """
    return 2.0 * max(abs(float(q_range[0])), abs(float(q_range[1])))


def mark_unstable(table: pd.DataFrame, model_name: str, reason: str) -> pd.DataFrame:
    """Replace a model's scores by the verdict "unstable" (its numbers are not results).

    Parameters
    ----------
    table : pandas.DataFrame
        NRMSE rows (:func:`validate_model`).
    model_name : str
        The model whose rows are marked.
    reason : str
        Why (:func:`debist.identify.stability.model_is_stable`).

    Returns
    -------
    pandas.DataFrame
        A copy with NaN scores, ``status = "unstable"`` and ``reason`` for that model.
    """
    out = table.copy()
    rows = out.model == model_name
    score = [c for c in out.columns if c.startswith(("nrmse_", "rms_q"))]
    score = [c for c in score if c != "nrmse_q_baseline" and out[c].dtype.kind == "f"]
    out.loc[rows, score] = np.nan
    out.loc[rows, "status"] = "unstable"
    if "reason" not in out:
        out["reason"] = ""
    out.loc[rows, "reason"] = reason
    return out


def validate_model(
    model: FreeRunModel,
    model_name: str,
    datasets: Sequence[DataSet],
    cfg: ValidateConfig,
    q_limit: float,
    phi: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[pd.DataFrame, dict[str, pd.DataFrame]]:
    """Free-run a model on every data set and score it (Eq. 41).

    Parameters
    ----------
    model : FreeRunModel
        The model to simulate.
    model_name : str
        Its row label ("rbf", "sindy", "analytical").
    datasets : sequence of DataSet
        Estimation and validation data; records with the same sample time are
        simulated as one batch.
    cfg : ValidateConfig
        Simulation and scoring options.
    q_limit : float
        Divergence bound on |q| [unit of q].
    phi : callable, optional
        The prototype's map ``phi(q)`` [rad] of ``q`` [m] (Eq. 1 through ``q_m(q)``); when
        given, ``nrmse_phi`` compares ``phi`` of the measured and the simulated ``q``.

    Returns
    -------
    table : pandas.DataFrame
        One row per data set: ``dataset, role, model, n_samples, nrmse_q,
        [nrmse_phi,] nrmse_q_dot, nrmse_q_ddot, rms_q`` (report unit), ``diverged``.
    simulated : dict of str to pandas.DataFrame
        Per data set: ``t, q, q_sim, q_dot_sim, q_ddot_sim``.

    Raises
    ------
    WorkflowError
        If the report unit does not fit q, or ``init_samples`` is 1 to 3 (the initial-
        state fit needs 4) or leaves fewer than 4 samples of a data set to score.
    ResourceError
        If a batch's free run would exceed the memory budget (naming ``[validate]
        substeps``), before it is allocated.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.2 and Eq. 41.
    """
    fit_min = 4  # samples the cubic of initial_state needs; as many must remain to score
    by_dt = by_sample_time(datasets)
    for ds in datasets:
        k = cfg.init_samples
        if 0 < k < fit_min or k > ds.q.size - fit_min:
            raise WorkflowError(
                f"[validate] init_samples = {k}: data set '{ds.name}' has {ds.q.size} samples; "
                f"the initial-state estimate needs at least {fit_min} of them and at least "
                f"{fit_min} must remain to score the free run (0 starts from the first sample)",
                key="validate.init_samples",
                value=k,
            )
    for dt, group in by_dt.items():
        check_free_run(
            model,
            [ds.v.shape[0] for ds in group],
            group[0].v.shape[1],
            dt,
            cfg.substeps,
            f"[validate] substeps = {cfg.substeps}",
        )
    results: dict[str, SimulationResult] = {}
    for dt, group in by_dt.items():
        q0, qd0 = initial_states(group, dt, cfg.init_samples)
        sims = simulate(
            model,
            [ds.v for ds in group],
            dt,
            q0,
            qd0,
            substeps=cfg.substeps,
            interpolation=cfg.input_interpolation,
            q_limit=q_limit,
            engine=cfg.engine,
            progress=progress.reporter(
                f"free run of {model_name}: {', '.join(ds.name for ds in group)}"
            ),
        )
        results.update({ds.name: sim for ds, sim in zip(group, sims, strict=True)})
    return score_free_runs(model_name, datasets, results, cfg, phi)


def by_sample_time(datasets: Sequence[DataSet]) -> dict[float, list[DataSet]]:
    """Group the data sets by sample time: each group is simulated as one batch.

    Parameters
    ----------
    datasets : sequence of DataSet
        The data sets.

    Returns
    -------
    dict of float to list of DataSet
        The sample time [s] (each record's median step rounded to 1e-12 s, the ``dt`` its
        free run takes) to its data sets, in their order.
    """
    by_dt: dict[float, list[DataSet]] = {}
    for ds in datasets:
        by_dt.setdefault(round(ds.dt, 12), []).append(ds)
    return by_dt


def initial_states(
    group: Sequence[DataSet], dt: float, init_samples: int
) -> tuple[np.ndarray, np.ndarray]:
    """Return each data set's initial q and q_dot: fitted to its first samples, or its first.

    Parameters
    ----------
    group : sequence of DataSet
        Data sets of one sample time.
    dt : float
        Their sample time [s].
    init_samples : int
        ``[validate] init_samples``: 0 starts from the first sample's ``q`` and ``q_dot``;
        more fit :func:`initial_state` to the first ``min(init_samples, 16)`` samples.

    Returns
    -------
    q0, q_dot0 : ndarray, shape (len(group),)
        Initial position [unit of q] and velocity [unit/s] of each free run.

    Raises
    ------
    ValueError
        If ``init_samples`` is 1 to 3 (:func:`initial_state` needs 4 samples).
    """
    q0, qd0 = [], []
    for ds in group:
        if init_samples > 0:
            a, b = initial_state(ds.q, dt, min(init_samples, 16))
        else:
            a, b = float(ds.q[0]), float(ds.q_dot[0])
        q0.append(a)
        qd0.append(b)
    return np.array(q0), np.array(qd0)


#: Bootstrap replicates simulated at once: the compiled kernel runs a chunk in lock step, one
#: block per thread. A larger block costs less per trajectory: Silverbox's 100 replicates took
#: 4.1 s as one chunk against 4.9 s as two (medians of five runs each, two threads).
REPLICATE_CHUNK = 100

#: Memory a chunk of replicates may hold [bytes]: their one shared input on the RK4 grid, and
#: their states and acceleration over one segment of the record. A long record runs in
#: shorter segments, each chunk going on from its states at the previous segment's last
#: sample, so that the memory per sample stays flat with the length while the chunk (and
#: with it the lock step) keeps its size.
REPLICATE_BUDGET = 128 * 2**20

#: Fewest samples in a segment of a chunk's free run (a record shorter runs whole).
REPLICATE_MIN_SEGMENT = 1000


def replicate_blocks(n_fine: int, n_inputs: int, n: int, n_states: int, B: int) -> tuple[int, int]:
    """Replicates simulated at once, and samples per segment, for a record within the budget.

    Parameters
    ----------
    n_fine, n_inputs : int
        Points of the RK4 input grid and inputs of the record (one copy, shared).
    n, n_states : int
        Samples of the record and states of the model.
    B : int
        Replicates in all.

    Returns
    -------
    chunk : int
        Replicates at once: ``min(B, REPLICATE_CHUNK)``, at least 1.
    segment : int
        Samples of a segment (its last sample is the next segment's first): the most that
        :data:`REPLICATE_BUDGET` admits for the chunk, at least
        :data:`REPLICATE_MIN_SEGMENT` and at most ``n``.
    """
    chunk = max(1, min(B, REPLICATE_CHUNK))
    # a replicate's sample: its states and acceleration, and four rows' worth of the band's
    # merge (TailPercentiles: the chunk negated, concatenated and sorted); the input is one
    # row shared by all (tile)
    per_sample = 8 * chunk * (n_states + 1 + 4)
    fits = (REPLICATE_BUDGET - 8 * n_fine * n_inputs) // per_sample
    return chunk, int(min(n, max(2, REPLICATE_MIN_SEGMENT, fits)))  # 2: a segment advances


def _replicate_runs(model, columns, deviations, ds, dt, ns, q0, qd0, cfg, q_limit):
    """Free-run the replicates on one data set in chunks and segments; return band and scores.

    A chunk runs one segment of the record at a time, from its states at the last sample of
    the one before (RK4 is a one-step scheme: every state is the one of a single run); only
    a segment's q is held, the band keeps the extreme ranks (:class:`TailPercentiles`) and
    each score its sum of squares. Returns the 2.5 and 97.5 percentiles, shape (2, n), and
    each replicate's NRMSE(q) after ``cfg.init_samples`` (inf where it diverged), shape (B,).
    """
    B, n = deviations.shape[0], ds.q.size
    fine = prepare_inputs([ds.v], ns, cfg.input_interpolation)
    _, n_fine, n_inputs = fine.values.shape
    chunk, segment = replicate_blocks(n_fine, n_inputs, n, model.n_states, B)
    x = np.full((B, model.n_states), np.nan)  # each replicate's states at a segment's start
    dead = np.zeros(B, dtype=bool)
    tables = {}  # chunk start -> (replicates alive, their model): rebuilt only when one diverges
    sq = np.zeros(B)  # sum of squared errors over the scored samples
    band = np.full((2, n), np.nan)
    a = 0
    while True:
        e = min(a + segment - 1, n - 1)  # the segment's last sample
        c = n if e == n - 1 else e  # columns [a, c) are this segment's
        seg = FineInputs(fine.values[:, a * 2 * ns : e * 2 * ns + 1], [e - a + 1], ns)
        tail = TailPercentiles(c - a, rows=B, percentiles=(2.5, 97.5))
        lo = max(a, cfg.init_samples)  # scored samples of the segment: [lo, c)
        for b0 in range(0, B, chunk):
            idx = np.flatnonzero(~dead[b0 : b0 + chunk]) + b0
            rows = min(chunk, B - b0)
            if idx.size:
                if tables.get(b0, (0,))[0] != idx.size:
                    tables[b0] = (idx.size, model.replicate_table(list(columns), deviations[idx]))
                run = simulate_batch(
                    tables[b0][1], seg.tile(idx.size), dt, np.full(idx.size, q0),
                    np.full(idx.size, qd0), substeps=ns, q_limit=q_limit, engine=cfg.engine,
                    x0=x[idx] if a else None,
                )  # fmt: skip
                x[idx] = run.states[:, -1]
                dead[idx[run.diverged_at >= 0]] = True
            if idx.size == rows:
                q_runs = run.q[:, : c - a]  # a view of the states
            else:  # NaN for those that diverged in an earlier segment
                q_runs = np.full((rows, c - a), np.nan)
                if idx.size:
                    q_runs[idx - b0] = run.q[:, : c - a]
            tail.add(q_runs)
            for i, q in zip(range(b0, b0 + q_runs.shape[0]), q_runs, strict=True):
                if lo < c and not dead[i]:
                    sq[i] += np.sum((ds.q[lo:c] - q[lo - a :]) ** 2)
        band[:, a:c] = tail.result()
        if c == n:
            break
        a = e
    s = ds.q[cfg.init_samples :]
    span = float(np.max(s) - np.min(s))
    with np.errstate(divide="ignore", invalid="ignore"):
        scores = np.where(dead, np.inf, np.sqrt(sq / s.size) / span)
    return band, scores


def replicate_spread(
    model,
    columns: Sequence[str],
    deviations: np.ndarray,
    datasets: Sequence[DataSet],
    cfg: ValidateConfig,
    q_limit: float,
) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """Free-run the bootstrap replicates of the model on every data set, as MATLAB's ``simsd``.

    Each replicate is the model with its parameters moved by one block-bootstrap replicate's
    deviation from the least-squares estimate (:meth:`debist.model.rbf.RBFModel.
    replicate_table`), simulated by the same kernel and scored by Eq. 41. The spread covers
    the estimation uncertainty only, never a prediction interval (docs/results/fleets.md).

    Parameters
    ----------
    model : RBFModel
        The identified model.
    columns : sequence of str
        Regressor column names of its fit.
    deviations : ndarray, shape (B, len(columns))
        Replicates minus the estimate (regression sign convention).
    datasets : sequence of DataSet
        The data sets (records with one sample time are simulated as one batch).
    cfg : ValidateConfig
        ``substeps``, ``input_interpolation``, ``init_samples``, ``engine``.
    q_limit : float
        Divergence bound on |q| [unit of q].

    Returns
    -------
    table : pandas.DataFrame
        One row per data set: ``dataset``, ``replicates`` (B), ``nrmse_q_lo``, ``nrmse_q_hi``
        (2.5th and 97.5th order statistics of NRMSE(q), a diverged replicate infinite),
        ``replicates_poor`` (share above :data:`debist.core.metrics.POOR_SHARE` of the mean
        baseline's, or diverged), ``replicates_hold_q`` (share of measured q in the band).
    bands : dict of str to ndarray, shape (2, n)
        Per data set the pointwise 2.5 and 97.5 percentiles of the replicates' q [unit of
        q] (NaN where every replicate diverged), stored as :data:`REPLICATE_BAND`.

    References
    ----------
    Efron & Tibshirani 1993, An Introduction to the Bootstrap, Ch. 6 and 13; MathWorks,
    System Identification Toolbox, ``simsd`` (simulation with parameter uncertainty);
    Masoud & Maas 2025, Eq. 41.
    """
    deviations = np.atleast_2d(np.asarray(deviations, dtype=float))
    B = deviations.shape[0]
    rows, bands = [], {}
    s = slice(cfg.init_samples, None)
    for dt, group in by_sample_time(datasets).items():
        # one sub-step count for every replicate, as if all ran in one batch
        ns = substeps_needed(model.replicate_table(list(columns), deviations), dt, cfg.substeps)
        q0, qd0 = initial_states(group, dt, cfg.init_samples)
        for k, ds in enumerate(group):
            band, scores = _replicate_runs(
                model, columns, deviations, ds, dt, ns, q0[k], qd0[k], cfg, q_limit
            )
            # all-NaN samples (every replicate diverged): NaN
            lo, hi = bands[ds.name] = band
            inside = (lo[s] <= ds.q[s]) & (ds.q[s] <= hi[s])  # NaN edges hold nothing
            base = mean_baseline_nrmse(ds.q[s])
            rows.append(
                {
                    "dataset": ds.name,
                    "replicates": B,
                    "nrmse_q_lo": float(np.percentile(scores, 2.5, method="lower")),
                    "nrmse_q_hi": float(np.percentile(scores, 97.5, method="higher")),
                    "replicates_poor": float(np.mean(scores > POOR_SHARE * base)),
                    "replicates_hold_q": float(np.mean(inside)) if inside.size else np.nan,
                }
            )
    return pd.DataFrame(rows), bands


def score_free_runs(
    model_name: str,
    datasets: Sequence[DataSet],
    results: Mapping[str, SimulationResult],
    cfg: ValidateConfig,
    phi: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[pd.DataFrame, dict[str, pd.DataFrame]]:
    """Score free runs against the measurements (Eq. 41): the rows of the NRMSE table.

    Parameters
    ----------
    model_name : str
        The rows' model label.
    datasets : sequence of DataSet
        The measured data sets.
    results : mapping of str to SimulationResult
        The free run of each data set (by name); NaN after a divergence. A model that
        predicts only q (a NARX model) gives NaN ``q_dot`` and ``q_ddot``: their NRMSE is
        then NaN, "not modelled".
    cfg : ValidateConfig
        ``init_samples`` (samples not scored) and ``report_unit``.
    phi : callable, optional
        As :func:`validate_model`.

    Returns
    -------
    table, simulated
        As :func:`validate_model`.

    Raises
    ------
    WorkflowError
        If the report unit does not fit q.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.2 and Eq. 41.
    """
    rows, simulated = [], {}
    for ds in datasets:
        sim = results[ds.name]
        factor, unit = report_factor(ds.q_unit, cfg.report_unit)
        s = slice(cfg.init_samples, None)
        rows.append(
            {
                "dataset": ds.name,
                "role": ds.role,
                "model": model_name,
                "n_samples": int(ds.q[s].size),
                "nrmse_q": nrmse(ds.q[s], sim.q[s]),
                **({"nrmse_phi": nrmse(phi(ds.q[s]), phi(sim.q[s]))} if phi else {}),
                "nrmse_q_dot": nrmse(ds.q_dot[s], sim.q_dot[s]),
                "nrmse_q_ddot": nrmse(ds.q_ddot[s], sim.q_ddot[s]),
                "rms_q": rms(ds.q[s] - sim.q[s]) * factor,
                "rms_unit": unit,
                "diverged": sim.diverged,
                "status": "diverged" if sim.diverged else "ok",
                "nrmse_q_baseline": mean_baseline_nrmse(ds.q[s]),
            }
        )
        simulated[ds.name] = pd.DataFrame(
            {
                "t": ds.t,
                "q": ds.q,
                "q_sim": sim.q,
                "q_dot_sim": sim.q_dot,
                "q_ddot_sim": sim.q_ddot,
            }
        )
    return pd.DataFrame(rows), simulated
