"""Tests of the differentiate stage: one contract, error-bound table, exactness, registry."""

from __future__ import annotations

import dataclasses
import inspect
import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from debist.core.errors import ConvergenceWarning, WorkflowError
from debist.differentiate.base import CONFIGS, DIFFERENTIATORS, differentiate
from debist.differentiate.result import Derivatives
from debist.differentiate.savgol import SavGolConfig, savgol_derivatives
from debist.differentiate.spectral import SpectralConfig, lowpass_gain, spectral_derivatives
from debist.differentiate.tvregdiff_method import TVRegDiffConfig, tvregdiff_derivatives

DT, N = 0.01, 1000
T = np.arange(N) * DT
W1, W2 = 2 * np.pi * 0.5, 2 * np.pi * 1.3
X = np.sin(W1 * T) + 0.5 * np.sin(W2 * T)
X_DOT = W1 * np.cos(W1 * T) + 0.5 * W2 * np.cos(W2 * T)
X_DDOT = -(W1**2) * np.sin(W1 * T) - 0.5 * W2**2 * np.sin(W2 * T)
INNER = slice(50, -50)


def nrmse(estimate: np.ndarray, exact: np.ndarray, part: slice) -> float:
    """Root-mean-square error over ``part``, relative to the RMS of ``exact``."""
    return float(np.sqrt(np.mean((estimate - exact)[part] ** 2) / np.mean(exact[part] ** 2)))


TVR_LARGE = {"alpha": 1e-4, "ep": 1e-6, "iterations": 20, "alpha2": 1e-3}
TVR_SMALL = TVR_LARGE | {"scale": "small"}

# method, params, noise sigma, part, bounds on the relative RMS errors of (x_hat, x_dot, x_ddot).
# Measured values are about 2/3 of each bound (seed 42).
ERROR_BOUNDS = [
    ("tvregdiff", TVR_LARGE, 0.0, INNER, (1.6e-3, 1.2e-2, 0.11)),
    ("tvregdiff", TVR_LARGE, 1e-3, INNER, (2.0e-3, 2.6e-2, 0.14)),
    ("tvregdiff", TVR_LARGE, 1e-2, INNER, (1.0e-2, 0.12, 0.9)),
    ("tvregdiff", TVR_SMALL, 1e-3, INNER, (1.6e-3, 4.4e-2, 0.2)),
    ("spectral", {"cutoff_hz": 3.0}, 0.0, slice(None), (6e-4, 3.1e-3, 1.3e-2)),
    ("spectral", {"cutoff_hz": 3.0}, 1e-3, INNER, (5e-4, 1.4e-3, 3.1e-3)),
    ("spectral", {"cutoff_hz": 3.0}, 1e-2, INNER, (4.5e-3, 1.1e-2, 2.1e-2)),
    ("savgol", {"window": 51, "polyorder": 4}, 0.0, slice(None), (1.7e-3, 3.9e-2, 4.0e-2)),
    ("savgol", {"window": 51, "polyorder": 4}, 1e-3, INNER, (1.6e-3, 3.9e-2, 3.1e-2)),
    ("savgol", {"window": 51, "polyorder": 4}, 1e-2, INNER, (5.6e-3, 4.2e-2, 4.8e-2)),
]


@pytest.mark.filterwarnings("ignore::debist.core.errors.ConvergenceWarning")
@pytest.mark.parametrize(("method", "params", "sigma", "part", "bounds"), ERROR_BOUNDS)
def test_error_bounds_on_noisy_sines(method, params, sigma, part, bounds):
    x = X + sigma * np.random.default_rng(42).standard_normal(N)
    d = differentiate(x, DT, method=method, params=params)
    errors = (nrmse(d.x_hat, X, part), nrmse(d.x_dot, X_DOT, part), nrmse(d.x_ddot, X_DDOT, part))
    assert np.all(np.less_equal(errors, bounds)), f"{method} {params} sigma={sigma}: {errors}"


