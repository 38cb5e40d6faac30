"""Automatic hyper-parameters of the RBF identification by blocked cross-validation.

Chooses ``M``, ``sigma_n``, ``lowpass`` and the smoothness penalty by the free-run error
estimated on the estimation records alone:

* each estimation record is cut into ``folds`` contiguous time blocks; fold ``k`` holds out
  block ``k`` of every record and fits on the remaining pieces (each trimmed by ``trim``);
* the fitted model runs free on the held-out block in windows of ``window`` samples, each
  restarted from the measured state, and scores NRMSE(q) (Eq. 41) over the windows
  (multiple shooting);
* a fit that raises :class:`~debist.core.errors.IdentificationError` or a free run that
  diverges scores ``+inf``;
* the chosen setting is the most parsimonious one whose score is within one standard error
  of the best (the one-standard-error rule), in the order of :data:`PARSIMONY`: fewer
  regressor columns, wider RBFs, stronger smoothing, lower ``lowpass`` corner. Every
  candidate is scored on the same folds, so the error compared is the paired one: the mean
  over the folds of ``log(score / best's score)`` against its standard error
  (:func:`paired_gaps`). One held-out block that holds a switch can score ten times the
  others for every candidate; unpaired, that spread between the blocks would admit every
  candidate, paired it cancels.

Grids of more than :data:`MAX_PRODUCT` settings are swept one coordinate at a time.
Rationale: docs/explanation/implementation.md.

References
----------
Masoud & Maas 2025, Eq. 37-41 and Fig. 11b, 11c (error against M and sigma_n); Hastie,
Tibshirani & Friedman 2009, Sec. 7.10 (K-fold cross-validation, one-standard-error rule);
Bergmeir & Benitez 2012, Inf. Sci. 191, 192-213 (blocked cross-validation of time series);
Dietterich 1998, Neural Comput. 10(7), 1895-1923 (paired comparisons on shared folds);
Bock & Plitt 1984, IFAC 9th World Congress (multiple shooting); Ribeiro, Tiels, Umenberger,
Schon & Aguirre 2020, Automatica 121 (smoothness of simulation-error costs).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core import progress as _progress
from debist.core.errors import IdentificationError, WorkflowError
from debist.core.metrics import nrmse
from debist.identify.config import (
    DEFAULT_WINDOW,
    IdentifyConfig,
    auto_settings,
    candidate_config,
    check_grid,
)
from debist.identify.fit import Record, fit_rbf_model, supported_size
from debist.model.terms import column_names
from debist.validate.freerun import default_q_limit
from debist.validate.prediction import restarted_runs

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "DEFAULT_WINDOW",
    "MAX_PRODUCT",
    "PARSIMONY",
    "AutoResult",
    "Fold",
    "auto_settings",
    "blocked_folds",
    "one_standard_error",
    "paired_gaps",
    "scored_folds",
    "select_hyperparameters",
    "undecided",
]

#: The search is undecided when the best candidate's standard error across the folds exceeds
#: this fraction of its mean score: its folds disagree (typically one lost a switch).
UNDECIDED_SE = 0.5
#: Largest cartesian product of the grid evaluated whole; larger grids are swept.
MAX_PRODUCT = 40
#: Parsimony order of the table's columns: (column, ascending) -- most parsimonious first.
PARSIMONY = (("n_params", True), ("sigma_n", False), ("lambda", False), ("lowpass", True))
#: Samples a held-out segment needs at least to be scored.
_MIN_SCORED = 10


@dataclass(frozen=True)
class Fold:
    """One fold of the blocked cross-validation: row spans ``(record, start, stop)``.

    Attributes
    ----------
    index : int
        Fold number, 0-based (the held-out block's position in each record).
    test : tuple of (int, int, int)
        The held-out block of every record: record index, first row, row after the last.
    train : tuple of (int, int, int)
        The records' remaining contiguous pieces (non-empty), in record and time order.
    """

    index: int
    test: tuple[tuple[int, int, int], ...]
    train: tuple[tuple[int, int, int], ...]


def blocked_folds(lengths: Sequence[int], folds: int) -> list[Fold]:
    """Cut every record into ``folds`` contiguous blocks; fold ``k`` holds out block ``k``.

    Parameters
    ----------
    lengths : sequence of int
        Samples of each record.
    folds : int
        Number of folds, at least 2.

    Returns
    -------
    list of Fold
        ``folds`` folds; their held-out blocks partition every record's rows (each row is
        held out exactly once), and a fold's training pieces are the rows it does not hold
        out. Block ``k`` of a record of ``n`` rows is ``[round(k n / K), round((k+1) n / K))``.

    Raises
    ------
    WorkflowError
        If ``folds < 2`` or a record has fewer rows than folds.

    References
    ----------
    Bergmeir & Benitez 2012, Inf. Sci. 191, 192-213 (blocked cross-validation).
    """
    if folds < 2:
        raise WorkflowError(f"blocked cross-validation needs folds >= 2, got {folds!r}")
    edges = []
    for j, n in enumerate(lengths):
        if n < folds:
            raise WorkflowError(f"record {j} has {n} samples, fewer than folds = {folds}")
        edges.append(np.round(np.linspace(0, n, folds + 1)).astype(int))
    out = []
    for k in range(folds):
        test, train = [], []
        for j, e in enumerate(edges):
            start, stop = int(e[k]), int(e[k + 1])
            test.append((j, start, stop))
            train += [(j, a, b) for a, b in ((0, start), (stop, int(e[-1]))) if b > a]
        out.append(Fold(k, tuple(test), tuple(train)))
    return out


def one_standard_error(table: pd.DataFrame) -> Any:
    """Choose by the one-standard-error rule: the most parsimonious row near the best.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per candidate with ``mean`` and ``se`` (the cross-validation score's mean
        and standard error over the folds; ``inf`` for a failed candidate), optionally
        ``gap`` and ``gap_se`` (:func:`paired_gaps`), and any of the parsimony columns of
        :data:`PARSIMONY` (``n_params``, ``sigma_n``, ``lambda``, ``lowpass``; NaN
        ``lowpass`` means no filter, ranked as the highest corner).

    Returns
    -------
    object
        Index label of the chosen row: among the rows near the best, the first in the
        parsimony order, ties broken by the lower mean. Near: ``gap <= gap_se`` where the
        table has the paired columns, else ``mean <= mean_best + se_best`` (``best`` the
        row of least finite mean).

    Raises
    ------
    IdentificationError
        If no row has a finite mean (every candidate failed).

    References
    ----------
    Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, 2nd ed., 2009,
    Sec. 7.10 (the one-standard-error rule).
    """
    finite = table[np.isfinite(table["mean"].to_numpy(dtype=float))]
    if finite.empty:
        raise IdentificationError(
            "every hyper-parameter candidate failed or diverged", reason="candidates"
        )
    near = finite[_near(finite)]
    keys = []
    for column, up in PARSIMONY:
        if column in near:
            values = near[column].astype(float)
            if column == "lowpass":
                values = values.fillna(np.inf)
            elif column == "lambda":
                values = values.fillna(0.0)
            keys.append(values if up else -values)
    keys.append(near["mean"].astype(float))
    order = pd.DataFrame({f"k{i}": k for i, k in enumerate(keys)}, index=near.index)
    return order.sort_values(list(order.columns), kind="stable").index[0]


def _near(finite: pd.DataFrame) -> np.ndarray:
    """Rows within one standard error of the best: paired when the gaps are there."""
    if {"gap", "gap_se"} <= set(finite.columns):
        gap = finite["gap"].to_numpy(dtype=float)
        return np.isfinite(gap) & (gap <= finite["gap_se"].to_numpy(dtype=float))
    best = finite["mean"].astype(float).idxmin()
    se = float(finite.loc[best, "se"])
    limit = float(finite.loc[best, "mean"]) + (se if np.isfinite(se) else 0.0)
    return (finite["mean"].astype(float) <= limit).to_numpy()


def paired_gaps(scores: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each candidate's paired log-ratio to the best over shared folds, with its standard error.

    Parameters
    ----------
    scores : ndarray, shape (n_candidates, n_folds)
        Fold scores (NRMSE(q) of each held-out block) [-], over the folds that rank the
        candidates (:func:`scored_folds`); a row with a non-finite score has no gap.

    Returns
    -------
    gap : ndarray, shape (n_candidates,)
        Mean over the folds of ``log(score / score of the best)``, the best being the row
        of least mean score: 0 for the best, ``inf`` for a row with a non-finite score.
    gap_se : ndarray, shape (n_candidates,)
        Standard error of that mean (sample standard deviation over sqrt(folds); 0 for the
        best, ``inf`` with fewer than two folds or no finite score).

    References
    ----------
    Dietterich 1998, Neural Comput. 10(7), 1895-1923 (paired differences on shared folds);
    Hastie, Tibshirani & Friedman 2009, Sec. 7.10 (the one-standard-error rule).

    Examples
    --------
    >>> gap, se = paired_gaps(np.array([[0.10, 0.01], [0.20, 0.02], [0.12, 0.03]]))
    >>> np.round(gap, 4).tolist(), np.round(se, 4).tolist()
    ([0.0, 0.6931, 0.6405], [0.0, 0.0, 0.4581])
    """
    scores = np.asarray(scores, dtype=float)
    n, k = scores.shape
    gap, gap_se = np.full(n, np.inf), np.full(n, np.inf)
    finite = np.isfinite(scores).all(axis=1)
    if not finite.any():
        return gap, gap_se
    mean = np.where(finite, scores.mean(axis=1), np.inf)
    # a perfect fold (score 0) counts as the smallest positive score
    logs = np.log(np.where(finite[:, None], np.maximum(scores, np.finfo(float).tiny), 1.0))
    diff = logs[finite] - logs[int(np.argmin(mean))]
    gap[finite] = diff.mean(axis=1)
    gap_se[finite] = diff.std(axis=1, ddof=1) / np.sqrt(k) if k > 1 else np.inf
    return gap, gap_se


