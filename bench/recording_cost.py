"""Amortised cost of recording every step to Rerun, per measurement.

The mix scenario (radar + Cartesian sensor, clutter, late arrivals) through the pipeline in
batches of 50 samples, with no sink, with the columnar RerunSink (fusion), and with a sink that
calls rec.log per row (the naive way), interleaved in one process. Reported: microseconds per
measurement, and the sink's share = (with sink - without) / measurements.
"""

from __future__ import annotations

import logging
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec

from fusion.io import wire
from fusion.io.rerun_sink import RerunSink
from fusion.pipeline import Pipeline
from fusion.tracking.results import StepResult
from fusion.tracking.tracker import Tracker
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream


class PerCallSink:
    """Logs every estimate with one rec.log call per archetype: the cost the columnar sink avoids."""

    def __init__(self, path: Path, tracker: Tracker) -> None:
        import rerun as rr

        self.rr = rr
        self.rec = rr.RecordingStream("fusion-bench", recording_id="percall")
        self.rec.save(str(path))
        self.pi = list(tracker.position_indices)

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        rr = self.rr
        for e in result.estimates:
            if e.status == "retracted":
                continue
            self.rec.set_time("t", timestamp=e.t_ns * 1e-9)
            self.rec.log(f"world/tracks/{e.track_id}", rr.Points2D([e.x[self.pi]]))
            self.rec.log(f"tracks/{e.track_id}/nis", rr.Scalars(e.nis or 0.0))

    def log_truth(self, target_id: str, t_ns: int, state: Any) -> None:
        pass

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        pass

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def _run(records: list, cfg: Any, ns: str, sink_kind: str, tmp: Path) -> tuple[float, float]:
    """(seconds of steady-state processing including every flush, seconds to open + close the file)."""
    tracker = Tracker(cfg.tracker)
    sink: Any = None
    t_open = time.perf_counter()
    if sink_kind == "columnar":
        sink = RerunSink(tmp / "c.rrd", layout=tracker.layout, position_indices=tracker.position_indices,
                         velocity_indices=tracker.velocity_indices, counts=lambda: tracker.counts.flat())
    elif sink_kind == "per-call":
        sink = PerCallSink(tmp / "p.rrd", tracker)
    fixed = time.perf_counter() - t_open
    pipe = Pipeline(tracker, wire.Codec(ns), sink=sink)
    t0 = time.perf_counter()
    for i in range(0, len(records), 50):
        pipe.ingest(records[i:i + 50])
    if isinstance(sink, RerunSink):
        sink.flush()  # every row handed to rerun: part of the steady-state cost
    steady = time.perf_counter() - t0
    t_close = time.perf_counter()
    if sink is not None:
        sink.close()
    return steady, fixed + time.perf_counter() - t_close


def run(*, quick: bool = False) -> dict[str, float]:
    logging.getLogger("fusion.pipeline").setLevel(logging.ERROR)
    sf = load_scenario_file(scenario_path("mix"))
    spec = msgspec.structs.replace(sf.scenario, duration_s=10.0 if quick else 60.0)
    samples, _ = build_stream(spec, namespace=sf.service.namespace)
    records = [(s.arrival_ns, s.key, s.payload) for s in samples]
    n_meas = sum(1 for s in samples if "/meas/" in s.key)
    repeats = 3 if quick else 7
    times: dict[str, list[float]] = {"none": [], "columnar": [], "per-call": []}
    fixed: dict[str, list[float]] = {k: [] for k in times}
    with tempfile.TemporaryDirectory() as d:
        for _ in range(repeats):
            for kind in times:  # interleaved, so drift hits all three alike
                steady, once = _run(records, sf.service, sf.service.namespace, kind, Path(d))
                times[kind].append(steady)
                fixed[kind].append(once)
    med = {k: statistics.median(v) for k, v in times.items()}
    base = med["none"]
    print(f"recording cost, mix scenario, {n_meas} measurements, median of {repeats} interleaved runs "
          "(steady state: every row buffered and flushed; opening and closing the file apart)")
    print(f"{'sink':>10} {'us/meas':>10} {'sink us/meas':>13} {'x no sink':>10} {'open+close ms':>14}")
    for k, v in med.items():
        print(f"{k:>10} {v / n_meas * 1e6:10.1f} {(v - base) / n_meas * 1e6:13.1f} {v / base:10.2f} "
              f"{statistics.median(fixed[k]) * 1e3:14.1f}")
    return {f"{k}_us_per_meas": v / n_meas * 1e6 for k, v in med.items()} | {
        "columnar_sink_us_per_meas": (med["columnar"] - base) / n_meas * 1e6,
        "per_call_sink_us_per_meas": (med["per-call"] - base) / n_meas * 1e6,
    }


if __name__ == "__main__":
    run()
