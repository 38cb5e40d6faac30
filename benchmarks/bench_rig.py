"""Benchmark of the virtual rig's plant integration: LSODA against Radau, compiled against NumPy.

Run from the repository root:

    .venv/bin/python benchmarks/bench_rig.py [--duration 37.5] [--repeat 3] [--no-peers] [--no-jit]

One experiment of the identification profile (Fig. 11a; 3 kV switching both ways plus
sub-threshold noise on a 1 ms DAC grid) on the default rig (paper prototype with anchor
offsets, Maxwell-slip friction, HV drivers, laser), logged at 10 ms. Timed, all in this run
(median of ``--repeat`` runs each): the default (compiled plant, ODEPACK's LSODA through
``scipy.integrate.odeint`` at its default tolerances), the previous default (``solve_ivp``
Radau, rtol 1e-4), and the peers: the NumPy reference plant with LSODA, BDF at rtol 1e-4;
then, once and untimed, a tight solution (LSODA, rtol 1e-10, atol 1e-14). Printed: wall
time, right-hand-side and Jacobian evaluations, the ratio to the default, the largest
differences of the noise-free q from the tight run and from the NumPy reference [um], and
the speed-up of the default over Radau. The compiled kernels are loaded (or compiled) before
the timing; the JIT table times the first plant evaluation in fresh processes with an empty
numba cache (compile) and with the cache it left (load).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from debist.rig.params import RigParams
from debist.rig.profiles import identification_profile
from debist.rig.run import simulate_rig

DEFAULT = "LSODA rtol 1e-8, compiled"
RADAU = "Radau rtol 1e-4, compiled"
REFERENCE = "LSODA rtol 1e-8, NumPy"
SETTINGS = (
    (DEFAULT, {}),
    (RADAU, {"method": "Radau"}),
    (REFERENCE, {"compiled": False}),
    ("BDF rtol 1e-4, compiled", {"method": "BDF"}),
)
#: The tight solution the differences are taken from (1.6 nm from rtol 1e-9, atol 1e-13).
TIGHT = {"method": "odeint", "rtol": 1e-10, "atol": 1e-14}

_FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from debist.physics.dynamics import well_state
from debist.rig.drivers import DriverOutput
from debist.rig.params import RigParams
from debist.rig.plant import RigPlant
rig = RigParams()
t = np.arange(10) * 1e-3
d = [DriverOutput(t, np.full(10, 1e3), tau=rig.driver_tau, slew=rig.driver_slew) for i in (0, 1)]
x = np.concatenate([well_state(rig.prototype, -1), np.zeros(rig.n_friction)])
t1 = time.perf_counter()
rhs, jac = RigPlant(rig, d[0], d[1])._compiled()
rhs(0.0, x)
jac(0.0, x)
print(t1 - t0, time.perf_counter() - t1)
"""


def bench_plant(duration: float = 37.5, *, peers: bool = True, repeat: int = 3) -> list[dict]:
    """Time one identification-profile experiment with each integrator setting.

    Parameters
    ----------
    duration : float
        Experiment length [s].
    peers : bool
        Also time the NumPy reference and BDF, and run the tight solution; without them
        ``max_dq_tight_um`` and ``max_dq_reference_um`` are NaN.
    repeat : int
        Timed runs per setting; the median is reported.

    Returns
    -------
    list of dict
        One row per setting: ``setting``, ``seconds`` (median wall time) [s], ``nfev``,
        ``njev``, ``ratio`` (time over the default's), ``max_dq_tight_um`` (largest
        difference of the noise-free q from the tight run) [um] and
        ``max_dq_reference_um`` (from the NumPy reference) [um].

    References
    ----------
    SciPy ``scipy.integrate.odeint`` (ODEPACK LSODA: Hindmarsh 1983, Petzold 1983) and
    ``scipy.integrate.solve_ivp`` (Radau, BDF); numba (``njit``).
    """
    prof = identification_profile(duration=duration)
    rig = RigParams()
    # load (or compile) the kernels outside the timing
    simulate_rig(rig, prof.t[:50], prof.r1[:50], prof.r2[:50], sample_time=0.01, seed=1)

    def run(kw):
        return simulate_rig(rig, prof.t, prof.r1, prof.r2, sample_time=0.01, seed=1, **kw)

    runs = []
    for label, kw in SETTINGS if peers else SETTINGS[:2]:
        seconds = []
        for _ in range(max(1, repeat)):
            t0 = time.perf_counter()
            out = run(kw)
            seconds.append(time.perf_counter() - t0)
        runs.append((label, statistics.median(seconds), out))
    tight = run(TIGHT).q_true if peers else None
    q = {label: out.q_true for label, _, out in runs}
    base = runs[0][1]

    def dq(a, b):
        return 1e6 * float(np.max(np.abs(a - b))) if b is not None else float("nan")

    return [
        {
            "setting": label,
            "seconds": seconds,
            "nfev": out.nfev,
            "njev": out.njev,
            "ratio": seconds / base,
            "max_dq_tight_um": dq(out.q_true, tight),
            "max_dq_reference_um": dq(out.q_true, q.get(REFERENCE)),
        }
        for label, seconds, out in runs
    ]


