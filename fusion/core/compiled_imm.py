r"""The IMM's stacked steps as a few compiled loops (numba), for fusion.core.imm_stack.

The arithmetic of fusion.core.imm_stack's numpy formulation, operation for operation (so the
numbers are the same bit for bit), with one compiled call where that took one numpy call per
operation and per mode. For N IMM states of M modes (mode states x_ki, P_ki, probabilities
mu_k, switching matrices Pi_k, predicted probabilities c_k = mu_k Pi_k, computed by the caller):
    distinct:        the distinct time steps of a stack (np.unique with its inverse);
    mix_many:        w_kij = Pi_kij mu_ki / c_kj (c_kj <= 0 taken as 1),
                     x0_kj = sum_i w_kij x_ki,  P0_kj = sum_i w_kij (P_ki + d d') for the rows
                     `sel` that move (compiled_stack.combine_into), mode-major (M, S, ...);
    predict_many:    each moving mode x-_kj = F_kj x0_kj (or f(x0_kj) where the model is
                     nonlinear: the caller's Xf), P-_kj = F_kj P0_kj F_kj' + Q_kj
                     (compiled.predict_work), F_kj = F[j, Fi[j, s]] for moving row s (so that
                     F and Q set by dt alone are given once per distinct dt), Q likewise;
                     rows that do not move keep their modes; then the
                     combination x_k = sum_j c_kj x-_kj, P_k likewise;
    innovate_modes:  each mode's S_kj, NIS and log-likelihood of its innovation y_kj, pair k
                     of predicted state rows[k] (compiled_stack.innovate_into per pair and mode);
    mixture_many:    the mixture innovation y_k = sum_j c_kj y_kj and
                     S_k = sum_j c_kj S_kj + sum_j (c_kj d_kj) d_kj', d_kj = y_kj - y_k, and
                     its NIS y_k' S_k^-1 y_k (numba's LAPACK solve: the same bits as numpy's
                     batched solve, bench.compiled_bits);
    posterior_many:  each mode's EKF update of the pairs `rows` (predicted state at[k] of pair
                     k; compiled.update_work) and their combination with the posterior
                     probabilities.
Arrays are allocated here (their sizes depend on the stack) and returned; the inputs must be
float64 and C-contiguous (the callers in imm_stack pass them so).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fusion.core.compiled import predict_work, update_work, update_work_size
from fusion.core.compiled_stack import combine_into, combine_many, innovate_into


@njit(cache=True, fastmath=False)
def distinct(dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(dt, return_inverse=True) of a float64 vector without NaN: the sorted distinct
    values du and inv with du[inv] == dt."""
    N = dt.shape[0]
    srt = np.sort(dt)
    du = np.empty(N)
    U = 0
    for k in range(N):
        if U == 0 or srt[k] != du[U - 1]:
            du[U] = srt[k]
            U += 1
    du = du[:U].copy()
    inv = np.searchsorted(du, dt)
    return du, inv.astype(np.intp)


