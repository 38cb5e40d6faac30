"""The CLI and runner on a small synthetic DE workflow: caching, status, verify, atomic failures."""

import json
import shutil
import subprocess
import sys

import pandas as pd
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core import artifacts
from debist.core.forking import fork_workers
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv


@pytest.fixture
def project(tmp_path, bistable_record):
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    return tmp_path


@pytest.fixture
def ran(synthetic_copy):
    """A copy of the session's complete run of the same workflow (``out/`` beside it)."""
    return synthetic_copy[0]


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.output


def stage_hashes(root):
    return {
        p.relative_to(root).as_posix(): artifacts.sha256_file(p)
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.mark.slow
def test_run_skip_status_and_downstream_only_rerun(project):
    wf = project / "wf.toml"
    code, out = invoke("run", wf)
    assert code == 0, out
    assert out.count("done") == 5
    table = pd.read_parquet(project / "out/validate/nrmse.parquet")
    assert set(table.dataset) == {"estimation", "check"}
    assert (table.nrmse_q < 0.05).all()  # free run of the identified model within 5 % of the range
    both = pd.read_parquet(project / "out/compare/nrmse.parquet")
    assert sorted(both.model.unique()) == ["narx", "rbf", "sindy"] and len(both) == 6
    assert (both.n_params > 0).all()
    assert "SINDy (" in out and "q_ddot =" in out
    ingest = pd.read_parquet(project / "out/ingest/estimation.parquet")
    assert list(ingest.columns) == ["t", "q", "v1", "v2"]
    assert ingest.v1.max() == pytest.approx(2500.0 + 250 * 6, rel=0.5)  # kV -> V
    assert abs(ingest.q).max() < 0.05  # mm -> m

    code, out = invoke("run", wf)
    assert code == 0 and out.count("up to date, skipping") == 5

    code, out = invoke("status", wf, "--json")
    assert {s["state"] for s in json.loads(out).values()} == {"up_to_date"}

    # changing the differentiation parameter reruns it and everything after it, not ingest
    before = stage_hashes(project / "out/ingest")
    (project / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=2e-6))
    code, out = invoke("status", wf, "--json")
    states = json.loads(out)
    assert states["ingest"]["state"] == "up_to_date"
    assert states["differentiate"] == {
        "state": "stale",
        "reasons": [{"kind": "config_changed", "detail": "config changed (alpha)"}],
    }
    assert states["validate"]["state"] == "stale"
    code, out = invoke("run", wf)
    assert code == 0
    assert "Stage 'ingest' is up to date" in out and "Stage 'differentiate' done" in out
    assert stage_hashes(project / "out/ingest") == before


@pytest.mark.slow
def test_verify_names_the_modified_file(ran):
    wf = ran / "wf.toml"
    assert invoke("verify", wf)[0] == 0
    target = ran / "out/differentiate/check.parquet"
    target.write_bytes(target.read_bytes() + b"\0")
    code, out = invoke("verify", wf)
    assert code == 3
    assert "check.parquet (modified)" in out


@pytest.mark.slow
def test_outputs_are_byte_identical_across_runs(ran):
    wf = ran / "wf.toml"
    first = stage_hashes(ran / "out")  # the session's run, in another folder
    shutil.rmtree(ran / "out")
    assert invoke("run", wf)[0] == 0
    second = stage_hashes(ran / "out")
    data = [k for k in first if k.endswith((".parquet", ".h5"))]
    assert len(data) >= 12 and "compare/sindy.h5" in data
    assert {k: first[k] for k in data} == {k: second[k] for k in data}


@pytest.mark.slow
def test_corrupt_input_fails_naming_file_and_keeps_previous_artifacts(ran):
    wf = ran / "wf.toml"
    before = stage_hashes(ran / "out")
    text = (ran / "rig.csv").read_text().splitlines()
    text[100] = text[100].replace(text[100].split(",")[1], "nan", 1)
    (ran / "rig.csv").write_text("\n".join(text) + "\n")
    code, out = invoke("run", wf)
    assert code == 1
    assert "rig.csv" in out and "laser" in out
    assert stage_hashes(ran / "out") == before
    assert not [p for p in (ran / "out").iterdir() if ".tmp-" in p.name or ".old-" in p.name]


def test_missing_channel_fails_and_writes_nothing(project):
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace('"v_right"', '"v_r"')
    (project / "wf.toml").write_text(text)
    code, out = invoke("ingest", project / "wf.toml")
    assert code == 1
    assert "rig.csv" in out and "v_r" in out
    assert not (project / "out").exists() or not any((project / "out").iterdir())


def test_stage_without_upstream_artifacts_is_refused(project):
    code, out = invoke("identify", project / "wf.toml")
    assert code == 2 and "run 'ingest' first" in out


