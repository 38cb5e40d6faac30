"""Names that become file names: one check, applied where a workflow is loaded.

A data set's name becomes ``ingest/<name>.parquet``, a rig experiment's ``rig/<name>.mat``, a
fleet member's ``<name>-<k>.toml``. Such a name is accepted only as a portable file-name
component (POSIX.1-2017's portable filename character set, Sec. 3.282: letters, digits,
``.``, ``_``, ``-``), not starting with a dot (no hidden files, no ``..``), at most
:data:`MAX_LENGTH` characters and not a name Windows reserves for a device, so that it
names one file inside the output folder on every system a lab uses.
"""

from __future__ import annotations

import re

from debist.core.errors import WorkflowError

__all__ = ["MAX_LENGTH", "check_file_name", "is_file_name"]

#: Longest accepted name [characters] (ext4, NTFS and APFS allow 255 bytes per component; the
#: rest is left for suffixes such as ``_truth.h5``).
MAX_LENGTH = 100
_PORTABLE = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")
_RESERVED = re.compile(r"(CON|PRN|AUX|NUL|COM[0-9]|LPT[0-9])(\..*)?", re.IGNORECASE)


def is_file_name(name: object) -> bool:
    r"""Whether ``name`` is a portable file-name component (see the module docstring).

    Parameters
    ----------
    name : object
        Candidate name.

    Returns
    -------
    bool

    Examples
    --------
    >>> is_file_name("identification"), is_file_name("run-2.b_c")
    (True, True)
    >>> [is_file_name(s) for s in ["../victim", "a/b", ".hidden", "", "x\x00", "nul.txt"]]
    [False, False, False, False, False, False]
    """
    return (
        isinstance(name, str)
        and 0 < len(name) <= MAX_LENGTH
        and _PORTABLE.fullmatch(name) is not None
        and _RESERVED.fullmatch(name) is None
    )


def check_file_name(name: object, where: str) -> str:
    """Return ``name`` if it is a portable file-name component, else refuse it.

    Parameters
    ----------
    name : object
        The name from the workflow (a TOML table name or value).
    where : str
        The workflow key, for the message (e.g. ``[datasets]``).

    Returns
    -------
    str
        ``name`` unchanged.

    Raises
    ------
    WorkflowError
        Naming the key and the name (its ``repr``, so that a NUL byte or a newline shows):
        the name would become a file name outside the plain ``A-Z a-z 0-9 . _ -`` set,
        starting with a dot, longer than :data:`MAX_LENGTH`, or reserved by Windows.

    Examples
    --------
    >>> check_file_name("unseen", "[datasets]")
    'unseen'
    >>> check_file_name("../../victim", "[datasets]")
    Traceback (most recent call last):
    ...
    debist.core.errors.WorkflowError: [datasets] '../../victim': a name that becomes a file name ...
    """
    if is_file_name(name):
        return str(name)
    raise WorkflowError(
        f"{where} {name!r}: a name that becomes a file name must be a plain file name: "
        f"1-{MAX_LENGTH} of the characters A-Z a-z 0-9 . _ -, not starting with '.', and not "
        "a device name (CON, NUL, ...)"
    )
