"""Filters, sensor measurement models and track initiation, built from a TrackerConfig."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.config import (
    CartesianSensorConfig,
    CustomSensorConfig,
    MotionConfig,
    RadarSensorConfig,
    SensorConfig,
    TrackerConfig,
)
from fusion.core.checks import Array
from fusion.core.imm import Filter
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import CartesianPosition, MeasurementModel, Radar2D, Radar3D
from fusion.core.modes import Mode, build_imm, mode_motion
from fusion.core.motion import ConstantAcceleration, ConstantVelocity, CoordinatedTurn, MotionModel
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import ConfigError
from fusion.models.loader import load_model

AXES = ("x", "y", "z")


def _q(psd: float) -> float:
    """The core models take q, the square root of the noise's spectral density."""
    return math.sqrt(psd)


def motion_model(cfg: MotionConfig, *, control: bool = False) -> MotionModel:
    """The motion model of a single-model tracker (the state space of an IMM's modes); with
    `control` the constant-velocity model takes an acceleration input."""
    if cfg.model == "cv":
        return ConstantVelocity(ndim=cfg.ndim, q=_q(cfg.accel_psd_m2s3), with_control=control)
    if cfg.model == "ca":
        assert cfg.jerk_psd_m2s5 is not None  # required for "ca" (TrackerConfig checks)
        return ConstantAcceleration(ndim=cfg.ndim, q=_q(cfg.jerk_psd_m2s5))
    if cfg.model == "ct":
        return CoordinatedTurn(q_accel=_q(cfg.accel_psd_m2s3), q_turn=_q(cfg.turn_psd_rad2s3))
    if cfg.model == "custom":
        model = load_model(cfg.custom, cfg.params)
        if not isinstance(model, MotionModel):
            raise ConfigError(f"motion model {cfg.custom}: a MotionModel is needed (fusion.core.motion), "
                              f"got {type(model).__name__}")
        if len(model.position_indices) != cfg.ndim:
            raise ConfigError(f"motion model {cfg.custom} has a {len(model.position_indices)}-D position; "
                              f"set motion.ndim = {len(model.position_indices)}")
        return model
    modes = imm_modes(cfg)  # an IMM: the first mode's model, in the state space they share
    return mode_motion(modes[0], ndim=cfg.ndim, turn_state=any(m.kind == "ct" for m in modes))


def imm_modes(cfg: MotionConfig) -> list[Mode]:
    return [Mode(kind=m.model, q=_q(m.accel_psd_m2s3), sojourn_s=m.sojourn_s, q_turn=_q(m.turn_psd_rad2s3))
            for m in cfg.modes]


def layout(cfg: MotionConfig, motion: MotionModel) -> tuple[str, ...]:
    """Names of the state components, in order."""
    if cfg.model == "custom":
        names = tuple(cfg.state_names) or tuple(getattr(motion, "state_names", ()))
        n = motion.ndim_state
        if names and len(names) != n:
            raise ConfigError(f"motion.state_names names {len(names)} components; the model has {n}")
        return names or tuple(f"s{i}" for i in range(n))
    if cfg.model == "ct" or (cfg.model == "imm" and any(m.model == "ct" for m in cfg.modes)):
        return ("x", "vx", "y", "vy", "omega")
    per = ("", "v", "a") if cfg.model == "ca" else ("", "v")
    return tuple(p + a for a in AXES[: cfg.ndim] for p in per)


def make_filter(cfg: MotionConfig, m: MotionModel) -> Filter:
    """The track filter over motion model `m` (an IMM builds its modes' own). Inputs are
    validated at intake, so the filters skip their checks."""
    if cfg.model == "imm":
        return build_imm(imm_modes(cfg), ndim=cfg.ndim, filter=cfg.filter, check=False)
    if cfg.filter == "ukf":
        return UnscentedKalmanFilter(m, check=False)
    return ExtendedKalmanFilter(m, check=False)


@dataclass(frozen=True)
class SensorModel:
    """The measurement models of one sensor, by measurement dimension, with the default noise
    (None where the configuration gives none: then every message must carry its own)."""

    config: SensorConfig
    index: int  # position of the sensor among the configured ones, sorted by id
    by_dim: dict[int, MeasurementModel]
    default_R: dict[int, Array | None]
    ndim: int

    @property
    def is_cartesian(self) -> bool:
        return isinstance(self.config, CartesianSensorConfig)

    @property
    def is_radar(self) -> bool:
        return isinstance(self.config, RadarSensorConfig)

    def model(self, m: int) -> MeasurementModel | None:
        return self.by_dim.get(m)

    def covers(self, pos: Array) -> np.ndarray | None:
        """Which positions (N, d) lie in the declared coverage; None without a declared one."""
        c = self.config
        if c.max_range_m is None and not c.region_m:
            return None
        ok = np.ones(pos.shape[0], dtype=bool)
        if c.max_range_m is not None:
            origin = np.asarray(c.position_m or [0.0] * self.ndim)
            ok &= np.sum((pos - origin) ** 2, axis=1) <= c.max_range_m**2
        if c.region_m:
            box = np.asarray(c.region_m).reshape(self.ndim, 2)
            ok &= ((pos >= box[:, 0]) & (pos <= box[:, 1])).all(axis=1)
        return ok

    def positions(self, Z: Array, R: Array) -> tuple[Array, Array]:
        """Measured points (k, d) in world coordinates of measurements Z (k, m) with noise R
        (k, m, m) of one dimension, and a per-axis variance bounding each point's spread:
        Rot R Rot' on the diagonal for a position sensor; for a radar the largest spread,
        R_range + r^2 (R_bearing (+ R_elevation)), on every axis; for a custom model the
        diagonal of its position_cov(z, R), point by point."""
        model = self.by_dim[Z.shape[1]]
        if isinstance(self.config, CustomSensorConfig):  # one by one, the variance from position_cov
            P = np.stack([np.asarray(model.position(z), dtype=np.float64) for z in Z])
            return P, np.stack([np.diagonal(model.position_cov(z, r)) for z, r in zip(Z, R, strict=True)])
        P = model.position(Z)
        if self.is_cartesian:
            Rot = getattr(model, "pose", None)
            C = R if Rot is None else Rot.Rot @ R @ Rot.Rot.T
            return P, np.diagonal(C, axis1=1, axis2=2).copy()
        r2 = Z[:, 0] ** 2
        var = R[:, 0, 0] + r2 * R[:, 1, 1]
        if self.ndim == 3:
            var = var + r2 * R[:, 2, 2]
        return P, np.repeat(var[:, None], self.ndim, axis=1)

    def position_cov(self, z: Array, R: Array) -> Array:
        """Covariance of one measured point in the world frame (for initiation)."""
        return self.by_dim[z.shape[0]].position_cov(z, R)


