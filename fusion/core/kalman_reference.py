r"""The plain numpy reference of the Kalman equations (fusion.core.kalman), and the checked update
of one state on the compiled kernel.

Predict: x- = F x (or f(x)), P- = F P F' + Q, symmetrised. Update given the innovation y:
S = H P H' + R = L L' (Cholesky; never inverted), K' = L'^-1 L^-1 H P (one forward and one back
substitution, row by row), NIS = |L^-1 y|^2, log-likelihood = -(NIS + log det S + m log 2 pi) / 2,
x+ = x + K y, P+ = (I - K H) P (I - K H)' + K R K' (Joseph form, product), symmetrised.
`predict_arrays` and `update_arrays` broadcast over leading dimensions; the tracker does not call
them (tests/core/test_kernels.py checks the compiled kernels against them, bench/core_step.py
times them). `update_single` is the compiled update of fusion.core.compiled for one state, with
the typed error for an S that is not positive definite.
"""

from __future__ import annotations

import math

import numpy as np

from fusion.core import compiled as _compiled
from fusion.core.checks import Array
from fusion.errors import NumericalError

LOG_2PI = math.log(2.0 * math.pi)


def _swap(a: Array) -> Array:
    return np.swapaxes(a, -1, -2)


def predict_arrays(x: Array, P: Array, F: Array, Q: Array, fx: Array | None = None) -> tuple[Array, Array]:
    """x- = F x (or fx, the nonlinear f(x) when given); P- = F P F' + Q, symmetrised."""
    xp = (F @ x[..., None])[..., 0] if fx is None else fx
    Pp = F @ P @ _swap(F) + Q
    return xp, 0.5 * (Pp + _swap(Pp))


def _forward(L: Array, B: Array) -> Array:
    """L^-1 B for lower-triangular L (..., m, m) and B (..., m, k), by forward substitution."""
    X = np.empty_like(B)
    for i in range(L.shape[-1]):
        acc = B[..., i, :]
        if i:
            acc = acc - np.einsum("...k,...kj->...j", L[..., i, :i], X[..., :i, :])
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def _backward(L: Array, B: Array) -> Array:
    """L'^-1 B for lower-triangular L (..., m, m) and B (..., m, k), by back substitution."""
    m = L.shape[-1]
    X = np.empty_like(B)
    for i in range(m - 1, -1, -1):
        acc = B[..., i, :]
        if i < m - 1:
            acc = acc - np.einsum("...k,...kj->...j", L[..., i + 1:, i], X[..., i + 1:, :])
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def update_arrays(
    x: Array, P: Array, y: Array, H: Array, R: Array
) -> tuple[Array, Array, Array, Array, Array]:
    """Joseph-form update given the innovation y; returns x+, P+, S, NIS, log-likelihood.

    Raises NumericalError where S is not positive definite.
    """
    PHt = P @ _swap(H)
    S = H @ PHt + R
    S = 0.5 * (S + _swap(S))
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise NumericalError(
            "innovation covariance S = H P H' + R is not positive definite; "
            "check R and the track covariance P"
        ) from None
    # One forward substitution with L for [H P | y], one back substitution with L' for the gain:
    # K' = L'^-1 L^-1 H P. Row by row (m <= 6 rows), vectorised over the stack: several times
    # cheaper than a stacked general solve on these sizes.
    m = y.shape[-1]
    rhs = np.concatenate([_swap(PHt), y[..., None]], axis=-1)
    W = _forward(L, rhs)
    Kt = _backward(L, W[..., :-1])
    w = W[..., -1]
    nis = np.einsum("...i,...i->...", w, w)
    logdet = 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)
    loglik = -0.5 * (nis + logdet + m * LOG_2PI)
    K = _swap(Kt)
    xn = x + (K @ y[..., None])[..., 0]
    IKH = np.eye(x.shape[-1]) - K @ H
    Pn = IKH @ P @ _swap(IKH) + K @ R @ Kt
    return xn, 0.5 * (Pn + _swap(Pn)), S, nis, loglik


def update_single(x: Array, P: Array, y: Array, H: Array, R: Array) -> tuple[Array, Array, Array, float, float]:
    """`update_arrays` for one state: the compiled kernel (fusion.core.compiled) on float64
    arrays. Raises NumericalError where S is not positive definite."""
    ok, xn, Pn, S, nis, ll = _compiled.update(
        x, P, y, np.ascontiguousarray(H, dtype=np.float64), np.ascontiguousarray(R, dtype=np.float64))
    if not ok:
        raise NumericalError(
            "innovation covariance S = H P H' + R is not positive definite; "
            "check R and the track covariance P"
        )
    return xn, Pn, S, nis, ll
