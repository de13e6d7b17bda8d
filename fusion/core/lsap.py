r"""The dense linear sum assignment problem, compiled (numba): for a square cost matrix C (n, n),
the permutation col(r) minimising sum_r C[r, col(r)].

Shortest augmenting paths (Jonker-Volgenant family, in the form of D. F. Crouse, "On implementing
2D rectangular assignment algorithms", IEEE Trans. AES 52(4), 2016, pp. 1685-1686), the algorithm
scipy.optimize.linear_sum_assignment runs, with its tie rules, so that the two return the same
assignment whenever they are given the same matrix, ties included (tests/core/test_gnn_assign.py:
random and integer-valued matrices, whose many equal costs exercise the tie rules):
  - the costs are made non-negative first: C - min(C);
  - rows are added one at a time (row r = 0, 1, ...); for each, a Dijkstra search over the columns
    with the reduced costs d(r', j) = m + C[r', j] - u[r'] - v[j] (m: the path's length so far,
    summed in that order) finds the nearest free column; the columns still to scan are kept in
    an array filled in reverse order (n-1, ..., 0) whose scanned entry is replaced by its last
    one, and among columns of equal path length the first in that array wins unless a later one
    is free (a free column ends the path at once);
  - the duals are then updated: u[r] += m, u[r'] += m - d(col(r')) for the other rows scanned,
    v[j] -= m - d(j) for the columns scanned; and the assignment is flipped along the path.
Only additions, subtractions and comparisons: the same order of them gives the same bits.
The matrix must be finite (the caller's "no pair" entries are large, not infinite) and have an
assignment of a moderate total: where every assignment takes a "no pair" entry (~1e18), the sums
lose the small costs and the two can pick different ones among those (82 of 30 000 random
matrices with such rows, 2026-12-07). fusion.core.association's matrices always have one (every
track and measurement can be left free at the miss cost).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def solve_dense(C: np.ndarray) -> np.ndarray:
    """col (n,) intp: the column assigned to each row of the square, finite cost matrix C."""
    n = C.shape[0]
    lowest_cost = C[0, 0]
    for r in range(n):
        for j in range(n):
            if C[r, j] < lowest_cost:
                lowest_cost = C[r, j]
    cost = np.empty((n, n))
    for r in range(n):
        for j in range(n):
            cost[r, j] = C[r, j] - lowest_cost
    u = np.zeros(n)
    v = np.zeros(n)
    dist = np.empty(n)
    via = np.full(n, -1, dtype=np.intp)  # the row a column was reached from
    col = np.full(n, -1, dtype=np.intp)
    row = np.full(n, -1, dtype=np.intp)
    seen_row = np.zeros(n, dtype=np.bool_)
    seen_col = np.zeros(n, dtype=np.bool_)
    todo = np.empty(n, dtype=np.intp)
    for start in range(n):
        # the shortest path from row `start` to a free column
        for k in range(n):
            todo[k] = n - 1 - k
            dist[k] = np.inf
            seen_row[k] = False
            seen_col[k] = False
        left = n
        m = 0.0
        r = start
        sink = -1
        while sink == -1:
            seen_row[r] = True
            best = -1
            low = np.inf
            for k in range(left):
                j = todo[k]
                d = m + cost[r, j] - u[r] - v[j]
                if d < dist[j]:
                    via[j] = r
                    dist[j] = d
                if dist[j] < low or (dist[j] == low and row[j] == -1):
                    low = dist[j]
                    best = k
            m = low
            j = todo[best]
            if row[j] == -1:
                sink = j
            else:
                r = row[j]
            seen_col[j] = True
            left -= 1
            todo[best] = todo[left]
        # the duals
        u[start] += m
        for r2 in range(n):
            if seen_row[r2] and r2 != start:
                u[r2] += m - dist[col[r2]]
        for j in range(n):
            if seen_col[j]:
                v[j] -= m - dist[j]
        # the assignment, flipped along the path
        j = sink
        while True:
            r2 = via[j]
            row[j] = r2
            nxt = col[r2]
            col[r2] = j
            j = nxt
            if r2 == start:
                break
    return col
