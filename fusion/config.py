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
SensorId = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.\-]{1,64}\Z")]


class Section(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Base of every configuration section."""


class _SensorBase(Section, tag_field="kind"):
    """What every sensor has: an id, a pose in the world frame (position_m; heading_rad about
    the vertical axis, and in 3-D pitch_rad and roll_rad) and an optional coverage. A sensor
    measures in its own frame: world point = Rot z + position_m. A sensor "could have seen" a track when the
    track's predicted position lies in its coverage; without a coverage, when the sensor has
    updated that track before. Only such sensors' scans count as chances (and misses) for a
    track's confirmation and deletion."""

    id: SensorId
    position_m: list[Coord] = []
    heading_rad: Angle = 0.0
    pitch_rad: Angle = 0.0  # 3-D sensors only (fusion.core.pose: Rot = Rz(heading) Ry(pitch) Rx(roll))
    roll_rad: Angle = 0.0
    max_range_m: PosFloat | None = None  # coverage: distance from position_m
    region_m: list[Coord] = []  # coverage: [xmin, xmax, ymin, ymax(, zmin, zmax)] in the world frame


class CartesianSensorConfig(_SensorBase, tag="cartesian"):
    """A position sensor: z is the target's position. std_m (per axis) is the noise used when a
    message carries none."""

    std_m: list[PosFloat] | None = None


class RadarSensorConfig(_SensorBase, tag="radar"):
    """A range-bearing radar (elevation with ndim 3, optional range rate). The standard
    deviations are the noise used when a message carries none."""

    range_std_m: PosFloat | None = None
    bearing_std_rad: PosFloat | None = None
    elevation_std_rad: PosFloat | None = None
    range_rate_std_mps: PosFloat | None = None


class CustomSensorConfig(_SensorBase, tag="custom", kw_only=True):
    """A user's measurement model by import path, "package.module:Name" built as Name(**params)
    and checked at load (shapes, a finite-difference Jacobian check; fusion.models.loader). Its
    h is in the world frame, so the pose goes into its params (position_m, heading_rad, pitch_rad
    and roll_rad are refused); its R is the noise used when a message carries none. Its z comes
    as a `cartesian` message's pos_m (1-3 components, noise std_m or cov_m2 in z's units)."""

    model: str
    params: dict[str, float | int | list[float]] = {}


SensorConfig = CartesianSensorConfig | RadarSensorConfig | CustomSensorConfig


class ModeConfig(Section):
    """One mode of an IMM: a motion model, its noise, and its mean sojourn time (how long the
    target stays in the mode on average; the switching rate out of it is 1 / sojourn_s)."""

    model: Literal["cv", "ct"]
    accel_psd_m2s3: NonNegFloat = 1.0
    turn_psd_rad2s3: NonNegFloat = 1e-4
    sojourn_s: PosFloat = 10.0


ACCEL_PSD_DEFAULT = 1.0


def mode_names(tracker: TrackerConfig) -> list[str]:
    """Names of an IMM's modes, for people ("cv", "ct"; numbered when two share a model, as
    "cv 1", "cv 2"); [] for a tracker that is not an IMM."""
    models = [md.model for md in tracker.motion.modes] if tracker.motion.model == "imm" else []
    return [f"{x} {models[:i].count(x) + 1}" if models.count(x) > 1 else x for i, x in enumerate(models)]


class MotionConfig(Section):
    """The motion model of every track.

    model: "cv" constant velocity, "ca" constant acceleration, "ct" coordinated turn (2-D),
    "imm" an interacting multiple model over `modes`, "custom" a user's model given by import
    path (`custom`, `params`): checked at load (shapes, a finite-difference Jacobian check).
    accel_psd_m2s3: power spectral density of the white acceleration noise of "cv" and "ct"
    (m^2/s^3), q^2 in Q_axis = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]].
    jerk_psd_m2s5: "ca" only, and needed there: the density of its white jerk noise (m^2/s^5),
    q^2 in Q_axis = q^2 [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]].
    turn_psd_rad2s3: density of the white turn-rate noise of "ct" (rad^2/s^3).
    filter: "ekf" (exact KF on linear models) or "ukf".
    """

    model: Literal["cv", "ca", "ct", "imm", "custom"] = "cv"
    ndim: Literal[1, 2, 3] = 2
    accel_psd_m2s3: NonNegFloat = ACCEL_PSD_DEFAULT
    jerk_psd_m2s5: NonNegFloat | None = None
    turn_psd_rad2s3: NonNegFloat = 1e-4
    modes: list[ModeConfig] = []
    filter: Literal["ekf", "ukf"] = "ekf"
    custom: str = ""  # "custom": the model's import path, "package.module:Name" (fusion.models.loader)
    params: dict[str, float | int | list[float]] = {}  # "custom": keyword arguments of Name
    state_names: list[str] = []  # "custom": a name per state component (default: the model's)


class InitConfig(Section):
    """Single-point initiation: position from the measurement, zero for the rest with this
    spread; state_std (one value per state component, the position's ignored) replaces the
    named ones, and is needed for a custom model with components other than position and
    velocity."""

    velocity_std_mps: PosFloat = 30.0
    acceleration_std_mps2: PosFloat = 5.0
    turn_rate_std_radps: PosFloat = 0.2
    state_std: list[PosFloat] = []


class GateConfig(Section):
    """Mahalanobis gate at this chi-square probability; coarse_margin >= 1 widens the
    Cartesian prefilter for nonlinear models."""

    probability: Prob = 0.999
    coarse_margin: Annotated[float, msgspec.Meta(ge=1.0, le=100.0)] = 2.0


class LifecycleConfig(Section):
    """M-of-N confirmation and deletion, counted in chances: scans of a sensor that could have
    seen the track (see the sensors' coverage). A tentative track is confirmed by confirm_m hits
    within its first confirm_n chances and deleted when it misses that. A confirmed track is
    deleted after more than max_misses chances in a row without a hit, after coast_s seconds
    without an update, or when its predicted position standard deviation exceeds
    max_position_std_m."""

    confirm_m: Annotated[int, msgspec.Meta(ge=1)] = 3
    confirm_n: Annotated[int, msgspec.Meta(ge=1)] = 5
    max_misses: Annotated[int, msgspec.Meta(ge=1)] = 10
    coast_s: PosFloat = 3.0
    max_position_std_m: PosFloat = 1000.0
    max_tracks: Annotated[int, msgspec.Meta(ge=1)] = 10_000


class TimeConfig(Section):
    """The out-of-order window, in sensor time.

    Every source (sensor, control source) has a clock robust to a few wrong timestamps: each
    valid measurement i gives an offset t_i - a_i (a_i its arrival time, 0 when unknown) and
    the source's clock is a + the (clock_outliers + 1)-th largest of its last clock_samples
    offsets. The window follows the slowest source still active (delivered within the last
    source_idle_s): data older than that watermark - lag_s are refused as too_late (the
    horizon only moves forward), data more than future_s ahead of their source's clock as
    future (fusion.tracking.clock). Inside the window late data
    is replayed exactly. max_lag_scans caps the history kept for replays (a memory guard:
    when it bites, older scans are committed early and data before them is too_late).
    """

    lag_s: NonNegFloat = 2.0
    future_s: PosFloat = 10.0
    clock_samples: Annotated[int, msgspec.Meta(ge=1, le=1000)] = 16
    clock_outliers: Annotated[int, msgspec.Meta(ge=0, le=100)] = 1
    source_idle_s: PosFloat = 5.0
    max_lag_scans: Annotated[int, msgspec.Meta(ge=1)] = 100_000


class ControlConfig(Section):
    """A known control input applied to every track through the motion model's B (for "cv":
    an acceleration per axis, B_axis = [dt^2/2, dt]). Inputs come from `source_id`, are held
    from their time until the next one, and are ordered and replayed with the measurements."""

    source_id: SensorId


class TrackerConfig(Section):
    """Everything the tracker needs."""

    sensors: list[SensorConfig]
    control: ControlConfig | None = None
    motion: MotionConfig = MotionConfig()
    init: InitConfig = InitConfig()
    gate: GateConfig = GateConfig()
    lifecycle: LifecycleConfig = LifecycleConfig()
    time: TimeConfig = TimeConfig()

    def __post_init__(self) -> None:
        ids = [s.id for s in self.sensors]
        if len(set(ids)) != len(ids):
            raise ValueError(f"sensor ids must be unique, got {ids}")
        if self.time.clock_outliers >= self.time.clock_samples:
            raise ValueError("time.clock_outliers must be smaller than time.clock_samples")
        if self.lifecycle.confirm_m > self.lifecycle.confirm_n:
            raise ValueError("confirm_m must not exceed confirm_n")
        m, d = self.motion, self.motion.ndim
        if (m.model == "ct" or any(x.model == "ct" for x in m.modes)) and d != 2:
            raise ValueError("the coordinated-turn model is 2-D: set motion.ndim = 2")
        if m.model == "ca" and (m.jerk_psd_m2s5 is None or m.accel_psd_m2s3 != ACCEL_PSD_DEFAULT):
            raise ValueError("motion.model = 'ca' takes its noise as motion.jerk_psd_m2s5 (m^2/s^5, the white "
                             "jerk's density), not accel_psd_m2s3 (the acceleration noise of 'cv' and 'ct')")
        if m.model != "ca" and m.jerk_psd_m2s5 is not None:
            raise ValueError(f"motion.jerk_psd_m2s5 is the noise of model 'ca'; model {m.model!r} takes accel_psd_m2s3")
        if m.model == "imm" and len(m.modes) < 2:
            raise ValueError("motion.model = 'imm' needs at least two [[motion.modes]]")
        if m.model != "imm" and m.modes:
            raise ValueError("motion.modes are used only with motion.model = 'imm'")
        if m.model == "custom" and not m.custom:
            raise ValueError("motion.model = 'custom' needs motion.custom = 'package.module:Name'")
        if m.model != "custom" and (m.custom or m.params or m.state_names):
            raise ValueError("motion.custom, params and state_names are used only with motion.model = 'custom'")
        if self.control is not None and m.model != "cv":
            raise ValueError("a control input needs motion.model = 'cv' (its B is the acceleration input)")
        if self.control is not None and self.control.source_id in ids:
            raise ValueError(f"control.source_id {self.control.source_id!r} is also a sensor id")
        for s in self.sensors:
            if isinstance(s, CustomSensorConfig) and (s.position_m or s.heading_rad or s.pitch_rad or s.roll_rad):
                raise ValueError(f"sensor {s.id}: a custom sensor's pose cannot be applied to its model: give it in "
                                 "params (its h is in the world frame)")
            if isinstance(s, RadarSensorConfig) and d == 1:
                raise ValueError(f"sensor {s.id}: a radar needs a 2-D or 3-D state (motion.ndim)")
            if s.position_m and len(s.position_m) != d:
                raise ValueError(f"sensor {s.id}: position_m must have {d} components")
            if d == 1 and s.heading_rad:
                raise ValueError(f"sensor {s.id}: a 1-D sensor has no heading (give position_m only)")
            if d < 3 and (s.pitch_rad or s.roll_rad):
                raise ValueError(f"sensor {s.id}: pitch_rad and roll_rad need a 3-D state (motion.ndim = 3)")
            if s.region_m and len(s.region_m) != 2 * d:
                raise ValueError(f"sensor {s.id}: region_m must have {2 * d} values [min, max per axis]")
            if isinstance(s, CartesianSensorConfig) and s.std_m is not None and len(s.std_m) != d:
                raise ValueError(f"sensor {s.id}: std_m must have {d} components")


def decode_tracker_config(data: bytes | str, *, source: str = "tracker configuration") -> TrackerConfig:
    """TrackerConfig from TOML text; errors name the source, line and field (fusion.config_errors)."""
    return convert(decode_toml(data, source=source), TrackerConfig, source=source, text=data)


def load_tracker_config(path: str | Path) -> TrackerConfig:
    """Read a TrackerConfig from a TOML file."""
    return decode_tracker_config(Path(path).read_bytes(), source=str(path))


Ident = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.\-]{1,64}\Z")]  # a sensor id, as in the keys
CommonName = Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"^\S(?:.*\S)?\Z")]


