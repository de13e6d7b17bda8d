"""The revisions of a scan run again (fusion.tracking.history.revise) as one compiled loop
(numba): the estimates produced looked up among what the scan reported before, by binary search
in its sorted track ids, and the new table merged in order, in one call instead of a dict of
tuples per scan (~120 bytes a track a scan) or a dozen numpy calls (np.isin most: more than the
work on a partial re-run's handful of estimates). Only arrays here; history.revise makes the
estimates. A table is one (4, k) int64 array, sorted by its first row: track id, revision,
signature, alive (1) or retracted (0) (one array: a compiled call's cost grows with its
arguments)."""

from __future__ import annotations

import numpy as np
from numba import njit

IDS, REV, SIG, ALIVE = 0, 1, 2, 3  # the rows of a table


@njit(cache=True, fastmath=False)
def revised(old: np.ndarray, new: np.ndarray, kept: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What a scan reports when run again, given its table of what it reported last (`old`) and
    the estimates it produces now (`new` (2, n): unique track ids in their given order, and
    signatures); `kept`: the ids of tracks whose stored estimates stand (a partial re-run), in
    any order. Returns
      same (n,) bool: produced unchanged (alive before, the same signature): not reported;
      rev (n,):       each produced estimate's revision (as before if unchanged, else the next
                      one; 0 if the scan never reported the track);
      gone (2, g):    the tracks it reported alive before and produces no more (nor keeps), in
                      id order, with the revision of their retraction (previous + 1);
      table:          every track produced, and every track of old not produced: kept ones as
                      they were, the others retracted (revision + 1 where it was alive)."""
    m, n = old.shape[1], new.shape[1]
    same = np.zeros(n, dtype=np.bool_)
    rev = np.zeros(n, dtype=np.int64)
    produced = np.zeros(m, dtype=np.bool_)
    for i in range(n):
        k = np.searchsorted(old[IDS], new[0, i])
        if k < m and old[IDS, k] == new[0, i]:
            produced[k] = True
            if old[ALIVE, k] != 0 and old[SIG, k] == new[1, i]:
                same[i] = True
                rev[i] = old[REV, k]
            else:
                rev[i] = old[REV, k] + 1
    kept = np.sort(kept)
    nk = kept.shape[0]
    gone = np.empty((2, m), dtype=np.int64)
    g = 0
    order = np.argsort(new[0])
    table = np.empty((4, n + m - produced.sum()), dtype=np.int64)
    a = b = w = 0
    while a < n or b < m:  # the produced rows (by id) merged with the old rows not produced
        if b < m and produced[b]:
            b += 1
            continue
        if b >= m or (a < n and new[0, order[a]] < old[IDS, b]):
            i = order[a]
            table[IDS, w], table[REV, w], table[SIG, w], table[ALIVE, w] = new[0, i], rev[i], new[1, i], 1
            a += 1
        else:
            table[IDS, w], table[REV, w], table[SIG, w], table[ALIVE, w] = \
                old[IDS, b], old[REV, b], old[SIG, b], old[ALIVE, b]
            j = np.searchsorted(kept, old[IDS, b])
            if not (j < nk and kept[j] == old[IDS, b]):  # not kept: retracted
                if old[ALIVE, b] != 0:
                    table[REV, w] += 1
                    gone[0, g], gone[1, g] = old[IDS, b], table[REV, w]
                    g += 1
                table[ALIVE, w] = 0
            b += 1
        w += 1
    return same, rev, gone[:, :g], table


_MIX1, _MIX2, _SEED = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB), np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, fastmath=False, inline="always")
def _mix(h: np.uint64) -> np.uint64:
    """splitmix64's finaliser: a bijection of 64-bit words that spreads every bit over all."""
    h = (h ^ (h >> np.uint64(30))) * _MIX1
    h = (h ^ (h >> np.uint64(27))) * _MIX2
    return h ^ (h >> np.uint64(31))


@njit(cache=True, fastmath=False)
def signatures(X: np.ndarray, P: np.ndarray, status: np.ndarray) -> np.ndarray:
    """A 64-bit signature of each row's bits: X (k, n) and P (k, n, n) float64, C-contiguous,
    viewed as 64-bit words, then status (k,): h <- mix(h ^ word) over the words in that order,
    from a fixed seed. mix is a bijection, so two rows that differ in one word never share a
    signature; rows that differ in more share one with probability ~2^-64 (what revise accepts:
    history.signatures_of). -0.0 and 0.0 differ, a NaN equals itself bit for bit, as bytes do."""
    k = X.shape[0]
    xw = X.reshape(k, -1).view(np.uint64)
    pw = P.reshape(k, -1).view(np.uint64)
    out = np.empty(k, dtype=np.uint64)
    for i in range(k):
        h = _SEED
        for j in range(xw.shape[1]):
            h = _mix(h ^ xw[i, j])
        for j in range(pw.shape[1]):
            h = _mix(h ^ pw[i, j])
        out[i] = _mix(h ^ np.uint64(status[i]))
    return out.view(np.int64)


def row_signatures(X: np.ndarray, P: np.ndarray, status: np.ndarray) -> np.ndarray:
    """signatures of rows x (k, n), P (k, n, n) and status codes (k,) in any dtype and layout:
    what history.revise compares, from a scan's blocks (fusion.tracking.scan: its estimates are
    their rows) or from estimates stacked (history.signatures_of)."""
    return signatures(np.ascontiguousarray(X, dtype=np.float64), np.ascontiguousarray(P, dtype=np.float64),
                      np.asarray(status).astype(np.int64))
