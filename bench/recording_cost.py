"""Cost of recording every step to Rerun, per measurement, at 10, 100 and 1000 targets, in the
shipped configuration.

What runs: `configs/service.toml`'s tracker (IMM of CV and CT, radar1 + cam1) behind
fusion.pipeline.Pipeline, the path every sample takes in `fusion serve`, with the recording the
service builds from its [recording] section (fusion.io.recording.service_recording: rotating
files, flushed every `flush_interval_s`, behind fusion.io.recording_guard.GuardedSink), and
`maybe_flush` after every batch as the service's loop does. Python's collector settled as
`fusion serve` settles it (fusion.io.gc_tuning).
The load: bench.e2e_load.Scene (T targets, radar1 at 10 Hz, cam1 at 5 Hz: 15 measurements per
target per second, as msgpack Measurements) plus every target's truth at every radar scan (so
every estimate is scored: error, NEES, OSPA/GOSPA), one `Pipeline.ingest` per scan (a service
keeping up in real time: the most steps, so the most per-step cost, per measurement).
Baseline: the same pipeline with the recording off, interleaved with it in every repeat.
Reported, per measurement: the cost = (with - without) / measurements, in wall time (the
machine's load makes it noisy) and in CPU time of the whole process (time.process_time: every
thread, Rerun's encoding and writing threads too, which share the 2 cores; other processes do not
count); and the CPU time inside the sink's calls (log_truths, log_step, maybe_flush; thread
time, less what the timer itself adds to each call: timer_overhead_s, measured in the run and
printed). Measured: the scans after the first WARM_S wall seconds of the recording-on run (the same scans
in the run without) up to the end, the final flush and close included (every row recorded is
paid for; about MEASURED_S seconds: more than one view flush). A file's start (the sink's CPU
time in its first WARM_S seconds) and its final flush and close (within the measured figure)
are also shown in ms. Also shown: the sink's CPU time per measurement in a file's steady state,
from the first scan after the warm-up at which the recording's viewed tracks are all chosen
(before that every confirmed track's rows are kept as a candidate's: fusion.io.viewed) to the
last scan, the close left out (once per file; a service's file lives up to rotate_s).
Median [min, max] over the repeats.
In real time (10 and 100 targets, REAL_S seconds each): the same data sent at their own pace,
each scan when its arrival time comes (150 and 1 500 measurements/s), the way a service with
those sensors sees them. The runs above go 15-70x faster and put ~2 000-6 000 measurements in
every record flush; here a flush interval (flush_interval_s, 0.2 s) holds ~30 or ~300 of them,
so what a flush costs whatever it holds (~0.8 ms at 10 targets) is paid per few measurements.
Reported: the CPU time inside the sink per measurement and per second over ~20 s of a file's
steady state, from the first scan after its first view flush (REAL_WARM_S: what a file pays once,
the layout and the views' series styles, is behind) to the last scan (the second view flush
falls inside), its close left out: a close (~40 ms at 10 targets) comes once per file, which a
service keeps up to rotate_s (an hour), and 20 s of 10 targets hold only ~3 000 measurements to
spread it over; it is shown apart, in ms. And the record flushes per second. No baseline is
needed (the sink alone is timed); the wall-time cost is the sleep. These runs come first, right
after the warm-up: made after the fast runs in the same process they were slower (100 targets:
20.1 us per measurement, against 14.7 in a fresh process with the same settings, 2026-12-06).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.e2e_load import SENSORS, Scene
from fusion import messages as m
from fusion.config import load_service_config, mode_names
from fusion.io import wire
from fusion.io.gc_tuning import settle_garbage_collector
from fusion.io.recording import service_recording
from fusion.io.recording_guard import GuardedSink
from fusion.io.rerun_sink import VIEW_INTERVAL_S
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "configs" / "service.toml"
TRUTH_LAYOUT = ["x", "vx", "y", "vy", "omega"]  # the scene flies straight: omega = 0


def batches(n_targets: int, seconds: float, *, ns: str, seed: int = 1) -> list[list[tuple[int, str, bytes]]]:
    """One list of (arrival_ns, key, payload) per scan: the truth of every target at radar scans,
    then the scan's measurements; arrival = sensor time + 1 ms."""
    scene = Scene(n_targets, seed)
    keys = [m.meas_key(ns, s) for s in SENSORS]
    t0 = 1_000_000_000
    out = []
    for t, s, payloads in scene.ticks(t0):
        if t - t0 >= seconds * 1e9:
            break
        recs = []
        if s == 0:
            for j in range(n_targets):
                x, y = scene.pos[j].tolist()
                vx, vy = scene.vel[j].tolist()
                tr = m.Truth(target_id=f"t{j}", t_ns=t, state=[x, vx, y, vy, 0.0], layout=TRUTH_LAYOUT)
                recs.append((t + 1_000_000, m.truth_key(ns, f"t{j}"), m.encode(tr)))
        recs.extend((t + 1_000_000, keys[s], p) for p in payloads)
        out.append(recs)
    return out


