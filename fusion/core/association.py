r"""Gating and global-nearest-neighbour assignment.

Coarse gate. If the Mahalanobis distance y' S^-1 y <= g, then every component obeys
|y_a| <= sqrt(g S_aa). In Cartesian space, with track position p_i (variance v_ia per axis)
and measured point m_j (variance w_ja per axis), a pair is kept when for every axis
    |p_ia - m_ja| <= k sqrt(v_ia + w_ja),     k = margin * sqrt(g)
which is exact for linear Cartesian models (margin 1) and a generous prefilter otherwise.
Candidates are found by a sweep (compiled, numba): measurements sorted on the first axis, and
for each track i the measurements within k sqrt(v_i0 + max_j w_j0) of p_i0 on that axis found
by binary search, then tested on every axis; so the cost grows with N log M plus the number of
candidates, not with tracks x measurements, and one wide track widens only its own window.

Assignment. Among gated pairs with costs c_ij (the negative log-likelihood NIS + ln det S)
and limits l_ij (g + ln det S: the cost at the gate's edge), GNN minimises the sum of pair
costs plus, for each unassigned track and each unassigned measurement, half the largest limit
of its component, so a pair alone is always taken (c < l) and pairs compete by likelihood.
The problem splits into connected components of the gated-pair graph (union-find over tracks
and measurements); a component of one pair takes it when c < l, and a larger one is solved as a
dense square problem (its a tracks and b measurements, each with a "left free" column or row at
the miss cost, the free-free block 0, pairs not gated 1e18) by fusion.core.lsap.solve_dense,
scipy's algorithm and tie rules compiled. All of it is one compiled call per assignment: the
components were a Python loop of numpy calls and a scipy call each (where gates overlap often, as
in the mix's scene at 1000 targets, 20 % of a scan; BENCHMARKS.md, Tracker).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.core.checks import Array
from fusion.core.lsap import solve_dense

NO_PAIR = 1e18  # the cost of a track and a measurement not gated together: never chosen


@njit(cache=True, fastmath=False)
def _sweep(track_pos: np.ndarray, track_var: np.ndarray, meas_pos: np.ndarray, meas_var: np.ndarray,
           k: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) with (p_ia - m_ja)^2 <= k^2 (v_ia + w_ja) on every axis a, sorted by (j, i)."""
    N, d = track_pos.shape
    M = meas_pos.shape[0]
    order = np.argsort(meas_pos[:, 0], kind="mergesort")
    xs = np.empty(M)
    for c in range(M):
        xs[c] = meas_pos[order[c], 0]
    wmax = meas_var[0, 0]
    for j in range(1, M):
        wmax = max(wmax, meas_var[j, 0])
    lo = np.empty(N, dtype=np.intp)
    hi = np.empty(N, dtype=np.intp)
    total = 0
    for i in range(N):
        # widened by a relative 1e-9 so that rounding never drops a pair the exact test keeps
        half = k * math.sqrt(track_var[i, 0] + wmax) * (1.0 + 1e-9) + 1e-300
        lo[i] = np.searchsorted(xs, track_pos[i, 0] - half, side="left")
        hi[i] = np.searchsorted(xs, track_pos[i, 0] + half, side="right")
        total += hi[i] - lo[i]
    kk = k * k
    ti = np.empty(total, dtype=np.intp)
    mj = np.empty(total, dtype=np.intp)
    n = 0
    for i in range(N):
        for c in range(lo[i], hi[i]):
            j = order[c]
            ok = True
            for a in range(d):
                e = abs(track_pos[i, a] - meas_pos[j, a])
                if not e * e <= kk * (track_var[i, a] + meas_var[j, a]):
                    ok = False
                    break
            if ok:
                ti[n] = i
                mj[n] = j
                n += 1
    # sorted by (j, i): a stable counting sort by j of pairs found in increasing i
    start = np.zeros(M + 1, dtype=np.intp)
    for p in range(n):
        start[mj[p] + 1] += 1
    for j in range(M):
        start[j + 1] += start[j]
    si = np.empty(n, dtype=np.intp)
    sj = np.empty(n, dtype=np.intp)
    for p in range(n):
        q = start[mj[p]]
        si[q] = ti[p]
        sj[q] = mj[p]
        start[mj[p]] = q + 1
    return si, sj


