"""Membership of ids (track ids, detection seqs) in a set of them, as one compiled loop (numba):
`of` sorted once, each value found by binary search. What np.isin answers; one call instead of
the several numpy calls (sort, search, clip, compare) that cost more than the search on the
arrays of a scan (tens to thousands of ids)."""

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


def grown(e_ids: np.ndarray, e_seqs: np.ndarray, seed_ids: np.ndarray, seed_seqs: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """The (ids, seqs) connected to the seeds over the edges (e_ids[k], e_seqs[k]), both sorted
    and distinct: the seeds, grown along the edges that touch them until nothing is added."""
    c = np.ascontiguousarray
    return _grown(c(e_ids, dtype=np.int64), c(e_seqs, dtype=np.int64), np.unique(c(seed_ids, dtype=np.int64)),
                  np.unique(c(seed_seqs, dtype=np.int64)))
