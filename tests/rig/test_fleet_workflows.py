"""Fleet workflows: one workflow per seeded prototype, written all-or-nothing, loadable."""

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core.artifacts import write_text_files
from debist.core.errors import OutputDirError, WorkflowError
from debist.engine.runner import Runner
from debist.rig.fleet_workflows import fleet_workflows
from debist.workflow.loader import load_workflow

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "workflows" / "paper-experiment.toml"


def render(out: Path, n: int = 3, seed: int = 1) -> dict[str, str]:
    raw = tomllib.loads(TEMPLATE.read_text(encoding="utf-8"))
    return dict(fleet_workflows(raw, TEMPLATE.parent, out, n, seed=seed))


@pytest.fixture(scope="module")
def fleet_1(tmp_path_factory) -> dict[str, str]:
    """The template's seed-1 fleet of three (each member's switching voltages take seconds);
    member k of a fleet is the same for every fleet size, so tests of fewer members read the
    first ones. Read only; made once for all pytest-xdist workers."""
    from tests.conftest import made_once

    _, text = made_once(tmp_path_factory, "fleet-1", lambda out: json.dumps(render(out, 3, 1)))
    return json.loads(text)


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


def test_existing_files_are_never_overwritten(tmp_path, fleet_1):
    files = dict(list(fleet_1.items())[:2])
    (tmp_path / "paper-experiment-001.toml").write_text("mine", encoding="utf-8")
    with pytest.raises(OutputDirError) as err:
        write_text_files(tmp_path, files)
    assert "paper-experiment-001.toml" in str(err.value)
    assert not (tmp_path / "paper-experiment-000.toml").exists()
    assert (tmp_path / "paper-experiment-001.toml").read_text() == "mine"


def test_template_without_rig_is_refused(tmp_path):
    with pytest.raises(WorkflowError) as err:
        fleet_workflows({"workflow": {"name": "x"}}, tmp_path, tmp_path, 2, seed=0)
    assert "needs" in str(err.value) and "section" in str(err.value)
    result = CliRunner().invoke(
        app, ["fleet", str(ROOT / "workflows" / "silverbox.toml"), "--dir", str(tmp_path / "f")]
    )
    assert result.exit_code == 2 and "[rig]" in result.output


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_draws_whose_logs_fail_the_template_ingest_are_skipped_and_named(
    tmp_path, monkeypatch, workers
):
    """Serially, and with the next draw checked in a forked process ahead of need: the same
    fleet, and a draw checked beyond it leaves no folder."""
    from debist.engine import fleetrun

    raw = tomllib.loads(TEMPLATE.read_text())
    runs = tmp_path / "runs"

    def problem(text, folder, name):  # may run in a forked process: it leaves a folder
        label = name.removesuffix(".toml")
        (runs / label).mkdir(parents=True)
        (tmp_path / f"checked-{label}").touch()
        return ("laser at its range limit" if label.endswith("-001") else None), runs / label

    monkeypatch.setattr(fleetrun, "_ingest_problem", problem)
    monkeypatch.setattr(fleetrun, "fork_workers", lambda n: min(n, workers))
    files, rejected, kept_runs = fleetrun.viable_fleet(raw, TEMPLATE.parent, tmp_path, 3, seed=4)
    name = raw["workflow"]["name"]
    assert list(files) == [f"{name}-000.toml", f"{name}-002.toml", f"{name}-003.toml"]
    assert rejected == {f"{name}-001": "laser at its range limit"}
    assert kept_runs == [runs / f"{name}-00{k}" for k in range(4)]
    # stops once the fleet is full: a draw checked ahead (-004) is removed again
    assert sorted(p.name for p in runs.iterdir()) == [f"{name}-00{k}" for k in range(4)]
    checked = sorted(p.name.removeprefix("checked-") for p in tmp_path.glob("checked-*"))
    assert checked[:4] == [f"{name}-00{k}" for k in range(4)]
    assert checked[4:] in ([], [f"{name}-004"] if workers == 2 else [])  # at most one ahead
    # a kept member is the same prototype as in the unchecked fleet
    assert files[f"{name}-002.toml"] == render(tmp_path / "x", n=3, seed=4)[f"{name}-002.toml"]


