"""Bands of the identified curves: curve maps, bands from the replicates, identified masks."""

import numpy as np

from debist.identify.bands import (
    curve_bands,
    curve_maps,
    curves_frame,
    identified_intervals,
    support_weights,
)
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from tests.conftest import bistable_truth


def _records(rec, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    q_ddot = rec["q_ddot"] + noise * rng.standard_normal(rec["q"].size)
    return [Record("sim", rec["q"], rec["q_dot"], q_ddot, rec["v"], rec["dt"])]


def _cfg(**kw):
    base = {"M": 10, "sigma_n": 0.5, "T_z": 0.0, "max_condition": 1e10}
    base.update(kw)
    return IdentifyConfig.from_dict(base)


def test_curve_maps_give_the_models_curves(bistable_record):
    """restoring = c(q) q + F_0, d and g_i of RBFModel.curves, from the term library."""
    backbone = ["linear_spring", "cubic_spring", "viscous", "offset", "input_gain"]
    model, diag = fit_rbf_model(_records(bistable_record), _cfg(backbone=backbone, bootstrap=0))
    q = np.linspace(*model.q_range, 57)
    maps = curve_maps(diag.columns, q, model.basis, 2, "v2", model.coulomb_velocity, model.prior)
    cur = model.curves(q)
    scale = lambda x: np.max(np.abs(x))  # noqa: E731
    restoring = cur["cq"] + model.backbone["F_0"]
    assert np.max(np.abs(maps["restoring"] @ diag.theta - restoring)) <= 1e-12 * scale(restoring)
    assert np.max(np.abs(maps["d"] @ diag.theta - cur["d"])) <= 1e-12 * scale(cur["d"])
    for j in range(2):
        g = cur["g"][:, j]
        assert np.max(np.abs(maps[f"g{j + 1}"] @ diag.theta - g)) <= 1e-12 * scale(g)


def test_support_weights_are_the_gaussian_sample_count():
    rng = np.random.default_rng(2)
    q = rng.uniform(-1.0, 1.0, 5000)
    grid = np.linspace(-1.0, 1.0, 11)
    exact = np.exp(-((grid[:, None] - q[None, :]) ** 2) / (2 * 0.1**2)).sum(axis=1)
    np.testing.assert_allclose(support_weights(grid, q, 0.1), exact, rtol=0.01)
    assert np.all(support_weights(grid, q, 0.1, q > 2.0) == 0.0)


def test_two_sided_support_vanishes_where_the_data_end():
    """Twice the smaller one-sided count: the plain count inside the data, about half of it
    where a point sees the data from one side only (the last sample's position), 0 beyond."""
    rng = np.random.default_rng(3)
    q = rng.uniform(0.0, 1.0, 20000)
    grid = np.array([0.3, 0.5, 0.7, q.max(), 1.2])
    kernel = np.exp(-((grid[:, None] - q[None, :]) ** 2) / (2 * 0.05**2))
    below = (kernel * (q[None, :] <= grid[:, None])).sum(axis=1)
    above = (kernel * (q[None, :] >= grid[:, None])).sum(axis=1)
    got = support_weights(grid, q, 0.05, two_sided=True)
    np.testing.assert_allclose(got[:3], 2 * np.minimum(below, above)[:3], rtol=0.02)
    np.testing.assert_allclose(got[:3], kernel.sum(axis=1)[:3], rtol=0.03)  # inside: plain
    plain = support_weights(grid, q, 0.05)
    assert got[3] < 0.02 * plain[3]  # the edge: every sample on one side
    assert plain[4] > 0.0 and got[4] == 0.0  # beyond: the Gaussian tails no longer count


def test_identified_intervals_are_the_runs_of_the_mask():
    q = np.linspace(0.0, 1.0, 11)
    mask = np.array([1, 1, 0, 0, 1, 1, 1, 0, 0, 0, 1], dtype=bool)
    assert identified_intervals(q, mask) == [[0.0, 0.1], [0.4, 0.6], [1.0, 1.0]]
    assert identified_intervals(q, np.zeros(11, bool)) == []


def test_a_systematic_bound_widens_each_band_edge_in_quadrature():
    rng = np.random.default_rng(5)
    m, p, B = 7, 3, 400
    maps = {"restoring": rng.standard_normal((m, p)), "d": rng.standard_normal((m, p))}
    theta = rng.standard_normal(p)
    boot = theta + 0.1 * rng.standard_normal((B, p))
    point = {name: a @ theta for name, a in maps.items()}
    support = {name: np.full(m, 100.0) for name in maps}
    plain = curve_bands(point, maps, theta, boot, support, 1.0, 10.0)
    wide = curve_bands(point, maps, theta, boot, support, 1.0, 10.0, {"restoring": 0.3})
    # independent computation: the percentile reach of each edge, then sqrt(reach^2 + 0.3^2)
    dev = (boot - theta) @ maps["restoring"].T
    down, up = -np.percentile(dev, 2.5, axis=0), np.percentile(dev, 97.5, axis=0)
    assert np.all(down > 0) and np.all(up > 0)
    value = point["restoring"]
    np.testing.assert_allclose(wide["restoring_lo"], value - np.sqrt(down**2 + 0.09), rtol=1e-12)
    np.testing.assert_allclose(wide["restoring_hi"], value + np.sqrt(up**2 + 0.09), rtol=1e-12)
    np.testing.assert_allclose(plain["restoring_lo"], value - down, rtol=1e-12)
    # a curve without a bound keeps its bootstrap band
    np.testing.assert_array_equal(wide["d_lo"], plain["d_lo"])
    np.testing.assert_array_equal(wide["d_hi"], plain["d_hi"])


def test_the_model_error_term_widens_each_band_by_its_share_of_the_curves_scale():
    """MODEL_ERROR's fractions scale with each curve's scale (range, or largest magnitude for
    a flat one-signed curve), a one-signed gain's with its local magnitude |g_i(q)|, and join
    the bootstrap reach and a systematic bound in quadrature; g1, g2 read the "g" entry (a g_i
    that changes sign takes the scale); a curve without an entry keeps its band."""
    from debist.identify.bands import MODEL_ERROR, band_label

    rng = np.random.default_rng(6)
    m, p, B = 9, 3, 400
    maps = {n: rng.standard_normal((m, p)) for n in ("restoring", "d", "g1")}
    maps["g1"] = 0.01 * maps["g1"] + np.array([1.0, 0.0, 0.0])  # flat, one-signed
    theta = np.array([2.0, 0.5, -0.3])
    boot = theta + 0.05 * rng.standard_normal((B, p))
    point = {n: a @ theta for n, a in maps.items()}
    support = {n: np.full(m, 100.0) for n in maps}
    table = {"restoring": 0.1, "g": 0.2}
    plain = curve_bands(point, maps, theta, boot, support, 1.0, 10.0)
    wide = curve_bands(point, maps, theta, boot, support, 1.0, 10.0, {"restoring": 0.3}, table)
    maps["g2"] = maps["g1"] - np.array([1.0, 0.0, 0.0])  # g1 shifted to straddle zero
    point["g2"], support["g2"] = maps["g2"] @ theta, np.full(m, 100.0)
    assert point["g2"].min() < 0 < point["g2"].max()
    wide = curve_bands(point, maps, theta, boot, support, 1.0, 10.0, {"restoring": 0.3}, table)
    for name, frac, extra in (("restoring", 0.1, 0.3), ("g1", 0.2, 0.0), ("g2", 0.2, 0.0)):
        value = point[name]
        scale = max(np.ptp(value), np.max(np.abs(value)))
        dev = (boot - theta) @ maps[name].T
        down, up = -np.percentile(dev, 2.5, axis=0), np.percentile(dev, 97.5, axis=0)
        assert np.all(down > 0) and np.all(up > 0)
        level = np.abs(value) if name == "g1" else scale  # g1 one-signed: its local magnitude
        term = np.hypot(extra, frac * level)
        np.testing.assert_allclose(wide[f"{name}_lo"], value - np.hypot(down, term), rtol=1e-12)
        np.testing.assert_allclose(wide[f"{name}_hi"], value + np.hypot(up, term), rtol=1e-12)
    g1 = point["g1"]
    assert np.max(np.abs(g1)) > 10 * np.ptp(g1)  # its scale is its magnitude, not its range
    np.testing.assert_array_equal(wide["d_lo"], plain["d_lo"])
    # a term wider than half the tolerance leaves nothing identified
    none = curve_bands(point, maps, theta, boot, support, 1.0, 0.3, None, {"restoring": 0.16})
    assert not none["restoring_identified"].any()
    assert curve_bands(point, maps, theta, boot, support, 1.0, 0.3)["restoring_identified"].all()
    assert set(MODEL_ERROR) == {"restoring", "d", "g", "F"}
    assert band_label(True).startswith("95 % band") and "bootstrap" in band_label(False)


def test_the_restoring_band_holds_the_coulomb_level(bistable_record):
    """With a Coulomb term the restoring band reaches at least |F_c| to each side."""
    records = _records(bistable_record, noise=0.01, seed=3)
    cfg = _cfg(backbone=["coulomb"], bootstrap=100, bootstrap_seed=1)
    model, diag = fit_rbf_model(records, cfg)
    F_c = abs(model.backbone["F_c"])
    assert F_c > 0
    frame, _ = curves_frame(model, diag, records, min_support=1.0, band_tolerance=10.0)
    assert np.all(frame.restoring - frame.restoring_lo >= F_c * (1 - 1e-12))
    assert np.all(frame.restoring_hi - frame.restoring >= F_c * (1 - 1e-12))


def test_bands_cover_a_truth_inside_the_model_class_under_coloured_noise(inside_class):
    """A model inside the class (no approximation bias), accelerations with AR(1) noise:
    the 95 % band of the restoring force holds the truth at >= 85 % of the identified
    points, and it is not trivially wide."""
    from tests.conftest import INSIDE_CLASS

    truth, rec = inside_class
    rng = np.random.default_rng(8)
    e = np.empty(rec["q"].size)
    e[0] = 0.0
    for k in range(1, e.size):  # AR(1), correlation time 10 samples
        e[k] = 0.9 * e[k - 1] + np.sqrt(1 - 0.81) * rng.standard_normal()
    rec["q_ddot"] = rec["q_ddot"] + 0.05 * np.std(rec["q_ddot"]) * e
    records = _records(rec)
    model, diag = fit_rbf_model(records, _cfg(**INSIDE_CLASS, bootstrap=300))
    frame, _ = curves_frame(model, diag, records, min_support=10, band_tolerance=0.25)
    q = frame.q.to_numpy()
    f_true = truth.curves(q)["cq"]
    ident = frame.restoring_identified.to_numpy()
    assert ident.mean() > 0.5
    inside = (frame.restoring_lo <= f_true) & (f_true <= frame.restoring_hi)
    assert inside[ident].mean() >= 0.85
    width = (frame.restoring_hi - frame.restoring_lo).to_numpy()
    assert np.median(width[ident]) < 0.1 * np.ptp(f_true)
    for name in ("restoring", "d", "g1", "g2"):
        assert (frame[f"{name}_lo"] <= frame[f"{name}_hi"]).all()


def _fit_with_input_only_where(bistable_record, j, keep, seed, **settings):
    """Fit the bistable truth's record with input ``j`` zeroed outside ``keep`` (the
    accelerations recomputed from the truth, 2 % noise), ``settings`` added to the identify
    configuration: (model, diag, records, rec)."""
    rec = dict(bistable_record)
    v = rec["v"].copy()
    v[:, j] = np.where(keep, v[:, j], 0.0)
    rec["v"] = v
    cur = bistable_truth(rec["q"])
    rec["q_ddot"] = (cur["g1"] * v[:, 0] ** 2 + cur["g2"] * v[:, 1] ** 2 - cur["c"] * rec["q"]
                     - cur["d"] * rec["q_dot"])  # fmt: skip
    records = _records(rec, noise=0.02 * np.std(rec["q_ddot"]), seed=seed)
    cfg = _cfg(backbone=["linear_spring", "cubic_spring", "viscous"], bootstrap=100, **settings)
    model, diag = fit_rbf_model(records, cfg)
    return model, diag, records, rec


def test_an_input_never_applied_is_not_identified_there(bistable_record):
    """g2 is unidentified where DE 2 was never energised (q > 0), whatever its band."""
    keep = bistable_record["q"] <= 0.0
    model, diag, records, _ = _fit_with_input_only_where(bistable_record, 1, keep, seed=4)
    frame, intervals = curves_frame(model, diag, records, min_support=10, band_tolerance=0.25)
    right = frame.q.to_numpy() > 0.005
    assert not frame.g2_identified.to_numpy()[right].any()
    assert frame.g1_identified.to_numpy()[right].any()
    assert intervals["g2"] and all(b <= 0.005 for _, b in intervals["g2"])


def test_a_gain_is_judged_against_its_magnitude_where_the_data_surround_it(bistable_record):
    """v_1 applied only at q < -4 mm, the weights beyond left free (``tie_undriven = false``):
    one RBF width past that edge g_1 is extrapolated (here thousands of times its size), so its
    band is judged against g_1's magnitude over the supported points only. Where marked the
    band is narrow against that magnitude and g_1 is within 5 % of the true curve's range;
    judged against the extrapolated magnitude every supported point would pass, dozens of them
    with bands wider than a quarter of the gain."""
    from debist.identify.excitation import input_active, quasi_static

    keep = bistable_record["q"] < -0.004
    model, diag, records, rec = _fit_with_input_only_where(
        bistable_record, 0, keep, seed=4, tie_undriven=False
    )
    frame, _ = curves_frame(model, diag, records, min_support=10, band_tolerance=0.25)
    q, g1 = frame.q.to_numpy(), frame.g1.to_numpy()
    # independent: the samples that inform g_1 and the points they surround / reach
    counted = input_active(rec["v"])[:, 0] & quasi_static(rec["q_dot"])
    sigma = model.basis.sigma
    surround = support_weights(q, rec["q"], sigma, counted, sigma, two_sided=True) >= 10
    reach = support_weights(q, rec["q"], sigma, counted, sigma) >= 10
    magnitude = max(np.ptp(g1[surround]), np.max(np.abs(g1[surround])))
    assert np.max(np.abs(g1[reach])) > 100 * magnitude  # the extrapolated gain
    marked = frame.g1_identified.to_numpy()
    width = (frame.g1_hi - frame.g1_lo).to_numpy()
    assert marked.sum() >= 20 and not marked[~surround].any()
    assert np.all(width[marked] <= 0.25 * magnitude)
    assert np.sum(surround & (width > 0.25 * magnitude)) >= 30  # left unmarked
    true = bistable_truth(q)["g1"]
    assert np.max(np.abs(g1 - true)[marked]) <= 0.05 * np.ptp(true)


def test_an_input_applied_only_in_transit_is_not_identified(bistable_record):
    """g1 with v_1 applied only where the beam moves fast (a transit) is unidentified.

    Along a transit q_dot is a function of q, so g_1 h(v_1) is not separated from c(q) q and
    d(q) z there; the same record with v_1 kept at the quasi-static samples marks g1.
    """
    from debist.identify.excitation import quasi_static

    slow = quasi_static(bistable_record["q_dot"])
    assert 0.2 < slow.mean() < 0.95  # both kinds of samples are present
    marked = {}
    for name, keep in (("transit", ~slow), ("quasi-static", slow)):
        model, diag, records, _ = _fit_with_input_only_where(bistable_record, 0, keep, seed=5)
        frame, _ = curves_frame(model, diag, records, min_support=10, band_tolerance=0.25)
        marked[name] = int(frame.g1_identified.sum())
    assert marked["transit"] == 0
    assert marked["quasi-static"] > 20


def test_creep_columns_enter_the_bootstrap_and_vanish_from_the_static_curves(bistable_record):
    """With creep the bootstrap resamples the creep columns like any other; the curve maps
    (the static curves, at rest: w = 0) still give the model's curves."""
    backbone = ["linear_spring", "cubic_spring", "viscous", "offset"]
    cfg = _cfg(backbone=backbone, bootstrap=20, creep=2.0)
    model, diag = fit_rbf_model(_records(bistable_record, noise=1.0), cfg)
    creep = [i for i, n in enumerate(diag.columns) if n.startswith("creep[")]
    assert len(creep) == 10 and diag.theta_boot.shape == (20, len(diag.columns))
    assert np.all(np.std(diag.theta_boot[:, creep], axis=0) > 0)
    q = np.linspace(*model.q_range, 41)
    maps = curve_maps(diag.columns, q, model.basis, 2, "v2", model.coulomb_velocity, model.prior)
    assert np.all(maps["restoring"][:, creep] == 0.0)
    restoring = model.curves(q)["cq"] + model.backbone["F_0"]
    err = np.max(np.abs(maps["restoring"] @ diag.theta - restoring))
    assert err <= 1e-12 * np.max(np.abs(restoring))


def test_the_scale_is_taken_where_the_data_reach_and_the_mask_where_they_surround():
    """A ramp whose two-sided support covers only its middle: marked there only, and judged
    against its scale over the one-sided reach (the whole ramp), not the middle's range."""
    m = 11
    grid = np.linspace(-1.0, 1.0, m)
    maps = {"restoring": np.column_stack([grid, np.ones(m)])}  # value = a q + b
    theta = np.array([1.0, 0.0])
    rng = np.random.default_rng(7)
    boot = theta + np.column_stack([np.zeros(400), 0.02 * rng.standard_normal(400)])
    point = {"restoring": maps["restoring"] @ theta}
    middle = {"restoring": np.where(np.abs(grid) <= 0.4, 100.0, 0.0)}
    reach = {"restoring": np.full(m, 100.0)}
    width = np.percentile(boot[:, 1], 97.5) - np.percentile(boot[:, 1], 2.5)
    tol = 1.5 * width / 2.0  # scale 2 over the reach: width <= tol * 2; middle's range 0.8: not
    assert width > tol * 0.8
    judged = curve_bands(point, maps, theta, boot, middle, 1.0, tol, reach=reach)
    alone = curve_bands(point, maps, theta, boot, middle, 1.0, tol)
    np.testing.assert_array_equal(judged["restoring_identified"], np.abs(grid) <= 0.4)
    assert not alone["restoring_identified"].any()


def test_each_model_reads_the_calibration_of_its_own_terms_and_scale():
    """Backbone ``physics_creep`` and ``effective_mass`` each have their own calibration (fleets
    of both plants run with them) and label. The effective-mass scale takes the lagged damping's
    apparent mass out of the curves: every curve's model error is at most the as-fitted one,
    and g_i's (of its local magnitude) falls from 0.55-0.58 to 0.32-0.44."""
    from debist.identify.bands import (
        MEASURED_COVERAGE_AS_FITTED,
        MEASURED_COVERAGE_CREEP,
        MODEL_ERROR,
        MODEL_ERROR_AS_FITTED,
        MODEL_ERROR_CREEP,
        MODEL_ERROR_CREEP_AS_FITTED,
        STIFFNESS_ERROR,
        STIFFNESS_ERROR_AS_FITTED,
        band_label,
        model_error_table,
    )

    assert model_error_table(["offset"]) is MODEL_ERROR
    assert model_error_table(["offset", "physics_creep"]) is MODEL_ERROR_CREEP
    assert model_error_table(["offset"], effective_mass=False) is MODEL_ERROR_AS_FITTED
    creep_as_fitted = model_error_table(["physics_creep"], effective_mass=False)
    assert creep_as_fitted is MODEL_ERROR_CREEP_AS_FITTED
    for scaled, fitted in ((MODEL_ERROR, MODEL_ERROR_AS_FITTED),
                           (MODEL_ERROR_CREEP, MODEL_ERROR_CREEP_AS_FITTED)):  # fmt: skip
        assert set(scaled) == set(fitted) == {"restoring", "d", "g", "F"}
        assert all(scaled[k] <= fitted[k] for k in fitted)
        assert scaled["g"] <= 0.44 < 0.55 <= fitted["g"]
    # a band is at least twice its model-error term wide: a restoring term of half the default
    # tolerance or more would mark the restoring force nowhere on any rig
    tolerance = IdentifyConfig().band_tolerance
    for table in (MODEL_ERROR, MODEL_ERROR_CREEP, MODEL_ERROR_AS_FITTED,
                  MODEL_ERROR_CREEP_AS_FITTED):  # fmt: skip
        assert 2 * table["restoring"] < tolerance
    assert STIFFNESS_ERROR < 0.5 * STIFFNESS_ERROR_AS_FITTED
    assert f"at {MEASURED_COVERAGE_CREEP} there" in band_label(True, creep=True)
    assert f"at {MEASURED_COVERAGE_AS_FITTED} there" in band_label(True, effective_mass=False)
    assert band_label(False, creep=True) == band_label(False)
    assert "at 81-100 % there" in band_label(True, creep=True, terms=["input_quadratic"])
    assert band_label(False, terms=["input_quadratic"]) == band_label(False)
    assert "at 99-100 % there" in band_label(True, creep=True, terms=["c", "gh"])
    assert "at 81-100 % there" in band_label(True, terms=["gh", "input_quadratic"])
    assert "at 97-100 % there" in band_label(True, terms=["gh", "physics_quadratic", "offset"])


def test_the_stiffness_band_is_the_slope_map_and_the_calibrated_model_error(bistable_record):
    """k* = dF/dq at each identified well: the band's map applied to the parameters is the
    stability table's k* (a replicate at 2 theta deviates by exactly k*), and without spread the
    band is k* (1 -+ STIFFNESS_ERROR), f_n its square-root image; saddles and the analytical
    rows get none."""
    from dataclasses import replace

    from debist.identify.bands import STIFFNESS_ERROR, STIFFNESS_ERROR_AS_FITTED, stiffness_bands
    from debist.identify.design import design_numbers

    records = _records(bistable_record)
    model, diag = fit_rbf_model(records, _cfg(bootstrap=0))
    eq = design_numbers(model, records)["equilibria"]
    wells = (eq.model == "rbf") & eq.static_stable.astype(bool)
    assert wells.sum() == 2 and (~wells).any()
    k = eq.k[wells].to_numpy()
    doubled = stiffness_bands(eq, model, replace(diag, theta_boot=2.0 * diag.theta[None]), False)
    np.testing.assert_allclose(doubled.k_lo[wells], 2.0 * k, rtol=1e-6)
    np.testing.assert_allclose(doubled.k_hi[wells], 2.0 * k, rtol=1e-6)
    flat = stiffness_bands(eq, model, replace(diag, theta_boot=diag.theta[None]), True)
    np.testing.assert_allclose(flat.k_lo[wells], (1 - STIFFNESS_ERROR) * k, rtol=1e-12)
    np.testing.assert_allclose(flat.k_hi[wells], (1 + STIFFNESS_ERROR) * k, rtol=1e-12)
    fitted = stiffness_bands(eq, model, replace(diag, theta_boot=diag.theta[None]), True, False)
    np.testing.assert_allclose(fitted.k_hi[wells], (1 + STIFFNESS_ERROR_AS_FITTED) * k, rtol=1e-12)
    m_q = eq.m_q[wells].to_numpy()
    f_lo = np.sqrt((1 - STIFFNESS_ERROR) * k / m_q) / (2 * np.pi)
    np.testing.assert_allclose(flat.f_n_lo[wells], f_lo, rtol=1e-12)
    assert flat.loc[~wells, ["k_lo", "k_hi", "f_n_lo", "f_n_hi"]].isna().all().all()
    none = stiffness_bands(eq, model, diag, True)  # no replicates: no band
    assert none[["k_lo", "k_hi"]].isna().all().all()
    assert flat.attrs == eq.attrs


def test_simulation_only_names_the_fitted_curves_that_hold_nowhere():
    """Only curves the model fits as RBF sums count; a backbone constant (rbf = []) is none."""
    from types import SimpleNamespace

    from debist.identify.bands import fitted_curves, simulation_only

    identified = {"restoring": [[-0.01, -0.007]], "d": [], "g1": [], "g2": [[0.0, 0.01]]}
    full = SimpleNamespace(theta_c=np.ones(6), theta_d=np.ones(6), theta_g=np.ones((2, 6)))
    assert fitted_curves(full) == {"restoring", "d", "g1", "g2"}
    assert simulation_only(identified, fitted_curves(full)) == (
        "d, g1 identified nowhere (restoring, g2 hold on part of q)"
    )
    idim = SimpleNamespace(theta_c=np.zeros(6), theta_d=np.zeros(6), theta_g=np.zeros((1, 6)))
    assert fitted_curves(idim) == set()
    assert simulation_only({"restoring": [], "d": [], "g1": []}, fitted_curves(idim)) == ""
    no_g2 = SimpleNamespace(theta_c=np.ones(6), theta_d=np.zeros(6),
                            theta_g=np.vstack([np.ones(6), np.zeros(6)]))  # fmt: skip
    assert simulation_only(identified, fitted_curves(no_g2)) == (
        "g1 identified nowhere (restoring holds on part of q)"
    )
