r"""Scores: RMSE, NEES, and the OSPA / GOSPA distances between sets of points.

OSPA (Schuhmacher et al. 2008), order p, cut-off c, for sets X (m points), Y (n points),
m <= n:  d = ( (min_perm sum_i min(c, |x_i - y_perm(i)|)^p + c^p (n - m)) / n )^(1/p), 0 if both
are empty.
GOSPA (Rahman et al. 2017) with alpha = 2:
d = ( min_assignment sum min(c, |x - y|)^p + c^p / 2 (number unassigned) )^(1/p).
With X the truth and Y the estimates, d^p splits into a localisation part (the assigned pairs'
|x - y|^p, each < c^p), a missed part (c^p / 2 per unassigned x) and a false part (c^p / 2 per
unassigned y): `gospa_parts`.
Both minimise the same sum over the same cut distances (a pair at c^p costs GOSPA as much as
leaving both free), so one assignment gives both: `ospa_gospa`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from fusion.core.checks import Array


def _cut_dist(X: Array, Y: Array, c: float, p: float) -> Array:
    D = np.linalg.norm(X[:, None, :] - Y[None, :, :], axis=-1)
    return np.minimum(D, c) ** p


def ospa(X: Array, Y: Array, *, c: float, p: float = 2.0) -> float:
    """OSPA distance between point sets X (m, d) and Y (n, d)."""
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    m, n = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if m == 0 and n == 0:
        return 0.0
    if m == 0 or n == 0:
        return float(c)
    if m > n:
        X, Y, m, n = Y, X, n, m
    D = _cut_dist(X, Y, c, p)
    r, k = linear_sum_assignment(D)
    return float(((D[r, k].sum() + c**p * (n - m)) / n) ** (1.0 / p))


@dataclass(frozen=True)
class GospaParts:
    """GOSPA (alpha = 2) and its parts: distance = (localisation + missed + false)^(1/p); the
    parts are in units of distance^p; n_missed / n_false count the unassigned truth / estimates."""

    distance: float
    localisation: float
    missed: float
    false: float
    n_missed: int
    n_false: int


def gospa_parts(X: Array, Y: Array, *, c: float, p: float = 2.0) -> GospaParts:
    """GOSPA (alpha = 2) between truth X (m, d) and estimates Y (n, d), with its parts."""
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    m, n = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    loc, n_pairs = 0.0, 0
    if m and n:
        D = _cut_dist(X, Y, c, p)
        # An assigned pair at distance >= c costs as much as leaving both free (c^p / 2 each).
        r, k = linear_sum_assignment(D)
        assigned = D[r, k] < c**p
        loc, n_pairs = float(D[r, k][assigned].sum()), int(assigned.sum())
    half = c**p / 2.0
    n_missed, n_false = m - n_pairs, n - n_pairs
    total = loc + half * (n_missed + n_false)
    return GospaParts(float(total ** (1.0 / p)), loc, half * n_missed, half * n_false, n_missed, n_false)


def gospa(X: Array, Y: Array, *, c: float, p: float = 2.0) -> float:
    """GOSPA distance (alpha = 2) between point sets X (m, d) and Y (n, d)."""
    return gospa_parts(X, Y, c=c, p=p).distance


def ospa_gospa(X: Array, Y: Array, *, c: float, p: float = 2.0) -> tuple[float, float]:
    """(OSPA, GOSPA) between point sets X (m, d) and Y (n, d) from one assignment: the costs a of
    its pairs give OSPA = ((sum a + c^p |n - m|) / max(m, n))^(1/p) and GOSPA = (sum of the a < c^p
    + c^p / 2 (m + n - 2 #{a < c^p}))^(1/p)."""
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    m, n = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if m == 0 or n == 0:
        return (0.0 if m == n else float(c)), float((c**p / 2.0 * (m + n)) ** (1.0 / p))
    D = _cut_dist(X, Y, c, p)
    r, k = linear_sum_assignment(D)
    a = D[r, k]
    kept = a < c**p
    o = ((a.sum() + c**p * abs(n - m)) / max(m, n)) ** (1.0 / p)
    g = (a[kept].sum() + c**p / 2.0 * (m + n - 2 * int(kept.sum()))) ** (1.0 / p)
    return float(o), float(g)


def nees(x_true: Array, x: Array, P: Array) -> Array:
    """(x_true - x)' P^-1 (x_true - x), broadcast over leading dimensions (solved, not inverted)."""
    e = x_true - x
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def rmse(a: Array, b: Array) -> float:
    """sqrt(mean(|a - b|^2)) over all rows, with |.| the Euclidean norm of the last axis."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=-1))))
