"""The excitation check before identification (debist.identify.excitation)."""

import json

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from debist.core.errors import WorkflowError
from debist.identify.excitation import check_excitation
from debist.identify.fit import Record
from debist.model.basis import RBFBasis
from tests.conftest import DUFFING_DT as DT
from tests.conftest import DUFFING_T_END, duffing_record

# --- (a) Duffing oscillator q'' + 2 zeta w q' + w^2 q + k3 q^3 = u(t) -------------------------

T_END = DUFFING_T_END


def _check(rec, **kw):
    basis = RBFBasis.equidistant(rec.q.min(), rec.q.max(), M=8, sigma_n=0.5)
    return check_excitation([rec], basis, "v", **kw)


@pytest.fixture(scope="module")
def sine_record():
    return duffing_record(lambda t: 15.0 * np.cos(2 * np.pi * 0.8 * t), "sine")


def _line_warnings(rep):
    return [w for w in rep.warnings if "spectral line" in w]


def test_single_sine_drive_is_flagged(sine_record):
    rep = _check(sine_record)
    q_row = rep.spectra.set_index("channel").loc["q"]
    assert rep.single_frequency == ["sine"]
    assert q_row["n_lines"] == 1 and bool(q_row["single_line"])
    assert abs(q_row["f_peak"] - 0.8) <= q_row["df"]
    assert q_row["bandwidth"] <= 6 * q_row["df"]
    (msg,) = _line_warnings(rep)
    assert "record 'sine'" in msg and "0.8" in msg and "inputs" in msg
    # a sinusoidal orbit has no transit: its speed never exceeds 3 robust SDs
    assert rep.transient_intervals == []


def test_multisine_drive_is_not_flagged():
    rng = np.random.default_rng(11)
    freqs = np.array([0.3, 0.55, 0.8, 1.3, 1.9])  # [Hz]
    phases = rng.uniform(0, 2 * np.pi, freqs.size)
    rec = duffing_record(
        lambda t: 8.0 * np.sum(np.cos(2 * np.pi * freqs * t + phases)), "multisine"
    )
    rep = _check(rec)
    spec = rep.spectra.set_index("channel")
    assert rep.single_frequency == [] and _line_warnings(rep) == []
    assert spec.loc["h1", "n_lines"] == 5
    assert spec.loc["q", "n_lines"] >= 3


def test_noise_drive_is_not_flagged():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 180.0 + DT, DT)
    sos = butter(4, 3.0, fs=1 / DT, output="sos")
    force = sosfiltfilt(sos, rng.standard_normal(t.size))
    force *= 10.0 / force.std()
    spline = CubicSpline(t, force)  # smooth interpolant: no kinks for the stepper
    rec = duffing_record(lambda tt: float(spline(tt)), "noise", t_end=180.0)
    rep = _check(rec)
    q_row = rep.spectra.set_index("channel").loc["q"]
    assert rep.single_frequency == [] and _line_warnings(rep) == []
    assert not q_row["single_line"]
    assert q_row["bandwidth"] > 10 * q_row["df"]
    assert rep.transient_intervals == []


# --- (b) bistable record: left well with input 1, right well with input 2, fast switches ---

MM = 1e-3
WELL, ORBIT = 10 * MM, 2 * MM  # wells at -+10 mm, in-well orbit +-2 mm [m]
DT_B = 1e-3  # [s]


def _bistable():
    """Dwell 2 s per well (1.5 Hz orbit, one input active), ballistic 0.1 s switches."""
    dwell = np.arange(0, 2.0, DT_B)
    ramp = np.arange(0, 0.1, DT_B) / 0.1
    q_parts, v_parts = [], []
    side = -1
    for _ in range(6):
        q_parts.append(side * WELL + ORBIT * np.sin(2 * np.pi * 1.5 * dwell))
        v_on = 1500.0 + 300.0 * np.sin(2 * np.pi * 0.7 * dwell)
        v = np.zeros((dwell.size, 2))
        v[:, 0 if side < 0 else 1] = v_on
        v[:, 1 if side < 0 else 0] = 20.0  # leakage voltage, inactive
        v_parts.append(v)
        # switch to the other well with both inputs off (the pulse has ended)
        q_parts.append(side * WELL - side * 2 * WELL * (1 - np.cos(np.pi * ramp)) / 2)
        v_parts.append(np.zeros((ramp.size, 2)))
        side = -side
    q = np.concatenate(q_parts)
    qd = np.gradient(q, DT_B)
    return Record("bistable", q, qd, np.gradient(qd, DT_B), np.vstack(v_parts), DT_B)


