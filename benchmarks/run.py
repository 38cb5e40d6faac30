"""debist's end-to-end benchmark: the main job, the paper experiment and a fleet, optionally
against an older revision measured in the same run, and a scaling table.

Each job runs as a fresh ``debist`` process (``--force``, its own output folder), ``--runs``
times; the table gives per job the median wall time [s], the peak resident memory of the
``debist`` process [MiB] (``os.wait4``: the process itself, not its forked figure or Dask
workers) and the median of each stage's time (``<stage>/timings.json``). With ``--against
REV`` the revision is unpacked by ``git archive`` into a temporary folder and installed into a
temporary venv (``pip install '<src>[narx]'``), and both revisions' runs alternate
(new, old, new, old, ...), so the ratios new / old are taken at the same moment of the
machine. ``--scaling`` runs ingest to validate on one long virtual-rig record of 10^4, 10^5 and
10^6 samples (the paper experiment's rig, the identification profile; the rig's recording is
not timed) and prints time and peak memory per sample, and per sample between consecutive
lengths (the marginal cost: flat when the cost grows linearly).

Run from the repository root::

    python benchmarks/run.py                      # main job, paper experiment, fleet of 20
    python benchmarks/run.py --against 0a89952 --runs 3
    python benchmarks/run.py --jobs= --scaling                   # 10^4, 10^5, 10^6 samples
    python benchmarks/run.py --jobs paper --scaling 10000,100000

References
----------
Linux ``wait4(2)`` (``ru_maxrss`` in KiB); Python documentation, :mod:`statistics`.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[1]
JOBS = ("main", "paper", "fleet")
STAGES = ("rig", "ingest", "differentiate", "identify", "validate", "compare", "study", "report")


def _timed(cmd: list[str], cwd: Path) -> tuple[float, float]:
    """Run ``cmd``; return its wall time [s] and peak RSS [MiB]; raise on a failure."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr.read().decode()[-2000:]}")
    return wall, usage.ru_maxrss / 1024.0


def _stage_times(out: Path) -> dict[str, float]:
    """Each stage's wall time [s] from its timings.json (its 'stage' entry, else the sum)."""
    times = {}
    for stage in STAGES:
        path = out / stage / "timings.json"
        if path.is_file():
            t = json.loads(path.read_text())
            times[stage] = float(t.get("stage", sum(v for v in t.values() if isinstance(v, float))))
    return times


def _job(name: str, debist: str, work: Path, root: Path) -> tuple[float, float, dict[str, float]]:
    """Run one job once with the ``debist`` executable given; return wall, peak, stages."""
    out = work / f"{name}-{time.monotonic_ns()}"
    if name == "main":
        wf = root / "workflows" / "silverbox.toml"
        wall, peak = _timed([debist, "-q", "run", str(wf), "--out", str(out), "--force"], work)
        return wall, peak, _stage_times(out)
    if name == "paper":
        wf = root / "workflows" / "paper-experiment.toml"
        wall, peak = _timed([debist, "-q", "run", str(wf), "--out", str(out), "--force"], work)
        return wall, peak, _stage_times(out)
    # the fleet of 20: 10 full and 10 reduced prototypes of seed 1, one batch over both
    walls, peaks = [], []
    for kind, template in (("full", "paper-experiment"), ("reduced", "paper-experiment-reduced")):
        wf = root / "workflows" / f"{template}.toml"
        w, p = _timed([debist, "fleet", str(wf), "--size", "10", "--seed", "1",
                       "--dir", str(out / kind)], work)  # fmt: skip
        walls.append(w)
        peaks.append(p)
    w2, p2 = _timed([debist, "-q", "batch", str(out / "full"), str(out / "reduced"),
                     "--workers", "2"], work)  # fmt: skip
    return sum(walls) + w2, max(*peaks, p2), {"fleet": sum(walls), "batch": w2}


def _install(rev: str, work: Path) -> tuple[str, Path]:
    """Unpack ``rev`` with git archive and install it into a venv; return its debist, source."""
    src, venv = work / f"src-{rev}", work / f"venv-{rev}"
    src.mkdir()
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive.stdout, check=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet"]
    subprocess.run([*pip, f"{src}[narx]"], check=True)
    return str(venv / "bin" / "debist"), src


