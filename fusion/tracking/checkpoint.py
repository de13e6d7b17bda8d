"""A tracker's state as data: what a restarted service needs to resume its tracks.

TrackerState holds every column of the live track set (ids, states, covariances, lifecycle
counters), the sources' clocks and the window, the held control inputs, and the counts. It is a
msgspec Struct (encode it with msgspec; fusion.io.checkpoint writes it to disk atomically). The
history of the window is not kept: a resumed tracker treats data before its newest scan as too
late (they cannot be replayed exactly), and is otherwise the tracker that stopped.

A checkpoint carries a digest of the tracker's configuration: one written by a differently
configured tracker is refused (`resume` raises ConfigError), never half-applied.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

import msgspec
import numpy as np

from fusion.config import TrackerConfig
from fusion.errors import ConfigError
from fusion.tracking.detection import Reason
from fusion.tracking.results import DeletionReason
from fusion.tracking.scan import Tally
from fusion.tracking.trackset import ROW_FIELDS, Rows

if TYPE_CHECKING:
    from fusion.tracking.tracker import Tracker

FORMAT = "fusion.tracker-state"
VERSION = 1


class Column(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    dtype: str
    shape: list[int]
    data: bytes

    @classmethod
    def of(cls, a: np.ndarray) -> Column:
        a = np.ascontiguousarray(a)
        return cls(a.dtype.str, list(a.shape), a.tobytes())

    def array(self) -> np.ndarray:
        return np.frombuffer(self.data, dtype=np.dtype(self.dtype)).reshape(self.shape).copy()


class ClockState(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    offsets: list[int]
    last_arrival_ns: int | None


class TrackerState(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    format: str = FORMAT
    version: int = VERSION
    config_digest: str
    rows: dict[str, Column]
    clocks: dict[str, ClockState]
    first_arrival_ns: int | None
    now_ns: int | None
    horizon_ns: int | None
    newest_scan: tuple[int, str] | None
    inputs: list[tuple[int, int, list[float]]]
    tallies: dict[str, int]
    intake_counts: dict[str, int]
    refused: dict[str, int]
    arrival: dict[str, int]


def config_digest(cfg: TrackerConfig) -> str:
    """blake2b of the configuration's canonical JSON: the same for the same configuration."""
    return hashlib.blake2b(msgspec.json.encode(cfg, order="sorted"), digest_size=16).hexdigest()


def _tally_key(k: Tally | DeletionReason) -> str:
    return f"deleted:{k.value}" if isinstance(k, DeletionReason) else f"tally:{k.value}"


def _tally_of(key: str) -> Tally | DeletionReason:
    kind, _, value = key.partition(":")
    return DeletionReason(value) if kind == "deleted" else Tally(value)


def state_of(tr: Tracker) -> TrackerState:
    """The tracker's state (see the module docstring)."""
    ts = tr.track_set
    intake = tr.intake
    return TrackerState(
        config_digest=config_digest(tr.config),
        rows={f: Column.of(getattr(ts, f)) for f in ROW_FIELDS if getattr(ts, f) is not None},
        clocks={s: ClockState(*c.state()) for s, c in intake.clocks.sources.items()},
        first_arrival_ns=intake.clocks.first_arrival_ns, now_ns=intake.now_ns, horizon_ns=intake.horizon_ns,
        newest_scan=tr.newest_scan,
        inputs=[] if tr.inputs is None else [(t, q, u.tolist()) for t, q, u in tr.inputs.items()],
        tallies={_tally_key(k): v for k, v in sorted(tr.history.tally().items(), key=lambda kv: _tally_key(kv[0]))},
        intake_counts=dict(tr.intake_counts), refused={r.value: n for r, n in tr.refused_counts.items()},
        arrival=dict(tr.arrival_counts),
    )


def restore(tr: Tracker, st: TrackerState) -> None:
    """Make a freshly built tracker the one that wrote `st` (ConfigError if it cannot be)."""
    if st.format != FORMAT or st.version != VERSION:
        raise ConfigError(f"not a tracker state this version reads ({st.format} v{st.version}; "
                          f"this build reads {FORMAT} v{VERSION})")
    if st.config_digest != config_digest(tr.config):
        raise ConfigError("the checkpoint was written by a tracker with another configuration")
    if set(st.clocks) != set(tr.intake.clocks.sources):
        raise ConfigError(f"the checkpoint's sources {sorted(st.clocks)} are not this tracker's")
    cols = {f: (st.rows[f].array() if f in st.rows else None) for f in ROW_FIELDS}
    tr.restore_rows(Rows(**cols))  # type: ignore[arg-type]
    for s, c in st.clocks.items():
        tr.intake.clocks.sources[s].restore(c.offsets, c.last_arrival_ns)
    tr.intake.clocks.restore_first_arrival(st.first_arrival_ns)
    tr.intake.now_ns, tr.intake.horizon_ns = st.now_ns, st.horizon_ns
    if st.newest_scan is not None:
        tr.intake.commit(tuple(st.newest_scan))  # type: ignore[arg-type]
    if tr.inputs is not None:
        for t, q, u in st.inputs:
            tr.inputs.add(t, q, np.asarray(u, dtype=np.float64))
    tr.history.committed.update({_tally_of(k): v for k, v in st.tallies.items()})
    tr.intake_counts.update(st.intake_counts)
    tr.refused_counts.update({Reason(k): v for k, v in st.refused.items()})
    tr.arrival_counts.update(st.arrival)
