"""Reading gzip-compressed rig logs within bounds: cut streams and bombs named, not crashed.

A gzip stream does not say how large it decompresses to (the trailer's ``ISIZE`` is the
size modulo 2^32 and anyone can write it), and deflate expands up to about 1032 times
(RFC 1951), so a 2 MB file may hold 3 GB of text. :func:`open_gzip` therefore counts the
decompressed bytes as they are read and stops at :func:`decompressed_limit`: the memory
budget divided by :data:`~debist.core.preflight.TEXT_PARSE_RATIO`, the most memory
pandas needs per byte of text. Every reader of text logs (format detection, the tail
check, pandas itself) reads through it, so the limit holds whoever reads, and a bomb is
refused after reading at most the limit, long before memory runs out.

A stream cut short (a copy interrupted half-way) or corrupt raises a
:class:`~debist.core.errors.RigLogError` naming the file, where :mod:`gzip` raises
``EOFError`` (which command-line frameworks take for end of input) or ``zlib.error``.

References
----------
Deutsch, RFC 1951 (deflate) and RFC 1952 (gzip file format; ``ISIZE``). Python
documentation, :mod:`gzip` and :class:`io.RawIOBase`.
"""

from __future__ import annotations

import gzip
import io
import zlib
from pathlib import Path

from debist.core.errors import RigLogError
from debist.core.preflight import BUDGET_ENV, TEXT_PARSE_RATIO, format_bytes, memory_budget

__all__ = ["GzipLog", "decompressed_limit", "open_gzip"]

_BUFFER = 1 << 20


def decompressed_limit() -> int:
    """Return the most bytes a gzip-compressed text log may decompress to.

    Returns
    -------
    int
        :func:`~debist.core.preflight.memory_budget` divided by
        :data:`~debist.core.preflight.TEXT_PARSE_RATIO` [bytes].

    Raises
    ------
    WorkflowError
        If ``DEBIST_MEMORY_BUDGET_GB`` is set but not a positive number.
    """
    return memory_budget() // TEXT_PARSE_RATIO


class GzipLog(io.RawIOBase):
    """A gzip file read as a raw byte stream, its decompressed size bounded.

    Parameters
    ----------
    path : pathlib.Path
        The gzip file.
    limit : int
        Most decompressed bytes that may be read [bytes].

    Raises
    ------
    RigLogError
        From :meth:`readinto`: naming the file, when the stream is cut short ("truncated
        gzip: ..."), corrupt ("corrupt gzip: ...") or decompresses to more than ``limit``.
    OSError
        If the file cannot be opened.

    References
    ----------
    Python documentation, :class:`io.RawIOBase` (``readinto``), :class:`gzip.GzipFile`.
    """

    def __init__(self, path: Path, limit: int):
        super().__init__()
        self.path = Path(path)
        self.limit = int(limit)
        self.count = 0
        self._gz = gzip.open(self.path, "rb")  # noqa: SIM115 (closed by close())

    def readable(self) -> bool:
        """Return True: the stream is read, never written."""
        return True

    def readinto(self, buffer) -> int:
        """Decompress into ``buffer``; return the bytes written (0 at the end).

        Parameters
        ----------
        buffer : writable bytes-like object
            Where the decompressed bytes go.

        Returns
        -------
        int
            Bytes written into ``buffer``.

        Raises
        ------
        RigLogError
            See the class.
        """
        try:
            n = self._gz.readinto(buffer)
        except EOFError as exc:
            raise RigLogError(
                f"truncated gzip: {exc}; the file was cut short, e.g. by an interrupted copy",
                path=self.path,
            ) from None
        except (gzip.BadGzipFile, zlib.error) as exc:
            raise RigLogError(f"corrupt gzip: {exc}", path=self.path) from None
        self.count += n
        if self.count > self.limit:
            raise RigLogError(
                f"gzip stream decompresses to more than {format_bytes(self.limit)}, the "
                f"largest text log the memory budget of {format_bytes(memory_budget())} can "
                f"parse ({TEXT_PARSE_RATIO} bytes per byte of text; {BUDGET_ENV} sets the "
                "budget): a compression bomb or a log too large for this machine",
                path=self.path,
            )
        return n

    def close(self) -> None:
        """Close the gzip file."""
        if not self.closed:
            self._gz.close()
        super().close()


def open_gzip(path: Path, limit: int | None = None) -> io.BufferedReader:
    """Open a gzip file for buffered binary reading, bounded as :class:`GzipLog`.

    Parameters
    ----------
    path : pathlib.Path
        The gzip file.
    limit : int, optional
        Most decompressed bytes [bytes]; :func:`decompressed_limit` by default.

    Returns
    -------
    io.BufferedReader
        The decompressed bytes.

    Raises
    ------
    RigLogError
        While reading: see :class:`GzipLog`.
    OSError
        If the file cannot be opened.
    WorkflowError
        If ``DEBIST_MEMORY_BUDGET_GB`` is set but not a positive number.
    """
    cap = decompressed_limit() if limit is None else limit
    return io.BufferedReader(GzipLog(path, cap), buffer_size=_BUFFER)
