"""One scan (all measurements of one sensor at one time): a pure function from a track set and
the scan's detections to the new track set and what happened.

  1. gate: constant-velocity coarse gate (fusion.core.association.coarse_pairs), then the fine
     gate of fusion.tracking.gating (NIS <= chi2_m(probability)), cost = NIS + ln det S;
  2. assign, confirmed tracks first: GNN over the confirmed tracks' pairs (likelihood cost),
     then GNN over the tentative tracks' pairs with the measurements left (Mahalanobis cost; the
     initiator gets leftovers, as in Stone Soup's tracker), so a tentative track never takes a
     confirmed one's measurement;
  3. assigned tracks take their posterior (and may be confirmed); a measurement no track took
     starts a tentative track, up to max_tracks;
  4. lifecycle: chances, misses and deletions (fusion.tracking.lifecycle).
"""

from __future__ import annotations

import functools
from collections import Counter
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from fusion.core.association import coarse_pairs
from fusion.core.checks import Array
from fusion.core.imm import IMM, Filter, combine_each
from fusion.tracking.association_kernels import built, confirmed_first
from fusion.tracking.detection import Detection, seqs_of
from fusion.tracking.gating import Gated, Gater, Measured
from fusion.tracking.id_sets import repeats
from fusion.tracking.lifecycle import Lifecycle
from fusion.tracking.models import SensorModel
from fusion.tracking.results import (
    NO_TRACK,
    OUTCOME_CODE,
    DeletionReason,
    Estimate,
    EventKind,
    Outcome,
    Review,
    ScanAssociations,
    ScanKey,
    TrackEvent,
)
from fusion.tracking.revision_kernel import row_signatures
from fusion.tracking.trackset import ROW_FIELDS, Layout, Rows, Status, TrackSet, track_id_for

_LABELS = {int(s): s.label for s in Status}
# association_kernels.built's codes: no track, then updated, born, unassigned, capacity
_BUILT_CODES = (NO_TRACK, *(OUTCOME_CODE[o] for o in (Outcome.UPDATED, Outcome.BORN, Outcome.UNASSIGNED,
                                                       Outcome.CAPACITY)))


class Tally(StrEnum):
    """What a scan counts (deletions are counted by their DeletionReason)."""

    UPDATES = "updates"
    BIRTHS = "births"
    BIRTHS_REFUSED_CAPACITY = "births_refused_capacity"
    UNASSIGNED = "unassigned"
    CONFIRMATIONS = "confirmations"
    NUMERICAL_SKIPS = "numerical_skips"


@dataclass(frozen=True)
class ScanContext:
    """Everything a scan needs besides its data; built once by the tracker."""

    sensors: dict[str, SensorModel]
    filter: Filter
    gater: Gater
    lifecycle: Lifecycle
    init_diag: Array  # prior variances of the unmeasured state components
    pos_idx: tuple[int, ...]
    coarse_k: float  # the coarse gate's half-width in standard deviations
    q2: float  # the coarse gate's process noise (the largest of the model's)
    max_tracks: int


@dataclass(frozen=True)
class ScanOutcome:
    after: TrackSet
    estimates: list[Estimate]  # sorted by track id
    events: list[TrackEvent]
    associations: ScanAssociations
    tally: Counter[Tally | DeletionReason]
    positions: Array  # (M, d) world points of the scan's measurements, in the order of its detections
    variances: Array | None = None  # (M, d) their per-axis variances (the coarse gate's)
    coarse: tuple[np.ndarray, np.ndarray] | None = None  # the coarse pairs (track rows, detection indices)
    signatures: np.ndarray | None = None  # (len(estimates),) int64: each estimate's (history.revise), in order


@dataclass(frozen=True)
class Coarse:
    """A scan's coarse gate, known before the scan runs: the pairs (track rows ti, detection
    indices mj) as fusion.core.association.coarse_pairs returns them (sorted by (mj, ti)), and
    the detections' world points and per-axis variances (as measured_points gives them)."""

    ti: np.ndarray
    mj: np.ndarray
    mpos: Array
    mvar: Array


