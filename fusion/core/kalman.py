r"""Kalman and extended Kalman filters.

Predict (motion Jacobian F evaluated at the prior state x):
    x- = f(x, dt) (+ B u)            P- = F P F' + Q
Update with z ~ N(h(x), R), H = dh/dx at x-:
    y = z - h(x-) (angles wrapped)   S = H P- H' + R = L L'   (Cholesky; never inverted)
    K = P- H' S^-1  (two triangular solves with L)
    x+ = x- + K y                    P+ = (I - K H) P- (I - K H)' + K R K'   (Joseph form)
    NIS = y' S^-1 y = |L^-1 y|^2     log-likelihood = -(NIS + log det S + m log 2 pi) / 2

`KalmanFilter` and `ExtendedKalmanFilter` step one state with the compiled kernels of
fusion.core.compiled, which evaluate the Joseph form expanded, P - K H P - (K H P)' + K S K'
(algebraically the same as above); the tracker's batched gate loops the same kernels over a
stack (fusion.core.compiled_stack). `predict_arrays` and `update_arrays` are a plain numpy
reference of the equations above, broadcast over leading dimensions, with the product Joseph
form; the tracker does not call them (tests/core/test_kernels.py checks the compiled kernels
against them, bench/core_step.py times them). They agree to rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from fusion.core import compiled as _compiled
from fusion.core.checks import Array, as_covariance, as_vector
from fusion.core.gaussian import GaussianState, Update
from fusion.core.measurement import MeasurementModel
from fusion.core.motion import LinearMotionModel, MotionModel
from fusion.core.timebase import dt_seconds
from fusion.errors import ConfigError, NumericalError, ShapeError

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


class FilterBase:
    """What every single-state filter shares: its motion model, input checks, initial state.

    Stateless: predict and update take a GaussianState and return new objects. With
    check=True (the default) inputs are validated: shapes, finiteness, R positive definite.
    """

    def __init__(self, motion: MotionModel, *, check: bool = True) -> None:
        self.motion = motion
        self.check = check

    @property
    def ndim_state(self) -> int:
        return self.motion.ndim_state

    def initial(self, x: ArrayLike, P: ArrayLike, *, t_ns: int) -> GaussianState:
        """A validated initial state for this filter."""
        st = GaussianState.create(x, P, t_ns=t_ns)
        if st.ndim != self.ndim_state:
            raise ShapeError(f"initial x has {st.ndim} components, the model has {self.ndim_state}")
        return st

    def _measurement(self, z: ArrayLike, R: ArrayLike | None, model: MeasurementModel) -> tuple[Array, Array]:
        """z and R as arrays (R defaults to the model's), validated when check is on."""
        if self.check:
            return as_vector("z", z, model.ndim_meas), (
                model.R if R is None else as_covariance("R", R, model.ndim_meas))
        zv = z if isinstance(z, np.ndarray) else np.asarray(z, dtype=np.float64)
        return zv, model.R if R is None else np.asarray(R, dtype=np.float64)

    def _control(self, x: Array, dt: float, u: ArrayLike | None) -> Array:
        """x + B(dt) u, refused for a model that takes no input."""
        if u is None:
            return x
        B = self.motion.control(dt)
        if B is None:
            raise ConfigError(f"{type(self.motion).__name__} takes no control input")
        return x + B @ as_vector("u", u, B.shape[1])

    def _finite(self, x: Array) -> None:
        if self.check and not np.isfinite(x).all():
            raise NumericalError(f"prediction produced a non-finite state: {x}")


class ExtendedKalmanFilter(FilterBase):
    """EKF over any motion model and any measurement model (exact KF when both are linear)."""

    def predict(self, state: GaussianState, t_ns: int, *, u: ArrayLike | None = None) -> GaussianState:
        """Predict to t_ns (>= state.t_ns); u is the control input if the model takes one."""
        dt = dt_seconds(state.t_ns, t_ns)
        m = self.motion
        F = m.jacobian(state.x, dt)  # at the prior state
        x, P = _compiled.predict_linear(state.x, state.P, F, m.Q(state.x, dt))
        if not m.is_linear:
            x = m.f(state.x, dt)
        x = self._control(x, dt, u)
        self._finite(x)
        return GaussianState(x, P, int(t_ns))

    def update(
        self, state: GaussianState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update:
        """Fold z (taken at state.t_ns) in; R defaults to the model's."""
        zv, Rm = self._measurement(z, R, model)
        x = state.x
        y = model.residual(zv, model.h(x))
        xn, Pn, S, nis, ll = update_single(x, state.P, y, model.jacobian(x), Rm)
        return Update(GaussianState(xn, Pn, state.t_ns), y, S, nis, ll)


class KalmanFilter(ExtendedKalmanFilter):
    """The linear Kalman filter: a linear motion model, linear measurement models only."""

    def __init__(self, motion: LinearMotionModel, *, check: bool = True) -> None:
        if not motion.is_linear:
            raise ConfigError(f"KalmanFilter needs a linear motion model, got {type(motion).__name__}")
        super().__init__(motion, check=check)

    def update(
        self, state: GaussianState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update:
        if not model.is_linear:
            raise ConfigError(
                f"KalmanFilter needs a linear measurement model, got {type(model).__name__}; "
                "use ExtendedKalmanFilter or UnscentedKalmanFilter"
            )
        return super().update(state, z, model, R=R)