class _Timed:
    """The pipeline's sink, timing the calls it passes on (CPU time of the calling thread: the
    machine's other load does not count), net of `overhead_s` per call: what a timed call with
    nothing inside adds (timer_overhead_s), which the service, calling its sink untimed, does
    not pay."""

    overhead_s = 0.0

    def __init__(self, sink: Any) -> None:
        self.sink = sink
        self.inside_s = 0.0

    def log_step(self, result: Any, *, arrival_ns: int | None = None) -> None:
        a = time.thread_time()
        self.sink.log_step(result, arrival_ns=arrival_ns)
        self.inside_s += time.thread_time() - a - self.overhead_s

    def log_truths(self, truths: Any) -> None:
        a = time.thread_time()
        self.sink.log_truths(truths)
        self.inside_s += time.thread_time() - a - self.overhead_s

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        a = time.thread_time()
        self.sink.log_text(t_ns, text, level)
        self.inside_s += time.thread_time() - a - self.overhead_s

    def maybe_flush(self) -> None:
        a = time.thread_time()
        self.sink.maybe_flush()
        self.inside_s += time.thread_time() - a - self.overhead_s

    def close(self) -> None:
        a = time.thread_time()
        self.sink.close()
        self.inside_s += time.thread_time() - a - self.overhead_s


class _Nothing:
    def log_truths(self, truths: Any) -> None: ...


def timer_overhead_s(calls: int = 5000, blocks: int = 7) -> float:
    """Seconds one _Timed call adds to inside_s with an empty sink behind it: the thread-CPU
    clock read twice (a system call each, ~0.6 us on this machine; truth samples alone make
    ~0.7 timed calls per measurement) and an empty call; the least of `blocks` means (the least
    disturbed: what is taken off is not more than the timer costs)."""
    means = []
    for _ in range(blocks):
        t = _Timed(_Nothing())
        for _ in range(calls):
            t.log_truths(())
        means.append(t.inside_s / calls)
    return min(means)


def _measurements_so_far(data: list) -> np.ndarray:
    """The measurements (samples not on a truth key) before each scan of `data`, and in all: (n_scans + 1,)."""
    return np.cumsum([0] + [sum(1 for _, key, _ in recs if "/truth/" not in key) for recs in data])


def _run(data: list, *, record: bool, tmp: Path, paced: bool = False) -> tuple[Any, int]:
    """Cumulative (wall s, process CPU s, CPU s inside the sink) after each scan, whether the
    recording's viewed tracks were all chosen by then (fusion.io.viewed: until then every
    confirmed track's rows are kept as a candidate's) and the record flushes so far (of the file's
    sink), (n_scans + 2, 5), and the measurements applied; the last row after a recording's final
    flush and close. `paced`: each scan waits for its arrival time (from the first scan's, in
    wall time), as in a service in real time."""
    cfg = load_service_config(CONFIG)
    tr = Tracker(cfg.tracker)
    pipe = Pipeline(tr, wire.Codec(cfg.namespace))
    timed = None
    if record:
        rotating = service_recording(
            cfg.recording, tmp, layout=tr.layout, position_indices=tr.position_indices,
            velocity_indices=tr.velocity_indices, counts=lambda: pipe.counts().flat(),
            meta={"namespace": cfg.namespace, "sensors": sorted(tr.sensors), "model": tr.model_name,
                  "modes": mode_names(cfg.tracker)})
        timed = _Timed(GuardedSink(rotating))
        pipe.sink = timed
    marks = np.zeros((len(data) + 2, 5))
    t0, c0 = time.perf_counter(), time.process_time()
    a0 = data[0][0][0] if data and data[0] else 0
    for k, recs in enumerate(data):
        if paced and recs:
            time.sleep(max(0.0, (recs[0][0] - a0) * 1e-9 - (time.perf_counter() - t0)))
        pipe.ingest(recs)
        if timed is not None:
            timed.maybe_flush()
        marks[k + 1] = (time.perf_counter() - t0, time.process_time() - c0, 0.0 if timed is None else timed.inside_s,
                        timed is not None and not rotating.sink.rows.choice.open,
                        0 if timed is None else rotating.sink.flushes)
    if timed is not None:
        timed.close()
        assert timed.sink.error is None, timed.sink.error
    marks[-1] = (time.perf_counter() - t0, time.process_time() - c0, 0.0 if timed is None else timed.inside_s,
                 marks[-2, 3], marks[-2, 4] + (timed is not None))  # the close's flush
    return marks, tr.counts.applied


