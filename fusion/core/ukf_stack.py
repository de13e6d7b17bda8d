r"""The UKF's predict and update (fusion.core.ukf) on stacks: N states, or N (state,
measurement) pairs, in one numpy call per operation instead of one filter call each.

The same equations, with k indexing the stack and s the 2n + 1 sigma points:
    X_k = [x_k, x_k +- columns of chol(c P_k)]          (c = n + lambda)
    predict:  X'_k = f(X_k, dt_k),  x-_k = sum_s Wm_s X'_ks,
              P-_k = sum_s Wc_s dX_ks dX_ks' + Q(x-_k, dt_k)   (dX = X' - x-), symmetrised;
    update:   Z_ks = h(X_ks),  zhat_k = sum_s Wm_s Z_ks (angles on the circle),
              S_k = sum_s Wc_s dZ_ks dZ_ks' + R_k (symmetrised),  Pxz_k = sum_s Wc_s dX_ks dZ_ks',
              K_k' = L_k'^-1 L_k^-1 Pxz_k'  (S_k = L_k L_k'),  x+_k = x-_k + K_k y_k,
              P+_k = P-_k - K_k S_k K_k' (symmetrised),  NIS_k = |L_k^-1 y_k|^2.
For a UKF with plain state arithmetic (UnscentedKalmanFilter.plain_state), a motion model that
broadcasts, and a measurement model that broadcasts and keeps MeasurementModel.mean.
The update comes in two halves so that a gate computes the posteriors of the pairs it keeps
only: innovate_ukf (y, S, NIS, likelihood) for every candidate pair, posterior_ukf for the kept.
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.core.kalman import LOG_2PI
from fusion.core.measurement import MeasurementModel
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import NumericalError


def stackable(ukf: UnscentedKalmanFilter) -> bool:
    return ukf.plain_state and ukf.motion.broadcasts


def stackable_measurement(model: MeasurementModel) -> bool:
    return model.broadcasts and type(model).mean is MeasurementModel.mean


def sigma_stack(x: Array, P: Array, c: float) -> Array:
    """(N, 2n + 1, n) sigma points of N states (rows as in UnscentedKalmanFilter.sigma_points)."""
    try:
        L = np.linalg.cholesky(c * P)
    except np.linalg.LinAlgError:
        raise NumericalError("P is not positive definite") from None
    Lt = np.swapaxes(L, -1, -2)
    return np.concatenate([x[:, None, :], x[:, None, :] + Lt, x[:, None, :] - Lt], axis=1)


def _weighted_outer(A: Array, w: Array, B: Array) -> Array:
    """sum_s w_s A_ks B_ks' for A (N, s, a), B (N, s, b)."""
    return np.matmul(np.swapaxes(A, -1, -2) * w, B)


def predict_ukf(ukf: UnscentedKalmanFilter, X: Array, P: Array, dt: Array) -> tuple[Array, Array]:
    """N states predicted by dt (N,) seconds each."""
    c, Wm, Wc = ukf.points.weights(ukf.motion.ndim_state)
    m = ukf.motion
    Y = m.f(sigma_stack(X, P, c), dt[:, None])
    x = np.matmul(Wm, Y)
    D = Y - x[:, None, :]
    Pp = _weighted_outer(D, Wc, D) + m.Q(x, dt)
    return x, 0.5 * (Pp + np.swapaxes(Pp, -1, -2))


def innovate_ukf(ukf: UnscentedKalmanFilter, x: Array, P: Array, Z: Array, R: Array, model: MeasurementModel
                 ) -> tuple[Array, Array, Array, Array, tuple[Array, ...]]:
    """The innovation half of the update of N predicted states with one measurement each
    (Z (N, m), R (N, m, m)): y, S, NIS, log-likelihood, and what posterior_ukf needs (sigma
    offsets dX, dZ, the Cholesky factor L). Raises NumericalError where some S is not positive
    definite."""
    c, Wm, Wc = ukf.points.weights(ukf.motion.ndim_state)
    SX = sigma_stack(x, P, c)
    Zs = model.h(SX)
    zhat = np.matmul(Wm, Zs)
    for i in model.angle_indices:
        zhat[:, i] = np.arctan2(np.matmul(np.sin(Zs[..., i]), Wm), np.matmul(np.cos(Zs[..., i]), Wm))
    dZ = model.residual(Zs, zhat[:, None, :])
    dX = SX - x[:, None, :]
    S = _weighted_outer(dZ, Wc, dZ) + R
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise NumericalError("an innovation covariance S is not positive definite") from None
    y = model.residual(Z, zhat)
    w = np.linalg.solve(L, y[..., None])[..., 0]
    nis = np.einsum("ka,ka->k", w, w)
    ll = -0.5 * (nis + 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1) + model.ndim_meas * LOG_2PI)
    return y, S, nis, ll, (dX, dZ, L)


def posterior_ukf(ukf: UnscentedKalmanFilter, x: Array, P: Array, y: Array, S: Array, inner: tuple[Array, ...]
                  ) -> tuple[Array, Array]:
    """x+, P+ from the innovation half (innovate_ukf) of some pairs: x, P, y, S and `inner` rows
    of the same pairs."""
    _, _, Wc = ukf.points.weights(ukf.motion.ndim_state)
    dX, dZ, L = inner
    Pxz = _weighted_outer(dX, Wc, dZ)
    Lt = np.swapaxes(L, -1, -2)
    Kt = np.linalg.solve(Lt, np.linalg.solve(L, np.swapaxes(Pxz, -1, -2)))
    xn = x + np.matmul(np.swapaxes(Kt, -1, -2), y[..., None])[..., 0]
    Pn = P - np.swapaxes(Kt, -1, -2) @ S @ Kt
    return xn, 0.5 * (Pn + np.swapaxes(Pn, -1, -2))
