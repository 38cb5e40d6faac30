"""The ``debist`` command line: a thin Typer adapter over :mod:`pipeline`.

Parses arguments, loads the workflow, calls the runner, prints with rich, and maps
debist's exceptions to exit codes in one place (:func:`pipeline.errors.exit_code`): 0 done,
1 a stage failed on its data, 2 a bad workflow or argument or a refused output folder, lock
or memory budget, 3 artifacts failed verification, 130 after Ctrl-C, 143 after SIGTERM.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape

from pipeline.errors import DebistError, Interrupted, VerificationError, WorkflowError, exit_code

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
OutOpt = Annotated[Path | None, typer.Option("--out", help="Override the workflow's output_dir.")]
WaitOpt = Annotated[
    bool,
    typer.Option(
        "--wait", help="If another debist run writes to the output folder, wait for it to end."
    ),
]


@app.callback()
def _options(
    memory_budget: Annotated[
        float | None,
        typer.Option(
            "--memory-budget",
            metavar="GB",
            min=0.001,
            help="Memory a stage may plan for, in GB; a setting that needs more is refused "
            "before it allocates (default: half of this machine's RAM, or the environment "
            "variable DEBIST_MEMORY_BUDGET_GB).",
        ),
    ] = None,
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            is_eager=True,
            callback=lambda value: _print_version(value),
            help="Print debist's version and exit.",
        ),
    ] = False,
) -> None:
    """Rig logs of bistable DE actuators to validated dynamic models (Masoud & Maas 2025)."""
    if memory_budget is not None:
        from pipeline.preflight import BUDGET_ENV

        os.environ[BUDGET_ENV] = repr(float(memory_budget))  # batch workers inherit it


def _print_version(value: bool) -> None:
    """Print the installed version (package metadata) and exit, for ``--version``."""
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("debist")
        except PackageNotFoundError:  # run from a source tree that is not installed
            text = "unknown (not installed)"
        console.print(f"debist {text}")
        raise typer.Exit(0)


@contextmanager
def _guard() -> Iterator[None]:
    """Turn debist's exceptions and interruptions into one line and their exit code."""
    try:
        yield
    except DebistError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(exit_code(exc)) from None
    except KeyboardInterrupt as exc:
        what = str(exc) if isinstance(exc, Interrupted) else "interrupted"
        err.print(
            f"[yellow]{escape(what)}[/yellow]: stopped; finished stages are kept, the "
            "unfinished one left nothing behind"
        )
        raise typer.Exit(exit_code(exc)) from None


def _on_sigterm(signum: int, _frame: object) -> None:
    raise Interrupted(signum)


def _runner(workflow: Path, out: Path | None, wait: bool = False):
    from pipeline.runner import Runner
    from pipeline.workflow import load_workflow

    return Runner(load_workflow(workflow, out), wait=wait)


def _event(stage: str, what: str, detail: str) -> None:
    if what == "skip":
        console.print(f"[dim]Stage '{stage}' is up to date, skipping[/dim]")
    elif what == "start":
        console.print(f"Running stage '{stage}' ...")
    elif what == "recovered":
        console.print(f"[yellow]recovered:[/yellow] {escape(detail)}")
    else:
        console.print(f"[green]Stage '{stage}' done[/green] ({detail})")


def _report(runner, manifests) -> None:
    from pipeline import report

    diff = manifests.get("differentiate")
    stopped = [n for n, ok in (diff.summary.get("converged", {}) if diff else {}).items() if not ok]
    if stopped:
        console.print(
            "[dim]differentiate: the iterative method stopped at its iteration limit on "
            f"{len(stopped)} data set(s), as configured (converged = false in the summary)[/dim]"
        )
    if "rig" in manifests:
        console.print(report.rig_table(manifests["rig"].summary))
    if "analyze" in manifests:
        console.print(report.analyze_table(manifests["analyze"].summary))
    if "identify" in manifests:
        console.print(report.identify_table(manifests["identify"].summary))
        design = report.design_table(manifests["identify"].summary)
        if design is not None:
            console.print(design)
        for line in manifests["identify"].summary.get("excitation", {}).get("warnings", []):
            console.print(f"[yellow]excitation:[/yellow] {escape(line)}")
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
    console.print(f"[dim]artifacts: {escape(str(runner.wf.output_dir))}[/dim]")