WARM_S = 2.0  # wall seconds of a recording's start left out (its first flush and blueprint)
MEASURED_S = 20.0  # wall seconds measured after them, about: more than one view flush (VIEW_INTERVAL_S)
# measurements per wall second the pipeline handles here with the recording on, about (2026-12-05:
# 10.5k, 30.0k and 32.8k/s; 7.7k, 20.2k and 24.6k on 2026-12-04): the data are sized so that the
# timed window lasts ~MEASURED_S of wall time and holds a view flush (every 15 s); a slower machine
# only makes the window longer
RATE = {10: 10500.0, 100: 30000.0, 1000: 33000.0}
REAL_WARM_S = VIEW_INTERVAL_S + WARM_S  # a real-time run's first view flush is behind (its layout, series styles)
REAL_S = REAL_WARM_S + 20.0  # seconds of sensor time sent in real time (10 and 100 targets)
PER_S = 15  # measurements per target per second of sensor time (bench.e2e_load)


def run(*, quick: bool = False, sizes: tuple[int, ...] = (10, 100, 1000)) -> dict[str, float]:
    settle_garbage_collector()
    repeats = 1 if quick else 3
    ns = load_service_config(CONFIG).namespace
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as d:  # compiled kernels, imports, Rerun: loaded before any timing
        _run(batches(20, 2.0, ns=ns), record=True, tmp=Path(d))
    _Timed.overhead_s = timer_overhead_s()
    print(f"(the sink's timer: {_Timed.overhead_s * 1e6:.2f} us per timed call with nothing inside, taken off "
          "every call's time in the 'in sink' columns)")
    out["timer_overhead_us_per_call"] = _Timed.overhead_s * 1e6
    real = tuple(n for n in sizes if n in (10, 100))
    if real:  # first: after the fast runs, in this process, they were slower (module docstring)
        out.update(real_time(real, repeats=repeats, ns=ns))
    print("recording cost per measurement, shipped configuration (configs/service.toml: IMM, radar1 + cam1, "
          f"the service's rotating recording), truth of every target at every radar scan; median [min, max] of "
          f"{repeats} interleaved repeats")
    print(f"{'targets':>7} {'meas':>6} {'off us/meas':>12} {'on us/meas':>11} {'cost (wall) us/meas':>22} "
          f"{'cost (CPU) us/meas':>22} {'in sink (CPU) us/meas':>22} {'close ms':>9} {'start ms':>9} "
          f"{'steady in sink us/meas':>22} {'its meas':>8} {'window s':>8}")
    for n_targets in sizes:
        wall_s = WARM_S + MEASURED_S
        data = batches(n_targets, wall_s * RATE[n_targets] / (PER_S * n_targets), ns=ns)
        runs: dict[bool, list[tuple[Any, int]]] = {False: [], True: []}
        with tempfile.TemporaryDirectory() as d:
            for k in range(repeats):
                for record in (False, True):
                    runs[record].append(_run(data, record=record, tmp=Path(d) / f"r{k}"))
        meas = _measurements_so_far(data)
        wall, cpu, ins, off_us, on_us, n_steady, steady, n_chosen, window, ends = [], [], [], [], [], [], [], [], [], []
        for (off, n_off), (on, n_on) in zip(runs[False], runs[True], strict=True):
            assert n_off == n_on == meas[-1], (n_off, n_on, meas[-1])  # every measurement applied, both ways
            k0 = int(np.searchsorted(on[:-1, 0], WARM_S))  # the first scan after the warm-up
            k1 = len(data)
            if k0 >= k1 - 1:
                raise RuntimeError(f"{n_targets} targets: the run ended within its warm-up; raise RATE")
            n = meas[k1] - meas[k0]
            d_off, d_on = off[-1] - off[k0], on[-1] - on[k0]  # to the end: the final flush and close included
            wall.append((d_on[0] - d_off[0]) / n * 1e6)
            cpu.append((d_on[1] - d_off[1]) / n * 1e6)
            ins.append(d_on[2] / n * 1e6)
            off_us.append(d_off[0] / n * 1e6)
            on_us.append(d_on[0] / n * 1e6)
            n_steady.append(int(n))
            window.append(float(on[k1, 0] - on[k0, 0]))
            ends.append(float(on[k1, 0]))
            # a file in its steady state: from the first scan after the warm-up with the viewed
            # tracks all chosen to the last scan, the close left out (once per file)
            chosen = np.flatnonzero(on[1:k1 + 1, 3] > 0)
            if chosen.size:
                j0 = max(k0, int(chosen[0]) + 1)
                if j0 < k1 and meas[k1] > meas[j0]:
                    steady.append((on[k1, 2] - on[j0, 2]) / (meas[k1] - meas[j0]) * 1e6)
                    n_chosen.append(int(meas[k1] - meas[j0]))
        closing = [(on[-1, 2] - on[-2, 2]) * 1e3 for on, _ in runs[True]]
        warm = [on[int(np.searchsorted(on[:-1, 0], WARM_S)), 2] * 1e3 for on, _ in runs[True]]

        def spread(v: list[float]) -> str:
            return f"{statistics.median(v):8.1f} [{min(v):.1f}, {max(v):.1f}]" if v else "-"

        print(f"{n_targets:>7} {statistics.median(n_steady):>6.0f} {statistics.median(off_us):12.1f} "
              f"{statistics.median(on_us):11.1f} {spread(wall):>22} {spread(cpu):>22} {spread(ins):>22} "
              f"{statistics.median(closing):9.0f} {statistics.median(warm):9.0f} {spread(steady):>22} "
              f"{statistics.median(n_chosen) if n_chosen else 0:>8.0f} {statistics.median(window):>8.1f}")
        if min(ends) < VIEW_INTERVAL_S:
            print(f"  ({n_targets} targets: a run ended {min(ends):.1f} s after its file began, before the first "
                  f"view flush ({VIEW_INTERVAL_S:.0f} s): the machine ran faster than RATE assumes)")
        if steady:
            out[f"recording_{n_targets}_in_sink_steady_cpu_us_per_meas"] = statistics.median(steady)
        out[f"recording_{n_targets}_cost_wall_us_per_meas"] = statistics.median(wall)
        out[f"recording_{n_targets}_cost_cpu_us_per_meas"] = statistics.median(cpu)
        out[f"recording_{n_targets}_in_sink_cpu_us_per_meas"] = statistics.median(ins)
        out[f"recording_{n_targets}_off_us_per_meas"] = statistics.median(off_us)
    return out


