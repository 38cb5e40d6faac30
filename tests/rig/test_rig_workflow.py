"""The virtual rig inside a workflow: rig stage -> MAT logs -> ingest, with caching and truth."""

import os
from pathlib import Path

import numpy as np
import pytest

from debist.core import artifacts
from debist.core.errors import WorkflowError
from debist.core.forking import fork_workers
from debist.engine.runner import Runner
from debist.rig import experiment
from debist.rig.profiles import make_profile
from debist.stages import ingest
from debist.workflow.loader import load_workflow

WORKFLOW = """
[workflow]
name = "tiny-rig"
output_dir = "runs"

[physics]
b = 23e-3

[rig]
sample_time = 0.01

[rig.prototype]
dz_1 = 0.15e-3

[rig.experiments.a73]
profile = "identification"
duration = 6.5
seed = 5
format = "7.3"

[rig.experiments.a5]
profile = "identification"
duration = 6.5
seed = 5
format = "5"

[ingest]
q = { regex = "Laser/q$", unit = "mm" }
v1 = { regex = "DE1/v_mon$", unit = "kV" }
v2 = { regex = "DE2/v_mon$", unit = "kV" }
r1 = { regex = "DE1/v_ref$", unit = "kV" }

[datasets.a73]
rig = "a73"
role = "estimation"

[datasets.a5]
rig = "a5"
"""


@pytest.fixture(scope="module")
def rig_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rig")
    path = tmp / "rig.toml"
    path.write_text(WORKFLOW, encoding="utf-8")
    wf = load_workflow(path)
    manifests = Runner(wf).run(["rig", "ingest"])
    return wf, manifests


def test_rig_writes_mat_logs_and_truth(rig_run):
    wf, manifests = rig_run
    outs = set(manifests["rig"].outputs)
    assert outs == {"a73.mat", "a73_truth.h5", "a5.mat", "a5_truth.h5", "summary.json"}
    rig_dir = wf.stage_dir("rig")
    assert (rig_dir / "a73.mat").read_bytes()[:10] == b"MATLAB 7.3"
    assert (rig_dir / "a5.mat").read_bytes()[:19] == b"MATLAB 5.0 MAT-file"
    summary = manifests["rig"].summary["a73"]
    assert summary["samples"] == 650 and summary["well_changes"] >= 1


def test_v5_and_v73_logs_ingest_to_identical_tables(rig_run):
    wf, _ = rig_run
    tables = Runner(wf).tables("ingest")
    a, b = tables["a73"], tables["a5"]
    assert list(a.columns) == ["t", "q", "v1", "v2", "r1"]
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
    assert a.attrs["units"]["q"] == "m"


def test_logged_q_is_the_truth_plus_sensor_noise(rig_run):
    wf, _ = rig_run
    table = Runner(wf).tables("ingest")["a73"]
    truth = artifacts.read_h5(wf.stage_dir("rig") / "a73_truth.h5")
    err = table["q"].to_numpy() - truth["states"]["q"]
    # 1 um rms per internal sample, FIR-decimated by 10: about 0.3 um in the log, 0.3 um
    # steps; during switching the anti-aliasing filter also removes content above 50 Hz
    assert 0.05e-6 < np.median(np.abs(err)) < 0.5e-6
    assert abs(np.median(err)) < 0.1e-6
    assert np.max(np.abs(err)) < 0.1e-3
    np.testing.assert_allclose(table["r1"].max(), 3000.0, rtol=1e-9)
    assert np.median(np.abs(table["v1"] - truth["states"]["v1"])) < 2.0  # monitor noise [V]


def test_rerun_skips_and_ingest_follows_the_rig(rig_run, tmp_path):
    wf, manifests = rig_run
    states = {s.stage: s.state for s in Runner(load_workflow(wf.path)).status()}
    assert states["rig"] == "up to date" and states["ingest"] == "up to date"
    assert manifests["ingest"].inputs["a73:source"] == manifests["rig"].outputs["a73.mat"]
    changed = Path(tmp_path / "changed.toml")
    changed.write_text(WORKFLOW.replace('seed = 5\nformat = "5"', 'seed = 6\nformat = "5"'))
    status = Runner(load_workflow(changed, wf.output_dir)).status()
    reasons = {s.stage: (s.state, s.reason) for s in status}
    assert reasons["rig"][0] == "stale" and "rig" in reasons["rig"][1]
    assert reasons["ingest"] == ("stale", "upstream 'rig' will rerun")


