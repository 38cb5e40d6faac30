"""SINDy baseline: exact recovery, independent evaluation, free run, round trip, config."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from debist.core.errors import IdentificationError, WorkflowError
from debist.model.sindy import SindyConfig, SindyModel, fit_sindy, fit_sindy_thresholds
from debist.simulate.freerun import simulate

# q'' = -k1 q - k3 q^3 - d q' + g1 (1 + a q) v1^2 + g2 v2^2, SI units (q ~ 1 mm, v ~ 1 kV).
K1 = (2 * np.pi * 50.0) ** 2  # [1/s^2]
K3 = 1.0e11  # [1/(m^2 s^2)]
D = 2 * 0.05 * 2 * np.pi * 50.0  # [1/s]
G1 = 1.0e-4  # [m/(s^2 V^2)]
A = 200.0  # [1/m]
G2 = 5.0e-5  # [m/(s^2 V^2)]
TRUE = {"q": -K1, "q^3": -K3, "q_dot": -D, "1 h1": G1, "q h1": G1 * A, "1 h2": G2}
DT = 1e-4  # [s]
N = 5000


def _inputs(seed: int):
    """Smooth multi-sine voltages [V], shape (len(t), 2), 5 .. 150 Hz, as a function of t."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(5.0, 150.0, (2, 6))
    ph = rng.uniform(0, 2 * np.pi, (2, 6))

    def v(t):
        t = np.atleast_1d(t)
        s = np.sin(2 * np.pi * f[None] * t[:, None, None] + ph[None])
        return 800.0 + 60.0 * s.sum(axis=2)

    return v


def _accel(q, q_dot, v):
    return -K1 * q - K3 * q**3 - D * q_dot + G1 * (1 + A * q) * v[..., 0] ** 2 + G2 * v[..., 1] ** 2


def _record(seed: int):
    t = np.arange(N) * DT
    vf = _inputs(seed)

    def f(tt, y):
        return [y[1], _accel(y[0], y[1], vf(tt)[0])]

    sol = solve_ivp(f, (0, t[-1]), [0.0, 0.0], method="DOP853", t_eval=t, rtol=1e-12, atol=1e-15)
    q, q_dot = sol.y
    v = vf(t)
    return q, q_dot, _accel(q, q_dot, v), v


@pytest.fixture(scope="module")
def data():
    return [_record(seed) for seed in (1, 2)]


@pytest.fixture(scope="module")
def model(data):
    q, q_dot, q_ddot, v = (list(x) for x in zip(*data, strict=True))
    return fit_sindy(q, q_dot, q_ddot, v, DT, SindyConfig())


def test_recovers_known_system_exactly(model):
    names = model.feature_names
    assert len(names) == 30  # 10 monomials of degree <= 3 in (q, q_dot), times [1, h1, h2]
    nonzero = {n for n, c in zip(names, model.coefficients, strict=True) if c != 0}
    assert nonzero == set(TRUE)
    assert model.n_params == len(TRUE)
    for name, value in TRUE.items():
        got = model.coefficients[names.index(name)]
        assert got == pytest.approx(value, rel=1e-6), name
    assert "q_ddot = " in model.equations


def test_rhs_equals_pysindy_library(model, data):
    import pysindy as ps

    lib = ps.GeneralizedLibrary(
        [ps.PolynomialLibrary(degree=3), ps.PolynomialLibrary(degree=1, include_bias=False)],
        tensor_array=[[1, 1]],
        inputs_per_library=[[0, 1], [2, 3]],
        exclude_libraries=[1],
    )
    rng = np.random.default_rng(7)
    B = 64
    x = np.column_stack([rng.uniform(-2e-3, 2e-3, B), rng.uniform(-1.0, 1.0, B)])
    v = rng.uniform(0.0, 1500.0, (B, 2))
    z = np.column_stack([x, v**2])
    lib.fit(z)
    assert lib.get_feature_names(["q", "q_dot", "h1", "h2"]) == model.feature_names
    expected = np.asarray(lib.transform(z)) @ model.coefficients
    x_dot, a = model.rhs(x, v)
    np.testing.assert_allclose(a, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())
    np.testing.assert_array_equal(x_dot[:, 0], x[:, 1])
    np.testing.assert_array_equal(x_dot[:, 1], a)


def test_free_run_reproduces_solve_ivp(model, data):
    q, q_dot, _, v = data[0]
    (res,) = simulate(model, [v], DT, np.array([q[0]]), np.array([q_dot[0]]))
    assert not res.diverged
    err = np.linalg.norm(res.q - q) / np.linalg.norm(q)
    assert err < 1e-3


