r"""Scores: RMSE, NEES, and the OSPA / GOSPA distances between sets of points.

OSPA (Schuhmacher et al. 2008), order p, cut-off c, for sets X (m points), Y (n points),
m <= n:  d = ( (min_perm sum_i min(c, |x_i - y_perm(i)|)^p + c^p (n - m)) / n )^(1/p), 0 if both
are empty.
GOSPA (Rahman et al. 2017) with alpha = 2:
d = ( min_assignment sum min(c, |x - y|)^p + c^p / 2 (number unassigned) )^(1/p).
"""

from __future__ import annotations

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


def gospa(X: Array, Y: Array, *, c: float, p: float = 2.0) -> float:
    """GOSPA distance (alpha = 2) between point sets X (m, d) and Y (n, d)."""
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    m, n = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if m == 0 or n == 0:
        return float((c**p / 2.0 * (m + n)) ** (1.0 / p))
    D = _cut_dist(X, Y, c, p)
    # An assigned pair at distance >= c costs as much as leaving both free (c^p / 2 each).
    r, k = linear_sum_assignment(D)
    assigned = D[r, k] < c**p
    cost = D[r, k][assigned].sum() + c**p / 2.0 * (m + n - 2 * int(assigned.sum()))
    return float(cost ** (1.0 / p))


def nees(x_true: Array, x: Array, P: Array) -> Array:
    """(x_true - x)' P^-1 (x_true - x), broadcast over leading dimensions (solved, not inverted)."""
    e = x_true - x
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def rmse(a: Array, b: Array) -> float:
    """sqrt(mean(|a - b|^2)) over all rows, with |.| the Euclidean norm of the last axis."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=-1))))
