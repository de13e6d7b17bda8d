"""Filters, sensor measurement models and track initiation, built from a TrackerConfig."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.config import MotionConfig, SensorConfig, TrackerConfig
from fusion.core.checks import Array
from fusion.core.imm import IMM, Filter
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import CartesianPosition, MeasurementModel, Radar2D, Radar3D
from fusion.core.motion import ConstantAcceleration, ConstantVelocity, CoordinatedTurn, MotionModel
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import ConfigError

AXES = ("x", "y", "z")


def motion_model(cfg: MotionConfig, *, q: float | None = None) -> MotionModel:
    q = cfg.q_mps2 if q is None else q
    if cfg.model in ("cv", "imm_cv"):
        return ConstantVelocity(ndim=cfg.ndim, q=q)
    if cfg.model == "ca":
        return ConstantAcceleration(ndim=cfg.ndim, q=q)
    if cfg.model == "ct":
        return CoordinatedTurn(q_accel=q, q_turn=cfg.q_turn_radps)
    raise ConfigError(f"unknown motion model {cfg.model!r}")


def layout(cfg: MotionConfig) -> tuple[str, ...]:
    """Names of the state components, in order."""
    if cfg.model == "ct":
        return ("x", "vx", "y", "vy", "omega")
    per = ("", "v", "a") if cfg.model == "ca" else ("", "v")
    return tuple(p + a for a in AXES[: cfg.ndim] for p in per)


def make_filter(cfg: MotionConfig) -> Filter:
    """The track filter. Inputs are validated at intake, so the filters skip their checks."""

    def one(m: MotionModel) -> Filter:
        if cfg.filter == "ukf":
            return UnscentedKalmanFilter(m, check=False)
        return ExtendedKalmanFilter(m, check=False)

    if cfg.model == "imm_cv":
        p = cfg.imm_p_stay
        return IMM(
            [one(motion_model(cfg)), one(motion_model(cfg, q=cfg.q_high_mps2))],
            [[p, 1 - p], [1 - p, p]],
        )
    return one(motion_model(cfg))


@dataclass(frozen=True)
class SensorModel:
    """The measurement models of one sensor, by measurement dimension."""

    config: SensorConfig
    by_dim: dict[int, MeasurementModel]
    ndim: int

    def model(self, m: int) -> MeasurementModel | None:
        return self.by_dim.get(m)

    def position_and_var(self, z: Array, R: Array) -> tuple[Array, Array]:
        """The measured point in world coordinates and a per-axis variance bounding its spread."""
        if self.config.kind == "cartesian":
            return z, np.diagonal(R).copy()
        model = self.by_dim[z.shape[0]]
        p = model.position(z)
        r = z[0]
        var = R[0, 0] + r * r * R[1, 1]
        if self.ndim == 3:
            var += r * r * R[2, 2]
        return p, np.full(self.ndim, var)

    def position_cov(self, z: Array, R: Array) -> Array:
        """Covariance of the measured point, J R J' with J = d position / d (range, angles)."""
        if self.config.kind == "cartesian":
            return R
        head = self.config.heading_rad
        r, a = z[0], z[1] + head
        if self.ndim == 2:
            J = np.array([[np.cos(a), -r * np.sin(a)], [np.sin(a), r * np.cos(a)]])
            return J @ R[:2, :2] @ J.T
        e = z[2]
        ca, sa, ce, se = np.cos(a), np.sin(a), np.cos(e), np.sin(e)
        J = np.array(
            [[ce * ca, -r * ce * sa, -r * se * ca], [ce * sa, r * ce * ca, -r * se * sa], [se, 0.0, r * ce]]
        )
        return J @ R[:3, :3] @ J.T


def sensor_models(cfg: TrackerConfig, motion: MotionModel) -> dict[str, SensorModel]:
    d = cfg.motion.ndim
    n = motion.ndim_state
    pos_idx, vel_idx = motion.position_indices, motion.velocity_indices
    out: dict[str, SensorModel] = {}
    for s in cfg.sensors:
        where = np.asarray(s.position_m or [0.0] * d, dtype=np.float64)
        by_dim: dict[int, MeasurementModel] = {}
        if s.kind == "cartesian":
            by_dim[d] = CartesianPosition(ndim_state=n, indices=pos_idx, R=np.square(s.std_m))
        elif d == 2:
            base = [s.range_std_m**2, s.bearing_std_rad**2]
            for rr in (False, True):
                R = base + ([s.range_rate_std_mps**2] if rr else [])
                by_dim[len(R)] = Radar2D(
                    R=R, position=where, heading_rad=s.heading_rad, pos_idx=pos_idx[:2],  # type: ignore[arg-type]
                    vel_idx=vel_idx[:2], range_rate=rr, ndim_state=n,  # type: ignore[arg-type]
                )
        else:
            base = [s.range_std_m**2, s.bearing_std_rad**2, s.elevation_std_rad**2]
            for rr in (False, True):
                R = base + ([s.range_rate_std_mps**2] if rr else [])
                by_dim[len(R)] = Radar3D(
                    R=R, position=where, heading_rad=s.heading_rad, pos_idx=pos_idx,  # type: ignore[arg-type]
                    vel_idx=vel_idx, range_rate=rr, ndim_state=n,  # type: ignore[arg-type]
                )
        out[s.id] = SensorModel(s, by_dim, d)
    return out


def initial_covariance_diag(cfg: TrackerConfig, n: int, motion: MotionModel) -> Array:
    """Prior variances of the unmeasured components (velocity, acceleration, turn rate)."""
    diag = np.zeros(n)
    diag[list(motion.velocity_indices)] = cfg.init.velocity_std_mps**2
    if cfg.motion.model == "ca":
        diag[[i + 1 for i in motion.velocity_indices]] = cfg.init.acceleration_std_mps2**2
    if cfg.motion.model == "ct":
        diag[4] = cfg.init.turn_rate_std_radps**2
    return diag
