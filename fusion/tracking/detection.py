"""What the tracker takes in (a Detection, a ControlInput) and the reasons it refuses one."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from operator import attrgetter
from typing import NamedTuple

import numpy as np

from fusion.core.checks import Array


class Reason(StrEnum):
    """Why a measurement was refused. Every refused measurement carries exactly one."""

    MALFORMED = "malformed"  # bytes that do not decode (used at the edge)
    INVALID = "invalid"  # wrong dimension, NaN/inf, bad sequence number or time
    BAD_COVARIANCE = "bad_covariance"  # a noise covariance that is not symmetric positive definite
    UNKNOWN_SENSOR = "unknown_sensor"
    UNSUPPORTED_VERSION = "unsupported_version"  # a message of a schema version this build does not read
    KEY_MISMATCH = "key_mismatch"  # a sample whose payload names another sensor (or target) than its key
    DUPLICATE = "duplicate"  # same (sensor_id, epoch, seq, t_ns) seen before
    TOO_LATE = "too_late"  # older than the out-of-order window
    FUTURE = "future"  # further ahead of the newest time than the tolerance


class Detection(NamedTuple):
    """One measurement: z in the sensor's measurement space at sensor time t_ns.

    Cartesian sensors: z = position (d,). Radar (2-D): [range_m, bearing_rad] or
    [range_m, bearing_rad, range_rate_mps]; radar (3-D): [range_m, azimuth_rad, elevation_rad]
    with an optional range rate last. R is the noise covariance; None takes the sensor's default.
    arrival_ns: when it arrived (the intake's clock), None when unknown. epoch: the publisher's
    boot id (0: none given); (sensor_id, epoch, seq, t_ns) identifies a measurement. radar_data:
    the kind of data the message carried (None: not said), checked against the sensor's kind.

    Immutable; a NamedTuple rather than a frozen dataclass because one is built per measurement
    on the intake's hot path (0.3 us against 0.9 us measured here).
    """

    sensor_id: str
    t_ns: int
    seq: int
    z: Array
    R: Array | None = None
    arrival_ns: int | None = None
    epoch: int = 0
    radar_data: bool | None = None  # what the producer says z is: range/bearing (True), a position (False)

    @property
    def key(self) -> tuple[int, str, int]:
        """The total processing order: (t_ns, sensor_id, seq)."""
        return (self.t_ns, self.sensor_id, self.seq)

    @classmethod
    def of(cls, sensor_id: str, t_ns: int, seq: int, z: object, R: object | None = None,
           arrival_ns: int | None = None, *, epoch: int = 0) -> Detection:
        return cls(
            sensor_id, int(t_ns), int(seq), np.asarray(z, dtype=np.float64),
            None if R is None else np.asarray(R, dtype=np.float64), None if arrival_ns is None else int(arrival_ns),
            int(epoch),
        )


SEQ = attrgetter("seq")  # a Detection's seq
EPOCH = attrgetter("epoch")
# the order of a scan's detections: by seq, then epoch (a restarted publisher's two epochs can send
# one seq at one time; a scan never holds one (epoch, seq) twice: admission refuses duplicates)
SCAN_ORDER = attrgetter("seq", "epoch")


def in_scan_order(dets: Sequence[Detection]) -> list[Detection]:
    """`dets` sorted by SCAN_ORDER, as two stable sorts (by epoch, then by seq): the same order,
    at a sixth of the cost a tuple key adds (667 detections: 65 us against 46 by seq alone and
    254 by the tuple, timeit)."""
    return sorted(sorted(dets, key=EPOCH), key=SEQ)


def seqs_of(dets: Sequence[Detection]) -> np.ndarray:
    """The detections' seqs, (n,) int64, in their order (one C-level pass: map and fromiter)."""
    return np.fromiter(map(SEQ, dets), dtype=np.int64, count=len(dets))


@dataclass(frozen=True, slots=True)
class ControlInput:
    """A known input u (e.g. an acceleration per axis) from source `source_id`, in force from
    t_ns until the source's next input (zero-order hold); before the first one u = 0."""

    source_id: str
    t_ns: int
    seq: int
    u: Array
    arrival_ns: int | None = None

    @classmethod
    def of(cls, source_id: str, t_ns: int, seq: int, u: object, arrival_ns: int | None = None) -> ControlInput:
        return cls(source_id, int(t_ns), int(seq), np.atleast_1d(np.asarray(u, dtype=np.float64)),
                   None if arrival_ns is None else int(arrival_ns))


@dataclass(frozen=True, slots=True)
class Refusal:
    """A refused measurement and why."""

    sensor_id: str
    t_ns: int
    seq: int
    reason: Reason
    detail: str
