"""The lifecycle's per-row rules (fusion.tracking.lifecycle) as one compiled loop (numba).

For each row i of a scan, given whether it was hit, whether the scan was a chance for it
(`chance`, hit included), its counters and status after the update, the seconds since its last
update in nanoseconds and whether its predicted spread is too wide:
    chances_i = chances_i + chance_i,   misses_i = 0 if hit_i else misses_i + chance_i,
    not confirmed: tentative, chances_i >= confirm_n and hits_i < confirm_m,
    misses:        confirmed and misses_i > max_misses,
    coasted:       t_ns - t_i > coast_ns,
    covariance:    too_wide_i,
    coasting:      confirmed, not deleted, misses_i == 1 and it had none before.
The reason code is the first rule that holds, in that order (0: none): the integer arithmetic
and comparisons of the numpy formulation, so the verdicts are the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit

NOT_CONFIRMED, MISSES, COASTED, COVARIANCE = 1, 2, 3, 4


@njit(cache=True, fastmath=False)
def verdicts(hit: np.ndarray, chance: np.ndarray, chances: np.ndarray, misses: np.ndarray, tentative: np.ndarray,
             hits: np.ndarray, t: np.ndarray, too_wide: np.ndarray, t_ns: int, confirm_n: int, confirm_m: int,
             max_misses: int, coast_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(chances, misses, reason code (0: kept), coasting) of every row (module docstring)."""
    N = hit.shape[0]
    c_out = np.empty(N, dtype=np.int64)
    m_out = np.empty(N, dtype=np.int64)
    why = np.zeros(N, dtype=np.int8)
    coasting = np.zeros(N, dtype=np.bool_)
    for i in range(N):
        ch = 1 if chance[i] else 0
        c = chances[i] + ch
        m = 0 if hit[i] else misses[i] + ch
        c_out[i] = c
        m_out[i] = m
        if tentative[i] and c >= confirm_n and hits[i] < confirm_m:
            why[i] = NOT_CONFIRMED
        elif not tentative[i] and m > max_misses:
            why[i] = MISSES
        elif t_ns - t[i] > coast_ns:
            why[i] = COASTED
        elif too_wide[i]:
            why[i] = COVARIANCE
        else:
            coasting[i] = not tentative[i] and m == 1 and misses[i] == 0
    return c_out, m_out, why, coasting
