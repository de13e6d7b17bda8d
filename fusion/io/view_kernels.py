"""Compiled loops (numba) of a view flush's per-row geometry, where numpy needs a pass over
memory per operation (the 2-sigma ellipse outlines: ten passes over n x 33 points) or Python
needs a step per row (the trail's choice, each row depending on the one drawn before). The
arithmetic is the numpy code's, operation for operation in the same order and without fused
multiply-adds (fastmath off), so the points are the same to the last bit."""

from __future__ import annotations

import functools

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def ellipse_outline(mean: np.ndarray, a: np.ndarray, b: np.ndarray, cos: np.ndarray, sin: np.ndarray,
                    circle: np.ndarray, out: np.ndarray) -> None:
    """out[i, j, :2] = the point of row i's ellipse at circle[j] = (c0, c1):
    x = m0 - (a sin) c0 + (b cos) c1, y = m1 + (a cos) c0 + (b sin) c1, evaluated left to right
    in float64 (a, b: the smaller and larger half axes; phi the larger's angle), then stored in
    out's dtype. out's other components are left as they are."""
    for i in range(mean.shape[0]):
        w00, w01 = a[i] * sin[i], b[i] * cos[i]
        w10, w11 = a[i] * cos[i], b[i] * sin[i]
        m0, m1 = mean[i, 0], mean[i, 1]
        for j in range(circle.shape[0]):
            c0, c1 = circle[j, 0], circle[j, 1]
            x = m0 - w00 * c0
            x = x + w01 * c1
            y = m1 + w10 * c0
            y = y + w11 * c1
            out[i, j, 0] = x
            out[i, j, 1] = y


@njit(cache=True, fastmath=False)
def trail_rows(t_ns: np.ndarray, pos: np.ndarray, r: np.ndarray, has_last: bool, last_t: int, last_pos: np.ndarray,
               last_r: float, spacing: float) -> tuple[np.ndarray, int, np.ndarray, float]:
    """The rows drawn (fusion.io.trail.pick): row i follows the last drawn (t0, p0, r0) when
    t_i > t0 and |p_i - p0| >= spacing (r0 + r_i); the first row is drawn when nothing was.
    Returns (rows, then the last drawn's t, position and radius)."""
    n, k = pos.shape
    out = np.empty(n, dtype=np.int64)
    m = 0
    lt, lp, lr, have = last_t, last_pos.copy(), last_r, has_last
    for i in range(n):
        take = not have
        if have and t_ns[i] > lt:
            s = 0.0
            for c in range(k):
                d = pos[i, c] - lp[c]
                s += d * d
            take = np.sqrt(s) >= spacing * (lr + r[i])
        if take:
            out[m] = i
            m += 1
            lt, lr, have = t_ns[i], r[i], True
            for c in range(k):
                lp[c] = pos[i, c]
    return out[:m], lt, lp, lr


@functools.cache
def warm() -> None:
    """Compile (or load from numba's cache) both kernels on tiny inputs: a recording's first view
    flush comes ~15 s into a file, and a first compile there (seconds, holding the GIL) would
    stall the service's loop. Called when a sink is made; once per process."""
    circle = np.zeros((2, 2))
    for dtype in (np.float32, np.float64):
        ellipse_outline(np.zeros((1, 2)), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), circle,
                        np.zeros((1, 2, 3), dtype=dtype))
    for k in (2, 3):
        trail_rows(np.zeros(1, dtype=np.int64), np.zeros((1, k)), np.zeros(1), False, 0, np.zeros(k), 0.0, 1.0)
