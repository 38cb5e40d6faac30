"""The analyze stage (`debist analyze`): a [physics]-only workflow through the runner and CLI."""

from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core import artifacts
from debist.core.errors import WorkflowError
from debist.engine.runner import Runner
from debist.workflow.loader import load_workflow

ROOT = Path(__file__).resolve().parents[2]
FIGURES = (
    "fig3_prestrain.png",
    "fig4_force_displacement.png",
    "fig5_capacitance.png",
    "fig6a_modes.png",
    "fig7_full_vs_reduced.png",
    "reduced_curves.png",
)

SMALL = """
[workflow]
name = "design"
output_dir = "runs"

[physics]
b = 23e-3

[analyze]
b_range = [17.5e-3, 30e-3]
n_b = 11
n_q = 41
t_end = 0.5
left = [0.05, 0.2]
right = [0.3, 0.4]
degree = 20
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "design.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("analyze")
    wf = load_workflow(write(tmp, SMALL))
    manifests = Runner(wf).run()
    return wf, manifests


@pytest.mark.slow
def test_physics_only_workflow_runs_just_analyze(analysed):
    wf, manifests = analysed
    assert list(manifests) == ["analyze"]
    assert wf.datasets == ()
    outputs = manifests["analyze"].outputs
    assert set(outputs) == {"statics.h5", "summary.json", *FIGURES}
    for name in FIGURES:
        assert (wf.stage_dir("analyze") / name).stat().st_size > 10_000


def test_statics_h5_holds_the_behaviour_points(analysed):
    wf, _ = analysed
    with h5py.File(wf.stage_dir("analyze") / "statics.h5") as fh:
        pre = fh["prestrain"]
        assert pre.attrs["z_b_min"] == pytest.approx(4.837e-3, abs=5e-6)
        assert pre.attrs["z_b_max"] == pytest.approx(11.653e-3, abs=5e-6)
        rest = fh["operating_points/v1_0kV_v2_0kV"]
        q, stable = rest["q"][()], rest["stable"][()]
        np.testing.assert_allclose(q, [-10.206e-3, 0.0, 10.206e-3], atol=2e-6)
        assert stable.tolist() == [True, False, True]
        assert fh["operating_points/v1_3kV_v2_0kV/q"][()] == pytest.approx([12.894e-3], abs=2e-6)
        fd = fh["force_displacement/v1_0kV_v2_0kV"]
        F = fd["F"][()]
        # F(q) is odd at v = 0 (symmetric prototype) and spans about +-100 mN on +-15 mm
        np.testing.assert_allclose(F, -F[::-1], atol=1e-9)
        assert 0.05 < np.max(np.abs(F)) < 0.2
        assert fh["comparison"].attrs["nrmse_q"] < 0.05
        assert fh["params/E"][()] == 2.1e9


def test_second_run_skips_and_config_change_reruns(analysed, tmp_path):
    wf, manifests = analysed
    again = Runner(load_workflow(wf.path)).run()
    assert again["analyze"].key == manifests["analyze"].key
    states = Runner(load_workflow(wf.path)).status()
    assert [(s.stage, s.state) for s in states] == [("analyze", "up to date")]
    changed = write(tmp_path, SMALL.replace("b = 23e-3", "b = 24e-3"))
    status = Runner(load_workflow(changed, wf.output_dir)).status()
    assert status[0].state == "stale" and "physics" in status[0].reason


def test_bad_physics_key_and_empty_workflow_are_workflow_errors(tmp_path):
    with pytest.raises(WorkflowError) as err:
        load_workflow(write(tmp_path, SMALL.replace("b = 23e-3", "Ee = 2e9")))
    assert err.value.key == "physics.Ee"
    assert "unknown" in str(err.value)
    assert "'E'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        load_workflow(write(tmp_path, SMALL.replace("b = 23e-3", "l_0 = -1.0")))
    assert err.value.key == "physics.l_0"
    assert "> 0" in str(err.value)
    assert "got -1.0" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        load_workflow(write(tmp_path, '[workflow]\nname = "x"\n'))
    assert "least" in str(err.value) and "datasets" in str(err.value)


def test_bad_analyze_key_fails_without_artifacts(tmp_path):
    path = write(tmp_path, SMALL.replace("n_b = 11", "n_b = 1"))
    result = CliRunner().invoke(app, ["analyze", str(path)])
    assert result.exit_code == 2
    assert "[analyze]" in result.output and "n_b" in result.output
    assert artifacts.read_manifest(tmp_path / "runs" / "analyze") is None


@pytest.mark.slow
def test_paper_analysis_workflow_through_the_cli(tmp_path):
    result = CliRunner().invoke(
        app, ["analyze", str(ROOT / "workflows" / "paper-analysis.toml"), "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    assert "4.837" in result.output and "11.65" in result.output
    for name in FIGURES:
        assert (tmp_path / "analyze" / name).is_file()
