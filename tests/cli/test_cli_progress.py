"""The CLI's progress display: what a refine run draws, and silence when not a terminal."""

import io
import re
import sys

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

from debist import cli, terminal
from debist.core import progress
from debist.physics.segments import solve_segments
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv

REFINE = """
[identify.refine]
windows = 4
length = 200
max_nfev = 4
"""
#: rich's cursor and colour control sequences, removed before reading the frames.
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.fixture
def project(tmp_path, bistable_record):
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6) + REFINE)
    return tmp_path


@pytest.fixture
def screen(monkeypatch):
    """A terminal for the progress display: rich's console on a string buffer."""
    buffer = io.StringIO()
    fake = Console(file=buffer, force_terminal=True, width=160, color_system=None)
    monkeypatch.setattr(terminal, "progress_console", lambda: fake)
    return buffer


def frames(buffer: io.StringIO) -> list[str]:
    """Every line the display drew, in order, without control sequences."""
    return [line.strip() for line in ANSI.sub("\n", buffer.getvalue()).splitlines() if line]


def test_refine_run_draws_stage_task_and_evaluations_done_of_total(project, screen):
    result = CliRunner().invoke(cli.app, ["run", str(project / "wf.toml"), "--until", "identify"])
    assert result.exit_code == 0, result.output
    lines = frames(screen)
    refine = [line for line in lines if line.startswith("identify: refine: optimiser evaluations")]
    assert refine, lines
    counts = [tuple(map(int, re.search(r"(\d+)/(\d+)", line).groups())) for line in refine]
    done = [d for d, _ in counts]
    assert done == sorted(done) and done[0] >= 1  # evaluations counted up as they happened
    assert counts[-1][0] == counts[-1][1]  # the last frame shows the task complete
    assert any(t == 4 for _, t in counts)  # the budget of [identify.refine] max_nfev
    # the two data sets of the workflow, differentiated one after the other
    assert any(re.search(r"^differentiate: data sets\b.*\b2/2\b", line) for line in lines), lines
    assert "left" in refine[0]  # the time-left column


def test_without_a_terminal_nothing_is_drawn(project):
    assert terminal.progress_console() is None  # CliRunner's stderr is no terminal
    result = CliRunner().invoke(cli.app, ["run", str(project / "wf.toml"), "--until", "ingest"])
    assert result.exit_code == 0, result.output
    assert "data sets" not in result.output and "━" not in result.output


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_quiet_draws_no_progress_even_on_a_terminal(monkeypatch):
    monkeypatch.setattr(sys, "stderr", _Terminal())
    terminal.level["value"] = 0
    assert terminal.progress_console() is not None
    terminal.level["value"] = -1
    try:
        assert terminal.progress_console() is None
    finally:
        terminal.level["value"] = 0


def test_segmented_integration_reports_simulated_time_up_to_the_end():
    seen = []
    with progress.listening(lambda task, done, total: seen.append((task, done, total))):
        sol = solve_segments(
            lambda t, x: -x, (0.0, 2.0), [1.0], np.linspace(0.0, 2.0, 21), [0.5, 1.5]
        )
    assert sol.success
    assert {task for task, _, _ in seen} == {"simulated time [ms]"}
    done = [d for _, d, _ in seen]
    assert done == sorted(done) and done[0] == 0 and max(done) >= 1900
    assert {total for _, _, total in seen} == {2000}
    # without a listener the right-hand side is not wrapped
    fun = lambda t, x: -x  # noqa: E731
    assert progress.tracking_time(fun, (0.0, 1.0)) is fun
