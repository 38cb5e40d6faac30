"""Compile the free-run kernels ahead, in a process beside the run that needs them.

numba compiles a kernel on its first call and keeps it in its on-disk cache (``cache=True``),
so only the first run after an install pays. That run meets the kernels one after the other
on one core: the sensitivities of the identification's refinement, then the serial free run,
the lock-step batch of the validation's replicates, and the NARX peer's free run. Called in
a forked process when a run starts (:class:`debist.core.beside.BesideRun`),
:func:`compile_kernels` compiles those the run needs after its first one, in that order, on
the other core, and writes them to the cache; the run then loads each from the cache when it
reaches it. With a warm cache the call only loads them (well under a second).

The tiny model below reaches the kernels with the argument types of every real call (the
kernels take the model as flat arrays: :func:`debist.simulate.kernel.table_arrays`), so the
signatures compiled here are the ones the run looks up.

References
----------
numba documentation, "Notes on caching" (``cache=True``: the index and the compiled
overloads of a function in ``__pycache__`` or ``NUMBA_CACHE_DIR``, read on a function's
first call in a process).
"""

from __future__ import annotations

import os

import numpy as np

from debist.model.basis import RBFBasis
from debist.model.narx_kernel import factor_tables, narx_free_run
from debist.model.rbf import RBFModel
from debist.simulate import kernel
from debist.simulate.freerun import simulate

__all__ = ["compile_kernels", "kernels_cached", "oscillator"]

#: The kernels :func:`compile_kernels` reaches, in the order a run first calls them.
KERNELS = (kernel._integrate, kernel._lockstep, narx_free_run)


def oscillator(k1: float = 100.0, dv: float = 2.0, T_z: float = 0.0) -> RBFModel:
    """Return the linear oscillator ``q'' + dv z + k1 q = v`` as an RBF model.

    Backbone terms only (every RBF weight zero), one input, unit mass: a valid term table
    whose free run has a closed form (with ``T_z = 0``, ``z = q_dot``).

    Parameters
    ----------
    k1 : float, optional
        Linear stiffness per unit mass [1/s^2].
    dv : float, optional
        Viscous damping per unit mass [1/s].
    T_z : float, optional
        Friction-state time constant [s] (0: ``z = q_dot``).

    Returns
    -------
    RBFModel
        Three centres on [-1, 1], sigma_n 0.5.

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (the backbone terms of the model).
    """
    zeros = np.zeros(3)
    return RBFModel(
        basis=RBFBasis.equidistant(-1.0, 1.0, 3, 0.5),
        input_map="v",
        n_inputs=1,
        m_q=1.0,
        T_z=T_z,
        coulomb_velocity=1e-3,
        theta_c=zeros,
        theta_d=zeros,
        theta_g=np.zeros((1, 3)),
        backbone={"k_1": k1, "d_v": dv, "g_0": np.array([1.0])},
        q_range=(-1.0, 1.0),
    )


def compile_kernels() -> int:
    """Compile or load the serial free run, the lock-step batch and the NARX free run.

    Returns
    -------
    int
        Number of kernel calls made (3).

    Notes
    -----
    The free runs are 20 samples of a linear oscillator; their results are discarded. The
    batch of three records takes the lock-step path wherever fewer than three threads run
    (:func:`debist.simulate.kernel.free_run`); with more threads it takes the
    one-trajectory-per-thread path, which a real batch of that size would take as well.
    """
    model = oscillator()
    v = np.sin(np.linspace(0.0, 2.0, 20))[:, None]
    zero = np.zeros(1)
    simulate(model, [v], 0.01, zero, zero, substeps=2, q_limit=10.0)
    simulate(model, [v, v, v], 0.01, np.zeros(3), np.zeros(3), substeps=2, q_limit=10.0)
    var, lag = factor_tables(np.array([[1001, 0], [2001, 1001]]))
    narx_free_run(np.zeros(1), np.zeros((20, 1)), var, lag, np.array([0.5, 0.1]), 10.0)
    return 3


def kernels_cached() -> bool:
    """Whether numba's cache holds an index for each kernel of :data:`KERNELS`.

    Loading the three kernels from the cache costs about a second of CPU, which a run with
    a warm cache need not spend twice. The index file's place is numba's own
    (``Dispatcher._cache._cache_file._index_path``, not a public attribute): where it cannot
    be read the answer is False, and the kernels are loaded once more than needed.

    Returns
    -------
    bool
        True when every index file exists (an index whose source changed since is still
        counted: numba then recompiles on the call, as without this module).
    """
    for dispatcher in KERNELS:
        try:
            path = dispatcher._cache._cache_file._index_path
        except AttributeError:
            return False
        if not os.path.exists(path):
            return False
    return True