@dataclass(frozen=True)
class AutoResult:
    """Outcome of :func:`select_hyperparameters`.

    Attributes
    ----------
    chosen : dict
        The chosen value of every grid parameter (as given in the grid: ``None`` for no
        low-pass, ``"gcv"`` for the GCV smoothing).
    table : pandas.DataFrame
        One row per evaluated candidate: ``candidate``, the grid parameters and ``M``,
        ``sigma_n``, ``lowpass`` [Hz] (NaN: none), ``smoothing`` (numbers, or text when a
        column mixes numbers and words), ``n_params`` (regressor columns), ``lambda`` (the
        penalty weight used, mean over the folds), ``mean`` and ``se`` of the fold scores,
        ``fold_1 .. fold_K`` (NRMSE(q) of each held-out block [-]; ``inf`` for a fold whose
        fit failed or whose free run diverged, NaN for folds not evaluated after a failed fit),
        ``gap`` and ``gap_se`` (:func:`paired_gaps`), ``status`` (``"ok"``, ``"fit
        failed"``, ``"diverged"``), ``message``, ``within_1se`` (within one paired standard
        error of the best) and ``chosen``.
    settings : list of dict
        The grid values of each row of ``table``, as given.
    folds : int
        Number of folds.
    strategy : str
        ``"product"`` (the whole cartesian product) or ``"sweep"`` (coordinate sweeps).
    best : int
        Row of the least mean score.
    threshold : float
        ``mean_best + se_best``: the best's score plus its standard error over the folds
        (what the figure draws; the choice compares paired gaps, ``within_1se``).
    seconds : float
        Wall time [s] of the search.
    """

    chosen: dict[str, Any]
    table: pd.DataFrame
    settings: list[dict[str, Any]]
    folds: int
    strategy: str
    best: int
    threshold: float
    seconds: float = field(default=0.0, compare=False)

    def to_summary(self) -> dict[str, Any]:
        """Return the result as JSON-able data (non-finite scores as ``None``).

        Returns
        -------
        dict
            ``chosen``, ``strategy``, ``folds``, ``best``, ``threshold``, ``n_candidates``
            and ``candidates``: per row its settings, ``n_params``, ``lambda``, ``mean``,
            ``se``, ``folds`` (list), ``status``, ``message``; ``undecided``
            (:func:`undecided`); ``unscored_folds`` (1-based folds no candidate scored,
            left out of ``mean`` and ``se``: :func:`scored_folds`). No wall time.
        """
        k = self.folds
        rows = []
        for i, row in self.table.iterrows():
            rows.append(
                {
                    "settings": _jsonable(self.settings[i]),
                    "n_params": int(row["n_params"]),
                    "lambda": _num(row["lambda"]),
                    "mean": _num(row["mean"]),
                    "se": _num(row["se"]),
                    "folds": [_num(row[f"fold_{j + 1}"]) for j in range(k)],
                    "status": str(row["status"]),
                    "message": str(row["message"]),
                }
            )
        return {
            "chosen": _jsonable(self.chosen),
            "strategy": self.strategy,
            "folds": k,
            "best": int(self.best),
            "threshold": _num(self.threshold),
            "n_candidates": len(rows),
            "candidates": rows,
            "undecided": undecided(self),
            "unscored_folds": list(self.table.attrs.get("unscored_folds", [])),
        }


