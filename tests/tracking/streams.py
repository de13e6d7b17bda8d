"""Seeded multi-target truth and sensor detections for the tracker tests. Pure: numpy in, data out.

Truth is 2-D, state [x, vx, y, vy] (the tracker's "cv" layout), sampled on a base tick of
TICK_NS. Targets move at constant velocity, optionally on paths that cross and with one
coordinated turn (a manoeuvre). Sensors:

  cartesian: z = [x, y] + N(0, diag(std_m^2))
  radar:     z = [range_m, bearing_rad] of the target relative to the sensor position, with
             bearing = atan2(dy, dx) wrapped into (-pi, pi], plus N(0, diag(range_std^2, bearing_std^2))

Each scan of a sensor detects each live target with probability pd, adds Poisson(clutter_mean)
false returns uniform in a rectangle, shuffles the returns and numbers them with the sensor's
running seq, so seq order says nothing about which target a return came from.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from fusion.config import CartesianSensorConfig, RadarSensorConfig, SensorConfig
from fusion.tracking.detection import Detection

NS_PER_S = 1_000_000_000
TICK_NS = 50_000_000  # 50 ms: every scan time is a multiple of the tick
CLUTTER = -1  # origin of a false return


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles into (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)


@dataclass(frozen=True)
class Truth:
    """t_ns (K,) on the tick grid; x (K, T, 4) states [x, vx, y, vy]; alive (K, T)."""

    t_ns: np.ndarray
    x: np.ndarray
    alive: np.ndarray

    @property
    def n_targets(self) -> int:
        return self.x.shape[1]

    def index(self, t_ns: int) -> int:
        k = (t_ns - int(self.t_ns[0])) // TICK_NS
        assert 0 <= k < len(self.t_ns) and self.t_ns[k] == t_ns, f"{t_ns} is not on the truth grid"
        return int(k)

    def positions(self, t_ns: int) -> np.ndarray:
        """(n_alive, 2) positions of the live targets at t_ns."""
        k = self.index(t_ns)
        return self.x[k][self.alive[k]][:, [0, 2]]


@dataclass(frozen=True)
class Sensor:
    """A simulated sensor: kind "cartesian" (std_m) or "radar" (range_std_m, bearing_std_rad at
    position_m). Scans at period_s, starting at offset_s."""

    id: str
    kind: str
    period_s: float = 0.5
    offset_s: float = 0.0
    std_m: float = 1.0
    range_std_m: float = 1.0
    bearing_std_rad: float = 0.01
    position_m: tuple[float, float] = (0.0, 0.0)

    def config(self) -> SensorConfig:
        if self.kind == "cartesian":
            return CartesianSensorConfig(id=self.id, std_m=[self.std_m, self.std_m])
        return RadarSensorConfig(id=self.id, position_m=list(self.position_m),
                            range_std_m=self.range_std_m, bearing_std_rad=self.bearing_std_rad)

    def measure(self, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy measurements of positions p (n, 2)."""
        if self.kind == "cartesian":
            return p + rng.normal(0.0, self.std_m, size=p.shape)
        return self.noiseless(p) + rng.normal(0.0, [self.range_std_m, self.bearing_std_rad], size=p.shape)

    def noiseless(self, p: np.ndarray) -> np.ndarray:
        if self.kind == "cartesian":
            return p.copy()
        d = p - np.asarray(self.position_m)
        return np.stack([np.hypot(d[:, 0], d[:, 1]), wrap_angle(np.arctan2(d[:, 1], d[:, 0]))], axis=-1)

    def scan_times(self, t0_ns: int, t1_ns: int) -> list[int]:
        step, off = round(self.period_s * NS_PER_S), round(self.offset_s * NS_PER_S)
        assert step % TICK_NS == 0 and off % TICK_NS == 0
        return list(range(t0_ns + off, t1_ns + 1, step))


