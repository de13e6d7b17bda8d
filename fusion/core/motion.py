"""Motion models: x_k = f(x_{k-1}, dt) + w, w ~ N(0, Q(dt)).

Every model works on one state x (n,) or a stack (..., n), with dt a float or an array of
the stack's leading shape, so that the tracker can predict many tracks in one call.

State layouts (interleaved per axis, so that position i sits at 2*i for constant velocity):
- ConstantVelocity(ndim=d):      [p1, v1, p2, v2, ...]           n = 2d
- ConstantAcceleration(ndim=d):  [p1, v1, a1, p2, v2, a2, ...]   n = 3d
- CoordinatedTurn:               [px, vx, py, vy, omega]         n = 5
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance
from fusion.core.compiled_motion import SMALL, ct_f_many, ct_jacobian_many
from fusion.errors import ConfigError


def _dt_array(dt_s: float | Array) -> Array:
    return np.asarray(dt_s, dtype=np.float64)[..., None, None]


class MotionModel(ABC):
    """f, its Jacobian at the prior state, and the process noise Q."""

    ndim_state: int
    position_indices: tuple[int, ...]
    velocity_indices: tuple[int, ...] = ()
    is_linear: bool = False
    # f, jacobian and Q accept a stack (..., n) with dt of the stack's leading shape: the
    # tracker then predicts and gates many tracks in one call.
    broadcasts: bool = False
    # Q(x, dt) does not read x: a stack's Q can be computed once per distinct dt (the stacked IMM
    # does); a subclass whose Q depends on the state sets it True.
    noise_depends_on_state: bool = True

    @abstractmethod
    def f(self, x: Array, dt_s: float | Array) -> Array:
        """The noise-free transition f(x, dt)."""

    @abstractmethod
    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        """df/dx evaluated at the prior state x (not at f(x))."""

    @abstractmethod
    def Q(self, x: Array, dt_s: float | Array) -> Array:
        """Process-noise covariance for a step of dt_s seconds."""

    def f_and_jacobian(self, x: Array, dt_s: float | Array) -> tuple[Array, Array]:
        """(f(x, dt), df/dx at x) together: the same arrays as the two calls (a model whose two
        share their terms computes them once: CoordinatedTurn)."""
        return self.f(x, dt_s), self.jacobian(x, dt_s)

    def control(self, dt_s: float | Array) -> Array | None:
        """Control-input matrix B(dt) for x' = f(x) + B u, or None if the model takes no input."""
        return None


class LinearMotionModel(MotionModel):
    """x' = F(dt) x (+ B(dt) u) + w. Subclasses define F and Q as functions of dt only."""

    is_linear = True
    noise_depends_on_state = False

    @abstractmethod
    def F(self, dt_s: float | Array) -> Array:
        """Transition matrix F(dt)."""

    @abstractmethod
    def Q_dt(self, dt_s: float | Array) -> Array:
        """Q(dt), independent of the state."""

    def f(self, x: Array, dt_s: float | Array) -> Array:
        return (self.F(dt_s) @ x[..., None])[..., 0]

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        return self.F(dt_s)

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        return self.Q_dt(dt_s)


def _wna_blocks(order: int) -> tuple[Array, list[Array]]:
    """Shift matrix E and the polynomial coefficient matrices of the exact white-noise Q.

    For a chain of `order` integrators driven by white noise of spectral density q^2 on the
    last derivative, F = expm(E dt) and Q = q^2 sum_k C_k dt^k (k = 1 .. 2*order-1).
    """
    E = np.diag(np.ones(order - 1), 1)
    Cs: list[Array] = [np.zeros((order, order)) for _ in range(2 * order)]
    # Q_ij = q^2 dt^(2*order-1-i-j) / ((order-1-i)! (order-1-j)! (2*order-1-i-j))
    from math import factorial

    for i in range(order):
        for j in range(order):
            a, b = order - 1 - i, order - 1 - j
            Cs[a + b + 1][i, j] = 1.0 / (factorial(a) * factorial(b) * (a + b + 1))
    return E, Cs


