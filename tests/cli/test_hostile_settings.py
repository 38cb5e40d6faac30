"""Settings a hostile probe tried: each refused with exit code 2 in one line, nothing written."""

from __future__ import annotations

import pytest

from debist import api
from debist.core.errors import WorkflowError
from debist.core.preflight import BUDGET_ENV
from tests.conftest import SYNTHETIC_WORKFLOW, invoke_cli, write_rig_csv

#: The paper's experiment on the virtual rig, shortened: its data come from [rig], so the
#: data's length (3750 samples) is known before any stage runs.
WORKFLOW = """
[workflow]
name = "probe"
output_dir = "runs/probe"

[physics]
b = 23e-3

[rig]
sample_time = 0.01

[rig.experiments.identification]
profile = "identification"
duration = 37.5

[ingest]
q = { regex = "Laser/q$", unit = "mm" }
v1 = { regex = "DE1/v_mon$", unit = "kV" }
v2 = { regex = "DE2/v_mon$", unit = "kV" }

[datasets.identification]
rig = "identification"
role = "estimation"

[identify]
M = 6
"""


@pytest.fixture
def probe(tmp_path, monkeypatch):
    """The workflow in a folder of its own, a fixed 4 GB budget, the folder's files before."""
    monkeypatch.setenv(BUDGET_ENV, "4")
    (tmp_path / "wf.toml").write_text(WORKFLOW)
    return tmp_path / "wf.toml"


def _files(folder):
    return sorted(p.relative_to(folder) for p in folder.rglob("*"))


def _one_line_error(out: str) -> str:
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1, out
    assert "Traceback" not in out
    return lines[0]


def test_a_huge_m_with_no_rbf_curve_is_refused_before_any_stage(probe):
    # no c, d or g curve: the least squares has 5 columns, but the stage still evaluates the
    # Gaussian basis on the curves' 4001 positions (3 x 8 bytes each): 9.6 GB for M = 10^5
    before = _files(probe.parent)
    code, out = invoke_cli(
        "run", probe, "--set", "identify.M=100000", "--set", "identify.rbf=[]",
        "--set", 'identify.m_q="identify"', "--set", "identify.input_gain=[1.0, -1.0]",
    )  # fmt: skip
    assert code == 2
    line = _one_line_error(out)
    assert "[identify] M = 100000:" in line and "3750 samples" in line
    assert "needs about 9.6 GB" in line and "budget is 4 GB" in line
    assert _files(probe.parent) == before


def test_a_large_m_on_a_log_file_is_refused_once_its_length_is_known(
    tmp_path, monkeypatch, bistable_record
):
    # a log file's length is known after the ingest. Before, M = 10^4 fits 1.2 GB: the
    # Gaussian basis on the curves' 4001 positions, 3 x 4001 x 10^4 x 8 bytes = 0.96 GB; on
    # the 6000 samples read it does not (1.44 GB), and the identify stage refuses the fit
    # before its support checks build samples x centres
    monkeypatch.setenv(BUDGET_ENV, "1.2")
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    code, out = invoke_cli(
        "run", tmp_path / "wf.toml", "--stages", "ingest,differentiate,identify",
        "--set", "identify.M=10000", "--set", "identify.rbf=[]",
        "--set", 'identify.m_q="identify"', "--set", "identify.input_gain=[1.0, -1.0]",
        "--set", "datasets.estimation.slice=[0, 6000]",
    )  # fmt: skip
    assert code == 2, out
    assert "Traceback" not in out and "MemoryError" not in out
    (line,) = [line for line in out.splitlines() if line.startswith("error:")]
    assert "[identify] M = 10000: the regressor of 6000 samples x 4 columns" in line
    assert "needs about 1.44 GB" in line
    (folder,) = tmp_path.glob("out.set-*")
    assert (folder / "differentiate").is_dir() and not (folder / "identify").exists()


def test_a_huge_m_on_a_log_file_is_refused_before_any_stage(tmp_path, monkeypatch):
    # whatever the data, the curves' 4001 positions x 10^6 centres need 3 x 8 bytes each
    monkeypatch.setenv(BUDGET_ENV, "4")
    (tmp_path / "rig.csv").write_text("time_ms,laser,v_left,v_right\n0,0,0,0\n")
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    before = _files(tmp_path)
    code, out = invoke_cli(
        "run", tmp_path / "wf.toml", "--set", "identify.M=1000000", "--set", "identify.rbf=[]",
        "--set", 'identify.m_q="identify"', "--set", "identify.input_gain=[1.0, -1.0]",
    )  # fmt: skip
    assert code == 2
    line = _one_line_error(out)
    assert "[identify] M = 1000000: the regressor of at least 4 samples" in line
    assert "needs about 96 GB" in line
    assert _files(tmp_path) == before