def _run(
    workflow: Path, stages: list[str] | None, force: bool, out: Path | None, wait: bool
) -> None:
    with _guard():
        runner = _runner(workflow, out, wait)
        manifests = runner.run(stages, force=force, on_event=_event)
        _report(runner, manifests)
        if stages is None and (digest := runner.digest()) is not None:
            console.print(f"run digest: [bold]{digest}[/bold]")
            console.print(
                f"[dim]check it later with: debist verify {escape(str(workflow))} "
                f"--digest {digest}[/dim]",
                soft_wrap=True,
            )


@app.command()
def run(
    workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None, wait: WaitOpt = False
) -> None:
    """Run every stage of WORKFLOW, skipping those that are up to date; print the run digest."""
    _run(workflow, None, force, out, wait)


def _stage_command(name: str, help_text: str, command: str | None = None) -> None:
    def command_fn(
        workflow: WorkflowArg, force: ForceOpt = False, out: OutOpt = None, wait: WaitOpt = False
    ) -> None:
        _run(workflow, [name], force, out, wait)

    command_fn.__doc__ = help_text
    app.command(command or name)(command_fn)


_stage_command("ingest", "Read the rig logs into canonical tables (t, q, v1..vN in SI units).")
_stage_command("differentiate", "Compute q_dot and q_ddot (TVRegDiff or the configured method).")
_stage_command(
    "identify", "Identify the RBF model of Eq. 37-40 by least squares with the T_z search."
)
_stage_command(
    "validate", "Free-run the identified model on every data set; NRMSE table and plots."
)
_stage_command(
    "compare", "Fit SINDy on the same data and derivatives; free-run it with the same simulator."
)
_stage_command(
    "study", "Sensitivity studies: RBF grid (M, sigma_n; Fig. 11b) and TVRegDiff alpha (Fig. 11c)."
)
_stage_command(
    "rig", "Run the virtual rig: dSPACE MAT logs and truth files per experiment.", "simulate-rig"
)


