"""Resource preflight: settings that would exhaust memory are refused before allocating."""

from __future__ import annotations

import gzip
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core import preflight
from debist.core.errors import ResourceError, WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.identify.refine import RefineConfig, refine_model
from debist.model.sindy import SindyConfig, fit_sindy
from debist.stages.studies import StudyConfig, rbf_grid_study
from debist.validate.config import ValidateConfig
from debist.validate.freerun import DataSet, validate_model

ROOT = Path(__file__).resolve().parents[2]
#: Bytes a refused call may allocate at most (a few small arrays, no regressor).
SMALL = 5e6


@pytest.fixture
def budget(monkeypatch):
    """A fixed 4 GB budget, so that the messages do not depend on this machine's RAM."""
    monkeypatch.setenv(preflight.BUDGET_ENV, "4")
    return 4e9


def _records(n: int, n_rec: int = 1, n_in: int = 1, seed: int = 3) -> list[Record]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_rec):
        q = rng.uniform(-1.0, 1.0, n)
        qd, qdd = rng.standard_normal((2, n))
        out.append(Record(f"r{k}", q, qd, qdd, rng.uniform(0.5, 2.0, (n, n_in)), 1e-3))
    return out


def _peak(call):
    """Run ``call``; return (its exception or None, tracemalloc peak [bytes]).

    The peak, not a wall time, shows that a refusal came before the allocation.
    """
    tracemalloc.start()
    try:
        call()
        exc = None
    except Exception as e:
        exc = e
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return exc, peak


# ------------------------------------------------------------------------------ budget
def test_budget_from_the_environment_and_by_default(monkeypatch):
    monkeypatch.setenv(preflight.BUDGET_ENV, "2.5")
    assert preflight.memory_budget() == 2_500_000_000
    monkeypatch.delenv(preflight.BUDGET_ENV)
    default = preflight.memory_budget()
    assert 0 < default <= 0.5 * psutil.virtual_memory().total
    for bad in ("lots", "-1", "0", "nan"):
        monkeypatch.setenv(preflight.BUDGET_ENV, bad)
        with pytest.raises(WorkflowError) as err:
            preflight.memory_budget()
        assert f"DEBIST_MEMORY_BUDGET_GB = '{bad}'" in str(err.value)


def test_check_memory_names_setting_estimate_and_budget(budget):
    preflight.check_memory(3.9e9, "[x] y = 1", "it")  # within the budget: nothing
    with pytest.raises(ResourceError) as err:
        preflight.check_memory(4.1e9, "[x] y = 2", "it", "peak")
    assert "y = 2" in str(err.value)
    assert "about 4.1 GB" in str(err.value)
    with pytest.raises(ResourceError) as err:
        preflight.check_memory(4.1e9, "[x] y = 2", "it")
    assert "is 4 GB" in str(err.value)
    assert "DEBIST_MEMORY" in str(err.value)


# ------------------------------------------------------------------------------ identify
@pytest.mark.parametrize(
    ("section", "n_in"),
    [
        ({"M": 7}, 1),
        ({"M": 5, "rbf": ["c", "g"], "backbone": ["offset", "input_gain"], "input_map": "v"}, 2),
        ({"M": 4, "rbf": ["c", "d"], "m_q": "identify", "input_gain": [2.0, 3.0]}, 2),
        ({"M": 6, "backbone": ["coulomb", "viscous", "cubic_spring"], "T_z": 0.0}, 1),
    ],
)
def test_column_count_is_that_of_the_fit(section, n_in):
    cfg = IdentifyConfig.from_dict({"max_condition": 1e300, "min_support": 0, **section})
    _, diag = fit_rbf_model(_records(600, n_in=n_in), cfg)
    assert preflight.identify_columns(cfg, n_in)[0] == len(diag.columns)


def test_huge_M_is_refused_by_the_fit_before_allocating(budget):
    records = _records(3950)  # 3750 rows after trim = 100
    cfg = IdentifyConfig.from_dict({"M": 100000, "input_map": "v", "trim": 100})
    exc, peak = _peak(lambda: fit_rbf_model(records, cfg))
    assert isinstance(exc, ResourceError)
    assert str(exc).startswith(
        "[identify] M = 100000: the regressor of 3750 samples x 300003 columns needs about "
    )
    assert (
        "(peak, with the SVD's copies)" in str(exc) and "budget" in str(exc) and "4 GB" in str(exc)
    )
    assert peak < SMALL  # the regressor alone would be 3750 x 300003 x 8 bytes = 9 GB


