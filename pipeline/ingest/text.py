"""Reader of delimited text rig logs (CSV, tab- or whitespace-separated) via pandas.

The delimiter, the decimal separator and the presence of a header line are detected from
the first lines (:func:`detect_dialect`, :func:`detect_header`) unless the ingest section
fixes them; parsing itself is :func:`pandas.read_csv` with the C engine (``sep`` and
``decimal``). European exports (``1,609;0,5``: ``;`` between fields, a decimal comma) are
recognised; a decimal comma needs a delimiter other than ``,``. Blank lines are skipped.
Channels are named by the header, or ``"column <i>"`` in a headerless file (select those
with ``column = i``).

A file cut inside its last line is refused before parsing (:func:`check_tail`); the rules
that tell a cut field from a complete one: docs/explanation/implementation.md.
"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import lazy_loader as lazy

from debist.core.errors import RigLogError
from debist.ingest.detect import is_gzip, open_binary
from debist.ingest.raw import RawChannel, RawLog

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = [
    "TAIL_LINES",
    "check_tail",
    "detect_decimal",
    "detect_delimiter",
    "detect_dialect",
    "detect_header",
    "read_text",
]

_SAMPLE_BYTES = 65536
_SAMPLE_LINES = 50
_CANDIDATES = ("\t", ";", ",", "|")
#: Data lines before the last one that its fields are compared with.
TAIL_LINES = 200
#: Bytes read from the end of the file for that comparison.
_TAIL_BYTES = 65536
_CHUNK = 1 << 20
#: A decimal number: sign, mantissa (digits, point, digits) and exponent.
_NUMBER = re.compile(r"[+-]?(\d*)(\.?)(\d*)(?:[eE]([+-]?)(\d+))?")
#: A number written with a decimal comma: digits, a comma, digits (``-0,5``, ``1,6e-3``).
_COMMA_NUMBER = re.compile(r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?")
#: A number written with a decimal point and at least one digit after it.
_POINT_NUMBER = re.compile(r"[+-]?\d*\.\d+(?:[eE][+-]?\d+)?")


def _split(line: str, delimiter: str) -> list[str]:
    if delimiter == "whitespace":
        return line.split()
    return [f.strip() for f in line.split(delimiter)]


def detect_delimiter(lines: list[str], decimal: str = ".") -> str:
    r"""Guess the field delimiter of a text rig log.

    Parameters
    ----------
    lines : list of str
        The first non-blank lines of the file.
    decimal : str
        The decimal separator; with ``","`` a comma is not a candidate delimiter.

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
        if candidate == decimal:
            continue
        counts = Counter(line.count(candidate) for line in lines)
        count, lines_with_it = counts.most_common(1)[0]
        if count > 0 and 2 * lines_with_it >= len(lines):
            return candidate
    return "whitespace"


def detect_decimal(lines: list[str], delimiter: str) -> str:
    """Guess the decimal separator of a text rig log.

    Parameters
    ----------
    lines : list of str
        The first non-blank lines of the file.
    delimiter : str
        The field delimiter (``"whitespace"`` or one character).

    Returns
    -------
    str
        ``","`` when the delimiter is not a comma and the fields holding a number with a
        comma between digits (``1,609``, ``-0,5``) are at least as many as those holding
        one with a decimal point, else ``"."``.

    Examples
    --------
    >>> detect_decimal(["t;q", "0,0;1,609", "0,1;0,5"], ";")
    ','
    >>> detect_decimal(["0.1;2", "0.2;3"], ";")
    '.'
    """
    if delimiter == ",":
        return "."
    fields = [f for line in lines for f in _split(line, delimiter)]
    commas = sum(1 for f in fields if _COMMA_NUMBER.fullmatch(f))
    points = sum(1 for f in fields if _POINT_NUMBER.fullmatch(f))
    return "," if commas and commas >= points else "."


def _whitespace_with_commas(lines: list[str]) -> bool:
    """Whether most lines are >= 2 blank-separated numbers, some with a decimal comma."""
    rows = [line.split() for line in lines]
    numeric = [
        r
        for r in rows
        if len(r) >= 2 and all(_COMMA_NUMBER.fullmatch(f) or f.lstrip("+-").isdigit() for f in r)
    ]
    return 2 * len(numeric) >= len(rows) and any(
        _COMMA_NUMBER.fullmatch(f) for r in numeric for f in r
    )


