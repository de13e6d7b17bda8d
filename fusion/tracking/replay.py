"""Selective replay: a scan run again after late data re-runs only what the late data can reach.

A scan was run on the track set B with detections D and produced the set A and its outcome (the
history's Entry). Run again, it has the set B' and detections D' (D and the late ones):
  seeds:    the rows of B' that differ bit for bit from B's row of the same track (or that B
            lacks), the tracks of B that B' lacks, and the detections of D' not in D;
  reach:    the connected components, over tracks (by id) and detections (by seq), that hold a
            seed, of the old run's fine pairs (a detection and the tracks in whose fine gate it
            fell: its ScanAssociations.gated) and the new run's coarse pairs of the changed tracks
            and of the new detections (fusion.core.association.coarse_pairs on B', D');
  re-run:   run_scan on the tracks and detections of the reach alone, with the new coarse pairs
            that have both ends in it;
  the rest: every other track and detection saw the same rows, the same detections and the same
            pairs in both runs, and every step of a scan after the coarse gate is per pair (fine
            gate), per component of the fine pairs (the assignment: fusion.core.association.gnn_assign
            decides each component alone; births take what it left) or per row (update,
            initiation, lifecycle), so its results are the stored ones: its rows are copied from
            A, its estimates, events and associations from the stored outcome.
            Why the fine pairs suffice: an unchanged track and an old detection make the same
            fine-gate decision in both runs, so an unchanged track's fine pairs are the old ones
            and its other coarse pairs can never be assigned; a changed track's new pairs are all
            followed (its coarse ones), and its old fine pairs lead to the detections it may give
            up. A reached track's coarse pair with a detection outside the reach is therefore no
            fine pair in either run, and the part leaves it out. At 667 targets with 10 % late
            data it re-runs 46 tracks a partial scan, against 73 over the coarse pairs of both
            runs (the same 62 664 revised estimates).
The after-set is assembled (fusion.tracking.splice) in the order the whole scan builds it (the
surviving rows of B' in their order, then the births in detection order), so the result is
bit-identical to running the whole scan. Where a rule counts over the whole scan the whole scan is run instead (`None`):
capacity (the old run refused a birth for max_tracks, or the births would not fit now) and
numerical skips in the old run (the batched gate then ran the whole dimension group pair by
pair, which agrees with the batched math to 1e-12, not bit for bit); and a scan that holds a seq
twice (a restarted publisher's two epochs sending the same seqs at the same time), where the
pairs, keyed by seq, no longer name one detection each.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from fusion.core.association import coarse_pairs
from fusion.core.checks import Array
from fusion.tracking.association_kernels import counted
from fusion.tracking.detection import Detection, seqs_of
from fusion.tracking.id_sets import member, member_sorted, repeats, rerun_sets
from fusion.tracking.results import OUTCOME_CODE, EventKind, Outcome, ScanAssociations, ScanKey, TrackEvent
from fusion.tracking.scan import Coarse, ScanContext, ScanOutcome, Tally, measured_points, run_scan
from fusion.tracking.splice import after_in_place, assembled_after, spliced
from fusion.tracking.trackset import TrackSet


@dataclass(frozen=True)
class Gates:
    """A scan run's coarse pairs, by track id and detection seq, and its detections' world points
    and variances (in the order of the scan's detections)."""

    ids: np.ndarray
    seqs: np.ndarray
    mpos: Array
    mvar: Array
    det_seqs: np.ndarray | None = None  # the seqs of the scan's detections, in their order


@dataclass(frozen=True)
class Stored:
    """A scan's previous run: its set before and after, detections, associations, tally and (if
    known) its gates."""

    before: TrackSet
    after: TrackSet
    dets: tuple[Detection, ...]
    associations: ScanAssociations
    tally: Counter
    gates: Gates | None = None


@dataclass(frozen=True)
class Hint:
    """What the previous partial re-run left: its after-set differs from `source` (the stored
    run's after-set) only in the rows of tracks `ids`."""

    source: TrackSet
    ids: np.ndarray


@dataclass(frozen=True)
class Partial:
    """A scan run again in part: its outcome (estimates and events of the re-run part only;
    associations, tally and the after-set whole), the track ids whose stored estimates and
    events stand, its gates, and the hint for the next scan."""

    outcome: ScanOutcome
    kept: np.ndarray  # the ids of the tracks whose stored estimates and events stand, sorted
    gates: Gates
    hint: Hint
    rerun_tracks: int
    rerun_dets: int


def gates_of(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], ctx: ScanContext,
             points: tuple[Array, Array] | None = None) -> Gates:
    """The coarse pairs of scan `key` on ts (fusion.core.association.coarse_pairs, as run_scan
    gates), by id and seq; `points`: the detections' world points if known."""
    mpos, mvar = points if points is not None else measured_points(ctx.sensors[key[1]], dets)
    tpos, tvar = ts.predicted_position(key[0], ctx.q2)
    ci, cj = coarse_pairs(tpos, tvar, mpos, mvar, k=ctx.coarse_k)
    seqs = seqs_of(dets)
    return Gates(ts.ids[ci], seqs[cj], mpos, mvar, seqs)


