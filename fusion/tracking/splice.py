"""A partial re-run's results put together with the stored run's (fusion.tracking.replay): the
associations of every detection in their order, and the after-set in the order the whole scan
builds it, so that the result is bit for bit the whole scan's."""

from __future__ import annotations

import numpy as np

from fusion.tracking import association_kernels as kernels
from fusion.tracking.id_sets import member
from fusion.tracking.results import ScanAssociations
from fusion.tracking.trackset import TrackSet


def spliced(stored: ScanAssociations, old_j: np.ndarray, n: int, part: ScanAssociations, js: np.ndarray
            ) -> ScanAssociations:
    """The associations of the n detections in their order: the stored ones (of the detections
    at positions old_j) with those of the re-run part (positions js) in their place."""
    c = np.ascontiguousarray
    cols = kernels.spliced(n, c(old_j, dtype=np.int64), c(js, dtype=np.int64),
                           *(getattr(b, f) for b in (stored, part) for f in _COLUMNS))
    return ScanAssociations(stored.sensor_id, stored.t_ns, *cols)


_COLUMNS = ("seq", "outcome", "track_id", "nis", "gated_at", "gated")


def after_in_place(ts: TrackSet, rows: np.ndarray, sub_after: TrackSet, A: TrackSet) -> TrackSet | None:
    """The after-set where the re-run changed rows only (what assembled_after gives then, in a few
    steps): ts holds the stored run's tracks in their order, no stored birth came from a re-run
    detection (both checked by the caller), the re-run part neither deleted nor started a track
    and every re-run track survived the stored run. Then the whole scan's order (ts's survivors,
    then the births by seq) is A's own, and the after-set is A with the re-run rows set; None
    where that does not hold."""
    ids = ts.ids[rows]
    if not np.array_equal(sub_after.ids, ids):
        return None
    if ids.size == 0:
        return A  # nothing re-run holds a row: the stored after-set itself
    if rows[-1] < len(A) and np.array_equal(A.ids[rows], ids):
        at = rows  # nothing deleted before them: the same rows
    else:
        at, found = A.rows_of(ids)
        if not found.all():
            return None
    return A.with_rows(at, sub_after, np.arange(ids.size))


def assembled_after(ts: TrackSet, rows: np.ndarray, sub_after: TrackSet | None, A: TrackSet,
                    rerun_seqs: np.ndarray, born_then: np.ndarray) -> TrackSet:
    """The after-set in the whole scan's order: the survivors of ts in ts's order (re-run rows from
    sub_after, the others from A: a kept row survives now iff it survived then), then the
    births by detection seq (those of re-run detections from sub_after, the others' from A).
    Where that is A's rows in their order with some rows from sub_after (the usual case:
    nothing born or deleted differently), A's columns are copied with those rows set, and
    the columns a track's id decides are A's own arrays (track sets are immutable). A: the stored
    run's after-set; `born_then`: which rows of A the stored run started."""
    rerun = np.zeros(len(ts), dtype=bool)
    rerun[rows] = True
    off = 0 if sub_after is None else len(sub_after)
    at_a, in_a = A.rows_of(ts.ids)
    src, ok = off + at_a, in_a & ~rerun
    born_a = np.flatnonzero(born_then & ~member(A.origin_seq, rerun_seqs))
    born_idx, born_seq = [off + born_a], [A.origin_seq[born_a]]
    if sub_after is not None:
        at_s, in_s = sub_after.rows_of(ts.ids)
        src = np.where(rerun, at_s, src)
        ok = np.where(rerun, in_s, ok)
        born_s = np.flatnonzero(~member(sub_after.ids, ts.ids))
        born_idx.append(born_s)
        born_seq.append(sub_after.origin_seq[born_s])
    bi, bs = np.concatenate(born_idx), np.concatenate(born_seq)
    idx = np.concatenate([src[ok], bi[np.argsort(bs, kind="stable")]]).astype(np.intp)
    if sub_after is None:
        return A.take(idx - off)
    fresh = np.flatnonzero(idx < off)  # the rows taken from sub_after
    from_a = idx >= off
    if idx.size == len(A) and (idx[from_a] - off == np.flatnonzero(from_a)).all() \
            and (sub_after.ids[idx[fresh]] == A.ids[fresh]).all():
        return A.with_rows(fresh, sub_after, idx[fresh])
    return sub_after.joined(A).take(idx)
