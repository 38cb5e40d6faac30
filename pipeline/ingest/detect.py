r"""Detection of a rig log's format from its first bytes ("magic bytes").

Content decides; the file extension only breaks a tie when the content is binary and
carries no known signature (a MAT v4 file has no header). A file whose content
contradicts its extension is read by its content.

Signatures
----------
- MAT v5/v7 (``"mat-v5"``): a 116-byte text header starting ``MATLAB 5.0 MAT-file``
  (or ``MATLAB 7.0``), 8 bytes of subsystem offset, the version ``0x0100`` and the
  endian indicator ``IM`` (little-endian) or ``MI`` at bytes 124-127.
- MAT v7.3 (``"mat-v7.3"``): the same header with version ``0x0200``, followed by an
  HDF5 file whose signature ``\x89HDF\r\n\x1a\n`` sits at offset 512 (the header is
  the HDF5 user block).
- Parquet (``"parquet"``): ``PAR1`` at the start (and at the end).
- ASAM MDF (``"mf4"``, versions 3 and 4): the file identifier ``MDF     `` (or
  ``UnFinMF `` for a file not finalised) in the first 8 bytes.
- Text (``"csv"``): anything without NUL bytes that decodes as UTF-8.

References
----------
The MathWorks, "MAT-File Format", MATLAB documentation (version 7, 2019), section
"MAT-File Header Format"; Apache Parquet, "File Format"; ASAM e.V., "ASAM MDF" 4.1.1
(2019), the identification block.
"""

from __future__ import annotations

from pathlib import Path

from debist.core.errors import RigLogError
from debist.ingest.compressed import open_gzip

__all__ = ["HDF5_SIGNATURE", "detect_format", "sniff_format"]

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_HEAD_BYTES = 4096
_MAT_FORMATS = ("mat-v5", "mat-v7.3", "mat-v4")
_EXTENSIONS = {
    ".mat": "mat-v4",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".csv": "csv",
    ".txt": "csv",
    ".tsv": "csv",
    ".dat": "csv",
    ".gz": "csv",
    ".mf4": "mf4",
    ".mdf": "mf4",
}
#: File identifiers of an ASAM MDF file (finalised, not finalised).
MDF_MAGIC = (b"MDF     ", b"UnFinMF ")


#: First bytes of a gzip stream (RFC 1952); a gzip-compressed text log is read as text.
GZIP_MAGIC = b"\x1f\x8b"


def open_binary(path: Path):
    """Open a file for binary reading, transparently decompressing a gzip stream.

    Parameters
    ----------
    path : Path
        The file; compressed or not is decided by its first bytes, not its name.

    Returns
    -------
    file object
        Yields the (decompressed) bytes.

    Raises
    ------
    OSError
        If the file cannot be opened.
    RigLogError
        While reading a gzip stream that is cut short, corrupt or decompresses to more
        than :func:`~debist.ingest.compressed.decompressed_limit`
        (:class:`~debist.ingest.compressed.GzipLog`).
    """
    return open_gzip(path) if is_gzip(path) else open(path, "rb")


def is_gzip(path: Path) -> bool:
    """Whether a file starts with the gzip magic bytes."""
    with open(path, "rb") as fh:
        return fh.read(2) == GZIP_MAGIC


def _is_text(head: bytes) -> bool:
    if b"\x00" in head:
        return False
    for cut in range(4):  # the head may end inside a multi-byte character
        try:
            head[: len(head) - cut].decode("utf-8")
        except UnicodeDecodeError:
            continue
        return True
    return False


def sniff_format(head: bytes) -> str | None:
    r"""Recognise a format from the first bytes of a file.

    Parameters
    ----------
    head : bytes
        The first bytes of the file (at least 520 to see the HDF5 signature of v7.3).

    Returns
    -------
    str or None
        ``"mat-v5"``, ``"mat-v7.3"``, ``"parquet"``, ``"mf4"``, ``"csv"`` (text), or None
        for binary content without a known signature.

    Raises
    ------
    RigLogError
        A MAT header that is cut short or declares an unknown version (no file name here;
        :func:`detect_format` adds it).

    Examples
    --------
    >>> sniff_format(b"PAR1....")
    'parquet'
    >>> sniff_format(b"0.1,0.2\n0.3,0.4\n")
    'csv'
    """
    if head.startswith(b"MATLAB") and b"MAT-file" in head[:116]:
        if len(head) < 128:
            raise RigLogError(
                f"truncated MAT file: the 128-byte header is cut at {len(head)} bytes"
            )
        endian = head[126:128]
        if endian not in (b"IM", b"MI"):
            raise RigLogError(f"corrupt MAT header: endian indicator {endian!r} at byte 126")
        version = int.from_bytes(head[124:126], "little" if endian == b"IM" else "big")
        if version == 0x0100:
            return "mat-v5"
        if version == 0x0200:
            if len(head) >= 520 and head[512:520] != HDF5_SIGNATURE:
                raise RigLogError(
                    "corrupt MAT v7.3 file: no HDF5 signature at offset 512 "
                    f"(found {head[512:520]!r})"
                )
            return "mat-v7.3"
        raise RigLogError(f"unsupported MAT file version 0x{version:04x} (bytes 124-125)")
    if head.startswith(b"PAR1"):
        return "parquet"
    if head.startswith(MDF_MAGIC):
        return "mf4"
    if head.startswith(HDF5_SIGNATURE):
        return None
    if _is_text(head):
        return "csv"
    return None


def detect_format(path: Path, declared: str = "auto") -> str:
    """Decide how to read a rig log.

    Parameters
    ----------
    path : Path
        The file.
    declared : {"auto", "mat", "csv", "parquet", "mf4"}
        The ``format`` key of the ingest section. ``"auto"`` trusts the content and uses
        the extension only for binary content without a signature; an explicit format
        must agree with the content.

    Returns
    -------
    str
        ``"mat-v5"``, ``"mat-v7.3"``, ``"mat-v4"`` (headerless MAT, read by scipy),
        ``"csv"``, ``"parquet"`` or ``"mf4"``.

    Raises
    ------
    RigLogError
        Naming the file: missing, empty, unreadable, a truncated MAT header or gzip
        stream, content that
        contradicts the declared format, or an unrecognised binary format.
    """
    try:
        with open_binary(path) as fh:
            head = fh.read(_HEAD_BYTES)
    except FileNotFoundError:
        raise RigLogError("no such file", path=path) from None
    except OSError as exc:
        raise RigLogError(f"cannot open ({exc.strerror or exc})", path=path) from exc
    if not head:
        raise RigLogError("empty file (0 bytes)", path=path)
    try:
        content = sniff_format(head)
    except RigLogError as exc:
        raise RigLogError(str(exc), path=path) from None
    by_extension = _EXTENSIONS.get(path.suffix.lower())
    if declared == "auto":
        if content is not None:
            return content
        if by_extension == "mat-v4":
            return by_extension
        raise RigLogError(
            f"unrecognised format: binary content starting {head[:8]!r} is neither MAT, "
            "Parquet, MF4 nor text",
            path=path,
        )
    if declared == "mat":
        if content in _MAT_FORMATS:
            return content
        if content is None and not head.startswith(HDF5_SIGNATURE):
            return "mat-v4"
    elif content == declared:
        return content
    found = "binary data of unknown format" if content is None else f"'{content}' content"
    raise RigLogError(f"format = '{declared}' but the file holds {found}", path=path)
