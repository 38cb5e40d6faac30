"""Exception and warning classes of debist.

Every error of the project derives from :class:`DebistError` and also from the
builtin that describes it (``ValueError`` for bad input, ``RuntimeError`` for a
failed computation), so callers may catch either. Messages name the file, the
channel or the parameter and echo the offending value.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager


class DebistError(Exception):
    """Base class of every error raised by debist.

    The keyword fields of a subclass (``path``, ``channel``, ``key``, ``value``, ...) are
    attributes of the exception, so a caller can test what went wrong without parsing the
    message; they survive pickling (a batch worker's error reaches the parent whole).
    """

    def __reduce__(self):
        return _rebuild, (type(self), self.args, self.__dict__)


def _rebuild(cls: type, args: tuple, fields: dict) -> BaseException:
    """Unpickle a :class:`DebistError`: its message and its fields, without ``__init__``."""
    exc = cls.__new__(cls)
    exc.args = args
    exc.__dict__.update(fields)
    return exc


class WorkflowError(DebistError, ValueError):
    """A workflow file or one of its sections is invalid (unknown key, wrong type, bad value).

    Parameters
    ----------
    message : str
        What is wrong: ``[section] key: expected ..., got ...``.
    key : str, optional
        The workflow key at fault, dotted from its section (``"identify.M"``,
        ``"ingest.q.unit"``, ``"compare.treshold"`` for an unknown key); ``None`` when the
        error is not about one key.
    value : object, optional
        The offending value as given (``None`` when there is none to echo).
    """

    def __init__(self, message: str = "", *, key: str | None = None, value: object = None):
        self.key = key
        self.value = value
        super().__init__(message)


class ArgumentError(WorkflowError, TypeError):
    """An argument of a Python API function has the wrong type (named, its value echoed)."""


class ResourceError(WorkflowError):
    """A setting would make a stage allocate more memory than the budget allows.

    Raised before the allocation, naming the workflow key and the estimate.
    """


class OutputDirError(WorkflowError):
    """debist refuses to write into an output directory (not its own, or a user's folder)."""


class RunLockedError(WorkflowError):
    """Another debist process holds the lock of the output directory."""


class RigLogError(DebistError, ValueError):
    """A rig log cannot be used: unreadable, truncated, a channel missing or invalid.

    Parameters
    ----------
    message : str
        What is wrong, with the offending value.
    path : str or os.PathLike, optional
        The file the problem was found in; prefixed to the message.
    channel : str, optional
        The channel the problem was found in; prefixed to the message.
    value : object, optional
        The offending value (a sample, a unit, a count), as the message echoes it.
    sample : int, optional
        The index of the first offending sample (or line, for a text file's line).
    """

    def __init__(
        self,
        message: str,
        *,
        path: object = None,
        channel: str | None = None,
        value: object = None,
        sample: int | None = None,
    ):
        self.path = None if path is None else str(path)
        self.channel = channel
        self.value = value
        self.sample = sample
        where = []
        if self.path is not None:
            where.append(f"file '{self.path}'")
        if channel is not None:
            where.append(f"channel '{channel}'")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + message)


class IdentificationError(DebistError, ValueError):
    """The identification problem is ill-posed (rank deficient, ill-conditioned, under-excited).

    Parameters
    ----------
    message : str
        What is wrong, with the numbers.
    reason : str, optional
        A short machine-readable cause: ``"support"`` (a centre without samples),
        ``"rank"``, ``"condition"``, ``"excitation"``, ``"inputs"``, ``"non-finite"``,
        ``"candidates"`` (every candidate of a search failed), ...
    """

    def __init__(self, message: str = "", *, reason: str | None = None):
        self.reason = reason
        super().__init__(message)


class ArtifactError(DebistError, RuntimeError):
    """A stage artifact is missing, modified or inconsistent with its manifest."""


class VerificationError(ArtifactError):
    """``debist verify`` found artifacts, manifests or their chain not as recorded.

    Parameters
    ----------
    problems : list of str
        One line per problem, each naming the file.
    """

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("; ".join(self.problems))


#: Exit codes of the ``debist`` command, the one place they are defined. The first class
#: in this order that an exception is an instance of gives its code.
EXIT_CODES: tuple[tuple[type[BaseException], int], ...] = (
    (VerificationError, 3),
    (WorkflowError, 2),
    (DebistError, 1),
    (OSError, 2),  # read-only or full disk, permissions: the environment, not the data
)
#: Exit code after SIGINT (Ctrl-C): 128 + 2, the shell convention.
EXIT_SIGINT = 130
#: Exit code after SIGTERM: 128 + 15.
EXIT_SIGTERM = 143


def exit_code(exc: BaseException) -> int:
    """Return the exit code of the ``debist`` command for an exception.

    Parameters
    ----------
    exc : BaseException
        The exception that ended the command.

    Returns
    -------
    int
        3 when verification failed, 2 for a bad workflow, bad arguments or a refused
        output directory, lock or memory budget or an OS error (read-only or full disk,
        permissions), 1 when a stage failed on its data, 130
        after SIGINT and 143 after SIGTERM (see :class:`Interrupted`); 1 for anything else.

    Examples
    --------
    >>> exit_code(WorkflowError("x")), exit_code(RigLogError("y")), exit_code(KeyboardInterrupt())
    (2, 1, 130)
    """
    if isinstance(exc, Interrupted):
        return exc.code
    if isinstance(exc, KeyboardInterrupt):
        return EXIT_SIGINT
    for cls, code in EXIT_CODES:
        if isinstance(exc, cls):
            return code
    return 1


def os_error_line(exc: OSError) -> str:
    """Describe an OS error in one line: what the system said, its errno name, the paths.

    Parameters
    ----------
    exc : OSError
        E.g. ``OSError(errno.ENOSPC, "No space left on device", "/out/x.parquet")``.

    Returns
    -------
    str
        ``"No space left on device [ENOSPC]: '/out/x.parquet'; nothing of the unfinished
        stage was kept"``.

    Examples
    --------
    >>> import errno
    >>> os_error_line(OSError(errno.EROFS, "Read-only file system", "/mnt/run"))
    "Read-only file system [EROFS]: '/mnt/run'; nothing of the unfinished stage was kept"
    """
    import errno

    what = exc.strerror or str(exc)
    name = errno.errorcode.get(exc.errno or -1)
    paths = [p for p in (exc.filename, exc.filename2) if p is not None]
    where = ": " + " -> ".join(f"'{os.fsdecode(p)}'" for p in paths) if paths else ""
    return f"{what}{f' [{name}]' if name else ''}{where}; nothing of the unfinished stage was kept"


class Interrupted(KeyboardInterrupt):
    """The process received SIGTERM (or SIGINT) and stops cleanly.

    A subclass of ``KeyboardInterrupt`` so that every ``except BaseException`` clean-up
    (temporary stage folders, locks) runs as it does for Ctrl-C.

    Parameters
    ----------
    signum : int
        The signal number.
    """

    def __init__(self, signum: int):
        import signal

        self.signum = int(signum)
        self.code = 128 + self.signum
        super().__init__(f"interrupted by {signal.Signals(self.signum).name}")


class DebistWarning(UserWarning):
    """Base class of debist's warnings (non-convergence, clipped inputs, ...)."""


class UnitMismatchWarning(DebistWarning):
    """A file declares another unit of the same quantity than the workflow: converted from it."""


class PlausibilityWarning(DebistWarning):
    """A setting or a record is accepted but looks like a slip.

    E.g. a low-pass cutoff at or above the Nyquist frequency (it filters nothing), or a
    stroke that fits another length unit than the one declared.
    """


class ConvergenceWarning(DebistWarning):
    """An iterative method stopped before meeting its tolerance; the result says so too."""


@contextmanager
def recording_warnings() -> Iterator[list[str]]:
    """Collect the messages of debist's warnings while passing every warning on as usual.

    Inside the block each :class:`DebistWarning` is shown once per message, whatever the
    filters outside say (the list goes into a stage's hashed summary, which must not depend
    on them; a stage run twice in one process records the same list), and its message is
    appended to the yielded list; other warnings behave as outside. A stage puts the list
    in its summary, so the warnings stay with its artifacts after the console has scrolled
    away.

    Yields
    ------
    list of str
        The messages, in order, each once.

    References
    ----------
    Python documentation, :mod:`warnings` (``catch_warnings``, ``showwarning``).

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as shown, recording_warnings() as notes:
    ...     warnings.warn("cutoff above Nyquist", PlausibilityWarning)
    >>> notes, len(shown)
    (['cutoff above Nyquist'], 1)
    """
    import warnings

    notes: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("default", DebistWarning)
        passed_on = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, DebistWarning):
                text = str(message)
                if text in notes:
                    return
                notes.append(text)
            passed_on(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield notes
