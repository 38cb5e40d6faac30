"""A stage's work in a forked process beside the others: result, errors, warnings, stop."""

import os
import signal
import time
import warnings

import pytest

from debist.core.beside import BesideRun
from debist.core.errors import ArtifactError, IdentificationError
from debist.core.forking import fork_workers
from debist.core.progress import listening, report

pytestmark = pytest.mark.skipif(
    fork_workers(2) < 2, reason="needs POSIX fork, the main thread and two cores"
)


def test_the_result_comes_from_another_process():
    run = BesideRun(lambda: (os.getpid(), sum(range(1000))), "sum")
    pid, total = run.result()
    assert pid != os.getpid() and total == 499500


def test_a_niceness_lowers_the_childs_priority_and_leaves_this_process_alone():
    """POSIX nice values: the child's is this process's plus the niceness (at most 19);
    without one it is this process's."""
    mine = os.nice(0)
    assert BesideRun(lambda: os.nice(0), "study", niceness=5).result() == min(mine + 5, 19)
    assert BesideRun(lambda: os.nice(0), "the NARX peer").result() == mine
    assert os.nice(0) == mine


def test_what_the_child_raises_is_raised_here_with_its_type_and_fields():
    def fail():
        raise IdentificationError("too few samples in well 2", reason="under-excited")

    with pytest.raises(IdentificationError, match="too few samples in well 2") as info:
        BesideRun(fail, "stage 'study'").result()
    assert info.value.reason == "under-excited"


def test_a_child_killed_halfway_is_an_artifact_error_naming_it():
    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    with pytest.raises(ArtifactError, match=r"stage 'study' .*exit code -9"):
        BesideRun(die, "stage 'study'").result()


def test_the_childs_warnings_are_issued_here_and_its_progress_is_not_drawn():
    seen = []

    def work():
        report("study: grid", 1, 2)  # a listener inherited from the parent must not hear it
        warnings.warn("sigma_n = 3 overlaps every centre", RuntimeWarning, stacklevel=1)
        return 7

    with listening(lambda *a: seen.append(a)):
        run = BesideRun(work, "study")
        with pytest.warns(RuntimeWarning, match="overlaps every centre"):
            assert run.result() == 7
    assert seen == []


def test_stop_ends_a_child_that_still_runs():
    run = BesideRun(lambda: time.sleep(60), "sleeper")
    t0 = time.perf_counter()
    run.stop()
    assert time.perf_counter() - t0 < 10
    assert run._proc.exitcode is not None and run._proc.exitcode != 0


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads process states in /proc")
def test_a_grandchild_whose_parent_was_stopped_ends_instead_of_waiting_for_a_reader(tmp_path):
    """A child that started its own BesideRun is stopped: the grandchild's result (larger
    than a pipe holds) finds no reader, and the grandchild ends rather than block forever."""
    marker = tmp_path / "grandchild.pid"

    def parent():
        def grandchild():
            marker.write_text(str(os.getpid()))
            time.sleep(0.5)  # the parent is stopped meanwhile
            return b"x" * 1_000_000

        BesideRun(grandchild, "grandchild").result()

    run = BesideRun(parent, "parent")
    while not marker.exists():
        time.sleep(0.05)
    run.stop()
    pid = int(marker.read_text())
    deadline = time.perf_counter() + 20
    while time.perf_counter() < deadline and _alive(pid):
        time.sleep(0.1)
    ended = not _alive(pid)
    if not ended:
        os.kill(pid, signal.SIGKILL)  # it holds this process's output open
    assert ended


def _alive(pid):
    """Whether a process runs (a zombie, ended but not reaped by init yet, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_one_core_keeps_the_block_from_forking():
    from debist.core.forking import one_core

    with one_core():
        assert fork_workers(2) == 1
        with one_core():
            assert fork_workers(4) == 1
        assert fork_workers(2) == 1
    assert fork_workers(2) == 2


# -- stop signals: one line from the parent, never a child's traceback -------------------------

_SIGNALLED = """
import os, signal, sys, time
from debist.cli import _on_sigterm
from debist.core.beside import BesideRun

signal.signal(signal.SIGTERM, _on_sigterm)  # as the command line installs it
marker, mode = sys.argv[1], sys.argv[2]

def work():
    open(marker, "w").close()
    if mode == "send":  # more than a pipe holds: the child waits in its send
        return b"x" * 8_000_000
    time.sleep(60)

run = BesideRun(work, "stage 'compare' (first part)")
try:
    time.sleep(60)  # this process is busy with another stage
except KeyboardInterrupt as exc:
    run.stop()
    print("stopped", run._proc.exitcode, file=sys.stderr)
    sys.exit(getattr(exc, "code", 130))
"""


def _signal_group(tmp_path, script, args, signum):
    """Start ``script`` in a session of its own, wait for its marker, signal the whole group
    (as a terminal's Ctrl-C does); return (exit code, stderr, processes left in the group)."""
    import subprocess
    import sys

    marker = tmp_path / "started"
    proc = subprocess.Popen(
        [sys.executable, "-c", script, str(marker), *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        for _ in range(600):
            if marker.exists() or proc.poll() is not None:
                break
            time.sleep(0.05)
        assert marker.exists(), proc.communicate(timeout=60)
        time.sleep(0.3)  # the child reaches its wait (in fn, or in its send)
        os.killpg(proc.pid, signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    time.sleep(0.2)
    left = subprocess.run(
        ["ps", "-o", "pid=", "-g", str(proc.pid)], capture_output=True, text=True
    ).stdout.split()
    return proc.returncode, err, left


@pytest.mark.parametrize("mode", ["work", "send"])
@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_to_the_group_stops_parent_and_child_without_a_childs_traceback(
    tmp_path, mode, signum, code
):
    """Ctrl-C (SIGINT to every process of the group) or SIGTERM while the child computes or
    waits to send a result larger than a pipe: the parent ends with 128 + signal, the child
    ends (no process is left) and prints nothing."""
    returncode, err, left = _signal_group(tmp_path, _SIGNALLED, [mode], signum)
    assert returncode == code, err
    assert err.splitlines()[-1].startswith("stopped"), err
    assert "Traceback" not in err and "Process " not in err, err
    assert len(err.splitlines()) == 1, err
    assert left == []


_POOL = """
import sys, time
from debist.core.forking import worker_pool

marker = sys.argv[1]
try:
    with worker_pool(2) as pool:
        jobs = [pool.submit(time.sleep, 0.5) for _ in range(40)]
        open(marker, "w").close()
        done = [job.result() for job in jobs]
except KeyboardInterrupt:
    print("cancelled", sum(job.cancelled() for job in jobs), file=sys.stderr)
    sys.exit(130)
"""


def test_a_ctrl_c_stops_a_worker_pool_quietly_and_cancels_the_jobs_not_started(tmp_path):
    """The workers ignore the group's SIGINT; the parent cancels what has not started, the
    running jobs finish, and no worker prints a traceback."""
    returncode, err, left = _signal_group(tmp_path, _POOL, [], signal.SIGINT)
    assert returncode == 130, err
    assert "Traceback" not in err and "Process " not in err, err
    (line,) = err.splitlines()
    assert line.startswith("cancelled") and int(line.split()[1]) > 0
    assert left == []
