r"""Radar measurement models, in the sensor's frame (pose convention: fusion.core.pose).

With p the target's position, v its velocity, t the sensor's position and Rot its rotation:
    d = p - t (world),   ds = Rot' d (sensor frame),   range = |d|,   range_rate = d'v / |d|
Radar2D (heading psi only): bearing = wrap(atan2(dy, dx) - psi) (= atan2(ds_y, ds_x)).
Radar3D (heading, pitch, roll): azimuth = atan2(ds_y, ds_x), elevation = atan2(ds_z, |ds_xy|).
Jacobians with respect to the world position: J = J_s Rot' (J_s: with respect to ds); the
range and range rate do not depend on the rotation (the sensor is at rest).
position(z) = Rot ps + t with ps = range [cos el cos az, cos el sin az, sin el] (2-D: el = 0),
and position_cov(z, R) = J R J' with J = Rot dps/d(range, angles).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_vector
from fusion.core.measurement import (
    KERNEL_NONE,
    KERNEL_RADAR2D,
    MeasurementModel,
    noise_covariance,
    wrap_angle,
    wrap_angle_scalar,
)
from fusion.core.pose import Pose


class Radar2D(MeasurementModel):
    """Range and bearing (and optionally range rate) from a sensor at `position` with `heading_rad`.

    pos_idx and vel_idx name the state components of (px, py) and (vx, vy).
    """

    broadcasts = True
    kernel_kind = KERNEL_RADAR2D

    def __init_subclass__(cls, **kwargs: object) -> None:
        """A subclass may change h: it takes the generic path unless it sets kernel_kind again."""
        super().__init_subclass__(**kwargs)
        if "kernel_kind" not in cls.__dict__:
            cls.kernel_kind = KERNEL_NONE

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
        self.pose = Pose.create(as_vector("position", position, 2), heading_rad=heading_rad)
        self.sensor = self.pose.t
        self._sx, self._sy = float(self.sensor[0]), float(self.sensor[1])
        self.heading_rad = self.pose.heading_rad
        self.pos_idx, self.vel_idx = tuple(pos_idx), tuple(vel_idx)
        self.range_rate = range_rate
        self.ndim_state = ndim_state
        self.ndim_meas = 3 if range_rate else 2
        self.angle_indices = (1,)
        self.R = noise_covariance(R, self.ndim_meas)
        self.kernel_spec = np.array([self._sx, self._sy, self.heading_rad, *self.pos_idx,
                                     *self.vel_idx, range_rate], dtype=np.float64)
        self.kernel_spec.flags.writeable = False

    def h(self, x: Array) -> Array:
        if x.ndim == 1:  # one state: math on floats
            dx = float(x[self.pos_idx[0]]) - self._sx
            dy = float(x[self.pos_idx[1]]) - self._sy
            r = math.hypot(dx, dy)
            out = [r, wrap_angle_scalar(math.atan2(dy, dx) - self.heading_rad)]
            if self.range_rate:
                out.append((dx * float(x[self.vel_idx[0]]) + dy * float(x[self.vel_idx[1]])) / r)
            return np.array(out)
        dx = x[..., self.pos_idx[0]] - self._sx
        dy = x[..., self.pos_idx[1]] - self._sy
        out = np.empty(dx.shape + (self.ndim_meas,))  # filled column by column (np.stack: ~4 us more)
        r = out[..., 0]
        np.hypot(dx, dy, out=r)
        out[..., 1] = wrap_angle(np.arctan2(dy, dx) - self.heading_rad)
        if self.range_rate:
            vx, vy = x[..., self.vel_idx[0]], x[..., self.vel_idx[1]]
            out[..., 2] = (dx * vx + dy * vy) / r
        return out

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

    def position_cov(self, z: Array, R: Array) -> Array:
        r, a = float(z[0]), float(z[1]) + self.heading_rad
        J = np.array([[math.cos(a), -r * math.sin(a)], [math.sin(a), r * math.cos(a)]])
        C = J @ R[:2, :2] @ J.T
        return 0.5 * (C + C.T)


class Radar3D(MeasurementModel):
    """Range, azimuth, elevation (and optionally range rate) from a sensor at `position`,
    turned by heading_rad, pitch_rad and roll_rad (fusion.core.pose).

    pos_idx and vel_idx name the state components of (px, py, pz) and (vx, vy, vz).
    """

    broadcasts = True

    def __init__(
        self,
        *,
        R: ArrayLike,
        position: ArrayLike = (0.0, 0.0, 0.0),
        heading_rad: float = 0.0,
        pitch_rad: float = 0.0,
        roll_rad: float = 0.0,
        pos_idx: tuple[int, int, int] = (0, 2, 4),
        vel_idx: tuple[int, int, int] = (1, 3, 5),
        range_rate: bool = False,
        ndim_state: int = 6,
    ) -> None:
        self.pose = Pose.create(as_vector("position", position, 3), heading_rad=heading_rad,
                                pitch_rad=pitch_rad, roll_rad=roll_rad)
        self.sensor = self.pose.t
        self.heading_rad = self.pose.heading_rad
        self.pos_idx, self.vel_idx = tuple(pos_idx), tuple(vel_idx)
        self.range_rate = range_rate
        self.ndim_state = ndim_state
        self.ndim_meas = 4 if range_rate else 3
        self.angle_indices = (1, 2)
        self.R = noise_covariance(R, self.ndim_meas)
        self._p, self._v = list(self.pos_idx), list(self.vel_idx)

    def h(self, x: Array) -> Array:
        d = x[..., self._p] - self.sensor
        ds = d @ self.pose.Rot
        rho = np.hypot(ds[..., 0], ds[..., 1])
        r = np.sqrt(rho * rho + ds[..., 2] * ds[..., 2])
        cols = [r, np.arctan2(ds[..., 1], ds[..., 0]), np.arctan2(ds[..., 2], rho)]
        if self.range_rate:
            cols.append(np.einsum("...i,...i->...", d, x[..., self._v]) / r)
        return np.stack(cols, axis=-1)

    def jacobian(self, x: Array) -> Array:
        d = x[..., self._p] - self.sensor
        ds = d @ self.pose.Rot
        dx, dy, dz = ds[..., 0], ds[..., 1], ds[..., 2]
        rho2 = dx * dx + dy * dy
        rho = np.sqrt(rho2)
        r2 = rho2 + dz * dz
        r = np.sqrt(r2)
        Js = np.zeros(x.shape[:-1] + (3, 3))  # d(range, azimuth, elevation) / d ds
        Js[..., 0, 0], Js[..., 0, 1], Js[..., 0, 2] = dx / r, dy / r, dz / r
        Js[..., 1, 0], Js[..., 1, 1] = -dy / rho2, dx / rho2
        Js[..., 2, 0] = -dx * dz / (r2 * rho)
        Js[..., 2, 1] = -dy * dz / (r2 * rho)
        Js[..., 2, 2] = rho / r2
        J = np.zeros(x.shape[:-1] + (self.ndim_meas, x.shape[-1]))
        J[..., :3, self._p] = Js @ self.pose.Rot.T
        if self.range_rate:
            v = x[..., self._v]
            rr = np.einsum("...i,...i->...", d, v) / r
            J[..., 3, self._p] = (v - (rr / r)[..., None] * d) / r[..., None]
            J[..., 3, self._v] = d / r[..., None]
        return J


    def position(self, z: Array) -> Array:
        r, az, el = z[..., 0], z[..., 1], z[..., 2]
        ps = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], axis=-1)
        return self.pose.to_world(ps)

    def position_cov(self, z: Array, R: Array) -> Array:
        r, az, el = float(z[0]), float(z[1]), float(z[2])
        ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
        Js = np.array([[ce * ca, -r * ce * sa, -r * se * ca], [ce * sa, r * ce * ca, -r * se * sa], [se, 0.0, r * ce]])
        J = self.pose.Rot @ Js  # d position / d(range, azimuth, elevation)
        C = J @ R[:3, :3] @ J.T
        return 0.5 * (C + C.T)
