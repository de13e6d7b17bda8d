"""A small, seeded tracker run with truth, for the recording tests."""

from __future__ import annotations

from collections.abc import Callable
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


def record_scenario(name: str, path, *, duration_s: float | None = None, batch: int = 50,
                    shuffle_seed: int | None = None, flush_rows: int = 200_000, flush_interval_s: float = 0.5,
                    write_interval_s: float | None = None, write_rows: int | None = None,
                    view_interval_s: float | None = None, view_rows_max: int | None = None,
                    view_slice: int | None = None, background: bool = False, behind: bool = False,
                    late: tuple[int, float] | None = None, reorder: Callable[[list], list] | None = None):
    """The reference scenario `name` (configs/scenarios/<name>.toml) as the service runs it: its
    stream of samples (measurements and truth) through the Pipeline with a RerunSink writing
    `path` (flushed and written as the arguments say; view_interval_s, view_rows_max None: the sink's defaults), `batch`
    samples per ingest; with `shuffle_seed`, the measurements of each block of 40
    samples come in a seeded random order (more late arrivals; truth keeps its places); with
    `background`, the sink behind the service's recording thread (fusion.io.sink_thread, the loop's
    counts taken before every call); with `behind` too, the loop always busy and behind after every
    batch, with max_defer_s 0 (the loop and the writer both make calls, in turns as they come);
    with `late` = (n, s), every n-th measurement comes after the samples of the next s seconds of
    sensor time (a replay from far back in the window); `reorder`:
    any other change of the records (arrival_ns, key, payload), made last. Returns the pipeline
    (its tracker and counts) after the sink is closed."""
    import msgspec

    from fusion.io import wire
    from fusion.io.gain_groups import measured_components
    from fusion.io.recording_guard import GuardedSink
    from fusion.io.rerun_sink import VIEW_INTERVAL_S, VIEW_ROWS_MAX, VIEW_SLICE, WRITE_ROWS, RerunSink
    from fusion.io.sink_thread import MAX_DEFER_S, SinkThread
    from fusion.pipeline import Pipeline
    from publishers.spec import load_scenario_file, scenario_path
    from publishers.stream import build_stream

    sf = load_scenario_file(scenario_path(name))
    spec = sf.scenario if duration_s is None else msgspec.structs.replace(sf.scenario, duration_s=duration_s)
    samples, _ = build_stream(spec, namespace=sf.service.namespace)
    tracker = Tracker(sf.service.tracker)
    pipe: Pipeline | None = None
    writer = SinkThread(counts=lambda: pipe.counts().flat(), counts_every_s=0.0,  # type: ignore[union-attr]
                        max_defer_s=0.0 if behind else MAX_DEFER_S) if background else None
    sink = RerunSink(path, recording_id=name, layout=tracker.layout, position_indices=tracker.position_indices,
                     velocity_indices=tracker.velocity_indices,
                     meta={"scenario": name, "measured": measured_components(tracker.sensors, tracker.layout)},
                     counts=writer.counts if writer is not None else lambda: pipe.counts().flat(),  # type: ignore[union-attr]
                     flush_rows=flush_rows, flush_interval_s=flush_interval_s, write_interval_s=write_interval_s,
                     write_rows=WRITE_ROWS if write_rows is None else write_rows,
                     view_interval_s=VIEW_INTERVAL_S if view_interval_s is None else view_interval_s,
                     view_rows_max=VIEW_ROWS_MAX if view_rows_max is None else view_rows_max,
                     view_slice=VIEW_SLICE if view_slice is None else view_slice)
    if writer is not None:
        writer.start(GuardedSink(sink))
    pipe = Pipeline(tracker, wire.Codec(sf.service.namespace), sink=writer if writer is not None else sink)
    records = [(s.arrival_ns, s.key, s.payload) for s in samples]
    if shuffle_seed is not None:
        rng = np.random.default_rng(shuffle_seed)
        meas = [i for i, r in enumerate(records) if "/truth/" not in r[1]]
        order = list(range(len(records)))
        for b in range(0, len(meas), 40):
            block = meas[b:b + 40]
            for i, j in zip(block, rng.permutation(block).tolist(), strict=True):
                order[i] = j
        records = [records[j] for j in order]
    if late is not None:
        records = _delayed(records, every=late[0], late_ns=round(late[1] * 1e9))
    if reorder is not None:
        records = reorder(records)
    try:
        for i in range(0, len(records), batch):
            if behind and writer is not None:
                writer.loop_busy()
            pipe.ingest(records[i:i + batch])
            if behind and writer is not None:
                writer.behind()
    finally:
        (writer if writer is not None else sink).close()
        pipe.warn.flush()  # its held-back warnings now, not in another test's flush_all
    return pipe


def _delayed(records: list, *, every: int, late_ns: int) -> list:
    """Every `every`-th measurement moved after the samples up to `late_ns` of sensor time later."""
    held = [i for i, (_, k, _) in enumerate(records) if "/truth/" not in k][::every]
    return moved_later(records, {i: late_ns for i in held})


def moved_later(records: list, late_ns: dict[int, int]) -> list:
    """The records `i` of `late_ns` moved after the samples up to late_ns[i] of sensor time after
    their own (in their order of due time), the others in place."""
    from fusion import messages as m

    t_of = [m.decode_truth(p).t_ns if "/truth/" in k else m.decode_measurement(p).t_ns for _, k, p in records]
    due = sorted((t_of[i] + d, i) for i, d in late_ns.items())
    out = []
    for i, r in enumerate(records):
        if i in late_ns:
            continue
        while due and due[0][0] < t_of[i]:
            out.append(records[due.pop(0)[1]])
        out.append(r)
    return out + [records[i] for _, i in due]


def record_maneuver(path, *, seed: int = 3, batch: int = 1, sink=None) -> tuple[list[StepResult], dict]:
    """maneuver_run(seed) through the tracker, `batch` detections per step, into a RerunSink at
    `path` (or into `sink`, e.g. a RotatingSink), truth logged first. Returns (results, truth)."""
    from fusion.io.rerun_sink import RerunSink

    tr, dets, truth = maneuver_run(seed=seed)
    out = sink if sink is not None else RerunSink(
        path, layout=tr.layout, position_indices=tr.position_indices, velocity_indices=tr.velocity_indices,
        counts=lambda: tr.counts.flat())
    results = []
    try:
        for t, x in sorted(truth.items()):
            out.log_truths([("target", t, x)])
        for i in range(0, len(dets), batch):
            r = tr.process(dets[i:i + batch])
            results.append(r)
            out.log_step(r)
    finally:
        out.close()
    return results, truth


def write_scenario_stream(name: str, path, *, duration_s: float | None = None):
    """The samples of the reference scenario `name` as a .fstream (what `fusion demo` records
    beside its .rrd), for `fusion replay`; returns `path`."""
    import msgspec

    from fusion.io.streamfile import StreamWriter
    from publishers.spec import load_scenario_file, scenario_path
    from publishers.stream import build_stream

    sf = load_scenario_file(scenario_path(name))
    spec = sf.scenario if duration_s is None else msgspec.structs.replace(sf.scenario, duration_s=duration_s)
    samples, _ = build_stream(spec, namespace=sf.service.namespace)
    with StreamWriter(path, namespace=sf.service.namespace) as w:
        for s in samples:
            w.write(s.arrival_ns, s.key, s.payload)
    return path
