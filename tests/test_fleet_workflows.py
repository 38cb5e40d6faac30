"""Fleet workflows: one workflow per seeded prototype, written all-or-nothing, loadable."""

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.engine.artifacts import write_text_files
from debist.engine.runner import Runner
from debist.errors import OutputDirError, WorkflowError
from debist.rig.fleet_workflows import fleet_workflows
from debist.workflow.loader import load_workflow

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "workflows" / "paper-experiment.toml"


def render(out: Path, n: int = 3, seed: int = 1) -> dict[str, str]:
    raw = tomllib.loads(TEMPLATE.read_text(encoding="utf-8"))
    return fleet_workflows(raw, TEMPLATE.parent, out, n, seed=seed)


@pytest.mark.slow
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


@pytest.mark.slow
def test_draws_whose_logs_fail_the_template_ingest_are_skipped_and_named(tmp_path, monkeypatch):
    from debist.engine import fleetrun

    raw = tomllib.loads(TEMPLATE.read_text())
    calls = []

    def problem(text, folder, label):
        calls.append(label)
        return "laser at its range limit" if label.endswith("-001") else None

    monkeypatch.setattr(fleetrun, "_ingest_problem", problem)
    files, rejected = fleetrun.viable_fleet(raw, TEMPLATE.parent, tmp_path, 3, seed=4)
    name = raw["workflow"]["name"]
    assert list(files) == [f"{name}-000.toml", f"{name}-002.toml", f"{name}-003.toml"]
    assert rejected == {f"{name}-001": "laser at its range limit"}
    assert calls == [f"{name}-00{k}" for k in range(4)]  # stops once the fleet is full
    # a kept member is the same prototype as in the unchecked fleet
    assert files[f"{name}-002.toml"] == render(tmp_path / "x", n=9, seed=4)[f"{name}-002.toml"]


@pytest.mark.slow
def test_a_fleet_whose_logs_all_fail_ingest_is_refused_with_the_reason(tmp_path):
    from debist.engine.fleetrun import viable_fleet
    from debist.rig.fleet import FleetError

    raw = tomllib.loads(TEMPLATE.read_text())
    for exp in raw["rig"]["experiments"].values():
        exp["duration"] = 8.0
    raw["ingest"]["q"]["range"] = [-2, 2]  # [mm]: every well lies outside
    with pytest.raises(FleetError, match=r"only 0 of 3 .* range limit"):
        viable_fleet(raw, TEMPLATE.parent, tmp_path, 1, seed=0)
    assert not list(tmp_path.glob("*.toml"))  # the scratch workflows are gone
