"""Per-sensor sequence gaps: how many seq values are missing, in bounded memory.

For one publisher run (sensor, epoch) with lowest seq seen lo and highest hi, the gap count is

    missing = (hi - lo + 1) - |distinct seq seen in [lo, hi]|

kept as a sorted list of half-open intervals [a, b) of missing values, so a jump of a million
costs one interval, not a million entries. A seq that arrives later inside an interval (a late
or recovered sample) splits it: that value is no longer missing (counted as `filled`). A seq
below lo extends the run downwards (the values in between become missing); one already seen is
ignored (duplicates are the tracker's business).

Bounded memory: at most `max_intervals` intervals per run; past that the lowest interval is
given up (its values stay counted as missing, but can no longer be filled). At most
`max_epochs` runs per sensor are kept; an older run's counts are folded into the sensor's
totals. `restarts` counts how many times a sensor came back with a new epoch.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass


@dataclass(frozen=True)
class SensorGaps:
    missing: int  # seq values missing now, over every run of the sensor
    filled: int  # values that were missing and arrived later
    epochs: int  # runs (publisher epochs) seen
    restarts: int  # times a new epoch replaced the newest one


class _Run:
    """The seen range and missing intervals of one (sensor, epoch)."""

    __slots__ = ("ends", "filled", "given_up", "hi", "lo", "starts")

    def __init__(self, seq: int) -> None:
        self.lo = self.hi = seq
        self.starts: list[int] = []  # missing [starts[i], ends[i]), sorted, disjoint
        self.ends: list[int] = []
        self.given_up = 0
        self.filled = 0

    def add(self, seq: int, max_intervals: int) -> None:
        if seq > self.hi:
            if seq > self.hi + 1:
                self.starts.append(self.hi + 1)
                self.ends.append(seq)
            self.hi = seq
        elif seq < self.lo:
            if seq < self.lo - 1:
                self.starts.insert(0, seq + 1)
                self.ends.insert(0, self.lo)
            self.lo = seq
        else:
            i = bisect.bisect_right(self.starts, seq) - 1
            if i < 0 or seq >= self.ends[i]:
                return  # seen before
            self.filled += 1
            a, b = self.starts[i], self.ends[i]
            if a == seq and b == seq + 1:
                del self.starts[i], self.ends[i]
            elif a == seq:
                self.starts[i] = seq + 1
            elif b == seq + 1:
                self.ends[i] = seq
            else:
                self.ends[i] = seq
                self.starts.insert(i + 1, seq + 1)
                self.ends.insert(i + 1, b)
        while len(self.starts) > max_intervals:
            self.given_up += self.ends.pop(0) - self.starts.pop(0)

    @property
    def missing(self) -> int:
        return self.given_up + sum(b - a for a, b in zip(self.starts, self.ends, strict=True))


class SeqGaps:
    """Gaps in each sensor's seq, per publisher epoch (see the module docstring)."""

    def __init__(self, *, max_intervals: int = 1024, max_epochs: int = 4) -> None:
        self.max_intervals = max_intervals
        self.max_epochs = max_epochs
        self._runs: dict[str, dict[int, _Run]] = {}  # by sensor, then epoch (insertion order)
        self._newest: dict[str, int] = {}  # the largest epoch seen per sensor
        self._restarts: dict[str, int] = {}
        self._epochs: dict[str, int] = {}
        self._past: dict[str, tuple[int, int]] = {}  # (missing, filled) of runs no longer kept

    def add(self, sensor_id: str, epoch: int, seq: int) -> None:
        runs = self._runs.setdefault(sensor_id, {})
        run = runs.get(epoch)
        if run is not None:
            run.add(seq, self.max_intervals)
            return
        runs[epoch] = _Run(seq)
        self._epochs[sensor_id] = self._epochs.get(sensor_id, 0) + 1
        newest = self._newest.get(sensor_id)
        if newest is None or epoch > newest:
            if newest is not None:
                self._restarts[sensor_id] = self._restarts.get(sensor_id, 0) + 1
            self._newest[sensor_id] = epoch
        if len(runs) > self.max_epochs:
            oldest = min(runs)
            gone = runs.pop(oldest)
            m, f = self._past.get(sensor_id, (0, 0))
            self._past[sensor_id] = (m + gone.missing, f + gone.filled)

    def add_many(self, sensor_id: str, epochs: list[int], seqs: list[int]) -> None:
        """add(sensor_id, epoch, seq) for each (epoch, seq) of zip(epochs, seqs), in order; the
        next seq of a run (the common case: nothing missing, nothing filled) inline."""
        runs = self._runs.get(sensor_id)
        for epoch, seq in zip(epochs, seqs, strict=True):
            run = None if runs is None else runs.get(epoch)
            if run is not None and seq == run.hi + 1:
                run.hi = seq
            else:
                self.add(sensor_id, epoch, seq)
                runs = self._runs[sensor_id]

    def report(self) -> dict[str, SensorGaps]:
        out = {}
        for s in sorted(self._runs):
            missing, filled = self._past.get(s, (0, 0))
            for run in self._runs[s].values():
                missing += run.missing
                filled += run.filled
            out[s] = SensorGaps(missing, filled, self._epochs[s], self._restarts.get(s, 0))
        return out
