"""Reading gzip-compressed rig logs: a cut or corrupt stream is named, not crashed on.

Every reader of text logs (format detection, the tail check, pandas itself) reads a gzip
file through :func:`open_gzip`. A stream cut short (a copy interrupted half-way) or
corrupt raises a :class:`~debist.errors.RigLogError` naming the file, where :mod:`gzip`
raises ``EOFError`` (which command-line frameworks take for end of input) or
``zlib.error``.

References
----------
Deutsch, RFC 1952 (gzip file format). Python documentation, :mod:`gzip` and
:class:`io.RawIOBase`.
"""

from __future__ import annotations

import gzip
import io
import zlib
from pathlib import Path

from debist.errors import RigLogError

__all__ = ["GzipLog", "open_gzip"]

_BUFFER = 1 << 20


class GzipLog(io.RawIOBase):
    """A gzip file read as a raw byte stream, its failures named.

    Parameters
    ----------
    path : pathlib.Path
        The gzip file.

    Raises
    ------
    RigLogError
        From :meth:`readinto`: naming the file, when the stream is cut short ("truncated
        gzip: ...") or corrupt ("corrupt gzip: ...").
    OSError
        If the file cannot be opened.

    References
    ----------
    Python documentation, :class:`io.RawIOBase` (``readinto``), :class:`gzip.GzipFile`.
    """

    def __init__(self, path: Path):
        super().__init__()
        self.path = Path(path)
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
        return n

    def close(self) -> None:
        """Close the gzip file."""
        if not self.closed:
            self._gz.close()
        super().close()


def open_gzip(path: Path) -> io.BufferedReader:
    """Open a gzip file for buffered binary reading through :class:`GzipLog`.

    Parameters
    ----------
    path : pathlib.Path
        The gzip file.

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
    """
    return io.BufferedReader(GzipLog(path), buffer_size=_BUFFER)
