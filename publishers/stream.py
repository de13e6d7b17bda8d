"""A scenario as the exact list of samples to publish: pure and seeded, no I/O.

`build_stream(spec, namespace=...)` returns every sample (arrival_ns, key, payload), sorted by
(arrival_ns, key, payload) so that the same seed gives a byte-identical stream. Truth samples
arrive at their own time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion import messages as m
from fusion.scenarios import REFERENCE_NAMES, Reference
from publishers.sensors import Emitted, _latency_ns, simulate_sensor
from publishers.spec import LatencySpec, ScenarioSpec, SensorSpec, SimulatedCartesian, SimulatedRadar
from publishers.truth import TargetTruth, load_reference, mix_truth


@dataclass(frozen=True)
class Sample:
    arrival_ns: int
    key: str
    payload: bytes


def reference_sensor(ref: Reference, spec: SensorSpec | None) -> SensorSpec:
    """The single sensor of a reference scenario, with the document's noise; `spec` (optional)
    names it and sets its latency, drop-outs and duplicates."""
    std = np.sqrt(np.diag(ref.meas.R))
    common = {
        "latency": spec.latency if spec else LatencySpec(),
        "dropout": spec.dropout if spec else 0.0,
        "duplicate": spec.duplicate if spec else 0.0,
    }
    if ref.sensor_kind == "radar":
        return SimulatedRadar(id=spec.id if spec else "radar", range_std_m=float(std[0]),
                              bearing_std_rad=float(std[1]), **common)  # type: ignore[arg-type]
    return SimulatedCartesian(id=spec.id if spec else "pos", std_m=std.tolist(), **common)  # type: ignore[arg-type]


def _reference_messages(ref: Reference, sensor: SensorSpec, rng: np.random.Generator) -> list[Emitted]:
    """The reference scenario's own measurements, with the sensor's latency and losses."""
    out = []
    for k, (t, z) in enumerate(zip(ref.t_ns.tolist(), ref.z, strict=True)):
        if isinstance(sensor, SimulatedRadar):
            data: m.Cartesian | m.Radar = m.Radar(
                range_m=float(z[0]), bearing_rad=float(z[1]), range_std_m=sensor.range_std_m,
                bearing_std_rad=sensor.bearing_std_rad)
        else:
            data = m.Cartesian(pos_m=[float(v) for v in z], std_m=list(sensor.std_m))
        msg = m.Measurement(sensor_id=sensor.id, t_ns=int(t), seq=k, data=data)
        if rng.random() < sensor.dropout:
            continue
        arrival = int(t) + _latency_ns(sensor, rng)
        out.append(Emitted(arrival, msg))
        if rng.random() < sensor.duplicate:
            out.append(Emitted(arrival + _latency_ns(sensor, rng) + 1_000_000, msg))
    return out


def truths_of(spec: ScenarioSpec) -> tuple[list[TargetTruth], Reference | None]:
    if spec.source == "mix":
        duration = spec.duration_s or 60.0
        return mix_truth(n_targets=spec.targets, dt_s=spec.dt_s, duration_s=duration, seed=spec.seed), None
    if spec.source not in REFERENCE_NAMES:
        raise ValueError(f"unknown scenario source {spec.source!r}; known: mix, {', '.join(REFERENCE_NAMES)}")
    ref, truth = load_reference(spec.source, seed=spec.seed)
    return [truth], ref


def build_stream(spec: ScenarioSpec, *, namespace: str, t0_ns: int = 0,
                 epoch: int = 0) -> tuple[list[Sample], list[TargetTruth]]:
    """Every sample of the scenario, sorted by arrival; sensor and truth times offset by t0_ns;
    every measurement carries the publisher's `epoch` (its boot id, 0 for none)."""
    rng = np.random.default_rng(spec.seed + 1_000_003)
    truths, ref = truths_of(spec)
    if spec.duration_s is not None:
        limit = int(spec.duration_s * 1e9)
        truths = [TargetTruth(t.target_id, t.t_ns[t.t_ns <= limit], t.states[t.t_ns <= limit], t.layout)
                  for t in truths]
    emitted: list[Emitted] = []
    if ref is not None:
        sensor = reference_sensor(ref, spec.sensors[0] if spec.sensors else None)
        n = len(truths[0].t_ns)
        emitted = [e for e in _reference_messages(ref, sensor, rng) if e.msg.seq < n]
    else:
        for s in spec.sensors:
            emitted.extend(simulate_sensor(s, truths, np.random.default_rng([spec.seed, _stable(s.id)])))
    samples = []
    for e in emitted:
        msg = e.msg if t0_ns == 0 and epoch == 0 else m.Measurement(
            sensor_id=e.msg.sensor_id, t_ns=e.msg.t_ns + t0_ns, seq=e.msg.seq, data=e.msg.data, epoch=epoch)
        samples.append(Sample(e.arrival_ns + t0_ns, m.meas_key(namespace, msg.sensor_id), m.encode(msg)))
    if ref is not None and ref.u is not None:
        samples.extend(_reference_inputs(ref, namespace, t0_ns, len(truths[0].t_ns)))
    for tr in truths:
        key = m.truth_key(namespace, tr.target_id)
        for t, x in zip(tr.t_ns.tolist(), tr.states, strict=True):
            msg = m.Truth(target_id=tr.target_id, t_ns=int(t) + t0_ns, state=x.tolist(), layout=list(tr.layout))
            samples.append(Sample(int(t) + t0_ns, key, m.encode(msg)))
    samples.sort(key=lambda s: (s.arrival_ns, s.key, s.payload))
    return samples, truths


CONTROL_SOURCE = "control"  # the source id of a reference scenario's known input (cv1d_d)


def _reference_inputs(ref: Reference, namespace: str, t0_ns: int, n: int) -> list[Sample]:
    """The reference scenario's known input: u[k] drives the step that ends at t_ns[k], so it is
    published in force from the step's start (t_ns[k-1], or 0), on time."""
    key = m.input_key(namespace, CONTROL_SOURCE)
    out = []
    for k in range(n):
        t = (0 if k == 0 else int(ref.t_ns[k - 1])) + t0_ns
        msg = m.Input(source_id=CONTROL_SOURCE, t_ns=t, seq=k, u=[float(v) for v in ref.u[k]])  # type: ignore[index]
        out.append(Sample(t, key, m.encode(msg)))
    return out


def _stable(s: str) -> int:
    """A stable integer of a string (Python's hash() is salted per process)."""
    import zlib

    return zlib.crc32(s.encode())
