"""What the command line draws on the terminal: progress bars, stage lines, a run's tables.

The commands of :mod:`debist.cli` parse arguments and call the API; this module holds the
consoles they print to (stdout for results, stderr for errors and progress), the output level
the global ``-q``/``-v`` options set, the progress display that draws the reports of
:mod:`debist.core.progress` as rich progress bars (only on a terminal, not with ``-q``), and the
printing of a run's results (:func:`print_summary`).

References
----------
rich documentation, ``rich.console.Console`` and ``rich.progress.Progress``.
"""

from __future__ import annotations

import json
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from debist.core.errors import DebistError

__all__ = [
    "Display",
    "bar_columns",
    "console",
    "convergence_notice",
    "err",
    "essential",
    "level",
    "print_report_line",
    "print_summary",
    "print_timings",
    "progress",
    "progress_console",
    "stage_events",
]

#: Reports written to a file or pipe are not squeezed to 80 columns (rich's default there).
console = Console(width=None if sys.stdout.isatty() else 140)
#: Errors, warnings and notes (stderr).
err = Console(stderr=True, soft_wrap=True)
#: Output level set by the global options: -1 with ``-q``, 1 with ``-v``, else 0.
level = {"value": 0}


def essential(text: str) -> None:
    """Print a line that ``-q`` keeps (the run digest, the lines of ``status``).

    Parameters
    ----------
    text : str
        rich markup; what comes from outside debist must be escaped by the caller.
    """
    quiet, console.quiet = console.quiet, False
    try:
        console.print(text, soft_wrap=True)
    finally:
        console.quiet = quiet


def progress_console() -> Console | None:
    """Return the console for progress bars: stderr if a terminal and not ``-q``, else None.

    Returns
    -------
    rich.console.Console or None
        A console on stderr, or None where bars would only garble a file or pipe.
    """
    try:
        terminal = sys.stderr.isatty()  # not rich's is_terminal: FORCE_COLOR must not draw bars
    except (AttributeError, ValueError):  # replaced or closed
        terminal = False
    return Console(stderr=True) if terminal and level["value"] >= 0 else None


def bar_columns(label) -> tuple:
    """Return the columns of every progress bar: ``label``, bar, done/total, elapsed, time left.

    Parameters
    ----------
    label : rich.progress.ProgressColumn
        The first column (the task's name).

    Returns
    -------
    tuple of rich.progress.ProgressColumn

    References
    ----------
    rich documentation, ``rich.progress`` (columns).
    """
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return (label, BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("left"),
            TimeRemainingColumn())  # fmt: skip


class Display:
    """Progress reports (:mod:`debist.core.progress`) drawn as rich progress bars, one per task.

    A row reads ``stage: task``, a bar, ``done/total``, the elapsed time and rich's
    estimate of the time left. A row goes when its task reaches its total; when a stage
    ends, its rows are drawn complete (work that stopped early, such as an optimiser that
    converged before its evaluation budget, is finished too) and removed.

    Parameters
    ----------
    target : rich.console.Console
        Where to draw (stderr, a terminal).

    References
    ----------
    rich documentation, ``rich.progress.Progress``.
    """

    def __init__(self, target: Console):
        from rich.progress import Progress, TextColumn

        self.bars = Progress(
            *bar_columns(TextColumn("{task.description}", markup=False)),
            console=target,
            transient=True,
            redirect_stdout=sys.stdout.isatty(),  # stage lines above the bars, not through them
            redirect_stderr=True,
        )
        self.stage = ""
        self._rows: dict[str, tuple[object, int]] = {}  # label -> (task id, done)
        self._lock = threading.Lock()

    def listen(self, task: str, done: int, total: int) -> None:
        """Show one report (the :data:`debist.core.progress.Listener` signature).

        Parameters
        ----------
        task : str
            What is counted, e.g. ``"refine: optimiser evaluations"``.
        done, total : int
            Units done and in all (``total <= 0``: unknown).
        """
        label = (
            task
            if not self.stage or task.startswith(f"{self.stage}:")
            else (f"{self.stage}: {task}")
        )
        total = max(total, done) if total > 0 else None
        with self._lock:
            row = self._rows.get(label)
            if row is not None and done < row[1]:  # the same task started over
                self.bars.remove_task(row[0])
                row = None
            if row is None:
                tid = self.bars.add_task(label, total=total, completed=done)
            else:
                tid = row[0]
                self.bars.update(tid, total=total, completed=done)
            self._rows[label] = (tid, done)
            if total is not None and done >= total:
                self.bars.refresh()
                self.bars.remove_task(tid)
                del self._rows[label]

    def finish(self) -> None:
        """Draw every open row complete, then remove it (at the end of a stage)."""
        with self._lock:
            for tid, done in self._rows.values():
                self.bars.update(tid, total=max(done, 1), completed=max(done, 1))
            if self._rows:
                self.bars.refresh()
            for tid, _done in self._rows.values():
                self.bars.remove_task(tid)
            self._rows.clear()


