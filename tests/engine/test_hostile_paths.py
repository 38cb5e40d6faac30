"""Names that become paths are plain file names; every write stays inside the output folder."""

import json
import os

import pandas as pd
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core.artifacts import write_stage
from debist.core.errors import OutputDirError, WorkflowError
from debist.core.names import check_file_name
from debist.workflow.loader import load_workflow
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv

HOSTILE = ["../../victim", "/tmp/x/abs", "unseen/part1", "a\x00b", ".hidden", "", "..", "CON"]


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.output


@pytest.fixture
def project(tmp_path, bistable_record):
    root = tmp_path / "a" / "b"
    root.mkdir(parents=True)
    write_rig_csv(root, bistable_record)
    return root


def _workflow(root, dataset_name):
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace(
        "[datasets.check]", f"[datasets.{json.dumps(dataset_name)}]"
    )
    (root / "wf.toml").write_text(text)
    return root / "wf.toml"


@pytest.mark.parametrize("name", HOSTILE)
def test_a_data_set_name_that_is_not_a_file_name_is_refused_before_anything_is_written(
    project, name
):
    victim = project.parent.parent / "victim.parquet"
    victim.write_bytes(b"the user's file")
    code, out = invoke("run", _workflow(project, name), "--stages", "ingest")
    assert code == 2, out
    assert "[datasets]" in out and "name" in out and repr(name) in out
    assert victim.read_bytes() == b"the user's file"
    assert not (project / "out").exists()
    assert not os.path.exists("/tmp/x/abs.parquet")


def test_a_plain_name_still_runs(project):
    code, out = invoke("run", _workflow(project, "unseen-part_1.v2"), "--stages", "ingest")
    assert code == 0, out
    assert (project / "out" / "ingest" / "unseen-part_1.v2.parquet").is_file()


def test_a_rig_experiment_name_is_checked_too(tmp_path):
    wf = tmp_path / "wf.toml"
    wf.write_text(
        '[workflow]\nname = "x"\n[physics]\nb = 23e-3\n[rig]\nsample_time = 0.01\n'
        '[rig.experiments."../escape"]\nprofile = "identification"\nduration = 5.0\n'
        '[datasets.a]\nrig = "../escape"\nrole = "estimation"\n'
    )
    with pytest.raises(WorkflowError) as err:
        load_workflow(wf)
    assert "'../escape'" in str(err.value)


def test_the_workflow_name_becomes_a_folder_only_when_it_is_a_file_name(project):
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace(
        'name = "synthetic"\noutput_dir = "out"\n', 'name = "../../evil"\n'
    )
    (project / "wf.toml").write_text(text)
    with pytest.raises(WorkflowError) as err:
        load_workflow(project / "wf.toml")
    assert "output_dir" in str(err.value)
    # with an output_dir the name is free text (it never becomes a path)
    (project / "wf.toml").write_text(text.replace("[ingest]", 'output_dir = "out"\n[ingest]', 1))
    wf = load_workflow(project / "wf.toml")
    assert wf.name == "../../evil" and wf.output_dir == (project / "out").resolve()


def test_output_dir_and_out_expand_the_home_folder(project, monkeypatch, tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace('output_dir = "out"', 'output_dir = "~"')
    (project / "wf.toml").write_text(text)
    assert load_workflow(project / "wf.toml").output_dir == home.resolve()
    assert load_workflow(project / "wf.toml", "~/runs").output_dir == (home / "runs").resolve()
    assert not (project / "~").exists()


@pytest.mark.parametrize("rel", ["../x.parquet", "/tmp/abs.parquet", "a/../../x.parquet"])
def test_write_stage_refuses_an_output_outside_its_folder(tmp_path, rel):
    stage = tmp_path / "out" / "ingest"
    with pytest.raises(OutputDirError) as err:
        write_stage(
            stage, stage="ingest", key="k", code="c", versions={}, config={}, inputs={},
            upstream={}, outputs={rel: pd.DataFrame({"a": [1.0]})},
        )  # fmt: skip
    assert "outside" in str(err.value) and "folder" in str(err.value)
    assert not (tmp_path / "out" / "x.parquet").exists() and not (tmp_path / "x.parquet").exists()
    assert not stage.exists()
    assert [p.name for p in (tmp_path / "out").iterdir()] == []  # no temporary folder left


def test_check_file_name_repr_shows_control_characters():
    with pytest.raises(WorkflowError) as err:
        check_file_name("a\nb", "[datasets]")
    assert "'a\\nb'" in str(err.value)
