"""Each export of a run's model reproduces the free run the run's validate stage scored.

With default settings (band-limited inputs, ns sub-steps) the C export compiled with
``-std=c99 -Wall -Werror``, the MATLAB export in Octave and the NumPy export, each driven by
each record's logged inputs from validate's initial state, give validate's
``simulated/<record>.parquet`` to 1e-6 of the record's q range; the header's NRMSE(q) of the
free run is validate's, that of the causal per-sample step the step's own. Three runs: the
main job (Silverbox), the paper experiment and a workflow made by ``debist init``.
"""

import ctypes
import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import debist
from debist.core import artifacts
from debist.core.metrics import nrmse
from debist.export.c import C_FILES
from debist.export.matlab import MATLAB_FILE, MATLAB_FREE_RUN_FILE
from debist.export.python import PYTHON_FILE
from debist.model.rbf import RBFModel
from debist.validate.config import ValidateConfig
from debist.validate.datasets import validation_datasets
from debist.validate.freerun import by_sample_time, initial_states
from tests.conftest import invoke_cli, made_once

ROOT = Path(__file__).resolve().parents[2]
GCC = shutil.which("gcc")
OCTAVE = shutil.which("octave-cli")
#: Samples of each record the Octave free run integrates (its interpreter takes ~10 ms one).
N_OCTAVE = 200
#: Samples of each record the NumPy module integrates (~0.3 ms one); the rest by C.
N_NUMPY = 4000

pytestmark = pytest.mark.slow


@pytest.fixture(scope="session")
def silverbox_run(tmp_path_factory):
    """One run of workflows/silverbox.toml; made once for all pytest-xdist workers."""

    def make(root: Path) -> str:
        code, out = invoke_cli("run", ROOT / "workflows" / "silverbox.toml", "--out", root / "run")
        assert code == 0, out
        return ""

    folder, _ = made_once(tmp_path_factory, "silverbox", make)
    return ROOT / "workflows" / "silverbox.toml", folder / "run"


@pytest.fixture(scope="session")
def init_run(tmp_path_factory, bistable_record):
    """A workflow that ``debist init`` made from two CSV rig logs (the synthetic bistable
    record: its first 8 s estimate, the rest validates), run once for all workers."""

    def make(root: Path) -> str:
        rec, cut = bistable_record, 4000
        rng = np.random.default_rng(0)
        for name, part in (("est.csv", slice(0, cut)), ("val.csv", slice(cut, None))):
            t = rec["t"][part]
            pd.DataFrame(
                {
                    "time_s": t - t[0],
                    "laser_mm": rec["q"][part] * 1e3 + 1e-4 * rng.standard_normal(t.size),
                    "hv_left_kv": rec["v"][part, 0] * 1e-3,
                    "hv_right_kv": rec["v"][part, 1] * 1e-3,
                }
            ).to_csv(root / name, index=False)
        code, out = invoke_cli(
            "init", root / "est.csv", root / "val.csv", "--out", root / "rig.toml",
            "--q", "laser_mm", "--unit", "q=mm", "--unit", "v1=kV", "--unit", "v2=kV",
        )  # fmt: skip
        assert code == 0, out
        code, out = invoke_cli("run", root / "rig.toml", "--out", root / "run")
        assert code == 0, out
        return ""

    folder, _ = made_once(tmp_path_factory, "export-init", make)
    return folder / "rig.toml", folder / "run"


@pytest.fixture(scope="session")
def paper_run(paper_experiment_run):
    return ROOT / "workflows" / "paper-experiment.toml", paper_experiment_run[0]


RUNS = ["silverbox_run", "paper_run", "init_run"]


def records(workflow: Path, out: Path):
    """Each record of the run as validate simulated it: name, dt, inputs, x0, q_sim, q."""
    model = RBFModel.from_tree(artifacts.read_h5(out / "identify/model.h5"))
    cfg = ValidateConfig.from_dict(debist.load_workflow(workflow).section("validate"))
    tables = {p.stem: pd.read_parquet(p) for p in sorted((out / "ingest").glob("*.parquet"))}
    derivs = {p.stem: pd.read_parquet(out / "differentiate" / p.name) for p in
              sorted((out / "ingest").glob("*.parquet"))}  # fmt: skip
    for dt, group in by_sample_time(validation_datasets(tables, derivs)).items():
        q0, qd0 = initial_states(group, dt, cfg.init_samples)
        x0 = model.initial_state(q0, qd0)
        for k, ds in enumerate(group):
            sim = pd.read_parquet(out / "validate/simulated" / f"{ds.name}.parquet")
            x = np.delete(x0[k], 2) if model.T_z == 0 else x0[k]  # the exports drop z = q_dot
            yield ds.name, dt, np.ascontiguousarray(ds.v), x, sim["q_sim"].to_numpy(), ds.q


def assert_reproduces(q, q_sim, q_measured, what):
    """``q`` is validate's free run to 1e-6 of the record's q range (NaN where it diverged)."""
    tol = 1e-6 * np.ptp(q_measured)
    n = len(q)
    np.testing.assert_array_equal(np.isnan(q), np.isnan(q_sim[:n]), err_msg=what)
    ok = ~np.isnan(q)
    assert ok.sum() > 100, what  # a run that diverged at once would prove little
    err = np.max(np.abs(q[ok] - q_sim[:n][ok]))
    assert err <= tol, f"{what}: {err:.3g} off validate's free run (tolerance {tol:.3g})"


def export(workflow, out, fmt, dest):
    # the runs are shared by the pytest-xdist workers, and an export holds the run's lock
    # while it reads the run: another worker's export of the same run waits for it
    result = debist.export_model(workflow, fmt, dest=dest, output_dir=out, wait=True)
    return {p.name: p.read_text(encoding="utf-8") for p in result.files}