def test_data_free_lower_bound_refuses_huge_M_and_passes_the_shipped_ones(budget):
    cfg = IdentifyConfig.from_dict({"M": 100000})
    p = 300003  # c, d, g of one input and the default backbone of 3 terms
    assert preflight.identify_columns(cfg, 1) == (p, 100001)
    assert preflight.identify_lower_bound(cfg, 1) >= 8 * p**2
    exc, peak = _peak(lambda: preflight.check_identify_config(cfg, 1))
    assert isinstance(exc, ResourceError)
    assert str(exc).startswith(f"[identify] M = 100000: the least squares of {p} columns")
    assert peak < 1e5
    preflight.check_identify_config(IdentifyConfig.from_dict({"M": 16, "rbf": ["c", "d", "g"]}), 2)


def test_estimate_agrees_with_the_measured_peak_of_a_real_fit():
    """tracemalloc sees 3 of the 5 regressor-sized arrays alive at the SVD (numpy's LAPACK
    copies are malloc'ed outside it): the estimate is 1.5 times its peak. Against the peak
    resident size (see debist.core.preflight) it is within 7 %."""
    records = _records(6000, n_rec=2)
    cfg = IdentifyConfig.from_dict({"M": 30, "T_z": 0.0, "max_condition": 1e300})
    estimate = preflight.identify_bytes(cfg, 1, 12000, 6000)
    exc, peak = _peak(lambda: fit_rbf_model(records, cfg))
    assert exc is None
    assert 1.2 < estimate / peak < 1.8


# ------------------------------------------------------------------------------ free runs
class _Oscillator:
    """q'' = -q - 0.1 q' + v: the smallest model the simulator accepts."""

    n_states = 2

    def initial_state(self, q0, q_dot0):
        return np.stack([q0, q_dot0], axis=-1)

    def rhs(self, x, v):
        acc = -x[:, 0] - 0.1 * x[:, 1] + v[:, 0]
        return np.stack([x[:, 1], acc], axis=1), acc

    def max_step(self):
        return np.inf


def _datasets(n: int = 1000) -> list[DataSet]:
    t = np.arange(n) * 1e-2
    q = np.sin(t)
    v = np.cos(t)[:, None]
    return [DataSet("check", "validation", t, q, np.cos(t), -q, v, "m")]


def test_huge_substeps_are_refused_naming_the_key(budget):
    cfg = ValidateConfig.from_dict({"substeps": 1_000_000_000})
    run = lambda: validate_model(_Oscillator(), "osc", _datasets(), cfg, 10.0)  # noqa: E731
    exc, peak = _peak(run)
    assert isinstance(exc, ResourceError)
    assert str(exc).startswith(
        "[validate] substeps = 1000000000: the free run of 1 record(s) of up to 1000 samples "
        "with 1000000000 RK4 sub-steps per sample needs about 32 TB"
    )
    assert peak < SMALL


def test_free_run_estimate_agrees_with_the_measured_peak():
    from debist.simulate.freerun import simulate

    model, v = _Oscillator(), [np.ones((60, 1)), np.ones((45, 1))]
    estimate = preflight.free_run_bytes([60, 45], 1, 2, 40)
    exc, peak = _peak(lambda: simulate(model, v, 1e-2, np.zeros(2), np.zeros(2), substeps=40))
    assert exc is None
    assert 0.9 < estimate / peak < 1.2


@pytest.mark.parametrize("init_samples", [100_000_000, 997, 2])
def test_init_samples_beyond_the_data_set_are_refused(init_samples):
    cfg = ValidateConfig.from_dict({"init_samples": init_samples})
    with pytest.raises(WorkflowError) as err:
        validate_model(_Oscillator(), "osc", _datasets(), cfg, 10.0)
    assert err.value.key == "validate.init_samples" and err.value.value == init_samples
    assert str(err.value).startswith(f"[validate] init_samples = {init_samples}: ")
    assert "'check'" in str(err.value)
    assert "has 1000" in str(err.value)
    table, _ = validate_model(
        _Oscillator(), "osc", _datasets(), ValidateConfig(init_samples=996), 10
    )
    assert table["n_samples"].tolist() == [4]


