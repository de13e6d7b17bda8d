"""Input checks shared by the core: shapes, finiteness, positive definiteness.

They raise typed errors from fusion.errors with a message that names the offending argument.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fusion.errors import NonFiniteError, NotPositiveDefiniteError, ShapeError

Array = NDArray[np.float64]


def as_vector(name: str, v: ArrayLike, n: int | None = None) -> Array:
    """A finite float64 vector of length n (any length if n is None)."""
    a = np.asarray(v, dtype=np.float64)
    if a.ndim != 1:
        if a.ndim == 0:
            a = a.reshape(1)
        else:
            raise ShapeError(f"{name} must be a vector, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ShapeError(f"{name} must have length {n}, got {a.shape[0]}")
    if not np.isfinite(a).all():
        raise NonFiniteError(f"{name} holds NaN or inf: {a}")
    return a


def as_matrix(name: str, m: ArrayLike, rows: int | None = None, cols: int | None = None) -> Array:
    """A finite float64 matrix of the given shape (a scalar is a 1x1 matrix)."""
    a = np.asarray(m, dtype=np.float64)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    if a.ndim != 2:
        raise ShapeError(f"{name} must be a matrix, got shape {a.shape}")
    if (rows is not None and a.shape[0] != rows) or (cols is not None and a.shape[1] != cols):
        raise ShapeError(f"{name} must have shape ({rows}, {cols}), got {a.shape}")
    if not np.isfinite(a).all():
        raise NonFiniteError(f"{name} holds NaN or inf")
    return a


def as_covariance(name: str, m: ArrayLike, n: int | None = None, *, psd: bool = False) -> Array:
    """A finite, symmetric, positive definite n x n matrix (semi-definite if psd=True).

    Symmetry is checked to a relative tolerance of 1e-9 and then enforced exactly.
    """
    a = as_matrix(name, m, n, n)
    if a.shape[0] != a.shape[1]:
        raise ShapeError(f"{name} must be square, got shape {a.shape}")
    scale = max(float(np.max(np.abs(a))), 1e-300)
    if np.max(np.abs(a - a.T)) > 1e-9 * scale:
        raise NotPositiveDefiniteError(f"{name} is not symmetric")
    a = 0.5 * (a + a.T)
    if psd:
        w = np.linalg.eigvalsh(a)
        if w[0] < -1e-12 * scale:
            raise NotPositiveDefiniteError(
                f"{name} is not positive semi-definite (smallest eigenvalue {w[0]:.3g})"
            )
        return a
    try:
        np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        w = np.linalg.eigvalsh(a)
        raise NotPositiveDefiniteError(
            f"{name} is not positive definite (smallest eigenvalue {w[0]:.3g})"
        ) from None
    return a
