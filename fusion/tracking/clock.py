"""The tracker's sense of time: a robust clock per source, and the watermark the window follows.

Each source (a configured sensor, or the control source) has its own clock. Detection i of a
source has the offset o_i = t_i - a_i (a_i its arrival time; 0 when arrival times are unknown)
and the source's clock at arrival a is
    clock_s(a) = a + the (k+1)-th largest of its last N offsets      (k = clock_outliers),
so it follows the source's freshest data, but k wrong timestamps cannot push it; with arrival
times it moves on by itself during a silence.

The window follows the slowest source that is still active (a watermark, as in stream
processing), so data are never "too late" because another sensor is faster, or because zenoh
delivered another key's backlog first (it keeps order per key, not across keys):
    watermark(a) = min over active sources of clock_s(a).
A source is active while it has delivered something within the last source_idle_s of arrival
time; a configured source that has not delivered yet holds the watermark back during the first
source_idle_s after the first arrival. Without arrival times, a source is active while its
clock is within source_idle_s of the most advanced source's.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterable


class SourceClock:
    """clock(a) = a + the (outliers+1)-th largest of the last `samples` offsets t_i - a_i; with
    fewer offsets than that, the smallest. That offset is kept current (`offset`) as offsets
    come and go, so reading the clock is one addition."""

    def __init__(self, samples: int, outliers: int) -> None:
        self._window: deque[int] = deque(maxlen=samples)
        self._sorted: list[int] = []
        self._rank = outliers + 1
        self.last_arrival_ns: int | None = None
        self.offset: int | None = None  # the clock minus the arrival time; None before any data
        self.settled = False  # enough offsets that `outliers` wrong ones cannot decide the clock

    def now(self, arrival_ns: int | None) -> int | None:
        """The clock at an arrival; None before any data."""
        o = self.offset
        return None if o is None else (arrival_ns or 0) + o

    def state(self) -> tuple[list[int], int | None]:
        """(offsets, oldest first; last arrival), for a checkpoint."""
        return list(self._window), self.last_arrival_ns

    def restore(self, offsets: list[int], last_arrival_ns: int | None) -> None:
        self._window.clear()
        self._sorted.clear()
        for o in offsets[-(self._window.maxlen or len(offsets)):]:
            self._window.append(o)
            bisect.insort(self._sorted, o)
        self.last_arrival_ns = last_arrival_ns
        self._settle()

    def observe(self, t_ns: int, arrival_ns: int | None) -> None:
        o = t_ns - (arrival_ns or 0)
        window, srt = self._window, self._sorted
        if len(window) == window.maxlen:
            del srt[bisect.bisect_left(srt, window[0])]
        window.append(o)
        bisect.insort(srt, o)
        self.last_arrival_ns = arrival_ns
        k = len(srt)  # _settle, inline: once per admitted measurement
        self.settled = k >= self._rank
        self.offset = srt[max(k - self._rank, 0)]

    def _settle(self) -> None:
        k = len(self._sorted)
        self.settled = k >= self._rank
        self.offset = self._sorted[max(k - self._rank, 0)] if k else None


class Clocks:
    """The clocks of every source and the watermark (see the module docstring)."""

    def __init__(self, sources: Iterable[str], *, samples: int, outliers: int, idle_ns: int) -> None:
        self.sources = {s: SourceClock(samples, outliers) for s in sorted(sources)}
        self.samples, self.outliers = samples, outliers
        self.idle_ns = idle_ns
        self._first_arrival: int | None = None

    def reference(self, source: str, arrival_ns: int | None) -> int | None:
        """The clock that judges whether a time from `source` is in the future: the source's
        own once settled, else the most advanced other source's (None before any data)."""
        own = self.sources[source]
        if own.settled:
            return (arrival_ns or 0) + own.offset  # type: ignore[operator]
        others = [c.now(arrival_ns) for s, c in self.sources.items() if s != source and c.settled]
        return max((t for t in others if t is not None), default=own.now(arrival_ns))

    @property
    def first_arrival_ns(self) -> int | None:
        return self._first_arrival

    def restore_first_arrival(self, arrival_ns: int | None) -> None:
        self._first_arrival = arrival_ns

    def observe(self, source: str, t_ns: int, arrival_ns: int | None) -> None:
        if arrival_ns is not None and self._first_arrival is None:
            self._first_arrival = arrival_ns
        self.sources[source].observe(t_ns, arrival_ns)

    def step(self, source: str, t_ns: int, arrival_ns: int | None, future_ns: int) -> tuple[int | None, int | None]:
        """One detection's time, as the intake judges it: (the reference it is judged against,
        the watermark after it), having observed it unless it is more than future_ns ahead of
        the reference (with arrival times; without, it always counts). Exactly
            arrival None: observe(source, t, None); reference(source, None); watermark(None)
            else:         ref = reference(source, a); observe(source, t, a) unless t > ref + future_ns;
                          watermark(a)
        with the common case (arrival time known, the source's clock settled) done inline."""
        c = self.sources[source]
        if arrival_ns is None or not c.settled:
            if arrival_ns is None:
                self.observe(source, t_ns, None)
                ref = self.reference(source, None)
            else:
                ref = self.reference(source, arrival_ns)
                if ref is None or t_ns <= ref + future_ns:
                    self.observe(source, t_ns, arrival_ns)
            return ref, self.watermark(arrival_ns)
        ref = arrival_ns + c.offset  # type: ignore[operator]
        if t_ns <= ref + future_ns:  # observe(source, t_ns, arrival_ns), inline
            if self._first_arrival is None:  # (a clock restored from a checkpoint without it)
                self._first_arrival = arrival_ns
            o = t_ns - arrival_ns
            window, srt = c._window, c._sorted
            if len(window) == window.maxlen:
                del srt[bisect.bisect_left(srt, window[0])]
            window.append(o)
            bisect.insort(srt, o)
            c.last_arrival_ns = arrival_ns
            k = len(srt)
            c.settled = k >= c._rank
            c.offset = srt[max(k - c._rank, 0)]
        low: int | None = None  # watermark(arrival_ns), inline
        idle, first = self.idle_ns, self._first_arrival
        for c in self.sources.values():
            last = c.last_arrival_ns
            if last is None:
                if first is not None and arrival_ns - first < idle:
                    return ref, None
                continue
            if arrival_ns - last > idle:
                continue
            o = c.offset
            if low is None or o < low:  # type: ignore[operator]
                low = o
        return ref, None if low is None else arrival_ns + low

    def watermark(self, arrival_ns: int | None) -> int | None:
        """min over active sources of their clocks; None while a source that must be waited
        for has no clock yet."""
        if arrival_ns is None:
            nows = [n for c in self.sources.values() if (n := c.now(None)) is not None]
            if not nows:
                return None
            newest = max(nows)
            return min(n for n in nows if n >= newest - self.idle_ns)
        low: int | None = None  # the smallest offset of the active sources
        for c in self.sources.values():
            last = c.last_arrival_ns
            if last is None:
                if self._first_arrival is not None and arrival_ns - self._first_arrival < self.idle_ns:
                    return None  # it may still start: wait for it
                continue
            if arrival_ns - last > self.idle_ns:
                continue  # idle: it does not hold the others back
            o = c.offset
            if low is None or o < low:  # type: ignore[operator]
                low = o
        return None if low is None else arrival_ns + low
