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

import subprocess
import sys

import numpy as np

#: Two parts of about the same compile time with an empty cache (about 20 s each here).
PARTS = ("warmup", "rest")


def _rest() -> None:
    """The refinement's sensitivities, the slip elements, the full model, the statics' terms and
    the rig's plant."""
    from debist.model.slip_kernel import stop_operator
    from debist.model.terms import term_sign
    from debist.physics import energy
    from debist.physics.dynamics import FullModel, well_state
    from debist.physics.params import PrototypeParams
    from debist.rig.drivers import DriverOutput
    from debist.rig.params import RigParams
    from debist.rig.plant import RigPlant
    from debist.simulate import kernel
    from debist.simulate.freerun import prepare_inputs
    from debist.simulate.warmup import oscillator

    model = oscillator(T_z=0.01)
    names, _ = model.parameters()
    arrays = kernel.kernel_arrays(model.table_model())
    signs = np.array([term_sign(n) for n in names], dtype=float)
    fine = prepare_inputs([np.sin(np.linspace(0.0, 2.0, 20))[:, None]], 2, "bandlimited").values
    x0 = np.zeros((1, arrays.n_states))
    n = len(names)
    kernel.free_run_sensitivity(
        arrays, fine, np.array([20]), 0.01, 2, x0, np.inf, np.arange(n), signs, n, n + 1, n + 2
    )
    stop_operator(np.array([1.0, 1.0, -1.0]), np.array([1.5]))
    params = PrototypeParams.paper()
    full = FullModel(params, lambda t: 1000.0, lambda t: 0.0)
    x = well_state(params, -1)
    full.rhs(0.0, x)
    full.jac(0.0, x)
    energy._evaluated = energy.PYTHON_STATES  # the statics' terms as a long solve reaches them
    energy.scalar_gradient_hessian(x[:4], params, params.b, 1000.0, 0.0)
    drive = DriverOutput([0.0, 1e-3, 2e-3], [0.0, 500.0, 500.0], tau=5e-3, slew=1e5)
    plant = RigPlant(RigParams(), drive, drive)
    rhs, jac = plant.functions()
    x = plant.rest_state(-1)
    rhs(0.0, x)
    jac(0.0, x)


def compile_part(part: str) -> None:
    """Compile (or load from the cache) the kernels of one of :data:`PARTS`.

    ``"warmup"`` is :func:`debist.simulate.warmup.compile_kernels` (the serial free run, the
    lock-step batch, the NARX free run); ``"rest"`` the kernels only the tests and the
    identification's refinement or the virtual rig reach.
    """
    if part == "warmup":
        from debist.simulate.warmup import compile_kernels

        compile_kernels()
    else:
        _rest()


def compile_ahead(root: str) -> str:
    """Compile every part in its own process, the parts side by side; wait for both.

    Parameters
    ----------
    root : str
        The repository's folder (the parent of ``tests``): the parts run there, so
        ``python -c`` imports ``tests.ahead`` from it.

    Returns
    -------
    str
        The standard error of the parts that failed ("" when both compiled): the workers
        then compile on their own, and a test that needs the kernel fails with its traceback.
    """
    code = "from tests.ahead import compile_part; compile_part({!r})"
    procs = [
        subprocess.Popen([sys.executable, "-c", code.format(part)], cwd=root,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for part in PARTS
    ]  # fmt: skip
    return "\n".join(err for proc in procs for err in [proc.communicate()[1]] if proc.returncode)
