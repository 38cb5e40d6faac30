"""The plant zoo: seeded members, their minimal workflows and truth, the batch's zoo table."""

import json
import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from debist import api
from debist.core.errors import OutputDirError, WorkflowError
from debist.engine.batch import expand_workflows
from debist.engine.zoo import member_workflow, write_zoo
from debist.engine.zooindex import ZooError, read_zoo
from debist.physics.params import PrototypeParams
from debist.rig.run import true_curves
from debist.rig.zoo import ESTIMATION_PROFILES, draw_member, member_ok

P0 = PrototypeParams.paper()


def test_a_member_depends_on_its_seed_and_index_only():
    a, b = draw_member(1, 3), draw_member(1, 3)
    assert a.rig == b.rig and a.name == "m003"
    assert draw_member(2, 3).rig != a.rig
    assert draw_member(1, 3, attempt=1).rig != a.rig
    with pytest.raises(ValueError) as err:
        draw_member(-1, 0)
    assert "seed" in str(err.value)


def test_members_span_the_plants_frictions_asymmetries_sensors_and_profiles():
    members = [draw_member(1, i) for i in range(60)]
    traits = pd.DataFrame([m.traits for m in members])
    plants = [m.rig["plant"] for m in members]
    protos = [m.rig["prototype"] for m in members]
    assert set(traits.plant) == {"full", "reduced"}
    assert set(traits.friction) == {"maxwell-slip", "coulomb+viscous", "viscous"}
    slips = traits.slip_elements[traits.friction == "maxwell-slip"]
    assert slips.min() == 1 and slips.max() == 5
    assert set(traits.sensor_average) == set(range(1, 11))
    assert set(traits.estimation_profile) == set(ESTIMATION_PROFILES)
    for p in plants:
        assert 0.85 <= p["gain_1"] <= 1.15 and 0.85 <= p["gain_2"] <= 1.15
        assert abs(p["sensor_offset"]) <= 0.5e-3 and abs(p["force_offset"]) <= 2e-3
        assert 1e-3 <= p["driver_tau"] <= 10e-3
        assert p["sensor_resolution"] <= 0.5 * p["sensor_noise"]
    mass = np.array([p["m"] / P0.m for p in protos])
    damping = np.array([p["eta"] / P0.eta for p in protos])
    assert mass.min() >= 0.7 and mass.max() <= 1.3 and np.ptp(mass) > 0.4
    assert damping.min() >= 0.5 and damping.max() <= 2.0 and damping.max() / damping.min() > 2.5
    for m in members:  # an estimation record and two unseen ones, of other profiles
        assert m.roles == {"estimation": "estimation", "unseen_1": "validation",
                           "unseen_2": "validation"}  # fmt: skip
        assert m.traits["estimation_profile"] not in m.traits["unseen_profiles"]


def test_the_member_workflow_holds_channels_units_input_map_and_roles_only():
    member = draw_member(1, 0)
    raw = tomllib.loads(member_workflow(member))
    assert set(raw) == {"workflow", "ingest", "identify", "datasets"}
    assert raw["identify"] == {"input_map": "v2"}
    assert set(raw["ingest"]) == {"q", "v1", "v2"}
    assert all(set(ch) == {"regex", "unit"} for ch in raw["ingest"].values())
    assert {n: d["role"] for n, d in raw["datasets"].items()} == member.roles
    assert raw["workflow"]["output_dir"] == "run"


def test_static_viability_includes_the_tip_force_and_the_gains():
    member = draw_member(1, 0)
    rig = member.rig_params()
    assert member_ok(rig)
    assert not member_ok(rig.replace(force_offset=40e-3))  # one well gone
    assert not member_ok(rig.replace(gain_1=0.05))  # DE 1 too weak to switch


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    folder = tmp_path_factory.mktemp("zoo") / "z"
    result = write_zoo(folder, 1, 1)
    return folder, result


@pytest.mark.slow
def test_write_zoo_writes_logs_workflow_and_truth_and_never_overwrites(zoo, tmp_path):
    folder, result = zoo
    member = folder / "m000"
    assert result.members == ("m000",) and result.written == ("m000",)
    files = {p.name for p in member.iterdir()}
    assert files == {"estimation.mat", "unseen_1.mat", "unseen_2.mat", "workflow.toml",
                     "truth.json", "truth.parquet"}  # fmt: skip
    truth = json.loads((member / "truth.json").read_text())
    assert read_zoo(folder)["members"] == ["m000"]
    for rec in truth["records"].values():
        assert 0.0 < rec["floor_nrmse_q"] < 2.0
    assert truth["records"]["estimation"]["well_changes"] >= 2
    frame = pd.read_parquet(member / "truth.parquet")
    assert list(frame.columns) == ["q", "restoring", "g1", "g2", "m_q"]
    # per unit mass, in the logged coordinate (tip + the laser's zero offset)
    draw = draw_member(1, 0, truth["zoo"]["attempt"])
    rig = draw.rig_params()
    offset = rig.sensor_offset
    i = len(frame) // 3
    c = true_curves(rig, frame.q.to_numpy()[i : i + 2] - offset)
    assert frame.restoring[i] == pytest.approx(c["f"][0] / c["m_q"][0], rel=1e-6)
    assert frame.g2[i] == pytest.approx(c["g2"][0] / c["m_q"][0], rel=1e-6)
    assert truth["plant"]["gain_1"] == pytest.approx(rig.gain_1)
    wells = np.array(truth["wells"])
    restoring_at_wells = np.interp(wells, frame.q, frame.restoring)
    assert np.all(np.abs(restoring_at_wells) < 0.05 * np.ptp(frame.restoring))
    # a rerun keeps the member; another seed or a foreign folder is refused
    again = write_zoo(folder, 1, 1)
    assert again.written == ()
    with pytest.raises(OutputDirError) as err:
        write_zoo(folder, 1, 2)
    assert "seed" in str(err.value)
    (tmp_path / "mine.txt").write_text("a user's file")
    with pytest.raises(OutputDirError) as err:
        write_zoo(tmp_path, 1, 1)
    assert "zoo" in str(err.value)
    assert (tmp_path / "mine.txt").read_text() == "a user's file"
    assert expand_workflows([folder]) == [(member / "workflow.toml").resolve()]


