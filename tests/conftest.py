"""Shared fixtures: synthetic data from a known model, integrated independently of debist."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

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


def excitation(t: np.ndarray) -> np.ndarray:
    """Two smooth voltage profiles [V]: switching pulses plus sub-threshold multisine."""
    rng = np.random.default_rng(7)
    f = rng.uniform(0.3, 6.0, size=(2, 6))
    ph = rng.uniform(0, 2 * np.pi, size=(2, 6))
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


@pytest.fixture(scope="session")
def synthetic_run(tmp_path_factory, bistable_record):
    """One complete run of the synthetic workflow (``out/``), and its run digest; copy it."""
    root = tmp_path_factory.mktemp("synthetic-run")
    write_rig_csv(root, bistable_record)
    (root / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    code, out = invoke_cli("run", root / "wf.toml")
    assert code == 0, out
    return root, out.split("run digest: ")[1].split()[0]
