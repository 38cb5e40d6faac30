"""The ``debist`` command line: a thin Typer adapter over :mod:`debist`.

Parses arguments, loads the workflow, calls the runner, prints with rich, and maps
debist's exceptions to exit codes in one place (:func:`debist.core.errors.exit_code`): 0 done,
1 a stage failed on its data, 2 a bad workflow or argument or a refused output folder, lock
or memory budget, 3 artifacts failed verification, 130 after Ctrl-C, 143 after SIGTERM.

What it draws (progress bars, stage lines, a run's tables) and the consoles it prints to are
in :mod:`debist.terminal`. Help texts are plain
text (Typer's ``rich_markup_mode=None``), so workflow sections such as ``[rig]`` and units
such as ``[s]`` print literally instead of being taken for rich markup.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated, NoReturn

import click
import typer
from rich.markup import escape
from typer.core import TyperCommand, TyperGroup

# debist's other modules are imported inside the commands, not here, so that `debist --help`
# and a bad argument answer at once instead of after loading numpy, pandas and scipy.
from debist.core.errors import (
    DebistError,
    Interrupted,
    OutputDirError,
    RunLockedError,
    VerificationError,
    WorkflowError,
    exit_code,
    os_error_line,
)
from debist.terminal import (
    bar_columns,
    console,
    err,
    essential,
    level,
    print_report_line,
    print_summary,
    progress,
    progress_console,
    stage_events,
)


class _Command(TyperCommand):
    """A command whose usage line names its arguments plainly (``WORKFLOW``, not ``{WORKFLOW}``)."""

    def collect_usage_pieces(self, ctx: click.Context) -> list[str]:
        """Return the usage pieces without Typer's braces around required arguments."""
        pieces = super().collect_usage_pieces(ctx)
        return [p[1:-1] if p.startswith("{") and p.endswith("}") else p for p in pieces]


#: Global options also accepted after the command (``debist run -q WF``).
_GLOBAL_FLAGS = frozenset({"-q", "--quiet", "-v", "--verbose"})


class _Commands(TyperGroup):
    """The command group, listing each command with its whole first paragraph of help.

    Click cuts the listing at the first period or at the terminal width, which would drop
    the sections and units of a help line (``Eq. 37`` ends a "sentence"). Global flags
    given after the command are moved before it, so ``debist run -q WF`` works.
    """

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        """Move ``-q``/``-v`` after the command name in front of it, then parse as Click does."""
        head, rest, command = [], [], False
        for i, arg in enumerate(args):
            if arg == "--":
                rest += args[i:]
                break
            if command and arg in _GLOBAL_FLAGS:
                head.append(arg)
                continue
            command = command or arg in self.commands
            rest.append(arg)
        return super().parse_args(ctx, head + rest)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """Write the Commands section (see :meth:`click.Group.format_commands`)."""
        rows = []
        for name in self.list_commands(ctx):
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                text = cmd.short_help or (cmd.help or "").split("\n\n")[0]
                rows.append((name, " ".join(text.split())))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


app = typer.Typer(
    cls=_Commands,
    help="Rig logs of bistable DE actuators to validated dynamic models (Masoud & Maas 2025).",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,  # help is plain text: "[rig]", "[s]" are words, not rich markup
)

WorkflowArg = Annotated[Path, typer.Argument(metavar="WORKFLOW", help="Workflow TOML file.")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Rerun even if up to date.")]
OutOpt = Annotated[
    Path | None,
    typer.Option(
        "--out", help="Output folder of the run (replaces [workflow] output_dir), also with --set."
    ),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        "-S",
        metavar="KEY=VALUE",
        help="Change one setting of the workflow for this command, e.g. identify.M=8 "
        "(repeatable; checked like the file; the manifests record the values used). Without "
        "--out the run goes to its own folder beside the output folder, named after it plus "
        "'.set-' and 8 hex digits of the settings' sha256, so the workflow's own run is never "
        "touched and the same --set finds that folder again; with --out it goes there.",
    ),
]
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
            help="Memory a stage may plan for [GB]; a setting that needs more is refused "
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
    quiet: Annotated[
        bool,
        typer.Option(
            "-q", "--quiet", help="Print only errors and the run digest; no progress bars."
        ),
    ] = False,
    verbose: Annotated[
        bool,
        typer.Option(
            "-v",
            "--verbose",
            help="Also print why each stage runs or is skipped, and its timings [s].",
        ),
    ] = False,
) -> None:
    """Rig logs of bistable DE actuators to validated dynamic models (Masoud & Maas 2025)."""
    if quiet and verbose:
        raise typer.BadParameter("give -q/--quiet or -v/--verbose, not both")
    level["value"] = -1 if quiet else (1 if verbose else 0)
    console.quiet = quiet
    if memory_budget is not None:
        from debist.core.preflight import BUDGET_ENV

        os.environ[BUDGET_ENV] = repr(float(memory_budget))  # batch workers inherit it