class _IntegratorChain(LinearMotionModel):
    """d independent axes, each a chain of `order` integrators (CV: 2, CA: 3)."""

    broadcasts = True

    def __init__(self, *, ndim: int, order: int, q: float, with_control: bool = False) -> None:
        if ndim not in (1, 2, 3):
            raise ConfigError(f"ndim must be 1, 2 or 3, got {ndim}")
        if not (np.isfinite(q) and q >= 0):
            raise ConfigError(f"process noise q must be finite and >= 0, got {q}")
        self.ndim = ndim
        self.order = order
        self.q = float(q)
        self.ndim_state = ndim * order
        self.position_indices = tuple(order * i for i in range(ndim))
        self.velocity_indices = tuple(order * i + 1 for i in range(ndim))
        E1, Cs1 = _wna_blocks(order)
        eye = np.eye(ndim)
        self._E = np.kron(eye, E1)
        self._E2 = self._E @ self._E
        self._C = [np.kron(eye, c) * self.q**2 for c in Cs1]
        self._C_used = [(k, C) for k, C in enumerate(self._C) if k >= 1 and C.any()]  # Q's nonzero terms
        self._I = np.eye(self.ndim_state)
        self._with_control = with_control
        self._cache_dt: float | None = None
        self._cache_F: Array = self._I
        self._cache_Q: Array = self._I

    def _fill(self, dt_s: float) -> None:
        self._cache_dt = dt_s
        self._cache_F = self._build_F(dt_s)
        self._cache_Q = self._build_Q(dt_s)

    def _build_F(self, dt_s: float | Array) -> Array:
        dt = _dt_array(dt_s)
        F = self._I + dt * self._E
        if self.order == 3:
            F = F + 0.5 * dt**2 * self._E2
        return F

    def _build_Q(self, dt_s: float | Array) -> Array:
        dt = _dt_array(dt_s)
        Q = np.zeros(dt.shape[:-2] + (self.ndim_state, self.ndim_state))
        for k, C in self._C_used:
            Q = Q + C * dt**k
        return Q

    def F(self, dt_s: float | Array) -> Array:
        if isinstance(dt_s, float):
            if dt_s != self._cache_dt:
                self._fill(dt_s)
            return self._cache_F
        return self._build_F(dt_s)

    def Q_dt(self, dt_s: float | Array) -> Array:
        if isinstance(dt_s, float):
            if dt_s != self._cache_dt:
                self._fill(dt_s)
            return self._cache_Q
        return self._build_Q(dt_s)

    def control(self, dt_s: float | Array) -> Array | None:
        """B(dt): the input drives the last derivative per axis; B_axis = [dt^2/2, dt] for CV."""
        if not self._with_control:
            return None
        dt = float(dt_s)
        col = np.array([dt ** (self.order - i) / _fact(self.order - i) for i in range(self.order)])
        return np.kron(np.eye(self.ndim), col[:, None])


def _fact(k: int) -> float:
    from math import factorial

    return float(factorial(k))


class ConstantVelocity(_IntegratorChain):
    r"""Constant velocity in 1, 2 or 3 dimensions with white-noise acceleration.

    Per axis, state [p, v]:
        F = [[1, dt], [0, 1]]
        Q = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]]
    With with_control=True the input u is an acceleration per axis: B = [[dt^2/2], [dt]].
    """

    def __init__(self, *, ndim: int = 2, q: float, with_control: bool = False) -> None:
        super().__init__(ndim=ndim, order=2, q=q, with_control=with_control)


class ConstantAcceleration(_IntegratorChain):
    r"""Constant acceleration in 1, 2 or 3 dimensions with white-noise jerk.

    Per axis, state [p, v, a]:
        F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]
        Q = q^2 [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]]
    """

    def __init__(self, *, ndim: int = 2, q: float) -> None:
        super().__init__(ndim=ndim, order=3, q=q)


