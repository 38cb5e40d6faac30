r"""Regular expressions from workflows (channel selectors), matched with a time limit.

A backtracking engine takes time exponential in the subject's length for some patterns
(``(a|aa)+$``, ``(\w+\s?)+$`` against a long channel name), so a careless selector could
hang ingest. Patterns are compiled and matched by the `regex` package, whose syntax is
that of :mod:`re` (``VERSION0``) and whose matching functions take a ``timeout``: the
matches of one selector against all the names of a rig log share :data:`MATCH_SECONDS`,
after which the selector is refused in one line naming the key and the pattern. Channel
names are short and selectors simple; a sound pattern needs microseconds.

References
----------
M. Barnett, `regex` (PyPI), "timeout" argument of the matching functions;
Python documentation, :mod:`re` (regular expression syntax).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import lazy_loader as lazy

from debist.core.errors import WorkflowError

# the library below loads on first use (lazy_loader): start-up of the CLI
regex = lazy.load("regex")

__all__ = ["MATCH_SECONDS", "check_pattern", "search_names"]

#: Time all matches of one selector against the names of one rig log may take [s].
MATCH_SECONDS = 1.0
_SHOWN = 60


def check_pattern(pattern: str) -> str:
    """Compile a pattern to check its syntax.

    Parameters
    ----------
    pattern : str
        A regular expression (:mod:`re` syntax).

    Returns
    -------
    str
        ``pattern``, unchanged.

    Raises
    ------
    ValueError
        Not a valid regular expression; the message is the compiler's reason.

    Examples
    --------
    >>> check_pattern("Model Root/.*/v_DE2$")
    'Model Root/.*/v_DE2$'
    """
    try:
        regex.compile(pattern)
    except regex.error as exc:
        raise ValueError(str(exc)) from None
    return pattern


def search_names(pattern: str, names: Sequence[str], where: str) -> list[int]:
    """Return the indices of the names ``pattern`` is found in, within :data:`MATCH_SECONDS`.

    Parameters
    ----------
    pattern : str
        The selector's regular expression, searched as by :func:`re.search`.
    names : sequence of str, length n_channels
        Channel names.
    where : str
        The file and key, for the message (``"file 'rig.mat': `q`"``).

    Returns
    -------
    list of int
        Indices into ``names``, in order.

    Raises
    ------
    WorkflowError
        ``"<where> = regex '<pattern>' did not finish within 1 s on channel name ...:
        it backtracks catastrophically ..."``.

    Examples
    --------
    >>> search_names("DE[12]/v$", ["t", "DE1/v", "DE2/v", "DE2/v_ref"], "`v1`")
    [1, 2]
    """
    compiled = regex.compile(pattern)
    deadline = time.monotonic() + MATCH_SECONDS
    hits = []
    for i, name in enumerate(names):
        try:
            found = compiled.search(name, timeout=max(deadline - time.monotonic(), 1e-3))
        except TimeoutError:
            shown = name if len(name) <= _SHOWN else name[:_SHOWN] + "..."
            raise WorkflowError(
                f"{where} = regex '{pattern}' did not finish within {MATCH_SECONDS:g} s on "
                f"channel name '{shown}' ({len(name)} characters): it backtracks "
                "catastrophically (nested or overlapping repeats such as (a|aa)+); write it "
                "without them, or select by `name` or `column`"
            ) from None
        if found is not None:
            hits.append(i)
    return hits