def gates_of_run(ts: TrackSet, seqs: np.ndarray, out: ScanOutcome) -> Gates | None:
    """The gates of a whole run of a scan on ts, from what run_scan returned (`seqs`: its
    detections' seqs, in their order)."""
    if out.coarse is None or out.variances is None:
        return None
    ci, cj = out.coarse
    return Gates(ts.ids[ci], seqs[cj], out.positions, out.variances, seqs)


def _points(old: Stored, old_gates: Gates, dets: tuple[Detection, ...], seqs: np.ndarray, old_j: np.ndarray,
            ctx: ScanContext, sensor_id: str) -> tuple[Array, Array]:
    """World points of dets: the stored ones' from the old gates, the new ones' measured."""
    if len(old.dets) == len(dets):
        return old_gates.mpos, old_gates.mvar
    new = np.ones(len(dets), dtype=bool)
    new[old_j] = False
    npos, nvar = measured_points(ctx.sensors[sensor_id], tuple(dets[j] for j in np.flatnonzero(new).tolist()))
    d = npos.shape[1]
    mpos, mvar = np.empty((len(dets), d)), np.empty((len(dets), d))
    mpos[old_j], mvar[old_j] = old_gates.mpos, old_gates.mvar
    mpos[new], mvar[new] = npos, nvar
    return mpos, mvar


def _added_pairs(ts: TrackSet, changed: np.ndarray, new: np.ndarray, points: tuple[Array, Array], seqs: np.ndarray,
                 t_ns: int, ctx: ScanContext) -> tuple[np.ndarray, np.ndarray]:
    """The coarse pairs the stored run could not have (by track id and detection seq): those of
    the changed tracks with every detection, and of the other tracks with the new detections
    (each pair is decided by its track's row and its detection alone: the rest are stored)."""
    mpos, mvar = points
    ids, sq = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]  # (none, if nothing changed or is new)
    ch, nj = np.flatnonzero(changed), np.flatnonzero(new)
    if ch.size:
        ci, cj = coarse_pairs(*ts.predicted_position(t_ns, ctx.q2, ch), mpos, mvar, k=ctx.coarse_k)
        ids.append(ts.ids[ch[ci]])
        sq.append(seqs[cj])
    if nj.size:
        un = np.flatnonzero(~changed)
        if un.size:
            ci, cj = coarse_pairs(*ts.predicted_position(t_ns, ctx.q2, un), mpos[nj], mvar[nj], k=ctx.coarse_k)
            ids.append(ts.ids[un[ci]])
            sq.append(seqs[nj[cj]])
    return np.concatenate(ids), np.concatenate(sq)


def _fine_pairs(assoc: ScanAssociations) -> tuple[np.ndarray, np.ndarray]:
    """The stored run's fine pairs (track id, detection seq): each detection with the tracks in
    whose fine gate it fell (ScanAssociations.gated)."""
    return assoc.gated, np.repeat(assoc.seq, np.diff(assoc.gated_at))


def stands(events: Iterable[TrackEvent], kept: np.ndarray) -> list[bool]:
    """Whether each event is of one of the tracks `kept` (Partial.kept: ids, sorted): a binary
    search each, not a set of the hundreds of ids a partial re-run keeps built for the few
    events to look up."""
    return member_sorted(np.fromiter((ev.track_id for ev in events), dtype=np.int64), kept).tolist()


_COUNTED_CODES = (OUTCOME_CODE[Outcome.UPDATED], OUTCOME_CODE[Outcome.BORN])  # association_kernels.counted's
_NO_SIGNATURES = np.empty(0, dtype=np.int64)


def _tally_of(assoc: ScanAssociations, rows: np.ndarray, events: list) -> Counter:
    """The tally of a part of a scan from what it did (fusion.tracking.scan counts the same):
    updates, births and unassigned (in a gate, not taken) from the associations `rows`;
    confirmations and deletions from the events. Used for parts without capacity refusals."""
    t: Counter = Counter()
    counts = counted(assoc.outcome, assoc.gated_at, rows, *_COUNTED_CODES)
    for kind, n in zip((Tally.UPDATES, Tally.UNASSIGNED, Tally.BIRTHS), counts, strict=True):
        if n:
            t[kind] += n
    for ev in events:
        if ev.kind == EventKind.CONFIRMED:
            t[Tally.CONFIRMATIONS] += 1
        elif ev.kind == EventKind.DELETED and ev.reason is not None:
            t[ev.reason] += 1
    return t


