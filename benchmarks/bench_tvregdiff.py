"""Benchmark of tvregdiff (exact banded steps) against pynumdiff's TVRegDiff port.

Run from the repository root:

    .venv/bin/python benchmarks/bench_tvregdiff.py [--repeats 21] [--ref-repeats 1]

Signal: an actuator-like bistable position trace, switching between -10 mm and +10 mm
at random instants (0.8-2 s apart) through a second-order response (4 Hz, damping 0.4),
in metres, plus 10 um of seeded white noise, dt = 0.01 s. TVRegDiff settings: 10
iterations, scale "large", alpha = 1e-5, ep = 1e-12 (the paper's 0.01 and 1e-6 for mm).
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import numpy as np
from scipy import signal

from debist.differentiate.tvregdiff import tvregdiff

DT = 0.01
ITERATIONS = 10
ALPHA = 1e-5
EP = 1e-12
SIZES = (3750, 82_800)
DENSE_LIMIT = 20_000  # pynumdiff forms a dense n x n Cholesky factor per iteration


def actuator_signal(n: int, dt: float = DT, seed: int = 0) -> np.ndarray:
    """Bistable switching position [m], +-10 mm, second-order response, 10 um noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    switches = np.cumsum(rng.uniform(0.8, 2.0, size=int(n * dt / 0.8) + 2))
    target = np.where(np.searchsorted(switches, t) % 2 == 0, -0.01, 0.01)
    wn, zeta = 2 * np.pi * 4.0, 0.4
    a = np.array([[0.0, 1.0], [-(wn**2), -2 * zeta * wn]])
    system = signal.StateSpace(a, [[0.0], [wn**2]], [[1.0, 0.0]], [[0.0]])
    _, q, _ = signal.lsim(system, target, t, X0=[-0.01, 0.0], interp=False)
    return q + 10e-6 * rng.standard_normal(n)


def median_time(func, repeats: int):
    """Median wall time [s] of ``repeats`` calls, and the last call's result."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def load_reference():
    """pynumdiff's TVRegDiff (called by total_variation_regularization.iterative_velocity)."""
    try:
        from pynumdiff.utils._chartrand_tvregdiff import TVRegDiff
    except ImportError as exc:
        return None, f"pynumdiff is not importable ({exc})"
    import pynumdiff

    return TVRegDiff, f"pynumdiff {pynumdiff.__version__}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=21, help="repeats of ours (median)")
    parser.add_argument("--ref-repeats", type=int, default=1, help="repeats of pynumdiff")
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # 10 iterations do not meet tol: ConvergenceWarning
    reference, ref_name = load_reference()
    print(f"tvregdiff: {ITERATIONS} iterations, scale 'large', alpha={ALPHA:g}, ep={EP:g}, dt={DT}")
    print(f"reference: {ref_name}")
    for n in SIZES:
        x = actuator_signal(n)
        t_ours, ours = median_time(
            lambda x=x: tvregdiff(x, ITERATIONS, ALPHA, scale="large", ep=EP, dx=DT),
            args.repeats,
        )
        t_small, _ = median_time(
            lambda x=x: tvregdiff(x, ITERATIONS, ALPHA, scale="small", ep=EP, dx=DT),
            max(3, args.repeats // 4),
        )
        print(f"\nn = {n}")
        print(
            f"  ours  large: {t_ours * 1e3:9.2f} ms  ({t_ours / n * 1e9:6.1f} ns/sample, "
            f"median of {args.repeats}); functional {ours.functional[-1]:.6e}"
        )
        print(f"  ours  small: {t_small * 1e3:9.2f} ms  ({t_small / n * 1e9:6.1f} ns/sample)")
        if reference is None:
            print(f"  pynumdiff: skipped, {ref_name}")
            continue
        if n > DENSE_LIMIT:
            gib = n * n * 8 / 2**30
            print(
                f"  pynumdiff: skipped, its 'large' scale builds a dense {n} x {n} Cholesky "
                f"factor each iteration ({gib:.0f} GiB per dense matrix)"
            )
            continue

        def run_reference(x=x):
            return reference(x, ITERATIONS, ALPHA, scale="large", ep=EP, dx=DT, plotflag=False)

        t_ref, u_ref = median_time(run_reference, args.ref_repeats)
        diff = np.max(np.abs(u_ref - ours.u)) / np.max(np.abs(ours.u))
        print(
            f"  pynumdiff large: {t_ref * 1e3:9.1f} ms  ({t_ref / n * 1e9:8.0f} ns/sample, "
            f"median of {args.ref_repeats})"
        )
        print(f"  ratio pynumdiff / ours: {t_ref / t_ours:.0f}x")
        print(f"  max |u_pynumdiff - u_ours| / max |u_ours| = {diff:.1e} (their CG rtol is 1e-4)")


if __name__ == "__main__":
    main()