@pytest.mark.slow
def test_batch_over_a_zoo_writes_the_zoo_table(zoo):
    folder, _ = zoo
    results = api.run_batch([folder], scheduler="synchronous")
    assert [r.status for r in results] == ["done"]
    table_path, page, table, summary = api.zoo_report(folder)
    row = table.iloc[0]
    assert row.status == "done" and table_path.name == "zoo.parquet"
    for model in ("rbf", "narx", "sindy"):
        value = row[f"{model}_unseen"]
        assert value > 0 and (math.isfinite(value) or row[f"{model}_status"] != "ok")
        assert isinstance(row[f"{model}_lost_switch"], bool | np.bool_)
    assert 0 < row.floor_unseen < 2 and row.narx_terms >= 1
    for curve in ("restoring", "g1", "g2"):
        assert row[f"{curve}_marked"] >= 0
        if row[f"{curve}_marked"]:
            assert 0 <= row[f"{curve}_coverage"] <= 100 and row[f"{curve}_max_error"] >= 0
    assert summary.loc["median", "floor_unseen"] == pytest.approx(row.floor_unseen)
    assert isinstance(row.unseen_extrapolated, bool | np.bool_)  # counted, not averaged:
    assert summary.loc["worst", "unseen_extrapolated"] == float(row.unseen_extrapolated)
    html = page.read_text()
    assert "Content-Security-Policy" in html and "<script" not in html
    assert pd.read_parquet(table_path).member.tolist() == ["m000"]


def test_a_damaged_zoo_index_is_refused_by_name(tmp_path):
    (tmp_path / "zoo.json").write_text('{"members": ["../../etc"]}')
    with pytest.raises(ZooError) as err:
        read_zoo(tmp_path)
    assert "json" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        expand_workflows([tmp_path])
    assert "zoo" in str(err.value)


def test_an_unfinished_zoo_is_marked_refused_by_batch_and_its_scratch_cleared(
    tmp_path, monkeypatch
):
    import debist.engine.zoo as zoo_module

    def stopped(seed, i):
        raise KeyboardInterrupt

    folder = tmp_path / "z"
    monkeypatch.setattr(zoo_module, "_simulate", stopped)
    with pytest.raises(KeyboardInterrupt):
        write_zoo(folder, 3, 1)
    index = read_zoo(folder)
    assert index["complete"] is False and index["members"] == ["m000", "m001", "m002"]
    with pytest.raises(WorkflowError) as err:
        expand_workflows([folder])
    assert str(err.value) == (
        f"the zoo '{folder}' is unfinished (0 of 3 members; debist zoo was stopped): finish it "
        f"first with: debist zoo --size 3 --seed 1 --dir {folder}"
    )
    # a member's scratch folder of a killed process goes at the next start, nothing else
    (folder / ".m000.0123abcd.tmp").mkdir()
    (folder / ".m000.0123abcd.tmp" / "estimation.mat").write_bytes(b"half")
    (folder / ".keep").write_text("a user's hidden file")
    with pytest.raises(KeyboardInterrupt):
        write_zoo(folder, 3, 1)
    assert sorted(p.name for p in folder.iterdir()) == [".keep", "zoo.json"]


@pytest.mark.slow
def test_a_zoo_stopped_by_sigterm_is_resumed_by_the_same_command(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    from debist.core.artifacts import sha256_file

    folder = tmp_path / "z"
    cmd = [sys.executable, "-m", "debist", "zoo", "--size", "2", "--dir", str(folder)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (folder / "m000").is_dir() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert (folder / "m000").is_dir()
        os.kill(proc.pid, signal.SIGTERM)
        _out, errs = proc.communicate(timeout=60)
    finally:
        proc.kill()
    again = f"debist zoo --size 2 --seed 1 --dir {folder}"
    assert proc.returncode == 143, errs
    assert errs.strip() == (
        "interrupted by SIGTERM: stopped; the members written are kept; finish the zoo with: "
        + again
    )
    kept = {p.name: sha256_file(p) for p in (folder / "m000").iterdir()}
    assert not (folder / "m001").exists() and read_zoo(folder)["complete"] is False
    batch = subprocess.run([sys.executable, "-m", "debist", "batch", str(folder)],
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    assert batch.returncode == 2 and batch.stderr.count("\n") == 1, batch.stderr
    assert f"finish it first with: {again}" in batch.stderr
    rerun = subprocess.run([sys.executable, "-m", "debist", *again.split()[1:]],
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert rerun.returncode == 0, rerun.stderr
    assert "(1 were there)" in rerun.stdout
    assert {p.name: sha256_file(p) for p in (folder / "m000").iterdir()} == kept
    index = read_zoo(folder)
    assert index["complete"] is True and index["members"] == ["m000", "m001"]
    assert (folder / "m001" / "truth.json").is_file()
