"""glibc's malloc thresholds and Python's collector for the process (debist.core.allocator).

Checked: mallopt takes both thresholds on glibc, a threshold the user set in the environment
is left alone, and a freed array of a record's size is reused from the heap afterwards (the
address of a second array of the same size is the first one's).
"""

import ctypes
import os
import platform
import subprocess
import sys

import pytest

from debist.core import allocator

GLIBC = platform.libc_ver()[0] == "glibc"


@pytest.mark.skipif(not GLIBC, reason="mallopt's thresholds are glibc's")
def test_thresholds_are_set_on_glibc_unless_the_user_set_one(monkeypatch):
    for name in allocator.ENVIRON:
        monkeypatch.delenv(name, raising=False)
    assert allocator.keep_freed_memory() is True
    assert allocator.keep_freed_memory() is True  # idempotent
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    assert allocator.keep_freed_memory() is False
    assert allocator.ENVIRON == {
        "MALLOC_MMAP_THRESHOLD_": "1073741824",
        "MALLOC_TRIM_THRESHOLD_": "2147483647",
    }


_PROBE = """
import ctypes, sys
if sys.argv[1] == "keep":
    from debist.core.allocator import keep_freed_memory
    assert keep_freed_memory()

class Mallinfo2(ctypes.Structure):  # glibc >= 2.33, malloc.h
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]

libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.mallinfo2.restype = Mallinfo2
before = libc.mallinfo2().hblks
block = libc.malloc(64 << 20)  # 64 MiB: above glibc's largest dynamic mmap threshold
mapped = libc.mallinfo2().hblks - before
libc.free(block)
print(mapped, libc.mallinfo2().arena >> 20)
"""


@pytest.mark.skipif(
    not GLIBC or not hasattr(ctypes.CDLL(None), "mallinfo2"), reason="glibc >= 2.33's mallinfo2"
)
def test_a_64_mib_block_comes_from_the_heap_and_stays_there_only_with_the_thresholds():
    """glibc's own statistics (mallinfo2): by default a 64 MiB block is a mapping of its own
    (one more in hblks) and the heap stays small; with the thresholds it is carved from the heap
    (hblks unchanged) and after free the heap keeps it (arena >= 64 MiB)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}

    def probe(mode: str) -> tuple[int, int]:
        out = subprocess.run(
            [sys.executable, "-c", _PROBE, mode], capture_output=True, text=True, env=env,
            check=True,
        ).stdout  # fmt: skip
        mapped, arena_mib = (int(x) for x in out.split())
        return mapped, arena_mib

    mapped, arena_mib = probe("default")
    assert mapped == 1 and arena_mib < 64
    mapped, arena_mib = probe("keep")
    assert mapped == 0 and arena_mib >= 64


_TRIM_PROBE = """
import ctypes
from debist.core.allocator import keep_freed_memory, release_freed_memory
assert keep_freed_memory()

def rss_mib():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20

libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
block = libc.malloc(64 << 20)
ctypes.memset(block, 1, 64 << 20)  # touched: resident
libc.free(block)
kept = rss_mib()
released = release_freed_memory()
print(kept - rss_mib(), released)
"""


@pytest.mark.skipif(
    not GLIBC or not os.path.exists("/proc/self/statm"), reason="glibc's malloc_trim, Linux's /proc"
)
def test_a_freed_block_the_heap_kept_goes_back_to_the_kernel_when_released():
    """With the thresholds a freed 64 MiB block stays resident in the heap (the previous test);
    release_freed_memory gives at least 60 MiB of it back."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run(
        [sys.executable, "-c", _TRIM_PROBE], capture_output=True, text=True, env=env, check=True
    ).stdout
    dropped, released = out.split()
    assert float(dropped) >= 60.0 and released == "True"


_POOL_PROBE = """
from debist.core.allocator import arrow_system_pool
print(arrow_system_pool())
import pyarrow as pa
print(pa.default_memory_pool().backend_name)
"""


@pytest.mark.parametrize(("user", "expected"), [(None, ["True", "system"]), ("jemalloc", None)])
def test_pyarrow_allocates_with_malloc_unless_the_user_chose_a_pool(user, expected):
    import pyarrow as pa

    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    if user is not None:
        try:
            getattr(pa, f"{user}_memory_pool")()
        except (NotImplementedError, AttributeError):
            pytest.skip(f"this pyarrow has no {user} pool")
        env["ARROW_DEFAULT_MEMORY_POOL"] = user
        expected = ["False", user]
    out = subprocess.run(
        [sys.executable, "-c", _POOL_PROBE], capture_output=True, text=True, env=env, check=True
    ).stdout
    assert out.split() == expected


def test_a_stage_freezes_the_collector_only_from_the_main_thread():
    """In the main thread the objects alive on entry leave the collections and come back on
    exit; in another thread (a batch's Dask worker) the process's collector is left alone."""
    import gc
    import threading

    from debist.core.allocator import collector_frozen

    assert gc.get_freeze_count() == 0
    with collector_frozen():
        frozen_here = gc.get_freeze_count()
    seen = []

    def worker():
        with collector_frozen():
            seen.append(gc.get_freeze_count())

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert frozen_here > 1000  # the imported modules, classes and functions at least
    assert seen == [0]
    assert gc.get_freeze_count() == 0
