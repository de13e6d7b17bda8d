"""A batch that ends where a burst of samples ends, not halfway through a sensor's scan.

A sensor publishes a scan as a burst: one message per return, all with the scan's time, sent
back to back (667 returns took ~1 ms from the benchmark's publisher). The tracker takes a
scan as every measurement of (t_ns, sensor_id) it holds; a batch drained while the burst is
still arriving hands it part of the scan, and the rest, in the next batch, runs the scan again
(a rescan: the same tracks, the same result, but every track the first part missed has coasted
and is withdrawn again, and every estimate of the first part is revised). Measured at 10k
measurements/s, 667 targets: ~3 200 coasting events and as many withdrawals per second, more
rows in the recording than measurements.

`drain_burst` drains up to `limit` samples; while the batch is short of `limit` and samples
keep coming (one arrived within `gap_s` of the last look), it waits for them, at most
`linger_s` after the first drain. A quiet queue costs one wait of `gap_s`; a backlog (full
batches) none. A batch that the limit or the linger cut while samples kept coming says so
(`cut`): the service then holds its last scan for the next batch (fusion.pipeline's `more`) when
more samples are queued, so a scan longer than the linger (a blast, a backlog) is not run in two
parts either. What the tracker computes does not depend on how samples are batched (its
results are a function of the accepted measurements), only how many revisions it reports on
the way.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import NamedTuple

from fusion.io.intake_queue import IntakeQueue, Record


class Drained(NamedTuple):
    """A batch, and whether it was cut while its burst was still arriving (`cut`: the limit
    reached, or the linger over with samples still coming; not when a gap ended it), so that its
    last scan may be missing its rest."""

    batch: list[Record]
    cut: bool


def drain_burst(q: IntakeQueue, wake: threading.Event, limit: int, *, gap_s: float, linger_s: float,
                on_chunk: Callable[[list[Record]], None] | None = None) -> Drained:
    """The oldest `limit` samples of `q`, including those of a burst still arriving (module
    docstring). `wake` is set by the producer when it queues a sample; it is cleared here before
    each look at the queue, so a sample queued after the look sets it again. `on_chunk` is
    called with each part of the batch as it is drained, in order, before looking for the rest;
    the quiet gap_s that ends a burst is counted from the look that found the part, so the work
    done there overlaps the wait (a part's samples decoded while the burst's end is awaited)."""
    batch = q.drain(limit)
    found = time.monotonic()  # the last look that found samples
    end = found + linger_s
    if batch and on_chunk is not None:
        on_chunk(batch)
    if not batch or linger_s <= 0.0 or gap_s <= 0.0:
        return Drained(batch, len(batch) >= limit)
    while len(batch) < limit:
        now = time.monotonic()
        left, quiet = end - now, gap_s - (now - found)  # the linger left; the gap left since the last find
        if left <= 0.0:
            return Drained(batch, True)  # samples still coming when the linger ran out
        wake.clear()
        if not len(q) and (quiet <= 0.0 or not wake.wait(min(quiet, left))) and not len(q):
            # nothing for gap_s since the last find, and nothing queued by the time this thread
            # runs again (a wait's timeout is seen only once it holds the GIL again, and a
            # callback holding the GIL first may have queued the burst's next samples
            # meanwhile): the burst is over, unless the linger cut this wait short of the gap
            return Drained(batch, left < quiet)
        more = q.drain(limit - len(batch))
        if more:
            found = time.monotonic()
            if on_chunk is not None:
                on_chunk(more)
        batch.extend(more)
    return Drained(batch, True)
