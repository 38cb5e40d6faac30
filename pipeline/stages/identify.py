"""The identify stage: the RBF model of Eq. 37-40 by least squares with the T_z search."""

from __future__ import annotations

import importlib
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core import preflight
from debist.core.artifacts import H5Tree
from debist.core.fileformats import REPORT_DPI
from debist.identify.bands import (
    band_label,
    curves_frame,
    model_error_table,
    static_frame,
    stiffness_bands,
    stiffness_label,
)
from debist.identify.config import IdentifyConfig
from debist.identify.design import (
    design_numbers,
    held_levels,
    mark_identified,
    mark_switching,
)
from debist.identify.excitation import check_excitation, thin_data
from debist.identify.fit import FitDiagnostics, fit_rbf_model, supported_range, supported_size
from debist.identify.mass import effective_mass
from debist.identify.physics_prior import physics_mass, physics_prior
from debist.identify.records import estimation_records
from debist.identify.searchspace import Facts, held_out_search, workflow_search
from debist.ingest.checks import check_varies
from debist.model.basis import RBFBasis
from debist.model.rbf import RBFModel
from debist.model.terms import PHYSICS_TERMS
from debist.physics.reduced import reduced_curves
from debist.report.plots import curves_figure
from debist.report.render import FigureJob, render_pngs
from debist.report.study_plots import autotune_figure
from debist.stages import StageInputs, StageOutput
from debist.validate.freerun import words_factor

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "IdentifyResult",
    "analytical_curves",
    "diagnostics_tree",
    "execute",
    "preload",
    "run_identify",
]


def preload(ctx: StageInputs) -> None:
    """Load matplotlib's ``Figure``: the stage draws its figures in processes forked from here.

    The runner calls it ahead of the stage, while a stage before it waits on its worker
    processes (:meth:`debist.engine.runner.Runner.load_ahead`); :func:`render_pngs` would
    load it just before it forks. Loads nothing else, decides nothing.

    Parameters
    ----------
    ctx : StageInputs
        Not read: what the stage loads does not depend on the workflow.
    """
    del ctx
    importlib.import_module("matplotlib.figure")


@dataclass(frozen=True)
class IdentifyResult:
    """Output of the identification stage.

    Attributes
    ----------
    model : RBFModel
        The identified model.
    diagnostics : FitDiagnostics
        Rank, condition number, residuals, T_z trace.
    curves : pandas.DataFrame
        Characteristic curves on a grid with 95 % bands and identified masks
        (:func:`debist.identify.bands.curves_frame`).
    summary : dict
        Scalars for reports (reproducible: no wall times).
    equation_error_model : RBFModel or None
        The least-squares model before simulation-error refinement.
    timings : dict of str to float
        Wall times [s]: ``fit`` (least squares with the T_z search), ``refine`` and
        ``hyper-parameters`` (the held-out search and its screens).
    design : dict of str to pandas.DataFrame
        Equilibria and switching voltages (:func:`debist.identify.design.design_numbers`)
        and the static force at the held input levels with bands and masks (``static``,
        :func:`debist.identify.bands.static_frame`).
    search : debist.identify.autotune.AutoResult or None
        The held-out search (:mod:`debist.identify.searchspace`; None when none ran).
    """

    model: RBFModel
    diagnostics: FitDiagnostics
    curves: pd.DataFrame
    summary: dict[str, Any] = field(default_factory=dict)
    equation_error_model: RBFModel | None = None
    timings: dict[str, float] = field(default_factory=dict)
    design: dict[str, pd.DataFrame] = field(default_factory=dict)
    search: Any = None