class TlsConfig(Section):
    """[zenoh.tls]: TLS on every Zenoh link (paths to PEM files, relative to the working directory).

    With this section every listen and connect endpoint must be `tls/HOST:PORT`, and no other
    protocol is accepted. root_ca: the CA that signs the other side's certificate. certificate
    and private_key: this node's own; a listener serves them (required there), a client presents
    them as its identity. require_client_certificate (listeners): mutual TLS, a client without a
    certificate signed by root_ca is refused at connection; access control needs it."""

    root_ca: str
    certificate: str = ""
    private_key: str = ""
    require_client_certificate: bool = False


class AccessControlConfig(Section):
    """[zenoh.access_control]: who may do what on fusion/<namespace>/..., enforced by zenoh on the
    node the others connect to (the service's peer). Identities are TLS client certificate common
    names, so [zenoh.tls] with require_client_certificate is needed; anyone else may do nothing.

    sensors:    sensor id -> the names that may put fusion/NS/meas/<that id> (and nothing else)
    inputs:     control source id -> the names that may put fusion/NS/input/<that id> (and
                nothing else)
    simulators: may put any fusion/NS/meas/*, fusion/NS/input/* and fusion/NS/truth/*
                (fusion-publish)
    consumers:  may subscribe fusion/NS/tracks/* and query fusion/NS/status and /snapshot
    recorders:  may subscribe fusion/NS/meas/*, input/* and truth/* (fusion record)
    services:   may put tracks and answer status/snapshot; needed only where the rules run on a
                router the service connects to (the service's own peer never filters itself)"""

    sensors: dict[Ident, list[CommonName]] = {}
    inputs: dict[Ident, list[CommonName]] = {}
    simulators: list[CommonName] = []
    consumers: list[CommonName] = []
    recorders: list[CommonName] = []
    services: list[CommonName] = []


