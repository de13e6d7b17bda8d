"""The intake queue between Zenoh's callback threads and the tracker thread: bounded in samples
and in bytes, a byte limit per message, per-source rate limits and fair queueing.

Every sample, whatever its key, goes through `offer(arrival_ns, key, size, payload_fn)` (or
`offer_many`, a chunk of them in order):
  1. size > max_message_bytes: refused "too_large", before its bytes are copied or decoded;
  2. its source over its rate (a token bucket of `rate_hz`, `burst` deep, per source): refused
     "rate_limited";
  3. the queue full (queue_max samples, or queue_max_bytes bytes with this one): the source that
     holds the most samples pays. If that is the sample's own source, the sample is refused
     "overload"; otherwise the biggest source's oldest samples are dropped ("overload", counted
     against it) until the new one fits. A flood from one source therefore costs that source
     alone: the others keep their place in the queue.
`drain(limit)` hands out the `limit` oldest samples across all sources, in the order they were
queued (a merge of the per-source queues by offer number), so that a batch never brings a
sample ahead of an older one of another source left for the next batch: under a backlog,
taking sources in turn handed one sensor's newer scans out before the other's older ones, and
every next batch was late data and a replay. Fairness is enforced at offer time (the flood
pays, step 3), so no source can hold more than its share of the queue, and so of a batch.

Sources (the fairness classes) are bounded in number: a measurement or input key whose id is a
configured source is its own class ("meas/cam1"); every truth key shares "truth"; every other
key (unknown sensors, wildcard puts) shares "other". Memory per sample is counted as payload +
key + RECORD_OVERHEAD_BYTES (the Python objects around them).

Counts (`refused`, by reason, `refused_by_source`, and `refused_kinds`: by the kind its key
names, "meas", "input", "truth" or "other", whatever its class) are what was offered and never
handed out: offered = handed out + sum(refused) + len(queue). One lock guards everything: `offer`
runs on Zenoh's threads, `drain` on the tracker's.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from fusion import messages as m

Record = tuple[int, str, bytes]
Offer = tuple[int, str, int, Callable[[], bytes]]  # (arrival_ns, key, size, payload_fn): a sample offered
# the Python objects of one queued sample beyond its payload's and key's bytes: the queue's tuple (offer
# number, record, cost) and the record's (arrival, key, payload), their ints, the key's str and the
# payload's bytes headers, the deque slot (CPython 3.11, tracemalloc: 490 bytes per sample of the e2e
# load, 149-byte payloads and 23-byte keys; 160 counted 332 of those 490)
RECORD_OVERHEAD_BYTES = 320

TOO_LARGE = "too_large"
RATE_LIMITED = "rate_limited"
OVERLOAD = "overload"


@dataclass(frozen=True)
class IntakeLimits:
    """queue_max samples and queue_max_bytes bytes in the queue; max_message_bytes per payload;
    rate_hz (0: no limit) and burst per source."""

    queue_max: int
    queue_max_bytes: int
    max_message_bytes: int
    rate_hz: float = 0.0
    burst: int = 1

    def __post_init__(self) -> None:
        if self.queue_max < 1 or self.queue_max_bytes < 1 or self.max_message_bytes < 1:
            raise ValueError("queue_max, queue_max_bytes and max_message_bytes must be at least 1")
        if self.rate_hz < 0 or self.burst < 1:
            raise ValueError("rate_hz must be >= 0 and burst >= 1")


def source_class(key: str, known: frozenset[str]) -> str:
    """The fairness class of a key expression fusion/NS/KIND/ID (see the module docstring)."""
    kind = key_kind(key)
    if kind == "truth":
        return "truth"
    if kind != "other" and (ident := key.rsplit("/", 1)[1]) in known:
        return f"{kind}/{ident}"
    return "other"


def key_kind(key: str) -> str:
    """The kind of sample a key expression fusion/NS/KIND/ID names (fusion.messages.key_kind):
    "meas", "input" or "truth", else "other"."""
    kind = m.key_kind(key)
    return kind if kind in _SAMPLE_KINDS else "other"


_SAMPLE_KINDS = frozenset(("meas", "input", "truth"))


class IntakeQueue:
    """See the module docstring. `known`: the configured sensor and control-source ids."""

    def __init__(self, limits: IntakeLimits, *, known: Iterable[str],
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.limits = limits
        self._known = frozenset(known)
        self._clock = clock
        self._lock = threading.Lock()
        self._queues: dict[str, deque[tuple[int, Record, int]]] = {}  # (offer number, record, cost)
        self._order: list[str] = []  # sorted class names with a queue
        self._seq = 0  # offer number of the next queued sample
        self._len = 0
        self._bytes = 0
        self._bucket: dict[str, tuple[float, float]] = {}  # class -> (tokens, time of last refill)
        self._classes: dict[str, str] = {}  # key expression -> its class (source_class), remembered
        self.offered = 0
        self.handed_out = 0
        self.refused: Counter[str] = Counter()
        self.refused_by_source: Counter[str] = Counter()
        self.refused_kinds: Counter[str] = Counter()
        self.max_depth = 0
        self.max_bytes = 0

    def __len__(self) -> int:
        return self._len

    @property
    def nbytes(self) -> int:
        return self._bytes

    @property
    def refused_total(self) -> int:
        return sum(self.refused.values())

    def depth_by_source(self) -> dict[str, int]:
        with self._lock:
            return {c: len(q) for c, q in sorted(self._queues.items()) if q}

    def _refuse(self, cls: str, reason: str, key: str) -> None:
        self.refused[reason] += 1
        self.refused_by_source[f"{cls}:{reason}"] += 1
        self.refused_kinds[key_kind(key)] += 1

    def _rate_ok(self, cls: str) -> bool:
        rate, burst = self.limits.rate_hz, float(self.limits.burst)
        if rate <= 0:
            return True
        now = self._clock()
        tokens, last = self._bucket.get(cls, (burst, now))
        tokens = min(burst, tokens + (now - last) * rate)
        if tokens < 1.0:
            self._bucket[cls] = (tokens, now)
            return False
        self._bucket[cls] = (tokens - 1.0, now)
        return True

    def offer(self, arrival_ns: int, key: str, size: int, payload: Callable[[], bytes]) -> str | None:
        """Queue one sample; None when queued, else the reason it was refused. `payload` is
        called (the bytes copied) only once the sample is admitted."""
        refusals: list[tuple[int, str]] = []
        self.offer_many(((arrival_ns, key, size, payload),), refusals)
        return refusals[0][1] if refusals else None

    def offer_many(self, samples: Iterable[Offer], refusals: list[tuple[int, str]] | None = None) -> int:
        """Queue samples (arrival_ns, key, size, payload_fn) in their order, each exactly as
        `offer` would, under one taking of the lock: a Zenoh channel's chunk, 0.87-0.93 us a
        sample against 1.19 one at a time, the Zenoh samples' accessors included (timeit, 50 000
        real samples, 2026-12-06). Returns how many were queued; (index, reason) of each refused
        one is appended to `refusals` when given."""
        lim = self.limits
        max_bytes, limited = lim.max_message_bytes, lim.rate_hz > 0
        queue_max, queue_max_bytes = lim.queue_max, lim.queue_max_bytes
        classes, queues = self._classes, self._queues
        queued = 0
        last_key: str | None = None
        cls = ""
        with self._lock:
            for i, (arrival_ns, key, size, payload) in enumerate(samples):
                if key != last_key:  # a chunk's samples mostly share their key
                    c = classes.get(key)
                    if c is None:  # a few keys carry every sample: each is classified once
                        if len(classes) >= 4096:
                            classes.clear()
                        c = classes[key] = source_class(key, self._known)
                    cls, last_key = c, key
                self.offered += 1
                reason = None
                if size > max_bytes:
                    reason = TOO_LARGE
                elif limited and not self._rate_ok(cls):
                    reason = RATE_LIMITED
                else:
                    cost = size + len(key) + RECORD_OVERHEAD_BYTES
                    while self._len + 1 > queue_max or self._bytes + cost > queue_max_bytes:
                        victim = self._biggest()
                        if victim is None or victim == cls or len(queues[victim]) <= len(queues.get(cls, ())):
                            reason = OVERLOAD
                            break
                        _, vrec, vcost = queues[victim].popleft()
                        self._len -= 1
                        self._bytes -= vcost
                        self._refuse(victim, OVERLOAD, vrec[1])
                if reason is not None:
                    self._refuse(cls, reason, key)
                    if refusals is not None:
                        refusals.append((i, reason))
                    continue
                q = queues.get(cls)
                if q is None:
                    q = queues[cls] = deque()
                    self._order = sorted(queues)
                q.append((self._seq, (arrival_ns, key, payload()), cost))
                self._seq += 1
                self._len += 1
                self._bytes += cost
                queued += 1
                if self._len > self.max_depth:
                    self.max_depth = self._len
                if self._bytes > self.max_bytes:
                    self.max_bytes = self._bytes
        return queued

    def _biggest(self) -> str | None:
        """The class with the most samples queued (ties: the first in sorted order)."""
        best, n = None, 0
        for c in self._order:
            if len(self._queues[c]) > n:
                best, n = c, len(self._queues[c])
        return best

    def drain(self, limit: int) -> list[Record]:
        """The `limit` oldest samples across sources (by offer number), in arrival order.

        A merge of the per-source queues: the source whose head is oldest hands out its run of
        samples older than every other source's head, in one slice."""
        out: list[Record] = []
        with self._lock:
            queues = [q for q in self._queues.values() if q]
            while len(out) < limit and queues:
                if len(queues) == 1:
                    q, bound = queues[0], None
                else:
                    queues.sort(key=lambda q: q[0][0])
                    q, bound = queues[0], queues[1][0][0]
                while q and len(out) < limit and (bound is None or q[0][0] < bound):
                    _, rec, cost = q.popleft()
                    out.append(rec)
                    self._len -= 1
                    self._bytes -= cost
                if not q:
                    queues.pop(0)
            self.handed_out += len(out)
        out.sort(key=lambda r: r[0])
        return out
