"""The process's allocators: freed arrays reused within a stage, returned between stages.

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

Between stages the opposite is right: a stage's temporaries are gone, and what the heap kept
of them would only raise the next stages' peak (and that of every process forked later, which
inherits the pages). The runner calls :func:`release_freed_memory` (glibc's ``malloc_trim``)
after each stage. pyarrow's default pool (mimalloc) likewise keeps segments of its own after
the Parquet reads and writes; :func:`arrow_system_pool` has pyarrow allocate with the C
library's ``malloc`` instead, whose freed memory the same trim returns. (The figures are drawn
outside the stage's process for the same reason: :mod:`debist.report.render`.)

Python's cyclic garbage collector costs time of its own: each full collection traverses every
container object alive, most of them the imported libraries' modules, classes and functions,
which live as long as the process. While a stage runs, :func:`collector_frozen` leaves the
objects alive when it started (its code, the run's configuration, the stages' data read so
far) out of the collections (``gc.freeze``) and hands them back when it ends; forked children
then do not write to those pages either. :func:`skip_final_collection` spares the command's
last collection at interpreter exit, which traverses everything once more only to free memory
the kernel frees anyway.

A user's own ``MALLOC_MMAP_THRESHOLD_`` or ``MALLOC_TRIM_THRESHOLD_`` (glibc's environment
variables) is kept; other C libraries (musl, macOS, Windows) are left alone.

References
----------
Python documentation, :mod:`gc` (``gc.freeze``, ``gc.unfreeze``); the GNU C Library manual,
"Malloc Tunable Parameters" (``mallopt``, ``M_MMAP_THRESHOLD``,
``M_TRIM_THRESHOLD``); mallopt(3) and malloc_trim(3), Linux man-pages; Apache Arrow
documentation, "Memory Management" (``ARROW_DEFAULT_MEMORY_POOL``).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import platform
import threading
from collections.abc import Iterator

__all__ = [
    "ARROW_ENVIRON",
    "ENVIRON",
    "MMAP_THRESHOLD",
    "TRIM_THRESHOLD",
    "arrow_system_pool",
    "collector_frozen",
    "keep_freed_memory",
    "release_freed_memory",
    "skip_final_collection",
]

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
#: pyarrow's allocator, chosen by its environment variable before pyarrow allocates.
ARROW_ENVIRON = {"ARROW_DEFAULT_MEMORY_POOL": "system"}


def _glibc() -> ctypes.CDLL | None:
    """Load the C library if it is glibc (None elsewhere or if it cannot be loaded)."""
    if platform.libc_ver()[0] != "glibc":
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None


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
    libc = _glibc()
    if libc is None or any(name in os.environ for name in ENVIRON):
        return False
    ok = libc.mallopt(_M_MMAP_THRESHOLD, ctypes.c_int(MMAP_THRESHOLD))
    return bool(ok and libc.mallopt(_M_TRIM_THRESHOLD, ctypes.c_int(TRIM_THRESHOLD)))


def release_freed_memory() -> bool:
    """Return the free pages of the C library's heap to the kernel (glibc's ``malloc_trim``).

    Memory still in use is untouched; only what :func:`keep_freed_memory` kept for reuse goes.

    Returns
    -------
    bool
        True if glibc released memory; False if there was none to release or the C library
        is not glibc.

    References
    ----------
    malloc_trim(3), Linux man-pages.

    Examples
    --------
    >>> isinstance(release_freed_memory(), bool)
    True
    """
    libc = _glibc()
    return bool(libc is not None and libc.malloc_trim(ctypes.c_size_t(0)))


def arrow_system_pool() -> bool:
    """Have pyarrow allocate with the C library's ``malloc`` (its ``system`` memory pool).

    Sets :data:`ARROW_ENVIRON` in this process's environment, which pyarrow reads when it
    first allocates and which processes started from this one inherit; call it before pyarrow
    is imported. A pool the user chose in the environment is kept.

    Returns
    -------
    bool
        True if the variable was set here; False if the user had set it.

    References
    ----------
    Apache Arrow documentation, "Memory Management", ``ARROW_DEFAULT_MEMORY_POOL``.

    Examples
    --------
    >>> ARROW_ENVIRON
    {'ARROW_DEFAULT_MEMORY_POOL': 'system'}
    """
    ((name, value),) = ARROW_ENVIRON.items()
    if name in os.environ:
        return False
    os.environ[name] = value
    return True


@contextlib.contextmanager
def collector_frozen() -> Iterator[None]:
    """Leave the objects alive now out of the cyclic garbage collector while the block runs.

    Every container object tracked on entry moves to the collector's permanent generation
    (``gc.freeze``): the collections inside the block traverse only what the block creates.
    On exit they return to the oldest generation (``gc.unfreeze``), so garbage among them is
    collected as before; nothing is kept alive longer than without the block. Not reentrant:
    the inner block's exit hands back the outer block's objects too. Outside the main thread
    it does nothing: there the process and its one collector belong to other threads too (a
    batch's Dask worker), and freezing them raised a worker's peak memory over four workflows
    from 621 to 757 MiB (617 MiB without).

    Yields
    ------
    None

    References
    ----------
    Python documentation, :func:`gc.freeze` and :func:`gc.unfreeze`.

    Examples
    --------
    >>> with collector_frozen():
    ...     gc.get_freeze_count() > 0
    True
    >>> gc.get_freeze_count()
    0
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def skip_final_collection() -> None:
    """Spare the collection Python runs at interpreter exit (call it when the work is done).

    Freezes every tracked object (``gc.freeze``), so the exit's collection traverses none of
    them; their memory goes back with the process. ``atexit`` handlers and the modules'
    teardown run as before, but an object that is garbage only as part of a reference cycle is
    not finalized: what must reach a file is closed before (every write of a run is, by
    ``with`` blocks and atomic renames).

    References
    ----------
    Python documentation, :func:`gc.freeze`.
    """
    gc.freeze()
