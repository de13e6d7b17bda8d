"""Simulated sensors: pure and seeded, no I/O. Truth in, (arrival_ns, Measurement) out.

Per scan: each target is detected with probability pd (its measurement lost on the way with
probability `dropout`), Poisson(clutter_per_scan) false alarms appear uniformly in the
clutter region, every message gets a latency base_ms + gamma jitter, and with probability
`duplicate` is sent a second time a little later. seq counts every message a sensor sends,
in sensor-time order, so gaps in seq come only from drop-outs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion import messages as m
from fusion.core.measurement import wrap_angle
from fusion.core.pose import Pose
from publishers.spec import SensorSpec, SimulatedCartesian, SimulatedRadar
from publishers.truth import TargetTruth


@dataclass(frozen=True)
class Emitted:
    arrival_ns: int
    msg: m.Measurement


def _scan_times(t_ns: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Indices of the truth samples at which the sensor measures."""
    if rate_hz is None or len(t_ns) < 2:
        return np.arange(len(t_ns))
    period_ns = 1e9 / rate_hz
    want = np.arange(t_ns[0], t_ns[-1] + 1, period_ns)
    idx = np.unique(np.clip(np.searchsorted(t_ns, want), 0, len(t_ns) - 1))
    return idx


def _pose(spec: SensorSpec, d: int) -> Pose:
    angles = {"heading_rad": spec.heading_rad} if d > 1 else {}
    if d == 3:
        angles.update(pitch_rad=spec.pitch_rad, roll_rad=spec.roll_rad)
    return Pose.create(spec.position_m or [0.0] * d, **angles)


def _radar(spec: SimulatedRadar, pos: np.ndarray, vel: np.ndarray | None, rng: np.random.Generator) -> m.Radar:
    """Range, bearing (elevation in 3-D), range rate of a world point, in the radar's frame."""
    pose = _pose(spec, len(pos))
    d = pose.to_sensor(pos)
    r = float(np.linalg.norm(d))
    b = float(wrap_angle(np.arctan2(d[1], d[0]) + rng.normal(0, spec.bearing_std_rad)))
    kw: dict[str, float] = {}
    if len(pos) == 3:
        el = np.arctan2(d[2], np.hypot(d[0], d[1])) + rng.normal(0, spec.elevation_std_rad)
        kw["elevation_rad"] = float(np.clip(el, -np.pi / 2, np.pi / 2))
        kw["elevation_std_rad"] = spec.elevation_std_rad  # type: ignore[assignment]
    if spec.range_rate and vel is not None:
        kw["range_rate_mps"] = float((pos - pose.t) @ vel / r + rng.normal(0, spec.range_rate_std_mps))
        kw["range_rate_std_mps"] = spec.range_rate_std_mps  # type: ignore[assignment]
    return m.Radar(range_m=max(r + rng.normal(0, spec.range_std_m), m.MIN_RANGE_M), bearing_rad=b,
                   range_std_m=spec.range_std_m, bearing_std_rad=spec.bearing_std_rad, **kw)


def _cartesian(spec: SimulatedCartesian, pos: np.ndarray, rng: np.random.Generator) -> m.Cartesian:
    """A world point in the sensor's frame, with the sensor's noise."""
    std = np.asarray(spec.std_m, dtype=np.float64)
    z = _pose(spec, len(pos)).to_sensor(pos)
    return m.Cartesian(pos_m=(z + rng.normal(0, 1, len(pos)) * std).tolist(), std_m=std.tolist())


def _latency_ns(spec: SensorSpec, rng: np.random.Generator) -> int:
    lat = spec.latency
    j = rng.gamma(lat.shape, lat.jitter_ms / lat.shape) if lat.jitter_ms > 0 else 0.0
    return round((lat.base_ms + j) * 1e6)


def simulate_sensor(spec: SensorSpec, truths: list[TargetTruth], rng: np.random.Generator) -> list[Emitted]:
    """Every message the sensor sends, in sending order (sensor time, then target)."""
    base = truths[0]
    d = len(base.positions()[0])
    out: list[Emitted] = []
    seq = 0
    region = np.asarray(spec.clutter_region_m, dtype=np.float64).reshape(-1, 2) if spec.clutter_region_m else None
    for k in _scan_times(base.t_ns, spec.rate_hz):
        t = int(base.t_ns[k])
        datas: list[m.Cartesian | m.Radar] = []
        for tr in truths:
            if k >= len(tr.t_ns) or rng.random() >= spec.pd:
                continue
            pos = tr.positions()[k]
            vel_idx = [tr.layout.index(a) for a in ("vx", "vy", "vz")[:d] if a in tr.layout]
            vel = tr.states[k, vel_idx] if len(vel_idx) == d else None
            radar = isinstance(spec, SimulatedRadar)
            datas.append(_radar(spec, pos, vel, rng) if radar else _cartesian(spec, pos, rng))  # type: ignore[arg-type]
        n_false = rng.poisson(spec.clutter_per_scan) if spec.clutter_per_scan > 0 and region is not None else 0
        for _ in range(n_false):
            p = rng.uniform(region[:d, 0], region[:d, 1])  # type: ignore[index]
            datas.append(_radar(spec, p, None, rng) if isinstance(spec, SimulatedRadar) else _cartesian(spec, p, rng))
        for data in datas:
            msg = m.Measurement(sensor_id=spec.id, t_ns=t, seq=seq, data=data)
            seq += 1
            if rng.random() < spec.dropout:
                continue
            arrival = t + _latency_ns(spec, rng)
            out.append(Emitted(arrival, msg))
            if rng.random() < spec.duplicate:
                out.append(Emitted(arrival + _latency_ns(spec, rng) + 1_000_000, msg))
    return out