def _print_version(value: bool) -> None:
    """Print the installed version (package metadata) and exit, for ``--version``."""
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("debist")
        except PackageNotFoundError:  # run from a source tree that is not installed
            text = "unknown (not installed)"
        typer.echo(f"debist {text}")
        raise typer.Exit(0)


@contextmanager
def _guard(
    kept: str = "finished stages are kept, the unfinished one left nothing behind",
) -> Iterator[None]:
    """Turn debist's exceptions and interruptions into one line and their exit code.

    ``kept``: what stays valid after an interruption, for its line.
    """
    try:
        yield
    except DebistError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}")
        raise typer.Exit(exit_code(exc)) from None
    except OSError as exc:  # the file system said no: read-only, full, permissions
        err.print(f"[red]error:[/red] {escape(os_error_line(exc))}")
        raise typer.Exit(exit_code(exc)) from None
    except KeyboardInterrupt as exc:
        _stopped(exc, kept)


def _stopped(exc: KeyboardInterrupt, kept: str) -> NoReturn:
    """Say in one line what stopped the command and what stays valid; exit 130 or 143."""
    what = str(exc) if isinstance(exc, Interrupted) else "interrupted"
    err.print(f"[yellow]{escape(what)}[/yellow]: stopped; {escape(kept)}", soft_wrap=True)
    raise typer.Exit(exit_code(exc)) from None


@contextmanager
def _wait_advice() -> Iterator[None]:
    """Name ``--wait`` in a refusal for a locked output folder (the commands that have it)."""
    try:
        yield
    except RunLockedError as exc:
        raise RunLockedError(f"{exc}, or pass --wait to wait for it") from None


def _on_sigterm(signum: int, _frame: object) -> None:
    raise Interrupted(signum)


def _on_unraisable(unraisable) -> None:
    """Deliver again a Ctrl-C or SIGTERM that was raised where it cannot propagate.

    A signal's exception raised inside a ctypes callback (llvmlite's object cache, while
    numba compiles) is printed as "Exception ignored" and lost: the run went on. Instead,
    a moment later (from a timer thread, once the callback has returned) the signal is
    sent again to the main thread, where it unwinds the run as any other (Python
    documentation, :func:`sys.unraisablehook` and :func:`signal.pthread_kill`).
    """
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        import threading

        signum = getattr(unraisable.exc_value, "signum", signal.SIGINT)
        main = threading.main_thread().ident
        again = threading.Timer(0.05, signal.pthread_kill, (main, signum))
        again.daemon = True
        again.start()
        return
    sys.__unraisablehook__(unraisable)


def _run(
    workflow: Path,
    stages: list[str] | None,
    force: bool,
    out: Path | None,
    wait: bool,
    select: dict[str, str | None] | None = None,
    sets: list[str] | None = None,
) -> None:
    from debist import api

    start = until = None
    with _guard(), _wait_advice():
        wf = api.load_workflow(workflow, sets or None, output_dir=out)
        if wf.overrides:
            where = "the folder --out names" if out is not None else "beside the workflow's"
            kept = "; the workflow's output folder stays as it is" if wf.own_output_dir else ""
            console.print(
                f"--set: this run writes to {escape(str(wf.output_dir))} ({where}{kept})",
                soft_wrap=True,
            )
        if select is not None:
            listed, start, until = select["stages"], select["start"], select["until"]
            stages = (
                [n.strip() for n in listed.split(",") if n.strip()] if listed is not None else None
            )
        ran: set[str] = set()
        with progress() as display:
            result = api.run(
                wf,
                stages=stages,
                start=start,
                until=until,
                force=force,
                wait=wait,
                on_progress=stage_events(wf, display, ran),
            )
        print_summary(wf, result.manifests, ran)
        if select is not None:  # `debist run`, not a stage command
            print_report_line(wf, result.manifests, workflow)
        if result.digest is not None:
            essential(f"run digest: [bold]{result.digest}[/bold]")
            line = _verify_command(workflow, result.digest, out, sets)
            console.print(f"[dim]check it later with: {escape(line)}[/dim]", soft_wrap=True)


