"""The wire schema: msgspec Structs, msgpack on the wire (JSON for humans and .jsonl files).

Every message is frozen, refuses unknown fields, and carries its schema version `v` on the
wire; a message of another version is refused as unsupported_version, with the reason. Validation
happens at decode: NaN and inf are refused (every float has both bounds), angles, ranges and
standard deviations are bounded, dimensions must match; the error names the field
(`Expected float >= 0.0, got -1.0 - at $.data.range_std_m`).

Key expressions, under a namespace NS (ids: letters, digits, '_', '-', '.'):
    fusion/NS/meas/SENSOR_ID     Measurement          (subscribe to fusion/NS/meas/* for all)
    fusion/NS/input/SOURCE_ID    Input                (a known control input: fusion/NS/input/*)
    fusion/NS/truth/TARGET_ID    Truth                (fusion/NS/truth/*)
    fusion/NS/tracks/TRACK_ID    Estimate             (fusion/NS/tracks/*)
    fusion/NS/events/TRACK_ID    Event                (confirmed, coasting, deleted: fusion/NS/events/*)
    fusion/NS/status             ServiceStatus        (queryable)
    fusion/NS/snapshot           Snapshot             (queryable: latest estimate per confirmed track;
                                                       ?t_ns=T: every confirmed track predicted to T)
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Annotated, Literal

import msgspec

from fusion.errors import (  # noqa: F401 (MessageError: re-exported)
    InputError,
    InvalidMessageError,
    MalformedMessageError,
    MessageError,
    UnsupportedVersionError,
)

SCHEMA_VERSION = 1
_BIG = 1e15
Finite = Annotated[float, msgspec.Meta(ge=-_BIG, le=_BIG)]
Positive = Annotated[float, msgspec.Meta(gt=0.0, le=_BIG)]
# Radar ranges from 10 cm to a million km. Outside, the tracker's polar-to-Cartesian covariance of
# a new track is numerically singular (near 0: the bearing's r^2 sigma^2 vanishes; past ~1e11 m:
# condition number over 1/eps) and the birth raised NotPositiveDefiniteError out of the pipeline
# (found by tests/security/test_hostile_properties.py; 22 of 123 bearings/noises failed at 1 mm).
MIN_RANGE_M = 0.1
MAX_RANGE_M = 1e9
Range = Annotated[float, msgspec.Meta(ge=MIN_RANGE_M, le=MAX_RANGE_M)]
Bearing = Annotated[float, msgspec.Meta(ge=-math.pi, le=math.pi)]
Elevation = Annotated[float, msgspec.Meta(ge=-math.pi / 2, le=math.pi / 2)]
Prob = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
TimeNs = Annotated[int, msgspec.Meta(ge=-(2**62), le=2**62)]
Seq = Annotated[int, msgspec.Meta(ge=0, le=2**62)]
Epoch = Annotated[int, msgspec.Meta(ge=0, le=2**63 - 1)]
Id = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.\-]{1,64}\Z")]  # \Z: "$" matches before a final newline
Version = Annotated[int, msgspec.Meta(ge=1, le=SCHEMA_VERSION)]


def _schema_version() -> int:
    """v's default, as a factory: msgspec omits defaults from the wire (omit_defaults) but not
    a factory's value, so every message carries its schema version."""
    return SCHEMA_VERSION


class Base(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, omit_defaults=True):
    """Base of every message."""


class Cartesian(Base, tag="cartesian", kw_only=True):
    """A measured position (1-D, 2-D or 3-D) in the sensor's frame, with its noise: per-axis
    std_m, or a full row-major covariance cov_m2 (d*d values), at most one of the two; with
    neither, the sensor's configured noise applies."""

    pos_m: list[Finite]
    std_m: list[Positive] | None = None
    cov_m2: list[Finite] | None = None

    def __post_init__(self) -> None:
        d = len(self.pos_m)
        std = self.std_m
        if 0 < d < 4 and self.cov_m2 is None and (std is None or len(std) == d):
            return  # the common cases, checked as below in fewer steps (decode's hot path)
        if d not in (1, 2, 3):
            raise ValueError(f"pos_m must have 1, 2 or 3 components, got {d}")
        if self.std_m is not None and self.cov_m2 is not None:
            raise ValueError("give at most one of std_m and cov_m2")
        if self.std_m is not None and len(self.std_m) != d:
            raise ValueError(f"std_m must have {d} components, got {len(self.std_m)}")
        if self.cov_m2 is not None and len(self.cov_m2) != d * d:
            raise ValueError(f"cov_m2 must have {d * d} components (row-major), got {len(self.cov_m2)}")


