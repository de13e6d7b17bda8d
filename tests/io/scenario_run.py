"""A small, seeded tracker run with truth, for the recording tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.config import CartesianSensorConfig, LifecycleConfig, MotionConfig, TrackerConfig
from fusion.scenarios import reference
from fusion.tracking.detection import Detection
from fusion.tracking.results import Estimate, StepResult
from fusion.tracking.tracker import Tracker


@dataclass
class Run:
    tracker: Tracker
    results: list[StepResult]
    truth: dict[int, np.ndarray]  # t_ns -> true state


def maneuver_run(*, seed: int = 3) -> tuple[Tracker, list[Detection], dict[int, np.ndarray]]:
    """maneuver2d of scenarios.md as one Cartesian sensor feeding the tracker."""
    ref = reference("maneuver2d", seed=seed)
    cfg = TrackerConfig(
        sensors=[CartesianSensorConfig(id="pos", std_m=[0.1, 0.1])],
        motion=MotionConfig(accel_psd_m2s3=0.0025),
        lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3),
    )
    dets = [Detection.of("pos", int(t), k, z) for k, (t, z) in enumerate(zip(ref.t_ns, ref.z, strict=True))]
    truth = {int(t): x for t, x in zip(ref.t_ns, ref.truth, strict=True)}
    return Tracker(cfg), dets, truth


def latest(results: list[StepResult]) -> dict[tuple[int, int, str], Estimate]:
    """The consumer's view: latest revision per (track, time, sensor), retractions removed."""
    out: dict[tuple[int, int, str], Estimate] = {}
    for r in results:
        for e in r.estimates:
            k = (e.track_id, e.t_ns, e.sensor_id)
            if e.status == "retracted":
                out.pop(k, None)
            else:
                out[k] = e
    return out


def record_scenario(name: str, path, *, duration_s: float | None = None, flush_rows: int = 200_000,
                    flush_interval_s: float = 0.5, view_interval_s: float | None = None):
    """The reference scenario `name` (configs/scenarios/<name>.toml) as the service runs it: its
    stream of samples (measurements and truth) through the Pipeline with a RerunSink writing
    `path` (flushed as the arguments say; view_interval_s None: the sink's default). Returns the
    pipeline (its tracker and counts) after the sink is closed."""
    import msgspec

    from fusion.io import wire
    from fusion.io.rerun_sink import VIEW_INTERVAL_S, RerunSink
    from fusion.pipeline import Pipeline
    from publishers.spec import load_scenario_file, scenario_path
    from publishers.stream import build_stream

    sf = load_scenario_file(scenario_path(name))
    spec = sf.scenario if duration_s is None else msgspec.structs.replace(sf.scenario, duration_s=duration_s)
    samples, _ = build_stream(spec, namespace=sf.service.namespace)
    tracker = Tracker(sf.service.tracker)
    pipe: Pipeline | None = None
    sink = RerunSink(path, recording_id=name, layout=tracker.layout, position_indices=tracker.position_indices,
                     velocity_indices=tracker.velocity_indices, meta={"scenario": name},
                     counts=lambda: pipe.counts().flat(),  # type: ignore[union-attr]
                     flush_rows=flush_rows, flush_interval_s=flush_interval_s,
                     view_interval_s=VIEW_INTERVAL_S if view_interval_s is None else view_interval_s)
    pipe = Pipeline(tracker, wire.Codec(sf.service.namespace), sink=sink)
    records = [(s.arrival_ns, s.key, s.payload) for s in samples]
    try:
        for i in range(0, len(records), 50):
            pipe.ingest(records[i:i + 50])
    finally:
        sink.close()
        pipe.warn.flush()  # its held-back warnings now, not in another test's flush_all
    return pipe
