r"""Unscented Kalman filter with scaled sigma points (Wan and van der Merwe).

lambda = alpha^2 (n + kappa) - n; sigma points x, x +- columns of chol((n + lambda) P);
Wm0 = lambda / (n + lambda), Wc0 = Wm0 + 1 - alpha^2 + beta, Wi = 1 / (2 (n + lambda)).
Predict: X' = f(X), x- = sum Wm X', P- = sum Wc (X' - x-)(X' - x-)' + Q.
Update: Z = h(X), zhat = mean(Z) (angles on the circle), dZ = residual(Z, zhat),
S = sum Wc dZ dZ' + R, Pxz = sum Wc dX dZ', K = Pxz S^-1 (solved with chol(S)),
x+ = x- + K y, P+ = P- - K S K'.
The default alpha = 1, beta = 2, kappa = 0 keeps every weight non-negative (lambda = 0).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState, Update
from fusion.core.kalman import LOG_2PI, FilterBase
from fusion.core.measurement import MeasurementModel
from fusion.core.motion import MotionModel
from fusion.core.timebase import dt_seconds
from fusion.errors import ConfigError, NumericalError


@dataclass(frozen=True, slots=True)
class SigmaPoints:
    """Scaled sigma-point parameters."""

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def weights(self, n: int) -> tuple[float, Array, Array]:
        """(n + lambda, Wm, Wc) for 2n + 1 points."""
        lam = self.alpha**2 * (n + self.kappa) - n
        c = n + lam
        if c <= 0:
            raise ConfigError(f"sigma points need n + lambda > 0, got {c}")
        Wm = np.full(2 * n + 1, 0.5 / c)
        Wc = Wm.copy()
        Wm[0] = lam / c
        Wc[0] = lam / c + 1 - self.alpha**2 + self.beta
        return c, Wm, Wc


def _chol(P: Array, what: str) -> Array:
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        raise NumericalError(f"{what} is not positive definite") from None


class UnscentedKalmanFilter(FilterBase):
    """UKF over any motion and measurement model. `state_residual` and `state_mean` default to
    plain subtraction and the weighted sum; give them for states that hold angles."""

    def __init__(
        self,
        motion: MotionModel,
        *,
        points: SigmaPoints | None = None,
        state_residual: Callable[[Array, Array], Array] | None = None,
        state_mean: Callable[[Array, Array], Array] | None = None,
        check: bool = True,
    ) -> None:
        super().__init__(motion, check=check)
        self.points = points or SigmaPoints()
        self._c, self.Wm, self.Wc = self.points.weights(motion.ndim_state)
        self.state_residual = state_residual or (lambda a, b: a - b)
        self.state_mean = state_mean or (lambda X, w: w @ X)
        # plain subtraction and weighted sums on the state: the equations then stack over many
        # states (fusion.core.ukf_stack)
        self.plain_state = state_residual is None and state_mean is None

    def sigma_points(self, x: Array, P: Array) -> Array:
        """The 2n + 1 sigma points as rows."""
        L = _chol(self._c * P, "P")
        return np.vstack([x, x + L.T, x - L.T])

    def predict(self, state: GaussianState, t_ns: int, *, u: ArrayLike | None = None) -> GaussianState:
        dt = dt_seconds(state.t_ns, t_ns)
        m = self.motion
        X = m.f(self.sigma_points(state.x, state.P), dt)
        x = self.state_mean(X, self.Wm)
        D = self.state_residual(X, x)
        P = (D.T * self.Wc) @ D + m.Q(x, dt)
        x = self._control(x, dt, u)
        self._finite(x)
        return GaussianState(x, 0.5 * (P + P.T), int(t_ns))

    def update(
        self, state: GaussianState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update:
        zv, Rm = self._measurement(z, R, model)
        X = self.sigma_points(state.x, state.P)
        Z = model.h(X)
        zhat = model.mean(Z, self.Wm)
        dZ = model.residual(Z, zhat)
        dX = self.state_residual(X, state.x)
        S = (dZ.T * self.Wc) @ dZ + Rm
        S = 0.5 * (S + S.T)
        Pxz = (dX.T * self.Wc) @ dZ
        L = _chol(S, "innovation covariance S")
        y = model.residual(zv, zhat)
        w = np.linalg.solve(L, y)
        Kt = np.linalg.solve(L.T, np.linalg.solve(L, Pxz.T))
        x = state.x + Kt.T @ y
        P = state.P - Kt.T @ S @ Kt
        nis = float(w @ w)
        ll = -0.5 * (nis + 2.0 * np.log(np.diag(L)).sum() + model.ndim_meas * LOG_2PI)
        return Update(GaussianState(x, 0.5 * (P + P.T), state.t_ns), y, S, nis, float(ll))