def bench_jit() -> list[dict]:
    """Time the compiled plant's first evaluation in fresh processes: cold and warm cache.

    A temporary ``NUMBA_CACHE_DIR`` is empty for the first process (numba compiles the
    kernels and writes them) and holds that cache for the second (numba loads them).

    Returns
    -------
    list of dict
        Rows ``cache`` ("empty" or "warm"), ``import_s`` (imports and set-up) [s] and
        ``first_call_s`` (first right-hand side and Jacobian) [s].

    References
    ----------
    numba documentation, ``NUMBA_CACHE_DIR`` and "Notes on caching".
    """
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for state in ("empty", "warm"):
            out = subprocess.run(
                [sys.executable, "-c", _FIRST_CALL], env=env, capture_output=True, text=True
            )
            if out.returncode:
                raise RuntimeError(out.stderr)
            setup, first = map(float, out.stdout.split())
            rows.append({"cache": state, "import_s": setup, "first_call_s": first})
    return rows


def main() -> None:
    """Time the plant integration with each setting (and the JIT) and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=37.5, help="experiment length [s]")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per setting")
    parser.add_argument(
        "--no-peers", action="store_true", help="skip the NumPy reference, BDF and the tight run"
    )
    parser.add_argument("--no-jit", action="store_true", help="skip the JIT table")
    args = parser.parse_args()
    if not args.no_jit:
        print("compiled plant, first rhs + jac in a fresh process")
        print(f"{'numba cache':12s} {'imports [s]':>12s} {'first call [s]':>15s}")
        for row in bench_jit():
            print(f"{row['cache']:12s} {row['import_s']:12.2f} {row['first_call_s']:15.2f}")
        print()
    rows = bench_plant(args.duration, peers=not args.no_peers, repeat=args.repeat)
    print(
        f"identification profile, {args.duration} s, 10 ms log, default rig, "
        f"median of {args.repeat}"
    )
    head = ("setting", "time [s]", "nfev", "njev", "x default", "dq tight [um]", "dq NumPy [um]")
    print(
        f"{head[0]:28s} {head[1]:>9s} {head[2]:>9s} {head[3]:>7s} {head[4]:>10s} "
        f"{head[5]:>14s} {head[6]:>14s}"
    )
    for r in rows:
        print(
            f"{r['setting']:28s} {r['seconds']:9.2f} {r['nfev']:9d} {r['njev']:7d} "
            f"{r['ratio']:10.2f} {r['max_dq_tight_um']:14.3f} {r['max_dq_reference_um']:14.3f}"
        )
    by = {r["setting"]: r["seconds"] for r in rows}
    print(
        f"\n{DEFAULT} vs {RADAU}: {by[DEFAULT]:.2f} s vs {by[RADAU]:.2f} s, "
        f"{by[RADAU] / by[DEFAULT]:.1f}x faster"
    )


if __name__ == "__main__":
    main()
