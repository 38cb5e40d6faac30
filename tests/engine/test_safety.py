"""Artifacts that never lose a user's file or vouch for a forged result.

Every case a new user met on the earlier main: user files in stage-named folders, forbidden
output folders, runs killed between two file-system operations (injected through
``DEBIST_FAULT``, not sleeps), SIGTERM, two runs on one folder, tampered artifacts,
manifests and summaries, and reproducibility across clones.
"""

import gzip
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core import artifacts
from debist.engine import outdir
from debist.engine.fingerprint import code_fingerprint, module_closure
from debist.stages.registry import STAGES

ROOT = Path(__file__).resolve().parents[2]

WORKFLOW = """
[workflow]
name = "safety"
output_dir = "out"

[ingest]
format = "csv"
sample_time = 1.6384e-3
q = { column = 1, unit = "V" }
v1 = { column = 0, unit = "V" }

[datasets.estimation]
source = "data/rig.csv"
role = "estimation"
slice = [0, 2500]

[datasets.check]
source = "data/rig.csv"
slice = [2500, 4000]

[differentiate]
method = "spectral"
cutoff_hz = 290.0
taper = 0.1

[identify]
M = 4
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

[compare]
degree = 3
"""
#: Files that differ between two identical runs by design (not results).
VOLATILE = {artifacts.TIMINGS, outdir.LOCK, outdir.HOLDER}


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result.exit_code, result.output


