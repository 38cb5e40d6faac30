"""Two runs side by side: the settings and the NRMSE rows that differ (dvc's params/metrics diff).

Reads only the runs' manifests (the resolved configuration each stage ran with) and their
NRMSE tables (``compare/nrmse.parquet``, else ``validate/nrmse.parquet``). Settings are
compared after each side's defaults are filled in (:func:`debist.workflow.defaults.
with_defaults`), and numbers by value (``2`` and ``2.0`` are the same setting).

References
----------
dvc's ``params diff`` and ``metrics diff`` (https://dvc.org/doc/command-reference); Masoud &
Maas 2025, Eq. 41 (NRMSE).
"""

from __future__ import annotations

import glob
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import lazy_loader as lazy

from debist.core import artifacts
from debist.core.errors import WorkflowError
from debist.stages.registry import names
from debist.workflow.defaults import with_defaults
from debist.workflow.overrides import SET_FOLDER

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["NRMSE_COLUMNS", "diff_runs", "is_run", "set_run_beside"]

#: NRMSE columns compared, each reported in percent.
NRMSE_COLUMNS = ("nrmse_q", "nrmse_q_dot", "nrmse_q_ddot", "nrmse_q_k")


def _flat(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flat(value, f"{name}."))
        else:
            out[name] = value
    return out


def is_run(folder: str | Path) -> bool:
    """Return whether a folder holds the manifest of at least one stage (a debist run).

    Parameters
    ----------
    folder : path-like
        A folder, which need not exist.

    Returns
    -------
    bool
    """
    folder = Path(folder)
    return folder.is_dir() and any((folder / s / artifacts.MANIFEST).is_file() for s in names())


def set_run_beside(folder: str | Path) -> Path | None:
    """Return the run with ``--set`` overrides beside a folder, if there is one.

    A run with overrides and no ``--out`` goes to ``<folder>.set-<8 hex>`` beside the
    workflow's output folder (:data:`debist.workflow.overrides.SET_FOLDER`); a user who names
    ``<folder>`` may mean it. Of several, the one modified last.

    Parameters
    ----------
    folder : path-like
        The folder the user named (it need not exist).

    Returns
    -------
    pathlib.Path or None
        ``folder`` with the name of that run (spelt as ``folder`` is: relative stays
        relative), or None when no such run lies beside it.

    Examples
    --------
    >>> set_run_beside("/nonexistent/runs/rig") is None
    True
    """
    folder = Path(folder)
    parent = folder.parent if folder.name else folder
    pattern = SET_FOLDER.format(name=glob.escape(folder.name), digest="[0-9a-f]" * 8)
    try:
        found = [p for p in parent.glob(pattern) if is_run(p)]
    except OSError:  # an unreadable parent: nothing to suggest
        return None
    if not found:
        return None
    newest = max(found, key=lambda p: (p.stat().st_mtime, p.name))
    return folder.with_name(newest.name)


def _nrmse(run: Path) -> pd.DataFrame | None:
    for stage in ("compare", "validate"):
        path = run / stage / "nrmse.parquet"
        if path.is_file():
            return artifacts.read_parquet(path)
    return None


def _number_free(value: Any) -> Any:
    """Numbers as floats (``2`` and ``2.0`` alike), recursively; booleans stay booleans."""
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, Mapping):
        return {k: _number_free(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_number_free(v) for v in value]
    return value


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    canon = artifacts.canonical_json
    return canon(_number_free(a)) == canon(_number_free(b))


def diff_runs(run_a: str | Path, run_b: str | Path) -> dict[str, list[dict[str, Any]]]:
    """Compare two output folders: settings per stage and NRMSE per data set and model.

    Parameters
    ----------
    run_a, run_b : path-like
        Output folders of two runs (``[workflow] output_dir``).

    Returns
    -------
    dict
        ``"config"``: rows ``{stage, key, a, b}`` for every setting that differs once
        both sides' defaults are filled in (a stage only one run has shows ``key =
        "(stage)"``); ``"nrmse"``: rows ``{dataset, model,
        metric, a, b, change}`` with the NRMSE in percent [%] (None where a run lacks the
        row), for every value that differs.

    Raises
    ------
    WorkflowError
        If a folder does not exist or holds no stage manifest; the message names the run
        with ``--set`` overrides beside it, if there is one (:func:`set_run_beside`).
    """
    runs = [Path(run_a), Path(run_b)]
    for run in runs:
        if not is_run(run):
            beside = set_run_beside(run)
            hint = f"; did you mean '{beside}' (a run with --set overrides)?" if beside else ""
            raise WorkflowError(
                f"'{run}' is not an output folder of a debist run (no manifests){hint}"
            )
    config = []
    for stage in names():
        found = [artifacts.read_manifest(run / stage) for run in runs]
        if all(m is None for m in found):
            continue
        if any(m is None for m in found):
            config.append(
                {"stage": stage, "key": "(stage)", "a": found[0] is not None,
                 "b": found[1] is not None}
            )  # fmt: skip
            continue
        a, b = (_flat(with_defaults(stage, m.config)) for m in found)
        for key in sorted(set(a) | set(b)):
            if not _same(a.get(key), b.get(key)):
                config.append({"stage": stage, "key": key, "a": a.get(key), "b": b.get(key)})
    tables = [_nrmse(run) for run in runs]
    rows = []
    if all(t is not None for t in tables):
        keyed = [
            {(r["dataset"], r["model"]): r for r in t.to_dict(orient="records")} for t in tables
        ]
        for dataset, model in sorted(set(keyed[0]) | set(keyed[1])):
            for metric in NRMSE_COLUMNS:
                va, vb = (k.get((dataset, model), {}).get(metric) for k in keyed)
                va, vb = (None if v is None or pd.isna(v) else 100 * float(v) for v in (va, vb))
                if va == vb:  # both absent, or equal
                    continue
                change = vb - va if va is not None and vb is not None else None
                rows.append(
                    {"dataset": dataset, "model": model, "metric": f"{metric} [%]",
                     "a": va, "b": vb, "change": change}
                )  # fmt: skip
    return {"config": config, "nrmse": rows}
