"""Running a part of a workflow (--stages, --from, --until) and `status --json`."""

import json
import shutil

import pytest
from typer.testing import CliRunner

from debist.cli import app
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv

#: The stages of the synthetic workflow, in order (it has no optional sections).
STAGES = ["ingest", "differentiate", "identify", "validate", "compare"]


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, " ".join(result.output.split())


@pytest.fixture(scope="module")
def differentiated(tmp_path_factory, bistable_record):
    """A project whose ingest and differentiate stages ran (``--stages``)."""
    root = tmp_path_factory.mktemp("base")
    write_rig_csv(root, bistable_record)
    (root / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    code, out = invoke("run", root / "wf.toml", "--stages", "differentiate,ingest")
    assert code == 0, out
    assert out.count(" done ") == 2 and "run digest" not in out  # a part has no digest
    return root


@pytest.fixture
def project(differentiated, tmp_path):
    shutil.copytree(differentiated, tmp_path, dirs_exist_ok=True)
    return tmp_path


@pytest.fixture
def fresh(tmp_path, bistable_record):
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    return tmp_path


def folders(root):
    out = root / "out"
    return sorted(p.name for p in out.iterdir() if p.is_dir()) if out.exists() else []


def test_stages_runs_exactly_the_listed_stages(differentiated):
    assert folders(differentiated) == ["differentiate", "ingest"]


@pytest.mark.slow
def test_from_until_runs_the_range_and_reuses_the_rest(project):
    code, out = invoke("run", project / "wf.toml", "--from", "identify", "--until", "validate")
    assert code == 0, out
    assert "Stage 'identify' done" in out and "Stage 'validate' done" in out
    assert "ingest" not in out.split("Stage 'identify'")[0]  # upstream neither run nor skipped
    assert folders(project) == ["differentiate", "identify", "ingest", "validate"]
    code, out = invoke("run", project / "wf.toml", "--from", "compare")
    assert code == 0 and "Stage 'compare' done" in out
    assert folders(project) == sorted(STAGES)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--stages", "identify,idnetify"], ["unknown stage 'idnetify'", *STAGES]),
        (["--from", "nope"], ["unknown stage 'nope'", *STAGES]),
        (["--until", "study"], ["not a stage of this workflow: 'study'", *STAGES]),
        (["--from", "validate", "--until", "identify"], ["'validate' runs after 'identify'"]),
        (["--stages", "identify", "--from", "ingest"], ["not both"]),
        (["--stages", " , "], ["no stage selected"]),
    ],
)
def test_a_bad_selection_exits_2_naming_it_and_writes_nothing(fresh, args, words):
    code, out = invoke("run", fresh / "wf.toml", *args)
    assert code == 2, out
    for word in words:
        assert word in out
    assert not (fresh / "out").exists()


def test_a_stage_whose_upstream_is_missing_is_refused(fresh):
    code, out = invoke("run", fresh / "wf.toml", "--stages", "identify")
    assert code == 2, out
    assert "'identify' reads" in out and "'ingest'" in out and "(never" in out
    assert not (fresh / "out").exists()
    code, out = invoke("identify", fresh / "wf.toml")  # the stage command says the same
    assert code == 2 and "'ingest'" in out and "missing" in out


def test_a_stage_whose_upstream_is_stale_is_refused_and_nothing_is_written(project):
    (project / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=2e-6))
    before = sorted(p.relative_to(project).as_posix() for p in (project / "out").rglob("*"))
    code, out = invoke("run", project / "wf.toml", "--stages", "identify,validate")
    assert code == 2, out
    assert "'differentiate'" in out and "stale (config" in out and "changed (alpha))" in out
    after = sorted(p.relative_to(project).as_posix() for p in (project / "out").rglob("*"))
    assert after == before
    code, out = invoke("run", project / "wf.toml", "--stages", "differentiate,identify")
    assert code == 0 and "Stage 'identify' done" in out


def test_status_json_is_an_object_per_stage_with_structured_reasons(project):
    wf = project / "wf.toml"
    code, out = invoke("status", wf, "--json")
    assert code == 0
    status = json.loads(out)
    assert list(status) == STAGES
    assert status["ingest"] == {"state": "up_to_date", "reasons": []}
    assert status["identify"] == {
        "state": "missing",
        "reasons": [{"kind": "never_run", "detail": "never run"}],
    }
    wf.write_text(SYNTHETIC_WORKFLOW.format(alpha=3e-6))
    target = project / "out/ingest/check.parquet"
    target.write_bytes(target.read_bytes() + b"\0")
    status = json.loads(invoke("status", wf, "--json")[1])
    assert {s["state"] for s in status.values()} <= {"up_to_date", "stale", "missing"}
    assert status["ingest"]["state"] == "stale"
    assert status["ingest"]["reasons"] == [
        {"kind": "artifact_modified", "detail": "outputs modified: check.parquet (modified)"}
    ]
    assert status["differentiate"]["state"] == "stale"
    assert status["differentiate"]["reasons"] == [  # its own change is not hidden
        {"kind": "upstream_stale", "detail": "upstream 'ingest' will rerun"},
        {"kind": "config_changed", "detail": "config changed (alpha)"},
    ]
    # the human form keeps the words
    code, out = invoke("status", wf)
    assert code == 0 and "stale (outputs" in out and "check.parquet (modified))" in out


def test_status_json_lists_every_reason_of_a_stale_stage(project):
    wf = project / "wf.toml"
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace("iterations = 10", "iterations = 11")
    wf.write_text(text)
    target = project / "out/differentiate/check.parquet"
    target.unlink()
    status = json.loads(invoke("status", wf, "--json")[1])
    kinds = [r["kind"] for r in status["differentiate"]["reasons"]]
    assert kinds == ["artifact_missing", "config_changed"]
    assert status["differentiate"]["reasons"][1]["detail"].endswith("(iterations)")