class Radar(Base, tag="radar", kw_only=True):
    """A radar return relative to the sensor's pose: range, bearing, optional elevation (3-D) and
    range rate. Its noise is either complete (a standard deviation for every value present) or
    absent (the sensor's configured noise applies)."""

    range_m: Range
    bearing_rad: Bearing
    range_std_m: Positive | None = None
    bearing_std_rad: Positive | None = None
    elevation_rad: Elevation | None = None
    elevation_std_rad: Positive | None = None
    range_rate_mps: Finite | None = None
    range_rate_std_mps: Positive | None = None

    def __post_init__(self) -> None:
        if self.range_std_m is None:
            if self.bearing_std_rad is None and self.elevation_std_rad is None and self.range_rate_std_mps is None:
                return  # no noise at all: valid (decode's hot path; the general rule below)
        elif (self.bearing_std_rad is not None and (self.elevation_std_rad is None) == (self.elevation_rad is None)
              and (self.range_rate_std_mps is None) == (self.range_rate_mps is None)):
            return  # a standard deviation for exactly the values present: valid
        values = [True, True, self.elevation_rad is not None, self.range_rate_mps is not None]
        stds = [self.range_std_m, self.bearing_std_rad, self.elevation_std_rad, self.range_rate_std_mps]
        if any(s is not None and not v for s, v in zip(stds, values, strict=True)):
            raise ValueError("a standard deviation is given for a value that is absent")
        given = [s is not None for s, v in zip(stds, values, strict=True) if v]
        if any(given) and not all(given):
            raise ValueError("give a standard deviation for every value present (range, bearing, and elevation "
                             "and range rate when present), or none to use the sensor's configured noise")

    @property
    def has_noise(self) -> bool:
        return self.range_std_m is not None


class Measurement(Base, tag="measurement", kw_only=True):
    """One measurement of one sensor at sensor time t_ns (integer nanoseconds).

    epoch: the publisher's boot id, fixed from its process start (fusion-publish uses the wall
    clock in ns at start); seq counts from 0 again in a new epoch. 0 (the default, left off the
    wire) means the publisher gives none: messages of schema 1 without it still decode."""

    v: Version = msgspec.field(default_factory=_schema_version)
    sensor_id: Id
    t_ns: TimeNs
    seq: Seq
    data: Cartesian | Radar
    epoch: Epoch = 0


class Input(Base, tag="input", kw_only=True):
    """A known control input of source `source_id` (e.g. a vehicle's commanded acceleration per
    axis), in force from t_ns until the source's next input."""

    v: Version = msgspec.field(default_factory=_schema_version)
    source_id: Id
    t_ns: TimeNs
    seq: Seq
    u: list[Finite]

    def __post_init__(self) -> None:
        if not 1 <= len(self.u) <= 6:
            raise ValueError(f"u must have 1 to 6 components, got {len(self.u)}")


class Truth(Base, tag="truth", kw_only=True):
    """The true state of a simulated target; layout names its components (x, vx, y, vy, ...)."""

    v: Version = msgspec.field(default_factory=_schema_version)
    target_id: Id
    t_ns: TimeNs
    state: list[Finite]
    layout: list[str]

    def __post_init__(self) -> None:
        if len(self.state) != len(self.layout):
            raise ValueError(f"state has {len(self.state)} components, layout names {len(self.layout)}")


class Estimate(Base, tag="estimate", kw_only=True):
    """A track's estimate after a measurement update. A higher revision replaces an earlier
    estimate of the same (track_id, t_ns, sensor_id); status "retracted" withdraws it."""

    v: Version = msgspec.field(default_factory=_schema_version)
    track_id: int
    t_ns: TimeNs
    sensor_id: str
    seq: int
    state: list[float]
    cov: list[float]  # row-major n*n
    layout: list[str]
    model: str
    status: Literal["tentative", "confirmed", "retracted", "predicted"]
    revision: int
    nis: float | None = None
    mode_probabilities: list[float] | None = None


class Event(Base, tag="event", kw_only=True):
    """A published track's lifecycle at sensor time t_ns: confirmed, coasting (it missed a
    chance: no update this scan), or deleted (with the reason). withdrawn=True takes back an
    event sent before: a late measurement changed the past, and the track's history no longer
    has it."""

    v: Version = msgspec.field(default_factory=_schema_version)
    track_id: int
    t_ns: TimeNs
    kind: Literal["confirmed", "coasting", "deleted"]
    reason: str | None = None
    withdrawn: bool = False


