"""Shared fixtures: synthetic data from a known model, integrated independently of debist."""

from __future__ import annotations

import atexit
import os
import pickle
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from filelock import FileLock
from scipy.integrate import solve_ivp
from threadpoolctl import threadpool_limits

from debist.core.forking import usable_cores
from debist.identify.fit import Record
from debist.model.basis import RBFBasis
from debist.model.rbf import RBFModel
from debist.simulate.freerun import simulate

# debist's user cache (import lists of its modules, pint's answers) goes to a folder of this
# test session, never the user's own; the CLI runs in subprocesses inherit it.
os.environ["DEBIST_CACHE_DIR"] = tempfile.mkdtemp(prefix="debist-cache-")
atexit.register(shutil.rmtree, os.environ["DEBIST_CACHE_DIR"], ignore_errors=True)


def _blas_threads() -> int:
    """BLAS threads per pytest-xdist worker: the usable cores shared among the workers."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return max(1, usable_cores() // max(workers, 1))


# n workers x n BLAS threads would oversubscribe the cores, and OpenBLAS's waiting threads then
# cost more than they give (SysIdentPy's FROLS on a zoo member: 16.5 s with one thread per
# process, 36 s with two, two processes at once). As for debist's own batch workers
# (debist.engine.batch): in each xdist worker the BLAS libraries loaded so far are limited
# here, those loaded later and the CLI's subprocesses read the variables; a variable the user
# set keeps its value.
if "PYTEST_XDIST_WORKER" in os.environ:
    for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(_name, str(_blas_threads()))
    threadpool_limits(limits=int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")


def pytest_configure(config):
    """Compile the numba kernels once before pytest-xdist starts its workers (tests/ahead.py).

    Only in the controlling process of an xdist run, and only when numba's cache lacks a
    kernel (a fresh install): with a warm cache the workers load them as before.
    """
    if "PYTEST_XDIST_WORKER" in os.environ or not getattr(config.option, "numprocesses", 0):
        return
    from debist.simulate.warmup import kernels_cached
    from tests.ahead import compile_ahead

    if not kernels_cached() and (failed := compile_ahead(str(config.rootpath))):
        warning = pytest.PytestWarning(f"compiling the kernels ahead failed:\n{failed}")
        config.issue_config_time_warning(warning, stacklevel=2)


SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared_data(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test when the folder is absent (a user's clone)."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is absent: ../shared is only beside CI and developer checkouts")
    return path


def bistable_truth(q: np.ndarray) -> dict[str, np.ndarray]:
    """A double-well actuator in the paper's form (Eq. 37): curves as functions of q [m]."""
    k1, k3 = -40.0, 4.0e5  # [N/m], [N/m^3] per unit mass: wells at +-10 mm
    return {
        "c": k1 + k3 * q**2,
        "d": 3.0 + 200.0 * q**2,
        "g1": 2.0e-7 * (1.0 + 30.0 * q),
        "g2": -2.0e-7 * (1.0 - 30.0 * q),
    }


