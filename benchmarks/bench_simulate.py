"""Benchmark of the free-run engines: the compiled kernel against the NumPy reference engine.

Run from the repository root (about two minutes, most of it the NumPy engine):

    .venv/bin/python benchmarks/bench_simulate.py [--repeats 5] [--skip-plant]

Cases, each timed with both engines in this run (median of ``--repeats`` calls after one
warm-up call) with the largest difference of q between them relative to its range:

* RBF model of Eq. 37, M = 10, two inputs (h = v^2), backbone and physics prior, T_z > 0,
  4 RK4 sub-steps, 3750 samples at 10 ms (the paper's identification record);
* SINDy, degree 3 in (q, q_dot) times [1, h_1, h_2] (30 terms), 2 sub-steps, 3750 samples;
* the refinement's batch: 60 windows x 400 samples, one parameter vector per window (the
  shape of one Jacobian column block), 2 sub-steps, the inputs interpolated once (as the
  refinement does);
* a 1,000,000-sample record (RBF, 2 sub-steps): the kernel in full; the NumPy engine on the
  first 20,000 samples, scaled linearly to the whole record (it takes about 20 minutes).

The JIT compile time is measured separately, in a fresh process with an empty numba cache
and again with the cache warm. With the plant benchmark (default), the virtual rig's plant
integration is timed too (:func:`bench_rig.bench_plant`: the compiled right-hand side and
Jacobian against the NumPy reference, one 37.5 s experiment).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from debist.model.basis import RBFBasis
from debist.model.rbf import RBFModel
from debist.model.sindy import SindyModel
from debist.model.terms import PhysicsPrior
from debist.model.termtable import TableModel
from debist.simulate.freerun import prepare_inputs, simulate

DT = 0.01


def _inputs(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    base = np.stack([np.sin(2 * np.pi * 0.3 * t + 1.0), np.sin(2 * np.pi * 0.7 * t)], axis=1)
    return 1500.0 + 1000.0 * base + 50.0 * rng.standard_normal((n, 2))


def rbf_model() -> RBFModel:
    rng = np.random.default_rng(1)
    M = 10
    grid = np.linspace(-0.025, 0.025, 2001)
    prior = PhysicsPrior(
        grid, -30.0 + 3e5 * grid**2, 2.0 + 100.0 * grid**2,
        np.stack([1e-7 * (1 + 20 * grid), -1e-7 * (1 - 20 * grid)], axis=1),
    )  # fmt: skip
    backbone = {"k_1": -40.0, "k_3": 4e5, "d_v": 5.0, "F_0": 0.01, "F_c": 0.02,
                "g_0": np.array([2e-7, -2e-7]), "s_c": 0.3, "s_d": 0.5,
                "s_g": np.array([0.4, 0.6])}  # fmt: skip
    return RBFModel(
        RBFBasis.equidistant(-0.012, 0.012, M, 0.5, "clip"), "v2", 2, 1.0, 0.02, 1e-3,
        rng.normal(0, 50, M) + 400, rng.normal(0, 1, M), rng.normal(0, 1e-7, (2, M)),
        backbone, (-0.012, 0.012), prior,
    )  # fmt: skip


def sindy_model() -> SindyModel:
    """A bistable SINDy model over the whole degree-3 library: 30 terms, all nonzero."""
    rng = np.random.default_rng(2)
    exps = [(a, b, c0, c1) for a in range(4) for b in range(4 - a)
            for c0, c1 in ((0, 0), (1, 0), (0, 1))]  # fmt: skip
    exps = np.array(exps)
    # every term contributes about 1e-4 m/s^2 at q = 10 mm, q_dot = 50 mm/s, h = 2e6 V^2 ...
    size = 0.01 ** exps[:, 0] * 0.05 ** exps[:, 1] * 2e6 ** exps[:, 2:].sum(axis=1)
    coef = 1e-4 * rng.standard_normal(len(exps)) / size
    main = {(1, 0, 0, 0): 40.0, (3, 0, 0, 0): -4e5, (0, 1, 0, 0): -5.0,
            (2, 1, 0, 0): -100.0, (0, 0, 1, 0): 2e-7, (0, 0, 0, 1): -2e-7}  # fmt: skip
    for key, value in main.items():
        coef[exps.tolist().index(list(key))] = value
    names = [f"f{i}" for i in range(len(exps))]
    return SindyModel(names, coef, exps, "v2", 2, "", 0.0, 0.0, (-0.012, 0.012))


def _time(fn, repeats: int) -> tuple[float, object]:
    out = fn()  # warm-up (and the result)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def _diff(a, b) -> float:
    qa = np.concatenate([r.q for r in a])
    qb = np.concatenate([r.q for r in b])
    ok = np.isfinite(qa) & np.isfinite(qb)
    return float(np.max(np.abs(qa[ok] - qb[ok])) / np.ptp(qa[ok]))


def case(name, model, records, q0, substeps, repeats, numpy_samples=None, prepared=False):
    """Time both engines on one case and return a table row.

    With ``prepared`` the inputs are interpolated onto the RK4 grid once, outside the timed
    calls, as the refinement does for its windows; otherwise every call interpolates them,
    as a validation does.
    """
    n = sum(len(r) for r in records)
    fine = prepare_inputs(records, substeps, "bandlimited") if prepared else None

    def run(engine, recs):
        inputs = fine if prepared and recs is records else recs
        return simulate(model, inputs, DT, q0, np.zeros_like(q0), substeps=substeps,
                        engine=engine)  # fmt: skip

    t_kernel, res_k = _time(lambda: run("compiled", records), repeats)
    if numpy_samples is None:
        t_numpy, res_n = _time(lambda: run("numpy", records), max(1, repeats // 2))
        diff = _diff(res_n, res_k)
        note = ""
    else:
        part = [r[:numpy_samples] for r in records]
        t_part, res_n = _time(lambda: run("numpy", part), 1)
        t_numpy = t_part * n / sum(len(r) for r in part)
        res_kp = run("compiled", part)
        diff = _diff(res_n, res_kp)
        note = f" (NumPy: first {numpy_samples} samples, scaled)"
    return (name + note, n, t_numpy, t_kernel, diff)


def compile_times() -> tuple[float, float]:
    """Seconds of the first free run in a fresh process: empty numba cache, then warm."""
    code = (
        "import time, numpy as np; t = time.perf_counter();"
        "import sys; sys.path.insert(0, 'benchmarks'); import bench_simulate as b;"
        "from debist.simulate.freerun import simulate;"
        "simulate(b.rbf_model(), [b._inputs(50, 0)], 0.01, np.zeros(1), np.zeros(1));"
        "print(time.perf_counter() - t)"
    )
    out = []
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for _ in range(2):
            proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                  text=True, check=True, cwd=Path(__file__).parents[1])  # fmt: skip
            out.append(float(proc.stdout.strip().splitlines()[-1]))
    return out[0], out[1]


def main() -> None:
    """Run every case and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per case")
    parser.add_argument("--skip-plant", action="store_true", help="leave out the rig plant")
    args = parser.parse_args()
    rows = []
    rbf = rbf_model()
    x0 = np.array([-0.0095])
    rows.append(case("RBF M=10, 2 inputs, 4 sub-steps", rbf, [_inputs(3750, 0)], x0, 4,
                     args.repeats))  # fmt: skip
    rows.append(case("SINDy degree 3 (30 terms), 2 sub-steps", sindy_model(),
                     [_inputs(3750, 1)], x0, 2, args.repeats))  # fmt: skip
    table = rbf.table_model()
    rng = np.random.default_rng(3)
    W = 60
    weights = table.weights * (1.0 + 1e-3 * rng.standard_normal((W, table.weights.shape[1])))
    batch = TableModel(table.table, weights, np.ones(W), np.full(W, 0.02))
    windows = [_inputs(400, 10 + i) for i in range(W)]
    rows.append(case("60 windows x 400 samples, batched (inputs prepared once)", batch,
                     windows, np.linspace(-0.01, 0.01, W), 2, args.repeats,
                     prepared=True))  # fmt: skip
    rows.append(case("1,000,000-sample record, 2 sub-steps", rbf, [_inputs(1_000_000, 4)], x0, 2,
                     1, numpy_samples=20_000))  # fmt: skip
    print(f"{'case':58s} {'samples':>9s} {'NumPy [s]':>10s} {'kernel [s]':>11s} "
          f"{'us/sample':>10s} {'ratio':>7s} {'max |dq|/range':>15s}")  # fmt: skip
    for name, n, t_np, t_k, diff in rows:
        print(f"{name:58s} {n:9d} {t_np:10.3f} {t_k:11.4f} {1e6 * t_k / n:10.3f} "
              f"{t_np / t_k:6.0f}x {diff:15.2e}")  # fmt: skip
    cold, warm = compile_times()
    print(f"\nfirst free run in a fresh process: {cold:.1f} s with an empty numba cache (JIT "
          f"compile), {warm:.2f} s with the cache warm (imports included)")  # fmt: skip
    if not args.skip_plant:
        sys.path.insert(0, str(Path(__file__).parent))
        try:
            from bench_rig import bench_plant
        except ImportError:
            print("\n(rig plant: bench_rig.bench_plant not available)")
            return
        print("\nvirtual rig plant, one 37.5 s identification experiment:")
        for row in bench_plant(37.5):
            print("  " + "  ".join(str(v) for v in row))


if __name__ == "__main__":
    main()
