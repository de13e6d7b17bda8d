"""Checkpoints, rewinding, revisions and pruning: what makes late data exact.

The history keeps, for every scan inside the window, its detections, the track set before it
(a reference: track sets are immutable) and what it reported: the revision and signature of
each estimate, its events and its tally. A late measurement rewinds to the checkpoint before
its scan; the scans from there are run again and compared with what they reported before:
  estimates: an unchanged estimate is not reported again; a changed one gets revision + 1;
             one the scan no longer produces is retracted (revision + 1, status "retracted");
  events:    a new event is reported; one the scan no longer produces is withdrawn
             (retracted=True).
So a consumer applying revisions and withdrawals ends up with the same estimates and events
for any arrival order. Tallies are replaced, never added again: the counts of what the data
did are the sum over committed and live scans.
"""

from __future__ import annotations

import bisect
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from fusion.tracking.association_kernels import changed, taken
from fusion.tracking.detection import Detection
from fusion.tracking.id_sets import repeats
from fusion.tracking.replay import Gates, stands
from fusion.tracking.results import Estimate, ScanAssociations, ScanKey, TrackEvent
from fusion.tracking.revision_kernel import ALIVE, IDS, REV, SIG, revised, row_signatures
from fusion.tracking.trackset import Status, TrackSet

Revision = tuple[int, int, bool]  # (revision, signature, alive)


class Emitted:
    """What a scan reported last of each track's estimate: a table (fusion.tracking.revision_kernel:
    one (4, k) int64 array sorted by track id: its revision, signature (signatures_of) and whether
    it is alive, not retracted), where a dict of tuples cost ~120 bytes a track a scan (4 kB a
    track over a 2 s window); `emitted[track_id]` reads one row as a Revision. Never changed."""

    __slots__ = ("table",)

    def __init__(self, table: np.ndarray) -> None:
        self.table = table

    def __len__(self) -> int:
        return self.table.shape[1]

    def _at(self, track_id: int) -> int:
        ids = self.table[IDS]
        i = int(np.searchsorted(ids, track_id))
        return i if i < len(ids) and ids[i] == track_id else -1

    def __contains__(self, track_id: int) -> bool:
        return self._at(track_id) >= 0

    def __getitem__(self, track_id: int) -> Revision:
        i = self._at(track_id)
        if i < 0:
            raise KeyError(track_id)
        return int(self.table[REV, i]), int(self.table[SIG, i]), bool(self.table[ALIVE, i])


NONE_EMITTED = Emitted(np.empty((4, 0), dtype=np.int64))
_NO_IDS = np.empty(0, dtype=np.int64)


@dataclass
class Entry:
    """One scan in the window."""

    key: ScanKey
    dets: tuple[Detection, ...]
    before: TrackSet
    emitted: Emitted = NONE_EMITTED  # track id -> latest reported
    events: dict[tuple[str, int, int, str], TrackEvent] = field(default_factory=dict)
    tally: Counter = field(default_factory=Counter)
    associations: ScanAssociations | None = None  # what its run did with each detection
    gates: Gates | None = None  # its coarse pairs, when a partial re-run computed them


@dataclass(frozen=True)
class Rewind:
    """Where to start again: the track set to start from, the old entries of the scans to run and
    the track set each of them left (the next one's `before`, or the current set)."""

    start: TrackSet
    old: dict[ScanKey, Entry]
    keys: list[ScanKey]  # every scan to run, in order: old ones and new ones
    after: dict[ScanKey, TrackSet]


class History:
    def __init__(self) -> None:
        self.entries: list[Entry] = []
        self.keys: list[ScanKey] = []
        self.committed: Counter = Counter()  # tallies of scans pruned from the window

    def __len__(self) -> int:
        return len(self.entries)

    def rewind(self, new_keys: set[ScanKey], current: TrackSet, *, touched: set[ScanKey] | None = None) -> Rewind:
        """Remove the entries from the earliest scan that new data touches (new scans, and
        `touched`: times whose later scans must run again, e.g. a control input's), and say
        what to run."""
        start = min(bisect.bisect_left(self.keys, k) for k in new_keys | (touched or set()))
        old = self.entries[start:]
        keys = sorted(set(self.keys[start:]) | new_keys)
        ts = old[0].before if old else current
        after = {e.key: (old[i + 1].before if i + 1 < len(old) else current) for i, e in enumerate(old)}
        del self.entries[start:]
        del self.keys[start:]
        return Rewind(ts, {e.key: e for e in old}, keys, after)

    @property
    def newest(self) -> ScanKey | None:
        return self.keys[-1] if self.keys else None

    def append(self, entry: Entry) -> None:
        self.entries.append(entry)
        self.keys.append(entry.key)

    def prune(self, horizon_ns: int, max_scans: int) -> list[Entry]:
        """Commit (drop) the scans before the horizon, and the oldest beyond max_scans."""
        drop = 0
        n = len(self.entries)
        while drop < n and (self.keys[drop][0] < horizon_ns or n - drop > max_scans):
            drop += 1
        gone = self.entries[:drop]
        for e in gone:
            self.committed.update(e.tally)
        del self.entries[:drop]
        del self.keys[:drop]
        return gone

    def tally(self) -> Counter:
        total = Counter(self.committed)
        for e in self.entries:
            total.update(e.tally)
        return total