def _num(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _jsonable(setting: Mapping[str, Any]) -> dict[str, Any]:
    out = {}
    for key, value in setting.items():
        if isinstance(value, tuple | list):
            value = list(value)
        elif isinstance(value, np.generic):
            value = value.item()
        out[key] = value
    return out


def _freeze(value: Any) -> Any:
    return tuple(value) if isinstance(value, list | tuple) else value


def _n_params(cfg: IdentifyConfig, n_inputs: int) -> int:
    force, inputs = column_names(
        cfg.rbf,
        cfg.backbone,
        cfg.M,
        n_inputs,
        cfg.creep is not False,
        cfg.n_slip,
        cfg.inertia_powers,
    )
    return len(force) + len(inputs) + (cfg.m_q == "identify")


def _pieces(records: Sequence[Record], spans, tag: str) -> list[Record]:
    out = []
    for j, a, b in spans:
        r = records[j]
        s = slice(a, b)
        name = f"{r.name} {tag} rows {a}:{b}"
        out.append(Record(name, r.q[s], r.q_dot[s], r.q_ddot[s], r.v[s], r.dt))
    return out


def _scored_spans(records, fold: Fold, trim: int) -> list[tuple[int, int, int]]:
    """Return the held-out blocks without each record's first and last ``trim`` rows."""
    spans = []
    for j, a, b in fold.test:
        n = records[j].q.size
        a, b = max(a, trim), min(b, n - trim)
        if b - a < _MIN_SCORED:
            continue
        spans.append((j, a, b))
    return spans


def _fold_score(model, records, spans, substeps, window) -> tuple[float, bool]:
    """Mean NRMSE(q) of the held-out spans' restarted windows; (inf, True) if one diverged.

    Each span is tiled by windows of ``window`` samples, each run free from the measured
    state at its start (:func:`debist.validate.prediction.restarted_runs`); the span's score is
    NRMSE(q) (Eq. 41) of the windows' runs against the measurement, normalised by the span's
    range.
    """
    scores = []
    by_dt: dict[float, list[tuple[int, int, int]]] = {}
    for span in spans:
        by_dt.setdefault(round(records[span[0]].dt, 12), []).append(span)
    q_limit = default_q_limit(model.q_range)
    for group in by_dt.values():
        wins = [(j, s, min(s + window, b)) for j, a, b in group for s in range(a, b - 1, window)]
        wins = [w for w in wins if w[2] - w[1] >= 2]
        runs = restarted_runs(
            model, records, wins, records[group[0][0]].dt, substeps=substeps, q_limit=q_limit
        )
        if not all(np.all(np.isfinite(run)) for run in runs):
            return np.inf, True
        for j, a, b in group:
            mine = [
                (w, run) for w, run in zip(wins, runs, strict=True) if w[0] == j and a <= w[1] < b
            ]
            measured = np.concatenate([records[j].q[w[1] : w[2]] for w, _ in mine])
            scores.append(nrmse(measured, np.concatenate([run for _, run in mine])))
    return float(np.mean(scores)), False


def _fold_basis(train: Sequence[Record], cfg: IdentifyConfig) -> IdentifyConfig:
    """Return the fold's configuration with no more centres than its training supports.

    A held-out block takes its samples away from the centres it covers; the fold then fits
    the most centres its training data support (:func:`debist.identify.fit.supported_size`),
    as the stage does for the whole data, instead of failing for every candidate alike.
    """
    q = np.concatenate([p.q for p in train])
    if not cfg.rbf or np.ptp(q) <= 0:
        return cfg
    return replace(cfg, M=min(cfg.M, supported_size(q, cfg)))


def _evaluate(
    records, cfg: IdentifyConfig, fold_list, substeps, window, adapt: bool = False
) -> dict[str, Any]:
    """Fit on each fold's training pieces and score the held-out block's free run.

    A fit that raises ends the candidate (its later folds stay NaN: not evaluated); a
    diverged free run scores that fold ``inf`` and the other folds are still evaluated.
    With ``adapt`` (``M`` not among the candidates) each fold fits the centres its
    training pieces support (:func:`_fold_basis`).
    """
    scores = np.full(len(fold_list), np.nan)
    lams: list[float] = []
    diverged: list[int] = []
    status, message = "ok", ""
    minimum = 2 * cfg.trim + 11
    for fold in fold_list:
        pieces = _pieces(records, fold.train, f"fold {fold.index + 1}")
        train = [p for p in pieces if p.q.size >= minimum]
        try:
            if not train:
                raise IdentificationError(
                    f"no training piece is longer than 2 trim + 10 = {minimum - 1} samples"
                )
            model, diag = fit_rbf_model(train, _fold_basis(train, cfg) if adapt else cfg)
        except (IdentificationError, np.linalg.LinAlgError) as exc:
            scores[fold.index] = np.inf
            status, message = "fit failed", f"fold {fold.index + 1}: {exc}"
            break
        lams.append(diag.smoothing)
        spans = _scored_spans(records, fold, cfg.trim)
        scores[fold.index], bad = _fold_score(model, records, spans, substeps, window)
        if bad:
            diverged.append(fold.index + 1)
    if diverged and status == "ok":
        status = "diverged"
        message = f"the free run diverged in fold(s) {diverged}"
    return {"scores": scores, "lambda": float(np.mean(lams)) if lams else np.nan,
            "status": status, "message": message}  # fmt: skip


def _mean(scores: np.ndarray) -> float:
    """Mean fold score; ``inf`` when a fold failed, diverged or was not evaluated."""
    return float(np.mean(scores)) if np.all(np.isfinite(scores)) else np.inf


def _column(values: list[Any]) -> list[Any] | np.ndarray:
    """Make a table column: numbers (None as NaN) if every value is a number, else text."""
    if all(v is None or isinstance(v, int | float | np.number) for v in values):
        if all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in values):
            return np.asarray(values, dtype=int)
        return np.array([np.nan if v is None else float(v) for v in values])
    return [str(list(v)) if isinstance(v, tuple | list) else str(v) for v in values]


