r"""Mode sets for the IMM: motion models that share one state space, and `build_imm`.

An IMM mixes its modes' states, so every mode must use the same state vector. Constant velocity
(CV) and the coordinated turn (CT, fusion.core.motion.CoordinatedTurn) share the CT state
[px, vx, py, vy, omega] through `ConstantVelocityWithTurnRate`:
    px' = px + dt vx,  vx' = vx,  py' = py + dt vy,  vy' = vy,  omega' = omega
    F = blockdiag(F_cv(dt), F_cv(dt), 1) (interleaved as [px, vx, py, vy]),  Q = blockdiag(Q_cv, q_turn^2 dt)
with the white-noise-acceleration Q_cv of ConstantVelocity (density q_accel^2 per axis).

What happens to omega in the CV mode: it is held (omega' = omega, plus the random walk of
density q_turn^2, 0 by default), and it does not act on the position. Why held rather than
decayed to 0: (a) the CV and CT modes then give omega the same dynamics, so mixing never
creates a jump in omega between the modes, and the only difference between them is whether
omega turns the velocity; (b) the IMM mixing already feeds the CV component the turn rate the
CT component estimated from the data (flying straight, that estimate is near 0 anyway); a
decay would add a time constant nobody could tune from data; (c) f(x, 0) = x holds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array
from fusion.core.imm import IMM, Filter
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.motion import ConstantVelocity, CoordinatedTurn, LinearMotionModel, MotionModel
from fusion.core.switching import rates_from_sojourn
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import ConfigError

ModeKind = Literal["cv", "ct"]


class ConstantVelocityWithTurnRate(LinearMotionModel):
    """Constant velocity in the coordinated-turn state [px, vx, py, vy, omega]; omega is held
    and does not act on the motion (see the module docstring)."""

    ndim_state = 5
    position_indices = (0, 2)
    velocity_indices = (1, 3)
    broadcasts = True

    def __init__(self, *, q_accel: float, q_turn: float = 0.0) -> None:
        if not (np.isfinite(q_turn) and q_turn >= 0):
            raise ConfigError(f"q_turn must be finite and >= 0, got {q_turn}")
        self._cv = ConstantVelocity(ndim=2, q=q_accel)
        self.q_accel = self._cv.q
        self.q_turn = float(q_turn)
        self._cache: tuple[float, Array, Array] | None = None
        self._stack_cache: tuple[Array, Array, Array] | None = None

    def _build(self, dt_s: float | Array) -> tuple[Array, Array]:
        dt = np.asarray(dt_s, dtype=np.float64)
        Fcv, Qcv = self._cv.F(dt_s), self._cv.Q_dt(dt_s)
        F = np.zeros(Fcv.shape[:-2] + (5, 5))
        F[..., :4, :4] = Fcv
        F[..., 4, 4] = 1.0
        Q = np.zeros(Qcv.shape[:-2] + (5, 5))
        Q[..., :4, :4] = Qcv
        Q[..., 4, 4] = self.q_turn**2 * dt
        return F, Q

    def _get(self, dt_s: float | Array) -> tuple[Array, Array]:
        """F and Q, kept for the last dt (a float, or a stack: the stacked IMM asks for F and Q
        of the same stack one after the other)."""
        if not isinstance(dt_s, float):
            c = self._stack_cache
            if c is not None and c[0].shape == np.shape(dt_s) and np.array_equal(c[0], dt_s):
                return c[1], c[2]
            F, Q = self._build(dt_s)
            F.flags.writeable = Q.flags.writeable = False  # shared by the callers of this stack
            self._stack_cache = (np.array(dt_s, dtype=np.float64), F, Q)
            return F, Q
        if self._cache is None or self._cache[0] != dt_s:
            self._cache = (dt_s, *self._build(dt_s))
        return self._cache[1], self._cache[2]

    def F(self, dt_s: float | Array) -> Array:
        return self._get(dt_s)[0]

    def Q_dt(self, dt_s: float | Array) -> Array:
        return self._get(dt_s)[1]


@dataclass(frozen=True, slots=True)
class Mode:
    """One IMM mode.

    kind: "cv" constant velocity or "ct" coordinated turn.
    q: white-noise acceleration density per axis (Q_cv = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]]).
    q_turn: turn-rate random-walk density (Q_omega = q_turn^2 dt); used by "ct", and by "cv"
        when the set holds a "ct" mode (the CV mode then lives in the CT state).
    sojourn_s: mean time the target stays in this mode, in seconds (> 0).
    """

    kind: ModeKind
    q: float
    sojourn_s: float
    q_turn: float = 0.0


def mode_motion(mode: Mode, *, ndim: int, turn_state: bool) -> MotionModel:
    """The motion model of one mode; in the CT state [px, vx, py, vy, omega] if turn_state."""
    if mode.kind == "ct":
        if not turn_state:
            raise ConfigError("a coordinated-turn mode needs the turn state (turn_state=True)")
        return CoordinatedTurn(q_accel=mode.q, q_turn=mode.q_turn)
    if mode.kind == "cv":
        if turn_state:
            return ConstantVelocityWithTurnRate(q_accel=mode.q, q_turn=mode.q_turn)
        return ConstantVelocity(ndim=ndim, q=mode.q)
    raise ConfigError(f"unknown mode kind {mode.kind!r}; known: cv, ct")


def build_imm(
    modes: Sequence[Mode],
    *,
    ndim: int = 2,
    filter: Literal["ekf", "ukf"] = "ekf",
    jump: ArrayLike | None = None,
    check: bool = True,
) -> IMM:
    """An IMM of `modes`, switching in continuous time with Lambda = rates_from_sojourn.

    If any mode is "ct" every mode lives in the CT state [px, vx, py, vy, omega] (ndim must be
    2); otherwise in the ConstantVelocity(ndim) state [p1, v1, ...]. `filter` picks the filter
    of every mode (the EKF is the exact KF on linear models); `jump` is the optional matrix of
    where a jump out of each mode lands (default: evenly over the other modes); check=False
    skips the filters' input checks (for callers that validate at intake).
    """
    if len(modes) < 2:
        raise ConfigError(f"an IMM needs at least two modes, got {len(modes)}")
    turn_state = any(m.kind == "ct" for m in modes)
    if turn_state and ndim != 2:
        raise ConfigError(f"a coordinated-turn mode is 2-D; got ndim={ndim}")
    if filter not in ("ekf", "ukf"):
        raise ConfigError(f"unknown filter {filter!r}; known: ekf, ukf")
    filters: list[Filter] = []
    for m in modes:
        motion = mode_motion(m, ndim=ndim, turn_state=turn_state)
        if filter == "ukf":
            filters.append(UnscentedKalmanFilter(motion, check=check))
        else:
            filters.append(ExtendedKalmanFilter(motion, check=check))
    return IMM(filters, rates=rates_from_sojourn([m.sojourn_s for m in modes], jump))
