"""A step's measured points (StepResult.measurements: one ScanPoints per scan) are the
measurements that call took, each once, at the world position its sensor gives it, whether its
scan ran for the first time, ran again with more of its measurements (a rescan), or late."""

from __future__ import annotations

import numpy as np

from fusion.config import MotionConfig, TrackerConfig
from fusion.tracking.results import StepResult
from fusion.tracking.tracker import Tracker
from tests.tracking.streams import Sensor, constant_velocity, detect, in_order, scans

CART = Sensor("cam1", "cartesian", period_s=0.2, std_m=3.0)
RADAR = Sensor("radar1", "radar", period_s=0.1, offset_s=0.05, range_std_m=5.0, bearing_std_rad=0.003,
               position_m=(500.0, -800.0))


def _points(r: StepResult) -> dict[tuple[str, int, int], bytes]:
    out = {}
    for sp in r.measurements:
        assert sp.seq.dtype == np.int64 and sp.position.shape == (len(sp.seq), 2)
        for seq, p in zip(sp.seq.tolist(), sp.position, strict=True):
            assert (sp.sensor_id, sp.t_ns, seq) not in out, "a point twice in one step"
            out[(sp.sensor_id, sp.t_ns, seq)] = p.tobytes()
    assert len({(sp.sensor_id, sp.t_ns) for sp in r.measurements}) == len(r.measurements), "two blocks of a scan"
    return out


def test_each_call_reports_the_points_of_the_measurements_it_took() -> None:
    rng = np.random.default_rng(3)
    truth = constant_velocity(n_targets=6, duration_s=6.0, rng=rng, spread_m=300.0)
    dets = in_order(*(detect(truth, s, rng=rng, pd=0.9, clutter_mean=1.0, region_m=(-400, 400, -400, 400))
                      for s in (CART, RADAR)))
    batches = [[d.det for d in b] for b in scans(dets)]

    def tracker() -> Tracker:
        return Tracker(TrackerConfig(sensors=[CART.config(), RADAR.config()], motion=MotionConfig(model="cv")))

    whole = tracker()
    reference: dict[tuple[str, int, int], bytes] = {}
    for b in batches:
        reference.update(_points(whole.process(b)))
    assert len(reference) == len(dets)

    parts = tracker()  # every third scan in two calls (a rescan), every fifth held back two scans (late)
    calls: list[list] = []
    held: list = []
    for k, b in enumerate(batches):
        if k % 5 == 4:
            held.append(b)
            continue
        if k % 3 == 0 and len(b) > 1:
            calls += [b[: len(b) // 2], b[len(b) // 2:]]
        else:
            calls.append(b)
        if k % 5 == 1 and held:
            calls.append(held.pop())
    calls += held
    seen: dict[tuple[str, int, int], bytes] = {}
    for c in calls:
        got = _points(parts.process(c))
        assert sorted(got) == sorted((d.sensor_id, d.t_ns, d.seq) for d in c), "not the call's own measurements"
        assert not set(got) & set(seen)
        seen.update(got)
    assert seen == reference  # the same world points, bit for bit, however the scans were split or delayed
    assert parts.counts.rescans > 0 and parts.counts.replays > 0  # both ways of running a scan again were taken
