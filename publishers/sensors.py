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
from publishers.spec import SensorSpec
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


def _radar(spec: SensorSpec, pos: np.ndarray, vel: np.ndarray | None, rng: np.random.Generator) -> m.Radar:
    s = np.asarray(spec.position_m or [0.0] * len(pos), dtype=np.float64)
    d = pos - s
    r = float(np.linalg.norm(d))
    b = float(wrap_angle(np.arctan2(d[1], d[0]) - spec.heading_rad + rng.normal(0, spec.bearing_std_rad)))
    kw: dict[str, float] = {}
    if len(pos) == 3:
        el = np.arctan2(d[2], np.hypot(d[0], d[1])) + rng.normal(0, spec.elevation_std_rad)
        kw["elevation_rad"] = float(np.clip(el, -np.pi / 2, np.pi / 2))
        kw["elevation_std_rad"] = spec.elevation_std_rad
    if spec.range_rate and vel is not None:
        kw["range_rate_mps"] = float(d @ vel / r + rng.normal(0, spec.range_rate_std_mps))
        kw["range_rate_std_mps"] = spec.range_rate_std_mps
    return m.Radar(range_m=max(r + rng.normal(0, spec.range_std_m), 1e-3), bearing_rad=b,
                   range_std_m=spec.range_std_m, bearing_std_rad=spec.bearing_std_rad, **kw)


def _cartesian(spec: SensorSpec, pos: np.ndarray, rng: np.random.Generator) -> m.Cartesian:
    std = np.asarray(spec.std_m, dtype=np.float64)
    return m.Cartesian(pos_m=(pos + rng.normal(0, 1, len(pos)) * std).tolist(), std_m=std.tolist())


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
            datas.append(_radar(spec, pos, vel, rng) if spec.kind == "radar" else _cartesian(spec, pos, rng))
        n_false = rng.poisson(spec.clutter_per_scan) if spec.clutter_per_scan > 0 and region is not None else 0
        for _ in range(n_false):
            p = rng.uniform(region[:d, 0], region[:d, 1])  # type: ignore[index]
            datas.append(_radar(spec, p, None, rng) if spec.kind == "radar" else _cartesian(spec, p, rng))
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