def _scaling(debist: str, work: Path, sizes: list[int]) -> list[dict[str, float]]:
    """Ingest to validate on one long identification record of each length [samples].

    The virtual rig records it first (not timed: it is the measurement, not the pipeline);
    then one ``debist run --until validate`` process is timed, the rig's record cached. Beside
    the cost per sample, the marginal cost per sample between consecutive lengths (the
    difference of wall time and peak over the difference of samples): a cost that grows
    linearly has a flat marginal cost, whatever its fixed part (imports, the kernels' load,
    the search's fixed grid).
    """
    base = tomllib.loads((ROOT / "workflows" / "paper-experiment.toml").read_text())
    rows: list[dict[str, float]] = []
    for n in sizes:
        wf = dict(base)
        dt = float(wf["rig"]["sample_time"])
        rig = dict(wf["rig"])
        rig["experiments"] = {"identification": {**rig["experiments"]["identification"],
                                                 "duration": n * dt}}  # fmt: skip
        wf["rig"] = rig
        wf["datasets"] = {"identification": {"rig": "identification", "role": "estimation"}}
        wf["workflow"] = {**wf["workflow"], "output_dir": str(work / f"scale-{n}")}
        for key in ("report", "study", "compare"):
            wf.pop(key, None)
        path = work / f"scale-{n}.toml"
        path.write_text(tomli_w.dumps(wf))
        _timed([debist, "-q", "run", str(path), "--until", "rig"], work)
        wall, peak = _timed([debist, "-q", "run", str(path), "--until", "validate"], work)
        row = {"samples": n, "wall_s": wall, "peak_mib": peak,
               "us_per_sample": 1e6 * wall / n, "kib_per_sample": 1024 * peak / n}  # fmt: skip
        if rows:
            prev = rows[-1]
            dn = n - prev["samples"]
            row["us_marginal"] = 1e6 * (wall - prev["wall_s"]) / dn
            row["kib_marginal"] = 1024 * (peak - prev["peak_mib"]) / dn
        rows.append(row)
    return rows


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its tables; return the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", default=",".join(JOBS), help="comma-separated: main, paper, fleet")
    ap.add_argument("--runs", type=int, default=3, help="runs per job and revision (median)")
    ap.add_argument("--against", help="an older revision to measure in the same run")
    ap.add_argument(
        "--scaling",
        nargs="?",
        const="10000,100000,1000000",
        default=None,
        help="also the scaling table, over these record lengths [samples] (default 10^4..10^6)",
    )
    args = ap.parse_args(argv)
    jobs = [j for j in args.jobs.split(",") if j]
    if set(jobs) - set(JOBS) or args.runs < 1:
        ap.error(f"--jobs from {', '.join(JOBS)}; --runs >= 1")
    new = shutil.which("debist") or str(Path(sys.executable).parent / "debist")
    with tempfile.TemporaryDirectory(prefix="debist-bench-") as tmp:
        work = Path(tmp)
        sides = {"new": (new, ROOT)}
        if args.against:
            sides["old"] = _install(args.against, work)
        results = {side: {job: [] for job in jobs} for side in sides}
        for job in jobs:
            for _ in range(args.runs):
                for side, (exe, root) in sides.items():  # alternate: new, old, new, old ...
                    results[side][job].append(_job(job, exe, work, root))
        print(f"{'job':6} {'side':4} {'wall [s]':>9} {'peak [MiB]':>11}  stages [s] (medians)")
        for job in jobs:
            for side in sides:
                runs = results[side][job]
                wall = _median([r[0] for r in runs])
                peak = _median([r[1] for r in runs])
                names = sorted({k for r in runs for k in r[2]}, key=lambda k: (k not in STAGES,
                               STAGES.index(k) if k in STAGES else 0))  # fmt: skip
                stages = ", ".join(f"{k} {_median([r[2][k] for r in runs if k in r[2]]):.2f}"
                                   for k in names)  # fmt: skip
                print(f"{job:6} {side:4} {wall:9.2f} {peak:11.1f}  {stages}")
            if "old" in sides:
                pairs = zip(results["new"][job], results["old"][job], strict=True)
                ratio = [(a[0] / b[0], a[1] / b[1]) for a, b in pairs]
                print(
                    f"{job:6} new/old wall {_median([r[0] for r in ratio]):.3f}, "
                    f"peak {_median([r[1] for r in ratio]):.3f} (paired medians)"
                )
        if args.scaling:
            print(f"\n{'samples':>9} {'wall [s]':>9} {'peak [MiB]':>11} {'us/sample':>10} "
                  f"{'KiB/sample':>11} {'marginal us/sample':>19} "
                  f"{'marginal KiB/sample':>20}")  # fmt: skip
            sizes = [int(x) for x in args.scaling.split(",")]
            for row in _scaling(new, work, sizes):
                marginal = (
                    f"{row['us_marginal']:19.2f} {row['kib_marginal']:20.3f}"
                    if "us_marginal" in row
                    else f"{'':19} {'':20}"
                )
                print(
                    f"{row['samples']:>9} {row['wall_s']:9.2f} {row['peak_mib']:11.1f} "
                    f"{row['us_per_sample']:10.2f} {row['kib_per_sample']:11.3f} {marginal}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
