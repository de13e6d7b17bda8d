r"""The helix motion models of the reference scenarios, as user-style models loadable by path
(`fusion.models.helix:HelixExact`, `fusion.models.helix:HelixDoc`; see fusion.models.loader).

All accept one state or a stack (..., n) with dt a float or an array of the stack's leading
shape.

HelixLinear, state [x, y, z, vz]: the source document's linear version, linearised about the
known circle: the x-y plane rotates by turn_radps dt, z climbs at vz.
    F = [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]],  Q = q I dt
(at dt = 1 s, exactly the document's F and Q = 0.1 I).

HelixExact, state [x, y, z, omega, vz]: the x-y plane rotates by omega dt exactly, z climbs at vz.
    x' = c x - s y,  y' = s x + c y   (c = cos(omega dt), s = sin(omega dt))
    z' = z + vz dt,  omega' = omega,  vz' = vz
    Q = diag(q_pos, q_pos, q_pos, q_omega, q_vz) dt
HelixDoc, state [x, y, z, w, a]: the source document's model exactly as written, one w used
both as turn rate and climb rate:
    x' = x - w y dt,  y' = y + w x dt,  z' = z + w dt,  w' = w,  a' = a + alpha dt
    Q = diag(q) per step (not scaled by dt, as the document has it)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fusion.core.checks import Array, as_vector
from fusion.core.motion import LinearMotionModel, MotionModel
from fusion.errors import ConfigError


def _nonneg(name: str, v: float) -> float:
    v = float(v)
    if not (np.isfinite(v) and v >= 0):
        raise ConfigError(f"{name} must be finite and >= 0, got {v}")
    return v


def _shape(x: Array, dt: Array) -> tuple[int, ...]:
    return np.broadcast_shapes(x.shape[:-1], dt.shape)


class HelixLinear(LinearMotionModel):
    """[x, y, z, vz]: a known rotation rate in x-y, constant climb rate (see the module docstring)."""

    ndim_state = 4
    position_indices = (0, 1, 2)
    velocity_indices = ()
    broadcasts = True
    state_names = ("x", "y", "z", "vz")

    def __init__(self, *, turn_radps: float = 0.1, q: float = 0.1) -> None:
        self.turn_radps = float(as_vector("turn_radps", [turn_radps], 1)[0])
        self.q = _nonneg("q", q)

    def F(self, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        c, s = np.cos(self.turn_radps * dt), np.sin(self.turn_radps * dt)
        F = np.zeros(dt.shape + (4, 4))
        F[..., 0, 0], F[..., 0, 1], F[..., 1, 0], F[..., 1, 1] = c, -s, s, c
        F[..., 2, 2], F[..., 2, 3], F[..., 3, 3] = 1.0, dt, 1.0
        return F

    def Q_dt(self, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        return self.q * np.eye(4) * dt[..., None, None]


class HelixExact(MotionModel):
    """[x, y, z, omega, vz]: exact rotation by omega dt in x-y, constant climb rate vz."""

    ndim_state = 5
    position_indices = (0, 1, 2)
    velocity_indices = ()
    broadcasts = True

    def __init__(self, *, q_pos: float = 0.1, q_omega: float = 1e-6, q_vz: float = 1e-4) -> None:
        self.q_pos = _nonneg("q_pos", q_pos)
        self.q_omega = _nonneg("q_omega", q_omega)
        self.q_vz = _nonneg("q_vz", q_vz)
        self._Q = np.diag([self.q_pos, self.q_pos, self.q_pos, self.q_omega, self.q_vz])

    def f(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        c, s = np.cos(x[..., 3] * dt), np.sin(x[..., 3] * dt)
        return np.stack([c * x[..., 0] - s * x[..., 1], s * x[..., 0] + c * x[..., 1],
                         x[..., 2] + x[..., 4] * dt, x[..., 3] + 0 * dt, x[..., 4] + 0 * dt], axis=-1)

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        c, s = np.cos(x[..., 3] * dt), np.sin(x[..., 3] * dt)
        J = np.zeros(_shape(x, dt) + (5, 5))
        J[..., 0, 0], J[..., 0, 1], J[..., 0, 3] = c, -s, dt * (-s * x[..., 0] - c * x[..., 1])
        J[..., 1, 0], J[..., 1, 1], J[..., 1, 3] = s, c, dt * (c * x[..., 0] - s * x[..., 1])
        J[..., 2, 2], J[..., 2, 4] = 1.0, dt
        J[..., 3, 3] = J[..., 4, 4] = 1.0
        return J

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        return self._Q * dt[..., None, None]


class HelixDoc(MotionModel):
    """[x, y, z, w, a]: the source document's helix model as written (see the module docstring)."""

    ndim_state = 5
    position_indices = (0, 1, 2)
    velocity_indices = ()
    broadcasts = True

    def __init__(self, *, alpha: float = 0.01, q: Sequence[float] = (0.1, 0.1, 0.1, 0.1, 0.01)) -> None:
        self.alpha = float(as_vector("alpha", [alpha], 1)[0])
        qv = as_vector("q", q, 5)
        if (qv < 0).any():
            raise ConfigError(f"q must be >= 0, got {qv}")
        self._Q = np.diag(qv)

    def f(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        w = x[..., 3]
        return np.stack([x[..., 0] - w * x[..., 1] * dt, x[..., 1] + w * x[..., 0] * dt, x[..., 2] + w * dt,
                         w + 0 * dt, x[..., 4] + self.alpha * dt], axis=-1)

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        w = x[..., 3]
        J = np.zeros(_shape(x, dt) + (5, 5))
        J[..., 0, 0], J[..., 0, 1], J[..., 0, 3] = 1.0, -w * dt, -x[..., 1] * dt
        J[..., 1, 0], J[..., 1, 1], J[..., 1, 3] = w * dt, 1.0, x[..., 0] * dt
        J[..., 2, 2], J[..., 2, 3] = 1.0, dt
        J[..., 3, 3] = J[..., 4, 4] = 1.0
        return J

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        dt = np.asarray(dt_s, dtype=np.float64)
        return np.broadcast_to(self._Q, dt.shape + (5, 5)).copy()