def _verify_command(workflow: Path, digest: str, out: Path | None, sets: list[str] | None) -> str:
    """Return the ``debist verify`` command line of a run, shell-quoted to paste as it is."""
    words = ["debist", "verify", str(workflow), "--digest", digest]
    if out is not None:
        words += ["--out", str(out)]
    for item in sets or ():
        words += ["--set", item]
    return shlex.join(words)


@app.command(cls=_Command)
def run(
    workflow: WorkflowArg,
    force: ForceOpt = False,
    out: OutOpt = None,
    wait: WaitOpt = False,
    stages: Annotated[
        str | None,
        typer.Option(
            "--stages",
            help="Run only these stages, comma-separated, e.g. 'identify,validate'; the "
            "stages they read must be up to date.",
        ),
    ] = None,
    start: Annotated[
        str | None,
        typer.Option("--from", help="Run from this stage on (in the workflow's order)."),
    ] = None,
    until: Annotated[
        str | None, typer.Option("--until", help="Run up to and including this stage.")
    ] = None,
    sets: SetOpt = None,
) -> None:
    """Run every stage of WORKFLOW, skipping those that are up to date; print the run digest.

    --stages, or --from and --until, run a part of the workflow (no digest then); a stage
    whose upstream stage outside the part is missing or stale is refused (exit 2). --set
    changes a setting for this run only: the run goes to --out, or without it to its own
    folder beside the output folder (its name plus .set- and 8 hex digits); status, verify,
    report, export and diff find it with the same --set and --out. The workflow's own run is
    not touched.
    """
    select = {"stages": stages, "start": start, "until": until}
    _run(workflow, None, force, out, wait, select, sets)


def _stage_command(name: str, help_text: str, command: str | None = None) -> None:
    def command_fn(
        workflow: WorkflowArg,
        force: ForceOpt = False,
        out: OutOpt = None,
        wait: WaitOpt = False,
        sets: SetOpt = None,
    ) -> None:
        _run(workflow, [name], force, out, wait, sets=sets)

    command_fn.__doc__ = help_text
    app.command(command or name, cls=_Command)(command_fn)


_stage_command(
    "ingest",
    "Read the rig logs of [datasets.*] into canonical tables (t [s], q [m], v1..vN [V]) "
    "as [ingest] maps their channels.",
)
_stage_command(
    "differentiate",
    "Compute q_dot [m/s] and q_ddot [m/s^2] by the [differentiate] method (TVRegDiff by default).",
)
_stage_command(
    "identify",
    "Identify the RBF model of Eq. 37-40 from [identify] by least squares with the search "
    "over the friction lag T_z [s].",
)
_stage_command(
    "validate",
    "Free-run the identified model on every data set as [validate] says; NRMSE table and runs.",
)
_stage_command(
    "compare",
    "Fit SINDy by [compare] on the same data and derivatives; free-run it with the same simulator.",
)
_stage_command(
    "study",
    "Sensitivity studies of [study]: RBF grid (M, sigma_n; Fig. 11b) and TVRegDiff alpha "
    "(Fig. 11c).",
)
_stage_command(
    "rig",
    "Run the virtual rig of [rig]: dSPACE MAT logs and truth files per experiment.",
    "simulate-rig",
)


def _channel_table(survey, roles: dict[str, str]):
    """One rich table of a file's channels: unit, samples, range and the role it maps to."""
    from rich.table import Table

    title = f"{escape(str(survey.path))} ({survey.format})"
    if survey.time_bases:
        title += f", time base {escape(', '.join(survey.time_bases))}"
    table = Table("channel", "unit", "samples", "min", "max", "maps to", title=title)
    for c in survey.channels:
        span = ("-", "-") if c.lo != c.lo else (f"{c.lo:.6g}", f"{c.hi:.6g}")
        table.add_row(escape(c.name), escape(c.unit or "?"), str(c.samples), *span,
                      roles.get(c.name, ""))  # fmt: skip
    return table