_STATUS_CODE = {s.label: int(s) for s in Status}  # an estimate's status label -> its Status


def signatures_of(estimates: list[Estimate]) -> np.ndarray:
    """The signature of each estimate's x, P and status (fusion.tracking.revision_kernel.row_signatures,
    as a scan computes it from its blocks): what decides whether a run again
    changed it. Kept for every estimate of the window (an int instead of the ~250 bytes
    themselves); compared only with the signature of the same track's estimate of the same scan
    in the same process (never stored in a checkpoint), so a changed estimate is taken for
    unchanged with probability ~2^-64 per comparison."""
    if not estimates:
        return _NO_IDS
    return row_signatures(np.stack([e.x for e in estimates]), np.stack([e.P for e in estimates]),
                          np.array([_STATUS_CODE[e.status] for e in estimates]))


def revise(entry: Entry, prev: Entry | None, new: list[Estimate], kept: np.ndarray = _NO_IDS,
           sigs: np.ndarray | None = None) -> list[Estimate]:
    """The estimates to report for a scan run (again): see the module docstring. `kept`: the ids
    (int64, any order) of the tracks of a partial re-run (fusion.tracking.replay) whose stored
    estimates stand as they were; `sigs`:
    the estimates' signatures if known (ScanOutcome.signatures), else signatures_of(new).
    Every track the previous run reported ends up in entry.emitted: produced again (unchanged:
    as it was; changed: revision + 1), standing (kept) or retracted (revision + 1 if it was
    alive): one compiled call (fusion.tracking.revision_kernel.revised). The estimates reported
    come in the order given, then the retractions by track id."""
    old = prev.emitted if prev else NONE_EMITTED
    n = len(new)
    produced = np.empty((2, n), dtype=np.int64)  # track ids, signatures
    produced[0] = np.fromiter((e.track_id for e in new), dtype=np.int64, count=n)
    produced[1] = signatures_of(new) if sigs is None else sigs
    same, rev, gone, table = revised(old.table, produced, kept)
    entry.emitted = Emitted(table)
    out = [e.with_revision(r) for e, r, s in zip(new, rev.tolist(), same.tolist(), strict=True) if not s]
    t_ns, sensor_id = entry.key
    out.extend(Estimate.retraction((tid, t_ns, sensor_id), r) for tid, r in zip(*gone.tolist(), strict=True))
    return out


def revise_associations(prev: Entry | None, new: ScanAssociations) -> ScanAssociations:
    """The associations to report for a scan run (again): every one of its first run; of a run
    again, those that differ from the previous run's (outcome, track, NIS, gated tracks) and the
    new measurements', in their order, as `revise` reports the estimates that changed. A late
    measurement re-runs the scans after it, each of hundreds of measurements, and changes the
    associations of a few: reported whole, they were ~23 times the rows of the in-order scans at
    667 targets with 10 % late data, and most of the recording (BENCHMARKS.md, Late data). The
    latest association of each measurement is the same either way. The stored run's rows are
    matched to the new run's by seq (`merged` keeps the stored detections in their order and
    puts an arrived one in its place). Where the new run holds a seq twice (two epochs of a
    publisher) a seq names no one row, and all of its rows are reported."""
    old = None if prev is None else prev.associations
    if old is None or not len(old) or repeats(new.seq):
        return new
    s_seq, seq = old.seq, new.seq
    old_pos = np.searchsorted(seq, s_seq)  # stored row k's position in the new run (no seq twice)
    diff = changed(old_pos, old.outcome, old.track_id, old.nis, old.gated_at, old.gated,
                   new.outcome, new.track_id, new.nis, new.gated_at, new.gated)
    if diff.all():
        return new
    rows = np.flatnonzero(diff)
    return ScanAssociations(new.sensor_id, new.t_ns, *taken(rows, seq, new.outcome, new.track_id, new.nis,
                                                            new.gated_at, new.gated))


def revise_events(entry: Entry, prev: Entry | None, new: list[TrackEvent], kept: np.ndarray = _NO_IDS
                  ) -> list[TrackEvent]:
    """The events to report for a scan run (again): new ones, and withdrawals of vanished ones;
    the stored events of the tracks `kept` (ids, sorted: Partial.kept) stand (a partial re-run)."""
    old = prev.events if prev else {}
    entry.events = {ev.key: ev for ev in new}
    if kept.size and old:
        entry.events.update({k: ev for (k, ev), s in zip(old.items(), stands(old.values(), kept), strict=True) if s})
    out = [ev for ev in new if ev.key not in old]
    out.extend(old[k].withdrawn() for k in sorted(old) if k not in entry.events)
    return out
