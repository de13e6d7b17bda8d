r"""Compiled single-state filter steps with the measurement model and the input checks inside.

One call per predict and one per update: each numba call costs about as much as the 4x4
arithmetic, and every numpy call on the way (h, its Jacobian, the residual, np.isfinite, a
Cholesky of R) as much again, so the model and the checks run inside the kernel.

Every kernel takes `ws`, a scratch array of at least work_size(n, m) floats that the caller owns
and the kernel overwrites (nothing is allocated inside; intermediates are indexed flat).

predict_fq(x, P, FQ, xn, Pn, ws): FQ = [F(dt); Q(dt)] stacked (2, n, n); x- = F x,
P- = F P F' + Q into xn, Pn (fusion.core.compiled.predict_work). Status OK, NONFINITE (x- is not
finite) or SHAPE (x, P and FQ disagree).

update_model(code, x, P, z, spec, R, xn, Pn, y, S, ws) -> (status, NIS, log-likelihood), with
code = kind << 2 | flags (the model's kernel_kind, CHECK_Z and CHECK_R):
  1. shapes: z (m,), R (m, m), P (n, n), the model's state size and indices must fit, else SHAPE;
  2. with CHECK_Z in flags: every z_i finite, else Z;
  3. with CHECK_R in flags (R given by the caller): R finite, max |R - R'| <= 1e-9 max |R|,
     R_s = (R + R') / 2 with a Cholesky factor, else R (what fusion.core.checks.as_covariance
     accepts); R_s is then used;
  4. h(x) and H = dh/dx for the model `kind` from its parameter vector `spec`;
  5. y = z - h(x) (angles wrapped into (-pi, pi]) into y, then the Joseph-form update of
     fusion.core.compiled.update_work into xn, Pn, S (status S when S is not positive definite).

step_model(code, x, P, FQ, z, spec, R, xn, Pn, y, S, ws): predict_fq into the head of ws, then
update_model from there: one call for predict + update, the same arithmetic in the same order
(so the same bits) as the two calls.

Models (the parameter vectors are built by the models' constructors):
- CARTESIAN, spec = [n, posed, idx_1..idx_m, t_1..t_m, Rot (m x m, row-major)]:
  h(x) = Rot' (x[idx] - t) (x[idx] without a pose), H[j, idx_i] += Rot[i, j].
- RADAR2D, spec = [sx, sy, heading, ix, iy, jvx, jvy, range_rate]: with dx = x_ix - sx,
  dy = x_iy - sy, r = hypot(dx, dy): h = [r, wrap(atan2(dy, dx) - heading), (dx vx + dy vy) / r],
  H the analytic Jacobian of fusion.core.radar.Radar2D.jacobian.
A status other than OK writes nothing the caller may use; the caller then takes its checked
numpy path, which raises the typed error with its message (or computes what it computed before).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.core.compiled import cholesky_into, predict_work, update_work, update_work_size
from fusion.core.measurement import KERNEL_CARTESIAN, KERNEL_RADAR2D

OK, NONFINITE, SHAPE, BAD_Z, BAD_R, S_NOT_PD = 0, 1, 2, 3, 4, 5
CHECK_Z, CHECK_R = 1, 2
_PI = math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True, fastmath=False, error_model="numpy")
def work_size(n: int, m: int) -> int:
    """Floats of scratch `step_model` needs for an n-state and an m-measurement (predict_fq
    needs n^2, update_model the same less n + n^2): x-, P-, F P; H, R_s, its factor, h(x);
    update_work's intermediates."""
    return n + 2 * n * n + m * n + 2 * m * m + m + update_work_size(n, m)


@njit(cache=True, fastmath=False, error_model="numpy")
def predict_fq(x: np.ndarray, P: np.ndarray, FQ: np.ndarray, xn: np.ndarray, Pn: np.ndarray,
               ws: np.ndarray) -> int:
    n = x.shape[0]
    if (P.shape[0] != n or P.shape[1] != n or FQ.shape[1] != n or FQ.shape[2] != n or xn.shape[0] != n
            or Pn.shape[0] != n or ws.shape[0] < n * n):
        return SHAPE
    return OK if predict_work(x, P, FQ[0], FQ[1], xn, Pn, ws) else NONFINITE


@njit(cache=True, fastmath=False, error_model="numpy")
def wrap(a: float) -> float:
    """fusion.core.measurement.wrap_angle_scalar: pi - ((pi - a) mod 2 pi) into (-pi, pi]."""
    r = _PI - np.fmod(_PI - a, _TWO_PI)
    if r > _PI:
        r -= _TWO_PI
    if abs(r) > _PI - 1e-9:  # the edge: numpy's floored mod, then -pi mapped to +pi
        md = np.fmod(_PI - a, _TWO_PI)
        if md < 0.0:
            md += _TWO_PI
        w = _PI - md
        return w + _TWO_PI if w <= -_PI else w
    return r


@njit(cache=True, fastmath=False, error_model="numpy")
def _checked_R(R: np.ndarray, Rs: np.ndarray, L: np.ndarray) -> bool:
    """as_covariance's checks on R, the symmetrised R into Rs (its factor into L); False where
    they refuse it."""
    m = R.shape[0]
    scale = 1e-300
    for i in range(m):
        for j in range(m):
            if not math.isfinite(R[i, j]):
                return False
            scale = max(scale, abs(R[i, j]))
    for i in range(m):
        for j in range(m):
            if abs(R[i, j] - R[j, i]) > 1e-9 * scale:
                return False
            Rs[i, j] = 0.5 * (R[i, j] + R[j, i])
    return cholesky_into(Rs, L)


