"""The exported C, MATLAB and Python model against debist's own free run (NumPy engine).

Every export gets the model as its term table and, without a run, validate's default scheme
(ns = 2 RK4 sub-steps, band-limited inputs). Driven by a seeded random input sequence (1500
samples; 400 under Octave, which interprets them), the per-sample step must agree with
``simulate(..., substeps=2, interpolation="linear")`` and the whole-record free run with
``simulate(..., substeps=2, interpolation="bandlimited")`` to 1e-9 relative on q, and the
curve tables with ``RBFModel.curves``.
"""

import ast
import ctypes
import importlib.util
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from debist.core.errors import ArtifactError, WorkflowError
from debist.export.c import C_FILES, c_sources
from debist.export.common import ExportInfo, curve_table
from debist.export.files import export_files
from debist.export.matlab import (
    MATLAB_FILE,
    MATLAB_FREE_RUN_FILE,
    MATLAB_NAME_FILE,
    matlab_source,
)
from debist.export.python import PYTHON_FILE, python_source
from debist.export.scheme import default_scheme
from debist.model.rbf import RBFModel
from debist.simulate.freerun import simulate, upsample_inputs
from debist.validate.config import ValidateConfig
from tests.conftest import (
    example_rbf_model,
    invoke_cli,
    with_physics_creep,
    with_physics_quadratic,
    with_quadratic,
    with_quadratic_curve,
    write_rig_csv,
)

DT = 0.01
N = 1500
#: Samples of the whole-record free run compared with the band-limited reference.
N_FREE = 600
#: The scheme of every export without a run: validate's defaults.
NS = ValidateConfig().substeps
CC = shutil.which("cc")
OCTAVE = shutil.which("octave-cli") or shutil.which("octave")
#: Steps of the Octave free run (about 4 ms a step in its interpreter).
N_OCTAVE = 400


def rbf_model(T_z=0.02, prior=True, outside="clip", input_map="v2"):
    """The shared example model (conftest) with the arguments in this file's order."""
    return example_rbf_model(T_z, outside, prior, input_map=input_map)