def select_hyperparameters(
    records: Sequence[Record],
    base_cfg: IdentifyConfig,
    grid: Mapping[str, Sequence[Any]],
    *,
    folds: int = 4,
    window: int = DEFAULT_WINDOW,
    substeps: int = 2,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    fallback: bool = False,
) -> AutoResult:
    """Choose RBF hyper-parameters by blocked cross-validation of the free-run error.

    Per candidate and fold (:func:`blocked_folds`) the model is fitted on the other blocks and
    scored by NRMSE(q) (Eq. 41) of restarted windows on the held-out block; the most
    parsimonious candidate within one standard error of the best is chosen.

    Parameters
    ----------
    records : sequence of Record
        Estimation records (never validation data).
    base_cfg : IdentifyConfig
        The configuration the candidates modify (``m_q`` a number).
    grid : mapping of str to list
        Values per :class:`IdentifyConfig` field, e.g. ``{"M": [6, 8, 10], "sigma_n": [0.5, 1.0]}``.
    folds, window, substeps, seed : int, optional
        Blocks per record (>= 2), samples per restarted window, RK4 steps per sample; unused.
    progress : callable, optional
        Called as ``progress(done, total)`` [candidates]; default the listener, if any.
    fallback : bool, optional
        When every candidate fails, choose ``base_cfg``'s own values instead of raising.

    Returns
    -------
    AutoResult
        The chosen setting, the score table, the strategy.

    Raises
    ------
    WorkflowError
        If the grid is empty, unknown or invalid, ``folds < 2``, or a record is too short.
    IdentificationError
        If every candidate failed or diverged (and not ``fallback``).
    ResourceError
        If a free run would exceed the memory budget.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-41, Fig. 11b, 11c; Hastie, Tibshirani & Friedman 2009, Sec. 7.10.
    """
    import time

    t0 = time.perf_counter()
    del seed  # deterministic: contiguous blocks, no sampling
    grid = check_grid(base_cfg, grid)
    if not records:
        raise WorkflowError("no estimation records to cross-validate")
    fold_list = blocked_folds([r.q.size for r in records], folds)
    for fold in fold_list:
        if len(_scored_spans(records, fold, base_cfg.trim)) < len(fold.test):
            raise WorkflowError(
                f"folds = {folds}: a held-out block of fold {fold.index + 1} keeps fewer than "
                f"{_MIN_SCORED} samples after trim = {base_cfg.trim}; use fewer folds"
            )
    report = progress or _progress.reporter("hyper-parameters") or (lambda done, total: None)
    n_in = records[0].v.shape[1]
    keys = list(grid)
    size = math.prod(len(v) for v in grid.values())
    strategy = "product" if size <= MAX_PRODUCT else "sweep"
    total = size if strategy == "product" else sum(len(v) for v in grid.values())
    cache: dict[tuple, dict[str, Any]] = {}
    order: list[dict[str, Any]] = []

    def run(setting: dict[str, Any]) -> dict[str, Any]:
        key = tuple(_freeze(setting[k]) for k in keys)
        if key not in cache:
            cfg = candidate_config(base_cfg, setting)
            scored = _evaluate(records, cfg, fold_list, substeps, window, "M" not in keys)
            cache[key] = {**scored, "cfg": cfg}
            order.append(dict(setting))
            report(len(order), total)
        return cache[key]

    if strategy == "product":
        for combo in itertools.product(*grid.values()):
            run(dict(zip(keys, combo, strict=True)))
    else:
        current = {k: getattr(base_cfg, k) for k in keys}
        for k in keys:
            sweep = [{**current, k: v} for v in grid[k]]
            means = [_mean(run(s)["scores"]) for s in sweep]
            if np.isfinite(means).any():
                current = sweep[int(np.argmin(means))]
    report(total, total)
    table = _table(order, cache, keys, n_in, len(fold_list))
    try:
        chosen = one_standard_error(table)
    except IdentificationError:
        if not fallback:
            raise
        own = {k: _freeze(getattr(base_cfg, k)) for k in keys}
        same = [i for i, s in enumerate(order) if {k: _freeze(s[k]) for k in keys} == own]
        chosen = same[0] if same else 0
    best = int(table["mean"].astype(float).idxmin())
    threshold = float(table.loc[best, "mean"] + np.nan_to_num(table.loc[best, "se"]))
    table["within_1se"] = _near(table)
    table["chosen"] = table.index == chosen
    return AutoResult(
        chosen=dict(order[chosen]),
        table=table,
        settings=order,
        folds=len(fold_list),
        strategy=strategy,
        best=best,
        threshold=threshold,
        seconds=time.perf_counter() - t0,
    )