def run_scan(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], ctx: ScanContext,
             coarse: Coarse | None = None, det_seqs: np.ndarray | None = None) -> ScanOutcome:
    """The scan `key` (see the module docstring); `dets` sorted by seq and epoch, R resolved. `coarse`:
    the scan's coarse gate if the caller knows it (a partial re-run: fusion.tracking.replay);
    `det_seqs`: the seqs of `dets`, if known (fusion.tracking.step_order.merged_seqs)."""
    t_ns, sensor_id = key
    sm = ctx.sensors[sensor_id]
    meas = _measured(sm, dets)
    tpos, tvar = ts.predicted_position(t_ns, ctx.q2)
    if coarse is None:
        mpos, mvar = _measured_points(sm, meas)
        ci, cj = coarse_pairs(tpos, tvar, mpos, mvar, k=ctx.coarse_k)
    else:
        ci, cj, mpos, mvar = coarse.ti, coarse.mj, coarse.mpos, coarse.mvar
    gated = ctx.gater.gate(ts, t_ns, ci, cj, meas)
    pairs = _assign_confirmed_first(gated, ts, len(dets))

    tally: Counter[Tally | DeletionReason] = Counter()
    tally[Tally.NUMERICAL_SKIPS] += gated.numerical_skips
    tally[Tally.UPDATES] += len(pairs)
    ti, mj = gated.ti[pairs], gated.mj[pairs]
    taken = gated.take(pairs)
    hits = ts.hits[ti] + 1
    confirm = ctx.lifecycle.confirms(ts.status[ti], hits, ts.chances[ti] + 1)
    status = np.where(confirm, np.int8(Status.CONFIRMED), ts.status[ti]).astype(np.int8)
    if det_seqs is None:
        det_seqs = seqs_of(dets)
    seqs = det_seqs[mj]
    # what an update changes in a row (its id, birth, origin and counters stay)
    changes = {"status": status, "hits": hits, "t_ns": np.full(ti.size, t_ns, np.int64),
               "last_sensor": np.full(ti.size, sm.index, np.int32), "last_seq": seqs, "X": taken.X, "P": taken.P,
               "MX": taken.MX, "MP": taken.MP, "MU": taken.MU}
    updated_ids = ts.ids[ti]
    events = [TrackEvent(EventKind.CONFIRMED, int(ts.ids[i]), t_ns) for i in ti[confirm].tolist()]
    tally[Tally.CONFIRMATIONS] += len(events)
    est_ids = updated_ids.tolist()
    nis = gated.nis[pairs].tolist()
    MU = [None] * ti.size if taken.MU is None else list(taken.MU)
    reviews, rows = taken.reviews(mpos[mj])
    estimates = [
        Estimate(tid, t_ns, sensor_id, seq, x, P, _LABELS[st], 0, v, mu, rv, r)
        for tid, seq, st, x, P, v, mu, rv, r in zip(
            est_ids, seqs.tolist(), status.tolist(), list(taken.X), list(taken.P), nis, MU, reviews, rows,
            strict=True)
    ]

    assoc, born, born_j = _births_and_associations(ts, key, dets, det_seqs, gated, pairs, ctx, sm, mpos, tally)
    born_review = Review(born.X, born.P, mpos[born_j], MU=born.MU) if born.ids.size else None
    for b in range(born.ids.size):
        tid = int(born.ids[b])
        events.append(TrackEvent(EventKind.BORN, tid, t_ns))
        if born.status[b] == Status.CONFIRMED:  # confirm_m == 1: the first hit confirms
            events.append(TrackEvent(EventKind.CONFIRMED, tid, t_ns))
            tally[Tally.CONFIRMATIONS] += 1
        estimates.append(Estimate(tid, t_ns, sensor_id, int(born.last_seq[b]), born.X[b], born.P[b],
                                  Status(int(born.status[b])).label, 0, None,
                                  None if born.MU is None else born.MU[b], born_review, b))
    tally[Tally.BIRTHS] += born.ids.size
    sigs = row_signatures(taken.X, taken.P, status)
    if born.ids.size:
        sigs = np.concatenate([sigs, row_signatures(born.X, born.P, born.status)])

    updated = ts.derive(update=(ti, changes))
    hit = np.zeros(len(ts), dtype=bool)
    hit[ti] = True
    sweep = ctx.lifecycle.sweep(ts, updated, hit, sm, t_ns, (tpos, tvar))
    for ev in sweep.events:
        if ev.reason is not None:  # deletions, by reason (coasting events are not counted)
            tally[ev.reason] += 1
    events.extend(sweep.events)
    after = updated.derive(counters=sweep.counters, delete=sweep.delete, born=born)
    if born.ids.size:  # track ids are unique: sorted by id (stably, as sorted() would)
        order = np.argsort(np.concatenate([updated_ids, born.ids]), kind="stable")
        estimates, sigs = [estimates[k] for k in order.tolist()], sigs[order]
    elif ti.size > 1 and not (np.diff(updated_ids) > 0).all():
        order = np.argsort(updated_ids, kind="stable")
        estimates, sigs = [estimates[k] for k in order.tolist()], sigs[order]
    return ScanOutcome(after, estimates, events, assoc, tally, mpos, mvar, (ci, cj), sigs)


