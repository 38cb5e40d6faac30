"""Compile debist's numba kernels once, before pytest-xdist starts its workers.

With an empty numba cache (a fresh install, as in CI) every worker compiles the kernels it
meets, and so does every process a test forks or starts, often the same kernel at the same
moment on both cores. :func:`compile_ahead` compiles each kernel once, in two processes side
by side; numba writes them to its cache, where the workers then find them.

Each part calls the kernels through debist's own functions, with tiny inputs of the types a
real call passes, so the signatures compiled are the ones the tests look up. Where a
signature differs, numba compiles it on the call as before: a cost, never a wrong result.

References
----------
numba documentation, "Notes on caching" (``cache=True``: compiled overloads in
``__pycache__`` or ``NUMBA_CACHE_DIR``, read on a function's first call in a process).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

#: Two parts of about the same compile time with an empty cache.
PARTS = ("serial", "batch")


def _term_table_model():
    from debist.simulate.warmup import oscillator

    return oscillator(T_z=0.01)


def _serial() -> None:
    """The serial free run, the slip elements, the full model and the virtual rig's plant."""
    from debist.model.slip_kernel import stop_operator
    from debist.physics.dynamics import FullModel, well_state
    from debist.physics.params import PrototypeParams
    from debist.rig.drivers import DriverOutput
    from debist.rig.params import RigParams
    from debist.rig.plant import RigPlant
    from debist.simulate.freerun import simulate

    v = np.sin(np.linspace(0.0, 2.0, 20))[:, None]
    zero = np.zeros(1)
    simulate(_term_table_model(), [v], 0.01, zero, zero, substeps=2, q_limit=10.0)
    stop_operator(np.array([1.0, 1.0, -1.0]), np.array([1.5]))
    params = PrototypeParams.paper()
    model = FullModel(params, lambda t: 1000.0, lambda t: 0.0)
    x = well_state(params, -1)
    model.rhs(0.0, x)
    model.jac(0.0, x)
    rig = RigParams()
    drive = DriverOutput([0.0, 1e-3, 2e-3], [0.0, 500.0, 500.0], tau=5e-3, slew=1e5)
    plant = RigPlant(rig, drive, drive)
    rhs, jac = plant.functions()
    x = plant.rest_state(-1)
    rhs(0.0, x)
    jac(0.0, x)


def _batch() -> None:
    """The lock-step batch, the refinement's sensitivities and the NARX peer's free run."""
    from debist.model.narx_kernel import factor_tables, narx_free_run
    from debist.model.terms import term_sign
    from debist.simulate import kernel
    from debist.simulate.freerun import prepare_inputs, simulate

    model = _term_table_model()
    v = np.sin(np.linspace(0.0, 2.0, 20))[:, None]
    simulate(model, [v, v, v], 0.01, np.zeros(3), np.zeros(3), substeps=2, q_limit=10.0)
    names, _ = model.parameters()
    arrays = kernel.kernel_arrays(model.table_model())
    signs = np.array([term_sign(n) for n in names], dtype=float)
    fine = prepare_inputs([v], 2, "bandlimited").values
    x0 = np.zeros((1, arrays.n_states))
    n = len(names)
    kernel.free_run_sensitivity(
        arrays, fine, np.array([20]), 0.01, 2, x0, np.inf, np.arange(n), signs, n, n + 1, n + 2
    )
    var, lag = factor_tables(np.array([[1001, 0], [2001, 1001]]))
    narx_free_run(np.zeros(1), np.zeros((20, 1)), var, lag, np.array([0.5, 0.1]), 10.0)


def compile_part(part: str) -> None:
    """Compile (or load from the cache) the kernels of one of :data:`PARTS`."""
    {"serial": _serial, "batch": _batch}[part]()


def compile_ahead(root: str) -> str:
    """Compile every part in its own process, the parts side by side; wait for both.

    Parameters
    ----------
    root : str
        The repository's folder (the parent of ``tests``), put on the parts' ``PYTHONPATH``.

    Returns
    -------
    str
        The standard error of the parts that failed ("" when both compiled): the workers
        then compile on their own, and a test that needs the kernel fails with its traceback.
    """
    path = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path}
    code = "from tests.ahead import compile_part; compile_part({!r})"
    procs = [
        subprocess.Popen([sys.executable, "-c", code.format(part)], env=env, cwd=root,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for part in PARTS
    ]  # fmt: skip
    return "\n".join(err for proc in procs for err in [proc.communicate()[1]] if proc.returncode)