@pytest.mark.slow
def test_a_fleet_whose_logs_all_fail_ingest_is_refused_with_the_reason(tmp_path):
    from debist.engine.fleetrun import viable_fleet
    from debist.rig.fleet import FleetError

    raw = tomllib.loads(TEMPLATE.read_text())
    for exp in raw["rig"]["experiments"].values():
        exp["duration"] = 8.0
    raw["ingest"]["q"]["range"] = [-2, 2]  # [mm]: every well lies outside
    with pytest.raises(FleetError) as err:
        viable_fleet(raw, TEMPLATE.parent, tmp_path, 1, seed=0)
    assert "only 0" in str(err.value)
    assert "of 3" in str(err.value)
    assert "range" in str(err.value)
    assert not list(tmp_path.glob("*.toml"))  # the scratch workflows are gone
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").iterdir())


def test_a_kept_members_rig_and_ingest_stay_up_to_date_for_the_batch(tmp_path):
    """The check's run is the member's own: the batch does not record the logs again, and a
    draw that fails leaves no folder."""
    import tomli_w

    from debist import api

    raw = tomllib.loads(TEMPLATE.read_text())
    for exp in raw["rig"]["experiments"].values():
        exp["duration"] = 8.0
    template = tmp_path / "short.toml"
    template.write_text(tomli_w.dumps(raw))
    made = api.fleet(template, 1, seed=1, folder=tmp_path / "fleet")
    (member,) = made.paths
    states = {s.stage: s.state for s in api.status(member)}
    assert states["rig"] == states["ingest"] == "up to date"
    assert states["differentiate"] == "missing"
    runs = sorted(p.name for p in (tmp_path / "fleet" / "runs").iterdir())
    assert runs == [member.stem]  # rejected draws' folders, if any, are gone
    assert sorted(p.name for p in (tmp_path / "fleet").glob("*.toml")) == [member.name]


def test_a_member_switching_below_the_template_gets_its_sub_threshold_levels_scaled(
    tmp_path, fleet_1
):
    """Seed 1, member 0 switches at 682 V (its left well is shallow); the template's prototype
    at 1244 V with the profiles' 1 kV: the member's levels become 1 kV x 682 / 1244."""
    from debist.physics.params import PrototypeParams
    from debist.physics.statics import switching_voltage

    raw = tomllib.loads(TEMPLATE.read_text(encoding="utf-8"))
    member = [tomllib.loads(text) for text in fleet_1.values()]
    template = PrototypeParams.from_dict({**raw["physics"], **raw["rig"]["prototype"]})
    v_template = min(switching_voltage(template, de) for de in (1, 2))
    v_member = switching_voltage(PrototypeParams.from_dict(member[0]["rig"]["prototype"]), 1)
    assert v_template == pytest.approx(1244.0, abs=1.0) and v_member == pytest.approx(682, abs=1)
    expected = 1000.0 * v_member / v_template  # to the thresholds' 1 V bisection
    levels = [e["v_sub"] for e in member[0]["rig"]["experiments"].values()]
    assert levels == [pytest.approx(expected, abs=1.0)] * 2 and levels[0] == levels[1]
    assert "threshold 682 V" in member[0]["workflow"]["description"]
    # member 2 switches at 1494 V, above the template: its experiments are the template's
    assert member[2]["rig"]["experiments"] == raw["rig"]["experiments"]
    # a level the template states is the one scaled
    for exp in raw["rig"]["experiments"].values():
        exp["v_sub"] = 800.0
    _, again = next(fleet_workflows(raw, TEMPLATE.parent, tmp_path, 1, seed=1))
    scaled = tomllib.loads(again)["rig"]["experiments"]["validation"]["v_sub"]
    assert scaled == pytest.approx(0.8 * levels[0], abs=0.1)


def test_the_scaled_levels_keep_the_validation_blocks_below_the_switch(fleet_1):
    """The validation profile's last block (DE 1 triangle to v_sub, 30.1-35.1 s, beam in the
    left well) snaps seed-1 member 0 over at the template's 1 kV; at its scaled level the
    beam stays in the left well, as the profile intends."""
    from debist.rig.config import RigConfig
    from debist.rig.experiment import run_experiment

    raw = tomllib.loads(TEMPLATE.read_text(encoding="utf-8"))
    rig = tomllib.loads(next(iter(fleet_1.values())))["rig"]
    crossings = {}
    for v_sub in (1000.0, rig["experiments"]["validation"]["v_sub"]):
        rig["experiments"] = {"validation": {"profile": "validation", "seed": 2, "v_sub": v_sub}}
        run = run_experiment(RigConfig.from_dict(rig, raw["physics"]), "validation")
        block = (run.t > 30.1) & (run.t < 35.1)
        assert run.q[block][0] < -2e-3  # the block starts in the left well
        crossings[v_sub] = int(np.count_nonzero(np.diff(np.sign(run.q[block]))))
    assert list(crossings.values()) == [1, 0], crossings
