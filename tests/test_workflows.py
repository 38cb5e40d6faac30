"""The shipped workflows on the shipped real data: the acceptance numbers of the README."""

import time
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli import app

ROOT = Path(__file__).resolve().parents[1]


def run(workflow, out):
    result = CliRunner().invoke(app, ["run", str(ROOT / "workflows" / workflow), "--out", str(out)])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.slow
def test_silverbox_protocol_rms_and_cached_rerun(tmp_path):
    out = run("silverbox.toml", tmp_path)
    table = pd.read_parquet(tmp_path / "validate/nrmse.parquet").set_index("dataset")
    assert (table.rms_unit == "mV").all()
    assert table.loc["test_multisine", "rms_q"] <= 2.5
    assert table.loc["test_arrow_no_extrapolation", "rms_q"] <= 2.5
    assert (
        table.loc["test_arrow_full", "rms_q"] < 10.0
        and not table.loc["test_arrow_full", "diverged"]
    )
    assert table.loc["test_multisine", "n_samples"] == 127400 - 105712 - 50
    assert "SUBNET" in out  # published rows printed beside ours
    t0 = time.perf_counter()
    again = run("silverbox.toml", tmp_path)
    assert time.perf_counter() - t0 < 3.0
    assert again.count("up to date, skipping") == 5
    both = pd.read_parquet(tmp_path / "compare/nrmse.parquet")
    assert set(both.model) == {"rbf", "sindy"}


@pytest.mark.slow
def test_emps_identifies_mass_and_friction_near_idim(tmp_path):
    out = run("emps.toml", tmp_path)
    import json

    summary = json.loads((tmp_path / "identify/manifest.json").read_text())["summary"]
    # published IDIM-LS: M = 95.11 kg, Fv = 203.50 N s/m, Fc = 20.39 N, OF = -3.16 N
    assert summary["m_q"] == pytest.approx(95.11, rel=0.03)
    assert summary["backbone"]["d_v"] == pytest.approx(203.5, rel=0.03)
    assert summary["backbone"]["F_c"] == pytest.approx(20.39, rel=0.05)
    assert summary["backbone"]["F_0"] == pytest.approx(-3.16, abs=0.3)
    table = pd.read_parquet(tmp_path / "validate/nrmse.parquet").set_index("dataset")
    assert table.loc["validation", "rms_unit"] == "mm"
    assert 0 < table.loc["validation", "rms_q"] < 50
    assert "Free-run validation" in out
