"""What the tracker reports: estimates, events, associations, replays, counts.

Every report is a function of the accepted measurements, never of their arrival order, once
revisions and retractions are applied the way a consumer applies them:
- an Estimate is keyed by (track_id, t_ns, sensor_id); a higher revision replaces a lower one,
  status "retracted" withdraws the key;
- a TrackEvent is keyed by (kind, track_id, t_ns, reason); `retracted=True` withdraws it.
Only Replay records and the arrival counts (replays, replayed scans, rescans, late_applied)
describe how the data arrived, and they are named so.

The per-track records (Estimate, TrackEvent), a scan's associations and new measured points
(ScanAssociations and ScanPoints, one per scan: arrays, not a record per measurement;
Association is one row as a record) and what a review reads of a scan's estimates beside their
posteriors (Review, a block per scan that its estimates refer to by row) are frozen msgspec
Structs without cyclic-GC tracking (they hold arrays, tuples, scalars and, an Estimate, its
Review: never a cycle): built thousands of times per batch, they cost ~0.4 us each where a
frozen dataclass cost ~3-5 us.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

import msgspec
import numpy as np

from fusion.core.checks import Array
from fusion.tracking.detection import Reason, Refusal

ScanKey = tuple[int, str]  # (t_ns, sensor_id): the processing order of scans
EstimateKey = tuple[int, int, str]  # (track_id, t_ns, sensor_id)


class EventKind(StrEnum):
    BORN = "born"
    CONFIRMED = "confirmed"
    COASTING = "coasting"  # a confirmed track missed a chance after a hit (it lives on)
    DELETED = "deleted"


class DeletionReason(StrEnum):
    """Why a track was deleted."""

    NOT_CONFIRMED = "not confirmed"  # fewer than M hits in its first N chances
    MISSES = "misses"  # more than max_misses chances in a row without a hit
    COASTED = "coasted"  # no update for coast_s seconds
    COVARIANCE = "covariance"  # predicted position spread above max_position_std_m


class Outcome(StrEnum):
    """What became of an accepted measurement in its scan."""

    UPDATED = "updated"  # it updated a track
    BORN = "born"  # it started a track
    UNASSIGNED = "unassigned"  # it fell in a gate, no track took it, and max_tracks left no room for a new one
    CAPACITY = "capacity"  # no track could be started: max_tracks reached


class Review(msgspec.Struct, frozen=True, gc=False):
    """Some of a scan's estimates stacked, for a review: one block per scan for the updates of
    one measurement dimension (their posteriors, measured positions, prior x and P, innovation
    y with its covariance S, and the measurement Jacobian H at the prior: the gain is
    K = prior_P H' S^-1), and one for the scan's births (posteriors and measured positions; no
    prior, no innovation). An estimate refers to its row of its block (Estimate.review,
    Estimate.row): a scan's estimates share their blocks, instead of holding a view of each
    array (six objects per estimate to make and to free), and a consumer of many estimates
    (the recording) reads them block by block. X, P: the estimates' x and P, the arrays they
    are rows of where they are (Estimate.x is X[row]); MU: an IMM's mode probabilities, the
    arrays its estimates' mode_probabilities are rows of (None with one model)."""

    X: Array  # (k, d)
    P: Array  # (k, d, d)
    meas_pos: Array  # (k, p): world position of each measurement used (the association)
    prior_x: Array | None = None  # (k, d)
    prior_P: Array | None = None  # (k, d, d)
    y: Array | None = None  # (k, m)
    S: Array | None = None  # (k, m, m)
    H: Array | None = None  # (k, m, d)
    MU: Array | None = None  # (k, modes)


# Estimate's properties: its rows of its Review block's fields of these names
REVIEW_ROWS = ("meas_pos", "prior_x", "prior_P", "y", "S", "H")


def _review_row(name: str) -> property:
    """An Estimate's row of its Review block's field `name` (None if it has no block, or the
    block not that field)."""

    def row_of(e: Estimate) -> Array | None:
        r = e.review
        a = None if r is None else getattr(r, name)
        return None if a is None else a[e.row]

    return property(row_of, doc=f"Its row of its Review block's {name} (None where it has none).")


class Estimate(msgspec.Struct, frozen=True, gc=False):
    """A track's posterior after a scan, or its retraction (status "retracted", empty x and P).

    `review`, `row`: its row of its scan's Review block (None for a retraction or a
    prediction); prior_x, prior_P, y, S, H and meas_pos read it (None at a birth, but for
    meas_pos).
    """

    track_id: int
    t_ns: int
    sensor_id: str
    seq: int  # the measurement that updated (or started) the track; -1 for a retraction
    x: Array
    P: Array
    status: str  # "tentative" | "confirmed" | "retracted" | "predicted" (Tracker.predict)
    revision: int
    nis: float | None
    mode_probabilities: Array | None = None
    review: Review | None = None
    row: int = 0

    @property
    def key(self) -> EstimateKey:
        return (self.track_id, self.t_ns, self.sensor_id)

    # its rows of its Review block (None where it has none)
    meas_pos = _review_row("meas_pos")
    prior_x = _review_row("prior_x")
    prior_P = _review_row("prior_P")
    y = _review_row("y")
    S = _review_row("S")
    H = _review_row("H")

    def with_revision(self, revision: int) -> Estimate:
        if revision == self.revision:
            return self
        return Estimate(self.track_id, self.t_ns, self.sensor_id, self.seq, self.x, self.P, self.status, revision,
                        self.nis, self.mode_probabilities, self.review, self.row)

    @classmethod
    def retraction(cls, key: EstimateKey, revision: int) -> Estimate:
        track_id, t_ns, sensor_id = key
        return cls(track_id, t_ns, sensor_id, -1, np.empty(0), np.empty((0, 0)), "retracted", revision, None)


class TrackEvent(msgspec.Struct, frozen=True, gc=False):
    """born | confirmed | coasting | deleted (with its reason), at the time of the scan that
    caused it.
    retracted=True withdraws an event reported earlier (a replay no longer produces it)."""

    kind: EventKind
    track_id: int
    t_ns: int
    reason: DeletionReason | None = None
    retracted: bool = False

    @property
    def key(self) -> tuple[str, int, int, str]:
        return (self.kind.value, self.track_id, self.t_ns, "" if self.reason is None else self.reason.value)

    def withdrawn(self) -> TrackEvent:
        return TrackEvent(self.kind, self.track_id, self.t_ns, self.reason, True)


class ScanPoints(msgspec.Struct, frozen=True, gc=False):
    """The newly accepted measurements of one scan, in world Cartesian coordinates (for
    recordings): their seqs (int64, k) and positions (k, d), in the scan's detection order."""

    sensor_id: str
    t_ns: int
    seq: Array
    position: Array


class Association(msgspec.Struct, frozen=True, gc=False):
    """What became of one accepted measurement in its scan, and the tracks in whose gate it fell:
    one row of its scan's ScanAssociations, as a record."""

    sensor_id: str
    t_ns: int
    seq: int
    outcome: Outcome
    track_id: int | None
    nis: float | None
    gated: tuple[int, ...]


OUTCOMES: tuple[Outcome, ...] = tuple(Outcome)  # ScanAssociations.outcome holds indices into this
OUTCOME_CODE: dict[Outcome, int] = {o: k for k, o in enumerate(OUTCOMES)}
NO_TRACK = -1  # ScanAssociations.track_id of a measurement that updated or started no track


class ScanAssociations(msgspec.Struct, frozen=True, gc=False):
    """What became of each accepted measurement of one scan (sensor_id, t_ns), as columns in the
    scan's detection order (by seq), one row per measurement: seq (M,) int64; outcome (M,) int8,
    an index into OUTCOMES; track_id (M,) int64, the track it updated or started (NO_TRACK: none);
    nis (M,) float64, its NIS in the gate of the track it updated (NaN: it updated none); the ids
    of the tracks in whose gate it fell, gated[gated_at[j]:gated_at[j + 1]] (int64; gated_at
    (M + 1,) int64). Association is one row as a record (`rows`). One block per scan instead of
    a record per measurement: the scan builds a few arrays, the window keeps them, the
    recording concatenates them."""

    sensor_id: str
    t_ns: int
    seq: Array
    outcome: Array
    track_id: Array
    nis: Array
    gated_at: Array
    gated: Array

    def __len__(self) -> int:
        return int(self.seq.shape[0])

    def rows(self) -> list[Association]:
        """Every row as an Association record, in order."""
        at, gated = self.gated_at.tolist(), self.gated.tolist()
        return [Association(self.sensor_id, self.t_ns, q, OUTCOMES[o], None if t == NO_TRACK else t,
                            None if o != _UPDATED else v, tuple(gated[at[j]:at[j + 1]]))
                for j, (q, o, t, v) in enumerate(zip(self.seq.tolist(), self.outcome.tolist(), self.track_id.tolist(),
                                                     self.nis.tolist(), strict=True))]


_UPDATED = OUTCOME_CODE[Outcome.UPDATED]


@dataclass(frozen=True, slots=True)
class Replay:
    """Late measurements rewound the tracker to from_t_ns and n_scans scans were run again."""

    from_t_ns: int
    n_scans: int
    trigger: tuple[tuple[str, int], ...]  # (sensor_id, seq) of the late measurements


@dataclass(frozen=True)
class Counts:
    """Cumulative counts of a tracker.

    Intake: received = applied + inputs + truth + sum(refused.values()) (applied: measurements;
    inputs: control inputs; duplicates are refused with reason "duplicate"; truth samples are
    counted by the pipeline, 0 in a bare tracker). Of the refused, inputs_refused were control
    inputs, truth_refused truth samples and other_refused samples on a key that names no kind
    (not fusion/NS/meas|input|truth/ID; the pipeline's), whatever the reason; the rest were
    measurements.
    What the data did (a function of the accepted measurements, whatever their arrival order):
    updates, births, births_refused_capacity, unassigned (in a gate, taken by no track; such a
    measurement starts a track like any other), confirmations, deletions by reason,
    numerical_skips. How the data arrived: replays (calls that rewound), replayed_scans (scans
    run again), rescans (a newest scan run again with more measurements), late_applied
    (measurements that landed before the newest scan).
    """

    received: int = 0
    applied: int = 0
    truth: int = 0
    inputs: int = 0
    inputs_refused: int = 0
    truth_refused: int = 0
    other_refused: int = 0
    refused: Mapping[Reason, int] = field(default_factory=dict)
    updates: int = 0
    births: int = 0
    births_refused_capacity: int = 0
    unassigned: int = 0
    confirmations: int = 0
    deletions: Mapping[DeletionReason, int] = field(default_factory=dict)
    numerical_skips: int = 0
    replays: int = 0
    replayed_scans: int = 0
    rescans: int = 0
    late_applied: int = 0

    @property
    def duplicates(self) -> int:
        return self.refused.get(Reason.DUPLICATE, 0)

    def flat(self) -> dict[str, int]:
        """Every count under a path-like name ("refused/duplicate", "deletions/misses"), sorted; like
        the refusals by reason, the refused inputs, truth and other samples are there once there were any."""
        out = {k: getattr(self, k) for k in ("received", "applied", "inputs", "truth", "updates", "births",
                                             "births_refused_capacity", "unassigned", "confirmations",
                                             "numerical_skips", "replays", "replayed_scans", "rescans", "late_applied")}
        out.update({k: n for k in ("inputs_refused", "truth_refused", "other_refused") if (n := getattr(self, k))})
        out.update({f"refused/{r.value}": n for r, n in self.refused.items()})
        out.update({f"deletions/{r.value.replace(' ', '_')}": n for r, n in self.deletions.items()})
        return dict(sorted(out.items()))


@dataclass(frozen=True)
class StepResult:
    """Everything one call to Tracker.process did."""

    estimates: tuple[Estimate, ...]
    events: tuple[TrackEvent, ...]
    refused: tuple[Refusal, ...]
    applied: int
    replays: tuple[Replay, ...]
    # one block per scan run (again): a first run's every association; a run again's new and changed
    # ones (fusion.tracking.history.revise_associations)
    associations: tuple[ScanAssociations, ...]
    measurements: tuple[ScanPoints, ...] = ()  # one per scan that took new measurements
    # sensor time before which nothing can change any more after this call (Tracker.horizon_ns;
    # None before the window has one): what a consumer derived from earlier rows is final
    horizon_ns: int | None = None

    def each_association(self) -> list[Association]:
        """Every association of the step as a record, scan by scan in the order they ran."""
        return [a for block in self.associations for a in block.rows()]

    @property
    def n_associations(self) -> int:
        """The associations' rows: one per measurement of a scan's first run, one per new or changed
        association of a scan run again."""
        return sum(len(block) for block in self.associations)