@app.command()
def fleet(
    template: Annotated[Path, typer.Argument(help="Workflow with a rig section.")],
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

    with _guard():
        try:
            raw = tomllib.loads(template.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise WorkflowError(f"cannot read the template '{template}': {exc}") from None
        files = fleet_workflows(raw, template.resolve().parent, folder, size, seed=seed)
        paths = artifacts.write_text_files(folder, files)
    console.print(f"wrote {len(paths)} workflows to {folder}; run them with: debist batch {folder}")


_stage_command(
    "analyze", "Design analysis of the physics section (Section 3): statics.h5 and Fig. 3-7 as PNG."
)


@app.command()
def status(
    workflow: WorkflowArg,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
    out: OutOpt = None,
) -> None:
    """Say per stage whether it is up to date, stale (and why) or missing; reads only."""
    from pipeline import outdir
    from pipeline.runner import STAGES

    with _guard():
        runner = _runner(workflow, out)
        states = runner.status()
        warning = ""
        try:
            outdir.check_output_dir(
                runner.wf.output_dir,
                workflow=runner.wf.name,
                workflow_dir=runner.wf.path.parent,
                sources=[d.source for d in runner.wf.datasets if not d.rig],
                stages=STAGES,
            )
        except DebistError as exc:
            warning = f"a run would stop: {exc}"
    if as_json:
        typer.echo(json.dumps([s.__dict__ for s in states], indent=2))
        return
    for s in states:
        color = {"up to date": "green", "stale": "yellow", "missing": "red"}[s.state]
        console.print(
            f"{s.stage:14s} [{color}]{s.state}[/{color}]"
            + (f"  ({escape(s.reason)})" if s.reason else ""),
            soft_wrap=True,
        )
    if warning:
        console.print(f"[yellow]{escape(warning)}[/yellow]")


@app.command()
def verify(
    workflow: WorkflowArg,
    digest: Annotated[
        str | None,
        typer.Option(
            "--digest",
            help="The run digest that `run` printed: the manifests must be exactly those.",
        ),
    ] = None,
    out: OutOpt = None,
) -> None:
    """Re-hash every artifact and check the chain of manifests; exit 3 naming any problem.

    With --digest, the manifests must also be exactly those of the quoted run.
    """
    with _guard():
        problems = _runner(workflow, out).verify(digest)
        if problems:
            for p in problems:
                err.print(f"[red]problem:[/red] {escape(p)}")
            raise typer.Exit(exit_code(VerificationError(problems)))
    what = "the quoted digest, " if digest else ""
    console.print(f"[green]all artifacts match their manifests, {what}and the chain holds[/green]")


@app.command()
def report(workflow: WorkflowArg, out: OutOpt = None) -> None:
    """Write one self-contained HTML page of the run: tables, figures, provenance.

    Goes to <output_dir>/report/report.html (replaced atomically); stages that have not run
    are left out. The page is not a hashed stage: `verify` checks the artifacts it shows.
    """
    from contextlib import nullcontext

    from pipeline import htmlreport, outdir

    with _guard():
        runner = _runner(workflow, out)
        folder = runner.wf.output_dir
        with outdir.output_lock(folder) if folder.is_dir() else nullcontext():
            html = htmlreport.render_report(htmlreport.load_run(runner, workflow))
            path = htmlreport.write_report(folder / "report", html)
    console.print(f"wrote {escape(str(path))}")


class ExportFormat(StrEnum):
    """Formats of ``debist export``: C99 header and source, or a NumPy module."""

    c = "c"
    python = "python"


@app.command()
def export(
    workflow: WorkflowArg,
    fmt: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            help="c: debist_model.h and debist_model.c (C99, math.h only, no allocation); "
            "python: debist_model.py (NumPy only).",
        ),
    ] = ExportFormat.c,
    dest: Annotated[
        Path | None,
        typer.Option("--dest", help="Folder for the files (default: <output_dir>/export)."),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Replace existing files of the same names.")
    ] = False,
    out: OutOpt = None,
) -> None:
    """Write the identified model as self-contained C99 or NumPy code for a controller.

    Model, RK4 step (inputs linear between samples) and curve table; needs identify up to date.
    """
    import shutil
    import tempfile
    from contextlib import nullcontext

    from pipeline import artifacts, outdir
    from pipeline.errors import OutputDirError
    from pipeline.export import export_files, load_identified

    with _guard():
        runner = _runner(workflow, out)
        folder = runner.wf.output_dir
        with outdir.output_lock(folder) if folder.is_dir() else nullcontext():
            model, info = load_identified(runner)
            files = export_files(model, fmt.value, info)
            target = dest if dest is not None else folder / "export"
            if force:  # each file replaced atomically (os.replace from a sibling folder)
                target.mkdir(parents=True, exist_ok=True)
                tmp = Path(tempfile.mkdtemp(prefix=".export.tmp-", dir=target))
                try:
                    for path in artifacts.write_text_files(tmp, files):
                        os.replace(path, target / path.name)
                finally:
                    shutil.rmtree(tmp, ignore_errors=True)
            else:
                try:
                    artifacts.write_text_files(target, files)
                except OutputDirError as exc:
                    raise OutputDirError(f"{exc}, or pass --force") from None
    for name in files:
        console.print(f"wrote {escape(str(target / name))}")
    console.print(f"run digest: {info.run_digest or 'n/a (not every stage has run)'}")


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
        help="processes (default): a local Dask cluster of worker processes under nannies; "
        "a workflow whose worker dies is retried once, then reported failed, and the others "
        "run on | distributed: the cluster at --address (the default with --address) | "
        "threads: one process | synchronous: one thread, for debugging.",
    ),
]
WorkersOpt = Annotated[
    int | None,
    typer.Option(
        "--workers",
        min=1,
        help="Local worker processes, or threads (default: one per workflow, at most one "
        "per core).",
    ),
]
AddressOpt = Annotated[
    str | None,
    typer.Option("--address", help="A running Dask scheduler, e.g. tcp://host:8786."),
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
    """Run many workflows (one per prototype) on Dask; exit 1 if any of them failed.

    Ends with a summary table, one row per workflow file, also after failures.
    """
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
    columns = ("workflow file", "name", "status", "seconds", "ran", "skipped")
    for column in (*columns, "RBF NRMSE(q)", "error"):
        justify = "right" if column == "seconds" else "left"
        table.add_column(column, overflow="fold", justify=justify)
    for row in frame.itertuples(index=False):
        style = "red" if row.status == "failed" else "green"
        where = f"{row.failed_stage}: " if row.failed_stage else ""
        table.add_row(
            escape(row.file),
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
    """Entry point of the ``debist`` console script (SIGTERM stops as cleanly as Ctrl-C)."""
    signal.signal(signal.SIGTERM, _on_sigterm)
    app()


if __name__ == "__main__":
    main()
