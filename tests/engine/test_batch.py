"""Batch runs on Dask: serial and parallel give the same bytes, failures stay per item, caching."""

import gzip
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from debist.core import artifacts
from debist.core.errors import DebistWarning, WorkflowError
from debist.engine.batch import (
    INDEX_MARKER,
    BatchResult,
    check_cluster_workers,
    expand_workflows,
    index_is_ours,
    local_cluster,
    run_batch,
    summary_table,
    write_index,
)
from debist.engine.outdir import OWN_FILES

ROOT = Path(__file__).resolve().parents[2]
STAGES = ["ingest", "differentiate", "identify", "validate"]
NAMES = ["proto-a", "proto-b", "proto-c"]

WORKFLOW = """
[workflow]
name = "{name}"
output_dir = "runs/{name}"

[ingest]
format = "csv"
sample_time = 1.6384e-3
q = {{ column = {q_column}, unit = "V" }}
v1 = {{ column = 0, unit = "V" }}

[datasets.estimation]
source = "{source}"
role = "estimation"
slice = [{start}, {stop}]

[datasets.check]
source = "{source}"
slice = [7000, 8000]

[differentiate]
method = "spectral"
cutoff_hz = 290.0
taper = 0.1

[identify]
M = {M}
sigma_n = 0.5
input_map = "v"
rbf = ["c"]
backbone = ["linear_spring", "cubic_spring", "viscous", "offset", "input_gain"]
T_z = 0.0
trim = 100

[validate]
substeps = 1
input_interpolation = "linear"
init_samples = 50
report_unit = "mV"
"""


def write_workflow(folder, name, *, start=0, stop=3000, M=4, q_column=1, source="rig.csv"):
    path = folder / f"{name}.toml"
    path.write_text(
        WORKFLOW.format(name=name, start=start, stop=stop, M=M, q_column=q_column, source=source)
    )
    return path


