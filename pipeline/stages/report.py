"""The report stage: one self-contained HTML page of the run, from hashed artifacts only.

The stage reads what the other stages of the workflow wrote (their summaries, tables,
free runs and PNG figures, each checked against its manifest), draws the report's own
figures (Fig. 11a, 12, 13, 15) and renders ``report.html`` (:mod:`debist.report.html`).
Its key hashes every upstream output, so the page is a pure function of hashed content:
it reruns when any of them changes, and ``debist verify`` checks it like any artifact.

References
----------
Masoud & Maas 2025, Front. Robot. AI 12, Table 2, Fig. 11-15.
"""

from __future__ import annotations

import os
import shlex
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lazy_loader as lazy

from debist.core import artifacts
from debist.core.errors import ArtifactError
from debist.core.fileformats import REPORT_DPI
from debist.identify.bands import BOOTSTRAP_LABEL
from debist.report.figures import (
    dynamic_window,
    excitation_figure,
    free_run_figure,
)
from debist.report.html import (
    FIGURE_GROUPS,
    REPORT_FILE,
    SECTIONS,
    ReportConfig,
    render_report,
)
from debist.report.render import FigureJob, render_pngs
from debist.stages import StageInputs, StageOutput
from debist.stages.registry import stage as registry_stage
from debist.validate.freerun import REPLICATE_BAND
from debist.workflow.overrides import override_args

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["ReportInputs", "ReportResult", "execute", "gather_run", "run_report"]

#: Stages whose free runs (``simulated/<data set>.parquet``) the report draws, and the
#: model each holds.
SIMULATED = (("validate", "rbf"), ("compare", "sindy"))
#: PNG outputs of upstream stages shown as they are: (stage, output, group, caption);
#: output None: every PNG of the stage.
IMAGES = (
    (
        "identify",
        "plots/curves.png",
        "identify",
        "Fig. 14: identified curves with their {band} (grey where not identified), "
        "dashed: the analytical model's",
    ),
    (
        "study",
        "rbf_grid.png",
        "study",
        "Fig. 11b: NRMSE of the free run over the RBF grid (number of centres M, width sigma_n)",
    ),
    ("study", "alpha.png", "study", "Fig. 11c: NRMSE of the free run over TVRegDiff's alpha"),
    (
        "identify",
        "plots/autotune.png",
        "study",
        "Settings chosen on held-out data (the workflow's [identify.auto] or debist's): "
        "held-out free-run NRMSE of each candidate by blocked cross-validation "
        "(Fig. 11b, 11c generalised), with the one-standard-error bound and the choice",
    ),
    ("analyze", None, "analyze", "Design analysis"),
)


@dataclass(frozen=True)
class ReportInputs:
    """What the report is made of: the upstream stages' results, read and checked.

    Attributes
    ----------
    workflow : str
        The workflow's name.
    datasets : list of dict
        ``name``, ``role`` and ``source`` (relative to the workflow file, or the rig
        experiment) per data set, in workflow order.
    summaries : dict of str to dict
        Upstream stage to its summary.
    tables : dict of str to pandas.DataFrame
        The ingested records (``t`` [s], ``q`` [SI], ``v1..vN`` [V]; ``attrs``: role, units).
    derivs : dict of str to pandas.DataFrame
        Their derivatives (``q_dot``, ``q_ddot``).
    runs : dict of str to dict of str to pandas.DataFrame
        Data set -> model -> free run (``t``, ``q``, ``q_sim``).
    images : dict of str to list of (str, bytes)
        Figure group -> caption and PNG bytes of upstream figures.
    provenance : dict
        ``digest`` (of the stages shown), ``verify`` (the command), ``stages`` (stage ->
        (key, manifest sha256)), ``versions`` (library -> version).
    """

    workflow: str
    datasets: list[dict[str, Any]] = field(default_factory=list)
    summaries: dict[str, dict[str, Any]] = field(default_factory=dict)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    derivs: dict[str, pd.DataFrame] = field(default_factory=dict)
    runs: dict[str, dict[str, pd.DataFrame]] = field(default_factory=dict)
    images: dict[str, list[tuple[str, bytes]]] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReportResult:
    """Output of :func:`run_report`.

    Attributes
    ----------
    html : str
        The page.
    figures : dict of str to int
        Figures per group of :data:`debist.report.html.FIGURE_GROUPS`.
    """

    html: str
    figures: dict[str, int]


#: Columns of a model's free run that the report draws: q and its replicate band.
_RUN_COLUMNS = ("q_sim", *REPLICATE_BAND)


def _nrmse_rows(summaries: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Return the NRMSE table: compare's (which includes validate's rows), else validate's."""
    for stage in ("compare", "validate"):
        if stage in summaries:
            return list(summaries[stage].get("table", []))
    return []


def _unit(table: pd.DataFrame) -> str:
    return table.attrs.get("units", {}).get("q", "m")


