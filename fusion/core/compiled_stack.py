"""The compiled single-state kernels of fusion.core.compiled, looped over a stack (numba).

The same arithmetic as one filter step per state (so a batched gate and one filter call per pair
give identical numbers), in one call per stack instead of one numpy call per operation:
    predict_many:  x-_k = F_k x_k,  P-_k = F_k P_k F_k' + Q_k
    update_many:   the Joseph-form update of fusion.core.compiled.update for each k, with
                   ok_k = False where S_k is not positive definite.
    combine_many:  moment-matched mixtures over the mode axis,
                   x_k = sum_m w_km x_km,  P_k = sum_m w_km P_km + sum_m w_km d_km d_km'
                   (d_km = x_km - x_k), symmetrised as (P_k + P_k') / 2.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fusion.core.compiled import predict_linear, update


@njit(cache=True, fastmath=False)
def predict_many(X: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    N, n = X.shape
    Xp = np.empty((N, n))
    Pp = np.empty((N, n, n))
    for k in range(N):
        x, p = predict_linear(X[k], P[k], F[k], Q[k])
        Xp[k] = x
        Pp[k] = p
    return Xp, Pp


@njit(cache=True, fastmath=False)
def update_many(X: np.ndarray, P: np.ndarray, Y: np.ndarray, H: np.ndarray, R: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    N, n = X.shape
    m = Y.shape[1]
    ok = np.ones(N, dtype=np.bool_)
    Xn = np.empty((N, n))
    Pn = np.empty((N, n, n))
    S = np.empty((N, m, m))
    nis = np.empty(N)
    ll = np.empty(N)
    for k in range(N):
        good, x, p, s, v, lk = update(X[k], P[k], Y[k], H[k], R[k])
        ok[k] = good
        Xn[k] = x
        Pn[k] = p
        S[k] = s
        nis[k] = v
        ll[k] = lk
    return ok, Xn, Pn, S, nis, ll


@njit(cache=True, fastmath=False)
def combine_many(xs: np.ndarray, Ps: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    N, M, n = xs.shape
    X = np.zeros((N, n))
    P = np.zeros((N, n, n))
    for k in range(N):
        for m in range(M):
            for a in range(n):
                X[k, a] += w[k, m] * xs[k, m, a]
        A = np.zeros((n, n))
        B = np.zeros((n, n))
        for m in range(M):
            wm = w[k, m]
            for a in range(n):
                da = wm * (xs[k, m, a] - X[k, a])
                for b in range(n):
                    A[a, b] += wm * Ps[k, m, a, b]
                    B[a, b] += da * (xs[k, m, b] - X[k, b])
        for a in range(n):
            for b in range(n):
                P[k, a, b] = 0.5 * ((A[a, b] + B[a, b]) + (A[b, a] + B[b, a]))
    return X, P


def combine_stack(xs: np.ndarray, Ps: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """combine_many on float64 C-contiguous copies: xs (N, M, n), Ps (N, M, n, n), w (N, M)."""
    c = np.ascontiguousarray
    return combine_many(c(xs, np.float64), c(Ps, np.float64), c(w, np.float64))


def predict_stack(X: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """predict_many on float64 C-contiguous copies of its inputs (F, Q broadcast to the stack)."""
    N, n = X.shape
    c = np.ascontiguousarray
    return predict_many(c(X, np.float64), c(P, np.float64), c(np.broadcast_to(F, (N, n, n)), np.float64),
                        c(np.broadcast_to(Q, (N, n, n)), np.float64))


def update_stack(X: np.ndarray, P: np.ndarray, Y: np.ndarray, H: np.ndarray, R: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """update_many on float64 C-contiguous copies (H, R broadcast to the stack): (ok, x+, P+, S,
    NIS, log-likelihood)."""
    N, n = X.shape
    m = Y.shape[1]
    c = np.ascontiguousarray
    return update_many(c(X, np.float64), c(P, np.float64), c(Y, np.float64),
                       c(np.broadcast_to(H, (N, m, n)), np.float64), c(np.broadcast_to(R, (N, m, m)), np.float64))
