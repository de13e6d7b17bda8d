"""Compiled single-state kernels (numba): the same math as fusion.core.kalman, in loops.

On 2x2 to 6x6 matrices each numpy call costs ~1 us here, so one numpy predict + update cannot
go below ~20 us; these loops do the whole step in about one call. Compiled on first use and
cached on disk (cache=True). The `*_into` kernels write into arrays the caller allocated:
returning a fresh array from a numba function costs more than the 4x4 arithmetic itself.

predict:  x- = F x,  P- = F P F' + Q  (predict_into also reports whether x- is finite)
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
    """`predict_into` on fresh arrays."""
    n = x.shape[0]
    xn = np.empty(n)
    Pn = np.empty((n, n))
    predict_into(x, P, F, Q, xn, Pn)
    return xn, Pn


@njit(cache=True, fastmath=False)
def predict_into(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray,
                 xn: np.ndarray, Pn: np.ndarray) -> bool:
    """x- = F x into xn, P- = F P F' + Q into Pn; returns whether every component of xn is finite."""
    n = x.shape[0]
    return predict_work(x, P, F, Q, xn, Pn, np.empty(n * n))


@njit(cache=True, fastmath=False)
def predict_work(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray,
                 xn: np.ndarray, Pn: np.ndarray, FP: np.ndarray) -> bool:
    """`predict_into` with the product F P in FP (n^2 floats, row-major, overwritten; nothing is
    allocated)."""
    n = x.shape[0]
    finite = True
    for i in range(n):
        s = 0.0
        for k in range(n):
            s += F[i, k] * x[k]
        xn[i] = s
        finite = finite and math.isfinite(s)
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += F[i, k] * P[k, j]
            FP[i * n + j] = s
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += FP[i * n + k] * F[j, k]
            Pn[i, j] = s + Q[i, j]
    return finite


@njit(cache=True, fastmath=False)
def update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray,
           R: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """`update_into` on fresh arrays; on failure (ok False) x and P are returned unchanged."""
    n = x.shape[0]
    m = y.shape[0]
    xn = np.empty(n)
    Pn = np.empty((n, n))
    S = np.empty((m, m))
    ok, nis, ll = update_into(x, P, y, H, R, xn, Pn, S)
    if not ok:
        return False, x, P, S, 0.0, 0.0
    return True, xn, Pn, S, nis, ll


@njit(cache=True, fastmath=False)
def cholesky_into(S: np.ndarray, L: np.ndarray) -> bool:
    """S = L L' into the lower triangle of L (the upper one is not written); False, with L
    partly written, where S is not positive definite (a pivot that is not > 0, NaN included)."""
    m = S.shape[0]
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


@njit(cache=True, fastmath=False)
def update_into(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray,
                xn: np.ndarray, Pn: np.ndarray, S: np.ndarray) -> tuple[bool, float, float]:
    """The update written into xn (n,), Pn (n, n) and S (m, m); returns (ok, NIS, log-likelihood).

    ok is False (and xn, Pn unwritten) when S is not positive definite; S is filled either way.
    """
    m, n = y.shape[0], x.shape[0]
    return update_work(x, P, y, H, R, xn, Pn, S, np.empty(update_work_size(n, m)))


@njit(cache=True, fastmath=False)
def update_work_size(n: int, m: int) -> int:
    """The scratch `update_work` needs for an n-state and an m-measurement: 4 m n + m^2 + m."""
    return 4 * m * n + m * m + m


@njit(cache=True, fastmath=False)
def update_work(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray,
                xn: np.ndarray, Pn: np.ndarray, S: np.ndarray, work: np.ndarray) -> tuple[bool, float, float]:
    """`update_into` with its intermediates in `work` (at least update_work_size(n, m) floats,
    overwritten; nothing is allocated). The intermediates are indexed flat (a reshape in a
    kernel costs more than this 4x4 arithmetic), row-major at these offsets:
    H P (m, n) at 0, W = L^-1 H P (m, n) at mn, K' = L'^-1 W (m, n) at 2 mn, K S (n, m) at
    3 mn, L (m, m, lower triangle; cholesky_into's arithmetic) at 4 mn, w = L^-1 y after it."""
    n = x.shape[0]
    m = y.shape[0]
    mn = m * n
    W, Kt, KS, L = mn, 2 * mn, 3 * mn, 4 * mn
    w = L + m * m
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += H[i, k] * P[k, j]
            work[i * n + j] = s
    for i in range(m):
        for j in range(m):
            s = 0.0
            for k in range(n):
                s += work[i * n + k] * H[j, k]
            S[i, j] = s + R[i, j]
    for i in range(m):
        for j in range(i):
            a = 0.5 * (S[i, j] + S[j, i])
            S[i, j] = a
            S[j, i] = a
    for j in range(m):  # S = L L' (cholesky_into, flat)
        d = S[j, j]
        for k in range(j):
            d -= work[L + j * m + k] * work[L + j * m + k]
        if not d > 0.0:
            return False, 0.0, 0.0
        work[L + j * m + j] = math.sqrt(d)
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s -= work[L + i * m + k] * work[L + j * m + k]
            work[L + i * m + j] = s / work[L + j * m + j]
    for i in range(m):
        lii = work[L + i * m + i]
        for j in range(n):
            s = work[i * n + j]
            for k in range(i):
                s -= work[L + i * m + k] * work[W + k * n + j]
            work[W + i * n + j] = s / lii
        s = y[i]
        for k in range(i):
            s -= work[L + i * m + k] * work[w + k]
        work[w + i] = s / lii
    for i in range(m - 1, -1, -1):
        lii = work[L + i * m + i]
        for j in range(n):
            s = work[W + i * n + j]
            for k in range(i + 1, m):
                s -= work[L + k * m + i] * work[Kt + k * n + j]
            work[Kt + i * n + j] = s / lii
    nis = 0.0
    logdet = 0.0
    for i in range(m):
        nis += work[w + i] * work[w + i]
        logdet += 2.0 * math.log(work[L + i * m + i])
    for i in range(n):
        s = x[i]
        for k in range(m):
            s += work[Kt + k * n + i] * y[k]
        xn[i] = s
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += work[Kt + k * n + i] * S[k, j]
            work[KS + i * m + j] = s
    for i in range(n):
        for j in range(n):
            a_ij = 0.0  # (K H P)[i, j]
            a_ji = 0.0
            ksk = 0.0
            for k in range(m):
                a_ij += work[Kt + k * n + i] * work[k * n + j]
                a_ji += work[Kt + k * n + j] * work[k * n + i]
                ksk += work[KS + i * m + k] * work[Kt + k * n + j]
            Pn[i, j] = P[i, j] - a_ij - a_ji + ksk
    for i in range(n):
        for j in range(i):
            a = 0.5 * (Pn[i, j] + Pn[j, i])
            Pn[i, j] = a
            Pn[j, i] = a
    ll = -0.5 * (nis + logdet + m * math.log(2.0 * math.pi))
    return True, nis, ll