@pytest.fixture(scope="module")
def bistable_report():
    basis = RBFBasis.equidistant(-12 * MM, 12 * MM, M=13, sigma_n=0.5)  # sigma = 1 mm
    return check_excitation([_bistable()], basis, "v2", unit_scale=1e3, unit_name="mm"), basis


def test_bistable_coverage_per_input(bistable_report):
    rep, basis = bistable_report
    sigma = basis.sigma
    tab = rep.table
    left = tab["centre"] <= -(WELL - ORBIT) + 1e-12
    right = tab["centre"] >= WELL - ORBIT - 1e-12
    assert tab.loc[left, "supported_g1"].all() and not tab.loc[~left, "supported_g1"].any()
    assert tab.loc[right, "supported_g2"].all() and not tab.loc[~right, "supported_g2"].any()
    assert tab["supported_c"].all()  # transits cross every centre often enough
    # constructed: input 1 is off for q > -8 mm, input 2 for q < +8 mm
    ((a1, b1),) = rep.unsupported["g1"]
    ((a2, b2),) = rep.unsupported["g2"]
    assert abs(a1 - (-(WELL - ORBIT))) <= sigma and b1 >= WELL + ORBIT
    assert abs(b2 - (WELL - ORBIT)) <= sigma and a2 <= -(WELL + ORBIT)
    g1 = [w for w in rep.warnings if w.startswith("g1:")]
    assert len(g1) == 1 and "input 1" in g1[0] and "never" in g1[0]
    assert f"[{a1 * 1e3:.1f}, {b1 * 1e3:.1f}] mm" in g1[0]
    assert not any(w.startswith("no data") for w in rep.warnings)


def test_bistable_transit_region_is_transient_only(bistable_report):
    rep, basis = bistable_report
    ((a, b),) = rep.transient_intervals
    assert abs(a - (-(WELL - ORBIT))) <= basis.sigma
    assert abs(b - (WELL - ORBIT)) <= basis.sigma
    (msg,) = [w for w in rep.warnings if w.startswith("transient only")]
    assert f"[{a * 1e3:.1f}, {b * 1e3:.1f}] mm" in msg
    # the quasi-static count is zero at the barrier and large in the wells
    mid = rep.table.set_index("centre")["n_quasi_static"]
    assert mid.iloc[6] == 0 and mid.iloc[1] > 1000 and mid.iloc[11] > 1000


def test_summary_is_json(bistable_report):
    rep, _ = bistable_report
    summary = json.loads(json.dumps(rep.to_summary()))
    assert summary["unit"] == "mm" and summary["sigma"] == pytest.approx(1.0)
    assert summary["centres"][0]["centre"] == pytest.approx(-12.0)
    assert summary["unsupported"]["g1"][0][0] == pytest.approx(rep.unsupported["g1"][0][0] * 1e3)
    assert summary["warnings"] == rep.warnings
    assert {r["channel"] for r in summary["spectra"]} == {"q", "h1", "h2"}


# --- (c) counts against an independent count ---------------------------------------------


