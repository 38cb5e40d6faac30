"""Kernels compiled ahead in another process are the ones a later run loads from the cache."""

import os
import subprocess
import sys

import numpy as np
import pytest

from debist.simulate import warmup
from debist.simulate.freerun import simulate


def test_the_oscillator_free_runs_as_its_closed_form():
    # q'' + dv q' + k1 q = 0 from q = 1: the damped cosine (RK4 error at dt = 1 ms is tiny)
    k1, dv = 100.0, 2.0
    model = warmup.oscillator(k1, dv)
    t = np.arange(0.0, 1.0, 1e-3)
    (res,) = simulate(model, [np.zeros((t.size, 1))], 1e-3, np.array([1.0]), np.array([0.0]))
    wd = np.sqrt(k1 - dv**2 / 4)
    exact = np.exp(-dv * t / 2) * (np.cos(wd * t) + dv / (2 * wd) * np.sin(wd * t))
    assert np.max(np.abs(res.q - exact)) < 1e-6


LOAD_ONLY = """
import numba
import numpy as np
from numba.core import event
from debist.model.narx_kernel import factor_tables, narx_free_run
from debist.simulate import warmup
from debist.simulate.freerun import simulate

compiled = []


class Listener(event.Listener):
    def on_start(self, e):
        pass

    def on_end(self, e):
        compiled.append(e.data["dispatcher"].py_func.__name__)


event.register("numba:compile", Listener())
numba.njit(lambda x: x + 1)(1)  # not cached: the listener must see its compile
model = warmup.oscillator(300.0, 0.5, T_z=0.01)  # another model, other lengths: same types
v = np.cos(np.linspace(0.0, 9.0, 57))[:, None]
simulate(model, [v], 2e-3, np.zeros(1), np.ones(1), substeps=3, q_limit=5.0)
simulate(model, [v] * 5, 2e-3, np.zeros(5), np.ones(5), substeps=3, q_limit=5.0)
var, lag = factor_tables(np.array([[1001, 1001, 0], [1002, 0, 0], [2001, 0, 0]]))
narx_free_run(np.ones(2), np.ones((40, 1)), var, lag, np.array([0.3, 0.2, 0.1]), 5.0)
kernels = sorted(set(compiled) & {k.py_func.__name__ for k in warmup.KERNELS})
print(f"{'<lambda>' in compiled} {','.join(kernels) or 'none'}")
"""


def _python(code: str, cache: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "NUMBA_NUM_THREADS": "2"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


@pytest.mark.slow
def test_compiled_ahead_the_kernels_load_from_the_cache_in_a_new_process(tmp_path):
    cached = "from debist.simulate import warmup; print(warmup.kernels_cached())"
    assert _python(cached, str(tmp_path)) == "False"
    _python("from debist.simulate import warmup; print(warmup.compile_kernels())", str(tmp_path))
    assert _python(cached, str(tmp_path)) == "True"
    assert _python(LOAD_ONLY, str(tmp_path)) == "True none"
