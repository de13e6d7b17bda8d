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
def _adjacency(ends: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs by one of their ends (dense indices < n), by a counting sort: (pair indices in
    the order of that end, start of each end's run in them: n + 1 offsets)."""
    start = np.zeros(n + 1, dtype=np.int64)
    for e in ends:
        start[e + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    order = np.empty(ends.size, dtype=np.int64)
    for p in range(ends.size):
        order[fill[ends[p]]] = p
        fill[ends[p]] += 1
    return order, start


@njit(cache=True, fastmath=False)
def _reached(pi: np.ndarray, pj: np.ndarray, n_i: int, n_j: int, hot_i: np.ndarray, hot_j: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Which of n_i tracks and n_j detections are connected to the hot ones over the pairs
    (pi[k], pj[k]) (dense indices): a breadth-first search of the pairs' bipartite graph, each
    pair visited from each end once."""
    by_i, at_i = _adjacency(pi, n_i)
    by_j, at_j = _adjacency(pj, n_j)
    seen_i = np.zeros(n_i, dtype=np.bool_)
    seen_j = np.zeros(n_j, dtype=np.bool_)
    todo = np.empty(n_i + n_j, dtype=np.int64)  # tracks as i, detections as n_i + j
    n = 0
    for i in hot_i:
        if not seen_i[i]:
            seen_i[i] = True
            todo[n] = i
            n += 1
    for j in hot_j:
        if not seen_j[j]:
            seen_j[j] = True
            todo[n] = n_i + j
            n += 1
    k = 0
    while k < n:
        v = todo[k]
        k += 1
        if v < n_i:
            for p in by_i[at_i[v]:at_i[v + 1]]:
                if not seen_j[pj[p]]:
                    seen_j[pj[p]] = True
                    todo[n] = n_i + pj[p]
                    n += 1
        else:
            for p in by_j[at_j[v - n_i]:at_j[v - n_i + 1]]:
                if not seen_i[pi[p]]:
                    seen_i[pi[p]] = True
                    todo[n] = pi[p]
                    n += 1
    return seen_i, seen_j


@njit(cache=True, fastmath=False)
def _dense_compiled(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.unique(values)
    return u, np.searchsorted(u, values)


NUMPY_SORT_FROM = 512  # pairs: from about here numpy's sort beats the compiled one (12 us for 512 ids; 21 / 62 at 1024)
_NO_IDS = np.zeros(0, dtype=np.int64)


@njit(cache=True, fastmath=False)
def _rerun_sets(old_ids: np.ndarray, old_seqs: np.ndarray, seed_ids: np.ndarray, add_ids: np.ndarray,
                add_seqs: np.ndarray, seed_seqs: np.ndarray, ts_ids: np.ndarray, seqs: np.ndarray,
                via_ids: np.ndarray, via_seqs: np.ndarray,
                uid: np.ndarray, inv_i: np.ndarray, useq: np.ndarray, inv_j: np.ndarray) -> tuple[np.ndarray, ...]:
    keep = ~_member(old_ids, seed_ids)
    new_ids = np.concatenate((old_ids[keep], add_ids))
    new_seqs = np.concatenate((old_seqs[keep], add_seqs))
    # the reach: what the seeds connect to over the stored run's pairs `via` and the added ones
    E = via_ids.size + add_ids.size
    if uid.size == 0:
        uid, inv_i = _dense_compiled(np.concatenate((via_ids, add_ids, seed_ids)))
    if useq.size == 0:
        useq, inv_j = _dense_compiled(np.concatenate((via_seqs, add_seqs, seed_seqs)))
    seen_i, seen_j = _reached(inv_i[:E], inv_j[:E], uid.size, useq.size, inv_i[E:], inv_j[E:])
    rows = np.flatnonzero(_member(ts_ids, uid[seen_i]))
    js = np.flatnonzero(_member(seqs, useq[seen_j]))
    # the new pairs inside the reach (both ends), as (row of the part, detection of the part), by (detection, row)
    sub = ts_ids[rows]
    sub_seqs = seqs[js]
    order = np.argsort(sub, kind="mergesort")
    inside = np.flatnonzero(_member(new_ids, sub) & _member(new_seqs, sub_seqs))
    i = order[np.searchsorted(sub[order], new_ids[inside])]
    j = np.searchsorted(sub_seqs, new_seqs[inside])
    o = np.argsort(j * (rows.shape[0] + 1) + i, kind="mergesort")
    return new_ids, new_seqs, rows, js, i[o], j[o]


def rerun_sets(old_ids: np.ndarray, old_seqs: np.ndarray, seed_ids: np.ndarray, add_ids: np.ndarray,
               add_seqs: np.ndarray, seed_seqs: np.ndarray, ts_ids: np.ndarray, seqs: np.ndarray,
               via: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, ...]:
    """The id-set steps of a partial re-run (fusion.tracking.replay) in one compiled call. The
    stored run's coarse pairs (old_ids[k] track, old_seqs[k] detection) less those of the tracks
    `seed_ids` (changed or gone: the seeds among the tracks), with the pairs `add_ids`, `add_seqs`
    (of the changed tracks and new detections: the seeds `seed_seqs`) added, are the new run's
    pairs. `via`: the stored run's pairs the reach follows besides the added ones (by default its
    coarse pairs; fusion.tracking.replay passes its fine ones). Returns:
      new_ids, new_seqs: the new run's pairs (the kept old ones in their order, then the added);
      rows, js:          the reach: the rows of ts_ids and positions of seqs (both ascending) of
                         the tracks and detections connected to the seeds over the pairs `via`
                         and the added ones (a breadth-first search from the seeds);
      ti, mj:            the new pairs with both ends inside the reach as indices into rows and
                         js, sorted by (mj, ti), as fusion.core.association.coarse_pairs orders them.
    `seqs` is sorted ascending."""
    c = np.ascontiguousarray
    via_ids, via_seqs = (old_ids, old_seqs) if via is None else via
    old_ids, old_seqs, seed_ids, add_ids, add_seqs, seed_seqs, ts_ids, seqs, via_ids, via_seqs = (
        c(a, dtype=np.int64) for a in (old_ids, old_seqs, seed_ids, add_ids, add_seqs, seed_seqs, ts_ids, seqs,
                                       via_ids, via_seqs))
    # the ids and seqs as dense indices (their sorted unique values, and each one's index in them):
    # numpy's sort for many pairs; for fewer (numpy's call costs more than the compiled sort of a
    # hundred ids, its sort far less at a thousand) the compiled call makes them
    uid = inv_i = useq = inv_j = _NO_IDS
    if via_ids.size + add_ids.size >= NUMPY_SORT_FROM:
        uid, inv_i = np.unique(np.concatenate((via_ids, add_ids, seed_ids)), return_inverse=True)
        useq, inv_j = np.unique(np.concatenate((via_seqs, add_seqs, seed_seqs)), return_inverse=True)
    return _rerun_sets(old_ids, old_seqs, seed_ids, add_ids, add_seqs, seed_seqs, ts_ids, seqs, via_ids, via_seqs,
                       uid, c(inv_i, np.int64), useq, c(inv_j, np.int64))