def run_identify(tables, derivs, section: Mapping[str, Any], physics=None) -> IdentifyResult:
    """Identify the RBF model (Eq. 37-40) on the estimation data sets.

    The settings the workflow leaves open are chosen first, by the held-out search of
    :mod:`debist.identify.searchspace`: a workflow's ``[identify.auto]`` grid, else the
    entries of its table :data:`~debist.identify.searchspace.SEARCH_SPACE` (the slip
    elements; ``M`` on thin data). Then the least squares on the estimation records, the
    optional simulation-error refinement, the curves with their bands, the design numbers.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical tables (``attrs['role']`` tells estimation data).
    derivs : mapping of str to pandas.DataFrame
        Their derivatives.
    section : mapping
        The ``[identify]`` section (see :class:`IdentifyConfig`).
    physics : PrototypeParams, optional
        The ``[physics]`` prototype, whose curves the ``physics_*`` backbone terms use and
        whose ``m_q`` at ``q = 0`` ``m_q = "physics"`` takes (:func:`physics_mass`).

    Returns
    -------
    IdentifyResult

    Raises
    ------
    IdentificationError
        If the problem is under-excited, rank deficient or badly conditioned, or every
        candidate of an ``[identify.auto]`` grid fails.
    ResourceError
        If the least squares of the estimation data would exceed the memory budget
        (:func:`debist.core.preflight.check_identify`), before any array of samples x
        centres is built.
    WorkflowError
        For an invalid section.
    """
    # here, not at the top: the refinement brings the numba kernel, loaded only when it runs
    from debist.identify.refine import refine_config, refine_model

    section = dict(section)
    if section.get("m_q") == "physics":
        section["m_q"] = physics_mass(physics)
    cfg = IdentifyConfig.from_dict(section)
    records = estimation_records(tables, derivs)
    sizes = [r.q.size for r in records]  # before the support checks build samples x M
    preflight.check_identify(cfg, records[0].v.shape[1], sum(sizes), max(sizes))
    if set(PHYSICS_TERMS) & set(cfg.backbone):
        cfg = replace(
            cfg,
            prior=physics_prior(physics, records, quadratic="physics_quadratic" in cfg.backbone),
        )
    cfg, search = workflow_search(records, cfg)  # [identify.auto]: the grid's choice
    asked = cfg.M
    q_all = np.concatenate([r.q for r in records])
    if np.ptp(q_all) > 0:  # (a motionless q is a data error, named by the excitation check)
        cfg = replace(cfg, M=supported_size(q_all, cfg))
    excitation = _excitation(records, cfg, tables)
    held = None
    if search is None:  # the settings the workflow leaves to debist, chosen on held-out data
        held = held_out_search(records, cfg, Facts(section, cfg, thin_data(excitation)))
        cfg, search = held.cfg, held.search
        if search is not None and "M" in search.chosen:
            excitation = _excitation(records, cfg, tables)
    if asked > cfg.M:  # thin data: fewer, wider centres rather than a failed fit
        note = _basis_note(asked, cfg, excitation)
        excitation = replace(excitation, warnings=[note, *excitation.warnings])
    t_fit = time.perf_counter()
    model, diag = fit_rbf_model(records, cfg)
    mass, physical = None, model.m_q  # physical: the mass the curves are forces of [kg]
    if cfg.effective_mass:  # the curves on the physical mass's scale; the free run unchanged
        model, diag, mass = effective_mass(model, diag)
        cfg = replace(cfg, m_q=model.m_q)  # the rigid mass, for the refinement
    timings = {"fit": time.perf_counter() - t_fit}
    inert = held.note if held is not None else ""
    if search is not None or inert:
        timings["hyper-parameters"] = held.seconds if held is not None else search.seconds
    ls_model, refine = model, None
    rcfg = refine_config(cfg.refine)
    if rcfg is not None:
        res = refine_model(model, diag, records, cfg, rcfg)
        model, refine, timings["refine"] = res.model, _refine_summary(res), res.seconds
    model_error = model_error_table(cfg.backbone, cfg.effective_mass) if cfg.model_error else None
    curves, identified = curves_frame(
        model, diag, records, min_support=cfg.min_support, band_tolerance=cfg.band_tolerance,
        model_error=model_error,
    )  # fmt: skip
    design, static = _design(model, diag, records, physics, physical, cfg, curves, model_error)
    summary = {
        **_fit_summary(model, diag, records, cfg, physical, refine, identified, model_error),
        "basis": {"M_asked": asked, "M": cfg.M},
        **({"dissipation": diag.dissipation} if diag.dissipation else {}),
        **({"undriven": diag.undriven} if diag.undriven else {}),
        "excitation": excitation.to_summary(),
        **({"creep_rate": model.creep_rate} if model.has_creep else {}),
        **({"slip": _slip_summary(model)} if model.has_slip else {}),
        **({"inertia": _inertia_summary(model)} if model.has_inertia else {}),
        **({"effective_mass": mass.to_summary()} if mass is not None else {}),
        "design": {
            "verdict": design["equilibria"].attrs["verdict"],
            "reason": design["equilibria"].attrs["reason"],
            "equilibria": _records_of(design["equilibria"]),
            "switching": _records_of(design["switching"]),
            "static": static,
        },
        "constraints": list(cfg.constraints),
        "units": _units(tables, cfg.input_map, physical),
    }
    if search is not None:
        summary["auto"] = search.to_summary()
    if inert:
        summary["auto_skipped"] = inert
    return IdentifyResult(model, diag, curves, summary, ls_model, timings, design, search)


