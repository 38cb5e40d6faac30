"""Thin data: a zoo member excited at one frequency gets a stable model and says what it lacks."""

import numpy as np
import pandas as pd
import pytest
import tomli_w

from debist import api
from debist.identify.spectrum import channel_lines, is_periodic, under_excitation
from debist.report.tables import verdict
from debist.rig.profiles import make_profile
from debist.rig.zoo import draw_member, sub_threshold

FS = 100.0  # [Hz]
T = np.arange(0.0, 20.0, 1.0 / FS)


def _spectrum(record, **channels):
    return pd.DataFrame(
        [
            {"record": record, "channel": k, **channel_lines(x, FS, None, 0.95, 6)}
            for k, x in channels.items()
        ]
    )


def test_a_tone_through_a_nonlinearity_is_periodic_and_noise_is_not():
    tone = 0.5 * (1.0 - np.cos(2.0 * np.pi * 0.5 * T))  # raised cosine, 0.5 Hz
    q = np.tanh(3.0 * np.sin(2.0 * np.pi * 0.5 * T))  # a saturating response: odd harmonics
    rows = _spectrum("a", q=q, h1=tone**2, h2=(1.0 - tone) ** 2)
    assert rows["harmonic"].all()
    assert np.allclose(rows["fundamental"], 0.5, atol=0.1)
    assert not rows.loc[rows.channel == "q", "single_line"].item()  # more than one line
    assert is_periodic(rows)
    noise = np.random.default_rng(3).normal(size=T.size)
    assert not is_periodic(_spectrum("b", q=q, h1=noise))  # a broad-band input
    other = 0.5 * (1.0 - np.cos(2.0 * np.pi * 1.3 * T))
    assert not is_periodic(_spectrum("c", q=q, h1=tone**2, h2=other**2))  # two fundamentals


def test_the_sine_profile_switches_twice_a_period_or_stays_below_v_sub():
    well = make_profile("sine", duration=10.0, v_sub=800.0, frequency=2.0)
    assert well.r1.max() == pytest.approx(800.0) and well.r2.max() == 0.0
    assert well.switch_times == ()
    switching = make_profile("sine", duration=10.0, switching=True)  # 0.5 Hz by default
    assert switching.r1.max() == pytest.approx(3000.0, rel=1e-6)
    assert np.allclose(switching.r1 + switching.r2, 3000.0 * (switching.t >= 0.5))
    assert switching.switch_sides[:3] == (1, 2, 1)
    assert np.diff(switching.switch_times) == pytest.approx(1.0)  # half a period apart
    with pytest.raises(ValueError) as err:
        make_profile("sine", duration=10.0, frequency=200.0)  # above a tenth of 1 / hold
    assert "frequency" in str(err.value)


def test_an_under_excited_row_says_so_before_anything_else():
    thin = under_excitation(
        {"single_frequency": [], "periodic": ["est"],
         "spectra": [{"record": "est", "channel": "q", "f_peak": 0.5, "fundamental": 0.5}]}
    )  # fmt: skip
    assert thin.startswith("one period (2 s)") and thin.endswith("'est'")
    rows = [
        {"dataset": "u", "model": "rbf", "nrmse_q": 0.006, "nrmse_q_baseline": 0.3},
        {"dataset": "u", "model": "narx", "nrmse_q": 0.001, "nrmse_q_baseline": 0.3},
    ]
    rows = [{**r, "under_excited": thin} for r in rows]
    assert verdict(rows[0], rows).startswith(f"under-excited: {thin}; ")
    assert verdict(rows[0], rows).endswith("narx (0.10 %)")
    assert verdict(rows[1], rows) == f"under-excited: {thin}"  # replaces "ok"
    assert verdict({**rows[1], "under_excited": ""}, rows) == "ok"


def _sine_member(tmp_path, switching: bool):
    """Zoo member m000 of seed 1 (full plant, two Maxwell-slip elements, 5-sample block
    average), estimation and unseen records of one tone each, minimal workflow."""
    member = draw_member(1, 0)
    v_sub = float(np.round(sub_threshold(member.rig_params()), 1))
    tone = {"profile": "sine", "switching": switching, "frequency": 0.5 if switching else 2.0,
            "duration": 20.0, "v_sub": v_sub, "format": "5"}  # fmt: skip
    rig = {**member.rig, "experiments": {"estimation": {**tone, "seed": 1},
                                         "unseen": {**tone, "seed": 2}}}  # fmt: skip
    wf = {
        "workflow": {"name": "tone", "output_dir": "run"},
        "rig": rig,
        "ingest": {
            "q": {"regex": "Laser/q$", "unit": "mm"},
            "v1": {"regex": "DE1/v_mon$", "unit": "kV"},
            "v2": {"regex": "DE2/v_mon$", "unit": "kV"},
        },
        "identify": {"input_map": "v2"},
        "datasets": {
            "estimation": {"rig": "estimation", "role": "estimation"},
            "unseen": {"rig": "unseen", "role": "validation"},
        },
    }
    path = tmp_path / "tone.toml"
    path.write_text(tomli_w.dumps(wf), encoding="utf-8")
    return api.run(path)


@pytest.mark.slow
@pytest.mark.parametrize("switching", [False, True], ids=["inside-one-well", "switching"])
def test_a_single_frequency_member_gets_a_stable_passive_model_or_says_why_not(tmp_path, switching):
    result = _sine_member(tmp_path, switching)
    ident = result.summary("identify")
    assert ident["design"]["verdict"] == "stable"
    lo, hi = ident["q_data_range"]  # [m]
    curves = result.curves
    visited = curves[(curves.q >= lo) & (curves.q <= hi)]
    assert len(visited) > 10 and (visited.d >= 0.0).all()  # passive on the visited range
    rows = result.nrmse_raw
    rbf = rows[rows["model"] == "rbf"]
    narx = rows[rows["model"] == "narx"].set_index("dataset")["nrmse_q"]
    assert (rbf["status"] == "ok").all()  # a free run, not "unstable"
    for row in rbf.itertuples():
        flagged = row.verdict.startswith("under-excited: ")
        assert flagged or row.nrmse_q <= narx[row.dataset]
    assert (rows["under_excited"] != "").all()  # every model row, in the Parquet table
    # friction and the block average put harmonics on q: one period, not one line
    kind = "one period (2 s)" if switching else "one period (0.5 s)"
    assert kind in rows["under_excited"].iloc[0]
    assert ident["auto"]["chosen"]["M"] < 10  # fewer centres, chosen on held-out data