def test_bad_workflow_key_is_a_usage_error(project):
    (project / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6) + "\n[identfy]\nM = 3\n")
    code, out = invoke("run", project / "wf.toml")
    assert code == 2 and "identfy" in out


@pytest.mark.slow
def test_study_stage_runs_only_when_configured(project):
    wf = project / "wf.toml"
    code, out = invoke("status", wf, "--json")
    assert "study" not in json.loads(out)
    text = (
        SYNTHETIC_WORKFLOW.format(alpha=1e-6)
        + "\n[study]\nM = [4, 6]\nsigma_n = [0.5, 1.0]\nalpha = [1e-7, 1e-6]\n"
    )
    text += "max_samples = 1500\n"
    wf.write_text(text)
    # a fresh process, as from the command line (no numba threads started before the fork)
    done = subprocess.run([sys.executable, "-m", "debist", "run", str(wf)], capture_output=True,
                          text=True, cwd=project)  # fmt: skip
    out = done.stdout + done.stderr
    assert done.returncode == 0, out
    grid = pd.read_parquet(project / "out/study/rbf_grid.parquet")
    assert len(grid) == 4 and {"condition", "nrmse_q_est", "status"} <= set(grid.columns)
    ok = grid[grid.status == "ok"]
    # Gaussian overlap: the condition number grows with sigma_n at fixed M
    for _, g in ok.groupby("M"):
        assert g.sort_values("sigma_n").condition.is_monotonic_increasing
    assert len(pd.read_parquet(project / "out/study/alpha.parquet")) == 2
    assert (project / "out/study/rbf_grid.png").stat().st_size > 10_000
    # with two cores it ran in its own process beside identify..compare, and wrote what a
    # serial run writes
    if fork_workers(2) >= 2:
        assert out.index("Running stage 'study'") < out.index("Running stage 'identify'")
        assert "in its own process beside the others" in out
    beside = stage_hashes(project / "out/study")
    code, out = invoke("run", wf, "--stages", "study", "--force")
    assert code == 0 and "in its own process" not in out, out
    serial = stage_hashes(project / "out/study")
    del beside["timings.json"], serial["timings.json"]
    assert serial == beside


AFTER_A_BATCH_OF_FREE_RUNS = """
import sys
import numba
import numpy as np
import debist
from debist.simulate import warmup
from debist.simulate.freerun import simulate

five = [np.zeros((20, 1))] * 5
simulate(warmup.oscillator(), five, 0.01, np.zeros(5), np.zeros(5))  # on the kernel's threads
events = []
debist.run(sys.argv[1], on_progress=lambda e: events.append((e.stage, e.what, e.detail)))
beside = any(s == "study" and w == "done" and "own process" in d for s, w, d in events)
try:
    layer = numba.threading_layer()
except ValueError:  # numba's threading layer never started
    layer = "none"
print(layer, beside)
"""


@pytest.mark.slow
def test_a_run_after_a_batch_of_free_runs_still_forks_the_study_beside(project):
    # the kernels run on Python threads, never on numba's threading layer (whose GNU OpenMP
    # flavour ends a child forked after it started), so a forked stage stays possible
    wf = project / "wf.toml"
    wf.write_text(
        SYNTHETIC_WORKFLOW.format(alpha=1e-6)
        + "\n[study]\nM = [4]\nsigma_n = [0.5]\nalpha = [1e-6]\nmax_samples = 1500\n"
    )
    done = subprocess.run([sys.executable, "-c", AFTER_A_BATCH_OF_FREE_RUNS, str(wf)],
                          capture_output=True, text=True, cwd=project)  # fmt: skip
    assert done.returncode == 0, done.stderr
    layer, beside = done.stdout.split()[-2:]
    assert layer == "none"
    assert beside == str(fork_workers(2) >= 2)
    assert len(pd.read_parquet(project / "out/study/rbf_grid.parquet")) == 1


def test_the_report_unit_enters_the_keys_of_the_stages_that_draw_q(project):
    """Fig. 14 (identify) and Fig. 3-7 (analyze) draw q in [validate] report_unit: a stated
    unit is part of their keys, validate's as before; compare and study hash their own."""
    from debist.engine.runner import stage_config
    from debist.workflow.loader import load_workflow

    plain = load_workflow(project / "wf.toml")
    shown = load_workflow(project / "wf.toml", overrides={"validate.report_unit": "um"})
    assert "report_unit" not in stage_config(plain, "identify")
    assert "report_unit" not in stage_config(plain, "analyze")
    assert stage_config(shown, "identify")["report_unit"] == "um"
    assert stage_config(shown, "analyze")["report_unit"] == "um"
    assert {k: v for k, v in stage_config(shown, "identify").items() if k != "report_unit"} == (
        stage_config(plain, "identify")
    )
    assert stage_config(shown, "differentiate") == stage_config(plain, "differentiate")
