"""The publishing loop: a built stream onto Zenoh, paced by arrival time.

Publishers are declared per key with blocking congestion control (the default, DROP, loses
messages in bursts). Measurements and inputs go through zenoh's advanced publisher
(fusion.io.zenoh_advanced: a cache of the last `cache_samples`, heartbeats, publisher
detection), so a service that joins late or drops a sample recovers it from the cache; the
loop still waits (bounded) until the service's subscriptions are announced (truth's too), so
that a burst larger than the cache is not lost before them. speed 1 is real time, speed 10 ten
times faster, speed 0 as fast as possible.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from fusion.io.zenoh_advanced import declare_recoverable_publisher, wait_for_recovering_subscriber
from fusion.io.zenoh_bus import wait_for_match
from publishers.stream import Sample

log = logging.getLogger("publishers")

_BOOT_EPOCH = time.time_ns()  # fixed at process start


def boot_epoch() -> int:
    """This process's publisher epoch (its boot id): the wall clock in ns when it started, so a
    restarted publisher has a new and larger one (fusion.messages.Measurement.epoch)."""
    return _BOOT_EPOCH


def publish(session: Any, samples: Sequence[Sample], *, speed: float = 1.0, match_timeout_s: float = 10.0,
            stop: threading.Event | None = None, progress: Callable[[int], None] | None = None,
            cache_samples: int = 1000) -> Counter[str]:
    """Put every sample on its key at its (scaled) arrival time; return counts per key kind.
    progress(n) is called with the number of samples put so far (for a progress bar)."""
    import zenoh

    pubs: dict[str, Any] = {}
    for s in samples:
        if s.key in pubs:
            continue
        if _recoverable(s.key):
            pubs[s.key] = declare_recoverable_publisher(session, s.key, cache_samples=cache_samples)
        else:
            pubs[s.key] = session.declare_publisher(s.key, congestion_control=zenoh.CongestionControl.BLOCK)
    counts: Counter[str] = Counter()
    try:
        # truth's too: a truth sample that reaches the service after the measurements of its
        # time cannot score them
        for k in sorted(pubs, key=lambda k: (not _recoverable(k), k)):
            matched = (wait_for_recovering_subscriber(session, k, timeout_s=match_timeout_s) if _recoverable(k)
                       else wait_for_match(pubs[k], timeout_s=match_timeout_s))
            if not matched:
                log.warning("no subscriber matched %s within %.1f s; publishing anyway", k, match_timeout_s)
                break
        if not samples:
            return counts
        a0 = samples[0].arrival_ns
        w0 = time.monotonic_ns()
        for s in samples:
            if stop is not None and stop.is_set():
                break
            if speed > 0:
                due = w0 + (s.arrival_ns - a0) / speed
                wait = (due - time.monotonic_ns()) / 1e9
                if wait > 0:
                    time.sleep(wait)
            pubs[s.key].put(s.payload)
            counts[s.key.split("/")[2]] += 1
            if progress is not None:
                progress(counts.total())
    finally:
        for p in pubs.values():
            p.undeclare()
    return counts


_KINDS = {"meas": "measurements", "input": "control inputs", "truth": "truth samples"}  # in the order said


def sent_words(counts: Mapping[str, int], *, always: tuple[str, ...] = ()) -> str:
    """Samples by kind (`publish`'s counts: "meas", "input", "truth") as words, in that order:
    "6496 measurements and 3600 truth samples", "100 measurements, 100 control inputs and 100
    truth samples"; kinds with none are left out unless in `always`; "nothing" if none at all."""
    parts = [f"{counts.get(k, 0)} {w}" for k, w in _KINDS.items() if counts.get(k, 0) or k in always]
    parts += [f"{n} {k}" for k, n in sorted(counts.items()) if k not in _KINDS and n]
    if not parts:
        return "nothing"
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def _recoverable(key: str) -> bool:
    """Measurements and inputs: published through the advanced publisher (truth is not)."""
    return "/meas/" in key or "/input/" in key