class CoordinatedTurn(MotionModel):
    r"""Nearly coordinated turn in 2-D with the turn rate in the state: [px, vx, py, vy, omega].

    With s = sin(omega dt), c = cos(omega dt):
        px' = px + s/omega vx - (1 - c)/omega vy      vx' = c vx - s vy
        py' = py + (1 - c)/omega vx + s/omega vy      vy' = s vx + c vy
        omega' = omega
    (the omega -> 0 limit is constant velocity). Q is white-noise acceleration of density
    q_accel^2 on each axis (the CV block) and q_turn^2 dt on omega.
    """

    ndim_state = 5
    position_indices = (0, 2)
    velocity_indices = (1, 3)
    broadcasts = True
    noise_depends_on_state = False

    def __init__(self, *, q_accel: float, q_turn: float) -> None:
        if not (q_accel >= 0 and q_turn >= 0 and np.isfinite(q_accel) and np.isfinite(q_turn)):
            raise ConfigError(f"q_accel and q_turn must be finite and >= 0, got {q_accel}, {q_turn}")
        self.q_accel = float(q_accel)
        self.q_turn = float(q_turn)
        self._cv = ConstantVelocity(ndim=2, q=q_accel)

    @staticmethod
    def _terms(w: Array, dt: Array) -> tuple[Array, Array, Array, Array]:
        """s/w, (1-c)/w, c, s with a Taylor series where |omega dt| is tiny."""
        wt = w * dt
        s, c = np.sin(wt), np.cos(wt)
        small = np.abs(wt) < SMALL
        w_safe = np.where(small, 1.0, w)
        sw = np.where(small, dt * (1 - wt**2 / 6), s / w_safe)
        cw = np.where(small, dt * (wt / 2 - wt**3 / 24), 2.0 * np.sin(0.5 * wt) ** 2 / w_safe)
        return sw, cw, c, s

    @staticmethod
    def _stack_terms(x: Array, dt_s: float | Array) -> tuple[Array, ...] | None:
        """For a stack x (N, 5) with dt (N,): (x, dt, sin, cos of omega dt, sin of omega dt / 2,
        (omega dt)^3, dt^3, dt^4), the numpy terms of fusion.core.compiled_motion's loops (the
        powers only where some |omega dt| needs the series); None for other shapes."""
        if not (isinstance(dt_s, np.ndarray) and dt_s.ndim == 1 and x.ndim == 2 and x.shape == (dt_s.shape[0], 5)):
            return None
        x = np.ascontiguousarray(x, dtype=np.float64)
        dt = np.ascontiguousarray(dt_s, dtype=np.float64)
        wt = x[:, 4] * dt
        s, c, sh = np.sin(wt), np.cos(wt), np.sin(0.5 * wt)
        if (np.abs(wt) < SMALL).any():
            return x, dt, s, c, sh, wt**3, dt**3, dt**4
        return x, dt, s, c, sh, wt, dt, dt  # the powers are not read

    def f(self, x: Array, dt_s: float | Array) -> Array:
        st = self._stack_terms(x, dt_s)
        if st is not None:
            return ct_f_many(*st[:6])
        dt = np.asarray(dt_s, dtype=np.float64)
        px, vx, py, vy, w = (x[..., i] for i in range(5))
        sw, cw, c, s = self._terms(w, dt)
        return np.stack(
            [px + sw * vx - cw * vy, c * vx - s * vy, py + cw * vx + sw * vy, s * vx + c * vy, w + 0 * dt],
            axis=-1,
        )

    def f_and_jacobian(self, x: Array, dt_s: float | Array) -> tuple[Array, Array]:
        """f and its Jacobian of a stack from one set of terms (_stack_terms: its sines and cosines
        once, not once per call)."""
        st = self._stack_terms(x, dt_s)
        if st is not None:
            return ct_f_many(*st[:6]), ct_jacobian_many(*st)
        return self.f(x, dt_s), self.jacobian(x, dt_s)

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        st = self._stack_terms(x, dt_s)
        if st is not None:
            return ct_jacobian_many(*st)
        dt = np.asarray(dt_s, dtype=np.float64)
        vx, vy, w = x[..., 1], x[..., 3], x[..., 4]
        sw, cw, c, s = self._terms(w, dt)
        wt = w * dt
        small = np.abs(wt) < SMALL
        w_safe = np.where(small, 1.0, w)
        # d(s/w)/dw and d((1-c)/w)/dw, with their series near omega dt = 0
        dsw = np.where(small, -(dt**3) * w / 3, (dt * c - sw) / w_safe)
        dcw = np.where(small, dt**2 / 2 - dt**4 * w**2 / 8, (dt * s - cw) / w_safe)
        J = np.zeros(np.broadcast(w, dt).shape + (5, 5))
        J[..., 0, 0] = 1
        J[..., 0, 1] = sw
        J[..., 0, 3] = -cw
        J[..., 0, 4] = dsw * vx - dcw * vy
        J[..., 1, 1] = c
        J[..., 1, 3] = -s
        J[..., 1, 4] = -dt * s * vx - dt * c * vy
        J[..., 2, 1] = cw
        J[..., 2, 2] = 1
        J[..., 2, 3] = sw
        J[..., 2, 4] = dcw * vx + dsw * vy
        J[..., 3, 1] = s
        J[..., 3, 3] = c
        J[..., 3, 4] = dt * c * vx - dt * s * vy
        J[..., 4, 4] = 1
        return J

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        Qcv = self._cv.Q_dt(dt_s if isinstance(dt_s, float) else dt)
        Q = np.zeros(dt.shape + (5, 5))
        Q[..., :4, :4] = Qcv
        Q[..., 4, 4] = self.q_turn**2 * dt
        return Q


