"""Measurement models: z = h(x) + v, v ~ N(0, R).

Each model works on one state (n,) or a stack (..., n). Angles in z are wrapped into
(-pi, pi] by `residual`, and averaged on the circle by `mean` (used by the UKF).

- CartesianPosition: z = x[indices] (linear; any subset of state components).
- Radar2D: z = [range_m, bearing_rad(, range_rate_mps)] from a sensor at (sx, sy) with
  heading psi:  dx = px - sx, dy = py - sy, range = sqrt(dx^2 + dy^2),
  bearing = wrap(atan2(dy, dx) - psi), range_rate = (dx vx + dy vy) / range.
- Radar3D: z = [range_m, azimuth_rad, elevation_rad(, range_rate_mps)] with
  azimuth = wrap(atan2(dy, dx) - psi), elevation = atan2(dz, sqrt(dx^2 + dy^2)).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance, as_vector
from fusion.errors import ConfigError

TWO_PI = 2.0 * np.pi


def _wrap1(a: float) -> float:
    """wrap_angle for one float: pi - ((pi - a) mod 2 pi), with the same edge at +pi."""
    r = math.pi - math.fmod(math.pi - a, TWO_PI)
    if r > math.pi:  # fmod keeps the sign of its argument; numpy's mod does not
        r -= TWO_PI
    if abs(r) > math.pi - 1e-9:  # at the +-pi edge, exactly what wrap_angle does
        return float(wrap_angle(a))
    return r


def wrap_angle(a: ArrayLike) -> Array:
    """Wrap angles into (-pi, pi]: wrap(a) = pi - ((pi - a) mod 2 pi).

    When pi - a is a tiny negative number the float mod rounds up to exactly 2 pi, giving -pi;
    that one value is mapped to +pi.
    """
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), TWO_PI)
    return np.where(w <= -np.pi, w + TWO_PI, w)


class MeasurementModel(ABC):
    """h, its Jacobian, the default noise R, and angle-aware residual and mean."""

    ndim_meas: int
    R: Array
    is_linear: bool = False
    angle_indices: tuple[int, ...] = ()

    @abstractmethod
    def h(self, x: Array) -> Array:
        """The noise-free measurement of state x."""

    @abstractmethod
    def jacobian(self, x: Array) -> Array:
        """dh/dx at x."""

    def residual(self, z: Array, zhat: Array) -> Array:
        """z - zhat with angle components wrapped into (-pi, pi]."""
        y = z - zhat
        if y.ndim == 1:  # one measurement: plain floats are ~10x cheaper than ufuncs here
            for i in self.angle_indices:
                y[i] = _wrap1(float(y[i]))
            return y
        if self.angle_indices:
            idx = list(self.angle_indices)
            y[..., idx] = wrap_angle(y[..., idx])
        return y

    def mean(self, Z: Array, weights: Array) -> Array:
        """Weighted mean of measurement points Z (k, m); angles averaged on the circle."""
        zbar = weights @ Z
        for i in self.angle_indices:
            zbar[i] = np.arctan2(weights @ np.sin(Z[:, i]), weights @ np.cos(Z[:, i]))
        return zbar

    @abstractmethod
    def position(self, z: Array) -> Array:
        """The measured point in world Cartesian coordinates (for initiation and plots)."""


def _heading(h: float) -> float:
    """A finite sensor heading in radians (NaN would turn every later update into NaN)."""
    return float(as_vector("heading_rad", [h], 1)[0])


def _noise(R: ArrayLike, m: int) -> Array:
    R = np.asarray(R, dtype=np.float64)
    if R.ndim == 1:
        R = np.diag(R)
    return as_covariance("R", R, m)


class CartesianPosition(MeasurementModel):
    """z = H x with H picking the state components `indices`; R is (m, m) or its diagonal."""

    is_linear = True

    def __init__(self, *, ndim_state: int, indices: tuple[int, ...], R: ArrayLike) -> None:
        if not indices or any(not 0 <= i < ndim_state for i in indices):
            raise ConfigError(f"indices {indices} must pick components of a {ndim_state}-state")
        self.ndim_state = ndim_state
        self.indices = tuple(indices)
        self.ndim_meas = len(indices)
        self.H = np.zeros((self.ndim_meas, ndim_state))
        self.H[np.arange(self.ndim_meas), list(indices)] = 1.0
        self.R = _noise(R, self.ndim_meas)
        self._idx = np.array(indices)

    def h(self, x: Array) -> Array:
        return x[self._idx] if x.ndim == 1 else x[..., self._idx]

    def jacobian(self, x: Array) -> Array:
        return self.H if x.ndim == 1 else np.broadcast_to(self.H, x.shape[:-1] + self.H.shape)

    def residual(self, z: Array, zhat: Array) -> Array:
        return z - zhat

    def position(self, z: Array) -> Array:
        return np.asarray(z, dtype=np.float64)


class Radar2D(MeasurementModel):
    """Range and bearing (and optionally range rate) from a sensor at `position` with `heading_rad`.

    pos_idx and vel_idx name the state components of (px, py) and (vx, vy).
    """

    def __init__(
        self,
        *,
        R: ArrayLike,
        position: ArrayLike = (0.0, 0.0),
        heading_rad: float = 0.0,
        pos_idx: tuple[int, int] = (0, 2),
        vel_idx: tuple[int, int] = (1, 3),
        range_rate: bool = False,
        ndim_state: int = 4,
    ) -> None:
        self.sensor = as_vector("position", position, 2)
        self._sx, self._sy = float(self.sensor[0]), float(self.sensor[1])
        self.heading_rad = _heading(heading_rad)
        self.pos_idx, self.vel_idx = tuple(pos_idx), tuple(vel_idx)
        self.range_rate = range_rate
        self.ndim_state = ndim_state
        self.ndim_meas = 3 if range_rate else 2
        self.angle_indices = (1,)
        self.R = _noise(R, self.ndim_meas)

    def h(self, x: Array) -> Array:
        if x.ndim == 1:  # one state: math on floats
            dx = float(x[self.pos_idx[0]]) - self._sx
            dy = float(x[self.pos_idx[1]]) - self._sy
            r = math.hypot(dx, dy)
            out = [r, _wrap1(math.atan2(dy, dx) - self.heading_rad)]
            if self.range_rate:
                out.append((dx * float(x[self.vel_idx[0]]) + dy * float(x[self.vel_idx[1]])) / r)
            return np.array(out)
        dx = x[..., self.pos_idx[0]] - self.sensor[0]
        dy = x[..., self.pos_idx[1]] - self.sensor[1]
        r = np.hypot(dx, dy)
        cols = [r, wrap_angle(np.arctan2(dy, dx) - self.heading_rad)]
        if self.range_rate:
            vx, vy = x[..., self.vel_idx[0]], x[..., self.vel_idx[1]]
            cols.append((dx * vx + dy * vy) / r)
        return np.stack(cols, axis=-1)

    def jacobian(self, x: Array) -> Array:
        ix, iy = self.pos_idx
        dx = x[..., ix] - self.sensor[0]
        dy = x[..., iy] - self.sensor[1]
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        J = np.zeros(x.shape[:-1] + (self.ndim_meas, x.shape[-1]))
        J[..., 0, ix] = dx / r
        J[..., 0, iy] = dy / r
        J[..., 1, ix] = -dy / r2
        J[..., 1, iy] = dx / r2
        if self.range_rate:
            jvx, jvy = self.vel_idx
            vx, vy = x[..., jvx], x[..., jvy]
            cross = vx * dy - vy * dx  # d(rr)/dpx = dy (vx dy - vy dx) / r^3
            J[..., 2, ix] = dy * cross / (r2 * r)
            J[..., 2, iy] = -dx * cross / (r2 * r)
            J[..., 2, jvx] = dx / r
            J[..., 2, jvy] = dy / r
        return J

    def position(self, z: Array) -> Array:
        a = z[..., 1] + self.heading_rad
        return np.stack(
            [self.sensor[0] + z[..., 0] * np.cos(a), self.sensor[1] + z[..., 0] * np.sin(a)], axis=-1
        )


class Radar3D(MeasurementModel):
    """Range, azimuth, elevation (and optionally range rate) from a sensor at `position`.

    pos_idx and vel_idx name the state components of (px, py, pz) and (vx, vy, vz).
    """

    def __init__(
        self,
        *,
        R: ArrayLike,
        position: ArrayLike = (0.0, 0.0, 0.0),
        heading_rad: float = 0.0,
        pos_idx: tuple[int, int, int] = (0, 2, 4),
        vel_idx: tuple[int, int, int] = (1, 3, 5),
        range_rate: bool = False,
        ndim_state: int = 6,
    ) -> None:
        self.sensor = as_vector("position", position, 3)
        self.heading_rad = _heading(heading_rad)
        self.pos_idx, self.vel_idx = tuple(pos_idx), tuple(vel_idx)
        self.range_rate = range_rate
        self.ndim_state = ndim_state
        self.ndim_meas = 4 if range_rate else 3
        self.angle_indices = (1, 2)
        self.R = _noise(R, self.ndim_meas)

    def h(self, x: Array) -> Array:
        d = [x[..., self.pos_idx[i]] - self.sensor[i] for i in range(3)]
        rho = np.hypot(d[0], d[1])
        r = np.sqrt(rho * rho + d[2] * d[2])
        cols = [r, wrap_angle(np.arctan2(d[1], d[0]) - self.heading_rad), np.arctan2(d[2], rho)]
        if self.range_rate:
            v = [x[..., self.vel_idx[i]] for i in range(3)]
            cols.append((d[0] * v[0] + d[1] * v[1] + d[2] * v[2]) / r)
        return np.stack(cols, axis=-1)

    def jacobian(self, x: Array) -> Array:
        ix, iy, iz = self.pos_idx
        dx, dy, dz = (x[..., self.pos_idx[i]] - self.sensor[i] for i in range(3))
        rho2 = dx * dx + dy * dy
        rho = np.sqrt(rho2)
        r2 = rho2 + dz * dz
        r = np.sqrt(r2)
        J = np.zeros(x.shape[:-1] + (self.ndim_meas, x.shape[-1]))
        J[..., 0, ix], J[..., 0, iy], J[..., 0, iz] = dx / r, dy / r, dz / r
        J[..., 1, ix], J[..., 1, iy] = -dy / rho2, dx / rho2
        J[..., 2, ix] = -dx * dz / (r2 * rho)
        J[..., 2, iy] = -dy * dz / (r2 * rho)
        J[..., 2, iz] = rho / r2
        if self.range_rate:
            v = [x[..., self.vel_idx[i]] for i in range(3)]
            d = (dx, dy, dz)
            rr = (dx * v[0] + dy * v[1] + dz * v[2]) / r
            for i, k in enumerate(self.pos_idx):
                J[..., 3, k] = (v[i] - rr * d[i] / r) / r
            for i, k in enumerate(self.vel_idx):
                J[..., 3, k] = d[i] / r
        return J

    def position(self, z: Array) -> Array:
        r, az, el = z[..., 0], z[..., 1] + self.heading_rad, z[..., 2]
        return np.stack(
            [
                self.sensor[0] + r * np.cos(el) * np.cos(az),
                self.sensor[1] + r * np.cos(el) * np.sin(az),
                self.sensor[2] + r * np.sin(el),
            ],
            axis=-1,
        )
