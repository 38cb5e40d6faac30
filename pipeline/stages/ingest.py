"""The ingest stage: every data set's rig log read into a canonical table."""

from __future__ import annotations

import importlib
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import lazy_loader as lazy

from debist.core.errors import recording_warnings
from debist.ingest.cache import RawLogCache
from debist.ingest.load import load_rig_log, read_raw
from debist.ingest.sensors import one_range_warning
from debist.ingest.spec import IngestSpec
from debist.stages import StageInputs, StageOutput

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

if TYPE_CHECKING:
    from debist.workflow.loader import DatasetSpec

__all__ = ["execute", "preload", "run_ingest"]


def preload(ctx: StageInputs) -> None:
    """Load the libraries of the tables the stage builds and writes: pandas, pyarrow's Parquet.

    The runner calls it ahead of the stage, while a stage before it waits on its worker
    processes (:meth:`debist.engine.runner.Runner.load_ahead`). Loads nothing else, decides
    nothing.

    Parameters
    ----------
    ctx : StageInputs
        Not read: what the stage loads does not depend on the workflow.
    """
    del ctx
    pd.DataFrame  # noqa: B018 (loads the lazy module)
    importlib.import_module("pyarrow.parquet")


def run_ingest(
    datasets: Sequence[DatasetSpec], base: str | os.PathLike | None = None
) -> dict[str, pd.DataFrame]:
    """Read every data set into a canonical rig-log table.

    Parameters
    ----------
    datasets : sequence of DatasetSpec
        Data sets with their merged ingest sections.
    base : path-like, optional
        The workflow's folder: ``attrs["source"]`` records each source path relative to
        it (POSIX separators), so the same workflow in two clones gives the same bytes; a
        virtual-rig log is recorded as ``"rig:<experiment>"``. Default: the path as read.

    Each source file is read once, however many data sets name it
    (:class:`debist.ingest.cache.RawLogCache`).

    Returns
    -------
    dict of str to pandas.DataFrame
        Table name to table (``t [s], q, v1..vN [V], ...``). A data set split at
        logging gaps gives ``<name>.seg<k>`` tables, each with the same role.

    Raises
    ------
    RigLogError
        For a file or channel that cannot be used (names file and channel).
    WorkflowError
        For an invalid ingest section.
    """
    tables: dict[str, pd.DataFrame] = {}
    cache = RawLogCache(read_raw, [ds.source for ds in datasets])
    with one_range_warning():  # a sensor's documented range: one line naming every file
        for ds in datasets:
            spec = IngestSpec.from_dict(ds.ingest)
            segments = load_rig_log(ds.source, spec, cache)
            for k, frame in enumerate(segments):
                name = ds.name if len(segments) == 1 else f"{ds.name}.seg{k}"
                frame.attrs["role"] = ds.role
                frame.attrs["dataset"] = ds.name
                frame.attrs["source"] = _recorded_source(ds, base)
                tables[name] = frame
    return tables


def _recorded_source(ds: DatasetSpec, base: str | os.PathLike | None) -> str:
    if ds.rig:
        return f"rig:{ds.rig}"
    if base is None:
        return str(ds.source)
    return Path(os.path.relpath(ds.source, base)).as_posix()


def execute(ctx: StageInputs) -> StageOutput:
    """Run the ingest stage on the workflow's data sets.

    Parameters
    ----------
    ctx : StageInputs
        The workflow (data sets, their sources and ingest sections).

    Returns
    -------
    StageOutput
        ``<table>.parquet`` per table; summary: samples per table and, when there were
        any, the messages of the warnings ingest gave (a stroke implausible for the
        declared unit, a sensor's default range, a unit the file declares otherwise).

    Raises
    ------
    RigLogError, WorkflowError
        As :func:`run_ingest`.
    """
    with recording_warnings() as notes:
        tables = run_ingest(ctx.wf.datasets, ctx.wf.path.parent)
    summary: dict = {"datasets": {n: len(f) for n, f in tables.items()}}
    if notes:  # the sources as recorded (relative), so that clones give the same bytes
        for ds in ctx.wf.datasets:
            recorded = _recorded_source(ds, ctx.wf.path.parent)
            notes = [n.replace(f"'{ds.source}'", f"'{recorded}'") for n in notes]
        summary["warnings"] = notes
    return StageOutput({f"{n}.parquet": f for n, f in tables.items()}, summary)
