"""The compiled free-run kernel against the NumPy reference engine, on every model class.

The NumPy engine calls each model's own ``rhs`` (the RBF model's curve form of Eq. 37, SINDy's
library, the analytical model's splines); the kernel gets the model as arrays. Agreement to
1e-10 relative checks the kernel and the arrays (the term library) at once.
"""

import numpy as np
import pytest

from debist.core import progress
from debist.model.sindy import SindyModel
from debist.model.terms import force_columns, input_columns, term_table
from debist.physics.freerun import analytical_model
from debist.physics.params import PrototypeParams
from debist.simulate import kernel
from debist.simulate.freerun import prepare_inputs, simulate
from tests.conftest import example_rbf_model, with_physics_creep

DT = 0.01


def inputs(n, seed, level=1500.0, n_in=2):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    f = rng.uniform(0.1, 1.0, size=n_in)
    return np.stack(
        [level + 0.6 * level * np.sin(2 * np.pi * f[i] * t + i) for i in range(n_in)], axis=1
    )


def rbf_model(T_z=0.02, outside="clip", prior=True, damping=5.0, creep_rate=0.0):
    """The shared example model (conftest): backbone, prior, friction lag (and creep)."""
    return example_rbf_model(T_z, outside, prior, damping, creep_rate=creep_rate)


def sindy_model():
    exps = np.array(
        [[0, 0, 0, 0], [1, 0, 0, 0], [3, 0, 0, 0], [0, 1, 0, 0], [2, 1, 0, 0],
         [0, 0, 1, 0], [0, 0, 0, 1], [1, 0, 1, 0], [1, 0, 0, 1], [0, 1, 1, 1]]
    )  # fmt: skip
    coef = np.array([0.5, 40.0, -4e5, -5.0, -100.0, 2e-7, -2e-7, 1e-5, 1e-5, 1e-16])
    names = [f"f{i}" for i in range(len(coef))]
    return SindyModel(names, coef, exps, "v2", 2, "", 0.0, 0.0, (-0.012, 0.012))


def both(model, records, q0, qd0, **kw):
    out = []
    for engine in ("numpy", "compiled"):
        out.append(simulate(model, records, DT, q0, qd0, engine=engine, **kw))
    return out


def assert_same(ref, new, tol=1e-10):
    for a, b in zip(ref, new, strict=True):
        assert a.diverged == b.diverged and a.diverged_at == b.diverged_at
        for x, y in ((a.q, b.q), (a.q_dot, b.q_dot), (a.q_ddot, b.q_ddot), (a.states, b.states)):
            assert np.array_equal(np.isnan(x), np.isnan(y))
            ok = ~np.isnan(x)
            scale = np.max(np.abs(x[ok])) if ok.any() else 1.0
            assert np.max(np.abs(x[ok] - y[ok]), initial=0.0) <= tol * scale


@pytest.mark.parametrize("substeps", [1, 4])
@pytest.mark.parametrize("interpolation", ["bandlimited", "linear"])
@pytest.mark.parametrize(("T_z", "outside", "prior"), [(0.02, "clip", True), (0.0, "zero", False)])
def test_rbf_model_with_backbone_and_prior(substeps, interpolation, T_z, outside, prior):
    model = rbf_model(T_z, outside, prior)
    records = [inputs(1500, 0), inputs(900, 1)]  # a batch of unequal lengths
    q0, qd0 = np.array([-0.01, 0.009]), np.array([0.0, 0.01])
    ref, new = both(model, records, q0, qd0, substeps=substeps, interpolation=interpolation)
    assert not any(r.diverged for r in ref)
    assert np.ptp(ref[0].q) > 1e-3  # it moves
    assert_same(ref, new)


