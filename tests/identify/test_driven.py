"""Where the estimation applied each input, and records that apply one elsewhere."""

import numpy as np
import pandas as pd
import pytest

from debist.identify.driven import beyond_driven, driven_ranges
from debist.report.tables import verdict
from debist.stages.validate import extrapolation


def _levels(n, on, rng):
    """Input levels [V]: 3 kV where ``on``, the driver's noise (2 V RMS) elsewhere."""
    return np.where(on, 3000.0, 0.0) + 2.0 * rng.standard_normal(n)


def test_the_driven_range_is_where_the_input_is_active_and_nan_where_never():
    rng = np.random.default_rng(5)
    q = np.linspace(-0.012, 0.012, 241)
    v = np.column_stack([_levels(241, q > 0.004, rng), np.zeros(241)])  # v2 never applied
    ranges = driven_ranges(q, v)
    np.testing.assert_allclose(ranges[0], [q[q > 0.004].min(), 0.012])
    assert np.isnan(ranges[1]).all()
    with pytest.raises(ValueError, match="241 samples, v 240"):
        driven_ranges(q, v[:-1])


def test_a_record_beyond_the_range_is_worded_per_side_and_counted():
    """Driven at [-10, -8] mm, margin 1 mm: a record with v2 on over [-12, 9] mm on a 0.1 mm
    grid has 10 samples below -11 mm and 160 above -7 mm, each side worded apart."""
    rng = np.random.default_rng(6)
    ranges = np.array([[-0.012, 0.012], [-0.010, -0.008]])
    q = np.round(np.arange(-0.012, 0.0090001, 1e-4), 10)
    v = np.column_stack([_levels(q.size, q < 0, rng), _levels(q.size, np.ones(q.size, bool), rng)])
    words = beyond_driven(ranges, q, v, margin=0.001, scale=1e3, unit="mm")
    below = int(np.sum(q < -0.011))
    above = int(np.sum(q > -0.007))
    assert words == (
        f"v2 applied at q = -12 to -11 mm ({below} samples) and -6.9 to 9 mm ({above} samples), "
        "where the estimation applied it only at -10 to -8 mm"
    )
    assert below == 10 and above == 160  # (-12.0..-11.1 mm) and (-6.9..9.0 mm)


def test_within_the_margin_or_below_the_count_nothing_is_said_and_never_applied_is():
    rng = np.random.default_rng(7)
    ranges = np.array([[-0.01, 0.0], [np.nan, np.nan]])
    q = np.linspace(-0.0105, 0.0005, 100)  # at most 0.5 mm beyond: inside a 1 mm margin
    v = np.column_stack([_levels(100, np.ones(100, bool), rng), np.zeros(100)])
    assert beyond_driven(ranges, q, v, margin=0.001) == ""
    q9 = np.linspace(0.002, 0.003, 9)  # nine samples beyond: fewer than MIN_SAMPLES
    v9 = np.column_stack([np.full(9, 3000.0), np.zeros(9)])
    v9 = np.vstack([v9, np.zeros((20, 2))])
    q9 = np.concatenate([q9, np.zeros(20)])
    assert beyond_driven(ranges, q9, v9, margin=0.001) == ""
    v2 = np.column_stack([np.zeros(100), _levels(100, q > -0.005, rng)])
    assert beyond_driven(ranges, q, v2, margin=0.001, scale=1e3, unit="mm").endswith(
        "where the estimation never applied it"
    )


def _table(role, q, v):
    frame = pd.DataFrame({"t": np.arange(q.size) * 1e-3, "q": q, "v1": v[:, 0], "v2": v[:, 1]})
    frame.attrs.update(role=role, units={"t": "s", "q": "m", "v1": "V", "v2": "V"})
    return frame


def test_the_stage_flags_the_unseen_record_and_the_verdict_says_so_first():
    rng = np.random.default_rng(8)
    q = np.linspace(-0.01, 0.01, 400)
    est = np.column_stack([_levels(400, q < -0.004, rng), _levels(400, q > 0.004, rng)])
    same = est[::-1].copy()
    other = np.column_stack([_levels(400, q > 0.004, rng), _levels(400, q < -0.004, rng)])
    tables = {
        "est": _table("estimation", q, est),
        "same": _table("validation", q[::-1].copy(), same),
        "other": _table("validation", q, other),
    }
    out = extrapolation(tables, margin=0.001)
    assert out["est"] == "" and out["same"] == ""
    assert out["other"].startswith("v1 applied at q = 4 to 10 mm (120 samples), where the ")
    assert "; v2 applied at q = -10 to -4 mm (120 samples)" in out["other"]
    in_metres = extrapolation(tables, margin=0.001, report_unit="m")["other"]  # the report unit
    assert in_metres.startswith("v1 applied at q = 0.004 to 0.01 m (120 samples), where the ")
    in_um = extrapolation(tables, margin=0.001, report_unit="um")["other"]  # no exponent
    assert in_um.startswith("v1 applied at q = 4000 to 10000 \u00b5m (120 samples), where the ")
    row = {"nrmse_q": 0.004, "nrmse_q_baseline": 0.2, "extrapolated": out["other"]}
    assert verdict(row) == f"extrapolated: {out['other']}"
    poor = {**row, "nrmse_q": 0.19}
    assert verdict(poor).startswith(f"extrapolated: {out['other']}; poor: 95 %")


