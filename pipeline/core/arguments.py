"""Checks of the Python API's arguments: one line naming the argument, never a deep error.

The functions of :mod:`debist.api` call these first, so that ``debist.verify(wf, 12345)``
or ``debist.fleet(wf, "3", ...)`` is refused with :class:`~debist.core.errors.ArgumentError`
(a ``TypeError`` and a ``WorkflowError``) naming the argument and echoing its value,
instead of a ``TypeError`` from deep inside the library.

References
----------
scipy's argument checks: messages that name the argument and echo the value.
"""

from __future__ import annotations

import contextlib
import operator
import os
import stat
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from debist.core.errors import ArgumentError, WorkflowError

__all__ = [
    "check_callable",
    "check_flag",
    "check_int",
    "check_names",
    "check_path",
    "check_path_text",
    "check_regular_file",
    "check_str",
]


def _got(value: object) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def check_path(value: Any, name: str, *, optional: bool = False) -> Path | None:
    """Return a path argument as a :class:`~pathlib.Path`.

    Parameters
    ----------
    value : str or os.PathLike or None
        The argument.
    name : str
        Its name, for the message.
    optional : bool, optional
        Whether None is accepted (and returned).

    Returns
    -------
    pathlib.Path or None

    Raises
    ------
    ArgumentError
        ``"dest: expected a path (str or pathlib.Path), got int 5"``.

    Examples
    --------
    >>> check_path("runs/a", "dest")
    PosixPath('runs/a')
    """
    if value is None and optional:
        return None
    if not isinstance(value, str | os.PathLike):
        raise ArgumentError(f"{name}: expected a path (str or pathlib.Path), got {_got(value)}")
    return Path(value)


def check_str(value: Any, name: str, *, optional: bool = False, example: str = "") -> str | None:
    """Return a string argument.

    Parameters
    ----------
    value : str or None
        The argument.
    name : str
        Its name, for the message.
    optional : bool, optional
        Whether None is accepted (and returned).
    example : str, optional
        A valid value, quoted in the message.

    Returns
    -------
    str or None

    Raises
    ------
    ArgumentError
        ``"digest: expected a str (e.g. result.digest), got int 12345"``.

    Examples
    --------
    >>> check_str("c", "fmt")
    'c'
    """
    if value is None and optional:
        return None
    if not isinstance(value, str):
        hint = f" (e.g. {example})" if example else ""
        raise ArgumentError(f"{name}: expected a str{hint}, got {_got(value)}")
    return value


def check_int(value: Any, name: str, *, minimum: int | None = None) -> int:
    """Return an integer argument (a Python or numpy integer, not a bool or a float).

    Parameters
    ----------
    value : int
        The argument.
    name : str
        Its name, for the message.
    minimum : int, optional
        Smallest value accepted.

    Returns
    -------
    int

    Raises
    ------
    ArgumentError
        Not an integer: ``"size: expected an int, got str '3'"``.
    WorkflowError
        Below ``minimum``: ``"size must be at least 1, got 0"``.

    References
    ----------
    Python documentation, :func:`operator.index`.

    Examples
    --------
    >>> check_int(3, "size", minimum=1)
    3
    """
    if isinstance(value, bool):
        raise ArgumentError(f"{name}: expected an int, got {_got(value)}")
    try:
        number = operator.index(value)
    except TypeError:
        raise ArgumentError(f"{name}: expected an int, got {_got(value)}") from None
    if minimum is not None and number < minimum:
        raise WorkflowError(f"{name} must be at least {minimum}, got {number}")
    return number


def check_flag(value: Any, name: str) -> bool:
    """Return a bool argument (``True``/``False``, or a numpy bool).

    Parameters
    ----------
    value : bool
        The argument.
    name : str
        Its name, for the message.

    Returns
    -------
    bool

    Raises
    ------
    ArgumentError
        ``"force: expected True or False, got str 'no'"``.

    Examples
    --------
    >>> check_flag(False, "force")
    False
    """
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return bool(value)
    raise ArgumentError(f"{name}: expected True or False, got {_got(value)}")