def test_a_rig_experiment_beyond_the_budget_is_refused_before_any_stage(probe):
    before = _files(probe.parent)
    code, out = invoke_cli("run", probe, "--set", "rig.experiments.identification.duration=2e5")
    assert code == 2
    line = _one_line_error(out)
    assert "[rig.experiments.identification] duration = 200000 s" in line
    assert "budget is 4 GB" in line
    assert _files(probe.parent) == before


def test_a_prototype_without_a_start_well_is_a_setting_error_not_a_traceback(probe):
    code, out = invoke_cli("run", probe, "--set", "physics.b=100000.0")
    assert code == 2, out
    assert "Traceback" not in out
    (line,) = [line for line in out.splitlines() if line.startswith("error:")]
    assert line.startswith("error: [rig.experiments.identification] side = -1: no stable")
    assert not list(probe.parent.glob("runs/probe*/rig/*.mat"))


def test_an_analysis_of_a_prototype_without_a_well_is_a_setting_error(tmp_path):
    (tmp_path / "wf.toml").write_text('[workflow]\noutput_dir = "out"\n[physics]\nb = 1e5\n')
    code, out = invoke_cli("run", tmp_path / "wf.toml")
    assert code == 2, out
    assert "Traceback" not in out
    (line,) = [line for line in out.splitlines() if line.startswith("error:")]
    assert line == (
        "error: [physics] the prototype cannot be analysed: no stable equilibrium with "
        "sign(q) = -1 (b = 100000.0); check its parameters"
    )
    assert not (tmp_path / "out" / "analyze").exists()


@pytest.mark.parametrize(
    "item",
    [
        'identify.M=6\n[workflow]\noutput_dir="elsewhere"',
        'identify.M=6\r\n[workflow]\r\noutput_dir="elsewhere"',
        "identify.M=6\u2028[workflow]",
        "identify.M=[\n6]",
    ],
)
def test_a_set_value_spanning_lines_is_refused_naming_the_option(probe, item):
    before = _files(probe.parent)
    code, out = invoke_cli("run", probe, "--set", item)
    assert code == 2
    line = _one_line_error(out)
    assert line.startswith(f"error: --set {item!r}: expected one KEY=VALUE on one line")
    assert _files(probe.parent) == before


def test_a_python_override_key_spanning_lines_is_refused(probe):
    with pytest.raises(WorkflowError, match="holds a line break: not a TOML key"):
        api.load_workflow(probe, overrides={"identify.M = 6\n[workflow]\noutput_dir": "x"})


def test_a_set_value_on_one_line_still_parses(probe):
    wf = api.load_workflow(probe, overrides=["identify.M=8", 'identify.constraints=["d >= 0"]'])
    assert wf.section("identify")["M"] == 8
    assert wf.section("identify")["constraints"] == ["d >= 0"]


@pytest.mark.parametrize("option", [("--set", 'workflow.output_dir="/"'), ("--out", "/")])
def test_the_file_system_root_as_output_folder_is_refused_in_one_line(probe, option):
    before = _files(probe.parent)
    code, out = invoke_cli("run", probe, *option)
    assert code == 2
    line = _one_line_error(out)
    assert "'/' is the root of the file system" in line
    assert _files(probe.parent) == before


def test_a_negative_fleet_seed_is_refused_before_the_folder_is_made(probe):
    code, out = invoke_cli("fleet", probe, "--size", 1, "--seed", -5, "--dir", probe.parent / "f")
    assert code == 2
    assert "--seed" in out and "Traceback" not in out
    assert not (probe.parent / "f").exists()


def test_a_negative_fleet_seed_is_refused_by_the_api(probe):
    with pytest.raises(WorkflowError, match=r"^seed must be at least 0, got -5$"):
        api.fleet(probe, 1, seed=-5, folder=probe.parent / "f")
    assert not (probe.parent / "f").exists()
