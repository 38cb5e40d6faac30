"""Reading one rig log: detect its format, read its channels, map, check and resample them.

:func:`load_rig_log` is what the ingest stage calls for each data set; :func:`read_raw` lists
what a file holds before a channel mapping is written. See :mod:`debist.ingest` for the
modules it composes.

References
----------
The user documentation of the accepted formats, the channel mapping and the units is
``data/README.md`` of the repository.
"""

from __future__ import annotations

import os
from pathlib import Path

import lazy_loader as lazy

from debist.core.units import UNITS
from debist.ingest.assemble import assemble, to_frame
from debist.ingest.cache import RawLogCache
from debist.ingest.channels import map_channels
from debist.ingest.detect import detect_format
from debist.ingest.mat import read_mat
from debist.ingest.mf4 import read_mf4
from debist.ingest.parquet import read_parquet
from debist.ingest.raw import RawLog
from debist.ingest.spec import FORMATS, ChannelSpec, IngestSpec, ResampleSpec
from debist.ingest.text import read_text

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "RIG_LOG_FORMATS",
    "UNITS",
    "ChannelSpec",
    "IngestSpec",
    "RawLogCache",
    "ResampleSpec",
    "detect_format",
    "load_rig_log",
    "read_raw",
]

#: Accepted values of the ``format`` key: ``("auto", "mat", "csv", "parquet", "mf4")``.
RIG_LOG_FORMATS: tuple[str, ...] = FORMATS


def read_raw(path: Path, spec: IngestSpec) -> RawLog:
    """Detect the format of a rig log and read all its channels, unmapped.

    Parameters
    ----------
    path : Path
        The rig log.
    spec : IngestSpec
        For ``format``, ``delimiter``, ``decimal`` and ``header``.

    Returns
    -------
    RawLog
        The channels as stored (see :mod:`debist.ingest.raw`); useful to list what a
        file holds before writing the channel mapping.

    Raises
    ------
    RigLogError
        Missing, empty, truncated or corrupt file; content contradicting ``format``.
    """
    fmt = detect_format(path, spec.format)
    if fmt.startswith("mat"):
        return read_mat(path, fmt)
    if fmt == "parquet":
        return read_parquet(path)
    if fmt == "mf4":
        return read_mf4(path)
    return read_text(path, spec.delimiter, spec.header, spec.decimal)


def load_rig_log(
    path: str | os.PathLike[str], spec: IngestSpec, cache: RawLogCache | None = None
) -> list[pd.DataFrame]:
    r"""Read a rig log into canonical tables, one per gap-free segment.

    Parameters
    ----------
    path : str or os.PathLike
        The rig log: MAT (dSPACE recording or plain variables), text, Parquet or MF4
        (docs/reference/formats.md); detected from the content unless ``spec.format``.
    spec : IngestSpec
        From :meth:`IngestSpec.from_dict`.
    cache : RawLogCache, optional
        Shares the reading of a file between calls; None reads the file.

    Returns
    -------
    list of pandas.DataFrame
        One per gap-free segment (one with ``gaps = "error"``): ``t`` [s], ``q``, ``v1 ...
        vN``, extra channels, float64 in SI units; ``attrs`` the units, source channels,
        format and segments (docs/reference/formats.md).

    Raises
    ------
    RigLogError
        Naming the file (and channel, value): an unreadable file, a missing or ambiguous
        channel, a wrong unit, a bad value or time, a gap under ``gaps = "error"``, an
        empty selection, no time, channels on several rasters without ``resample``.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     log = Path(tmp) / "log.csv"
    ...     _ = log.write_text("t,x,u\n0,1,2\n1,2,3\n2,3,4\n3,4,5\n")
    ...     spec = IngestSpec.from_dict({"time": {"name": "t", "unit": "ms"},
    ...         "q": {"name": "x", "unit": "mm"}, "v1": {"name": "u", "unit": "kV"}})
    ...     (frame,) = load_rig_log(log, spec)
    >>> frame.to_numpy().tolist()[1]
    [0.001, 0.002, 3000.0]
    >>> frame.attrs["units"]
    {'t': 's', 'q': 'm', 'v1': 'V'}
    """
    path = Path(path)
    log = read_raw(path, spec) if cache is None else cache.read(path, spec)
    mapped = map_channels(log, spec)
    segments, time_source = assemble(mapped, spec, path)
    return [
        to_frame(
            segment,
            number=i,
            n_segments=len(segments),
            mapped=mapped,
            spec=spec,
            path=path,
            fmt=log.format,
            time_source=time_source,
        )
        for i, segment in enumerate(segments)
    ]
