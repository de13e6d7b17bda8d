"""HeapTrimmer: calls its trim function on its cadence from its own thread and stops; inert
without one; and glibc's malloc_trim, where there is one, gives freed arena pages back (the
resident memory of a process that freed every other one of 512 blocks of 96 kB)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

from fusion.io.heap_trim import HeapTrimmer, glibc_malloc_trim


def test_calls_trim_on_its_cadence_from_another_thread_until_stopped() -> None:
    threads: list[str] = []

    def trim() -> int:
        threads.append(threading.current_thread().name)
        return 1

    with HeapTrimmer(0.02, trim) as t:
        assert t.active
        time.sleep(0.3)
    n = t.calls
    assert 5 <= n <= 16, n
    assert len(threads) == n and set(threads) == {"fusion-heap-trim"}
    assert t.seconds >= 0 and t.longest_s <= t.seconds
    time.sleep(0.1)
    assert t.calls == n  # stopped: no more calls
    assert not any(th.name == "fusion-heap-trim" for th in threading.enumerate())


def test_without_malloc_trim_it_does_nothing() -> None:
    before = threading.active_count()
    with HeapTrimmer(0.01, None) as t:
        assert not t.active
        assert threading.active_count() == before
        time.sleep(0.05)
    assert t.calls == 0


def test_a_cadence_must_be_positive() -> None:
    with pytest.raises(ValueError, match="interval_s must be > 0"):
        HeapTrimmer(0.0, lambda: 0)


FRAGMENT = """
import ctypes
from fusion.io.heap_trim import glibc_malloc_trim
from fusion.io.memory import process_memory
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
blocks = []
for _ in range(512):  # 96 kB blocks (under glibc's mmap threshold), touched
    p = libc.malloc(96 * 1024)
    ctypes.memset(p, 1, 96 * 1024)
    blocks.append(p)
held = process_memory().anon_mb
for p in blocks[::2]:  # every other one freed: holes the live ones keep apart (and from the heap's top)
    libc.free(p)
freed = process_memory().anon_mb
glibc_malloc_trim()()
print(held - freed, freed - process_memory().anon_mb)
"""


@pytest.mark.skipif(glibc_malloc_trim() is None, reason="no malloc_trim in this C library")
def test_glibc_malloc_trim_gives_freed_pages_back() -> None:
    r = subprocess.run([sys.executable, "-c", FRAGMENT], capture_output=True, text=True, check=True, timeout=60)
    by_free, by_trim = (float(v) for v in r.stdout.split())
    assert by_free < 5, by_free  # the control: free() alone leaves the holes resident
    assert by_trim > 15, by_trim  # of the 24 MB freed
