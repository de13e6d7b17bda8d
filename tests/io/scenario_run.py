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