@app.command(cls=_Command)
def init(
    data: Annotated[
        list[Path], typer.Argument(metavar="DATA", help="Rig logs: the estimation file first.")
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", metavar="FILE", help="Workflow to write (default: debist.toml in this folder)."
        ),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --out file.")] = False,
    only_list: Annotated[
        bool, typer.Option("--list", help="Only list the files' channels; write nothing.")
    ] = False,
    time: Annotated[
        str | None, typer.Option("--time", metavar="NAME", help="The time channel.")
    ] = None,
    q: Annotated[
        str | None, typer.Option("--q", metavar="NAME", help="The displacement q.")
    ] = None,
    v: Annotated[
        list[str] | None,
        typer.Option("--v", metavar="NAME", help="An input (repeat: v1 first, then v2, ...)."),
    ] = None,
    units: Annotated[
        list[str] | None,
        typer.Option(
            "--unit",
            metavar="ROLE=UNIT",
            help="Unit of a role as recorded: time=ms, q=mm, v=kV (every input) or v1=V "
            "(repeatable).",
        ),
    ] = None,
    sample_time: Annotated[
        float | None,
        typer.Option(
            "--sample-time",
            metavar="SECONDS",
            help="Sample time [s] of files without a time channel.",
        ),
    ] = None,
) -> None:
    """Write a first workflow for your rig logs: [ingest] channels guessed, [report] on.

    Lists each file's channels and maps time, q, v1, v2 by their names and units (the
    guess is printed; --time, --q, --v and --unit change it). The first file is the
    estimation data set, the others validation data sets. Never overwrites a file.
    """
    from debist import api

    with _guard():
        if only_list:
            for survey in api.list_channels(data):
                console.print(_channel_table(survey, {}))
            return
        done = api.init_workflow(data, out, force=force, time=time, q=q, v=v or (),
                                 units=units, sample_time=sample_time)  # fmt: skip
    for ds in done.datasets:
        roles = {g.channel.name: g.role for g in ds.mapping.guesses}
        console.print(_channel_table(ds.mapping.survey, roles))
        console.print(f"{escape(ds.name)} ({ds.role}):")
        for g in ds.mapping.guesses:
            line = f"  {g.role:4s} <- {g.channel.name!r} [{g.unit}]  ({g.why}; unit {g.unit_why})"
            console.print(escape(line), style="yellow" if g.assumed else None, soft_wrap=True)
    console.print(escape(done.advice), soft_wrap=True)
    path = str(done.path)
    essential(escape(f"wrote {path}; run it with: debist run {shlex.quote(path)}"))


@app.command(cls=_Command)
def fleet(
    template: Annotated[Path, typer.Argument(help="Workflow with a [rig] section.")],
    size: Annotated[int, typer.Option("--size", min=1, help="Number of prototypes.")] = 10,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of the scatter.")] = 0,
    folder: Annotated[Path, typer.Option("--dir", help="Folder for the workflows.")] = Path(
        "fleet"
    ),
) -> None:
    """Write one workflow per prototype of a seeded fleet around TEMPLATE's rig (for batch).

    Each prototype's rig experiments are run once and its logs checked by TEMPLATE's own
    ingest; a draw whose logs fail (e.g. the beam overshoots the laser's range) is skipped
    and said so, and the next draw is taken.
    """
    from debist import api

    with _guard("nothing of the fleet is kept; the same command writes it anew"):
        made = api.fleet(template, size, seed=seed, folder=folder)
    if made.replaced:
        console.print(f"removed {len(made.replaced)} unscreened files and folders of the fleet "
                      f"stopped earlier in {escape(str(folder))}")  # fmt: skip
    for name, why in made.rejected.items():
        console.print(f"skipped {escape(name)}: its log fails the template's ingest: {escape(why)}")
    console.print(
        f"wrote {len(made.paths)} workflows to {escape(str(folder))}; run them with: debist "
        f"batch {escape(str(folder))}"
    )