def scored_folds(scores: np.ndarray) -> np.ndarray:
    """Folds that can rank the candidates: where at least one candidate scored.

    Parameters
    ----------
    scores : ndarray, shape (n_candidates, n_folds)
        Fold scores [-]; ``inf`` for a failed fit or a diverged free run, NaN for a fold
        not evaluated.

    Returns
    -------
    ndarray of bool, shape (n_folds,)
        False for a fold where no candidate has a finite score (a held-out block that
        every candidate loses, e.g. one with a switch no training piece shows: it says
        nothing about which candidate is better), unless fewer than two folds would remain,
        in which case every fold counts.

    References
    ----------
    Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, 2nd ed., 2009,
    Sec. 7.10 (K-fold cross-validation).
    """
    used = np.isfinite(scores).any(axis=0)
    return used if used.sum() >= 2 else np.ones(scores.shape[1], dtype=bool)


def _table(order, cache, keys, n_in, k) -> pd.DataFrame:
    rows = [cache[tuple(_freeze(s[key]) for key in keys)] for s in order]
    cfgs = [r["cfg"] for r in rows]
    scores = np.array([r["scores"] for r in rows]).reshape(len(rows), k)
    used = scored_folds(scores)
    kept = scores[:, used]
    finite = np.isfinite(kept).all(axis=1)  # a failed or unevaluated fold: mean inf
    mean = np.where(finite, kept.mean(axis=1), np.inf)
    se = np.full(len(rows), np.inf)
    se[finite] = kept[finite].std(axis=1, ddof=1) / np.sqrt(used.sum())
    data: dict[str, Any] = {"candidate": np.arange(len(rows))}
    for name in dict.fromkeys(["M", "sigma_n", "lowpass", "smoothing", *keys]):
        data[name] = _column([getattr(c, name) for c in cfgs])
    data["n_params"] = [_n_params(c, n_in) for c in cfgs]
    data["lambda"] = [r["lambda"] for r in rows]
    data["mean"] = mean
    data["se"] = se
    data["gap"], data["gap_se"] = paired_gaps(kept)
    for j in range(k):
        data[f"fold_{j + 1}"] = scores[:, j]
    data["status"] = [r["status"] for r in rows]
    data["message"] = [r["message"] for r in rows]
    frame = pd.DataFrame(data)
    frame.attrs["unscored_folds"] = [j + 1 for j in range(k) if not used[j]]
    return frame


def undecided(search: AutoResult) -> bool:
    """Say whether a hyper-parameter search's folds disagree too much to support its choice.

    Parameters
    ----------
    search : AutoResult
        The search.

    Returns
    -------
    bool
        True when the best candidate's standard error of the fold scores exceeds
        :data:`UNDECIDED_SE` of their mean (or the mean is not finite): the folds disagree,
        e.g. one held-out block of a bistable record lost a switch, so the score itself is
        uncertain (the choice compares paired gaps, which that spread does not enter).

    References
    ----------
    Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, 2nd ed., 2009,
    Sec. 7.10 (the standard error of a K-fold estimate).
    """
    row = search.table.loc[search.best]
    mean, se = float(row["mean"]), float(row["se"])
    return not np.isfinite(mean) or not np.isfinite(se) or se > UNDECIDED_SE * mean