@pytest.mark.parametrize(("T_z", "substeps"), [(0.02, 1), (0.0, 3)])
@pytest.mark.slow
def test_rbf_model_with_creep_states_in_both_engines_and_its_term_table(T_z, substeps):
    """The creep of Eq. 26 as M extra states w_j' = phi_j(q) q_dot - lambda w_j: the model's
    own rhs, its term table's NumPy rhs and the compiled kernel agree to 1e-12."""
    model = rbf_model(T_z, creep_rate=3.7)
    assert model.n_states == 13 and kernel.kernel_arrays(model).n_states == 13
    records = [inputs(1500, 0), inputs(900, 1)]
    q0, qd0 = np.array([-0.01, 0.009]), np.array([0.0, 0.01])
    ref, new = both(model, records, q0, qd0, substeps=substeps)
    table = simulate(model.table_model(), records, DT, q0, qd0, engine="numpy", substeps=substeps)
    assert_same(ref, new, tol=1e-12)
    assert_same(ref, table, tol=1e-12)
    w = ref[0].states[:, 3:]
    assert np.all(w[0] == 0.0) and np.max(np.abs(w)) > 1e-3  # at rest, then it creeps
    plain = simulate(rbf_model(T_z), records, DT, q0, qd0, substeps=substeps)
    assert np.max(np.abs(plain[0].q - ref[0].q)) > 1e-3  # the creep force matters


def test_a_lockstep_batch_of_creep_models_equals_one_trajectory_at_a_time(two_threads):
    model = rbf_model(creep_rate=3.7)
    records = [inputs(500 + 150 * i, 40 + i) for i in range(5)]
    q0 = np.linspace(-0.01, 0.01, 5)
    ref, new = both(model, records, q0, np.zeros(5), substeps=2)
    assert len(records) > two_threads
    assert_same(ref, new, tol=1e-12)
    for i, rec in enumerate(records):
        one = simulate(model, [rec], DT, q0[i : i + 1], np.zeros(1), substeps=2)
        np.testing.assert_array_equal(new[i].states, one[0].states)


def test_sindy_polynomials_with_input_products():
    model = sindy_model()
    records = [inputs(1200, 2), inputs(700, 7)]
    ref, new = both(model, records, np.array([0.01, -0.01]), np.zeros(2), substeps=2)
    assert np.ptp(ref[0].q) > 1e-4
    assert_same(ref, new)


@pytest.mark.parametrize("n_records", [1, 3])
def test_analytical_model_on_its_splines(n_records):
    """One record runs serially, a batch on numba's threads (the spline model's short layout
    once crashed the parallel loop, which read the table model's offsets from it)."""
    model = analytical_model(PrototypeParams.paper())
    v = np.zeros((600, 2))
    v[100:250, 0] = 3000.0  # a switching pulse on DE 1
    records = [v, v[:400, ::-1], v[:500]][:n_records]
    q0 = np.array([-0.0102, 0.0102, -0.0102])[:n_records]
    ref, new = both(model, records, q0, np.zeros(n_records), substeps=4)
    assert ref[0].q[-1] > 0.005  # it switched to the right well
    if n_records > 1:
        assert ref[1].q[-1] < -0.005  # and the mirrored pulse to the left one
    assert_same(ref, new)


def test_a_diverging_model_diverges_at_the_same_sample_in_both_engines():
    model = rbf_model(damping=-40.0)  # negative damping: the oscillation grows
    records = [inputs(2000, 3), inputs(2000, 4, level=100.0)]
    q0, qd0 = np.array([0.009, 0.0]), np.array([0.0, 0.0])
    ref, new = both(model, records, q0, qd0, substeps=2, q_limit=0.05)
    assert ref[0].diverged and ref[0].diverged_at > 10
    assert np.isnan(ref[0].q[ref[0].diverged_at :]).all()
    assert_same(ref, new)


@pytest.fixture
def two_threads(monkeypatch):
    """The kernel's threads set to 2, so that a batch of more runs in lockstep blocks."""
    monkeypatch.setattr(kernel, "kernel_threads", lambda: 2)
    return 2


