"""The ``debist`` command line: a thin Typer adapter over :mod:`pipeline`.

Parses arguments, loads the workflow, calls the runner, prints with rich, and
maps debist's exception classes to exit codes (1: a stage failed on its data;
2: bad workflow or arguments; 3: artifacts failed verification).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape

from pipeline.errors import ArtifactError, DebistError, WorkflowError

app = typer.Typer(
    help="Rig logs of bistable DE actuators to validated dynamic models (Masoud & Maas 2025).",
    no_args_is_help=True,
    add_completion=False,
)
#: Reports written to a file or pipe are not squeezed to 80 columns (rich's default there).
console = Console(width=None if sys.stdout.isatty() else 140)
err = Console(stderr=True, soft_wrap=True)

WorkflowArg = Annotated[Path, typer.Argument(help="Workflow TOML file.")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Rerun even if up to date.")]
OutOpt = Annotated[Path | None, typer.Option("--out", help="Override [workflow] output_dir.")]


def _runner(workflow: Path, out: Path | None):
    from pipeline.runner import Runner
    from pipeline.workflow import load_workflow

    return Runner(load_workflow(workflow, out))


def _event(stage: str, what: str, detail: str) -> None:
    if what == "skip":
        console.print(f"[dim]Stage '{stage}' is up to date, skipping[/dim]")
    elif what == "start":
        console.print(f"Running stage '{stage}' ...")
    else:
        console.print(f"[green]Stage '{stage}' done[/green] ({detail})")


def _report(runner, manifests) -> None:
    from pipeline import report

    diff = manifests.get("differentiate")
    stopped = [n for n, ok in (diff.summary.get("converged", {}) if diff else {}).items() if not ok]
    if stopped:
        console.print(
            "[dim]differentiate: the iterative method stopped at its iteration limit on "
            f"{len(stopped)} data set(s), as configured (converged = false in the manifest)[/dim]"
        )
    if "rig" in manifests:
        console.print(report.rig_table(manifests["rig"].summary))
    if "analyze" in manifests:
        console.print(report.analyze_table(manifests["analyze"].summary))
    if "identify" in manifests:
        console.print(report.identify_table(manifests["identify"].summary))
    last = "compare" if "compare" in manifests else "validate"
    if "compare" in manifests:
        s = manifests["compare"].summary
        console.print(f"SINDy ({s['n_params']} terms): {s['equations']}", soft_wrap=True)
    if last in manifests:
        summary = manifests[last].summary
        console.print(report.nrmse_table(summary["table"]))
        table = report.published_table(
            summary["table"], summary.get("published", []), summary.get("order")
        )
        if table is not None:
            console.print(table)
    console.print(f"[dim]artifacts: {runner.wf.output_dir}[/dim]")


def _run(workflow: Path, stages: list[str] | None, force: bool, out: Path | None) -> None:
    try:
        runner = _runner(workflow, out)
        manifests = runner.run(stages, force=force, on_event=_event)
        _report(runner, manifests)
    except WorkflowError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2) from None
    except DebistError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(1) from None


@app.command()
def run(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Run every stage of WORKFLOW, skipping those that are up to date."""
    _run(workflow, None, force, out)