@pytest.fixture
def protos(tmp_path):
    """Three prototypes: overlapping 3000-sample slices of the Silverbox estimation record."""
    with gzip.open(ROOT / "data/silverbox/SNLS80mV.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()
    (tmp_path / "rig.csv").write_text("\n".join(lines[40650:48650]) + "\n")
    return [
        write_workflow(tmp_path, name, start=start, stop=start + 3000, M=M)
        for name, start, M in zip(NAMES, (0, 2000, 4000), (4, 5, 6), strict=True)
    ]


def file_hashes(root):
    """sha256 of every stage output: not the manifests, wall times, output marker and lock."""
    skip = {artifacts.MANIFEST, artifacts.TIMINGS, *OWN_FILES}
    return {
        p.relative_to(root).as_posix(): artifacts.sha256_file(p)
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in skip
    }


@pytest.mark.slow
def test_processes_write_the_bytes_of_a_serial_run_and_a_rerun_skips_everything(protos):
    runs = protos[0].parent / "runs"
    serial = run_batch(protos, stages=STAGES, scheduler="synchronous")
    assert [r.name for r in serial] == NAMES and all(r.ok for r in serial), serial
    assert all(r.ran == tuple(STAGES) for r in serial)
    assert all(r.worker == f"{os.uname().nodename}:{os.getpid()}" for r in serial)
    serial_files = file_hashes(runs)
    # ingest 2, differentiate 2, identify 2 + plot + design 3 (equilibria, switching, static),
    # validate nrmse + residuals + 2 simulated (the report draws them), a summary each
    assert len(serial_files) == 3 * 18  # 18 artifacts per prototype
    # the manifests' output hashes are those of the files on disk
    for r in serial:
        for stage, outputs in r.outputs.items():
            for rel, digest in outputs.items():
                assert serial_files[f"{r.name}/{stage}/{rel}"] == digest
    # different prototypes, different models
    assert len({r.outputs["identify"]["model.h5"] for r in serial}) == 3
    rows = {row["dataset"]: row for row in serial[0].summary["nrmse"]}
    assert set(rows) == {"estimation", "check"}
    assert 0 < rows["check"]["nrmse_q"] < 0.1 and rows["check"]["rms_unit"] == "mV"

    shutil.rmtree(runs)
    done = []
    parallel = run_batch(
        protos, stages=STAGES, scheduler="processes", workers=2, on_done=done.append
    )
    assert [r.name for r in parallel] == NAMES and all(r.ok for r in parallel), parallel
    assert all(r.ran == tuple(STAGES) for r in parallel)  # really ran again
    assert sorted(r.name for r in done) == NAMES  # one callback per workflow
    assert not {r.worker for r in parallel} & {serial[0].worker}  # in worker processes
    assert [r.outputs for r in parallel] == [r.outputs for r in serial]
    assert file_hashes(runs) == serial_files

    again = run_batch(protos, stages=STAGES, scheduler="threads", workers=2)
    assert all(r.ok and r.ran == () and r.skipped == tuple(STAGES) for r in again)
    assert [r.outputs for r in again] == [r.outputs for r in serial]
    assert again[0].summary == parallel[0].summary
    table = summary_table(again)
    assert list(table.name) == NAMES
    assert list(table.file) == [str(p) for p in protos]  # outside the current directory
    assert (table.ran == 0).all() and (table.skipped == 4).all() and (table.status == "done").all()


def test_broken_workflows_fail_alone_naming_their_files(protos):
    folder = protos[0].parent
    bad_channel = write_workflow(folder, "bad-channel", q_column=5)
    no_source = write_workflow(folder, "no-source", source="missing.csv")
    paths = [protos[0], bad_channel, protos[1], no_source]
    results = run_batch(paths, stages=["ingest", "differentiate"], workers=2)
    assert [r.status for r in results] == ["done", "failed", "done", "failed"]
    by_name = {r.name: r for r in results}

    channel = by_name["bad-channel"]
    assert channel.error.startswith("RigLogError: ") and "rig.csv" in channel.error
    assert "channel 'column 5'" in channel.error
    assert channel.failed_stage == "ingest" and channel.traceback == ""
    assert channel.outputs == {} and not (folder / "runs/bad-channel/ingest").exists()

    source = by_name["no-source"]
    assert source.error.startswith("WorkflowError: ")
    assert "no-source.toml" in source.error and "missing.csv" in source.error
    assert source.failed_stage == "" and source.events == () and source.output_dir is None

    for good in (results[0], results[2]):
        assert good.ran == ("ingest", "differentiate")
        assert (good.output_dir / "differentiate/check.parquet").is_file()

    table = summary_table(results)
    assert list(table.status) == ["done", "failed", "done", "failed"]
    assert list(table.failed_stage) == ["", "ingest", "", ""]
    assert table.error[1] == channel.error and table.path[3] == str(no_source)


def test_unexpected_exception_is_a_failed_item_with_its_traceback(protos, monkeypatch):
    import debist.engine.runner as runner

    def flaky(point, workflow=None):  # the runner's fault point as a stage starts
        if point == "stage:differentiate:start" and workflow == "proto-b":
            raise ZeroDivisionError("synthetic fault")

    monkeypatch.setattr(runner, "fault_point", flaky)
    results = run_batch(protos, stages=["ingest", "differentiate"], scheduler="synchronous")
    assert [r.status for r in results] == ["done", "failed", "done"]
    failed = results[1]
    assert failed.error.startswith("ZeroDivisionError: ") and failed.error.endswith("fault")
    assert "Traceback" in failed.traceback and "flaky" in failed.traceback
    assert [(e.stage, e.action) for e in failed.events] == [
        ("ingest", "ran"),
        ("differentiate", "failed"),
    ]


def test_dask_progress_bar_and_callbacks(protos, capsys):
    seen = []
    results = run_batch(
        protos[:2], stages=["ingest"], scheduler="synchronous", on_done=seen.append, progress=True
    )
    assert sorted(seen, key=lambda r: r.name) == results  # dask picks the order of execution
    out = capsys.readouterr().out
    assert "100% Completed" in out  # dask.diagnostics.ProgressBar


def test_arguments_are_checked_before_anything_runs(protos):
    folder = protos[0].parent
    with pytest.raises(WorkflowError) as err:
        run_batch(protos, scheduler="cluster")
    assert "'cluster'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        run_batch(protos, stages=["ingest", "identfy"])
    assert "'identfy'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        run_batch(protos, scheduler="threads", address="tcp://127.0.0.1:8786")
    assert "'distributed'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        run_batch(protos, workers=0)
    assert "least 1" in str(err.value)
    twin = folder / "twin.toml"
    twin.write_text(protos[1].read_text())  # same name, same output_dir
    with pytest.raises(WorkflowError) as err:
        run_batch([protos[0], protos[1], twin], scheduler="synchronous")
    assert "same" in str(err.value) and "directory" in str(err.value)
    assert "proto-b.toml" in str(err.value) and "twin.toml" in str(err.value)
    assert not (folder / "runs").exists()
    assert run_batch([]) == []


def test_worker_processes_without_the_distributed_package_say_how_to_install_it(
    protos, monkeypatch
):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    for scheduler in ("processes", "distributed"):
        with pytest.raises(WorkflowError) as err:
            run_batch(protos, scheduler=scheduler)
        assert "pip" in str(err.value) and "distributed" in str(err.value)
    assert not (protos[0].parent / "runs").exists()


def test_expand_workflows_files_directories_and_patterns(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a/sub").mkdir()
    (tmp_path / "empty").mkdir()
    for rel in ("a/2.toml", "a/1.toml", "a/notes.txt", "a/sub/3.toml", "top.toml"):
        (tmp_path / rel).write_text("")
    a = tmp_path / "a"
    assert expand_workflows(a) == [a / "1.toml", a / "2.toml"]  # sorted, *.toml only
    assert expand_workflows([str(tmp_path / "top.toml"), a, a / "2.toml"]) == [
        tmp_path / "top.toml",
        a / "1.toml",
        a / "2.toml",
    ]  # argument order, duplicates dropped
    assert expand_workflows([str(tmp_path / "**/*.toml")]) == [
        a / "1.toml",
        a / "2.toml",
        a / "sub/3.toml",
        tmp_path / "top.toml",
    ]
    assert expand_workflows([str(tmp_path / "a/s*")]) == [a / "sub/3.toml"]  # a matched directory
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert expand_workflows("a/1.toml") == [a / "1.toml"]  # relative -> absolute
    finally:
        os.chdir(cwd)
    with pytest.raises(WorkflowError) as err:
        expand_workflows([str(a), str(tmp_path / "nothing*.toml")])
    assert "pattern" in str(err.value) and "file" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        expand_workflows([str(tmp_path / "missing.toml")])
    assert "missing" in str(err.value) and "exist" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        expand_workflows([tmp_path / "empty"])
    assert "holds" in str(err.value) and "toml" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        expand_workflows([])
    assert "workflow" in str(err.value) and "given" in str(err.value)


def test_local_cluster_workers_get_single_threaded_blas_unless_set_and_one_retry(monkeypatch):
    blas = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
    heap = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")
    monkeypatch.setenv("OMP_NUM_THREADS", "3")  # the user's own setting is kept
    for name in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", *heap, "ARROW_DEFAULT_MEMORY_POOL"):
        monkeypatch.delenv(name, raising=False)
    before = dict(os.environ)
    with local_cluster(2) as client:
        seen = client.run(lambda: {name: os.environ.get(name) for name in blas})
        heaps = client.run(lambda: {name: os.environ.get(name) for name in heap})
        pools = client.run(lambda: os.environ.get("ARROW_DEFAULT_MEMORY_POOL"))
        pids = client.run(os.getpid)
        retries = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.allowed_failures)
        threads = client.nthreads()
        ctrl_c = client.run(lambda: signal.getsignal(signal.SIGINT))
    assert list(ctrl_c.values()) == [signal.SIG_IGN] * 2  # the command's to handle
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # this process's
    assert (
        list(seen.values())
        == [{"OMP_NUM_THREADS": "3", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}] * 2
    )
    # glibc keeps freed arrays in the worker's heap (not dask's 64 KiB trim threshold)
    assert (
        list(heaps.values()) == [{h: str(1 << 30 if "MMAP" in h else 2**31 - 1) for h in heap}] * 2
    )
    assert list(pools.values()) == ["system"] * 2  # pyarrow allocates with malloc there too
    assert len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    assert sorted(threads.values()) == [1, 1] and retries == 1
    assert dict(os.environ) == before  # what the nannies set in this process is undone


@pytest.mark.slow
def test_a_killed_batch_worker_fails_its_workflow_only(protos, monkeypatch, capsys):
    """SIGKILL (as the out-of-memory killer sends) in proto-b's worker, on both attempts."""
    folder = protos[0].parent
    monkeypatch.chdir(folder)
    monkeypatch.setenv("DEBIST_FAULT", "stage:ingest:start@proto-b")  # inherited by workers
    done = []
    results = run_batch(
        protos, stages=["ingest", "differentiate"], workers=2, on_done=done.append, progress=True
    )
    assert [r.status for r in results] == ["done", "failed", "done"], results
    assert sorted(r.name for r in done) == NAMES
    assert "100% Completed" in capsys.readouterr().out

    killed = results[1]
    assert killed.name == "proto-b" and killed.path == protos[1] and killed.file == "proto-b.toml"
    assert killed.error == (
        "KilledWorker: worker process died twice while running it "
        "(killed by a signal or out of memory)"
    )
    assert killed.outputs == {} and killed.output_dir == folder / "runs/proto-b"
    assert artifacts.read_manifest(folder / "runs/proto-b/ingest") is None
    assert killed.worker.startswith("tcp://127.0.0.1:")  # the last of its dead workers

    for good in (results[0], results[2]):
        # A result still held by a worker that is then killed is computed again elsewhere
        # (distributed recomputes lost results): that second run finds every stage up to
        # date, so the stages ran once, in one attempt or the other.
        assert good.ran + good.skipped == ("ingest", "differentiate")
        recorded = {
            f"{stage}/{rel}": digest
            for stage, outputs in good.outputs.items()
            for rel, digest in outputs.items()
        }
        assert len(recorded) == 6 and recorded == file_hashes(good.output_dir)
        for stage in good.outputs:  # the manifests on disk vouch for the bytes on disk
            manifest = artifacts.read_manifest(good.output_dir / stage)
            assert dict(manifest.outputs) == good.outputs[stage]
            assert artifacts.changed_outputs(good.output_dir / stage, manifest) == []

    # the command line: the summary table of all three workflow files, exit 1, no traceback
    script = Path(sys.executable).with_name("debist")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "debist"]
    run = subprocess.run(
        [*command, "batch", ".", "--stages", "ingest,differentiate", "--workers", "2"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = run.stdout + run.stderr
    assert run.returncode == 1, out
    assert "Batch: 3 workflows, 1 failed" in run.stdout
    for name in NAMES:
        assert f"{name}.toml" in run.stdout
    assert "KilledWorker" in run.stdout and "died" in run.stdout  # the error column (wrapped)
    assert "Traceback" not in out


def test_a_worker_death_that_a_retry_survives_is_reported(protos, monkeypatch, tmp_path):
    monkeypatch.chdir(protos[0].parent)
    monkeypatch.setenv("DEBIST_FAULT", "stage:ingest:start@proto-b")  # its first worker only
    monkeypatch.setenv("DEBIST_FAULT_ONCE", str(tmp_path / "fired"))
    results = run_batch(protos, stages=["ingest"], workers=2, force=True)
    assert [r.status for r in results] == ["done", "done", "done"], results
    assert (tmp_path / "fired").exists()
    assert [r.worker_deaths for r in results] == [0, 1, 0]
    assert results[1].note == (
        "its worker process died once (killed or out of memory); retried on a fresh one"
    )
    frame = summary_table(results)
    assert frame.note.tolist() == ["", results[1].note, ""]
    page = write_index(results, tmp_path / "index")
    assert results[1].note in page.read_text()


#: What the workflows of the next test saw: their worker, and whether they met.
_MET: dict = {}


def _meeting_item(path, stages=None, force=False):
    """A batch item on an in-process worker: proto-a waits (bounded) for proto-b to start."""
    import threading

    from distributed import get_worker

    import debist.engine.batch as batch

    name = Path(path).stem
    _MET[name] = get_worker().address
    if name == "proto-b":
        _MET["event"].set()
    if name == "proto-a":
        _MET["met"] = _MET["event"].wait(timeout=60)  # a guard: the test fails without b
    assert isinstance(_MET["event"], threading.Event)
    return batch.BatchResult(path=Path(path), name=name, status="done", seconds=0.0)


def test_workers_that_join_a_cluster_late_get_workflows_at_once(protos, monkeypatch):
    """A batch started before its SLURM jobs run: workers that join later get workflows
    while the first ones still run, not only as each one finishes."""
    import threading

    import distributed

    import debist.engine.batch as batch

    monkeypatch.setattr(batch, "run_workflow_item", _meeting_item)
    monkeypatch.setattr(batch, "_REFILL_SECONDS", 0.2)
    monkeypatch.setitem(_MET, "event", threading.Event())
    with distributed.LocalCluster(n_workers=0, threads_per_worker=1, processes=False,
                                  dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        out = {}
        runner = threading.Thread(
            target=lambda: out.update(
                results=run_batch(protos[:2], address=cluster.scheduler_address)
            )
        )
        runner.start()
        try:
            deadline = time.monotonic() + 60
            while not cluster.scheduler.tasks and time.monotonic() < deadline:
                time.sleep(0.02)  # proto-a is submitted to a cluster without workers
            assert len(cluster.scheduler.tasks) == 1
            cluster.scale(2)
        finally:
            runner.join(timeout=120)
    assert not runner.is_alive()
    assert [r.name for r in out["results"]] == ["proto-a", "proto-b"]
    assert _MET["met"] is True and _MET["proto-a"] != _MET["proto-b"]


def test_cluster_workers_with_several_threads_are_warned_about(monkeypatch):
    """A cluster the user started: workers of several threads, or free runs on several."""
    import warnings

    import distributed

    from debist.simulate import kernel

    monkeypatch.setattr(kernel, "kernel_threads", lambda: 1)  # the in-process workers' own
    for threads in (1, 2):
        with (
            distributed.LocalCluster(n_workers=1, threads_per_worker=threads, processes=False,
                                     dashboard_address="127.0.0.1:0") as cluster,
            distributed.Client(cluster, set_as_default=False) as client,
            warnings.catch_warnings(record=True) as shown,
        ):  # fmt: skip
            warnings.simplefilter("always")
            said = check_cluster_workers(client)
            monkeypatch.setattr(kernel, "kernel_threads", lambda: 3)
            wide = check_cluster_workers(client)
            monkeypatch.setattr(kernel, "kernel_threads", lambda: 1)
        if threads == 1:
            assert said == []
        else:
            assert len(said) == 1 and "more than one thread" in said[0]
            assert said[0].endswith("start the workers with --nthreads 1")
        assert wide[:-1] == said and "NUMBA_NUM_THREADS=1" in wide[-1] and ", 3)" in wide[-1]
        assert [str(w.message) for w in shown] == said + wide
        assert all(w.category is DebistWarning for w in shown)


@pytest.mark.slow
def test_local_dask_cluster_gives_the_serial_bytes(protos):
    import distributed

    runs = protos[0].parent / "runs"
    serial = run_batch(protos, stages=STAGES, scheduler="synchronous")
    serial_files = file_hashes(runs)
    shutil.rmtree(runs)
    # threads_per_worker=1: the validate stage draws with pyplot, which is not thread-safe
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        done = []
        results = run_batch(
            protos, stages=STAGES, address=cluster.scheduler_address, on_done=done.append
        )
    assert [r.name for r in results] == NAMES and all(r.ok for r in results), results
    assert all(isinstance(r, BatchResult) and r.ran == tuple(STAGES) for r in results)
    assert sorted(r.name for r in done) == NAMES
    assert [r.outputs for r in results] == [r.outputs for r in serial]
    assert file_hashes(runs) == serial_files


@pytest.mark.slow
def test_a_task_lost_on_the_cluster_is_a_failed_item(protos, monkeypatch):
    import distributed

    import debist.engine.batch as batch

    item = batch.run_workflow_item

    def lost(path, stages=None, force=False):
        if Path(path).stem == "proto-b":  # fails outside the item's own error capture
            raise MemoryError("worker out of memory")
        return item(path, stages, force)

    monkeypatch.setattr(batch, "run_workflow_item", lost)
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        results = run_batch(protos, stages=["ingest"], address=cluster.scheduler_address)
    assert [r.status for r in results] == ["done", "failed", "done"]
    assert results[1].error.startswith("MemoryError: ") and "memory" in results[1].error
    assert results[1].name == "proto-b" and results[1].path == protos[1]


@pytest.mark.slow
def test_a_batch_member_has_the_digest_of_its_solo_run(tmp_path, monkeypatch,
                                                       paper_experiment_run):  # fmt: skip
    """The paper experiment in a test process (the session's solo run, through the CLI) and in
    a batch worker process (single-threaded BLAS there): the bootstrap bands' sums gave bytes
    6.6e-24 apart before stages ran with one BLAS thread everywhere."""
    from debist.engine.runner import Runner
    from debist.workflow.loader import load_workflow

    root = Path(__file__).resolve().parents[2]
    shipped = root / "workflows" / "paper-experiment.toml"
    wf = tmp_path / shipped.name  # the report names the workflow file: the same name
    wf.write_text(
        shipped.read_text().replace(
            'output_dir = "../runs/paper-experiment"', 'output_dir = "batch"'
        )
    )
    monkeypatch.chdir(tmp_path)
    (result,) = run_batch([wf], workers=1)
    assert result.ok, result.error
    batch = Runner(load_workflow(wf)).digest()
    solo, _ = paper_experiment_run
    assert batch is not None
    assert Runner(load_workflow(shipped, solo)).digest() == batch


def test_the_batch_index_never_replaces_a_users_index_html(protos, monkeypatch):
    """Output folders in a user's web folder: the batch writes its index only where it may."""
    from tests.conftest import invoke_cli

    root = protos[0].parent
    monkeypatch.chdir(root)
    for path in protos[:2]:
        text = path.read_text().replace('output_dir = "runs/', 'output_dir = "../web/run-')
        path.write_text(text)
    web = root.parent / "web"
    web.mkdir()
    mine = b"<!DOCTYPE html><title>Lab 4: actuators</title><p>our rig</p>\n"
    (web / "index.html").write_bytes(mine)
    code, out = invoke_cli("batch", *protos[:2], "--stages", "ingest", "--scheduler", "synchronous")
    assert code == 0, out
    assert (web / "index.html").read_bytes() == mine  # kept, byte for byte
    assert not (web / INDEX_MARKER).exists()
    lines = [line for line in out.splitlines() if "batch index not written" in line]
    assert len(lines) == 1 and str(web / "index.html") in lines[0], out
    assert "index of the reports" not in out
    # without the user's page the index goes there, and a later batch replaces its own page
    (web / "index.html").unlink()
    code, out = invoke_cli("batch", *protos[:2], "--stages", "ingest", "--scheduler", "synchronous")
    assert code == 0 and f"index of the reports: {web / 'index.html'}" in out, out
    assert index_is_ours(web) and "proto-b" in (web / "index.html").read_text()
    # a page of debist's that the user edited is theirs now
    with open(web / "index.html", "a", encoding="utf-8") as fh:
        fh.write("<p>notes</p>\n")
    edited = (web / "index.html").read_bytes()
    assert not index_is_ours(web)
    code, out = invoke_cli("batch", *protos[:2], "--stages", "ingest", "--scheduler", "synchronous")
    assert code == 0 and "batch index not written" in out, out
    assert (web / "index.html").read_bytes() == edited


def test_an_index_html_of_an_older_debist_is_recognised_by_its_title(tmp_path):
    assert index_is_ours(tmp_path)  # nothing there
    (tmp_path / "index.html").write_text("<!DOCTYPE html>\n<html>\n<title>debist batch: 3 p")
    assert index_is_ours(tmp_path)  # no record: an older debist's page
    (tmp_path / "index.html").write_text("<html><title>Lab</title></html>")
    assert not index_is_ours(tmp_path)
    (tmp_path / "index.html").unlink()
    (tmp_path / "index.html").symlink_to(tmp_path / "elsewhere.html")
    assert not index_is_ours(tmp_path)  # a link: whatever it points to is not replaced


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "group", "code", "what"),
    [
        (signal.SIGTERM, False, 143, "interrupted by SIGTERM"),
        (signal.SIGINT, True, 130, "interrupted"),
    ],
)
def test_a_stopped_batch_says_so_in_one_line_without_worker_tracebacks(
    protos, sig, group, code, what
):
    """SIGTERM to the command, or a terminal's Ctrl-C to its whole process group (the local
    cluster's workers too): one line, exit 143 or 130, and a rerun finishes the batch."""
    import psutil

    root = protos[0].parent
    cmd = [sys.executable, "-m", "debist", "batch", *map(str, protos), "--stages", ",".join(STAGES)]
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not list(root.glob("runs/*/ingest/manifest.json")) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()  # a worker is running a workflow now
        workers = psutil.Process(proc.pid).children(recursive=True)
        os.killpg(proc.pid, sig) if group else os.kill(proc.pid, sig)
        out, errs = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == code, errs
    line = (
        f"{what}: stopped; the workflows' finished stages are kept (each stage is written "
        "whole, and a stage cut short left nothing that counts); run the same batch again to "
        "finish the rest"
    )
    assert errs.count(line) == 1 and "Traceback" not in errs and "KeyboardInterrupt" not in errs
    assert "Batch:" not in out  # no summary table, no index of a batch that did not end
    assert not (root / "runs" / "index.html").exists()
    _gone, alive = psutil.wait_procs(workers, timeout=30)
    assert not alive  # the cluster's worker processes went with it
    # what was written stays valid: the rerun finishes the batch
    again = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stdout + again.stderr
    for name in NAMES:
        assert (root / "runs" / name / "validate" / "manifest.json").is_file()