def check_names(
    value: Any, name: str, *, what: str = "names", optional: bool = True
) -> tuple[str, ...] | None:
    """Return a sequence-of-names argument (stage names) as a tuple.

    Parameters
    ----------
    value : sequence of str or None
        The argument.
    name : str
        Its name, for the message.
    what : str, optional
        What the names are, for the message (``"stage names"``).
    optional : bool, optional
        Whether None is accepted (and returned).

    Returns
    -------
    tuple of str or None

    Raises
    ------
    ArgumentError
        A single string (``"stages: expected a list of stage names, got the string 'ingest';
        pass ['ingest']"``), a non-sequence or an item that is not a string.

    Examples
    --------
    >>> check_names(["ingest", "differentiate"], "stages")
    ('ingest', 'differentiate')
    """
    if value is None and optional:
        return None
    if isinstance(value, str | bytes):
        raise ArgumentError(
            f"{name}: expected a list of {what}, got the string {value!r}; pass [{value!r}]"
        )
    if not isinstance(value, Sequence | set | frozenset):
        raise ArgumentError(f"{name}: expected a list of {what}, got {_got(value)}")
    items = tuple(value)
    for item in items:
        if not isinstance(item, str):
            raise ArgumentError(f"{name}: expected {what} (str), got {_got(item)} among them")
    return items


def check_callable(value: Any, name: str) -> Callable[..., Any] | None:
    """Return a callback argument (or None).

    Parameters
    ----------
    value : callable or None
        The argument.
    name : str
        Its name, for the message.

    Returns
    -------
    callable or None

    Raises
    ------
    ArgumentError
        ``"on_progress: expected a function or None, got int 3"``.

    Examples
    --------
    >>> check_callable(print, "on_progress") is print
    True
    """
    if value is None or callable(value):
        return value
    raise ArgumentError(f"{name}: expected a function or None, got {_got(value)}")


def check_regular_file(path: str | os.PathLike, what: str) -> None:
    """Refuse a path that is a FIFO, socket or device, before it is opened.

    Opening a FIFO for reading waits for a writer (forever, for a command line), and a
    device or socket is no file debist reads. A missing path passes (the reader says so).

    Parameters
    ----------
    path : path-like
        The file about to be read (symbolic links followed).
    what : str
        What it is, for the message, e.g. ``"rig log"``.

    Raises
    ------
    WorkflowError
        If ``path`` is a FIFO, socket or device, naming it.

    References
    ----------
    POSIX ``stat(2)`` (``S_ISREG``) and ``open(2)`` (opening a FIFO blocks until a writer
    opens it).
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):  # missing, unreadable, NUL byte: the reader says why
        return
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise WorkflowError(
            f"{what} '{os.fspath(path)}' is not a regular file (a FIFO, socket or device): "
            "refused before reading it"
        )


def check_path_text(path: str | os.PathLike, what: str) -> None:
    """Refuse a path that this process cannot pass to the file system or write as text.

    Under a locale whose encoding is ASCII (``LC_ALL=C`` with ``PYTHONUTF8=0``), a name
    such as ``Müller`` read from a TOML file cannot be encoded for the file system, and
    one given on the command line arrives with undecodable bytes (surrogate escapes) that
    cannot be written into a UTF-8 file.

    Parameters
    ----------
    path : path-like
        The path.
    what : str
        What it is, for the message (``"[workflow] output_dir"``).

    Raises
    ------
    WorkflowError
        Naming the path, the character and the file-name encoding, and how to fix it.

    References
    ----------
    PEP 383 (surrogate escapes of undecodable bytes) and PEP 540 (Python's UTF-8 mode).
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        return
    for check in (os.fsencode, lambda t: t.encode("utf-8")):
        try:
            check(text)
        except UnicodeEncodeError as exc:
            bad = text[exc.start : exc.end]
            with contextlib.suppress(UnicodeEncodeError):  # undecodable bytes: show them
                bad = bad.encode(sys.getfilesystemencoding(), "surrogateescape")
            raise WorkflowError(
                f"{what} {text!r}: {bad!r} cannot be written in this "
                f"system's file-name encoding ({sys.getfilesystemencoding()}); use a UTF-8 "
                "locale (e.g. LC_ALL=C.UTF-8) or PYTHONUTF8=1, or an ASCII name"
            ) from None
