"""Building the frozen configuration dataclasses of the stages from workflow sections."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

from pipeline.errors import WorkflowError

_C = TypeVar("_C")


def config_from_section(cls: type[_C], section: Mapping[str, Any], where: str) -> _C:
    """Build the frozen config dataclass ``cls`` from a workflow section.

    Parameters
    ----------
    cls : type
        A dataclass whose constructor or ``__post_init__`` checks its values
        (raising ``ValueError`` or ``TypeError``).
    section : mapping of str to value
        The keys given in the workflow.
    where : str
        Where the section sits, for the messages (e.g. ``"[identify]"``).

    Returns
    -------
    object
        ``cls(**section)``.

    Raises
    ------
    WorkflowError
        On a section that is not a table, an unknown key (named, with the known
        keys) or an invalid value.
    """
    if not isinstance(section, Mapping):
        raise WorkflowError(f"{where}: must be a table, got {type(section).__name__}")
    known = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    unknown = [key for key in section if key not in known]
    if unknown:
        raise WorkflowError(f"{where}: unknown key '{unknown[0]}'; known keys: {', '.join(known)}")
    try:
        return cls(**section)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, WorkflowError):
            raise
        raise WorkflowError(f"{where}: {exc}") from exc