class LatencyStats(Base, kw_only=True):
    count: int
    mean_ms: float
    p50_ms: float
    p99_ms: float
    max_ms: float


class Counts(Base, kw_only=True):
    """received = applied + inputs + truth + duplicates + sum(refused.values()) + queued (inputs:
    control inputs applied; 0 from a service before they were counted here). Of the duplicates
    and refused, inputs_refused were control inputs, truth_refused truth samples and
    other_refused samples on a key that names no kind (not fusion/NS/meas|input|truth/ID), at the
    pipeline, the intake queue or dropped at shutdown (0 from a service before they were
    counted); the rest measurements."""

    received: int
    applied: int
    duplicates: int
    refused: dict[str, int]
    queued: int
    replays: int
    late_applied: int
    published: int
    truth: int
    inputs: int = 0
    inputs_refused: int = 0
    truth_refused: int = 0
    other_refused: int = 0


class SeqGapStats(Base, kw_only=True):
    """A sensor's seq gaps (fusion.io.gaps): missing now, filled later, publisher runs seen, and
    samples zenoh's miss detection reported lost before recovery (zenoh_missed)."""

    missing: int
    filled: int
    epochs: int
    restarts: int
    zenoh_missed: int = 0


class ZenohLink(Base, kw_only=True):
    """How the service is joined to zenoh: state "listening" (a peer), "connected" or
    "disconnected" (a client); connect_attempts it took at start; reconnects since."""

    mode: str
    state: str
    routers: int
    peers: int
    connect_attempts: int
    reconnects: int


class CheckpointStatus(Base, kw_only=True):
    """The service's checkpoint: how many tracks were resumed from one how old (seconds, None:
    none resumed), why one found at start was refused, writes so far, the age of the last one,
    and the last write error (None when the last write worked)."""

    path: str
    resumed_tracks: int
    resumed_age_s: float | None = None
    refused: str | None = None
    written: int
    last_written_age_s: float | None = None
    error: str | None = None


class ServiceStatus(Base, tag="status", kw_only=True):
    v: Version = msgspec.field(default_factory=_schema_version)
    uptime_s: float
    counts: Counts
    tracks: dict[str, int]  # by status
    latency: dict[str, LatencyStats]  # by sensor: arrival time - sensor time
    recording: str | None
    recording_bytes: int
    queue_depth: int
    gaps: dict[str, SeqGapStats] = {}  # by sensor
    zenoh: ZenohLink | None = None
    checkpoint: CheckpointStatus | None = None
    recording_error: str | None = None  # why the recording or the stream file stopped, if it did
    recording_queue: int = 0  # rows handed to the recording's thread and not written yet (fusion.io.sink_thread)


class Snapshot(Base, tag="snapshot", kw_only=True):
    v: Version = msgspec.field(default_factory=_schema_version)
    estimates: list[Estimate]


Message = Measurement | Input | Truth | Estimate | Event | ServiceStatus | Snapshot

_enc = msgspec.msgpack.Encoder()
_json_enc = msgspec.json.Encoder()
_dec_meas = msgspec.msgpack.Decoder(Measurement)
_dec_truth = msgspec.msgpack.Decoder(Truth)
_dec_input = msgspec.msgpack.Decoder(Input)
_dec_est = msgspec.msgpack.Decoder(Estimate)
_dec_event = msgspec.msgpack.Decoder(Event)
_dec_status = msgspec.msgpack.Decoder(ServiceStatus)
_dec_snap = msgspec.msgpack.Decoder(Snapshot)
_dec_any = msgspec.msgpack.Decoder(Message)
_json_any = msgspec.json.Decoder(Message)


class _Versioned(msgspec.Struct):
    """Any message's schema version, the rest of it ignored (a sender without `v` speaks 1)."""

    v: int = 1


_version_of = {msgspec.msgpack.Decoder: msgspec.msgpack.Decoder(_Versioned),
               msgspec.json.Decoder: msgspec.json.Decoder(_Versioned)}


def encode(msg: Message) -> bytes:
    """msgpack bytes of a message."""
    return _enc.encode(msg)


def encode_json(msg: Message) -> bytes:
    """One line of JSON (no newline) of a message."""
    return _json_enc.encode(msg)


