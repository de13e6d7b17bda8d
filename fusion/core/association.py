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
The problem splits into connected components of the gated-pair graph; each is solved with
scipy's linear_sum_assignment.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fusion.core.checks import Array


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
    cost = np.asarray(cost, dtype=np.float64)
    limit = np.asarray(limit, dtype=np.float64)
    if np.bincount(ti).max() == 1 and np.bincount(mj).max() == 1:  # every pair its own component
        return _by_measurement(np.flatnonzero(cost < limit), ti, mj)
    g = coo_matrix((np.ones(ti.size), (ti, n_tracks + mj)), shape=(n_tracks + n_meas,) * 2)
    _, labels = connected_components(g, directed=False)
    comp = labels[ti]
    sizes = np.bincount(comp, minlength=labels.max() + 1)
    # Components with one gated pair (the common case) are decided at once: take it if it wins.
    single = sizes[comp] == 1
    out = [np.flatnonzero(single & (cost < limit))]
    big = 1e18
    rest = np.flatnonzero(~single)
    if rest.size:
        order = rest[np.argsort(comp[rest], kind="stable")]
        bounds = np.flatnonzero(np.diff(comp[order])) + 1
        for sel in np.split(order, bounds):
            miss_cost = 0.5 * float(limit[sel].max())
            ut, it = np.unique(ti[sel], return_inverse=True)
            um, im = np.unique(mj[sel], return_inverse=True)
            a, b = ut.size, um.size
            C = np.full((a + b, b + a), big)
            C[it, im] = cost[sel]
            C[np.arange(a), b + np.arange(a)] = miss_cost  # track i left free
            C[a + np.arange(b), np.arange(b)] = miss_cost  # measurement j left free
            C[a:, b:] = 0.0
            where = np.full((a, b), -1, dtype=np.intp)
            where[it, im] = sel
            r, k = linear_sum_assignment(C)
            real = (r < a) & (k < b)
            r, k = r[real], k[real]
            out.append(where[r, k][C[r, k] < big])
    return _by_measurement(np.concatenate(out), ti, mj)


def _by_measurement(p: np.ndarray, ti: np.ndarray, mj: np.ndarray) -> np.ndarray:
    """Pair positions p sorted by (mj[p], ti[p])."""
    return p[np.lexsort((ti[p], mj[p]))].astype(np.intp)
