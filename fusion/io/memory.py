"""A process's resident memory as Linux reports it (/proc/PID/status), split by what holds it.

RSS = RssAnon + RssFile + RssShmem: anonymous pages (the heaps: Python's objects, numpy's arrays,
glibc's arenas, the Rust allocators of Zenoh and Rerun, thread stacks) and pages of mapped files
(the shared libraries: llvmlite, rerun, zenoh, arrow, numpy; ~160 MB for `fusion serve`, fixed
once they are loaded). A leak or a backlog shows in the anonymous part; the file part only grows
while code is first used.
"""

from __future__ import annotations

from pathlib import Path

import msgspec

_FIELDS = {"VmRSS": "rss_mb", "RssAnon": "anon_mb", "RssFile": "file_mb", "RssShmem": "shmem_mb", "VmHWM": "peak_mb"}


class Memory(msgspec.Struct, frozen=True, kw_only=True):
    """Resident memory in MB (2^20 bytes): total, anonymous, file-backed, shared memory, and the
    peak total so far (VmHWM)."""

    rss_mb: float
    anon_mb: float
    file_mb: float
    shmem_mb: float
    peak_mb: float


def parse_status(text: str) -> Memory:
    """The Memory of a /proc/PID/status text (its fields are in kB)."""
    got: dict[str, float] = {}
    for line in text.splitlines():
        name, _, rest = line.partition(":")
        if name in _FIELDS:
            got[_FIELDS[name]] = int(rest.split()[0]) / 1024
    missing = [k for k, v in _FIELDS.items() if v not in got]
    if missing:
        raise ValueError(f"/proc status without {', '.join(missing)}")
    return Memory(**got)


def process_memory(pid: int | str = "self") -> Memory:
    """The resident memory of process `pid` (default: this one). OSError if it is not there (no
    such process, no /proc)."""
    return parse_status(Path(f"/proc/{pid}/status").read_text())
