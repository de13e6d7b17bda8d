"""Gaps in each sensor's sequence numbers, as the samples arrive: what the network lost.

`SeqGaps.see(sensor_id, seq)` per arriving measurement of a configured sensor. Per sensor it
keeps the highest seq seen and the set of missing numbers below it (at most `max_missing`,
the oldest forgotten first): a seq above the highest opens a gap of the numbers skipped; a late
one that fills a gap closes it (counted as `filled`); one seen before is a repeat (the tracker
refuses it as a duplicate). A seq more than `restart_window` below the highest is a publisher
that started again: counted as a `restart`, and its numbering starts afresh. `status()`: per
sensor, missing now, filled, restarts, and the highest seq.

`peek(payload)` reads only sensor_id and seq from a msgpack measurement (about 0.3 us; None
for anything that is not one), so the count costs almost nothing before the real decoding.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import msgspec


class _Peek(msgspec.Struct):
    sensor_id: str
    seq: int


_peek = msgspec.msgpack.Decoder(_Peek)


def peek(payload: bytes) -> tuple[str, int] | None:
    try:
        p = _peek.decode(payload)
    except (msgspec.DecodeError, UnicodeDecodeError, ValueError, OverflowError):
        return None
    return p.sensor_id, p.seq


@dataclass
class _Sensor:
    highest: int
    missing: OrderedDict[int, None] = field(default_factory=OrderedDict)
    filled: int = 0
    restarts: int = 0


class SeqGaps:
    """See the module docstring."""

    def __init__(self, *, max_missing: int = 10_000, restart_window: int = 1000) -> None:
        self.max_missing = max_missing
        self.restart_window = restart_window
        self._s: dict[str, _Sensor] = {}

    def see(self, sensor_id: str, seq: int) -> None:
        s = self._s.get(sensor_id)
        if s is None:
            self._s[sensor_id] = _Sensor(highest=seq)
            return
        if seq > s.highest:
            for q in range(max(s.highest + 1, seq - self.max_missing), seq):
                s.missing[q] = None
            while len(s.missing) > self.max_missing:
                s.missing.popitem(last=False)
            s.highest = seq
        elif seq in s.missing:
            del s.missing[seq]
            s.filled += 1
        elif seq < s.highest - self.restart_window:
            s.restarts += 1
            s.highest = seq
            s.missing.clear()

    def status(self) -> dict[str, dict[str, int]]:
        return {k: {"missing": len(s.missing), "filled": s.filled, "restarts": s.restarts, "highest_seq": s.highest}
                for k, s in sorted(self._s.items())}
