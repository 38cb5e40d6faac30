"""TOML text parsed with a bound on how deeply arrays and inline tables nest.

:mod:`tomllib` parses nested arrays and inline tables recursively, so a few hundred
brackets (``M = [[[[...]]]]``, one kilobyte of text) exhaust the interpreter's stack. No
workflow setting nests more than a few levels, so the text is scanned first (brackets
outside strings and comments) and refused above :data:`MAX_NESTING` levels, before the
parser sees it.
"""

from __future__ import annotations

import re
import tomllib
from typing import Any

from debist.core.errors import WorkflowError

__all__ = ["MAX_NESTING", "check_nesting", "loads"]

#: Deepest nesting of arrays and inline tables accepted in a workflow or a ``--set`` value.
MAX_NESTING = 32

# One token per match: a string or a comment (skipped whole, so the brackets inside them
# do not count), a table header at the start of a line, or one bracket. A quote without
# its closing quote runs to the end of its line (tomllib then reports it).
_TOKEN = re.compile(
    r'"""(?:\\.|[^\\])*?"""'
    r"|'''.*?'''"
    r'|"(?:\\.|[^"\\\n])*"'
    r"|'[^'\n]*'"
    r"|[\"'][^\n]*"
    r"|#[^\n]*"
    r"|(?P<bracket>[\[\]{}])",
    re.DOTALL,
)
# A table header: ``[name]`` or ``[[name]]`` alone on its line (outside any value).
_HEADER = re.compile(r"[ \t]*\[\[?(?P<name>[^\]\n]*)\]\]?")
_KEY = re.compile(r"([^=\n]*)=[^=\n]*\Z")


def check_nesting(text: str, where: str, limit: int = MAX_NESTING) -> None:
    r"""Refuse TOML text whose arrays or inline tables nest deeper than ``limit``.

    Parameters
    ----------
    text : str
        TOML document (or one ``key = value`` line).
    where : str
        What the text is, for the message (``"workflow file 'wf.toml'"``).
    limit : int, optional
        Deepest nesting accepted; :data:`MAX_NESTING` by default.

    Raises
    ------
    WorkflowError
        ``"<where>: [identify] M nests arrays or inline tables deeper than 32 levels
        (line 40); at most 32 are accepted"``.

    References
    ----------
    TOML v1.0.0 specification (https://toml.io/en/v1.0.0): strings, comments, table
    headers, arrays and inline tables.

    Examples
    --------
    >>> check_nesting("M = [[1, 2], '[[[']", "x")
    >>> try:
    ...     check_nesting("[identify]\nM = [[[1]]]", "wf.toml", limit=2)
    ... except WorkflowError as exc:
    ...     print(str(exc).replace("; ", ";\n"))
    wf.toml: [identify] M nests arrays or inline tables deeper than 2 levels (line 2);
    at most 2 are accepted
    """
    depth, table, key, pos = 0, "", "", 0
    while (match := _TOKEN.search(text, pos)) is not None:
        pos = match.end()
        bracket = match.group("bracket")
        if bracket is None:
            continue
        if bracket in "[{":
            if depth == 0:
                start = text.rfind("\n", 0, match.start()) + 1
                header = _HEADER.match(text, start) if bracket == "[" else None
                if header is not None and not text[start : match.start()].strip():
                    table, pos = header.group("name").strip(), header.end()
                    continue
                found = _KEY.search(text[start : match.start()])
                key = found.group(1).strip() if found else "a value"
            depth += 1
            if depth > limit:
                name = f"[{table}] {key}" if table else key
                line = text.count("\n", 0, match.start()) + 1
                at = f" (line {line})" if "\n" in text else ""
                raise WorkflowError(
                    f"{where}: {name} nests arrays or inline tables deeper than {limit} "
                    f"levels{at}; at most {limit} are accepted"
                )
        else:
            depth = max(depth - 1, 0)


def loads(text: str, where: str) -> dict[str, Any]:
    """Parse TOML text after :func:`check_nesting`.

    Parameters
    ----------
    text : str
        TOML document.
    where : str
        What the text is, for the messages (``"workflow file 'wf.toml'"``).

    Returns
    -------
    dict
        The parsed document, as :func:`tomllib.loads` returns it.

    Raises
    ------
    WorkflowError
        Nesting deeper than :data:`MAX_NESTING` (see :func:`check_nesting`), or the
        parser's stack exhausted all the same.
    tomllib.TOMLDecodeError
        The text is not valid TOML (the caller words it).

    References
    ----------
    Python documentation, :func:`tomllib.loads`.
    """
    check_nesting(text, where)
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise WorkflowError(
            f"{where}: arrays or inline tables nested too deeply to parse; at most "
            f"{MAX_NESTING} levels are accepted"
        ) from None