def rerun(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], ctx: ScanContext, old: Stored,
          old_events: list, hint: Hint | None = None, seqs: np.ndarray | None = None) -> Partial | None:
    """Scan `key` run again on `ts` with `dets` (sorted by seq and epoch), reusing `old` where the late data
    cannot reach; None where the whole scan must run (module docstring). `old_events`: the events
    the stored run reported; `hint`: the previous scan's partial re-run, if any; `seqs`: the seqs
    of `dets`, if known (fusion.tracking.step_order.merged_seqs)."""
    if old.tally[Tally.BIRTHS_REFUSED_CAPACITY] or old.tally[Tally.NUMERICAL_SKIPS]:
        return None  # the old run's counts are not per component: run the whole scan
    old_gates = old.gates if old.gates is not None else gates_of(old.before, key, old.dets, ctx)
    old_seqs = old_gates.det_seqs if old_gates.det_seqs is not None else seqs_of(old.dets)
    if len(dets) == len(old.dets):  # dets hold old.dets: the same detections
        seqs, old_j = old_seqs, np.arange(len(dets))
    else:
        seqs = seqs_of(dets) if seqs is None else seqs
        old_j = np.searchsorted(seqs, old_seqs)  # both sorted by seq
    if repeats(seqs):
        return None  # a seq twice (two epochs of a publisher): pairs keyed by seq would be ambiguous
    new = np.ones(len(dets), dtype=bool)
    new[old_j] = False
    changed = ts.changed_since(old.before, among=hint.ids if hint is not None and hint.source is old.before else None)
    same_ids = ts.ids is old.before.ids or np.array_equal(ts.ids, old.before.ids)
    gone = old.before.ids[:0] if same_ids else old.before.ids[~member(old.before.ids, ts.ids)]
    if not (changed.any() or gone.size or new.any()):  # nothing changed: the stored run stands
        if not np.array_equal(ts.ids, old.before.ids):
            return None  # the same rows in another order: the whole scan orders its output by them
        kept = np.union1d(ts.ids, old.after.ids)
        return Partial(ScanOutcome(old.after, [], [], old.associations, old.tally, old_gates.mpos,
                                   signatures=_NO_SIGNATURES), kept,
                       old_gates, Hint(old.after, np.zeros(0, np.int64)), 0, 0)
    points = _points(old, old_gates, dets, seqs, old_j, ctx, key[1])
    add_ids, add_seqs = _added_pairs(ts, changed, new, points, seqs, key[0], ctx)
    seeds = np.concatenate([ts.ids[changed], gone])  # the tracks whose pairs change
    new_ids, new_seqs, rows, js, ti, mj = rerun_sets(old_gates.ids, old_gates.seqs, seeds, add_ids, add_seqs,
                                                     seqs[new], ts.ids, seqs, via=_fine_pairs(old.associations))
    new_gates = Gates(new_ids, new_seqs, *points, seqs)
    if rows.size == len(ts) and js.size == len(dets):
        return None  # everything is reached: the whole scan is the same work
    sub_dets = tuple(dets[j] for j in js.tolist())
    sub = run_scan(ts.take(rows), key, sub_dets, ctx, Coarse(ti, mj, points[0][js], points[1][js]), seqs[js]) \
        if rows.size or js.size else None
    if sub is not None and (sub.tally[Tally.BIRTHS_REFUSED_CAPACITY] or sub.tally[Tally.NUMERICAL_SKIPS]):
        return None
    in_js = np.zeros(len(dets), dtype=bool)
    in_js[js] = True
    gone_k = np.flatnonzero(in_js[old_j])  # the stored detections run again
    A = old.after
    born_then = ~member(A.ids, old.before.ids)  # the stored run's births
    kept_births = A.ids[born_then & ~member(A.origin_seq, seqs[js])]
    n_born = kept_births.size + (0 if sub is None else int(sub.tally[Tally.BIRTHS]))
    if n_born > ctx.max_tracks - len(ts):
        return None  # births the whole scan would refuse for capacity: its counts are global
    after = None
    if same_ids and sub is not None and kept_births.size == born_then.sum():
        after = after_in_place(ts, rows, sub.after, A)
    if after is None:
        after = assembled_after(ts, rows, None if sub is None else sub.after, A, seqs[js], born_then)
    touched = np.unique(np.concatenate([ts.ids[rows]] + ([] if sub is None else [sub.after.ids])))
    kept = np.concatenate([ts.ids, kept_births])
    kept = np.sort(kept[~member(kept, touched)])
    # the stored tally less what the re-run part counted in the stored run, plus what it counts now
    gone_events = [ev for ev, s in zip(old_events, stands(old_events, kept), strict=True) if not s]
    tally = old.tally - _tally_of(old.associations, gone_k, gone_events)
    assoc, estimates, events, sigs = old.associations, [], [], _NO_SIGNATURES
    if sub is not None:
        tally.update(sub.tally)
        assoc = spliced(old.associations, old_j, len(dets), sub.associations, js)
        estimates, events, sigs = sub.estimates, sub.events, sub.signatures
    return Partial(ScanOutcome(after, estimates, events, assoc, tally, new_gates.mpos, signatures=sigs), kept,
                   new_gates, Hint(old.after, touched), int(rows.size), int(js.size))