def test_a_lockstep_batch_of_uneven_diverging_runs_equals_both_references(two_threads, monkeypatch):
    """More trajectories than threads run in lockstep blocks: uneven lengths, runs that
    diverge at different samples and progress chunks change no number."""
    monkeypatch.setattr(kernel, "CHUNK", 450)
    model = rbf_model(damping=-3.0)  # negative damping: runs leave the wells, some after a chunk
    lengths = [2000, 1300, 700, 2000, 1700, 900, 2000, 450, 1100]
    levels = [1500.0, 100.0, 1500.0, 100.0, 1200.0, 100.0, 1500.0, 1500.0, 100.0]
    records = [
        inputs(n, 20 + i, level=lv) for i, (n, lv) in enumerate(zip(lengths, levels, strict=True))
    ]
    q0 = np.array([0.009, 0.0, 0.003, 0.0, -0.009, 0.0, 0.0, 0.009, 0.0])
    assert len(records) > two_threads
    with progress.listening(lambda *_: None):  # chunked: the blocks resume between chunks
        ref, new = both(model, records, q0, np.zeros(len(records)), substeps=2, q_limit=0.05)
    died = [r.diverged_at for r in ref if r.diverged]
    assert len(set(died)) >= 3 and max(died) > kernel.CHUNK  # at different samples and chunks
    assert not all(r.diverged for r in ref)
    assert_same(ref, new)
    for i, rec in enumerate(records):  # bit for bit the numbers of one trajectory at a time
        one = simulate(model, [rec], DT, q0[i : i + 1], np.zeros(1), substeps=2, q_limit=0.05)
        np.testing.assert_array_equal(new[i].states, one[0].states)
        np.testing.assert_array_equal(new[i].q_ddot, one[0].q_ddot)


def test_a_lockstep_batch_of_sindy_models_with_linear_input(two_threads):
    model = sindy_model()
    records = [inputs(600 + 100 * i, 30 + i) for i in range(5)]
    q0 = np.linspace(-0.01, 0.01, 5)
    ref, new = both(model, records, q0, np.zeros(5), substeps=3, interpolation="linear")
    assert np.ptp(ref[0].q) > 1e-4
    assert_same(ref, new)


def test_the_term_table_columns_are_the_terms_of_eq_37_written_out():
    """Each regressor column against its expression written out with NumPy (Eq. 37-40)."""
    model = rbf_model()
    rng = np.random.default_rng(5)
    q = rng.uniform(-0.02, 0.02, 200)  # beyond the centres: the clip must hold q at the edge
    z = rng.normal(0, 0.05, 200)
    hv = rng.uniform(0, 3000, (200, 2)) ** 2
    names, _ = model.parameters()
    cols = term_table(names, model.basis, 2, "v2", 1e-3, model.prior).columns(q, z, hv)
    xi, sigma = model.basis.xi, model.basis.sigma
    q_c = np.clip(q, xi[0], xi[-1])
    phi = np.exp(-((q_c[:, None] - xi[None, :]) ** 2) / (2 * sigma**2))  # Eq. 38
    pri = model.prior
    expected = {"linear_spring": q, "cubic_spring": q**3, "viscous": z,
                "coulomb": np.tanh(z / 1e-3), "offset": np.ones_like(q),
                "physics_spring": np.interp(q, pri.q, pri.c) * q,
                "physics_damping": np.interp(q, pri.q, pri.d) * z}  # fmt: skip
    for i in range(model.basis.M):
        expected[f"c[{i}]"] = phi[:, i] * q
        expected[f"d[{i}]"] = phi[:, i] * z
        for j in range(2):
            expected[f"g{j + 1}[{i}]"] = phi[:, i] * hv[:, j]
    for j in range(2):
        expected[f"input_gain{j + 1}"] = hv[:, j]
        expected[f"physics_gain{j + 1}"] = np.interp(q, pri.q, pri.g[:, j]) * hv[:, j]
    assert sorted(names) == sorted(expected)
    for j, name in enumerate(names):
        np.testing.assert_allclose(cols[:, j], expected[name], rtol=1e-12, atol=1e-300)
    backbone = ("linear_spring", "cubic_spring", "viscous", "coulomb", "offset",
                "physics_spring", "physics_damping")  # fmt: skip
    F, f_names = force_columns(q, z, model.basis, ("c", "d"), backbone, 1e-3, pri)
    np.testing.assert_array_equal(F, cols[:, [names.index(n) for n in f_names]])
    G, g_names = input_columns(q, hv, model.basis, ("g",), ("input_gain", "physics_gain"), pri)
    np.testing.assert_array_equal(G, cols[:, [names.index(n) for n in g_names]])


