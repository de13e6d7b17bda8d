"""Compile (or load from numba's cache) every kernel a tracker configuration runs, before data.

The tracker's compiled kernels (fusion.core.compiled*, the lifecycle, id-set and intake window kernels) are
compiled lazily by numba at their first call and cached on disk (`cache=True`). On the first run
after an install that first call costs about 20 s on the reference machine; a service meeting it
on its first measurement falls that far behind its sensors, and a demo's first run looks stalled.
`warm_up(config)` takes that cost up front: it runs a throwaway Tracker of the same
configuration over a short synthetic scene of every configured sensor (cartesian and radar, each
of its measurement dimensions, e.g. a radar with and without range rate), so every path real data
take runs once:
  - in-order scans, one process call each, then pairs of scans per call: initiation, gating,
    association, updates, confirmation (the scene lasts longer than confirm_n scans), the
    lifecycle sweep;
  - one measurement held back and delivered late: the (selective) replay;
  - the same measurement again, without its arrival time: the intake's pass for callers of
    Tracker that have none (fusion.tracking.window_kernel), and the duplicate refusal;
  - `predict` ahead of the newest scan: what the snapshot queryable and periodic publication run.
  - the row comparison of a partial re-run with many changed rows (fusion.tracking.row_bits.warm),
    which the scene's few tracks never reach.
The scene: three targets per sensor in straight flight at 5 m/s, 300 m from the sensor (the centre
of its declared coverage when it has one), seen every 100 ms of sensor time for 1.2 s, with z =
h(x) exactly (the kernels' types do not depend on the values). Custom sensors (a user's model,
fusion.models.loader) get no synthetic detections: their h has no domain fusion can rely on,
and the tracker kernels they reach are the ones the other sensors warm; a configuration of
custom sensors only is warmed by its first real data, as before.

Nothing of the throwaway tracker is kept (trackers share no state) and nothing here reads a clock
or does I/O; the caller (fusion.service) times it and says so. Returns what it ran, as a count.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fusion.config import CustomSensorConfig, TrackerConfig
from fusion.tracking import row_bits
from fusion.tracking.detection import Detection
from fusion.tracking.models import SensorModel
from fusion.tracking.tracker import Tracker

SCANS = 12  # per sensor, at SCAN_NS apart: longer than any usual confirm_n (the shipped one is 6)
SCAN_NS = 100_000_000
START_NS = 1_000_000_000
TARGETS = 3
RANGE_M = 300.0  # from the sensor (or the centre of its coverage)
SPEED_MPS = 5.0


class WarmUp(NamedTuple):
    """What the warm-up ran: detections offered, process calls, late ones folded in."""

    detections: int
    calls: int
    late_applied: int


def _centre(s: SensorModel) -> np.ndarray:
    """Where the sensor's synthetic targets fly: the centre of its declared coverage, else
    RANGE_M from its position along (1, 1, ...)."""
    c, d = s.config, s.ndim
    if c.region_m:
        return np.asarray(c.region_m, dtype=np.float64).reshape(d, 2).mean(axis=1)
    origin = np.asarray(c.position_m or [0.0] * d, dtype=np.float64)
    r = RANGE_M if c.max_range_m is None else min(RANGE_M, 0.5 * c.max_range_m)
    return origin + r * np.ones(d) / np.sqrt(d)


def _noise(s: SensorModel, m: int, kind: int) -> np.ndarray | None:
    """The three forms R takes on arrival (fusion.io.wire.detection_of): kind 0 none (the sensor's
    default; the model's R where it has none), 1 a read-only diagonal shared between messages
    (per-axis standard deviations), 2 a writable matrix (a full covariance)."""
    R = s.default_R[m]
    if kind == 0 and R is not None:
        return None
    R = np.array(s.by_dim[m].R if R is None else R, dtype=np.float64)
    if kind == 1:
        R = np.diag(np.diagonal(R))
        R.flags.writeable = False
    return R


def _scans(tracker: Tracker) -> list[list[Detection]]:
    """Every non-custom sensor's scans over the synthetic scene, in (t_ns, sensor) order; a
    sensor's measurement dimensions take turns scan by scan, every third scan holds one
    detection (the single-row stacks), and the noise takes its three arrival forms in turn."""
    pi, vi = tracker.position_indices, tracker.velocity_indices
    n = len(tracker.layout)
    by_key: dict[tuple[int, str], list[Detection]] = {}
    for k_sensor, (sid, s) in enumerate(sorted(tracker.sensors.items())):
        if isinstance(s.config, CustomSensorConfig):
            continue
        d = s.ndim
        heading = np.zeros(d)
        heading[0] = 1.0
        dims = sorted(s.by_dim)
        for k in range(SCANS):
            t = START_NS + k * SCAN_NS + k_sensor * 1_000_000  # sensors a millisecond apart
            m = dims[k % len(dims)]
            model = s.by_dim[m]
            for j in range(TARGETS if k % 3 != 2 else 1):  # every third scan a single detection
                x = np.zeros(n)
                offset = np.zeros(d)
                offset[-1] = 40.0 * (j - 1)
                x[list(pi[:d])] = _centre(s) + offset + heading * SPEED_MPS * (t - START_NS) / 1e9
                x[list(vi[:d])] = (heading * SPEED_MPS)[:len(vi[:d])]  # (a custom model may name no velocity)
                z = np.array(model.h(x), dtype=np.float64)
                by_key.setdefault((t, sid), []).append(
                    Detection(sid, t, k * TARGETS + j, z, _noise(s, m, (k + j) % 3), t, 0, s.is_radar))
    return [by_key[key] for key in sorted(by_key)]


def warm_up(config: TrackerConfig) -> WarmUp:
    """Run a throwaway Tracker of `config` over the synthetic scene (module docstring)."""
    tracker = Tracker(config)
    data = _scans(tracker)
    if not data:
        return WarmUp(0, 0, 0)
    late_scan = len(data) - 4
    held = data[late_scan][0]
    calls: list[list[Detection]] = []
    half = len(data) // 2
    for scan in data[:half]:  # one scan per call
        calls.append([d for d in scan if d is not held])
    for k in range(half, len(data), 2):  # two scans per call, as a batch of the service's drains
        calls.append([d for kk in (k, k + 1) if kk < len(data) for d in data[kk] if d is not held])
    calls.append([held])  # late: replayed from its scan on
    calls.append([held._replace(arrival_ns=None)])  # again, untimed: a duplicate, refused
    for batch in calls:
        tracker.process(batch)
    newest = data[-1][0].t_ns
    tracker.predict(newest + SCAN_NS // 2)
    row_bits.warm()  # changed_since's kernel, which the scene's few tracks never reach
    return WarmUp(sum(len(s) for s in data), len(calls), tracker.counts.late_applied)