@app.command(cls=_Command)
def zoo(
    size: Annotated[int, typer.Option("--size", min=1, help="Number of members.")] = 20,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of the zoo.")] = 1,
    folder: Annotated[Path, typer.Option("--dir", help="Folder of the zoo.")] = Path("zoo"),
) -> None:
    """Write a plant zoo: seeded virtual DE rigs with their logs, minimal workflows and truth.

    Members differ in plant (full or reduced), friction law, DE asymmetry, mass, damping,
    drivers, sensor (block averaging, lag, noise, quantisation) and excitation. Seed 1 is
    for choosing and tuning, seed 2 for checking out of sample. Run them with debist batch
    on the folder; the batch then writes the zoo table (zoo.parquet, zoo.html).
    """
    from debist import api

    again = shlex.join(["debist", "zoo", "--size", str(size), "--seed", str(seed), "--dir",
                        str(folder)])  # fmt: skip
    with _guard(f"the members written are kept; finish the zoo with: {again}"):
        made = api.zoo(size, seed=seed, folder=folder)
    for name, why in made.rejected.items():
        console.print(f"{escape(name)}: redrawn ({escape('; '.join(why))})")
    kept = len(made.members) - len(made.written)
    console.print(
        f"wrote {len(made.written)} zoo members to {escape(str(folder))}"
        + (f" ({kept} were there)" if kept else "")
        + f"; run them with: debist batch {escape(str(folder))}"
    )


_stage_command(
    "analyze", "Design analysis of [physics] (Section 3): statics.h5 and Fig. 3-7 as PNG."
)


@app.command(cls=_Command)
def status(
    workflow: WorkflowArg,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='One JSON object keyed by stage: {"state": "up_to_date" | "stale" | '
            '"missing", "reasons": [{"kind": ..., "detail": ...}]}.',
        ),
    ] = False,
    out: OutOpt = None,
    sets: SetOpt = None,
) -> None:
    """Say per stage whether it is up to date, stale (and why) or missing; reads only."""
    from debist import api

    with _guard():
        wf = api.load_workflow(workflow, sets or None, output_dir=out)
        states = api.status(wf)
        blocker = api.run_blocker(wf)
        warning = f"a run would stop: {blocker}" if blocker else ""
    if as_json:
        typer.echo(json.dumps({s.stage: s.to_json() for s in states}, indent=2))
        if warning:
            err.print(f"[yellow]{escape(warning)}[/yellow]")
        return
    for s in states:
        color = {"up to date": "green", "stale": "yellow", "missing": "red"}[s.state]
        essential(
            f"{s.stage:14s} [{color}]{s.state}[/{color}]"
            + (f"  ({escape(s.reason)})" if s.reason else "")
        )
    warning = warning or api.missing_output(wf)  # the --set run meant, as diff and verify say
    if warning:
        console.print(f"[yellow]{escape(warning)}[/yellow]")


@app.command(cls=_Command)
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
    sets: SetOpt = None,
) -> None:
    """Re-hash every artifact and check the chain of manifests; exit 3 naming any problem.

    The run is checked against the workflow as it is now (with any --set): a setting that
    changed since the run, a source that changed, or ingest tables that the sources no
    longer give are problems. With --digest, the manifests must also be exactly those of
    the quoted run; a mismatch names the first stage that departs from it.
    """
    from debist import api

    with _guard():
        found = api.verify(workflow, digest, overrides=sets or None, output_dir=out)
        for note in found.notes:  # a note, not a failure
            err.print(f"[yellow]note:[/yellow] {escape(note)} (a rerun may give other bytes)")
        if found.problems:
            for p in found.problems:
                err.print(f"[red]problem:[/red] {escape(p)}")
            raise typer.Exit(exit_code(VerificationError(list(found.problems))))
    what = "the quoted digest, " if digest else ""
    console.print(f"[green]all artifacts match their manifests, {what}and the chain holds[/green]")


