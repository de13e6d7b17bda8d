"""Sets of ids (track ids, detection seqs) as compiled loops (numba). Membership: `of` sorted
once, each value found by binary search; what np.isin answers, in one call instead of the several
numpy calls (sort, search, clip, compare) that cost more than the search on the arrays of a scan
(tens to thousands of ids). A partial re-run's pairs, reach and part (rerun_sets): the same,
for the dozen steps of fusion.tracking.replay that are set logic on ids."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def _member(values: np.ndarray, of: np.ndarray) -> np.ndarray:
    srt = np.sort(of)
    n = srt.shape[0]
    out = np.zeros(values.shape[0], dtype=np.bool_)
    for i in range(values.shape[0]):
        k = np.searchsorted(srt, values[i])
        out[i] = k < n and srt[k] == values[i]
    return out


def positions(ids: np.ndarray, want: np.ndarray, order: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(index in `ids` of each of `want`, found) for unique ids: found[k] iff want[k] is in ids,
    and then ids[index[k]] == want[k]. `order`: np.argsort(ids, kind="stable"), if known."""
    if ids.size == 0:
        return np.zeros(want.size, dtype=np.intp), np.zeros(want.size, dtype=bool)
    if order is None:
        order = np.argsort(ids, kind="stable")
    at = order[np.minimum(np.searchsorted(ids, want, sorter=order), ids.size - 1)]
    return at, ids[at] == want


def member(values: np.ndarray, of: np.ndarray) -> np.ndarray:
    """values[i] in `of`, for each i of a vector of integers (np.isin(values, of))."""
    if of.size == 0 or values.size == 0:
        return np.zeros(values.shape, dtype=bool)
    return _member(np.ascontiguousarray(values, dtype=np.int64), np.ascontiguousarray(of, dtype=np.int64))


@njit(cache=True, fastmath=False)
def _grown(e_ids: np.ndarray, e_seqs: np.ndarray, hot_ids: np.ndarray, hot_seqs: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    while True:
        m = _member(e_ids, hot_ids) | _member(e_seqs, hot_seqs)
        more_ids = np.unique(np.concatenate((hot_ids, e_ids[m])))
        more_seqs = np.unique(np.concatenate((hot_seqs, e_seqs[m])))
        if more_ids.size == hot_ids.size and more_seqs.size == hot_seqs.size:
            return hot_ids, hot_seqs
        hot_ids, hot_seqs = more_ids, more_seqs


@njit(cache=True, fastmath=False)
def _rerun_sets(old_ids: np.ndarray, old_seqs: np.ndarray, seed_ids: np.ndarray, add_ids: np.ndarray,
                add_seqs: np.ndarray, seed_seqs: np.ndarray, ts_ids: np.ndarray, seqs: np.ndarray
                ) -> tuple[np.ndarray, ...]:
    keep = ~_member(old_ids, seed_ids)
    new_ids = np.concatenate((old_ids[keep], add_ids))
    new_seqs = np.concatenate((old_seqs[keep], add_seqs))
    # the new pairs are the old ones less some, and the added ones: the union of both runs'
    hot_ids, hot_seqs = _grown(np.concatenate((old_ids, add_ids)), np.concatenate((old_seqs, add_seqs)),
                               np.unique(seed_ids), np.unique(seed_seqs))
    rows = np.flatnonzero(_member(ts_ids, hot_ids))
    js = np.flatnonzero(_member(seqs, hot_seqs))
    # the new pairs inside the reach, as (row of the part, detection of the part), by (detection, row)
    sub = ts_ids[rows]
    order = np.argsort(sub, kind="mergesort")
    inside = np.flatnonzero(_member(new_ids, sub))
    i = order[np.searchsorted(sub[order], new_ids[inside])]
    j = np.searchsorted(seqs[js], new_seqs[inside])
    o = np.argsort(j * (rows.shape[0] + 1) + i, kind="mergesort")
    return new_ids, new_seqs, rows, js, i[o], j[o]


def rerun_sets(old_ids: np.ndarray, old_seqs: np.ndarray, seed_ids: np.ndarray, add_ids: np.ndarray,
               add_seqs: np.ndarray, seed_seqs: np.ndarray, ts_ids: np.ndarray, seqs: np.ndarray
               ) -> tuple[np.ndarray, ...]:
    """The id-set steps of a partial re-run (fusion.tracking.replay) in one compiled call. The
    stored run's coarse pairs (old_ids[k] track, old_seqs[k] detection) less those of the tracks
    `seed_ids` (changed or gone: the seeds among the tracks), with the pairs `add_ids`, `add_seqs`
    (of the changed tracks and new detections: the seeds `seed_seqs`) added, are the new run's
    pairs. Returns:
      new_ids, new_seqs: the new run's pairs (the kept old ones in their order, then the added);
      rows, js:          the reach: the rows of ts_ids and positions of seqs (both ascending) of
                         the tracks and detections connected to the seeds over the pairs of both
                         runs (grown from the seeds along the pairs until nothing is added);
      ti, mj:            the new pairs inside the reach as indices into rows and js, sorted by
                         (mj, ti), as fusion.core.association.coarse_pairs orders them.
    `seqs` is sorted ascending; the reach is closed under the pairs (a pair with one end in it has
    both), so every pair inside has its detection among js."""
    c = np.ascontiguousarray
    return _rerun_sets(*(c(a, dtype=np.int64) for a in (old_ids, old_seqs, seed_ids, add_ids, add_seqs, seed_seqs,
                                                          ts_ids, seqs)))