def test_progress_is_reported_in_chunks_and_does_not_change_the_numbers(monkeypatch):
    monkeypatch.setattr(kernel, "CHUNK", 700)
    model = rbf_model()
    v = inputs(3000, 6)
    quiet = simulate(model, [v], DT, np.array([0.01]), np.array([0.0]))
    seen = []
    with progress.listening(lambda task, done, total: seen.append((task, done, total))):
        loud = simulate(model, [v], DT, np.array([0.01]), np.array([0.0]))
    assert [s[1] for s in seen] == [700, 1400, 2100, 2800, 3000]
    assert {s[2] for s in seen} == {3000}
    np.testing.assert_array_equal(quiet[0].states, loud[0].states)  # bit for bit
    np.testing.assert_array_equal(quiet[0].q_ddot, loud[0].q_ddot)


def test_parallel_batch_equals_one_trajectory_at_a_time():
    model = rbf_model()
    records = [inputs(800, s) for s in range(6)]
    q0 = np.linspace(-0.01, 0.01, 6)
    batch = simulate(model, records, DT, q0, np.zeros(6), substeps=2)
    for i, rec in enumerate(records):
        one = simulate(model, [rec], DT, q0[i : i + 1], np.zeros(1), substeps=2)
        np.testing.assert_array_equal(batch[i].states, one[0].states)


def test_sensitivities_do_not_depend_on_the_threads(monkeypatch):
    """Five trajectories of uneven length dealt out to 1, 2 and 3 threads: the same bits."""
    from debist.model.terms import term_sign, term_table
    from debist.model.termtable import TableModel

    model = rbf_model(T_z=0.02)
    names, theta = model.parameters()
    table = term_table(names, model.basis, 2, "v2", 1e-3, model.prior)
    signs = np.array([term_sign(n) for n in names])
    n = len(names)
    arrays = kernel.kernel_arrays(
        TableModel(table, signs * theta, np.array([1.0]), np.array([0.02]))
    )
    lengths = np.array([300, 120, 260, 300, 90])
    fine = prepare_inputs([inputs(300, s) for s in range(5)], 2, "bandlimited").values
    x0 = np.zeros((5, arrays.n_states))
    x0[:, 0] = np.linspace(-0.01, 0.01, 5)
    runs = []
    for threads in (1, 2, 3):
        monkeypatch.setattr(kernel, "kernel_threads", lambda t=threads: t)
        runs.append(kernel.free_run_sensitivity(arrays, fine, lengths, DT, 2, x0, np.inf,
                                                np.arange(n), signs, n, n + 1, n + 2))  # fmt: skip
    assert np.isfinite(runs[0][1][4, :90]).all() and np.isnan(runs[0][1][4, 90:]).all()
    for q, dq in runs[1:]:
        np.testing.assert_array_equal(q, runs[0][0])
        np.testing.assert_array_equal(dq, runs[0][1])


def test_on_threads_runs_every_block_and_raises_the_first_error():
    import threading

    seen, names = [], set()
    together = threading.Barrier(3, timeout=30)  # passes only when three blocks run at once

    def call(block):
        together.wait()
        names.add(threading.current_thread().name)
        seen.extend(block.tolist())
        if 7 in block:
            raise ValueError("block with 7")

    blocks = [np.arange(0, 4), np.arange(4, 6), np.array([], dtype=np.int64), np.arange(6, 9)]
    with pytest.raises(ValueError, match="block with 7"):
        kernel.on_threads(call, blocks)
    assert sorted(seen) == list(range(9))  # every block ran, the failing one included
    assert len(names) == 3 and all(n.startswith("debist-rk4") for n in names)
    seen.clear()
    kernel.on_threads(lambda b: seen.extend(b.tolist()), [np.arange(3)])  # one block: no thread
    assert seen == [0, 1, 2]


def test_kernel_arrays_check_the_spline_shape():
    with pytest.raises(ValueError) as err:
        kernel.spline_arrays(np.arange(3.0), np.zeros((4, 2, 7)), 1.0, 1.0)
    assert "shape" in str(err.value)
    fine = prepare_inputs([inputs(10, 0)], 1, "linear")
    assert fine.values.shape == (1, 19, 2)