def test_counts_match_independent_count():
    rng = np.random.default_rng(2024)
    recs = []
    for k, n in enumerate((37, 53)):
        q = rng.uniform(-1.2, 1.2, n)
        qd = rng.normal(0, 1.0, n)
        v = rng.uniform(-100, 100, (n, 2)) * (rng.random((n, 2)) < 0.4)
        recs.append(Record(f"r{k}", q, qd, np.zeros(n), v, 0.01))
    basis = RBFBasis.equidistant(-1.0, 1.0, M=5, sigma_n=0.6)
    rep = check_excitation(recs, basis, "v", min_samples=8, off_fraction=0.3, moving_fraction=0.5)
    q = np.concatenate([r.q for r in recs])
    qd = np.concatenate([r.q_dot for r in recs])
    h = np.vstack([r.v for r in recs])  # h(v) = v
    rms = np.sqrt(np.mean(qd**2))
    for k, xi in enumerate(basis.xi):
        row = rep.table.iloc[k]
        n_tot = n_mov = n_idle = 0
        n_act = [0, 0]
        neff = 0.0
        for qi, qdi, hi in zip(q, qd, h, strict=True):
            if abs(qi - xi) <= basis.sigma:
                n_tot += 1
                n_mov += abs(qdi) > 0.5 * rms
                on = [abs(hi[j]) > 0.3 * np.abs(h[:, j]).max() for j in range(2)]
                n_act[0] += on[0]
                n_act[1] += on[1]
                n_idle += not any(on)
            neff += np.exp(-((qi - xi) ** 2) / (2 * basis.sigma**2))
        assert row["centre"] == xi
        assert row["n_total"] == n_tot and row["n_moving"] == n_mov
        assert row["n_input1_active"] == n_act[0] and row["n_input2_active"] == n_act[1]
        assert row["n_inactive"] == n_idle
        assert row["neff_total"] == pytest.approx(neff)
        assert bool(row["supported_c"]) == (n_tot >= 8)
        assert bool(row["supported_g2"]) == (n_act[1] >= 8)
    assert np.array_equal(rep.table["n_total"], basis.support(q))


def test_merged_intervals_and_zero_input():
    # samples only near the outer centres; input 2 never switched on
    q = np.concatenate([np.full(20, -1.0), np.full(20, 1.0)])
    rec = Record("gap", q, np.ones(40), np.zeros(40), np.column_stack([np.ones(40), 0 * q]), 0.1)
    basis = RBFBasis.equidistant(-1.0, 1.0, M=5, sigma_n=0.5)  # xi = -1, -.5, 0, .5, 1
    rep = check_excitation([rec], basis, "v2", min_samples=5)
    assert rep.unsupported["c"] == [(-0.5 - 0.25, 0.5 + 0.25)]
    assert rep.unsupported["g2"] == [(-1.25, 1.25)]
    assert rep.warnings[0].startswith("no data") and "[-0.75, 0.75] m" in rep.warnings[0]
    assert any(w.startswith("g2: input 2 is zero in every estimation record") for w in rep.warnings)
    assert rep.transient_intervals == []  # constant speed is not a transit


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"off_fraction": 1.5}, "off_fraction"),
        ({"noise_factor": 0.0}, "noise_factor"),
        ({"power_fraction": 1.0}, "power_fraction"),
        ({"min_samples": 0}, "min_samples"),
        ({"bin_width": -1.0}, "bin_width"),
    ],
)
def test_bad_settings_raise(kw, match):
    rec = Record("r", np.zeros(4), np.zeros(4), np.zeros(4), np.zeros((4, 1)), 0.1)
    basis = RBFBasis.equidistant(-1.0, 1.0, M=3, sigma_n=0.5)
    with pytest.raises(WorkflowError, match=match):
        check_excitation([rec], basis, **kw)


def test_records_must_agree_in_inputs():
    basis = RBFBasis.equidistant(-1.0, 1.0, M=3, sigma_n=0.5)
    z = np.zeros(4)
    recs = [
        Record("a", z, z, z, np.zeros((4, 1)), 0.1),
        Record("b", z, z, z, np.zeros((4, 2)), 0.1),
    ]
    with pytest.raises(WorkflowError) as err:
        check_excitation(recs, basis)
    assert "number" in str(err.value) and "inputs" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        check_excitation([], basis)
    assert "estimation" in str(err.value) and "records" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        check_excitation(recs[:1], basis, "v3")
    assert "input_map" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        check_excitation([Record("c", z, z, z, np.zeros((4, 1)), 0.0)], basis)
    assert "'c'" in str(err.value)