def _decode(dec: msgspec.msgpack.Decoder | msgspec.json.Decoder, data: bytes | str, what: str) -> Message:
    try:
        return dec.decode(data)
    except msgspec.ValidationError as e:
        v = _version(dec, data)
        if v is not None and v != SCHEMA_VERSION:
            raise UnsupportedVersionError(f"{what} of an unsupported schema version ({e}); this service reads "
                                          f"version {SCHEMA_VERSION}: upgrade it or the sender") from None
        raise InvalidMessageError(f"invalid {what}: {e}") from None
    except (msgspec.DecodeError, UnicodeDecodeError, ValueError, OverflowError) as e:
        # msgspec raises UnicodeDecodeError for invalid UTF-8 in a string, not DecodeError
        raise MalformedMessageError(f"malformed {what}: {type(e).__name__}: {e}") from None


def _version(dec: msgspec.msgpack.Decoder | msgspec.json.Decoder, data: bytes | str) -> int | None:
    """The schema version a message that failed validation says it has (None: no integer `v`
    in an object; such a message is invalid, whatever its version)."""
    try:
        return _version_of[type(dec)].decode(data).v
    except msgspec.DecodeError:  # ValidationError included: a `v` that is not an integer
        return None


def decode_measurement(data: bytes) -> Measurement:
    return _decode(_dec_meas, data, "measurement")  # type: ignore[return-value]


def measurement_decoder() -> Callable[[bytes], Measurement]:
    """The decode behind decode_measurement, for a loop over many payloads: it raises msgspec's
    errors, not the typed ones; hand a payload it fails on to decode_measurement for those."""
    return _dec_meas.decode


def decode_input(data: bytes) -> Input:
    return _decode(_dec_input, data, "input")  # type: ignore[return-value]


def decode_truth(data: bytes) -> Truth:
    return _decode(_dec_truth, data, "truth")  # type: ignore[return-value]


def decode_estimate(data: bytes) -> Estimate:
    return _decode(_dec_est, data, "estimate")  # type: ignore[return-value]


def decode_event(data: bytes) -> Event:
    return _decode(_dec_event, data, "event")  # type: ignore[return-value]


def decode_status(data: bytes) -> ServiceStatus:
    return _decode(_dec_status, data, "status")  # type: ignore[return-value]


def decode_snapshot(data: bytes) -> Snapshot:
    return _decode(_dec_snap, data, "snapshot")  # type: ignore[return-value]


def decode_any(data: bytes) -> Message:
    return _decode(_dec_any, data, "message")


def decode_json(line: bytes | str) -> Message:
    """A message from one line of JSON (as written by encode_json)."""
    return _decode(_json_any, line, "JSON message")


# ---- key expressions ---------------------------------------------------------------------------
_ID = re.compile(r"[A-Za-z0-9_.\-]{1,64}")  # used with fullmatch: "$" would let "cam1\n" through


def check_id(what: str, value: str) -> str:
    """An id safe inside a key expression (no '/', '*', '$', '#', '?', spaces)."""
    if not isinstance(value, str) or not _ID.fullmatch(value):
        raise InputError(f"{what} {value!r} must be 1-64 of letters, digits, '_', '-', '.'")
    return value


def meas_key(ns: str, sensor_id: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/meas/{check_id('sensor_id', sensor_id)}"


def input_key(ns: str, source_id: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/input/{check_id('source_id', source_id)}"


def all_input_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/input/*"


def truth_key(ns: str, target_id: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/truth/{check_id('target_id', target_id)}"


def track_key(ns: str, track_id: int) -> str:
    return f"fusion/{check_id('namespace', ns)}/tracks/{int(track_id)}"


def all_meas_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/meas/*"


def all_truth_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/truth/*"


def event_key(ns: str, track_id: int) -> str:
    return f"fusion/{check_id('namespace', ns)}/events/{int(track_id)}"


def all_events_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/events/*"


def all_tracks_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/tracks/*"


def status_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/status"


def snapshot_key(ns: str) -> str:
    return f"fusion/{check_id('namespace', ns)}/snapshot"


def key_kind(key: str) -> str:
    """"meas", "input", "truth", "tracks", "status", "snapshot" or "other" for a key expression."""
    parts = key.split("/")
    if len(parts) >= 3 and parts[0] == "fusion":
        kinds = ("meas", "input", "truth", "tracks", "events", "status", "snapshot")
        return parts[2] if parts[2] in kinds else "other"
    return "other"