#: Maxwell-slip elements of the sensitivity test: break-away deflections [m], stiffnesses [N/m].
SLIP = ((3e-5, 1e-4, 4e-4), (400.0, 150.0, 40.0))
#: A position-dependent inertia m(q) = m_q + 2 q + 900 q^2 (tests/model/test_inertia.py).
INERTIA = np.array([2.0, 900.0])


def inertia_models(T_z, slip):
    """The creep model (with slip elements) without and with the inertia :data:`INERTIA`."""
    from dataclasses import replace

    model = rbf_model(T_z, creep_rate=3.7)
    if slip:
        model = replace(model, slip_width=(2e-4, 8e-4, 3.2e-3),
                        theta_slip=np.array([400.0, 150.0, 40.0]))  # fmt: skip
    return model, replace(model, theta_inertia=INERTIA)


@pytest.mark.parametrize("slip", [False, True])
@pytest.mark.parametrize("T_z", [0.02, 0.0])
def test_inertia_terms_in_the_compiled_kernel_serial_and_in_lockstep(two_threads, T_z, slip):
    """A mass m(q) with the force 1/2 m'(q) q_dot^2 (inertia terms): the compiled kernel, one
    trajectory at a time and in lockstep blocks, against the NumPy engine to 1e-12, the
    blocks bit for bit the one-trajectory numbers; the inertia changes the runs."""
    plain, model = inertia_models(T_z, slip)
    table = model.table_model().table
    assert table.has_inertia and table.names.count("inertia[1]") == 1
    assert "inertia[2]" in table.names and not plain.table_model().table.has_inertia
    records = [inputs(800, 0), inputs(600, 1)]  # no more than the threads: one at a time
    q0, qd0 = np.array([-0.01, 0.009]), np.array([0.0, 0.01])
    ref, new = both(model, records, q0, qd0, substeps=2)
    assert not any(r.diverged for r in ref) and np.ptp(ref[0].q) > 1e-3
    assert_same(ref, new, tol=1e-12)
    without = simulate(plain, records, DT, q0, qd0, substeps=2)
    for r, w in zip(ref, without, strict=True):  # m(q) varies by ~10 %: so do the runs
        assert np.max(np.abs(r.q - w.q)) > 5e-3 * np.ptp(w.q)
    records = [inputs(300 + 100 * i, 60 + i) for i in range(5)]
    q0 = np.linspace(-0.01, 0.01, 5)
    assert len(records) > two_threads  # lockstep blocks
    ref, new = both(model, records, q0, np.zeros(5), substeps=2)
    assert_same(ref, new, tol=1e-12)
    for i, rec in enumerate(records):
        one = simulate(model, [rec], DT, q0[i : i + 1], np.zeros(1), substeps=2)
        np.testing.assert_array_equal(new[i].states, one[0].states)
        np.testing.assert_array_equal(new[i].q_ddot, one[0].q_ddot)


@pytest.mark.parametrize("slip", [False, True])
@pytest.mark.parametrize("T_z", [0.02, 0.0])
def test_physics_creep_in_the_compiled_kernel_serial_and_in_lockstep(two_threads, T_z, slip):
    """The creep of Eq. 26 in the analytical form (two strains driven by tabulated k_i(q),
    the force on tabulated k_bar k_i(q)): the compiled kernel, one trajectory at a time and
    in lockstep blocks, against the NumPy engine to 1e-12; the creep changes the runs."""
    from dataclasses import replace

    plain = rbf_model(T_z)
    if slip:
        plain = replace(plain, slip_width=SLIP[0], theta_slip=np.array(SLIP[1]))
    model = with_physics_creep(plain)
    assert model.n_states == plain.n_states + 2 == kernel.kernel_arrays(model).n_states
    records = [inputs(800, 0), inputs(600, 1)]
    q0, qd0 = np.array([-0.01, 0.009]), np.array([0.0, 0.01])
    ref, new = both(model, records, q0, qd0, substeps=2)
    assert not any(r.diverged for r in ref) and np.ptp(ref[0].q) > 1e-3
    assert_same(ref, new, tol=1e-12)
    eps = ref[0].states[:, 3:5]
    assert np.all(eps[0] == 0.0) and np.max(np.abs(eps)) > 1e-3  # relaxed, then it creeps
    without = simulate(plain, records, DT, q0, qd0, substeps=2)
    assert np.max(np.abs(ref[0].q - without[0].q)) > 1e-3 * np.ptp(without[0].q)
    records = [inputs(300 + 100 * i, 60 + i) for i in range(5)]
    q0 = np.linspace(-0.01, 0.01, 5)
    ref, new = both(model, records, q0, np.zeros(5), substeps=2)
    assert_same(ref, new, tol=1e-12)