@app.command()
def ingest(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Read the rig logs into canonical tables (t [s], q, v1..vN [V])."""
    _run(workflow, ["ingest"], force, out)


@app.command()
def differentiate(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Compute q_dot and q_ddot (TVRegDiff or the configured differentiator)."""
    _run(workflow, ["differentiate"], force, out)


@app.command()
def identify(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Identify the RBF model of Eq. 37-40 by least squares with the T_z search."""
    _run(workflow, ["identify"], force, out)


@app.command()
def validate(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Free-run the identified model on every data set; NRMSE table and plots."""
    _run(workflow, ["validate"], force, out)


@app.command()
def compare(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Fit SINDy on the same data and derivatives; free-run it with the same simulator."""
    _run(workflow, ["compare"], force, out)


@app.command()
def study(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Sensitivity studies: RBF grid (M, sigma_n; Fig. 11b) and TVRegDiff alpha (Fig. 11c)."""
    _run(workflow, ["study"], force, out)


@app.command("simulate-rig")
def simulate_rig(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Run the virtual rig of [rig]: dSPACE MAT logs and truth files per experiment."""
    _run(workflow, ["rig"], force, out)


@app.command()
def fleet(
    template: Annotated[Path, typer.Argument(help="Workflow with a [rig] section.")],
    size: Annotated[int, typer.Option("--size", min=1, help="Number of prototypes.")] = 10,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the scatter.")] = 0,
    folder: Annotated[Path, typer.Option("--dir", help="Folder for the workflows.")] = Path(
        "fleet"
    ),
) -> None:
    """Write one workflow per prototype of a seeded fleet around TEMPLATE's rig (for batch)."""
    import tomllib

    from pipeline import artifacts
    from pipeline.rig.fleet_workflows import fleet_workflows

    try:
        raw = tomllib.loads(template.read_text(encoding="utf-8"))
        files = fleet_workflows(raw, template.resolve().parent, folder, size, seed=seed)
        paths = artifacts.write_text_files(folder, files)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2) from None
    except DebistError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2 if isinstance(exc, WorkflowError | ArtifactError) else 1) from None
    console.print(f"wrote {len(paths)} workflows to {folder}; run them with: debist batch {folder}")


@app.command()
def analyze(workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None) -> None:
    """Design analysis of [physics] (Section 3): statics.h5 and Fig. 3, 4, 5, 6a, 7 as PNG."""
    _run(workflow, ["analyze"], force, out)


@app.command()
def status(
    workflow: WorkflowArg,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
    out: OutOpt = None,
) -> None:
    """Say per stage whether it is up to date, stale (and why) or missing."""
    try:
        states = _runner(workflow, out).status()
    except DebistError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2) from None
    if as_json:
        typer.echo(json.dumps([s.__dict__ for s in states], indent=2))
        return
    for s in states:
        color = {"up to date": "green", "stale": "yellow", "missing": "red"}[s.state]
        console.print(
            f"{s.stage:14s} [{color}]{s.state}[/{color}]" + (f"  ({s.reason})" if s.reason else "")
        )


@app.command()
def verify(workflow: WorkflowArg, out: OutOpt = None) -> None:
    """Re-hash every artifact; exit 3 naming any file that changed."""
    try:
        problems = _runner(workflow, out).verify()
    except (WorkflowError, ArtifactError) as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2) from None
    if problems:
        for p in problems:
            err.print(f"[red]changed:[/red] {escape(p)}")
        raise typer.Exit(3)
    console.print("[green]all artifacts match their manifests[/green]")


StagesOpt = Annotated[
    str | None,
    typer.Option(
        "--stages", help="Comma-separated stages, e.g. 'ingest,differentiate' (default: all)."
    ),
]
SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="synchronous | threads | processes | distributed "
        "(default: processes, or distributed with --address).",
    ),
]
WorkersOpt = Annotated[
    int | None,
    typer.Option("--workers", min=1, help="Local worker processes (default: one per core)."),
]
AddressOpt = Annotated[
    str | None,
    typer.Option(
        "--address", help='Dask scheduler, e.g. tcp://host:8786 (pip install "debist\\[cluster]").'
    ),
]


@app.command()
def batch(
    paths: Annotated[
        list[str],
        typer.Argument(help="Workflow files, directories (their *.toml) or glob patterns."),
    ],
    stages: StagesOpt = None,
    force: ForceOpt = False,
    scheduler: SchedulerOpt = None,
    workers: WorkersOpt = None,
    address: AddressOpt = None,
) -> None:
    """Run many workflows (one per prototype) on Dask; exit 1 if any of them failed."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )
    from rich.table import Table

    from pipeline.batch import expand_workflows, run_batch, summary_table

    selected = [s.strip() for s in stages.split(",") if s.strip()] if stages else None
    try:
        files = expand_workflows(paths)
        columns = (TextColumn("batch"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
        with Progress(*columns, console=console, transient=True) as bar:
            task = bar.add_task("batch", total=len(files))
            results = run_batch(
                files,
                stages=selected,
                force=force,
                scheduler=scheduler,
                workers=workers,
                address=address,
                on_done=lambda _result: bar.advance(task),
            )
    except WorkflowError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(2) from None
    frame = summary_table(results)
    failed = int((frame.status == "failed").sum())
    table = Table(title=f"Batch: {len(frame)} workflows, {failed} failed")
    for column in ("workflow", "status", "seconds", "ran", "skipped", "RBF NRMSE(q)", "error"):
        justify = "right" if column == "seconds" else "left"
        table.add_column(column, overflow="fold", justify=justify)
    for row in frame.itertuples(index=False):
        style = "red" if row.status == "failed" else "green"
        where = f"{row.failed_stage}: " if row.failed_stage else ""
        table.add_row(
            escape(row.name),
            f"[{style}]{row.status}[/{style}]",
            f"{row.seconds:.1f}",
            str(row.ran),
            str(row.skipped),
            escape(row.rbf_nrmse_q),
            escape(where + row.error),
        )
    console.print(table)
    if failed:
        raise typer.Exit(1)


def main() -> None:
    """Entry point of the ``debist`` console script."""
    app()


if __name__ == "__main__":
    main()
