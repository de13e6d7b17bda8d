"""glibc's free heap pages given back to the system every few seconds, on a thread of their own.

Most of what the service allocates outside Python's own small-object heap (numpy's arrays,
Zenoh's buffers) comes from glibc's malloc. Once an array of a few hundred kB has been freed,
glibc raises its mmap threshold (up to 32 MB), so the next ones of that size come from its
arenas too; a freed one leaves a hole that stays resident (touched) until it is reused, and the
holes move as the load's sizes do. Measured in the soak's service (10k measurements/s at 667
targets, recording on; mallinfo2 and malloc_info from inside the process, 2026-12-06): glibc
held ~105 MB in use and 50-70 MB free in its arenas, mostly in chunks of 0.1-2.6 MB, and the
arenas grew from 159 to 171 MB over 20 minutes while what was in use did not (105 -> 104 MB);
Python's heap (91 arenas) and the rest (Rerun's mimalloc, stacks) stayed within a few MB.
`malloc_trim(0)` gives the free pages of every arena back (madvise), 30-40 MB of resident memory
there, in 2-4 ms of its caller's time; called every 60 s the holes were resident again within the
minute, so it runs every TRIM_INTERVAL_S.

The call does not hold Python's GIL (ctypes releases it), so on its own thread it costs the
service's loop nothing but glibc's arena locks for those milliseconds. Where the C library has
no malloc_trim (musl, macOS) the trimmer does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger("fusion.heap_trim")

TRIM_INTERVAL_S = 5.0


def glibc_malloc_trim() -> Callable[[], int] | None:
    """The C library's `malloc_trim(0)` as a function (returns 1 when memory was given back), or
    None where there is none."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        fn = libc.malloc_trim
    except (OSError, AttributeError, TypeError):
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return lambda: int(fn(0))


class HeapTrimmer:
    """Calls `trim` every `interval_s` on a daemon thread from start() until stop(); counts the
    calls and the time they took. Does nothing when `trim` is None (no malloc_trim here)."""

    def __init__(self, interval_s: float = TRIM_INTERVAL_S, trim: Callable[[], int] | None = None) -> None:
        if interval_s <= 0:
            raise ValueError(f"interval_s must be > 0, got {interval_s}")
        self.interval_s = interval_s
        self._trim = trim
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.calls = 0
        self.seconds = 0.0  # time inside trim, summed
        self.longest_s = 0.0

    @classmethod
    def for_this_process(cls, interval_s: float = TRIM_INTERVAL_S) -> HeapTrimmer:
        """A trimmer of this process's glibc heap (inert without glibc)."""
        return cls(interval_s, glibc_malloc_trim())

    @property
    def active(self) -> bool:
        """Whether there is something to call (glibc's malloc_trim, or the function given)."""
        return self._trim is not None

    def start(self) -> HeapTrimmer:
        if self._trim is not None and self._thread is None:
            self._thread = threading.Thread(target=self._run, name="fusion-heap-trim", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        trim = self._trim
        assert trim is not None
        while not self._stop.wait(self.interval_s):
            t0 = time.perf_counter()
            trim()
            took = time.perf_counter() - t0
            self.calls += 1
            self.seconds += took
            self.longest_s = max(self.longest_s, took)

    def stop(self) -> None:
        """Stop the thread (waits for a call in progress)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.calls:
            log.debug("heap trimmed %d times, %.1f ms each on average, %.1f ms at most", self.calls,
                      self.seconds / self.calls * 1e3, self.longest_s * 1e3)

    def __enter__(self) -> HeapTrimmer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
