"""Settings overridden for one run (``--set KEY=VALUE``): their folder, written back.

A run with overrides gets its own output folder beside the workflow's
(:func:`override_folder`), named by the digest of the settings, so an experiment never
overwrites the workflow's own run and the same settings find their folder again.
:func:`override_args` writes the settings back as ``--set`` options (the verify command a
run prints, the report's provenance).

References
----------
TOML v1.0.0 (https://toml.io/en/v1.0.0), keys and values; FIPS 180-4 (SHA-256).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "SET_FOLDER",
    "override_args",
    "override_digest",
    "override_folder",
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
    workflow's own run, and the same settings find the same folder again.

    Parameters
    ----------
    output_dir : path-like
        The workflow's own output folder (``[workflow] output_dir`` or ``--out``).
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
