"""Where numba keeps debist's compiled kernels: a writable folder, or one for this process only.

The compiled kernels are decorated with ``numba.njit(cache=True)``, and numba looks for their
cache folder when a module defining one is imported: ``$NUMBA_CACHE_DIR`` if set, else the
``__pycache__`` folder beside the module, else its user-wide folder (``~/.cache/numba``); if
none is writable the import fails (``RuntimeError: cannot cache function ...: no locator
available``). An installation owned by another user (a lab's shared environment) under an
account without a writable home is such a case. :func:`prepare_cache`, called by each such
module before its first decoration, checks the folder numba would use first and, when it
is not writable, points ``NUMBA_CACHE_DIR`` at debist's user cache folder
(:func:`debist.core.cache.cache_dir`, ``numba`` in it), else at a temporary folder of this
process (removed at exit): the kernels are then compiled once per process instead of once
per installation. Results are the same either way; only the start-up time differs. A
``NUMBA_CACHE_DIR`` the user set is left as it is.

References
----------
numba documentation, "Notes on Caching" and "Environment variables" (``NUMBA_CACHE_DIR``:
the cache folder used instead of ``__pycache__`` beside the source; the locators tried in
order, each checked by creating a file in its folder).
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

__all__ = ["ENV", "note", "prepare_cache"]

#: numba's environment variable of its cache folder.
ENV = "NUMBA_CACHE_DIR"

#: What :func:`prepare_cache` chose, one line for ``-v`` (empty when numba's own folder is used).
_NOTE = ""
_DONE = False


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (created if missing), as numba checks it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except (OSError, ValueError):
        return False
    return True


def _remove_at_exit(folder: str) -> None:
    """Remove ``folder`` when this process exits (not when a forked child does)."""
    owner = os.getpid()

    def remove() -> None:
        if os.getpid() == owner:
            shutil.rmtree(folder, ignore_errors=True)

    atexit.register(remove)


def _use(folder: str) -> None:
    os.environ[ENV] = folder
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba read the environment already: tell it too
        config.CACHE_DIR = folder


def prepare_cache(module_file: str | os.PathLike) -> str:
    """Make sure numba finds a writable cache folder for the kernels of ``module_file``.

    Call it before the module's first ``cache=True`` decoration. The first call decides
    for the whole process (its forked and started children inherit the choice through
    the environment); later calls return at once.

    Parameters
    ----------
    module_file : path-like
        The ``__file__`` of the module that defines compiled kernels.

    Returns
    -------
    str
        One line saying where the kernels are cached when it is not numba's own choice
        (for ``-v``), else ``""``.

    Notes
    -----
    Raises nothing: a folder that cannot be written is skipped. If not even a temporary
    folder can be made, numba's own ``RuntimeError`` follows at the decoration.
    """
    global _DONE, _NOTE
    if _DONE:
        return _NOTE
    _DONE = True
    if os.environ.get(ENV) or _writable(Path(module_file).parent / "__pycache__"):
        return _NOTE
    from debist.core.cache import cache_dir

    user = cache_dir() / "numba"
    if _writable(user):
        _use(str(user))
        _NOTE = f"numba cache: '{user}' (the installation's __pycache__ is not writable)"
        return _NOTE
    try:
        temporary = tempfile.mkdtemp(prefix="debist-numba-")
    except OSError:
        _NOTE = "numba cache: no writable folder; the kernels cannot be compiled"
        return _NOTE
    _remove_at_exit(temporary)
    _use(temporary)
    _NOTE = (
        "numba cache: none (no writable cache folder); the kernels are compiled for "
        "this process only"
    )
    return _NOTE


def note() -> str:
    """Return the line :func:`prepare_cache` wrote (``""`` if numba's own folder is used).

    Returns
    -------
    str

    Examples
    --------
    >>> isinstance(note(), str)
    True
    """
    return _NOTE