def run_report(inputs: ReportInputs, section: Mapping[str, Any]) -> ReportResult:
    """Draw the report's figures and render the page (no file IO).

    Parameters
    ----------
    inputs : ReportInputs
        The upstream results.
    section : mapping
        The ``[report]`` section (see :class:`debist.report.html.ReportConfig`).

    Returns
    -------
    ReportResult

    Raises
    ------
    WorkflowError
        For an invalid section.
    ArtifactError
        If an upstream figure is not a PNG file.

    References
    ----------
    Masoud & Maas 2025, Fig. 11a (excitation of the estimation records), Fig. 12 and 15
    (free runs on estimation and unseen data), Fig. 13 (zoom on the most dynamic window).
    """
    cfg = ReportConfig.from_dict(section)
    nrmse = _nrmse_rows(inputs.summaries)
    figures: dict[str, list[tuple[str, bytes]]] = {g: list(v) for g, v in inputs.images.items()}
    roles = {d["name"]: d["role"] for d in inputs.datasets}
    order = [d["name"] for d in inputs.datasets if d["name"] in inputs.tables]
    order += sorted(set(inputs.tables) - set(order))
    jobs: dict[str, list[tuple[str, FigureJob]]] = {"excitation": [], "free_run": []}
    validate = inputs.summaries.get("validate") or {}
    report_unit, init_samples = validate.get("report_unit"), int(validate.get("init_samples", 0))
    for name in order:
        if roles.get(name) == "estimation" and name in inputs.derivs:
            table = inputs.tables[name]
            args = (
                table,
                inputs.derivs[name][["q_dot", "q_ddot"]],
                name,
                _unit(table),
                report_unit,
            )
            caption = f"Fig. 11a: estimation record '{name}': q, q_dot, q_ddot and the inputs v_i"
            jobs["excitation"].append((caption, FigureJob(excitation_figure, args, dpi=REPORT_DPI)))
    for name in order:
        runs = inputs.runs.get(name) or {}
        if not runs or name not in inputs.derivs:
            continue
        measured = next(iter(runs.values()))[["t", "q"]]
        deriv = inputs.derivs[name]
        window = dynamic_window(deriv["t"].to_numpy(), deriv["q_ddot"].to_numpy(), cfg.zoom_window)
        rows = {r["model"]: r for r in nrmse if r.get("dataset") == name}
        scores = {model: r.get("nrmse_q") for model, r in rows.items()}
        unit = _unit(inputs.tables[name]) if name in inputs.tables else "m"
        runs = {m: run[[c for c in _RUN_COLUMNS if c in run]] for m, run in runs.items()}
        args = (measured, runs, window, name, unit, scores, rows, report_unit, init_samples)
        job = FigureJob(free_run_figure, args, dpi=REPORT_DPI)
        what = (
            "Fig. 12, estimation data"
            if roles.get(name) == "estimation"
            else ("Fig. 15, cross-validation on unseen data")
        )
        caption = (
            f"{what} '{name}': measured q and the free run of "
            f"{', '.join(runs)}; middle: Fig. 13, the {cfg.zoom_window:g} s window with the "
            "largest q_ddot RMS; bottom: the errors"
            + (f"; shaded: the first {init_samples} samples, not scored" if init_samples else "")
        )
        jobs["free_run"].append((caption, job))
    # the figures are drawn in parallel processes: the same PNG bytes as one after the other
    pngs = iter(render_pngs([job for group in jobs.values() for _, job in group]))
    for group, items in jobs.items():
        figures[group] = [(caption, next(pngs)) for caption, _ in items]
    datasets = []
    for d in inputs.datasets:
        t = inputs.tables[d["name"]]["t"] if d["name"] in inputs.tables else None
        samples = int(t.size) if t is not None else "-"
        duration = f"{float(t.iloc[-1] - t.iloc[0]):.4g}" if t is not None and t.size else "-"
        datasets.append({**d, "samples": samples, "duration": duration})
    run = {
        "workflow": inputs.workflow,
        "datasets": datasets,
        "identify": inputs.summaries.get("identify"),
        "report_unit": report_unit,
        "nrmse": nrmse,
        "equations": inputs.summaries.get("compare", {}).get("equations"),
        "figures": figures,
        **inputs.provenance,
    }
    html = render_report(run)
    return ReportResult(html, {g: len(figures.get(g, [])) for g in FIGURE_GROUPS})


def _read_png(stage_dir: Path, rel: str, manifest: artifacts.Manifest) -> bytes:
    """Read a PNG output after checking it against its manifest's sha256."""
    path = stage_dir / rel
    data = path.read_bytes() if path.is_file() else b""
    if artifacts.sha256_bytes(data) != manifest.outputs[rel]:
        raise ArtifactError(
            f"'{path}' is missing or changed since the stage wrote it (run `debist verify`)"
        )
    return data


