"""Start-up of the command line: a no-op ``debist run`` and ``debist status`` against 1 s.

Run from the repository root (about a minute; the first call runs the workflow if it is not
up to date, which takes longer once)::

    .venv/bin/python benchmarks/bench_startup.py
    .venv/bin/python benchmarks/bench_startup.py --repeats 21 --workflow workflows/silverbox.toml

Each command is a fresh process (``python -m debist ...``, what a shell or a batch script
pays), timed wall-clock with :func:`time.perf_counter` around :func:`subprocess.run`, output
discarded; the commands take turns, so a slow spell of the machine hits all of them. Peers
measured in the same run: the bare interpreter (``python -c pass``) and the import of the
libraries every debist command needs (numpy, pydantic, typer and rich), the floor no CLI
built on them can go under. "cold cache" is the no-op run with an empty user cache
(:mod:`debist.core.cache`), i.e. the first command after an install or a code change.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = 1.0  # [s], the start-up target of a no-op run and of status


def _time(argv: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr}")
    return elapsed


def main() -> None:
    """Time the commands and print medians, ranges and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--workflow", default="workflows/silverbox.toml")
    args = parser.parse_args()
    py = sys.executable
    env = dict(os.environ)
    cold_env = dict(env)
    subprocess.run(
        [py, "-m", "debist", "run", args.workflow],
        cwd=ROOT,
        env=env,
        check=True,
        capture_output=True,
    )  # brings the run up to date and fills the user cache
    commands = {
        "python -c pass": [py, "-c", "pass"],
        "import numpy, pydantic, typer, rich": [
            py,
            "-c",
            "import numpy, pydantic, typer, rich.console",
        ],
        "debist status": [py, "-m", "debist", "status", args.workflow],
        "debist run (no-op)": [py, "-m", "debist", "run", args.workflow],
        "debist run (no-op), cold cache": [py, "-m", "debist", "run", args.workflow],
    }
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(args.repeats):
        for name, argv in commands.items():
            if "cold cache" in name:
                with tempfile.TemporaryDirectory() as empty:
                    cold_env["DEBIST_CACHE_DIR"] = empty
                    times[name].append(_time(argv, cold_env))
            else:
                times[name].append(_time(argv, env))
    floor = statistics.median(times["import numpy, pydantic, typer, rich"])
    print(f"{args.workflow}, {args.repeats} runs each, wall time of a fresh process [s]")
    print(f"{'command':34s} {'median':>7s} {'min':>6s} {'max':>6s} {'x floor':>8s}  target")
    for name, values in times.items():
        med = statistics.median(values)
        target = ""
        if name.startswith("debist") and "cold" not in name:
            target = f"{'met' if med < TARGET else 'MISSED'} (< {TARGET:g} s)"
        print(
            f"{name:34s} {med:7.3f} {min(values):6.3f} {max(values):6.3f} "
            f"{med / floor:8.2f}  {target}"
        )


if __name__ == "__main__":
    main()
