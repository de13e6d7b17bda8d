"""Tracks and the immutable set of them that the tracker checkpoints.

A TrackSet is never modified: each scan builds a new one, so a checkpoint is a reference and
rewinding for a late measurement costs nothing. Beside the Track records it holds arrays
(position, velocity and their variances per axis at each track's own time, lifecycle
counters) so that gating and the lifecycle sweep are vectorised over tracks.
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
    """One track: its posterior at its last update (state.t_ns) and its lifecycle counters."""

    id: int
    state: GaussianState | IMMState
    status: Status
    hits: int
    birth_scan: int
    last_hit_scan: int
    birth_t_ns: int
    origin: tuple[str, int]  # (sensor_id, seq) of the measurement that started it


class TrackSet:
    """An immutable, ordered set of tracks with vectorised views for gating."""

    __slots__ = (
        "_index",
        "birth_scan",
        "hits",
        "ids",
        "last_hit_scan",
        "pos",
        "status",
        "t_ns",
        "tracks",
        "vel",
        "vpp",
        "vpv",
        "vvv",
    )

    def __init__(self, tracks: tuple[Track, ...], arrays: dict[str, np.ndarray] | None, *,
                 pos_idx: tuple[int, ...], vel_idx: tuple[int, ...]) -> None:
        self.tracks = tracks
        if arrays is None:
            arrays = _rows(tracks, pos_idx, vel_idx)
        self.ids = arrays["ids"]
        self.pos, self.vel = arrays["pos"], arrays["vel"]
        self.vpp, self.vpv, self.vvv = arrays["vpp"], arrays["vpv"], arrays["vvv"]
        self.t_ns, self.status, self.hits = arrays["t_ns"], arrays["status"], arrays["hits"]
        self.birth_scan, self.last_hit_scan = arrays["birth_scan"], arrays["last_hit_scan"]
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

    def derive(self, replace: dict[int, Track], born: list[Track], delete: np.ndarray | None,
               *, pos_idx: tuple[int, ...], vel_idx: tuple[int, ...]) -> TrackSet:
        """A new set: rows `replace` (by index) swapped, `born` appended, rows where `delete`
        is true removed. Only the changed rows are recomputed."""
        tracks = list(self.tracks)
        arr = {k: v.copy() for k, v in self.arrays().items()} if (replace or delete is not None) else self.arrays()
        if replace:
            idx = np.fromiter(replace.keys(), dtype=np.intp, count=len(replace))
            new = tuple(replace.values())
            for i, t in zip(idx, new, strict=True):
                tracks[i] = t
            r = _rows(new, pos_idx, vel_idx)
            for k in ARRAY_FIELDS:
                arr[k][idx] = r[k]
        if born:
            tracks.extend(born)
            r = _rows(tuple(born), pos_idx, vel_idx)
            arr = {k: np.concatenate([arr[k], r[k]]) for k in ARRAY_FIELDS}
        if delete is not None and delete.any():
            keep = ~np.concatenate([delete, np.zeros(len(born), dtype=bool)])
            tracks = [t for t, k in zip(tracks, keep, strict=True) if k]
            arr = {k: v[keep] for k, v in arr.items()}
        return TrackSet(tuple(tracks), arr, pos_idx=pos_idx, vel_idx=vel_idx)


ARRAY_FIELDS = ("ids", "pos", "vel", "vpp", "vpv", "vvv", "t_ns", "status", "hits", "birth_scan", "last_hit_scan")


def _rows(tracks: tuple[Track, ...], pos_idx: tuple[int, ...], vel_idx: tuple[int, ...]) -> dict[str, np.ndarray]:
    n = len(tracks)
    d = len(pos_idx)
    if n == 0:
        z = np.zeros((0, d))
        zi = np.zeros(0, dtype=np.int64)
        return {"ids": zi, "pos": z, "vel": z, "vpp": z, "vpv": z, "vvv": z, "t_ns": zi,
                "status": zi.astype(np.int8), "hits": zi, "birth_scan": zi, "last_hit_scan": zi}
    X = np.stack([t.state.x for t in tracks])
    P = np.stack([t.state.P for t in tracks])
    pi, vi = np.array(pos_idx), np.array(vel_idx)
    return {
        "ids": np.fromiter((t.id for t in tracks), dtype=np.int64, count=n),
        "pos": X[:, pi],
        "vel": X[:, vi],
        "vpp": P[:, pi, pi],
        "vpv": P[:, pi, vi],
        "vvv": P[:, vi, vi],
        "t_ns": np.fromiter((t.state.t_ns for t in tracks), dtype=np.int64, count=n),
        "status": np.fromiter((t.status for t in tracks), dtype=np.int8, count=n),
        "hits": np.fromiter((t.hits for t in tracks), dtype=np.int64, count=n),
        "birth_scan": np.fromiter((t.birth_scan for t in tracks), dtype=np.int64, count=n),
        "last_hit_scan": np.fromiter((t.last_hit_scan for t in tracks), dtype=np.int64, count=n),
    }
