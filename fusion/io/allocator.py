"""Rerun's allocator in a long-running service: give freed pages back to the system at once.

Rerun's Python bindings allocate through their own mimalloc (v3 in rerun-sdk 0.41), not
glibc's malloc. An open .rrd file keeps its footer's manifest in that allocator until the file
is closed: one row per chunk, dense over every (timeline, component) pair the file holds
(measured: a 512 MB file of the soak, 10k measurements/s at 667 targets, holds 4 117 chunks and
332 manifest columns, 9.8 MB as written). Closing the file at a rotation frees it, and mimalloc
by default keeps freed pages committed for `purge_delay` (1 000 ms) and purges them lazily, on
later allocations; Python's heap and glibc's arenas stayed flat over the same soak
(/proc/PID/smaps: 134 and 151 MB), the saw-tooth of resident memory was rerun's allocator alone.
Over 20-25 minutes both grow a little (measured from inside the soak's service, 2026-12-06;
bench/HISTORY.md, End to end: the soak): glibc's main arena by the holes freed numpy arrays leave, and this
allocator's resident part between rotations.

Measured with the soak (`python -m bench --only soak`: 10 minutes at 10k measurements/s, 667
targets, recording on; bench/HISTORY.md): resident memory after the first minute varied by 8.4-11.8 %
(max/min - 1) in four runs before, and by 3.8 % and 4.1 % in two runs with this setting and the
record written every second (recording.write_interval_s: fewer chunks, so a smaller footer index
held per open file); bench/HISTORY.md has what each of the two does alone.

mimalloc reads its options from the environment once, when it starts (the moment rerun's
bindings are loaded), so this must run before the first `import rerun`; a value the user set
in the environment is kept.
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

PURGE_DELAY_ENV = "MIMALLOC_PURGE_DELAY"
PURGE_DELAY_MS = 0  # purge freed pages at once (mimalloc's default: 1 000 ms, lazily)


def settle_allocator(environ: MutableMapping[str, str] = os.environ) -> bool:
    """Set MIMALLOC_PURGE_DELAY (unless already set) for rerun's allocator; True when rerun's
    bindings are not loaded yet, so the setting takes effect when they are."""
    environ.setdefault(PURGE_DELAY_ENV, str(PURGE_DELAY_MS))
    return "rerun_bindings" not in sys.modules
