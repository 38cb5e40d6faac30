"""`run --set KEY=VALUE` (one setting changed for one run) and `diff RUN_A RUN_B`."""

import json
import shutil

import pytest
from conftest import invoke_cli

from debist.engine import artifacts
from debist.errors import WorkflowError
from debist.workflow.loader import load_workflow, parse_overrides


def invoke(*args):
    code, out = invoke_cli(*args)
    return code, " ".join(out.split())


@pytest.fixture
def base(synthetic_run):
    return synthetic_run[0]


def test_overrides_parse_as_toml_with_a_string_fallback_and_are_checked(tmp_path, base):
    assert parse_overrides(["identify.M=6", 'datasets."a.b".role="validation"', "x.y=[1, 2]"]) == {
        "identify": {"M": 6},
        "datasets": {"a.b": {"role": "validation"}},
        "x": {"y": [1, 2]},
    }
    assert parse_overrides(["differentiate.method=spectral"]) == {
        "differentiate": {"method": "spectral"}
    }
    with pytest.raises(WorkflowError, match="expected KEY=VALUE"):
        parse_overrides(["identify.M"])
    with pytest.raises(WorkflowError, match=r"\[identify\] M: expected an integer, got 'six'"):
        load_workflow(base / "wf.toml", overrides=["identify.M=six"])
    with pytest.raises(WorkflowError, match=r"\[identify\] unknown key 'N'"):
        load_workflow(base / "wf.toml", overrides={"identify.N": 3})
    wf = load_workflow(base / "wf.toml", overrides={"identify.M": 6, "identify.sigma_n": 1.0})
    assert wf.sections["identify"]["M"] == 6 and wf.sections["identify"]["sigma_n"] == 1.0


@pytest.mark.slow
def test_run_set_changes_one_setting_records_it_and_diff_shows_it(base, tmp_path):
    shutil.copytree(base, tmp_path / "p")
    root = tmp_path / "p"
    code, out = invoke("run", root / "wf.toml", "--out", tmp_path / "b", "--set", "identify.M=6")
    assert code == 0, out
    assert artifacts.read_manifest(tmp_path / "b" / "identify").config["M"] == 6
    assert artifacts.read_manifest(root / "out" / "identify").config["M"] == 8
    # verify and status judge the run by the workflow they are given
    assert invoke("verify", root / "wf.toml", "--out", tmp_path / "b", "-S", "identify.M=6")[0] == 0
    code, out = invoke("verify", root / "wf.toml", "--out", tmp_path / "b")
    assert code == 3 and "[identify] M (6 -> 8)" in out

    code, out = invoke("diff", root / "out", tmp_path / "b", "--json")
    assert code == 0, out
    found = json.loads(out)
    assert {"stage": "identify", "key": "M", "a": 8, "b": 6} in found["config"]
    assert all(r["stage"] != "ingest" for r in found["config"])
    rbf = [r for r in found["nrmse"] if r["model"] == "rbf" and r["metric"] == "nrmse_q [%]"]
    assert rbf and all(r["a"] != r["b"] for r in rbf)
    table = artifacts.read_parquet(tmp_path / "b" / "compare" / "nrmse.parquet")
    row = table[(table.model == "rbf") & (table.dataset == "check")].iloc[0]
    (check,) = [r for r in rbf if r["dataset"] == "check"]
    assert check["b"] == pytest.approx(100 * row.nrmse_q)
    code, out = invoke("diff", root / "out", tmp_path / "b")
    assert code == 0 and "settings that differ" in out and "NRMSE that differs" in out
    code, out = invoke("diff", root / "out", root / "out")
    assert code == 0 and "same settings and NRMSE" in out
    code, out = invoke("diff", root / "out", tmp_path / "nowhere")
    assert code == 2 and "not an output folder" in out