def test_tree_round_trip(model):
    back = SindyModel.from_tree(model.to_tree())
    assert back.feature_names == model.feature_names
    np.testing.assert_array_equal(back.coefficients, model.coefficients)
    np.testing.assert_array_equal(back.exponents, model.exponents)
    assert (back.input_map, back.n_inputs, back.equations) == ("v2", 2, model.equations)
    assert back.q_range == model.q_range
    x = np.array([[1e-3, 0.1]])
    v = np.array([[900.0, 700.0]])
    np.testing.assert_array_equal(back.rhs(x, v)[1], model.rhs(x, v)[1])


def test_config_rejects_unknown_and_bad_values():
    assert SindyConfig.from_dict(None) == SindyConfig()
    assert SindyConfig.from_dict({"degree": 2, "optimizer": "SR3"}).degree == 2
    with pytest.raises(WorkflowError) as err:
        SindyConfig.from_dict({"treshold": 0.1})
    assert err.value.key == "compare.treshold"
    assert "unknown" in str(err.value)
    assert "'threshold'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        SindyConfig.from_dict({"optimizer": "lasso"})
    assert err.value.key == "compare.optimizer"
    assert "'STLSQ'" in str(err.value)
    assert "'SR3'" in str(err.value)
    assert "'lasso'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        SindyConfig.from_dict({"degree": 0})
    assert err.value.key == "compare.degree"
    assert ">= 1" in str(err.value)
    assert "got 0" in str(err.value)


def test_sr3_recovers_the_same_terms(data):
    q, q_dot, q_ddot, v = data[0]
    m = fit_sindy(q, q_dot, q_ddot, v, DT, SindyConfig(optimizer="SR3"))
    nonzero = {n for n, c in zip(m.feature_names, m.coefficients, strict=True) if c != 0}
    assert nonzero == set(TRUE)
    for name, value in TRUE.items():
        assert m.coefficients[m.feature_names.index(name)] == pytest.approx(value, rel=1e-6)


@pytest.mark.filterwarnings("ignore::debist.core.errors.ConvergenceWarning")  # SR3 on noise
@pytest.mark.parametrize("optimizer", ["STLSQ", "SR3"])
def test_thresholds_on_one_library_are_the_separate_fits(data, optimizer):
    """Several thresholds on one library matrix: each model the bits of its own fit."""
    q, q_dot, q_ddot, v = data[0]
    noisy = q_ddot + np.random.default_rng(7).normal(0.0, 0.05 * np.std(q_ddot), q_ddot.size)
    cfg = SindyConfig(optimizer=optimizer)
    thresholds = (1e-3, 1e-2, 5e-2)
    together = fit_sindy_thresholds(q, q_dot, noisy, v, DT, cfg, thresholds)
    assert len({m.n_params for m in together}) > 1  # the thresholds give different models
    for threshold, got in zip(thresholds, together, strict=True):
        alone = fit_sindy(q, q_dot, noisy, v, DT, SindyConfig(optimizer=optimizer,
                                                              threshold=threshold))  # fmt: skip
        assert got.threshold == alone.threshold == threshold
        assert got.feature_names == alone.feature_names
        np.testing.assert_array_equal(got.coefficients, alone.coefficients)
        np.testing.assert_array_equal(got.exponents, alone.exponents)
        assert got.equations == alone.equations


def test_constant_input_gains_library(data):
    q, q_dot, q_ddot, v = data[0]
    m = fit_sindy(q, q_dot, q_ddot, v, DT, SindyConfig(input_terms=False, degree=2))
    assert m.feature_names[-2:] == ["h1", "h2"] and len(m.feature_names) == 6 + 2
    x = np.column_stack([q[:50], q_dot[:50]])
    np.testing.assert_allclose(
        m.rhs(x, v[:50])[1], m.features(q[:50], q_dot[:50], v[:50]) @ m.coefficients, rtol=1e-12
    )


def test_rejects_inconsistent_records(data):
    q, q_dot, q_ddot, v = data[0]
    with pytest.raises(IdentificationError) as err:
        fit_sindy(q, q_dot[:-1], q_ddot, v, DT, SindyConfig())
    assert "record 0" in str(err.value)
    with pytest.raises(IdentificationError) as err:
        fit_sindy([q, q], [q_dot], [q_ddot], [v], DT, SindyConfig())
    assert "number" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        fit_sindy(q, q_dot, q_ddot, v, 0.0, SindyConfig())
    assert "dt" in str(err.value)
    with pytest.raises(ValueError, match="at least one threshold"):
        fit_sindy_thresholds(q, q_dot, q_ddot, v, DT, SindyConfig(), ())
