"""The recording's cost with and without truth, fed fast, per measurement (goal 2 of issue 11:
<= 10 us a measurement).

bench.recording_cost sends the truth of every target at every radar scan, as a simulation does,
so every estimate is scored (error, NEES, OSPA/GOSPA: fusion.io.track_rows). A deployment has no
truth (it comes from simulators only), so this runs the same thing both ways: recording_cost's
data and the same data with the truth samples left out (`without_truth`), each through
recording_cost's `_run` (configs/service.toml's tracker and its rotating recording, one
`Pipeline.ingest` per scan, the sink's calls timed in thread CPU time less the timer's own
cost), interleaved, `repeats` times. Reported, median [min, max]: the CPU time inside the sink
per measurement from the first scan after WARM_S of wall time to the end, the final flush and
close included (recording_cost's "in sink" column), with truth, without, and the difference:
what logging truth and scoring every estimate against it costs. The measurements, and so the
tracks, are the same both ways."""

from __future__ import annotations

import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench import recording_cost as rc
from fusion.config import load_service_config
from fusion.io.gc_tuning import settle_garbage_collector


def without_truth(data: list[list[tuple[int, str, bytes]]]) -> list[list[tuple[int, str, bytes]]]:
    """`data` (rc.batches: one list of (arrival_ns, key, payload) per scan) with the truth samples
    left out; every measurement kept, in its place."""
    return [[r for r in recs if "/truth/" not in r[1]] for recs in data]


def _in_sink_us(marks: Any, meas: np.ndarray) -> float:
    """CPU us in the sink per measurement, from the first scan after rc.WARM_S to the end (the close
    included), of one rc._run's marks."""
    k0 = int(np.searchsorted(marks[:-1, 0], rc.WARM_S))
    n = meas[-1] - meas[k0]
    if n <= 0:
        raise RuntimeError("the run ended within its warm-up; raise recording_cost.RATE")
    return float((marks[-1, 2] - marks[k0, 2]) / n * 1e6)


def run(*, quick: bool = False, sizes: tuple[int, ...] = (10, 100)) -> dict[str, float]:
    settle_garbage_collector()
    repeats = 1 if quick else 3
    ns = load_service_config(rc.CONFIG).namespace
    with tempfile.TemporaryDirectory() as d:  # compiled kernels, imports, Rerun: loaded before any timing
        rc._run(rc.batches(20, 2.0, ns=ns), record=True, tmp=Path(d))
    rc._Timed.overhead_s = rc.timer_overhead_s()
    print(f"recording cost with and without truth, fed fast, shipped configuration; CPU in the sink per "
          f"measurement (the timer's {rc._Timed.overhead_s * 1e6:.2f} us a call taken off), median [min, max] of "
          f"{repeats} interleaved repeats")
    print(f"{'targets':>7} {'meas':>7} {'with truth us/meas':>20} {'without us/meas':>20} {'truth us/meas':>20}")
    out: dict[str, float] = {}
    for n_targets in sizes:
        wall_s = rc.WARM_S + rc.MEASURED_S
        with_t = rc.batches(n_targets, wall_s * rc.RATE[n_targets] / (rc.PER_S * n_targets), ns=ns)
        data = {True: with_t, False: without_truth(with_t)}
        meas = rc._measurements_so_far(with_t)
        got: dict[bool, list[float]] = {True: [], False: []}
        with tempfile.TemporaryDirectory() as d:
            for k in range(repeats):
                for truth in (True, False):
                    marks, applied = rc._run(data[truth], record=True, tmp=Path(d) / f"r{k}{truth:d}")
                    assert applied == meas[-1], (applied, meas[-1])  # every measurement applied, both ways
                    got[truth].append(_in_sink_us(marks, meas))
        diff = [a - b for a, b in zip(got[True], got[False], strict=True)]

        def spread(v: list[float]) -> str:
            return f"{statistics.median(v):.1f} [{min(v):.1f}, {max(v):.1f}]"

        print(f"{n_targets:>7} {int(meas[-1]):>7} {spread(got[True]):>20} {spread(got[False]):>20} "
              f"{spread(diff):>20}")
        out[f"recording_{n_targets}_with_truth_in_sink_cpu_us_per_meas"] = statistics.median(got[True])
        out[f"recording_{n_targets}_without_truth_in_sink_cpu_us_per_meas"] = statistics.median(got[False])
    return out


if __name__ == "__main__":
    sel = tuple(int(a) for a in sys.argv[1:] if a.isdigit()) or (10, 100)
    run(quick="--quick" in sys.argv, sizes=sel)