def _refine_summary(res) -> dict[str, Any]:
    """Return the simulation-error refinement's numbers for the summary (no wall time)."""
    return {
        "accepted": res.accepted,
        "window_rms_equation_error": res.window_rms_ls,
        "window_rms_simulation_error": res.window_rms_refined,
        "full_rms_equation_error": res.full_rms_ls,
        "full_rms_simulation_error": res.full_rms_refined,
        "holdout_rms_equation_error": res.holdout_rms_ls,
        "holdout_rms_simulation_error": res.holdout_rms_refined,
        "holdout_windows": res.holdout_windows,
        "nfev": res.nfev,
        "message": res.message,
        "prior": res.prior,
        **({"candidates": list(res.candidates)} if res.candidates else {}),
    }


def _design(model, diag, records, physics, physical, cfg, curves, model_error):
    """Return the design numbers with the static force at the held levels, and its summary."""
    design = design_numbers(model, records, physics, physical)
    design["static"], static = static_frame(
        model, diag, records, held_levels(records), min_support=cfg.min_support,
        band_tolerance=cfg.band_tolerance, model_error=model_error,
    )  # fmt: skip
    design["equilibria"] = stiffness_bands(
        mark_identified(design["equilibria"], curves, design["static"]), model, diag,
        cfg.model_error, cfg.effective_mass,
    )  # fmt: skip
    design["switching"] = mark_switching(design["switching"], curves)
    return design, static


def _fit_summary(model, diag, records, cfg, physical, refine, identified, model_error):
    """Return the fit's scalars for the summary, in the summary's order up to ``basis``."""
    q_data = np.concatenate([r.q for r in records])
    return {
        "T_z": model.T_z,
        "m_q": model.m_q,
        "m_q_curves": physical,  # the curves' mass: m_q, or m_q lambda with the scale
        "q_range": list(model.q_range),  # Eq. 39's range; narrower than the data's where
        "q_data_range": [float(q_data.min()), float(q_data.max())],  # the ends lack support
        "condition": diag.condition,
        "rank": diag.rank,
        "n_columns": len(diag.columns),
        "n_params": model.n_params,
        "n_samples": diag.n_samples,
        "fit_r2": diag.fit_r2,
        "residual_rms": diag.residual_rms,
        "backbone": {k: (np.asarray(v).tolist()) for k, v in model.backbone.items()},
        "published": dict(cfg.published or {}),
        "refine": refine,
        "identified": identified,
        "bootstrap": {"replicates": cfg.bootstrap, "block": diag.block},
        "bands": {
            "label": band_label(
                cfg.model_error,
                "physics_creep" in cfg.backbone,
                cfg.effective_mass,
                (*cfg.backbone, *cfg.rbf),
            ),
            "stiffness_label": stiffness_label(cfg.model_error, cfg.effective_mass),
            "model_error": model_error or {},
            "tolerance": cfg.band_tolerance,
        },
        "smoothing": diag.smoothing,
    }


