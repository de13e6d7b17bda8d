r"""The fused single-state step (fusion.core.compiled_step.step_model) with its constants packed.

A numba call costs about 80 ns per array argument (the dispatcher types each one) on top of a
fixed cost, as much as the 4x4 arithmetic of the step when there are a dozen of them; and inside
the call every view of a scratch array (a slice, a reshape) costs about as much as a 4x4 product.
Here everything that is fixed for one (filter, measurement model, dt) is packed into one float64
array, `blob`, built once (fusion.core.step_plan) and then passed as is, and the kernel indexes
it flat. A step is one call with eight arrays (the state, z, the blob and the four fresh results)
instead of eleven and an integer:

    step_packed(x, P, z, blob, xn, Pn, y, S) -> (status, NIS, log-likelihood)

blob (row-major, flat) = [code, n, m, s | F(dt) (n x n) | Q(dt) (n x n) | spec (s) | R (m x m) | ws]
  code: kind << 2 | flags as in step_model, the flags CHECK_Z (a validating filter) or none: R
  is the model's own, validated when the model was built (CHECK_R is not read here);
  spec: the model's kernel_spec (s floats; layouts in fusion.core.compiled_step);
  ws: scratch of work_size(n, m) floats, overwritten by every call (the blob is only ever used
  inside one call, which holds the GIL): x-, P-, F P, H, h(x-), then update_work's
  intermediates at update_work's offsets (fusion.core.compiled).
xn (n,), Pn (n, n), y (m,), S (m, m): the results x+, P+, y, S, written by the call.

The arithmetic is that of step_model (predict_work, the model's h and H, the residual, then
update_work), written out on flat indices with every sum in the same order, so the results are
the same bits (tests/core/test_packed_step.py) and the statuses the same: NONFINITE (x- not
finite, with CHECK_Z), BAD_Z, S_NOT_PD, and SHAPE when x, P, z, the results or the spec do not
fit the sizes the blob names. A status other than OK leaves nothing the caller may use; the
caller then takes its checked path, which raises the typed error.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.core.compiled_step import BAD_Z, CHECK_Z, NONFINITE, OK, S_NOT_PD, SHAPE, work_size, wrap
from fusion.core.measurement import KERNEL_CARTESIAN, KERNEL_RADAR2D

HEAD = 4  # code, n, m, s


def blob_size(n: int, m: int, s: int) -> int:
    """Floats of a blob for an n-state, an m-measurement and a spec of s floats."""
    return HEAD + 2 * n * n + s + m * m + work_size(n, m)


@njit(cache=True, fastmath=False, error_model="numpy")
def _model(kind: int, sp: int, blob: np.ndarray, n: int, m: int, xp: int, H: int, zh: int) -> bool:
    """h(x-) into blob[zh:zh + m] and H (m x n, zeroed first) into blob[H:], for the model `kind`
    with its spec at blob[sp:] and x- at blob[xp:] (fusion.core.compiled_step._cartesian and
    _radar2d, flat); False where the spec does not fit."""
    for i in range(m * n):
        blob[H + i] = 0.0
    if kind == KERNEL_CARTESIAN:
        if int(blob[3]) != 2 + 2 * m + m * m or int(blob[sp]) != n:
            return False
        for i in range(m):
            if not 0 <= int(blob[sp + 2 + i]) < n:
                return False
        posed = blob[sp + 1] != 0.0
        rot = sp + 2 + 2 * m
        for j in range(m):
            if posed:
                s = 0.0
                for i in range(m):
                    c = int(blob[sp + 2 + i])
                    s += (blob[xp + c] - blob[sp + 2 + m + i]) * blob[rot + i * m + j]
                    blob[H + j * n + c] += blob[rot + i * m + j]
                blob[zh + j] = s
            else:
                c = int(blob[sp + 2 + j])
                blob[zh + j] = blob[xp + c]
                blob[H + j * n + c] = 1.0
        return True
    if kind != KERNEL_RADAR2D:
        return False
    rr = blob[sp + 7] != 0.0
    if int(blob[3]) != 8 or m != (3 if rr else 2):
        return False
    ix, iy, jvx, jvy = int(blob[sp + 3]), int(blob[sp + 4]), int(blob[sp + 5]), int(blob[sp + 6])
    if not (0 <= ix < n and 0 <= iy < n and 0 <= jvx < n and 0 <= jvy < n):
        return False
    dx = blob[xp + ix] - blob[sp]
    dy = blob[xp + iy] - blob[sp + 1]
    r = math.hypot(dx, dy)
    blob[zh] = r
    blob[zh + 1] = wrap(math.atan2(dy, dx) - blob[sp + 2])
    r2 = dx * dx + dy * dy
    rj = math.sqrt(r2)
    blob[H + ix] = dx / rj
    blob[H + iy] = dy / rj
    blob[H + n + ix] = -dy / r2
    blob[H + n + iy] = dx / r2
    if rr:
        vx, vy = blob[xp + jvx], blob[xp + jvy]
        blob[zh + 2] = (dx * vx + dy * vy) / r
        cross = vx * dy - vy * dx
        blob[H + 2 * n + ix] = dy * cross / (r2 * rj)
        blob[H + 2 * n + iy] = -dx * cross / (r2 * rj)
        blob[H + 2 * n + jvx] = dx / rj
        blob[H + 2 * n + jvy] = dy / rj
    return True


@njit(cache=True, fastmath=False, error_model="numpy")
def _update(blob: np.ndarray, n: int, m: int, xp: int, Pp: int, H: int, R: int, w0: int,
            y: np.ndarray, xn: np.ndarray, Pn: np.ndarray, S: np.ndarray) -> tuple[bool, float, float]:
    """fusion.core.compiled.update_work with x- at blob[xp:], P- at blob[Pp:], H at blob[H:],
    R at blob[R:] and its work at blob[w0:] (the same offsets within it), flat."""
    mn = m * n
    W, Kt, KS, L = w0 + mn, w0 + 2 * mn, w0 + 3 * mn, w0 + 4 * mn
    w = L + m * m
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += blob[H + i * n + k] * blob[Pp + k * n + j]
            blob[w0 + i * n + j] = s
    for i in range(m):
        for j in range(m):
            s = 0.0
            for k in range(n):
                s += blob[w0 + i * n + k] * blob[H + j * n + k]
            S[i, j] = s + blob[R + i * m + j]
    for i in range(m):
        for j in range(i):
            a = 0.5 * (S[i, j] + S[j, i])
            S[i, j] = a
            S[j, i] = a
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= blob[L + j * m + k] * blob[L + j * m + k]
        if not d > 0.0:
            return False, 0.0, 0.0
        blob[L + j * m + j] = math.sqrt(d)
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s -= blob[L + i * m + k] * blob[L + j * m + k]
            blob[L + i * m + j] = s / blob[L + j * m + j]
    for i in range(m):
        lii = blob[L + i * m + i]
        for j in range(n):
            s = blob[w0 + i * n + j]
            for k in range(i):
                s -= blob[L + i * m + k] * blob[W + k * n + j]
            blob[W + i * n + j] = s / lii
        s = y[i]
        for k in range(i):
            s -= blob[L + i * m + k] * blob[w + k]
        blob[w + i] = s / lii
    for i in range(m - 1, -1, -1):
        lii = blob[L + i * m + i]
        for j in range(n):
            s = blob[W + i * n + j]
            for k in range(i + 1, m):
                s -= blob[L + k * m + i] * blob[Kt + k * n + j]
            blob[Kt + i * n + j] = s / lii
    nis = 0.0
    logdet = 0.0
    for i in range(m):
        nis += blob[w + i] * blob[w + i]
        logdet += 2.0 * math.log(blob[L + i * m + i])
    for i in range(n):
        s = blob[xp + i]
        for k in range(m):
            s += blob[Kt + k * n + i] * y[k]
        xn[i] = s
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += blob[Kt + k * n + i] * S[k, j]
            blob[KS + i * m + j] = s
    for i in range(n):
        for j in range(n):
            a_ij = 0.0
            a_ji = 0.0
            ksk = 0.0
            for k in range(m):
                a_ij += blob[Kt + k * n + i] * blob[w0 + k * n + j]
                a_ji += blob[Kt + k * n + j] * blob[w0 + k * n + i]
                ksk += blob[KS + i * m + k] * blob[Kt + k * n + j]
            Pn[i, j] = blob[Pp + i * n + j] - a_ij - a_ji + ksk
    for i in range(n):
        for j in range(i):
            a = 0.5 * (Pn[i, j] + Pn[j, i])
            Pn[i, j] = a
            Pn[j, i] = a
    ll = -0.5 * (nis + logdet + m * math.log(2.0 * math.pi))
    return True, nis, ll


@njit(cache=True, fastmath=False, error_model="numpy")
def step_packed(x: np.ndarray, P: np.ndarray, z: np.ndarray, blob: np.ndarray, xn: np.ndarray,
                Pn: np.ndarray, y: np.ndarray, S: np.ndarray) -> tuple[int, float, float]:
    code, n, m, s = int(blob[0]), int(blob[1]), int(blob[2]), int(blob[3])
    nn, mm = n * n, m * m
    F = HEAD
    Q = F + nn
    sp = Q + nn
    R = sp + s
    xp = R + mm  # the scratch: x-, P-, F P, H, h(x-), then update_work's
    Pp = xp + n
    FP = Pp + nn
    H = FP + nn
    zh = H + m * n
    if (x.shape[0] != n or P.shape[0] != n or P.shape[1] != n or z.shape[0] != m or xn.shape[0] != n
            or Pn.shape[0] != n or Pn.shape[1] != n or y.shape[0] != m or S.shape[0] != m or S.shape[1] != m
            or blob.shape[0] < xp + work_size(n, m)):
        return SHAPE, 0.0, 0.0
    finite = True  # predict_work
    for i in range(n):
        t = 0.0
        for k in range(n):
            t += blob[F + i * n + k] * x[k]
        blob[xp + i] = t
        finite = finite and math.isfinite(t)
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += blob[F + i * n + k] * P[k, j]
            blob[FP + i * n + j] = t
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += blob[FP + i * n + k] * blob[F + j * n + k]
            blob[Pp + i * n + j] = t + blob[Q + i * n + j]
    check = code & CHECK_Z
    if not finite and check:
        return NONFINITE, 0.0, 0.0
    if check:
        for i in range(m):
            if not math.isfinite(z[i]):
                return BAD_Z, 0.0, 0.0
    kind = code >> 2
    if not _model(kind, sp, blob, n, m, xp, H, zh):
        return SHAPE, 0.0, 0.0
    for i in range(m):
        y[i] = z[i] - blob[zh + i]
    if kind == KERNEL_RADAR2D:
        y[1] = wrap(y[1])
    ok, nis, ll = _update(blob, n, m, xp, Pp, H, R, zh + m, y, xn, Pn, S)
    return (OK if ok else S_NOT_PD), nis, ll