class ZenohConfig(Section):
    """How the service joins Zenoh. The default is an embedded peer that listens on loopback
    only, with multicast and gossip scouting off: nothing else is needed on the machine.
    mode "client" connects to `connect` endpoints (a router or another peer). A listen endpoint
    off loopback is refused unless allow_remote is true. tls and access_control: see their
    sections and SECURITY.md. A client service whose peer is not there yet retries for
    connect_wait_s (backoff from 0.1 s, doubling, at most retry_max_s between tries; 0: once),
    and reconnects by itself (same backoff) when the peer goes away and comes back."""

    mode: Literal["peer", "client"] = "peer"
    listen: list[str] = msgspec.field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    connect: list[str] = []
    allow_remote: bool = False
    tls: TlsConfig | None = None
    access_control: AccessControlConfig | None = None
    connect_wait_s: Annotated[float, msgspec.Meta(ge=0.0, le=86400.0)] = 30.0
    retry_max_s: Annotated[float, msgspec.Meta(gt=0.0, le=60.0)] = 2.0


class RecordingConfig(Section):
    """Rerun recordings of every step, rotated by size or duration; names sort by time.
    `stream` also keeps the raw input (every sample with its arrival time) for `fusion replay`,
    in a `.fstream` beside each `.rrd` that rotates with it (and on its own past rotate_mb).
    Retention: the oldest files are deleted while more than `keep_files` recordings are kept or
    all of them take more than `keep_mb` (0: no limit). A recording or stream that fails while
    the service runs (disk full, folder gone) stops; tracking and publishing go on, and the
    status says why (fusion.io.recording_guard, fusion.io.stream_rotation).
    `flush_interval_s`: the record is scored every 0.2 s, in small pieces: a flush of 0.5 s of rows
    at 10k measurements/s took ~20-50 ms (bench/HISTORY.md); but only once `flush_min_rows` rows wait
    (the record makes ~2.75 rows a measurement: 4000 rows are 0.2 s at ~7 300 measurements/s),
    else at the next write: a flush costs ~0.8 ms however few rows it holds, which slower streams
    paid again and again (10 targets in real time: ~30 measurements in 0.2 s). `write_interval_s`: the scored rows go to
    the file every 1 s (or once an entity holds 4 096 rows), in fewer, larger chunks: Rerun keeps a
    row of the file's footer index per chunk in memory until the file closes (fusion.io.allocator).
    `background`: the recording is written on a thread of its own that works while the loop waits
    for samples (fusion.io.sink_thread), so a flush does not hold back the scans behind it; in a
    backlog, where the loop never waits, the loop writes it itself every 0.25 s, as with false;
    false writes it on the loop, which waits for each flush. A killed service loses at most the last
    write_interval_s of the record, and what its thread had not written yet (at most ~10 s of rows,
    usually none; its raw input is in the stream file)."""

    enabled: bool = True
    directory: str = "recordings"
    prefix: str = "fusion"
    rotate_mb: Annotated[float, msgspec.Meta(gt=0.0)] = 512.0
    rotate_s: Annotated[float, msgspec.Meta(gt=0.0)] = 3600.0
    flush_interval_s: Annotated[float, msgspec.Meta(gt=0.0, le=60.0)] = 0.2
    write_interval_s: Annotated[float, msgspec.Meta(gt=0.0, le=60.0)] = 1.0
    flush_min_rows: Annotated[int, msgspec.Meta(ge=0)] = 4000
    background: bool = True
    stream: bool = True
    keep_files: Annotated[int, msgspec.Meta(ge=0)] = 0
    keep_mb: NonNegFloat = 10_000.0