def test_refinement_with_huge_windows_is_refused(budget):
    records = _records(3000)
    cfg = IdentifyConfig.from_dict({"M": 4, "T_z": 0.0, "max_condition": 1e300})
    model, diag = fit_rbf_model(records, cfg)
    rcfg = RefineConfig(windows=1_000_000, length=400)
    exc, peak = _peak(lambda: refine_model(model, diag, records, cfg, rcfg))
    assert isinstance(exc, ResourceError)
    assert str(exc).startswith("[identify.refine] windows = 1000000, length = 400: the Jacob")
    assert peak < SMALL


# ------------------------------------------------------------------------- SINDy, studies
def test_sindy_library_above_the_budget_is_refused(monkeypatch):
    import pysindy  # noqa: F401  (its import would dominate the allocation peak)

    monkeypatch.setenv(preflight.BUDGET_ENV, "0.001")  # 1 MB
    (r,) = _records(5000)
    exc, peak = _peak(lambda: fit_sindy(r.q, r.q_dot, r.q_ddot, r.v, 1e-3, SindyConfig()))
    assert isinstance(exc, ResourceError)
    assert str(exc).startswith("[compare] degree = 3: the SINDy library of 5000 samples x 20")
    assert peak < SMALL


def test_grid_study_with_a_huge_M_is_refused_before_the_first_fit(budget):
    (r,) = _records(4000)
    t = np.arange(r.q.size) * r.dt
    table = pd.DataFrame({"t": t, "q": r.q, "v1": r.v[:, 0]})
    table.attrs.update(role="estimation", units={"t": "s", "q": "m", "v1": "V"})
    deriv = pd.DataFrame({"t": t, "q": r.q, "q_dot": r.q_dot, "q_ddot": r.q_ddot})
    deriv.attrs["dt"] = r.dt
    cfg = StudyConfig.from_dict({"M": [4, 100000], "sigma_n": [0.5], "free_run": False})
    with pytest.raises(ResourceError) as err:
        rbf_grid_study({"e": table}, {"e": deriv}, {"M": 4}, {}, cfg)
    assert "M = 100000" in str(err.value)
    assert "of 4000" in str(err.value)


# ------------------------------------------------------------------------------------ CLI
WORKFLOW = """
[workflow]
name = "preflight"
output_dir = "runs/preflight"

[ingest]
format = "csv"
sample_time = 1.6384e-3
q = {{ column = 1, unit = "V" }}
v1 = {{ column = 0, unit = "V" }}

[datasets.estimation]
source = "rig.csv"
role = "estimation"
slice = [0, 3000]

[datasets.check]
source = "rig.csv"
slice = [3000, 4000]

[differentiate]
method = "spectral"
cutoff_hz = 290.0
taper = 0.1

[identify]
M = {M}
sigma_n = 0.5
input_map = "v"
rbf = ["c", "d", "g"]
backbone = ["linear_spring", "cubic_spring", "viscous", "offset", "input_gain"]
T_z = 0.0
trim = 100
"""


def test_cli_refuses_huge_M_with_exit_code_2_naming_the_key(tmp_path, monkeypatch, budget):
    with gzip.open(ROOT / "data/silverbox/SNLS80mV.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()
    (tmp_path / "rig.csv").write_text("\n".join(lines[40650:44650]) + "\n")
    wf = tmp_path / "wf.toml"
    wf.write_text(WORKFLOW.format(M=4))
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for stage in ("ingest", "differentiate"):
        result = runner.invoke(app, [stage, str(wf)])
        assert result.exit_code == 0, result.output
    wf.write_text(WORKFLOW.format(M=100000))
    result = runner.invoke(app, ["identify", str(wf)])
    assert result.exit_code == 2, result.output
    assert "[identify] M = 100000" in result.output
    assert "budget" in result.output and "4 GB" in result.output


def test_a_huge_bootstrap_is_refused_naming_bootstrap_not_M(budget):
    """Where the bootstrap's replicates are what exceeds the budget, the refusal names
    ``[identify] bootstrap``; with a modest bootstrap and a huge M it names M."""
    records = _records(600)
    cfg = IdentifyConfig.from_dict({"M": 4, "T_z": 0.0, "bootstrap": 1_000_000_000})
    with pytest.raises(ResourceError) as info:
        fit_rbf_model(records, cfg)
    assert "bootstrap = 1000000000" in str(info.value)
    assert "M = 4" not in str(info.value)
    big_m = IdentifyConfig.from_dict({"M": 200_000, "T_z": 0.0, "bootstrap": 10})
    with pytest.raises(ResourceError) as err:
        preflight.check_identify(big_m, 1, 600)
    assert "M = 200000" in str(err.value)
