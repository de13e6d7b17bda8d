"""The compiled single-state kernels of fusion.core.compiled, looped over a stack (numba).

The same arithmetic as one filter step per state (so a batched gate and one filter call per pair
give identical numbers), in one call per stack instead of one numpy call per operation:
    predict_many:  x-_k = F_k x_k,  P-_k = F_k P_k F_k' + Q_k
    update_many:   the Joseph-form update of fusion.core.compiled.update for each k, with
                   ok_k = False where S_k is not positive definite.
    innovate_many: the first half of that update alone (what a gate needs to decide):
                   S_k = H_k P_k H_k' + R_k (symmetrised) = L_k L_k', w_k = L_k^-1 y_k,
                   NIS_k = w_k'w_k, log-likelihood -(NIS_k + ln det S_k + m ln 2 pi) / 2, with
                   the same operations in the same order as update, so the numbers are identical
                   and the posterior need only be computed for the pairs a gate keeps.
    combine_many:  moment-matched mixtures over the mode axis,
                   x_k = sum_m w_km x_km,  P_k = sum_m w_km P_km + sum_m w_km d_km d_km'
                   (d_km = x_km - x_k), symmetrised as (P_k + P_k') / 2.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.core.compiled import cholesky_into, predict_linear, update


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
def innovate_many(P: np.ndarray, Y: np.ndarray, H: np.ndarray, R: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    N, n = P.shape[0], P.shape[1]
    m = Y.shape[1]
    ok = np.ones(N, dtype=np.bool_)
    S_out = np.empty((N, m, m))
    nis_out = np.zeros(N)
    ll_out = np.zeros(N)
    HP = np.empty((m, n))
    L = np.empty((m, m))
    w = np.empty(m)
    for q in range(N):
        good, nis, ll = innovate_into(P[q], Y[q], H[q], R[q], S_out[q], HP, L, w)
        if not good:
            ok[q] = False
            continue
        nis_out[q] = nis
        ll_out[q] = ll
    return ok, S_out, nis_out, ll_out


@njit(cache=True, fastmath=False)
def innovate_into(P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray, S: np.ndarray, HP: np.ndarray,
                  L: np.ndarray, w: np.ndarray) -> tuple[bool, float, float]:
    """One pair of innovate_many: S = H P H' + R (symmetrised) into S; (ok, NIS, log-likelihood);
    HP (m, n), L (m, m), w (m,) are the caller's work arrays."""
    m, n = H.shape[0], H.shape[1]
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += H[i, k] * P[k, j]
            HP[i, j] = s
    for i in range(m):
        for j in range(m):
            s = 0.0
            for k in range(n):
                s += HP[i, k] * H[j, k]
            S[i, j] = s + R[i, j]
    for i in range(m):
        for j in range(i):
            a = 0.5 * (S[i, j] + S[j, i])
            S[i, j] = a
            S[j, i] = a
    L[:, :] = 0.0
    if not cholesky_into(S, L):
        return False, 0.0, 0.0
    for i in range(m):
        s = y[i]
        for k in range(i):
            s -= L[i, k] * w[k]
        w[i] = s / L[i, i]
    nis = 0.0
    logdet = 0.0
    for i in range(m):
        nis += w[i] * w[i]
        logdet += 2.0 * math.log(L[i, i])
    return True, nis, -0.5 * (nis + logdet + m * math.log(2.0 * math.pi))


@njit(cache=True, fastmath=False)
def combine_into(xs: np.ndarray, Ps: np.ndarray, w: np.ndarray, X: np.ndarray, P: np.ndarray,
                 A: np.ndarray, B: np.ndarray) -> None:
    """One moment-matched mixture of xs (M, n), Ps (M, n, n) with weights w (M,) into X (n,),
    P (n, n); A, B (n, n) are the caller's work arrays."""
    M, n = xs.shape
    X[:] = 0.0
    for m in range(M):
        for a in range(n):
            X[a] += w[m] * xs[m, a]
    A[:, :] = 0.0
    B[:, :] = 0.0
    for m in range(M):
        wm = w[m]
        for a in range(n):
            da = wm * (xs[m, a] - X[a])
            for b in range(n):
                A[a, b] += wm * Ps[m, a, b]
                B[a, b] += da * (xs[m, b] - X[b])
    for a in range(n):
        for b in range(n):
            P[a, b] = 0.5 * ((A[a, b] + B[a, b]) + (A[b, a] + B[b, a]))


@njit(cache=True, fastmath=False)
def combine_many(xs: np.ndarray, Ps: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    N, n = xs.shape[0], xs.shape[2]
    X = np.empty((N, n))
    P = np.empty((N, n, n))
    A = np.empty((n, n))
    B = np.empty((n, n))
    for k in range(N):
        combine_into(xs[k], Ps[k], w[k], X[k], P[k], A, B)
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


def innovate_stack(P: np.ndarray, Y: np.ndarray, H: np.ndarray, R: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """innovate_many on float64 C-contiguous copies (H, R broadcast to the stack): (ok, S, NIS,
    log-likelihood), equal bit for bit to those of update_stack."""
    N, n = P.shape[0], P.shape[1]
    m = Y.shape[1]
    c = np.ascontiguousarray
    return innovate_many(c(P, np.float64), c(Y, np.float64), c(np.broadcast_to(H, (N, m, n)), np.float64),
                         c(np.broadcast_to(R, (N, m, m)), np.float64))