def detect_dialect(lines: list[str]) -> tuple[str, str]:
    """Guess the delimiter and the decimal separator of a text rig log together.

    Parameters
    ----------
    lines : list of str
        The first non-blank lines of the file.

    Returns
    -------
    delimiter : str
        As :func:`detect_delimiter`, except that blank-separated numbers with decimal
        commas (``1,609  0,5``), which look comma-separated, give ``"whitespace"``.
    decimal : str
        ``"."`` or ``","``, see :func:`detect_decimal`.

    Examples
    --------
    >>> detect_dialect(["1,609;0,5", "1,610;0,6"])
    (';', ',')
    >>> detect_dialect(["0.1,0.2", "0.3,0.4"])
    (',', '.')
    >>> detect_dialect(["1,609  0,5", "1,610  0,6"])
    ('whitespace', ',')
    """
    delimiter = detect_delimiter(lines)
    if delimiter == "," and _whitespace_with_commas(lines):
        return "whitespace", ","
    return delimiter, detect_decimal(lines, delimiter)


def _dot(field: str, decimal: str) -> str:
    return field.replace(",", ".") if decimal == "," else field


def detect_header(line: str, delimiter: str, decimal: str = ".") -> bool:
    """Tell whether the first line of a text rig log holds channel names.

    Parameters
    ----------
    line : str
        The first non-blank line.
    delimiter : str
        As returned by :func:`detect_delimiter`.
    decimal : str
        The decimal separator, ``"."`` or ``","``.

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
            float(_dot(field, decimal))
        except ValueError:
            return True
    return False


def _check_unique_header(line: str, sep: str, path: Path) -> None:
    """Refuse a header that names a channel twice (pandas would rename the second ``q.1``)."""
    import csv

    if sep == "whitespace":
        tokens = line.split()
    else:
        tokens = next(csv.reader([line], delimiter=sep, skipinitialspace=True), [])
    seen: dict[str, int] = {}
    for i, token in enumerate(t.strip() for t in tokens):
        if token in seen:
            raise RigLogError(
                f"the header names channel {token!r} twice (columns {seen[token]} and {i}, "
                "counted from 0): rename one, so that a channel means one column",
                path=path,
                value=token,
            )
        seen[token] = i


def _sample_lines(path: Path) -> list[str]:
    with open_binary(path) as fh:
        chunk = fh.read(_SAMPLE_BYTES)
        at_end = not fh.read(1)
    text = chunk.decode("utf-8-sig", errors="replace")
    lines = text.splitlines()
    if not at_end and lines:
        lines = lines[:-1]  # possibly cut in the middle
    return [line for line in lines if line.strip()][:_SAMPLE_LINES]


def _read_tail(path: Path) -> tuple[bytes, int | None, bool]:
    """Last bytes of the (decompressed) file, its newline count if counted, whether whole."""
    if is_gzip(path):
        newlines, size, tail = 0, 0, b""
        with open_binary(path) as fh:
            while chunk := fh.read(_CHUNK):
                newlines += chunk.count(b"\n")
                size += len(chunk)
                tail = (tail + chunk)[-_TAIL_BYTES:]
        return tail, newlines, size <= _TAIL_BYTES
    with open(path, "rb") as fh:
        size = fh.seek(0, 2)
        fh.seek(max(0, size - _TAIL_BYTES))
        return fh.read(), None, size <= _TAIL_BYTES


def _count_newlines(path: Path) -> int:
    count = 0
    with open_binary(path) as fh:
        while chunk := fh.read(_CHUNK):
            count += chunk.count(b"\n")
    return count


def _number(text: str) -> re.Match[str] | None:
    """Split a decimal number into its parts (None for "-", "1e", "nan" and the like)."""
    match = _NUMBER.fullmatch(text)
    if match is None:
        return None
    try:
        float(text)
    except ValueError:
        return None
    return match


def _decimals(m: re.Match[str]) -> int:
    return len(m.group(3)) if m.group(2) else 0


def _exponent(m: re.Match[str]) -> int:
    return len(m.group(5) or "")


def _significant(m: re.Match[str]) -> int:
    digits = m.group(1) + (m.group(3) if m.group(2) else "")
    return len(digits.lstrip("0"))


def _cut_reason(field: str, before: list[str]) -> str | None:
    """Why the last field of a file without a final newline looks cut (rules a-e)."""
    m = _number(field)
    if m is None:
        return "is not a number"
    earlier = [_number(v) for v in before]
    if any(e is None for e in earlier):
        return None  # a column of text, or an explicit nan: nothing to compare with
    n = len(earlier)
    if field.endswith(".") and not any(v.endswith(".") for v in before):
        return f"ends with its decimal point, none of the {n} values before it does"
    if n < 10:
        return None
    decimals = {_decimals(e) for e in earlier}
    if len(decimals) == 1 and (d := decimals.pop()) >= 1 and _decimals(m) < d:
        return (
            f"has {_decimals(m)} digit(s) after the point, the {n} values before it in "
            f"this column all have {d}"
        )
    exponents = {_exponent(e) for e in earlier}
    if len(exponents) == 1 and (x := exponents.pop()) >= 1 and _exponent(m) < x:
        return (
            f"has {_exponent(m)} exponent digit(s), the {n} values before it in this "
            f"column all have {x}"
        )
    least = min(_significant(e) for e in earlier)
    if _significant(m) <= least - 2:
        return (
            f"has {_significant(m)} significant digit(s), the {n} values before it in "
            f"this column at least {least}"
        )
    return None


def check_tail(path: Path, delimiter: str, header: bool, decimal: str = ".") -> None:
    """Refuse a text rig log whose last line was cut (see the module notes).

    Parameters
    ----------
    path : Path
        The file, plain or gzip-compressed.
    delimiter : str
        ``"whitespace"`` or one character, as for :func:`read_text`.
    header : bool
        Whether the first non-blank line of the file holds channel names (it is not
        compared).
    decimal : str
        The decimal separator, ``"."`` or ``","`` (a decimal comma is read as a point
        for rules a-e).

    Raises
    ------
    RigLogError
        Naming the file and the line number, if the last non-blank line has fewer
        fields than the lines before it, or (without a final newline) its last field
        looks cut by rules a-e of the module notes; a gzip stream cut short or corrupt
        (:class:`~debist.ingest.compressed.GzipLog`).
    OSError
        If the file cannot be read.

    References
    ----------
    RFC 4180, Sec. 2 (the last record may lack a final line break).
    """
    tail, newlines, whole = _read_tail(path)
    ends_with_newline = tail.endswith(b"\n")
    text = tail.decode("utf-8", errors="replace")
    lines = text.removeprefix("\ufeff").split("\n") if whole else text.split("\n")[1:]
    if ends_with_newline:
        lines.pop()
    data = [(j, line.rstrip("\r")) for j, line in enumerate(lines) if line.strip()]
    if whole and header:
        data = data[1:]
    if len(data) < 2:
        return
    j_last, last = data[-1]
    before = [_split(line, delimiter) for _, line in data[-1 - TAIL_LINES : -1]]
    fields = _split(last, delimiter)
    usual = Counter(len(f) for f in before).most_common(1)[0][0]
    problem = None
    if len(fields) < usual:
        problem = (
            f"has {len(fields)} field(s), the lines before it have {usual}: the file is "
            "truncated inside its last line"
        )
    elif not ends_with_newline:
        column = [f[len(fields) - 1] for f in before if len(f) == len(fields)]
        reason = _cut_reason(_dot(fields[-1], decimal), [_dot(v, decimal) for v in column])
        if reason is not None:
            problem = (
                f"ends the file without a newline and its last field {fields[-1]!r} {reason}: "
                "the file is truncated inside a number"
            )
    if problem is None:
        return
    if newlines is None:
        newlines = _count_newlines(path)
    total = newlines + (0 if ends_with_newline else 1)
    number = total - (len(lines) - 1 - j_last)
    raise RigLogError(f"line {number} {problem}", path=path, sample=number)


def _check_decimal(frame: pd.DataFrame, names: list[str], decimal: str, path: Path) -> None:
    """Refuse a column left as text because its numbers use the other decimal separator."""
    other, pattern = (",", _COMMA_NUMBER) if decimal == "." else (".", _POINT_NUMBER)
    for i, name in enumerate(names):
        column = frame.iloc[:, i]
        if pd.api.types.is_numeric_dtype(column.dtype):
            continue
        values = column.dropna().astype(str).str.strip()
        hits = values[values.str.fullmatch(pattern.pattern)]
        if len(hits):
            mark = "comma" if other == "," else "point"
            raise RigLogError(
                f"column {i} holds {hits.iloc[0]!r} at sample {hits.index[0]}, a number with a "
                f"decimal {mark}, but the decimal separator is {decimal!r}; set "
                f'`decimal = "{other}"` (or "auto")',
                path=path,
                channel=name,
                value=hits.iloc[0],
                sample=int(hits.index[0]),
            )


def read_text(
    path: Path, delimiter: str = "auto", header: bool | None = None, decimal: str = "auto"
) -> RawLog:
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
    decimal : str
        ``"auto"``, ``"."`` or ``","``. With ``delimiter`` and ``decimal`` both
        ``"auto"`` both are guessed together (:func:`detect_dialect`); with one fixed
        the other is guessed given it (:func:`detect_delimiter`, :func:`detect_decimal`).

    Returns
    -------
    RawLog
        One channel per column, selectable by ``column`` and, with a header, by name.

    Raises
    ------
    RigLogError
        No data line, a truncated last line (:func:`check_tail`, naming the line), a gzip
        stream cut short or corrupt (:class:`~debist.ingest.compressed.GzipLog`), a header
        that names a channel twice, a decimal comma as delimiter, a column of numbers
        written with the other decimal separator (naming the column, sample and value), or
        pandas cannot parse the file (e.g. a row with too many fields); the pandas message
        (with its line number) is quoted.

    References
    ----------
    pandas, :func:`pandas.read_csv` (``sep``, ``decimal``).
    """
    try:
        lines = _sample_lines(path)
    except OSError as exc:
        raise RigLogError(f"cannot read ({exc})", path=path) from exc
    if not lines:
        raise RigLogError("text file without any data line", path=path)
    if delimiter == "auto" and decimal == "auto":
        sep, dec = detect_dialect(lines)
    else:
        sep = detect_delimiter(lines, decimal) if delimiter == "auto" else delimiter
        dec = detect_decimal(lines, sep) if decimal == "auto" else decimal
    if sep == dec:
        raise RigLogError(
            f"the delimiter and the decimal separator are both {sep!r}; set `delimiter`",
            path=path,
        )
    has_header = detect_header(lines[0], sep, dec) if header is None else header
    try:
        check_tail(path, sep, has_header, dec)
    except OSError as exc:
        raise RigLogError(f"cannot read ({type(exc).__name__}: {exc})", path=path) from exc
    try:
        with open_binary(path) as fh:
            frame = pd.read_csv(
                fh,
                sep=r"\s+" if sep == "whitespace" else sep,
                decimal=dec,
                header=0 if has_header else None,
                engine="c",
                encoding="utf-8-sig",
                skip_blank_lines=True,
                skipinitialspace=sep != "whitespace",
            )
    except RigLogError:
        raise
    except (ValueError, OSError, EOFError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise RigLogError(
            f"cannot parse as delimited text (delimiter {sep!r}, decimal {dec!r}): "
            f"{type(exc).__name__}: {exc}",
            path=path,
        ) from exc
    if has_header:
        names = [str(c).strip() for c in frame.columns]
        _check_unique_header(lines[0], sep, path)
    else:
        names = [f"column {i}" for i in range(frame.shape[1])]
    _check_decimal(frame, names, dec, path)
    channels = tuple(RawChannel(name, frame.iloc[:, i].to_numpy()) for i, name in enumerate(names))
    return RawLog(path, "csv", channels, by_column=True, has_names=has_header)