@pytest.mark.filterwarnings("ignore::debist.core.errors.ConvergenceWarning")
@pytest.mark.parametrize("method", sorted(DIFFERENTIATORS))
def test_every_method_honours_the_contract(method):
    f = DIFFERENTIATORS[method]
    sig = inspect.signature(f)
    assert list(sig.parameters)[:2] == ["x", "dt"]
    assert sig.parameters["config"].kind is inspect.Parameter.KEYWORD_ONLY
    d = f(list(X[:200]), DT, config=CONFIGS[method]())
    assert isinstance(d, Derivatives) and d.method == method
    for a in (d.x_hat, d.x_dot, d.x_ddot):
        assert isinstance(a, np.ndarray) and a.shape == (200,) and a.dtype == np.float64
    assert isinstance(d.converged, bool) and isinstance(d.info, dict)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.method = "other"  # type: ignore[misc]


# ---------------------------------------------------------------- exactness


def test_spectral_periodic_is_exact_for_band_limited_periodic_signal():
    n, dt = 256, 0.01
    period = n * dt
    t = np.arange(n) * dt
    ks, amps, phases = [1, 3, 7, 12], [1.0, 0.5, 0.2, 0.05], [0.3, 1.1, -0.4, 2.0]
    w = [2 * np.pi * k / period for k in ks]
    x = 0.7 + sum(a * np.sin(wk * t + p) for a, wk, p in zip(amps, w, phases, strict=True))
    x_dot = sum(a * wk * np.cos(wk * t + p) for a, wk, p in zip(amps, w, phases, strict=True))
    x_ddot = sum(-a * wk**2 * np.sin(wk * t + p) for a, wk, p in zip(amps, w, phases, strict=True))
    cfg = SpectralConfig(cutoff_hz=10.0, taper=0.2, extension="periodic")  # pass band to 8 Hz
    d = spectral_derivatives(x, dt, config=cfg)
    np.testing.assert_allclose(d.x_hat, x, atol=1e-12)
    np.testing.assert_allclose(d.x_dot, x_dot, atol=1e-9 * np.abs(x_dot).max())
    np.testing.assert_allclose(d.x_ddot, x_ddot, atol=1e-9 * np.abs(x_ddot).max())
    assert d.info["n_fft"] == n


def test_spectral_odd_is_exact_for_line_plus_half_range_sines():
    n, dt = 301, 0.01
    span = (n - 1) * dt
    t = np.arange(n) * dt
    x = -0.2 + 1.5 * t + np.sin(np.pi * 2 * t / span) + 0.3 * np.sin(np.pi * 9 * t / span)
    x_dot = 1.5 + (2 * np.pi / span) * np.cos(2 * np.pi * t / span)
    x_dot += 0.3 * (9 * np.pi / span) * np.cos(9 * np.pi * t / span)
    x_ddot = -((2 * np.pi / span) ** 2) * np.sin(2 * np.pi * t / span)
    x_ddot -= 0.3 * (9 * np.pi / span) ** 2 * np.sin(9 * np.pi * t / span)
    d = spectral_derivatives(x, dt, config=SpectralConfig(cutoff_hz=20.0))
    np.testing.assert_allclose(d.x_hat, x, atol=1e-12)
    np.testing.assert_allclose(d.x_dot, x_dot, atol=1e-9 * np.abs(x_dot).max())
    np.testing.assert_allclose(d.x_ddot, x_ddot, atol=1e-9 * np.abs(x_ddot).max())


def test_spectral_odd_does_not_ring_at_the_ends_of_a_ramp():
    t = np.arange(500) * 0.01
    x = 3.0 * t + 0.1 * t**2
    d = spectral_derivatives(x, 0.01, config=SpectralConfig(cutoff_hz=5.0))
    periodic = spectral_derivatives(x, 0.01, config=SpectralConfig(5.0, extension="periodic"))
    # The odd extension of a ramp minus its chord is smooth to first order.
    assert np.max(np.abs(d.x_dot - (3.0 + 0.2 * t))) < 0.02
    assert np.max(np.abs(periodic.x_dot - (3.0 + 0.2 * t))) > 10.0