def real_time(sizes: tuple[int, ...], *, repeats: int, ns: str) -> dict[str, float]:
    """The sink's CPU time per measurement with the data sent in real time (module docstring)."""
    print(f"in real time ({REAL_S:.0f} s of sensor time each, paced by arrival; CPU in the sink from the first "
          f"{REAL_WARM_S:.0f} s to the last scan, the close apart); median [min, max] of {repeats}")
    print(f"{'targets':>7} {'meas/s':>7} {'meas':>6} {'in sink (CPU) us/meas':>22} {'ms/s':>6} "
          f"{'record flushes/s':>17} {'close ms':>9}")
    out: dict[str, float] = {}
    for n_targets in sizes:
        data = batches(n_targets, REAL_S, ns=ns)
        meas = _measurements_so_far(data)
        ins, ms_s, per_s, n_meas, closing = [], [], [], [], []
        with tempfile.TemporaryDirectory() as d:
            for k in range(repeats):
                on, n = _run(data, record=True, tmp=Path(d) / f"p{k}", paced=True)
                assert n == meas[-1], (n, meas[-1])
                k0, k1 = int(np.searchsorted(on[:-1, 0], REAL_WARM_S)), len(data)
                n_t, wall_s = meas[k1] - meas[k0], on[k1, 0] - on[k0, 0]
                ins.append((on[k1, 2] - on[k0, 2]) / n_t * 1e6)
                ms_s.append((on[k1, 2] - on[k0, 2]) / wall_s * 1e3)
                n_meas.append(int(n_t))
                per_s.append((on[k1, 4] - on[k0, 4]) / wall_s)
                closing.append((on[-1, 2] - on[k1, 2]) * 1e3)
        print(f"{n_targets:>7} {PER_S * n_targets:>7} {statistics.median(n_meas):>6.0f} "
              f"{statistics.median(ins):8.1f} [{min(ins):.1f}, {max(ins):.1f}]      {statistics.median(ms_s):6.1f} "
              f"{statistics.median(per_s):17.1f} {statistics.median(closing):9.0f}")
        out[f"recording_{n_targets}_real_time_in_sink_cpu_us_per_meas"] = statistics.median(ins)
        out[f"recording_{n_targets}_real_time_in_sink_cpu_ms_per_s"] = statistics.median(ms_s)
    return out


if __name__ == "__main__":
    sel = tuple(int(a) for a in sys.argv[1:] if a.isdigit()) or (10, 100, 1000)
    run(quick="--quick" in sys.argv, sizes=sel)