def constant_velocity(
    *,
    n_targets: int,
    duration_s: float,
    rng: np.random.Generator,
    speed_mps: tuple[float, float] = (8.0, 15.0),
    crossing: bool = False,
    spread_m: float = 1000.0,
    manoeuvre: tuple[int, float, float, float] | None = None,
    lifetimes_s: Sequence[tuple[float, float]] | None = None,
    t0_ns: int = 0,
) -> Truth:
    """Constant-velocity targets on the tick grid.

    crossing: all paths cross at the origin; the targets pass it in turn, 1 s apart, around the
    middle of the run (so at the crossing they are about one second of travel apart).
    Otherwise: start uniform in [-spread_m, spread_m]^2, random headings.
    manoeuvre: (target, start_s, stop_s, turn_rate_radps): that target turns at a constant
    rate in [start_s, stop_s). lifetimes_s: per target (appear_s, vanish_s).
    """
    K = round(duration_s * NS_PER_S) // TICK_NS + 1
    t_ns = t0_ns + TICK_NS * np.arange(K, dtype=np.int64)
    x = np.empty((K, n_targets, 4))
    speed = rng.uniform(*speed_mps, size=n_targets)
    if crossing:
        # Headings pi/n apart over a half turn (crossing angles >= pi/n - 0.2, never head-on),
        # each target passing the origin at its own time, 1 s apart, around the middle of the run.
        th = np.pi * np.arange(n_targets) / n_targets + rng.uniform(-0.1, 0.1, size=n_targets)
        t_cross = duration_s / 2 + (np.arange(n_targets) - (n_targets - 1) / 2) * 1.0
        v = -speed[:, None] * np.stack([np.cos(th), np.sin(th)], axis=1)
        p = -v * t_cross[:, None]
    else:
        p = rng.uniform(-spread_m, spread_m, size=(n_targets, 2))
        th = rng.uniform(-np.pi, np.pi, size=n_targets)
        v = speed[:, None] * np.stack([np.cos(th), np.sin(th)], axis=1)
    dt = TICK_NS / NS_PER_S
    for k in range(K):
        x[k, :, 0], x[k, :, 1], x[k, :, 2], x[k, :, 3] = p[:, 0], v[:, 0], p[:, 1], v[:, 1]
        if manoeuvre is not None:
            i, start, stop, w = manoeuvre
            if start <= k * dt < stop:  # exact coordinated turn over one tick
                c, s = np.cos(w * dt), np.sin(w * dt)
                vx, vy = v[i]
                p[i] += np.array([vx * s - vy * (1 - c), vy * s + vx * (1 - c)]) / w
                v[i] = [c * vx - s * vy, s * vx + c * vy]
                p[np.arange(n_targets) != i] += v[np.arange(n_targets) != i] * dt
                continue
        p = p + v * dt
    alive = np.ones((K, n_targets), dtype=bool)
    if lifetimes_s is not None:
        ts = (t_ns - t0_ns) / NS_PER_S
        for i, (a, b) in enumerate(lifetimes_s):
            alive[:, i] = (ts >= a) & (ts < b)
    return Truth(t_ns, x, alive)


@dataclass(frozen=True)
class Labeled:
    """A detection with its origin: the target index, or CLUTTER."""

    det: Detection
    origin: int


def detect(
    truth: Truth,
    sensor: Sensor,
    *,
    rng: np.random.Generator,
    pd: float = 1.0,
    clutter_mean: float = 0.0,
    region_m: tuple[float, float, float, float] = (-500.0, 500.0, -500.0, 500.0),
    seq0: int = 0,
) -> list[Labeled]:
    """The detections of one sensor over the whole truth, in (t_ns, seq) order."""
    out: list[Labeled] = []
    seq = seq0
    x0, x1, y0, y1 = region_m
    for t in sensor.scan_times(int(truth.t_ns[0]), int(truth.t_ns[-1])):
        k = truth.index(t)
        live = np.flatnonzero(truth.alive[k])
        hit = live[rng.random(live.size) < pd]
        z = sensor.measure(truth.x[k, hit][:, [0, 2]], rng)
        nc = rng.poisson(clutter_mean)
        cp = np.stack([rng.uniform(x0, x1, nc), rng.uniform(y0, y1, nc)], axis=1)
        zs = np.concatenate([z, sensor.noiseless(cp)]) if nc else z
        origins = np.concatenate([hit, np.full(nc, CLUTTER)])
        for j in rng.permutation(len(zs)):
            out.append(Labeled(Detection.of(sensor.id, t, seq, zs[j]), int(origins[j])))
            seq += 1
    return out


def in_order(*streams: list[Labeled]) -> list[Labeled]:
    """All detections in the tracker's processing order (t_ns, sensor_id, seq)."""
    return sorted((d for s in streams for d in s), key=lambda d: d.det.key)


def scans(dets: Sequence[Labeled]) -> Iterator[list[Labeled]]:
    """Consecutive runs of detections with the same (t_ns, sensor_id)."""
    batch: list[Labeled] = []
    for d in dets:
        if batch and (batch[0].det.t_ns, batch[0].det.sensor_id) != (d.det.t_ns, d.det.sensor_id):
            yield batch
            batch = []
        batch.append(d)
    if batch:
        yield batch


def circling_scans(
    *,
    n_targets: int,
    n_scans: int,
    rng: np.random.Generator,
    period_s: float = 0.1,
    std_m: float = 1.0,
    pd: float = 0.95,
    clutter_mean: float = 1.0,
    sensor_id: str = "cart",
) -> Iterator[list[Detection]]:
    """A long, lazily generated stream for memory tests: targets on circles (radius 2 km,
    20 m/s, so 0.2 m/s^2 of acceleration), one Cartesian sensor, clutter in the 6 km square."""
    centre = rng.uniform(-1000.0, 1000.0, size=(n_targets, 2))
    phase = rng.uniform(0, 2 * np.pi, size=n_targets)
    w = 20.0 / 2000.0
    seq = 0
    step = round(period_s * NS_PER_S)
    for k in range(n_scans):
        t = k * step
        a = phase + w * t / NS_PER_S
        p = centre + 2000.0 * np.stack([np.cos(a), np.sin(a)], axis=1)
        p = p[rng.random(n_targets) < pd]
        z = p + rng.normal(0.0, std_m, size=p.shape)
        nc = rng.poisson(clutter_mean)
        z = np.concatenate([z, rng.uniform(-3000.0, 3000.0, size=(nc, 2))])
        batch = []
        for j in rng.permutation(len(z)):
            batch.append(Detection.of(sensor_id, t, seq, z[j]))
            seq += 1
        yield batch