@contextmanager
def progress() -> Iterator[Display | None]:
    """Draw the progress reports made inside the block, if there is a terminal to draw on.

    Yields
    ------
    Display or None
        The display listening to :mod:`debist.core.progress`, or None without a terminal.
    """
    from debist.core.progress import listening

    target = progress_console()
    if target is None:
        yield None
        return
    display = Display(target)
    with display.bars, listening(display.listen):
        try:
            yield display
        finally:
            display.finish()


def stage_events(wf, display: Display | None, ran: set[str]):
    """Return the API's ``on_progress`` callback: stage lines, bars, and with ``-v`` timings.

    Parameters
    ----------
    wf : debist.workflow.loader.Workflow
        The workflow (its stage folders, for the timings).
    display : Display or None
        Where step reports are drawn (:func:`progress`).
    ran : set of str
        Receives the names of the stages that ran.

    Returns
    -------
    callable
        Takes a :class:`debist.api.ProgressEvent`.
    """
    verbose = level["value"] > 0

    def on_progress(event) -> None:
        stage, what, detail = event.stage, event.what, event.detail
        why = f" ({escape(detail)})" if verbose and detail else ""
        if what == "step":
            if display is not None:
                display.listen(detail, event.done, event.total)
        elif what == "skip":
            console.print(f"[dim]Stage '{stage}' is up to date, skipping{why}[/dim]")
        elif what == "start":
            if display is not None:
                display.finish()
                display.stage = stage
            console.print(f"Running stage '{stage}' ...{why}")
        elif what == "recovered":
            console.print(f"[yellow]recovered:[/yellow] {escape(detail)}")
        else:
            if display is not None:
                display.finish()
            ran.add(stage)
            console.print(f"[green]Stage '{stage}' done[/green] ({detail})")
            if verbose:
                print_timings(wf.stage_dir(stage))

    return on_progress


