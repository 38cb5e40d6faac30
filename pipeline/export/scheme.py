"""The integration scheme an export carries: validate's, and what it scores on the run's records.

The validate stage scores the identified model's free run with ``ns`` RK4 sub-steps per
sample (``[validate] substeps``, raised by :func:`debist.simulate.freerun.substeps_needed`)
and inputs interpolated band-limited or linearly (``[validate] input_interpolation``). An
export bakes the same scheme into its code: :func:`run_scheme` computes it with the
functions validate runs (one source of truth), and scores, per record of the run, the
exported whole-record free run (validate's scheme, so validate's number) and the causal
per-sample step (the same ``ns``, inputs linear between two samples), both by the simulator
(:func:`debist.simulate.freerun.simulate`) and by validate's scoring
(:func:`debist.validate.freerun.score_free_runs`).

References
----------
Masoud & Maas 2025, Sec. 5 and Eq. 41 (free-run validation, NRMSE); Hairer, Norsett &
Wanner, Solving ODEs I, Sec. II.1 (classical RK4 with sub-steps).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from debist.core.errors import WorkflowError
from debist.simulate.freerun import bandlimited_phases, simulate, substeps_needed
from debist.validate.config import ValidateConfig
from debist.validate.freerun import (
    DataSet,
    by_sample_time,
    default_q_limit,
    initial_states,
    report_factor,
    score_free_runs,
)

__all__ = ["RecordScore", "Scheme", "default_scheme", "run_scheme"]


@dataclass(frozen=True)
class RecordScore:
    """What the exported code scores on one record of the run (Eq. 41).

    Attributes
    ----------
    name : str
        The data set.
    dt : float
        Its sample time [s] (as validate's free run takes it).
    substeps : int
        The RK4 sub-steps per sample validate used on it.
    free_run : float
        NRMSE(q) [1] of the exported whole-record free run (validate's scheme); NaN when it
        diverged.
    step : float
        NRMSE(q) [1] of the causal per-sample step (inputs linear between samples); NaN
        when it diverged.
    free_run_diverged, step_diverged : int
        First sample index at which the run left the bound, -1 if none.
    reported : float or None
        Validate's NRMSE(q) of the identified model (``validate/nrmse.parquet``) [1]; None
        when the validate stage is not up to date.
    """

    name: str
    dt: float
    substeps: int
    free_run: float
    step: float
    free_run_diverged: int = -1
    step_diverged: int = -1
    reported: float | None = None


@dataclass(frozen=True)
class Scheme:
    """The free-run scheme baked into an export.

    Attributes
    ----------
    substeps : int
        RK4 sub-steps per sample ``ns`` (what validate used at the run's sample time).
    interpolation : {"bandlimited", "linear"}
        The input interpolation of the whole-record free run.
    q_limit : float
        Bound on ``|q|`` beyond which a free run stops (diverged) [unit of q].
    q_unit : str
        SI unit of q ("m", or e.g. "V" for an electrical circuit).
    dt : float or None
        The run's sample time [s]; None without a run or with several.
    init_samples : int
        ``[validate] init_samples``: validate's initial state is fitted to the first ones
        and its NRMSE scores the samples after them (0: the first sample, all scored).
    records : tuple of RecordScore
        The scores on the run's records (empty without a run).
    report_unit : str or None
        ``[validate] report_unit``: the header gives what it says about q in it too
        (:func:`debist.validate.freerun.report_factor`; None: mm for q in m).
    """

    substeps: int
    interpolation: str
    q_limit: float
    q_unit: str = "m"
    dt: float | None = None
    init_samples: int = 0
    records: tuple[RecordScore, ...] = ()
    report_unit: str | None = None

    def shown(self) -> tuple[float, str] | None:
        """Return the factor and ASCII name of the report unit, None when it is q's own.

        Returns
        -------
        tuple of (float, str) or None
            Multiply a value in ``q_unit`` by the factor for the report unit (``"um"`` for
            µm: the headers are ASCII); None when the report unit is ``q_unit``, cannot
            express q or has no ASCII name.

        Examples
        --------
        >>> Scheme(2, "linear", 0.03).shown(), Scheme(2, "linear", 0.03, report_unit="um").shown()
        ((1000.0, 'mm'), (1000000.0, 'um'))
        >>> Scheme(2, "linear", 0.03, report_unit="m").shown() is None
        True
        """
        try:
            factor, unit = report_factor(self.q_unit, self.report_unit)
        except WorkflowError:  # validate refuses such a unit; the header keeps q's own
            return None
        unit = unit.replace("\u00b5", "u")
        return None if unit == self.q_unit or not unit.isascii() else (factor, unit)

    def taps(self) -> np.ndarray:
        """Return the polyphase FIR taps of the band-limited interpolation onto half sub-steps.

        Returns
        -------
        ndarray, shape (2 ns, 2 D + 1)
            :func:`debist.simulate.freerun.bandlimited_phases` of ``2 substeps`` [1].
        """
        return bandlimited_phases(2 * self.substeps)


def default_scheme(model, cfg: ValidateConfig | None = None) -> Scheme:
    """Return the scheme of ``[validate]`` (default settings without ``cfg``) without a run.

    Parameters
    ----------
    model : RBFModel
        The identified model (its q range gives the default divergence bound).
    cfg : ValidateConfig, optional
        The ``[validate]`` table.

    Returns
    -------
    Scheme
        ``substeps`` as set (no sample time to raise it by), the interpolation and the
        bound of :func:`debist.validate.freerun.default_q_limit` unless set; no records.
    """
    cfg = cfg or ValidateConfig()
    q_limit = cfg.q_limit if cfg.q_limit is not None else default_q_limit(model.q_range)
    return Scheme(
        int(cfg.substeps),
        cfg.input_interpolation,
        float(q_limit),
        init_samples=int(cfg.init_samples),
        report_unit=cfg.report_unit,
    )


def run_scheme(
    model,
    datasets: Sequence[DataSet],
    cfg: ValidateConfig,
    reported: Mapping[str, float] | None = None,
) -> Scheme:
    """Return the scheme validate used on a run's records and what the exported code scores.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    datasets : sequence of DataSet
        The run's records (:func:`debist.validate.datasets.validation_datasets`).
    cfg : ValidateConfig
        The run's ``[validate]`` table.
    reported : mapping of str to float, optional
        Validate's NRMSE(q) per data set (its ``rbf`` rows) [1].

    Returns
    -------
    Scheme
        ``substeps`` the largest ``ns`` validate used (one per sample time: the same for all
        records of one sample time), the records' scores: the whole-record free run in
        validate's scheme and the causal per-sample step, each with the initial states,
        divergence bound and scoring of validate.

    Raises
    ------
    WorkflowError, ResourceError
        As :func:`debist.simulate.freerun.simulate`.
    """
    base = default_scheme(model, cfg)
    groups = by_sample_time(datasets)
    if not groups:
        return base
    used = {dt: substeps_needed(model, dt, cfg.substeps) for dt in groups}
    ns = max(used.values())
    reported = reported or {}
    records = []
    for dt, group in groups.items():
        q0, qd0 = initial_states(group, dt, cfg.init_samples)
        scores = {}
        for kind, interpolation in (("free", cfg.input_interpolation), ("step", "linear")):
            sims = simulate(
                model, [ds.v for ds in group], dt, q0, qd0, substeps=ns,
                interpolation=interpolation, q_limit=base.q_limit, engine=cfg.engine,
            )  # fmt: skip
            results = {ds.name: sim for ds, sim in zip(group, sims, strict=True)}
            scores[kind] = (score_free_runs("export", group, results, cfg)[0], results)
        for ds in group:
            free, step = (scores[k][0].set_index("dataset").loc[ds.name] for k in ("free", "step"))
            records.append(
                RecordScore(
                    name=ds.name,
                    dt=float(dt),
                    substeps=used[dt],
                    free_run=float(free["nrmse_q"]),
                    step=float(step["nrmse_q"]),
                    free_run_diverged=scores["free"][1][ds.name].diverged_at,
                    step_diverged=scores["step"][1][ds.name].diverged_at,
                    reported=reported.get(ds.name),
                )
            )
    return Scheme(
        substeps=ns,
        interpolation=base.interpolation,
        q_limit=base.q_limit,
        q_unit=datasets[0].q_unit,
        dt=float(min(groups)) if len(groups) == 1 else None,
        init_samples=base.init_samples,
        records=tuple(records),
        report_unit=base.report_unit,
    )
