"""Reader of Parquet rig logs via pyarrow.

Every top-level column is a channel, selectable by name or 0-based ``column`` index.
A column's field metadata key ``unit`` (bytes), when present, is the unit the file
declares and is checked against the ingest spec like a dSPACE ``Unit``. Timestamp and
duration columns are converted to seconds (since the Unix epoch for timestamps) and
declare the unit ``s``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from debist.core.errors import RigLogError
from debist.ingest.raw import RawChannel, RawLog

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["read_parquet"]


def _channel(field: pa.Field, column: pa.ChunkedArray) -> RawChannel:
    unit = None
    if field.metadata and b"unit" in field.metadata:
        unit = field.metadata[b"unit"].decode("utf-8", "replace")
    data = column.to_numpy()
    if data.dtype.kind in "mM":
        integers = data.astype(f"{data.dtype.str[:2]}8[ns]").astype(np.int64)
        data = np.where(np.isnat(data), np.nan, integers * 1e-9)
        unit = "s"
    return RawChannel(field.name, data, unit)


def read_parquet(path: Path) -> RawLog:
    """Read a Parquet rig log.

    Parameters
    ----------
    path : Path
        The file.

    Returns
    -------
    RawLog
        One channel per column, in schema order.

    Raises
    ------
    RigLogError
        pyarrow cannot read the file (truncated footer, corrupt pages); its message is
        quoted and the exception chained.
    """
    import pyarrow as pa  # here, not at the top: pyarrow takes 0.15 s to load
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
        channels = tuple(_channel(field, table.column(i)) for i, field in enumerate(table.schema))
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise RigLogError(
            f"cannot read Parquet file, it is truncated or corrupt ({type(exc).__name__}: {exc})",
            path=path,
        ) from exc
    return RawLog(path, "parquet", channels, by_column=True)
