"""Fleet workflows: one workflow per seeded prototype, written all-or-nothing, loadable."""

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli import app
from pipeline.artifacts import write_text_files
from pipeline.errors import OutputDirError, WorkflowError
from pipeline.rig.fleet_workflows import fleet_workflows
from pipeline.runner import Runner
from pipeline.workflow import load_workflow

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "workflows" / "paper-experiment.toml"


def render(out: Path, n: int = 3, seed: int = 1) -> dict[str, str]:
    raw = tomllib.loads(TEMPLATE.read_text(encoding="utf-8"))
    return fleet_workflows(raw, TEMPLATE.parent, out, n, seed=seed)


def test_members_are_seeded_distinct_and_loadable(tmp_path):
    files = render(tmp_path)
    assert list(files) == [f"paper-experiment-{k:03d}.toml" for k in range(3)]
    assert files == render(tmp_path)  # same seed, same fleet
    assert files != render(tmp_path, seed=2)
    paths = write_text_files(tmp_path, files)
    workflows = [load_workflow(p) for p in paths]
    protos = [tomllib.loads(p.read_text())["rig"]["prototype"] for p in paths]
    assert len({(pr["b"], pr["dz_1"], pr["dz_2"]) for pr in protos}) == 3
    for wf in workflows:
        assert wf.section("physics") == {"b": 0.023}  # the nominal design stays
        assert wf.output_dir == (tmp_path / "runs" / wf.name).resolve()
        assert Runner(wf).stages()[:2] == ["rig", "ingest"]


def test_existing_files_are_never_overwritten(tmp_path):
    files = render(tmp_path, n=2)
    (tmp_path / "paper-experiment-001.toml").write_text("mine", encoding="utf-8")
    with pytest.raises(OutputDirError, match=r"paper-experiment-001\.toml' exists"):
        write_text_files(tmp_path, files)
    assert not (tmp_path / "paper-experiment-000.toml").exists()
    assert (tmp_path / "paper-experiment-001.toml").read_text() == "mine"


def test_template_without_rig_is_refused(tmp_path):
    with pytest.raises(WorkflowError, match="needs a \\[rig\\] section"):
        fleet_workflows({"workflow": {"name": "x"}}, tmp_path, tmp_path, 2, seed=0)
    result = CliRunner().invoke(
        app, ["fleet", str(ROOT / "workflows" / "silverbox.toml"), "--dir", str(tmp_path / "f")]
    )
    assert result.exit_code == 2 and "[rig]" in result.output
