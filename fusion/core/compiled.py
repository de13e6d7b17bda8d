"""Compiled single-state kernels (numba): the same math as fusion.core.kalman, in loops.

On 2x2 to 6x6 matrices each numpy call costs ~1 us here, so one numpy predict + update cannot
go below ~20 us; these loops do the whole step in about one call. Compiled on first use and
cached on disk (cache=True).

predict:  x- = F x,  P- = F P F' + Q
update:   S = H P H' + R = L L' (Cholesky; ok = False when S is not positive definite),
          W = L^-1 H P,  K' = L'^-1 W,  w = L^-1 y,  NIS = w'w,
          P+ = P - A - A' + K S K' with A = K H P (the Joseph form, expanded), symmetrised.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def predict_linear(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = x.shape[0]
    xn = np.zeros(n)
    FP = np.zeros((n, n))
    for i in range(n):
        s = 0.0
        for k in range(n):
            s += F[i, k] * x[k]
        xn[i] = s
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += F[i, k] * P[k, j]
            FP[i, j] = s
    Pn = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += FP[i, k] * F[j, k]
            Pn[i, j] = s + Q[i, j]
    return xn, Pn


@njit(cache=True, fastmath=False)
def update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray,
           R: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, float, float]:
    n = x.shape[0]
    m = y.shape[0]
    HP = np.zeros((m, n))  # H P (= (P H')')
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += H[i, k] * P[k, j]
            HP[i, j] = s
    S = np.empty((m, m))
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
    L = np.zeros((m, m))
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False, x, P, S, 0.0, 0.0
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    W = np.empty((m, n))  # L^-1 H P (forward substitution)
    w = np.empty(m)  # L^-1 y
    for i in range(m):
        for j in range(n):
            s = HP[i, j]
            for k in range(i):
                s -= L[i, k] * W[k, j]
            W[i, j] = s / L[i, i]
        s = y[i]
        for k in range(i):
            s -= L[i, k] * w[k]
        w[i] = s / L[i, i]
    Kt = np.empty((m, n))  # L'^-1 W = S^-1 H P (back substitution)
    for i in range(m - 1, -1, -1):
        for j in range(n):
            s = W[i, j]
            for k in range(i + 1, m):
                s -= L[k, i] * Kt[k, j]
            Kt[i, j] = s / L[i, i]
    nis = 0.0
    logdet = 0.0
    for i in range(m):
        nis += w[i] * w[i]
        logdet += 2.0 * math.log(L[i, i])
    xn = np.empty(n)
    for i in range(n):
        s = x[i]
        for k in range(m):
            s += Kt[k, i] * y[k]
        xn[i] = s
    KS = np.zeros((n, m))  # K S
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += Kt[k, i] * S[k, j]
            KS[i, j] = s
    Pn = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a_ij = 0.0  # (K H P)[i, j]
            a_ji = 0.0
            ksk = 0.0
            for k in range(m):
                a_ij += Kt[k, i] * HP[k, j]
                a_ji += Kt[k, j] * HP[k, i]
                ksk += KS[i, k] * Kt[k, j]
            Pn[i, j] = P[i, j] - a_ij - a_ji + ksk
    for i in range(n):
        for j in range(i):
            a = 0.5 * (Pn[i, j] + Pn[j, i])
            Pn[i, j] = a
            Pn[j, i] = a
    ll = -0.5 * (nis + logdet + m * math.log(2.0 * math.pi))
    return True, xn, Pn, S, nis, ll