def header_scores(text, free, step):
    """Per record: (free run NRMSE, validate's, per-sample step NRMSE) [%] from the header."""
    pattern = (
        rf"  (\S+) \(dt = [^)]*\): {free} (\S+) % \(validate reported (\S+) %\), {step} (\S+) %"
    )
    return {m[0]: tuple(float(x) for x in m[1:]) for m in re.findall(pattern, text)}


def nrmse_table(out):
    table = pd.read_parquet(out / "validate/nrmse.parquet")
    return table[table["model"] == "rbf"].set_index("dataset")["nrmse_q"]


@pytest.mark.skipif(GCC is None, reason="no gcc on PATH")
@pytest.mark.parametrize("run", RUNS)
def test_c_export_reproduces_validates_free_run(request, tmp_path, run):
    workflow, out = request.getfixturevalue(run)
    files = export(workflow, out, "c", tmp_path / "c")
    lib = tmp_path / "libdebist_model.so"
    subprocess.run(
        [GCC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-shared", "-fPIC",
         str(tmp_path / "c" / C_FILES[1]), "-o", str(lib), "-lm"],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    dll = ctypes.CDLL(str(lib))
    p = ctypes.POINTER(ctypes.c_double)
    dll.debist_free_run.argtypes = [p, ctypes.c_size_t, ctypes.c_double, p, p]
    dll.debist_free_run.restype = ctypes.c_size_t
    dll.debist_rk4_step.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                     ctypes.c_double]  # fmt: skip

    def ptr(a):
        return a.ctypes.data_as(p)

    scores = header_scores(files[C_FILES[0]], "debist_free_run", "debist_rk4_step")
    reported = nrmse_table(out)
    cfg = ValidateConfig.from_dict(debist.load_workflow(workflow).section("validate"))
    s = slice(cfg.init_samples, None)
    seen = 0
    for name, dt, v, x0, q_sim, q_meas in records(workflow, out):
        q = np.empty(len(v))
        done = dll.debist_free_run(ptr(v), len(v), dt, ptr(x0.copy()), ptr(q))
        assert done == np.isfinite(q_sim).sum()
        assert_reproduces(q, q_sim, q_meas, f"C debist_free_run on {name}")
        x, q_step = x0.copy(), np.empty(len(v))
        q_step[0] = x[0]
        row, at = v.strides[0], v.ctypes.data  # v is C-contiguous: sample k at at + k row
        for k in range(len(v) - 1):
            dll.debist_rk4_step(x.ctypes.data, at + k * row, at + (k + 1) * row, dt)
            q_step[k + 1] = x[0]
        free, said, step = scores[name]
        assert free == said == float(f"{100 * reported[name]:.4g}")
        assert step == float(f"{100 * nrmse(q_meas[s], q_step[s]):.4g}")
        # band-limited scoring: the causal step is another scheme, beyond the tolerance
        assert np.max(np.abs(q_step - q_sim)) > 1e-5 * np.ptp(q_meas)
        seen += 1
    assert seen == len(reported) >= 2
    assert "DEBIST_SUBSTEPS 2" in files[C_FILES[0]] and "DEBIST_BANDLIMITED 1" in files[C_FILES[0]]


@pytest.mark.parametrize("run", RUNS)
def test_numpy_export_reproduces_validates_free_run(request, tmp_path, run):
    workflow, out = request.getfixturevalue(run)
    export(workflow, out, "python", tmp_path)
    spec = importlib.util.spec_from_file_location(f"debist_model_{run}", tmp_path / PYTHON_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    sys.modules.pop(spec.name, None)
    assert mod.SUBSTEPS == 2 and mod.INTERPOLATION == "bandlimited"
    for name, dt, v, x0, q_sim, q_meas in records(workflow, out):
        q, states = mod.free_run(v, dt, x0, n_out=N_NUMPY)
        assert len(q) == min(N_NUMPY, len(v)) and states.shape == (len(q), mod.N_STATES)
        assert_reproduces(q, q_sim, q_meas, f"NumPy free_run on {name}")


@pytest.mark.skipif(OCTAVE is None, reason="Octave is not installed (apt-get install octave)")
@pytest.mark.parametrize("run", RUNS)
def test_matlab_export_reproduces_validates_free_run_in_octave(request, tmp_path, run):
    workflow, out = request.getfixturevalue(run)
    files = export(workflow, out, "matlab", tmp_path)
    assert MATLAB_FILE in files and MATLAB_FREE_RUN_FILE in files
    lines = []
    cases = list(records(workflow, out))
    for k, (_, dt, v, x0, _, _) in enumerate(cases):
        np.savetxt(tmp_path / f"v{k}.txt", v, fmt="%.17g")
        x = "; ".join(repr(float(a)) for a in x0)
        lines.append(
            f"q = debist_free_run(load('v{k}.txt'), {dt!r}, [{x}], {N_OCTAVE});"
            f"fid = fopen('q{k}.txt', 'w'); fprintf(fid, '%.17g\\n', q); fclose(fid);"
        )
    (tmp_path / "drive.m").write_text("\n".join(lines) + "\n", encoding="utf-8")
    done = subprocess.run(
        [OCTAVE, "--no-gui", "--norc", "--quiet", "drive.m"],
        cwd=tmp_path, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    for k, (name, _, _, _, q_sim, q_meas) in enumerate(cases):
        q = np.loadtxt(tmp_path / f"q{k}.txt")
        assert len(q) == N_OCTAVE
        assert_reproduces(q, q_sim, q_meas, f"MATLAB debist_free_run on {name}")