def _slip_summary(model) -> dict[str, Any]:
    """Return the slip elements as lists (:meth:`debist.model.rbf.RBFModel.slip_elements`)."""
    return {k: np.asarray(v).tolist() for k, v in model.slip_elements().items()}


def _inertia_summary(model) -> dict[str, Any]:
    """Return the coefficients of m(q) and the mass at the range's edges and at q = 0."""
    q = np.array([model.q_range[0], 0.0, model.q_range[1]])
    return {"mu": np.asarray(model.theta_inertia, dtype=float).tolist(), "q": q.tolist(),
            "m": model.mass(q).tolist()}  # fmt: skip


def _basis_note(asked: int, cfg: IdentifyConfig, excitation) -> str:
    """Say that the data support fewer centres than asked, and over which range."""
    unit, sigma = excitation.unit_name, excitation.sigma * excitation.unit_scale
    return (
        f"M = {asked} centres are not all supported by the estimation data (min_support = "
        f"{cfg.min_support} samples within one width): {cfg.M} centres of width {sigma:.3g} "
        f"{unit} are fitted instead, so the curves are coarser; excite more of the range for more"
    )


def _excitation(records, cfg: IdentifyConfig, tables):
    """Run the excitation check on the estimation records (warnings in the data's unit)."""
    q = np.concatenate([r.q for r in records])
    if np.ptp(q) == 0:  # nothing moved: a data error of the logs, named as such
        frame = next(t for t in tables.values() if t.attrs.get("role") == "estimation")
        check_varies(
            q, role="q", unit=frame.attrs.get("units", {}).get("q", "m"),
            channel=frame.attrs.get("channels", {}).get("q", "q"),
            path=Path(str(frame.attrs.get("source", "?"))),
            where="estimation data sets (" + ", ".join(r.name for r in records) + ")",
        )  # fmt: skip
    lo, hi = cfg.q_range or supported_range(q, cfg)
    basis = RBFBasis.equidistant(lo, hi, cfg.M, cfg.sigma_n, cfg.outside)
    unit = next(iter(tables.values())).attrs.get("units", {}).get("q", "m")
    factor, name = words_factor(unit)
    return check_excitation(
        records, basis, cfg.input_map, rbf=cfg.rbf, min_samples=cfg.min_support,
        unit_scale=factor, unit_name=name,
    )  # fmt: skip


def _units(tables, input_map: str, m_q_curves: float) -> dict[str, Any]:
    """Units of q and the inputs (SI), the input map and whether the curves are per unit mass."""
    attrs = next(iter(tables.values())).attrs.get("units", {})
    units = {k: v for k, v in attrs.items() if k == "q" or (k[:1] == "v" and k[1:].isdigit())}
    return {
        **{"q": "m", **units},
        "input_map": input_map,
        "per_unit_mass": m_q_curves == 1.0,
    }