def debist(*args, cwd, fault=None):
    """The CLI in its own process (its real entry point, with the SIGTERM handler)."""
    env = {k: v for k, v in os.environ.items() if k != "DEBIST_FAULT"}
    if fault:
        env["DEBIST_FAULT"] = fault
    return subprocess.run(
        [sys.executable, "-m", "debist", *map(str, args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def hashes(root):
    return {
        p.relative_to(root).as_posix(): artifacts.sha256_file(p)
        for p in sorted(Path(root).rglob("*"))
        if p.is_file() and p.name not in VOLATILE
    }


def make_project(folder):
    (folder / "data").mkdir(parents=True)
    with gzip.open(ROOT / "data/silverbox/SNLS80mV.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()
    (folder / "data/rig.csv").write_text("\n".join(lines[40650:44650]) + "\n")
    (folder / "wf.toml").write_text(WORKFLOW)
    return folder


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """A project that has run once: data, workflow, output folder (made once for all
    pytest-xdist workers; copied by :func:`project`)."""
    from tests.conftest import made_once

    def make(folder):
        root = make_project(folder / "project")
        code, out = invoke("run", root / "wf.toml")
        assert code == 0, out
        return ""

    folder, _ = made_once(tmp_path_factory, "safety-template", make)
    return folder / "project"


@pytest.fixture
def project(template, tmp_path):
    dest = tmp_path / "project"
    shutil.copytree(template, dest)
    return dest


@pytest.fixture
def fresh(tmp_path):
    return make_project(tmp_path / "fresh")


def digest_of(out_text):
    return next(line.split()[-1] for line in out_text.splitlines() if line.startswith("run digest"))


# ------------------------------------------------------------------ ownership


@pytest.mark.parametrize("stage", ["ingest", "validate", "compare"])
def test_user_file_in_a_stage_named_folder_is_refused_and_kept(fresh, stage):
    notes = fresh / "mine" / stage / "my_notes.txt"
    notes.parent.mkdir(parents=True)
    notes.write_text("x")
    code, out = invoke("ingest", fresh / "wf.toml", "--out", fresh / "mine")
    assert code == 2
    assert "mine" in out and "not debist's" in out
    assert notes.read_text() == "x"
    assert sorted(p.name for p in (fresh / "mine").iterdir()) == [stage]


def test_foreign_file_in_a_stage_folder_of_a_run_is_named_and_nothing_moves(project):
    before = hashes(project / "out")
    notes = project / "out/validate/notes.txt"
    notes.write_text("my notes")
    code, out = invoke("run", project / "wf.toml", "--force")
    assert code == 2
    assert "notes.txt" in out and "write" in out
    assert notes.read_text() == "my notes"
    after = hashes(project / "out")
    assert after.pop("validate/notes.txt") and after == before
    code, out = invoke("status", project / "wf.toml")
    assert "notes.txt" in out


def test_forbidden_output_folders_are_refused_before_anything_is_written(fresh, monkeypatch):
    wf = fresh / "wf.toml"
    code, out = invoke("ingest", wf, "--out", "/")
    assert code == 2 and "root" in out
    own = fresh / "own.toml"
    own.write_text(WORKFLOW.replace('output_dir = "out"', 'output_dir = ""'))
    code, out = invoke("ingest", own)
    assert code == 2 and "output_dir" in out
    code, out = invoke("ingest", wf, "--out", fresh)
    assert code == 2 and "folder" in out and "own" in out
    code, out = invoke("ingest", wf, "--out", fresh / "data")
    assert code == 2 and "source" in out
    home = fresh / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    code, out = invoke("ingest", wf, "--out", home)
    assert code == 2 and "home" in out
    assert sorted(p.name for p in fresh.iterdir()) == ["data", "home", "own.toml", "wf.toml"]
    assert sorted(p.name for p in (fresh / "data").iterdir()) == ["rig.csv"]


def test_folder_of_another_workflow_is_refused(project):
    other = project / "other.toml"
    other.write_text(WORKFLOW.replace('name = "safety"', 'name = "other"'))
    before = hashes(project / "out")
    code, out = invoke("run", other)
    assert code == 2 and "belongs" in out and "wf.toml" in out
    assert hashes(project / "out") == before


def test_another_workflow_file_with_the_same_name_is_refused_too(project):
    twin = project / "twin.toml"  # same [workflow] name "safety", another file
    twin.write_text(WORKFLOW.replace("[differentiate]", "[differentiate]\n# another workflow"))
    before = hashes(project / "out")
    code, out = invoke("run", twin)
    assert code == 2 and "belongs" in out and "twin.toml" in out
    assert hashes(project / "out") == before
    # the owner itself, edited, still runs into its own folder
    (project / "wf.toml").write_text((project / "wf.toml").read_text() + "\n# edited\n")
    code, out = invoke("run", project / "wf.toml")
    assert code == 0, out


def test_failed_first_run_leaves_no_folder(fresh):
    (fresh / "wf.toml").write_text(WORKFLOW.replace("column = 0", "column = 7"))
    code, out = invoke("run", fresh / "wf.toml")
    assert code == 1 and "rig.csv" in out
    assert not (fresh / "out").exists()


@pytest.mark.parametrize("how", ["replaced", "written in place"])
def test_a_source_changed_while_ingest_reads_it_is_refused_and_nothing_recorded(
    fresh, monkeypatch, how
):
    """The manifest's source hash must describe the bytes ingest read, or nothing is written."""
    import hashlib

    import debist.stages.ingest as ingest_stage

    source = fresh / "data/rig.csv"
    original = source.read_bytes()
    other = original.replace(b"0", b"2", 50)  # another recording of the same shape
    read = ingest_stage.read_raw

    def changing(path, spec):  # another program changes the log as ingest opens it
        if source.read_bytes() == original:
            if how == "replaced":
                (fresh / "data/new.csv").write_bytes(other)
                os.replace(fresh / "data/new.csv", source)
            else:
                with open(source, "r+b") as fh:
                    fh.write(other)
        return read(path, spec)

    monkeypatch.setattr(ingest_stage, "read_raw", changing)
    code, out = invoke("run", fresh / "wf.toml")
    lines = [line for line in out.splitlines() if line.startswith("error:")]
    assert code == 1 and len(lines) == 1, out
    assert f"'{source}'" in lines[0] and "while ingest read it" in lines[0]
    assert not (fresh / "out").exists()  # no table, no manifest
    # the file is stable now: the next run records exactly the bytes it ingests
    monkeypatch.setattr(ingest_stage, "read_raw", read)
    code, out = invoke("run", fresh / "wf.toml", "--stages", "ingest")
    assert code == 0, out
    manifest = json.loads((fresh / "out/ingest/manifest.json").read_text())
    assert manifest["inputs"]["estimation:source"] == hashlib.sha256(other).hexdigest()
    table = pd.read_parquet(fresh / "out/ingest/estimation.parquet")
    first = other.decode().splitlines()[0].split(",")
    assert table["v1"].iloc[0] == pytest.approx(float(first[0]))
    assert table["q"].iloc[0] == pytest.approx(float(first[1]))


def test_file_identity_tells_a_replaced_or_rewritten_file(tmp_path):
    from debist.core.fileformats import file_identity, sha256_identified

    path = tmp_path / "log.csv"
    path.write_bytes(b"1,2\n")
    digest, identity = sha256_identified(path)
    assert digest == artifacts.sha256_file(path) and identity == file_identity(path)
    (tmp_path / "new.csv").write_bytes(b"1,2\n")  # the same bytes, another file
    os.replace(tmp_path / "new.csv", path)
    assert file_identity(path) != identity
    identity = file_identity(path)
    os.utime(path, ns=(1, 1))  # touched: its change time moves
    assert file_identity(path) != identity
    path.unlink()
    assert file_identity(path) is None


def test_stage_folders_get_the_umask_permissions(fresh):
    old = os.umask(0o027)
    try:
        code, out = invoke("ingest", fresh / "wf.toml")
    finally:
        os.umask(old)
    assert code == 0, out
    assert (fresh / "out/ingest").stat().st_mode & 0o777 == 0o750
    assert (fresh / "out/ingest/estimation.parquet").stat().st_mode & 0o777 == 0o640


def test_an_unmarked_output_folder_of_an_earlier_version_is_adopted(project):
    (project / "out" / outdir.MARKER).unlink()
    path = project / "out/compare" / artifacts.MANIFEST
    data = json.loads(path.read_text())
    del data["upstream"]
    data["summary"] = {}  # the layout before the chain
    path.write_text(json.dumps(data))
    code, out = invoke("run", project / "wf.toml")
    assert code == 0, out
    assert "Stage 'compare' done" in out and "Stage 'validate' is up to date" in out
    assert (project / "out" / outdir.MARKER).is_file()


# ------------------------------------------------------------ crash recovery


@pytest.mark.parametrize(
    ("point", "left"),
    [
        ("written", [".identify.tmp-"]),
        ("moved-old", [".identify.old-", ".identify.tmp-"]),
        ("moved-new", [".identify.old-"]),
    ],
)
@pytest.mark.slow
def test_killed_swap_is_recovered_to_the_same_bytes(project, point, left):
    before = hashes(project / "out")
    proc = debist("identify", "wf.toml", "--force", cwd=project, fault=f"swap:identify:{point}")
    assert proc.returncode == -signal.SIGKILL
    found = [p.name for p in outdir.leftovers(project / "out")]
    assert [name[: len(prefix)] for name, prefix in zip(found, left, strict=False)] == left
    assert len(found) == len(left)
    assert (project / "out/identify").exists() == (point != "moved-old")

    code, out = invoke("status", project / "wf.toml")
    assert found[0] in out
    code, out = invoke("verify", project / "wf.toml")
    assert code == 3 and found[0] in out

    code, out = invoke("run", project / "wf.toml")
    assert code == 0, out
    assert "recovered: " in out and found[0] in out
    assert outdir.leftovers(project / "out") == []
    assert hashes(project / "out") == before
    assert invoke("verify", project / "wf.toml")[0] == 0


def test_sigterm_in_a_stage_exits_143_and_keeps_the_previous_state(project):
    before = hashes(project / "out")
    proc = debist("run", "wf.toml", "--force", cwd=project, fault="stage:identify:start=TERM")
    assert proc.returncode == 143
    assert "SIGTERM" in proc.stderr and "Traceback" not in proc.stderr
    assert "Stage 'differentiate' done" in proc.stdout
    assert outdir.leftovers(project / "out") == []
    assert hashes(project / "out") == before
    assert invoke("verify", project / "wf.toml")[0] == 0


@pytest.mark.slow
def test_sigterm_during_a_swap_waits_for_the_swap_to_end(project):
    before = hashes(project / "out")
    proc = debist(
        "identify", "wf.toml", "--force", cwd=project, fault="swap:identify:moved-old=TERM"
    )
    assert proc.returncode == 143 and "Traceback" not in proc.stderr
    assert outdir.leftovers(project / "out") == []
    assert hashes(project / "out") == before  # the swap finished: the new (same) identify
    assert invoke("verify", project / "wf.toml")[0] == 0


# --------------------------------------------------------------- one writer


def _wait_until_stopped(pid, timeout=120.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if psutil.Process(pid).status() == psutil.STATUS_STOPPED:
            return
        time.sleep(0.05)
    raise AssertionError(f"process {pid} did not reach its stop point")


@pytest.mark.slow
def test_a_second_run_is_refused_naming_the_first_or_waits(project):
    env = {**os.environ, "DEBIST_FAULT": "stage:identify:start=STOP"}
    cmd = [sys.executable, "-m", "debist"]
    first = subprocess.Popen(
        [*cmd, "run", "wf.toml", "--force"],
        cwd=project,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_until_stopped(first.pid)
        second = debist("run", "wf.toml", cwd=project)
        assert second.returncode == 2
        assert f"pid {first.pid}" in second.stderr and "--wait" in second.stderr
        waiting = subprocess.Popen(
            [*cmd, "run", "wf.toml", "--wait"],
            cwd=project,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(1.0)
        assert waiting.poll() is None  # blocked on the lock, not failed
    finally:
        os.kill(first.pid, signal.SIGCONT)
    out, errs = first.communicate(timeout=300)
    assert first.returncode == 0, errs
    out, errs = waiting.communicate(timeout=300)
    assert waiting.returncode == 0, errs
    assert out.count("up to date, skipping") == 5
    assert invoke("verify", project / "wf.toml")[0] == 0


def test_verify_while_a_run_writes_says_so(project):
    with outdir.output_lock(project / "out"):
        code, out = invoke("verify", project / "wf.toml")
    assert code == 2 and f"pid {os.getpid()}" in out


def test_export_while_a_run_writes_names_its_own_wait_option_and_waits_with_it(project):
    import threading

    dest = project / "model-code"
    with outdir.output_lock(project / "out"):
        code, out = invoke("export", project / "wf.toml", "--dest", dest)
        assert code == 2 and f"pid {os.getpid()}" in out, out
        assert out.count("\n") == 1 and out.rstrip().endswith("or pass --wait to wait for it")
        assert not dest.exists()  # nothing written
        waited = {}
        waiting = threading.Thread(
            target=lambda: waited.update(result=invoke("export", project / "wf.toml",
                                                        "--dest", dest, "--wait")),
        )  # fmt: skip
        waiting.start()
        waiting.join(timeout=1.0)
        assert waiting.is_alive() and not dest.exists()  # blocked on the lock, not failed
    waiting.join(timeout=120)
    code, out = waited["result"]
    assert code == 0 and sorted(p.name for p in dest.iterdir()) == [
        "debist_model.c", "debist_model.h"
    ], out  # fmt: skip


# ----------------------------------------------------------- the chain


def _rewrite_hash(stage_dir, rel):
    path = stage_dir / artifacts.MANIFEST
    data = json.loads(path.read_text())
    data["outputs"][rel] = artifacts.sha256_file(stage_dir / rel)
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")


def _edit_parquet(path, column, delta):
    frame = artifacts.read_parquet(path)
    frame.loc[10, column] += delta
    frame.to_parquet(path, index=False)


def _tamper_model_drop_manifest(out):
    (out / "identify/manifest.json").unlink()
    with open(out / "identify/model.h5", "r+b") as fh:
        fh.seek(-8, os.SEEK_END)
        fh.write(b"\x01" * 8)
    return ["identify/manifest.json", "validate/manifest.json"]


def _tamper_model_and_hash(out):
    with open(out / "identify/model.h5", "r+b") as fh:
        fh.seek(-8, os.SEEK_END)
        fh.write(b"\x01" * 8)
    _rewrite_hash(out / "identify", "model.h5")
    return ["validate/manifest.json", "identify/manifest.json"]


def _tamper_ingested_value(out):
    _edit_parquet(out / "ingest/estimation.parquet", "v1", 1e-3)
    _rewrite_hash(out / "ingest", "estimation.parquet")
    return ["differentiate/manifest.json", "ingest/manifest.json"]


def _tamper_summary(out):
    path = out / "compare/summary.json"
    data = json.loads(path.read_text())
    data["table"][0]["nrmse_q"] *= 0.5
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    return ["compare/summary.json (modified)"]


def _tamper_summary_and_hash(out):
    _tamper_summary(out)
    _rewrite_hash(out / "compare", "summary.json")
    return ["compare/manifest.json"]


def _tamper_config(out):
    path = out / "identify/manifest.json"
    path.write_text(path.read_text().replace('"M": 4', '"M": 5'))
    return ["identify/manifest.json", "edited"]


@pytest.mark.parametrize(
    "tamper",
    [
        _tamper_model_drop_manifest,
        _tamper_model_and_hash,
        _tamper_ingested_value,
        _tamper_summary,
        _tamper_summary_and_hash,
        _tamper_config,
    ],
)
def test_each_tampering_fails_verify_with_the_digest_naming_the_file(project, tamper):
    code, out = invoke("run", project / "wf.toml")
    digest = digest_of(out)
    assert invoke("verify", project / "wf.toml", "--digest", digest)[0] == 0
    names = tamper(project / "out")
    code, out = invoke("verify", project / "wf.toml", "--digest", digest)
    assert code == 3
    for name in names:
        assert name in out


def test_only_the_digest_catches_a_consistent_edit_of_the_last_stage(project):
    digest = digest_of(invoke("run", project / "wf.toml")[1])
    _tamper_summary_and_hash(project / "out")
    assert invoke("verify", project / "wf.toml")[0] == 0  # internally consistent
    code, out = invoke("verify", project / "wf.toml", "--digest", digest)
    assert code == 3 and "compare/manifest.json'" in out and "'compare' differs" in out


def test_run_prints_only_what_the_hashes_vouch_for(project):
    summary = project / "out/compare/summary.json"
    rows = json.loads(summary.read_text())["table"]
    true = rows[0]["nrmse_q"]
    forged = summary.read_text().replace(json.dumps(true), "0.000123", 1)
    assert forged != summary.read_text()
    summary.write_text(forged)
    code, out = invoke("run", project / "wf.toml")
    assert code == 0
    assert "Stage 'compare' done" in out  # its outputs no longer matched: rerun
    assert "0.01 %" not in out and f"{100 * true:.2f} %" in out


def test_verify_of_a_never_run_folder_and_of_missing_or_extra_stage_folders(project, fresh):
    code, out = invoke("verify", fresh / "wf.toml")
    assert code == 3 and "exist" in out
    shutil.rmtree(project / "out/compare")
    code, out = invoke("verify", project / "wf.toml")
    assert code == 3 and "compare/manifest.json" in out and "missing" in out
    shutil.copytree(project / "out/differentiate", project / "out/study")
    code, out = invoke("verify", project / "wf.toml")
    assert code == 3 and "extra" in out


@pytest.mark.slow
def test_manifests_are_byte_deterministic_and_the_same_in_two_clones(tmp_path):
    a = make_project(tmp_path / "a")
    b = make_project(tmp_path / "elsewhere" / "deeper" / "b")
    code_a, out_a = invoke("run", a / "wf.toml")
    code_b, out_b = invoke("run", b / "wf.toml")
    assert code_a == code_b == 0
    ha, hb = hashes(a / "out"), hashes(b / "out")
    assert len([k for k in ha if k.endswith(("manifest.json", ".parquet", ".h5"))]) >= 15
    assert ha == hb
    assert digest_of(out_a) == digest_of(out_b)
    frame = pd.read_parquet(a / "out/ingest/estimation.parquet")
    assert artifacts.read_parquet(a / "out/ingest/estimation.parquet").attrs["source"] == (
        "data/rig.csv"
    )
    assert len(frame) == 2500
    timings = json.loads((a / "out/identify" / artifacts.TIMINGS).read_text())
    assert timings["stage"] > 0 and "fit" in timings


# ------------------------------------------------------- code fingerprints


def _copy_package(tmp_path):
    root = tmp_path / "src" / "pipeline"
    shutil.copytree(ROOT / "pipeline", root, ignore=shutil.ignore_patterns("__pycache__"))
    return root


def _fingerprints(root):
    return {s.name: code_fingerprint(s.module, root) for s in STAGES}


def _edited(tmp_path, rel, edit):
    """Fingerprints of every stage for the package as it is and with one file edited."""
    before = _fingerprints(_copy_package(tmp_path / "before"))
    root = _copy_package(tmp_path / "after")
    path = root / rel
    path.write_text(edit(path.read_text()))
    after = _fingerprints(root)
    return sorted(s for s in before if before[s] != after[s])


def test_editing_the_rig_leaves_the_data_stages_up_to_date(tmp_path):
    changed = _edited(tmp_path, "rig/profiles.py", lambda t: t.replace('"""', '"""Edited. ', 1))
    assert changed == ["rig"]


def test_editing_the_identification_reruns_identify_and_what_follows(tmp_path):
    changed = _edited(tmp_path, "identify/fit.py", lambda t: t + "\n# edited\n")
    # validate and report read the identified model (debist.model.rbf), never the fitter;
    # compare's records hold fit.Record, the study refits
    assert changed == ["compare", "identify", "study"]
    closure = module_closure("debist.stages.differentiate", ROOT / "pipeline")
    assert "debist.identify.fit" not in closure and "debist.differentiate" in closure


def test_a_stage_runs_with_one_blas_thread_even_where_scipy_loads_late():
    """SciPy's own OpenBLAS, loaded inside a stage (the CLI imports SciPy on first use), is
    limited too: else a stage run on its own would sum in another order than in a full run."""
    code = (
        "import threadpoolctl\n"
        "from debist.engine.runner import one_blas_thread\n"
        "with one_blas_thread():\n"
        "    import scipy.linalg\n"
        "    blas = [i for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas']\n"
        "print(len(blas), max(i['num_threads'] for i in blas))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    n_libraries, threads = map(int, out.stdout.split())
    assert n_libraries >= 2 and threads == 1  # numpy's and SciPy's OpenBLAS, one thread each