def test_the_stages_after_the_rig_load_while_its_workers_integrate(tmp_path, monkeypatch):
    """The runner loads the pending stages (``preload``) in this process during the rig
    stage when its experiments run in workers, before the next stage starts; with the rig
    alone, or the experiments run serially, nothing is loaded ahead."""
    path = tmp_path / "rig.toml"
    path.write_text(WORKFLOW, encoding="utf-8")
    wf = load_workflow(path)
    events = []
    real_execute = ingest.execute
    monkeypatch.setattr(ingest, "preload", lambda ctx: events.append(("preload", os.getpid())))
    monkeypatch.setattr(
        ingest, "execute", lambda ctx: events.append(("execute", os.getpid())) or real_execute(ctx)
    )
    Runner(wf).run(["rig"], force=True)
    assert events == []
    Runner(wf).run(["rig", "ingest"], force=True)
    if fork_workers(2) >= 2:
        assert events == [("preload", os.getpid()), ("execute", os.getpid())]
    events.clear()
    monkeypatch.setattr(experiment, "fork_workers", lambda n: 1)
    Runner(wf).run(["rig", "ingest"], force=True)
    assert events == [("execute", os.getpid())]


def test_rig_workflow_errors(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(WORKFLOW.replace('rig = "a5"', 'rig = "nope"'), encoding="utf-8")
    with pytest.raises(WorkflowError) as err:
        load_workflow(path)
    assert err.value.key == "datasets.a5.rig"
    assert "name" in str(err.value) and "rig" in str(err.value)
    path.write_text(WORKFLOW.replace('format = "5"', 'format = "6"'), encoding="utf-8")
    with pytest.raises(WorkflowError) as err:
        Runner(load_workflow(path)).run(["rig"])
    assert err.value.key == "rig.experiments.a5.format"
    assert "'6'" in str(err.value)
    assert not (tmp_path / "runs" / "rig").exists()


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"experiments": {"a": {"profile": "chirp"}}}, r"\[rig.experiments.a\] profile: .*'chirp'"),
        ({"plant": {"friction_q": 1}, "experiments": {"a": {}}}, r"\[rig.plant\] unknown key"),
        ({"experiments": {"a": {"seeed": 1}}}, r"\[rig.experiments.a\] unknown key 'seeed'"),
        ({"experiments": {"a": {"format": "6"}}}, r"\[rig.experiments.a\] format: .*got '6'"),
        (
            {"experiments": {"a": {"profile": "validation", "ramps": [1.0]}}},
            r"\[rig.experiments.a\] ramps: only the identification profile has ramps",
        ),
        ({"experiments": {"a": {"ramps": []}}}, r"\[rig.experiments.a\] ramps: expected at least"),
        ({"experiments": {"a": {"ramps": [-1]}}}, r"\[rig.experiments.a\] ramps\[0\]: .*>= 0"),
        ({"experiments": {}}, r"\[rig\] experiments: expected at least one \[rig.experiments"),
        ({"sample_time": -1, "experiments": {"a": {}}}, r"\[rig\] sample_time: .* > 0, got -1"),
    ],
)
def test_rig_section_errors_name_the_table(section, match):
    from debist.rig.experiment import RigConfig

    with pytest.raises(WorkflowError, match=match):
        RigConfig.from_dict(section, {})


def test_ramps_reach_the_identification_profile():
    from debist.rig.experiment import RigConfig

    rig = RigConfig.from_dict({"experiments": {"a": {"ramps": [0, 1.5]}}}, {})
    kwargs = rig.experiments["a"].profile_kwargs()
    assert kwargs["ramps"] == (0.0, 1.5)
    exc = make_profile("identification", **kwargs)
    pulses = [b - a for lab, a, b in exc.segments if lab.startswith("pulse")]
    assert pulses[:2] == pytest.approx([0.6, 0.8 + 2 * 1.5])


def test_the_rig_builds_its_profile_from_every_experiment_setting(monkeypatch):
    """run_experiment hands the experiment's whole profile_kwargs to the profile (a copy of
    them once dropped ``ramps`` silently)."""
    from debist.rig import experiment
    from debist.rig.experiment import RigConfig

    seen = {}

    class Stop(Exception):
        pass

    def spy(name, **kwargs):
        seen.update(name=name, **kwargs)
        raise Stop

    monkeypatch.setattr(experiment, "make_profile", spy)
    table = {"ramps": [0, 1.5], "v_sub": 900.0, "profile_seed": 7, "duration": 20.0}
    rig = RigConfig.from_dict({"experiments": {"a": table}}, {})
    with pytest.raises(Stop):
        experiment.run_experiment(rig, "a")
    assert seen == {"name": "identification", **rig.experiments["a"].profile_kwargs()}
    assert (seen["ramps"], seen["v_sub"], seen["seed"], seen["duration"]) == (
        (0.0, 1.5),
        900.0,
        7,
        20.0,
    )
