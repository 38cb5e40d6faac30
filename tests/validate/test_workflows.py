"""The shipped workflows on the shipped real data: the acceptance numbers of docs/results/."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from debist.cli import app

ROOT = Path(__file__).resolve().parents[2]


def run(workflow, out):
    result = CliRunner().invoke(app, ["run", str(ROOT / "workflows" / workflow), "--out", str(out)])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.slow
def test_silverbox_protocol_rms_and_cached_rerun(tmp_path):
    out = run("silverbox.toml", tmp_path)
    table = pd.read_parquet(tmp_path / "validate/nrmse.parquet")
    assert (table.rms_unit == "mV").all()
    rms = table.pivot(index="model", columns="dataset", values="rms_q")
    # issue 2: the equation-error (least-squares) RBF model
    assert rms.loc["rbf-ls", "test_multisine"] <= 2.5
    assert rms.loc["rbf-ls", "test_arrow_no_extrapolation"] <= 2.5
    assert np.isfinite(rms.loc["rbf-ls", "test_arrow_full"])
    # issue 3: refined by simulation error, at or below SUBNET (L4DC 2021): 0.36, 1.4, 0.32 mV
    assert rms.loc["rbf", "test_multisine"] <= 0.36
    assert rms.loc["rbf", "test_arrow_full"] <= 1.4
    assert rms.loc["rbf", "test_arrow_no_extrapolation"] <= 0.32
    assert not table.diverged.any()
    assert (table[table.dataset == "test_multisine"].n_samples == 127400 - 105712 - 50).all()
    identify = json.loads((tmp_path / "identify/summary.json").read_text())
    assert identify["refine"]["accepted"]
    refine = identify["refine"]
    assert refine["full_rms_simulation_error"] <= refine["full_rms_equation_error"]
    assert "SUBNET" in out  # published rows printed beside ours
    again = run("silverbox.toml", tmp_path)  # its time: benchmarks, not a test
    assert again.count("up to date, skipping") == out.count("done") == 7  # report included
    both = pd.read_parquet(tmp_path / "compare/nrmse.parquet")
    assert set(both.model) == {"narx", "rbf", "rbf-ls", "sindy"}
    # the protocol's own split: the arrow's full record leaves the amplitude range of the
    # estimation input (its first 32000 samples do not): said on every model's row
    beyond = both.groupby("dataset").extrapolated.agg(lambda x: set(x))
    assert beyond["test_arrow_no_extrapolation"] == beyond["test_multisine"] == {""}
    (words,) = beyond["test_arrow_full"]
    # in the report unit, mV, as the RMS column
    assert words.startswith("v1 applied at q = -300 to -250 mV (7 samples) and 250 to 280 mV")
    assert words.endswith("where the estimation applied it only at -210 to 220 mV")
    assert (both[both.dataset == "test_arrow_full"].verdict.str.startswith("extrapolated:")).all()


@pytest.mark.slow
def test_emps_identifies_mass_and_friction_near_idim(tmp_path):
    out = run("emps.toml", tmp_path)
    summary = json.loads((tmp_path / "identify/summary.json").read_text())
    # published IDIM-LS: M = 95.11 kg, Fv = 203.50 N s/m, Fc = 20.39 N, OF = -3.16 N
    assert summary["m_q"] == pytest.approx(95.11, rel=0.03)
    assert summary["backbone"]["d_v"] == pytest.approx(203.5, rel=0.03)
    assert summary["backbone"]["F_c"] == pytest.approx(20.39, rel=0.05)
    assert summary["backbone"]["F_0"] == pytest.approx(-3.16, abs=0.3)
    table = pd.read_parquet(tmp_path / "validate/nrmse.parquet").set_index("dataset")
    assert table.loc["validation", "rms_unit"] == "mm"
    assert 0 < table.loc["validation", "rms_q"] < 50
    assert "Free-run" in out and "validation" in out
    both = pd.read_parquet(tmp_path / "compare/nrmse.parquet").set_index(["model", "dataset"])
    # the black-box peer: on EMPS's unseen record the polynomial NARX (2.3 %) beats the
    # four-parameter IDIM structure (3.3 %), and the verdict column says so
    rbf, narx = both.loc[("rbf", "validation")], both.loc[("narx", "validation")]
    assert narx.nrmse_q < rbf.nrmse_q < 1.5 * narx.nrmse_q
    assert rbf.verdict.startswith("worse") and rbf.verdict.endswith(
        f"narx ({100 * narx.nrmse_q:.2f} %)"
    )


# Table 2 of Masoud & Maas 2025, the RBF model on its identification data (NRMSE, Eq. 41)
PAPER_TABLE2_RBF = {
    "nrmse_q": 0.021,
    "nrmse_phi": 0.020,
    "nrmse_q_dot": 0.041,
    "nrmse_q_ddot": 0.050,
}


@pytest.fixture(scope="module")
def paper_experiment(paper_experiment_run):
    """The session's run of workflows/paper-experiment.toml: output, folder and the curves vs
    truth (read only)."""
    from debist.core import artifacts
    from debist.model.rbf import RBFModel

    out_dir, out = paper_experiment_run
    model = RBFModel.from_tree(artifacts.read_h5(out_dir / "identify/model.h5"))
    truth = artifacts.read_h5(out_dir / "rig/identification_truth.h5")["curves"]
    # the q bins (2 mm) the identification data visit (>= 20 samples)
    q = pd.read_parquet(out_dir / "ingest/identification.parquet").q.to_numpy()
    edges = np.arange(-0.02, 0.0201, 0.002)
    counts, _ = np.histogram(q, edges)
    bins = np.digitize(truth["q"], edges) - 1
    sel = (bins >= 0) & (bins < counts.size)
    sel[sel] &= counts[bins[sel]] >= 20
    identified = model.curves(truth["q"][sel])
    return out, out_dir, identified, model, {k: v[sel] for k, v in truth.items() if k != "attrs"}


@pytest.mark.slow
def test_paper_experiment_on_the_virtual_rig_meets_table_2(paper_experiment):
    out, tmp_path, identified, model, truth = paper_experiment
    assert "Free-run" in out and "validation" in out and "analytical" in out
    table = pd.read_parquet(tmp_path / "compare/nrmse.parquet").set_index(["model", "dataset"])
    rbf_id, rbf_val = table.loc[("rbf", "identification")], table.loc[("rbf", "validation")]
    for key, bound in PAPER_TABLE2_RBF.items():
        assert rbf_id[key] <= bound, key
    assert rbf_val.nrmse_q <= 0.01  # unseen validation with the shipped settings
    for ds in ("identification", "validation"):
        assert table.loc[("rbf", ds)].nrmse_q < table.loc[("analytical", ds)].nrmse_q
    # the NARX peer: within 0.1 points of the RBF model on its estimation record, beaten on
    # the unseen one, where it keeps the switches (<= 2 %)
    assert table.loc[("narx", "identification")].nrmse_q < rbf_id.nrmse_q + 0.001
    assert rbf_val.nrmse_q < table.loc[("narx", "validation")].nrmse_q <= 0.02
    # the identified restoring force c(q) q + F_0 against the truth over the visited bins
    f_id = identified["cq"] + model.backbone["F_0"]
    f_true = truth["f"]
    assert np.max(np.abs(f_id - f_true)) <= 0.10 * np.ptp(f_true)


@pytest.mark.slow  # the paper experiment end to end, shared with the Table 2 test
@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="open in issue 5 (blocked): Eq. 37's g_i(q) v_i^2 is not separable from c(q) q "
    "where the profile only ever applies v_i = 3 kV (transit, beam pushed past the well), and "
    "the full model's force is not linear in v_i^2; see docs/results/paper-experiment.md, "
    "'What the identified g_i are'",
)
def test_paper_experiment_input_gains_match_the_truth(paper_experiment):
    """g_i against the 3 kV secant of Fig. 4 (what the switching pulses see) over the bins
    where v_i is applied (above 10 % of its peak, >= 20 samples)."""
    _, out_dir, _, model, _ = paper_experiment
    from debist.core import artifacts

    truth = artifacts.read_h5(out_dir / "rig/identification_truth.h5")["curves"]
    data = pd.read_parquet(out_dir / "ingest/identification.parquet")
    edges = np.arange(-0.02, 0.0201, 0.002)
    bins = np.digitize(truth["q"], edges) - 1
    inside = (bins >= 0) & (bins < edges.size - 1)
    identified = model.curves(truth["q"])["g"]
    for i in (1, 2):
        v = data[f"v{i}"].to_numpy()
        counts, _ = np.histogram(data.q.to_numpy()[v > 0.1 * v.max()], edges)
        sel = inside.copy()
        sel[inside] = counts[bins[inside]] >= 20
        g_true = truth[f"g{i}_vmax"][sel]
        error = np.max(np.abs(identified[sel, i - 1] - g_true))
        assert error <= 0.10 * np.ptp(g_true), f"g{i}: {error / np.ptp(g_true):.2f} of range"
