"""Keep freed large arrays in the process's heap for reuse (glibc's malloc, Linux).

The identification and the free runs allocate and free many temporaries of one or a few
columns of a record (regressor columns, filtered copies, projections): 8 MB each at 10^6
samples. glibc serves a request above its mmap threshold (dynamic, at most 32 MiB) with a
fresh ``mmap`` and returns it to the kernel on ``free``, so every such temporary is paid again
in page faults and zeroed pages, a cost per sample that grows with the record's length.
:func:`keep_freed_memory` raises the mmap threshold and the trim threshold (``mallopt``), so
freed blocks stay in the heap and the next temporary of the same size reuses them. The peak
resident memory is that of the largest set of arrays alive at once, as before, plus what
fragmentation leaves; benchmarks/README.md has the measurements. The ``debist`` command calls
it at start; a batch's Dask workers get the same thresholds through glibc's environment
variables (:data:`ENVIRON`).

A user's own ``MALLOC_MMAP_THRESHOLD_`` or ``MALLOC_TRIM_THRESHOLD_`` (glibc's environment
variables) is kept; other C libraries (musl, macOS, Windows) are left alone.

References
----------
The GNU C Library manual, "Malloc Tunable Parameters" (``mallopt``, ``M_MMAP_THRESHOLD``,
``M_TRIM_THRESHOLD``); mallopt(3), Linux man-pages.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import platform

__all__ = ["ENVIRON", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

#: Requests at least this large still get their own mapping [bytes] (1 GiB).
MMAP_THRESHOLD = 1 << 30
#: The heap's free top is returned to the kernel only beyond this [bytes] (2 GiB - 1).
TRIM_THRESHOLD = (1 << 31) - 1
#: mallopt's parameter numbers (glibc's malloc.h).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: The same thresholds as glibc's environment variables, read when a process starts.
ENVIRON = {
    "MALLOC_MMAP_THRESHOLD_": str(MMAP_THRESHOLD),
    "MALLOC_TRIM_THRESHOLD_": str(TRIM_THRESHOLD),
}


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (idempotent).

    Returns
    -------
    bool
        True if both thresholds were set; False on a C library other than glibc, where the
        user set either threshold in the environment, or where ``mallopt`` refused.

    References
    ----------
    The GNU C Library manual, "Malloc Tunable Parameters"; mallopt(3).

    Examples
    --------
    >>> isinstance(keep_freed_memory(), bool)
    True
    """
    if platform.libc_ver()[0] != "glibc" or any(name in os.environ for name in ENVIRON):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return False
    ok = libc.mallopt(_M_MMAP_THRESHOLD, ctypes.c_int(MMAP_THRESHOLD))
    return bool(ok and libc.mallopt(_M_TRIM_THRESHOLD, ctypes.c_int(TRIM_THRESHOLD)))