def test_lowpass_gain_shape():
    f = np.linspace(0, 10, 1001)
    g = lowpass_gain(f, 5.0, 0.2)
    assert np.all(g[f <= 4.0] == 1.0) and np.all(g[f >= 5.0] == 0.0)
    assert np.all(np.diff(g) <= 0) and g[f == 4.5] == pytest.approx(0.5)
    np.testing.assert_array_equal(lowpass_gain(f, None, 0.2), np.ones_like(f))
    np.testing.assert_array_equal(lowpass_gain(f, 5.0, 0.0), (f < 5.0).astype(float))


@pytest.mark.parametrize(("window", "polyorder"), [(5, 3), (21, 3), (31, 5)])
def test_savgol_is_exact_for_a_cubic(window, polyorder):
    t = np.arange(120) * 0.05 - 2.0
    x = 0.3 - 1.2 * t + 0.8 * t**2 - 0.25 * t**3
    d = savgol_derivatives(x, 0.05, config=SavGolConfig(window=window, polyorder=polyorder))
    np.testing.assert_allclose(d.x_hat, x, atol=1e-10 * np.abs(x).max())
    np.testing.assert_allclose(d.x_dot, -1.2 + 1.6 * t - 0.75 * t**2, atol=1e-9)
    np.testing.assert_allclose(d.x_ddot, 1.6 - 1.5 * t, atol=1e-8)
    assert d.info == {"window": window, "polyorder": polyorder, "window_s": window * 0.05}


# ---------------------------------------------------------------- tvregdiff method


def test_tvregdiff_method_matches_two_passes_and_reports():
    from debist.differentiate.tvregdiff import tvregdiff

    x = X + 1e-3 * np.random.default_rng(1).standard_normal(N)
    cfg = TVRegDiffConfig(alpha=1e-4, ep=1e-6, iterations=5, alpha2=1e-3, iterations2=3)
    with pytest.warns(ConvergenceWarning) as record:
        d = tvregdiff_derivatives(x, DT, config=cfg)
    assert len(record) == 2  # one per pass
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        first = tvregdiff(x, 5, 1e-4, scale="large", ep=1e-6, dx=DT)
        second = tvregdiff(first.derivative, 3, 1e-3, scale="large", ep=1e-6, dx=DT)
    np.testing.assert_array_equal(d.x_dot, first.derivative)
    np.testing.assert_array_equal(d.x_ddot, second.derivative)
    assert not d.converged
    assert d.info["n_iter"] == 5 and d.info["n_iter2"] == 3
    assert d.info["alpha2"] == 1e-3 and d.info["ep2"] == 1e-6
    # x_hat is the integral of x_dot with the least-squares constant.
    np.testing.assert_allclose(np.diff(d.x_hat), DT * 0.5 * (d.x_dot[1:] + d.x_dot[:-1]))
    assert np.mean(d.x_hat - x) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("alpha", [1e-4, 1e-2])
