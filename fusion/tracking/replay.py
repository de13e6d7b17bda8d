"""Selective replay: a scan run again after late data re-runs only what the late data can reach.

A scan was run on the track set B with detections D and produced the set A and its outcome (the
history's Entry). Run again, it has the set B' and detections D' (D and the late ones):
  seeds:    the rows of B' that differ bit for bit from B's row of the same track (or that B
            lacks), the tracks of B that B' lacks, and the detections of D' not in D;
  reach:    the connected components, over tracks (by id) and detections (by seq), of the coarse
            pairs of both runs (fusion.core.association.coarse_pairs on B, D and on B', D'), that
            hold a seed;
  re-run:   run_scan on the tracks and detections of the reach alone;
  the rest: every other track and detection saw the same rows, the same detections and the same
            pairs in both runs, and every step of a scan after the coarse gate is per pair (fine
            gate), per component of the pairs (the assignment: fusion.core.association.gnn_assign
            decides each component alone) or per row (update, initiation, lifecycle), so its
            results are the stored ones: its rows are copied from A, its estimates, events and
            associations from the stored outcome.
The after-set is assembled in the order the whole scan builds it (the surviving rows of B' in
their order, then the births in detection order), so the result is bit-identical to running the
whole scan. Where a rule counts over the whole scan the whole scan is run instead (`None`):
capacity (the old run refused a birth for max_tracks, or the births would not fit now) and
numerical skips in the old run (the batched gate then ran the whole dimension group pair by
pair, which agrees with the batched math to 1e-12, not bit for bit).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fusion.core.association import coarse_pairs
from fusion.core.checks import Array
from fusion.tracking.detection import Detection
from fusion.tracking.results import Association, DeletionReason, EventKind, Outcome, ScanKey
from fusion.tracking.scan import ScanContext, ScanOutcome, Tally, measured_points, run_scan
from fusion.tracking.trackset import TrackSet


@dataclass(frozen=True)
class Stored:
    """A scan's previous run: its set before and after, detections, associations and tally."""

    before: TrackSet
    after: TrackSet
    dets: tuple[Detection, ...]
    associations: list[Association]
    tally: Counter


@dataclass(frozen=True)
class Partial:
    """A scan run again in part: its outcome (estimates and events of the re-run part only;
    associations, tally and the after-set whole) and the track ids whose stored estimates and
    events stand."""

    outcome: ScanOutcome
    kept: set[int]
    rerun_tracks: int
    rerun_dets: int


def _pairs(ts: TrackSet, t_ns: int, mpos: Array, mvar: Array, ctx: ScanContext) -> tuple[np.ndarray, np.ndarray]:
    tpos, tvar = ts.predicted_position(t_ns, ctx.q2)
    return coarse_pairs(tpos, tvar, mpos, mvar, k=ctx.coarse_k)


def _reach(old: Stored, ts: TrackSet, dets: tuple[Detection, ...], key: ScanKey, ctx: ScanContext,
           mpos: Array, mvar: Array) -> tuple[np.ndarray, np.ndarray] | None:
    """(rows of ts, indices of dets) in the components of the seeds (module docstring); None
    when there is no seed (the stored run stands as it is)."""
    t_ns = key[0]
    seqs = np.array([d.seq for d in dets], dtype=np.int64)
    old_seqs = np.array([d.seq for d in old.dets], dtype=np.int64)
    old_j = np.searchsorted(seqs, old_seqs)  # dets and old.dets are sorted by seq; old.dets within dets
    ids = np.unique(np.concatenate([ts.ids, old.before.ids]))
    n_t = ids.size
    ci, cj = _pairs(ts, t_ns, mpos, mvar, ctx)
    if len(old.dets):
        sm = ctx.sensors[key[1]]
        opos, ovar = measured_points(sm, old.dets)
        oi, oj = _pairs(old.before, t_ns, opos, ovar, ctx)
    else:
        oi = oj = np.zeros(0, dtype=np.intp)
    a = np.concatenate([np.searchsorted(ids, ts.ids[ci]), np.searchsorted(ids, old.before.ids[oi])])
    b = n_t + np.concatenate([cj, old_j[oj]])
    n = n_t + len(dets)
    g = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    _, label = connected_components(g, directed=False)
    seed = np.zeros(n, dtype=bool)
    seed[np.searchsorted(ids, ts.ids[ts.changed_since(old.before)])] = True
    gone = ~np.isin(old.before.ids, ts.ids)
    seed[np.searchsorted(ids, old.before.ids[gone])] = True
    new_det = np.ones(len(dets), dtype=bool)
    new_det[old_j] = False
    seed[n_t + np.flatnonzero(new_det)] = True
    if not seed.any():
        return None
    hot = np.isin(label, np.unique(label[seed]))
    rows = np.flatnonzero(hot[np.searchsorted(ids, ts.ids)])
    return rows, np.flatnonzero(hot[n_t:])


