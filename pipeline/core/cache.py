"""debist's per-user cache folder: derived data that only saves time, never decides a result.

Two things live there: the import lists of debist's own modules, keyed by the sha256 of each
module's source (:mod:`debist.engine.fingerprint`), and pint's parsed unit definitions
(:func:`debist.core.units.registry`). Both are recomputed when missing, unreadable or not
writable, so deleting the folder, a read-only home or a full disk cost only start-up time.
The folder is ``$DEBIST_CACHE_DIR`` when set, else the platform's user cache folder
(``~/.cache/debist`` on Linux, by platformdirs).

References
----------
platformdirs, ``user_cache_path`` (https://platformdirs.readthedocs.io); XDG Base Directory
Specification (``XDG_CACHE_HOME``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import platformdirs

from debist.core.fileformats import atomic_write

__all__ = ["cache_dir", "read_json", "write_json"]

#: Environment variable that moves the cache folder (tests point it at a temporary folder).
ENV = "DEBIST_CACHE_DIR"


def cache_dir() -> Path:
    """Return debist's user cache folder (not created).

    Returns
    -------
    pathlib.Path
        ``$DEBIST_CACHE_DIR`` when set and not empty, else platformdirs' user cache path
        for ``debist``.

    Examples
    --------
    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, {"DEBIST_CACHE_DIR": "/tmp/debist-cache"}):
    ...     str(cache_dir())
    '/tmp/debist-cache'
    """
    given = os.environ.get(ENV)
    return Path(given) if given else platformdirs.user_cache_path("debist", appauthor=False)


def read_json(name: str) -> Any:
    """Read ``name`` from the cache folder, or None when it is missing or unreadable.

    Parameters
    ----------
    name : str
        A file name of debist's own (a constant, never user input).

    Returns
    -------
    object or None
        The parsed JSON; None on any error (a cache is never a reason to fail).
    """
    try:
        return json.loads((cache_dir() / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def write_json(name: str, value: Any) -> bool:
    """Write ``value`` as JSON to ``name`` in the cache folder, atomically, if possible.

    Parameters
    ----------
    name : str
        A file name of debist's own (a constant, never user input).
    value : object
        JSON-serialisable.

    Returns
    -------
    bool
        True when written; False when the folder cannot be created or written (read-only
        home, full disk): the caller goes on without the cache.
    """
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write(folder / name, json.dumps(value, sort_keys=True))
    except OSError:
        return False
    return True
