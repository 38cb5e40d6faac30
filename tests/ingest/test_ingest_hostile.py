"""Absurd values, a unit slip inside a record and a motionless q: data errors, named."""

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core.errors import RigLogError
from debist.ingest.checks import check_plausible, check_scale_jump
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, " ".join(result.output.split())


@pytest.fixture
def project(tmp_path, bistable_record):
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    return tmp_path


def edit_log(root, change):
    log = pd.read_csv(root / "rig.csv")
    change(log)
    log.to_csv(root / "rig.csv", index=False)


def test_an_absurd_value_is_refused_at_ingest_naming_file_channel_and_value(project):
    edit_log(
        project, lambda log: log.__setitem__("laser", log["laser"].where(log.index != 700, 1e308))
    )
    code, out = invoke("run", project / "wf.toml", "--stages", "ingest")
    assert code == 1
    assert "rig.csv" in out and "channel 'laser'" in out and "1e+305 m" in out
    assert "sample 700" in out and "plausible" in out and "length" in out
    assert not (project / "out" / "ingest").exists()


def test_a_unit_slip_inside_the_record_is_refused_with_its_time(project):
    def slip(log):  # from sample 3000 on, q written in m instead of mm
        log.loc[3000:, "laser"] = log.loc[3000:, "laser"] / 1000.0

    edit_log(project, slip)
    code, out = invoke("run", project / "wf.toml", "--stages", "ingest")
    assert code == 1
    assert "channel 'laser'" in out and "10^-3" in out and "sample 3000" in out
    assert "t = 6 s" in out


def test_fast_switching_and_zero_crossings_are_not_a_unit_slip(bistable_record):
    q = bistable_record["q"]
    t = bistable_record["t"]
    assert np.sign(q).min() < 0 < np.sign(q).max()  # the record switches wells
    check_scale_jump(q, t, np.arange(q.size), role="q", channel="laser", path=__file__)
    rng = np.random.default_rng(2)  # settling at q = 0 from a well, with um noise
    settle = np.r_[np.full(200, 0.01), 2e-6 * rng.standard_normal(200)]
    check_scale_jump(settle, np.arange(400.0), np.arange(400), role="q", channel="x", path="x")


def test_plausibility_by_quantity():
    t, idx = np.arange(3.0), np.arange(3)
    check_plausible(np.array([0, 99.0, -99.0]), t, idx, role="q", quantity="length", unit="m",
                    channel="x", path="f")  # fmt: skip
    check_plausible(np.array([0, 1e30, 0]), t, idx, role="q", quantity="dimensionless",
                    unit="1", channel="x", path="f")  # fmt: skip
    with pytest.raises(RigLogError) as err:
        check_plausible(np.array([0, 2e6, 0]), t, idx, role="v1", quantity="voltage", unit="V",
                        channel="x", path="f")  # fmt: skip
    assert "`v1`" in str(err.value)
    assert err.value.value == 2e6 and "2e+06 V" in str(err.value)
    assert err.value.sample == 1
    assert "voltage" in str(err.value)


def test_a_motionless_q_is_a_data_error_naming_file_and_channel(project):
    edit_log(project, lambda log: log.__setitem__("laser", 1.0))
    code, out = invoke("run", project / "wf.toml")
    assert code == 1, out
    assert "channel 'laser'" in out and "rig.csv" in out
    assert "constant (0.001 m)" in out and "(estimation)" in out
    assert "operating" not in out


def test_a_laser_error_code_beyond_the_ild2300_range_is_refused_without_a_range(project):
    """The channel names a known sensor: its documented +-25 mm is the default `range`."""
    from debist.core.errors import DebistWarning

    def rename(log):
        log.insert(1, "ILD2300 distance", log.pop("laser"))  # same column, the sensor's name
        log.loc[1500:1504, "ILD2300 distance"] = 262.14  # an error code for 5 samples

    edit_log(project, rename)
    wf = project / "wf.toml"
    wf.write_text(wf.read_text().replace('name = "laser"', 'name = "ILD2300 distance"'))
    with pytest.warns(DebistWarning, match=r"ILD2300.*no `range`"):
        code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 1
    assert "channel 'ILD2300 distance'" in out and "limit 25 mm" in out
    assert not (project / "out" / "ingest").exists()
