"""The memory a whole workflow will need, estimated from its settings before any stage runs.

:func:`workflow_estimates` estimates the largest arrays of every stage whose size a workflow
key controls, from the checked settings alone: the virtual rig's integration, the
identification's least squares and bootstrap, the refinement's window runs, the validation's
free runs, the SINDy and NARX peers, the hyper-parameter study, the design analysis and the
Savitzky-Golay filter. Where the data's length is not known before the ingest (a rig-log
file), the estimate takes the least the stage needs whatever the data (a least squares
needs at least as many samples as columns, a record at least two samples).
:func:`check_workflow_budget` refuses the first estimate above the memory budget
(:func:`debist.core.preflight.memory_budget`) in one line naming the key, so a setting such
as ``[rig.experiments.identification] duration = 2e5`` exits with code 2 before anything is
written, instead of ending in the kernel's out-of-memory killer. Each stage checks its own
estimate again with the data's real sizes (:mod:`debist.core.preflight`).

References
----------
Masoud & Maas 2025, Sec. 4-5 (the stages); numpy documentation, "Data type objects"
(float64: 8 bytes).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

from debist.core import preflight
from debist.core.forking import fork_workers
from debist.identify.config import refine_config
from debist.physics.config import AnalyzeConfig

__all__ = [
    "Estimate",
    "check_rig_budget",
    "check_workflow_budget",
    "rig_estimates",
    "workflow_estimates",
]

#: Bytes of one float64.
_F8 = 8
#: float64 elements the virtual rig holds per internal step, per plant state and besides the
#: states (the integrator's output and its copies, the tip, laser and monitor arrays), and
#: per DAC sample of the profile (its times and references, the drivers' held and slewed
#: copies and their interpolation): fitted to the peak resident set of
#: :func:`debist.rig.experiment.run_experiment` in a fresh process after a warm-up run, on
#: the paper's identification experiment (13 states, hold 1 ms, sample time 10 ms): 310 MB
#: for 375 s at oversample 10, 233 MB for 187.5 s at oversample 20 (estimates 312 and 238 MB;
#: a second measurement: 313 and 242 MB).
_RIG_PER_STATE, _RIG_BESIDE, _RIG_PER_REFERENCE = 4, 2, 50
#: Samples of the design analysis's switching simulation per second (its output step 1 ms,
#: :func:`debist.physics.reduced.compare_full_reduced`), and float64 elements per simulated
#: sample, per position of the force-displacement curves and per screw position of the
#: pre-strain sweep (each a continuation of the static path for every voltage state): fitted
#: to the peak resident set of :func:`debist.physics.analysis.run_analysis` above a run with
#: the defaults, for t_end = 50 and 200 s (60 and 304 MB), n_q = 100000 (189 MB) and
#: n_b = 1001 (763 MB).
_ANALYZE_RATE, _ANALYZE_PER_SAMPLE, _ANALYZE_PER_Q, _ANALYZE_PER_B = 1000, 200, 240, 110_000


@dataclass(frozen=True)
class Estimate:
    """The peak memory of one stage's arrays, and the setting that sizes them.

    Parameters
    ----------
    setting : str
        The workflow key(s) and value(s), e.g. ``"[validate] substeps = 2"``.
    need : str
        What needs the memory, e.g. ``"the free run of 2 records of 3750 samples"``.
    nbytes : int
        Estimated peak [bytes].
    detail : str
        What the estimate includes (empty: nothing to add).
    """

    setting: str
    need: str
    nbytes: int
    detail: str = ""


def _rig_estimate(rig: Any, name: str, exp: Any) -> Estimate:
    """Estimate one experiment of the virtual rig (profile and integration)."""
    plant = rig.rig
    n_states = (10 if plant.model == "full" else 4) + plant.n_friction
    n_log = math.floor(exp.duration / rig.sample_time + 1e-9)
    steps = (n_log + 2 * 50) * plant.oversample  # the log's padding, 50 samples either end
    refs = math.ceil(exp.duration / exp.hold)
    elements = steps * (_RIG_PER_STATE * n_states + _RIG_BESIDE) + refs * _RIG_PER_REFERENCE
    return Estimate(
        f"[rig.experiments.{name}] duration = {exp.duration:g} s (with [rig] sample_time = "
        f"{rig.sample_time:g} s, [rig.plant] oversample = {plant.oversample}, hold = "
        f"{exp.hold:g} s)",
        f"the rig's integration of {steps} internal steps x {n_states} states",
        _F8 * elements,
        "states, drivers, sensors and the profile",
    )


def rig_estimates(rig: Any) -> list[Estimate]:
    """Estimate each experiment of the virtual rig, one per forked worker.

    Parameters
    ----------
    rig : RigConfig
        The checked ``[rig]`` section.

    Returns
    -------
    list of Estimate
        One per experiment: ``duration / sample_time x oversample`` internal steps, each
        holding the plant's states and the drivers', sensors' and recorder's arrays, and
        ``duration / hold`` DAC samples of the profile.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (the rig's experiments); :func:`debist.rig.run.simulate_rig`.
    """
    return [_rig_estimate(rig, name, exp) for name, exp in rig.experiments.items()]


def check_rig_budget(rig: Any) -> None:
    """Refuse a rig experiment whose simulation would exceed the memory budget.

    Called before any profile is built, so that a duration of 2e5 s is refused in
    microseconds, naming it.

    Parameters
    ----------
    rig : RigConfig
        The checked ``[rig]`` section.

    Raises
    ------
    ResourceError
        If an estimate of :func:`rig_estimates` exceeds
        :func:`debist.core.preflight.memory_budget`, naming the experiment's keys, or the
        largest of them that run at once in forked workers (one per core,
        :func:`debist.core.forking.fork_workers`) do together.

    References
    ----------
    :func:`debist.rig.run.simulate_rig`.
    """
    estimates = rig_estimates(rig)
    for est in estimates:
        preflight.check_memory(est.nbytes, est.setting, est.need, est.detail)
    at_once = fork_workers(len(estimates))  # the experiments that run in parallel
    largest = sorted(estimates, key=lambda est: est.nbytes, reverse=True)[:at_once]
    if at_once > 1:
        names = " and ".join(est.setting.split(" (with", 1)[0] for est in largest)
        preflight.check_memory(
            sum(est.nbytes for est in largest),
            f"{names} (run in parallel, one per core)",
            f"the integration of {at_once} experiments at once",
            "one forked worker each",
        )


def _rows(checked: Any) -> dict[str, int | None]:
    """Return the samples of each data set the settings fix (a rig experiment), else None."""
    rig = checked.rig
    out: dict[str, int | None] = {}
    for name, (entry, spec) in checked.datasets.items():
        if entry.rig is not None and rig is not None:
            exp = rig.experiments[entry.rig]
            step = spec.resample.sample_time if spec.resample is not None else rig.sample_time
            out[name] = math.floor(exp.duration / step + 1e-9)
        else:
            out[name] = None
    return out


def _resampled(checked: Any, rows: dict[str, int | None]) -> Iterator[Estimate]:
    """Estimate the ingest's resampling of each data set the settings fix the length of."""
    for name, (_, spec) in checked.datasets.items():
        n = rows[name]
        if spec.resample is None or n is None:
            continue
        channels = len(spec.channels) + 1
        yield Estimate(
            f"[ingest] resample.sample_time = {spec.resample.sample_time:g} s (as "
            f"[datasets.{name}] reads it)",
            f"resampling {channels - 1} channels onto {n} samples",
            _F8 * preflight.RESAMPLE_COPIES * n * channels,
            "the grid, the resampled channels and their copies",
        )


def _n_inputs(checked: Any) -> int:
    """Return the inputs of the data (the most of any data set; 1 without data sets)."""
    return max((spec.n_inputs for _, spec in checked.datasets.values()), default=1)


def _identify(cfg: Any, n_in: int, estimation: list[int | None], where: str) -> Iterator[Estimate]:
    """Estimate the least squares, its bootstrap and the refinement of ``[identify]``."""
    p, _ = preflight.identify_columns(cfg, n_in)
    known = all(n is not None for n in estimation) and estimation
    rows = sum(estimation) if known else p  # type: ignore[arg-type]
    longest = max(estimation) if known else rows  # type: ignore[type-var]
    setting = preflight.identify_setting(cfg, n_in, rows, longest)
    if where != "[identify]":
        setting = setting.replace("[identify]", where)
    data = f"{rows} samples" if known else f"at least {rows} samples (as many as columns)"
    yield Estimate(
        setting,
        f"the regressor of {data} x {p} columns and the Gaussian basis of {cfg.M} centres",
        preflight.identify_bytes(cfg, n_in, rows, longest),
        "peak, with the SVD's copies and the bootstrap",
    )
    if where != "[identify]" or not cfg.refine:
        return
    rcfg = refine_config(cfg.refine)
    if rcfg is None:
        return
    log_tz = bool(rcfg.refine_T_z)  # T_z refined: one more parameter, sub-steps doubled
    W, L, ns = int(rcfg.windows), int(rcfg.length), int(rcfg.substeps) * (1 + log_tz)
    P = p + log_tz
    yield Estimate(
        f"[identify.refine] windows = {W}, length = {L}, substeps = {rcfg.substeps}",
        f"the Jacobian's batched free run of {W} windows x {P + 1} parameter vectors",
        preflight.refine_bytes(W, L, P, n_in, ns, p, int(cfg.M), 3 + cfg.n_slip),
        "at least: a T_z shorter than the sample time needs more sub-steps",
    )


def _validate(cfg: Any, n_in: int, n_states: int, lengths: list[int]) -> Iterator[Estimate]:
    """Estimate the free runs and the k-step predictions of ``[validate]``."""
    ns = int(cfg.substeps)
    yield Estimate(
        f"[validate] substeps = {ns}",
        f"the free run of {len(lengths)} record(s) of up to {max(lengths)} samples",
        preflight.free_run_bytes(lengths, n_in, n_states, ns),
        "fine input grid and trajectories",
    )
    k = int(cfg.predict_steps)
    windows = sum(max(n - k, 0) for n in lengths)
    span = 2 * k * ns + 1
    yield Estimate(
        f"[validate] predict_steps = {k} (with substeps = {ns})",
        f"the k-step predictions of {windows} restarted windows",
        _F8 * windows * span * (n_in + n_states + 1),
        "their inputs on the RK4 grid and states",
    )


def _compare(cfg: Any, n_in: int, estimation: list[int | None], narx: Any) -> Iterator[Estimate]:
    """Estimate the SINDy and NARX peers of ``[compare]``."""
    f = preflight.sindy_terms(cfg.degree, n_in, cfg.input_terms)
    known = all(n is not None for n in estimation) and estimation
    rows = max(sum(estimation), f) if known else f  # type: ignore[arg-type]
    data = f"{rows} samples" if known and rows > f else "at least as many samples as terms"
    yield Estimate(
        f"[compare] degree = {cfg.degree}",
        f"the SINDy library of {data} x {f:.3g} terms",
        preflight.sindy_bytes(rows, f),
        "pysindy's library blocks and copies",
    )
    if narx is None or not narx.enabled:
        return
    lag, degree = max(narx.lags), max(narx.degree)
    samples = min(int(narx.max_samples), sum(estimation)) if known else 0  # type: ignore[arg-type]
    yield Estimate(
        f"[compare.narx] max_samples = {narx.max_samples} (with lags = {lag}, degree = {degree})",
        f"the NARX candidate regressor of {samples} samples",
        preflight.narx_bytes(samples, lag, degree, n_in),
        "the matrix and its orthogonalised copies",
    )


def _analyze(cfg: Any) -> Estimate:
    """Estimate the design analysis's grids and its switching simulation."""
    samples = math.ceil(cfg.t_end * _ANALYZE_RATE) + 1
    elements = _ANALYZE_PER_B * int(cfg.n_b) + _ANALYZE_PER_Q * int(cfg.n_q)
    return Estimate(
        f"[analyze] n_b = {cfg.n_b}, n_q = {cfg.n_q}, t_end = {cfg.t_end:g} s",
        f"the analysis's grids of {cfg.n_b} pre-strains and {cfg.n_q} positions and "
        f"{samples} simulated samples",
        _F8 * (elements + _ANALYZE_PER_SAMPLE * samples),
        "paths, energies, forces and both models' trajectories",
    )


def workflow_estimates(checked: Any) -> list[Estimate]:
    """Estimate the peak memory of every stage of a checked workflow, from its settings.

    Parameters
    ----------
    checked : CheckedWorkflow
        The typed sections (:func:`debist.workflow.schema.check_workflow`).

    Returns
    -------
    list of Estimate
        One per sized phase: each rig experiment (:func:`rig_estimates`), the ingest's
        resampling, the identification (:func:`debist.core.preflight.identify_bytes`, with
        the largest ``M`` of ``[identify.auto]``, and of the study on ``max_samples``) and
        refinement
        (:func:`debist.core.preflight.refine_bytes`), the validation's free runs and k-step
        predictions (:func:`debist.core.preflight.free_run_bytes`), the SINDy library
        (:func:`debist.core.preflight.sindy_bytes`) and the NARX regressor, the design
        analysis, the Savitzky-Golay coefficients.

    Notes
    -----
    A data set recorded by the virtual rig has ``duration / sample_time`` samples (its
    ``resample.sample_time`` where it is resampled); a
    rig-log file's length is not known before the ingest, and the estimates then take the
    least the stage needs whatever the data: as many samples as least-squares columns (or
    SINDy terms), two samples per free-run record.

    References
    ----------
    Masoud & Maas 2025, Sec. 4.2 (Eq. 40) and 5; Golub & Van Loan, Matrix Computations, 4th
    ed., Sec. 5.3 (a least squares needs rows >= columns).
    """
    out: list[Estimate] = []
    if checked.rig is not None:
        out += rig_estimates(checked.rig)
    rows = _rows(checked)
    out += _resampled(checked, rows)
    n_in = _n_inputs(checked)
    estimation = [rows[name] for name, (e, _) in checked.datasets.items() if e.role == "estimation"]
    icfg = checked.identify
    if checked.datasets and icfg is not None:
        out += _identify(icfg, n_in, estimation, "[identify]")
        candidates = (icfg.auto or {}).get("M")
        if isinstance(candidates, list) and candidates:  # [identify.auto] fits each M
            largest = replace(icfg, M=max(candidates), auto=None, refine=None)
            out += _identify(largest, n_in, estimation, "[identify.auto]")
        n_states = 3 + icfg.n_slip
        lengths = [max(n or 2, 2) for n in rows.values()]
        out += _validate(checked.validate, n_in, n_states, lengths)
    if checked.datasets and checked.compare is not None:
        out += _compare(checked.compare, n_in, estimation, checked.narx)
    if checked.datasets and checked.study is not None:
        study, scfg, _ = checked.study
        grid_cfg = replace(scfg, M=max(study.M), bootstrap=0, refine=None)
        capped = [min(n, study.max_samples) if n is not None else None for n in estimation]
        out += _identify(grid_cfg, n_in, capped, "[study]")
    if checked.analyze is not None or (checked.physics is not None and not checked.datasets):
        out.append(_analyze(checked.analyze or AnalyzeConfig()))  # a design analysis
    window = getattr(checked.differentiate, "window", None)
    if window is not None:
        order = int(checked.differentiate.polyorder)
        out.append(
            Estimate(
                f"[differentiate] window = {window} (with polyorder = {order})",
                f"the Savitzky-Golay fit of {window} samples x {order + 1} coefficients",
                _F8 * 4 * int(window) * (order + 1),
                "the Vandermonde matrix, its pseudo-inverse and copies",
            )
        )
    return out


def check_workflow_budget(checked: Any) -> None:
    """Refuse a workflow any of whose stages would exceed the memory budget.

    Parameters
    ----------
    checked : CheckedWorkflow
        The typed sections.

    Raises
    ------
    ResourceError
        For the first estimate of :func:`workflow_estimates` above
        :func:`debist.core.preflight.memory_budget`, in one line naming its setting, the
        estimate and the budget.
    WorkflowError
        If ``DEBIST_MEMORY_BUDGET_GB`` is set but not a positive number.

    References
    ----------
    :mod:`debist.core.preflight`.
    """
    for est in workflow_estimates(checked):
        preflight.check_memory(est.nbytes, est.setting, est.need, est.detail)
