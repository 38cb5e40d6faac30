"""Benchmark of the virtual rig's plant integration: the chosen settings against the peers.

Run from the repository root:

    .venv/bin/python benchmarks/bench_rig.py [--duration 37.5]

One experiment of the identification profile (Fig. 11a; 3 kV switching both ways plus
sub-threshold noise on a 1 ms DAC grid) on the default rig (paper prototype with anchor
offsets, Maxwell-slip friction, HV drivers, laser), logged at 10 ms. Timed: the default
(Radau, rtol 1e-4, atol 1e-8) and the peers, all in this run: BDF at the same tolerances, and
Radau at rtol 1e-6 / atol 1e-10. Printed: wall time, right-hand-side evaluations, the ratio
to the default, and the largest difference of the noise-free q from the tightest run [um].
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pipeline.rig.params import RigParams
from pipeline.rig.plant import simulate_rig
from pipeline.rig.profiles import identification_profile

PEERS = (
    ("Radau rtol 1e-4 (default)", {"method": "Radau", "rtol": 1e-4, "atol": 1e-8}),
    ("BDF rtol 1e-4", {"method": "BDF", "rtol": 1e-4, "atol": 1e-8}),
    ("Radau rtol 1e-6", {"method": "Radau", "rtol": 1e-6, "atol": 1e-10}),
)


def main() -> None:
    """Time the plant integration with each setting and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=37.5, help="experiment length [s]")
    args = parser.parse_args()
    prof = identification_profile(duration=args.duration)
    rig = RigParams()
    results = []
    for label, kw in PEERS:
        t0 = time.perf_counter()
        run = simulate_rig(rig, prof.t, prof.r1, prof.r2, sample_time=0.01, seed=1, **kw)
        results.append((label, time.perf_counter() - t0, run.nfev, run.q_true))
    ref = results[-1][3]
    base = results[0][1]
    print(f"identification profile, {args.duration} s, 10 ms log, default rig")
    head = ("setting", "time [s]", "nfev", "x default", "max |dq| [um]")
    print(f"{head[0]:28s} {head[1]:>9s} {head[2]:>9s} {head[3]:>10s} {head[4]:>14s}")
    for label, seconds, nfev, q in results:
        dq = 1e6 * float(np.max(np.abs(q - ref)))
        print(f"{label:28s} {seconds:9.2f} {nfev:9d} {seconds / base:10.2f} {dq:14.3f}")


if __name__ == "__main__":
    main()