def test_the_kernel_groups_the_inertia_terms_last_and_checks_their_form():
    """Inertia terms form the last groups (the fast path's loop stops before them); a table
    without them keeps its term order; an inertia term with inputs or q^0 is refused."""
    from debist.model.termtable import S_ACC, TableModel, TermTableBuilder

    plain, model = inertia_models(0.02, False)
    arrays, table = kernel.kernel_arrays(model), model.table_model().table
    assert arrays.lay[kernel._NA] == 2 and kernel.kernel_arrays(plain).lay[kernel._NA] == 0
    order = [table.names[j] for j in arrays.term_order]
    assert order[-2:] == ["inertia[1]", "inertia[2]"]
    plain_table = plain.table_model().table
    assert order[:-2] == [plain_table.names[j] for j in kernel.kernel_arrays(plain).term_order]
    for hpow, qpow in (([1], 1), ([0], 0)):
        build = TermTableBuilder(1, "v")
        build.term("bad", build.one(), qpow=qpow, skind=S_ACC, hpow=hpow)
        bad = TableModel(build.build(), np.ones((1, 1)), np.ones(1), np.zeros(1))
        with pytest.raises(ValueError) as err:
            kernel.table_arrays(bad)
        assert "inertia" in str(err.value) and "term" in str(err.value)


@pytest.mark.parametrize(
    ("extra", "T_z"),
    [
        ("none", 0.02),
        ("creep+slip", 0.02),
        ("inertia+creep+slip", 0.02),
        ("inertia", 0.0),
        ("physics_creep+slip", 0.02),
    ],
)
def test_forward_sensitivities_are_the_derivative_of_the_free_run(extra, T_z):
    """The refinement's Jacobian: d q / d p from the sensitivity equations against central
    differences of the kernel's own free run, for weights, the mass and log T_z, and with the
    creep states of Eq. 26 and Maxwell-slip elements (their stiffnesses, and every weight
    through their states), and with inertia terms m(q) = m + 2 q + 900 q^2 (their weights,
    and every weight and the mass through m(q)), with the friction lag and without."""
    from dataclasses import replace

    from debist.model.terms import term_sign, term_table
    from debist.model.termtable import TableModel

    model = rbf_model(T_z=T_z, creep_rate=3.7 if "creep" in extra.split("+") else 0.0)
    if "physics_creep" in extra:
        model = with_physics_creep(model)
    if "slip" in extra:
        model = replace(model, slip_width=SLIP[0], theta_slip=np.array(SLIP[1]))
    if "inertia" in extra:
        model = replace(model, theta_inertia=INERTIA)
    names, theta = model.parameters()
    assert ("inertia[2]" in names) == ("inertia" in extra)
    table = term_table(names, model.basis, 2, "v2", 1e-3, model.prior, model.creep_rate,
                       model.slip_width or None)  # fmt: skip
    signs = np.array([term_sign(n) for n in names])
    n, lagged = len(names), T_z > 0

    def build(p):
        tz = np.exp(p[n + 1]) if lagged else 0.0
        return TableModel(table, signs * p[:n], np.array([p[n]]), np.array([tz]))

    p0 = np.concatenate([theta, [1.0, np.log(T_z)] if lagged else [1.0]])
    fine = prepare_inputs([inputs(300, 0), inputs(300, 1)], 2, "bandlimited").values
    x0 = np.zeros((2, build(p0).n_states))
    x0[:, :3] = [[-0.01, 0.0, 0.0], [0.009, 0.01, 0.01]]
    x0[1, 3:] = 1e-5  # creep states and slip deflections away from rest on one trajectory
    lengths = np.array([300, 300])

    def q_of(p):
        states = kernel.free_run(kernel.kernel_arrays(build(p)), fine, lengths, DT, 2, x0, np.inf)[
            0
        ]
        return states[..., 0]

    q, dq = kernel.free_run_sensitivity(
        kernel.kernel_arrays(build(p0)), fine, lengths, DT, 2, x0, np.inf, np.arange(n), signs, n,
        n + 1 if lagged else -1, p0.size,
    )  # fmt: skip
    np.testing.assert_array_equal(q, q_of(p0))
    if "slip" in extra:  # the elements stick and slip along the runs: the test covers both
        states = kernel.free_run(kernel.kernel_arrays(build(p0)), fine, lengths, DT, 2, x0, np.inf)[
            0
        ]
        at_width = np.isclose(np.abs(states[..., -3:]), SLIP[0], rtol=1e-12, atol=0)
        assert 0.05 < at_width.mean() < 0.95
    for i in range(p0.size):
        step = 1e-6 * abs(p0[i])
        up, down = p0.copy(), p0.copy()
        up[i] += step
        down[i] -= step
        fd = (q_of(up) - q_of(down)) / (2 * step)
        assert np.max(np.abs(fd - dq[..., i])) <= 1e-3 * np.max(np.abs(fd)), names[i : i + 1]


