"""The lagged damping's apparent mass and the rescale that makes m_q physical (identify/mass.py).

On the backbone-only double well of conftest (c = k1 + k3 q^2, constant d_v on the lagged
friction state z, T_z = 0.01 s) the ratio has a closed form at its two wells: with
k* = -2 k1 and omega_n^2 = k*/m_q, lambda = 1 - d_v T_z / ((1 + (omega_n T_z)^2) m_q).
"""

import numpy as np
import pandas as pd
import pytest

from debist.core.errors import WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import FitDiagnostics
from debist.identify.mass import effective_mass, effective_mass_ratio
from debist.simulate.freerun import simulate
from debist.stages.identify import run_identify
from tests.conftest import K1, M_Q, D, bistable_truth, double_well


def _diagnostics(p: int) -> FitDiagnostics:
    rng = np.random.default_rng(0)
    return FitDiagnostics(
        n_samples=100, columns=[f"c[{i}]" for i in range(p)], rank=p, condition=10.0,
        singular_values=np.ones(p), residual_rms=0.5, fit_r2=0.9, support=np.ones(p, int),
        T_z_trace=np.empty((0, 2)), theta=rng.normal(size=p), column_norms=np.ones(p),
        y_norm=3.0, theta_boot=rng.normal(size=(5, p)),
    )  # fmt: skip


def test_the_ratio_has_the_closed_form_of_a_lagged_damping():
    model = double_well(d_v=0.3)
    omega = np.sqrt(-2 * K1 / M_Q)
    expected = 1 - 0.3 * model.T_z / ((1 + (omega * model.T_z) ** 2) * M_Q)
    ratio, wells, ratios = effective_mass_ratio(model)
    assert len(wells) == 2 and wells[0] < 0 < wells[1]
    assert ratios == pytest.approx([expected, expected], rel=1e-6)
    assert ratio == pytest.approx(expected, rel=1e-6) and 0 < ratio < 1


def test_without_a_lag_the_ratio_is_one():
    from dataclasses import replace

    model = replace(double_well(), T_z=0.0)
    assert effective_mass_ratio(model) == (1.0, (), ())
    out, _, info = effective_mass(model, _diagnostics(3))
    assert out is model and not info.applied and "T_z = 0" in info.reason


def test_the_rescale_leaves_the_free_run_and_scales_every_curve():
    model = double_well(d_v=0.3)
    scaled, diag, info = effective_mass(model, _diagnostics(3))
    s = 1.0 / info.ratio
    assert info.applied and s > 1.02
    assert scaled.m_q == pytest.approx(M_Q * s, rel=1e-15)
    q = np.linspace(-0.012, 0.012, 7)
    for key, value in model.curves(q).items():
        assert scaled.curves(q)[key] == pytest.approx(value * s, rel=1e-12), key
    # the ratio is invariant under the rescale: applying it twice changes nothing more
    assert effective_mass_ratio(scaled)[0] == pytest.approx(info.ratio, rel=1e-9)
    rng = np.random.default_rng(1)
    v = np.repeat(rng.uniform(0, 2500, (12, 2)), 50, axis=0)
    runs = [
        simulate(m, [v], 2e-3, np.array([-0.01]), np.array([0.0]), engine="numpy")[0]
        for m in (model, scaled)
    ]
    assert np.ptp(runs[0].q) > 5e-3  # it moves (and switches)
    assert np.max(np.abs(runs[1].q - runs[0].q)) < 1e-12
    base = _diagnostics(3)
    assert diag.theta == pytest.approx(base.theta * s, rel=1e-15)
    assert diag.theta_boot == pytest.approx(base.theta_boot * s, rel=1e-15)
    assert (diag.residual_rms, diag.y_norm) == pytest.approx((0.5 * s, 3.0 * s), rel=1e-15)


def test_a_lag_heavier_than_the_mass_is_not_applied():
    model = double_well(d_v=50 * D)  # d T_z far above m_q: lambda < 0
    out, _, info = effective_mass(model, _diagnostics(3))
    assert out is model and not info.applied and info.ratio < 0 and "(0, 1]" in info.reason


def test_the_scale_is_the_default_unless_the_mass_is_identified():
    assert IdentifyConfig.from_dict({}).effective_mass is True
    assert IdentifyConfig.from_dict({"effective_mass": False}).effective_mass is False
    identified = {"m_q": "identify", "input_gain": [1.0], "rbf": ["c", "d"]}
    assert IdentifyConfig.from_dict(identified).effective_mass is False