class LinearModel(LinearMotionModel):
    """A user's linear model: F(dt), Q(dt) and optionally B(dt) given as functions of dt_s.

    Example (cv1d variant B of scenarios.md):
        LinearModel(F=lambda dt: np.array([[1, dt], [0, 1]]), Q=lambda dt: 0.01 * np.eye(2),
                    position_indices=(0,), velocity_indices=(1,))
    """

    def __init__(
        self,
        *,
        F: Callable[[float], ArrayLike],
        Q: Callable[[float], ArrayLike],
        B: Callable[[float], ArrayLike] | None = None,
        position_indices: tuple[int, ...],
        velocity_indices: tuple[int, ...] = (),
    ) -> None:
        F0 = np.asarray(F(1.0), dtype=np.float64)
        if F0.ndim != 2 or F0.shape[0] != F0.shape[1]:
            raise ConfigError(f"F(dt) must return a square matrix, got shape {F0.shape}")
        self.ndim_state = F0.shape[0]
        as_covariance("Q(1.0)", Q(1.0), self.ndim_state, psd=True)
        self._F, self._Q, self._B = F, Q, B
        self.position_indices = position_indices
        self.velocity_indices = velocity_indices

    def F(self, dt_s: float | Array) -> Array:
        return np.asarray(self._F(float(dt_s)), dtype=np.float64)

    def Q_dt(self, dt_s: float | Array) -> Array:
        return np.asarray(self._Q(float(dt_s)), dtype=np.float64)

    def control(self, dt_s: float | Array) -> Array | None:
        return None if self._B is None else np.asarray(self._B(float(dt_s)), dtype=np.float64)


class NonlinearModel(MotionModel):
    """A user's nonlinear model: f(x, dt), its Jacobian df/dx(x, dt) and Q(x, dt).

    The functions receive a single state (n,) and a float dt_s.
    """

    def __init__(
        self,
        *,
        f: Callable[[Array, float], ArrayLike],
        jacobian: Callable[[Array, float], ArrayLike],
        Q: Callable[[Array, float], ArrayLike],
        ndim_state: int,
        position_indices: tuple[int, ...],
        velocity_indices: tuple[int, ...] = (),
    ) -> None:
        self._f, self._J, self._Qf = f, jacobian, Q
        self.ndim_state = ndim_state
        self.position_indices = position_indices
        self.velocity_indices = velocity_indices

    def f(self, x: Array, dt_s: float | Array) -> Array:
        return np.asarray(self._f(x, float(dt_s)), dtype=np.float64)

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        return np.asarray(self._J(x, float(dt_s)), dtype=np.float64)

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        return np.asarray(self._Qf(x, float(dt_s)), dtype=np.float64)
