"""Signs physics implies (d >= 0, a DE gain of one sign): kept where a fit breaks them."""

import numpy as np

from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model


def _record(rec, anti_damping):
    """The bistable truth's exact record with ``anti_damping * q_dot`` added to q_ddot: the
    data of a mechanism whose damping is ``d(q) - anti_damping``, negative near the wells."""
    q_ddot = rec["q_ddot"] + anti_damping * rec["q_dot"]
    return Record("bistable", rec["q"], rec["q_dot"], q_ddot, rec["v"], rec["dt"])


CFG = {"M": 8, "T_z": 0.0, "input_map": "v2", "bootstrap": 0}


def test_negative_damping_from_least_squares_is_refitted_with_d_nonnegative(
    bistable_record, monkeypatch
):
    """True d = 3 + 200 q^2 [1/s] minus 6: about -3 1/s at q = 0. Least squares alone follows
    the data (negative d); the default imposes d >= 0 and says so."""
    import debist.identify.fit as fit

    rec = _record(bistable_record, 6.0)
    grid = np.linspace(rec.q.min(), rec.q.max(), 401)
    with monkeypatch.context() as patch:
        patch.setattr(fit, "physical_signs", lambda *a, **k: ((), ""))
        free, _ = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    assert free.curves(grid)["d"].min() < -1.0
    model, diag = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    d = model.curves(grid)["d"]
    assert d.min() >= -1e-9
    assert diag.dissipation.startswith("imposed d >= 0")
    assert "least-squares" in diag.dissipation and "d = -" in diag.dissipation


def test_a_dissipative_fit_is_left_as_least_squares_made_it(bistable_record):
    """With the truth's own positive damping nothing is imposed and the fit recovers d."""
    rec = _record(bistable_record, 0.0)
    model, diag = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    assert diag.dissipation == ""
    q = np.linspace(-0.008, 0.008, 9)
    np.testing.assert_allclose(model.curves(q)["d"], 3.0 + 200.0 * q**2, rtol=0.05)


def test_a_sign_the_workflow_states_for_d_is_its_own(bistable_record):
    """Stated in the workflow, the bound is the workflow's: d is not said to be imposed."""
    rec = _record(bistable_record, 6.0)
    cfg = IdentifyConfig.from_dict({**CFG, "constraints": ["d >= 0"]})
    model, diag = fit_rbf_model([rec], cfg)
    assert "d >= 0" not in diag.dissipation
    assert model.curves(np.linspace(rec.q.min(), rec.q.max(), 401))["d"].min() >= -1e-9


def test_a_gain_that_changes_sign_on_the_visited_range_keeps_the_data_s_sign(bistable_record):
    """Data of g1 = 2e-7 + 3e-5 q [m/s^2/V^2], zero at q = -6.7 mm inside the visited range:
    least squares follows it across zero; the default keeps g1 >= 0, the direction q moves
    when DE 1 is energised."""
    rec = _record(bistable_record, 0.0)
    extra = 2.4e-5 * rec.q * rec.v[:, 0] ** 2
    rec = Record("bistable", rec.q, rec.q_dot, rec.q_ddot + extra, rec.v, rec.dt)
    grid = np.linspace(rec.q.min(), rec.q.max(), 401)
    model, diag = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    assert diag.dissipation.startswith("imposed g1 >= 0")
    assert "least-squares" in diag.dissipation and "g1 = -" in diag.dissipation
    g1 = np.asarray(model.curves(grid)["g"]).reshape(grid.size, -1)[:, 0]
    assert g1.min() >= -1e-12 and g1.max() > 1e-7


def test_a_sign_broken_by_the_refit_under_another_is_imposed_too(bistable_record, monkeypatch):
    """The first check is made to see only the broken gain (as when least squares keeps d >= 0
    and the gain's refit moves d below zero): the refit under g1 >= 0 still has the data's
    d about -3 1/s, so a second round imposes d >= 0 and the result keeps both signs."""
    import debist.identify.fit as fit
    from debist.identify.signs import physical_signs

    rec = _record(bistable_record, 6.0)
    extra = 2.4e-5 * rec.q * rec.v[:, 0] ** 2
    rec = Record("bistable", rec.q, rec.q_dot, rec.q_ddot + extra, rec.v, rec.dt)
    calls = []

    def first_without_d(model, q, h, cfg, **kw):
        signs, reason = physical_signs(model, q, h, cfg, **kw)
        calls.append(signs)
        if len(calls) == 1:
            assert "d >= 0" in signs and "g1 >= 0" in signs
            kept = tuple(s for s in signs if s != "d >= 0")
            return kept, f"imposed {', '.join(kept)}: (the first check, d left out)"
        return signs, reason

    monkeypatch.setattr(fit, "physical_signs", first_without_d)
    model, diag = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    assert len(calls) == 3 and "d >= 0" in calls[1] and calls[2] == ()
    grid = np.linspace(rec.q.min(), rec.q.max(), 401)
    curves = model.curves(grid)
    assert curves["d"].min() >= -1e-9
    assert np.asarray(curves["g"]).reshape(grid.size, -1)[:, 0].min() >= -1e-12
    first, then = diag.dissipation.split("; then ")
    assert first.startswith("imposed g1 >= 0") and "d >= 0" not in first
    assert then.startswith("imposed d >= 0") and "had d = -" in then


def test_a_later_model_with_negative_damping_the_fit_did_not_have_is_named(bistable_record):
    """d lowered by twice its largest value: named with its lowest value and where; the fit
    itself, and a reference whose d was negative already, name nothing."""
    from dataclasses import replace

    from debist.identify.signs import lost_dissipation

    rec = _record(bistable_record, 0.0)
    model, _ = fit_rbf_model([rec], IdentifyConfig.from_dict(CFG))
    grid = np.linspace(rec.q.min(), rec.q.max(), 801)
    d = model.curves(grid)["d"]
    assert d.min() > 0 and lost_dissipation(model, model, rec.q) == ""
    worse = replace(model, theta_d=model.theta_d - 2.0 * d.max())
    low = worse.curves(grid)["d"]
    k = int(np.argmin(low))
    assert low[k] < 0
    assert lost_dissipation(model, worse, rec.q) == f"d = {low[k]:.4g} 1/s at q = {grid[k]:.4g}"
    assert lost_dissipation(worse, worse, rec.q) == ""