def gather_run(ctx: StageInputs, upstream: list[str]) -> ReportInputs:
    """Read the upstream stages' results through their manifests.

    Parameters
    ----------
    ctx : StageInputs
        The runner.
    upstream : list of str
        The stages the report shows (those of the workflow among the report's upstream).

    Returns
    -------
    ReportInputs

    Raises
    ------
    ArtifactError
        If a stage has no manifest, or a summary or figure does not match its manifest.
    """
    wf = ctx.wf
    manifests = {}
    for stage in upstream:
        manifest = artifacts.read_manifest(wf.stage_dir(stage))
        if manifest is None:
            raise ArtifactError(f"stage '{stage}' has no artifacts in '{wf.stage_dir(stage)}'")
        manifests[stage] = manifest
    summaries = {s: artifacts.read_summary(wf.stage_dir(s), m) for s, m in manifests.items()}
    tables = ctx.tables("ingest") if "ingest" in manifests else {}
    derivs = ctx.tables("differentiate") if "differentiate" in manifests else {}
    runs: dict[str, dict[str, pd.DataFrame]] = {}
    for stage, model in SIMULATED:
        if stage not in manifests:
            continue
        for rel in sorted(manifests[stage].outputs):
            if rel.startswith("simulated/") and rel.endswith(".parquet"):
                name = rel[len("simulated/") : -len(".parquet")]
                runs.setdefault(name, {}).update(_split_runs(ctx.read_parquet(stage, rel), model))
    images: dict[str, list[tuple[str, bytes]]] = {}
    for stage, rel, group, caption in IMAGES:
        if stage not in manifests:
            continue
        outputs = manifests[stage].outputs
        rels = [rel] if rel is not None else sorted(r for r in outputs if r.endswith(".png"))
        for r in rels:
            if r in outputs:
                text = caption if rel is not None else f"{caption}: {r}"
                # the identify stage says what its bands are (older runs: bootstrap bands)
                band = summaries["identify"].get("bands", {}) if stage == "identify" else {}
                text = text.replace("{band}", band.get("label", BOOTSTRAP_LABEL))
                data = _read_png(wf.stage_dir(stage), r, manifests[stage])
                images.setdefault(group, []).append((text, data))
    versions: dict[str, set[str]] = {}
    own = artifacts.library_versions(registry_stage("report").libraries)
    for found in [*(m.versions for m in manifests.values()), own]:
        for lib, version in found.items():
            versions.setdefault(lib, set()).add(str(version))
    datasets = [
        {"name": d.name, "role": d.role, "source": d.rig or _relative(d.source, wf.path.parent)}
        for d in wf.datasets
    ]
    provenance = {
        "digest": artifacts.run_digest(wf.output_dir, upstream),
        "verify": shlex.join(
            ["debist", "verify", wf.path.name]
            + [word for arg in override_args(wf.overrides) for word in ("--set", arg)]
        ),
        "stages": {
            s: (m.key, artifacts.manifest_digest(wf.stage_dir(s))) for s, m in manifests.items()
        },
        "versions": {lib: " / ".join(sorted(v)) for lib, v in versions.items()},
    }
    return ReportInputs(
        workflow=wf.name,
        datasets=datasets,
        summaries=summaries,
        tables=tables,
        derivs=derivs,
        runs=runs,
        images=images,
        provenance=provenance,
    )


def _relative(source, folder) -> str:
    return Path(os.path.relpath(source, folder)).as_posix()


def _split_runs(frame: pd.DataFrame, model: str) -> dict[str, pd.DataFrame]:
    """Split one ``simulated/<data set>.parquet`` into the free run of each model it holds.

    Its own model's ``q_sim`` (with the band of its bootstrap replicates,
    :data:`debist.validate.freerun.REPLICATE_BAND`) and, from the other columns ``q_sim_<other>``,
    the other models the validate stage ran beside it (analytical, equation-error).
    """
    runs = {model: frame}
    for col in frame.columns:
        if col.startswith("q_sim_") and col not in REPLICATE_BAND:
            other = col[len("q_sim_") :]
            runs[other] = frame[["t", "q"]].assign(q_sim=frame[col].to_numpy())
    return runs


def execute(ctx: StageInputs) -> StageOutput:
    """Run the report stage: ``report.html`` from the artifacts of the workflow's stages.

    Parameters
    ----------
    ctx : StageInputs
        The runner (its ``stages()`` names the workflow's stages).

    Returns
    -------
    StageOutput
        ``report.html``; summary: the sections, the figures per group and the digest of
        the stages shown.

    Raises
    ------
    ArtifactError, WorkflowError
        As :func:`gather_run` and :func:`run_report`.
    """
    mine = set(ctx.stages())
    upstream = [s for s in registry_stage("report").upstream if s in mine]
    inputs = gather_run(ctx, upstream)
    res = run_report(inputs, ctx.section("report"))
    summary = {
        "sections": list(SECTIONS),
        "figures": res.figures,
        "shown": upstream,
        "digest_shown": inputs.provenance["digest"],
    }
    return StageOutput({REPORT_FILE: res.html}, summary)
