"""Typed configuration: frozen msgspec Structs, loaded from TOML with `load_config`.

Every section refuses unknown fields, so a typo names itself: `Object contains unknown field
`rate_hx` - at `$.sensors[0]``. Units are in the names.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from fusion.config_errors import convert, decode_toml

PosFloat = Annotated[float, msgspec.Meta(gt=0.0, le=1e12)]
NonNegFloat = Annotated[float, msgspec.Meta(ge=0.0, le=1e12)]
Coord = Annotated[float, msgspec.Meta(ge=-1e12, le=1e12)]
Angle = Annotated[float, msgspec.Meta(ge=-2 * math.pi, le=2 * math.pi)]
Prob = Annotated[float, msgspec.Meta(gt=0.0, lt=1.0)]


class Section(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Base of every configuration section."""


class SensorConfig(Section):
    """One sensor. kind "cartesian": std_m per axis. kind "radar": range/bearing noise; with
    ndim 3 the radar also reports elevation; range_rate_std_mps is used when a return carries
    a range rate. position_m and heading_rad place the sensor in the world frame."""

    id: str
    kind: Literal["cartesian", "radar"]
    position_m: list[Coord] = []
    heading_rad: Angle = 0.0
    std_m: list[PosFloat] = []
    range_std_m: PosFloat = 1.0
    bearing_std_rad: PosFloat = 0.01
    elevation_std_rad: PosFloat = 0.01
    range_rate_std_mps: PosFloat = 1.0


class MotionConfig(Section):
    """The motion model of every track.

    model: "cv" constant velocity, "ca" constant acceleration, "ct" coordinated turn (2-D),
    "imm_cv" an IMM of two constant-velocity models (q_mps2 and q_high_mps2).
    q_mps2: white-noise acceleration density (jerk density for "ca").
    filter: "ekf" (exact KF on linear models) or "ukf".
    """

    model: Literal["cv", "ca", "ct", "imm_cv"] = "cv"
    ndim: Literal[1, 2, 3] = 2
    q_mps2: NonNegFloat = 1.0
    q_high_mps2: NonNegFloat = 10.0
    q_turn_radps: NonNegFloat = 0.05
    imm_p_stay: Prob = 0.95
    filter: Literal["ekf", "ukf"] = "ekf"


class InitConfig(Section):
    """Single-point initiation: position from the measurement, zero velocity with this spread."""

    velocity_std_mps: PosFloat = 30.0
    acceleration_std_mps2: PosFloat = 5.0
    turn_rate_std_radps: PosFloat = 0.2


class GateConfig(Section):
    """Mahalanobis gate at this chi-square probability; coarse_margin >= 1 widens the
    Cartesian prefilter for nonlinear models."""

    probability: Prob = 0.999
    coarse_margin: Annotated[float, msgspec.Meta(ge=1.0, le=100.0)] = 2.0


class LifecycleConfig(Section):
    """M-of-N confirmation (scans counted over all sensors); deletion of confirmed tracks after
    max_misses scans without a hit, coast_s seconds without an update, or a predicted position
    standard deviation above max_position_std_m."""

    confirm_m: Annotated[int, msgspec.Meta(ge=1)] = 3
    confirm_n: Annotated[int, msgspec.Meta(ge=1)] = 5
    max_misses: Annotated[int, msgspec.Meta(ge=1)] = 10
    coast_s: PosFloat = 3.0
    max_position_std_m: PosFloat = 1000.0
    max_tracks: Annotated[int, msgspec.Meta(ge=1)] = 10_000


class TimeConfig(Section):
    """Out-of-order window: late data within lag_s (and max_lag_scans scans) is replayed
    exactly; older data is refused as too_late. Data more than future_s ahead of the newest
    time seen is refused as future."""

    lag_s: NonNegFloat = 2.0
    max_lag_scans: Annotated[int, msgspec.Meta(ge=1)] = 100_000
    future_s: PosFloat = 10.0


