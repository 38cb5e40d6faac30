"""The shipped defaults end to end: the paper experiment against the previous defaults, a fleet.

What it times (wall clock of whole ``debist`` processes, as a user sees them):

1. ``debist run workflows/paper-experiment.toml --force`` with today's defaults, against the
   same command with the defaults before the calibrated bands, the NARX peer, the slip
   elements, the refinement and the replicates (``--set`` of every new default
   back to its old value: :data:`PREVIOUS`), in alternating pairs (A B A B ...) so that a
   drift of the machine's speed hits both; the median of each and the median of the pairwise
   ratios. Both write into their own output folders under ``--dir``; the rig logs are made
   once before the pairs (``--until ingest``), so the pairs time the identification pipeline.
2. ``debist fleet workflows/paper-experiment.toml --size 10 --seed 1`` and ``debist batch``
   of its members on ``--workers`` Dask workers, from a cold output folder.

Targets: the paper experiment at most twice the previous defaults' time, measured
in the same run; the fleet of 10 on 2 workers under 3 minutes.

Run from the repository root::

    python benchmarks/bench_defaults.py --pairs 5 --dir /tmp/bench-defaults
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW = ROOT / "workflows" / "paper-experiment.toml"
#: The defaults before those additions, as ``--set`` values: bootstrap-only bands, no NARX row, no
#: Maxwell-slip elements, no simulation-error refinement, no bootstrap replicates run free.
PREVIOUS = (
    "identify.model_error=false",
    "compare.narx.enabled=false",
    "identify.slip=false",
    "identify.refine=false",
    "validate.replicates=0",
)


def _debist(*args: str) -> float:
    """Run the CLI; return its wall time [s]; fail loudly if it fails."""
    cmd = [sys.executable, str(ROOT / "cli.py"), *args]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {done.returncode}:\n{done.stderr[-2000:]}")
    return seconds


def _sets(values: tuple[str, ...]) -> list[str]:
    return [arg for value in values for arg in ("-S", value)]


def main() -> None:
    """Time the paper experiment (new vs previous defaults) and a fleet of 10."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, default=5)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--dir", type=Path, required=True)
    p.add_argument("--skip-fleet", action="store_true")
    args = p.parse_args()
    new, old = args.dir / "new", args.dir / "previous"
    for out, extra in ((new, ()), (old, PREVIOUS)):
        _debist("run", str(WORKFLOW), "--out", str(out), *_sets(extra))  # warm-up, rig logs
    t_new, t_old = [], []
    for _ in range(args.pairs):
        t_new.append(_debist("run", str(WORKFLOW), "--out", str(new), "--force",
                             "--from", "differentiate"))  # fmt: skip
        t_old.append(_debist("run", str(WORKFLOW), "--out", str(old), "--force",
                             "--from", "differentiate", *_sets(PREVIOUS)))  # fmt: skip
    ratios = [a / b for a, b in zip(t_new, t_old, strict=True)]
    print(f"paper experiment, differentiate to report, {args.pairs} pairs (wall, seconds):")
    print(f"  today's defaults   median {statistics.median(t_new):6.2f}  "
          f"(min {min(t_new):.2f}, max {max(t_new):.2f})")  # fmt: skip
    print(f"  previous defaults  median {statistics.median(t_old):6.2f}  "
          f"(min {min(t_old):.2f}, max {max(t_old):.2f})")  # fmt: skip
    print(f"  ratio today / previous, median of pairs: {statistics.median(ratios):.2f} "
          "(target <= 2)")  # fmt: skip
    if args.skip_fleet:
        return
    fleet = args.dir / "fleet"
    shutil.rmtree(fleet, ignore_errors=True)
    t_fleet = _debist("fleet", str(WORKFLOW), "--size", "10", "--seed", "1", "--dir", str(fleet))
    members = sorted(str(f) for f in fleet.glob("*.toml"))
    t_batch = _debist("-q", "batch", *members, "--workers", str(args.workers))
    print(f"fleet of {len(members)}: fleet {t_fleet:.1f} s, batch on {args.workers} workers "
          f"{t_batch:.1f} s, together {t_fleet + t_batch:.1f} s (target < 180 s)")  # fmt: skip


if __name__ == "__main__":
    main()