def test_undriven_centres_are_the_end_runs_below_ten_samples_worth_of_information():
    """Information of centre k for input i: over the active samples, 1 within one width and
    phi_k^2 / phi_k(sigma)^2 = exp(1 - (q - xi_k)^2 / sigma^2) beyond (Eq. 38). v1 on at
    q > 2 mm; v2 on at |q| > 7 mm only: its middle centres are thin but lie between informed
    ones (a barrier crossed quickly), so only end runs are flagged."""
    from debist.identify.driven import undriven_centres
    from debist.model.basis import RBFBasis

    rng = np.random.default_rng(8)
    q = np.sort(rng.uniform(-0.012, 0.012, 2400))
    v = np.column_stack([_levels(2400, q > 0.002, rng), _levels(2400, np.abs(q) > 0.007, rng)])
    basis = RBFBasis.equidistant(-0.012, 0.012, 9, 0.5, "clip")
    flags = undriven_centres(q, v, basis)
    on = [q > 0.002, np.abs(q) > 0.007]
    for j in range(2):
        info = np.minimum(1.0, np.exp(1 - (q[on[j], None] - basis.xi) ** 2 / basis.sigma**2))
        info = info.sum(axis=0)
        thin = info < 10
        first, last = np.flatnonzero(~thin)[[0, -1]]
        want = thin & ((np.arange(9) < first) | (np.arange(9) > last))
        np.testing.assert_array_equal(flags[j], want)
    assert flags[0, :3].all() and not flags[0, 5:].any()  # below ~ -3 mm: v1 never on
    assert not flags[1].any()  # v2's thin middle centres lie between informed ones
    assert np.minimum(1, np.exp(1 - (q[on[1]] - basis.xi[4]) ** 2 / basis.sigma**2)).sum() < 10


@pytest.mark.parametrize(("sigma_n", "expected"), [(0.25, 0.73), (0.5, 0.028), (1.0, 0.0)])
def test_the_basis_ripple_is_that_of_a_lattice_of_gaussians(sigma_n, expected):
    """Against the sum over an infinite lattice of unit spacing (101 terms), between two
    centres: 1 - S(1/2) / S(0) for the narrow bases, flat to 1e-6 at sigma_n = 1."""
    from debist.identify.driven import basis_ripple
    from debist.model.basis import RBFBasis

    k = np.arange(-50, 51)
    x = np.linspace(0.0, 1.0, 201)
    lattice = np.exp(-((x[:, None] - k) ** 2) / (2 * sigma_n**2)).sum(axis=1)
    independent = 1.0 - lattice.min() / lattice.max()
    ripple = basis_ripple(RBFBasis.equidistant(-1.0, 1.0, 21, sigma_n))
    assert ripple == pytest.approx(independent, abs=1e-6)
    assert ripple == pytest.approx(expected, abs=0.005)


def test_a_narrow_basis_leaves_the_undriven_weights_free_and_says_why():
    """v1 applied only at q > 4 mm, v2 only at q < 0: g1's first and g2's last centres are
    undriven on both bases; with sigma_n = 0.5 they are tied, with sigma_n = 0.25 (73 %
    ripple) left free, in words."""
    from debist.identify.config import IdentifyConfig
    from debist.identify.driven import undriven_weights
    from debist.identify.fit import Record
    from debist.model.basis import RBFBasis

    rng = np.random.default_rng(7)
    q = np.linspace(-0.012, 0.012, 2401)
    v = np.column_stack([_levels(q.size, q > 0.004, rng), _levels(q.size, q < 0.0, rng)])
    zeros = np.zeros_like(q)
    records = [Record("est", q, zeros, zeros, v, 1e-3)]
    cfg = IdentifyConfig.from_dict({"input_map": "v2"})
    tied, text = undriven_weights(records, RBFBasis.equidistant(-0.012, 0.012, 7, 0.5), cfg)
    assert tied[0] == "g1[0]" and tied[-1] == "g2[6]"
    assert text.startswith("g1 continued from its neighbours at centre(s) 1")
    assert "; g2 continued from its neighbours at centre(s) " in text
    free, text = undriven_weights(records, RBFBasis.equidistant(-0.012, 0.012, 7, 0.25), cfg)
    assert free == []
    assert text.startswith("g1 left free at centre(s) 1") and "73 % ripple" in text
    assert "; g2 left free at centre(s) " in text