def _births_and_associations(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], det_seqs: np.ndarray,
                             gated: Gated, pairs: list[int], ctx: ScanContext, sm: SensorModel, mpos: Array,
                             tally: Counter) -> tuple[ScanAssociations, Rows, np.ndarray]:
    """What became of each measurement, the gated pairs `pairs` having updated their tracks
    (fusion.tracking.association_kernels.built): one that no track took starts a track (up to
    max_tracks), born with single-point initiation, whether or not it fell in a gate (as Stone
    Soup's initiator takes every unassociated detection: the tentative track it starts dies unless
    the data keep it, and a confirmed track is never outbid by it). Returns the scan's
    associations, the births' rows and the births' measurement indices."""
    t_ns, sensor_id = key
    gids = ts.ids[gated.ti]
    taken = np.asarray(pairs, dtype=np.intp)
    outcome, track_id, nis, at, births, unassigned, refused = built(
        len(dets), gated.mj.astype(np.int64, copy=False), gids, gated.nis, taken, max(ctx.max_tracks - len(ts), 0),
        *_BUILT_CODES)
    twice = frozenset()  # seqs the scan holds twice (two epochs of a publisher): their births' ids take the epoch
    if births.size and repeats(det_seqs):
        twice = frozenset(det_seqs[1:][det_seqs[1:] == det_seqs[:-1]].tolist())
    born = _born_rows(ts, [dets[j] for j in births.tolist()], mpos[births], sm, ctx, twice)
    track_id[births] = born.ids
    tally[Tally.UNASSIGNED] += unassigned
    tally[Tally.BIRTHS_REFUSED_CAPACITY] += refused
    return ScanAssociations(sensor_id, t_ns, det_seqs, outcome, track_id, nis, at, gids), born, births


def _assign_confirmed_first(g: Gated, ts: TrackSet, n_meas: int) -> list[int]:
    """Pair indices assigned: GNN over confirmed tracks (cost NIS + ln det S, the negative
    log-likelihood), then over tentative tracks and the measurements the first stage left, by
    Mahalanobis distance sqrt(NIS) as an initiator does: among tentative tracks the likelihood
    would favour the narrowest (often clutter-born) gate over the right one (bench/gospa.py
    measured both; BENCHMARKS.md). One compiled call (association_kernels.confirmed_first)."""
    if g.ti.size == 0:
        return []
    return confirmed_first(g.ti, g.mj, g.cost, g.limit, g.nis, ts.status[g.ti], Status.CONFIRMED.value, len(ts),
                           n_meas).tolist()