def coarse_pairs(
    track_pos: Array, track_var: Array, meas_pos: Array, meas_var: Array, *, k: float
) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j) of tracks and measurements within the per-axis coarse gate.

    track_pos, track_var: (N, d); meas_pos, meas_var: (M, d). Pairs come sorted by (j, i).
    """
    N, M = track_pos.shape[0], meas_pos.shape[0]
    if N == 0 or M == 0:
        e = np.empty(0, dtype=np.intp)
        return e, e
    c = np.ascontiguousarray
    return _sweep(c(track_pos, np.float64), c(track_var, np.float64), c(meas_pos, np.float64),
                  c(meas_var, np.float64), float(k))


def gnn_assign(
    ti: np.ndarray, mj: np.ndarray, cost: Array, limit: Array, *, n_tracks: int, n_meas: int
) -> np.ndarray:
    """Optimal assignment over gated pairs (ti[p], mj[p]) with cost[p] and limit[p] (see the
    module docstring). Returns the positions p of the chosen pairs, sorted by (mj[p], ti[p])."""
    if ti.size == 0:
        return np.zeros(0, dtype=np.intp)
    c = np.ascontiguousarray
    return gnn_positions(c(ti, np.intp), c(mj, np.intp), c(cost, np.float64), c(limit, np.float64), int(n_tracks),
                int(n_meas))


@njit(cache=True, fastmath=False)
def _root(parent: np.ndarray, a: int) -> int:
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, fastmath=False)
def gnn_positions(ti: np.ndarray, mj: np.ndarray, cost: np.ndarray, limit: np.ndarray, n_tracks: int,
                  n_meas: int) -> np.ndarray:
    """gnn_assign's work, for compiled callers (intp ti, mj; float64 cost, limit; at least one
    pair): components by union-find (nodes: tracks, then n_tracks + measurement), each decided
    or solved, the chosen positions sorted by (mj, ti)."""
    n_pairs = ti.size
    parent = np.arange(n_tracks + n_meas)
    for p in range(n_pairs):
        a, b = _root(parent, ti[p]), _root(parent, n_tracks + mj[p])
        if a != b:
            parent[max(a, b)] = min(a, b)
    comp = np.empty(n_pairs, dtype=np.intp)
    for p in range(n_pairs):
        comp[p] = _root(parent, ti[p])
    chosen = np.zeros(n_pairs, dtype=np.bool_)
    # the pairs grouped by component (a stable counting sort: each group in increasing p)
    start = np.zeros(n_tracks + n_meas + 1, dtype=np.intp)
    for p in range(n_pairs):
        start[comp[p] + 1] += 1
    for k in range(n_tracks + n_meas):
        start[k + 1] += start[k]
    at = start[:-1].copy()
    order = np.empty(n_pairs, dtype=np.intp)
    for p in range(n_pairs):
        order[at[comp[p]]] = p
        at[comp[p]] += 1
    for g in range(n_tracks + n_meas):
        lo, hi = start[g], start[g + 1]
        if hi - lo == 1:  # one pair: taken if it wins against leaving both free
            p = order[lo]
            chosen[p] = cost[p] < limit[p]
        elif hi > lo:
            _solve_component(order[lo:hi], ti, mj, cost, limit, chosen)
    out = np.flatnonzero(chosen)
    key = np.empty(out.size, dtype=np.int64)
    for k in range(out.size):
        key[k] = mj[out[k]] * np.int64(n_tracks) + ti[out[k]]
    return out[np.argsort(key, kind="mergesort")].astype(np.intp)


@njit(cache=True, fastmath=False)
def _solve_component(sel: np.ndarray, ti: np.ndarray, mj: np.ndarray, cost: np.ndarray, limit: np.ndarray,
                     chosen: np.ndarray) -> None:
    """One component of more than one pair (positions sel): its a tracks and b measurements (each
    sorted), the dense (a + b) square problem of the module docstring, the real pairs it picks."""
    miss = limit[sel[0]]
    for p in sel:
        miss = max(miss, limit[p])
    miss = 0.5 * miss
    ut, um = np.unique(ti[sel]), np.unique(mj[sel])
    a, b = ut.size, um.size
    C = np.full((a + b, b + a), NO_PAIR)
    where = np.full((a, b), -1, dtype=np.intp)
    for p in sel:
        r, k = np.searchsorted(ut, ti[p]), np.searchsorted(um, mj[p])
        C[r, k] = cost[p]
        where[r, k] = p
    for r in range(a):
        C[r, b + r] = miss  # track r left free
    for k in range(b):
        C[a + k, k] = miss  # measurement k left free
    C[a:, b:] = 0.0
    col = solve_dense(C)
    for r in range(a):
        k = col[r]
        if k < b and C[r, k] < NO_PAIR:
            chosen[where[r, k]] = True