@app.command(cls=_Command)
def diff(
    run_a: Annotated[
        Path,
        typer.Argument(metavar="RUN_A", help="Output folder of a run, or a workflow with --set."),
    ],
    run_b: Annotated[
        Path | None, typer.Argument(metavar="RUN_B", help="Output folder of another run.")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = False,
    sets: SetOpt = None,
    out: OutOpt = None,
) -> None:
    """Show the settings and the NRMSE rows that differ between two runs (reads only).

    Either two output folders, or a workflow and --set options: `debist diff WF --set
    identify.M=6` compares the run with those settings with the workflow's own run. A
    setting stated on one side and left to its default on the other does not differ.
    """
    from rich.table import Table

    from debist import api

    with _guard():
        found = api.diff(run_a, run_b, overrides=sets or None, output_dir=out)
    name_a, name_b = found["runs"]
    if as_json:
        typer.echo(json.dumps(found, indent=2, default=str))
        return
    if not found["config"] and not found["nrmse"]:
        console.print("the two runs have the same settings and NRMSE")
        return
    if found["config"]:
        heads = ("stage", "setting", escape(name_a), escape(name_b))
        table = Table(*heads, title="settings that differ")
        for r in found["config"]:
            table.add_row(r["stage"], r["key"], escape(str(r["a"])), escape(str(r["b"])))
        console.print(table)
    if found["nrmse"]:
        table = Table("data set", "model", "metric", "A", "B", "B - A", title="NRMSE that differs")

        def fmt(x):
            return "-" if x is None else f"{x:.3f}"

        for r in found["nrmse"]:
            table.add_row(r["dataset"], r["model"], r["metric"], fmt(r["a"]), fmt(r["b"]),
                          fmt(r["change"]))  # fmt: skip
        console.print(table)


@app.command(cls=_Command)
def report(
    workflow: WorkflowArg,
    force: ForceOpt = False,
    out: OutOpt = None,
    wait: WaitOpt = False,
    sets: SetOpt = None,
) -> None:
    """Run the report stage: one self-contained HTML page of the run (needs a [report] section).

    Writes report/report.html in the output folder (tables, figures, provenance) from the
    artifacts of the workflow's stages, which must be up to date; `debist run` makes it as its
    last step, and `debist verify` checks it like every artifact.
    """
    from debist import api
    from debist.report.html import REPORT_FILE

    with _guard():
        wf = api.load_workflow(workflow, sets or None, output_dir=out)
        if "report" not in api.workflow_stages(wf):
            raise WorkflowError(
                f"[report] workflow '{workflow}' has no [report] section: add an empty "
                "`[report]` table to it (`debist run` then writes the report too)"
            )
    _run(workflow, ["report"], force, out, wait, sets=sets)
    console.print(f"report: {escape(str(wf.stage_dir('report') / REPORT_FILE))}")


@app.command(cls=_Command)
def schema() -> None:
    """Print the JSON Schema of a workflow file: every section and key, its type and default.

    For editors that check TOML against a schema, and for the workflow-key reference.
    """
    from debist import api

    typer.echo(json.dumps(api.workflow_schema(), indent=2))


class ExportFormat(StrEnum):
    """Formats of ``debist export``: C99 header and source, a MATLAB function, a NumPy module."""

    c = "c"
    matlab = "matlab"
    python = "python"


@app.command(cls=_Command)
def export(
    workflow: WorkflowArg,
    fmt: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            help="c: debist_model.h and debist_model.c (C99, math.h only, no allocation); "
            "matlab: debist_model.m (a Simulink MATLAB Function block or Octave) and "
            "debist_free_run.m; "
            "python: debist_model.py (NumPy only).",
        ),
    ] = ExportFormat.c,
    dest: Annotated[
        Path | None,
        typer.Option(
            "--dest", help="Folder for the files (default: export/ in the output folder)."
        ),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Replace existing files of the same names.")
    ] = False,
    out: OutOpt = None,
    sets: SetOpt = None,
    wait: WaitOpt = False,
) -> None:
    """Write the identified model as self-contained C99, MATLAB or NumPy code for a controller.

    Model, whole-record free run in validate's scheme (reproduces its NRMSE), causal per-sample
    RK4 step and curve table; needs identify up to date.
    """
    from debist import api

    with _guard(), _wait_advice():
        try:
            done = api.export_model(
                workflow, fmt.value, dest=dest, force=force, overrides=sets or None,
                output_dir=out, wait=wait,
            )  # fmt: skip
        except OutputDirError as exc:
            if force:
                raise
            raise OutputDirError(f"{exc}, or pass --force") from None
    for path in done.files:
        console.print(f"wrote {escape(str(path))}")
    console.print(f"run digest: {done.run_digest or 'n/a (not every stage has run)'}")


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
        help="Local worker processes, or threads (default: one per workflow; at most one "
        "per workflow, per core and per GB of the memory budget).",
    ),
]
AddressOpt = Annotated[
    str | None,
    typer.Option("--address", help="A running Dask scheduler, e.g. tcp://host:8786."),
]


