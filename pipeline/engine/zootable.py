"""The zoo table: every member's free runs and curves against its truth, in one table.

After ``debist batch`` over a zoo folder (:mod:`debist.engine.zoo`), :func:`zoo_table` reads
each member's truth and its run's checked artifacts and gives one row per member:

- the unseen NRMSE(q) [%] (Eq. 41) of the identified model (``rbf``), the NARX peer and SINDy:
  the mean over the unseen records and the worst one (``inf`` where a free run diverged or
  the model is unstable; ``*_status`` says which),
  whether a free run rests in the wrong well for 0.5 s or more on an unseen record
  (``*_lost_switch``), whether an unseen record applies an input where the estimation
  record never did (``unseen_extrapolated``), the NARX structure (terms, lags, degree);
- the measurement floor [%]: the logged q against the true q (noise, quantisation, block
  averaging, sensor lag), on the estimation and the unseen records;
- per curve (``restoring``, ``g1``, ``g2``, per unit mass) the largest error where marked
  identified as a share of the true range [%], the share of those points inside the band
  [%], the points marked, and for ``g1``, ``g2`` whether they are marked within 2 mm of each
  well.

:func:`zoo_summary` gives the medians and worst cases, :func:`write_zoo_table` writes
``zoo.parquet`` into the zoo folder (the page ``zoo.html`` is :mod:`debist.report.zoo`'s).

References
----------
Masoud & Maas 2025, Eq. 37, 41; Wasserman 2006, Sec. 5.7 (band coverage).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from debist.core.artifacts import checked_output, read_manifest, read_summary
from debist.core.errors import ArtifactError
from debist.core.fileformats import read_parquet, write_output
from debist.engine.zooindex import ZooError, read_zoo
from debist.report.zoo import FLAGS
from debist.rig.truthscore import curve_score, lost_switch, marked_near

__all__ = [
    "CURVES",
    "MODELS",
    "PAGE_FILE",
    "TABLE_FILE",
    "WELL_DISTANCE",
    "write_zoo_table",
    "zoo_summary",
    "zoo_table",
]

#: Models of the free-run columns, as the NRMSE table names them.
MODELS = ("rbf", "narx", "sindy")
#: Curves scored against the truth.
CURVES = ("restoring", "g1", "g2")
#: A gain counts as identified at a well when marked within this distance of it [m].
WELL_DISTANCE = 2e-3
#: The zoo table's file and page in the zoo folder.
TABLE_FILE, PAGE_FILE = "zoo.parquet", "zoo.html"


def _stage(run: Path, stage: str):
    manifest = read_manifest(run / stage)
    if manifest is None:
        raise ArtifactError(f"'{run / stage}' has no manifest: the stage did not run")
    return run / stage, manifest


def _parquet(run: Path, stage: str, rel: str):
    folder, manifest = _stage(run, stage)
    return read_parquet(checked_output(folder, manifest, rel))


def _free_runs(run: Path, truth: dict, row: dict) -> None:
    """Unseen and estimation NRMSE per model, lost switches and the NARX structure."""
    folder, manifest = _stage(run, "compare")
    table = read_parquet(checked_output(folder, manifest, "nrmse.parquet"))
    summary = read_summary(folder, manifest)
    unseen = [n for n, r in truth["records"].items() if r["role"] == "validation"]
    for model in MODELS:
        part = table[table.model == model].set_index("dataset")
        scores = [_percent(part, name) for name in unseen]
        row[f"{model}_unseen"] = float(np.mean(scores)) if scores else np.nan
        row[f"{model}_unseen_max"] = float(np.max(scores)) if scores else np.nan
        row[f"{model}_estimation"] = _percent(part, "estimation")
        status = part.status.astype(str) if "status" in part else []
        row[f"{model}_status"] = "; ".join(sorted(set(status) - {"ok"})) or "ok"
    for model, stage, column in (("rbf", "validate", "q_sim"), ("narx", "compare", "q_sim_narx"),
                                 ("sindy", "compare", "q_sim")):  # fmt: skip
        row[f"{model}_lost_switch"] = _lost(run, stage, column, unseen, truth)
    beyond = table.loc[(table.model == "rbf") & table.dataset.isin(unseen)]
    row["unseen_extrapolated"] = bool(
        "extrapolated" in beyond and (beyond.extrapolated.fillna("").astype(str) != "").any()
    )
    narx = summary.get("narx") or {}
    row["narx_terms"] = narx.get("n_params", np.nan)
    row["narx_lag"] = narx.get("lag", np.nan)
    row["narx_degree"] = narx.get("degree", np.nan)


def _percent(part, name: str) -> float:
    """NRMSE(q) of one data set in percent; inf where there is no free run to score.

    A free run that diverged, or a model the validation calls unstable, has no finite
    NRMSE: it counts as the worst score (its ``*_status`` column says which).
    """
    if name not in part.index:
        return np.nan
    value = float(part.loc[name, "nrmse_q"])
    return 100.0 * value if np.isfinite(value) else np.inf


def _lost(run: Path, stage: str, column: str, unseen: list[str], truth: dict) -> bool | None:
    """Whether any unseen free run of a model rests in the wrong well (None: no free run)."""
    lost = []
    for name in unseen:
        try:
            sim = _parquet(run, stage, f"simulated/{name}.parquet")
        except ArtifactError:
            return None
        if column not in sim:
            return None
        t = sim.t.to_numpy()
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        lost.append(lost_switch(sim.q.to_numpy(), sim[column].to_numpy(), truth["barrier"], dt))
    return bool(any(lost))


def _curves(run: Path, member: Path, truth: dict, row: dict) -> None:
    """Each curve's error and band coverage where marked, and g_i near the wells."""
    curves = _parquet(run, "identify", "curves.parquet")
    folder, manifest = _stage(run, "identify")
    summary = read_summary(folder, manifest)
    m_q = float(summary.get("m_q_curves", summary.get("m_q", 1.0)))  # the curves' mass
    true = read_parquet(member / "truth.parquet")
    q = curves.q.to_numpy()
    for name in CURVES:
        est, lo, hi = (curves[c].to_numpy() / m_q for c in (name, f"{name}_lo", f"{name}_hi"))
        marked = curves[f"{name}_identified"].to_numpy()
        score = curve_score(q, est, lo, hi, marked, true.q.to_numpy(), true[name].to_numpy())
        row[f"{name}_marked"] = score.marked
        row[f"{name}_max_error"] = 100.0 * score.max_error
        row[f"{name}_coverage"] = 100.0 * score.coverage
        if name != "restoring":
            row[f"{name}_near_wells"] = marked_near(q, marked, truth["wells"], WELL_DISTANCE)


