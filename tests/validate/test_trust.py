"""Numbers the data do not support are not shown as numbers: unstable, diverged, baseline."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from debist.core.metrics import nrmse
from debist.report.tables import nrmse_table
from debist.stages.validate import run_validate
from debist.validate.freerun import default_q_limit
from tests.conftest import double_well, duffing_record, logged_tables


def test_a_model_with_negative_damping_at_its_wells_is_unstable_not_a_number():
    truth = double_well()
    tables, derivs = logged_tables(truth)
    bad = double_well(d_v=-0.2)
    res = run_validate(bad, tables, derivs, {"substeps": 1})
    rows = res.table[res.table.model == "rbf"]
    assert (rows.status == "unstable").all()
    assert rows.nrmse_q.isna().all() and rows.rms_q.isna().all()
    assert rows.reason.str.contains("negative damping d = -0.2").all()
    text = str(nrmse_table(res.table.to_dict(orient="records")).columns[-1]._cells)
    assert "unstable" in text
    good = run_validate(truth, tables, derivs, {"substeps": 1})
    ok = good.table[good.table.model == "rbf"]
    assert (ok.status == "ok").all() and (ok.nrmse_q < 1e-3).all()


def test_every_row_has_the_mean_as_baseline_and_a_warning_when_it_is_not_beaten():
    truth = double_well()
    tables, derivs = logged_tables(truth)
    res = run_validate(truth, tables, derivs, {"substeps": 1})
    q = tables["val"]["q"].to_numpy()
    row = res.table[(res.table.dataset == "val")].iloc[0]
    assert row.nrmse_q_baseline == pytest.approx(nrmse(q, np.full(q.size, q.mean())), rel=1e-12)
    assert row.nrmse_q_baseline > 0.2  # switching between the wells: the mean is a poor model
    rows = res.table.to_dict(orient="records")
    rows[0] = {**rows[0], "nrmse_q": rows[0]["nrmse_q_baseline"] * 1.01}
    notes = nrmse_table(rows).columns[-1]._cells
    assert "better" in notes[0] and "mean" in notes[0] and notes[1] == "ok"


def test_a_free_run_that_leaves_twice_the_estimation_range_is_diverged():
    assert default_q_limit((-0.012, 0.01)) == pytest.approx(0.024)
    truth = double_well()
    tables, derivs = logged_tables(truth)
    # a stable, damped well at q = 0 whose softening (k_3 < 0) lets the 3 kV pulses push the
    # beam over the barrier at +-10 mm (0.72 N against at most 0.154 N): it escapes to infinity
    escape = double_well(g=8e-8, k1=40.0)
    escape.backbone["k_3"] = -4e5
    res = run_validate(escape, tables, derivs, {"substeps": 1})
    rows = res.table[res.table.model == "rbf"]
    assert rows.diverged.all() and (rows.status == "diverged").all()
    assert rows.nrmse_q.isna().all()


def test_a_single_frequency_duffing_gets_the_excitation_warning_and_an_honest_row():
    """One sine cannot separate stiffness from damping: identify says so; the validation row
    is a number only if the identified damping at the well is positive, else 'unstable'."""

    from debist.stages.identify import run_identify

    rec = duffing_record(lambda t: 15.0 * np.cos(2 * np.pi * 0.8 * t), "sine", t_end=120.0)
    t = np.arange(rec.q.size) * rec.dt
    tables, derivs = {}, {}
    for name, role in (("est", "estimation"), ("val", "validation")):
        frame = pd.DataFrame({"t": t, "q": rec.q, "v1": rec.v[:, 0]})
        frame.attrs.update(role=role, units={"q": "m", "t": "s", "v1": "V"})
        tables[name] = frame
        derivs[name] = pd.DataFrame({"q_dot": rec.q_dot, "q_ddot": rec.q_ddot})
        derivs[name].attrs["dt"] = rec.dt
    section = {"M": 8, "T_z": 0.0, "input_map": "v", "rbf": ["c", "d"], "bootstrap": 20,
               "backbone": ["linear_spring", "cubic_spring", "viscous", "input_gain"]}  # fmt: skip
    res = run_identify(tables, derivs, section)
    exc = res.summary["excitation"]
    assert exc["single_frequency"]
    assert any("spectral" in w for w in exc["warnings"])
    val = run_validate(res.model, tables, derivs, {"substeps": 2})
    rows = val.table[val.table.model == "rbf"]
    d_at_rest = res.model.curves(np.array([0.0]))["d"][0]
    if d_at_rest < 0:
        assert (rows.status == "unstable").all() and rows.nrmse_q.isna().all()
    else:
        assert (rows.status == "ok").all() and (rows.nrmse_q < 0.05).all()


def test_a_replicate_is_the_model_with_its_parameters_moved():
    from debist.simulate.freerun import simulate
    from tests.conftest import DT_LOG, M_Q, G

    truth = double_well()
    tables, _ = logged_tables(truth)
    v = tables["val"][["v1", "v2"]].to_numpy()
    names = ["input_gain1", "input_gain2", "m_q", "d[3]"]  # d[3]: a term the model lacks
    dev = np.array([[0.0, 0.0, 0.0, 0.0], [0.1 * G, -0.1 * G, 0.0, 0.0], [0, 0, 0.1 * M_Q, 0]])
    reps = simulate(truth.replicate_table(names, dev), [v] * 3, DT_LOG, np.full(3, -0.01),
                    np.zeros(3))  # fmt: skip
    same = [double_well(), double_well(g=1.1 * G)]
    heavier = replace(double_well(), m_q=1.1 * M_Q)
    for rep, model in zip(reps, [*same, heavier], strict=True):
        ref = simulate(model, [v], DT_LOG, np.array([-0.01]), np.zeros(1))[0]
        np.testing.assert_allclose(rep.q, ref.q, rtol=0, atol=1e-15)
    with pytest.raises(ValueError) as err:
        truth.replicate_table(names, dev[:, :3])
    assert "3 columns" in str(err.value)
    assert "for 4" in str(err.value)


def test_replicates_that_lose_the_switch_make_a_low_nrmse_fragile():
    """Two replicates: the estimate itself, and one whose gains are 30 % lower, so that the
    3 kV pulses (0.18 N against the barrier's 0.154 N) no longer switch the beam."""
    from tests.conftest import G

    truth = double_well()
    tables, derivs = logged_tables(truth)
    dev = np.array([[0.0, 0.0], [-0.3 * G, 0.3 * G]])
    res = run_validate(
        truth, tables, derivs, {"substeps": 1}, replicates=(["input_gain1", "input_gain2"], dev)
    )
    weak = run_validate(double_well(g=0.7 * G), tables, derivs, {"substeps": 1}).table
    row = res.table[(res.table.dataset == "val") & (res.table.model == "rbf")].iloc[0]
    lost = weak[(weak.dataset == "val") & (weak.model == "rbf")].nrmse_q.iloc[0]
    assert lost > 0.5 * row.nrmse_q_baseline  # the weak replicate really loses the switch
    assert row.replicates == 2 and row.replicates_poor == 0.5
    assert row.nrmse_q_lo == pytest.approx(row.nrmse_q, abs=1e-9)
    assert row.nrmse_q_hi == pytest.approx(lost, rel=1e-9)
    sim = res.simulated["val"]
    assert (sim.q_sim_lo <= sim.q_sim_hi).all() and (sim.q_sim_hi - sim.q_sim_lo).max() > 0.01
    q = tables["val"]["q"].to_numpy()  # what the band held, counted independently
    held = np.mean((sim.q_sim_lo.to_numpy() <= q) & (q <= sim.q_sim_hi.to_numpy()))
    assert 0.0 < held < 1.0 and row.replicates_hold_q == pytest.approx(held, abs=1e-15)
    note = nrmse_table(res.table.to_dict(orient="records")).columns[-1]._cells[1]
    assert "fragile: 50 % of 2 bootstrap" in note and "(95 % of" in note
    none = run_validate(truth, tables, derivs, {"substeps": 1, "replicates": 0},
                        replicates=(["input_gain1", "input_gain2"], dev))  # fmt: skip
    assert "replicates_poor" not in none.table
