"""The coarse gate's constant-velocity extrapolation of track positions, as one compiled loop
(numba): what TrackSet.predicted_position answers. For track i and an axis with position
component p and velocity component v, a step of dt_i seconds:
    position  x_p + x_v dt
    variance  max(P_pp + 2 dt P_pv + dt^2 P_vv + q2 dt^3 / 3, 0)
and without a velocity component x_p and P_pp + q2 |dt|. The caller gives dt and the noise term
q2 dt^3 / 3 per track, computed by numpy: numpy's power is not the C library's pow (they differ
in the last bit for about 4 % of steps here), and these bits are the ones the tracker has always
used. The rest is numpy's arithmetic of the same expressions, in the same order, without
fast-math: one call instead of the dozen numpy calls that cost more than the arithmetic on the
few rows of a partial re-run (fusion.tracking.replay).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def extrapolated(X: np.ndarray, P: np.ndarray, rows: np.ndarray, dt: np.ndarray, noise: np.ndarray,
                 pos_idx: np.ndarray, vel_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(positions (N, d), per-axis variances (N, d)) of tracks `rows` of X (n_tracks, n), P
    (n_tracks, n, n), each dt[k] seconds on, with the noise term noise[k] = q2 dt[k]^3 / 3 (with
    velocity components) or q2 (without: vel_idx empty)."""
    N, d = rows.shape[0], pos_idx.shape[0]
    has_v = vel_idx.shape[0] > 0
    pos, var = np.empty((N, d)), np.empty((N, d))
    for k in range(N):
        i, h = rows[k], dt[k]
        for a in range(d):
            p = pos_idx[a]
            if has_v:
                v = vel_idx[a]
                s = P[i, p, p] + 2.0 * h * P[i, p, v] + h * h * P[i, v, v] + noise[k]
                var[k, a] = s if (s >= 0.0 or np.isnan(s)) else 0.0  # np.maximum(s, 0.0)
                pos[k, a] = X[i, p] + X[i, v] * h
            else:
                var[k, a] = P[i, p, p] + noise[k] * abs(h)
                pos[k, a] = X[i, p]
    return pos, var
