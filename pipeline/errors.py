"""Exception and warning classes of debist.

Every error of the project derives from :class:`DebistError` and also from the
builtin that describes it (``ValueError`` for bad input, ``RuntimeError`` for a
failed computation), so callers may catch either. Messages name the file, the
channel or the parameter and echo the offending value.
"""

from __future__ import annotations


class DebistError(Exception):
    """Base class of every error raised by debist."""


class WorkflowError(DebistError, ValueError):
    """A workflow file or one of its sections is invalid (unknown key, wrong type, bad value)."""


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
    """

    def __init__(self, message: str, *, path: object = None, channel: str | None = None):
        self.path = None if path is None else str(path)
        self.channel = channel
        where = []
        if self.path is not None:
            where.append(f"file '{self.path}'")
        if channel is not None:
            where.append(f"channel '{channel}'")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + message)


class IdentificationError(DebistError, ValueError):
    """The identification problem is ill-posed (rank deficient, ill-conditioned, under-excited)."""


class ArtifactError(DebistError, RuntimeError):
    """A stage artifact is missing, modified or inconsistent with its manifest."""


class DebistWarning(UserWarning):
    """Base class of debist's warnings (non-convergence, clipped inputs, ...)."""


class ConvergenceWarning(DebistWarning):
    """An iterative method stopped before meeting its tolerance; the result says so too."""