def test_a_stopped_tvregdiff_measures_how_far_four_times_the_iterations_move_it(alpha):
    """The check equals an independent run with both counts times CHECK_FACTOR."""
    from debist.differentiate.tvregdiff_method import CHECK_FACTOR

    x = X + 1e-3 * np.random.default_rng(2).standard_normal(N)
    cfg = TVRegDiffConfig(alpha=alpha, ep=1e-6, iterations=5, alpha2=1e-3, iterations2=3)
    longer = replace(cfg, iterations=5 * CHECK_FACTOR, iterations2=3 * CHECK_FACTOR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        d = tvregdiff_derivatives(x, DT, config=cfg)
        long = tvregdiff_derivatives(x, DT, config=longer)
    check = d.info["check"]
    assert check["iterations"] == 20
    for key, short, ref in (("q_dot", d.x_dot, long.x_dot), ("q_ddot", d.x_ddot, long.x_ddot)):
        want = np.linalg.norm(short - ref) / np.linalg.norm(ref)
        assert check[key] == pytest.approx(want, rel=1e-6)
        assert check[key] > 0
    converged = replace(cfg, iterations=500, iterations2=500, tol=1e-3)
    assert "check" not in tvregdiff_derivatives(x, DT, config=converged).info


def test_tvregdiff_config_defaults_auto_alpha_and_the_papers_ep_in_metres():
    cfg = TVRegDiffConfig()
    # Paper: alpha = 0.01, ep = 1e-6 with q in mm; data * c -> alpha * c, ep * c**2.
    assert cfg.alpha == "auto" and cfg.ep == pytest.approx(1e-6 * 1e-6)
    assert (cfg.iterations, cfg.scale, cfg.alpha2, cfg.iterations2) == (10, "large", None, None)


def _noisy_motion(seed: int, noise: float):
    """Two switches between wells plus ringing, sampled at 100 Hz, with white sensor noise [m]."""
    t = np.arange(1500) * 0.01
    q = 0.01 * np.tanh(3.0 * np.sin(2 * np.pi * 0.2 * t)) + 1e-3 * np.exp(-((t % 5) / 0.5)) * (
        np.sin(2 * np.pi * 3.0 * t)
    )
    q_dot = np.gradient(q, 0.01)
    return t, q + noise * np.random.default_rng(seed).standard_normal(t.size), q_dot


def test_auto_alpha_takes_the_largest_alpha_where_the_residual_levels_off():
    """The choice follows the documented rule, recomputed here from fixed-alpha runs."""
    from debist.differentiate.tvregdiff_method import AUTO_GRID_MM, AUTO_SLOPE

    _, x, _ = _noisy_motion(5, 20e-6)
    auto = TVRegDiffConfig(alpha="auto", ep=1e-6, unit="mm", iterations=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        d = tvregdiff_derivatives(x, 0.01, config=auto)
        residual = []
        for a in AUTO_GRID_MM:
            fixed = tvregdiff_derivatives(x, 0.01, config=replace(auto, alpha=a, alpha2=a))
            residual.append(float(np.sqrt(np.mean((x - fixed.x_hat) ** 2))))
    slopes = np.diff(np.log(residual)) / np.diff(np.log(AUTO_GRID_MM))
    expected = AUTO_GRID_MM[int(np.flatnonzero(slopes < AUTO_SLOPE)[0])]
    assert d.info["alpha"] == pytest.approx(expected)
    got = [row["residual"] * 1e-3 for row in d.info["alpha_search"]]  # mm -> m
    assert got == pytest.approx(residual, rel=1e-9)
    # the rule is not trivially an end of the grid on this signal
    assert min(AUTO_GRID_MM) < d.info["alpha"] < max(AUTO_GRID_MM)


@pytest.mark.parametrize("noise", [5e-6, 20e-6, 50e-6])
def test_auto_alpha_velocity_error_is_near_the_best_of_the_grid(noise):
    """Against the true derivative (which the rule never sees), auto is within 1.25x the best."""
    from debist.differentiate.tvregdiff_method import AUTO_GRID_MM

    _, x, q_dot = _noisy_motion(6, noise)
    inner = slice(50, -50)
    auto = TVRegDiffConfig(alpha="auto", ep=1e-6, unit="mm", iterations=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        err = {}
        for a in AUTO_GRID_MM:
            d = tvregdiff_derivatives(x, 0.01, config=replace(auto, alpha=a, alpha2=a))
            err[a] = float(np.sqrt(np.mean((d.x_dot - q_dot)[inner] ** 2)))
        chosen = tvregdiff_derivatives(x, 0.01, config=auto)
    got = float(np.sqrt(np.mean((chosen.x_dot - q_dot)[inner] ** 2)))
    assert got <= 1.25 * min(err.values()), (got, err)


def test_tvregdiff_unit_mm_takes_the_papers_values_as_printed():
    x = X[:300] + 1e-5 * np.random.default_rng(4).standard_normal(300)  # q [m]
    in_mm = TVRegDiffConfig(alpha=0.01, ep=1e-6, unit="mm", iterations=4)
    in_m = TVRegDiffConfig(alpha=0.01 * 1e-3, ep=1e-6 * 1e-6, iterations=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        a = tvregdiff_derivatives(x, DT, config=in_mm)
        b = tvregdiff_derivatives(x, DT, config=in_m)
    np.testing.assert_allclose(a.x_dot, b.x_dot, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(a.x_ddot, b.x_ddot, rtol=1e-6, atol=1e-10)
    assert a.info["unit"] == "mm"
    with pytest.raises(WorkflowError) as err:
        TVRegDiffConfig.from_dict({"unit": "bananas"})
    assert err.value.key == "differentiate.unit"
    assert "unit" in str(err.value)
    assert "'bananas'" in str(err.value)


# ---------------------------------------------------------------- registry and configs


def test_registry_and_configs_agree():
    assert set(DIFFERENTIATORS) == set(CONFIGS) == {"tvregdiff", "spectral", "savgol"}
    with pytest.raises(TypeError):
        DIFFERENTIATORS["mine"] = savgol_derivatives  # type: ignore[index]


@pytest.mark.parametrize("method", sorted(CONFIGS))
def test_unknown_key_names_key_and_method(method):
    with pytest.raises(WorkflowError) as err:
        differentiate(X, DT, method=method, params={"alpah": 1.0})
    assert err.value.key == "differentiate.alpah"
    assert "unknown" in str(err.value)
    assert f"'{method}'" in str(err.value)


def test_unknown_method_is_a_workflow_error():
    with pytest.raises(WorkflowError) as err:
        differentiate(X, DT, method="kalman", params={})
    assert err.value.key == "differentiate.method"
    assert "'kalman'" in str(err.value)


@pytest.mark.parametrize(
    ("method", "params", "match"),
    [
        (
            "tvregdiff",
            {"alpha": -1.0},
            r"^\[differentiate\] alpha: expected a number > 0 or 'auto', got -1.0$",
        ),
        ("tvregdiff", {"iterations": 0}, r"iterations: expected an integer >= 1, got 0$"),
        ("tvregdiff", {"scale": "huge"}, r"scale: expected 'large' or 'small', got 'huge'$"),
        ("tvregdiff", {"alpha2": 0}, r"alpha2: expected a number > 0, got 0$"),
        ("tvregdiff", {"alpha": "1e-7"}, r"alpha: expected a number or 'auto', got '1e-7'$"),
        ("spectral", {"cutoff_hz": 0.0}, r"^\[differentiate\] cutoff_hz: expected a number > 0"),
        ("spectral", {"taper": 1.5}, r"taper: expected a number in \[0, 1\], got 1.5$"),
        ("spectral", {"extension": "even"}, r"extension: expected 'odd' or 'periodic', got 'even'"),
        ("savgol", {"window": 20}, r"^\[differentiate\] window: expected an odd integer, got 20$"),
        ("savgol", {"window": 5, "polyorder": 5}, r"polyorder: expected an integer < window = 5"),
        ("savgol", {"polyorder": 1}, r"polyorder: expected an integer >= 2, got 1$"),
        ("savgol", {"window": "21"}, r"window: expected an integer, got '21'$"),
        ("savgol", {"window": 21.0}, r"window: expected an integer, got 21.0$"),
    ],
)
def test_invalid_values_are_workflow_errors(method, params, match):
    with pytest.raises(WorkflowError, match=match):
        differentiate(X, DT, method=method, params=params)


def test_params_default_to_config_defaults():
    d = differentiate(X, DT, method="savgol")
    assert d.info["window"] == SavGolConfig().window
    assert SpectralConfig.from_dict({}) == SpectralConfig()
    assert TVRegDiffConfig.from_dict({"alpha": 2e-5}) == TVRegDiffConfig(alpha=2e-5)
    with pytest.raises(WorkflowError) as err:
        SavGolConfig.from_dict([("window", 5)])  # type: ignore[arg-type]
    assert "differentiate" in str(err.value)


@pytest.mark.parametrize("method", sorted(DIFFERENTIATORS))
@pytest.mark.parametrize(
    ("x", "dt", "match"),
    [
        (np.array([0.0, np.nan, 1.0, 2.0] * 10), DT, r"`x` must be finite, got nan at index 1"),
        (np.zeros(2), DT, r"`x` must have at least 3 samples, got 2"),
        (np.zeros((4, 4)), DT, r"`x` must be 1-D"),
        (X, 0.0, r"`dt` must be positive and finite, got 0.0"),
        (X, np.nan, r"`dt` must be positive and finite, got nan"),
    ],
)
def test_invalid_signal_raises(method, x, dt, match):
    with pytest.raises(ValueError, match=match):
        DIFFERENTIATORS[method](x, dt, config=CONFIGS[method]())


def test_savgol_window_longer_than_record():
    with pytest.raises(ValueError) as err:
        savgol_derivatives(np.zeros(10), DT)
    assert "`x`" in str(err.value)
    assert "`window`" in str(err.value)
    assert "21 samples" in str(err.value)
    assert "got 10" in str(err.value)


# ---------------------------------------------------------------- properties


@settings(max_examples=20, deadline=None)
@given(
    a=st.floats(-1e3, 1e3),
    b=st.floats(-1e3, 1e3),
    method=st.sampled_from(["spectral", "savgol"]),
)
def test_linear_methods_are_linear(a, b, method):
    rng = np.random.default_rng(5)
    x, y = rng.standard_normal(64), rng.standard_normal(64)
    cfg = CONFIGS[method](**({"window": 9} if method == "savgol" else {}))
    f = DIFFERENTIATORS[method]
    dx, dy, dz = f(x, DT, config=cfg), f(y, DT, config=cfg), f(a * x + b * y, DT, config=cfg)
    scale = (abs(a) + abs(b) + 1.0) * 1e-9
    for name in ("x_hat", "x_dot", "x_ddot"):
        combo = a * getattr(dx, name) + b * getattr(dy, name)
        got = getattr(dz, name)
        assert np.max(np.abs(got - combo)) <= scale * (1 + np.max(np.abs(combo)))


@settings(max_examples=10, deadline=None)
@given(c=st.floats(1e-3, 1e3))
def test_tvregdiff_method_unit_scaling(c):
    x = X[:300] + 1e-3 * np.random.default_rng(2).standard_normal(300)
    base = TVRegDiffConfig(alpha=1e-4, ep=1e-6, iterations=3)
    scaled = TVRegDiffConfig(alpha=c * 1e-4, ep=c**2 * 1e-6, iterations=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        d0 = tvregdiff_derivatives(x, DT, config=base)
        d1 = tvregdiff_derivatives(c * x, DT, config=scaled)
    np.testing.assert_allclose(d1.x_dot, c * d0.x_dot, rtol=1e-6, atol=1e-9 * c)
    np.testing.assert_allclose(d1.x_ddot, c * d0.x_ddot, rtol=1e-6, atol=1e-9 * c)


def test_a_record_shorter_than_the_savgol_window_is_refused_naming_file_and_data_set():
    """Ten samples against a window of 15: a one-line error with the file, the data set, its
    length and the window, not scipy's bare ValueError."""
    import pandas as pd

    from debist.core.errors import RigLogError
    from debist.differentiate.tables import differentiate_tables

    frame = pd.DataFrame({"t": np.arange(10) * 0.01, "q": np.linspace(0, 1e-3, 10)})
    frame.attrs["source"] = "logs/short.csv"
    with pytest.raises(RigLogError) as info:
        differentiate_tables({"short": frame}, {"method": "savgol", "window": 15})
    text = str(info.value)
    assert text.startswith("file 'logs/short.csv': data set 'short' (10 samples)")
    assert "window" in text and "15" in text