#: What stays valid after a batch was stopped.
_BATCH_KEPT = (
    "the workflows' finished stages are kept (each stage is written whole, and a stage cut "
    "short left nothing that counts); run the same batch again to finish the rest"
)


@app.command(cls=_Command)
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
    from rich.progress import Progress, TextColumn
    from rich.table import Table

    from debist import api

    selected = [s.strip() for s in stages.split(",") if s.strip()] if stages else None
    try:
        files = api.find_workflows(paths)
        target = progress_console()
        columns = bar_columns(TextColumn("batch: workflows"))
        with Progress(*columns, console=target, transient=True, disable=target is None) as bar:
            task = bar.add_task("batch", total=len(files))
            results = api.run_batch(
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
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: the batch stops, in one line
        _stopped(exc, _BATCH_KEPT)
    frame = api.batch_table(results)
    failed = int((frame.status == "failed").sum())
    table = Table(title=f"Batch: {len(frame)} workflows, {failed} failed")
    columns = ("workflow file", "name", "status", "seconds", "ran", "skipped")
    for column in (*columns, "RBF NRMSE(q)", "error / note"):
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
            escape("; ".join(x for x in (where + row.error, row.note) if x)),
        )
    console.print(table)
    pages = [
        (f"zoo table of {folder.name}", _zoo_report(folder)) for folder in api.find_zoos(paths)
    ]
    try:
        index = api.batch_index(results, pages=pages)
    except OutputDirError as exc:  # a user's index.html where the index would go: kept
        err.print(f"[yellow]batch index not written:[/yellow] {escape(str(exc))}", soft_wrap=True)
        index = None
    if index is not None:
        console.print(f"index of the reports: {escape(str(index))}")
    if failed:
        raise typer.Exit(1)


def _zoo_report(folder: Path) -> Path:
    """Write and print a zoo's table after its batch (medians and worst cases); its page."""
    from rich.table import Table

    from debist import api

    with _guard():
        table_path, page, table, summary = api.zoo_report(folder)
    shown = [c for c in ("floor_unseen", "rbf_unseen", "narx_unseen", "sindy_unseen",
                         "restoring_max_error", "g1_max_error", "g2_max_error")
             if c in summary.columns]  # fmt: skip
    out = Table(title=f"Zoo {escape(str(folder))}: {len(table)} members, NRMSE(q) and errors [%]")
    out.add_column("")
    for column in shown:
        out.add_column(column, justify="right")
    for label in ("median", "worst"):
        out.add_row(label, *(_zoo_cell(summary.loc[label, c]) for c in shown))
    out.add_row("no free run", *(f"{int(summary.loc['no_free_run', c])} of "
                                 f"{int(summary.loc['count', c])}" for c in shown))  # fmt: skip
    console.print(out)
    console.print(f"zoo table: {escape(str(table_path))}; page: {escape(str(page))}")
    return page


def _zoo_cell(value: float) -> str:
    if value != value:  # NaN
        return "n/a"
    return "no free run" if value == float("inf") else f"{value:.2f}"


def _warning_line(message, category, *_args, **_kwargs) -> str:
    """One line per warning: its class and message, not the source line that raised it."""
    return f"warning ({category.__name__}): {message}\n"


def main() -> None:
    """Entry point of the ``debist`` console script (SIGTERM stops as cleanly as Ctrl-C)."""
    import warnings

    from debist.core.allocator import (
        arrow_system_pool,
        keep_freed_memory,
        skip_final_collection,
    )

    warnings.formatwarning = _warning_line
    signal.signal(signal.SIGTERM, _on_sigterm)
    sys.unraisablehook = _on_unraisable
    keep_freed_memory()
    arrow_system_pool()
    try:
        app()
    finally:
        _numba_cache_note()
        skip_final_collection()


def _numba_cache_note() -> None:
    """Under -v, say in one line where numba cached the kernels if not in its own folder."""
    jit = sys.modules.get("debist.core.jitcache")
    if jit is not None and jit.note() and level["value"] > 0:
        console.print(escape(jit.note()), soft_wrap=True)


if __name__ == "__main__":
    main()
