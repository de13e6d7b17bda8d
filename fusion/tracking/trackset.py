"""The immutable set of tracks that the tracker checkpoints, as arrays (one row per track).

A TrackSet is never modified: each scan builds a new one, so a checkpoint is a reference and
rewinding for a late measurement costs nothing. Everything is a column, so gating, updates and
the lifecycle are vectorised over tracks and a scan builds no per-track objects:
  ids, status, hits, birth_t_ns, t_ns (of the last update), chances (scans of sensors that
  could have seen the track, since its birth), misses (such chances in a row without a hit),
  seen_by (N, S): which sensors have updated it, origin and last (sensor index, seq) of the
  measurements that started and last updated it;
  X (N, n), P (N, n, n): the posterior at t_ns; for an IMM also the modes' MX (N, M, n),
  MP (N, M, n, n) and probabilities MU (N, M) (X, P being their combination).
`Track` is a read-only view of one row, built on demand.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass, fields
from enum import IntEnum

import numpy as np

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState
from fusion.core.imm import IMMState
from fusion.tracking.cv_extrapolation import extrapolated
from fusion.tracking.id_sets import member, positions
from fusion.tracking.row_bits import still_same


class Status(IntEnum):
    TENTATIVE = 0
    CONFIRMED = 1

    @property
    def label(self) -> str:
        return _LABELS[self]


_LABELS = {Status.TENTATIVE: "tentative", Status.CONFIRMED: "confirmed"}


@functools.cache
def _axes(pos_idx: tuple[int, ...], vel_idx: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The position and velocity components of the state, as index arrays (a velocity for every
    position axis, or none)."""
    if vel_idx and len(vel_idx) != len(pos_idx):
        raise ValueError(f"velocity components {vel_idx} do not match the position components {pos_idx}")
    return np.array(pos_idx, np.intp), np.array(vel_idx, np.intp)


def track_id_for(sensor_id: str, seq: int, t_ns: int, epoch: int | None = None) -> int:
    """A track's id, derived from the measurement that started it: the first 63 bits of
    blake2b(sensor_id, seq, t_ns), and of its publisher's `epoch` too where given: where its scan
    holds its seq twice (two epochs of a publisher sending the same seqs at the same time,
    fusion.tracking.scan). The same under any arrival order, and the same for a run's data
    whatever epoch its publisher drew (the epoch is a boot time); a sensor that reuses a seq
    (counter restart or wrap) at another time starts a track with another id; unique in
    practice otherwise (a collision among a million tracks has probability ~1e-7)."""
    key = f"{sensor_id}\x00{seq}\x00{t_ns}" if epoch is None else f"{sensor_id}\x00{seq}\x00{t_ns}\x00{epoch}"
    h = hashlib.blake2b(key.encode(), digest_size=8).digest()
    return int.from_bytes(h, "big") >> 1


@dataclass(frozen=True, slots=True)
class Track:
    """One track, as a view of its TrackSet row: its posterior at its last update (state.t_ns),
    its status and hit count, and the measurements that started and last updated it."""

    id: int
    state: GaussianState | IMMState
    status: Status
    hits: int
    birth_t_ns: int
    origin: tuple[str, int]  # (sensor_id, seq) of the measurement that started it
    last: tuple[str, int]  # (sensor_id, seq) of the measurement that last updated it


@dataclass(frozen=True, slots=True)
class Layout:
    """What the columns mean: the state's position and velocity components, the sensors (by
    index, sorted by id), and the number of IMM modes (0 without an IMM)."""

    pos_idx: tuple[int, ...]
    vel_idx: tuple[int, ...]
    sensors: tuple[str, ...]
    n_state: int
    n_modes: int = 0


@dataclass(frozen=True)
class Rows:
    """Columns of k tracks (k rows of every field of a TrackSet)."""

    ids: np.ndarray
    status: np.ndarray
    hits: np.ndarray
    birth_t_ns: np.ndarray
    t_ns: np.ndarray
    chances: np.ndarray
    misses: np.ndarray
    seen_by: np.ndarray
    origin_sensor: np.ndarray
    origin_seq: np.ndarray
    last_sensor: np.ndarray
    last_seq: np.ndarray
    X: np.ndarray
    P: np.ndarray
    MX: np.ndarray | None = None
    MP: np.ndarray | None = None
    MU: np.ndarray | None = None

    @classmethod
    def empty(cls, layout: Layout) -> Rows:
        i = np.zeros(0, dtype=np.int64)
        n, M = layout.n_state, layout.n_modes
        return cls(i, np.zeros(0, np.int8), i, i, i, i, i, np.zeros((0, len(layout.sensors)), bool),
                   np.zeros(0, np.int32), i, np.zeros(0, np.int32), i, np.zeros((0, n)), np.zeros((0, n, n)),
                   *((np.zeros((0, M, n)), np.zeros((0, M, n, n)), np.zeros((0, M))) if M else (None, None, None)))