def _tally_of(assoc: list[Association], events: list, *, skips: int = 0) -> Counter:
    """The tally of a part of a scan from what it did (fusion.tracking.scan counts the same):
    updates, births and unassigned (in a gate, not taken) from the associations; confirmations
    and deletions from the events. Used for parts without capacity refusals."""
    t: Counter = Counter()
    for a in assoc:
        if a.outcome == Outcome.UPDATED:
            t[Tally.UPDATES] += 1
        else:
            if a.gated:
                t[Tally.UNASSIGNED] += 1
            if a.outcome == Outcome.BORN:
                t[Tally.BIRTHS] += 1
    for ev in events:
        if ev.kind == EventKind.CONFIRMED:
            t[Tally.CONFIRMATIONS] += 1
        elif ev.kind == EventKind.DELETED and ev.reason is not None:
            t[ev.reason] += 1
    if skips:
        t[Tally.NUMERICAL_SKIPS] += skips
    return t


def rerun(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], ctx: ScanContext, old: Stored,
          old_events: list) -> Partial | None:
    """Scan `key` run again on `ts` with `dets` (sorted by seq), reusing `old` where the late data
    cannot reach; None where the whole scan must run (module docstring). `old_events`: the events
    the stored run reported."""
    if old.tally[Tally.BIRTHS_REFUSED_CAPACITY] or old.tally[Tally.NUMERICAL_SKIPS]:
        return None  # the old run's counts are not per component: run the whole scan
    mpos, mvar = measured_points(ctx.sensors[key[1]], dets)
    reach = _reach(old, ts, dets, key, ctx, mpos, mvar)
    if reach is None:  # nothing changed: the stored run stands, its after-set shared
        if not np.array_equal(ts.ids, old.before.ids):
            return None  # the same rows in another order: the whole scan orders its output by them
        kept = {int(i) for i in ts.ids.tolist()} | {int(i) for i in old.after.ids.tolist()}
        return Partial(ScanOutcome(old.after, [], [], old.associations, old.tally, mpos), kept, 0, 0)
    rows, js = reach
    if rows.size == len(ts) and js.size == len(dets):
        return None  # everything is reached: the whole scan is the same work
    sub_dets = tuple(dets[j] for j in js.tolist())
    sub = run_scan(ts.take(rows), key, sub_dets, ctx) if rows.size or js.size else None
    if sub is not None and (sub.tally[Tally.BIRTHS_REFUSED_CAPACITY] or sub.tally[Tally.NUMERICAL_SKIPS]):
        return None
    rerun_seqs = {d.seq for d in sub_dets}
    kept_assoc = [a for a in old.associations if a.seq not in rerun_seqs]
    kept_births = [a.track_id for a in kept_assoc if a.outcome == Outcome.BORN]
    n_born = len(kept_births) + (0 if sub is None else int(sub.tally[Tally.BIRTHS]))
    if n_born > ctx.max_tracks - len(ts):
        return None  # births the whole scan would refuse for capacity: its counts are global
    after = _assemble(ts, rows, sub.after if sub is not None else None, old, rerun_seqs)
    rerun_ids = set(ts.ids[rows].tolist()) | ({int(i) for i in sub.after.ids.tolist()} if sub is not None else set())
    kept = ({int(i) for i in ts.ids.tolist()} | {int(i) for i in kept_births if i is not None}) - rerun_ids
    kept_events = [ev for ev in old_events if ev.track_id in kept]
    tally = _tally_of(kept_assoc, kept_events)
    assoc = kept_assoc
    estimates, events = [], []
    if sub is not None:
        tally.update(sub.tally)
        assoc = sorted(kept_assoc + sub.associations, key=lambda a: a.seq)
        estimates, events = sub.estimates, sub.events
    return Partial(ScanOutcome(after, estimates, events, assoc, tally, mpos), kept, int(rows.size), int(js.size))


def _assemble(ts: TrackSet, rows: np.ndarray, sub_after: TrackSet | None, old: Stored, rerun_seqs: set[int]
              ) -> TrackSet:
    """The after-set in the whole scan's order: the survivors of ts in ts's order (re-run rows from
    sub_after, the others from old.after), then the births by detection seq (those of re-run
    detections from sub_after, the others' from old.after)."""
    A = old.after
    rerun = np.zeros(len(ts), dtype=bool)
    rerun[rows] = True
    pool = A if sub_after is None else sub_after.joined(A)
    off = 0 if sub_after is None else len(sub_after)
    in_a = {int(t): off + i for i, t in enumerate(A.ids.tolist())}
    in_sub = {} if sub_after is None else {int(t): i for i, t in enumerate(sub_after.ids.tolist())}
    order: list[int] = []
    for r, tid in enumerate(ts.ids.tolist()):
        i = in_sub.get(tid) if rerun[r] else in_a.get(tid)  # a kept row survives now iff it survived then
        if i is not None:
            order.append(i)
    births: list[tuple[int, int]] = []  # (seq of the detection that started it, row in pool)
    was = set(old.before.ids.tolist())
    for i, tid in enumerate(A.ids.tolist()):
        if tid not in was and int(A.origin_seq[i]) not in rerun_seqs:
            births.append((int(A.origin_seq[i]), off + i))
    now = set(ts.ids.tolist())
    if sub_after is not None:
        births.extend((int(sub_after.origin_seq[i]), i) for i, tid in enumerate(sub_after.ids.tolist())
                      if tid not in now)
    order.extend(i for _, i in sorted(births))
    return pool.take(np.array(order, dtype=np.intp))
