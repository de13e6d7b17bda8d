"""Tracks and the immutable set of them that the tracker checkpoints.

A TrackSet is never modified: each scan builds a new one, so a checkpoint is a reference and
rewinding for a late measurement costs nothing. Beside the Track records it holds arrays, one
row per track, so that gating and the lifecycle are vectorised over tracks:
  pos, vel (N, d) and the per-axis variances vpp, vpv, vvv at each track's own time t_ns;
  status, hits; chances (scans of sensors that could have seen it, since its birth), misses
  (such chances in a row without a hit) and seen_by (N, S): which sensors have updated it.
The lifecycle counters live only in the arrays: a scan that changes them for every covered
track builds no Track objects.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState
from fusion.core.imm import IMMState


class Status(IntEnum):
    TENTATIVE = 0
    CONFIRMED = 1

    @property
    def label(self) -> str:
        return _LABELS[self]


_LABELS = {Status.TENTATIVE: "tentative", Status.CONFIRMED: "confirmed"}


def track_id_for(sensor_id: str, seq: int, t_ns: int) -> int:
    """A track's id, derived from the measurement that started it: the first 63 bits of
    blake2b(sensor_id, seq, t_ns). The same under any arrival order; a sensor that reuses a seq
    (counter restart or wrap) at another time starts a track with another id; unique in
    practice otherwise (a collision among a million tracks has probability ~1e-7)."""
    h = hashlib.blake2b(f"{sensor_id}\x00{seq}\x00{t_ns}".encode(), digest_size=8).digest()
    return int.from_bytes(h, "big") >> 1


@dataclass(frozen=True, slots=True)
class Track:
    """One track: its posterior at its last update (state.t_ns), its status and hit count."""

    id: int
    state: GaussianState | IMMState
    status: Status
    hits: int
    birth_t_ns: int
    origin: tuple[str, int]  # (sensor_id, seq) of the measurement that started it
    last: tuple[str, int]  # (sensor_id, seq) of the measurement that last updated it


@dataclass(frozen=True, slots=True)
class Rows:
    """Where the arrays' columns come from: the state's position and velocity components, and
    the number of sensors (columns of seen_by)."""

    pos_idx: tuple[int, ...]
    vel_idx: tuple[int, ...]
    n_sensors: int


ARRAY_FIELDS = ("ids", "pos", "vel", "vpp", "vpv", "vvv", "t_ns", "status", "hits", "chances", "misses", "seen_by")
COUNTERS = ("chances", "misses", "seen_by")


class TrackSet:
    """An immutable, ordered set of tracks with vectorised views for gating and the lifecycle."""

    __slots__ = ("_index", "chances", "hits", "ids", "misses", "pos", "rows", "seen_by", "status", "t_ns",
                 "tracks", "vel", "vpp", "vpv", "vvv")

    def __init__(self, tracks: tuple[Track, ...], arrays: dict[str, np.ndarray] | None, rows: Rows) -> None:
        self.tracks = tracks
        self.rows = rows
        if arrays is None:
            arrays = _rows(tracks, rows)
        self.ids = arrays["ids"]
        self.pos, self.vel = arrays["pos"], arrays["vel"]
        self.vpp, self.vpv, self.vvv = arrays["vpp"], arrays["vpv"], arrays["vvv"]
        self.t_ns, self.status, self.hits = arrays["t_ns"], arrays["status"], arrays["hits"]
        self.chances, self.misses, self.seen_by = arrays["chances"], arrays["misses"], arrays["seen_by"]
        self._index: dict[int, int] | None = None

    def __len__(self) -> int:
        return len(self.tracks)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in ARRAY_FIELDS}

    def index_of(self, track_id: int) -> int | None:
        if self._index is None:
            self._index = {int(t): i for i, t in enumerate(self.ids)}
        return self._index.get(track_id)

    def predicted_position(self, t_ns: int, q2: float) -> tuple[Array, Array]:
        """Constant-velocity extrapolation of every track's position to t_ns, with the
        per-axis variance vpp + 2 dt vpv + dt^2 vvv + q2 dt^3 / 3."""
        dt = ((t_ns - self.t_ns) * 1e-9)[:, None]
        var = self.vpp + 2.0 * dt * self.vpv + dt * dt * self.vvv + q2 * dt**3 / 3.0
        return self.pos + self.vel * dt, np.maximum(var, 0.0)

    def derive(self, *, replace: dict[int, Track] | None = None, counters: dict[str, np.ndarray] | None = None,
               delete: np.ndarray | None = None, born: tuple[Track, ...] = (), born_sensor: int = 0) -> TrackSet:
        """A new set: rows `replace` (by index) swapped, the lifecycle `counters` replaced,
        rows where `delete` is true removed, then `born` appended (first seen by sensor
        `born_sensor`). Only the changed rows are recomputed."""
        tracks = list(self.tracks)
        arr = self.arrays()
        if replace:
            arr = {k: (v if k in COUNTERS else v.copy()) for k, v in arr.items()}
            idx = np.fromiter(replace.keys(), dtype=np.intp, count=len(replace))
            new = tuple(replace.values())
            for i, t in zip(idx.tolist(), new, strict=True):
                tracks[i] = t
            r = _rows(new, self.rows)
            for k in ARRAY_FIELDS:
                if k not in COUNTERS:
                    arr[k][idx] = r[k]
        if counters:
            arr = {**arr, **counters}
        if delete is not None and delete.any():
            keep = ~delete
            tracks = [t for t, k in zip(tracks, keep.tolist(), strict=True) if k]
            arr = {k: v[keep] for k, v in arr.items()}
        if born:
            tracks.extend(born)
            r = _rows(born, self.rows)
            r["seen_by"][:, born_sensor] = True
            arr = {k: np.concatenate([arr[k], r[k]]) for k in ARRAY_FIELDS}
        return TrackSet(tuple(tracks), arr, self.rows)


def _rows(tracks: tuple[Track, ...], rows: Rows) -> dict[str, np.ndarray]:
    """Array rows of new tracks; the lifecycle counters start at a birth's values (one chance,
    one hit, no misses, seen by nobody yet: `derive` marks the birth sensor)."""
    n = len(tracks)
    d = len(rows.pos_idx)
    zi = np.zeros(n, dtype=np.int64)
    out = {"ids": zi, "pos": np.zeros((n, d)), "vel": np.zeros((n, d)), "vpp": np.zeros((n, d)),
           "vpv": np.zeros((n, d)), "vvv": np.zeros((n, d)), "t_ns": zi, "status": zi.astype(np.int8),
           "hits": zi, "chances": np.ones(n, dtype=np.int64), "misses": zi.copy(),
           "seen_by": np.zeros((n, rows.n_sensors), dtype=bool)}
    if n == 0:
        return out
    X = np.stack([t.state.x for t in tracks])
    P = np.stack([t.state.P for t in tracks])
    pi, vi = np.array(rows.pos_idx), np.array(rows.vel_idx)
    out.update(
        ids=np.fromiter((t.id for t in tracks), dtype=np.int64, count=n),
        pos=X[:, pi], vel=X[:, vi], vpp=P[:, pi, pi], vpv=P[:, pi, vi], vvv=P[:, vi, vi],
        t_ns=np.fromiter((t.state.t_ns for t in tracks), dtype=np.int64, count=n),
        status=np.fromiter((t.status for t in tracks), dtype=np.int8, count=n),
        hits=np.fromiter((t.hits for t in tracks), dtype=np.int64, count=n),
    )
    return out
