"""debist's NARX peer against a direct SysIdentPy fit on every member of a plant zoo.

For each member of a zoo that has run (``debist zoo`` then ``debist batch``), the NARX model is
fitted on the estimation record's ingested table and run free on the unseen records, once by
debist (:func:`debist.model.narx.fit_narx` with the settings given) and once by SysIdentPy
itself, as a user would call it: ``FROLS`` with a ``Polynomial`` basis of degree 3, lags 3,
the inputs ``v1^2, v2^2``, AIC, ``n_info_values = 40``, on ``q`` [mm] and ``v`` [kV] as
logged. Prints per member
the unseen NRMSE(q) [%] (mean over the unseen records; ``inf`` for a diverged run) of both and
their ratio, and the largest ratio.

A polynomial NARX fitted on raw ``q`` depends on where the sensor's zero lies; debist's row
does not (its origins move with the data). ``--shifts`` refits the direct model with the
sensor's zero moved by each given amount [m] and prints the direct fit's lowest, median and
highest unseen NRMSE(q) over them, and debist's ratio to that median: how far the yardstick
itself moves with a choice no rig makes on purpose.

Run from the repository root::

    python benchmarks/narx_peer.py /path/to/zoo [--set info_criteria=bic ...]
    python benchmarks/narx_peer.py /path/to/zoo --shifts=-5e-4,-1e-4,1e-4,5e-4
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from debist.core.metrics import nrmse
from debist.model.narx import NarxConfig, _sysidentpy, fit_narx


def _inputs(frame: pd.DataFrame) -> np.ndarray:
    return frame[[c for c in frame.columns if c.startswith("v")]].to_numpy() ** 2


def _score(q: np.ndarray, sim: np.ndarray, skip: int) -> float:
    if not np.all(np.isfinite(sim[skip:])) or np.max(np.abs(sim[skip:])) > 0.05:
        return np.inf
    return 100.0 * nrmse(q[skip:], sim[skip:])


def direct_sysidentpy(est: pd.DataFrame, unseen: list[pd.DataFrame]) -> list[float]:
    """SysIdentPy's FROLS as documented, on q and v as logged (mm, kV); unseen NRMSE(q) [%]."""
    FROLS, Polynomial, LeastSquares = _sysidentpy()
    model = FROLS(order_selection=True, n_info_values=40, info_criteria="aic", ylag=3,
                  xlag=[[1, 2, 3], [1, 2, 3]], basis_function=Polynomial(degree=3),
                  estimator=LeastSquares(), model_type="NARMAX")  # fmt: skip
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X=1e-6 * _inputs(est), y=1e3 * est.q.to_numpy()[:, None])
        out = []
        for frame in unseen:
            q = 1e3 * frame.q.to_numpy()
            sim = model.predict(X=1e-6 * _inputs(frame), y=q[: model.max_lag, None])[:, 0]
            out.append(_score(1e-3 * q, 1e-3 * sim, model.max_lag))
    return out


def debist_narx(est: pd.DataFrame, unseen: list[pd.DataFrame], cfg: NarxConfig) -> tuple:
    """debist's NARX peer; unseen NRMSE(q) [%] per record, and the model."""
    v = est[[c for c in est.columns if c.startswith("v")]].to_numpy()
    model = fit_narx([est.q.to_numpy()], [v], "v2", cfg, q_limit=0.05)
    out = []
    for frame in unseen:
        q = frame.q.to_numpy()
        v = frame[[c for c in frame.columns if c.startswith("v")]].to_numpy()
        sim, _ = model.simulate(q, v)
        out.append(_score(q, sim, model.max_lag))
    return out, model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("zoo", type=Path)
    parser.add_argument("--set", action="append", default=[], help="NarxConfig KEY=VALUE")
    parser.add_argument("--shift", type=float, default=0.0, help="add this to every q [m]")
    parser.add_argument("--shifts", default="", help="comma-separated sensor-zero moves [m]")
    args = parser.parse_args()
    settings = {}
    for item in args.set:
        key, value = item.split("=", 1)
        settings[key] = json.loads(value) if value[:1] in "[{0123456789-" else value
    cfg = NarxConfig.from_dict(settings)
    shifts = [float(x) for x in args.shifts.split(",") if x.strip()]
    index = json.loads((args.zoo / "zoo.json").read_text())
    rows = []
    for name in index["members"]:
        ingest = args.zoo / name / "run" / "ingest"
        truth = json.loads((args.zoo / name / "truth.json").read_text())
        unseen_names = [n for n, r in truth["records"].items() if r["role"] == "validation"]
        if not (ingest / "estimation.parquet").is_file():
            continue
        names = ["estimation", *unseen_names]
        frames = {n: pd.read_parquet(ingest / f"{n}.parquet") for n in names}
        for f in frames.values():
            f["q"] = f["q"] + args.shift
        unseen = [frames[n] for n in unseen_names]
        ours, model = debist_narx(frames["estimation"], unseen, cfg)
        direct = direct_sysidentpy(frames["estimation"], unseen)
        a, b = float(np.mean(ours)), float(np.mean(direct))
        row = {"member": name, "debist": a, "direct": b, "ratio": a / b,
               "terms": model.n_params, "lag": model.lag}  # fmt: skip
        if shifts:
            moved = [b]
            for dq in shifts:
                frames_dq = [f.assign(q=f.q + dq) for f in (frames["estimation"], *unseen)]
                moved.append(float(np.mean(direct_sysidentpy(frames_dq[0], frames_dq[1:]))))
            low, mid, high = np.min(moved), np.median(moved), np.max(moved)
            with np.errstate(invalid="ignore"):  # both diverged: NaN, counted as within
                row |= {"direct_min": low, "direct_median": mid, "direct_max": high,
                        "ratio_to_median": a / mid}  # fmt: skip
        rows.append(row)
    table = pd.DataFrame(rows)
    print(table.round(3).to_string(index=False))
    finite = table.replace([np.inf], np.nan)
    diverged = {k: int(np.isinf(table[k]).sum()) for k in ("debist", "direct")}
    print(f"median debist {finite.debist.median():.2f} %, direct {finite.direct.median():.2f} %; "
          f"worst ratio {table.ratio.max():.2f}; diverged {diverged}")  # fmt: skip
    if shifts:
        low, high = table.direct_min, table.direct_max
        moved = int(((high > 1.5 * low) & ~(np.isinf(low) & np.isinf(high))).sum())
        print(f"the direct fit moves by more than 1.5x with the sensor zero on {moved} of "
              f"{len(table)} members; debist above 1.5x the direct median on "
              f"{int((table.ratio_to_median > 1.5).sum())}")  # fmt: skip


if __name__ == "__main__":
    main()