class IntakeConfig(Section):
    """The bounded hand-over from Zenoh threads to the tracker thread (fusion.io.intake_queue),
    for every key the service subscribes to. A payload over `max_message_bytes` is refused
    "too_large" before it is copied or decoded; a source (a configured sensor's or control
    source's key; all truth keys together; everything else together) sending faster than
    `source_rate_hz` (0: no limit; bursts of `source_burst`) is refused "rate_limited"; when
    `queue_max` samples or `queue_max_bytes` bytes wait, the source holding the most samples
    loses its oldest ones, or the new sample when it is that source's ("overload"). All counted,
    so memory stays bounded, Zenoh is never blocked, and one source's flood costs only that
    source. `batch_max` samples are processed per tracker call, taken round-robin across sources;
    a full batch that holds late measurements (of a scan before the tracker's newest) with more
    samples queued takes up to `late_batch_max`, so that one replay serves the late data of more
    scans (measured, 1000 targets, 10 % late, blast: 24.2k against 18.4k measurements/s with
    20 000 against 5 000; batches that large for every backlog cost ~8 % in order, hence only
    for batches with late data). Results do not depend on batching; a larger batch makes the
    status and snapshot answers wait longer under such a backlog (20 000 samples at the 26k/s
    measured with 10 % late at 1000 targets: ~0.8 s).
    A batch waits for a burst still arriving (fusion.io.burst): while samples keep coming, each
    within `burst_gap_ms` of the last, for at most `burst_linger_ms` (0: no wait), so a sensor's
    scan reaches the tracker whole instead of run again for its second half.
    `drain_deadline_s`: at shutdown, the queue is drained for at most this long; what is left is
    dropped and counted as "shutdown" (the recording is then closed complete).
    Before the queue, each subscriber's samples wait in a Zenoh channel of `channel_capacity`
    samples until its intake thread takes them (fusion.io.channel_intake); a full channel makes
    Zenoh wait."""

    queue_max: Annotated[int, msgspec.Meta(ge=1)] = 200_000
    queue_max_bytes: Annotated[int, msgspec.Meta(ge=1)] = 256_000_000
    max_message_bytes: Annotated[int, msgspec.Meta(ge=1)] = 65_536
    source_rate_hz: NonNegFloat = 0.0
    source_burst: Annotated[int, msgspec.Meta(ge=1)] = 1000
    batch_max: Annotated[int, msgspec.Meta(ge=1)] = 5_000
    late_batch_max: Annotated[int, msgspec.Meta(ge=1)] = 20_000
    burst_gap_ms: NonNegFloat = 2.0
    burst_linger_ms: NonNegFloat = 20.0
    drain_deadline_s: NonNegFloat = 10.0
    channel_capacity: Annotated[int, msgspec.Meta(ge=1)] = 4096
    max_future_wall_s: PosFloat = 3600.0  # refuse sensor times this far ahead of the wall clock

    def __post_init__(self) -> None:
        if self.max_message_bytes >= self.queue_max_bytes:
            raise ValueError("intake.max_message_bytes must be smaller than intake.queue_max_bytes")


