"""Settings overridden for one run (``--set KEY=VALUE`` or a Python mapping).

:func:`overrides_table` turns Python overrides into the tables a workflow file holds:
``{"identify.M": 8}``, ``{"identify": {"M": 8}}`` and ``{"compare.narx": {"enabled": False}}``
mean what the dotted keys mean on the command line; nested mappings are flattened into dotted
keys, each key is parsed as a TOML key (``datasets."run.2".role``), and values must be TOML
values (``None`` is refused: TOML has no null; numpy scalars are taken as the Python numbers
they hold, tuples as arrays). A run with overrides and no output folder of its own (``--out``)
gets one beside the workflow's (:func:`override_folder`), named by the digest of the settings,
so an experiment never overwrites the workflow's own run and the same settings find their
folder again; an output folder the user names is used as it is.
:func:`override_args` writes the settings back as ``--set`` options (the verify command a
run prints, the report's provenance).

References
----------
TOML v1.0.0 (https://toml.io/en/v1.0.0): keys (bare, quoted, dotted) and value types;
FIPS 180-4 (SHA-256).
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from debist.core.errors import ArgumentError, WorkflowError
from debist.workflow.tomltext import MAX_NESTING

__all__ = [
    "SET_FOLDER",
    "override_args",
    "override_digest",
    "override_folder",
    "overrides_table",
    "toml_value",
]

#: How the output folder of a run with overrides is named: ``<output folder>.set-<8 hex>``.
SET_FOLDER = "{name}.set-{digest}"


def toml_value(value: Any) -> str:
    """Write one value as TOML text on one line (for a ``{"identify.M": 8}`` override).

    Parameters
    ----------
    value : object
        A TOML value: string, number, boolean, date/time, array (list or tuple) or table.

    Returns
    -------
    str
        Arrays and tables inline (``[0, 30]``, ``{prior = 30}``); a scalar as
        :mod:`tomli_w` writes it.

    Raises
    ------
    TypeError
        For a value TOML cannot hold (raised by :mod:`tomli_w`).

    References
    ----------
    TOML v1.0.0 (https://toml.io/en/v1.0.0), arrays and inline tables.

    Examples
    --------
    >>> toml_value([0, 30]), toml_value({"prior": 30}), toml_value("spectral")
    ('[0, 30]', '{prior = 30}', '"spectral"')
    """
    import tomli_w

    if isinstance(value, Mapping):
        items = ", ".join(f"{_toml_key(k)} = {toml_value(v)}" for k, v in value.items())
        return f"{{{items}}}"
    if isinstance(value, (list, tuple)):
        return f"[{', '.join(toml_value(v) for v in value)}]"
    return tomli_w.dumps({"v": value}).partition("=")[2].strip()


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(part: str) -> str:
    """Return one part of a TOML key: bare when it may be, else a quoted string."""
    return part if _BARE_KEY.fullmatch(part) else json.dumps(part, ensure_ascii=False)


def override_digest(overrides: Mapping[str, Any]) -> str:
    """Return the first 8 hex digits of the sha256 of the overrides' canonical JSON.

    The same settings give the same digest however they were written (``identify.M=8``,
    ``{"identify.M": 8}``, ``{"identify": {"M": 8}}``): the nested tables of
    :func:`~debist.workflow.loader.parse_overrides` are serialised with sorted keys and no spaces.

    Parameters
    ----------
    overrides : mapping
        Nested tables, as :func:`~debist.workflow.loader.parse_overrides` returns them.

    Returns
    -------
    str
        8 lowercase hex digits.

    References
    ----------
    FIPS 180-4 (SHA-256); RFC 8259 (JSON).

    Examples
    --------
    >>> override_digest({"identify": {"M": 8}, "validate": {"substeps": 4}})
    'ca98b8cd'
    >>> override_digest({"validate": {"substeps": 4}, "identify": {"M": 8}})
    'ca98b8cd'
    >>> len(override_digest({"identify": {"M": 8}}))
    8
    """
    text = json.dumps(
        overrides, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str
    )
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:8]


def override_folder(output_dir: str | os.PathLike, overrides: Mapping[str, Any]) -> Path:
    """Return the output folder of a run with overrides: beside the workflow's own folder.

    ``runs/silverbox`` with ``--set identify.M=8`` becomes ``runs/silverbox.set-<8 hex>``
    (:data:`SET_FOLDER`, :func:`override_digest`), so an experiment never overwrites the
    workflow's own run, and the same settings find the same folder again. Used only when
    the user names no output folder (``--out``): a named one is the run's folder as it is.

    Parameters
    ----------
    output_dir : path-like
        The workflow's own output folder (``[workflow] output_dir``, or ``runs/<name>``).
    overrides : mapping
        Nested tables (:func:`~debist.workflow.loader.parse_overrides`); empty: the
        workflow's own folder, ``output_dir`` itself.

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> override_folder("runs/a", {}).as_posix()
    'runs/a'
    >>> override_folder("runs/a", {"identify": {"M": 8}}).name.startswith("a.set-")
    True
    """
    out = Path(output_dir)
    if not overrides:
        return out
    return out.with_name(SET_FOLDER.format(name=out.name, digest=override_digest(overrides)))


def override_args(overrides: Mapping[str, Any]) -> list[str]:
    """Write nested overrides back as ``KEY=VALUE`` settings for ``--set`` (sorted by key).

    Parameters
    ----------
    overrides : mapping
        Nested tables (:func:`~debist.workflow.loader.parse_overrides`).

    Returns
    -------
    list of str
        One TOML dotted key and TOML value per leaf, which
        :func:`~debist.workflow.loader.parse_overrides` reads back to ``overrides``.

    References
    ----------
    TOML v1.0.0 (https://toml.io/en/v1.0.0), keys and values.

    Examples
    --------
    >>> override_args({"identify": {"M": 8}, "datasets": {"a.b": {"role": "validation"}}})
    ['datasets."a.b".role="validation"', 'identify.M=8']
    """

    def leaves(tree: Mapping[str, Any], prefix: str) -> list[str]:
        out = []
        for name, value in sorted(tree.items()):
            dotted = f"{prefix}{_toml_key(name)}"
            if isinstance(value, Mapping) and value:
                out += leaves(value, f"{dotted}.")
            else:
                out.append(f"{dotted}={toml_value(value)}")
        return out

    return leaves(overrides, "")


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
    if key.splitlines() != [key]:  # a line break would let the key's text hold more TOML
        raise WorkflowError(f"overrides: {where!r} holds a line break: not a TOML key")
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
