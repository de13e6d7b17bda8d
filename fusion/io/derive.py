"""What a recording shows, derived from the tracker's estimates with stacked numpy (no rerun here).

Scoring against truth, for n estimates stacked as X (n, d), P (n, d, d):
- a truth state at the same t_ns is matched to an estimate when it is the nearest true target in
  position and within MATCH_D2 in squared Mahalanobis distance of the position block;
- error e = x - x_true (every component), and its +-2 sigma band 2 sqrt(P_ii);
- NEES over the kinematic components k (position and velocity, which every motion model and the
  truth share): e_k' P_kk^-1 e_k, chi-square with len(k) degrees of freedom for a consistent filter.
  Components such as an IMM turn rate are left out: the truth defines them only as a model-free
  by-product and the models disagree on them.
- 95 % bounds of NIS (m = measurement dimension) and NEES: the two-sided chi-square quantiles
  chi2.ppf(0.025, m), chi2.ppf(0.975, m).
- Kalman gain K = P- H' S^-1 (prior covariance, measurement Jacobian, innovation covariance).
- OSPA / GOSPA (fusion.core.metrics, order 2, cut-off OSPA_C_M) per scan time: the positions of the
  confirmed tracks updated at that time against the truth positions at that time.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from scipy.spatial import cKDTree
from scipy.stats import chi2

from fusion.core.checks import Array
from fusion.core.metrics import ospa_gospa
from fusion.io.truth_table import TruthTable
from fusion.io.view_kernels import ellipse_outline

MATCH_D2 = 100.0
OSPA_C_M = 10.0
_CIRCLE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 33)), np.sin(np.linspace(0, 2 * np.pi, 33))], axis=1)


@cache
def chi2_bounds(dof: int) -> tuple[float, float]:
    """Two-sided 95 % interval of a chi-square variable with `dof` degrees of freedom."""
    return float(chi2.ppf(0.025, dof)), float(chi2.ppf(0.975, dof))


def eig_sym2(cov: Array) -> tuple[Array, Array, Array]:
    """Eigen-decomposition of symmetric 2x2 matrices [[a, b], [b, c]] (..., 2, 2) in closed form
    (numpy's eigh calls LAPACK once per matrix: ~1 us each here): eigenvalues h -+ q with
    h = (a + c) / 2, q = hypot((a - c) / 2, b), the larger's eigenvector (cos phi, sin phi) with
    phi = atan2(2 b, a - c) / 2 and the smaller's (-sin phi, cos phi). Returns (smaller, larger,
    phi), each (...,). b is read as the mean of the off-diagonal pair."""
    a, c = cov[..., 0, 0], cov[..., 1, 1]
    b = 0.5 * (cov[..., 0, 1] + cov[..., 1, 0])
    h, q = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    return h - q, h + q, 0.5 * np.arctan2(2.0 * b, a - c)


def ellipse_points(mean: Array, cov: Array, *, n_sigma: float = 2.0, dims: int = 2, dtype: type = np.float64) -> Array:
    """Points of the n-sigma ellipse of 2-D Gaussians: mean + n L u for u = (cos t, sin t) on the
    unit circle, L L' = cov with L's columns the eigenvectors scaled by the square roots of their
    eigenvalues (negative ones, from rounding, as 0), smaller first (eig_sym2).
    mean (..., 2), cov (..., 2, 2) -> (..., 33, dims): dims = 3 gives world points (z = 0,
    as `world` would make them) without another copy of the points; `dtype` float32 gives the
    float64 points rounded (what a recording stores) without a float64 copy of them all."""
    lo, hi, phi = eig_sym2(np.asarray(cov, dtype=np.float64))
    a = n_sigma * np.sqrt(np.clip(lo, 0.0, None))  # the smaller axis' half length
    b = n_sigma * np.sqrt(np.clip(hi, 0.0, None))
    out = np.zeros((*np.shape(mean)[:-1], len(_CIRCLE), dims), dtype=dtype)
    m = np.ascontiguousarray(np.reshape(mean, (-1, 2)), dtype=np.float64)
    # x = m0 - (a sin) c0 + (b cos) c1 and y = m1 + (a cos) c0 + (b sin) c1, in float64 in that
    # order, stored in `out` (compiled: numpy's ten passes over the n x 33 points were most of it)
    ellipse_outline(m, a.ravel(), b.ravel(), np.cos(phi).ravel(), np.sin(phi).ravel(), _CIRCLE,
                    out.reshape(-1, len(_CIRCLE), dims))
    return out


def world(p: Array) -> Array:
    """Positions (..., 1|2|3) as 3-D world points: 1-D on the x axis, 2-D in the z = 0 plane."""
    p = np.asarray(p, dtype=np.float64)
    if p.shape[-1] == 3:
        return p
    pad = np.zeros((*p.shape[:-1], 3 - p.shape[-1]))
    return np.concatenate([p, pad], axis=-1)


def ellipsoid_axes(cov: Array) -> tuple[Array, Array]:
    """2-sigma half sizes (n, 3) and rotation quaternions (x, y, z, w) (n, 4) of 3-D covariances."""
    w, V = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    V = V.copy()
    flip = np.linalg.det(V) < 0
    V[flip, :, 0] = -V[flip, :, 0]
    return 2.0 * np.sqrt(np.clip(w, 0.0, None)), quaternions(V)


def quaternions(R: Array) -> Array:
    """Quaternions (x, y, z, w) of proper rotation matrices R (n, 3, 3) (Shepperd's method)."""
    R = np.asarray(R)
    q = np.empty((R.shape[0], 4))
    for i, m in enumerate(R):
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            q[i] = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
            continue
        a = int(np.argmax(np.diagonal(m)))
        b, c = (a + 1) % 3, (a + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[a, a] - m[b, b] - m[c, c])
        q[i, a] = 0.25 * s
        q[i, b] = (m[b, a] + m[a, b]) / s
        q[i, c] = (m[c, a] + m[a, c]) / s
        q[i, 3] = (m[c, b] - m[b, c]) / s
    return q


def match_truth(t_ns: Array, X: Array, P: Array, truth: TruthTable, pi: list[int]
                ) -> tuple[Array, Array, list[str]]:
    """(row indices, true states (k, d), target ids) of the estimates matched to a truth target.

    The true targets at each estimate's time, in the order of their ids (the time's block of
    `truth`), are its candidates; the nearest in position is found for every estimate at once
    where a time has at most 16 (the distances to all candidates, padded), by a k-d tree per time
    where it has more; one batched solve gives every squared Mahalanobis distance (in closed form
    for 2-D positions, P's (0, 1) element as the off-diagonal pair)."""
    d = X.shape[1]
    times, inverse = np.unique(t_ns, return_inverse=True)
    start = np.zeros(len(times), dtype=np.int64)
    count = np.zeros(len(times), dtype=np.int64)
    blocks: list[Array] = []
    names: list[str] = []
    n_c = 0
    at = truth.at
    for u, tt in enumerate(times.tolist()):
        T = at(tt)
        if T is None or T.S.shape[1] != d:  # none, or a truth in another layout: nothing to match
            continue
        start[u], count[u] = n_c, len(T.ids)
        n_c += len(T.ids)
        blocks.append(T.S)
        names.extend(T.ids)
    rows = np.flatnonzero(count[inverse] > 0)
    if not rows.size:
        return np.empty(0, dtype=np.int64), np.empty((0, d)), []
    C_all = np.concatenate(blocks)  # every time's candidates, one block (float64)
    Cp = C_all[:, pi]
    u_r, Xp = inverse[rows], X[rows][:, pi]
    best = np.empty(len(rows), dtype=np.int64)
    small = count[u_r] <= 16
    if small.any():  # nearest among at most 16: all distances, padded with +inf
        k = count[u_r[small]]
        j = np.arange(int(k.max()))
        valid = j[None, :] < k[:, None]
        cand = start[u_r[small]][:, None] + np.where(valid, j[None, :], 0)
        D = sum_last(np.square(Xp[small][:, None, :] - Cp[cand]))
        best[small] = cand[np.arange(len(k)), np.argmin(np.where(valid, D, np.inf), axis=1)]
    for u in np.unique(u_r[~small]).tolist():  # nearest true target by a k-d tree: O(k log j)
        at = np.flatnonzero(u_r == u)
        s0 = int(start[u])
        best[at] = s0 + cKDTree(Cp[s0:s0 + count[u]]).query(Xp[at])[1]
    dp = Xp - Cp[best]
    Pp = P[rows][:, pi][:, :, pi]
    if len(pi) == 2:  # dp' Pp^-1 dp in closed form (a batched solve is a LAPACK call per row)
        a, b, c = Pp[:, 0, 0], Pp[:, 0, 1], Pp[:, 1, 1]
        x, y = dp[:, 0], dp[:, 1]
        d2 = (c * x * x - 2.0 * b * x * y + a * y * y) / (a * c - b * b)
    else:
        d2 = np.einsum("ij,ij->i", dp, np.linalg.solve(Pp, dp[..., None])[..., 0])
    ok = d2 < MATCH_D2
    return rows[ok], C_all[best[ok]], [names[b] for b in best[ok].tolist()]


def sum_last(a: Array) -> Array:
    """np.sum(a, axis=-1), in numpy's order for a last axis of fewer than 8 components (left to
    right; the same bits, checked in tests/io/test_sum_last.py), without its per-row
    reduction loop (~0.2 us a row here); np.sum itself for more."""
    if a.shape[-1] >= 8:
        return np.sum(a, axis=-1)
    out = a[..., 0].copy()
    for i in range(1, a.shape[-1]):
        out += a[..., i]
    return out


def nees(E: Array, P: Array, ki: list[int]) -> Array:
    """e_k' P_kk^-1 e_k per row, over the components ki."""
    e = E[:, ki]
    Pk = P[:, ki][:, :, ki]
    return np.einsum("ij,ij->i", e, np.linalg.solve(Pk, e[..., None])[..., 0])


def set_distances(points: Array, truth_points: Array) -> tuple[float, float]:
    """(OSPA, GOSPA) between estimated and true positions, order 2, cut-off OSPA_C_M metres (one
    assignment for both: fusion.core.metrics.ospa_gospa)."""
    return ospa_gospa(points, truth_points, c=OSPA_C_M)


def set_distance_series(t_ns: Array, track: Array, W: Array, truth: dict[int, Array], scan_t: Array, *,
                        max_points: int) -> tuple[Array, Array]:
    """OSPA and GOSPA (set_distances) at each scan time in `scan_t` that has truth: the positions W
    (k, 3) of the estimates at that time (rows t_ns, track; the last row of a track at a time
    counts, the caller orders them) against truth[t] (j, 3). Times where either set has more than
    `max_points` points are left out (the assignment is cubic). Returns (ospa, gospa) per time."""
    order = np.lexsort((np.arange(t_ns.size), t_ns))
    ts = t_ns[order]
    starts = np.searchsorted(ts, scan_t, side="left")
    ends = np.searchsorted(ts, scan_t, side="right")
    ospa_v: list[float] = []
    gospa_v: list[float] = []
    for t, a, b in zip(scan_t.tolist(), starts.tolist(), ends.tolist(), strict=True):
        T = truth.get(t)
        if T is None:
            continue
        rows = order[a:b]
        last = {int(k): int(i) for k, i in zip(track[rows].tolist(), rows.tolist(), strict=True)}
        pts = W[sorted(last.values())] if last else np.empty((0, 3))
        if len(pts) > max_points or len(T) > max_points:
            continue
        o, g = set_distances(pts, T)
        ospa_v.append(o)
        gospa_v.append(g)
    return np.asarray(ospa_v), np.asarray(gospa_v)