def test_by_default_the_stage_gives_the_curves_of_the_physical_mass(bistable_record):
    """A lag the plant lacks (T_z = 0.02 s on data with z = q_dot, m_q = 1) lowers the fitted
    curves by lambda: with the default scale they are per the configured m_q (the summary's
    ``m_q_curves``, still per unit mass) and nearer the truth than as fitted."""
    r = bistable_record
    frame = pd.DataFrame({"t": r["t"], "q": r["q"], "v1": r["v"][:, 0], "v2": r["v"][:, 1]})
    frame.attrs.update(role="estimation", units={"q": "m", "t": "s", "v1": "V", "v2": "V"})
    deriv = pd.DataFrame({"q_dot": r["q_dot"], "q_ddot": r["q_ddot"]})
    deriv.attrs["dt"] = r["dt"]
    section = {"M": 6, "T_z": 0.02, "slip": False, "bootstrap": 0, "max_condition": 1e10}
    scaled = run_identify({"sim": frame}, {"sim": deriv}, section)
    plain = run_identify({"sim": frame}, {"sim": deriv}, {**section, "effective_mass": False})
    info = scaled.summary["effective_mass"]
    assert info["applied"] and 0.9 < info["ratio"] < 0.97
    assert scaled.summary["m_q_curves"] == 1.0 and plain.summary["m_q_curves"] == 1.0
    assert scaled.summary["m_q"] == pytest.approx(1.0 / info["ratio"], rel=1e-12)
    assert scaled.summary["units"]["per_unit_mass"] and "effective_mass" not in plain.summary
    q = scaled.curves.q.to_numpy()
    truth = bistable_truth(q)
    for name, true in (("restoring", truth["c"] * q), ("g2", truth["g2"])):
        np.testing.assert_allclose(
            scaled.curves[name], plain.curves[name] / info["ratio"], rtol=1e-9, atol=0
        )
        error = [
            np.max(np.abs(c[name] - true)) / np.ptp(true) for c in (scaled.curves, plain.curves)
        ]
        assert error[0] < 0.7 * error[1], (name, error)
    restoring = [np.max(np.abs(c.restoring - truth["c"] * q)) / np.ptp(truth["c"] * q)
                 for c in (scaled.curves, plain.curves)]  # fmt: skip
    assert restoring[0] < 0.02 < 0.03 < restoring[1]


def test_an_identified_mass_is_refused():
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict(
            {"m_q": "identify", "input_gain": [1.0], "rbf": ["c", "d"], "effective_mass": True}
        )
    assert "effective_mass" in str(err.value)


def test_the_tables_say_the_mass_is_rigid_and_give_lambda():
    from debist.report.tables import mass_rows

    plain = mass_rows({"m_q": 0.0402}, "kg")
    assert plain == [("mass m_q", "kg", 0.0402, "m_q")]
    info = {"ratio": 0.8, "applied": True, "reason": ""}
    rows = mass_rows({"m_q": 0.05025, "effective_mass": info}, "kg")
    assert rows[0][0].startswith("rigid mass m_q") and rows[0][2] == 0.05025
    assert rows[1][1:3] == ("-", 0.8) and "lambda" in rows[1][0]
    skipped = {"ratio": 1.0, "applied": False, "reason": "no well at rest"}
    rows = mass_rows({"m_q": 0.0402, "effective_mass": skipped}, "kg")
    assert rows[0][0] == "mass m_q" and rows[1][0].endswith(": no well at rest)")


def test_a_per_unit_mass_model_says_what_its_mass_number_is():
    from debist.report.tables import mass_rows

    info = {"ratio": 0.8, "applied": True, "reason": ""}
    (rigid, ratio) = mass_rows({"m_q": 1.25, "effective_mass": info}, "1")
    # 1 / lambda effective masses: a ratio, worded, not a mass in an unnamed unit "1"
    assert rigid[1:3] == ("-", 1.25) and rigid[2] * ratio[2] == pytest.approx(1.0)
    assert "multiples of the effective mass" in rigid[0] and "physical one is unknown" in rigid[0]
    (plain,) = mass_rows({"m_q": 1.0}, "1")
    assert plain[1:3] == ("-", 1.0) and "unit mass" in plain[0] and "accelerations" in plain[0]
    skipped = {"ratio": 1.0, "applied": False, "reason": "T_z = 0: no lag"}
    rows = mass_rows({"m_q": 1.0, "effective_mass": skipped}, "1")
    assert "unit mass" in rows[0][0] and rows[1][0].endswith(": T_z = 0: no lag)")