def measured_points(sm: SensorModel, dets: tuple[Detection, ...]) -> tuple[Array, Array]:
    """World points and per-axis variances of a scan's detections, as run_scan computes them."""
    return _measured_points(sm, _measured(sm, dets))


def _measured(sm: SensorModel, dets: tuple[Detection, ...]) -> Measured:
    """The scan's measurements with their models and noise (fusion.tracking.gating.Measured)."""
    zs = tuple([d.z for d in dets])
    by_dim = sm.by_dim
    return Measured.of(zs, tuple([d.R for d in dets]), tuple([by_dim[z.shape[0]] for z in zs]))  # type: ignore[misc]


def _measured_points(sm: SensorModel, meas: Measured) -> tuple[Array, Array]:
    """World points of the scan's measurements and per-axis variances, one call per dimension."""
    if len(meas.Z) == 1:  # one dimension: the stacks are the measurements in order
        (m, Z), = meas.Z.items()
        return sm.positions(Z, meas.Rs[m])
    M = meas.dims.size
    mpos = np.empty((M, sm.ndim))
    mvar = np.empty((M, sm.ndim))
    for m, Z in meas.Z.items():
        rows = np.flatnonzero(meas.dims == m)
        mpos[rows], mvar[rows] = sm.positions(Z, meas.Rs[m])
    return mpos, mvar


@functools.cache
def _no_rows(layout: Layout) -> Rows:
    """No rows of `layout` (read-only: one per layout, shared by every scan without births)."""
    rows = Rows.empty(layout)
    for f in ROW_FIELDS:
        if (c := getattr(rows, f)) is not None:
            c.setflags(write=False)
    return rows


def _born_rows(ts: TrackSet, born: list[Detection], pos: Array, sm: SensorModel, ctx: ScanContext,
               twice: frozenset[int] = frozenset()) -> Rows:
    """Single-point initiation: position and its covariance from the measurement, the rest from
    the configured prior (zero mean); an IMM starts with equal mode probabilities. A birth from a
    seq the scan holds twice (`twice`: two epochs of a publisher) has its epoch in its id."""
    k = len(born)
    L = ts.layout
    if not k:
        return _no_rows(L)
    pi = list(ctx.pos_idx)
    X = np.zeros((k, L.n_state))
    X[:, pi] = pos
    P = np.repeat(np.diag(ctx.init_diag)[None], k, axis=0)
    for b, d in enumerate(born):
        P[b][np.ix_(pi, pi)] = sm.position_cov(d.z, d.R)  # type: ignore[arg-type]
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    MX = MP = MU = None
    if isinstance(ctx.filter, IMM):  # every mode starts at (x, P), equally likely (IMM.initial)
        M = len(ctx.filter.filters)
        MU = np.full((k, M), 1.0 / M)
        MX, MP = np.repeat(X[:, None], M, axis=1), np.repeat(P[:, None], M, axis=1)
        X, P = combine_each(MX, MP, MU)  # their combination, by the IMM's own arithmetic
    t = np.array([d.t_ns for d in born], dtype=np.int64)
    seq = np.array([d.seq for d in born], dtype=np.int64)
    sensor = np.full(k, sm.index, np.int32)
    seen = np.zeros((k, len(L.sensors)), dtype=bool)
    seen[:, sm.index] = True
    ids = np.array([track_id_for(d.sensor_id, d.seq, d.t_ns, d.epoch if d.seq in twice else None) for d in born],
                   dtype=np.int64)
    status = np.full(k, ctx.lifecycle.born_status(), np.int8)
    one = np.ones(k, dtype=np.int64)
    return Rows(ids, status, one, t, t, one.copy(), np.zeros(k, np.int64), seen, sensor, seq, sensor.copy(),
                seq.copy(), X, P, MX, MP, MU)