def print_timings(stage_dir: Path) -> None:
    """Print the parts of a stage's wall time from its ``timings.json`` (``-v``), and the sum.

    Parameters
    ----------
    stage_dir : pathlib.Path
        The stage's folder; an unreadable ``timings.json`` prints nothing.
    """
    try:
        timings = json.loads((stage_dir / "timings.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    parts = [f"{k} {v:.2f} s" for k, v in timings.items() if k != "stage" and isinstance(v, float)]
    total = timings.get("stage") if isinstance(timings, dict) else None
    if parts:
        text = ", ".join(parts) + (f" (stage {total:.2f} s)" if isinstance(total, float) else "")
        console.print(f"[dim]  timings: {escape(text)}[/dim]", soft_wrap=True)


def convergence_notice(wf, manifests) -> str | None:
    """Say on how many data sets TVRegDiff stopped at its iteration limit, and what to change.

    Not when the workflow states ``iterations`` itself (as the paper's fixed count): the
    differentiate summary still records ``converged = false`` per data set.

    Parameters
    ----------
    wf : debist.workflow.loader.Workflow
        The workflow (its ``[differentiate]`` section).
    manifests : mapping of str to debist.core.artifacts.Manifest
        The run's manifests.

    Returns
    -------
    str or None
        The notice, or None when every data set converged or the count is the workflow's.

    References
    ----------
    Chartrand 2011, ISRN Applied Mathematics (TVRegDiff's iterations).
    """
    diff = manifests.get("differentiate")
    stopped = [n for n, ok in (diff.summary.get("converged", {}) if diff else {}).items() if not ok]
    if not stopped:
        return None
    names = ", ".join(stopped[:3]) + (", ..." if len(stopped) > 3 else "")
    section = wf.section("differentiate")
    if "iterations" in section:  # a count the workflow states (the paper's 10): its choice
        return None
    try:
        from debist.differentiate.tvregdiff_method import TVRegDiffConfig

        params = {k: v for k, v in section.items() if k != "method"}
        cfg = TVRegDiffConfig.from_dict(params)
        iterations, tol = cfg.iterations, cfg.tol
        second = cfg.iterations if cfg.iterations2 is None else cfg.iterations2
    except DebistError:  # another method: name the keys without their values
        iterations = tol = second = "?"
    head = (
        f"differentiate: TVRegDiff stopped at its iteration limit before its tolerance on "
        f"{len(stopped)} data set(s) ({names}; converged = false in the summary)"
    )
    raise_it = (
        f"raise [differentiate] iterations (now {iterations}) and iterations2 (now {second}), "
        f"or loosen [differentiate] tol (now {tol})"
    )
    moved = _longer_run(diff.summary.get("longer_run") or {}, stopped)
    if moved is None:  # an older summary: no record of a longer run
        return (
            f"{head}. A fixed small count is how Chartrand and the paper run it; for "
            f"converged derivatives {raise_it}."
        )
    settled, words = moved
    if settled:
        return f"{head}. It does not matter: {words}. To converge anyway, {raise_it}."
    return f"{head}. It may matter: {words}; {raise_it}."


def _longer_run(checks: dict, stopped: list[str]) -> tuple[bool, str] | None:
    """Say how far a run with more iterations moved q_dot and q_ddot: ``(settled, words)``.

    The largest relative change over the stopped data sets
    (:func:`debist.differentiate.tvregdiff_method.longer_run`), judged against
    :data:`debist.differentiate.tvregdiff_method.SETTLED`; None without a record of it.
    """
    from debist.differentiate.tvregdiff_method import SETTLED

    rows = [checks[n] for n in stopped if n in checks]
    if not rows:
        return None
    q_dot, q_ddot = (max(float(r[k]) for r in rows) for k in ("q_dot", "q_ddot"))
    counts = sorted({int(r["iterations"]) for r in rows})
    settled = max(q_dot, q_ddot) < SETTLED
    words = (
        f"a run with {'/'.join(map(str, counts))} iterations moved q_dot by {100 * q_dot:.3g} % "
        f"and q_ddot by {100 * q_ddot:.3g} % (relative change, largest data set), "
        f"{'below' if settled else 'not below'} {100 * SETTLED:g} %"
    )
    return settled, words


def print_summary(wf, manifests, ran: set[str]) -> None:
    """Print a run's results: the rig, design, identification and NRMSE tables, SINDy's model.

    Parameters
    ----------
    wf : debist.workflow.loader.Workflow
        The workflow (its output folder).
    manifests : mapping of str to debist.core.artifacts.Manifest
        The run's manifests; a stage without one prints nothing.
    ran : set of str
        The stages that ran in this call (the TVRegDiff notice prints once, when
        differentiate ran, or with ``-v``).

    References
    ----------
    Masoud & Maas 2025, Table 2 (the NRMSE table, Eq. 41).
    """
    from debist.report import tables as report

    notice = convergence_notice(wf, manifests)
    if notice and ("differentiate" in ran or level["value"] > 0):  # once, not on every rerun
        console.print(f"[dim]{escape(notice)}[/dim]", soft_wrap=True)
    unit = (wf.section("validate") or {}).get("report_unit")  # of q and what is made of q
    if "rig" in manifests:
        console.print(report.rig_table(manifests["rig"].summary, unit))
    if "analyze" in manifests:
        console.print(report.analyze_table(manifests["analyze"].summary, unit))
    if "identify" in manifests:
        identify = report.display_summary(manifests["identify"].summary, unit)
        console.print(report.identify_table(identify))
        design = report.design_table(identify)
        if design is not None and console.width < report.DESIGN_TABLE_WIDTH:
            for line in report.design_lines(identify):
                console.print(line, markup=False)
        elif design is not None:
            console.print(design)
        for line in identify.get("excitation", {}).get("warnings", []):
            console.print(f"[yellow]excitation:[/yellow] {escape(line)}")
        line = report.auto_line(manifests["identify"].summary)
        if line:
            warn = manifests["identify"].summary.get("auto", {}).get("undecided")
            console.print(escape(line), style="yellow" if warn else None)
    last = "compare" if "compare" in manifests else "validate"
    if "compare" in manifests:
        s = manifests["compare"].summary
        console.print(f"SINDy ({s['n_params']} terms):")
        for equation in str(s["equations"]).splitlines():  # a term per line, not one long line
            for line in report.wrap_equation(equation):
                console.print(f"  {escape(line)}", soft_wrap=True)
        ident = manifests["identify"].summary if "identify" in manifests else {}
        console.print(escape(f"  (coefficients as fitted, in SI: {report.sindy_units(ident)})"))
    if last in manifests:
        summary = manifests[last].summary
        console.print(report.nrmse_table(summary["table"]))
        table = report.published_table(
            summary["table"], summary.get("published", []), summary.get("order")
        )
        if table is not None:
            console.print(table)
    console.print(f"[dim]artifacts: {escape(str(wf.output_dir))}[/dim]")


def print_report_line(wf, manifests, workflow: Path) -> None:
    """Say where the run's report is, or that the workflow writes none and how to get one.

    Parameters
    ----------
    wf : debist.workflow.loader.Workflow
        The workflow (its sections, the report's folder).
    manifests : mapping of str to debist.core.artifacts.Manifest
        The run's manifests.
    workflow : pathlib.Path
        The workflow file as given on the command line.
    """
    from debist.report.html import REPORT_FILE

    if "report" in manifests:
        console.print(
            f"report: {escape(str(wf.stage_dir('report') / REPORT_FILE))}", soft_wrap=True
        )
    elif "report" not in wf.sections:
        text = (
            f"no report written: workflow '{workflow}' has no [report] section; add the line "
            "[report] to it for one HTML page of the run (report/report.html)"
        )
        console.print(escape(text), soft_wrap=True)
