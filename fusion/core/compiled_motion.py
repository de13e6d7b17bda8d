r"""The coordinated turn's f and Jacobian on a stack of states, as compiled loops (numba).

fusion.core.motion.CoordinatedTurn's formulas (see its docstring), with the transcendental
terms computed by numpy beforehand on the whole stack (sin(omega dt), cos(omega dt),
sin(omega dt / 2), and the powers (omega dt)^3, dt^3, dt^4 where some |omega dt| < 1e-6 needs
the series), so that the numbers equal those of the numpy formulation bit for bit: the loops do
only the arithmetic, in the same order. With wt = omega dt and w_safe = omega (1 where small):
    s/w = s / w_safe,  (1 - c)/w = 2 sin(wt/2)^2 / w_safe   (series: dt (1 - wt^2/6), dt (wt/2 - wt^3/24))
    d(s/w)/dw = (dt c - s/w) / w_safe,  d((1-c)/w)/dw = (dt s - (1-c)/w) / w_safe
                                         (series: -dt^3 w / 3, dt^2/2 - dt^4 w^2 / 8).
"""

from __future__ import annotations

import numpy as np
from numba import njit

SMALL = 1e-6  # |omega dt| below which the series are used


@njit(cache=True, fastmath=False)
def _terms(w: float, dt: float, s: float, sh: float, wt3: float) -> tuple[bool, float, float, float]:
    """(small, s/w, (1-c)/w, w_safe) of one state."""
    wt = w * dt
    small = abs(wt) < SMALL
    ws = 1.0 if small else w
    if small:
        return True, dt * (1 - wt * wt / 6), dt * (wt / 2 - wt3 / 24), ws
    return False, s / ws, 2.0 * (sh * sh) / ws, ws


@njit(cache=True, fastmath=False)
def ct_f_many(x: np.ndarray, dt: np.ndarray, s: np.ndarray, c: np.ndarray, sh: np.ndarray,
              wt3: np.ndarray) -> np.ndarray:
    """f(x_k, dt_k) for x (N, 5); s, c, sh = sin, cos of omega dt and sin of omega dt / 2;
    wt3 = (omega dt)^3 (read where small only)."""
    N = x.shape[0]
    out = np.empty((N, 5))
    for k in range(N):
        px, vx, py, vy, w = x[k, 0], x[k, 1], x[k, 2], x[k, 3], x[k, 4]
        _, sw, cw, _ = _terms(w, dt[k], s[k], sh[k], wt3[k])
        out[k, 0] = px + sw * vx - cw * vy
        out[k, 1] = c[k] * vx - s[k] * vy
        out[k, 2] = py + cw * vx + sw * vy
        out[k, 3] = s[k] * vx + c[k] * vy
        out[k, 4] = w + 0 * dt[k]
    return out


@njit(cache=True, fastmath=False)
def ct_jacobian_many(x: np.ndarray, dt: np.ndarray, s: np.ndarray, c: np.ndarray, sh: np.ndarray,
                     wt3: np.ndarray, dt3: np.ndarray, dt4: np.ndarray) -> np.ndarray:
    """df/dx at x (N, 5); the trigonometric terms as in ct_f_many, dt3 = dt^3, dt4 = dt^4
    (read where small only)."""
    N = x.shape[0]
    J = np.zeros((N, 5, 5))
    for k in range(N):
        vx, vy, w, d = x[k, 1], x[k, 3], x[k, 4], dt[k]
        sk, ck = s[k], c[k]
        small, sw, cw, ws = _terms(w, d, sk, sh[k], wt3[k])
        if small:
            dsw = -dt3[k] * w / 3
            dcw = d * d / 2 - dt4[k] * (w * w) / 8
        else:
            dsw = (d * ck - sw) / ws
            dcw = (d * sk - cw) / ws
        J[k, 0, 0] = 1
        J[k, 0, 1] = sw
        J[k, 0, 3] = -cw
        J[k, 0, 4] = dsw * vx - dcw * vy
        J[k, 1, 1] = ck
        J[k, 1, 3] = -sk
        J[k, 1, 4] = -d * sk * vx - d * ck * vy
        J[k, 2, 1] = cw
        J[k, 2, 2] = 1
        J[k, 2, 3] = sw
        J[k, 2, 4] = dcw * vx + dsw * vy
        J[k, 3, 1] = sk
        J[k, 3, 3] = ck
        J[k, 3, 4] = d * ck * vx - d * sk * vy
        J[k, 4, 4] = 1
    return J
