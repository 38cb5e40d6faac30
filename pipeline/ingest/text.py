"""Reader of delimited text rig logs (CSV, tab- or whitespace-separated) via pandas.

The delimiter and the presence of a header line are detected from the first lines
(:func:`detect_delimiter`, :func:`detect_header`) unless the ingest section fixes them;
parsing itself is :func:`pandas.read_csv` with the C engine. Decimal separator ``.``;
blank lines are skipped. Channels are named by the header, or ``"column <i>"`` in a
headerless file (select those with ``column = i``).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pandas as pd

from pipeline.errors import RigLogError
from pipeline.ingest.detect import is_gzip, open_binary
from pipeline.ingest.raw import RawChannel, RawLog

__all__ = ["detect_delimiter", "detect_header", "read_text"]

_SAMPLE_BYTES = 65536
_SAMPLE_LINES = 50
_CANDIDATES = ("\t", ";", ",", "|")


def _split(line: str, delimiter: str) -> list[str]:
    if delimiter == "whitespace":
        return line.split()
    return [f.strip() for f in line.split(delimiter)]


def detect_delimiter(lines: list[str]) -> str:
    r"""Guess the field delimiter of a text rig log.

    Parameters
    ----------
    lines : list of str
        The first non-blank lines of the file.

    Returns
    -------
    str
        The first of tab, ``;``, ``,``, ``|`` that occurs the same non-zero number of
        times in at least half of the lines (a ragged or truncated line does not hide
        it), else ``"whitespace"`` (runs of blanks and tabs).

    Examples
    --------
    >>> detect_delimiter(["0.1,0.2", "0.3,0.4"])
    ','
    >>> detect_delimiter(["0.000\t3.561", "10.000\t3.561"])
    '\t'
    >>> detect_delimiter(["  1.0   2.0", "  3.0 4.0"])
    'whitespace'
    """
    for candidate in _CANDIDATES:
        counts = Counter(line.count(candidate) for line in lines)
        count, lines_with_it = counts.most_common(1)[0]
        if count > 0 and 2 * lines_with_it >= len(lines):
            return candidate
    return "whitespace"


def detect_header(line: str, delimiter: str) -> bool:
    """Tell whether the first line of a text rig log holds channel names.

    Parameters
    ----------
    line : str
        The first non-blank line.
    delimiter : str
        As returned by :func:`detect_delimiter`.

    Returns
    -------
    bool
        True unless every field of the line parses as a number.

    Examples
    --------
    >>> detect_header("time,q,v", ",")
    True
    >>> detect_header("0.0057756,0.0093978", ",")
    False
    """
    for field in _split(line, delimiter):
        try:
            float(field)
        except ValueError:
            return True
    return False


def _sample_lines(path: Path) -> list[str]:
    with open_binary(path) as fh:
        chunk = fh.read(_SAMPLE_BYTES)
        at_end = not fh.read(1)
    text = chunk.decode("utf-8-sig", errors="replace")
    lines = text.splitlines()
    if not at_end and lines:
        lines = lines[:-1]  # possibly cut in the middle
    return [line for line in lines if line.strip()][:_SAMPLE_LINES]


def read_text(path: Path, delimiter: str = "auto", header: bool | None = None) -> RawLog:
    """Read a delimited text rig log.

    Parameters
    ----------
    path : Path
        The file (UTF-8, optionally with a byte-order mark).
    delimiter : str
        ``"auto"`` (see :func:`detect_delimiter`), ``"whitespace"`` or one character.
    header : bool or None
        Whether the first line holds channel names; None detects it
        (:func:`detect_header`).

    Returns
    -------
    RawLog
        One channel per column, selectable by ``column`` and, with a header, by name.

    Raises
    ------
    RigLogError
        No data line, or pandas cannot parse the file (e.g. a row with too many fields);
        the pandas message (with its line number) is quoted.
    """
    try:
        lines = _sample_lines(path)
    except OSError as exc:
        raise RigLogError(f"cannot read ({exc})", path=path) from exc
    if not lines:
        raise RigLogError("text file without any data line", path=path)
    sep = detect_delimiter(lines) if delimiter == "auto" else delimiter
    has_header = detect_header(lines[0], sep) if header is None else header
    try:
        frame = pd.read_csv(
            path,
            sep=r"\s+" if sep == "whitespace" else sep,
            header=0 if has_header else None,
            engine="c",
            encoding="utf-8-sig",
            compression="gzip" if is_gzip(path) else None,
            skip_blank_lines=True,
            skipinitialspace=sep != "whitespace",
        )
    except (ValueError, OSError, EOFError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise RigLogError(
            f"cannot parse as delimited text (delimiter {sep!r}): {type(exc).__name__}: {exc}",
            path=path,
        ) from exc
    if has_header:
        names = [str(c).strip() for c in frame.columns]
    else:
        names = [f"column {i}" for i in range(frame.shape[1])]
    channels = tuple(RawChannel(name, frame.iloc[:, i].to_numpy()) for i, name in enumerate(names))
    return RawLog(path, "csv", channels, by_column=True, has_names=has_header)