def random_inputs(seed, n=N, level=1500.0):
    """Seeded random inputs [V]: a random walk around ``level`` with white jitter."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0, 15.0, (n, 2)), axis=0)
    return np.clip(level + walk + rng.normal(0, 30.0, (n, 2)), 0.0, 3000.0)


def reference(model, v, q0=0.004, q_dot0=0.0, interpolation="linear"):
    """debist's free run in the exports' default scheme, inputs as ``interpolation``."""
    (res,) = simulate(
        model, [v], DT, np.array([q0]), np.array([q_dot0]),
        substeps=NS, interpolation=interpolation, engine="numpy",
    )  # fmt: skip
    assert not res.diverged
    return res.q


def assert_close_q(q, ref):
    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(q, ref, rtol=1e-9, atol=1e-9 * scale)


_FREE_RUNS: dict = {}


def free_run(tmp_path_factory, key):
    """The model, its inputs and debist's free run: the NumPy reference is slow, so it is run
    once a session for all pytest-xdist workers (:func:`tests.conftest.computed_once`)."""
    from tests.conftest import computed_once

    def compute():
        model = MODELS[key]()
        v = random_inputs(3)
        return model, v, reference(model, v)

    if key not in _FREE_RUNS:
        name = f"export-free-run-{list(MODELS).index(key)}"
        _FREE_RUNS[key] = computed_once(tmp_path_factory, name, compute)
    return _FREE_RUNS[key]


#: Models whose whole-record free run (band-limited inputs) is checked: the interpolation is
#: the same code for every model, the sub-steps with lag, creep, slip, inertia and h = v.
BAND_KEYS = ["lag+prior", "creep+slip+inertia", "T_z=0+slip", "zero-outside,h=v"]


def band_run(tmp_path_factory, key):
    """The model, the first N_FREE inputs and debist's free run of them with band-limited
    inputs (validate's default scheme); once a session for all workers."""
    from tests.conftest import computed_once

    def compute():
        model = MODELS[key]()
        v = random_inputs(3)[:N_FREE]
        return model, v, reference(model, v, interpolation="bandlimited")

    name = f"export-band-run-{list(MODELS).index(key)}"
    return computed_once(tmp_path_factory, name, compute)


def with_slip(model, widths=(3e-5, 1e-4, 4e-4), stiffness=(400.0, 150.0, 40.0)):
    """``model`` with three Maxwell-slip elements (break-away deflections ``widths`` [m])."""
    return replace(model, slip_width=widths, theta_slip=np.array(stiffness))


def with_inertia(model, theta=(2.0, 900.0)):
    """``model`` with the position-dependent mass m(q) = m_q + 2 q + 900 q^2 (inertia terms)."""
    return replace(model, theta_inertia=np.array(theta))


MODELS = {
    "lag+prior": lambda: rbf_model(),
    "T_z=0": lambda: rbf_model(T_z=0.0, prior=False),
    "zero-outside,h=v": lambda: rbf_model(outside="zero", input_map="v"),
    "creep+slip": lambda: with_slip(example_rbf_model(creep_rate=3.7)),
    "T_z=0+slip": lambda: with_slip(rbf_model(T_z=0.0, prior=False)),
    "creep+slip+inertia": lambda: with_inertia(with_slip(example_rbf_model(creep_rate=3.7))),
    "T_z=0+inertia": lambda: with_inertia(rbf_model(T_z=0.0, prior=False)),
    "physics_creep+slip": lambda: with_physics_creep(with_slip(example_rbf_model())),
    "input_quadratic": lambda: with_quadratic(rbf_model()),
    "gh": lambda: with_quadratic_curve(rbf_model()),
    "physics_quadratic": lambda: with_physics_quadratic(rbf_model(), s_gh=(4.0, 6.0)),
}


def n_states(model):
    """States of the exported model: [q, q_dot], z with T_z > 0, creep and slip states."""
    extra = (model.basis.M if model.has_creep else 0) + len(model.slip_width)
    extra += model.n_inputs if model.has_physics_creep else 0
    return (3 if model.T_z > 0 else 2) + extra


def load_python(tmp_path, model, info=None):
    files = python_source(model, info)
    path = tmp_path / PYTHON_FILE
    path.write_text(files[PYTHON_FILE], encoding="utf-8")
    name = f"debist_model_{abs(hash(str(tmp_path)))}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules.pop(name, None)
    return module


def build_c(tmp_path, model, info=None):
    for name, text in c_sources(model, info).items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    lib = tmp_path / "libdebist_model.so"
    cmd = [CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-shared", "-fPIC"]
    subprocess.run(
        [*cmd, str(tmp_path / C_FILES[1]), "-o", str(lib), "-lm"],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    dll = ctypes.CDLL(str(lib))
    arr = ctypes.POINTER(ctypes.c_double)
    dll.debist_rk4_step.argtypes = [arr, arr, arr, ctypes.c_double]
    dll.debist_free_run.argtypes = [arr, ctypes.c_size_t, ctypes.c_double, arr, arr]
    dll.debist_free_run.restype = ctypes.c_size_t
    dll.debist_deriv.argtypes = [arr, arr, arr]
    dll.debist_curves.argtypes = [ctypes.c_double, arr]
    return dll


def ptr(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@pytest.mark.parametrize("key", list(MODELS))
def test_python_export_matches_free_run(tmp_path, tmp_path_factory, key):
    model, v, ref = free_run(tmp_path_factory, key)
    mod = load_python(tmp_path, model)
    assert n_states(model) == mod.N_STATES
    x = mod.initial_state(0.004, 0.0)
    q = np.empty(N)
    q[0] = x[0]
    states = [x]
    for k in range(N - 1):
        x = mod.rk4_step(x, v[k], v[k + 1], DT)
        q[k + 1] = x[0]
        states.append(x)
    assert np.ptp(ref) > 1e-3  # the run moves (a trivial trajectory would prove little)
    assert_close_q(q, ref)
    if model.has_slip:  # every element both sticks and slips along the run, and never passes
        delta = np.array(states)[:, -len(model.slip_width) :]
        width = np.array(model.slip_width)
        assert np.all(np.abs(delta) <= width)
        assert np.all(np.mean(np.abs(delta) == width, axis=0) > 0.02)
        assert np.all(np.mean(np.abs(delta) < width, axis=0) > 0.02)


@pytest.mark.skipif(CC is None, reason="no C compiler (cc) on PATH")
@pytest.mark.parametrize("key", list(MODELS))
def test_c_export_matches_free_run(tmp_path, tmp_path_factory, key):
    model, v, ref = free_run(tmp_path_factory, key)
    dll = build_c(tmp_path, model)
    x = np.zeros(n_states(model))
    x[0] = 0.004
    q = np.empty(N)
    q[0] = x[0]
    for k in range(N - 1):
        v0, v1 = np.ascontiguousarray(v[k]), np.ascontiguousarray(v[k + 1])
        dll.debist_rk4_step(ptr(x), ptr(v0), ptr(v1), DT)
        q[k + 1] = x[0]
    assert np.ptp(ref) > 1e-3
    assert_close_q(q, ref)


@pytest.mark.parametrize("key", BAND_KEYS)
def test_whole_record_free_runs_match_bandlimited_free_run(tmp_path, tmp_path_factory, key):
    """free_run (NumPy) and debist_free_run (C): validate's scheme, band-limited inputs."""
    model, v, ref = band_run(tmp_path_factory, key)
    x0 = np.zeros(n_states(model))
    x0[0] = 0.004
    mod = load_python(tmp_path, model)
    q, states = mod.free_run(v, DT, x0)
    assert states.shape == (N_FREE, n_states(model)) and np.array_equal(states[:, 0], q)
    assert np.ptp(ref) > 1e-3
    assert_close_q(q, ref)
    # the causal step is another scheme: its run differs by far more than rounding
    x, q_step = x0, [x0[0]]
    for k in range(N_FREE - 1):
        x = mod.rk4_step(x, v[k], v[k + 1], DT)
        q_step.append(x[0])
    assert np.max(np.abs(np.array(q_step) - ref)) > 1e-6 * np.ptp(ref)
    if CC is not None:
        dll = build_c(tmp_path, model)
        q_c, vv = np.empty(N_FREE), np.ascontiguousarray(v)
        assert dll.debist_free_run(ptr(vv), N_FREE, DT, ptr(x0.copy()), ptr(q_c)) == N_FREE
        assert_close_q(q_c, ref)


@pytest.mark.parametrize("key", ["creep+slip", "T_z=0+inertia"])
def test_linear_scheme_free_run_is_the_step(tmp_path, tmp_path_factory, key):
    """With validate's linear interpolation the whole-record free run is the scored run and
    the per-sample step's (NumPy and C, both against simulate(..., "linear"))."""
    model, v, ref = free_run(tmp_path_factory, key)
    scheme = default_scheme(model, ValidateConfig.from_dict({"input_interpolation": "linear"}))
    x0 = np.zeros(n_states(model))
    x0[0] = 0.004
    path = tmp_path / PYTHON_FILE
    path.write_text(python_source(model, scheme=scheme)[PYTHON_FILE], encoding="utf-8")
    spec = importlib.util.spec_from_file_location(f"linear_{abs(hash(str(tmp_path)))}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.INTERPOLATION == "linear"
    assert_close_q(mod.free_run(v, DT, x0)[0], ref)
    if CC is not None:
        for name, text in c_sources(model, scheme=scheme).items():
            (tmp_path / name).write_text(text, encoding="utf-8")
        assert "#define DEBIST_BANDLIMITED 0" in (tmp_path / C_FILES[0]).read_text()
        assert "static const double phases" not in (tmp_path / C_FILES[1]).read_text()
        lib = tmp_path / "liblinear.so"
        subprocess.run(
            [CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-shared", "-fPIC",
             str(tmp_path / C_FILES[1]), "-o", str(lib), "-lm"], check=True, capture_output=True,
        )  # fmt: skip
        dll = ctypes.CDLL(str(lib))
        arr = ctypes.POINTER(ctypes.c_double)
        dll.debist_free_run.argtypes = [arr, ctypes.c_size_t, ctypes.c_double, arr, arr]
        dll.debist_free_run.restype = ctypes.c_size_t
        q, vv = np.empty(N), np.ascontiguousarray(v)
        assert dll.debist_free_run(ptr(vv), N, DT, ptr(x0.copy()), ptr(q)) == N
        assert_close_q(q, ref)


@pytest.mark.parametrize("n", [1, 2, 5, 12, 33, 40, 300])
@pytest.mark.parametrize("substeps", [1, 2, 3])
def test_exported_interpolation_is_validates(tmp_path, n, substeps):
    """The NumPy export's fine input grid is upsample_inputs' (band-limited and linear)."""
    model = rbf_model(T_z=0.0, prior=False)
    v = np.random.default_rng(n).normal(1500.0, 300.0, (n, 2))
    for method in ("bandlimited", "linear"):
        cfg = ValidateConfig.from_dict({"substeps": substeps, "input_interpolation": method})
        files = python_source(model, scheme=default_scheme(model, cfg))
        (tmp_path / method).mkdir(exist_ok=True)
        path = tmp_path / method / PYTHON_FILE
        path.write_text(files[PYTHON_FILE], encoding="utf-8")
        spec = importlib.util.spec_from_file_location(f"fine_{method}_{n}_{substeps}", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        want = upsample_inputs(v, 2 * substeps, method)
        np.testing.assert_allclose(mod.fine_inputs(v), want, rtol=1e-13, atol=1e-12)


@pytest.mark.skipif(CC is None, reason="no C compiler (cc) on PATH")
def test_c_free_run_stops_at_the_divergence_bound(tmp_path):
    """Past |q| > q_limit the run is NaN from that sample on and the count says where."""
    model = rbf_model()
    v = np.ascontiguousarray(random_inputs(3)[:N_FREE])

    def run(q_limit):
        (res,) = simulate(
            model, [v], DT, np.array([0.0]), np.array([0.0]),
            substeps=NS, q_limit=q_limit, engine="numpy",
        )  # fmt: skip
        return res

    free = np.abs(run(np.inf).q)
    half = N_FREE // 2
    q_limit = 0.5 * (free[:half].max() + free[half:].max())  # first crossed in the second half
    assert free[:half].max() < q_limit < free[half:].max()
    ref = run(q_limit)
    assert ref.diverged and half < ref.diverged_at < N_FREE
    scheme = default_scheme(model, ValidateConfig.from_dict({"q_limit": q_limit}))
    for name, text in c_sources(model, scheme=scheme).items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    lib = tmp_path / "lib.so"
    subprocess.run(
        [CC, "-std=c99", "-Wall", "-Werror", "-shared", "-fPIC", str(tmp_path / C_FILES[1]),
         "-o", str(lib), "-lm"], check=True, capture_output=True,
    )  # fmt: skip
    dll = ctypes.CDLL(str(lib))
    arr = ctypes.POINTER(ctypes.c_double)
    dll.debist_free_run.argtypes = [arr, ctypes.c_size_t, ctypes.c_double, arr, arr]
    dll.debist_free_run.restype = ctypes.c_size_t
    q, x0 = np.empty(N_FREE), np.zeros(3)
    assert dll.debist_free_run(ptr(v), N_FREE, DT, ptr(x0), ptr(q)) == ref.diverged_at
    assert np.isnan(q[ref.diverged_at :]).all()
    assert_close_q(q[: ref.diverged_at], ref.q[: ref.diverged_at])


@pytest.mark.skipif(CC is None, reason="no C compiler (cc) on PATH")
def test_c_deriv_and_curves_match_model(tmp_path):
    model = rbf_model()
    dll = build_c(tmp_path, model)
    rng = np.random.default_rng(5)
    tm = model.table_model()
    for _ in range(20):
        x = np.array([rng.uniform(-0.02, 0.02), rng.normal(0, 0.1), rng.normal(0, 0.1)])
        v = rng.uniform(0, 3000, 2)
        h = v * v
        dx = np.empty(3)
        dll.debist_deriv(ptr(x), ptr(h), ptr(dx))
        want, _ = tm.rhs(x[None, :], v[None, :])
        np.testing.assert_allclose(dx, want[0], rtol=1e-12, atol=1e-12 * np.abs(want).max())
    q, names, values = curve_table(model)
    mid = 0.5 * (q[:-1] + q[1:])
    out = np.empty(len(names))
    for qq in [*q[::17], *mid[::13], q[0] - 1.0, q[-1] + 1.0]:
        dll.debist_curves(qq, ptr(out))
        want = [np.interp(qq, q, row) for row in values]
        np.testing.assert_allclose(out, want, rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize("key", ["creep+slip+inertia", "T_z=0+inertia"])
def test_inertia_deriv_matches_table_model(tmp_path, key):
    """The exports' state derivative with a mass m(q): the NumPy model's (TableModel.rhs)."""
    model = MODELS[key]()
    tm = model.table_model()
    assert tm.table.has_inertia
    mod = load_python(tmp_path, model)
    dll = build_c(tmp_path, model) if CC is not None else None
    rng = np.random.default_rng(11)
    n_x = n_states(model)
    for _ in range(20):
        x = np.concatenate([[rng.uniform(-0.02, 0.02)], rng.normal(0, 0.3, n_x - 1)])
        x[n_x - len(model.slip_width) :] *= 1e-3  # slip deflections about their widths
        v = rng.uniform(0, 3000, 2)
        if model.T_z > 0:
            want, _ = tm.rhs(x[None, :], v[None, :])
        else:  # the table model keeps z = q_dot where T_z = 0; the exports drop it
            want, _ = tm.rhs(np.insert(x, 2, x[1])[None, :], v[None, :])
            want = np.delete(want, 2, axis=1)
        tol = {"rtol": 1e-12, "atol": 1e-12 * np.abs(want).max()}
        np.testing.assert_allclose(mod.deriv(x, mod.map_inputs(v)), want[0], **tol)
        if dll is not None:
            h, dx = v * v, np.empty(n_x)
            dll.debist_deriv(ptr(x), ptr(h), ptr(dx))
            np.testing.assert_allclose(dx, want[0], **tol)
    # the mass law m(q) = m_q + sum_a mu_a q^a is in every file's head, with its coefficients
    files = {**c_sources(model), **python_source(model), **matlab_source(model)}
    for name in (*C_FILES, PYTHON_FILE, MATLAB_FILE):
        head = files[name][:3000]
        assert "m(q) = m_q + sum_a mu_a q^a" in head and "mu_1 = 2.0, mu_2 = 900.0" in head
    plain = {**c_sources(rbf_model()), **python_source(rbf_model())}
    assert not any("m(q)" in text or "S_ACC" in text for text in plain.values())


def run_octave(folder, v, q0, dt, n_x, q_curves=()):
    """Drive the exported debist_model.m in Octave; return q of the free run and curve rows."""
    np.savetxt(folder / "v.txt", v, fmt="%.17g")
    np.savetxt(folder / "qc.txt", [*q_curves, 0.0], fmt="%.17g")  # never an empty file
    x0 = ", ".join(repr(x) for x in [q0] + [0.0] * (n_x - 1))
    (folder / "drive.m").write_text(
        f"""v = load('v.txt'); x = [{x0}]'; n = size(v, 1); q = zeros(n, 1); q(1) = x(1);
for k = 1:n - 1
  x = debist_model(x, v(k, :)', v(k + 1, :)', {dt!r}); q(k + 1) = x(1);
end
fid = fopen('q.txt', 'w'); fprintf(fid, '%.17g\\n', q); fclose(fid);
qc = load('qc.txt'); fid = fopen('curves.txt', 'w');
for k = 1:numel(qc) - 1
  [~, c] = debist_model([qc(k); zeros({n_x - 1}, 1)], v(1, :)', v(1, :)', 0.0);
  fprintf(fid, '%.17g ', c); fprintf(fid, '\\n');
end
fclose(fid);
""",
        encoding="utf-8",
    )
    done = subprocess.run(
        [OCTAVE, "--no-gui", "--norc", "--quiet", "drive.m"],
        cwd=folder, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    curves = np.loadtxt(folder / "curves.txt", ndmin=2) if len(q_curves) else None
    return np.loadtxt(folder / "q.txt"), curves


@pytest.mark.skipif(OCTAVE is None, reason="Octave is not installed (apt-get install octave)")
@pytest.mark.parametrize("key", list(MODELS))
@pytest.mark.slow
def test_matlab_export_matches_free_run_in_octave(tmp_path, tmp_path_factory, key):
    model, v, ref = free_run(tmp_path_factory, key)
    (tmp_path / MATLAB_FILE).write_text(matlab_source(model)[MATLAB_FILE], encoding="utf-8")
    q_grid, names, values = curve_table(model)
    probes = [q_grid[0] - 1.0, *q_grid[::37], 0.5 * (q_grid[3] + q_grid[4]), q_grid[-1] + 1.0]
    q, curves = run_octave(tmp_path, v[:N_OCTAVE], 0.004, DT, n_states(model), probes)
    assert np.ptp(ref[:N_OCTAVE]) > 1e-3
    assert_close_q(q, ref[:N_OCTAVE])
    want = np.array([[np.interp(p, q_grid, row) for row in values] for p in probes])
    np.testing.assert_allclose(curves, want, rtol=1e-13, atol=1e-300)
    assert len(names) == curves.shape[1]


@pytest.mark.skipif(OCTAVE is None, reason="Octave is not installed (apt-get install octave)")
@pytest.mark.slow
def test_matlab_free_run_in_octave_both_interpolations(tmp_path, tmp_path_factory):
    """debist_free_run.m: the band-limited and the linear scheme, against simulate()."""
    n_out, key = 200, "creep+slip+inertia"
    runs = {
        "bandlimited": band_run(tmp_path_factory, key),
        "linear": free_run(tmp_path_factory, key),
    }
    for method, (model, v, ref) in runs.items():
        folder = tmp_path / method
        folder.mkdir()
        cfg = ValidateConfig.from_dict({"input_interpolation": method})
        for name, text in matlab_source(model, scheme=default_scheme(model, cfg)).items():
            (folder / name).write_text(text, encoding="utf-8")
        np.savetxt(folder / "v.txt", v, fmt="%.17g")
        x0 = "; ".join(repr(x) for x in [0.004] + [0.0] * (n_states(model) - 1))
        (folder / "drive.m").write_text(
            f"[q, x] = debist_free_run(load('v.txt'), {DT!r}, [{x0}], {n_out});\n"
            "fid = fopen('q.txt', 'w'); fprintf(fid, '%.17g\\n', q); fclose(fid);\n"
            f"assert(isequal(size(x), [{n_out}, {n_states(model)}]));\n",
            encoding="utf-8",
        )
        done = subprocess.run(
            [OCTAVE, "--no-gui", "--norc", "--quiet", "drive.m"],
            cwd=folder, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        assert_close_q(np.loadtxt(folder / "q.txt"), ref[:n_out])


def test_matlab_file_is_fixed_size_code_for_simulink():
    model = rbf_model()
    info = ExportInfo(workflow="proto-7", run_digest="ef" * 32, identify_manifest="01" * 32)
    text = matlab_source(model, info)[MATLAB_FILE]
    assert text.startswith("function [x_next, curves] = debist_model(x, v0, v1, dt)\n")
    local = re.findall(r"^function .*?(\w+)\(", text, flags=re.M)
    assert local == [
        "debist_model", "map_inputs", "rk4_substep", "deriv", "interp_held", "lookup_curves"
    ]  # fmt: skip
    assert text.count("\nend\n") == len(local)  # every function closed: one file, one style
    free = matlab_source(model, info)[MATLAB_FREE_RUN_FILE]
    local = re.findall(r"^function .*?(\w+)\(", free, flags=re.M)
    assert local == [
        "debist_free_run", "fine_inputs", "map_inputs", "rk4_substep", "deriv", "interp_held"
    ]  # fmt: skip
    assert free.count("\nend\n") == len(local)
    for needle in ("ef" * 32, "01" * 32, "[-0.012, 0.012] m", "q [m]", "v [V]", "dt [s]"):
        assert needle in text
    # nothing code generation refuses or a Simulink block cannot size at compile time
    inertia = matlab_source(MODELS["creep+slip+inertia"]())[MATLAB_FILE]
    for file in (text, inertia):
        code = "\n".join(ln for ln in file.splitlines() if not ln.lstrip().startswith("%"))
        for banned in ("{", "}", "persistent", "containers.Map", "global", "eval(", "cell(", "'"):
            assert banned not in code, banned  # no cells, state, maps or char arrays (strings)
    weights = re.search(r"weights = \[ \.\.\.\n(.*?)\];", text, flags=re.S).group(1)
    got = [float(w) for w in weights.replace("...", "").split(",")]
    assert got == model.table_model().weights[0].tolist()  # round-trip literals
    # T_z = 0: two states and no friction-state line; no prior: no table branch
    plain = matlab_source(rbf_model(T_z=0.0, prior=False))[MATLAB_FILE]
    assert "dx(3)" not in plain and "s = x(2);" in plain and "tables(" not in plain
    assert "dx(3) = (x(2) - s) / (0.02);" in text


def test_python_curves_match_model(tmp_path):
    model = rbf_model()
    mod = load_python(tmp_path, model)
    grid = np.linspace(*model.q_range, 201)
    cur = model.curves(grid)
    got = np.array([mod.curves(qq) for qq in grid])
    assert mod.CURVE_NAMES == ["restoring", "d", "g1", "g2"]
    np.testing.assert_allclose(got[:, 0], cur["cq"] + model.backbone["F_0"], rtol=1e-12)
    np.testing.assert_allclose(got[:, 1], cur["d"], rtol=1e-12)
    np.testing.assert_allclose(got[:, 2:], cur["g"], rtol=1e-12)


def test_header_states_provenance_and_range():
    model = rbf_model()
    info = ExportInfo(
        workflow="proto-7",
        run_digest="ab" * 32,
        identify_manifest="cd" * 32,
        identified={"restoring": [[-0.011, 0.0095]]},
        version="9.9.9",
    )
    files = {**c_sources(model, info), **python_source(model, info), **matlab_source(model, info)}
    assert set(files) == {
        *C_FILES, PYTHON_FILE, MATLAB_FILE, MATLAB_FREE_RUN_FILE, MATLAB_NAME_FILE
    }  # fmt: skip
    # the workflow's name is free text: a string literal, never in a comment
    assert 'const char DEBIST_WORKFLOW[] = "proto-7";' in files[C_FILES[1]]
    assert "WORKFLOW = 'proto-7'" in files[PYTHON_FILE]
    assert "name = 'proto-7';" in files[MATLAB_NAME_FILE]
    for text in (files[f] for f in (*C_FILES, PYTHON_FILE, MATLAB_FILE)):
        head = text[:5000]
        for needle in ("ab" * 32, "cd" * 32, "debist 9.9.9", "[-0.012, 0.012]"):
            assert needle in head
        assert "restoring" in head and "[-0.011, 0.0095]" in head
        assert "q [m]" in head and "v [V]" in head and "[s]" in head
    assert "#define DEBIST_N_STATES 3" in files[C_FILES[0]]
    assert "#define DEBIST_N_STATES 2" in c_sources(rbf_model(T_z=0.0))[C_FILES[0]]
    assert "digest: n/a" in c_sources(model)[C_FILES[0]]


def test_header_states_scheme_and_one_unit_system():
    """The scheme (ns, interpolation, which entry is scored) and units consistent with q's."""
    from debist.export.scheme import Scheme

    model = replace(rbf_model(), m_q=0.05)  # a mass [kg] (the example's m_q is 1)
    head = c_sources(model)[C_FILES[0]][:5000]
    assert "ns = 2 classical RK4 sub-steps" in head and "band-limited" in head
    assert "debist_rk4_step (one sample, causal)" in head and "NOT the scored scheme" in head
    assert "NRMSE(q) on the run's records: n/a" in head
    assert "m_q = 0.05 [kg], the terms are forces [N]" in head
    volts = Scheme(3, "linear", 0.5, q_unit="V")
    head = c_sources(model, scheme=volts)[C_FILES[0]][:5000]
    assert "ns = 3" in head and "NOT the scored" not in head and "|q| > 0.5 V" in head
    assert "q [V], q_dot [V/s]" in head and "forces [M V/s^2]" in head
    assert "[N]" not in head and "[kg]" not in head and "[-0.012, 0.012] V" in head
    assert "#define DEBIST_SUBSTEPS 3" in head and "#define DEBIST_BANDLIMITED 0" in head
    unit_mass = replace(model, m_q=1.0)
    text = python_source(unit_mass, scheme=volts)[PYTHON_FILE][:5000]
    assert "m_q = 1 [1]: per unit mass, the terms are accelerations [V/s^2]" in text
    assert "SUBSTEPS = 3" in text and "INTERPOLATION = 'linear'" in text


def test_header_gives_q_in_the_report_unit_too():
    """The code keeps q's unit; every q number of the header is also in the report unit."""
    from debist.export.scheme import Scheme

    model = rbf_model()  # q_range [-0.012, 0.012] m
    info = ExportInfo(workflow="w", identified={"restoring": [[-0.011, 0.0095]], "d": []})
    cases = [
        (Scheme(2, "linear", 0.03), "m", "([-12, 12] mm)", "([-11, 9.5] mm)", "0.03 m (30 mm)"),
        (Scheme(2, "linear", 0.03, report_unit="um"), "m", "([-12000, 12000] um)",
         "([-11000, 9500] um)", "0.03 m (30000 um)"),
        (Scheme(2, "linear", 0.03, q_unit="V", report_unit="mV"), "V", "([-12, 12] mV)",
         "([-11, 9.5] mV)", "0.03 V (30 mV)"),
    ]  # fmt: skip
    for scheme, u, q_range, spans, limit in cases:
        files = {
            **c_sources(model, info, scheme=scheme),
            **python_source(model, info, scheme=scheme),
            **matlab_source(model, info, scheme=scheme),
        }
        for name in (*C_FILES, PYTHON_FILE, MATLAB_FILE):
            head = files[name][:6000]
            assert f"[-0.012, 0.012] {u} {q_range};" in head, name
            assert f"[-0.011, 0.0095] {u} {spans}" in head, name
            assert f"|q| > {limit} (the rest" in head and "identified on q in: none\n" in head
    # in q's own unit already: nothing twice
    plain = c_sources(model, info, scheme=Scheme(2, "linear", 0.03, report_unit="m"))
    head = plain[C_FILES[0]][:6000]
    assert "[-0.012, 0.012] m;" in head and "mm" not in head


def test_export_files_and_errors():
    model = rbf_model()
    assert set(export_files(model, "c")) == set(C_FILES)
    assert set(export_files(model, "python")) == {PYTHON_FILE}
    assert set(export_files(model, "matlab")) == {
        MATLAB_FILE, MATLAB_FREE_RUN_FILE, MATLAB_NAME_FILE
    }  # fmt: skip
    with pytest.raises(WorkflowError) as err:
        export_files(model, "fortran")
    assert "fortran" in str(err.value)
    bad = rbf_model(T_z=0.0)
    object.__setattr__(bad, "q_range", (0.0, 0.0))
    with pytest.raises(ArtifactError) as err:
        c_sources(bad)
    assert "q_range" in str(err.value)
    nan = rbf_model()
    nan.theta_c[0] = np.nan
    with pytest.raises(ArtifactError) as err:
        python_source(nan)
    assert "NaN" in str(err.value)


WORKFLOW = """
[workflow]
name = "export-check"
output_dir = "out"

[ingest]
time = { name = "time_ms", unit = "ms" }
q = { name = "laser", unit = "mm" }
v1 = { name = "v_left", unit = "kV" }
v2 = { name = "v_right", unit = "kV" }

[datasets.estimation]
source = "rig.csv"
role = "estimation"
slice = [0, 5000]

[differentiate]
method = "tvregdiff"
alpha = 1e-6
iterations = 10

[identify]
M = 8
sigma_n = 0.5
T_z = 0.0
trim = 50
max_condition = 1e10
"""


@pytest.mark.slow
def test_cli_export_needs_identify_and_never_overwrites(tmp_path, bistable_record):
    import pandas as pd
    from typer.testing import CliRunner

    from debist.cli import app
    from debist.core import artifacts

    def invoke(*args):
        result = CliRunner().invoke(app, [str(a) for a in args])
        return result.exit_code, result.output

    write_rig_csv(tmp_path, bistable_record)
    wf = tmp_path / "wf.toml"
    wf.write_text(WORKFLOW)
    code, out = invoke("export", wf)
    assert code == 2 and "identify" in out and "never" in out  # a usage error

    for stage in ("ingest", "differentiate", "identify"):
        code, out = invoke(stage, wf)
        assert code == 0, out
    code, out = invoke("export", wf, "--format", "c")
    assert code == 0, out
    export = tmp_path / "out/export"
    header = (export / C_FILES[0]).read_text()
    sha = artifacts.manifest_digest(tmp_path / "out/identify")
    assert (
        sha in header and 'DEBIST_WORKFLOW[] = "export-check"' in (export / C_FILES[1]).read_text()
    )
    assert "restoring" in header and "identified" in header  # intervals from curves.parquet

    before = (export / C_FILES[1]).read_bytes()
    code, out = invoke("export", wf)
    assert code == 2 and C_FILES[0] in out and "--force" in out
    assert (export / C_FILES[1]).read_bytes() == before
    (export / C_FILES[1]).write_text("edited")
    code, out = invoke("export", wf, "--force")
    assert code == 0 and (export / C_FILES[1]).read_bytes() == before
    assert sorted(p.name for p in export.iterdir()) == sorted(C_FILES)  # no temporary left

    # the Python module reproduces debist's free run of the identified model
    code, out = invoke("export", wf, "--format", "python", "--dest", tmp_path / "py")
    assert code == 0, out
    model = RBFModel.from_tree(artifacts.read_h5(tmp_path / "out/identify/model.h5"))
    data = pd.read_parquet(tmp_path / "out/ingest/estimation.parquet")
    v = data[["v1", "v2"]].to_numpy()[:300]
    dt = float(data.t.iloc[1] - data.t.iloc[0])
    q0 = float(data.q.iloc[0])
    (ref,) = simulate(
        model, [v], dt, np.array([q0]), np.array([0.0]),
        substeps=NS, interpolation="linear", engine="numpy",
    )  # fmt: skip
    spec = importlib.util.spec_from_file_location("debist_model_cli", tmp_path / "py" / PYTHON_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    x = mod.initial_state(q0, 0.0)
    q = [x[0]]
    for k in range(len(v) - 1):
        x = mod.rk4_step(x, v[k], v[k + 1], dt)
        q.append(x[0])
    assert_close_q(np.array(q), ref.q)

    # the MATLAB function of the same run: its provenance, and in Octave the same free run
    code, out = invoke("export", wf, "--format", "matlab", "--dest", tmp_path / "m")
    assert code == 0, out
    text = (tmp_path / "m" / MATLAB_FILE).read_text()
    assert sha in text and f"[{model.q_range[0]!r}," in text
    assert "name = 'export-check';" in (tmp_path / "m" / MATLAB_NAME_FILE).read_text()
    if OCTAVE is not None:
        q_m, _ = run_octave(tmp_path / "m", v, q0, dt, 2)
        assert_close_q(q_m, ref.q)

    # a modified model.h5 is refused, naming the file
    with open(tmp_path / "out/identify/model.h5", "ab") as fh:
        fh.write(b"\0")
    code, out = invoke("export", wf, "--force")
    assert code == 2 and "model.h5" in out and "stale" in out  # as `run --stages` says it


def test_export_before_identify_is_refused_like_run_stages(tmp_path):
    """Both a usage problem (exit 2): the stage export reads has never run."""
    root = Path(__file__).resolve().parents[2]
    shutil.copytree(root / "workflows", tmp_path / "workflows")
    wf = tmp_path / "workflows" / "paper-experiment.toml"
    code, out = invoke_cli("export", wf, "--format", "c", "--dest", tmp_path / "c")
    assert code == 2 and "'identify'" in out and "never" in out
    assert not (tmp_path / "c").exists()
    code, out = invoke_cli("run", wf, "--stages", "validate")
    assert code == 2


#: Workflow names that try to break out of a comment, docstring, literal or template field.
HOSTILE_NAMES = [
    '"""\nimport pathlib; pathlib.Path("PWNED").touch()\n"""',
    '*/ int evil = 1; /* \\ ??/ "q" @N_TERMS@',
    "x\nsystem('touch PWNED')\n% '' '",
    "\u00e9t\u00e9 \u2028 \U0001f600 \t\r\n\x0b end",
    "",
]


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_hostile_workflow_names_are_escaped_in_every_export(tmp_path, name):
    model, v = MODELS["lag+prior"](), random_inputs(3)
    info = ExportInfo(workflow=name, run_digest="ab" * 32)
    x0 = np.array([0.004, 0.0, 0.0])
    v0, v1 = v[0].tolist(), v[1].tolist()

    # Python: importing runs nothing, and the name comes back exactly
    (tmp_path / PYTHON_FILE).write_text(python_source(model, info)[PYTHON_FILE], encoding="utf-8")
    probe = (
        "import debist_model as m, numpy as np, sys; sys.stdout.write(repr((m.WORKFLOW, "
        f"m.rk4_step(np.array({x0.tolist()!r}), {v0!r}, {v1!r}, {DT!r}).tolist())))"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    got_name, got_step = ast.literal_eval(done.stdout)
    assert got_name == name
    assert not (tmp_path / "PWNED").exists()

    # C: compiles warning-free, and the literal holds the name's UTF-8 bytes
    if CC is not None:
        dll = build_c(tmp_path, model, info)
        raw = (ctypes.c_char * (len(name.encode()) + 1)).in_dll(dll, "DEBIST_WORKFLOW")
        assert bytes(raw)[:-1] == name.encode() and bytes(raw)[-1:] == b"\0"
        x = x0.copy()
        dll.debist_rk4_step(ptr(x), ptr(v[0].copy()), ptr(v[1].copy()), DT)
        np.testing.assert_array_equal(x, got_step)

    # MATLAB: the function file parses and runs in Octave and returns the name's code units
    files = matlab_source(model, info)
    for fname, text in files.items():
        (tmp_path / fname).write_text(text, encoding="utf-8")
    assert "PWNED" not in files[MATLAB_FILE]
    if OCTAVE is not None:
        script = (
            "n = debist_model_workflow(); printf('%d ', double(n)); printf('\\n');"
            f"x = debist_model([{float(x0[0])!r}; 0; 0], [{v0[0]!r}; {v0[1]!r}], "
            f"[{v1[0]!r}; {v1[1]!r}], {DT!r}); printf('%.17g ', x);"
        )
        out = subprocess.run(
            [OCTAVE, "--no-gui", "--quiet", "--eval", script],
            cwd=tmp_path, capture_output=True, text=True, check=True,
        ).stdout.split("\n")  # fmt: skip
        assert [int(c) for c in out[0].split()] == list(name.encode())  # Octave: UTF-8 chars
        np.testing.assert_allclose([float(s) for s in out[1].split()], got_step, rtol=1e-13)
    assert not (tmp_path / "PWNED").exists()


#: Provenance that would end the comment or docstring it is written into, per format.
HOSTILE_PROVENANCE = {
    "c": ExportInfo(run_digest="ab */ int evil = 1; /* cd"),
    "matlab": ExportInfo(identify_manifest="ab\nsystem('touch PWNED')"),
    "python": ExportInfo(version='1.0"""\nimport os  #'),
}


@pytest.mark.parametrize("fmt", list(HOSTILE_PROVENANCE))
def test_provenance_that_could_leave_a_comment_is_refused(fmt):
    """Provenance goes into comments only as printable ASCII that cannot end them."""
    with pytest.raises(ArtifactError) as err:
        export_files(rbf_model(), fmt, HOSTILE_PROVENANCE[fmt])
    assert "cannot" in str(err.value) and "into" in str(err.value)


def test_templates_insert_only_filtered_text_and_integers():
    """A raw string or float in ``{{ ... }}`` is an error, as is a missing value."""
    import jinja2

    from debist.export.common import Code, _environment

    env = _environment({"quote": lambda s: f"'{s}'"})

    def render(text, **values):
        return env.from_string(text).render(**values)

    assert render("{{ n }} {{ s | quote }} {{ c }}", n=3, s="a", c=Code("x")) == "3 'a' x"
    for value in ("*/ evil", 1.5, True, None, [1]):
        with pytest.raises(TypeError) as err:
            render("{{ v }}", v=value)
        assert "without" in str(err.value) and "filter" in str(err.value)
    with pytest.raises(TypeError) as err:
        render("{{ s | quote | upper }}", s="a")  # a built-in filter's str is raw again
    assert "without" in str(err.value) and "filter" in str(err.value)
    with pytest.raises(jinja2.UndefinedError):
        render("{{ missing }}")
    with pytest.raises(jinja2.UndefinedError):
        render("{{ missing | quote }}")