class CheckpointConfig(Section):
    """[checkpoint]: the tracker's state written atomically every `interval_s` and at shutdown,
    and resumed at start (same track ids; the status says how old the checkpoint was). path ""
    is <recording.directory>/<recording.prefix>.checkpoint for a service with rotating
    recordings, and no checkpoint for a one-file run (fusion demo) unless a path is given. A
    checkpoint that cannot be used (damaged, of another tracker configuration, or written by the
    service of another namespace) is moved aside and the service starts clean
    (fusion.io.checkpointer)."""

    enabled: bool = True
    path: str = ""
    interval_s: PosFloat = 10.0


class PublicationConfig(Section):
    """[publication]: period_s > 0 also publishes, every period_s of stream (sensor) time, every
    confirmed track predicted to that tick on fusion/<ns>/predicted (fusion.prediction); 0: off.
    smooth_lag = L > 0 also publishes each confirmed estimate smoothed over the L estimates of
    its track after it, x_k|k+L, on fusion/<ns>/smoothed/<track_id> (fusion.fixed_lag); 0: off."""

    period_s: NonNegFloat = 0.0
    smooth_lag: Annotated[int, msgspec.Meta(ge=0, le=1000)] = 0


class ServiceConfig(Section):
    """`fusion serve --config FILE`: everything the service needs."""

    tracker: TrackerConfig
    namespace: str = "demo"
    zenoh: ZenohConfig = ZenohConfig()
    recording: RecordingConfig = RecordingConfig()
    intake: IntakeConfig = IntakeConfig()
    checkpoint: CheckpointConfig = CheckpointConfig()
    publication: PublicationConfig = PublicationConfig()
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
