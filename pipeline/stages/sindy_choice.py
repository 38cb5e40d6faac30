"""SINDy's library and threshold chosen on held-out estimation data, never on validation data.

Blocked cross-validation over the estimation records: each record is cut into :data:`FOLDS`
contiguous blocks; per fold, each candidate (polynomial degree, sparsity threshold; the
input-state products as the user sets them) is fitted on every other block (SINDy regresses
given derivatives sample by sample, so a gap costs nothing) and run free, from the measured
state, over the held-out block with the simulator every model is compared with. The fewest
terms whose mean held-out NRMSE(q) (Eq. 41; a diverged block counts as
:data:`DIVERGED_SCORE`) is within :data:`SIMPLER_WITHIN` of the best win,
and that candidate is refitted on the whole records. Settings the user gives in ``[compare]``
are kept as given (a given degree is not searched, a given threshold neither).

References
----------
Brunton, Proctor & Kutz 2016, PNAS (SINDy); Bergmeir & Benitez 2012, Inf. Sci. 191 (blocked
cross-validation of time series); Hastie, Tibshirani & Friedman 2009, Sec. 7.10 (prefer the
simpler model within the noise of the score).
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from debist.core.errors import IdentificationError
from debist.model.sindy import SindyConfig, fit_sindy_thresholds
from debist.validate.config import ValidateConfig
from debist.validate.freerun import DataSet, default_q_limit, validate_model

__all__ = ["DEGREES", "DIVERGED_SCORE", "FOLDS", "SIMPLER_WITHIN", "THRESHOLDS", "choose_sindy"]

#: Candidate library degrees and relative thresholds searched when the workflow sets none.
DEGREES = (2, 3)
THRESHOLDS = (1e-3, 1e-2, 5e-2)
#: Contiguous blocks per estimation record, each held out once.
FOLDS = 4
#: Relative margin of the held-out score within which fewer terms are preferred.
SIMPLER_WITHIN = 0.1
#: Score of a held-out block whose free run diverged: NRMSE(q) of 1, the whole range.
DIVERGED_SCORE = 1.0


def _folds(records, q_unit: str):
    """Per fold: the training pieces (records without the block) and the held-out blocks."""
    for k in range(FOLDS):
        train, held = [], []
        for r in records:
            edges = np.linspace(0, r.q.size, FOLDS + 1).round().astype(int)
            a, b = edges[k], edges[k + 1]
            train += [_piece(r, 0, a), _piece(r, b, r.q.size)]
            t = np.arange(b - a) * r.dt
            held.append(DataSet(f"{r.name} [{a}:{b}]", "estimation", t, *_piece(r, a, b)[:3],
                                r.v[a:b], q_unit))  # fmt: skip
        yield [t for t in train if t[0].size > 0], held


def _piece(r, a: int, b: int):
    return r.q[a:b], r.q_dot[a:b], r.q_ddot[a:b], r.v[a:b]


def choose_sindy(
    records: Sequence[Any],
    cfg: SindyConfig,
    given: Mapping[str, Any],
    vcfg: ValidateConfig,
    q_unit: str = "m",
    input_units: Sequence[str] | None = None,
) -> tuple[SindyConfig, list[dict[str, Any]]]:
    """Choose SINDy's degree and threshold on the held-out ends of the estimation records.

    Parameters
    ----------
    records : sequence of debist.identify.fit.Record
        The estimation records (``q`` [m], ``q_dot``, ``q_ddot``, ``v`` [V], ``dt`` [s]).
    cfg : SindyConfig
        The ``[compare]`` settings (defaults where the workflow gives none).
    given : mapping
        The keys the workflow's ``[compare]`` sets: ``degree`` or ``threshold`` there are
        kept as given.
    vcfg : ValidateConfig
        Simulation settings of the free runs (substeps, input interpolation).
    q_unit : str
        SI unit of q (``"m"``; ``"V"`` for an electric circuit).
    input_units : sequence of str, optional
        Units of the inputs, for the equations' legend.

    Returns
    -------
    cfg : SindyConfig
        The chosen settings (``cfg`` itself when nothing is searched).
    candidates : list of dict
        Per candidate: ``degree``, ``threshold``, ``n_terms``, ``holdout_nrmse_q`` (the mean
        over the held-out blocks, :data:`DIVERGED_SCORE` for a diverged one; inf when the fit
        failed), ``status``; empty when nothing is searched.

    Raises
    ------
    IdentificationError
        If no candidate can be fitted.
    """
    degrees = (cfg.degree,) if "degree" in given else DEGREES
    thresholds = (cfg.threshold,) if "threshold" in given else THRESHOLDS
    if len(degrees) * len(thresholds) == 1:
        return cfg, []
    sim_cfg = replace(vcfg, init_samples=0, analytical=False)
    scores, terms, failed = _holdout_scores(
        list(_folds(records, q_unit)), records[0].dt, cfg, degrees, thresholds, sim_cfg, input_units
    )
    rows = []
    for candidate, got in scores.items():
        row = {"degree": candidate[0], "threshold": candidate[1], "n_terms": 0,
               "holdout_nrmse_q": np.inf, "status": failed.get(candidate, "ok")}  # fmt: skip
        if candidate not in failed:
            diverged = int(np.sum(np.asarray(got) == DIVERGED_SCORE))
            row["n_terms"] = int(np.median(terms[candidate]))
            row["holdout_nrmse_q"] = float(np.mean(got))
            row["status"] = f"diverged in {diverged} of {len(got)} blocks" if diverged else "ok"
        rows.append(row)
    ok = [r for r in rows if np.isfinite(r["holdout_nrmse_q"])]
    if not ok:
        raise IdentificationError(
            "SINDy: no candidate library could be fitted on the estimation records"
        )
    best = min(r["holdout_nrmse_q"] for r in ok)
    near = [r for r in ok if r["holdout_nrmse_q"] <= (1.0 + SIMPLER_WITHIN) * best]
    pick = min(near, key=lambda r: (r["n_terms"], r["degree"], -r["threshold"]))
    return replace(cfg, degree=pick["degree"], threshold=pick["threshold"]), rows


def _holdout_scores(folds, dt, cfg, degrees, thresholds, sim_cfg, input_units):
    """Per candidate (degree, threshold): its held-out scores, term counts and first failure.

    Per fold and degree one library is built and every threshold fitted on it
    (:func:`debist.model.sindy.fit_sindy_thresholds`: the models of separate fits; a fit
    that raises fails every threshold of its degree in that fold); a candidate that failed
    in a fold (its fit or its free run raised) is not tried again.
    """
    scores = {c: [] for c in itertools.product(degrees, thresholds)}
    terms = {c: [] for c in scores}
    failed: dict[tuple[int, float], str] = {}
    for train, held in folds:
        for degree in degrees:
            todo = [th for th in thresholds if (degree, th) not in failed]
            if not todo:
                continue
            with warnings.catch_warnings():  # a candidate's convergence is its score's
                warnings.simplefilter("ignore")
                try:
                    models = fit_sindy_thresholds(*(list(x) for x in zip(*train, strict=True)),
                                                  dt, replace(cfg, degree=degree), todo,
                                                  input_units=input_units)  # fmt: skip
                except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
                    failed.update({(degree, th): f"fit failed: {exc}" for th in todo})
                    continue
                for threshold, model in zip(todo, models, strict=True):
                    try:
                        table, _ = validate_model(model, "sindy", held, sim_cfg,
                                                  default_q_limit(model.q_range))  # fmt: skip
                    except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
                        failed[(degree, threshold)] = f"fit failed: {exc}"
                        continue
                    scores[(degree, threshold)] += np.where(
                        np.isfinite(table.nrmse_q), table.nrmse_q, DIVERGED_SCORE
                    ).tolist()
                    terms[(degree, threshold)].append(model.n_params)
    return scores, terms, failed
