"""Batches on a Dask cluster started apart from debist, as a lab starts one on its machines.

A ``dask scheduler`` and two ``dask worker`` processes (one thread each, under a nanny), all on
the loopback interface and in this Python environment, with the address read from the
scheduler file; ``debist batch --address`` runs a fleet of two on them. Every process is
bounded in time and its process group is killed at the end, whatever happens.

References
----------
dask.distributed documentation: "Command Line" (``dask scheduler``, ``dask worker``,
``--scheduler-file``), "Why did my worker die?" (``allowed-failures``, ``KilledWorker``).
"""

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "workflows" / "paper-experiment.toml"
#: Bound on starting the scheduler and its workers [s] (a guard, not a timing test).
START_TIMEOUT = 120
#: Bound on one ``debist`` command [s].
COMMAND_TIMEOUT = 900
#: One BLAS and one free-run thread per worker process, as docs/how-to/cluster.md tells a lab.
ONE_THREAD = dict.fromkeys(
    ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"), "1"
)

pytestmark = pytest.mark.slow


def debist(*args: str, cwd: Path, timeout: float = COMMAND_TIMEOUT) -> subprocess.CompletedProcess:
    """Run the ``debist`` command of this environment in a folder (bounded in time)."""
    return subprocess.run(
        [sys.executable, "-m", "debist", *args],
        cwd=cwd, capture_output=True, text=True, timeout=timeout, check=False,
    )  # fmt: skip


@pytest.fixture(scope="module")
def made_fleet(tmp_path_factory) -> Path:
    """``debist fleet`` of the paper's experiment, two members, seed 1, made once."""
    from tests.conftest import made_once

    def make(folder: Path) -> str:
        done = debist("fleet", str(TEMPLATE), "--size", "2", "--seed", "1", "--dir", "fleet",
                      cwd=folder)  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        return ""

    folder, _ = made_once(tmp_path_factory, "cluster-fleet", make)
    return folder / "fleet"


@pytest.fixture
def fleet(made_fleet, tmp_path) -> Path:
    """This test's own copy of the fleet (its members' workflows and output folders)."""
    shutil.copytree(made_fleet, tmp_path / "fleet", symlinks=True)
    return tmp_path / "fleet"


@contextlib.contextmanager
def dask_cluster(folder: Path, *, allowed_failures: int | None = None) -> Iterator[tuple]:
    """A scheduler and two workers on 127.0.0.1, each a process group of its own.

    Yields ``(address, workers)``: the scheduler's address and the two worker commands'
    ``Popen`` objects (each the nanny of one worker process). ``allowed_failures`` sets the
    scheduler's ``distributed.scheduler.allowed-failures`` (default: distributed's own).
    """
    from distributed import Client

    env = {**os.environ, **ONE_THREAD, "DASK_DISTRIBUTED__LOGGING__DISTRIBUTED": "warning"}
    if allowed_failures is not None:
        env["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"] = str(allowed_failures)
    scheduler_file = folder / "scheduler.json"
    procs: list[subprocess.Popen] = []

    def start(module: str, *args: str, log: str) -> subprocess.Popen:
        with open(folder / log, "wb") as out:
            proc = subprocess.Popen(
                [sys.executable, "-m", module, *args], cwd=folder, env=env,
                stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
            )  # fmt: skip
        procs.append(proc)
        return proc

    try:
        start("distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
              "--no-dashboard", "--scheduler-file", str(scheduler_file),
              log="scheduler.log")  # fmt: skip
        deadline = time.monotonic() + START_TIMEOUT
        while not scheduler_file.is_file() or not scheduler_file.read_text().strip():
            assert procs[0].poll() is None, (folder / "scheduler.log").read_text()
            assert time.monotonic() < deadline, "the scheduler wrote no scheduler file"
            time.sleep(0.1)
        time.sleep(0.2)  # the file is written at once, but read it whole
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:"), address
        workers = [
            start("distributed.cli.dask_worker", "--scheduler-file", str(scheduler_file),
                  "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1",
                  "--memory-limit", "3GB", "--no-dashboard", log=f"worker-{i}.log")
            for i in range(2)
        ]  # fmt: skip
        with Client(address, timeout=START_TIMEOUT, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT)
        yield address, workers
    finally:
        for proc in procs:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)  # the nanny and its worker process
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=30)


def _listens(pid: int, port: int) -> bool:
    """Whether the process ``pid`` or one of its children listens on the TCP ``port``."""
    import psutil

    parent = psutil.Process(pid)
    for proc in (parent, *parent.children(recursive=True)):
        connections = getattr(proc, "net_connections", None) or proc.connections  # psutil < 6
        with contextlib.suppress(psutil.Error):
            if any(c.status == psutil.CONN_LISTEN and c.laddr.port == port
                   for c in connections(kind="tcp")):  # fmt: skip
                return True
    return False