def test_a_changed_compiled_helper_is_refused_until_the_kernel_records_it(monkeypatch):
    """numba's cache sees changes of kernel.py only: a change in rk4, basis or friction must
    change kernel.py's COMPILED_FROM_SHA256, and the import check says so, naming the value."""
    from debist.simulate import kernel, rk4

    kernel._check_compiled_from()  # the recorded value is the sources' own
    monkeypatch.setattr(rk4, "NODES", (0.0, 0.5, 0.5, 0.999))
    with pytest.raises(ImportError) as raised:
        kernel._check_compiled_from()
    assert "COMPILED_FROM_SHA256" in str(raised.value)
    assert kernel._compiled_from_sha256() in str(raised.value)


@pytest.mark.parametrize("B", [2, 5])  # two: a thread per trajectory; five: lockstep blocks
@pytest.mark.parametrize("engine", ["compiled", "numpy"])
def test_one_shared_input_row_drives_a_batch_as_its_own_copies_do(engine, B):
    """Bootstrap replicates share their record's input: a batch given that one row (what
    ``FineInputs.tile`` of one record makes) runs every trajectory bit for bit as a batch
    given B copies of it, from B initial states, each with its own replicate's weights."""
    from debist.simulate.freerun import FineInputs, simulate_batch
    from tests.conftest import G, double_well

    dev = np.random.default_rng(4).normal(0.0, 0.2 * G, size=(B, 2))
    model = double_well().replicate_table(["input_gain1", "input_gain2"], dev)
    one = prepare_inputs([inputs(400, 3)], 2, "bandlimited")
    shared = one.tile(B)
    copies = FineInputs(np.tile(one.values, (B, 1, 1)), one.lengths * B, one.substeps)
    assert shared.values.shape[0] == 1 and copies.values.shape[0] == B
    q0, qd0 = np.linspace(-0.011, 0.011, B), np.linspace(-0.05, 0.05, B)
    runs = [simulate_batch(model, f, DT, q0, qd0, engine=engine) for f in (shared, copies)]
    assert np.isfinite(runs[0].states).all() and np.ptp(runs[0].q[:, -1]) > 0  # B runs apart
    for field in ("states", "acc", "diverged_at", "lengths"):
        assert np.array_equal(getattr(runs[0], field), getattr(runs[1], field), equal_nan=True)
    with pytest.raises(ValueError, match="inputs for 2 trajectories"):
        kernel.free_run(kernel.kernel_arrays(model), copies.values[:2], np.full(3, 400), DT, 2,
                        np.zeros((3, model.n_states)), 1.0)  # fmt: skip