def _member_row(member: Path) -> dict[str, Any]:
    truth = json.loads((member / "truth.json").read_text(encoding="utf-8"))
    records = truth["records"]
    row: dict[str, Any] = {"member": member.name, **{
        k: truth["traits"][k] for k in ("plant", "friction", "slip_elements", "sensor_average",
                                        "sample_time", "estimation_profile")}}  # fmt: skip
    row["floor_estimation"] = float(records["estimation"]["floor_nrmse_q"])
    row["floor_unseen"] = float(np.mean([r["floor_nrmse_q"] for r in records.values()
                                         if r["role"] == "validation"]))  # fmt: skip
    run = member / "run"
    try:
        _free_runs(run, truth, row)
        _curves(run, member, truth, row)
        row["status"] = "done"
    except (ArtifactError, OSError, KeyError, ValueError) as exc:
        row["status"] = f"not scored: {exc}"
    return row


def zoo_table(folder: str | os.PathLike) -> Any:
    """Build the zoo table of a zoo whose members have run (``debist batch``).

    Parameters
    ----------
    folder : path-like
        The zoo folder (with ``zoo.json``).

    Returns
    -------
    pandas.DataFrame
        One row per member (columns: see the module docstring; NRMSE, errors and coverage
        in percent; ``status`` says ``"done"`` or why a member could not be scored).

    Raises
    ------
    ZooError
        If the folder is not a zoo.

    References
    ----------
    Masoud & Maas 2025, Eq. 41.
    """
    import pandas as pd

    folder = Path(folder)
    index = read_zoo(folder)
    if index is None:
        raise ZooError(f"'{folder}' is not a zoo folder (no zoo.json)")
    rows = [_member_row(folder / name) for name in index["members"]
            if (folder / name / "truth.json").is_file()]  # fmt: skip
    frame = pd.DataFrame(rows)
    frame.attrs = {"zoo": {"seed": index["seed"], "version": index["version"]},
                   "units": "NRMSE(q), errors and coverage in percent"}  # fmt: skip
    return frame


def zoo_summary(table: Any) -> Any:
    """Medians and worst cases of a zoo table's numeric columns.

    Parameters
    ----------
    table : pandas.DataFrame
        From :func:`zoo_table`.

    Returns
    -------
    pandas.DataFrame
        Rows ``median`` (a member without a free run, inf, counts as the worst score, so
        the median is inf once half the members have none), ``worst`` (the largest NRMSE or
        error, the smallest coverage; for the boolean columns the count of True, and no
        median), ``count`` (members with a value) and ``no_free_run`` (members whose value is
        inf), one column per numeric column of the table.
    """
    import pandas as pd

    out = {}
    for column in table.columns:
        values = table[column]
        if values.dtype == bool or column.endswith(FLAGS):
            flags = values.dropna().astype(bool)
            out[column] = {"median": np.nan, "worst": float(flags.sum()), "count": len(flags)}
        elif pd.api.types.is_numeric_dtype(values.dtype):
            worst = values.min() if column.endswith("_coverage") else values.max()
            out[column] = {"median": float(values.median()), "worst": float(worst),
                           "count": int(values.notna().sum()),
                           "no_free_run": int(np.isinf(values).sum())}  # fmt: skip
    return pd.DataFrame(out)


def write_zoo_table(folder: str | os.PathLike) -> tuple[Path, Any]:
    """Build the zoo table and write it as ``zoo.parquet`` into the zoo folder.

    Parameters
    ----------
    folder : path-like
        The zoo folder.

    Returns
    -------
    path : pathlib.Path
        The table written.
    table : pandas.DataFrame
        The table (:func:`zoo_table`).

    Raises
    ------
    ZooError
        If the folder is not a zoo.
    """
    folder = Path(folder)
    table = zoo_table(folder)
    write_output(table, folder / TABLE_FILE)
    return folder / TABLE_FILE, table