ROW_FIELDS = tuple(f.name for f in fields(Rows))
COUNTERS = ("chances", "misses", "seen_by")
# the columns a track's id decides (it is derived from the measurement that started it)
BY_ID = ("ids", "birth_t_ns", "origin_sensor", "origin_seq")
# changed_since compares the columns a scan changes most first (a row found changed is compared no further)
_COMPARE_ORDER = ("X", "MU", "t_ns", *(f for f in ROW_FIELDS if f not in ("X", "MU", "t_ns")))
_FEW_ROWS = 8  # changed_since compares up to this many rows one by one (bytes), more by column passes


class TrackSet:
    """An immutable set of tracks (see the module docstring): the columns of Rows, and layout."""

    __slots__ = (*ROW_FIELDS, "_index", "_order", "_views", "layout")
    ids: np.ndarray
    status: np.ndarray
    hits: np.ndarray
    birth_t_ns: np.ndarray
    t_ns: np.ndarray
    chances: np.ndarray
    misses: np.ndarray
    seen_by: np.ndarray
    origin_sensor: np.ndarray
    origin_seq: np.ndarray
    last_sensor: np.ndarray
    last_seq: np.ndarray
    X: np.ndarray
    P: np.ndarray
    MX: np.ndarray | None
    MP: np.ndarray | None
    MU: np.ndarray | None

    def __init__(self, rows: Rows, layout: Layout) -> None:
        self._fill({f: getattr(rows, f) for f in ROW_FIELDS}, layout)

    def _fill(self, cols: dict[str, np.ndarray | None], layout: Layout) -> None:
        for f in ROW_FIELDS:
            setattr(self, f, cols[f])
        self.layout = layout
        self._index: dict[int, int] | None = None
        self._order: np.ndarray | None = None
        self._views: tuple[Track, ...] | None = None

    @classmethod
    def _of(cls, cols: dict[str, np.ndarray | None], layout: Layout) -> TrackSet:
        """A set of the columns `cols` (every field of Rows), without building a Rows first."""
        ts = cls.__new__(cls)
        ts._fill(cols, layout)
        return ts

    @classmethod
    def start(cls, layout: Layout) -> TrackSet:
        return cls(Rows.empty(layout), layout)

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def index_of(self, track_id: int) -> int | None:
        if self._index is None:
            self._index = {int(t): i for i, t in enumerate(self.ids.tolist())}
        return self._index.get(track_id)

    def rows_of(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row of each of `ids`, found): found[k] iff the set holds a track ids[k], and then
        row[k] is its row (by binary search over the ids' order, sorted once per set)."""
        if self._order is None:
            self._order = np.argsort(self.ids, kind="stable")
        return positions(self.ids, ids, self._order)

    def state(self, i: int) -> GaussianState | IMMState:
        t = int(self.t_ns[i])
        if self.MX is None:
            return GaussianState(self.X[i], self.P[i], t)
        return IMMState(self.MX[i], self.MP[i], self.MU[i], self.X[i], self.P[i], t)  # type: ignore[index]

    def track(self, i: int) -> Track:
        s = self.layout.sensors
        return Track(int(self.ids[i]), self.state(i), Status(int(self.status[i])), int(self.hits[i]),
                     int(self.birth_t_ns[i]), (s[int(self.origin_sensor[i])], int(self.origin_seq[i])),
                     (s[int(self.last_sensor[i])], int(self.last_seq[i])))

    @property
    def tracks(self) -> tuple[Track, ...]:
        """Views of every row, in order (built once per set, on first use)."""
        if self._views is None:
            self._views = tuple(self.track(i) for i in range(len(self)))
        return self._views

    def predicted_position(self, t_ns: int, q2: float, rows: np.ndarray | None = None) -> tuple[Array, Array]:
        """Constant-velocity extrapolation of every track's position to t_ns (of tracks `rows`
        only, if given: elementwise, so the same bits as those rows of the whole), with the
        per-axis variance P_pp + 2 dt P_pv + dt^2 P_vv + q2 dt^3 / 3 (no velocity: P_pp + q2 dt):
        fusion.tracking.cv_extrapolation."""
        L = self.layout
        at_p, at_v = _axes(L.pos_idx, L.vel_idx)
        rows = np.arange(len(self)) if rows is None else np.ascontiguousarray(rows, dtype=np.intp)
        dt = (t_ns - self.t_ns[rows]) * 1e-9
        noise = q2 * dt**3 / 3.0 if L.vel_idx else np.full(rows.size, float(q2))
        return extrapolated(self.X, self.P, rows, dt, noise, at_p, at_v)

    def take(self, idx: np.ndarray) -> TrackSet:
        """The rows `idx` (indices, in that order) as a set of their own."""
        return TrackSet._of({f: None if (c := getattr(self, f)) is None else c[idx] for f in ROW_FIELDS}, self.layout)

    def with_rows(self, at: np.ndarray, other: TrackSet, src: np.ndarray) -> TrackSet:
        """This set with its rows `at` replaced by `other`'s rows `src`, rows of the same tracks
        (so the columns a track's id decides are this set's own arrays)."""
        cols = {}
        for f in ROW_FIELDS:
            c = getattr(self, f)
            if c is not None and f not in BY_ID:
                c = c.copy()
                c[at] = getattr(other, f)[src]
            cols[f] = c
        return TrackSet._of(cols, self.layout)

    def joined(self, other: TrackSet) -> TrackSet:
        """This set's rows, then `other`'s (of the same layout)."""
        return TrackSet._of({f: None if (c := getattr(self, f)) is None else np.concatenate([c, getattr(other, f)])
                             for f in ROW_FIELDS}, self.layout)

    def changed_since(self, old: TrackSet, *, among: np.ndarray | None = None) -> np.ndarray:
        """For each row: False if `old` holds a row of the same track id identical to it bit for
        bit in every column, else True (a track old does not hold, or one whose row differs).
        `among`: the only track ids that can differ (the others are known to be old's rows)."""
        n = len(self)
        if self is old:
            return np.zeros(n, dtype=bool)
        rows = np.arange(n) if among is None else np.flatnonzero(member(self.ids, among))
        if len(old) == 0 or rows.size == 0:
            out = np.zeros(n, dtype=bool)
            out[rows] = len(old) == 0
            return out
        if self.ids is old.ids or (self.ids.shape == old.ids.shape and np.array_equal(self.ids, old.ids)):
            at, found = rows, np.ones(rows.size, dtype=bool)
        else:
            at, found = old.rows_of(self.ids[rows])
        if rows.size <= _FEW_ROWS:  # a partial re-run's few rows: compared row by row, without the column passes
            out = np.zeros(n, dtype=bool)
            cols = [(a, getattr(old, f)) for f in _COMPARE_ORDER if (a := getattr(self, f)) is not None]
            for r, o, ok in zip(rows.tolist(), at.tolist(), found.tolist(), strict=True):
                out[r] = not ok or any(a[r].tobytes() != b[o].tobytes() for a, b in cols)
            return out
        same = found.copy()
        rows_, at_ = rows.astype(np.int64, copy=False), at.astype(np.int64, copy=False)
        for f in _COMPARE_ORDER:  # bits, not values (fusion.tracking.row_bits)
            a = getattr(self, f)
            if a is not None:
                still_same(a, getattr(old, f), rows_, at_, same)
        out = np.zeros(n, dtype=bool)
        out[rows] = ~same
        return out

    def derive(self, *, update: tuple[np.ndarray, dict[str, np.ndarray | None]] | None = None,
               counters: dict[str, np.ndarray] | None = None, delete: np.ndarray | None = None,
               born: Rows | None = None) -> TrackSet:
        """A new set: in rows `update[0]` the columns named in `update[1]` replaced by its
        values (the others, and the counters, kept), the lifecycle `counters` replaced, rows
        where `delete` is true removed, `born` appended."""
        cols = {f: getattr(self, f) for f in ROW_FIELDS}
        if update is not None and update[0].size:
            idx, new = update
            for f, v in new.items():
                if f not in COUNTERS and cols[f] is not None:
                    c = cols[f].copy()
                    c[idx] = v
                    cols[f] = c
        if counters:
            cols.update(counters)
        if delete is not None and delete.any():
            keep = ~delete
            cols = {f: None if c is None else c[keep] for f, c in cols.items()}
        if born is not None and born.ids.size:
            cols = {f: None if c is None else np.concatenate([c, getattr(born, f)]) for f, c in cols.items()}
        return TrackSet._of(cols, self.layout)
