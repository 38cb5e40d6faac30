"""Settings overridden from Python: a mapping turned into the tables a workflow file holds.

``{"identify.M": 8}``, ``{"identify": {"M": 8}}`` and ``{"identify": {"M": 8}, "compare.narx":
{"enabled": False}}`` mean what the dotted keys ``identify.M = 8`` and ``compare.narx.enabled =
false`` mean on the command line (``--set``): nested mappings are flattened into dotted keys,
each key is parsed as a TOML key (``datasets."run.2".role``), and the result is merged into
the workflow's tables as ``--set`` merges it. Values must be TOML values: ``None`` is refused
(TOML has no null), as are objects TOML cannot write; numpy scalars are taken as the Python
numbers they hold, tuples as arrays.

References
----------
TOML v1.0.0 specification (https://toml.io/en/v1.0.0): keys (bare, quoted, dotted) and value
types.
"""

from __future__ import annotations

import datetime
import tomllib
from collections.abc import Mapping
from typing import Any

from debist.errors import ArgumentError, WorkflowError
from debist.workflow.tomltext import MAX_NESTING

__all__ = ["overrides_table"]

_SCALARS = (bool, int, float, str, datetime.date, datetime.time)  # datetime is a date


def _key_parts(key: object, prefix: tuple[str, ...]) -> tuple[str, ...]:
    """Split one TOML key into its parts (``'datasets."run.2".role'``: three parts)."""
    where = ".".join((*prefix, str(key)))
    if not isinstance(key, str):
        inside = f" (inside {'.'.join(prefix)!r})" if prefix else ""
        raise ArgumentError(
            f"overrides: key {key!r}{inside} is of type {type(key).__name__}, not a string "
            "such as 'identify.M'"
        )
    try:
        table = tomllib.loads(f"{key} = 0")
    except tomllib.TOMLDecodeError:
        raise WorkflowError(
            f"overrides: {where!r} is not a TOML key (dotted names such as 'identify.M'; "
            "quote a part with dots or spaces: 'datasets.\"run.2\".role')"
        ) from None
    parts: list[str] = []
    while isinstance(table, dict):
        (name, table), *_ = table.items()
        parts.append(name)
    return (*prefix, *parts)


def _value(value: Any, where: str, depth: int) -> Any:
    """Return the TOML value of a Python one, checked all the way down."""
    if depth > MAX_NESTING:
        raise WorkflowError(
            f"overrides: {where!r} nests lists or mappings deeper than {MAX_NESTING} levels; "
            f"at most {MAX_NESTING} are accepted"
        )
    if value is None:
        raise WorkflowError(
            f"overrides: {where!r} = None, but TOML has no null; leave the key out to keep "
            "the workflow's value"
        )
    if hasattr(value, "dtype") and hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        value = value.item()  # a numpy scalar
    if isinstance(value, _SCALARS):
        return value
    if isinstance(value, list | tuple):
        return [_value(item, where, depth + 1) for item in value]
    if isinstance(value, Mapping):  # an inline table inside an array
        table = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise ArgumentError(
                    f"overrides: key {k!r} in {where!r} is of type {type(k).__name__}, not a string"
                )
            table[k] = _value(v, f"{where}.{k}", depth + 1)
        return table
    raise ArgumentError(
        f"overrides: {where!r} = {value!r} is of type {type(value).__name__}, not a TOML "
        "value (bool, int, float, str, date or time, a list or a mapping of them)"
    )


def _flatten(mapping: Mapping[Any, Any], prefix: tuple[str, ...], depth: int):
    """Yield ``(key parts, value)`` per leaf of nested mappings."""
    if depth > MAX_NESTING:
        raise WorkflowError(
            f"overrides: {'.'.join(prefix)!r} nests mappings deeper than {MAX_NESTING} levels"
        )
    for key, value in mapping.items():
        parts = _key_parts(key, prefix)
        if isinstance(value, Mapping) and value:
            yield from _flatten(value, parts, depth + 1)
        elif isinstance(value, Mapping):
            yield parts, {}
        else:
            yield parts, _value(value, ".".join(parts), 0)


def overrides_table(overrides: Mapping[Any, Any]) -> dict[str, Any]:
    """Turn Python overrides into nested tables, as ``--set`` items would give them.

    Parameters
    ----------
    overrides : mapping
        Dotted keys or nested mappings to values: ``{"identify.M": 5}``,
        ``{"identify": {"M": 5}}``, ``{"compare.narx": {"enabled": False}}``.

    Returns
    -------
    dict
        Nested tables, e.g. ``{"identify": {"M": 5}}``; a later key wins, and a table
        set by an earlier key is extended, not replaced.

    Raises
    ------
    ArgumentError
        One line naming the key: a key that is not a string, a value of a type TOML
        cannot hold.
    WorkflowError
        One line naming the key: not a TOML key, a value ``None`` (TOML has no null),
        lists and mappings nested deeper than :data:`~debist.workflow.tomltext.MAX_NESTING`.

    References
    ----------
    TOML v1.0.0 specification, "Keys" (dotted keys) and "Table".

    Examples
    --------
    >>> overrides_table({"identify": {"M": 5}, "compare.narx": {"enabled": False}})
    {'identify': {'M': 5}, 'compare': {'narx': {'enabled': False}}}
    >>> overrides_table({"identify.M": 5, "identify": {"sigma_n": 0.5}})
    {'identify': {'M': 5, 'sigma_n': 0.5}}
    """
    out: dict[str, Any] = {}
    for parts, value in _flatten(overrides, (), 0):
        table = out
        for i, name in enumerate(parts[:-1]):
            inner = table.setdefault(name, {})
            if not isinstance(inner, dict):
                raise WorkflowError(
                    f"overrides: {'.'.join(parts)!r} sets a key inside "
                    f"{'.'.join(parts[: i + 1])!r}, which another key sets to {inner!r}"
                )
            table = inner
        last = parts[-1]
        if isinstance(value, dict) and isinstance(table.get(last), dict):
            continue  # an empty table adds nothing to one already set
        table[last] = value
    return out
