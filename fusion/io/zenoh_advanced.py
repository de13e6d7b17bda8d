"""Zenoh's advanced publisher and subscriber for measurements: nothing lost that can be recovered.

A publisher (`declare_recoverable_publisher`) keeps its last `cache_samples` samples, numbers
them (zenoh's own source sequence number), announces itself (publisher detection, a liveliness
token `<key>/@adv/pub/<zid>/<eid>/...`) and sends a heartbeat with its last number every
`heartbeat_s`. A `RecoveringSubscription`:
  - joins late without loss: on start, and whenever a new publisher appears, it asks the
    publishers' caches for what they hold (HistoryConfig(detect_late_publishers=True));
  - recovers a dropped sample: a hole in a publisher's numbers (seen on the next sample, or on
    the heartbeat when the lost one was the last) makes it query that publisher's cache;
  - counts what could not be recovered (the cache had moved on): zenoh's sample-miss listener
    reports (publisher, number missed), mapped to the key id (sensor) the publisher announced.
Samples recovered go to the same handler (a callback, or the service's channel) as live ones.
The publisher and miss callbacks run on zenoh's threads and only count under a lock (the miss
counts are read from the service's loop).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

_PUB_TOKEN = "/@adv/pub/"
_SUB_TOKEN = "/@adv/sub/"


def declare_recoverable_publisher(session: Any, key: str, *, cache_samples: int = 1000,
                                  heartbeat_s: float = 0.5) -> Any:
    """An advanced publisher on `key`: blocking congestion control, a cache of `cache_samples`,
    miss detection with a heartbeat every `heartbeat_s`, publisher detection."""
    import zenoh
    import zenoh.ext as zx

    return zx.declare_advanced_publisher(
        session, key, congestion_control=zenoh.CongestionControl.BLOCK,
        cache=zx.CacheConfig(max_samples=cache_samples),
        sample_miss_detection=zx.MissDetectionConfig(heartbeat=heartbeat_s), publisher_detection=True)


def wait_for_recovering_subscriber(session: Any, key: str, *, timeout_s: float) -> bool:
    """Wait until a RecoveringSubscription whose key covers `key` is announced (its liveliness
    token); True if one is. Samples put before that are not lost while they are in the cache,
    but a burst larger than the cache would be."""
    deadline = time.monotonic() + timeout_s
    while True:
        replies = session.liveliness().get(key + _SUB_TOKEN + "**", timeout=min(1.0, max(timeout_s, 0.01)))
        if any(r.ok is not None for r in replies):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)


def _entity(zid: Any, eid: Any) -> tuple[str, int]:
    return (str(zid), int(eid))


class RecoveringSubscription:
    """An advanced subscriber on `key` (e.g. fusion/NS/meas/*) handing every sample, live or
    recovered, to `handler`: a callback, or a Zenoh channel read through `handler` (the
    service's: fusion.io.channel_intake); `missed()` says how many samples zenoh reported lost for
    good, by the key id (last segment) of the publisher that sent them."""

    def __init__(self, session: Any, key: str, handler: Callable[[Any], None] | Any) -> None:
        import zenoh.ext as zx

        self._lock = threading.Lock()
        self._key_of: dict[tuple[str, int], str] = {}  # publisher (zid, eid) -> its key id
        self._missed: dict[str, int] = {}
        self._sub = zx.declare_advanced_subscriber(
            session, key, handler, history=zx.HistoryConfig(detect_late_publishers=True),
            recovery=zx.RecoveryConfig(heartbeat=True), subscriber_detection=True)
        self._publishers = self._sub.detect_publishers(self._on_publisher, history=True)
        self._listener = self._sub.sample_miss_listener(self._on_miss)

    @property
    def handler(self) -> Any:
        """The channel's receiving end, when a channel was given (None for a callback)."""
        return self._sub.handler

    def _on_publisher(self, sample: Any) -> None:
        """A publisher's liveliness token `<key>/@adv/pub/<zid>/<eid>/...`."""
        token = str(sample.key_expr)
        key, sep, rest = token.partition(_PUB_TOKEN)
        parts = rest.split("/")
        if sep and len(parts) >= 2 and parts[1].isdigit():
            with self._lock:
                self._key_of[(parts[0], int(parts[1]))] = key.rsplit("/", 1)[-1]

    def _on_miss(self, miss: Any) -> None:
        src = miss.source
        with self._lock:
            who = self._key_of.get(_entity(src.zid, src.eid), "unknown publisher")
            self._missed[who] = self._missed.get(who, 0) + int(miss.nb)

    def missed(self) -> dict[str, int]:
        """Samples reported missed and not recovered, by key id."""
        with self._lock:
            return dict(sorted(self._missed.items()))

    def undeclare(self) -> None:
        self._listener.undeclare()
        self._publishers.undeclare()
        self._sub.undeclare()