def _multisine(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies [Hz] and phases [rad] of :func:`excitation`'s multisine, shape (2, 6) each."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.3, 6.0, size=(2, 6)), rng.uniform(0, 2 * np.pi, size=(2, 6))


#: Drawn once: the ODE solvers of the truth records call :func:`excitation` per step.
_F, _PH = _multisine()


def excitation(t: np.ndarray) -> np.ndarray:
    """Two smooth voltage profiles [V]: switching pulses plus sub-threshold multisine."""
    f, ph = _F, _PH
    base = np.stack(
        [np.sum(np.sin(2 * np.pi * f[i] * t[:, None] + ph[i]), axis=1) for i in range(2)], axis=1
    )
    pulse = lambda t0: 0.5 * (np.tanh((t - t0) / 0.05) - np.tanh((t - t0 - 1.0) / 0.05))  # noqa: E731
    v1 = 2500.0 * (pulse(1.0) + pulse(7.0)) + 250.0 * base[:, 0]
    v2 = 2500.0 * (pulse(4.0) + pulse(10.0)) + 250.0 * base[:, 1]
    return np.abs(np.stack([v1, v2], axis=1))


@pytest.fixture(scope="session")
def bistable_record():
    """Noise-free trajectory of the truth with z = q_dot, integrated by solve_ivp (DOP853)."""
    dt = 0.002
    t = np.arange(0, 13.0, dt)

    def rhs(tt, x):
        q, qd = x
        v = excitation(np.array([tt]))[0]
        cur = bistable_truth(np.array([q]))
        qdd = (
            cur["g1"][0] * v[0] ** 2 + cur["g2"][0] * v[1] ** 2 - cur["c"][0] * q - cur["d"][0] * qd
        )
        return [qd, qdd]

    sol = solve_ivp(
        rhs, (t[0], t[-1]), [-0.01, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13
    )
    q, q_dot = sol.y
    v = excitation(t)
    cur = bistable_truth(q)
    q_ddot = cur["g1"] * v[:, 0] ** 2 + cur["g2"] * v[:, 1] ** 2 - cur["c"] * q - cur["d"] * q_dot
    return {"t": t, "dt": dt, "q": q, "q_dot": q_dot, "q_ddot": q_ddot, "v": v}


def example_rbf_model(
    T_z=0.02, outside="clip", prior=True, damping=5.0, input_map="v2", creep_rate=0.0
):
    """An RBF model with backbone, physics prior (tabulated curves) and friction lag (seeded).

    With ``creep_rate`` [1/s] > 0 it has the DE creep of Eq. 26 too (seeded weights ~100 N/m).
    """
    from debist.model.basis import RBFBasis
    from debist.model.rbf import RBFModel
    from debist.model.terms import PhysicsPrior

    rng = np.random.default_rng(1)
    M = 10
    basis = RBFBasis.equidistant(-0.012, 0.012, M, 0.5, outside)
    grid = np.linspace(-0.025, 0.025, 101)
    pri = PhysicsPrior(
        q=grid,
        c=-30.0 + 3e5 * grid**2,
        d=2.0 + 100.0 * grid**2,
        g=np.stack([1e-7 * (1 + 20 * grid), -1e-7 * (1 - 20 * grid)], axis=1),
    )
    backbone = {"k_1": -40.0, "k_3": 4e5, "d_v": damping, "F_0": 0.01, "F_c": 0.02}
    backbone["g_0"] = np.array([2e-7, -2e-7])
    if prior:
        backbone.update({"s_c": 0.3, "s_d": 0.5, "s_g": np.array([0.4, 0.6])})
    scale = 1.0 if input_map == "v2" else 1500.0  # h = v: gains per V, not per V^2
    return RBFModel(
        basis,
        input_map,
        2,
        1.0,
        T_z,
        1e-3,
        rng.normal(0, 50, M) + 400,
        rng.normal(0, 1, M),
        rng.normal(0, 1e-7, (2, M)) * scale,
        {k: (v * scale if k in ("g_0", "s_g") else v) for k, v in backbone.items()},
        (-0.012, 0.012),
        pri if prior else None,
        creep_rate,
        np.random.default_rng(3).normal(0, 20, M) + 100.0 if creep_rate > 0 else None,
    )


def with_physics_creep(model, s_k=(0.8, 1.3), rate=3.7, k_bar=0.02):
    """``model`` with the DEs' creep of Eq. 26 in the analytical form (backbone
    ``physics_creep``, scales ``s_k``): k_1 = -40 - 2e3 q, k_2 = 40 - 2e3 q [1/m] on the
    model's prior grid (a zero prior on +-40 mm without one), ``k_bar`` [N m], ``rate`` [1/s]."""

    from debist.model.terms import PhysicsPrior

    prior = model.prior
    if prior is None:
        grid = np.linspace(-0.04, 0.04, 401)
        prior = PhysicsPrior(grid, 0 * grid, 0 * grid, np.zeros((grid.size, 2)))
    k = np.stack([-40.0 - 2e3 * prior.q, 40.0 - 2e3 * prior.q], axis=1)
    prior = replace(prior, k=k, k_bar=k_bar, creep_rate=rate)
    backbone = {**model.backbone, "s_k": np.asarray(s_k, dtype=float)}
    return replace(model, prior=prior, creep_rate=rate, backbone=backbone)


#: The synthetic rig-log workflow of the CLI tests (``{alpha}``: TVRegDiff's alpha).
SYNTHETIC_WORKFLOW = """
[workflow]
name = "synthetic"
output_dir = "out"

[ingest]
time = {{ name = "time_ms", unit = "ms" }}
q = {{ name = "laser", unit = "mm" }}
v1 = {{ name = "v_left", unit = "kV" }}
v2 = {{ name = "v_right", unit = "kV" }}

[datasets.estimation]
source = "rig.csv"
role = "estimation"
slice = [0, 5000]

[datasets.check]
source = "rig.csv"
slice = [5000, 6500]

[differentiate]
method = "tvregdiff"
alpha = {alpha}
iterations = 10

[identify]
M = 8
sigma_n = 0.5
T_z = 0.0
trim = 50
max_condition = 1e10

[validate]
substeps = 2

[compare.narx]
# the NARX peer on the first 2000 of the 5000 estimation samples: these runs test the engine,
# the CLI and the stages (the peer's own tests are in tests/model/test_narx.py), and its
# search over all 5000 took 4.3 s of a 10 s run
max_samples = 2000
"""


def write_rig_csv(folder, rec) -> None:
    """Write a record as the synthetic rig log ``rig.csv`` (ms, mm, kV; seeded laser noise)."""
    import pandas as pd

    rng = np.random.default_rng(0)
    pd.DataFrame(
        {
            "time_ms": rec["t"] * 1e3,
            "laser": rec["q"] * 1e3 + 1e-4 * rng.standard_normal(rec["t"].size),
            "v_left": rec["v"][:, 0] * 1e-3,
            "v_right": rec["v"][:, 1] * 1e-3,
        }
    ).to_csv(folder / "rig.csv", index=False)


def invoke_cli(*args) -> tuple[int, str]:
    """Run the ``debist`` CLI in-process: exit code and the output (stdout and stderr)."""
    from typer.testing import CliRunner

    from debist.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.output


def made_once(tmp_path_factory, name: str, make: Callable[[Path], str]) -> tuple[Path, str]:
    """A folder made once in a test session, shared by its pytest-xdist workers; read it only.

    The first worker to ask makes it, ``make(folder)``, under a file lock in the folder the
    workers' temporary folders share; the others wait for the lock and find it made. A folder
    whose making failed is made again by the next to ask.

    Returns
    -------
    folder : pathlib.Path
        The folder (copy it to change anything in it).
    text : str
        What ``make`` returned.

    References
    ----------
    pytest-xdist documentation, "Making session-scoped fixtures execute only once"; filelock.
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # pytest-of-<user>/pytest-<n>/, shared by the session's workers
    folder, done = base / name, base / f"{name}.made"
    with FileLock(base / f"{name}.lock"):
        if not done.is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            done.with_suffix(".tmp").write_text(make(folder))
            done.with_suffix(".tmp").rename(done)
    return folder, done.read_text()


def computed_once(tmp_path_factory, name: str, compute: Callable[[], Any]) -> Any:
    """``compute()`` once in a test session for all its pytest-xdist workers (pickled).

    For a module fixture that both workers would compute: the value is pickled in a folder
    of :func:`made_once`, and every worker reads its own copy of it.
    """

    def make(folder: Path) -> str:
        (folder / "value.pickle").write_bytes(pickle.dumps(compute()))
        return ""

    folder, _ = made_once(tmp_path_factory, name, make)
    return pickle.loads((folder / "value.pickle").read_bytes())


@pytest.fixture(scope="session")
def synthetic_run(tmp_path_factory, bistable_record):
    """One complete run of the synthetic workflow (``out/``), and its run digest; copy it.

    Made once for all pytest-xdist workers (:func:`made_once`): read it, or copy it.
    """

    def make(root: Path) -> str:
        write_rig_csv(root, bistable_record)
        (root / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
        code, out = invoke_cli("run", root / "wf.toml")
        assert code == 0, out
        return out.split("run digest: ")[1].split()[0]

    return made_once(tmp_path_factory, "synthetic-run", make)


@pytest.fixture
def synthetic_copy(synthetic_run, tmp_path):
    """A private copy of the session's complete synthetic run: its folder and the run digest."""
    root, digest = synthetic_run
    shutil.copytree(root, tmp_path / "p")
    return tmp_path / "p", digest


@pytest.fixture(scope="session")
def paper_experiment_run(tmp_path_factory):
    """One complete run of workflows/paper-experiment.toml (its output folder) and what it
    printed; made once for all pytest-xdist workers (:func:`made_once`): read it only."""
    workflow = Path(__file__).resolve().parents[1] / "workflows" / "paper-experiment.toml"

    def make(root: Path) -> str:
        code, out = invoke_cli("run", workflow, "--out", root / "run")
        assert code == 0, out
        return out

    folder, out = made_once(tmp_path_factory, "paper-experiment", make)
    return folder / "run", out


# --- a backbone-only double well with known curves (stability, design, trust, report tests) ---
# f(q) = k1 q + k3 q^3 with k1 < 0: wells at +-sqrt(-k1/k3), local maximum F_MAX.

K1, K3, M_Q, D, G = -40.0, 4e5, 0.04, 0.5, 2e-8
Q_RANGE = (-0.012, 0.012)
F_MAX = 2.0 * (-K1 / 3.0) ** 1.5 / np.sqrt(K3)  # local maximum of f [N]


def double_well(d_v=D, g=G, input_map="v2", k1=K1, prior=None, s_d=0.0):
    """Backbone-only model: c = k1 + k3 q^2, d = d_v (+ s_d d_prior), g = [g, -g]."""
    M = 10
    basis = RBFBasis.equidistant(*Q_RANGE, M, 0.5)
    backbone = {"k_1": k1, "k_3": K3, "d_v": d_v, "g_0": np.array([g, -g])}
    if prior is not None:
        backbone.update({"s_c": 0.0, "s_d": s_d, "s_g": np.zeros(2)})
    zeros = np.zeros(M)
    return RBFModel(
        basis, input_map, 2, M_Q, 0.01, 1e-3, zeros, zeros, np.zeros((2, M)), backbone,
        Q_RANGE, prior,
    )  # fmt: skip


DT_LOG = 2e-3  # [s], sample time of logged_tables


def logged_tables(model, seed=0, n=3000):
    """Logs of a model's free run under random sub-threshold and switching inputs."""
    rng = np.random.default_rng(seed)
    v = np.zeros((n, 2))
    v[:, 0] = np.repeat(rng.uniform(0, 900, n // 100), 100)
    v[:, 1] = np.repeat(rng.uniform(0, 900, n // 100), 100)
    v[1000:1300, 0] = 3000.0  # switch right (0.18 N against a barrier force of 0.154 N)
    v[2000:2300, 1] = 3000.0  # and back
    sim = simulate(model, [v], DT_LOG, np.array([-0.01]), np.array([0.0]), engine="numpy")[0]
    assert not sim.diverged and sim.q.max() > 0.008 and sim.q.min() < -0.008  # both wells
    tables, derivs = {}, {}
    for name, role in (("est", "estimation"), ("val", "validation")):  # the same log twice
        t = np.arange(n) * DT_LOG
        frame = pd.DataFrame({"t": t, "q": sim.q, "v1": v[:, 0], "v2": v[:, 1]})
        frame.attrs.update(role=role, units={"q": "m", "t": "s", "v1": "V", "v2": "V"})
        tables[name] = frame
        derivs[name] = pd.DataFrame({"q_dot": sim.q_dot, "q_ddot": sim.q_ddot})
    return tables, derivs


# --- (a) Duffing oscillator q'' + 2 zeta w q' + w^2 q + k3 q^3 = u(t) (excitation tests) ---

DUFFING_W0 = 2 * np.pi * 1.0  # [rad/s]
DUFFING_ZETA = 0.05
DUFFING_K3 = 0.5 * DUFFING_W0**2  # hardening: the cubic force is half the linear one at q = 1
DUFFING_DT = 0.02  # [s]
# [s]: exp(-zeta w0 40 s) ~ 4e-6, the free transient is gone after T_SETTLE
DUFFING_T_END, DUFFING_T_SETTLE = 200.0, 40.0


def duffing_record(u, name, t_end=DUFFING_T_END):
    """Steady-state record of the Duffing oscillator driven by the force u(t), h(v) = v."""

    def rhs(t, x):
        w0, zeta, k3 = DUFFING_W0, DUFFING_ZETA, DUFFING_K3
        return [x[1], u(t) - 2 * zeta * w0 * x[1] - w0**2 * x[0] - k3 * x[0] ** 3]

    t = np.arange(0.0, t_end, DUFFING_DT)
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-7, atol=1e-9)
    keep = t >= DUFFING_T_SETTLE
    q, qd = sol.y[0][keep], sol.y[1][keep]
    f = np.array([u(tt) for tt in t[keep]])
    qdd = f - 2 * DUFFING_ZETA * DUFFING_W0 * qd - DUFFING_W0**2 * q - DUFFING_K3 * q**3
    return Record(name, q, qd, qdd, f[:, None], DUFFING_DT)


# --- a model inside the identified class, and noise-free data of it (identify, bands) ---


def truth_model(rng):
    """An RBF model with seeded random curves inside the identified class (M = 8)."""
    basis = RBFBasis.equidistant(-0.03, 0.03, 8, 0.5)
    return RBFModel(
        basis=basis,
        input_map="v2",
        n_inputs=2,
        m_q=1.0,
        T_z=0.0,
        coulomb_velocity=1e-3,
        theta_c=rng.uniform(-20, 20, 8),
        theta_d=rng.uniform(1, 3, 8),
        theta_g=rng.uniform(1e-7, 3e-7, (2, 8)) * np.array([[1.0], [-1.0]]),
        backbone={"k_1": -40.0, "k_3": 4e5, "d_v": 2.0, "g_0": np.zeros(2)},
        q_range=(-0.03, 0.03),
    )


def random_states(seed: int, n: int = 40):
    """Seeded states and inputs inside the truth's range: q [m], q_dot [m/s], v (n, 2) [V]."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.012, 0.012, n)
    q_dot = rng.uniform(-0.3, 0.3, n)
    return q, q_dot, rng.uniform(0.0, 2500.0, (n, 2))


def inside_class_record(truth, t):
    """Noise-free data of a model inside the class (solve_ivp DOP853, exact q'')."""

    def rhs(tt, x):
        return [
            x[1],
            truth.accel(np.array([x[0]]), np.array([x[1]]), excitation(np.array([tt])))[0],
        ]

    sol = solve_ivp(
        rhs, (t[0], t[-1]), [-0.01, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12
    )
    q, q_dot = sol.y
    v = excitation(t)
    return {"q": q, "q_dot": q_dot, "q_ddot": truth.accel(q, q_dot, v), "v": v, "dt": t[1] - t[0]}


@pytest.fixture(scope="session")
def _inside_class_shared(tmp_path_factory, bistable_record):
    return computed_once(
        tmp_path_factory,
        "inside-class-record",
        lambda: inside_class_record(truth_model(np.random.default_rng(2)), bistable_record["t"]),
    )


@pytest.fixture
def inside_class(_inside_class_shared):
    """``truth_model`` of seed 2 and its noise-free record on :func:`bistable_record`'s grid
    (:func:`inside_class_record`): solved once for all pytest-xdist workers, a fresh copy per
    test (change it at will)."""
    record = {
        k: np.copy(v) if isinstance(v, np.ndarray) else v for k, v in _inside_class_shared.items()
    }
    return truth_model(np.random.default_rng(2)), record


#: [identify] settings whose model class holds truth_model.
INSIDE_CLASS = {
    "M": 8,
    "q_range": [-0.03, 0.03],
    "backbone": ["linear_spring", "cubic_spring", "viscous"],
    "max_condition": 1e10,
    "min_support": 0,
}


def with_quadratic(model, g_h=(-6e-15, 5e-15)):
    """``model`` with the input force g_h,i h(v_i)^2 (backbone ``input_quadratic``): per unit
    mass [m/s^2 / V^4], at 2.5 kV -0.23 and +0.20 m/s^2, each against its gain's sign."""
    return replace(model, backbone={**model.backbone, "g_h": np.asarray(g_h, dtype=float)})


def quadratic_curve_weights(basis) -> np.ndarray:
    """Weights theta_gh (2, M) of g_h,i(q) per unit mass [m/s^2 / V^4]: -3e-15 .. -9e-15 for
    DE 1 and the mirror for DE 2, each against its gain's sign, larger near q = 0."""
    shape = 3e-15 + 6e-15 * np.exp(-((basis.xi / 0.01) ** 2))
    return np.stack([-shape, shape])


def with_quadratic_curve(model):
    """``model`` with the input force g_h,i(q) h(v_i)^2 (RBF term ``gh``)."""
    return replace(model, theta_gh=quadratic_curve_weights(model.basis))


def with_physics_quadratic(model, s_gh=(0.7, 1.3)):
    """``model`` with the backbone term ``physics_quadratic``: scales ``s_gh`` of a prior whose
    g_h,i(q) has the shape of :func:`quadratic_curve_weights`' curve (-3e-15 .. -9e-15 per unit
    mass [m/s^2 / V^4] for DE 1, the mirror for DE 2) on the model's prior grid (a zero prior
    on +-40 mm without one)."""
    from debist.model.terms import PhysicsPrior

    prior = model.prior
    if prior is None:
        grid = np.linspace(-0.04, 0.04, 401)
        prior = PhysicsPrior(grid, 0 * grid, 0 * grid, np.zeros((grid.size, 2)))
    shape = 3e-15 + 6e-15 * np.exp(-((prior.q / 0.01) ** 2))
    prior = replace(prior, gh=np.stack([-shape, shape], axis=1))
    backbone = {**model.backbone, "s_gh": np.asarray(s_gh, dtype=float)}
    return replace(model, prior=prior, backbone=backbone)


#: Break-away deflections [m] of the three Maxwell-slip elements of :func:`with_slip`.
SLIP_WIDTHS = (2e-4, 8e-4, 3.2e-3)


def with_slip(model: RBFModel, stiffness=(400.0, 150.0, 40.0)) -> RBFModel:
    """``model`` with three Maxwell-slip elements (widths :data:`SLIP_WIDTHS`, stiffnesses per
    unit mass [N/m])."""
    return replace(model, slip_width=SLIP_WIDTHS, theta_slip=np.array(stiffness))


def slip_record(truth: RBFModel, n=6500, dt=0.002):
    """Noise-free states of a model with slip elements (RK4, 4 sub-steps), exact q''."""
    t = np.arange(n) * dt
    v = excitation(t)
    run = simulate(truth, [v], dt, np.array([-0.01]), np.array([0.0]), substeps=4)[0]
    x = run.states
    q_ddot = truth.accel(x[:, 0], x[:, 1], v, x[:, 3:])
    return Record("sim", x[:, 0], x[:, 1], q_ddot, v, dt), x
