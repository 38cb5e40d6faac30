"""Read each rig log once per ingest stage, however many data sets name it.

Several data sets often cut one long recording (the Silverbox workflow reads four slices
of one 105 MB CSV); parsing it four times costs minutes. :class:`RawLogCache` keeps the
unmapped :class:`~debist.ingest.raw.RawLog` of a file for as long as data sets still
need it. The key is the resolved path, the file's modification time and size (a file
rewritten in between is read again) and the read options of the ingest spec (``format``,
``delimiter``, ``decimal``, ``header``): two data sets reading one file with different
options read it twice.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from debist.ingest.raw import RawLog
    from debist.ingest.spec import IngestSpec

__all__ = ["RawLogCache", "cache_key"]

Key = tuple[str, int, int, str, str, str, str]


def cache_key(path: Path, spec: IngestSpec) -> Key | None:
    """Return the key of a read, or None when the file cannot be stat'ed.

    Parameters
    ----------
    path : Path
        The rig log.
    spec : IngestSpec
        For its read options ``format``, ``delimiter``, ``decimal`` and ``header``.

    Returns
    -------
    tuple or None
        ``(resolved path, mtime [ns], size [bytes], format, delimiter, decimal, header)``;
        None for a missing or unreadable file (the reader then reports it).
    """
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return (
        str(Path(path).resolve()),
        stat.st_mtime_ns,
        stat.st_size,
        spec.format,
        spec.delimiter,
        spec.decimal,
        str(spec.header),
    )


class RawLogCache:
    """The raw logs of one ingest stage call, each read once.

    Parameters
    ----------
    reader : callable
        ``reader(path, spec) -> RawLog``, e.g. :func:`debist.ingest.load.read_raw`.
    sources : iterable of path-like, optional
        Every source the stage will read, one entry per data set: a log is dropped from
        memory after its last use. Without it logs are kept until the cache is dropped.

    Examples
    --------
    >>> calls = []
    >>> cache = RawLogCache(lambda path, spec: calls.append(path) or path)
    >>> spec = type("S", (), {"format": "auto", "delimiter": "auto", "decimal": "auto",
    ...                       "header": None})()
    >>> cache.read(Path(__file__), spec) == cache.read(Path(__file__), spec), len(calls)
    (True, 1)
    """

    def __init__(
        self,
        reader: Callable[[Path, IngestSpec], RawLog],
        sources: Iterable[str | os.PathLike[str]] | None = None,
    ) -> None:
        self._reader = reader
        self._logs: dict[Key, RawLog] = {}
        self._left = None if sources is None else Counter(str(Path(s).resolve()) for s in sources)

    def read(self, path: Path, spec: IngestSpec) -> RawLog:
        """Return the raw log of a file, reading it on the first request only.

        Parameters
        ----------
        path : Path
            The rig log.
        spec : IngestSpec
            Its read options are part of the key.

        Returns
        -------
        RawLog
            As the reader returns it (shared between data sets: never modify it).

        Raises
        ------
        RigLogError
            As the reader.
        """
        key = cache_key(path, spec)
        if key is None:
            return self._reader(path, spec)
        log = self._logs.get(key)
        if log is None:
            log = self._reader(path, spec)
            self._logs[key] = log
        if self._left is not None:
            self._left[key[0]] -= 1
            if self._left[key[0]] <= 0:
                for k in [k for k in self._logs if k[0] == key[0]]:
                    del self._logs[k]
        return log