class TrackerConfig(Section):
    """Everything the tracker needs."""

    sensors: list[SensorConfig]
    motion: MotionConfig = MotionConfig()
    init: InitConfig = InitConfig()
    gate: GateConfig = GateConfig()
    lifecycle: LifecycleConfig = LifecycleConfig()
    time: TimeConfig = TimeConfig()

    def __post_init__(self) -> None:
        ids = [s.id for s in self.sensors]
        if len(set(ids)) != len(ids):
            raise ValueError(f"sensor ids must be unique, got {ids}")
        if self.lifecycle.confirm_m > self.lifecycle.confirm_n:
            raise ValueError("confirm_m must not exceed confirm_n")
        d = self.motion.ndim
        if self.motion.model == "ct" and d != 2:
            raise ValueError("the coordinated-turn model is 2-D: set motion.ndim = 2")
        for s in self.sensors:
            if s.kind == "radar" and d == 1:
                raise ValueError(f"sensor {s.id}: a radar needs a 2-D or 3-D state (motion.ndim)")
            if s.position_m and len(s.position_m) != d:
                raise ValueError(f"sensor {s.id}: position_m must have {d} components")
            if s.kind == "cartesian" and len(s.std_m) != d:
                raise ValueError(f"sensor {s.id}: std_m must have {d} components")


def decode_tracker_config(data: bytes | str, *, source: str = "tracker configuration") -> TrackerConfig:
    """TrackerConfig from TOML text; errors name the source, line and field (fusion.config_errors)."""
    return convert(decode_toml(data, source=source), TrackerConfig, source=source, text=data)


def load_tracker_config(path: str | Path) -> TrackerConfig:
    """Read a TrackerConfig from a TOML file."""
    return decode_tracker_config(Path(path).read_bytes(), source=str(path))


class ZenohConfig(Section):
    """How the service joins Zenoh. The default is an embedded peer that listens on loopback
    only, with multicast and gossip scouting off: nothing else is needed on the machine.
    mode "client" connects to `connect` endpoints (a router or another peer)."""

    mode: Literal["peer", "client"] = "peer"
    listen: list[str] = msgspec.field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    connect: list[str] = []


class RecordingConfig(Section):
    """Rerun recordings of every step, rotated by size or duration; names sort by time.
    `stream` also keeps the raw input (every sample with its arrival time) for `fusion replay`."""

    enabled: bool = True
    directory: str = "recordings"
    prefix: str = "fusion"
    rotate_mb: Annotated[float, msgspec.Meta(gt=0.0)] = 512.0
    rotate_s: Annotated[float, msgspec.Meta(gt=0.0)] = 3600.0
    flush_interval_s: Annotated[float, msgspec.Meta(gt=0.0, le=60.0)] = 0.5
    stream: bool = True


class IntakeConfig(Section):
    """The bounded hand-over from Zenoh threads to the tracker thread. When `queue_max` samples
    wait, new ones are refused with reason "overload" (counted), so memory stays bounded and
    Zenoh is never blocked. `batch_max` samples are processed per tracker call."""

    queue_max: Annotated[int, msgspec.Meta(ge=1)] = 200_000
    batch_max: Annotated[int, msgspec.Meta(ge=1)] = 5_000
    max_future_wall_s: PosFloat = 3600.0  # refuse sensor times this far ahead of the wall clock


class ServiceConfig(Section):
    """`fusion serve --config FILE`: everything the service needs."""

    tracker: TrackerConfig
    namespace: str = "demo"
    zenoh: ZenohConfig = ZenohConfig()
    recording: RecordingConfig = RecordingConfig()
    intake: IntakeConfig = IntakeConfig()
    publish_tentative: bool = False
    warnings_per_minute: Annotated[int, msgspec.Meta(ge=1)] = 60


def decode_service_config(data: bytes | str, *, source: str = "service configuration") -> ServiceConfig:
    """ServiceConfig from TOML text; errors name the source, line and field (fusion.config_errors).
    A scenario file (configs/scenarios/*.toml) works too: its [service] table is the service's
    configuration."""
    raw = decode_toml(data, source=source)
    prefix: list[str | int] = []
    if isinstance(raw, dict) and "service" in raw and "tracker" not in raw:
        raw, prefix = raw["service"], ["service"]
    return convert(raw, ServiceConfig, source=source, text=data, prefix=prefix)


def load_service_config(path: str | Path) -> ServiceConfig:
    """Read a ServiceConfig from a TOML file (OSError if it cannot be read)."""
    return decode_service_config(Path(path).read_bytes(), source=str(path))