def members(fleet: Path) -> list[Path]:
    found = sorted(fleet.glob("*.toml"))
    assert len(found) == 2, found
    return found


def test_a_fleet_on_a_cluster_on_loopback_gives_each_members_solo_digest(fleet):
    """Each member's run digest after the batch on the cluster is that of ``debist run`` of the
    member alone, in a copy of the fleet as ``debist fleet`` left it."""
    from debist.engine.runner import Runner
    from debist.workflow.loader import load_workflow

    root = fleet.parent
    alone = root / "alone"
    shutil.copytree(fleet, alone / fleet.name, symlinks=True)
    with dask_cluster(root) as (address, _workers):
        done = debist("batch", "fleet", "--address", address, cwd=root)
    out = done.stdout + done.stderr
    assert done.returncode == 0, out
    assert "Batch: 2 workflows, 0 failed" in done.stdout and "Traceback" not in out
    assert "thread" not in done.stderr, done.stderr  # the workers are set up as the page says
    for member in members(fleet):
        solo = debist("run", f"{fleet.name}/{member.name}", cwd=alone)
        assert solo.returncode == 0, solo.stdout + solo.stderr
        in_batch = Runner(load_workflow(member)).digest()
        assert in_batch is not None
        assert Runner(load_workflow(alone / fleet.name / member.name)).digest() == in_batch


@pytest.mark.parametrize("allowed_failures", [None, 0])
def test_a_worker_killed_mid_batch_is_reported_and_loses_nothing(fleet, allowed_failures):
    """SIGKILL to the process group of the worker that runs a member (a node that dies): by the
    scheduler's ``allowed-failures`` (distributed's default 3) the member is retried on the
    other worker and done, or (0) failed with ``KilledWorker``; the other member finishes."""
    from distributed import Client

    from debist.engine.runner import Runner
    from debist.workflow.loader import load_workflow

    root = fleet.parent
    with dask_cluster(root, allowed_failures=allowed_failures) as (address, workers):
        batch = subprocess.Popen(
            [sys.executable, "-m", "debist", "batch", "fleet", "--address", address],
            cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            start_new_session=True,
        )  # fmt: skip
        try:
            with Client(address, timeout=START_TIMEOUT, set_as_default=False) as client:
                # the fleet ran rig and ingest: wait until a member is past differentiate
                deadline = time.monotonic() + COMMAND_TIMEOUT
                while not (past := list(fleet.glob("runs/*/differentiate/manifest.json"))):
                    assert batch.poll() is None, batch.communicate()
                    assert time.monotonic() < deadline, "no member got past differentiate"
                    time.sleep(0.05)
                killed = past[0].parents[1].name  # the member's output folder is its stem
                (worker,) = [w for w, keys in client.processing().items()
                             if any(f"-{killed}-" in k for k in keys)]  # fmt: skip
            # its process: the one listening on the worker's port (not Client.run(os.getpid),
            # whose signature parse on the worker's event loop can race the task's ast.parse
            # in CPython 3.11: "SystemError: AST constructor recursion depth mismatch")
            (victim,) = [p for p in workers if _listens(p.pid, int(worker.rsplit(":", 1)[1]))]
            os.killpg(victim.pid, signal.SIGKILL)  # the nanny and the worker: the node is gone
            out, errs = batch.communicate(timeout=COMMAND_TIMEOUT)
        finally:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(batch.pid, signal.SIGKILL)
            batch.wait(timeout=30)
    said = f"exit {batch.returncode}\n{out}{errs}"
    assert "Traceback" not in out + errs, said
    text = " ".join(out.split())  # the table wraps its columns
    if allowed_failures == 0:
        assert batch.returncode == 1, said
        assert "Batch: 2 workflows, 1 failed" in out, said
        assert "KilledWorker" in text and "died" in text, said
        assert any(killed in row and " failed " in row for row in out.splitlines()), said
    else:
        assert batch.returncode == 0, said
        assert "Batch: 2 workflows, 0 failed" in out, said
        assert "its worker process died" in text and "retried on a" in text, said
        note = "its worker process died once (killed or out of memory); retried on a fresh one"
        assert note in (fleet / "runs" / "index.html").read_text(), said  # the index, unwrapped
    # nothing is lost: the other member is whole, and the stages the killed one finished
    # before the kill stay valid (up to date), whatever happened to the stage cut short
    for member in members(fleet):
        runner = Runner(load_workflow(member))
        status = debist("status", str(member), cwd=root)
        if member.stem != killed or allowed_failures != 0:
            assert status.returncode == 0 and runner.digest() is not None, status.stdout
            assert runner.verify() == [], member.name
            continue
        states = {s.stage: s.state for s in runner.status()}
        finished = list(states)[: list(states).index("differentiate") + 1]
        assert {stage: states[stage] for stage in finished} == dict.fromkeys(
            finished, "up to date"
        ), status.stdout
