"""Per-sensor arrival latency (arrival time - sensor time) statistics, in bounded memory."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LatencyStats:
    count: int
    mean_ms: float
    p50_ms: float
    p99_ms: float
    max_ms: float


class LatencyTracker:
    """Exact count, mean and max; p50 and p99 over the last `window` arrivals of each sensor."""

    def __init__(self, *, window: int = 4096) -> None:
        self.window = window
        self._ring: dict[str, np.ndarray] = {}
        self._n: dict[str, int] = {}
        self._sum: dict[str, float] = {}
        self._max: dict[str, float] = {}

    def add(self, sensor_id: str, latency_ns: int) -> None:
        ms = latency_ns * 1e-6
        ring = self._ring.get(sensor_id)
        if ring is None:
            ring = self._ring[sensor_id] = np.empty(self.window)
            self._n[sensor_id], self._sum[sensor_id], self._max[sensor_id] = 0, 0.0, -np.inf
        n = self._n[sensor_id]
        ring[n % self.window] = ms
        self._n[sensor_id] = n + 1
        self._sum[sensor_id] += ms
        if ms > self._max[sensor_id]:
            self._max[sensor_id] = ms

    def add_many(self, sensor_id: str, latencies_ns: list[int]) -> None:
        """add(sensor_id, x) for each x in order, with the same floats (the sum accumulated in
        the same order), in one call."""
        if not latencies_ns:
            return
        if sensor_id not in self._ring:
            self.add(sensor_id, latencies_ns[0])
            latencies_ns = latencies_ns[1:]
            if not latencies_ns:
                return
        ms = [x * 1e-6 for x in latencies_ns]
        ring, w, n = self._ring[sensor_id], self.window, self._n[sensor_id]
        total = self._sum[sensor_id]
        for v in ms:
            total += v
        self._sum[sensor_id] = total
        top = max(ms)
        if top > self._max[sensor_id]:
            self._max[sensor_id] = top
        k = len(ms)
        if k > w:  # only the last `window` land in the ring
            ms, n, k = ms[k - w:], n + k - w, w
        ring[(np.arange(n, n + k) % w)] = ms
        self._n[sensor_id] += len(latencies_ns)

    def stats(self) -> dict[str, LatencyStats]:
        out = {}
        for s in sorted(self._ring):
            n = self._n[s]
            r = self._ring[s][: min(n, self.window)]
            p50, p99 = np.percentile(r, [50, 99])
            out[s] = LatencyStats(n, self._sum[s] / n, float(p50), float(p99), float(self._max[s]))
        return out