def _radar_R(s: RadarSensorConfig, ndim: int, range_rate: bool) -> Array | None:
    stds = [s.range_std_m, s.bearing_std_rad] + ([s.elevation_std_rad] if ndim == 3 else [])
    if range_rate:
        stds.append(s.range_rate_std_mps)
    if any(v is None for v in stds):
        return None
    return np.diag(np.square(np.asarray(stds, dtype=np.float64)))


def sensor_models(cfg: TrackerConfig, motion: MotionModel) -> dict[str, SensorModel]:
    d = cfg.motion.ndim
    n = motion.ndim_state
    pos_idx, vel_idx = motion.position_indices, motion.velocity_indices
    out: dict[str, SensorModel] = {}
    for index, s in enumerate(sorted(cfg.sensors, key=lambda s: s.id)):
        by_dim: dict[int, MeasurementModel] = {}
        default: dict[int, Array | None] = {}
        pose = {"heading_rad": s.heading_rad} | ({"pitch_rad": s.pitch_rad, "roll_rad": s.roll_rad} if d == 3 else {})
        if isinstance(s, CustomSensorConfig):
            model = custom_sensor(s, n, d)
            by_dim[model.ndim_meas] = model
            default[model.ndim_meas] = np.asarray(model.R, dtype=np.float64)
        elif isinstance(s, CartesianSensorConfig):
            R = None if s.std_m is None else np.diag(np.square(np.asarray(s.std_m, dtype=np.float64)))
            by_dim[d] = CartesianPosition(ndim_state=n, indices=pos_idx, R=np.eye(d) if R is None else R,
                                          position=s.position_m or None, **pose)
            default[d] = R
        else:
            where = np.asarray(s.position_m or [0.0] * d, dtype=np.float64)
            cls = Radar2D if d == 2 else Radar3D
            for rr in (False, True):
                R = _radar_R(s, d, rr)
                m = d + rr
                by_dim[m] = cls(R=np.eye(m) if R is None else R, position=where, pos_idx=pos_idx[:d],  # type: ignore[arg-type]
                                vel_idx=vel_idx[:d], range_rate=rr, ndim_state=n, **pose)  # type: ignore[arg-type]
                default[m] = R
        out[s.id] = SensorModel(s, index, by_dim, default, d)
    return out


def custom_sensor(s: CustomSensorConfig, n: int, d: int) -> MeasurementModel:
    """A custom sensor's model, loaded and checked (fusion.models.loader), of this state."""
    model = load_model(s.model, s.params)
    where = f"sensor {s.id}: measurement model {s.model}"
    if not isinstance(model, MeasurementModel):
        raise ConfigError(f"{where}: a MeasurementModel is needed (fusion.core.measurement), got "
                          f"{type(model).__name__}")
    if model.ndim_state != n:
        raise ConfigError(f"{where} has ndim_state {model.ndim_state}; the tracker's state has {n} components")
    if model.ndim_meas > 3:
        raise ConfigError(f"{where} has ndim_meas {model.ndim_meas}; the wire carries 1-3 components (pos_m)")
    x = 10.0 * np.random.default_rng(0).standard_normal(n)  # the loader's first check state
    p = np.asarray(model.position(model.h(x)), dtype=np.float64)
    if p.shape != (d,):
        raise ConfigError(f"{where}: position(z) must give a {d}-D world point, got shape {p.shape}")
    return model


def initial_covariance_diag(cfg: TrackerConfig, n: int, motion: MotionModel) -> Array:
    """Prior variances of the unmeasured components (velocity, acceleration, turn rate; or
    init.state_std)."""
    if cfg.init.state_std:
        if len(cfg.init.state_std) != n:
            raise ConfigError(f"init.state_std has {len(cfg.init.state_std)} values; the state has {n}")
        return np.square(np.asarray(cfg.init.state_std, dtype=np.float64))
    named = set(motion.position_indices) | set(motion.velocity_indices)
    if cfg.motion.model == "custom" and len(named) < n:
        raise ConfigError(f"init.state_std is needed: the custom model's components {sorted(set(range(n)) - named)} "
                          "are neither position nor velocity")
    diag = np.zeros(n)
    diag[list(motion.velocity_indices)] = cfg.init.velocity_std_mps**2
    if cfg.motion.model == "ca":
        diag[[i + 1 for i in motion.velocity_indices]] = cfg.init.acceleration_std_mps2**2
    if n == 5 and layout(cfg.motion, motion)[-1] == "omega":
        diag[4] = cfg.init.turn_rate_std_radps**2
    return diag
