"""The true states a recording scores its estimates against, by time.

Each time's truth is one block: its targets' ids sorted (a list) and their states stacked in that
order, S (k, d) float64. Scoring a flush's estimates (fusion.io.derive.match_truth) and its
OSPA/GOSPA read a time's truth as that one array; a batch of truth samples goes in as the block of
each time it holds (usually one: a simulation's truth of every target at a time), where a dict of
dicts took a Python call and a dict entry per sample, and every read stacked the samples again.

A sample for a (time, target) already held replaces it: the last one given wins, within a batch
and across batches. Times are dropped from the oldest: `forget_before(t_ns)`, once no estimate
left to score is before t_ns, and the oldest half past `kept` times (a bound for a run without a
window)."""

from __future__ import annotations

from operator import lt
from typing import NamedTuple

import numpy as np

from fusion.core.checks import Array

KEPT = 100_000  # times held at most (the oldest half dropped past it)


class TruthAt(NamedTuple):
    """The truth of one time: target ids (k,) sorted, and their states S (k, d) in that order."""

    ids: list[str]
    S: Array


class TruthTable:
    """Time (ns) -> TruthAt; see the module docstring. `newest_ns`: the newest time given (None
    before any)."""

    __slots__ = ("_at", "kept", "newest_ns")

    def __init__(self, kept: int = KEPT) -> None:
        self._at: dict[int, TruthAt] = {}
        self.kept = kept
        self.newest_ns: int | None = None

    def __len__(self) -> int:
        """The number of times held."""
        return len(self._at)

    def at(self, t_ns: int) -> TruthAt | None:
        return self._at.get(t_ns)

    def add(self, ids: list[str], t_ns: list[int], S: Array) -> None:
        """Samples: target ids[i] at time t_ns[i] in state S[i] ((n, d) float64). A batch of one
        new time with its ids in order (a simulation's truth of every target) is taken as it is
        (Python's checks, ~2 us a batch); anything else is sorted and merged per time."""
        n = len(t_ns)
        if not n:
            return
        t0 = t_ns[0]
        if t_ns.count(t0) == n:
            old = self._at.get(t0)
            if old is None and all(map(lt, ids, ids[1:])):
                self._at[t0] = TruthAt(list(ids), S)
            else:
                self._at[t0] = _merged(old, list(ids), S)
            newest = t0
        else:
            by_t: dict[int, list[int]] = {}
            for i, t in enumerate(t_ns):
                by_t.setdefault(t, []).append(i)
            for t, rows in by_t.items():
                self._at[t] = _merged(self._at.get(t), [ids[i] for i in rows], S[rows])
            newest = max(t_ns)
        if self.newest_ns is None or newest > self.newest_ns:
            self.newest_ns = newest
        if len(self._at) > self.kept:
            for k in sorted(self._at)[: self.kept // 2]:
                del self._at[k]

    def forget_before(self, t_ns: int) -> None:
        """Drop the times before t_ns."""
        for k in [k for k in self._at if k < t_ns]:
            del self._at[k]

    def continue_from(self, other: TruthTable) -> None:
        """Hold what `other` holds too (a recording's next file scores against the same truth)."""
        self._at.update(other._at)
        if other.newest_ns is not None and (self.newest_ns is None or other.newest_ns > self.newest_ns):
            self.newest_ns = other.newest_ns


def _merged(old: TruthAt | None, ids: list[str], S: Array) -> TruthAt:
    """The block of a time: what it held (if any) and the new samples, sorted by id, the last
    given of each id kept."""
    if old is not None:
        ids, S = old.ids + ids, np.concatenate([old.S, S])
    order = sorted(range(len(ids)), key=ids.__getitem__)  # stable: of one id, the last given last
    if len(set(ids)) < len(ids):
        order = [i for i, j in zip(order, [*order[1:], None], strict=True) if j is None or ids[j] != ids[i]]
    return TruthAt([ids[i] for i in order], S[order])