def _records_of(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """Rows of a table as JSON-able dicts (NaN as None)."""
    rows = frame.astype(object).where(frame.notna(), None).to_dict(orient="records")
    return [{k: (v.item() if hasattr(v, "item") else v) for k, v in r.items()} for r in rows]


def diagnostics_tree(diag: FitDiagnostics) -> dict[str, Any]:
    """HDF5 layout of the fit diagnostics."""
    return {
        "attrs": {
            "rank": diag.rank,
            "condition": diag.condition,
            "n_samples": diag.n_samples,
            "residual_rms": diag.residual_rms,
            "fit_r2": diag.fit_r2,
        },
        "columns": np.array(diag.columns),
        "singular_values": diag.singular_values,
        "support": diag.support,
        "T_z_trace": diag.T_z_trace,
        **({} if diag.theta_boot is None else {"theta": diag.theta, "theta_boot": diag.theta_boot}),
        **({"gcv_trace": diag.gcv_trace} if diag.gcv_trace.size else {}),
        **({"creep_trace": diag.creep_trace} if diag.creep_trace.size else {}),
    }


def execute(ctx: StageInputs) -> StageOutput:
    """Run the identify stage on the ingested tables and their derivatives.

    Parameters
    ----------
    ctx : StageInputs
        The workflow and the ingest and differentiate artifacts.

    Returns
    -------
    StageOutput
        ``model.h5`` (the model, its fit diagnostics and, after refinement, the
        equation-error model), ``curves.parquet`` and ``plots/curves.png`` (Fig. 14, with
        the analytical curves when the workflow has ``[physics]``; q and the curves in
        ``[validate] report_unit``, as the report's tables), ``equilibria.parquet``,
        ``switching.parquet`` and ``static.parquet`` (the static force at the held levels);
        with ``[identify.auto]`` ``autotune.parquet`` and ``plots/autotune.png`` (the
        search's table and figure).

    Raises
    ------
    IdentificationError, WorkflowError
        As :func:`run_identify`.
    """
    res = run_identify(
        ctx.tables("ingest"), ctx.tables("differentiate"), ctx.section("identify"), ctx.physics()
    )
    tree = {**res.model.to_tree(), "diagnostics": diagnostics_tree(res.diagnostics)}
    if res.equation_error_model is not None and res.equation_error_model is not res.model:
        tree["equation_error"] = res.equation_error_model.to_tree()["model"]
    physics = ctx.physics()
    analytical = (
        analytical_curves(physics, res.model, res.summary["m_q_curves"])
        if physics is not None
        else None
    )
    report_unit = ctx.section("validate").get("report_unit")  # q's unit in the report
    args = (res.curves, analytical, res.summary, report_unit)
    figures = {"plots/curves.png": FigureJob(curves_figure, args, dpi=REPORT_DPI)}
    outputs = {"model.h5": H5Tree(tree), "curves.parquet": res.curves}
    outputs.update({f"{name}.parquet": frame for name, frame in res.design.items()})
    if res.search is not None:
        outputs["autotune.parquet"] = res.search.table
        figures["plots/autotune.png"] = FigureJob(autotune_figure, (res.search,), dpi=REPORT_DPI)
    outputs.update(zip(figures, render_pngs(list(figures.values())), strict=True))
    return StageOutput(outputs, res.summary, res.timings)


def analytical_curves(physics, model: RBFModel, mass: float | None = None) -> pd.DataFrame:
    """Tabulate the analytical model's curves in the identified model's units, for Fig. 14.

    Parameters
    ----------
    physics : PrototypeParams
        The ``[physics]`` prototype.
    model : RBFModel
        The identified model (its ``q_range`` and ``m_q``).
    mass : float, optional
        The mass the identified curves are forces of [kg] (the summary's ``m_q_curves``:
        ``m_q lambda`` under the effective-mass scale); default ``model.m_q``.

    Returns
    -------
    pandas.DataFrame
        ``q`` [m], ``restoring`` (``f(q)`` at ``v = 0``), ``d``, ``g1``, ``g2``, times
        ``mass / m_q,phys(0)``: the identified curves are per that mass (``m_q = 1``
        identifies them per unit mass), the analytical ones per the prototype's.

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 33, Fig. 14.
    """
    grid = np.linspace(model.q_range[0], model.q_range[1], 201)
    cur = reduced_curves(physics, grid)
    scale = (model.m_q if mass is None else mass) / float(np.interp(0.0, grid, cur.m_q))
    frame = {"q": grid, "restoring": cur.f, "d": cur.d, "g1": cur.g1, "g2": cur.g2}
    return pd.DataFrame({k: (v if k == "q" else scale * v) for k, v in frame.items()})