@njit(cache=True, fastmath=False, error_model="numpy")
def _cartesian(spec: np.ndarray, x: np.ndarray, zhat: np.ndarray, H: np.ndarray) -> bool:
    m, n = zhat.shape[0], x.shape[0]
    if spec.shape[0] != 2 + 2 * m + m * m or int(spec[0]) != n:
        return False
    posed = spec[1] != 0.0
    for i in range(m):
        if not 0 <= int(spec[2 + i]) < n:
            return False
    rot = 2 + 2 * m
    for j in range(m):
        if posed:
            s = 0.0
            for i in range(m):
                s += (x[int(spec[2 + i])] - spec[2 + m + i]) * spec[rot + i * m + j]
                H[j, int(spec[2 + i])] += spec[rot + i * m + j]
            zhat[j] = s
        else:
            zhat[j] = x[int(spec[2 + j])]
            H[j, int(spec[2 + j])] = 1.0
    return True


@njit(cache=True, fastmath=False, error_model="numpy")
def _radar2d(spec: np.ndarray, x: np.ndarray, zhat: np.ndarray, H: np.ndarray) -> bool:
    m, n = zhat.shape[0], x.shape[0]
    rr = spec[7] != 0.0
    if spec.shape[0] != 8 or m != (3 if rr else 2):
        return False
    ix, iy, jvx, jvy = int(spec[3]), int(spec[4]), int(spec[5]), int(spec[6])
    if not (0 <= ix < n and 0 <= iy < n and 0 <= jvx < n and 0 <= jvy < n):
        return False
    dx = x[ix] - spec[0]
    dy = x[iy] - spec[1]
    r = math.hypot(dx, dy)
    zhat[0] = r
    zhat[1] = wrap(math.atan2(dy, dx) - spec[2])
    r2 = dx * dx + dy * dy
    rj = math.sqrt(r2)
    H[0, ix] = dx / rj
    H[0, iy] = dy / rj
    H[1, ix] = -dy / r2
    H[1, iy] = dx / r2
    if rr:
        vx, vy = x[jvx], x[jvy]
        zhat[2] = (dx * vx + dy * vy) / r
        cross = vx * dy - vy * dx
        H[2, ix] = dy * cross / (r2 * rj)
        H[2, iy] = -dx * cross / (r2 * rj)
        H[2, jvx] = dx / rj
        H[2, jvy] = dy / rj
    return True


@njit(cache=True, fastmath=False, error_model="numpy")
def update_model(code: int, x: np.ndarray, P: np.ndarray, z: np.ndarray, spec: np.ndarray, R: np.ndarray,
                 xn: np.ndarray, Pn: np.ndarray, y: np.ndarray, S: np.ndarray,
                 ws: np.ndarray) -> tuple[int, float, float]:
    n, m = x.shape[0], y.shape[0]
    if (z.shape[0] != m or R.shape[0] != m or R.shape[1] != m or P.shape[0] != n or P.shape[1] != n
            or xn.shape[0] != n or Pn.shape[0] != n or S.shape[0] != m
            or ws.shape[0] < work_size(n, m) - n - 2 * n * n):
        return SHAPE, 0.0, 0.0
    flags, kind = code & (CHECK_Z | CHECK_R), code >> 2
    if flags & CHECK_Z:
        for i in range(m):
            if not math.isfinite(z[i]):
                return BAD_Z, 0.0, 0.0
    H = ws[:m * n].reshape((m, n))
    H[:] = 0.0
    Ru = R
    o = m * n
    if flags & CHECK_R:
        Ru = ws[o:o + m * m].reshape((m, m))
        if not _checked_R(R, Ru, ws[o + m * m:o + 2 * m * m].reshape((m, m))):
            return BAD_R, 0.0, 0.0
    o += 2 * m * m
    zhat = ws[o:o + m]
    if kind == KERNEL_CARTESIAN:
        if not _cartesian(spec, x, zhat, H):
            return SHAPE, 0.0, 0.0
        for i in range(m):
            y[i] = z[i] - zhat[i]
    elif kind == KERNEL_RADAR2D:
        if not _radar2d(spec, x, zhat, H):
            return SHAPE, 0.0, 0.0
        for i in range(m):
            y[i] = z[i] - zhat[i]
        y[1] = wrap(y[1])
    else:
        return SHAPE, 0.0, 0.0
    ok, nis, ll = update_work(x, P, y, H, Ru, xn, Pn, S, ws[o + m:])
    return (OK if ok else S_NOT_PD), nis, ll


@njit(cache=True, fastmath=False, error_model="numpy")
def step_model(code: int, x: np.ndarray, P: np.ndarray, FQ: np.ndarray, z: np.ndarray, spec: np.ndarray,
               R: np.ndarray, xn: np.ndarray, Pn: np.ndarray, y: np.ndarray, S: np.ndarray,
               ws: np.ndarray) -> tuple[int, float, float]:
    """predict_fq into ws (x- and P- at its head), then update_model from there; the status is
    NONFINITE when x- is not finite and code has CHECK_Z (a validating filter), else theirs."""
    n, m = x.shape[0], y.shape[0]
    if ws.shape[0] < work_size(n, m):
        return SHAPE, 0.0, 0.0
    xp = ws[:n]
    Pp = ws[n:n + n * n].reshape((n, n))
    status = predict_fq(x, P, FQ, xp, Pp, ws[n + n * n:])
    if status == SHAPE or (status == NONFINITE and code & CHECK_Z):
        return status, 0.0, 0.0
    return update_model(code, xp, Pp, z, spec, R, xn, Pn, y, S, ws[n + n * n:])