@njit(cache=True, fastmath=False)
def mix_many(xs: np.ndarray, Ps: np.ndarray, mu: np.ndarray, Pi: np.ndarray, c: np.ndarray,
             sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    M, n = xs.shape[1], xs.shape[2]
    S = sel.shape[0]
    X0 = np.empty((M, S, n))
    P0 = np.empty((M, S, n, n))
    w = np.empty(M)
    A = np.empty((n, n))
    B = np.empty((n, n))
    for s in range(S):
        k = sel[s]
        for j in range(M):
            d = c[k, j] if c[k, j] > 0 else 1.0
            for i in range(M):
                w[i] = Pi[k, i, j] * mu[k, i] / d
            combine_into(xs[k], Ps[k], w, X0[j, s], P0[j, s], A, B)
    return X0, P0


@njit(cache=True, fastmath=False)
def predict_many(xs: np.ndarray, Ps: np.ndarray, sel: np.ndarray, X0: np.ndarray, P0: np.ndarray,
                 F: np.ndarray, Fi: np.ndarray, Q: np.ndarray, Qi: np.ndarray, Xf: np.ndarray,
                 use_f: np.ndarray, c: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    M, n = xs.shape[1], xs.shape[2]
    pxs = xs.copy()
    pPs = Ps.copy()
    FP = np.empty(n * n)
    for s in range(sel.shape[0]):
        k = sel[s]
        for j in range(M):
            predict_work(X0[j, s], P0[j, s], F[j, Fi[j, s]], Q[j, Qi[j, s]], pxs[k, j], pPs[k, j], FP)
            if use_f[j]:
                pxs[k, j] = Xf[j, s]
    X, P = combine_many(pxs, pPs, c)
    return pxs, pPs, X, P


@njit(cache=True, fastmath=False)
def innovate_modes(Ps: np.ndarray, rows: np.ndarray, Y: np.ndarray, H: np.ndarray, R: np.ndarray
                   ) -> tuple[bool, np.ndarray, np.ndarray]:
    N, M, n = rows.shape[0], Ps.shape[1], Ps.shape[2]
    m = Y.shape[2]
    Ss = np.empty((N, M, m, m))
    ll = np.empty((N, M))
    HP = np.empty((m, n))
    L = np.empty((m, m))
    w = np.empty(m)
    for k in range(N):
        for j in range(M):
            good, _, lj = innovate_into(Ps[rows[k], j], Y[k, j], H[k, j], R[k], Ss[k, j], HP, L, w)
            if not good:
                return False, Ss, ll
            ll[k, j] = lj
    return True, Ss, ll


@njit(cache=True, fastmath=False)
def mixture_many(c: np.ndarray, ys: np.ndarray, Ss: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    N, M, m = ys.shape
    y = np.zeros((N, m))
    S = np.empty((N, m, m))
    nis = np.empty(N)
    A = np.empty((m, m))
    B = np.empty((m, m))
    for k in range(N):
        for j in range(M):
            for a in range(m):
                y[k, a] += c[k, j] * ys[k, j, a]
        A[:, :] = 0.0
        B[:, :] = 0.0
        for j in range(M):
            for a in range(m):
                cd = c[k, j] * (ys[k, j, a] - y[k, a])
                for b in range(m):
                    A[a, b] += c[k, j] * Ss[k, j, a, b]
                    B[a, b] += cd * (ys[k, j, b] - y[k, b])
        for a in range(m):
            for b in range(m):
                S[k, a, b] = A[a, b] + B[a, b]
        nis[k] = _quadratic(y[k], np.linalg.solve(S[k], y[k]))
    return y, S, nis


@njit(cache=True, fastmath=False)
def _quadratic(y: np.ndarray, w: np.ndarray) -> float:
    """sum_a y_a w_a in numpy einsum's order for a short contiguous axis ("ka,ka->k"): the even
    terms, the odd terms, then the two (bench.compiled_bits: the same bits for 1 to 5 terms)."""
    even = y[0] * w[0]
    for a in range(2, y.shape[0], 2):
        even += y[a] * w[a]
    if y.shape[0] > 1:
        odd = y[1] * w[1]
        for a in range(3, y.shape[0], 2):
            odd += y[a] * w[a]
        even += odd
    return even


@njit(cache=True, fastmath=False)
def posterior_many(xs: np.ndarray, Ps: np.ndarray, at: np.ndarray, ys: np.ndarray, Hs: np.ndarray,
                   R: np.ndarray, mu: np.ndarray, rows: np.ndarray
                   ) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    M, n = xs.shape[1], xs.shape[2]
    m = ys.shape[2]
    K = rows.shape[0]
    uxs = np.empty((K, M, n))
    uPs = np.empty((K, M, n, n))
    S = np.empty((m, m))
    work = np.empty(update_work_size(n, m))
    for q in range(K):
        k = rows[q]
        p = at[k]
        for j in range(M):
            good, _, _ = update_work(xs[p, j], Ps[p, j], ys[k, j], Hs[k, j], R[k], uxs[q, j], uPs[q, j], S, work)
            if not good:
                return False, uxs, uPs, uxs[:, 0], uPs[:, 0]
    X = np.empty((K, n))
    P = np.empty((K, n, n))
    A = np.empty((n, n))
    B = np.empty((n, n))
    for q in range(K):
        combine_into(uxs[q], uPs[q], mu[rows[q]], X[q], P[q], A, B)
    return True, uxs, uPs, X, P
